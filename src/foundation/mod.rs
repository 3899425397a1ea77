//! The foundation the cloth plugins stand on, importing nothing from them: the schedule the
//! group simulates in and its phases ([`ClothSystems`]), where entities are at the current
//! fixed step ([`FixedPoses`]), reading Bevy meshes ([`read_mesh`]) and naming entities in
//! messages ([`EntityName`]).
//!
//! Colliders, wind and cloth all order their systems by [`ClothSystems`] in the schedule
//! [`ClothFoundationPlugin`] stores in [`ClothSchedule`]; `ClothPlugins` adds it first, so
//! every plugin of the group (and the physics bridges) reads the same schedule.

#[cfg(feature = "animation")]
mod animation;
mod mesh;
mod pose;
mod workers;

#[cfg(feature = "animation")]
pub use animation::ClothAnimationPlugin;

pub use mesh::{MeshData, MeshError, grid_mesh, read_mesh, strip_triangles, try_grid_mesh};
pub(crate) use mesh::{finite_bounds, mesh_fingerprint, modified_meshes};
pub use pose::FixedPoses;
pub use workers::{ClothWorkers, TaskPoolParallel};

use bevy::asset::AssetEventSystems;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::prelude::*;
use bevy::transform::TransformSystems;

/// Marks an entity whose mesh is simulated as cloth. [`Cloth`](crate::cloth::Cloth) requires
/// it (and removing `Cloth` removes it), so that the layers below the cloth's own can tell a
/// cloth's entity apart: a mesh [`ClothCollider`](crate::collider::ClothCollider) taking its
/// mesh from the entity's `Mesh3d` is refused on a cloth (that mesh is the cloth itself).
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SimulatedCloth;

/// The phases of cloth simulation, in order.
///
/// 1. `Prepare` ([`ClothSchedule`], `FixedPostUpdate` by default): create simulations for
///    new cloths, apply changed configs and pins, move pins to their anchors, gather the
///    colliders and the wind of this step.
/// 2. `Simulate` (the same schedule): step every cloth by the schedule's time step.
/// 3. `Writeback` ([`PostUpdate`], after transform propagation and before Bevy's asset events,
///    so the renderer draws the new shape in the same frame): write positions, normals and
///    tangents of cloths that moved into their meshes, once per rendered frame.
///
/// With `ClothPlugins::new(PostUpdate)` the first two run once a frame in `PostUpdate`, after
/// Bevy's animation and before `Writeback`.
///
/// Order your own systems against these, e.g. move a pin anchor `.before(ClothSystems::Prepare)`
/// or read results `.after(ClothSystems::Simulate)` in the same schedule.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ClothSystems {
    /// Create and configure simulations; gather colliders and wind.
    Prepare,
    /// Step the solver.
    Simulate,
    /// Copy results into meshes.
    Writeback,
}

/// The schedule every cloth plugin simulates in (a resource, set by [`ClothFoundationPlugin`]
/// from `ClothPlugins::new(schedule)`; `FixedPostUpdate` by default).
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClothSchedule(pub InternedScheduleLabel);

impl ClothSchedule {
    /// The schedule of `app`'s cloth plugins: the [`ClothSchedule`] resource if a
    /// [`ClothFoundationPlugin`] put one there; otherwise it adds that plugin with the default
    /// schedule (a plugin of the group used on its own).
    pub fn of(app: &mut App) -> InternedScheduleLabel {
        if !app.world().contains_resource::<ClothSchedule>() {
            app.add_plugins(ClothFoundationPlugin::default());
        }
        app.world().resource::<ClothSchedule>().0
    }
}

impl ClothSchedule {
    /// Whether the schedule runs on the fixed clock (one of Bevy's `Fixed…` schedules).
    #[must_use]
    pub fn is_fixed(&self) -> bool {
        [
            bevy::app::FixedMain.intern(),
            FixedFirst.intern(),
            FixedPreUpdate.intern(),
            FixedUpdate.intern(),
            FixedPostUpdate.intern(),
            FixedLast.intern(),
        ]
        .contains(&self.0)
    }

    /// The fixed step's length and the frame's overstep over it (`0..1`: how far the frame
    /// is past the last fixed step), for drawing cloth between fixed steps; `None` when the
    /// schedule is not a fixed one, or without a fixed clock.
    #[must_use]
    pub fn overstep(schedule: Option<&Self>, fixed: Option<&Time<Fixed>>) -> Option<(f32, f32)> {
        let fixed = fixed?;
        let on_fixed = schedule.is_none_or(Self::is_fixed);
        on_fixed.then(|| (fixed.timestep().as_secs_f32(), fixed.overstep_fraction()))
    }
}

/// Sets up what every cloth plugin shares: the [`ClothSchedule`] resource and the order of the
/// [`ClothSystems`] phases. The first plugin of `ClothPlugins`.
#[derive(Clone, Copy, Debug)]
pub struct ClothFoundationPlugin {
    /// The schedule cloth is simulated in (a fixed-timestep schedule keeps results frame-rate
    /// independent).
    pub schedule: InternedScheduleLabel,
}

impl ClothFoundationPlugin {
    /// Simulates in `schedule`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for ClothFoundationPlugin {
    fn default() -> Self {
        Self::new(FixedPostUpdate)
    }
}

impl Plugin for ClothFoundationPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(ClothSchedule(self.schedule))
            .configure_sets(
                self.schedule,
                (ClothSystems::Prepare, ClothSystems::Simulate).chain(),
            )
            .configure_sets(
                PostUpdate,
                ClothSystems::Writeback
                    .after(TransformSystems::Propagate)
                    .before(AssetEventSystems),
            );
        if self.schedule == PostUpdate.intern() {
            // Simulated once a frame in PostUpdate (for characters a game moves in `Update`):
            // after this frame's animation poses the bones, and stepped before its write-back.
            app.configure_sets(
                PostUpdate,
                (ClothSystems::Prepare, ClothSystems::Simulate)
                    .after(bevy::app::AnimationSystems)
                    .before(ClothSystems::Writeback),
            );
        }
    }
}

/// Present once the plugin marked `P` has its systems in the cloth schedule.
#[cfg(any(feature = "avian", feature = "rapier", feature = "animation"))]
#[derive(Resource)]
struct Scheduled<P>(core::marker::PhantomData<fn() -> P>);

/// Adds a plugin's systems (`add`) to the cloth schedule once, whichever of it and
/// `ClothPlugins` was added first: from the plugin's `build` when the [`ClothSchedule`] is
/// known (`ClothPlugins` came first), otherwise from its `finish` (`in_finish`), once every
/// plugin is built. For plugins outside the group (the physics bridges, animation).
#[cfg(any(feature = "avian", feature = "rapier", feature = "animation"))]
pub(crate) fn schedule_once<P: 'static>(
    app: &mut App,
    in_finish: bool,
    add: fn(&mut App, InternedScheduleLabel),
) {
    if app.world().contains_resource::<Scheduled<P>>()
        || (!in_finish && !app.world().contains_resource::<ClothSchedule>())
    {
        return;
    }
    let schedule = ClothSchedule::of(app);
    app.insert_resource(Scheduled::<P>(core::marker::PhantomData));
    add(app, schedule);
}

/// An entity as messages name it: `"Cape" (12v0)` when it has a [`Name`], `12v0` otherwise.
#[derive(Clone, Copy, Debug)]
pub struct EntityName<'a> {
    /// The entity.
    pub entity: Entity,
    /// Its name, if it has one.
    pub name: Option<&'a Name>,
}

impl<'a> EntityName<'a> {
    /// `entity` with `name`.
    #[must_use]
    pub fn new(entity: Entity, name: Option<&'a Name>) -> Self {
        Self { entity, name }
    }

    /// `entity` with its name in `world`, if it has one.
    #[must_use]
    pub fn in_world(world: &'a World, entity: Entity) -> Self {
        Self::new(entity, world.get::<Name>(entity))
    }
}

impl core::fmt::Display for EntityName<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.name {
            Some(name) => write!(f, "{:?} ({})", name.as_str(), self.entity),
            None => write!(f, "{}", self.entity),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_read_well_in_messages() {
        let e = Entity::from_raw_u32(12).unwrap();
        let name = Name::new("Cape");
        assert_eq!(
            EntityName::new(e, Some(&name)).to_string(),
            format!("\"Cape\" ({e})")
        );
        assert_eq!(EntityName::new(e, None).to_string(), e.to_string());
    }
}
