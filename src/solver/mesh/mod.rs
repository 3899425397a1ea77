//! Meshes and topology: a triangle mesh (or a [`Grid`]) turned into the edges, hinges and
//! triangles the constraints act on ([`Topology`]), the user's vertices welded onto particles
//! ([`MeshBinding`]), hinge geometry measured from the rest shape, and the normals and tangents
//! drawn from the simulated positions.

mod grid;
pub(crate) mod hinge;
mod shading;
mod topology;
mod weld;

pub use grid::Grid;
pub use hinge::{bend_angle, dihedral_angle, dihedral_weight, hinge_coefficients, hinge_curvature};
pub use shading::MeshShading;
pub use topology::{
    Bend, BendRest, BendingModel, Edge, EdgeKind, MassDistribution, Topology, TopologyError,
    TopologyOptions,
};
pub use weld::{HARD_EDGE_COS, MeshAttributes, MeshBinding, Weld};
