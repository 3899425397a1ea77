//! The per-cloth simulation component and the systems that create, configure and step it.

use bevy::prelude::*;
use bevy::tasks::{ComputeTaskPool, TaskPool};

use crate::collider::{ClothColliders, ClothContactImpulse, add_impulses};
use crate::solver::{
    Environment, Features, ManyItem, MeshBinding, Parallel, Pin, SelfCollision, Serial, Simulation,
    SolverError, SolverParams, StateError, StepReport, TetherParams, TopologyOptions, Weld,
    Workers, limits, step_many,
};
use crate::wind::ClothWindField;

use super::mesh::{cloth_mesh, read_mesh};
use super::pose::FixedPoses;
use super::{
    Cloth, ClothConfig, ClothPins, ClothSelfCollision, ClothTearing, ClothTethers, ClothTorn,
    PinAnchor,
};

/// Why a cloth is not simulated. Logged once (naming the entity) and stored in
/// [`ClothInvalid`]; every other cloth keeps running.
#[derive(Clone, Debug, PartialEq)]
pub enum ClothError {
    /// The mesh is not a triangle list (the topology found is given).
    NotTriangleList(String),
    /// The mesh has no `POSITION` attribute.
    NoPositions,
    /// The positions are not `Float32x3` (the format found is given).
    PositionFormat(String),
    /// The mesh has no index buffer.
    NoIndices,
    /// The mesh's vertex data lives only in the render world (`RenderAssetUsages::RENDER_WORLD`):
    /// the CPU cannot read it.
    MeshNotInMainWorld,
    /// The entity's [`Mesh3d`] handle points at no mesh asset (it failed to load or was removed).
    MeshMissing,
    /// The cloth's total mass is outside [`limits::MASS`].
    BadMass(f32),
    /// [`Cloth::teleport_distance`] is outside [`limits::TELEPORT_DISTANCE`].
    BadTeleportDistance(f32),
    /// [`Cloth::weld_tolerance`] is outside [`limits::WELD_TOLERANCE`].
    BadWeldTolerance(f32),
    /// The solver rejected the mesh, masses, pins or parameters.
    Solver(SolverError),
}

impl core::fmt::Display for ClothError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ClothError::NotTriangleList(t) => {
                write!(f, "mesh topology is {t}, not a triangle list")
            }
            ClothError::NoPositions => write!(f, "mesh has no POSITION attribute"),
            ClothError::PositionFormat(t) => write!(f, "mesh positions are {t}, not Float32x3"),
            ClothError::NoIndices => write!(f, "mesh has no indices"),
            ClothError::MeshNotInMainWorld => write!(
                f,
                "mesh data is only in the render world; create it with RenderAssetUsages::MAIN_WORLD"
            ),
            ClothError::MeshMissing => write!(f, "the Mesh3d handle points at no mesh asset"),
            ClothError::BadMass(m) => {
                let l = limits::MASS;
                write!(f, "cloth mass {m} is outside [{}, {}] kg", l.min, l.max)
            }
            ClothError::BadTeleportDistance(d) => {
                let l = limits::TELEPORT_DISTANCE;
                write!(
                    f,
                    "teleport distance {d} is outside [{}, {}] m (infinity turns it off)",
                    l.min, l.max
                )
            }
            ClothError::BadWeldTolerance(t) => {
                let l = limits::WELD_TOLERANCE;
                write!(f, "weld tolerance {t} is outside [{}, {}]", l.min, l.max)
            }
            ClothError::Solver(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for ClothError {}

impl From<SolverError> for ClothError {
    fn from(e: SolverError) -> Self {
        ClothError::Solver(e)
    }
}

/// Sent once when a cloth is found invalid (the same moment the error is logged), so gameplay
/// or tools can react; the cloth then carries [`ClothInvalid`].
#[derive(Message, Clone, Debug, PartialEq)]
pub struct ClothFailed {
    /// The cloth entity.
    pub cloth: Entity,
    /// What is wrong with it.
    pub error: ClothError,
}

/// Present on a cloth entity that cannot be simulated, with the reason.
///
/// The plugin tries again when [`Cloth`], [`ClothConfig`], [`ClothPins`] or [`Mesh3d`] change.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct ClothInvalid(pub ClothError);

/// The running simulation of a cloth entity, inserted by the plugin on its first step.
///
/// Read it for the simulated positions (world space), normals and strain; mutate it through
/// [`ClothSim::simulation_mut`] to teleport or reset the cloth.
///
/// The solver simulates *particles*: the mesh's vertices after welding (see
/// [`Cloth::weld_tolerance`]). For a mesh without duplicated vertices particle `i` is mesh
/// vertex `i`; in general [`ClothSim::particle`] maps a mesh vertex to its particle, and
/// [`ClothSim::position`] reads a mesh vertex directly.
#[derive(Component)]
pub struct ClothSim {
    pub(crate) sim: Simulation,
    pub(crate) mesh: Handle<Mesh>,
    pub(crate) binding: MeshBinding,
    /// Mesh-space rest position of every particle (for pins that follow the cloth entity).
    rest_local: Vec<Vec3>,
    pub(crate) u16_indices: bool,
    steps: u64,
    pub(crate) dirty: bool,
    /// The triangles changed (tearing): the index buffer must be rewritten.
    pub(crate) indices_dirty: bool,
    torn_edges: usize,
    recoveries: u32,
    /// Wall-clock seconds of the last CPU step.
    step_seconds: f32,
    /// Calls of [`ClothSim::simulation_mut`] so far (a GPU cloth restarts from an edited state).
    pub(crate) edits: u64,
    /// How far the whole cloth jumped with its pins' anchors at the start of this fixed step
    /// (the teleport rule; the GPU backend applies it to its own state).
    pub(crate) teleport: Option<Vec3>,
    /// A config or feature change that was refused (the last valid settings run meanwhile).
    settings_error: Option<ClothError>,
    /// A pin list that was refused (the last valid pins hold meanwhile).
    pins_error: Option<ClothError>,
}

impl ClothSim {
    /// The solver-side simulation (topology, state in world space, parameters), in particle
    /// indices.
    #[must_use]
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// Mutable access, e.g. to [`ClothState::reset`](crate::solver::ClothState::reset) the
    /// cloth. Changes are written to the mesh at the next write-back; a cloth on the GPU
    /// restarts from the state as edited here.
    pub fn simulation_mut(&mut self) -> &mut Simulation {
        self.dirty = true;
        self.edits += 1;
        &mut self.sim
    }

    /// After a NaN or infinite state: the rest pose, placed where the entity is now
    /// (`placement`, when known), counted and logged.
    pub(crate) fn recover(&mut self, entity: Entity, placement: Option<GlobalTransform>) {
        self.sim.reset_to_rest();
        if let Some(t) = placement {
            let placed: Vec<Vec3> = self
                .rest_local
                .iter()
                .map(|p| t.transform_point(*p))
                .collect();
            self.sim.reset_to(&placed);
        }
        self.recoveries += 1;
        self.binding.retain(self.sim.topology());
        self.indices_dirty = true;
        self.dirty = true;
        warn!(
            "cloth {entity}: its state became NaN or infinite at step {}; reset to the rest \
             pose (recovery {})",
            self.steps, self.recoveries
        );
    }

    /// After edges tore (particle pairs): counts them, drops their triangles from the drawn
    /// mesh and sends [`ClothTorn`] (in mesh vertices).
    pub(crate) fn note_torn(
        &mut self,
        entity: Entity,
        torn: &[[u32; 2]],
        messages: &mut MessageWriter<ClothTorn>,
    ) {
        if torn.is_empty() {
            return;
        }
        self.torn_edges += torn.len();
        self.binding.retain(self.sim.topology());
        self.indices_dirty = true;
        let weld = self.binding.weld();
        messages.write(ClothTorn {
            cloth: entity,
            edges: torn
                .iter()
                .map(|e| e.map(|p| weld.representative(p)))
                .collect(),
        });
    }

    /// Counts steps the GPU took.
    pub(crate) fn count_steps(&mut self, steps: u64) {
        self.steps += steps;
    }

    /// Takes positions (`xyz`; the inverse masses stay) and velocities read back from the GPU.
    pub(crate) fn take_gpu_state(&mut self, positions: &[Vec4], velocities: &[Vec4]) {
        let state = self.sim.state_mut();
        if positions.len() != state.len() || velocities.len() != state.len() {
            return;
        }
        for (x, g) in state.positions.iter_mut().zip(positions) {
            *x = g.truncate().extend(x.w);
        }
        state.velocities.copy_from_slice(velocities);
    }

    /// The cloth's own mesh asset (a copy of the source mesh).
    #[must_use]
    pub fn mesh(&self) -> &Handle<Mesh> {
        &self.mesh
    }

    /// How the mesh's vertices map onto particles.
    #[must_use]
    pub fn weld(&self) -> &Weld {
        self.binding.weld()
    }

    /// The rest position of every particle in the mesh's own space (before the entity's
    /// transform): where [`PinAnchor::Rest`](crate::cloth::PinAnchor::Rest) pins hold them.
    #[must_use]
    pub fn rest_shape(&self) -> &[Vec3] {
        &self.rest_local
    }

    /// The particle that simulates mesh vertex `vertex`.
    ///
    /// # Panics
    /// If `vertex` is not a vertex of the mesh.
    #[must_use]
    pub fn particle(&self, vertex: u32) -> u32 {
        self.binding.weld().particle(vertex)
    }

    /// Where a world-space ray (e.g. from `Camera::viewport_to_world` under the cursor)
    /// meets the cloth first, from either side, and the mesh vertex nearest that point: for
    /// grabbing the cloth or choosing vertices to pin. A cloth on the GPU is picked where
    /// [`ClothSim`] knows it to be (see [`ClothReadback`](crate::gpu::ClothReadback)).
    #[must_use]
    pub fn pick(&self, ray: Ray3d) -> Option<ClothPick> {
        let hit = crate::solver::ray_hit(
            &self.sim.state().positions,
            self.sim.topology().triangles(),
            ray.origin,
            *ray.direction,
        )?;
        Some(ClothPick {
            vertex: self.binding.weld().representative(hit.nearest),
            particle: hit.nearest,
            point: hit.point,
            distance: hit.t,
        })
    }

    /// World position of mesh vertex `vertex` now.
    ///
    /// # Panics
    /// If `vertex` is not a vertex of the mesh.
    #[must_use]
    pub fn position(&self, vertex: u32) -> Vec3 {
        self.sim.state().position(self.particle(vertex) as usize)
    }

    /// World-space unit normal of every mesh vertex, as of the last write-back.
    #[must_use]
    pub fn normals(&self) -> &[Vec3] {
        self.binding.shading().normals()
    }

    /// World-space tangents of every mesh vertex as of the last write-back (empty when the
    /// mesh has neither UVs nor tangents).
    #[must_use]
    pub fn tangents(&self) -> &[Vec4] {
        self.binding.shading().tangents()
    }

    /// Steps simulated so far.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Edges torn so far (every edge that left the cloth, as in [`ClothTorn`]).
    #[must_use]
    pub fn torn_edges(&self) -> usize {
        self.torn_edges
    }

    /// Times the state went NaN or infinite and was reset to the rest pose (each one is
    /// logged as a warning).
    #[must_use]
    pub fn recoveries(&self) -> u32 {
        self.recoveries
    }

    /// Why the latest [`ClothConfig`], opt-in feature or [`ClothPins`] change was refused,
    /// while the cloth runs on its last valid ones; `None` when everything asked for is in use.
    #[must_use]
    pub fn rejected(&self) -> Option<&ClothError> {
        self.settings_error.as_ref().or(self.pins_error.as_ref())
    }

    /// Wall-clock seconds the last CPU step of this cloth took (0 before the first step and
    /// for a cloth stepped on the GPU). Cloths are stepped in parallel with each other, so
    /// this is the time of this cloth's own step, not its share of the frame.
    #[must_use]
    pub fn step_seconds(&self) -> f32 {
        self.step_seconds
    }

    /// Whether the cloth is asleep: it came to rest, its steps are skipped and its mesh is not
    /// rewritten until a pin, a collider near it, the wind at it or its settings change
    /// ([`ClothConfig::sleep`](crate::cloth::ClothConfig::sleep) sets when).
    #[must_use]
    pub fn is_sleeping(&self) -> bool {
        self.sim.is_sleeping()
    }
}

/// What [`ClothSim::pick`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClothPick {
    /// The mesh vertex nearest the point hit (the first copy of its particle, for a welded
    /// mesh): what [`ClothPins`] and [`ClothSim::position`] take.
    pub vertex: u32,
    /// Its particle.
    pub particle: u32,
    /// The point hit, in world space.
    pub point: Vec3,
    /// Distance from the ray's origin to the point, in metres.
    pub distance: f32,
}

/// The mesh a cloth was built from and the cloth's own copy of it (which its [`Mesh3d`] shows
/// and the simulation rewrites). Inserted by the plugin; rebuilding the cloth starts again from
/// `source` as long as the entity still shows `copy`, and removing [`Cloth`] puts `source`
/// back on the entity.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct ClothSource {
    /// The mesh the user gave.
    pub source: Handle<Mesh>,
    /// The cloth's own copy.
    pub copy: Handle<Mesh>,
}

/// Runs solver work items on Bevy's [`ComputeTaskPool`].
#[derive(Clone, Copy)]
pub struct TaskPoolParallel<'a>(pub &'a TaskPool);

impl Parallel for TaskPoolParallel<'_> {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        if items.len() < 2 || self.0.thread_num() == 0 {
            items.iter_mut().for_each(f);
            return;
        }
        let f = &f;
        self.0.scope(|s| {
            for item in items.iter_mut() {
                s.spawn(async move { f(item) });
            }
        });
    }

    fn threads(&self) -> usize {
        // The pool's threads and the thread that waits on the scope, which works too.
        self.0.thread_num() + 1
    }
}

/// The pins of `pins` in particle terms, first pin of a particle winning.
fn pin_list(pins: &ClothPins, weld: &Weld) -> Result<Vec<(u32, PinAnchor)>, ClothError> {
    let n = weld.vertex_count();
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::with_capacity(pins.0.len());
    for p in &pins.0 {
        if p.vertex as usize >= n {
            return Err(SolverError::State(StateError::PinOutOfRange {
                vertex: p.vertex,
                vertex_count: n,
            })
            .into());
        }
        let particle = weld.particle(p.vertex);
        if seen.insert(particle) {
            out.push((particle, p.anchor));
        }
    }
    Ok(out)
}

/// Where a pin should be now (`None`: its anchor entity has no pose; the pin stays).
fn pin_target(
    particle: u32,
    anchor: PinAnchor,
    rest_local: &[Vec3],
    own: &GlobalTransform,
    poses: &FixedPoses,
) -> Option<Vec3> {
    match anchor {
        PinAnchor::Rest => rest_local
            .get(particle as usize)
            .map(|r| own.transform_point(*r)),
        PinAnchor::World(w) => Some(w),
        PinAnchor::Entity { entity, offset } => {
            poses.get(entity).map(|t| t.transform_point(offset))
        }
    }
}

/// Replaces the pins of `sim` with `list`. Vertices pinned before and after keep the teleport
/// rule: if their anchors jumped farther than `teleport` since the last step, the whole cloth
/// moves with them. Atomic: on error nothing changes.
fn repin(
    sim: &mut Simulation,
    list: &[(u32, PinAnchor)],
    rest_local: &[Vec3],
    own: &GlobalTransform,
    poses: &FixedPoses,
    teleport: f32,
) -> Result<Option<Vec3>, ClothError> {
    let old: std::collections::HashMap<u32, Vec3> = sim
        .state()
        .pins()
        .iter()
        .map(|p| (p.vertex, p.target))
        .collect();
    let new: Vec<Pin> = list
        .iter()
        .map(|&(particle, anchor)| Pin {
            vertex: particle,
            target: pin_target(particle, anchor, rest_local, own, poses)
                .unwrap_or_else(|| sim.state().position(particle as usize)),
        })
        .collect();
    let jumps: Vec<Vec3> = new
        .iter()
        .filter_map(|p| old.get(&p.vertex).map(|o| p.target - *o))
        .filter(|d| d.length() > teleport)
        .collect();
    let state = sim.state_mut();
    state
        .set_pins(new.iter().copied())
        .map_err(SolverError::from)?;
    if jumps.is_empty() {
        return Ok(None);
    }
    let offset = jumps.iter().sum::<Vec3>() / jumps.len() as f32;
    state.translate(offset);
    state.set_pin_targets(new.iter().map(|p| p.target));
    state.snap_pins();
    Ok(Some(offset))
}

/// Moves the pins of an unchanged pin list to their anchors; a jump past `teleport` moves the
/// whole cloth by the pins' mean jump (returned).
fn follow_anchors(
    sim: &mut Simulation,
    list: &[(u32, PinAnchor)],
    rest_local: &[Vec3],
    own: &GlobalTransform,
    poses: &FixedPoses,
    teleport: f32,
) -> Option<Vec3> {
    let targets: Vec<Option<Vec3>> = list
        .iter()
        .map(|&(p, a)| pin_target(p, a, rest_local, own, poses))
        .collect();
    let current: Vec<Vec3> = sim.state().pins().iter().map(|p| p.target).collect();
    let jumps: Vec<Vec3> = targets
        .iter()
        .zip(&current)
        .filter_map(|(t, c)| t.map(|t| t - *c))
        .filter(|d| d.length() > teleport)
        .collect();
    let state = sim.state_mut();
    let offset = (!jumps.is_empty()).then(|| jumps.iter().sum::<Vec3>() / jumps.len() as f32);
    if let Some(offset) = offset {
        state.translate(offset);
    }
    state.set_pin_targets(
        targets
            .into_iter()
            .zip(current)
            .map(|(t, c)| t.unwrap_or(c)),
    );
    if offset.is_some() {
        state.snap_pins();
    }
    offset
}

struct Built {
    sim: Simulation,
    binding: MeshBinding,
    rest_local: Vec<Vec3>,
    mesh: Mesh,
    u16_indices: bool,
}

fn build(
    cloth: &Cloth,
    config: &ClothConfig,
    pins: &ClothPins,
    mesh: &Mesh,
    own: &GlobalTransform,
    poses: &FixedPoses,
) -> Result<Built, ClothError> {
    if !limits::MASS.contains(cloth.mass) {
        return Err(ClothError::BadMass(cloth.mass));
    }
    if !limits::TELEPORT_DISTANCE.contains(cloth.teleport_distance) {
        return Err(ClothError::BadTeleportDistance(cloth.teleport_distance));
    }
    if !limits::WELD_TOLERANCE.contains(cloth.weld_tolerance) {
        return Err(ClothError::BadWeldTolerance(cloth.weld_tolerance));
    }
    let data = read_mesh(mesh)?;
    let (lo, hi) = data.positions.iter().filter(|p| p.is_finite()).fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let size = if lo.cmple(hi).all() {
        (hi - lo).length()
    } else {
        0.0
    };
    let binding = MeshBinding::new(
        &data.positions,
        data.attributes(),
        &data.indices,
        cloth.weld_tolerance * size,
    )
    .map_err(SolverError::from)?;
    // The rest shape is the mesh placed by the entity's transform, so a scaled entity gets a
    // scaled cloth (rest lengths in world units).
    let world: Vec<Vec3> = data
        .positions
        .iter()
        .map(|p| own.transform_point(*p))
        .collect();
    let topology = binding
        .topology(
            &world,
            TopologyOptions {
                bend_rest: cloth.bend_rest,
                bending: cloth.bending_model,
            },
        )
        .map_err(SolverError::from)?;
    let masses = topology.masses(cloth.mass, cloth.mass_distribution);
    let mut sim = Simulation::new(topology, &masses, (*config).into())?;
    let rest_local = binding.weld().gather(&data.positions);
    let list = pin_list(pins, binding.weld())?;
    repin(
        &mut sim,
        &list,
        &rest_local,
        own,
        poses,
        cloth.teleport_distance,
    )?;
    sim.state_mut().snap_pins();
    let mut binding = binding;
    binding.update_shading(&sim.state().positions);
    Ok(Built {
        sim,
        binding,
        rest_local,
        mesh: cloth_mesh(mesh, &data),
        u16_indices: data.u16_indices,
    })
}

/// The solver features a cloth's opt-in components ask for.
fn features(
    sim: &Simulation,
    self_collision: Option<&ClothSelfCollision>,
    tethers: Option<&ClothTethers>,
    tearing: Option<&ClothTearing>,
) -> Features {
    Features {
        self_collision: self_collision.map(|sc| SelfCollision {
            thickness: sc.thickness.unwrap_or_else(|| {
                let e = sim.topology().edges();
                e.iter().map(|e| e.rest).sum::<f32>() / e.len().max(1) as f32
            }),
            friction: sc.friction,
        }),
        tethers: tethers.map(|t| TetherParams {
            slack: t.slack,
            pins_per_vertex: t.pins_per_vertex,
        }),
        tear_threshold: tearing.map(|t| t.threshold),
    }
}

fn report(commands: &mut Commands, entity: Entity, error: ClothError) {
    error!("cloth {entity}: {error}; it is not simulated");
    commands.write_message(ClothFailed {
        cloth: entity,
        error: error.clone(),
    });
    // Drop any running simulation too: an invalid cloth is not simulated, and fixing it
    // rebuilds it from scratch.
    commands
        .entity(entity)
        .try_remove::<ClothSim>()
        .try_insert(ClothInvalid(error));
}

/// Creates the simulation of cloths that have none yet (waiting while their mesh loads).
#[expect(clippy::type_complexity, reason = "a query filter, read once")]
pub(crate) fn init_cloths(
    mut commands: Commands,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    asset_server: Option<Res<AssetServer>>,
    new: Query<
        (
            Entity,
            &Cloth,
            &ClothConfig,
            &ClothPins,
            &Mesh3d,
            Option<&ClothSource>,
            FeatureQuery,
        ),
        (Without<ClothSim>, Without<ClothInvalid>),
    >,
    poses: FixedPoses,
) {
    let Some(meshes) = meshes.as_deref_mut() else {
        return;
    };
    for (entity, cloth, config, pins, mesh3d, source, (sc, tethers, tearing)) in &new {
        // Rebuilding (after a change to `Cloth` or a fix): start from the mesh the user gave,
        // not from the cloth's own, deformed copy — unless the user has put another mesh in.
        let source_handle = match source {
            Some(s) if s.copy == mesh3d.0 => s.source.clone(),
            _ => mesh3d.0.clone(),
        };
        let Some(mesh) = meshes.get(&source_handle) else {
            // Not loaded yet: wait. Failed to load: say so once.
            let failed = asset_server.as_ref().is_some_and(|s| {
                matches!(
                    s.get_load_state(&source_handle),
                    Some(bevy::asset::LoadState::Failed(_))
                )
            });
            if failed {
                report(&mut commands, entity, ClothError::MeshMissing);
            }
            continue;
        };
        // Where the entity is at this step, even if it was spawned in this fixed step and
        // has no propagated GlobalTransform yet.
        let own = poses.get(entity).unwrap_or_default();
        let built = build(cloth, config, pins, mesh, &own, &poses).and_then(|mut b| {
            // Features are checked before the cloth starts, so a bad one never runs a step.
            let wanted = features(&b.sim, sc, tethers, tearing);
            b.sim.set_features(wanted).map_err(SolverError::Params)?;
            Ok(b)
        });
        match built {
            Ok(b) => {
                let handle = meshes.add(b.mesh);
                commands.entity(entity).try_insert((
                    Mesh3d(handle.clone()),
                    ClothSource {
                        source: source_handle,
                        copy: handle.clone(),
                    },
                    ClothSim {
                        sim: b.sim,
                        mesh: handle,
                        binding: b.binding,
                        rest_local: b.rest_local,
                        u16_indices: b.u16_indices,
                        steps: 0,
                        dirty: true,
                        indices_dirty: false,
                        torn_edges: 0,
                        recoveries: 0,
                        step_seconds: 0.0,
                        edits: 0,
                        teleport: None,
                        settings_error: None,
                        pins_error: None,
                    },
                ));
            }
            Err(e) => report(&mut commands, entity, e),
        }
    }
}

/// Clears [`ClothInvalid`] when the user changes what made the cloth invalid, so it is tried
/// again; drops the simulation (to rebuild it) when the entity's mesh is replaced by another
/// one or its [`Cloth`] changes.
#[expect(clippy::type_complexity, reason = "a query filter, read once")]
pub(crate) fn retry_cloths(
    mut commands: Commands,
    invalid: Query<
        Entity,
        (
            With<ClothInvalid>,
            Or<(
                Changed<Cloth>,
                Changed<ClothConfig>,
                Changed<ClothPins>,
                Changed<Mesh3d>,
                Changed<ClothSelfCollision>,
                Changed<ClothTethers>,
                Changed<ClothTearing>,
            )>,
        ),
    >,
    swapped: Query<(Entity, &Mesh3d, &ClothSim), Changed<Mesh3d>>,
    rebuilt: Query<Entity, (Changed<Cloth>, With<ClothSim>)>,
) {
    // Mass, mass distribution, bend rest and welding are baked into the simulation: rebuild
    // it (the cloth starts again from its rest shape).
    for entity in &rebuilt {
        commands.entity(entity).remove::<ClothSim>();
    }
    for entity in &invalid {
        commands.entity(entity).remove::<(ClothInvalid, ClothSim)>();
    }
    for (entity, mesh, sim) in &swapped {
        if mesh.0 != sim.mesh {
            commands.entity(entity).remove::<ClothSim>();
        }
    }
}

/// Removing [`Cloth`] stops the simulation and gives the entity its own mesh back; adding it
/// again starts afresh.
pub(crate) fn on_cloth_removed(
    removed: On<Remove, Cloth>,
    mut commands: Commands,
    cloths: Query<(Option<&ClothSource>, Option<&Mesh3d>)>,
) {
    let entity = removed.entity;
    if let Ok((Some(source), Some(mesh))) = cloths.get(entity)
        && mesh.0 == source.copy
    {
        commands
            .entity(entity)
            .try_insert(Mesh3d(source.source.clone()));
    }
    commands
        .entity(entity)
        .try_remove::<(ClothSim, ClothSource, ClothInvalid)>();
    crate::gpu::forget_gpu_cloth(&mut commands, entity);
}

/// The optional components of a cloth entity.
type FeatureQuery = (
    Option<&'static ClothSelfCollision>,
    Option<&'static ClothTethers>,
    Option<&'static ClothTearing>,
);

/// Logs and sends a refused change once, when a cloth goes from fine to refused.
fn note_rejection(
    commands: &mut Commands,
    entity: Entity,
    slot: &mut Option<ClothError>,
    result: Result<(), ClothError>,
    what: &str,
) {
    match result {
        Ok(()) => {
            if slot.take().is_some() {
                info!("cloth {entity}: its {what} are valid again and in use");
            }
        }
        Err(e) => {
            if slot.is_none() {
                error!("cloth {entity}: {e}; it keeps its last valid {what}");
                commands.write_message(ClothFailed {
                    cloth: entity,
                    error: e.clone(),
                });
            }
            *slot = Some(e);
        }
    }
}

/// Applies changed configs, pins and features, and moves pin targets to their anchors
/// (moving the whole cloth along when an anchor teleports).
#[expect(clippy::type_complexity, reason = "a query, read once")]
pub(crate) fn sync_cloths(
    mut commands: Commands,
    mut cloths: Query<
        (
            Entity,
            &Cloth,
            &mut ClothSim,
            Ref<ClothConfig>,
            Ref<ClothPins>,
            FeatureQuery,
        ),
        Without<ClothInvalid>,
    >,
    poses: FixedPoses,
) {
    for (entity, cloth, mut sim, config, pins, (sc, tethers, tearing)) in &mut cloths {
        let cs = &mut *sim;
        let own = poses.get(entity).unwrap_or_default();
        // A changed (or still refused) config is applied with the features; otherwise only
        // changed features are.
        let config_due = config.is_changed() || cs.settings_error.is_some();
        let wanted = features(&cs.sim, sc, tethers, tearing);
        let params = SolverParams::from(*config);
        let params_due = config_due && params != *cs.sim.params();
        let features_due = wanted != *cs.sim.features();
        if config_due || features_due {
            let result = if params_due {
                cs.sim.set_params(params)
            } else {
                Ok(())
            }
            .and_then(|()| {
                if features_due {
                    cs.sim.set_features(wanted)
                } else {
                    Ok(())
                }
            })
            .map_err(|e| ClothError::Solver(SolverError::Params(e)));
            note_rejection(
                &mut commands,
                entity,
                &mut cs.settings_error,
                result,
                "settings",
            );
        }
        let list = pin_list(&pins, cs.binding.weld());
        cs.teleport = None;
        if pins.is_changed() || cs.pins_error.is_some() {
            let result = list.and_then(|list| {
                repin(
                    &mut cs.sim,
                    &list,
                    &cs.rest_local,
                    &own,
                    &poses,
                    cloth.teleport_distance,
                )
            });
            if let Ok(offset) = &result {
                cs.teleport = *offset;
            }
            note_rejection(
                &mut commands,
                entity,
                &mut cs.pins_error,
                result.map(|_| ()),
                "pins",
            );
            cs.dirty = true;
            continue;
        }
        if let Ok(list) = list
            && let Some(offset) = follow_anchors(
                &mut cs.sim,
                &list,
                &cs.rest_local,
                &own,
                &poses,
                cloth.teleport_distance,
            )
        {
            cs.teleport = Some(offset);
            cs.dirty = true;
        }
    }
}

/// Advances every valid cloth by one fixed step among the colliders and the wind.
/// Cloths the CPU steps: valid, and neither on the GPU backend nor waiting for its last state.
type CpuCloths = (
    Without<ClothInvalid>,
    Without<crate::gpu::ClothOnGpu>,
    Without<crate::gpu::ClothLeavingGpu>,
);

/// The worker threads the plugin steps CPU cloths on ([`Workers::per_core`]: one helper per
/// core besides the thread running the system). They spin for a moment after each parallel
/// region and then sleep, so an idle app pays nothing for them. Remove the resource to step
/// on Bevy's `ComputeTaskPool` instead (slower for one cloth: waking its threads takes about
/// as long as a substep's work at 64 × 64), or insert `ClothWorkers(Workers::new(0))` to step
/// on the calling thread only.
#[derive(Resource, Debug)]
pub struct ClothWorkers(pub Workers);

impl Default for ClothWorkers {
    fn default() -> Self {
        Self(Workers::per_core())
    }
}

pub(crate) fn step_cloths(
    (time, workers): (Res<Time>, Option<Res<ClothWorkers>>),
    colliders: Option<Res<ClothColliders>>,
    wind: Option<Res<ClothWindField>>,
    mut cloths: Query<(Entity, &mut ClothSim), CpuCloths>,
    mut impulses: Query<&mut ClothContactImpulse>,
    mut torn: MessageWriter<ClothTorn>,
    poses: FixedPoses,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    let no_colliders = ClothColliders::default();
    let colliders = colliders.as_deref().unwrap_or(&no_colliders);
    let env = Environment {
        colliders: &colliders.colliders,
        wind: wind.as_deref().map(|w| &w.field),
        time: wind.as_deref().map_or(0.0, |w| w.time),
    };
    // Big cloths one after another with their parts in parallel, then the small ones in
    // parallel with each other (`step_many`).
    let mut list: Vec<(Entity, Mut<ClothSim>)> = cloths.iter_mut().collect();
    let reports: Vec<(StepReport, f32)> = {
        let mut items: Vec<ManyItem<'_>> = list
            .iter_mut()
            .map(|(_, c)| ManyItem {
                sim: &mut c.sim,
                report: StepReport::default(),
                seconds: 0.0,
            })
            .collect();
        // The task pool only without `ClothWorkers` (then serial if there is none).
        match workers.as_deref() {
            Some(workers) => step_many(&mut items, dt, &env, &workers.0),
            None => match ComputeTaskPool::try_get() {
                Some(pool) => step_many(&mut items, dt, &env, &TaskPoolParallel(pool)),
                None => step_many(&mut items, dt, &env, &Serial),
            },
        }
        items.into_iter().map(|i| (i.report, i.seconds)).collect()
    };
    for ((entity, mut cloth), (report, seconds)) in list.into_iter().zip(reports) {
        let cloth = &mut *cloth;
        cloth.step_seconds = seconds;
        if report.recovered {
            // The solver already reset to its rest shape where the cloth was created; place
            // the rest shape where the entity is now.
            cloth.recover(entity, poses.get(entity));
        }
        add_impulses(colliders, cloth.sim.impulses(), &mut impulses);
        cloth.note_torn(entity, &report.torn, &mut torn);
        cloth.steps += 1;
        // A sleeping cloth did not move: its mesh stays as it is.
        cloth.dirty |= !report.asleep;
    }
}
