//! Picking: which triangle of a cloth a ray meets first, and its vertex nearest the hit (for
//! grabbing cloth with the mouse, or choosing vertices to pin in an editor).

use glam::{Vec3, Vec4, Vec4Swizzles};

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
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = s.cross(e1);
        let v = dir.dot(q) * inv;
        if !(v >= 0.0 && u + v <= 1.0) {
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
    use crate::solver::Grid;

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
