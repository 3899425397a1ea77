//! The teleport rule: a pin's anchor or a collider that jumps farther than a limit in one step
//! has teleported, it did not move there.
//!
//! A cloth whose pins teleport goes with them, whole, instead of being dragged across the
//! world by its pinned corners (a character stepping through a portal keeps its cape); a
//! collider that teleports appears at its new place instead of sweeping through every cloth
//! on the way. The plugin decides with [`teleport_offset`] and [`is_teleport`] and moves the
//! cloth with [`ClothState::teleport`]; the GPU's `teleport` kernel
//! (`gpu/shaders/step_begin.wgsl`) is the twin of that last one.

use glam::Vec3;

use super::state::ClothState;

/// Default teleport distance of pins and colliders: a jump of more than 2 m in one fixed step
/// is a teleport, not a motion.
pub const DEFAULT_TELEPORT_DISTANCE: f32 = 2.0;

/// Whether going from `from` to `to` in one step is a teleport: a jump farther than `limit`.
#[inline]
#[must_use]
pub fn is_teleport(from: Vec3, to: Vec3, limit: f32) -> bool {
    from.distance(to) > limit
}

/// How far a whole cloth jumps when its pins' anchors move by `moves` (`(from, to)` of each
/// pin that was pinned before and after): the mean of the jumps that are teleports, `None`
/// when no pin teleported.
#[must_use]
pub fn teleport_offset(moves: impl IntoIterator<Item = (Vec3, Vec3)>, limit: f32) -> Option<Vec3> {
    let (sum, count) = moves
        .into_iter()
        .filter(|&(from, to)| is_teleport(from, to, limit))
        .fold((Vec3::ZERO, 0u32), |(s, n), (from, to)| {
            (s + (to - from), n + 1)
        });
    (count > 0).then(|| sum / count as f32)
}

impl ClothState {
    /// Teleports the cloth: every vertex moves by `offset` (velocities kept), then the pins
    /// take `targets` (in the order of [`Self::pins`]) and their vertices land on them at rest.
    pub fn teleport(&mut self, offset: Vec3, targets: impl IntoIterator<Item = Vec3>) {
        self.translate(offset);
        self.set_pin_targets(targets);
        self.snap_pins();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_jumps_past_the_limit_count_and_they_are_averaged() {
        assert_eq!(teleport_offset([(Vec3::ZERO, Vec3::X)], 2.0), None);
        let moves = [
            (Vec3::ZERO, Vec3::new(3.0, 0.0, 0.0)),
            (Vec3::ZERO, Vec3::new(0.0, 5.0, 0.0)),
            (Vec3::ZERO, Vec3::new(0.0, 0.0, 1.0)), // a step, not a jump: left out
        ];
        assert_eq!(teleport_offset(moves, 2.0), Some(Vec3::new(1.5, 2.5, 0.0)));
        assert!(!is_teleport(Vec3::ZERO, Vec3::X, f32::INFINITY));
        assert!(is_teleport(Vec3::ZERO, Vec3::X, 0.5));
    }
}
