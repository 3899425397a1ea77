//! Cloth simulation for Bevy: Position Based Dynamics on the CPU, or on the GPU as compute
//! passes in Bevy's render graph, as a group of plugins.
//!
//! Add [`ClothPlugins`], put a [`Cloth`](cloth::Cloth) on an entity with a
//! [`Mesh3d`], pin a few vertices, and the mesh hangs, swings and folds:
//! flags, capes, curtains and banners, with colliders (shapes, meshes, rapier and avian bodies, the
//! cloth itself), wind, tearing and a two-sided velvet material.
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
//! A mesh whose vertex indices the game does not know (a glTF cape, Bevy's `Plane3d`) is
//! pinned by a [`ClothPinRule`](cloth::ClothPinRule) instead: its top edge, the vertices in a
//! box, or those painted in its vertex colours.
//!
//! # Modules, bottom to top
//! Each imports only from those listed before it (`tests/layers.rs` checks it).
//! - [`solver`]: the pure solver (no Bevy): topology, constraints, collisions, wind, tearing,
//!   the step, shading data.
//! - [`foundation`]: what every plugin shares: the schedule and [`ClothSystems`](foundation::ClothSystems)
//!   phases, poses at the fixed step, mesh reading.
//! - [`collider`]: shapes cloth collides with; with the `rapier` and `avian` features, the
//!   bevy_rapier3d and avian3d bridges and two-way coupling. [`wind`]: global and local wind. [`render`]: the velvet
//!   material (two-sided) and its CPU reference BRDF.
//! - [`cloth`]: components, the CPU plugin and its systems, mesh write-back.
//! - [`gpu`]: the GPU backend: the step as WGSL compute kernels in the render graph.
//! - [`editor`]: the fly camera, and with the `editor` feature the in-app editor.
//! - [`ClothPlugins`], here, puts the plugins together.
//!
//! # Headless
//! A [`MinimalPlugins`] app simulates cloth with no window and
//! no GPU; add `TransformPlugin`, `AssetPlugin` and `MeshPlugin` for transforms and meshes.
//! See the README and `tests/headless.rs`.

pub mod cloth;
pub mod collider;
pub mod editor;
pub mod foundation;
pub mod gpu;
pub mod render;
pub mod solver;
pub mod wind;

use bevy::app::PluginGroupBuilder;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::prelude::*;

use cloth::ClothPlugin;
use collider::ClothColliderPlugin;
use foundation::ClothFoundationPlugin;
use gpu::ClothGpuPlugin;
use wind::ClothWindPlugin;

/// All cloth plugins, simulating in one schedule.
///
/// | plugin | what it does |
/// |---|---|
/// | [`ClothFoundationPlugin`] | the schedule ([`ClothSchedule`](foundation::ClothSchedule)) and the order of the [`ClothSystems`](foundation::ClothSystems) phases |
/// | [`ClothColliderPlugin`] | [`ClothCollider`](collider::ClothCollider)s: shapes, mesh SDFs, contact impulses |
/// | [`ClothWindPlugin`] | the [`Wind`](wind::Wind) resource and [`WindZone`](wind::WindZone)s |
/// | [`ClothPlugin`] | creates, steps and writes back every [`Cloth`](cloth::Cloth) on the CPU |
/// | [`ClothGpuPlugin`] | cloths that ask for it ([`ClothBackend`](gpu::ClothBackend)) stepped by GPU kernels in the render graph |
///
/// The physics-engine bridges (`ClothRapierPlugin`, cargo feature `rapier`; `ClothAvianPlugin`,
/// cargo feature `avian`) are not in the group: add one (or both) to opt in; they run in the
/// group's schedule.
///
/// Replace a part with `ClothPlugins::default().build().disable::<X>().add(Custom)`; simulate
/// in another schedule with [`ClothPlugins::new`].
#[derive(Clone, Copy, Debug)]
pub struct ClothPlugins {
    schedule: InternedScheduleLabel,
}

impl ClothPlugins {
    /// Cloth plugins simulating in `schedule` (a fixed-timestep schedule keeps results
    /// frame-rate independent; `PostUpdate` steps once a frame after `Update`, so that a
    /// character a game moves in `Update` wears its cloth in the same frame).
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for ClothPlugins {
    fn default() -> Self {
        Self::new(FixedPostUpdate)
    }
}

impl PluginGroup for ClothPlugins {
    fn build(self) -> PluginGroupBuilder {
        PluginGroupBuilder::start::<Self>()
            .add(ClothFoundationPlugin {
                schedule: self.schedule,
            })
            .add(ClothColliderPlugin)
            .add(ClothWindPlugin)
            .add(ClothPlugin)
            .add(ClothGpuPlugin::default())
    }
}

/// The types most apps need.
pub mod prelude {
    pub use crate::ClothPlugins;
    pub use crate::cloth::{
        Cloth, ClothBackstop, ClothConfig, ClothError, ClothFailed, ClothInertia, ClothInvalid,
        ClothPick, ClothPin, ClothPinRule, ClothPins, ClothPlugin, ClothSelfCollision, ClothSim,
        ClothSkinning, ClothSmoothing, ClothTearing, ClothTethers, ClothTorn, ColorChannel,
        MaxDistance, PinAnchor, VertexSelection,
    };
    #[cfg(feature = "avian")]
    pub use crate::collider::avian::ClothAvianPlugin;
    #[cfg(feature = "rapier")]
    pub use crate::collider::rapier::ClothRapierPlugin;
    pub use crate::collider::{ClothCollider, ClothContactImpulse, ColliderMesh, ColliderShape};
    #[cfg(feature = "editor")]
    pub use crate::editor::ClothEditorPlugin;
    pub use crate::editor::{ClothCameraPlugin, ClothFlyCamera};
    #[cfg(feature = "animation")]
    pub use crate::foundation::ClothAnimationPlugin;
    pub use crate::foundation::{ClothSystems, grid_mesh, try_grid_mesh};
    pub use crate::gpu::{ClothBackend, ClothBackendInUse, ClothGpuPlugin, ClothReadback};
    pub use crate::render::{
        VelvetExtension, VelvetMaterial, VelvetPlugin, lined_velvet, velvet_material,
        velvet_material_from,
    };
    pub use crate::solver::{
        Aerodynamics, BendRest, BendingModel, BendingSolve, Grid, MassDistribution, Sleep, Solver,
        SolverParams, WindParams,
    };
    pub use crate::wind::{Wind, WindZone};
}

/// The README's code blocks, compiled as doc tests so they cannot go stale.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
