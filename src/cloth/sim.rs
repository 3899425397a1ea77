//! The per-cloth simulation component and the systems that create, configure and step it.

use bevy::prelude::*;
use bevy::tasks::{ComputeTaskPool, TaskPool};

use crate::collider::{ClothColliders, ClothContactImpulse, add_impulses};
use crate::solver::{
    Environment, Features, Parallel, Pin, SelfCollision, Serial, Simulation, SolverError,
    SolverParams, TetherParams, Topology, TopologyOptions,
};
use crate::wind::ClothWindField;

use super::mesh::{cloth_mesh, read_mesh};
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
    /// The cloth's total mass is not finite and positive.
    BadMass(f32),
    /// [`Cloth::teleport_distance`] is NaN or not positive.
    BadTeleportDistance(f32),
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
            ClothError::BadMass(m) => write!(f, "cloth mass {m} must be finite and > 0"),
            ClothError::BadTeleportDistance(d) => {
                write!(
                    f,
                    "teleport distance {d} must be > 0 (infinity turns it off)"
                )
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
#[derive(Component)]
pub struct ClothSim {
    pub(crate) sim: Simulation,
    pub(crate) mesh: Handle<Mesh>,
    /// Mesh-space rest positions (for pins that follow the cloth entity).
    rest_local: Vec<Vec3>,
    steps: u64,
    pub(crate) dirty: bool,
    /// The triangles changed (tearing): the index buffer must be rewritten.
    pub(crate) indices_dirty: bool,
    torn_edges: usize,
    recoveries: u32,
}

impl ClothSim {
    /// The solver-side simulation (topology, state in world space, parameters).
    #[must_use]
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// Mutable access, e.g. to [`ClothState::reset`](crate::solver::ClothState::reset) the
    /// cloth. Changes are written to the mesh at the next write-back.
    pub fn simulation_mut(&mut self) -> &mut Simulation {
        self.dirty = true;
        &mut self.sim
    }

    /// The cloth's own mesh asset (a copy of the source mesh).
    #[must_use]
    pub fn mesh(&self) -> &Handle<Mesh> {
        &self.mesh
    }

    /// Steps simulated so far.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Edges torn so far.
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
}

/// The mesh a cloth was built from and the cloth's own copy of it (which its [`Mesh3d`] shows
/// and the simulation rewrites). Inserted by the plugin; rebuilding the cloth starts again from
/// `source` as long as the entity still shows `copy`.
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
}

/// Where each pin should be now.
fn pin_targets<'a>(
    pins: &'a ClothPins,
    rest: &'a [Vec3],
    own: &'a GlobalTransform,
    transforms: &'a Query<&GlobalTransform>,
) -> impl Iterator<Item = Option<Vec3>> + 'a {
    pins.0.iter().map(move |p| match p.anchor {
        PinAnchor::Rest => rest.get(p.vertex as usize).map(|r| own.transform_point(*r)),
        PinAnchor::World(w) => Some(w),
        PinAnchor::Entity { entity, offset } => transforms
            .get(entity)
            .ok()
            .map(|t| t.transform_point(offset)),
    })
}

type Built = (Simulation, Vec<Vec3>, Mesh);

fn build(
    cloth: &Cloth,
    config: &ClothConfig,
    pins: &ClothPins,
    mesh: &Mesh,
    own: &GlobalTransform,
    transforms: &Query<&GlobalTransform>,
) -> Result<Built, ClothError> {
    if !(cloth.mass.is_finite() && cloth.mass > 0.0) {
        return Err(ClothError::BadMass(cloth.mass));
    }
    if cloth.teleport_distance.is_nan() || cloth.teleport_distance <= 0.0 {
        return Err(ClothError::BadTeleportDistance(cloth.teleport_distance));
    }
    let data = read_mesh(mesh)?;
    // The rest shape is the mesh placed by the entity's transform, so a scaled entity gets a
    // scaled cloth (rest lengths in world units).
    let world: Vec<Vec3> = data
        .positions
        .iter()
        .map(|p| own.transform_point(*p))
        .collect();
    let topology = Topology::from_triangles(
        &world,
        data.uvs.as_deref(),
        &data.indices,
        TopologyOptions {
            bend_rest: cloth.bend_rest,
        },
    )
    .map_err(SolverError::from)?;
    let masses = topology.masses(cloth.mass, cloth.mass_distribution);
    let mut sim = Simulation::new(topology, &masses, (*config).into())?;
    set_pins(&mut sim, pins, &data.positions, own, transforms)?;
    sim.state_mut().snap_pins();
    sim.update_shading();
    Ok((sim, data.positions.clone(), cloth_mesh(mesh, &data)))
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

fn set_pins(
    sim: &mut Simulation,
    pins: &ClothPins,
    rest: &[Vec3],
    own: &GlobalTransform,
    transforms: &Query<&GlobalTransform>,
) -> Result<(), SolverError> {
    let current: Vec<Vec3> = pins
        .0
        .iter()
        .map(|p| {
            sim.state()
                .positions
                .get(p.vertex as usize)
                .map_or(Vec3::ZERO, |x| x.truncate())
        })
        .collect();
    let list: Vec<Pin> = pins
        .0
        .iter()
        .zip(pin_targets(pins, rest, own, transforms))
        .zip(current)
        .map(|((p, target), here)| Pin {
            vertex: p.vertex,
            target: target.unwrap_or(here),
        })
        .collect();
    sim.state_mut().set_pins(list)?;
    Ok(())
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
            &GlobalTransform,
            Option<&ClothSource>,
            FeatureQuery,
        ),
        (Without<ClothSim>, Without<ClothInvalid>),
    >,
    transforms: Query<&GlobalTransform>,
) {
    let Some(meshes) = meshes.as_deref_mut() else {
        return;
    };
    for (entity, cloth, config, pins, mesh3d, own, source, (sc, tethers, tearing)) in &new {
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
        let built = build(cloth, config, pins, mesh, own, &transforms).and_then(|b| {
            // Features are checked before the cloth starts, so a bad one never runs a step.
            let mut b = b;
            let wanted = features(&b.0, sc, tethers, tearing);
            b.0.set_features(wanted).map_err(SolverError::Params)?;
            Ok(b)
        });
        match built {
            Ok((sim, rest_local, mesh)) => {
                let handle = meshes.add(mesh);
                commands.entity(entity).try_insert((
                    Mesh3d(handle.clone()),
                    ClothSource {
                        source: source_handle,
                        copy: handle.clone(),
                    },
                    ClothSim {
                        sim,
                        mesh: handle,
                        rest_local,
                        steps: 0,
                        dirty: true,
                        indices_dirty: false,
                        torn_edges: 0,
                        recoveries: 0,
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
    // Mass, mass distribution and bend rest are baked into the simulation: rebuild it (the
    // cloth starts again from its rest shape).
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

/// The optional components of a cloth entity.
type FeatureQuery = (
    Option<&'static ClothSelfCollision>,
    Option<&'static ClothTethers>,
    Option<&'static ClothTearing>,
);

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
            &GlobalTransform,
            FeatureQuery,
        ),
        Without<ClothInvalid>,
    >,
    transforms: Query<&GlobalTransform>,
) {
    for (entity, cloth, mut sim, config, pins, own, (sc, tethers, tearing)) in &mut cloths {
        let cs = &mut *sim;
        if config.is_changed()
            && *cs.sim.params() != SolverParams::from(*config)
            && let Err(e) = cs.sim.set_params((*config).into())
        {
            report(&mut commands, entity, SolverError::Params(e).into());
            continue;
        }
        let wanted = features(&cs.sim, sc, tethers, tearing);
        if wanted != *cs.sim.features()
            && let Err(e) = cs.sim.set_features(wanted)
        {
            report(&mut commands, entity, SolverError::Params(e).into());
            continue;
        }
        if pins.is_changed() {
            if let Err(e) = set_pins(&mut cs.sim, &pins, &cs.rest_local, own, &transforms) {
                report(&mut commands, entity, e.into());
            }
            continue;
        }
        let targets: Vec<Option<Vec3>> =
            pin_targets(&pins, &cs.rest_local, own, &transforms).collect();
        let current: Vec<Vec3> = cs.sim.state().pins().iter().map(|p| p.target).collect();
        // A jump past the teleport distance moves the whole cloth by the pins' mean jump.
        let jumps: Vec<Vec3> = targets
            .iter()
            .zip(&current)
            .filter_map(|(t, c)| t.map(|t| t - *c))
            .filter(|d| d.length() > cloth.teleport_distance)
            .collect();
        if !jumps.is_empty() {
            let offset = jumps.iter().sum::<Vec3>() / jumps.len() as f32;
            cs.sim.state_mut().translate(offset);
            cs.dirty = true;
        }
        cs.sim.state_mut().set_pin_targets(
            targets
                .into_iter()
                .zip(current)
                .map(|(t, c)| t.unwrap_or(c)),
        );
        if !jumps.is_empty() {
            cs.sim.state_mut().snap_pins();
        }
    }
}

/// Advances every valid cloth by one fixed step among the colliders and the wind.
pub(crate) fn step_cloths(
    time: Res<Time>,
    colliders: Option<Res<ClothColliders>>,
    wind: Option<Res<ClothWindField>>,
    mut cloths: Query<(Entity, &mut ClothSim, Option<&GlobalTransform>), Without<ClothInvalid>>,
    mut impulses: Query<&mut ClothContactImpulse>,
    mut torn: MessageWriter<ClothTorn>,
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
    let pool = ComputeTaskPool::try_get();
    for (entity, mut cloth, transform) in &mut cloths {
        let cloth = &mut *cloth;
        let report = match pool {
            Some(pool) => cloth.sim.step_in(dt, &env, &TaskPoolParallel(pool)),
            None => cloth.sim.step_in(dt, &env, &Serial),
        };
        if report.recovered {
            // The solver already reset to its rest shape where the cloth was created; place
            // the rest shape where the entity is now.
            if let Some(t) = transform {
                let placed: Vec<Vec3> = cloth
                    .rest_local
                    .iter()
                    .map(|p| t.transform_point(*p))
                    .collect();
                cloth.sim.reset_to(&placed);
            }
            cloth.recoveries += 1;
            cloth.indices_dirty = true;
            warn!(
                "cloth {entity}: its state became NaN or infinite at step {}; reset to the rest \
                 pose (recovery {})",
                cloth.steps, cloth.recoveries
            );
        }
        add_impulses(colliders, cloth.sim.impulses(), &mut impulses);
        if !report.torn.is_empty() {
            cloth.torn_edges += report.torn.len();
            cloth.indices_dirty = true;
            torn.write(ClothTorn {
                cloth: entity,
                edges: report.torn,
            });
        }
        cloth.steps += 1;
        cloth.dirty = true;
    }
}
