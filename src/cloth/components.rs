//! The components a user puts on a cloth entity.

use bevy::prelude::*;
use bevy::reflect::impl_reflect_opaque;

use crate::solver::{BendRest, MassDistribution, Solver, SolverParams};

impl_reflect_opaque!((in bevy_cloth::solver) Solver(Debug, Clone, PartialEq));
impl_reflect_opaque!((in bevy_cloth::solver) BendRest(Debug, Clone, PartialEq, Default));
impl_reflect_opaque!((in bevy_cloth::solver) MassDistribution(Debug, Clone, PartialEq, Default));

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
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
#[require(
    // Solver settings; defaults are XPBD, 10 substeps × 1 iteration.
    ClothConfig,
    // Pins; none by default.
    ClothPins,
    // The simulation writes world positions back through the entity's transform.
    Transform
)]
pub struct Cloth {
    /// Total mass in kilograms (finite, > 0).
    pub mass: f32,
    /// How the mass is spread over the vertices.
    pub mass_distribution: MassDistribution,
    /// Rest angle of the bending constraints: flat, or the mesh's modelled folds.
    pub bend_rest: BendRest,
}

impl Default for Cloth {
    /// 0.2 kg (a 1 m² cotton sheet), area-weighted, flat at rest.
    fn default() -> Self {
        Self {
            mass: 0.2,
            mass_distribution: MassDistribution::Area,
            bend_rest: BendRest::Flat,
        }
    }
}

/// How a cloth is solved: solver and material, substeps, iterations, gravity, damping.
///
/// Changing it at runtime takes effect on the next step without a rebuild.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothConfig {
    /// Solver and its stiffnesses or compliances.
    pub solver: Solver,
    /// Substeps per fixed step.
    pub substeps: u32,
    /// Constraint iterations per substep.
    pub iterations: u32,
    /// Gravity in m/s².
    pub gravity: Vec3,
    /// Linear velocity damping in 1/s (not used by the lab solver).
    pub damping: f32,
}

impl Default for ClothConfig {
    fn default() -> Self {
        SolverParams::default().into()
    }
}

impl From<SolverParams> for ClothConfig {
    fn from(p: SolverParams) -> Self {
        Self {
            solver: p.solver,
            substeps: p.substeps,
            iterations: p.iterations,
            gravity: p.gravity,
            damping: p.damping,
        }
    }
}

impl From<ClothConfig> for SolverParams {
    fn from(c: ClothConfig) -> Self {
        Self {
            solver: c.solver,
            substeps: c.substeps,
            iterations: c.iterations,
            gravity: c.gravity,
            damping: c.damping,
        }
    }
}

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
}

/// One pinned vertex.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Clone, PartialEq)]
pub struct ClothPin {
    /// Vertex index in the mesh.
    pub vertex: u32,
    /// Where the vertex is held.
    pub anchor: PinAnchor,
}

/// The pinned vertices of a cloth (inverse mass 0, moved only by their anchor).
///
/// Replacing or mutating this component re-pins the cloth on the next step (the report's
/// "update anchors" button): vertices no longer listed fall free, new ones are pulled to their
/// anchors over one step.
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothPins(pub Vec<ClothPin>);

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

    /// Adds a pin.
    #[must_use]
    pub fn with(mut self, vertex: u32, anchor: PinAnchor) -> Self {
        self.0.push(ClothPin { vertex, anchor });
        self
    }
}
