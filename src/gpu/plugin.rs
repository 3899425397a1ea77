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
//!    draw the new shape.

use std::collections::HashMap;
use std::sync::Arc;

use bevy::camera::visibility::NoFrustumCulling;
use bevy::core_pipeline::schedule::camera_driver;
use bevy::mesh::MeshVertexAttribute;
use bevy::prelude::*;
use bevy::render::mesh::allocator::{MeshAllocator, MeshAllocatorSettings};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderQueue};
use bevy::render::{Extract, ExtractSchedule, Render, RenderApp, RenderSystems};

use super::kernels::{GpuCloth, GpuKernels, GpuStepInput};
use super::mesh::{MeshKernel, MeshWriter, VertexLayout};
use crate::cloth::{ClothSim, ClothSystems};
use crate::collider::ClothColliders;
use crate::solver::{Collider, Simulation};
use crate::wind::ClothWindField;

/// Which solver steps a cloth.
///
/// Put it on a [`Cloth`](crate::cloth::Cloth) entity; without it the cloth uses
/// [`ClothGpuPlugin::default_backend`]. Which one a cloth actually runs on, and why, is in
/// [`ClothBackendInUse`].
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
/// Part of [`ClothPlugins`](crate::cloth::ClothPlugins) with `default_backend: Cpu`: nothing
/// changes until a cloth asks for [`ClothBackend::Gpu`] or [`ClothBackend::Auto`], or the
/// default is set, e.g. `ClothPlugins::default().set(ClothGpuPlugin { default_backend:
/// ClothBackend::Auto })`. In an app without a renderer (`MinimalPlugins`) every cloth runs on
/// the CPU.
///
/// What the GPU backend runs: PBD and XPBD with substeps and iterations, stretch, shear and
/// isometric bending, pins (moving with their anchors), gravity, damping, the speed limit, air
/// drag/lift/friction with the wind, sphere/box/capsule/plane colliders with friction, normals.
/// What keeps a cloth on the CPU: self-collision, tethers, tearing, dihedral or implicit
/// bending, the lab solver. Mesh (SDF) colliders are ignored by GPU cloths. The results stay
/// on the GPU: [`ClothSim`]'s state is the one the cloth started from (or had when its
/// settings last changed), contact impulses are not sent to colliders, and a change of
/// settings or pins restarts the GPU cloth from that state.
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
}

/// A cloth the GPU steps, with this frame's queued steps (main world).
#[derive(Component)]
pub struct ClothOnGpu {
    generation: u64,
    upload: Arc<GpuUpload>,
    /// Settings the upload was made with (a change re-uploads).
    key: String,
    pending: Vec<Vec<Vec3>>,
    dt: f32,
    colliders_first: Vec<Collider>,
    colliders_last: Vec<Collider>,
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
        app.register_type::<ClothBackend>()
            .insert_resource(DefaultBackend(self.default_backend))
            .add_systems(First, clear_queued_steps)
            .add_systems(
                FixedPostUpdate,
                (
                    choose_backends
                        .in_set(ClothSystems::Prepare)
                        .after(crate::cloth::sim::sync_cloths),
                    queue_gpu_steps.in_set(ClothSystems::Simulate),
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
        render_app
            .init_resource::<ExtractedGpuCloths>()
            .init_resource::<GpuClothInstances>()
            .add_systems(ExtractSchedule, extract_gpu_cloths)
            .add_systems(
                Render,
                prepare_gpu_cloths.in_set(RenderSystems::PrepareResources),
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
    let (mut position, mut normal) = (None, None);
    for (attribute, _) in mesh.attributes() {
        let attribute: &MeshVertexAttribute = attribute;
        if attribute.id == Mesh::ATTRIBUTE_POSITION.id {
            position = Some(offset);
        } else if attribute.id == Mesh::ATTRIBUTE_NORMAL.id {
            normal = Some(offset);
        }
        offset += attribute.format.size() as u32;
    }
    match (position, normal) {
        (Some(position), Some(normal)) => Ok(VertexLayout {
            stride: offset,
            position,
            normal,
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
    reason = "a query over the cloth, its backend choice and its GPU twin"
)]
fn choose_backends(
    mut commands: Commands,
    support: Option<Res<ClothGpuSupport>>,
    default: Res<DefaultBackend>,
    meshes: Option<Res<Assets<Mesh>>>,
    mut cloths: Query<(
        Entity,
        &ClothSim,
        Option<&ClothBackend>,
        Option<&mut ClothBackendInUse>,
        Option<&mut ClothOnGpu>,
    )>,
    mut generation: Local<u64>,
) {
    for (entity, cloth, backend, in_use, on_gpu) in &mut cloths {
        let wanted = backend.copied().unwrap_or(default.0);
        let verdict: Result<(), String> = match wanted {
            ClothBackend::Cpu => Err(String::new()),
            ClothBackend::Gpu | ClothBackend::Auto => support
                .as_deref()
                .map_or(Some("ClothGpuPlugin is not added".to_owned()), |s| {
                    s.unavailable.clone()
                })
                .map_or(Ok(()), Err)
                .and_then(|()| GpuCloth::supports(cloth.simulation()).map_err(|e| e.0)),
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
                if key != g.key {
                    *generation += 1;
                    g.generation = *generation;
                    g.upload = Arc::new(upload(cloth, layout));
                    g.key = key;
                }
            }
            (Ok(layout), None) => {
                *generation += 1;
                info!("cloth {entity}: runs on the GPU");
                commands.entity(entity).insert((
                    ClothOnGpu {
                        generation: *generation,
                        upload: Arc::new(upload(cloth, layout)),
                        key: settings_key(cloth.simulation()),
                        pending: Vec::new(),
                        dt: 0.0,
                        colliders_first: Vec::new(),
                        colliders_last: Vec::new(),
                        air: Vec::new(),
                    },
                    // The mesh's bounds are those of the rest shape it was made with.
                    NoFrustumCulling,
                    ClothBackendInUse {
                        gpu: true,
                        reason: None,
                    },
                ));
            }
            (Err(why), on_gpu) => {
                if on_gpu.is_some() {
                    commands
                        .entity(entity)
                        .remove::<(ClothOnGpu, NoFrustumCulling)>();
                }
                let reason = (!why.is_empty()).then_some(why);
                let changed = in_use
                    .as_deref()
                    .is_none_or(|u| u.gpu || u.reason != reason);
                if changed {
                    if let Some(why) = &reason {
                        if wanted == ClothBackend::Gpu {
                            warn!("cloth {entity}: asked for the GPU, runs on the CPU: {why}");
                        } else {
                            info!("cloth {entity}: runs on the CPU: {why}");
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
}

fn upload(cloth: &ClothSim, layout: VertexLayout) -> GpuUpload {
    let binding = &cloth.binding;
    GpuUpload {
        sim: cloth.simulation().clone(),
        weld: binding.weld().clone(),
        drawn: binding.drawn_indices().collect(),
        layout,
    }
}

fn clear_queued_steps(mut cloths: Query<&mut ClothOnGpu>) {
    for mut g in &mut cloths {
        g.pending.clear();
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
        let sim = &mut cloth.sim;
        g.pending
            .push(sim.state().pins().iter().map(|p| p.target).collect());
        g.dt = dt;
        if g.colliders_first.is_empty() {
            g.colliders_first = list.to_vec();
        }
        g.colliders_last = list.to_vec();
        match wind.as_deref() {
            Some(w) if !w.field.is_empty() && !sim.params().air.is_none() => {
                sim.sample_air(&w.field, w.time + 0.5 * f64::from(dt), &mut g.air);
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
    upload: Arc<GpuUpload>,
    steps: Vec<Vec<Vec3>>,
    dt: f32,
    colliders: Vec<Collider>,
    air: Vec<Vec4>,
    transform: bevy::math::Affine3A,
}

#[derive(Resource, Default)]
struct ExtractedGpuCloths(Vec<ExtractedGpuCloth>);

fn extract_gpu_cloths(
    mut out: ResMut<ExtractedGpuCloths>,
    cloths: Extract<Query<(Entity, &ClothOnGpu, &Mesh3d, &GlobalTransform)>>,
) {
    out.0.clear();
    for (entity, g, mesh, transform) in &cloths {
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
            upload: g.upload.clone(),
            steps: g.pending.clone(),
            dt: g.dt,
            colliders,
            air: g.air.clone(),
            transform: transform.affine(),
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
}

#[derive(Resource, Default)]
struct GpuClothInstances(HashMap<Entity, Instance>);

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
        .0
        .retain(|e, _| extracted.0.iter().any(|x| x.entity == *e));
    for x in &extracted.0 {
        let fresh = instances
            .0
            .get(&x.entity)
            .is_none_or(|i| i.generation != x.generation);
        if fresh {
            let sim = &x.upload.sim;
            let Ok(cloth) = GpuCloth::new(device, &pipelines.kernels, sim) else {
                continue;
            };
            cloth.upload_state(&queue, sim);
            let writer = MeshWriter::new(device, &x.upload.weld, &x.upload.drawn, x.upload.layout);
            instances.0.insert(
                x.entity,
                Instance {
                    generation: x.generation,
                    cloth,
                    writer,
                    mesh: x.mesh,
                    transform: x.transform,
                },
            );
        }
        let Some(i) = instances.0.get_mut(&x.entity) else {
            continue;
        };
        i.mesh = x.mesh;
        i.transform = x.transform;
        i.cloth.prepare(
            device,
            &queue,
            &pipelines.kernels,
            &x.upload.sim,
            x.dt,
            &x.steps,
            GpuStepInput {
                colliders: &x.colliders,
                air_velocities: &x.air,
            },
        );
    }
}

fn run_gpu_cloths(
    mut ctx: RenderContext,
    pipelines: Option<Res<GpuClothPipelines>>,
    instances: Res<GpuClothInstances>,
    allocator: Res<MeshAllocator>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let Some(pipelines) = pipelines else {
        return;
    };
    for i in instances.0.values() {
        let Some(slice) = allocator.mesh_vertex_slice(&i.mesh) else {
            continue;
        };
        let encoder = ctx.command_encoder();
        i.cloth.record(encoder, &pipelines.kernels);
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
}
