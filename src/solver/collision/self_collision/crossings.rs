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
    // Uniform grid over triangle bounding boxes, cells of about the mean edge length, its
    // buckets laid out one after another (counted, then filled).
    let mean_edge =
        edges.iter().map(|e| p(e[0]).distance(p(e[1]))).sum::<f32>() / edges.len() as f32;
    let cell = mean_edge.max(1e-6) * 2.0;
    let inv = Vec3::splat(1.0 / cell);
    let size = triangles.len() * 4;
    // Each triangle's bounding box, padded past what rounding could move a crossing by: an
    // edge whose box misses it cannot cross it (most of those in a pile's buckets).
    let boxes: Vec<Option<(Vec3, Vec3)>> = triangles
        .iter()
        .map(|tri| {
            let [a, b, c] = tri.map(p);
            (a.is_finite() && b.is_finite() && c.is_finite()).then(|| {
                let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                let pad = 1e-4 * cell + 1e-6 * lo.abs().max(hi.abs()).max_element();
                (lo - Vec3::splat(pad), hi + Vec3::splat(pad))
            })
        })
        .collect();
    let each_cell = |(lo, hi): (Vec3, Vec3), f: &mut dyn FnMut(usize)| {
        let (lo, hi) = (cell_of(lo, inv), cell_of(hi, inv));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    f(hash(IVec3::new(x, y, z), size));
                }
            }
        }
    };
    let mut start = vec![0usize; size + 1];
    for b in boxes.iter().flatten() {
        each_cell(*b, &mut |k| start[k + 1] += 1);
    }
    for k in 0..size {
        start[k + 1] += start[k];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; start[size]];
    for (t, b) in boxes.iter().enumerate() {
        if let Some(b) = b {
            each_cell(*b, &mut |k| {
                items[fill[k]] = t as u32;
                fill[k] += 1;
            });
        }
    }
    // Each edge tests each triangle in the buckets its box covers once: `seen[t]` holds the
    // last edge (plus one) that tested triangle `t`.
    let mut seen = vec![0u32; triangles.len()];
    let mut count = 0;
    for (k, e) in edges.iter().enumerate() {
        let (a, b) = (p(e[0]), p(e[1]));
        if !(a.is_finite() && b.is_finite()) {
            continue;
        }
        let stamp = k as u32 + 1;
        each_cell((a.min(b), a.max(b)), &mut |bucket| {
            for &t in &items[start[bucket]..start[bucket + 1]] {
                if seen[t as usize] == stamp {
                    continue;
                }
                seen[t as usize] = stamp;
                let Some((lo, hi)) = boxes[t as usize] else {
                    continue;
                };
                if lo.cmpgt(a.max(b)).any() || hi.cmplt(a.min(b)).any() {
                    continue;
                }
                let tri = triangles[t as usize];
                if !(tri.contains(&e[0]) || tri.contains(&e[1]))
                    && segment_crosses_triangle(a, b, tri.map(p))
                {
                    count += 1;
                }
            }
        });
    }
    count
}

/// Möller–Trumbore segment–triangle intersection (strictly inside both).
pub(super) fn segment_crosses_triangle(a: Vec3, b: Vec3, [v0, v1, v2]: [Vec3; 3]) -> bool {
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
