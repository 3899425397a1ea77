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
//! threads; within a bucket by vertex) and its lanes, one lane a work item.
//!
//! The CPU's hash keeps the cells of a row along x in consecutive buckets and the positions,
//! rest positions and positions two steps ahead in separate lanes; its cells are narrow along
//! x, so that a query reads a few runs of whole buckets in sequence (a row's cells beyond its
//! x range left out) and tests eight entries at a time (vectorised), in one walk: the
//! groups of eight holding some of the vertex's own neighbourhood are kept for the fold test
//! and its triangles after it, and a triangle is first tested against a bound from its
//! centroid (most of those looked at lie beside the vertex, farther than it can slide; for
//! the own neighbourhood's, the slide bounded from the speed of the first corner and the
//! fastest corner around it) before it is projected. The GPU's (`contact.wgsl`, `sc_query`)
//! is a linked list per bucket. Both find the same vertices and triangles and keep the same
//! lowest-numbered ones.
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
//! substeps instead of jumping out at once; what a vertex pair undoes of such an overlap moves
//! the substep's start too, so it puts them apart without throwing them apart, while a
//! vertex–triangle contact keeps that velocity); against a triangle with a corner resting nearer
//! the vertex than the thickness allows, a closed cloth keeps a thinner layer and an open one
//! of even edges undoes the older overlap only as far as its edges allow
//! ([`NEAR_CORNER_THICKNESS`]). A vertex pair's other vertex moves by its own
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
//!
//! The code: `grid.rs` makes the step's hash (cells, buckets, its parallel sort and lanes),
//! `query.rs` the once-a-step lists from it, `pass.rs` the per-substep pass over them, and
//! `crossings.rs` counts the edge–triangle pairs that cross (what the tests and examples
//! measure); the settings, the scratch and what the query and the pass share are here.

use std::ops::Range;
use std::sync::atomic::{AtomicI32, AtomicU32, Ordering};

use glam::{IVec3, Vec3, Vec4, Vec4Swizzles};

use crate::solver::parallel::Parallel;

mod crossings;
mod grid;
mod pass;
mod query;
#[cfg(test)]
mod tests;

pub use crossings::count_self_crossings;
use grid::*;
use pass::*;
pub(crate) use pass::{Scales, limits_depenetration, near_corner_rule, self_collide};
pub use query::triangle_reach;
use query::*;
pub(crate) use query::{find_self_collision_candidates, first_corner_reach};

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
    /// Per vertex, the fastest a corner of a triangle it is the first corner of moves
    /// relative to it at the step's start (a bound for the query's slide, see
    /// [`Query::triangles_through`]).
    corner_speeds: Vec<f32>,
    /// Tests: the query slides over the own neighbourhood's triangles by the whole margin in
    /// its bound, as it did before [`SelfCollisionScratch::corner_speeds`].
    #[cfg(test)]
    margin_slides: bool,
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
    /// Per active vertex, the part of its vertex–vertex contacts' corrections that undoes an
    /// overlap older than the substep (moved without velocity: see [`self_collide`]).
    unmoving: Vec<Vec3>,
    /// Per vertex, the reactions of the vertex–triangle contacts it is a corner of.
    reactions: Reactions,
    /// The triangles in some vertex's list: one bit a triangle, and per word of bits the
    /// number set before it (a listed triangle's place among them, see [`Listed::rank`]).
    listed: Listed,
    /// The listed triangles' [`Plane`]s at the current pass's start, in triangle order.
    pass_planes: Vec<Plane>,
    /// A closed cloth's: per vertex, for each of its listed triangles (in its slots' places),
    /// the most it keeps off the triangle ([`pass::triangle_cap`]), which depends on the mesh
    /// alone: made by a step's first pass, read by every pass after it.
    caps: Vec<f32>,
    /// Whether `caps` holds the current lists' (the query clears it).
    caps_ready: bool,
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
    /// Offsets per vertex into `vertex_tris`, then every triangle through it, in triangle
    /// order (the GPU's `tri_offsets`): which vertices an edge joins it to.
    vertex_start: Vec<u32>,
    vertex_tris: Vec<u32>,
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
        // Every triangle through each vertex, in triangle order.
        self.vertex_start.clear();
        self.vertex_start.resize(n + 1, 0);
        for t in triangles.iter().filter(|t| valid(t)) {
            for &k in t {
                self.vertex_start[k as usize + 1] += 1;
            }
        }
        for k in 0..n {
            self.vertex_start[k + 1] += self.vertex_start[k];
        }
        self.vertex_tris.resize(self.vertex_start[n] as usize, 0);
        let mut fill = self.vertex_start.clone();
        for (ti, t) in triangles.iter().enumerate().filter(|(_, t)| valid(t)) {
            for &k in t {
                let at = &mut fill[k as usize];
                self.vertex_tris[*at as usize] = ti as u32;
                *at += 1;
            }
        }
    }

    /// Whether an edge joins vertex `i` to each corner of `tri`, none of which is `i`: then
    /// `i` and the triangle are as rigid as a tetrahedron of edges, and `i` stays as far from
    /// the triangle's plane as it rests (`pass::triangle_cap`). The GPU's `sc_joined_to_all`.
    fn joined_to_all(&self, i: usize, tri: [u32; 3]) -> bool {
        let (Some(&start), Some(&end)) = (self.vertex_start.get(i), self.vertex_start.get(i + 1))
        else {
            return false;
        };
        let mut found = [false; 3];
        for &t in self
            .vertex_tris
            .get(start as usize..end as usize)
            .unwrap_or(&[])
        {
            let Some(own) = self.triangles.get(t as usize) else {
                continue;
            };
            for (f, k) in found.iter_mut().zip(tri) {
                *f |= own.contains(&k);
            }
        }
        found == [true; 3] && !tri.contains(&(i as u32))
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

/// The most a vertex of a closed cloth is kept off a triangle, in rest distances from the
/// triangle's nearest corner ([`Topology::is_closed`](crate::solver::Topology::is_closed));
/// on an open cloth of even edges, the farthest from the triangle's plane an overlap older
/// than the substep is pushed out to (what the pair closed within the substep is undone up to
/// the whole thickness, which opens a crumpled sheet's tight folds; pushing on from there
/// every substep kept a cloth draped over a collider trembling for ever).
/// A vertex over a triangle through its own neighbour (a corner one edge away, under a
/// thickness at the default) can get no farther from that triangle's plane than from that
/// corner, so a whole thickness is more than its edges allow: the contact pushed it out every
/// substep and the edges pulled it back. Where the cloth can unfold, that push is what opens a
/// crumpled sheet's tight folds (capped on open sheets, 15 of 27 crumpled uneven cloths ended
/// crossed instead of 4); a closed shape cannot unfold (a flattened cube, sphere or torus must
/// crease), and there the push went on for ever: with self-collision none came to rest, its
/// vertices moving at 3–12 m/s on the ground after 10 s (docs/experiments.md).
pub const NEAR_CORNER_THICKNESS: f32 = 0.9;

/// A triangle whose first corner rests more than 2.5 thicknesses from the vertex is only looked
/// at when that corner is now closer to it than 0.9 of their rest distance (squared here): the
/// cloth has folded or piled up between them. Written squared, not as `0.9 * 0.9`: WGSL folds
/// that product exactly before rounding (0.81) and `f32` rounds each factor (0.80999994), and
/// the two sides must compare against the same number.
const FOLDED2: f32 = 0.81;

/// The query's grid cells are the query's radius over this across the rows (4/3 of the radius
/// in y and z): a query reads four to nine rows. Narrower rows (1 or 1.5 per radius) look at
/// fewer vertices outside the radius but cost more rows; measured at 256² with self-collision
/// (`tradeoff --scene-costs`), this width is faster than those and than rows twice as wide.
/// The cell sizes change what is looked at, never what is found.
const CELLS_PER_RADIUS: f32 = 0.75;

/// Along a row (x) the cells are this share of their size across it (a third of the radius),
/// so that a row's range is a run of whole buckets, read without a search for where the
/// radius begins and ends in them: a bucket holds few vertices, and the row's ends are cut
/// within a few hundredths of the radius's width. Measured (`tradeoff --scene-costs`, 256²,
/// one thread, the query's first frames): 1/8 to 1/4 alike, 1/2 slower, whole cells with the
/// search (before) slower still.
const X_CELL: f32 = 0.25;

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

/// Vertices handled by one parallel work item (at most: see [`chunk_for`]).
const CHUNK: usize = 512;

/// The fewest vertices a work item of the query or the pass gets.
const MIN_CHUNK: usize = 64;

/// Vertices per work item of the query and the pass for `n` vertices on `threads` threads:
/// [`CHUNK`], or on several threads about a quarter of a thread's share where that is less
/// (at least [`MIN_CHUNK`]), so that a cloth of a few hundred or thousand vertices, whose
/// self-collision is most of its step, is spread over the threads too. Each vertex's lists
/// and correction are its own and the reactions are summed in fixed point, so the split
/// changes nothing in the results.
fn chunk_for(n: usize, threads: usize) -> usize {
    if threads <= 1 {
        CHUNK
    } else {
        n.div_ceil(4 * threads).clamp(MIN_CHUNK, CHUNK)
    }
}
