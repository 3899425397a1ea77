//! [`ClothPlugin`], the [`ClothPlugins`] group and the public [`ClothSystems`] sets.

use bevy::app::PluginGroupBuilder;
use bevy::asset::AssetEventSystems;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::prelude::*;
use bevy::transform::TransformSystems;

use super::sim::{
    ClothFailed, ClothWorkers, init_cloths, on_cloth_removed, retry_cloths, step_cloths,
    sync_cloths,
};
use super::writeback::write_back;
use super::{
    Cloth, ClothConfig, ClothPin, ClothPins, ClothSelfCollision, ClothTearing, ClothTethers,
    ClothTorn, PinAnchor,
};
use crate::collider::ClothColliderPlugin;
use crate::gpu::ClothGpuPlugin;
use crate::wind::ClothWindPlugin;

/// The phases of cloth simulation, in order.
///
/// 1. `Prepare` (simulation schedule): create simulations for new cloths, apply changed
///    configs and pins, move pins to their anchors.
/// 2. `Simulate` (simulation schedule): step every cloth by the schedule's time step.
/// 3. `Writeback` ([`PostUpdate`], after transform propagation and before Bevy's asset events,
///    so the renderer draws the new shape in the same frame): write positions, normals and
///    tangents of cloths that moved into their meshes, once per rendered frame.
///
/// Order your own systems against these, e.g. move a pin anchor `.before(ClothSystems::Prepare)`.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ClothSystems {
    /// Create and configure simulations.
    Prepare,
    /// Step the solver.
    Simulate,
    /// Copy results into meshes.
    Writeback,
}

/// Simulates every [`Cloth`] entity on the CPU.
///
/// Runs in a fixed-timestep schedule ([`FixedPostUpdate`] by default), so a dropped frame
/// changes how many steps run, never their length: the result does not depend on the frame
/// rate. Set the rate with `Time::<Fixed>::from_hz(..)`.
pub struct ClothPlugin {
    schedule: InternedScheduleLabel,
}

impl ClothPlugin {
    /// Simulates in `schedule` (a fixed-timestep schedule keeps results frame-rate independent).
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for ClothPlugin {
    fn default() -> Self {
        Self::new(FixedPostUpdate)
    }
}

impl Plugin for ClothPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<Cloth>()
            .register_type::<ClothConfig>()
            .register_type::<ClothPins>()
            .register_type::<ClothPin>()
            .register_type::<PinAnchor>()
            .register_type::<ClothSelfCollision>()
            .register_type::<ClothTethers>()
            .register_type::<ClothTearing>()
            .init_resource::<ClothWorkers>()
            .add_message::<ClothTorn>()
            .add_message::<ClothFailed>()
            .configure_sets(
                self.schedule,
                (ClothSystems::Prepare, ClothSystems::Simulate).chain(),
            )
            .configure_sets(
                PostUpdate,
                ClothSystems::Writeback
                    .after(TransformSystems::Propagate)
                    .before(AssetEventSystems),
            )
            .add_observer(on_cloth_removed)
            .add_systems(
                self.schedule,
                (
                    (retry_cloths, init_cloths, sync_cloths)
                        .chain()
                        .in_set(ClothSystems::Prepare),
                    step_cloths.in_set(ClothSystems::Simulate),
                ),
            )
            .add_systems(PostUpdate, write_back.in_set(ClothSystems::Writeback));
    }

    fn finish(&self, app: &mut App) {
        if !app.world().contains_resource::<Assets<Mesh>>() {
            warn!(
                "ClothPlugin: no Assets<Mesh> resource; add MeshPlugin (part of DefaultPlugins) \
                 and AssetPlugin, or no cloth will be simulated"
            );
        }
    }
}

/// All cloth plugins.
///
/// | plugin | what it does |
/// |---|---|
/// | [`ClothPlugin`] | creates, steps and writes back every [`Cloth`] on the CPU |
/// | [`ClothColliderPlugin`] | [`ClothCollider`](crate::collider::ClothCollider)s: shapes, mesh SDFs, contact impulses |
/// | [`ClothWindPlugin`] | the [`Wind`](crate::wind::Wind) resource and [`WindZone`](crate::wind::WindZone)s |
/// | [`ClothGpuPlugin`] | cloths that ask for it ([`ClothBackend`](crate::gpu::ClothBackend)) stepped by GPU kernels in the render graph |
///
/// The rapier bridge (`ClothRapierPlugin`, cargo feature `rapier`) is not in the group: add it
/// to opt in.
///
/// Replace a part with `ClothPlugins::default().build().disable::<X>().add(Custom)`; simulate
/// in another schedule with [`ClothPlugins::new`].
pub struct ClothPlugins {
    schedule: InternedScheduleLabel,
}

impl ClothPlugins {
    /// Cloth plugins simulating in `schedule`.
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
            .add(ClothPlugin {
                schedule: self.schedule,
            })
            .add(ClothColliderPlugin {
                schedule: self.schedule,
            })
            .add(ClothWindPlugin {
                schedule: self.schedule,
            })
            .add(ClothGpuPlugin::default())
    }
}
