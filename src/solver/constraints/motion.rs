//! Motion constraints: each vertex kept within a distance of where something else puts it —
//! for skinned clothing, where the animated skin puts it (NvCloth's motion and separation
//! constraints, Unity Cloth's max distance and backstop).
//!
//! Per vertex a target moves linearly over the step's substeps from where it was at the step's
//! start to where it is at the end; after the constraints of every substep a vertex farther
//! than its *max distance* from the target is brought back onto that sphere (max distance 0:
//! the vertex follows the target exactly, a negative one: the vertex is free). Optionally a
//! *backstop*: a sphere of radius `backstop_radius` behind the skin, its surface `backstop`
//! metres behind the target along the skin's normal, which the vertex may not enter, so
//! cloth swinging back against the body stops at the skin instead of passing through it.

use glam::{Vec4, Vec4Swizzles};

/// One step's motion constraints of a cloth: per vertex (all three slices as long as the
/// cloth, or the constraints are ignored).
#[derive(Clone, Copy, Debug, Default)]
pub struct MotionConstraints<'a> {
    /// Each vertex's target at the start of the step (`w` ignored).
    pub start: &'a [Vec4],
    /// Each vertex's target at the end of the step (xyz) and its max distance (`w`, metres;
    /// 0: the vertex follows the target; negative or not finite: the vertex is free).
    pub end: &'a [Vec4],
    /// The skin's outward unit normal at each target at the end of the step (xyz) and how far
    /// behind the target the backstop sphere's surface lies (`w`, metres; negative or not
    /// finite: no backstop for that vertex). Empty: no backstops.
    pub backstop: &'a [Vec4],
    /// Radius of every backstop sphere, metres (not finite or ≤ 0: no backstops).
    pub backstop_radius: f32,
}

impl MotionConstraints<'_> {
    /// Whether these constraints apply to a cloth of `n` vertices.
    #[must_use]
    pub fn applies_to(&self, n: usize) -> bool {
        n > 0 && self.start.len() == n && self.end.len() == n
    }

    /// Whether there are backstops at all.
    fn backstops(&self) -> bool {
        !self.backstop.is_empty() && self.backstop_radius.is_finite() && self.backstop_radius > 0.0
    }

    /// Vertex `i` (free, at `x`) after substep `s` of `substeps`: within its max distance of
    /// its target, outside its backstop. A vertex whose target is not finite is left alone.
    #[inline]
    pub fn constrain(&self, i: usize, x: &mut Vec4, s: u32, substeps: u32) {
        let (Some(a), Some(b)) = (self.start.get(i), self.end.get(i)) else {
            return;
        };
        let f = (s + 1) as f32 / substeps.max(1) as f32;
        let target = a.xyz() + (b.xyz() - a.xyz()) * f;
        if !target.is_finite() {
            return;
        }
        let p = x.xyz();
        let mut q = p;
        let r = b.w;
        if r.is_finite() && r >= 0.0 {
            let d = q - target;
            let l2 = d.length_squared();
            if l2 > r * r {
                q = target + d * (r / l2.sqrt());
            }
        }
        if self.backstops()
            && let Some(n) = self.backstop.get(i)
            && n.w.is_finite()
            && n.w >= 0.0
            && n.xyz().is_finite()
        {
            let radius = self.backstop_radius;
            let centre = target - n.xyz() * (radius + n.w);
            let d = q - centre;
            let l2 = d.length_squared();
            if l2 < radius * radius {
                let l = l2.sqrt();
                q = if l > 1e-12 {
                    centre + d * (radius / l)
                } else {
                    centre + n.xyz() * radius
                };
            }
        }
        if q != p && q.is_finite() {
            *x = q.extend(x.w);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f32, y: f32, z: f32, w: f32) -> Vec4 {
        Vec4::new(x, y, z, w)
    }

    #[test]
    fn a_vertex_stays_within_its_max_distance_of_the_moving_target() {
        let start = [v(0.0, 0.0, 0.0, 0.0)];
        let end = [v(1.0, 0.0, 0.0, 0.1)];
        let m = MotionConstraints {
            start: &start,
            end: &end,
            ..Default::default()
        };
        // Halfway through the step the target is at x = 0.5; a vertex left at the origin is
        // pulled to 0.1 of it.
        let mut x = v(0.0, 0.0, 0.0, 1.0);
        m.constrain(0, &mut x, 1, 4);
        assert!((x.x - 0.4).abs() < 1e-6, "{x}");
        assert_eq!(x.w, 1.0);
        // Within reach: left alone.
        let mut y = v(0.95, 0.05, 0.0, 1.0);
        m.constrain(0, &mut y, 3, 4);
        assert_eq!(y, v(0.95, 0.05, 0.0, 1.0));
    }

    #[test]
    fn zero_follows_negative_is_free_and_nan_is_ignored() {
        let start = [Vec4::ZERO, Vec4::ZERO, Vec4::ZERO];
        let end = [
            v(0.0, 1.0, 0.0, 0.0),
            v(0.0, 1.0, 0.0, -1.0),
            v(f32::NAN, 1.0, 0.0, 0.0),
        ];
        let m = MotionConstraints {
            start: &start,
            end: &end,
            ..Default::default()
        };
        let mut xs = [v(5.0, 0.0, 0.0, 1.0); 3];
        for (i, x) in xs.iter_mut().enumerate() {
            m.constrain(i, x, 1, 2);
        }
        assert_eq!(xs[0], v(0.0, 1.0, 0.0, 1.0));
        assert_eq!(xs[1], v(5.0, 0.0, 0.0, 1.0));
        assert_eq!(xs[2], v(5.0, 0.0, 0.0, 1.0));
        assert!(m.applies_to(3) && !m.applies_to(2));
    }

    #[test]
    fn the_backstop_keeps_a_vertex_in_front_of_the_skin() {
        // Skin at the origin facing +z, max distance 0.2, backstop 1 m sphere touching the
        // skin (distance 0): a vertex 0.1 behind the skin is pushed back onto it (z = 0),
        // one 0.1 in front stays.
        let start = [Vec4::ZERO];
        let end = [v(0.0, 0.0, 0.0, 0.2)];
        let back = [v(0.0, 0.0, 1.0, 0.0)];
        let m = MotionConstraints {
            start: &start,
            end: &end,
            backstop: &back,
            backstop_radius: 1.0,
        };
        let mut behind = v(0.0, 0.0, -0.1, 1.0);
        m.constrain(0, &mut behind, 0, 1);
        assert!(behind.z.abs() < 1e-6, "{behind}");
        let mut front = v(0.0, 0.05, 0.1, 1.0);
        m.constrain(0, &mut front, 0, 1);
        assert_eq!(front, v(0.0, 0.05, 0.1, 1.0));
        // Backstop 0.05 behind the skin: the vertex may go 0.05 deep, no deeper.
        let back = [v(0.0, 0.0, 1.0, 0.05)];
        let m = MotionConstraints {
            backstop: &back,
            ..m
        };
        let mut deep = v(0.0, 0.0, -0.15, 1.0);
        m.constrain(0, &mut deep, 0, 1);
        assert!((deep.z + 0.05).abs() < 1e-5, "{deep}");
    }
}
