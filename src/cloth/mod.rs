//! The Bevy side of a cloth: components, the CPU plugin, its systems, mesh write-back.
//!
//! Data flow: a [`Cloth`] entity's [`Mesh3d`](bevy::prelude::Mesh3d) is read once, its
//! vertices welded into particles ([`MeshBinding`](crate::solver::MeshBinding)), into a solver
//! [`Simulation`](crate::solver::Simulation), stored in a [`ClothSim`] component. Each fixed
//! step ([`ClothSystems::Prepare`](crate::foundation::ClothSystems),
//! [`ClothSystems::Simulate`](crate::foundation::ClothSystems)) applies config and pin changes,
//! moves pins to their anchors (poses as of this step,
//! [`FixedPoses`](crate::foundation::FixedPoses)), gathers the colliders and wind below it and
//! steps the solver; each frame `ClothSystems::Writeback` copies positions, normals and tangents
//! into every vertex of the cloth's own mesh asset. A cloth marked [`ClothSteppedElsewhere`]
//! (the GPU backend marks its cloths) is built and kept in sync but not stepped or written here.

mod build;
mod components;
mod error;
mod inertia;
mod material;
mod mesh;
mod pin_rule;
mod pins;
mod plugin;
mod sim;
mod skinning;
mod systems;
mod writeback;

pub use crate::foundation::{ClothWorkers, TaskPoolParallel};
pub use build::{ClothParts, check_cloth};
pub use components::{
    Cloth, ClothConfig, ClothInertia, ClothPin, ClothPins, ClothSelfCollision, ClothSmoothing,
    ClothSteppedElsewhere, ClothTearing, ClothTethers, ClothTorn, PinAnchor,
};
pub use error::{ClothError, ClothFailed, ClothInvalid};
pub use pin_rule::{ClothPinRule, ColorChannel, PinRuleError, VertexSelection};
pub use plugin::ClothPlugin;
pub use sim::{ClothPick, ClothSim, ClothSource, OVERSTRETCH, OVERSTRETCH_SECONDS};
pub use skinning::{ClothBackstop, ClothSkinning, MaxDistance};
