//! Where entities are *at this fixed step*.
//!
//! Bevy propagates `GlobalTransform` once per frame, in `PostUpdate`; a character moved in
//! `FixedUpdate` has a stale `GlobalTransform` in the fixed schedule (last frame's pose, the
//! same for every fixed step of a frame), and an entity spawned in `FixedUpdate` has none yet.
//! Pins, colliders and new cloths therefore read poses through [`FixedPoses`], which computes
//! the global transform from the `Transform`s up the entity's hierarchy, as they are now. Only
//! the entities the cloth needs are computed, not the whole world.

use bevy::ecs::system::SystemParam;
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

/// Global transforms as of now, in any schedule.
#[derive(SystemParam)]
pub struct FixedPoses<'w, 's> {
    helper: TransformHelper<'w, 's>,
    globals: Query<'w, 's, &'static GlobalTransform>,
}

impl FixedPoses<'_, '_> {
    /// The entity's global transform from its and its ancestors' `Transform`s now; its
    /// `GlobalTransform` component if it has no `Transform` chain; `None` if neither.
    #[must_use]
    pub fn get(&self, entity: Entity) -> Option<GlobalTransform> {
        self.helper
            .compute_global_transform(entity)
            .ok()
            .or_else(|| self.globals.get(entity).ok().copied())
    }
}
