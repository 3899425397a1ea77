//! Shading data from the simulated positions (report §3.2): area-weighted vertex normals and
//! UV tangents.
//!
//! Normals: each triangle adds its unnormalised normal `(x1 − x0)×(x2 − x0)` (length = twice
//! its area) to its three vertices, then each sum is normalised. Tangents: each triangle's
//! `T' = ((v2 − v0)·q0 + (v0 − v1)·q1)/((u1 − u0)(v2 − v0) − (v1 − v0)(u2 − u0))` with
//! `q0 = x1 − x0`, `q1 = x2 − x0`, summed per vertex, made orthogonal to the normal
//! (`T = T' − (T'·N)N`) and normalised; `w` is the handedness (`±1`) in Bevy's convention
//! (`bitangent = w·N×T`).

use glam::{Vec2, Vec3, Vec4, Vec4Swizzles};

/// Writes area-weighted unit normals into `out` (resized to the vertex count). A vertex in
/// no triangle, or only in zero-area ones, keeps the normal it had in `out` (or +Y).
pub fn vertex_normals(positions: &[Vec4], triangles: &[[u32; 3]], out: &mut Vec<Vec3>) {
    let n = positions.len();
    let fallback: Vec<Vec3> = (0..n)
        .map(|i| {
            out.get(i)
                .copied()
                .filter(|v| v.is_finite())
                .unwrap_or(Vec3::Y)
        })
        .collect();
    out.clear();
    out.resize(n, Vec3::ZERO);
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize].xyz());
        let face = (b - a).cross(c - a);
        if face.is_finite() {
            for &i in t {
                out[i as usize] += face;
            }
        }
    }
    for (o, f) in out.iter_mut().zip(fallback) {
        *o = o.try_normalize().unwrap_or(f);
    }
}

/// Writes unit tangents with handedness into `out` from `uvs` and the unit `normals`.
/// Where UVs are degenerate, the tangent is any unit vector orthogonal to the normal.
pub fn vertex_tangents(
    positions: &[Vec4],
    uvs: &[Vec2],
    normals: &[Vec3],
    triangles: &[[u32; 3]],
    out: &mut Vec<Vec4>,
) {
    let n = positions.len();
    let mut tan = vec![Vec3::ZERO; n];
    let mut bit = vec![Vec3::ZERO; n];
    for t in triangles {
        let [i0, i1, i2] = t.map(|i| i as usize);
        let p = [i0, i1, i2].map(|i| positions[i].xyz());
        if let Some((tp, bp)) = triangle_tangent(p, [uvs[i0], uvs[i1], uvs[i2]]) {
            for i in [i0, i1, i2] {
                tan[i] += tp;
                bit[i] += bp;
            }
        }
    }
    out.clear();
    out.extend((0..n).map(|i| finish_tangent(normals[i], tan[i], bit[i], None)));
}

/// A triangle's unnormalised tangent and bitangent `(T', B')` from its corners and their UVs
/// (the formula in the module docs); `None` where the UVs are degenerate or the result is not
/// finite.
pub(crate) fn triangle_tangent(p: [Vec3; 3], uv: [Vec2; 3]) -> Option<(Vec3, Vec3)> {
    let [uv0, uv1, uv2] = uv;
    let (q0, q1) = (p[1] - p[0], p[2] - p[0]);
    let det = (uv1.x - uv0.x) * (uv2.y - uv0.y) - (uv1.y - uv0.y) * (uv2.x - uv0.x);
    if det.abs() < 1e-20 {
        return None;
    }
    let r = 1.0 / det;
    let tp = ((uv2.y - uv0.y) * q0 + (uv0.y - uv1.y) * q1) * r;
    let bp = ((uv0.x - uv2.x) * q0 + (uv1.x - uv0.x) * q1) * r;
    (tp.is_finite() && bp.is_finite()).then_some((tp, bp))
}

/// A vertex's unit tangent with handedness from its unit `normal` and its summed `tan` and
/// `bit`: `tan` made orthogonal to the normal (any orthogonal unit vector if nothing is
/// left), `w` = `handedness` if given, else the sign that makes `w·N×T` follow `bit`.
pub(crate) fn finish_tangent(normal: Vec3, tan: Vec3, bit: Vec3, handedness: Option<f32>) -> Vec4 {
    let t = (tan - normal * normal.dot(tan))
        .try_normalize()
        .unwrap_or_else(|| normal.any_orthonormal_vector());
    let w = match handedness {
        Some(h) => h,
        None if normal.cross(t).dot(bit) < 0.0 => -1.0,
        None => 1.0,
    };
    t.extend(w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::topology::Grid;

    fn grid() -> (Grid, Vec<Vec4>, Vec<[u32; 3]>) {
        let g = Grid::new(4, 3, 2.0, 1.0);
        let p = g.positions().iter().map(|p| p.extend(1.0)).collect();
        let t = g.indices().chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        (g, p, t)
    }

    #[test]
    fn flat_grid_normals_and_tangents() {
        let (g, p, t) = grid();
        let mut n = Vec::new();
        vertex_normals(&p, &t, &mut n);
        assert!(n.iter().all(|v| (*v - Vec3::Y).length() < 1e-6));
        let mut tg = Vec::new();
        vertex_tangents(&p, &g.uvs(), &n, &t, &mut tg);
        // u grows with +x, v grows with −z: T = +X, bitangent −Z = +Y×X, so w = +1.
        assert!(
            tg.iter()
                .all(|v| (*v - Vec4::new(1.0, 0.0, 0.0, 1.0)).length() < 1e-6)
        );
    }

    #[test]
    fn normals_are_area_weighted() {
        // A big triangle in the XY plane and a small one in the XZ plane share vertex 0.
        let p: Vec<Vec4> = [
            Vec3::ZERO,
            Vec3::X * 10.0,
            Vec3::Y * 10.0,
            Vec3::X,
            -Vec3::Z,
        ]
        .iter()
        .map(|v| v.extend(1.0))
        .collect();
        let t = [[0, 1, 2], [0, 3, 4]];
        let mut n = Vec::new();
        vertex_normals(&p, &t, &mut n);
        // Face normals 100·Z and 1·Y (twice the areas): the sum points mostly along Z.
        let expect = Vec3::new(0.0, 1.0, 100.0).normalize();
        assert!((n[0] - expect).length() < 1e-6, "{}", n[0]);
        assert_eq!(n[1], Vec3::Z);
    }

    #[test]
    fn mirrored_uvs_flip_handedness_and_degenerate_inputs_stay_finite() {
        let (g, p, t) = grid();
        let uvs: Vec<Vec2> = g
            .uvs()
            .iter()
            .map(|uv| Vec2::new(uv.x, 1.0 - uv.y))
            .collect();
        let mut n = Vec::new();
        vertex_normals(&p, &t, &mut n);
        let mut tg = Vec::new();
        vertex_tangents(&p, &uvs, &n, &t, &mut tg);
        assert!(tg.iter().all(|v| v.w == -1.0));
        // All vertices coincide and all UVs are equal: nothing to go on, but no NaN.
        let flat = vec![Vec4::new(1.0, 2.0, 3.0, 1.0); p.len()];
        vertex_normals(&flat, &t, &mut n);
        vertex_tangents(&flat, &vec![Vec2::ZERO; p.len()], &n, &t, &mut tg);
        assert!(
            n.iter()
                .all(|v| v.is_finite() && (v.length() - 1.0).abs() < 1e-5)
        );
        assert!(tg.iter().all(|v| v.is_finite()));
    }
}
