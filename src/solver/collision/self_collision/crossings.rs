//! Counting the edge–triangle pairs of a mesh that cross: how the tests and examples tell
//! that a cloth passed through itself.

use super::*;

/// Number of (edge, triangle) pairs of a mesh that cross each other, the edge sharing no vertex
/// with the triangle: 0 for a cloth that never passed through itself.
#[must_use]
pub fn count_self_crossings(
    positions: &[Vec4],
    triangles: &[[u32; 3]],
    edges: &[[u32; 2]],
) -> usize {
    if triangles.is_empty() || edges.is_empty() {
        return 0;
    }
    let p = |i: u32| positions[i as usize].xyz();
    // Uniform grid over triangle bounding boxes, cells of about the mean edge length.
    let mean_edge =
        edges.iter().map(|e| p(e[0]).distance(p(e[1]))).sum::<f32>() / edges.len() as f32;
    let cell = mean_edge.max(1e-6) * 2.0;
    let inv = 1.0 / cell;
    let size = triangles.len() * 4;
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); size];
    for (t, tri) in triangles.iter().enumerate() {
        let [a, b, c] = tri.map(p);
        if !(a.is_finite() && b.is_finite() && c.is_finite()) {
            continue;
        }
        let lo = cell_of(a.min(b).min(c), inv);
        let hi = cell_of(a.max(b).max(c), inv);
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    buckets[hash(IVec3::new(x, y, z), size)].push(t as u32);
                }
            }
        }
    }
    let mut count = 0;
    let mut seen = Vec::new();
    for e in edges {
        let (a, b) = (p(e[0]), p(e[1]));
        if !(a.is_finite() && b.is_finite()) {
            continue;
        }
        let lo = cell_of(a.min(b), inv);
        let hi = cell_of(a.max(b), inv);
        seen.clear();
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    seen.extend_from_slice(&buckets[hash(IVec3::new(x, y, z), size)]);
                }
            }
        }
        seen.sort_unstable();
        seen.dedup();
        for &t in &seen {
            let tri = triangles[t as usize];
            if tri.contains(&e[0]) || tri.contains(&e[1]) {
                continue;
            }
            if segment_crosses_triangle(a, b, tri.map(p)) {
                count += 1;
            }
        }
    }
    count
}

/// Möller–Trumbore segment–triangle intersection (strictly inside both).
fn segment_crosses_triangle(a: Vec3, b: Vec3, [v0, v1, v2]: [Vec3; 3]) -> bool {
    let dir = b - a;
    let (e1, e2) = (v1 - v0, v2 - v0);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return false;
    }
    let f = 1.0 / det;
    let s = a - v0;
    let u = f * s.dot(h);
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = s.cross(e1);
    let v = f * dir.dot(q);
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let t = f * e2.dot(q);
    t > 0.0 && t < 1.0
}
