//! Bevy's animation on the cloth's fixed clock (cargo feature `animation`).
//!
//! ([`ClothAnimationPlugin`] says what and why.)

use bevy::animation::{AnimationPlayer, advance_animations, animate_targets};
use bevy::app::AnimationSystems;
use bevy::prelude::*;

use bevy::ecs::schedule::InternedScheduleLabel;

use super::{ClothSchedule, ClothSystems, schedule_once};

/// Advances Bevy's animations on the cloth's fixed clock.
///
/// Bevy advances and applies animations once a frame, in `PostUpdate`, after the fixed steps of
/// that frame have run. A cloth pinned to a bone, or colliding with a capsule on a limb, would
/// then see last frame's pose in every fixed step: at 30 frames a second two steps see one
/// pose and the pins jump between frames; at 144, several frames pass between steps and the
/// cloth lags the body it hangs on. [`ClothAnimationPlugin`] moves the advance into the cloth
/// schedule instead: before [`ClothSystems::Prepare`] of every fixed step it advances every
/// [`AnimationPlayer`] by the fixed step and poses its bones, so pins and colliders read the
/// bone poses of the step they are used in, whatever the frame rate. The renderer draws the
/// pose of the frame's last step, as it draws the cloth.
///
/// In `PostUpdate` the plugin holds the players still around Bevy's own animation systems
/// (paused, then resumed), which then re-apply the same pose; transitions between animations
/// (`AnimationTransitions`) still blend per frame, and Bevy's per-frame check for animation
/// events sees only the last fixed step of a frame (events in earlier ones may be missed). Bevy prepares a new animation graph in `PostUpdate`, so an
/// animation started in a frame is applied from the first fixed step of the next frame on.
///
/// Add it beside `ClothPlugins` (and Bevy's `AnimationPlugin`, part of `DefaultPlugins`). With
/// cloth simulated once a frame instead (`ClothPlugins::new(PostUpdate)`, after Bevy's
/// animation) there is nothing to move and it does nothing.
///
/// # Example
/// ```no_run
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// App::new()
///     .add_plugins((DefaultPlugins, ClothPlugins::default(), ClothAnimationPlugin))
///     .run();
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothAnimationPlugin;

impl Plugin for ClothAnimationPlugin {
    /// Added after `ClothPlugins`, its systems go into the cloth schedule here; added
    /// before, in [`Plugin::finish`], once every plugin is built.
    fn build(&self, app: &mut App) {
        schedule_once::<Self>(app, false, schedule_advance);
    }

    fn finish(&self, app: &mut App) {
        schedule_once::<Self>(app, true, schedule_advance);
    }
}

/// Advances the animations in the cloth schedule and holds Bevy's own per-frame advance (the
/// cloth's clock is the fixed one); in a schedule that is not fixed
/// (`ClothPlugins::new(PostUpdate)`) Bevy's per-frame animation is the cloth's clock already
/// and nothing is added.
fn schedule_advance(app: &mut App, schedule: InternedScheduleLabel) {
    if !ClothSchedule(schedule).is_fixed() {
        return;
    }
    app.init_resource::<Held>()
        .add_systems(
            schedule,
            (advance_animations, animate_targets)
                .chain()
                .before(ClothSystems::Prepare),
        )
        .add_systems(PostUpdate, hold.before(AnimationSystems))
        .add_systems(
            PostUpdate,
            release
                .after(AnimationSystems)
                .before(bevy::transform::TransformSystems::Propagate),
        );
}

/// The animations [`hold`] paused this frame, to resume.
#[derive(Resource, Default)]
struct Held(Vec<(Entity, bevy::animation::graph::AnimationNodeIndex)>);

/// Pauses every playing animation before Bevy's per-frame advance (it advanced on the fixed
/// clock already).
fn hold(mut players: Query<(Entity, &mut AnimationPlayer)>, mut held: ResMut<Held>) {
    held.0.clear();
    for (entity, mut player) in &mut players {
        for (node, active) in player.playing_animations_mut() {
            if !active.is_paused() {
                active.pause();
                held.0.push((entity, *node));
            }
        }
    }
}

/// Resumes what [`hold`] paused.
fn release(mut players: Query<&mut AnimationPlayer>, mut held: ResMut<Held>) {
    for (entity, node) in held.0.drain(..) {
        if let Ok(mut player) = players.get_mut(entity)
            && let Some(active) = player.animation_mut(node)
        {
            active.resume();
        }
    }
}
