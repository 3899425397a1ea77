//! Axis arrows: drag the selected object along world X, Y or Z only.
//!
//! The arrows are drawn by the panel (three lines from the object's origin, a fixed fraction
//! of its distance to the camera long, so they keep their size on screen). Pressing on one
//! starts an [`AxisDrag`]; while the button is held the object's translation follows the
//! point of the axis line nearest the pointer's ray ([`axis_parameter`]); nothing but that
//! one coordinate changes.
//!
//! `transform-gizmo-bevy` 0.11, the crate that does axis gizmos for Bevy 0.19, needs Rust
//! 1.96 (its core crate says `rust-version = "1.96.0"`); this project builds with 1.95, so the
//! arrows are ours (see ARCHITECTURE.md).

use bevy::math::Ray3d;
use bevy::prelude::*;

/// The three world axes, in arrow order (X red, Y green, Z blue).
pub const AXES: [Vec3; 3] = [Vec3::X, Vec3::Y, Vec3::Z];

/// Arrow length as a fraction of the distance from the camera to the object.
pub const ARROW_SCALE: f32 = 0.18;

/// Farthest a single drag may move an object, metres (a ray almost parallel to the axis
/// would otherwise fling it to infinity).
pub const MAX_DRAG: f32 = 1.0e3;

/// The parameter `s` of the point `origin + s·axis` nearest the ray (the closest points of
/// two lines), or `None` when the ray is parallel to the axis or anything is not finite.
#[must_use]
pub fn axis_parameter(ray: Ray3d, origin: Vec3, axis: Vec3) -> Option<f32> {
    let d = *ray.direction;
    let w0 = origin - ray.origin;
    let a = axis.length_squared();
    let b = axis.dot(d);
    let c = d.length_squared();
    let dd = axis.dot(w0);
    let e = d.dot(w0);
    let denom = a * c - b * b;
    // Lines within about half a degree of parallel: the nearest point is ill-defined.
    let parallel = denom.is_nan() || denom <= 1e-4 * a * c;
    if parallel {
        return None;
    }
    let s = (b * e - c * dd) / denom;
    s.is_finite().then_some(s)
}

/// A drag along one axis, from the press to the release.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisDrag {
    /// The entity moved.
    pub entity: Entity,
    /// Which axis (0 = X, 1 = Y, 2 = Z).
    pub axis: usize,
    /// World position of the entity's origin when the drag started.
    pub start: Vec3,
    /// Axis parameter under the pointer when the drag started.
    pub grab: f32,
}

impl AxisDrag {
    /// Starts dragging `entity` (at world position `origin`) along `axis` from where `ray`
    /// meets it; `None` when the ray runs along the axis.
    #[must_use]
    pub fn begin(entity: Entity, axis: usize, origin: Vec3, ray: Ray3d) -> Option<Self> {
        let grab = axis_parameter(ray, origin, AXES[axis])?;
        Some(Self {
            entity,
            axis,
            start: origin,
            grab,
        })
    }

    /// Where the entity's origin should be with the pointer's ray now: moved from the start
    /// along the axis only, by at most [`MAX_DRAG`]. `None` keeps it where it is.
    #[must_use]
    pub fn target(&self, ray: Ray3d) -> Option<Vec3> {
        let axis = AXES[self.axis];
        let s = axis_parameter(ray, self.start, axis)?;
        let shift = (s - self.grab).clamp(-MAX_DRAG, MAX_DRAG);
        Some(self.start + axis * shift)
    }
}

/// Moves `entity`'s [`Transform`] so that its world origin is at `world` (through its
/// parent's transform, if it has one). Returns whether it moved.
pub fn move_to(world: &mut World, entity: Entity, target: Vec3) -> bool {
    if !target.is_finite() {
        return false;
    }
    let parent = world
        .get::<ChildOf>(entity)
        .and_then(|c| world.get::<GlobalTransform>(c.parent()))
        .copied();
    let local = match parent {
        Some(p) => p.affine().inverse().transform_point3(target),
        None => target,
    };
    let Some(mut t) = world.get_mut::<Transform>(entity) else {
        return false;
    };
    if !local.is_finite() {
        return false;
    }
    t.translation = local;
    // Keep the GlobalTransform in step, so the next frame's arrows and picks see the move.
    let global = match parent {
        Some(p) => p.mul_transform(*t),
        None => GlobalTransform::from(*t),
    };
    if let Some(mut g) = world.get_mut::<GlobalTransform>(entity) {
        *g = global;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(origin: Vec3, toward: Vec3) -> Ray3d {
        Ray3d::new(origin, Dir3::new(toward - origin).unwrap())
    }

    #[test]
    fn the_nearest_axis_point_follows_the_pointer() {
        // Camera at z = 5 looking at points on the x axis: the parameter is their x.
        for x in [-2.0, 0.0, 0.5, 3.0] {
            let s = axis_parameter(
                ray(Vec3::new(0.0, 1.0, 5.0), Vec3::new(x, 0.0, 0.0)),
                Vec3::ZERO,
                Vec3::X,
            )
            .unwrap();
            assert!((s - x).abs() < 1e-4, "{s} vs {x}");
        }
        // A ray along the axis: no answer.
        assert_eq!(
            axis_parameter(
                ray(Vec3::new(-5.0, 0.0, 0.0), Vec3::ZERO),
                Vec3::ZERO,
                Vec3::X
            ),
            None
        );
    }

    #[test]
    fn a_drag_moves_along_its_axis_only() {
        let entity = World::new().spawn_empty().id();
        let eye = Vec3::new(1.0, 2.0, 6.0);
        let origin = Vec3::new(0.5, 1.0, 0.0);
        let drag = AxisDrag::begin(entity, 1, origin, ray(eye, origin + Vec3::Y * 0.1)).unwrap();
        let moved = drag.target(ray(eye, origin + Vec3::Y * 0.6)).unwrap();
        // The pointer moved 0.5 up the axis: the object moved 0.5 up, nothing else.
        assert!(
            (moved - (origin + Vec3::Y * 0.5)).length() < 1e-3,
            "{moved}"
        );
        assert_eq!(moved.x, origin.x);
        assert_eq!(moved.z, origin.z);
        // Pointing off to the side moves it along the axis still: x and z stay.
        let aside = drag.target(ray(eye, Vec3::new(3.0, 0.2, 1.0))).unwrap();
        assert_eq!((aside.x, aside.z), (origin.x, origin.z));
    }
}
