//! Collisions between cloth vertices and rigid shapes.
//!
//! A [`Collider`] is a [`Shape`] in a [`Pose`] (its pose at the start and at the end of the
//! step; substeps interpolate between them, so a moving collider sweeps through the cloth in
//! small steps rather than jumping). Each substep, after the constraints, every vertex closer
//! than `thickness` to a collider is pushed out along the surface normal, and its tangential
//! motion relative to the surface is reduced by Coulomb friction (`friction × push depth`,
//! Macklin et al. 2014). The momentum this takes from or gives to the cloth is summed per
//! collider, so the ECS side can push rigid bodies back (two-way coupling).
//!
//! Tunnelling: a collider of radius `r` (half the thinnest extent for a box) moving at speed
//! `v` is caught as long as `v·h < r + thickness`, with `h` the substep length. At 60 Hz and 10
//! substeps (`h` ≈ 1.7 ms) a 0.2 m ball survives speeds up to about 120 m/s.

use glam::{Mat3, Vec3, Vec4, Vec4Swizzles};
use wide::{CmpGt, CmpLe, f32x4};

use super::shape::{Pose, Shape};
use crate::solver::limits::{self, MAX_COORDINATE, within_range};

/// A shape that cloth collides with.
#[derive(Clone, Debug, PartialEq)]
pub struct Collider {
    /// The shape in its local frame.
    pub shape: Shape,
    /// Pose at the start of the step.
    pub start: Pose,
    /// Pose at the end of the step.
    pub end: Pose,
    /// Distance kept between cloth vertices and the surface, in metres (≥ 0).
    pub thickness: f32,
    /// Coulomb friction coefficient (≥ 0): 0 slides freely, 1 grips.
    pub friction: f32,
}

impl Collider {
    /// A collider that does not move during the step.
    #[must_use]
    pub fn fixed(shape: Shape, pose: Pose, thickness: f32, friction: f32) -> Self {
        Self {
            shape,
            start: pose,
            end: pose,
            thickness,
            friction,
        }
    }

    /// Checks that the collider can be collided with: thickness, friction and sizes within
    /// their [`limits`], poses finite and within range, scale positive.
    ///
    /// # Errors
    /// What is wrong, in words (the step itself drops any push that lands out of range, so an
    /// invalid collider cannot poison the cloth; this is for reporting it).
    pub fn validate(&self) -> Result<(), String> {
        limits::COLLIDER_THICKNESS
            .check(self.thickness)
            .map_err(|e| e.to_string())?;
        limits::COLLIDER_FRICTION
            .check(self.friction)
            .map_err(|e| e.to_string())?;
        if !self.shape.sizes_valid() {
            return Err(format!(
                "a size of {:?} is negative, not finite or over {MAX_COORDINATE} m",
                self.shape
            ));
        }
        for pose in [self.start, self.end] {
            if !(within_range(pose.translation)
                && pose.rotation.is_finite()
                && pose.scale > 0.0
                && pose.scale <= MAX_COORDINATE)
            {
                return Err(format!("pose {pose:?} is not finite or out of range"));
            }
        }
        Ok(())
    }
}

/// Linear and angular impulse (about the collider's origin at the end of the step) that the
/// cloth applied to a collider during a step, in N·s and N·m·s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactImpulse {
    /// Linear impulse on the collider.
    pub linear: Vec3,
    /// Angular impulse on the collider about its origin.
    pub angular: Vec3,
}

/// Colliders posed for one substep: the poses at the substep's start and end.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SubstepPose {
    pub from: Pose,
    pub to: Pose,
    /// Squared distance beyond which a vertex cannot touch (bounding ball + thickness).
    pub reach2: f32,
    /// Squared distance from the shape's core (see `Shape::core_radius`), in its local
    /// frame, beyond which a vertex surely does not touch it: the core's radius plus the
    /// thickness in local units, widened (see [`CORE_SLACK`]) so that rounding never skips
    /// a vertex the full test would push; infinite where the shape has no core.
    pub core2: f32,
    /// The rows of the matrix taking `p − to.translation` into the shape's frame (`to`'s
    /// inverse rotation over its scale), for the core test; the full test turns the point
    /// with the quaternion.
    pub local: [Vec3; 3],
}

/// Widening of [`SubstepPose::core2`], relative to the core's reach and to the bounding
/// ball's (in which the points tested lie): far above the roundings between the core test
/// (a matrix turn, a few products) and the full one (a quaternion turn, square roots), each
/// at most a few times 6e-8 of those lengths.
const CORE_SLACK: f32 = 1e-5;

/// The colliders' poses for each of a step's `n` substeps, substep by substep (`out[s·m +
/// i]` for collider `i` of `m`). Each pose between two substeps is interpolated once: the
/// end of one substep is the start of the next.
pub(crate) fn substep_poses(colliders: &[Collider], n: u32, out: &mut Vec<SubstepPose>) {
    out.clear();
    let finite2 = |r: f32| if r.is_finite() { r * r } else { f32::INFINITY };
    for s in 0..n {
        let t1 = (s + 1) as f32 / n as f32;
        for (i, c) in colliders.iter().enumerate() {
            let from = match s.checked_sub(1) {
                Some(before) => out[before as usize * colliders.len() + i].to,
                None => c.start.lerp(&c.end, 0.0),
            };
            let to = c.start.lerp(&c.end, t1);
            let bounding = c.shape.bounding_radius();
            let reach = bounding * to.scale + c.thickness;
            let own = c.thickness / to.scale;
            let core = c.shape.core_radius() + own;
            let ball = bounding + own;
            let turn = Mat3::from_quat(to.rotation.inverse()) * (1.0 / to.scale);
            out.push(SubstepPose {
                from,
                to,
                reach2: finite2(reach),
                core2: finite2(core + CORE_SLACK * (core + ball)),
                local: [0, 1, 2].map(|i| turn.row(i)),
            });
        }
    }
}

/// Vertices whose reach test [`collide_vertices`] makes at once.
const LANES: usize = 4;

/// Pushes a run of vertices out of every collider and applies friction; adds the momentum
/// they gave each collider (`−m·Δx/h`, before dividing by `h`) to `impulses`.
///
/// `pos` holds the vertices after the substep's constraints, `prev` where they started the
/// substep (same length). Each vertex meets the colliders in their order, and each
/// collider's momentum is summed over the vertices in theirs: the same values as taking the
/// vertices one at a time through every collider. The cheap tests — within the bounding
/// ball's reach, then (spheres, capsules, boxes) near enough to the shape's core — take four
/// vertices at a time in SIMD lanes; only the vertices that pass take the exact one.
pub(crate) fn collide_vertices(
    pos: &mut [Vec4],
    prev: &[Vec4],
    colliders: &[Collider],
    poses: &[SubstepPose],
    impulses: &mut [ContactImpulse],
) {
    for ((c, pose), imp) in colliders.iter().zip(poses).zip(impulses.iter_mut()) {
        let centre = pose.to.translation;
        let (cx, cy, cz) = (
            f32x4::splat(centre.x),
            f32x4::splat(centre.y),
            f32x4::splat(centre.z),
        );
        let reach2 = f32x4::splat(pose.reach2);
        // The core test: spheres, capsules and boxes (a plane's or a mesh's `core2` is
        // infinite, as is any core out of range).
        let core2 = f32x4::splat(pose.core2);
        let cull = pose.core2.is_finite();
        for (xs, ps) in pos.chunks_mut(LANES).zip(prev.chunks(LANES)) {
            // Which of these vertices are within reach, as bits, four at a time in SIMD
            // lanes (each lane's squared distance the same operations as
            // `Vec3::length_squared`; missing lanes of a short last group read w = 0). Pinned
            // vertices (w = 0) are not pushed; a vertex that is not finite is left alone
            // either way (any push of it would land out of range).
            let at = |k: usize| xs.get(k).copied().unwrap_or(Vec4::ZERO);
            let v: [Vec4; LANES] = core::array::from_fn(at);
            let lane = |f: fn(Vec4) -> f32| f32x4::new(v.map(f));
            let (dx, dy, dz) = (lane(|v| v.x) - cx, lane(|v| v.y) - cy, lane(|v| v.z) - cz);
            let d2 = dx * dx + dy * dy + dz * dz;
            let within = d2.cmp_le(reach2) & lane(|v| v.w).cmp_gt(f32x4::ZERO);
            let mut near = within.move_mask() as u32;
            // Of those, the ones surely out of touch of the shape's core (no square root,
            // no division; a NaN keeps the vertex for the full test).
            if near != 0 && cull {
                let row = |r: Vec3| {
                    f32x4::splat(r.x) * dx + f32x4::splat(r.y) * dy + f32x4::splat(r.z) * dz
                };
                let [lx, ly, lz] = pose.local.map(row);
                let d2 = match c.shape {
                    Shape::Capsule { half_length, .. } => {
                        let h = f32x4::splat(half_length);
                        let ay = ly - ly.max(-h).min(h);
                        lx * lx + ay * ay + lz * lz
                    }
                    Shape::Cuboid { half_extents: e } => {
                        let out = |l: f32x4, e: f32| (l.abs() - f32x4::splat(e)).max(f32x4::ZERO);
                        let (ox, oy, oz) = (out(lx, e.x), out(ly, e.y), out(lz, e.z));
                        ox * ox + oy * oy + oz * oz
                    }
                    // A sphere (planes and meshes have no core).
                    _ => lx * lx + ly * ly + lz * lz,
                };
                near &= !(d2.cmp_gt(core2).move_mask() as u32);
            }
            while near != 0 {
                let k = near.trailing_zeros() as usize;
                near &= near - 1;
                touch(&mut xs[k], ps[k], c, pose, imp);
            }
        }
    }
}

/// Pushes one vertex within a collider's reach out of it and applies friction.
#[inline(never)]
fn touch(x: &mut Vec4, prev: Vec4, c: &Collider, pose: &SubstepPose, imp: &mut ContactImpulse) {
    let p = x.xyz();
    let local = pose.to.inverse_apply(p);
    let (d_local, n_local) = c.shape.distance(local);
    let d = d_local * pose.to.scale;
    // NaN distances (a degenerate shape) count as "no contact".
    if d.is_nan() || d >= c.thickness {
        return;
    }
    let n = pose.to.rotation * n_local;
    let push = c.thickness - d;
    let mut corrected = p + n * push;
    // Friction against the surface's own motion during the substep.
    let surface = pose.to.apply(local) - pose.from.apply(local);
    let slide = (corrected - prev.xyz()) - surface;
    let tangential = slide - n * n.dot(slide);
    let t_len = tangential.length();
    let limit = c.friction * push;
    if t_len > 0.0 {
        corrected -= if t_len <= limit {
            tangential
        } else {
            tangential * (limit / t_len)
        };
    }
    // A push out of a huge or broken shape that lands nowhere sensible is dropped.
    if !within_range(corrected) {
        return;
    }
    // Momentum given to the cloth is m·Δx/h; the collider gets the opposite (h applied later).
    let dp = (corrected - p) / x.w;
    imp.linear -= dp;
    imp.angular -= (p - pose.to.translation).cross(dp);
    *x = corrected.extend(x.w);
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn analytic_distances() {
        let s = Shape::Sphere { radius: 2.0 };
        assert_eq!(s.distance(Vec3::new(0.0, 3.0, 0.0)), (1.0, Vec3::Y));
        let b = Shape::Cuboid {
            half_extents: Vec3::new(1.0, 2.0, 3.0),
        };
        let (d, n) = b.distance(Vec3::new(0.0, 0.0, 5.0));
        assert_eq!((d, n), (2.0, Vec3::Z));
        let (d, n) = b.distance(Vec3::new(0.9, 0.0, 0.0));
        assert!((d + 0.1).abs() < 1e-6 && n == Vec3::X);
        let (d, _) = b.distance(Vec3::new(2.0, 3.0, 0.0));
        assert!((d - 2f32.sqrt()).abs() < 1e-6);
        let c = Shape::Capsule {
            half_length: 1.0,
            radius: 0.5,
        };
        assert_eq!(c.distance(Vec3::new(1.0, 0.3, 0.0)), (0.5, Vec3::X));
        assert!((c.distance(Vec3::new(0.0, 2.0, 0.0)).0 - 0.5).abs() < 1e-6);
        assert_eq!(
            Shape::Plane.distance(Vec3::new(5.0, -0.25, 1.0)),
            (-0.25, Vec3::Y)
        );
    }

    #[test]
    fn pose_round_trip() {
        let pose = Pose {
            translation: Vec3::new(1.0, 2.0, 3.0),
            rotation: Quat::from_rotation_z(0.7),
            scale: 2.0,
        };
        let p = Vec3::new(-0.3, 0.8, 0.1);
        assert!((pose.inverse_apply(pose.apply(p)) - p).length() < 1e-6);
    }

    #[test]
    fn vertex_is_pushed_to_thickness_and_collider_gets_the_opposite_momentum() {
        let c = [Collider::fixed(
            Shape::Sphere { radius: 1.0 },
            Pose::default(),
            0.1,
            0.0,
        )];
        let mut poses = Vec::new();
        substep_poses(&c, 1, &mut poses);
        let mut imp = [ContactImpulse::default()];
        let mut x = Vec4::new(0.0, 0.5, 0.0, 2.0); // inverse mass 2 → mass 0.5
        let prev = x;
        collide_vertices(core::slice::from_mut(&mut x), &[prev], &c, &poses, &mut imp);
        assert!((x.y - 1.1).abs() < 1e-6 && x.x == 0.0 && x.z == 0.0);
        // Δx = 0.6 up, m = 0.5: the cloth gained 0.3 (×1/h) upwards, the sphere lost it.
        assert!((imp[0].linear - Vec3::new(0.0, -0.3, 0.0)).length() < 1e-6);
    }

    /// The core test of `collide_vertices` skips only vertices the full test leaves alone:
    /// points placed a few roundings either side of touching distance from spheres,
    /// capsules and boxes (long and thin ones too; turned, scaled from 1e-3 to 1e3,
    /// thickness 0 to 1 m, friction on) come out the same bit for bit, impulses included,
    /// with the core test and without it.
    #[test]
    fn the_core_bound_skips_no_vertex_the_full_test_would_push() {
        let shapes = [
            Shape::Sphere { radius: 0.3 },
            Shape::Sphere { radius: 0.0 },
            Shape::Capsule {
                radius: 0.05,
                half_length: 0.2,
            },
            Shape::Cuboid {
                half_extents: Vec3::new(0.2, 0.05, 0.4),
            },
            // Long and thin: points far from the origin, close to the surface.
            Shape::Capsule {
                radius: 0.01,
                half_length: 2.0,
            },
            Shape::Cuboid {
                half_extents: Vec3::new(1.5, 0.01, 1.5),
            },
        ];
        let mut seed = 0x2545_f491_u32;
        let mut unit = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32
        };
        let (mut pushed, mut checked) = (0, 0);
        for shape in shapes {
            for scale in [1e-3, 0.37, 1.0, 3.0, 1e3] {
                for thickness in [0.0, 1e-4, 0.01, 0.3, 1.0] {
                    let to = Pose {
                        translation: Vec3::new(0.3, -1.2, 2.0),
                        rotation: Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.7),
                        scale,
                    };
                    let c = [Collider {
                        shape: shape.clone(),
                        start: Pose::at(Vec3::new(0.2, -1.0, 2.0)),
                        end: to,
                        thickness,
                        friction: 0.4,
                    }];
                    let mut poses = Vec::new();
                    substep_poses(&c, 1, &mut poses);
                    let mut open = poses.clone();
                    open[0].core2 = f32::INFINITY;
                    for _ in 0..400 {
                        // A surface point (the nearest one to a random local point), then
                        // out along its normal by the thickness, give or take a few ulps.
                        let dir = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5);
                        let local = dir * 0.8 * shape.bounding_radius();
                        let (d, n) = shape.distance(local);
                        let on = local - n * d;
                        let off = thickness / scale * (1.0 + (unit() - 0.5) * 4e-6);
                        let p = to.apply(on + n * off);
                        let x = p.extend(1.5);
                        let prev = (p + Vec3::new(0.01, 0.02, -0.01)).extend(1.5);
                        let (mut a, mut b) = (x, x);
                        let (mut ia, mut ib) =
                            ([ContactImpulse::default()], [ContactImpulse::default()]);
                        collide_vertices(
                            core::slice::from_mut(&mut a),
                            &[prev],
                            &c,
                            &poses,
                            &mut ia,
                        );
                        collide_vertices(
                            core::slice::from_mut(&mut b),
                            &[prev],
                            &c,
                            &open,
                            &mut ib,
                        );
                        assert_eq!(
                            a.to_array().map(f32::to_bits),
                            b.to_array().map(f32::to_bits),
                            "{shape:?} scale {scale} thickness {thickness} at {x}"
                        );
                        assert_eq!(ia, ib);
                        pushed += usize::from(b != x);
                        checked += 1;
                    }
                }
            }
        }
        // About half of them were touching: the boundary was where the points were.
        assert!(
            pushed > checked / 5 && pushed < checked * 4 / 5,
            "{pushed} of {checked}"
        );
    }

    #[test]
    fn friction_holds_or_slides() {
        let plane = |friction| {
            [Collider::fixed(
                Shape::Plane,
                Pose::default(),
                0.0,
                friction,
            )]
        };
        // Coulomb: the slide is cut by at most μ × the push depth (0.1 here).
        for (friction, expect_x) in [(0.0, 0.5), (1.0, 0.4), (10.0, 0.0), (0.1, 0.49)] {
            let c = plane(friction);
            let mut poses = Vec::new();
            substep_poses(&c, 1, &mut poses);
            let mut imp = [ContactImpulse::default()];
            // Moved 0.5 along x and sank 0.1 below the plane during the substep.
            let prev = Vec4::new(0.0, 0.0, 0.0, 1.0);
            let mut x = Vec4::new(0.5, -0.1, 0.0, 1.0);
            collide_vertices(core::slice::from_mut(&mut x), &[prev], &c, &poses, &mut imp);
            assert!(x.y.abs() < 1e-6);
            assert!((x.x - expect_x).abs() < 1e-5, "μ {friction}: x {}", x.x);
        }
    }

    #[test]
    fn moving_surface_carries_the_vertex_with_friction() {
        // A plane sliding along +x by 0.2 during the substep drags a vertex resting on it.
        let c = [Collider {
            shape: Shape::Plane,
            start: Pose::default(),
            end: Pose::at(Vec3::new(0.2, 0.0, 0.0)),
            thickness: 0.0,
            friction: 50.0, // 50 × the 1 cm push: enough to hold against a 20 cm slide
        }];
        let mut poses = Vec::new();
        substep_poses(&c, 1, &mut poses);
        let mut imp = [ContactImpulse::default()];
        let prev = Vec4::new(0.0, 0.0, 0.0, 1.0);
        let mut x = Vec4::new(0.0, -0.01, 0.0, 1.0);
        collide_vertices(core::slice::from_mut(&mut x), &[prev], &c, &poses, &mut imp);
        assert!((x.x - 0.2).abs() < 1e-5, "{x}");
    }
}
