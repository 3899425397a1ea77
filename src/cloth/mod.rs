//! The Bevy side of a cloth: components, plugin, systems, mesh write-back.
//!
//! Data flow: a [`Cloth`] entity's [`Mesh3d`](bevy::prelude::Mesh3d) is read once, its
//! vertices welded into particles ([`MeshBinding`](crate::solver::MeshBinding)), into a solver
//! [`Simulation`](crate::solver::Simulation), stored in a [`ClothSim`] component. Each fixed
//! step ([`ClothSystems::Prepare`], [`ClothSystems::Simulate`]) applies config and pin changes,
//! moves pins to their anchors (poses as of this step, [`FixedPoses`]) and steps the solver;
//! each frame [`ClothSystems::Writeback`] copies positions, normals and tangents into every
//! vertex of the cloth's own mesh asset.

mod components;
mod mesh;
mod plugin;
mod pose;
pub(crate) mod sim;
pub(crate) mod writeback;

pub use components::{
    Cloth, ClothConfig, ClothPin, ClothPins, ClothSelfCollision, ClothTearing, ClothTethers,
    ClothTorn, DEFAULT_TELEPORT_DISTANCE, PinAnchor,
};
pub use mesh::{MeshData, grid_mesh, read_mesh};
pub use plugin::{ClothPlugin, ClothPlugins, ClothSystems};
pub use pose::FixedPoses;
pub use sim::{
    ClothError, ClothFailed, ClothInvalid, ClothPick, ClothSim, ClothSource, ClothWorkers,
    TaskPoolParallel,
};
