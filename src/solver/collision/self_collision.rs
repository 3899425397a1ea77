//! Self-collision: the cloth keeps `thickness` between its vertices and between each vertex
//! and the triangles of other layers, and no vertex passes through a triangle it was in front
//! of when the step began.
//!
//! Once per step, vertices go into a dense spatial hash (cells as wide as the farthest a query
//! reaches; Müller, "Ten Minute Physics" 11) and every vertex collects, in parallel:
//! - the vertices closer than the *reach* (`thickness` plus a margin for the motion during the
//!   step: twice the fastest vertex's travel, at most 1.5 thicknesses), the
//!   [`MAX_SELF_NEIGHBOURS`] lowest-numbered ones;
//! - the triangles closer than the reach, the [`MAX_SELF_TRIANGLES`] lowest-numbered ones, each
//!   with the side of it the vertex is on when the step begins (when the vertex is over the
//!   triangle; otherwise the side is decided when it gets over it). A triangle is found
//!   through its first corner, which lies within the reach plus [`triangle_reach`] of the
//!   vertex; where that corner rests more than 2.5 thicknesses away, only when it is now at
//!   least 10 % closer to the vertex than at rest: the cloth has folded or piled up between
//!   them (a flat or stretched sheet's own distant triangles are never looked at).
//!
//! Parts of the cloth that rest close together (a vertex and a vertex or triangle corner
//! closer than 2.5 thicknesses in the rest shape) are left to the distance and bending
//! constraints: touching would need a fold tighter than bending allows.
//!
//! Each substep then moves every vertex by the mean of its corrections (Jacobi, so every vertex
//! is one independent piece of work on the CPU's threads and one GPU invocation): from each
//! vertex closer than `thickness`, pushed apart along their axis (mass-weighted); from each
//! triangle it is over and closer than `thickness` to *on its side*, pushed out to `thickness`
//! on that side along the triangle's normal, which also brings back a vertex that went
//! through within the step. Both with friction on the sliding. The other party moves by its
//! own lists (the layers push each other apart symmetrically). Cost is linear in the vertex
//! count for a given density.

use glam::{IVec3, Vec3, Vec4, Vec4Swizzles};

use crate::solver::parallel::Parallel;

/// Self-collision settings of one cloth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelfCollision {
    /// Distance kept between the layers of the cloth, in metres. About the edge length works
    /// well: smaller lets edges slip between vertices.
    pub thickness: f32,
    /// Coulomb friction between touching parts of the cloth.
    pub friction: f32,
}

/// Hash table and per-vertex candidate lists, reused between steps.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SelfCollisionScratch {
    start: Vec<u32>,
    entries: Vec<u32>,
    /// Each entry's position and cell, in bucket order (read in sequence by the queries).
    entry_pos: Vec<Vec3>,
    entry_cells: Vec<IVec3>,
    /// Cell of each vertex, to tell it from other cells sharing its bucket.
    cells: Vec<IVec3>,
    /// Triangles by their first corner (offsets per vertex, then triangle indices).
    first_start: Vec<u32>,
    first_tris: Vec<u32>,
    /// Per vertex: its neighbours' count and [`MAX_SELF_NEIGHBOURS`] slots.
    neighbour_count: Vec<u32>,
    neighbours: Vec<u32>,
    /// Per vertex: its triangles' count and [`MAX_SELF_TRIANGLES`] slots (see [`slot`]),
    /// the triangles it is over first.
    triangle_count: Vec<u32>,
    triangles: Vec<u32>,
    corrections: Vec<Vec3>,
}

/// Most vertices a vertex keeps as neighbours (the GPU's fixed-size lists); further ones in a
/// crowded pile are left out.
pub const MAX_SELF_NEIGHBOURS: usize = 32;

/// Most triangles a vertex keeps (the GPU's fixed-size lists).
pub const MAX_SELF_TRIANGLES: usize = 64;

/// Side codes in the low two bits of a triangle slot: the vertex began the step in front of
/// the triangle (along its normal, `(b - a) × (c - a)`), behind it, or beside it (the side is
/// taken from where the vertex is when it comes over the triangle).
pub(crate) const SIDE_FRONT: u32 = 0;
pub(crate) const SIDE_BACK: u32 = 1;
pub(crate) const SIDE_FREE: u32 = 2;

/// Vertices that rest closer than this many thicknesses are left to the cloth's constraints;
/// also the farthest a query's reach goes.
const SKIP: f32 = 2.5;

/// Triangles with a corner resting closer than this many thicknesses to a vertex are left to
/// the constraints (its own ring): a vertex is never over those unless the sheet folds onto
/// itself within an edge or two, which is what the triangle test is for.
const TRIANGLE_SKIP: f32 = 0.5;

/// A triangle whose first corner rests more than 2.5 thicknesses from the vertex is only looked
/// at when that corner is now closer to it than this share of their rest distance: the cloth
/// has folded or piled up between them.
const FOLDED: f32 = 0.9;

/// Vertices handled by one parallel work item.
const CHUNK: usize = 512;

#[inline]
fn cell_of(p: Vec3, inv_cell: f32) -> IVec3 {
    // floor() without a libm call (x86-64's baseline has no rounding instruction):
    // truncate, then step down for negative non-integers.
    let v = p * inv_cell;
    let t = v.as_ivec3();
    t - IVec3::select(t.as_vec3().cmpgt(v), IVec3::ONE, IVec3::ZERO)
}

/// The query's bucket of cell `c` in a table of `mask + 1` (a power of two) buckets.
#[inline]
fn bucket(c: IVec3, mask: usize) -> usize {
    mix(c) & mask
}

/// The cell hash both tables use (the GPU's `sc_hash` mixes the same way).
#[inline]
fn mix(c: IVec3) -> usize {
    let h = (c.x.wrapping_mul(92_837_111))
        ^ (c.y.wrapping_mul(689_287_499))
        ^ (c.z.wrapping_mul(283_923_481));
    h.unsigned_abs() as usize
}

#[inline]
fn hash(c: IVec3, size: usize) -> usize {
    mix(c) % size
}

/// How far past a triangle's nearest point its first corner may lie: the longest rest edge
/// and a quarter for stretch, at most 4 thicknesses (so a mesh with a few long triangles does
/// not make every query cover the whole cloth; a vertex over the middle of a triangle longer
/// than that can be missed, as it is far from all three corners). The GPU backend stores the
/// same value in the cloth's record.
#[must_use]
pub fn triangle_reach(rest: &[Vec3], triangles: &[[u32; 3]], thickness: f32) -> f32 {
    let at = |i: u32| rest.get(i as usize).copied().unwrap_or(Vec3::ZERO);
    let longest2 = triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.map(at);
            [
                a.distance_squared(b),
                b.distance_squared(c),
                c.distance_squared(a),
            ]
        })
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    (1.25 * longest2.sqrt()).min(4.0 * thickness)
}

/// Where `p`'s projection onto the plane of `[a, b, c]` falls: the unit normal, `p`'s signed
/// distance along it, the projection's barycentric weights (all ≥ 0 when it is inside) and
/// twice the triangle's area; `None` for a degenerate triangle. The GPU's `sc_project` does the same operations.
#[inline]
fn project(p: Vec3, [a, b, c]: [Vec3; 3]) -> Option<(Vec3, f32, Vec3, f32)> {
    let e1 = b - a;
    let e2 = c - a;
    let nn = e1.cross(e2);
    let len = nn.length();
    if len.is_nan() || len <= 1e-12 {
        return None;
    }
    let n = nn / len;
    let ap = p - a;
    let d = ap.dot(n);
    let d00 = e1.dot(e1);
    let d01 = e1.dot(e2);
    let d11 = e2.dot(e2);
    let d20 = ap.dot(e1);
    let d21 = ap.dot(e2);
    let denom = d00 * d11 - d01 * d01;
    if denom.is_nan() || denom <= 0.0 {
        return None;
    }
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    Some((n, d, Vec3::new(1.0 - v - w, v, w), len))
}

/// A triangle's slot: `triangle << 2 | side`, with [`BESIDE`] set for a triangle the vertex is
/// not over yet, so that a full list keeps the triangles it is over first.
#[inline]
fn slot(t: u32, code: u32) -> u32 {
    let beside = if code == SIDE_FREE { BESIDE } else { 0 };
    beside | (t << 2) | code
}

/// The high bit of a slot: the vertex is beside the triangle.
const BESIDE: u32 = 1 << 31;

/// Keeps the `max` smallest values of a list in increasing order (insertion, as the GPU does).
#[inline]
fn keep_smallest(list: &mut [u32], count: &mut usize, value: u32) {
    let max = list.len();
    if *count == max && value >= list[max - 1] {
        return;
    }
    let mut k = (*count).min(max - 1);
    while k > 0 && list[k - 1] > value {
        list[k] = list[k - 1];
        k -= 1;
    }
    list[k] = value;
    *count = (*count + 1).min(max);
}

/// What a step's query reads.
struct Query<'a> {
    pos: &'a [Vec4],
    vel: &'a [Vec4],
    dt: f32,
    rest: &'a [Vec3],
    triangles: &'a [[u32; 3]],
    start: &'a [u32],
    entries: &'a [u32],
    entry_pos: &'a [Vec3],
    entry_cells: &'a [IVec3],
    first_start: &'a [u32],
    first_tris: &'a [u32],
    thickness: f32,
    reach: f32,
    radius: f32,
    skip: f32,
    cell: f32,
}

impl Query<'_> {
    /// Vertex `i`'s neighbours and triangles into its slots; returns their counts.
    fn vertex(&self, i: usize, neighbours: &mut [u32], tris: &mut [u32]) -> (usize, usize) {
        let (mut nc, mut tc) = (0, 0);
        let p = self.pos[i].xyz();
        if !p.is_finite() {
            return (0, 0);
        }
        let inv = 1.0 / self.cell;
        let mask = self.start.len() - 2;
        let (r2, big2, skip2) = (
            self.reach * self.reach,
            self.radius * self.radius,
            self.skip * self.skip,
        );
        let rest_i = self.rest[i];
        let tri_skip = TRIANGLE_SKIP * self.thickness;
        let tri_skip2 = tri_skip * tri_skip;
        let margin = self.reach - self.thickness;
        let v = self.vel[i];
        let lo = cell_of(p - Vec3::splat(self.radius), inv);
        let hi = cell_of(p + Vec3::splat(self.radius), inv);
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let cell = IVec3::new(x, y, z);
                    let h = bucket(cell, mask);
                    for k in self.start[h] as usize..self.start[h + 1] as usize {
                        let d2 = self.entry_pos[k].distance_squared(p);
                        let j = self.entries[k] as usize;
                        // Other cells hashed into this bucket are visited through their own
                        // coordinates: each vertex is seen once.
                        if d2.is_nan() || d2 >= big2 || j == i || self.entry_cells[k] != cell {
                            continue;
                        }
                        let rest2 = rest_i.distance_squared(self.rest[j]);
                        if rest2.is_nan() || rest2 <= tri_skip2 {
                            continue;
                        }
                        if d2 < r2 && rest2 > skip2 {
                            keep_smallest(neighbours, &mut nc, j as u32);
                        }
                        // Triangles through a `j` resting farther than 2.5 thicknesses away:
                        // only where the cloth has come closer to itself than it is at rest (a
                        // fold, a pile), never across a flat or stretched sheet, whose own
                        // triangles lie beside its vertices. Nearer ones always (a sharp fold).
                        if rest2 > skip2 && d2 >= FOLDED * FOLDED * rest2 {
                            continue;
                        }
                        let first = &self.first_tris
                            [self.first_start[j] as usize..self.first_start[j + 1] as usize];
                        for &t in first {
                            let tri = self.triangles[t as usize];
                            if !tri[1..].iter().all(|&k| {
                                rest_i.distance_squared(self.rest[k as usize]) > tri_skip2
                            }) {
                                continue;
                            }
                            let corners = tri.map(|k| self.pos[k as usize].xyz());
                            if !corners.iter().all(|c| c.is_finite()) {
                                continue;
                            }
                            // Over the triangle, or beside it by no more than it can slide
                            // over in the step (the sheet's own triangles around the vertex
                            // are beside it, in its plane).
                            let Some((_, d, bary, area2)) = project(p, corners) else {
                                continue;
                            };
                            if d.is_nan() || d.abs() >= self.reach {
                                continue;
                            }
                            let code = if bary.min_element() >= 0.0 {
                                if d >= 0.0 { SIDE_FRONT } else { SIDE_BACK }
                            } else {
                                // How far it can slide over the triangle in the step: the margin;
                                // over its own neighbourhood (which moves with it) twice its
                                // fastest speed relative to a corner and a quarter thickness.
                                let slide = if rest2 > skip2 {
                                    margin
                                } else {
                                    let rel = tri
                                        .iter()
                                        .map(|&k| (self.vel[k as usize] - v).xyz().length_squared())
                                        .fold(0.0f32, f32::max);
                                    (2.0 * self.dt * rel.sqrt() + 0.25 * self.thickness).min(margin)
                                };
                                // At least −(the negative weight) altitudes from the triangle
                                // (an altitude is at least twice the area over the longest
                                // edge): most of a sheet's own triangles end here.
                                let [a, b, c] = corners;
                                let longest2 = a
                                    .distance_squared(b)
                                    .max(b.distance_squared(c))
                                    .max(c.distance_squared(a));
                                let below = -bary.min_element() * area2 / longest2.sqrt();
                                if below > slide {
                                    continue;
                                }
                                let q = super::sdf::closest_point_on_triangle(p, &corners);
                                let near2 = q.distance_squared(p);
                                if !(near2 < r2 && near2 - d * d <= slide * slide) {
                                    continue;
                                }
                                SIDE_FREE
                            };
                            keep_smallest(tris, &mut tc, slot(t, code));
                        }
                    }
                }
            }
        }
        (nc, tc)
    }
}

/// One parallel work item of the query: a run of vertices and their slots.
struct QueryChunk<'a> {
    first: usize,
    neighbour_count: &'a mut [u32],
    neighbours: &'a mut [u32],
    triangle_count: &'a mut [u32],
    triangles: &'a mut [u32],
}

impl SelfCollisionScratch {
    /// Fills the hash with the current positions and every vertex's lists (see the module
    /// docs), the vertices in parallel.
    #[expect(clippy::too_many_arguments)]
    fn find(
        &mut self,
        pos: &[Vec4],
        vel: &[Vec4],
        dt: f32,
        rest: &[Vec3],
        triangles: &[[u32; 3]],
        thickness: f32,
        reach: f32,
        par: &impl Parallel,
    ) {
        let skip = SKIP * thickness;
        let tri_reach = triangle_reach(rest, triangles, thickness);
        // Cells as wide as the farthest query (the reach is at most 2.5 thicknesses), in a
        // power-of-two table (a bucket is a mask).
        let cell = skip + tri_reach;
        let n = pos.len();
        let size = (2 * n).next_power_of_two().max(2);
        let mask = size - 1;
        let inv = 1.0 / cell;
        self.start.clear();
        self.start.resize(size + 1, 0);
        self.entries.resize(n, 0);
        self.entry_pos.resize(n, Vec3::ZERO);
        self.entry_cells.resize(n, IVec3::ZERO);
        self.cells.clear();
        self.cells.extend(pos.iter().map(|p| cell_of(p.xyz(), inv)));
        for (p, c) in pos.iter().zip(&self.cells) {
            if p.xyz().is_finite() {
                self.start[bucket(*c, mask)] += 1;
            }
        }
        let mut acc = 0;
        for s in &mut self.start {
            acc += *s;
            *s = acc;
        }
        for (i, p) in pos.iter().enumerate() {
            if p.xyz().is_finite() {
                let h = bucket(self.cells[i], mask);
                self.start[h] -= 1;
                let k = self.start[h] as usize;
                self.entries[k] = i as u32;
                self.entry_pos[k] = p.xyz();
                self.entry_cells[k] = self.cells[i];
            }
        }
        // Triangles by first corner, in triangle order.
        self.first_start.clear();
        self.first_start.resize(n + 1, 0);
        let valid = |t: &[u32; 3]| t.iter().all(|&k| (k as usize) < n);
        for t in triangles.iter().filter(|t| valid(t)) {
            self.first_start[t[0] as usize + 1] += 1;
        }
        for k in 0..n {
            self.first_start[k + 1] += self.first_start[k];
        }
        self.first_tris.resize(self.first_start[n] as usize, 0);
        let mut fill = self.first_start.clone();
        for (ti, t) in triangles.iter().enumerate().filter(|(_, t)| valid(t)) {
            let at = &mut fill[t[0] as usize];
            self.first_tris[*at as usize] = ti as u32;
            *at += 1;
        }

        self.neighbour_count.clear();
        self.neighbour_count.resize(n, 0);
        self.neighbours.resize(n * MAX_SELF_NEIGHBOURS, 0);
        self.triangle_count.clear();
        self.triangle_count.resize(n, 0);
        self.triangles.resize(n * MAX_SELF_TRIANGLES, 0);
        let query = Query {
            pos,
            vel,
            dt,
            rest,
            triangles,
            start: &self.start,
            entries: &self.entries,
            entry_pos: &self.entry_pos,
            entry_cells: &self.entry_cells,
            first_start: &self.first_start,
            first_tris: &self.first_tris,
            thickness,
            reach,
            radius: reach + tri_reach,
            skip,
            cell,
        };
        let mut chunks: Vec<QueryChunk> = self
            .neighbour_count
            .chunks_mut(CHUNK)
            .zip(self.neighbours.chunks_mut(CHUNK * MAX_SELF_NEIGHBOURS))
            .zip(self.triangle_count.chunks_mut(CHUNK))
            .zip(self.triangles.chunks_mut(CHUNK * MAX_SELF_TRIANGLES))
            .enumerate()
            .map(|(k, (((nc, nl), tc), tl))| QueryChunk {
                first: k * CHUNK,
                neighbour_count: nc,
                neighbours: nl,
                triangle_count: tc,
                triangles: tl,
            })
            .collect();
        par.for_each_mut(&mut chunks, |c| {
            for k in 0..c.neighbour_count.len() {
                let (nc, tc) = query.vertex(
                    c.first + k,
                    &mut c.neighbours[k * MAX_SELF_NEIGHBOURS..(k + 1) * MAX_SELF_NEIGHBOURS],
                    &mut c.triangles[k * MAX_SELF_TRIANGLES..(k + 1) * MAX_SELF_TRIANGLES],
                );
                c.neighbour_count[k] = nc as u32;
                c.triangle_count[k] = tc as u32;
            }
        });
    }
}

/// Query distance: `thickness` plus a margin for the step's motion; `None` when off.
fn reach(vel: &[Vec4], params: SelfCollision, dt: f32) -> Option<f32> {
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
    Some(thickness + margin)
}

/// Coulomb friction on a contact pushed `push` along `n`: the tangential part of `slide` and
/// the share of it to take back (at most all of it); `None` when nothing slides.
#[inline]
fn sliding(slide: Vec3, n: Vec3, push: f32, friction: f32) -> Option<(Vec3, f32)> {
    let tangential = slide - n * n.dot(slide);
    let t_len = tangential.length();
    (t_len > 0.0).then(|| (tangential, (friction * push / t_len).min(1.0)))
}

/// The correction of vertex `a` (with `prev_a`) from its pair with `b`: pushed apart to
/// `thickness`, mass-weighted, with friction on the pair's sliding. `None` when the pair does
/// not touch or the result is not finite.
#[inline]
fn pair_correction(
    a: Vec4,
    prev_a: Vec4,
    b: Vec4,
    prev_b: Vec4,
    params: SelfCollision,
) -> Option<Vec3> {
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
    let db = -n * (push * wb / w);
    // Friction on the relative sliding of the pair during the substep.
    let slide = (a.xyz() + da - prev_a.xyz()) - (b.xyz() + db - prev_b.xyz());
    if let Some((tangential, keep)) = sliding(slide, n, push, params.friction) {
        da -= tangential * (keep * wa / w);
    }
    da.is_finite().then_some(da)
}

/// The correction of vertex `a` (with `prev_a`) from a triangle (`x`, `prev_x`) and the side
/// code it keeps to: when `a` is over the triangle and closer than `thickness` on its side, or
/// through it to the other side (by less than 2.5 thicknesses), pushed out to `thickness` on
/// its side along the normal, its share by the inverse masses (the triangle's at the point
/// under `a`), with friction on the sliding. `None` when it does not touch.
#[inline]
fn triangle_correction(
    a: Vec4,
    prev_a: Vec4,
    x: [Vec4; 3],
    prev_x: [Vec4; 3],
    code: u32,
    params: SelfCollision,
) -> Option<Vec3> {
    let wa = a.w;
    if wa.is_nan() || wa <= 0.0 {
        return None;
    }
    let (n, d, bary, _) = project(a.xyz(), x.map(|v| v.xyz()))?;
    if bary.min_element() < 0.0 {
        return None;
    }
    let side = match code {
        SIDE_FRONT => 1.0,
        SIDE_BACK => -1.0,
        _ => {
            if d >= 0.0 {
                1.0
            } else {
                -1.0
            }
        }
    };
    let thickness = params.thickness;
    let ds = side * d;
    if ds >= thickness || ds <= -SKIP * thickness {
        return None;
    }
    let wt = bary.x * x[0].w + bary.y * x[1].w + bary.z * x[2].w;
    let share = wa / (wa + wt);
    let push = thickness - ds;
    let mut da = n * (side * push * share);
    let q = x[0].xyz() * bary.x + x[1].xyz() * bary.y + x[2].xyz() * bary.z;
    let q_prev = prev_x[0].xyz() * bary.x + prev_x[1].xyz() * bary.y + prev_x[2].xyz() * bary.z;
    let slide = (a.xyz() + da - prev_a.xyz()) - (q - q_prev);
    if let Some((tangential, keep)) = sliding(slide, n, push, params.friction) {
        da -= tangential * (keep * share);
    }
    da.is_finite().then_some(da)
}

/// One parallel work item of a pass: a run of vertices' corrections.
struct PassChunk<'a> {
    first: usize,
    corrections: &'a mut [Vec3],
}

/// One self-collision pass (Jacobi): every vertex sums its corrections from its touching
/// neighbours and triangles against the positions before the pass, divided by their number,
/// and all vertices move at once (`prev`: positions at the substep's start). The vertices run
/// in parallel; the result does not depend on how they are split.
pub(crate) fn self_collide(
    pos: &mut [Vec4],
    prev: &[Vec4],
    triangles: &[[u32; 3]],
    params: SelfCollision,
    scratch: &mut SelfCollisionScratch,
    par: &impl Parallel,
) {
    let n = pos.len();
    if scratch.neighbour_count.len() != n || scratch.triangle_count.len() != n {
        return;
    }
    scratch.corrections.clear();
    scratch.corrections.resize(n, Vec3::ZERO);
    let (nc, nl) = (&scratch.neighbour_count, &scratch.neighbours);
    let (tc, tl) = (&scratch.triangle_count, &scratch.triangles);
    let read: &[Vec4] = pos;
    let mut chunks: Vec<PassChunk> = scratch
        .corrections
        .chunks_mut(CHUNK)
        .enumerate()
        .map(|(k, corrections)| PassChunk {
            first: k * CHUNK,
            corrections,
        })
        .collect();
    par.for_each_mut(&mut chunks, |c| {
        for (k, out) in c.corrections.iter_mut().enumerate() {
            let i = c.first + k;
            let (a, prev_a) = (read[i], prev[i]);
            let mut sum = Vec3::ZERO;
            let mut touching = 0u32;
            let count = nc[i] as usize;
            for &j in &nl[i * MAX_SELF_NEIGHBOURS..i * MAX_SELF_NEIGHBOURS + count] {
                let j = j as usize;
                if let Some(da) = pair_correction(a, prev_a, read[j], prev[j], params) {
                    sum += da;
                    touching += 1;
                }
            }
            let count = tc[i] as usize;
            for &slot in &tl[i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count] {
                let Some(tri) = triangles.get(((slot & !BESIDE) >> 2) as usize) else {
                    continue;
                };
                let x = tri.map(|v| read[v as usize]);
                let px = tri.map(|v| prev[v as usize]);
                if let Some(da) = triangle_correction(a, prev_a, x, px, slot & 3, params) {
                    sum += da;
                    touching += 1;
                }
            }
            if touching > 0 {
                *out = sum / touching as f32;
            }
        }
    });
    drop(chunks);
    for (x, c) in pos.iter_mut().zip(&scratch.corrections) {
        *x += c.extend(0.0);
    }
}

/// Collects the candidates for this step: vertices and triangles closer than `thickness` plus
/// a margin for how far they can move in `dt` (see the module docs), as per-vertex lists for
/// [`self_collide`] (the GPU kernels' CPU twin).
#[expect(clippy::too_many_arguments)]
pub(crate) fn find_self_collision_candidates(
    pos: &[Vec4],
    vel: &[Vec4],
    rest: &[Vec3],
    triangles: &[[u32; 3]],
    params: SelfCollision,
    dt: f32,
    scratch: &mut SelfCollisionScratch,
    par: &impl Parallel,
) {
    if let Some(reach) = reach(vel, params, dt) {
        scratch.find(pos, vel, dt, rest, triangles, params.thickness, reach, par);
    } else {
        scratch.neighbour_count.clear();
        scratch.neighbour_count.resize(pos.len(), 0);
        scratch.triangle_count.clear();
        scratch.triangle_count.resize(pos.len(), 0);
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
    use crate::solver::parallel::Serial;

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
            &[],
            params,
            1.0 / 60.0,
            &mut s,
            &Serial,
        );
        self_collide(&mut pos, &prev, &[], params, &mut s, &Serial);
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
            &[],
            params,
            1.0 / 60.0,
            &mut s,
            &Serial,
        );
        self_collide(&mut pos, &prev, &[], params, &mut s, &Serial);
        assert_eq!(pos, prev);
    }

    #[test]
    fn a_vertex_is_kept_on_its_side_of_a_triangle() {
        // A triangle in the XY plane and a vertex over it, far away along the cloth.
        let tri = [[0u32, 1, 2]];
        let rest = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z * 10.0];
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        let start = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 1.0, 0.0, 1.0),
            Vec4::new(0.25, 0.25, 0.02, 1.0),
        ];
        let mut s = SelfCollisionScratch::default();
        find_self_collision_candidates(
            &start,
            &[Vec4::ZERO; 4],
            &rest,
            &tri,
            params,
            1.0 / 60.0,
            &mut s,
            &Serial,
        );
        assert_eq!(s.triangle_count[3], 1);
        assert_eq!(s.triangles[3 * MAX_SELF_TRIANGLES], SIDE_FRONT);
        // Too close on its side: pushed out along +z, its share half the push (equal masses).
        let mut pos = start.clone();
        self_collide(&mut pos, &start, &tri, params, &mut s, &Serial);
        assert!((pos[3].z - 0.06).abs() < 1e-6, "{}", pos[3]);
        // Went through during the substep: brought back to its side.
        let mut pos = start.clone();
        pos[3].z = -0.05;
        self_collide(&mut pos, &start, &tri, params, &mut s, &Serial);
        assert!((pos[3].z - (-0.05 + 0.075)).abs() < 1e-6, "{}", pos[3]);
        // The triangle's corners are moved by their own lists (they have none here).
        assert_eq!(&pos[..3], &start[..3]);
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
