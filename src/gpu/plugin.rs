//! [`ClothGpuPlugin`]: cloths stepped by the GPU kernels inside Bevy's render graph, writing
//! their mesh's vertex slab in place.
//!
//! Frame flow for a cloth on the GPU:
//! 1. Main world, fixed schedule: `ClothSystems::Prepare` as for every cloth (pins follow
//!    their anchors, settings apply); [`choose_backends`] decides CPU or GPU; in
//!    `ClothSystems::Simulate` the CPU step is skipped and the step's pin targets, colliders
//!    and air are queued on [`ClothOnGpu`] instead.
//! 2. Extract: the queued steps, the entity's transform and (when the cloth was created or
//!    its settings changed) a snapshot of the simulation go to the render world.
//! 3. Render world, `Render` schedule (`PrepareResources`): buffers are made or updated.
//! 4. `RenderGraph` schedule, before the camera driver: the steps' compute passes, then the
//!    mesh write into the vertex slab; the main, shadow and prepass passes of the same frame
//!    draw the new shape. The step's status (NaN guard) and, for cloths with
//!    [`ClothReadback`] or leaving the GPU, the positions and velocities are copied to a
//!    staging buffer, mapped in `Cleanup`.
//! 5. Next extracts: mapped results go to the main world, where [`PreUpdate`] applies them
//!    to [`ClothSim`] (a few frames late), recovers a cloth whose state went bad, and hands
//!    a cloth that left the GPU to the CPU.

use std::collections::HashMap;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

use bevy::camera::visibility::NoFrustumCulling;
use bevy::core_pipeline::schedule::camera_driver;
use bevy::mesh::MeshVertexAttribute;
use bevy::prelude::*;
use bevy::render::mesh::allocator::{MeshAllocator, MeshAllocatorSettings};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderQueue};
use bevy::render::{Extract, ExtractSchedule, MainWorld, Render, RenderApp, RenderSystems};

use super::kernels::{GpuCloth, GpuKernels, GpuStepInput, sum_impulses};
use super::mesh::{MeshKernel, MeshWriter, TangentSource, VertexLayout};
use crate::cloth::{Cloth, ClothSim, ClothSteppedElsewhere, ClothTorn};
use crate::collider::{ClothColliders, ClothContactImpulse};
use crate::foundation::{ClothSchedule, ClothSystems, EntityName};
use crate::solver::{Collider, ContactImpulse, Simulation};
use crate::wind::ClothWindField;

/// Which solver steps a cloth.
///
/// Put it on a [`Cloth`](crate::cloth::Cloth) entity; without it the cloth uses
/// [`ClothGpuPlugin::default_backend`]. Which one a cloth actually runs on, and why, is in
/// [`ClothBackendInUse`].
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Component)]
pub enum ClothBackend {
    /// The CPU solver: every feature, results in [`ClothSim`] every step.
    Cpu,
    /// The GPU kernels in the render graph; the CPU (with a warning) where the GPU cannot
    /// run this cloth.
    Gpu,
    /// The GPU where it can run this cloth, else the CPU (with an info line saying why).
    #[default]
    Auto,
}

/// The backend a cloth runs on now, and why not the other (set by [`ClothGpuPlugin`]).
#[derive(Component, Clone, Debug, Default, PartialEq, Eq)]
pub struct ClothBackendInUse {
    /// Whether the GPU steps it.
    pub gpu: bool,
    /// Why it is not on the GPU (when it is not and the GPU was asked for), in words.
    pub reason: Option<String>,
}

/// Whether this app can run cloths on the GPU (a main-world resource, set in
/// `Plugin::finish`).
#[derive(Resource, Clone, Debug, PartialEq, Eq)]
pub struct ClothGpuSupport {
    /// `None` when available; otherwise why not.
    pub unavailable: Option<String>,
}

/// Runs cloths on the GPU: their steps go to the render world, run as compute passes in the
/// `RenderGraph` schedule before the camera driver, and land in the mesh's vertex slab.
///
/// Part of [`ClothPlugins`](crate::ClothPlugins) with `default_backend: Cpu`: nothing
/// changes until a cloth asks for [`ClothBackend::Gpu`] or [`ClothBackend::Auto`], or the
/// default is set, e.g. `ClothPlugins::default().set(ClothGpuPlugin { default_backend:
/// ClothBackend::Auto })`. In an app without a renderer (`MinimalPlugins`) every cloth runs on
/// the CPU.
///
/// What the GPU backend runs: the lab solver, PBD and XPBD with substeps and iterations,
/// stretch, shear, isometric and dihedral bending, pins (moving with their anchors, with the
/// teleport rule), tethers, gravity, damping, the speed limit, air drag/lift/friction with the
/// wind, sphere/box/capsule/plane and mesh (baked SDF) colliders with friction, self-collision
/// (in its parallel form: each vertex moves by the mean of its contacts' corrections; the CPU
/// projects contacts one by one), tearing (checked on the GPU, done on the CPU after a
/// readback), normals and tangents. What keeps a cloth on the CPU: `BendingSolve::Implicit`.
/// Bending the CPU would solve implicitly under `BendingSolve::Auto` is projected.
///
/// The results stay on the GPU: [`ClothSim`]'s state is the one the cloth started from unless
/// the cloth has [`ClothReadback`]. What comes back from the GPU comes a few frames late
/// (three or four with Bevy's pipelined rendering): read-back states, contact impulses on
/// colliders (added to their `ClothContactImpulse`), tears (`ClothTorn`), and the recovery of
/// a NaN or infinite state (as on the CPU: rest pose, [`ClothSim::recoveries`], a warning).
/// A change of settings or pins carries the GPU state over; an edit through
/// [`ClothSim::simulation_mut`] restarts the GPU cloth from the edited state; switching to the
/// CPU reads the state back first (the cloth holds still until it arrives).
#[derive(Clone, Copy, Debug)]
pub struct ClothGpuPlugin {
    /// Backend of cloths without a [`ClothBackend`] component.
    pub default_backend: ClothBackend,
}

impl Default for ClothGpuPlugin {
    fn default() -> Self {
        Self {
            default_backend: ClothBackend::Cpu,
        }
    }
}

#[derive(Resource, Clone, Copy)]
struct DefaultBackend(ClothBackend);

/// What the render world needs to build a cloth's buffers.
struct GpuUpload {
    sim: Simulation,
    weld: crate::solver::Weld,
    drawn: Vec<u32>,
    layout: VertexLayout,
    tangents: Option<TangentSource>,
    /// Start from the GPU state of the previous upload (a settings change), not from `sim`'s.
    carry: bool,
}

/// Copies a GPU cloth's positions and velocities into its [`ClothSim`] every frame, a frame
/// or two after the GPU computed them (opt-in: the copy costs bus bandwidth and CPU time).
///
/// Without it a GPU cloth's [`ClothSim`] keeps the state the cloth started from: gameplay that
/// reads vertex positions, strain or sleep state of a GPU cloth needs this component.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Component)]
pub struct ClothReadback;

/// A cloth that left the GPU and waits for its last GPU state before the CPU steps it on.
#[derive(Component)]
pub(crate) struct ClothLeavingGpu {
    generation: u64,
    frames: u32,
}

/// Frames a cloth leaving the GPU waits for its state before going on from the main world's.
const LEAVE_TIMEOUT_FRAMES: u32 = 30;

/// Removing [`Cloth`] removes its GPU components too.
fn forget_gpu_cloth(removed: On<Remove, Cloth>, mut commands: Commands) {
    commands.entity(removed.entity).try_remove::<(
        ClothOnGpu,
        ClothLeavingGpu,
        ClothBackendInUse,
        ClothSteppedElsewhere,
        NoFrustumCulling,
    )>();
}

/// What a GPU frame read back for one cloth.
struct GpuResult {
    entity: Entity,
    generation: u64,
    /// A step left a NaN or infinite position or velocity.
    failed: bool,
    /// A step ended with an edge past the tear threshold.
    torn: bool,
    /// Positions and velocities, when asked for.
    state: Option<(Vec<Vec4>, Vec<Vec4>)>,
    /// The impulse the frame's steps gave each collider.
    impulses: Vec<(Entity, ContactImpulse)>,
}

/// GPU cloths' impulses on colliders, waiting for the next fixed step's
/// [`ClothContactImpulse`](crate::collider::ClothContactImpulse)s.
#[derive(Resource, Default)]
struct GpuImpulses(Vec<(Entity, ContactImpulse)>);

/// Results waiting for the main world (filled during extraction).
#[derive(Resource, Default)]
struct GpuClothResults(Vec<GpuResult>);

/// A cloth the GPU steps, with this frame's queued steps (main world).
#[derive(Component)]
pub struct ClothOnGpu {
    generation: u64,
    upload: Arc<GpuUpload>,
    /// [`ClothSim::simulation_mut`] calls the upload was made after.
    edits: u64,
    /// Upload the main world's state again (after a recovery).
    restart: bool,
    /// Settings the upload was made with (a change re-uploads).
    key: String,
    pending: Vec<Vec<Vec3>>,
    /// Per pending step, how far the whole cloth jumps at its start (the teleport rule).
    teleports: Vec<Vec3>,
    dt: f32,
    colliders_first: Vec<Collider>,
    colliders_last: Vec<Collider>,
    /// The entities of `colliders_last`.
    collider_entities: Vec<Entity>,
    air: Vec<Vec4>,
}

impl ClothOnGpu {
    /// Steps queued for the GPU this frame.
    #[must_use]
    pub fn queued_steps(&self) -> usize {
        self.pending.len()
    }
}

impl Plugin for ClothGpuPlugin {
    fn build(&self, app: &mut App) {
        let schedule = ClothSchedule::of(app);
        app.register_type::<ClothBackend>()
            .register_type::<ClothReadback>()
            .insert_resource(DefaultBackend(self.default_backend))
            .init_resource::<GpuClothResults>()
            .init_resource::<GpuImpulses>()
            .add_observer(forget_gpu_cloth)
            .add_systems(First, clear_queued_steps)
            .add_systems(PreUpdate, apply_gpu_results)
            .add_systems(
                schedule,
                (
                    // Between the phases: once every cloth is built and its settings and pins
                    // are applied, before anything steps.
                    choose_backends
                        .after(ClothSystems::Prepare)
                        .before(ClothSystems::Simulate),
                    (queue_gpu_steps, add_gpu_impulses).in_set(ClothSystems::Simulate),
                ),
            );
        let has_renderer = app.get_sub_app(RenderApp).is_some();
        // Refined in `finish`, once the renderer has its device.
        app.insert_resource(ClothGpuSupport {
            unavailable: Some(
                if has_renderer {
                    "the renderer is not set up yet"
                } else {
                    "the app has no renderer"
                }
                .to_owned(),
            ),
        });
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        let (sender, receiver) = channel();
        render_app
            .init_resource::<ExtractedGpuCloths>()
            .init_resource::<GpuClothInstances>()
            .insert_resource(ReadbackChannel {
                sender,
                receiver: Mutex::new(receiver),
            })
            .add_systems(
                ExtractSchedule,
                (send_gpu_results, extract_gpu_cloths).chain(),
            )
            .add_systems(
                Render,
                (
                    prepare_gpu_cloths.in_set(RenderSystems::PrepareResources),
                    map_readbacks.in_set(RenderSystems::Cleanup),
                ),
            )
            .add_systems(RenderGraph, run_gpu_cloths.before(camera_driver));
    }

    fn finish(&self, app: &mut App) {
        let unavailable = match app.get_sub_app_mut(RenderApp) {
            None => Some("the app has no renderer".to_owned()),
            Some(render_app) => match render_app.world().get_resource::<RenderDevice>() {
                None => Some("the renderer has no device".to_owned()),
                Some(device) => match GpuKernels::check_limits(&device.limits()) {
                    Err(e) => Some(e.0),
                    Ok(()) => {
                        let wgpu_device = device.wgpu_device();
                        let pipelines = GpuClothPipelines {
                            kernels: GpuKernels::new(wgpu_device),
                            mesh: MeshKernel::new(wgpu_device),
                        };
                        let world = render_app.world_mut();
                        world.insert_resource(pipelines);
                        // Mesh slabs as storage buffers, so the kernels write vertices in
                        // place (read when the allocator is made, at render startup).
                        if let Some(mut settings) =
                            world.get_resource_mut::<MeshAllocatorSettings>()
                        {
                            settings.extra_buffer_usages |= wgpu::BufferUsages::STORAGE;
                            None
                        } else {
                            Some("the renderer has no mesh allocator".to_owned())
                        }
                    }
                },
            },
        };
        if let Some(why) = &unavailable {
            debug!("bevy_cloth: GPU backend unavailable: {why}");
        }
        app.insert_resource(ClothGpuSupport { unavailable });
    }
}

/// Where positions and normals sit in `mesh`'s interleaved vertex buffer (attributes sorted
/// by id, tightly packed), or why the GPU cannot write it.
fn vertex_layout(mesh: &Mesh) -> Result<VertexLayout, String> {
    let mut offset = 0u32;
    let (mut position, mut normal, mut tangent) = (None, None, None);
    for (attribute, _) in mesh.attributes() {
        let attribute: &MeshVertexAttribute = attribute;
        if attribute.id == Mesh::ATTRIBUTE_POSITION.id {
            position = Some(offset);
        } else if attribute.id == Mesh::ATTRIBUTE_NORMAL.id {
            normal = Some(offset);
        } else if attribute.id == Mesh::ATTRIBUTE_TANGENT.id {
            tangent = Some(offset);
        }
        offset += attribute.format.size() as u32;
    }
    match (position, normal) {
        (Some(position), Some(normal)) => Ok(VertexLayout {
            stride: offset,
            position,
            normal,
            tangent,
        }),
        _ => Err("the mesh has no normals for the GPU to write".to_owned()),
    }
}

/// A short fingerprint of what the GPU buffers were built from: settings, features, pinned
/// vertices.
fn settings_key(sim: &Simulation) -> String {
    let pins: Vec<u32> = sim.state().pins().iter().map(|p| p.vertex).collect();
    format!(
        "{:?}{:?}{pins:?}{}",
        sim.params(),
        sim.features(),
        sim.topology().edges().len()
    )
}

#[expect(
    clippy::type_complexity,
    clippy::too_many_arguments,
    reason = "a query over the cloth, its backend choice and its GPU twin; a system's inputs"
)]
fn choose_backends(
    mut commands: Commands,
    support: Option<Res<ClothGpuSupport>>,
    default: Res<DefaultBackend>,
    meshes: Option<Res<Assets<Mesh>>>,
    mut cloths: Query<(
        (Entity, Option<&Name>),
        &ClothSim,
        Option<&ClothBackend>,
        Option<&mut ClothBackendInUse>,
        Option<&mut ClothOnGpu>,
        Has<ClothLeavingGpu>,
        Has<ClothReadback>,
    )>,
    fixed: Res<Time<Fixed>>,
    mut generation: Local<u64>,
    // Per cloth: the settings the model was last checked with, and the verdict.
    mut checked: Local<HashMap<Entity, (String, Result<(), String>)>>,
) {
    let dt = fixed.timestep().as_secs_f32();
    let mut seen = std::collections::HashSet::new();
    for ((entity, name), cloth, backend, in_use, on_gpu, leaving, readback) in &mut cloths {
        let who = EntityName::new(entity, name);
        seen.insert(entity);
        if leaving {
            // Waits for its last GPU state (`apply_gpu_results`).
            continue;
        }
        let wanted = backend.copied().unwrap_or(default.0);
        let verdict: Result<(), String> = match wanted {
            ClothBackend::Cpu => Err(String::new()),
            ClothBackend::Gpu | ClothBackend::Auto => support
                .as_deref()
                .map_or(Some("ClothGpuPlugin is not added".to_owned()), |s| {
                    s.unavailable.clone()
                })
                .map_or(Ok(()), Err)
                .and_then(|()| {
                    // The model check (O(n) for stiff bending) once per change of settings.
                    let key = settings_key(cloth.simulation());
                    match checked.get(&entity) {
                        Some((k, verdict)) if *k == key => verdict.clone(),
                        _ => {
                            let verdict =
                                GpuCloth::supports(cloth.simulation(), dt).map_err(|e| e.0);
                            checked.insert(entity, (key, verdict.clone()));
                            verdict
                        }
                    }
                }),
        };
        let layout = verdict.clone().and_then(|()| {
            meshes
                .as_deref()
                .and_then(|m| m.get(cloth.mesh()))
                .ok_or_else(|| "the cloth's mesh is not loaded".to_owned())
                .and_then(vertex_layout)
        });
        match (layout, on_gpu) {
            (Ok(layout), Some(mut g)) => {
                let key = settings_key(cloth.simulation());
                let edited = cloth.edit_count() != g.edits || g.restart;
                if key != g.key || edited {
                    // New settings go on from the GPU's state; an edit of the state wins.
                    *generation += 1;
                    g.generation = *generation;
                    g.upload = Arc::new(upload(cloth, layout, !edited));
                    g.key = key;
                    g.edits = cloth.edit_count();
                    g.restart = false;
                }
            }
            (Ok(layout), None) => {
                *generation += 1;
                if readback {
                    info!("cloth {who}: runs on the GPU");
                } else {
                    info!(
                        "cloth {who}: runs on the GPU; its ClothSim keeps the state it started \
                         from (add ClothReadback to read the GPU's state back)"
                    );
                }
                commands.entity(entity).insert((
                    ClothOnGpu {
                        generation: *generation,
                        upload: Arc::new(upload(cloth, layout, false)),
                        edits: cloth.edit_count(),
                        restart: false,
                        key: settings_key(cloth.simulation()),
                        pending: Vec::new(),
                        teleports: Vec::new(),
                        dt: 0.0,
                        colliders_first: Vec::new(),
                        colliders_last: Vec::new(),
                        collider_entities: Vec::new(),
                        air: Vec::new(),
                    },
                    ClothSteppedElsewhere,
                    // The mesh's bounds are those of the rest shape it was made with.
                    NoFrustumCulling,
                    ClothBackendInUse {
                        gpu: true,
                        reason: None,
                    },
                ));
            }
            (Err(why), on_gpu) => {
                if let Some(g) = on_gpu {
                    // The CPU goes on from the GPU's state once it is read back.
                    commands
                        .entity(entity)
                        .remove::<(ClothOnGpu, NoFrustumCulling)>()
                        .insert(ClothLeavingGpu {
                            generation: g.generation,
                            frames: 0,
                        });
                }
                let reason = (!why.is_empty()).then_some(why);
                let changed = in_use
                    .as_deref()
                    .is_none_or(|u| u.gpu || u.reason != reason);
                if changed {
                    if let Some(why) = &reason {
                        if wanted == ClothBackend::Gpu {
                            warn!("cloth {who}: asked for the GPU, runs on the CPU: {why}");
                        } else {
                            info!("cloth {who}: runs on the CPU: {why}");
                        }
                    }
                    let value = ClothBackendInUse { gpu: false, reason };
                    match in_use {
                        Some(mut u) => *u = value,
                        None => {
                            commands.entity(entity).insert(value);
                        }
                    }
                }
            }
        }
    }
    checked.retain(|e, _| seen.contains(e));
}

fn upload(cloth: &ClothSim, layout: VertexLayout, carry: bool) -> GpuUpload {
    let binding = cloth.binding();
    let shading = binding.shading();
    let tangents = shading.corner_uvs().map(|uvs| TangentSource {
        corner_uvs: binding
            .drawn_triangles()
            .iter()
            .map(|&t| uvs[t as usize])
            .collect(),
        handedness: shading.handedness().map(<[f32]>::to_vec),
    });
    GpuUpload {
        sim: cloth.simulation().clone(),
        weld: binding.weld().clone(),
        drawn: binding.drawn_indices().collect(),
        layout,
        tangents,
        carry,
    }
}

/// Main world: applies what the GPU read back. A bad state is recovered as on the CPU (and
/// re-uploaded); positions and velocities go into [`ClothSim`]; a cloth leaving the GPU
/// takes its last state and goes on on the CPU.
#[expect(
    clippy::type_complexity,
    reason = "a cloth, its GPU state, its placement"
)]
fn apply_gpu_results(
    mut commands: Commands,
    mut results: ResMut<GpuClothResults>,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut torn_messages: MessageWriter<ClothTorn>,
    mut impulses: ResMut<GpuImpulses>,
    mut cloths: Query<(
        (Entity, Option<&Name>),
        &mut ClothSim,
        Option<&mut ClothOnGpu>,
        Option<&mut ClothLeavingGpu>,
        Option<&GlobalTransform>,
    )>,
) {
    let mut results = core::mem::take(&mut results.0);
    // The latest result per cloth (a slow frame can bring two).
    results.reverse();
    let mut seen = Vec::new();
    for r in results {
        // Every frame's impulses happened, whichever result is the latest.
        impulses.0.extend(r.impulses.iter().copied());
        if seen.contains(&r.entity) {
            continue;
        }
        seen.push(r.entity);
        let Ok(((entity, name), mut cloth, on_gpu, leaving, transform)) = cloths.get_mut(r.entity)
        else {
            continue;
        };
        let current = on_gpu
            .as_ref()
            .map(|g| g.generation)
            .or(leaving.as_ref().map(|l| l.generation));
        if current != Some(r.generation) {
            continue;
        }
        // An edit of the state since the upload wins over what the GPU computed before it.
        if on_gpu
            .as_ref()
            .is_some_and(|g| g.edits != cloth.edit_count())
        {
            continue;
        }
        let cloth = &mut *cloth;
        if r.failed && on_gpu.as_ref().is_some_and(|g| g.restart) {
            // Already recovered; the restart is on its way.
            continue;
        }
        if r.failed {
            cloth.recover(EntityName::new(entity, name), transform.copied());
        } else if let Some((positions, velocities)) = &r.state {
            cloth.receive_state(positions, velocities);
            // Tear on the CPU; the new topology goes to the GPU as a settings change (its
            // state carried over), and the index buffer loses the torn triangles.
            if r.torn
                && cloth.tear_now(entity, &mut torn_messages)
                && let Some(mesh) = meshes.as_deref_mut().and_then(|m| m.get_mut(cloth.mesh()))
            {
                cloth.write_indices(mesh.into_inner());
            }
        }
        if leaving.is_some() && (r.failed || r.state.is_some()) {
            cloth.mark_changed();
            commands
                .entity(entity)
                .remove::<(ClothLeavingGpu, ClothSteppedElsewhere)>();
        } else if r.failed
            && let Some(mut g) = on_gpu
        {
            // Restart the GPU cloth from the recovered state (a new generation).
            g.restart = true;
        }
    }
    for ((entity, name), mut cloth, _, leaving, _) in &mut cloths {
        if let Some(mut l) = leaving {
            l.frames += 1;
            if l.frames > LEAVE_TIMEOUT_FRAMES {
                let who = EntityName::new(entity, name);
                warn!(
                    "cloth {who}: its GPU state did not come back; the CPU goes on from the \
                     state it last had"
                );
                cloth.mark_changed();
                commands
                    .entity(entity)
                    .remove::<(ClothLeavingGpu, ClothSteppedElsewhere)>();
            }
        }
    }
}

fn clear_queued_steps(mut cloths: Query<&mut ClothOnGpu>) {
    for mut g in &mut cloths {
        g.pending.clear();
        g.teleports.clear();
        g.colliders_first.clear();
        g.colliders_last.clear();
    }
}

/// In place of the CPU step: queue the step's pin targets, colliders and air for the GPU.
fn queue_gpu_steps(
    time: Res<Time>,
    colliders: Option<Res<ClothColliders>>,
    wind: Option<Res<ClothWindField>>,
    mut cloths: Query<(&mut ClothSim, &mut ClothOnGpu)>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    let list: &[Collider] = colliders.as_deref().map_or(&[], |c| &c.colliders);
    for (mut cloth, mut g) in &mut cloths {
        let g = &mut *g;
        g.pending.push(
            cloth
                .simulation()
                .state()
                .pins()
                .iter()
                .map(|p| p.target)
                .collect(),
        );
        cloth.count_external_steps(1);
        g.teleports
            .push(cloth.take_teleport().unwrap_or(Vec3::ZERO));
        g.dt = dt;
        if g.colliders_first.is_empty() {
            g.colliders_first = list.to_vec();
        }
        g.colliders_last = list.to_vec();
        g.collider_entities = colliders
            .as_deref()
            .map_or_else(Vec::new, |c| c.entities.clone());
        match wind.as_deref() {
            Some(w) if !w.field.is_empty() && !cloth.simulation().params().air.is_none() => {
                cloth.sample_air(&w.field, w.time + 0.5 * f64::from(dt), &mut g.air);
            }
            _ => g.air.clear(),
        }
    }
}

/// One GPU cloth's frame, in the render world.
struct ExtractedGpuCloth {
    entity: Entity,
    mesh: AssetId<Mesh>,
    generation: u64,
    /// `None` for a cloth leaving the GPU (read back, not stepped).
    upload: Option<Arc<GpuUpload>>,
    steps: Vec<Vec<Vec3>>,
    teleports: Vec<Vec3>,
    dt: f32,
    colliders: Vec<Collider>,
    collider_entities: Vec<Entity>,
    air: Vec<Vec4>,
    transform: bevy::math::Affine3A,
    /// Read positions and velocities back this frame.
    readback: bool,
}

#[derive(Resource, Default)]
struct ExtractedGpuCloths(Vec<ExtractedGpuCloth>);

#[expect(
    clippy::type_complexity,
    reason = "the GPU cloths and those leaving the GPU"
)]
fn extract_gpu_cloths(
    mut out: ResMut<ExtractedGpuCloths>,
    cloths: Extract<
        Query<(
            Entity,
            &ClothOnGpu,
            &Mesh3d,
            &GlobalTransform,
            Has<ClothReadback>,
        )>,
    >,
    leaving: Extract<Query<(Entity, &ClothLeavingGpu, &Mesh3d, &GlobalTransform)>>,
) {
    out.0.clear();
    for (entity, g, mesh, transform, readback) in &cloths {
        // A tearing cloth is always read back: the CPU tears it.
        let readback = readback || g.upload.sim.features().tear_threshold.is_some();
        // Colliders over the whole frame: poses at its first step's start and its last
        // step's end (the same shapes in both unless one came or went mid-frame).
        let colliders = if g.colliders_first.len() == g.colliders_last.len() {
            g.colliders_first
                .iter()
                .zip(&g.colliders_last)
                .map(|(a, b)| Collider {
                    end: b.end,
                    ..a.clone()
                })
                .collect()
        } else {
            g.colliders_last.clone()
        };
        out.0.push(ExtractedGpuCloth {
            entity,
            mesh: mesh.id(),
            generation: g.generation,
            upload: Some(g.upload.clone()),
            steps: g.pending.clone(),
            teleports: g.teleports.clone(),
            dt: g.dt,
            colliders,
            collider_entities: g.collider_entities.clone(),
            air: g.air.clone(),
            transform: transform.affine(),
            readback,
        });
    }
    for (entity, l, mesh, transform) in &leaving {
        out.0.push(ExtractedGpuCloth {
            entity,
            mesh: mesh.id(),
            generation: l.generation,
            upload: None,
            steps: Vec::new(),
            teleports: Vec::new(),
            dt: 0.0,
            colliders: Vec::new(),
            collider_entities: Vec::new(),
            air: Vec::new(),
            transform: transform.affine(),
            readback: true,
        });
    }
}

#[derive(Resource)]
struct GpuClothPipelines {
    kernels: GpuKernels,
    mesh: MeshKernel,
}

struct Instance {
    generation: u64,
    cloth: GpuCloth,
    writer: MeshWriter,
    mesh: AssetId<Mesh>,
    transform: bevy::math::Affine3A,
    /// The state buffer of the instance this one replaced, to carry over this frame.
    carry_from: Option<wgpu::Buffer>,
    /// Steps to run this frame (0: nothing to step or write).
    steps: usize,
    /// Read positions and velocities back this frame (the status is read every frame).
    readback: bool,
    /// Staging buffers not being mapped (a few, of the sizes recently used).
    staging: Vec<wgpu::Buffer>,
    /// The colliders of this frame's steps (their impulses go back to these entities).
    collider_entities: Vec<Entity>,
    /// Still on the GPU (not leaving it).
    on_gpu: bool,
}

/// A copy of a cloth's state on its way to the main world.
struct Readback {
    entity: Entity,
    generation: u64,
    full: bool,
    /// The colliders whose impulse slots follow the state (empty: none copied).
    colliders: Vec<Entity>,
    buffer: wgpu::Buffer,
    /// The mapped bytes (`None` if mapping failed).
    data: Option<Vec<u8>>,
}

#[derive(Resource, Default)]
struct GpuClothInstances {
    cloths: HashMap<Entity, Instance>,
    /// Copies recorded this frame, to map once submitted.
    requested: Vec<Readback>,
}

#[derive(Resource)]
struct ReadbackChannel {
    sender: Sender<Readback>,
    receiver: Mutex<Receiver<Readback>>,
}

fn prepare_gpu_cloths(
    extracted: Res<ExtractedGpuCloths>,
    pipelines: Option<Res<GpuClothPipelines>>,
    mut instances: ResMut<GpuClothInstances>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let Some(pipelines) = pipelines else {
        return;
    };
    let device = device.wgpu_device();
    instances
        .cloths
        .retain(|e, _| extracted.0.iter().any(|x| x.entity == *e));
    for x in &extracted.0 {
        let old = instances.cloths.get(&x.entity);
        let fresh = old.is_none_or(|i| i.generation != x.generation);
        if let (true, Some(upload)) = (fresh, &x.upload) {
            let sim = &upload.sim;
            let Ok(cloth) = GpuCloth::new(device, &pipelines.kernels, sim) else {
                continue;
            };
            cloth.upload_state(&queue, sim);
            // New settings go on from where the GPU cloth is (same particles only).
            let carry_from = old
                .filter(|o| upload.carry && o.cloth.len() == cloth.len())
                .map(|o| o.cloth.state_buffer().clone());
            let writer = MeshWriter::new(
                device,
                &upload.weld,
                &upload.drawn,
                upload.layout,
                upload.tangents.as_ref(),
            );
            let staging = Vec::new();
            instances.cloths.insert(
                x.entity,
                Instance {
                    generation: x.generation,
                    cloth,
                    writer,
                    mesh: x.mesh,
                    transform: x.transform,
                    carry_from,
                    steps: 0,
                    readback: false,
                    staging,
                    collider_entities: Vec::new(),
                    on_gpu: true,
                },
            );
        }
        let Some(i) = instances.cloths.get_mut(&x.entity) else {
            continue;
        };
        if i.generation != x.generation {
            continue;
        }
        i.mesh = x.mesh;
        i.transform = x.transform;
        i.steps = x.steps.len();
        i.readback = x.readback;
        i.on_gpu = x.upload.is_some();
        i.collider_entities.clone_from(&x.collider_entities);
        if let Some(upload) = &x.upload {
            i.cloth.prepare(
                device,
                &queue,
                &pipelines.kernels,
                &upload.sim,
                x.dt,
                &x.steps,
                GpuStepInput {
                    colliders: &x.colliders,
                    air_velocities: &x.air,
                    teleports: &x.teleports,
                },
            );
        }
    }
}

fn run_gpu_cloths(
    mut ctx: RenderContext,
    pipelines: Option<Res<GpuClothPipelines>>,
    mut instances: ResMut<GpuClothInstances>,
    allocator: Res<MeshAllocator>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let Some(pipelines) = pipelines else {
        return;
    };
    let instances = &mut *instances;
    for (&entity, i) in &mut instances.cloths {
        let encoder = ctx.command_encoder();
        if let Some(from) = i.carry_from.take() {
            i.cloth.record_carry(encoder, &pipelines.kernels, &from);
        }
        if i.steps > 0 {
            i.cloth.record(encoder, &pipelines.kernels);
        }
        // The mesh every frame while on the GPU: a change of the mesh asset (torn triangles
        // leaving the index buffer) uploads its main-world vertices again.
        if i.on_gpu
            && let Some(slice) = allocator.mesh_vertex_slice(&i.mesh)
        {
            i.writer.record(
                device.wgpu_device(),
                &queue,
                &pipelines.mesh,
                encoder,
                i.cloth.state_buffer(),
                slice.buffer,
                slice.range.start,
                i.transform,
            );
        }
        if i.steps == 0 && !i.readback {
            continue;
        }
        // The status after the steps, the state when asked for, the colliders' impulses
        // when the steps had colliders: [status | positions | velocities | impulse slots].
        let region = 16 * i.cloth.len() as u64;
        let state_bytes = if i.readback { 2 * region } else { 0 };
        let (impulse_at, impulse_bytes) = if i.steps > 0 {
            i.cloth.impulse_region()
        } else {
            (0, 0)
        };
        let size = 16 + state_bytes + impulse_bytes;
        let buffer = match i.staging.iter().position(|b| b.size() == size) {
            Some(k) => i.staging.swap_remove(k),
            None => device.wgpu_device().create_buffer(&wgpu::BufferDescriptor {
                label: Some("cloth_readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        };
        let state = i.cloth.state_buffer();
        encoder.copy_buffer_to_buffer(state, i.cloth.status_offset(), &buffer, 0, 16);
        if state_bytes > 0 {
            encoder.copy_buffer_to_buffer(state, 0, &buffer, 16, region);
            encoder.copy_buffer_to_buffer(state, 2 * region, &buffer, 16 + region, region);
        }
        if impulse_bytes > 0 {
            encoder.copy_buffer_to_buffer(
                i.cloth.scratch_buffer(),
                impulse_at,
                &buffer,
                16 + state_bytes,
                impulse_bytes,
            );
        }
        instances.requested.push(Readback {
            entity,
            generation: i.generation,
            full: i.readback,
            colliders: if impulse_bytes > 0 {
                i.collider_entities.clone()
            } else {
                Vec::new()
            },
            buffer,
            data: None,
        });
    }
}

/// `Cleanup`, after the frame's commands were submitted: maps this frame's copies; the
/// results come back through the channel when the GPU is done.
fn map_readbacks(mut instances: ResMut<GpuClothInstances>, channel: Res<ReadbackChannel>) {
    for mut r in instances.requested.drain(..) {
        let sender = channel.sender.clone();
        let buffer = r.buffer.clone();
        buffer
            .clone()
            .map_async(wgpu::MapMode::Read, .., move |result| {
                if result.is_ok() {
                    r.data = Some(buffer.get_mapped_range(..).to_vec());
                    buffer.unmap();
                }
                // The receiver lives as long as the render world.
                let _ = sender.send(r);
            });
    }
}

/// Extraction: what the GPU finished goes to the main world; staging buffers return to their
/// cloths.
fn send_gpu_results(
    channel: Res<ReadbackChannel>,
    mut instances: ResMut<GpuClothInstances>,
    mut main_world: ResMut<MainWorld>,
) {
    let Ok(receiver) = channel.receiver.lock() else {
        return;
    };
    let mut out = Vec::new();
    for r in receiver.try_iter() {
        if let Some(i) = instances.cloths.get_mut(&r.entity)
            && i.generation == r.generation
            && i.staging.len() < 4
        {
            i.staging.push(r.buffer.clone());
        }
        let Some(data) = &r.data else {
            continue;
        };
        let Some(n) = instances.cloths.get(&r.entity).map(|i| i.cloth.len()) else {
            continue;
        };
        let status: Vec4 = bytemuck::pod_read_unaligned(&data[..16]);
        let state_bytes = if r.full { 32 * n } else { 0 };
        let state = (r.full && data.len() >= 16 + state_bytes).then(|| {
            let values: Vec<Vec4> = bytemuck::pod_collect_to_vec(&data[16..16 + state_bytes]);
            (values[..n].to_vec(), values[n..].to_vec())
        });
        let words: Vec<u32> =
            bytemuck::pod_collect_to_vec(&data[(16 + state_bytes).min(data.len())..]);
        let impulses = sum_impulses(&words, r.colliders.len());
        out.push(GpuResult {
            entity: r.entity,
            generation: r.generation,
            failed: status.x != 0.0,
            torn: status.y != 0.0,
            state,
            impulses: r.colliders.iter().copied().zip(impulses).collect(),
        });
    }
    if !out.is_empty()
        && let Some(mut results) = main_world.get_resource_mut::<GpuClothResults>()
    {
        results.0.extend(out);
    }
}

/// In the fixed step after they arrive (their `ClothContactImpulse`s were just reset): GPU
/// cloths' impulses on colliders, a few frames after the GPU computed them.
fn add_gpu_impulses(
    mut pending: ResMut<GpuImpulses>,
    mut targets: Query<&mut ClothContactImpulse>,
) {
    for (entity, imp) in pending.0.drain(..) {
        if let Ok(mut t) = targets.get_mut(entity) {
            t.linear += imp.linear;
            t.angular += imp.angular;
        }
    }
}
