//! The components a user puts on a cloth entity.

use bevy::ecs::component::{Component, Mutable, StorageType};
use bevy::ecs::entity::{EntityMapper, MapEntities};
use bevy::prelude::*;
use bevy::reflect::impl_reflect_opaque;

use crate::solver::{
    Aerodynamics, BendRest, BendingModel, BendingSolve, DEFAULT_TELEPORT_DISTANCE,
    MassDistribution, Sleep, Solver, SolverParams,
};

impl_reflect_opaque!((in bevy_cloth::solver) Solver(Debug, Clone, PartialEq));
impl_reflect_opaque!((in bevy_cloth::solver) BendRest(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) BendingModel(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) Aerodynamics(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) BendingSolve(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) MassDistribution(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) Sleep(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) SolverParams(Debug, Clone, PartialEq, Default, Component));

/// Marks an entity with a [`Mesh3d`] as cloth: the plugin simulates its vertices.
///
/// The mesh must be a triangle list with positions and indices (UVs give tangents and tell
/// stretch from shear edges). On the first simulation step the plugin copies the mesh into a
/// new asset owned by this cloth and points the entity's [`Mesh3d`] at it, so a mesh shared
/// with other entities is never deformed. The cloth is simulated in world space: the entity's
/// transform places the rest shape when the cloth starts and carries [`PinAnchor::Rest`] pins.
///
/// # Example
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// fn spawn(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>) {
///     let grid = Grid::new(32, 32, 1.0, 1.0);
///     commands.spawn((
///         Mesh3d(meshes.add(grid_mesh(&grid))),
///         Cloth { mass: 0.5, ..default() },
///         ClothConfig { substeps: 15, ..default() },
///         ClothPins::rest([grid.index(0, 0), grid.index(31, 0)]),
///     ));
/// }
/// # bevy::ecs::system::assert_is_system(spawn);
/// ```
///
/// Changing a `Cloth` at runtime applies to the running cloth: a new mass, mass distribution,
/// bending model or bend rest remakes its masses and constraints and it goes on from where
/// it is (a wet flag getting heavier); a new `weld_tolerance` (other particles) builds it again
/// from its mesh, starting from the rest shape. [`ClothConfig`] and [`ClothPins`] change
/// without a rebuild.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
#[require(
    // Solver settings; defaults are XPBD, 10 substeps × 1 iteration.
    ClothConfig,
    // Pins; none by default.
    ClothPins,
    // The simulation writes world positions back through the entity's transform.
    Transform,
    // Tells the layers below that this entity is a cloth.
    crate::foundation::SimulatedCloth
)]
#[component(on_add = warn_without_plugin)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Cloth {
    /// Total mass in kilograms (finite, > 0).
    pub mass: f32,
    /// How the mass is spread over the vertices.
    pub mass_distribution: MassDistribution,
    /// Rest angle of the bending constraints: flat, or the mesh's modelled folds.
    pub bend_rest: BendRest,
    /// How bending is measured: isometric (default, cheap) or the dihedral angle (used anyway
    /// for [`BendRest::RestShape`]). Both give the same material for the same compliance.
    pub bending_model: BendingModel,
    /// When a pin's anchor jumps farther than this in one step (metres), the whole cloth is
    /// moved with it instead of being dragged (a teleported character keeps its cape). The
    /// same rule, with the same default ([`DEFAULT_TELEPORT_DISTANCE`]), applies to colliders.
    pub teleport_distance: f32,
    /// Mesh vertices closer than this fraction of the mesh's bounding-box diagonal are one
    /// particle (finite, ≥ 0; 0 welds exact duplicates only). Exporters split vertices along
    /// UV seams and hard edges; welding keeps such a mesh in one piece. The copies are all
    /// written back; where their source normals agree (a UV seam) they share a smooth normal,
    /// where they differ (a hard edge) each keeps its own side's normal.
    pub weld_tolerance: f32,
}

/// Put into the app by [`ClothPlugin`](super::ClothPlugin): a [`Cloth`] added to an app without
/// it is simulated by nothing.
#[derive(Resource, Default)]
pub(crate) struct ClothPluginPresent;

/// Put into the app the first time a [`Cloth`] is added without [`ClothPlugin`](super::ClothPlugin)
/// (and said once).
#[derive(Resource, Default)]
pub(crate) struct ClothPluginMissing;

/// A `Cloth` added to a running app (one with a clock: not a scene's own world) that has no
/// `ClothPlugin` is simulated by nothing: said once, with the fix.
fn warn_without_plugin(
    mut world: bevy::ecs::world::DeferredWorld,
    ctx: bevy::ecs::lifecycle::HookContext,
) {
    if world.contains_resource::<ClothPluginPresent>()
        || world.contains_resource::<ClothPluginMissing>()
        || !world.contains_resource::<Time>()
    {
        return;
    }
    world.commands().init_resource::<ClothPluginMissing>();
    warn!(
        "a Cloth was added (entity {}) to an app without the cloth plugins, so nothing \
         simulates it; add `ClothPlugins::default()` to the app (after `DefaultPlugins`)",
        ctx.entity
    );
}

impl Cloth {
    /// Whether the mass, teleport distance and weld tolerance are within their limits (what
    /// the mesh needs is checked when the cloth is built from it).
    ///
    /// # Errors
    /// [`ClothError::BadMass`](super::ClothError::BadMass),
    /// [`BadTeleportDistance`](super::ClothError::BadTeleportDistance) or
    /// [`BadWeldTolerance`](super::ClothError::BadWeldTolerance), naming the value.
    pub fn validate(&self) -> Result<(), super::ClothError> {
        use super::ClothError;
        use crate::solver::limits;
        if !limits::MASS.contains(self.mass) {
            return Err(ClothError::BadMass(self.mass));
        }
        if !limits::TELEPORT_DISTANCE.contains(self.teleport_distance) {
            return Err(ClothError::BadTeleportDistance(self.teleport_distance));
        }
        if !limits::WELD_TOLERANCE.contains(self.weld_tolerance) {
            return Err(ClothError::BadWeldTolerance(self.weld_tolerance));
        }
        Ok(())
    }
}

impl Default for Cloth {
    /// 0.2 kg (a 1 m² cotton sheet), area-weighted, flat at rest, teleport beyond 2 m, welding
    /// copies within 1e-5 of the mesh's size.
    fn default() -> Self {
        Self {
            mass: 0.2,
            mass_distribution: MassDistribution::Area,
            bend_rest: BendRest::Flat,
            bending_model: BendingModel::Isometric,
            teleport_distance: DEFAULT_TELEPORT_DISTANCE,
            weld_tolerance: 1e-5,
        }
    }
}

/// Keeps a cloth from passing through itself (opt-in: add it to the cloth entity).
///
/// Parts of the cloth that meet are stopped at once; parts that already overlap (layers a
/// collider squeezed together, a cloth set down folded tighter than the thickness) are pushed
/// apart by at most about a third of the thickness a substep, so they come apart over a few
/// substeps instead of jumping.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothSelfCollision {
    /// Distance kept between any two vertices; `None` uses the mean rest edge length, which
    /// stops edges slipping between vertices, and on a mesh of even edges at most
    /// [`DEFAULT_SHORT_EDGE_THICKNESS`](crate::solver::DEFAULT_SHORT_EDGE_THICKNESS) short
    /// edges, so that a cloth swung hard (a running character's cape) does not fold through
    /// itself ([`Topology::default_self_collision_thickness`](crate::solver::Topology::default_self_collision_thickness)). At most
    /// [`MAX_SELF_COLLISION_EDGES`](crate::solver::MAX_SELF_COLLISION_EDGES) mean rest edge
    /// is used (more is brought down to that, with a warning): layers thicker than an edge
    /// pass through each other where the cloth crumples. For a thicker layer, a coarser mesh.
    /// On an open mesh the default is also at most half the narrowest gap across its rest
    /// shape ([`REST_GAP_THICKNESS`](crate::solver::REST_GAP_THICKNESS): a sleeve's width, the
    /// side beyond a right-angled crease), so that its layers are not held farther apart than
    /// its shape allows; a thickness set wider than half that gap
    /// ([`Topology::rest_clearance`](crate::solver::Topology::rest_clearance)) is used with a
    /// warning. On a low-poly model (tens to hundreds of vertices) the mean edge is
    /// still a large part of it, and some keep moving at a few metres a second: set about
    /// 1–2 % of the model's size (README, *Limits*).
    pub thickness: Option<f32>,
    /// Friction between touching parts of the cloth (Coulomb, 0 by default). The
    /// `self_collision` example's strip settles within three seconds at 0 and moved for about
    /// ten at 0.2 (measured before triangles took their contacts' reactions).
    pub friction: f32,
}

/// Long-range attachments: no vertex gets farther from its nearest pin than its rest distance
/// along the cloth (plus `slack`), so capes and banners do not stretch like rubber at few
/// iterations (opt-in; recommended for anything hanging from pins).
///
/// On a 64² cloth hanging from two corners at 10 substeps × 1 iteration they bring the
/// largest stretch after a second from about 200 % to 9 % for about 15 % more time a step,
/// and they let a fine cloth come to rest (and sleep) where it would otherwise keep moving.
/// They hold a stretchy material to its rest length from the pins: raise `slack` to allow
/// more.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothTethers {
    /// Allowed stretch beyond the rest distance to a pin (0.02 = 2 %).
    pub slack: f32,
    /// Pins each vertex is tethered to (its nearest ones along the cloth; at least 1).
    pub pins_per_vertex: usize,
}

impl Default for ClothTethers {
    fn default() -> Self {
        Self {
            slack: 0.0,
            pins_per_vertex: 2,
        }
    }
}

/// How much of its anchor's motion a cloth feels, for fast movers (opt-in): a cape on a
/// sprinting character, a flag on a vehicle. `1` feels all of it (world space, as without
/// this component); `0` feels none (the cloth moves rigidly with its anchor, as if glued to
/// it); in between, the rest of the motion is carried rigidly each step, so a dash stretches
/// and swings the cloth less. As Unity's world velocity scale and NvCloth's inertia
/// multipliers.
///
/// The motion not felt still moves the cloth through the air: its aerodynamics meet the air
/// less the carried motion's velocity, so a flag glued to a car (inertia 0) streams in the
/// car's airflow. [`ClothSmoothing`] draws it along that velocity too.
///
/// The anchor is `anchor`, or the cloth's own entity when `None` (a cloth parented to a
/// character). Its pose is read at each fixed step (as pins read theirs); a jump farther
/// than [`Cloth::teleport_distance`] is a teleport, not a motion, and is not carried.
/// Values outside `0..=1`, or an anchor that does not exist, are reported once
/// ([`ClothFailed`](super::ClothFailed)) and the cloth feels all of its motion until fixed.
/// Both backends: the GPU applies each step's carried motion in its `teleport` kernel.
///
/// `anchor` is mapped as Bevy maps entity references: a scene spawned twice, or a character
/// cloned with its children (`clone_and_spawn_with_opt_out(|b| { b.linked_cloning(true); })`),
/// gives each copy of the cloth its own copy of the anchor.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothInertia {
    /// Share of the anchor's linear motion felt, `0..=1`.
    pub linear: f32,
    /// Share of the anchor's rotation felt, `0..=1`.
    pub angular: f32,
    /// The entity whose motion is the reference; `None`: the cloth's own entity.
    #[entities]
    pub anchor: Option<Entity>,
}

impl Default for ClothInertia {
    /// Feels everything (the same as no component).
    fn default() -> Self {
        Self::new(1.0)
    }
}

impl ClothInertia {
    /// The same share `inertia` of linear and angular motion, relative to the cloth's own
    /// entity.
    #[must_use]
    pub fn new(inertia: f32) -> Self {
        Self {
            linear: inertia,
            angular: inertia,
            anchor: None,
        }
    }

    /// Relative to `anchor`'s motion instead of the cloth entity's.
    #[must_use]
    pub fn relative_to(self, anchor: Entity) -> Self {
        Self {
            anchor: Some(anchor),
            ..self
        }
    }

    /// Whether both shares are within `0..=1`.
    ///
    /// # Errors
    /// [`ClothError::BadInertia`](super::ClothError::BadInertia) naming them.
    pub fn validate(&self) -> Result<(), super::ClothError> {
        let ok = |v: f32| (0.0..=1.0).contains(&v);
        if ok(self.linear) && ok(self.angular) {
            Ok(())
        } else {
            Err(super::ClothError::BadInertia {
                linear: self.linear,
                angular: self.angular,
            })
        }
    }

    /// Whether the cloth feels all of its anchor's motion (both shares 1 or more: nothing to
    /// carry).
    #[must_use]
    pub fn is_world_space(&self) -> bool {
        self.linear >= 1.0 && self.angular >= 1.0
    }
}

/// Lets a cloth tear: an edge stretched past `threshold ×` its rest length breaks, its
/// triangles disappear, and a [`ClothTorn`] message says which (opt-in).
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothTearing {
    /// Stretch factor at which an edge breaks (> 1).
    pub threshold: f32,
}

impl Default for ClothTearing {
    fn default() -> Self {
        Self { threshold: 1.6 }
    }
}

/// When between fixed steps a cloth is drawn (opt-in; without it, as of the frame's last
/// step: [`ClothSmoothing::LastStep`]). The cloth steps on the fixed clock; a frame drawn
/// between two steps (a 144 Hz display, a 64 Hz fixed step) shows it where it was at the last
/// one, so a cape jumps every second or third frame while the camera glides, and a character
/// drawn interpolated between its fixed poses (avian's `PhysicsInterpolationPlugin`,
/// `bevy_transform_interpolation`) is drawn up to a step behind where its cape hangs.
///
/// `Interpolate` draws the cloth as far behind its last step as interpolated entities are
/// (`1 − overstep fraction` of the fixed step); `Extrapolate` as far ahead of it as
/// extrapolated ones (the overstep). Each vertex is placed along its velocity at the end of
/// the step, `x + s·v`: a pinned vertex moving with its anchor lands where the anchor is
/// drawn, to within the anchor's change of velocity over the shift; normals and tangents come
/// from the shifted shape. Only the drawn mesh moves (`ClothSim` reads the stepped state) and
/// nothing is stepped again. Extrapolated cloth falling onto a collider may be drawn up to a
/// step's travel into it for a frame. Both backends; no effect when the cloth plugins run
/// outside the fixed schedules ([`ClothSchedule`](crate::foundation::ClothSchedule)).
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub enum ClothSmoothing {
    /// As the last fixed step left it (the default).
    #[default]
    LastStep,
    /// Between the last two fixed steps, as interpolated entities are drawn.
    Interpolate,
    /// Past the last fixed step by the time not yet stepped, as extrapolated entities are.
    Extrapolate,
}

impl ClothSmoothing {
    /// How far along its velocity a vertex is drawn, in seconds: `step × (fraction − 1)`
    /// interpolated, `step × fraction` extrapolated, where `fraction` is the fixed clock's
    /// overstep over its step (in `0..1`). Zero for `LastStep` and for a step or fraction that
    /// is not finite and positive.
    #[must_use]
    pub fn shift(self, step: f32, fraction: f32) -> f32 {
        if !(step.is_finite() && step > 0.0 && fraction.is_finite()) {
            return 0.0;
        }
        let fraction = fraction.clamp(0.0, 1.0);
        match self {
            Self::LastStep => 0.0,
            Self::Interpolate => step * (fraction - 1.0),
            Self::Extrapolate => step * fraction,
        }
    }

    /// Where a vertex at `position` moving at `velocity` is drawn `shift` seconds from its
    /// step: `position + shift·velocity`, `w` (the inverse mass) kept. The GPU's `mesh.wgsl`
    /// computes the same (it may fuse the multiply–add: within a rounding of it).
    #[must_use]
    #[inline]
    pub fn place(position: Vec4, velocity: Vec4, shift: f32) -> Vec4 {
        (position.truncate() + velocity.truncate() * shift).extend(position.w)
    }
}

/// Sent when edges of a cloth tear.
#[derive(Message, Clone, Debug, PartialEq)]
pub struct ClothTorn {
    /// The cloth entity.
    pub cloth: Entity,
    /// Every edge that left the cloth in this step, as pairs of mesh vertex indices: those
    /// stretched past the threshold and those that lost all their triangles with them. A
    /// welded vertex is named by its first copy in the mesh.
    pub edges: Vec<[u32; 2]>,
}

/// How a cloth is solved: solver and material, substeps, iterations, gravity, damping, air,
/// sleep: the solver's own [`SolverParams`], used as a component.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// let config = ClothConfig { substeps: 15, damping: 0.3, ..default() };
/// ```
///
/// Changing it at runtime takes effect on the next step without a rebuild. An invalid value
/// (say substeps 0 while a slider passes through it) is reported once (an error log and a
/// [`ClothFailed`](crate::cloth::ClothFailed) message); the cloth keeps running with its last
/// valid settings ([`ClothSim::rejected`](crate::cloth::ClothSim::rejected) says why) and
/// takes the new ones as soon as they are valid.
pub type ClothConfig = SolverParams;

impl Component for SolverParams {
    const STORAGE_TYPE: StorageType = StorageType::Table;
    type Mutability = Mutable;
}

/// Marks a cloth that something other than the CPU plugin steps (the GPU backend, or a
/// backend of your own): the plugin still builds its [`ClothSim`](crate::cloth::ClothSim),
/// applies its settings and moves its pins every step, but neither steps it nor writes its
/// mesh. Whoever steps it hands results back through `ClothSim`'s methods
/// ([`receive_state`](crate::cloth::ClothSim::receive_state),
/// [`count_external_steps`](crate::cloth::ClothSim::count_external_steps), ...).
///
/// Not copied when the entity is cloned: the other backend's state of the cloth is not either,
/// so a copy is stepped by the CPU plugin until a backend marks it again (the GPU backend does
/// at the copy's first step when it runs there).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[component(clone_behavior = Ignore)]
pub struct ClothSteppedElsewhere;

/// Where a pinned vertex is held.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Clone, PartialEq)]
pub enum PinAnchor {
    /// At its rest position, carried by the cloth entity's own transform: move the entity and
    /// the pinned vertices follow.
    Rest,
    /// At a fixed world position.
    World(Vec3),
    /// At `offset` in another entity's local space (a cape on a character's shoulders, a flag
    /// on a moving pole). If that entity has no [`GlobalTransform`] the pin stays where it is.
    Entity {
        /// The entity carrying the pin.
        entity: Entity,
        /// Position in that entity's local space.
        offset: Vec3,
    },
    /// Where the vertex is when the pin is applied, carried from then on by another entity:
    /// the vertex keeps the offset it had from the entity at that moment, whichever way the
    /// entity was turned or scaled. The easy way to hang a cape on a character that already
    /// stands somewhere, rotated: spawn the cloth around it and attach its top row.
    Attached(Entity),
}

/// One pinned vertex.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Clone, PartialEq)]
pub struct ClothPin {
    /// Vertex index in the mesh (any copy of a welded vertex pins the particle; the first
    /// pin of a particle wins).
    pub vertex: u32,
    /// Where the vertex is held.
    pub anchor: PinAnchor,
}

/// The pinned vertices of a cloth (inverse mass 0, moved only by their anchor).
///
/// Replacing or mutating this component re-pins the cloth on the next step (the report's
/// "update anchors" button): vertices no longer listed fall free, new ones are pulled to their
/// anchors over one step. Vertices pinned before and after keep the teleport rule: if their
/// anchors jumped farther than [`Cloth::teleport_distance`], the whole cloth moves with them.
/// An invalid pin list (a vertex out of range, a non-finite anchor) is reported once and the
/// old pins are kept until the list is valid again.
///
/// The entities of [`PinAnchor::Entity`] and [`PinAnchor::Attached`] are mapped as Bevy maps
/// entity references: in a scene spawned twice each cloth is pinned to its own instance's
/// bone, and a character cloned with its children
/// (`clone_and_spawn_with_opt_out(|b| { b.linked_cloning(true); })`) gives the cloned cape
/// pins on the cloned bones. A cloth cloned on its own stays pinned to the same entities.
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq)]
#[component(map_entities)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothPins(pub Vec<ClothPin>);

impl MapEntities for ClothPins {
    fn map_entities<E: EntityMapper>(&mut self, mapper: &mut E) {
        for pin in &mut self.0 {
            match &mut pin.anchor {
                PinAnchor::Entity { entity, .. } | PinAnchor::Attached(entity) => {
                    *entity = mapper.get_mapped(*entity);
                }
                PinAnchor::Rest | PinAnchor::World(_) => {}
            }
        }
    }
}

impl ClothPins {
    /// Pins these vertices at their rest positions (following the cloth entity).
    pub fn rest(vertices: impl IntoIterator<Item = u32>) -> Self {
        Self(
            vertices
                .into_iter()
                .map(|vertex| ClothPin {
                    vertex,
                    anchor: PinAnchor::Rest,
                })
                .collect(),
        )
    }

    /// Pins these vertices to `entity` where they are when the pins are applied
    /// ([`PinAnchor::Attached`]).
    pub fn attached(vertices: impl IntoIterator<Item = u32>, entity: Entity) -> Self {
        Self(
            vertices
                .into_iter()
                .map(|vertex| ClothPin {
                    vertex,
                    anchor: PinAnchor::Attached(entity),
                })
                .collect(),
        )
    }

    /// Adds a pin.
    #[must_use]
    pub fn with(mut self, vertex: u32, anchor: PinAnchor) -> Self {
        self.0.push(ClothPin { vertex, anchor });
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Spawning a `Cloth` in an app without the plugin is said once; not in a world with no
    /// clock (a scene's own world), nor where the plugin is.
    #[test]
    fn a_cloth_in_an_app_without_the_plugin_is_named() {
        let mut scene = World::new();
        scene.spawn(Cloth::default());
        scene.flush();
        assert!(!scene.contains_resource::<ClothPluginMissing>());
        let mut bare = World::new();
        bare.init_resource::<Time>();
        bare.spawn(Cloth::default());
        bare.flush();
        assert!(bare.contains_resource::<ClothPluginMissing>());
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, super::super::ClothPlugin));
        app.world_mut().spawn(Cloth::default());
        app.world_mut().flush();
        assert!(!app.world().contains_resource::<ClothPluginMissing>());
    }
}
