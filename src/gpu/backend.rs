//! The main world's side of the GPU backend: which cloths run on the GPU
//! ([`ClothBackend`], [`ClothBackendInUse`]), what each fixed step queues for them
//! ([`ClothOnGpu`], the frame's colliders), and what comes back (states, recoveries, tears,
//! impulses).
//!
//! Frame flow for a cloth on the GPU:
//! 1. Main world, the cloth schedule: `ClothSystems::Prepare` as for every cloth (pins follow
//!    their anchors, settings apply); `choose_backends`, between the phases, decides CPU or
//!    GPU (a GPU cloth carries `ClothSteppedElsewhere`, so the CPU plugin leaves it alone); in
//!    `ClothSystems::Simulate` each step's colliders (once, for every GPU cloth) and each
//!    cloth's pin targets, teleport and air are queued.
//! 2. Render world (`render.rs`): extracted, packed into worlds, stepped, written into mesh
//!    slabs, read back.
//! 3. `PreUpdate`, a few frames later: what came back is applied to [`ClothSim`].

use std::collections::HashMap;
use std::sync::Arc;

use bevy::camera::visibility::NoFrustumCulling;
use bevy::mesh::MeshVertexAttribute;
use bevy::prelude::*;

use super::layout::BatchesCell;
use super::mesh::{TangentSource, VertexLayout};
use super::world::{GpuWorld, MotionTargets};
use crate::cloth::{Cloth, ClothSim, ClothSteppedElsewhere, ClothTorn};
use crate::collider::{ClothColliders, ClothContactImpulse};
use crate::foundation::EntityName;
use crate::solver::{
    Carry, Collider, ContactImpulse, DEFAULT_TELEPORT_DISTANCE, Environment, Simulation,
};
use crate::wind::ClothWindField;

/// Which solver steps a cloth.
///
/// Put it on a [`Cloth`] entity; without it the cloth uses
/// [`ClothGpuPlugin::default_backend`](super::ClothGpuPlugin::default_backend). Which one a cloth actually runs on, and why, is in
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
    /// The GPU where it can run this cloth, else the CPU (with an info line saying why). A
    /// software renderer (llvmpipe) counts as none: the CPU solver is faster there (see
    /// [`ClothGpuSupport::software_adapter`]).
    #[default]
    Auto,
}

/// The backend a cloth runs on now, and why not the other (set by [`ClothGpuPlugin`](super::ClothGpuPlugin)).
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
    /// The adapter's name when it is a software renderer (wgpu's `DeviceType::Cpu`: Mesa's
    /// llvmpipe, SwiftShader, WARP). The kernels run there, but on the same CPU cores and
    /// 30–70 times slower than the CPU solver (docs/performance.md, *On llvmpipe*), so
    /// [`ClothBackend::Auto`] runs cloths on the CPU; [`ClothBackend::Gpu`] still runs them
    /// on it (tests, correctness runs).
    pub software_adapter: Option<String>,
}

#[derive(Resource, Clone, Copy)]
pub(crate) struct DefaultBackend(pub ClothBackend);

/// What the render world needs to build a cloth's buffers.
pub(crate) struct GpuUpload {
    pub sim: Simulation,
    pub weld: crate::solver::Weld,
    pub drawn: Vec<u32>,
    /// For a tearing cloth, per drawn triangle its cloth triangle (what hides torn triangles
    /// until the host's tear).
    pub drawn_cloth_triangles: Option<Vec<u32>>,
    /// Whether the mesh's indices are 16-bit.
    pub u16_indices: bool,
    pub layout: VertexLayout,
    pub tangents: Option<TangentSource>,
    /// Start from the GPU state of the previous upload (a settings change), not from `sim`'s.
    pub carry: bool,
    /// How many of the frame's queued steps, from its first, have their carries (the motion
    /// and change of size carried into them) in `sim`'s state already: a cloth that starts
    /// from that state skips them on the GPU instead of carrying it twice.
    pub carried: usize,
    /// The cloth's own mesh (its copy, drawn through `Mesh3d`), the only one the GPU writes:
    /// a mesh the game puts in `Mesh3d` is the source of the next build, not a target.
    pub mesh: AssetId<Mesh>,
    /// Its GPU batches, made when a world is first laid out with it.
    pub batches: Arc<BatchesCell>,
}

/// Copies a GPU cloth's positions and velocities into its [`ClothSim`] every frame, a frame
/// or two after the GPU computed them (opt-in: the copy costs bus bandwidth and CPU time).
///
/// Without it a GPU cloth's [`ClothSim`] keeps the state the cloth started from (and, while
/// it may be coming to rest, the states read back to tell when it sleeps, then the one it
/// sleeps in: [`ClothSim::is_sleeping`] works either way): gameplay that reads vertex
/// positions or strain of a moving GPU cloth needs this component.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Component)]
pub struct ClothReadback;

/// A cloth that left the GPU and waits for its last GPU state before the CPU steps it on.
#[derive(Component)]
pub(crate) struct ClothLeavingGpu {
    pub generation: u64,
    frames: u32,
}

/// Frames a cloth leaving the GPU waits for its state before going on from the main world's.
const LEAVE_TIMEOUT_FRAMES: u32 = 30;

/// Removing [`Cloth`] removes its GPU components too.
pub(crate) fn forget_gpu_cloth(removed: On<Remove, Cloth>, mut commands: Commands) {
    commands.entity(removed.entity).try_remove::<(
        ClothOnGpu,
        ClothLeavingGpu,
        ClothBackendInUse,
        ClothSteppedElsewhere,
        NoFrustumCulling,
    )>();
}

/// What a GPU frame read back for one cloth.
pub(crate) struct GpuResult {
    pub entity: Entity,
    pub generation: u64,
    /// A step left a NaN or infinite position or velocity.
    pub failed: bool,
    /// A step ended with an edge past the tear threshold.
    pub tear: bool,
    /// The edges the GPU tore (its own vertex indices), when it keeps torn flags (all but
    /// the lab solver).
    pub torn: Option<Vec<[u32; 2]>>,
    /// Positions and velocities, when asked for.
    pub state: Option<(Vec<Vec4>, Vec<Vec4>)>,
    /// Steps the cloth took in the frame (0: it was at rest, or not on the GPU).
    pub steps: u32,
    /// The largest squared speed a free vertex ended one of those steps with, for a cloth that
    /// may sleep (`None` when it took no step).
    pub max_speed_squared: Option<f32>,
}

/// GPU cloths' impulses on colliders, waiting for the next fixed step's
/// [`ClothContactImpulse`]s.
#[derive(Resource, Default)]
pub(crate) struct GpuImpulses(pub Vec<(Entity, ContactImpulse)>);

/// Results waiting for the main world (filled during extraction): per cloth, and the
/// impulses of every frame that came back.
#[derive(Resource, Default)]
pub(crate) struct GpuClothResults {
    pub cloths: Vec<GpuResult>,
    pub impulses: Vec<(Entity, ContactImpulse)>,
    /// Cloths the device cannot run (too large for its buffers): entity, generation, why.
    pub refused: Vec<(Entity, u64, String)>,
}

/// The steps queued this frame for every GPU cloth: each step's length and colliders (with
/// their impulse slots), and the frame's collider entities (slot → entity).
#[derive(Resource, Default, Clone, Debug)]
pub(crate) struct GpuStepQueue {
    pub steps: Vec<QueuedStep>,
    pub entities: Vec<Entity>,
}

/// One queued step.
#[derive(Clone, Debug)]
pub(crate) struct QueuedStep {
    pub dt: f32,
    pub colliders: Vec<Collider>,
    pub slots: Vec<u32>,
}

/// A cloth the GPU steps, with this frame's queued steps (main world).
#[derive(Component)]
pub struct ClothOnGpu {
    pub(crate) generation: u64,
    pub(crate) upload: Arc<GpuUpload>,
    /// [`ClothSim::simulation_mut`] calls the upload was made after.
    edits: u64,
    /// Upload the main world's state again (after a recovery).
    restart: bool,
    /// Settings the upload was made with (a change re-uploads).
    key: String,
    /// Per queued step, every pin's target at its end.
    pub(crate) pending: Vec<Vec<Vec3>>,
    /// How many of the first queued steps hold targets for pins the cloth no longer has
    /// (its pins changed between two fixed steps of a frame): the next queued step's targets
    /// replace theirs.
    stale_targets: usize,
    /// The queued steps' carries fold into the first at the next step queued (a new rest
    /// shape within the frame).
    fold_carries: bool,
    /// The [`ClothSim::reshape_count`] of the last upload.
    reshapes: u64,
    /// The index of the first queued step among the frame's steps ([`GpuStepQueue`]).
    pub(crate) first_step: u32,
    /// Per queued step, how far the whole cloth jumps at its start (the teleport rule).
    pub(crate) teleports: Vec<Vec3>,
    /// Per queued step, the rigid motion carried at its start (`ClothInertia`).
    pub(crate) carries: Vec<Carry>,
    /// The air at each vertex, sampled at the last queued step.
    pub(crate) air: Vec<Vec4>,
    /// Per queued step, the motion targets (skinned clothing; empty entries for none).
    pub(crate) motion: Vec<MotionTargets>,
    /// Where it is on its way to sleep.
    rest: GpuRest,
    /// Its state is read back every frame to count its steps towards rest: the last frame
    /// found it slow (no vertex faster than [`Simulation::may_be_at_rest`] allows, or a state
    /// read back under the mean energy [`Simulation::may_be_at_rest_in`] allows), or it is
    /// looked at ([`PROBE_FRAMES`]).
    watch: bool,
    /// Frames stepped not slow, but with no vertex faster than [`PROBE_SPEED_RATIO`] times
    /// the speed a slow one allows, until its state is looked at.
    probe_in: u32,
    /// The length of its last queued step, seconds (0 before the first): what its steps read
    /// back are counted with.
    step_dt: f32,
    /// The velocities it fell asleep with this frame (its `ClothSim`'s, the free vertices'
    /// zeroed), for its GPU state to take: extracted once, dropped the next frame.
    pub(crate) sleep_velocities: Option<Arc<Vec<Vec4>>>,
}

/// A GPU cloth on its way to sleep (main world). The GPU measures each frame the largest
/// speed a free vertex ends a step with ([`GpuResult::max_speed_squared`]); while that is
/// slow enough for the cloth to be coming to rest ([`Simulation::may_be_at_rest`]: 0.1 m/s
/// at the default [`Sleep`]), or while a state read back has the mean energy of one
/// ([`Simulation::may_be_at_rest_in`]: a pile of cloth whose few trembling vertices are
/// faster), its state is read back every frame and counted by the CPU's rules
/// ([`Simulation::count_rest`]). A cloth whose fastest vertex is not far past the first rule
/// has its state looked at every [`PROBE_FRAMES`] frames for the second. At rest, its
/// [`ClothSim`] falls asleep in the state read back last ([`Simulation::sleep_in`]: what
/// would wake it, the CPU's rules) and the cloth stops taking steps; the state it stopped in
/// is read back once more and it sleeps in that, until something that could move it changes.
///
/// [`Sleep`]: crate::solver::Sleep
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
enum GpuRest {
    /// Stepping.
    #[default]
    Awake,
    /// At rest and asleep, waiting for the state it stopped in (read back from a frame it sat
    /// out).
    Stopping,
    /// Asleep ([`ClothSim::is_sleeping`]): it takes no step until something wakes it.
    Asleep,
}

/// Frames between two looks at the state of a GPU cloth whose fastest vertex is not slow
/// but within [`PROBE_SPEED_RATIO`] of it (a quarter of a second at 60 frames a second): a
/// pile of cloth with self-collision has a few vertices trembling at up to about 1 m/s while
/// the mean is at rest (docs/experiments.md, *A GPU pile with self-collision never slept*).
pub(crate) const PROBE_FRAMES: u32 = 15;

/// How many times the speed [`Simulation::may_be_at_rest`] allows (2 m/s at the default
/// [`Sleep`]) a GPU cloth's fastest vertex may move for its state to be looked at every
/// [`PROBE_FRAMES`] frames: a cloth flapping faster is not read back for it.
///
/// [`Sleep`]: crate::solver::Sleep
pub(crate) const PROBE_SPEED_RATIO: f32 = 20.0;

impl ClothOnGpu {
    /// Steps queued for the GPU this frame.
    #[must_use]
    pub fn queued_steps(&self) -> usize {
        self.pending.len()
    }

    /// Whether it takes no step now (at rest).
    pub(crate) fn is_frozen(&self) -> bool {
        !matches!(self.rest, GpuRest::Awake)
    }

    /// Whether its state is read back this frame, `readback` asked for or not
    /// ([`ClothReadback`]; a tearing cloth always is): to count towards rest, or to sleep in;
    /// not while it sleeps (its state on the GPU stays as it was read back).
    pub(crate) fn reads_back(&self, readback: bool) -> bool {
        match self.rest {
            GpuRest::Awake => self.asks(readback) || self.watch,
            GpuRest::Stopping => true,
            GpuRest::Asleep => false,
        }
    }

    /// Whether its [`ClothSim`] takes the state read back last, after the frame's results were
    /// counted towards rest: asked for ([`ClothReadback`], tearing), or the cloth is coming
    /// to rest; not a state only looked at ([`PROBE_FRAMES`]) that found it moving.
    fn keeps_state(&self, readback: bool) -> bool {
        self.asks(readback) || self.watch || self.rest != GpuRest::Awake
    }

    /// Whether its state is asked for every frame: `readback` ([`ClothReadback`]) or tearing
    /// (the CPU tears it).
    fn asks(&self, readback: bool) -> bool {
        readback || self.upload.sim.features().tear_threshold.is_some()
    }

    /// Counts a frame read back towards rest ([`GpuRest`]): a slow frame has the state read
    /// back from the next one on, and a read-back state is counted by the CPU's rules; at
    /// rest, the cloth falls asleep in it among `env` and stops. A frame it stepped that was
    /// not slow, read back after it stopped (it was taken before), wakes it again.
    ///
    /// Slow: with a state read back, by its mean energy ([`Simulation::may_be_at_rest_in`]);
    /// without, by the fastest vertex ([`Simulation::may_be_at_rest`]). A frame not slow whose
    /// fastest vertex is within [`PROBE_SPEED_RATIO`] of slow counts down to a look at its
    /// state ([`PROBE_FRAMES`]).
    fn count_rest(&mut self, r: &GpuResult, cloth: &mut ClothSim, env: &Environment<'_>, dt: f32) {
        if r.steps == 0 || self.rest == GpuRest::Asleep {
            return;
        }
        let sim = cloth.simulation();
        let fastest = r.max_speed_squared;
        let slow = match &r.state {
            Some((positions, velocities)) => sim.may_be_at_rest_in(positions, velocities),
            None => fastest.is_some_and(|s2| sim.may_be_at_rest(s2)),
        };
        let near = fastest.is_some_and(|s2| sim.may_be_at_rest(s2 / PROBE_SPEED_RATIO.powi(2)));
        match (self.rest, slow) {
            (GpuRest::Awake, true) => {
                self.watch = true;
                self.probe_in = PROBE_FRAMES;
                // The first slow frame was not read back: counted from the next one.
                let Some((positions, velocities)) = &r.state else {
                    return;
                };
                cloth.receive_state(positions, velocities);
                if cloth.stepped_elsewhere().count_rest(r.steps, dt) {
                    cloth.stepped_elsewhere().sleep_in(env, dt);
                    if cloth.is_sleeping() {
                        self.rest = GpuRest::Stopping;
                        self.watch = false;
                    }
                }
            }
            (GpuRest::Awake, false) => {
                cloth.stepped_elsewhere().reset_rest_count();
                if self.watch && r.state.is_none() {
                    // Taken before the watch began: the states read back decide.
                    return;
                }
                self.watch = false;
                if near && r.state.is_none() {
                    self.probe_in = self.probe_in.saturating_sub(1);
                    if self.probe_in == 0 {
                        // Looked at from the next frame on, until a state comes back.
                        self.watch = true;
                        self.probe_in = PROBE_FRAMES;
                    }
                }
            }
            (_, false) => self.wake(cloth),
            // Taken before it stopped, and slow: it stays stopped.
            (_, true) => {}
        }
    }

    /// The state the cloth stopped in came back (`r`, from a frame it sat out, already in
    /// `cloth`): it sleeps in that among `env`.
    fn stopped(&mut self, r: &GpuResult, cloth: &mut ClothSim, env: &Environment<'_>, dt: f32) {
        if r.steps == 0 && r.state.is_some() && self.rest == GpuRest::Stopping {
            cloth.stepped_elsewhere().wake();
            cloth.stepped_elsewhere().sleep_in(env, dt);
            self.rest = if cloth.is_sleeping() {
                self.sleep_velocities =
                    Some(Arc::new(cloth.simulation().state().velocities.clone()));
                GpuRest::Asleep
            } else {
                GpuRest::Awake
            };
        }
    }

    /// Before a fixed step of a cloth at rest: whether anything that could move it changed,
    /// by the CPU's rules ([`Simulation::stays_asleep_in`]: its pins, the colliders near it,
    /// the air at it; a teleport, a carried motion or the skin holding it come in as
    /// `moved`). Wakes it if so.
    fn wakes(&mut self, cloth: &mut ClothSim, env: &Environment<'_>, dt: f32, moved: bool) -> bool {
        let woken = self.rest == GpuRest::Awake
            || moved
            || !cloth.stepped_elsewhere().stays_asleep_in(env, dt);
        if woken {
            self.wake(cloth);
        }
        woken
    }

    /// Wakes it: it steps, and counts towards rest afresh.
    fn wake(&mut self, cloth: &mut ClothSim) {
        cloth.stepped_elsewhere().wake();
        self.rest = GpuRest::Awake;
        self.watch = false;
    }

    /// Drops the steps queued so far this frame (the GPU cloth sits them out).
    fn forget_queued_steps(&mut self) {
        self.pending.clear();
        self.stale_targets = 0;
        self.fold_carries = false;
        self.teleports.clear();
        self.carries.clear();
        self.motion.clear();
    }
}

/// The vertices `sim` pins, in its pins' order.
fn pinned_vertices(sim: &Simulation) -> Vec<u32> {
    sim.state().pins().iter().map(|p| p.vertex).collect()
}

/// Where positions and normals sit in `mesh`'s interleaved vertex buffer (attributes sorted
/// by id, tightly packed), or why the GPU cannot write it.
pub(crate) fn vertex_layout(mesh: &Mesh) -> Result<VertexLayout, String> {
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
/// vertices, the rest shape's scale and masses, the step (a new one settles the cloth, which
/// the GPU takes over with an upload).
fn settings_key(cloth: &ClothSim, dt: f32) -> String {
    let sim = cloth.simulation();
    let pins = pinned_vertices(sim);
    format!(
        "{:?}{:?}{pins:?}{} {} {dt}",
        sim.params(),
        sim.features(),
        sim.topology().edges().len(),
        cloth.reshape_count()
    )
}

#[expect(
    clippy::type_complexity,
    clippy::too_many_arguments,
    reason = "a query over the cloth, its backend choice and its GPU twin; a system's inputs"
)]
pub(crate) fn choose_backends(
    mut commands: Commands,
    support: Option<Res<ClothGpuSupport>>,
    default: Res<DefaultBackend>,
    meshes: Option<Res<Assets<Mesh>>>,
    mut cloths: Query<(
        (Entity, Option<&Name>),
        Mut<ClothSim>,
        Option<&ClothBackend>,
        Option<&mut ClothBackendInUse>,
        Option<&mut ClothOnGpu>,
        Has<ClothLeavingGpu>,
        Has<ClothReadback>,
    )>,
    fixed: Res<Time<Fixed>>,
    mut results: ResMut<GpuClothResults>,
    mut generation: Local<u64>,
    // Per cloth: the settings the model was last checked with, and the verdict.
    mut checked: Local<HashMap<Entity, (String, Result<(), String>)>>,
) {
    let dt = fixed.timestep().as_secs_f32();
    // Cloths the device turned down (by the generation it was given): they run on the CPU
    // until their settings change.
    let refused: HashMap<Entity, (u64, String)> = results
        .refused
        .drain(..)
        .map(|(e, g, why)| (e, (g, why)))
        .collect();
    let mut seen = std::collections::HashSet::new();
    // A software renderer (when the GPU backend is available at all).
    let software = support
        .as_deref()
        .filter(|s| s.unavailable.is_none())
        .and_then(|s| s.software_adapter.as_deref());
    for ((entity, name), mut cloth, backend, in_use, on_gpu, leaving, readback) in &mut cloths {
        let who = EntityName::new(entity, name);
        seen.insert(entity);
        if leaving {
            // Waits for its last GPU state (`apply_gpu_results`).
            continue;
        }
        let refusal = refused
            .get(&entity)
            .filter(|(g, _)| on_gpu.as_ref().is_some_and(|o| o.generation == *g));
        if let Some((_, why)) = refusal {
            checked.insert(
                entity,
                (
                    settings_key(&cloth, dt),
                    Err(format!("too large for this GPU: {why}")),
                ),
            );
        }
        let wanted = backend.copied().unwrap_or(default.0);
        let verdict: Result<(), String> = match (wanted, software) {
            (ClothBackend::Cpu, _) => Err(String::new()),
            (ClothBackend::Auto, Some(name)) => Err(format!(
                "the GPU is a software renderer ({name}), slower than the CPU solver; \
                 ClothBackend::Gpu runs the cloth there anyway"
            )),
            (ClothBackend::Gpu | ClothBackend::Auto, _) => support
                .as_deref()
                .map_or(Some("ClothGpuPlugin is not added".to_owned()), |s| {
                    s.unavailable.clone()
                })
                .map_or(Ok(()), Err)
                .and_then(|()| {
                    // The model check (O(n) for stiff bending) once per change of settings.
                    let key = settings_key(&cloth, dt);
                    match checked.get(&entity) {
                        Some((k, verdict)) if *k == key => verdict.clone(),
                        _ => {
                            let verdict =
                                GpuWorld::supports(cloth.simulation(), dt).map_err(|e| e.0);
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
                let key = settings_key(&cloth, dt);
                // A cloth built again (another mesh, new `Cloth` settings) starts from its new
                // simulation's state, as on the CPU.
                let rebuilt = cloth.is_added();
                let edited = cloth.edit_count() != g.edits || g.restart || rebuilt;
                if key != g.key || edited {
                    // New settings go on from the GPU's state; an edit of the state wins.
                    *generation += 1;
                    g.generation = *generation;
                    let pins_before: Vec<u32> = pinned_vertices(&g.upload.sim);
                    let reshaped = cloth.reshape_count() != g.reshapes;
                    g.reshapes = cloth.reshape_count();
                    // Its state has the carries of the steps queued so far and of this one
                    // (queued next); an edit forgets the others.
                    let carried = if edited { 1 } else { g.pending.len() + 1 };
                    let last = g.upload.clone();
                    g.upload = Arc::new(upload(&mut cloth, layout, !edited, carried, Some(&last)));
                    hand_over_settle(&mut cloth);
                    g.key = key;
                    g.edits = cloth.edit_count();
                    g.restart = false;
                    // Built again, it steps (and counts towards rest) afresh.
                    if g.is_frozen() {
                        g.wake(cloth.bypass_change_detection());
                    }
                    g.watch = false;
                    if edited {
                        // This frame's earlier steps were queued for a state that is gone: the
                        // new one starts now and sits them out.
                        g.forget_queued_steps();
                    } else if reshaped {
                        // A new rest shape (the entity's scale changed): the GPU solves all
                        // this frame's steps with it, so they all run at its size. The earlier
                        // steps take this step's pin targets, and the frame's carries (their
                        // stretches) apply at its first step (see `queue_gpu_steps`).
                        g.stale_targets = g.pending.len();
                        g.fold_carries = true;
                    } else if pins_before != pinned_vertices(&g.upload.sim) {
                        // Other pins: the earlier steps' targets are for the old ones; they
                        // take this step's targets instead.
                        g.stale_targets = g.pending.len();
                    }
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
                let first = Arc::new(upload(&mut cloth, layout, false, 1, None));
                hand_over_settle(&mut cloth);
                // Asleep on the CPU, it starts awake on the GPU (and sleeps there once at rest).
                if cloth.is_sleeping() {
                    cloth.bypass_change_detection().stepped_elsewhere().wake();
                }
                commands.entity(entity).insert((
                    ClothOnGpu {
                        generation: *generation,
                        upload: first,
                        edits: cloth.edit_count(),
                        restart: false,
                        key: settings_key(&cloth, dt),
                        pending: Vec::new(),
                        stale_targets: 0,
                        fold_carries: false,
                        reshapes: cloth.reshape_count(),
                        first_step: 0,
                        teleports: Vec::new(),
                        carries: Vec::new(),
                        air: Vec::new(),
                        motion: Vec::new(),
                        rest: GpuRest::Awake,
                        watch: false,
                        probe_in: PROBE_FRAMES,
                        step_dt: 0.0,
                        sleep_velocities: None,
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
                if on_gpu.is_some() && refusal.is_some() {
                    // No world holds its GPU state (the one it was to join was not built):
                    // the CPU goes on from its `ClothSim`.
                    cloth.mark_changed();
                    commands
                        .entity(entity)
                        .remove::<(ClothOnGpu, NoFrustumCulling, ClothSteppedElsewhere)>();
                } else if let Some(g) = on_gpu {
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

/// After an upload: a settle of a settings change in it is the GPU's now (it runs it from the
/// upload's simulation); the main world's copy forgets it, so that a later upload (new pins,
/// another change) does not start it again.
fn hand_over_settle(cloth: &mut Mut<ClothSim>) {
    if cloth.simulation().settle_state().0 > 0 {
        cloth.bypass_change_detection().settle_handed_over();
    }
}

/// What the render world needs of `cloth` to build its part of the GPU world; its tethers made
/// here (kept from upload to upload while its pins stay, scaled with its rest shape).
fn upload(
    cloth: &mut Mut<ClothSim>,
    layout: VertexLayout,
    carry: bool,
    carried: usize,
    last: Option<&GpuUpload>,
) -> GpuUpload {
    cloth.bypass_change_detection().prepare_tethers();
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
    let drawn: Vec<u32> = binding.drawn_indices().collect();
    let sim = cloth.simulation();
    let drawn_cloth_triangles = sim.features().tear_threshold.map(|_| {
        super::mesh::drawn_cloth_triangles(binding.weld(), &drawn, sim.topology().triangles())
    });
    GpuUpload {
        sim: sim.clone(),
        weld: binding.weld().clone(),
        drawn,
        drawn_cloth_triangles,
        u16_indices: cloth.u16_indices(),
        layout,
        tangents,
        carry,
        carried,
        mesh: cloth.mesh().id(),
        // Measured again from the last upload's where only the rest shape changed.
        batches: Arc::new(BatchesCell::after(last.map(|u| &u.batches))),
    }
}

/// Main world: applies what the GPU read back. A bad state is recovered as on the CPU (and
/// re-uploaded); positions and velocities go into [`ClothSim`]; a cloth leaving the GPU
/// takes its last state and goes on on the CPU.
#[expect(
    clippy::type_complexity,
    reason = "a cloth, its GPU state, its placement"
)]
pub(crate) fn apply_gpu_results(
    mut commands: Commands,
    (time, fixed, colliders, wind): (
        Res<Time>,
        Res<Time<Fixed>>,
        Option<Res<ClothColliders>>,
        Option<Res<ClothWindField>>,
    ),
    mut results: ResMut<GpuClothResults>,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut torn_messages: MessageWriter<ClothTorn>,
    mut impulses: ResMut<GpuImpulses>,
    mut cloths: Query<(
        (Entity, Option<&Name>, Has<ClothReadback>),
        &mut ClothSim,
        Option<&mut ClothOnGpu>,
        Option<&mut ClothLeavingGpu>,
        Option<&GlobalTransform>,
        Option<&Cloth>,
    )>,
) {
    // Velocities handed to the GPU last frame were extracted with it.
    for (_, _, g, ..) in &mut cloths {
        if let Some(mut g) = g.filter(|g| g.sleep_velocities.is_some()) {
            g.sleep_velocities = None;
        }
    }
    // Every frame's impulses happened, whichever result per cloth is the latest.
    impulses.0.append(&mut results.impulses);
    // Every frame's steps count towards rest, in the order they were taken, among the last
    // fixed step's colliders and air, with the length of the cloth's steps.
    let fixed_dt = fixed.timestep().as_secs_f32();
    let dt_of = |g: &ClothOnGpu| if g.step_dt > 0.0 { g.step_dt } else { fixed_dt };
    let env = Environment {
        colliders: colliders.as_deref().map_or(&[], |c| &c.colliders),
        wind: wind.as_deref().map(|w| &w.field),
        time: wind.as_deref().map_or(0.0, |w| w.time),
    };
    for r in &results.cloths {
        if let Ok((_, mut cloth, Some(mut g), ..)) = cloths.get_mut(r.entity)
            && g.generation == r.generation
            && g.edits == cloth.edit_count()
            && !r.failed
        {
            let dt = dt_of(&g);
            g.count_rest(r, &mut cloth, &env, dt);
        }
    }
    let mut results = core::mem::take(&mut results.cloths);
    // The latest result per cloth (a slow frame can bring two).
    results.reverse();
    let mut seen = Vec::new();
    for r in results {
        if seen.contains(&r.entity) {
            continue;
        }
        seen.push(r.entity);
        let Ok(((entity, name, asked), mut cloth, mut on_gpu, leaving, transform, settings)) =
            cloths.get_mut(r.entity)
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
        // A state looked at for rest that found the cloth moving stays out of a `ClothSim`
        // that did not ask for it.
        let looked_only = on_gpu.as_ref().is_some_and(|g| !g.keeps_state(asked));
        if r.failed {
            cloth.recover(EntityName::new(entity, name), transform.copied());
        } else if let Some((positions, velocities)) = r.state.as_ref().filter(|_| !looked_only) {
            cloth.receive_state(positions, velocities);
            cloth.watch_stretch(time.delta_secs(), EntityName::new(entity, name));
            if let Some(g) = on_gpu.as_deref_mut() {
                let dt = dt_of(g);
                g.stopped(&r, cloth, &env, dt);
            }
            if leaving.is_some() {
                // The last GPU state is some steps old; an anchor that teleported since
                // takes the cloth along, as it would have on either backend.
                let limit = settings.map_or(DEFAULT_TELEPORT_DISTANCE, |c| c.teleport_distance);
                cloth.catch_up_with_pins(limit);
            }
            // Tear on the CPU the edges the GPU tore (it let go of them at once; the lab
            // solver only says that some edge is past the threshold, so its cloth tears what
            // is in the state read back). The new topology goes to the GPU as a settings
            // change (its state carried over, the edges it tore since torn again before its
            // first step), and the index buffer loses the torn triangles.
            let tore = r.tear
                && match &r.torn {
                    Some(edges) => cloth.tear_edges_now(entity, edges, &mut torn_messages),
                    None => cloth.tear_now(entity, &mut torn_messages),
                };
            if tore && let Some(mesh) = meshes.as_deref_mut().and_then(|m| m.get_mut(cloth.mesh()))
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
    for ((entity, name, _), mut cloth, _, leaving, _, _) in &mut cloths {
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

pub(crate) fn clear_queued_steps(
    mut queue: ResMut<GpuStepQueue>,
    mut cloths: Query<&mut ClothOnGpu>,
) {
    queue.steps.clear();
    queue.entities.clear();
    for mut g in &mut cloths {
        g.forget_queued_steps();
    }
}

/// Each fixed step with GPU cloths: its length and colliders (every GPU cloth feels the same
/// ones), each collider in its frame slot.
pub(crate) fn queue_gpu_colliders(
    time: Res<Time>,
    colliders: Option<Res<ClothColliders>>,
    mut queue: ResMut<GpuStepQueue>,
    gpu: Query<(), With<ClothOnGpu>>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 || gpu.is_empty() {
        return;
    }
    let (list, entities): (&[Collider], &[Entity]) = colliders
        .as_deref()
        .map_or((&[], &[]), |c| (&c.colliders, &c.entities));
    let queue = &mut *queue;
    let slots = entities
        .iter()
        .map(|e| match queue.entities.iter().position(|x| x == e) {
            Some(k) => k as u32,
            None => {
                queue.entities.push(*e);
                (queue.entities.len() - 1) as u32
            }
        })
        .collect();
    queue.steps.push(QueuedStep {
        dt,
        colliders: list.to_vec(),
        slots,
    });
}

/// In place of the CPU step: queue the step's pin targets, teleport and air for the GPU.
pub(crate) fn queue_gpu_steps(
    time: Res<Time>,
    queue: Res<GpuStepQueue>,
    wind: Option<Res<ClothWindField>>,
    mut cloths: Query<(&mut ClothSim, &mut ClothOnGpu)>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    let step = queue.steps.len().saturating_sub(1) as u32;
    let (field, t) = wind
        .as_deref()
        .map_or((None, 0.0), |w| (Some(&w.field), w.time));
    let env = Environment {
        colliders: queue.steps.last().map_or(&[], |s| &s.colliders),
        wind: field,
        time: t,
    };
    for (mut cloth, mut g) in &mut cloths {
        let g = &mut *g;
        g.step_dt = dt;
        let teleport = cloth.take_teleport();
        let carry = cloth.take_carry();
        if g.is_frozen() {
            // At rest: the step is sat out unless something could move the cloth.
            let moved = teleport.is_some()
                || carry.is_some_and(|c| c != Carry::IDENTITY)
                || cloth.simulation().motion_targets().is_some();
            if !g.wakes(&mut cloth, &env, dt, moved) {
                cloth.count_external_steps(1);
                continue;
            }
        }
        if g.pending.is_empty() {
            g.first_step = step;
        }
        let targets: Vec<Vec3> = cloth
            .simulation()
            .state()
            .pins()
            .iter()
            .map(|p| p.target)
            .collect();
        let stale = core::mem::take(&mut g.stale_targets).min(g.pending.len());
        for t in &mut g.pending[..stale] {
            t.clone_from(&targets);
        }
        g.pending.push(targets);
        cloth.count_external_steps(1);
        g.teleports.push(teleport.unwrap_or(Vec3::ZERO));
        let mut carry = carry.unwrap_or(Carry::IDENTITY);
        if core::mem::take(&mut g.fold_carries) && !g.carries.is_empty() {
            // The frame's steps run with the rest shape uploaded now: every carry of the frame
            // (this one's too) applies at its first step, so that the cloth is at that size
            // from then on.
            let folded = g.carries[1..]
                .iter()
                .chain([&carry])
                .fold(g.carries[0], |all, c| all.then(*c));
            g.carries.fill(Carry::IDENTITY);
            g.carries[0] = folded;
            carry = Carry::IDENTITY;
        }
        g.carries.push(carry);
        g.motion.push(
            cloth
                .simulation()
                .motion_targets()
                .map_or_else(MotionTargets::default, |m| MotionTargets::of(&m)),
        );
        cloth.motion_step_taken();
        cloth.step_air(field, t + 0.5 * f64::from(dt), dt, &mut g.air);
    }
}

/// In the fixed step after they arrive (their `ClothContactImpulse`s were just reset): GPU
/// cloths' impulses on colliders, a few frames after the GPU computed them.
pub(crate) fn add_gpu_impulses(
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
