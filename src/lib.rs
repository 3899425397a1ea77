//! Cloth simulation for Bevy: Position Based Dynamics on the CPU, as a plugin.
//!
//! Add [`ClothPlugins`](cloth::ClothPlugins), put a [`Cloth`](cloth::Cloth) on an entity with a
//! [`Mesh3d`](bevy::prelude::Mesh3d), pin a few vertices, and the mesh hangs, swings and folds.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_cloth::prelude::*;
//!
//! fn main() {
//!     App::new()
//!         .add_plugins((DefaultPlugins, ClothPlugins::default()))
//!         .add_systems(Startup, setup)
//!         .run();
//! }
//!
//! fn setup(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>) {
//!     let grid = Grid::new(32, 32, 1.0, 1.0);
//!     commands.spawn((
//!         Mesh3d(meshes.add(grid_mesh(&grid))),
//!         Cloth::default(),
//!         ClothPins::rest([grid.index(0, 0), grid.index(31, 0)]),
//!     ));
//! }
//! ```
//!
//! # Modules
//! - [`solver`]: the pure solver (no Bevy): topology, constraints, collisions, wind, tearing,
//!   the step, shading data.
//! - [`cloth`]: components, plugin and systems.
//! - [`collider`]: shapes cloth collides with; with the `rapier` feature, the bevy_rapier3d
//!   bridge and two-way coupling.
//! - [`wind`]: global and local wind.
//! - [`gpu`]: the GPU backend: the step as WGSL compute kernels in the render graph.
//! - [`render`]: the velvet material (two-sided, report §3.4) and its CPU reference BRDF.
//!
//! # Headless
//! A [`MinimalPlugins`](bevy::prelude::MinimalPlugins) app simulates cloth with no window and
//! no GPU; add `TransformPlugin`, `AssetPlugin` and `MeshPlugin` for transforms and meshes.
//! See the README and `tests/headless.rs`.

pub mod cloth;
pub mod collider;
pub mod editor;
pub mod gpu;
pub mod render;
pub mod solver;
pub mod wind;

/// The types most apps need.
pub mod prelude {
    pub use crate::cloth::{
        Cloth, ClothConfig, ClothError, ClothFailed, ClothInvalid, ClothPick, ClothPin, ClothPins,
        ClothPlugin, ClothPlugins, ClothSelfCollision, ClothSim, ClothSystems, ClothTearing,
        ClothTethers, ClothTorn, PinAnchor, grid_mesh,
    };
    #[cfg(feature = "rapier")]
    pub use crate::collider::rapier::ClothRapierPlugin;
    pub use crate::collider::{ClothCollider, ClothContactImpulse, ColliderShape};
    #[cfg(feature = "editor")]
    pub use crate::editor::ClothEditorPlugin;
    pub use crate::editor::{ClothCameraPlugin, ClothFlyCamera};
    pub use crate::gpu::{ClothBackend, ClothBackendInUse, ClothGpuPlugin, ClothReadback};
    pub use crate::render::{
        VelvetExtension, VelvetMaterial, VelvetPlugin, lined_velvet, velvet_material,
        velvet_material_from,
    };
    pub use crate::solver::{
        Aerodynamics, BendRest, BendingModel, BendingSolve, Grid, MassDistribution, Sleep, Solver,
        WindParams,
    };
    pub use crate::wind::{Wind, WindZone};
}

/// The README's code blocks, compiled as doc tests so they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
