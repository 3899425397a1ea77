//! Self-collision: the cloth keeps `thickness` between its vertices and between each vertex
//! and the triangles of other layers, and no vertex passes through a triangle it was in front
//! of when the step began.
//!
//! On a mesh of uneven edges each vertex keeps its own thickness, `thickness` times its
//! [`Topology::self_collision_scales`](crate::solver::Topology::self_collision_scales);
//! everything below that says *thickness* is then the querying or correcting vertex's own. On
//! an even mesh (no scales) every vertex keeps `thickness`. From triangles a vertex of an
//! uneven mesh keeps at most [`SHORT_EDGE_THICKNESS`](crate::solver::SHORT_EDGE_THICKNESS)
//! of its shortest rest edge
//! ([`Topology::self_collision_triangle_scales`](crate::solver::Topology::self_collision_triangle_scales)):
//! where the mesh is finer one way than the other, the triangles one short edge beyond its
//! own lie within its thickness, and holding it a whole thickness off them tears the cloth.
//!
//! Once per step, vertices go into a dense spatial hash (Müller, "Ten Minute Physics" 11) and
//! every vertex collects, in parallel:
//! - the vertices closer than the *reach* (`thickness` plus a margin for the motion during the
//!   step: twice the fastest vertex's travel, at most 1.5 thicknesses), the
//!   [`MAX_SELF_NEIGHBOURS`] lowest-numbered ones;
//! - the triangles closer than the reach, the [`MAX_SELF_TRIANGLES`] lowest-numbered ones, each
//!   with the side of it the vertex is on when the step begins (when the vertex is over the
//!   triangle; otherwise the side is decided when it gets over it). A triangle is found
//!   through its first corner, which lies within the reach plus [`triangle_reach`] (the
//!   query's *radius*) of the vertex. Where that corner rests more than 2.5 thicknesses away,
//!   only when it is now at least 10 % closer to the vertex than at rest: the cloth has folded
//!   or piled up between them (a flat or stretched sheet's own distant triangles are never
//!   looked at). Where it rests nearer (the vertex's own neighbourhood), only when the
//!   neighbourhood has *folded*: one of its vertices within the radius is now, or two steps
//!   on at the velocities the step begins with, at least 3 % closer to the vertex than at
//!   rest. A sheet lying flat, stretched or curving gently around a vertex does not bring its
//!   own triangles over it within the step; testing them anyway cost five times the rest of
//!   the query.
//!
//! The triangles by first corner and the longest rest edge depend on the mesh alone: they are
//! kept from step to step (rebuilt when the triangles or rest positions differ, as after a
//! tear). The grid is made in parallel: the vertices' buckets, their order (a counting sort
//! by runs of vertices, then by bins of buckets, which gives the same order on any number of
//! threads; within a bucket by x) and its lanes, one lane a work item.
//!
//! The CPU's hash keeps the cells of a row along x in consecutive buckets and the positions,
//! rest positions and positions two steps ahead in separate lanes, and a bucket's entries
//! in order of x, so that a query reads a few runs of entries in sequence (a row's ends
//! beyond its x range left out) and tests eight at a time (vectorised), in one walk: the
//! groups of eight holding some of the vertex's own neighbourhood are kept for the fold test
//! and its triangles after it, and a triangle is first tested against a bound from its
//! centroid (most of those looked at lie beside the vertex, farther than it can slide)
//! before it is projected. The GPU's (`contact.wgsl`, `sc_query`) is a linked list per bucket.
//! Both find the same vertices and triangles and keep the same lowest-numbered ones.
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
//! through within the step. Both with friction on the sliding, and both undoing all of what
//! the pair closed within the substep but at most [`DEPENETRATION`] thicknesses of an overlap
//! the substep began with (a vertex found deep in or through a layer comes out over a few
//! substeps instead of jumping out at once). A vertex pair's other vertex moves by its own
//! list (the pair pushes both apart). A triangle the vertex was over when the step began
//! takes the reaction at its corners (`−Δa · w_c b_c / wₐ`, `b_c` the corner's weight at the
//! point under the vertex), so that the contact moves no momentum: without it a pile of cloth
//! pushed itself along the floor and never came to rest (docs/experiments.md). The reactions
//! are summed per corner in fixed point ([`REACTION_UNITS`] a metre, atomics on the threads),
//! so their sum does not depend on the order they arrive in, and count in the corner's mean
//! like its own contacts. A triangle the vertex came over within the step (beside it when the
//! lists were made) takes none: with those too, crumpled cloths of uneven edges ended tangled
//! more often. A triangle sits in many
//! vertices' lists, so a pass makes the plane of each listed triangle once (the query marks
//! them in a bitmap as it lists them) and a vertex beside a triangle costs one projection;
//! the same operations as projecting per vertex, so the same bits as the GPU's, which
//! projects per vertex. Cost is linear in the vertex count for a given density.

use std::ops::Range;
use std::sync::atomic::{AtomicI32, AtomicU32, Ordering};

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
    grid: Grid,
    /// What depends on the mesh alone, kept while the mesh stays the same.
    mesh: MeshLists,
    /// Every triangle's [`Frame`] at the step's start.
    frames: Vec<Frame>,
    /// Per vertex: its neighbours' count and [`MAX_SELF_NEIGHBOURS`] slots.
    neighbour_count: Vec<u32>,
    neighbours: Vec<u32>,
    /// Per vertex: its triangles' count and [`MAX_SELF_TRIANGLES`] slots (see [`slot`]),
    /// the triangles it is over first.
    triangle_count: Vec<u32>,
    triangles: Vec<u32>,
    /// The vertices with something in their lists (a fifth of a crumpled cloth's): the only
    /// ones a pass looks at.
    active: Vec<u32>,
    /// Per active vertex, the sum of its own contacts' corrections in the current pass and
    /// their number.
    corrections: Vec<Vec3>,
    touching: Vec<u32>,
    /// Per vertex, the reactions of the vertex–triangle contacts it is a corner of.
    reactions: Reactions,
    /// The triangles in some vertex's list: one bit a triangle, and per word of bits the
    /// number set before it (a listed triangle's place among them, see [`Listed::rank`]).
    listed: Listed,
    /// The listed triangles' [`Plane`]s at the current pass's start, in triangle order.
    pass_planes: Vec<Plane>,
}

/// Per vertex, the reactions a pass's vertex–triangle contacts give the triangles' corners,
/// summed in fixed point ([`REACTION_UNITS`] a metre) so that the sum does not depend on the
/// order the contacts arrive in: `x`, `y`, `z` and the number of reactions, four atomics a
/// vertex, each left at zero after the pass that reads it.
#[derive(Default)]
struct Reactions(Vec<AtomicI32>);

impl Reactions {
    /// Room for `n` vertices, all zero.
    fn reset(&mut self, n: usize) {
        if self.0.len() != 4 * n {
            self.0 = (0..4 * n).map(|_| AtomicI32::new(0)).collect();
        }
    }

    /// Adds `r` to vertex `v`'s reactions (several threads at once).
    #[inline]
    fn add(&self, v: usize, r: Vec3) {
        let at = &self.0[4 * v..4 * v + 4];
        for (a, x) in at.iter().zip(r.to_array()) {
            a.fetch_add(to_fixed(x), Ordering::Relaxed);
        }
        at[3].fetch_add(1, Ordering::Relaxed);
    }

    /// Vertex `v`'s reactions summed and their number; leaves them at zero.
    #[inline]
    fn take(&self, v: usize) -> (Vec3, u32) {
        let at = &self.0[4 * v..4 * v + 4];
        // Most vertices have none: a load, not four swaps.
        if at[3].load(Ordering::Relaxed) == 0 {
            return (Vec3::ZERO, 0);
        }
        let [x, y, z, n] = [0, 1, 2, 3].map(|k| at[k].swap(0, Ordering::Relaxed));
        (
            Vec3::new(x as f32, y as f32, z as f32) / REACTION_UNITS,
            n.cast_unsigned(),
        )
    }
}

impl Clone for Reactions {
    fn clone(&self) -> Self {
        Self(
            self.0
                .iter()
                .map(|a| AtomicI32::new(a.load(Ordering::Relaxed)))
                .collect(),
        )
    }
}

impl PartialEq for Reactions {
    fn eq(&self, other: &Self) -> bool {
        self.0.len() == other.0.len()
            && self
                .0
                .iter()
                .zip(&other.0)
                .all(|(a, b)| a.load(Ordering::Relaxed) == b.load(Ordering::Relaxed))
    }
}

impl core::fmt::Debug for Reactions {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Reactions({} vertices)", self.0.len() / 4)
    }
}

/// Fixed-point units a metre of the reactions' sums ([`Reactions`]; the GPU's
/// `SC_REACTION_UNITS`): 2²⁶, a range of ±32 m.
const REACTION_UNITS: f32 = 67_108_864.0;

/// `x` metres in [`REACTION_UNITS`], rounded to even as WGSL's `round` does, within `i32`.
#[inline]
fn to_fixed(x: f32) -> i32 {
    (x * REACTION_UNITS).clamp(-2.0e9, 2.0e9).round_ties_even() as i32
}

/// A set of triangles as bits, with the rank of each member.
#[derive(Clone, Debug, Default, PartialEq)]
struct Listed {
    words: Vec<u32>,
    /// Per word, the members in the words before it; one more at the end (the count).
    before: Vec<u32>,
}

impl Listed {
    /// A member's place among the members in triangle order; `None` when `t` is not one.
    #[inline]
    fn rank(&self, t: usize) -> Option<usize> {
        let (w, bit) = (t / 32, t % 32);
        let word = *self.words.get(w)?;
        ((word >> bit) & 1 == 1)
            .then(|| (self.before[w] + (word & ((1u32 << bit) - 1)).count_ones()) as usize)
    }

    /// The set of `words` (one bit a triangle) and its ranks.
    fn set(&mut self, words: Vec<AtomicU32>) {
        self.words.clear();
        self.words
            .extend(words.into_iter().map(AtomicU32::into_inner));
        self.before.clear();
        self.before.push(0);
        let mut count = 0;
        for w in &self.words {
            count += w.count_ones();
            self.before.push(count);
        }
    }

    /// Marks triangle `t` in `words` (several threads at once).
    #[inline]
    fn mark(words: &[AtomicU32], t: usize) {
        let bit = 1 << (t % 32);
        // Most are set already (a triangle goes into many lists): read first.
        if let Some(word) = words.get(t / 32)
            && word.load(Ordering::Relaxed) & bit == 0
        {
            word.fetch_or(bit, Ordering::Relaxed);
        }
    }

    /// The members in words `words`, in order.
    fn members(&self, words: Range<usize>) -> impl Iterator<Item = usize> + '_ {
        words.flat_map(|w| bits(self.words[w]).map(move |b| w * 32 + b))
    }

    /// The members' [`Plane`]s at `pos` into `out`, in triangle order (a pass's: each is
    /// projected onto by several vertices; the same bits as projecting per vertex), runs of
    /// members in parallel.
    fn planes(
        &self,
        triangles: &[[u32; 3]],
        pos: &[Vec4],
        out: &mut Vec<Plane>,
        par: &impl Parallel,
    ) {
        let words = self.words.len();
        out.resize(
            self.before.last().copied().unwrap_or(0) as usize,
            Plane::default(),
        );
        let mut runs = Vec::new();
        let mut rest: &mut [Plane] = out;
        for w0 in (0..words).step_by(CHUNK / 8) {
            let w1 = (w0 + CHUNK / 8).min(words);
            let (run, after) = rest.split_at_mut((self.before[w1] - self.before[w0]) as usize);
            runs.push((w0..w1, run));
            rest = after;
        }
        par.for_each_mut(&mut runs, |(words, run)| {
            for (plane, t) in run.iter_mut().zip(self.members(words.clone())) {
                *plane = match triangles.get(t) {
                    Some(tri) => Plane::of(tri.map(|v| pos[v as usize].xyz())),
                    None => Plane {
                        area2: f32::NAN,
                        ..Plane::default()
                    },
                };
            }
        });
    }
}

/// A mesh's triangles by their first corner and its longest rest edge, with the triangles and
/// rest positions they were made from (compared each step: a step with another mesh, or the
/// same cloth after a tear, rebuilds them).
#[derive(Clone, Debug, Default, PartialEq)]
struct MeshLists {
    triangles: Vec<[u32; 3]>,
    rest: Vec<Vec3>,
    /// Offsets per vertex into `first_tris`, then triangle indices.
    first_start: Vec<u32>,
    first_tris: Vec<u32>,
    longest: f32,
}

impl MeshLists {
    /// Brings the lists up to date with `rest` and `triangles`.
    fn update(&mut self, rest: &[Vec3], triangles: &[[u32; 3]], par: &impl Parallel) {
        if same(&self.triangles, triangles, par) && same(&self.rest, rest, par) {
            return;
        }
        let n = rest.len();
        self.triangles.clear();
        self.triangles.extend_from_slice(triangles);
        self.rest.clear();
        self.rest.extend_from_slice(rest);
        self.longest = longest_rest_edge(rest, triangles);
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
    }
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

/// How far a contact pushes a vertex out of an overlap it already had when the substep began,
/// per substep, in thicknesses: a contact undoes all of what its pair closed within the substep
/// and at most this much of the overlap before it (as a physics engine's *maximum depenetration
/// velocity*). Pushed out of a deep overlap at once (a vertex found through a layer, up to
/// 3.5 thicknesses), a vertex dragged its edges through the triangles around it: with it, the
/// crumpled, folded and dropped cloths of `tests/self_collision.rs` swept over 66 runs crossed
/// at most 169 pairs mid-run instead of 6 948 (1 595 summed instead of 11 265) and a running
/// character's cape stretched 45 % instead of 68 % (docs/experiments.md).
const DEPENETRATION: f32 = 0.35;

/// Triangles with a corner resting closer than this many thicknesses to a vertex are left to
/// the constraints (its own ring): a vertex is never over those unless the sheet folds onto
/// itself within an edge or two, which is what the triangle test is for.
const TRIANGLE_SKIP: f32 = 0.5;

/// A triangle whose first corner rests more than 2.5 thicknesses from the vertex is only looked
/// at when that corner is now closer to it than 0.9 of their rest distance (squared here): the
/// cloth has folded or piled up between them. Written squared, not as `0.9 * 0.9`: WGSL folds
/// that product exactly before rounding (0.81) and `f32` rounds each factor (0.80999994), and
/// the two sides must compare against the same number.
const FOLDED2: f32 = 0.81;

/// The query's grid cells are the query's radius over this (4/3 of the radius wide): a query
/// reads four to nine rows of two or three cells each, in sequence. Narrower cells (1.5 per
/// radius) look at fewer vertices outside the radius but cost more rows; measured at 256²
/// with self-collision (`tradeoff --scene-costs`), this width is faster than that (about 10 %
/// on one thread, a third on two) and than cells as wide as the radius or twice as wide. The
/// cell width changes what is looked at, never what is found.
const CELLS_PER_RADIUS: f32 = 0.75;

/// A vertex's own neighbourhood (the vertices resting between half a thickness and 2.5
/// thicknesses from it) has *folded* when one of them is closer to it than 0.97 of their rest
/// distance (squared here, as [`FOLDED2`]), now or [`AHEAD`] × the step later at their
/// velocities when the step begins; only then are the triangles through them looked at. A
/// sheet lying flat, stretched or gently curved around a vertex does not bring its own
/// triangles over it within a step (measured: the crossing counts of the tests and the
/// `self_collision` example are what they were without this gate).
const NEAR_FOLDED2: f32 = 0.9409;

/// How many steps ahead the fold test of [`NEAR_FOLDED2`] also looks.
const AHEAD: f32 = 2.0;

/// Padding after the grid's entries: the query reads them eight at a time.
const LANES: usize = 8;

/// Groups of eight grid entries with some of the own neighbourhood in them that a query keeps
/// from its walk (see [`Query::vertex`]).
const NEAR_GROUPS: usize = 64;

/// Eight grid entries from `k` on, in `range` of the query's ranges, and the lanes of them of
/// the own neighbourhood (`near`) and folded (`fold`).
#[derive(Clone, Copy, Default)]
struct Group {
    k: u32,
    range: u8,
    near: u8,
    fold: u8,
}

/// The set bits of a mask, lowest first.
#[inline]
fn bits(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let l = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            l
        })
    })
}

/// Vertices handled by one parallel work item.
const CHUNK: usize = 512;

/// Vertices a work item of the grid's sort lays out by bin ([`Grid::sort`]).
const SORT_RUN: usize = 4096;

/// The grid's sort splits the buckets into at most `2^BIN_BITS` bins by their high bits.
const BIN_BITS: u32 = 8;

#[inline]
fn cell_of(p: Vec3, inv_cell: f32) -> IVec3 {
    // floor() without a libm call (x86-64's baseline has no rounding instruction):
    // truncate, then step down for negative non-integers. The cast saturates far out (a cloth
    // flung 2³¹ cells away): the step down then wraps, as WGSL's does, and never panics.
    let v = p * inv_cell;
    let t = v.as_ivec3();
    t.wrapping_sub(IVec3::select(t.as_vec3().cmpgt(v), IVec3::ONE, IVec3::ZERO))
}

/// The cell hash of [`count_self_crossings`] (the GPU's `sc_hash` mixes the same way).
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

/// The query grid's bucket of cell `c` in a table of `mask + 1` (a power of two) buckets: the
/// cells of a row along x fall into consecutive buckets.
#[inline]
fn grid_bucket(c: IVec3, mask: usize) -> usize {
    row_base(c.y, c.z).wrapping_add(c.x as isize as usize) & mask
}

#[inline]
fn row_base(y: i32, z: i32) -> usize {
    mix(IVec3::new(0, y, z))
}

/// How far `v` lies outside `[lo, hi)` (0 inside).
#[inline]
fn gap(v: f32, lo: f32, hi: f32) -> f32 {
    (lo - v).max(v - hi).max(0.0)
}

/// How far past a triangle's nearest point its first corner may lie: the longest rest edge
/// and a quarter for stretch, at most 4 thicknesses (so a mesh with a few long triangles does
/// not make every query cover the whole cloth; a vertex over the middle of a triangle longer
/// than that can be missed, as it is far from all three corners). The GPU backend stores the
/// same value in the cloth's record.
#[must_use]
pub fn triangle_reach(rest: &[Vec3], triangles: &[[u32; 3]], thickness: f32) -> f32 {
    reach_of_longest(longest_rest_edge(rest, triangles), thickness)
}

/// How far past a triangle's nearest point its first corner may lie before the cap of
/// [`triangle_reach`]: 1.25 × the longest rest edge (the GPU backend caps it per vertex).
pub(crate) fn first_corner_reach(rest: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    1.25 * longest_rest_edge(rest, triangles)
}

/// [`triangle_reach`] from the longest rest edge.
#[inline]
fn reach_of_longest(longest: f32, thickness: f32) -> f32 {
    (1.25 * longest).min(4.0 * thickness)
}

/// The longest finite rest edge of the triangles (0 for none).
fn longest_rest_edge(rest: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
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
    longest2.sqrt()
}

/// A vertex's query distance: its thickness plus the step's motion margin, at most 1.5 of its
/// thicknesses (the GPU's `sc_reach` the same).
#[inline]
fn reach_of(thickness: f32, motion: f32) -> f32 {
    thickness + motion.min(1.5 * thickness)
}

/// What the query needs of a triangle at the step's start: the bound of
/// [`Frame::surely_apart`], and the normal, area and longest edge for the tests after it (the
/// rest of its [`Plane`] is made from the corners when it gets that far: a third of the
/// memory a query reads per triangle).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Frame {
    /// Unit normal, `(b - a) × (c - a)` normalised.
    n: Vec3,
    /// Twice the area; NaN for a degenerate triangle (or one not finite).
    area2: f32,
    /// The longest edge.
    longest: f32,
    /// The centroid, and the farthest a corner lies from it: every point of the triangle lies
    /// within `spread` of `centre`.
    centre: Vec3,
    spread: f32,
}

impl Frame {
    /// The frame of `[a, b, c]`; its `area2` is NaN when the triangle is degenerate.
    #[inline]
    fn of([a, b, c]: [Vec3; 3]) -> Self {
        let plane = Plane::of([a, b, c]);
        let centre = (a + b + c) / 3.0;
        let spread = a
            .distance_squared(centre)
            .max(b.distance_squared(centre))
            .max(c.distance_squared(centre))
            .sqrt();
        let longest2 = a
            .distance_squared(b)
            .max(b.distance_squared(c))
            .max(c.distance_squared(a));
        Self {
            n: plane.n,
            area2: plane.area2,
            longest: longest2.sqrt(),
            centre,
            spread,
        }
    }

    /// Whether `p` is certainly more than `reach` from the triangle's plane or more than
    /// `slide` beside the triangle along it (measured from the centre: a conservative bound
    /// with slack for rounding, so it never rejects what [`Query::triangles_through`]'s exact
    /// tests keep). Cheaper than projecting; about half the triangles a query looks at end here.
    #[inline]
    fn surely_apart(&self, p: Vec3, slide: f32, reach: f32) -> bool {
        let dc = p - self.centre;
        let dn = dc.dot(self.n);
        let along2 = dc.length_squared() - dn * dn;
        let limit = slide + self.spread;
        along2 > limit * limit * 1.001 + 1e-4 * reach * reach || dn.abs() > 1.001 * reach
    }
}

/// What projecting onto a triangle needs of it (the same operations in the same order as the
/// GPU's `sc_project`, so the results are the same bits).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Plane {
    /// Unit normal, `(b - a) × (c - a)` normalised.
    n: Vec3,
    e1: Vec3,
    e2: Vec3,
    d00: f32,
    d01: f32,
    d11: f32,
    denom: f32,
    /// Twice the area; NaN for a degenerate triangle (or one not finite).
    area2: f32,
}

impl Plane {
    /// The plane of `[a, b, c]`; its `area2` is NaN when the triangle is degenerate.
    #[inline]
    fn of([a, b, c]: [Vec3; 3]) -> Self {
        let nn = (b - a).cross(c - a);
        let len = nn.length();
        let plane = Self::with_normal([a, b, c], nn / len, len);
        let denom = plane.denom;
        let ok = !(len.is_nan() || len <= 1e-12 || denom.is_nan() || denom <= 0.0);
        Self {
            area2: if ok { len } else { f32::NAN },
            ..plane
        }
    }

    /// The plane of `[a, b, c]` with the normal and `area2` of its [`Plane::of`] (or
    /// [`Frame::of`]) given: the same bits, without the cross product and square root again.
    #[inline]
    fn with_normal([a, b, c]: [Vec3; 3], n: Vec3, area2: f32) -> Self {
        let e1 = b - a;
        let e2 = c - a;
        let d00 = e1.dot(e1);
        let d01 = e1.dot(e2);
        let d11 = e2.dot(e2);
        Self {
            n,
            e1,
            e2,
            d00,
            d01,
            d11,
            denom: d00 * d11 - d01 * d01,
            area2,
        }
    }

    /// `p`'s signed distance along the normal and its projection's barycentric weights (all
    /// ≥ 0 inside), `a` being the first corner; `None` for a degenerate triangle.
    #[inline]
    fn project(&self, p: Vec3, a: Vec3) -> Option<(f32, Vec3)> {
        if self.area2.is_nan() {
            return None;
        }
        let ap = p - a;
        let d = ap.dot(self.n);
        let d20 = ap.dot(self.e1);
        let d21 = ap.dot(self.e2);
        let v = (self.d11 * d20 - self.d01 * d21) / self.denom;
        let w = (self.d00 * d21 - self.d01 * d20) / self.denom;
        Some((d, Vec3::new(1.0 - v - w, v, w)))
    }
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

/// What a step's query reads; `thickness`, `reach`, `radius` and `skip` are the querying
/// vertex's (see [`Query::vertex`]).
#[derive(Clone, Copy)]
struct Query<'a> {
    /// Per vertex, its thickness over `cloth_thickness` (none: 1).
    scale: &'a [f32],
    cloth_thickness: f32,
    /// The step's motion margin (twice the fastest vertex's travel).
    motion: f32,
    longest: f32,
    pos: &'a [Vec4],
    vel: &'a [Vec4],
    dt: f32,
    rest: &'a [Vec3],
    triangles: &'a [[u32; 3]],
    grid: &'a Grid,
    first_start: &'a [u32],
    first_tris: &'a [u32],
    frames: &'a [Frame],
    /// The triangles put into some list (see [`Listed`]).
    listed: &'a [AtomicU32],
    thickness: f32,
    reach: f32,
    radius: f32,
    skip: f32,
}

/// A vertex's query in progress.
struct Found<'a> {
    neighbours: &'a mut [u32],
    nc: usize,
    tris: &'a mut [u32],
    tc: usize,
    folded: bool,
}

/// What one look at eight grid entries found, as bit masks: within the radius and resting
/// farther than 2.5 thicknesses, and neither a neighbour nor through a fold (`far` is only a
/// candidate: the row is checked after); of the own neighbourhood and within the radius
/// (`near`); of it and folded (`fold`).
struct Lanes {
    far: u32,
    near: u32,
    fold: u32,
}

impl Query<'_> {
    /// Vertex `i`'s neighbours and triangles into its slots; returns their counts. `ranges`
    /// is working space. `WALK_TWICE` takes the path of a crowd too big for [`NEAR_GROUPS`]
    /// (a second walk for the own neighbourhood) for every vertex, as the tests compare.
    fn vertex<const WALK_TWICE: bool>(
        &self,
        i: usize,
        neighbours: &mut [u32],
        tris: &mut [u32],
        ranges: &mut Vec<(Row, usize, usize)>,
    ) -> (usize, usize) {
        // The vertex's own thickness and the distances that follow from it.
        let thickness = self.cloth_thickness * self.scale.get(i).copied().unwrap_or(1.0);
        let reach = reach_of(thickness, self.motion);
        let own = Query {
            thickness,
            reach,
            radius: reach + reach_of_longest(self.longest, thickness),
            skip: SKIP * thickness,
            ..*self
        };
        own.vertex_with::<WALK_TWICE>(i, neighbours, tris, ranges)
    }

    /// [`Query::vertex`] with the vertex's own distances in `self`.
    fn vertex_with<const WALK_TWICE: bool>(
        &self,
        i: usize,
        neighbours: &mut [u32],
        tris: &mut [u32],
        ranges: &mut Vec<(Row, usize, usize)>,
    ) -> (usize, usize) {
        let p = self.pos[i].xyz();
        if !p.is_finite() {
            return (0, 0);
        }
        ranges.clear();
        self.ranges(p, ranges);
        let mut found = Found {
            neighbours,
            nc: 0,
            tris,
            tc: 0,
            folded: false,
        };
        let ahead = AHEAD * self.dt;
        let pa = p + self.vel[i].xyz() * ahead;
        let rest_i = self.rest[i];
        // The groups of eight entries with some of the own neighbourhood in them, kept for
        // after the walk (stored whether or not they have, to keep the walk free of branches);
        // more than the buffer holds and the walk is repeated for them.
        let mut groups = [Group::default(); NEAR_GROUPS];
        let mut ng = 0usize;
        for (r, &(row, k0, k1)) in ranges.iter().enumerate() {
            let mut k = k0;
            while k < k1 {
                let m = (k1 - k).min(LANES);
                let keep = (1u32 << m) - 1;
                let lanes = self.lanes(k, p, pa, rest_i);
                let mut far = lanes.far & keep;
                while far != 0 {
                    let l = far.trailing_zeros() as usize;
                    far &= far - 1;
                    self.far_hit(i, p, row, k + l, &mut found);
                }
                let near = lanes.near & keep;
                if let Some(g) = groups.get_mut(ng) {
                    *g = Group {
                        k: k as u32,
                        range: r as u8,
                        near: near as u8,
                        fold: (lanes.fold & keep) as u8,
                    };
                }
                ng += usize::from(near != 0);
                k += LANES;
            }
        }
        // The own neighbourhood's triangles, where it has folded.
        if !WALK_TWICE && ng <= NEAR_GROUPS && ranges.len() <= 256 {
            let groups = &groups[..ng];
            let row = |g: &Group| ranges[g.range as usize].0;
            found.folded = groups.iter().any(|g| {
                bits(g.fold.into()).any(|l| self.in_row(i, row(g), g.k as usize + l).is_some())
            });
            if found.folded {
                for g in groups {
                    for l in bits(g.near.into()) {
                        self.near_hit(i, p, rest_i, row(g), g.k as usize + l, &mut found);
                    }
                }
            }
        } else {
            self.near_walk(i, p, pa, rest_i, ranges, &mut found);
        }
        (found.nc, found.tc)
    }

    /// The triangles through the own-neighbourhood vertex of grid entry `k`, when it is read
    /// through its own row.
    #[inline]
    fn near_hit(&self, i: usize, p: Vec3, rest_i: Vec3, row: Row, k: usize, found: &mut Found) {
        if let Some(j) = self.in_row(i, row, k) {
            let rest2 = (self.rest[j] - rest_i).length_squared();
            self.triangles_through(i, p, j, rest2, found);
        }
    }

    /// The own neighbourhood's fold test and triangles from a second walk (a crowd too big
    /// for [`NEAR_GROUPS`]).
    fn near_walk(
        &self,
        i: usize,
        p: Vec3,
        pa: Vec3,
        rest_i: Vec3,
        ranges: &[(Row, usize, usize)],
        found: &mut Found,
    ) {
        let each = |f: &mut dyn FnMut(Row, usize, Lanes)| {
            for &(row, k0, k1) in ranges {
                for k in (k0..k1).step_by(LANES) {
                    let keep = (1u32 << (k1 - k).min(LANES)) - 1;
                    let lanes = self.lanes(k, p, pa, rest_i);
                    let masked = Lanes {
                        far: lanes.far & keep,
                        near: lanes.near & keep,
                        fold: lanes.fold & keep,
                    };
                    f(row, k, masked);
                }
            }
        };
        let mut folded = false;
        each(&mut |row, k, lanes| {
            folded |= bits(lanes.fold).any(|l| self.in_row(i, row, k + l).is_some());
        });
        found.folded = folded;
        if folded {
            each(&mut |row, k, lanes| {
                for l in bits(lanes.near) {
                    self.near_hit(i, p, rest_i, row, k + l, found);
                }
            });
        }
    }

    /// The grid ranges within the radius of `p`: rows (cells along x) whose y–z square comes
    /// within it, each trimmed to the x range it leaves there (a hundredth of a cell of slack
    /// against rounding).
    fn ranges(&self, p: Vec3, out: &mut Vec<(Row, usize, usize)>) {
        let g = self.grid;
        let (cell, inv) = (g.cell, 1.0 / g.cell);
        let big2 = self.radius * self.radius;
        let size = g.start.len() - 1;
        let mask = size - 1;
        let lo = cell_of(p - Vec3::splat(self.radius), inv);
        let hi = cell_of(p + Vec3::splat(self.radius), inv);
        // Slack for the rounding of cell bounds; more than four million cells out (or beyond
        // an `i32`, where the cells saturate) whole rows are read.
        let far = p.abs().max_element();
        let slack = 0.01 * cell + far * 1e-6;
        let exact = (far + self.radius) * inv < 4.0e6;
        let bounds = |c: i32| (c as f32 * cell, (c as f32 + 1.0) * cell);
        for z in lo.z..=hi.z {
            let (z0, z1) = bounds(z);
            let gz = if exact {
                (gap(p.z, z0, z1) - slack).max(0.0)
            } else {
                0.0
            };
            for y in lo.y..=hi.y {
                let (y0, y1) = bounds(y);
                let gy = if exact {
                    (gap(p.y, y0, y1) - slack).max(0.0)
                } else {
                    0.0
                };
                let left = big2 - gy * gy - gz * gz;
                if left < 0.0 {
                    continue;
                }
                // The x range the row's entries within the radius lie in.
                let half = if exact {
                    left.sqrt() + slack
                } else {
                    f32::INFINITY
                };
                let (x0, x1) = if exact {
                    (
                        cell_of(Vec3::splat(p.x - half), inv).x.max(lo.x),
                        cell_of(Vec3::splat(p.x + half), inv).x.min(hi.x),
                    )
                } else {
                    (lo.x, hi.x)
                };
                if x0 > x1 {
                    continue;
                }
                let row = Row { y, z, x0, x1 };
                let cells = (i64::from(x1) - i64::from(x0) + 1) as u64;
                if cells >= size as u64 {
                    out.push((row, g.start[0] as usize, g.start[size] as usize));
                    continue;
                }
                let base = row_base(y, z);
                let b0 = base.wrapping_add(x0 as isize as usize) & mask;
                let b1 = base.wrapping_add(x1 as isize as usize) & mask;
                // A bucket's entries are ordered by x: the first bucket's below the range and
                // the last one's above it are left out.
                let (from, to) = (p.x - half, p.x + half);
                let first = g.start[b0] as usize
                    + g.x[g.start[b0] as usize..g.start[b0 + 1] as usize]
                        .partition_point(|&x| x < from);
                let last = g.start[b1] as usize
                    + g.x[g.start[b1] as usize..g.start[b1 + 1] as usize]
                        .partition_point(|&x| x <= to);
                if b0 <= b1 {
                    out.push((row, first, last.max(first)));
                } else {
                    out.push((row, first, g.start[size] as usize));
                    out.push((row, g.start[0] as usize, last));
                }
            }
        }
    }

    /// Grid entries `k..k + 8` against vertex `i` at `p` (`pa` ahead, resting at `rest_i`):
    /// plain arithmetic on the grid's lanes, which the compiler vectorises.
    #[inline(always)]
    fn lanes(&self, k: usize, p: Vec3, pa: Vec3, rest_i: Vec3) -> Lanes {
        let g = self.grid;
        let big2 = self.radius * self.radius;
        let r2 = self.reach * self.reach;
        let skip2 = self.skip * self.skip;
        let tri_skip = TRIANGLE_SKIP * self.thickness;
        let tri_skip2 = tri_skip * tri_skip;
        let at = |lane: &[f32]| -> [f32; LANES] {
            lane[k..k + LANES].try_into().unwrap_or([f32::NAN; LANES])
        };
        let (x, y, z) = (at(&g.x), at(&g.y), at(&g.z));
        let (rx, ry, rz) = (at(&g.rx), at(&g.ry), at(&g.rz));
        let (ax, ay, az) = (at(&g.ax), at(&g.ay), at(&g.az));
        let (mut far, mut near, mut fold) = (0u32, 0u32, 0u32);
        for l in 0..LANES {
            let (dx, dy, dz) = (x[l] - p.x, y[l] - p.y, z[l] - p.z);
            let d2 = dx * dx + dy * dy + dz * dz;
            let (ex, ey, ez) = (rx[l] - rest_i.x, ry[l] - rest_i.y, rz[l] - rest_i.z);
            let rest2 = ex * ex + ey * ey + ez * ez;
            let (fx, fy, fz) = (ax[l] - pa.x, ay[l] - pa.y, az[l] - pa.z);
            let a2 = fx * fx + fy * fy + fz * fz;
            let inside = d2 < big2;
            let is_far = rest2 > skip2;
            let is_near = rest2 > tri_skip2 && !is_far;
            let f2 = NEAR_FOLDED2 * rest2;
            far |= u32::from(inside & is_far & ((d2 < r2) | (d2 < FOLDED2 * rest2))) << l;
            near |= u32::from(inside & is_near) << l;
            fold |= u32::from(inside & is_near & ((d2 < f2) | (a2 < f2))) << l;
        }
        Lanes { far, near, fold }
    }

    /// The vertex of grid entry `k` when it is not `i` and read through its own row (cells of
    /// other rows hashed into these buckets are read through theirs: each vertex is seen once).
    #[inline]
    fn in_row(&self, i: usize, row: Row, k: usize) -> Option<usize> {
        let c = self.grid.cells[k];
        let j = self.grid.entries[k] as usize;
        (c.y == row.y && c.z == row.z && c.x >= row.x0 && c.x <= row.x1 && j != i).then_some(j)
    }

    /// Grid entry `k` within the radius of vertex `i` at `p`, resting more than 2.5
    /// thicknesses from it, and close enough to be a neighbour or to have folded towards it.
    fn far_hit(&self, i: usize, p: Vec3, row: Row, k: usize, found: &mut Found) {
        let Some(j) = self.in_row(i, row, k) else {
            return;
        };
        let g = self.grid;
        let d2 = (Vec3::new(g.x[k], g.y[k], g.z[k]) - p).length_squared();
        let rest2 = (self.rest[j] - self.rest[i]).length_squared();
        if d2 < self.reach * self.reach {
            keep_smallest(found.neighbours, &mut found.nc, j as u32);
        }
        // Triangles through a `j` resting farther than 2.5 thicknesses away: only where the
        // cloth has come closer to itself than it is at rest (a fold, a pile), never across a
        // flat or stretched sheet, whose own triangles lie beside its vertices.
        if d2 < FOLDED2 * rest2 {
            self.triangles_through(i, p, j, rest2, found);
        }
    }

    /// The triangles whose first corner is `j` (resting `rest2` from vertex `i` at `p`) that
    /// `i` is over, or beside by no more than it can slide over in the step, into its list.
    fn triangles_through(&self, i: usize, p: Vec3, j: usize, rest2: f32, found: &mut Found) {
        let rest_i = self.rest[i];
        let tri_skip = TRIANGLE_SKIP * self.thickness;
        let tri_skip2 = tri_skip * tri_skip;
        let margin = self.reach - self.thickness;
        let r2 = self.reach * self.reach;
        let v = self.vel[i];
        let first =
            &self.first_tris[self.first_start[j] as usize..self.first_start[j + 1] as usize];
        for &t in first {
            let frame = &self.frames[t as usize];
            if frame.surely_apart(p, margin, self.reach) {
                continue;
            }
            let tri = self.triangles[t as usize];
            if !tri[1..]
                .iter()
                .all(|&k| (self.rest[k as usize] - rest_i).length_squared() > tri_skip2)
            {
                continue;
            }
            let corners = tri.map(|k| self.pos[k as usize].xyz());
            if !corners.iter().all(|c| c.is_finite()) {
                continue;
            }
            // Over the triangle, or beside it by no more than it can slide over in the step
            // (the sheet's own triangles around the vertex are beside it, in its plane).
            let plane = Plane::with_normal(corners, frame.n, frame.area2);
            let Some((d, bary)) = plane.project(p, corners[0]) else {
                continue;
            };
            if d.is_nan() || d.abs() >= self.reach {
                continue;
            }
            let code = if bary.min_element() >= 0.0 {
                if d >= 0.0 { SIDE_FRONT } else { SIDE_BACK }
            } else {
                // How far it can slide over the triangle in the step: the margin; over its
                // own neighbourhood (which moves with it) twice its fastest speed relative to
                // a corner and a quarter thickness.
                let slide = if rest2 > self.skip * self.skip {
                    margin
                } else {
                    let rel = tri
                        .iter()
                        .map(|&k| (self.vel[k as usize] - v).xyz().length_squared())
                        .fold(0.0f32, f32::max);
                    (2.0 * self.dt * rel.sqrt() + 0.25 * self.thickness).min(margin)
                };
                // At least −(the negative weight) altitudes from the triangle (an altitude is
                // at least twice the area over the longest edge): most of a sheet's own
                // triangles end here.
                let below = -bary.min_element() * frame.area2 / frame.longest;
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
            Listed::mark(self.listed, t as usize);
            keep_smallest(found.tris, &mut found.tc, slot(t, code));
        }
    }
}

/// A row of the query grid: cells `x0..=x1` at `y`, `z`.
#[derive(Clone, Copy)]
struct Row {
    y: i32,
    z: i32,
    x0: i32,
    x1: i32,
}

/// The step's grid of vertices (cells of [`CELLS_PER_RADIUS`] to the query radius), its
/// entries in bucket order with their positions in separate lanes.
#[derive(Clone, Debug, Default, PartialEq)]
struct Grid {
    cell: f32,
    /// Per bucket, its first entry; one more at the end.
    start: Vec<u32>,
    entries: Vec<u32>,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    /// Rest positions.
    rx: Vec<f32>,
    ry: Vec<f32>,
    rz: Vec<f32>,
    /// Positions [`AHEAD`] × the step on at the step's start velocities.
    ax: Vec<f32>,
    ay: Vec<f32>,
    az: Vec<f32>,
    cells: Vec<IVec3>,
    /// Cell of each vertex, and its bucket (`u32::MAX`: its position is not finite).
    vertex_cells: Vec<IVec3>,
    vertex_buckets: Vec<u32>,
    /// Working space of [`Grid::sort`]: per run of vertices its count and first place per
    /// bin, its vertices by bin; each bin's first entry.
    bin_counts: Vec<u32>,
    bin_offsets: Vec<u32>,
    by_bin: Vec<u32>,
    bin_start: Vec<u32>,
}

impl Grid {
    /// Every vertex with a finite position into its cell's bucket, in parallel (see
    /// [`Grid::sort`]).
    fn fill(
        &mut self,
        pos: &[Vec4],
        vel: &[Vec4],
        rest: &[Vec3],
        ahead: f32,
        cell: f32,
        par: &impl Parallel,
    ) {
        let n = pos.len();
        let size = (2 * n).next_power_of_two().max(2);
        let mask = size - 1;
        let inv = 1.0 / cell;
        self.cell = cell;
        self.vertex_cells.resize(n, IVec3::ZERO);
        fill_each(&mut self.vertex_cells, par, |i| cell_of(pos[i].xyz(), inv));
        self.vertex_buckets.resize(n, 0);
        let cells = &self.vertex_cells;
        fill_each(&mut self.vertex_buckets, par, |i| {
            if pos[i].xyz().is_finite() {
                grid_bucket(cells[i], mask) as u32
            } else {
                u32::MAX
            }
        });
        let real = self.sort(size, pos, par);
        let count = real + LANES;
        // The lanes, one a work item: each read through the entries in order.
        let entries = &self.entries[..real];
        let mut lanes: Vec<(usize, &mut [f32])> = [
            &mut self.x,
            &mut self.y,
            &mut self.z,
            &mut self.rx,
            &mut self.ry,
            &mut self.rz,
            &mut self.ax,
            &mut self.ay,
            &mut self.az,
        ]
        .into_iter()
        .enumerate()
        .map(|(kind, lane)| {
            lane.resize(count, 0.0);
            (kind, &mut lane[..real])
        })
        .collect();
        par.for_each_mut(&mut lanes, |(kind, out)| {
            let out = &mut **out;
            match *kind {
                0 => gather(out, entries, |i| pos[i].x),
                1 => gather(out, entries, |i| pos[i].y),
                2 => gather(out, entries, |i| pos[i].z),
                3 => gather(out, entries, |i| rest[i].x),
                4 => gather(out, entries, |i| rest[i].y),
                5 => gather(out, entries, |i| rest[i].z),
                6 => gather(out, entries, |i| pos[i].x + vel[i].x * ahead),
                7 => gather(out, entries, |i| pos[i].y + vel[i].y * ahead),
                _ => gather(out, entries, |i| pos[i].z + vel[i].z * ahead),
            }
        });
    }

    /// The entries in bucket order, the `size` buckets' starts and the entries' cells from
    /// the vertices' buckets and cells; returns the number of entries (vertices with a finite
    /// position). A parallel counting sort whose order does not depend on the threads: runs
    /// of [`SORT_RUN`] vertices are each laid out by bin (the buckets' high bits) in their own
    /// stretch, then each bin gathers its stretches in run order and sorts them by bucket;
    /// then each bucket's entries are ordered by their x (ties: rising vertex order), so a
    /// query can leave out the ends of a row beyond its x range ([`Query::ranges`]).
    fn sort(&mut self, size: usize, pos: &[Vec4], par: &impl Parallel) -> usize {
        let n = self.vertex_buckets.len();
        let cells = &self.vertex_cells;
        // About a bin per 1024 vertices, at most 2^BIN_BITS: a small cloth's sort is a few
        // items, not hundreds of tiny ones.
        let bin_bits = (n / 1024).max(1).ilog2().min(BIN_BITS);
        let log = size.trailing_zeros();
        let shift = log - log.min(bin_bits);
        let bins = size >> shift;
        let runs = n.div_ceil(SORT_RUN);
        // Per run: its count per bin, where each bin's part starts in its stretch, and its
        // vertices laid out by bin there.
        self.bin_counts.clear();
        self.bin_counts.resize(runs * bins, 0);
        self.bin_offsets.resize(runs * bins, 0);
        self.by_bin.resize(n, 0);
        let buckets = &self.vertex_buckets;
        let mut items: Vec<_> = self
            .bin_counts
            .chunks_mut(bins)
            .zip(self.bin_offsets.chunks_mut(bins))
            .zip(self.by_bin.chunks_mut(SORT_RUN))
            .enumerate()
            .map(|(r, ((counts, offsets), out))| (r * SORT_RUN, counts, offsets, out))
            .collect();
        par.for_each_mut(&mut items, |(first, counts, offsets, out)| {
            let run = &buckets[*first..*first + out.len()];
            for &b in run.iter().filter(|&&b| b != u32::MAX) {
                counts[(b >> shift) as usize] += 1;
            }
            let mut at = [0u32; 1 << BIN_BITS];
            let mut acc = 0;
            for ((a, o), &c) in at.iter_mut().zip(offsets.iter_mut()).zip(counts.iter()) {
                (*a, *o) = (acc, acc);
                acc += c;
            }
            for (k, &b) in run.iter().enumerate().filter(|&(_, &b)| b != u32::MAX) {
                let a = &mut at[(b >> shift) as usize];
                out[*a as usize] = (*first + k) as u32;
                *a += 1;
            }
        });
        // Where each bin's entries go.
        self.bin_start.clear();
        self.bin_start.push(0);
        for b in 0..bins {
            let total: u32 = (0..runs).map(|r| self.bin_counts[r * bins + b]).sum();
            self.bin_start.push(self.bin_start[b] + total);
        }
        let real = self.bin_start[bins] as usize;
        self.entries.resize(real + LANES, 0);
        self.cells.resize(real + LANES, IVec3::ZERO);
        self.start.clear();
        self.start.resize(size + 1, 0);
        self.start[size] = real as u32;
        // Each bin: its buckets' starts and its entries, in parallel.
        let (by_bin, counts, offsets) = (&self.by_bin, &self.bin_counts, &self.bin_offsets);
        let mut entries = &mut self.entries[..real];
        let mut entry_cells = &mut self.cells[..real];
        let mut items = Vec::with_capacity(bins);
        for (b, starts) in self.start[..size].chunks_mut(1 << shift).enumerate() {
            let len = (self.bin_start[b + 1] - self.bin_start[b]) as usize;
            let (e, rest) = entries.split_at_mut(len);
            entries = rest;
            let (c, rest) = entry_cells.split_at_mut(len);
            entry_cells = rest;
            items.push((b, starts, e, c));
        }
        let bin_start = &self.bin_start;
        par.for_each_mut(&mut items, |(b, starts, e, c)| {
            let b = *b;
            let low = (1u32 << shift) - 1;
            let stretch = |r: usize| {
                let at = r * SORT_RUN + offsets[r * bins + b] as usize;
                &by_bin[at..at + counts[r * bins + b] as usize]
            };
            let each = || (0..runs).flat_map(stretch);
            for &j in each() {
                starts[(buckets[j as usize] & low) as usize] += 1;
            }
            let mut acc = 0;
            for s in starts.iter_mut() {
                let count = *s;
                *s = acc;
                acc += count;
            }
            // Placed with the starts as cursors: each ends at its bucket's end, the next
            // bucket's start.
            for &j in each() {
                let s = &mut starts[(buckets[j as usize] & low) as usize];
                e[*s as usize] = j;
                *s += 1;
            }
            // Each bucket by x, equal x by vertex (an unstable sort: no allocation, and no
            // two entries compare equal), then the cells in the same order.
            let mut from = 0;
            for &end in starts.iter() {
                let bucket = &mut e[from as usize..end as usize];
                if bucket.len() > 1 {
                    bucket.sort_unstable_by(|&a, &b| {
                        let x = |j: u32| pos[j as usize].x;
                        x(a).total_cmp(&x(b)).then(a.cmp(&b))
                    });
                }
                from = end;
            }
            for (c, &j) in c.iter_mut().zip(e.iter()) {
                *c = cells[j as usize];
            }
            starts.rotate_right(1);
            starts[0] = 0;
            for s in starts.iter_mut() {
                *s += bin_start[b];
            }
        });
        real
    }
}

/// `value` of every run of `4 × CHUNK` indices below `len` (the last one shorter), the runs
/// in parallel.
fn per_run<R: Send + Default>(
    len: usize,
    par: &impl Parallel,
    value: impl Fn(Range<usize>) -> R + Sync,
) -> Vec<R> {
    let run = 4 * CHUNK;
    let mut runs: Vec<(Range<usize>, R)> = (0..len.div_ceil(run))
        .map(|k| (k * run..((k + 1) * run).min(len), R::default()))
        .collect();
    par.for_each_mut(&mut runs, |(range, out)| *out = value(range.clone()));
    runs.into_iter().map(|r| r.1).collect()
}

/// Whether `a` and `b` are equal, compared in runs in parallel.
fn same<T: PartialEq + Sync>(a: &[T], b: &[T], par: &impl Parallel) -> bool {
    a.len() == b.len()
        && per_run(a.len(), par, |r| a[r.clone()] == b[r])
            .into_iter()
            .all(|equal| equal)
}

/// `each(first, run)` for every run of `4 × CHUNK` items of `out` (the last one shorter),
/// `first` its first index, the runs in parallel.
fn each_run<T: Send>(out: &mut [T], par: &impl Parallel, each: impl Fn(usize, &mut [T]) + Sync) {
    let mut runs: Vec<(usize, &mut [T])> = out
        .chunks_mut(4 * CHUNK)
        .enumerate()
        .map(|(k, run)| (k * 4 * CHUNK, run))
        .collect();
    par.for_each_mut(&mut runs, |(first, run)| each(*first, run));
}

/// `out[i] = value(i)` for every `i`, in runs of `4 × CHUNK` in parallel.
fn fill_each<T: Send>(out: &mut [T], par: &impl Parallel, value: impl Fn(usize) -> T + Sync) {
    each_run(out, par, |first, run| {
        for (k, o) in run.iter_mut().enumerate() {
            *o = value(first + k);
        }
    });
}

/// `out[k] = value(entries[k])` for every entry.
#[inline]
fn gather(out: &mut [f32], entries: &[u32], value: impl Fn(usize) -> f32) {
    for (o, &i) in out.iter_mut().zip(entries) {
        *o = value(i as usize);
    }
}

/// One parallel work item of the query: a run of vertices and their slots.
struct QueryChunk<'a> {
    first: usize,
    neighbour_count: &'a mut [u32],
    neighbours: &'a mut [u32],
    triangle_count: &'a mut [u32],
    triangles: &'a mut [u32],
    /// Its vertices with something in their lists, rising.
    active: Vec<u32>,
}

impl SelfCollisionScratch {
    /// Fills the grid with the current positions and every vertex's lists (see the module
    /// docs), the vertices in parallel (`WALK_TWICE`: see [`Query::vertex`]).
    #[expect(clippy::too_many_arguments)]
    fn find<const WALK_TWICE: bool>(
        &mut self,
        pos: &[Vec4],
        vel: &[Vec4],
        dt: f32,
        rest: &[Vec3],
        triangles: &[[u32; 3]],
        scales: &[f32],
        thickness: f32,
        motion: f32,
        par: &impl Parallel,
    ) {
        let n = pos.len();
        self.mesh.update(rest, triangles, par);
        // The grid's cells from the thickest vertex's radius (scales only on uneven meshes).
        let thickest = thickness * scales.iter().copied().fold(1.0, f32::max);
        let radius = reach_of(thickest, motion) + reach_of_longest(self.mesh.longest, thickest);
        self.grid
            .fill(pos, vel, rest, AHEAD * dt, radius / CELLS_PER_RADIUS, par);
        let valid = |t: &[u32; 3]| t.iter().all(|&k| (k as usize) < n);

        self.frames.resize(triangles.len(), Frame::default());
        fill_each(&mut self.frames, par, |t| {
            let tri = triangles[t];
            if valid(&tri) {
                Frame::of(tri.map(|k| pos[k as usize].xyz()))
            } else {
                Frame {
                    area2: f32::NAN,
                    ..Frame::default()
                }
            }
        });

        self.neighbour_count.clear();
        self.neighbour_count.resize(n, 0);
        self.neighbours.resize(n * MAX_SELF_NEIGHBOURS, 0);
        self.triangle_count.clear();
        self.triangle_count.resize(n, 0);
        self.triangles.resize(n * MAX_SELF_TRIANGLES, 0);
        // The triangles put into a list (one that is later pushed out of a full list too:
        // its plane is made for nothing).
        let listed: Vec<AtomicU32> = (0..triangles.len().div_ceil(32))
            .map(|_| AtomicU32::new(0))
            .collect();
        let query = Query {
            scale: scales,
            cloth_thickness: thickness,
            motion,
            longest: self.mesh.longest,
            pos,
            vel,
            dt,
            rest,
            triangles,
            grid: &self.grid,
            first_start: &self.mesh.first_start,
            first_tris: &self.mesh.first_tris,
            frames: &self.frames,
            listed: &listed,
            // The querying vertex's, set per vertex.
            thickness,
            reach: reach_of(thickness, motion),
            radius,
            skip: SKIP * thickness,
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
                active: Vec::new(),
            })
            .collect();
        par.for_each_mut(&mut chunks, |c| {
            let mut ranges = Vec::new();
            for k in 0..c.neighbour_count.len() {
                let (nc, tc) = query.vertex::<WALK_TWICE>(
                    c.first + k,
                    &mut c.neighbours[k * MAX_SELF_NEIGHBOURS..(k + 1) * MAX_SELF_NEIGHBOURS],
                    &mut c.triangles[k * MAX_SELF_TRIANGLES..(k + 1) * MAX_SELF_TRIANGLES],
                    &mut ranges,
                );
                c.neighbour_count[k] = nc as u32;
                c.triangle_count[k] = tc as u32;
                if nc + tc > 0 {
                    c.active.push((c.first + k) as u32);
                }
            }
        });
        self.active.clear();
        for c in &chunks {
            self.active.extend_from_slice(&c.active);
        }
        self.listed.set(listed);
    }
}

/// The step's motion margin: twice the fastest vertex's travel in `dt` (a vertex's reach adds
/// it to its thickness, at most 1.5 thicknesses: [`reach_of`]); `None` when off.
fn motion_margin(vel: &[Vec4], params: SelfCollision, dt: f32, par: &impl Parallel) -> Option<f32> {
    let thickness = params.thickness;
    if !(thickness.is_finite() && thickness > 0.0) {
        return None;
    }
    let fastest2 = |run: &[Vec4]| {
        run.iter()
            .map(|v| v.xyz().length_squared())
            .filter(|s| s.is_finite())
            .fold(0.0f32, f32::max)
    };
    // A maximum per run in parallel: the same whatever the order.
    let fastest = per_run(vel.len(), par, |r| fastest2(&vel[r]))
        .into_iter()
        .fold(0.0f32, f32::max)
        .sqrt();
    Some(2.0 * fastest * dt)
}

/// How far a contact pushes its pair apart: the `overlap` with the contact's thickness
/// (`thickness - distance`), but of it at most what the pair closed within the substep
/// (`approach`, along the contact's normal) plus [`DEPENETRATION`] thicknesses.
#[inline]
fn limited_push(overlap: f32, approach: f32, thickness: f32) -> f32 {
    overlap.min(approach.max(0.0) + DEPENETRATION * thickness)
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
/// `thickness` (at most what they closed within the substep plus [`DEPENETRATION`]
/// thicknesses), mass-weighted, with friction on the pair's sliding. `None` when the pair does
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
    let approach = n.dot(prev_a.xyz() - prev_b.xyz()) - len;
    let push = limited_push(limit - len, approach, limit);
    let mut da = n * (push * wa / w);
    let db = -n * (push * wb / w);
    // Friction on the relative sliding of the pair during the substep.
    let slide = (a.xyz() + da - prev_a.xyz()) - (b.xyz() + db - prev_b.xyz());
    if let Some((tangential, keep)) = sliding(slide, n, push, params.friction) {
        da -= tangential * (keep * wa / w);
    }
    da.is_finite().then_some(da)
}

/// The correction of vertex `a` (with `prev_a`) from triangle `tri` (its corners in `read`,
/// `prev`; `plane` its [`Plane`] at `read`) and the side code it keeps to: when `a` is
/// over the triangle and closer than `thickness` on its side, or through it to the other side
/// (by less than 2.5 thicknesses), pushed out to `thickness` on its side along the normal (at
/// most what it closed on the triangle within the substep plus [`DEPENETRATION`] thicknesses), its
/// share by the inverse masses (the triangle's at the point under `a`), with friction on the
/// sliding; with the barycentric weights of the point under `a`. `None` when it does not
/// touch. (The GPU's `sc_triangle` projects the same way.)
#[inline]
#[expect(clippy::too_many_arguments)]
fn triangle_correction(
    a: Vec4,
    prev_a: Vec4,
    plane: &Plane,
    tri: [u32; 3],
    read: &[Vec4],
    prev: &[Vec4],
    code: u32,
    params: SelfCollision,
) -> Option<(Vec3, Vec3)> {
    let wa = a.w;
    if wa.is_nan() || wa <= 0.0 {
        return None;
    }
    let (d, bary) = plane.project(a.xyz(), read[tri[0] as usize].xyz())?;
    if bary.min_element() < 0.0 {
        return None;
    }
    let n = plane.n;
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
    let x = tri.map(|v| read[v as usize]);
    let prev_x = tri.map(|v| prev[v as usize]);
    let wt = bary.x * x[0].w + bary.y * x[1].w + bary.z * x[2].w;
    let share = wa / (wa + wt);
    let q = x[0].xyz() * bary.x + x[1].xyz() * bary.y + x[2].xyz() * bary.z;
    let q_prev = prev_x[0].xyz() * bary.x + prev_x[1].xyz() * bary.y + prev_x[2].xyz() * bary.z;
    // What the vertex closed on the triangle's point under it within the substep (or went
    // through by).
    let approach = side * n.dot((prev_a.xyz() - q_prev) - (a.xyz() - q));
    let push = limited_push(thickness - ds, approach, thickness);
    let mut da = n * (side * push * share);
    let slide = (a.xyz() + da - prev_a.xyz()) - (q - q_prev);
    if let Some((tangential, keep)) = sliding(slide, n, push, params.friction) {
        da -= tangential * (keep * share);
    }
    da.is_finite().then_some((da, bary))
}

/// What a vertex–triangle contact that moved its vertex (inverse mass `wa`) by `da` moves the
/// triangle's corner of inverse mass `wc` and weight `b` at the point under the vertex by: the
/// reaction, so that the contact moves no momentum (`Σ Δx / w = 0` over the four). The GPU's
/// `sc_react`.
#[inline]
fn reaction(da: Vec3, wa: f32, wc: f32, b: f32) -> Vec3 {
    -da * (wc * b / wa)
}

/// One parallel work item of a pass: a run of active vertices' corrections and their counts.
struct PassChunk<'a> {
    active: &'a [u32],
    corrections: &'a mut [Vec3],
    touching: &'a mut [u32],
}

/// Per vertex, the thickness it keeps from other vertices and from triangles over the
/// cloth's ([`Topology::self_collision_scales`](crate::solver::Topology::self_collision_scales)
/// and [`Topology::self_collision_triangle_scales`](crate::solver::Topology::self_collision_triangle_scales));
/// empty: the cloth's.
#[derive(Clone, Copy, Default)]
pub(crate) struct Scales<'a> {
    pub vertices: &'a [f32],
    pub triangles: &'a [f32],
}

/// One self-collision pass (Jacobi): every vertex sums its corrections from its touching
/// neighbours and triangles against the positions before the pass; each triangle it is over
/// (listed so at the step's start) takes the reaction of its correction at its corners
/// ([`reaction`], summed per corner in [`Reactions`]); every vertex then moves by the mean
/// of its corrections and reactions, all at once (`prev`: positions at the substep's start).
/// The vertices run in parallel; the result does not depend on how they are split.
pub(crate) fn self_collide(
    pos: &mut [Vec4],
    prev: &[Vec4],
    triangles: &[[u32; 3]],
    scales: Scales<'_>,
    params: SelfCollision,
    scratch: &mut SelfCollisionScratch,
    par: &impl Parallel,
) {
    let Scales {
        vertices: scales,
        triangles: triangle_scales,
    } = scales;
    let n = pos.len();
    if scratch.neighbour_count.len() != n || scratch.triangle_count.len() != n {
        return;
    }
    let read: &[Vec4] = pos;
    scratch
        .listed
        .planes(triangles, read, &mut scratch.pass_planes, par);
    scratch.reactions.reset(n);
    let listed = &scratch.listed;
    let planes = &scratch.pass_planes;
    let active = &scratch.active;
    let reactions = &scratch.reactions;
    scratch.corrections.clear();
    scratch.corrections.resize(active.len(), Vec3::ZERO);
    scratch.touching.clear();
    scratch.touching.resize(active.len(), 0);
    let (nc, nl) = (&scratch.neighbour_count, &scratch.neighbours);
    let (tc, tl) = (&scratch.triangle_count, &scratch.triangles);
    let mut chunks: Vec<PassChunk> = active
        .chunks(CHUNK)
        .zip(scratch.corrections.chunks_mut(CHUNK))
        .zip(scratch.touching.chunks_mut(CHUNK))
        .map(|((active, corrections), touching)| PassChunk {
            active,
            corrections,
            touching,
        })
        .collect();
    par.for_each_mut(&mut chunks, |c| {
        let outs = c.corrections.iter_mut().zip(c.touching.iter_mut());
        for (&i, (out, out_touching)) in c.active.iter().zip(outs) {
            let i = i as usize;
            let (a, prev_a) = (read[i], prev[i]);
            // The vertex keeps its own thickness from the others, and from triangles at most
            // its triangle thickness (`Topology::self_collision_triangle_scales`).
            let scale = scales.get(i).copied().unwrap_or(1.0);
            let triangle_params = SelfCollision {
                thickness: params.thickness * triangle_scales.get(i).copied().unwrap_or(scale),
                ..params
            };
            let params = SelfCollision {
                thickness: params.thickness * scale,
                ..params
            };
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
                let t = ((slot & !BESIDE) >> 2) as usize;
                let (Some(&tri), Some(plane)) =
                    (triangles.get(t), listed.rank(t).and_then(|k| planes.get(k)))
                else {
                    continue;
                };
                let code = slot & 3;
                if let Some((da, bary)) =
                    triangle_correction(a, prev_a, plane, tri, read, prev, code, triangle_params)
                {
                    sum += da;
                    touching += 1;
                    // A triangle the vertex was over when the step began pushes back; one it
                    // came over within the step (beside it then) does not: with those too, the
                    // uneven crumpled cloth ended crossed in 7 of 12 runs (docs/experiments.md).
                    if slot & BESIDE == 0 {
                        for (k, &v) in tri.iter().enumerate() {
                            let (wc, b) = (read[v as usize].w, bary[k]);
                            let r = reaction(da, a.w, wc, b);
                            if wc > 0.0 && b > 0.0 && r.is_finite() {
                                reactions.add(v as usize, r);
                            }
                        }
                    }
                }
            }
            *out = sum;
            *out_touching = touching;
        }
    });
    drop(chunks);
    // All move at once, by runs of vertices in parallel (`active` rises): each by the mean of
    // its own corrections and its reactions.
    let (corrections, touching) = (&scratch.corrections, &scratch.touching);
    each_run(pos, par, |first, run| {
        let mut k = active.partition_point(|&i| (i as usize) < first);
        for (v, x) in run.iter_mut().enumerate() {
            let v = first + v;
            let (mut sum, mut count) = reactions.take(v);
            if active.get(k).is_some_and(|&i| i as usize == v) {
                sum += corrections[k];
                count += touching[k];
                k += 1;
            }
            if count > 0 && x.w > 0.0 {
                *x += (sum / count as f32).extend(0.0);
            }
        }
    });
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
    scales: &[f32],
    params: SelfCollision,
    dt: f32,
    scratch: &mut SelfCollisionScratch,
    par: &impl Parallel,
) {
    if let Some(motion) = motion_margin(vel, params, dt, par) {
        let t = params.thickness;
        scratch.find::<false>(pos, vel, dt, rest, triangles, scales, t, motion, par);
    } else {
        scratch.neighbour_count.clear();
        scratch.neighbour_count.resize(pos.len(), 0);
        scratch.triangle_count.clear();
        scratch.triangle_count.resize(pos.len(), 0);
        scratch.active.clear();
        scratch.listed.set(Vec::new());
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
    use crate::solver::parallel::{Serial, Workers};

    /// The candidate lists of one step of 1/60 s, on one thread.
    fn candidates(
        pos: &[Vec4],
        vel: &[Vec4],
        rest: &[Vec3],
        tris: &[[u32; 3]],
        params: SelfCollision,
    ) -> SelfCollisionScratch {
        let mut s = SelfCollisionScratch::default();
        find_self_collision_candidates(
            pos,
            vel,
            rest,
            tris,
            &[],
            params,
            1.0 / 60.0,
            &mut s,
            &Serial,
        );
        s
    }

    #[test]
    fn close_vertices_are_pushed_apart_to_thickness() {
        let mut pos = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 0.01, 0.0, 1.0),
            Vec4::new(5.0, 0.0, 0.0, 1.0),
        ];
        // They closed from 0.11 apart within the substep.
        let mut prev = pos.clone();
        prev[0].y = -0.05;
        prev[1].y = 0.06;
        let rest = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        let mut s = candidates(&pos, &[Vec4::ZERO; 3], &rest, &[], params);
        self_collide(
            &mut pos,
            &prev,
            &[],
            Scales::default(),
            params,
            &mut s,
            &Serial,
        );
        assert!((pos[0].xyz().distance(pos[1].xyz()) - 0.1).abs() < 1e-6);
        assert_eq!(pos[2], prev[2]);
        // Equal masses: symmetric push.
        assert!((pos[0].y + 0.045).abs() < 1e-6 && (pos[1].y - 0.055).abs() < 1e-6);
    }

    /// An overlap a pair already had when the substep began is undone by `DEPENETRATION`
    /// thicknesses a substep, not at once; what the pair closed within the substep, at once.
    #[test]
    fn an_old_overlap_is_undone_a_little_each_substep() {
        let start = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 0.01, 0.0, 1.0),
        ];
        let rest = [Vec3::ZERO, Vec3::X];
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        let step = DEPENETRATION * params.thickness;
        let mut s = candidates(&start, &[Vec4::ZERO; 2], &rest, &[], params);
        // One pass from `prev`; how far apart the two are after it.
        let mut pass = |pos: &mut Vec<Vec4>, prev: &[Vec4]| {
            self_collide(pos, prev, &[], Scales::default(), params, &mut s, &Serial);
            pos[0].xyz().distance(pos[1].xyz())
        };
        let mut pos = start.clone();
        let apart = pass(&mut pos, &start);
        assert!((apart - (0.01 + step)).abs() < 1e-6, "{apart}");
        // Closing 0.02 within the next substep: that is undone, and another share.
        let prev = pos.clone();
        pos[1].y -= 0.02;
        let apart = pass(&mut pos, &prev);
        assert!((apart - (0.01 + 2.0 * step)).abs() < 1e-6, "{apart}");
        // What is left (0.02) is less than a share: apart to the thickness.
        let prev = pos.clone();
        let apart = pass(&mut pos, &prev);
        assert!((apart - 0.1).abs() < 1e-6, "{apart}");
    }

    #[test]
    fn neighbours_resting_within_two_thicknesses_are_left_to_their_constraints() {
        let mut pos = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(0.05, 0.0, 0.0, 1.0),
        ];
        let prev = pos.clone();
        let rest = [Vec3::ZERO, Vec3::X * 0.05];
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        let mut s = candidates(&pos, &[Vec4::ZERO; 2], &rest, &[], params);
        self_collide(
            &mut pos,
            &prev,
            &[],
            Scales::default(),
            params,
            &mut s,
            &Serial,
        );
        assert_eq!(pos, prev);
    }

    /// One pass of [`self_collide`] on one thread, every vertex at the cloth's thickness.
    fn pass(
        pos: &mut [Vec4],
        prev: &[Vec4],
        tris: &[[u32; 3]],
        params: SelfCollision,
        s: &mut SelfCollisionScratch,
    ) {
        self_collide(pos, prev, tris, Scales::default(), params, s, &Serial);
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
        let mut s = candidates(&start, &[Vec4::ZERO; 4], &rest, &tri, params);
        assert_eq!(s.triangle_count[3], 1);
        assert_eq!(s.triangles[3 * MAX_SELF_TRIANGLES], SIDE_FRONT);
        // Come within the substep from 0.2 over it, too close on its side: pushed out along
        // +z, its share half the push (equal masses).
        let mut from = start.clone();
        from[3].z = 0.2;
        let mut pos = start.clone();
        pass(&mut pos, &from, &tri, params, &mut s);
        assert!((pos[3].z - 0.06).abs() < 1e-6, "{}", pos[3]);
        // Went through during the substep: brought back to its side.
        let mut pos = start.clone();
        pos[3].z = -0.05;
        pass(&mut pos, &from, &tri, params, &mut s);
        assert!((pos[3].z - (-0.05 + 0.075)).abs() < 1e-6, "{}", pos[3]);
        // Too close since before the substep: pushed out by DEPENETRATION thicknesses.
        let mut pos = start.clone();
        pass(&mut pos, &start, &tri, params, &mut s);
        let push = 0.5 * DEPENETRATION * params.thickness;
        assert!((pos[3].z - (0.02 + push)).abs() < 1e-6, "{}", pos[3]);
        // The triangle takes the reaction at its corners, by their weights at the point under
        // the vertex (0.5, 0.25, 0.25; equal masses): the contact moves no momentum.
        for (k, b) in [0.5, 0.25, 0.25].into_iter().enumerate() {
            let moved = pos[k] - start[k];
            assert!(
                (moved.z + push * b).abs() < 1e-6 && moved.x == 0.0 && moved.y == 0.0,
                "corner {k} moved by {moved}"
            );
        }
        let momentum: f32 = pos.iter().zip(&start).map(|(p, s)| (p.z - s.z) / p.w).sum();
        assert!(momentum.abs() < 1e-6, "{momentum}");
    }

    /// A vertex that came over a triangle within the step (beside it when the lists were made)
    /// is stopped by it, but the triangle takes no reaction: with it, crumpled cloths of
    /// uneven edges ended tangled more often (docs/experiments.md).
    #[test]
    fn a_triangle_the_vertex_came_over_within_the_step_takes_no_reaction() {
        let tri = [[0u32, 1, 2]];
        let rest = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z * 10.0];
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        // Beside the triangle when the lists are made, moving over it.
        let mut start = vec![
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 1.0, 0.0, 1.0),
            Vec4::new(-0.05, 0.25, 0.05, 1.0),
        ];
        let vel = [
            Vec4::ZERO,
            Vec4::ZERO,
            Vec4::ZERO,
            Vec4::new(6.0, 0.0, 0.0, 0.0),
        ];
        let mut s = candidates(&start, &vel, &rest, &tri, params);
        assert_eq!(s.triangle_count[3], 1);
        assert_ne!(s.triangles[3 * MAX_SELF_TRIANGLES] & BESIDE, 0);
        start[3].x = 0.25;
        let mut pos = start.clone();
        pass(&mut pos, &start, &tri, params, &mut s);
        assert!(pos[3].z > 0.05, "the vertex is pushed off: {}", pos[3]);
        assert_eq!(&pos[..3], &start[..3]);
    }

    /// A 5 × 5 sheet in the XY plane, 0.1 apart, its triangles and rest positions.
    fn sheet() -> (Vec<Vec4>, Vec<Vec3>, Vec<[u32; 3]>) {
        let rest: Vec<Vec3> = (0..25)
            .map(|k| Vec3::new((k % 5) as f32 * 0.1, (k / 5) as f32 * 0.1, 0.0))
            .collect();
        let mut tris = Vec::new();
        for y in 0..4u32 {
            for x in 0..4u32 {
                let k = y * 5 + x;
                tris.push([k, k + 1, k + 6]);
                tris.push([k, k + 6, k + 5]);
            }
        }
        (rest.iter().map(|p| p.extend(1.0)).collect(), rest, tris)
    }

    #[test]
    fn the_own_neighbourhood_is_looked_at_only_where_it_folded() {
        let (pos, rest, tris) = sheet();
        let params = SelfCollision {
            thickness: 0.1,
            friction: 0.0,
        };
        let lists = |pos: &[Vec4], vel: &[Vec4]| {
            let s = candidates(pos, vel, &rest, &tris, params);
            let count = s.triangle_count[12] as usize;
            s.triangles[12 * MAX_SELF_TRIANGLES..12 * MAX_SELF_TRIANGLES + count].to_vec()
        };
        // The middle vertex leaves the flat sheet fast along its normal: fast enough to slide
        // over the triangles beside it (within a thickness), but the sheet around it only
        // stretches, so none of them is looked at.
        let mut vel = vec![Vec4::ZERO; 25];
        vel[12] = Vec4::new(0.0, 0.0, 3.0, 0.0);
        assert_eq!(lists(&pos, &vel), Vec::<u32>::new());
        // The same with a vertex two edges away come 10 % closer (the sheet folds between
        // them): the triangles beside it that it can slide over are.
        let mut folded = pos.clone();
        folded[14].x -= 0.02;
        let found = lists(&folded, &vel);
        assert!(!found.is_empty());
        assert!(found.iter().all(|s| s & 3 == SIDE_FREE), "{found:?}");
        // Or the same vertex coming that close within two steps at its velocity (rising with
        // the middle one).
        let mut closing = vel.clone();
        closing[14] = Vec4::new(-0.6, 0.0, 3.0, 0.0);
        let ahead = lists(&pos, &closing);
        assert!(!ahead.is_empty());
        assert!(ahead.iter().all(|s| s & 3 == SIDE_FREE), "{ahead:?}");
        // Only just not: 2 % closer within two steps.
        closing[14].x = -0.12;
        assert_eq!(lists(&pos, &closing), Vec::<u32>::new());
    }

    /// The grid finds every neighbour brute force finds, wherever the vertices are: a pile
    /// around the origin, around a point 10⁹ m out (cells beyond what an `i32`
    /// counts), two vertices alone (fewer buckets than a row has cells) and non-finite ones.
    #[test]
    fn the_grid_finds_what_brute_force_finds() {
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let params = SelfCollision {
            thickness: 0.05,
            friction: 0.0,
        };
        for (n, at) in [(400, Vec3::ZERO), (400, Vec3::splat(1e9)), (2, Vec3::ZERO)] {
            let spread = if n == 2 { 0.04 } else { 0.3 };
            let mut pos: Vec<Vec4> = (0..n)
                .map(|_| (at + Vec3::new(next(), next(), next()) * spread).extend(1.0))
                .collect();
            if n > 2 {
                pos[3].x = f32::NAN;
                pos[5].y = f32::INFINITY;
            }
            // Rest far apart: every pair can be neighbours.
            let rest: Vec<Vec3> = (0..n).map(|k| Vec3::X * k as f32).collect();
            let vel = vec![Vec4::ZERO; n];
            let s = candidates(&pos, &vel, &rest, &[], params);
            let reach = params.thickness;
            let mut total = 0;
            for i in 0..n {
                let p = pos[i].xyz();
                let mut want: Vec<u32> = (0..n)
                    .filter(|&j| {
                        j != i
                            && p.is_finite()
                            && pos[j].xyz().is_finite()
                            && (pos[j].xyz() - p).length_squared() < reach * reach
                    })
                    .map(|j| j as u32)
                    .collect();
                want.truncate(MAX_SELF_NEIGHBOURS);
                let count = s.neighbour_count[i] as usize;
                let got = &s.neighbours[i * MAX_SELF_NEIGHBOURS..i * MAX_SELF_NEIGHBOURS + count];
                assert_eq!(got, &want[..], "vertex {i} of {n} at {at}");
                total += count;
            }
            assert!(total > 0, "{n} at {at}: no pairs to compare");
        }
    }

    /// The own neighbourhood's groups of entries kept from the walk give the lists a second
    /// walk gives, in a sheet crumpled to half its size (folded everywhere) with a thickness
    /// of three edges (some vertices see more than [`NEAR_GROUPS`] groups of their own
    /// neighbourhood, and take the second walk either way).
    /// A 40 × 40 sheet crumpled to half its size, its velocities random, and a thickness of
    /// three edges.
    #[expect(clippy::type_complexity)]
    fn crumpled_sheet() -> (
        Vec<Vec4>,
        Vec<Vec4>,
        Vec<Vec3>,
        Vec<[u32; 3]>,
        SelfCollision,
    ) {
        let mut seed = 11u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let side = 40;
        let h = 0.01;
        let at = |i: usize| Vec3::new((i % side) as f32, (i / side) as f32, 0.0) * h;
        let rest: Vec<Vec3> = (0..side * side).map(at).collect();
        let pos: Vec<Vec4> = rest
            .iter()
            .map(|r| (*r * 0.5 + Vec3::new(next(), next(), next()) * h).extend(1.0))
            .collect();
        let vel: Vec<Vec4> = (0..pos.len())
            .map(|_| Vec3::new(next(), next(), next()).extend(0.0))
            .collect();
        let mut tris = Vec::new();
        for y in 0..side - 1 {
            for x in 0..side - 1 {
                let i = (y * side + x) as u32;
                let s = side as u32;
                tris.push([i, i + 1, i + s + 1]);
                tris.push([i, i + s + 1, i + s]);
            }
        }
        let params = SelfCollision {
            thickness: 3.0 * h,
            friction: 0.0,
        };
        (pos, vel, rest, tris, params)
    }

    #[test]
    fn the_kept_groups_find_what_a_second_walk_finds() {
        let (pos, vel, rest, tris, params) = crumpled_sheet();
        let dt = 1.0 / 60.0;
        let motion = motion_margin(&vel, params, dt, &Serial).unwrap();
        let t = params.thickness;
        let mut kept = SelfCollisionScratch::default();
        kept.find::<false>(&pos, &vel, dt, &rest, &tris, &[], t, motion, &Serial);
        let mut walked = SelfCollisionScratch::default();
        walked.find::<true>(&pos, &vel, dt, &rest, &tris, &[], t, motion, &Serial);
        assert_eq!(kept.neighbour_count, walked.neighbour_count);
        assert_eq!(kept.triangle_count, walked.triangle_count);
        let mut found = 0;
        for (i, &count) in kept.triangle_count.iter().enumerate() {
            let slots = i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count as usize;
            assert_eq!(
                kept.triangles[slots.clone()],
                walked.triangles[slots],
                "vertex {i}"
            );
            found += count;
        }
        assert!(
            found > 1000,
            "only {found} triangles found: the sheet did not fold"
        );
    }

    /// The lists kept from one mesh (triangles by first corner, longest edge) are rebuilt for
    /// another: a scratch that stepped the whole sheet, then the sheet with half its triangles
    /// gone (as after a tear), finds what a fresh scratch finds.
    #[test]
    fn a_scratch_stepping_another_mesh_finds_what_a_fresh_one_finds() {
        let (pos, vel, rest, tris, params) = crumpled_sheet();
        let dt = 1.0 / 60.0;
        let mut reused = candidates(&pos, &vel, &rest, &tris, params);
        let whole = reused.triangle_count.clone();
        let torn = &tris[tris.len() / 2..];
        find_self_collision_candidates(
            &pos,
            &vel,
            &rest,
            torn,
            &[],
            params,
            dt,
            &mut reused,
            &Serial,
        );
        let fresh = candidates(&pos, &vel, &rest, torn, params);
        assert_ne!(
            reused.triangle_count, whole,
            "the torn sheet found the same triangles"
        );
        assert_eq!(reused.neighbour_count, fresh.neighbour_count);
        assert_eq!(reused.triangle_count, fresh.triangle_count);
        for (i, &count) in fresh.triangle_count.iter().enumerate() {
            let slots = i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count as usize;
            assert_eq!(
                reused.triangles[slots.clone()],
                fresh.triangles[slots],
                "vertex {i}"
            );
        }
    }

    #[test]
    fn the_grid_sorts_every_vertex_into_its_bucket_whatever_the_threads() {
        // Three runs of the sort, a few positions not finite, cells of a few vertices each.
        let n = 2 * SORT_RUN + 1000;
        let mut seed = 11u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut pos: Vec<Vec4> = (0..n)
            .map(|_| Vec3::new(next(), next(), next()).extend(1.0))
            .collect();
        // Some equal x in a bucket: vertex order decides.
        for k in (100..200).step_by(10) {
            pos[k + 5] = pos[k] + Vec4::new(0.0, 0.001, 0.0, 0.0);
        }
        for k in [0, 17, SORT_RUN, n - 1] {
            pos[k].y = f32::NAN;
        }
        let vel = vec![Vec4::ZERO; n];
        let rest = vec![Vec3::ZERO; n];
        let fill = |par: &dyn Fn(&mut Grid)| {
            let mut g = Grid::default();
            par(&mut g);
            g
        };
        let serial = fill(&|g| g.fill(&pos, &vel, &rest, 0.0, 0.05, &Serial));
        let pool = Workers::new(3);
        let threaded = fill(&|g| g.fill(&pos, &vel, &rest, 0.0, 0.05, &pool));
        assert_eq!(serial, threaded);
        let g = serial;
        let size = g.start.len() - 1;
        let real = g.start[size] as usize;
        assert_eq!(real, n - 4);
        let mut seen = vec![false; n];
        for h in 0..size {
            let bucket = &g.entries[g.start[h] as usize..g.start[h + 1] as usize];
            assert!(
                bucket.windows(2).all(|w| {
                    let (a, b) = (pos[w[0] as usize].x, pos[w[1] as usize].x);
                    a < b || (a == b && w[0] < w[1])
                }),
                "ordered by x, then by vertex"
            );
            for (k, &j) in bucket.iter().enumerate() {
                let j = j as usize;
                let c = cell_of(pos[j].xyz(), 1.0 / 0.05);
                assert_eq!(grid_bucket(c, size - 1), h, "vertex {j}");
                assert_eq!(g.cells[g.start[h] as usize + k], c);
                assert!(!std::mem::replace(&mut seen[j], true), "vertex {j} twice");
            }
        }
        assert_eq!(seen.iter().filter(|&&s| s).count(), n - 4);
    }

    #[test]
    fn same_compares_every_run() {
        let pool = Workers::new(2);
        let a: Vec<u32> = (0..3 * 4 * CHUNK as u32 + 5).collect();
        let mut b = a.clone();
        assert!(same(&a, &b, &pool) && same(&a, &b, &Serial));
        *b.last_mut().unwrap() += 1;
        assert!(!same(&a, &b, &pool) && !same(&a, &b, &Serial));
        assert!(!same(&a, &a[1..], &pool));
        assert!(same::<u32>(&[], &[], &pool));
    }

    #[test]
    fn listed_triangles_rank_in_triangle_order() {
        let members = [0usize, 5, 31, 32, 33, 64, 100, 127];
        let words: Vec<AtomicU32> = (0..4).map(|_| AtomicU32::new(0)).collect();
        // Marked out of order and twice, as the query's threads do.
        for &t in members.iter().rev().chain(&members) {
            Listed::mark(&words, t);
        }
        Listed::mark(&words, 128); // past the set: ignored
        let mut listed = Listed::default();
        listed.set(words);
        for t in 0..130 {
            let expected = members.iter().position(|&m| m == t);
            assert_eq!(listed.rank(t), expected, "triangle {t}");
        }
        assert_eq!(listed.before.last(), Some(&(members.len() as u32)));
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
        // Beyond i32's range the cast saturates; the step down must not overflow.
        let far = cell_of(Vec3::new(-1e12, 1e12, -3.5e9), 1.0);
        assert_eq!(far.y, i32::MAX);
        assert!(far.x == i32::MIN || far.x == i32::MAX, "{far}");
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
