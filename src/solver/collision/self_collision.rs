//! Self-collision: vertices of one cloth keep a minimum distance from each other.
//!
//! Once per step, vertices go into a dense spatial hash (cells of the query distance, counting
//! sort into a table of twice the vertex count; Müller, "Ten Minute Physics" 11) and every
//! vertex collects the vertices in the (at most 8) cells its query ball touches that are closer than `thickness`
//! plus a margin for the motion during the step (twice the fastest vertex's travel, at most
//! 1.5 thicknesses). Topological neighbours, vertices that rest closer than 2.5 thicknesses,
//! are skipped: their distance and bending constraints keep them apart, and touching would
//! need a fold tighter than bending allows. Each substep then walks only the candidate pairs:
//! each pair closer than `thickness` is pushed apart along its axis, mass-weighted, with
//! friction on the pair's relative sliding. Cost is
//! linear in the vertex count for a given density.

use glam::{IVec3, Vec3, Vec4, Vec4Swizzles};

/// Self-collision settings of one cloth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelfCollision {
    /// Distance kept between any two vertices, in metres. About the edge length works well:
    /// smaller lets edges slip between vertices.
    pub thickness: f32,
    /// Coulomb friction between touching parts of the cloth.
    pub friction: f32,
}

/// Hash table and candidate pairs, reused between substeps.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SelfCollisionScratch {
    start: Vec<u32>,
    entries: Vec<u32>,
    /// Cell of each vertex, to tell it from other cells sharing its bucket.
    cells: Vec<IVec3>,
    pairs: Vec<(u32, u32)>,
    /// The parallel form (see [`self_collide_parallel`]): per vertex its neighbours' count,
    /// and [`MAX_SELF_NEIGHBOURS`] slots each.
    neighbour_count: Vec<u32>,
    neighbours: Vec<u32>,
    corrections: Vec<Vec3>,
}

/// Most neighbours a vertex keeps in the parallel self-collision (the GPU's fixed-size lists);
/// further ones in a crowded pile are left out.
pub const MAX_SELF_NEIGHBOURS: usize = 32;

#[inline]
fn cell_of(p: Vec3, inv_cell: f32) -> IVec3 {
    // floor() without a libm call (x86-64's baseline has no rounding instruction):
    // truncate, then step down for negative non-integers.
    let v = p * inv_cell;
    let t = v.as_ivec3();
    t - IVec3::select(t.as_vec3().cmpgt(v), IVec3::ONE, IVec3::ZERO)
}

#[inline]
fn hash(c: IVec3, size: usize) -> usize {
    let h = (c.x.wrapping_mul(92_837_111))
        ^ (c.y.wrapping_mul(689_287_499))
        ^ (c.z.wrapping_mul(283_923_481));
    (h.unsigned_abs() as usize) % size
}

impl SelfCollisionScratch {
    /// Fills the hash with the current positions and collects the pairs closer than `reach`,
    /// leaving out neighbours that rest closer than `skip` (their distance constraints keep
    /// them apart).
    fn find_pairs(&mut self, pos: &[Vec4], rest: &[Vec3], reach: f32, skip: f32) {
        let n = pos.len();
        let size = (2 * n).max(1);
        let inv = 1.0 / reach;
        self.start.clear();
        self.start.resize(size + 1, 0);
        self.entries.resize(n, 0);
        self.cells.clear();
        self.cells.extend(pos.iter().map(|p| cell_of(p.xyz(), inv)));
        for (p, c) in pos.iter().zip(&self.cells) {
            if p.xyz().is_finite() {
                self.start[hash(*c, size)] += 1;
            }
        }
        let mut acc = 0;
        for s in &mut self.start {
            acc += *s;
            *s = acc;
        }
        for (i, p) in pos.iter().enumerate() {
            if p.xyz().is_finite() {
                let h = hash(self.cells[i], size);
                self.start[h] -= 1;
                self.entries[self.start[h] as usize] = i as u32;
            }
        }
        self.pairs.clear();
        let r2 = reach * reach;
        let skip2 = skip * skip;
        for (i, p) in pos.iter().enumerate() {
            let p = p.xyz();
            if !p.is_finite() {
                continue;
            }
            // Cells are `reach` wide: the query ball touches at most 2 of them per axis.
            let lo = cell_of(p - Vec3::splat(reach), inv);
            let hi = cell_of(p + Vec3::splat(reach), inv);
            for z in lo.z..=hi.z {
                for y in lo.y..=hi.y {
                    for x in lo.x..=hi.x {
                        let cell = IVec3::new(x, y, z);
                        let h = hash(cell, size);
                        for &j in &self.entries[self.start[h] as usize..self.start[h + 1] as usize]
                        {
                            let j = j as usize;
                            // Other cells hashed into this bucket are visited through their
                            // own coordinates: counting each vertex once needs no dedup.
                            if j > i
                                && self.cells[j] == cell
                                && pos[j].xyz().distance_squared(p) < r2
                                && rest[i].distance_squared(rest[j]) > skip2
                            {
                                self.pairs.push((i as u32, j as u32));
                            }
                        }
                    }
                }
            }
        }
    }
}

impl SelfCollisionScratch {
    /// The parallel form of [`Self::find_pairs`]: every vertex lists each other vertex it
    /// would pair with (so a pair appears in both lists), the [`MAX_SELF_NEIGHBOURS`]
    /// lowest-numbered ones in increasing order (the GPU keeps the same ones, so both sum
    /// the same corrections in the same order, whatever order the hash found them in).
    fn find_neighbours(&mut self, pos: &[Vec4], rest: &[Vec3], reach: f32, skip: f32) {
        self.find_pairs(pos, rest, reach, skip);
        let n = pos.len();
        // Every candidate of every vertex, grouped by vertex, then sorted and cut.
        let mut start = vec![0u32; n + 1];
        for &(i, j) in &self.pairs {
            start[i as usize + 1] += 1;
            start[j as usize + 1] += 1;
        }
        for k in 0..n {
            start[k + 1] += start[k];
        }
        let mut all = vec![0u32; start[n] as usize];
        let mut fill = start.clone();
        for &(i, j) in &self.pairs {
            for (a, b) in [(i, j), (j, i)] {
                all[fill[a as usize] as usize] = b;
                fill[a as usize] += 1;
            }
        }
        self.neighbour_count.clear();
        self.neighbour_count.resize(n, 0);
        self.neighbours.resize(n * MAX_SELF_NEIGHBOURS, 0);
        for v in 0..n {
            let list = &mut all[start[v] as usize..start[v + 1] as usize];
            list.sort_unstable();
            let kept = list.len().min(MAX_SELF_NEIGHBOURS);
            self.neighbours[v * MAX_SELF_NEIGHBOURS..v * MAX_SELF_NEIGHBOURS + kept]
                .copy_from_slice(&list[..kept]);
            self.neighbour_count[v] = kept as u32;
        }
        self.pairs.clear();
    }
}

/// Query distance (`thickness` plus a margin for the step's motion) and the rest distance
/// under which vertices are left to their constraints; `None` when off.
fn reach_and_skip(vel: &[Vec4], params: SelfCollision, dt: f32) -> Option<(f32, f32)> {
    let thickness = params.thickness;
    if !(thickness.is_finite() && thickness > 0.0) {
        return None;
    }
    let fastest = vel
        .iter()
        .map(|v| v.xyz().length_squared())
        .filter(|s| s.is_finite())
        .fold(0.0f32, f32::max)
        .sqrt();
    let margin = (2.0 * fastest * dt).min(1.5 * thickness);
    Some((thickness + margin, 2.5 * thickness))
}

/// The correction of vertex `a` (with `prev_a`) from its pair with `b`: pushed apart to
/// `thickness`, mass-weighted, with friction on the pair's sliding. `None` when the pair does
/// not touch or the result is not finite. Both self-collision passes use it.
#[inline]
fn pair_correction(
    a: Vec4,
    prev_a: Vec4,
    b: Vec4,
    prev_b: Vec4,
    params: SelfCollision,
) -> Option<(Vec3, Vec3)> {
    let limit = params.thickness;
    let (wa, wb) = (a.w, b.w);
    let w = wa + wb;
    if w <= 0.0 {
        return None;
    }
    let d = a.xyz() - b.xyz();
    let len = d.length();
    if len >= limit || len <= 1e-9 {
        return None;
    }
    let n = d / len;
    let push = limit - len;
    let mut da = n * (push * wa / w);
    let mut db = -n * (push * wb / w);
    // Friction on the relative sliding of the pair during the substep.
    let slide = (a.xyz() + da - prev_a.xyz()) - (b.xyz() + db - prev_b.xyz());
    let tangential = slide - n * n.dot(slide);
    let t_len = tangential.length();
    if t_len > 0.0 {
        let keep = (params.friction * push / t_len).min(1.0);
        da -= tangential * (keep * wa / w);
        db += tangential * (keep * wb / w);
    }
    (da.is_finite() && db.is_finite()).then_some((da, db))
}

/// Self-collision as the GPU runs it (Jacobi): every vertex sums its corrections from all its
/// touching neighbours against the positions before the pass, divided by their number, and
/// all vertices move at once. Pair by pair ([`self_collide`]) converges a little faster; this
/// form needs no ordering, so every vertex is one GPU invocation.
pub(crate) fn self_collide_parallel(
    pos: &mut [Vec4],
    prev: &[Vec4],
    params: SelfCollision,
    scratch: &mut SelfCollisionScratch,
) {
    let n = pos.len();
    if scratch.neighbour_count.len() != n {
        return;
    }
    scratch.corrections.clear();
    scratch.corrections.resize(n, Vec3::ZERO);
    for i in 0..n {
        let count = scratch.neighbour_count[i] as usize;
        let mut sum = Vec3::ZERO;
        let mut touching = 0u32;
        for &j in &scratch.neighbours[i * MAX_SELF_NEIGHBOURS..i * MAX_SELF_NEIGHBOURS + count] {
            let j = j as usize;
            if let Some((da, _)) = pair_correction(pos[i], prev[i], pos[j], prev[j], params) {
                sum += da;
                touching += 1;
            }
        }
        if touching > 0 {
            scratch.corrections[i] = sum / touching as f32;
        }
    }
    for (x, c) in pos.iter_mut().zip(&scratch.corrections) {
        *x += c.extend(0.0);
    }
}

/// Collects the candidates for this step: vertices closer than `thickness` plus a margin for
/// how far they can move in `dt` (see the module docs), as pairs for [`self_collide`] or, with
/// `parallel`, as per-vertex neighbour lists for [`self_collide_parallel`] (the GPU kernels'
/// CPU twin).
pub(crate) fn find_self_collision_candidates(
    pos: &[Vec4],
    vel: &[Vec4],
    rest: &[Vec3],
    params: SelfCollision,
    dt: f32,
    parallel: bool,
    scratch: &mut SelfCollisionScratch,
) {
    match (reach_and_skip(vel, params, dt), parallel) {
        (Some((reach, skip)), true) => scratch.find_neighbours(pos, rest, reach, skip),
        (Some((reach, skip)), false) => scratch.find_pairs(pos, rest, reach, skip),
        (None, true) => {
            scratch.neighbour_count.clear();
            scratch.neighbour_count.resize(pos.len(), 0);
        }
        (None, false) => scratch.pairs.clear(),
    }
}

/// One self-collision pass over the candidate pairs (`prev`: positions at the substep's
/// start).
pub(crate) fn self_collide(
    pos: &mut [Vec4],
    prev: &[Vec4],
    params: SelfCollision,
    scratch: &SelfCollisionScratch,
) {
    let thickness = params.thickness;
    if !(thickness.is_finite() && thickness > 0.0) {
        return;
    }
    for &(i, j) in &scratch.pairs {
        let (i, j) = (i as usize, j as usize);
        if let Some((da, db)) = pair_correction(pos[i], prev[i], pos[j], prev[j], params) {
            pos[i] += da.extend(0.0);
            pos[j] += db.extend(0.0);
        }
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_vertices_are_pushed_apart_to_thickness() {
        let mut pos = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 0.01, 0.0, 1.0),
            Vec4::new(5.0, 0.0, 0.0, 1.0),
        ];
        let prev = pos.clone();
        let rest = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        let mut s = SelfCollisionScratch::default();
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        find_self_collision_candidates(
            &pos,
            &[Vec4::ZERO; 3],
            &rest,
            params,
            1.0 / 60.0,
            false,
            &mut s,
        );
        self_collide(&mut pos, &prev, params, &s);
        assert!((pos[0].xyz().distance(pos[1].xyz()) - 0.1).abs() < 1e-6);
        assert_eq!(pos[2], prev[2]);
        // Equal masses: symmetric push.
        assert!((pos[0].y + 0.045).abs() < 1e-6 && (pos[1].y - 0.055).abs() < 1e-6);
    }

    #[test]
    fn neighbours_resting_within_two_thicknesses_are_left_to_their_constraints() {
        let mut pos = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(0.05, 0.0, 0.0, 1.0),
        ];
        let prev = pos.clone();
        let rest = [Vec3::ZERO, Vec3::X * 0.05];
        let mut s = SelfCollisionScratch::default();
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        find_self_collision_candidates(
            &pos,
            &[Vec4::ZERO; 2],
            &rest,
            params,
            1.0 / 60.0,
            false,
            &mut s,
        );
        self_collide(&mut pos, &prev, params, &s);
        assert_eq!(pos, prev);
    }

    #[test]
    fn cell_of_is_floor() {
        for x in [-2.5f32, -1.0, -0.5, 0.0, 0.5, 1.0, 2.5, -0.0001] {
            let c = cell_of(Vec3::new(x, -x, x * 3.0), 1.0);
            assert_eq!(
                c,
                IVec3::new(
                    x.floor() as i32,
                    (-x).floor() as i32,
                    (x * 3.0).floor() as i32
                ),
                "{x}"
            );
        }
    }

    #[test]
    fn crossings_are_counted() {
        // A triangle in the XY plane and an edge through it along z, and one beside it.
        let pos: Vec<Vec4> = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.2, 0.2, -1.0),
            Vec3::new(0.2, 0.2, 1.0),
            Vec3::new(2.0, 2.0, -1.0),
            Vec3::new(2.0, 2.0, 1.0),
        ]
        .iter()
        .map(|p| p.extend(1.0))
        .collect();
        let tris = [[0, 1, 2]];
        assert_eq!(count_self_crossings(&pos, &tris, &[[3, 4], [5, 6]]), 1);
        // Edges touching the triangle's own vertices never count.
        assert_eq!(count_self_crossings(&pos, &tris, &[[0, 4]]), 0);
    }
}
