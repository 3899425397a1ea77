//! Picking: which triangle of a cloth a ray meets first, and its vertex nearest the hit (for
//! grabbing cloth with the mouse, or choosing vertices to pin in an editor).

use glam::{Vec3, Vec4, Vec4Swizzles};

use super::shape::{Pose, Shape};

/// Where a ray meets a cloth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Index of the triangle hit (in the list given).
    pub triangle: usize,
    /// Distance along the ray (in units of the ray's direction length).
    pub t: f32,
    /// The point hit.
    pub point: Vec3,
    /// The corner of the triangle nearest the point (a particle index).
    pub nearest: u32,
}

/// Barycentric slack of [`ray_hit`] (a fraction of the triangle).
const EDGE_SLACK: f32 = 1e-5;

/// The first triangle of `triangles` (particle indices into `positions`) that the ray
/// `origin + t·dir`, `t ≥ 0`, meets, from either side (Möller–Trumbore). Degenerate
/// triangles, non-finite positions and a zero or non-finite ray meet nothing.
#[must_use]
pub fn ray_hit(
    positions: &[Vec4],
    triangles: &[[u32; 3]],
    origin: Vec3,
    dir: Vec3,
) -> Option<RayHit> {
    if !(origin.is_finite() && dir.is_finite()) || dir.length_squared() == 0.0 {
        return None;
    }
    let mut best: Option<RayHit> = None;
    for (i, tri) in triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|v| positions.get(v as usize).map(|p| p.xyz()));
        let (Some(a), Some(b), Some(c)) = (a, b, c) else {
            continue;
        };
        let (e1, e2) = (b - a, c - a);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        // Parallel to the triangle, or a degenerate one (NaN compares false: skipped too).
        let tiny = f32::EPSILON * e1.length() * e2.length() * dir.length();
        if det.abs() <= tiny || det.is_nan() {
            continue;
        }
        let inv = 1.0 / det;
        let s = origin - a;
        let u = s.dot(p) * inv;
        // A little slack on the barycentric tests: a ray through a shared edge or vertex
        // must not slip between the triangles that share it by rounding.
        if !(-EDGE_SLACK..=1.0 + EDGE_SLACK).contains(&u) {
            continue;
        }
        let q = s.cross(e1);
        let v = dir.dot(q) * inv;
        if !(v >= -EDGE_SLACK && u + v <= 1.0 + EDGE_SLACK) {
            continue;
        }
        let t = e2.dot(q) * inv;
        if !(t >= 0.0 && t.is_finite()) || best.is_some_and(|h| h.t <= t) {
            continue;
        }
        let point = origin + dir * t;
        let nearest = tri
            .iter()
            .zip([a, b, c])
            .min_by(|x, y| {
                point
                    .distance_squared(x.1)
                    .total_cmp(&point.distance_squared(y.1))
            })
            .map_or(tri[0], |(v, _)| *v);
        best = Some(RayHit {
            triangle: i,
            t,
            point,
            nearest,
        });
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::Grid;

    #[test]
    fn rays_through_vertices_and_edges_do_not_slip_between_triangles() {
        // A crumpled 12×10 sheet; rays from several eyes aimed exactly at every interior
        // vertex and edge midpoint must meet it.
        let g = Grid::new(12, 10, 1.0, 1.0);
        let pos: Vec<Vec4> = g
            .positions()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let f = i as f32;
                (*p + Vec3::new(
                    0.013 * (f * 1.7).sin(),
                    0.2 * (f * 0.37).sin() + 0.07 * (f * 2.3).cos(),
                    0.011 * (f * 0.9).cos(),
                ))
                .extend(1.0)
            })
            .collect();
        let tris: Vec<[u32; 3]> = g.indices().chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let mut misses = 0;
        let mut tries = 0;
        for eye in [
            Vec3::new(0.0, 1.0, 8.0),
            Vec3::new(0.3, 5.0, 0.2),
            Vec3::new(-3.0, 2.0, 1.0),
            Vec3::new(2.0, -4.0, 0.5),
        ] {
            for j in 1..9 {
                for i in 1..11 {
                    let v = pos[g.index(i, j) as usize].xyz();
                    let w = pos[g.index(i + 1, j) as usize].xyz();
                    for target in [v, (v + w) * 0.5] {
                        tries += 1;
                        if ray_hit(&pos, &tris, eye, target - eye).is_none() {
                            misses += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(misses, 0, "{misses} of {tries} rays slipped through");
    }

    fn grid(y: f32) -> (Vec<Vec4>, Vec<[u32; 3]>) {
        let g = Grid::new(5, 5, 1.0, 1.0);
        let p = g
            .positions()
            .iter()
            .map(|p| (*p + Vec3::Y * y).extend(1.0))
            .collect();
        let t = g.indices().chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        (p, t)
    }

    #[test]
    fn a_ray_from_above_hits_the_vertex_under_it() {
        let (p, t) = grid(0.0);
        // Vertex (3, 1) of the 5 × 5 grid, nudged a little: the nearest corner is still it.
        let target = p[5 + 3].xyz() + Vec3::new(0.05, 0.0, -0.03);
        let hit = ray_hit(&p, &t, target + Vec3::Y * 2.0, Vec3::NEG_Y).expect("hit");
        assert_eq!(hit.nearest, 5 + 3);
        assert!((hit.t - 2.0).abs() < 1e-5 && (hit.point - target).length() < 1e-5);
        // From below too (cloth has two sides), and with an unnormalised direction.
        let below = ray_hit(&p, &t, target - Vec3::Y, Vec3::Y * 4.0).expect("hit from below");
        assert_eq!(below.nearest, hit.nearest);
        assert!((below.t - 0.25).abs() < 1e-5);
    }

    #[test]
    fn the_nearest_layer_wins_and_misses_are_none() {
        let (mut p, mut t) = grid(0.0);
        let (p2, t2) = grid(0.5);
        let n = p.len() as u32;
        p.extend(p2);
        t.extend(t2.iter().map(|tri| tri.map(|v| v + n)));
        let hit = ray_hit(&p, &t, Vec3::new(0.1, 3.0, 0.1), Vec3::NEG_Y).unwrap();
        assert!(hit.nearest >= n, "the upper layer is hit first");
        assert!((hit.point.y - 0.5).abs() < 1e-6);
        // Beside the cloth, away from it, along it, or with a broken ray: nothing.
        assert!(ray_hit(&p, &t, Vec3::new(3.0, 3.0, 0.0), Vec3::NEG_Y).is_none());
        assert!(ray_hit(&p, &t, Vec3::new(0.1, 3.0, 0.1), Vec3::Y).is_none());
        assert!(ray_hit(&p, &t, Vec3::new(-3.0, 0.25, 0.1), Vec3::X).is_none());
        assert!(ray_hit(&p, &t, Vec3::NAN, Vec3::NEG_Y).is_none());
        assert!(ray_hit(&p, &t, Vec3::Y, Vec3::ZERO).is_none());
    }
}

/// Where the ray `origin + t·dir` (`t ≥ 0`, `dir` of any non-zero length) first meets the
/// surface of `shape` placed at `pose`, as `t`: analytically for a plane, by sphere tracing
/// the signed distance inside the shape's bounding ball for the others. A ray starting inside
/// a shape meets it at `t = 0`. Non-finite or zero rays and poses meet nothing.
#[must_use]
pub fn ray_shape(shape: &Shape, pose: &Pose, origin: Vec3, dir: Vec3) -> Option<f32> {
    let usable = origin.is_finite()
        && dir.is_finite()
        && pose.translation.is_finite()
        && pose.rotation.is_finite()
        && pose.scale > 0.0
        && pose.scale.is_finite();
    if !usable {
        return None;
    }
    let len = dir.length();
    if len == 0.0 || !len.is_finite() {
        return None;
    }
    // Work in the shape's frame, with a unit direction (distances in local units).
    let o = pose.inverse_apply(origin);
    let d = (pose.rotation.inverse() * dir) / pose.scale;
    let dl = d.length();
    let d = d / dl;
    // Local distance along the unit local direction → world `t` for `dir`.
    let to_t = |s: f32| s / dl;
    if let Shape::Plane = shape {
        if o.y <= 0.0 {
            return Some(0.0);
        }
        return (d.y < 0.0).then(|| to_t(-o.y / d.y));
    }
    let r = shape.bounding_radius();
    // Entry and exit of the bounding ball.
    let b = o.dot(d);
    let c = o.length_squared() - r * r;
    let disc = b * b - c;
    // A miss (or NaN).
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    let (mut s, exit) = ((-b - root).max(0.0), -b + root);
    if exit < 0.0 {
        return None;
    }
    let eps = 1e-5 * r.max(1e-3);
    for _ in 0..256 {
        let (dist, _) = shape.distance(o + d * s);
        if !dist.is_finite() {
            return None;
        }
        if dist <= eps {
            return Some(to_t(s));
        }
        s += dist;
        if s > exit {
            return None;
        }
    }
    None
}

#[cfg(test)]
mod shape_tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn rays_meet_shapes_where_they_should() {
        let pose = Pose {
            translation: Vec3::new(0.0, 1.0, 0.0),
            rotation: Quat::from_rotation_y(0.7),
            scale: 2.0,
        };
        let down = Vec3::new(0.0, -2.0, 0.0);
        let above = Vec3::new(0.0, 5.0, 0.0);
        // Ball of radius 0.5 × 2: top at y = 2, t = 3 in units of |dir| = 2.
        let t = ray_shape(&Shape::Sphere { radius: 0.5 }, &pose, above, down).unwrap();
        assert!((t - 1.5).abs() < 1e-3, "{t}");
        // Box of half height 0.25 × 2: top at y = 1.5.
        let cube = Shape::Cuboid {
            half_extents: Vec3::new(0.3, 0.25, 0.3),
        };
        let t = ray_shape(&cube, &pose, above, down).unwrap();
        assert!((t - 1.75).abs() < 1e-3, "{t}");
        // Capsule along y: top of its cap at 1 + 2·(0.2 + 0.1).
        let cap = Shape::Capsule {
            half_length: 0.2,
            radius: 0.1,
        };
        let t = ray_shape(&cap, &pose, above, down).unwrap();
        assert!((t - (5.0 - 1.6) / 2.0).abs() < 1e-3, "{t}");
        // The floor through y = 1.
        let t = ray_shape(&Shape::Plane, &pose, above, down).unwrap();
        assert!((t - 2.0).abs() < 1e-5, "{t}");
        // Missing: beside the ball, pointing away, upward over the floor, broken rays.
        let beside = Vec3::new(3.0, 5.0, 0.0);
        assert_eq!(
            ray_shape(&Shape::Sphere { radius: 0.5 }, &pose, beside, down),
            None
        );
        assert_eq!(ray_shape(&cube, &pose, above, -down), None);
        assert_eq!(ray_shape(&Shape::Plane, &pose, above, -down), None);
        assert_eq!(ray_shape(&cube, &pose, Vec3::NAN, down), None);
        assert_eq!(ray_shape(&cube, &pose, above, Vec3::ZERO), None);
        // Inside: met at once.
        assert_eq!(ray_shape(&cube, &pose, pose.translation, down), Some(0.0));
    }
}
