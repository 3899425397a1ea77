//! The per-substep pass: every vertex moved by the mean of its contacts' corrections and
//! the reactions of the triangles it presses on (Jacobi, in fixed point for the reactions).

use super::*;
use crate::solver::collision::sdf::closest_point_on_triangle;

/// Per vertex, the reactions a pass's vertex–triangle contacts give the triangles' corners,
/// summed in fixed point ([`REACTION_UNITS`] a metre) so that the sum does not depend on the
/// order the contacts arrive in: `x`, `y`, `z` and the number of reactions, four atomics a
/// vertex, each left at zero after the pass that reads it.
#[derive(Default)]
pub(super) struct Reactions(Vec<AtomicI32>);

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
pub(super) const REACTION_UNITS: f32 = 67_108_864.0;

/// `x` metres in [`REACTION_UNITS`], rounded to even as WGSL's `round` does, within `i32`.
#[inline]
fn to_fixed(x: f32) -> i32 {
    (x * REACTION_UNITS).clamp(-2.0e9, 2.0e9).round_ties_even() as i32
}

/// How far a contact pushes its pair apart: the `overlap` with the contact's thickness
/// (`thickness - distance`), but of it at most what the pair closed within the substep
/// (`approach`, along the contact's normal) plus `depenetration` (usually [`DEPENETRATION`]
/// thicknesses).
#[inline]
fn limited_push(overlap: f32, approach: f32, depenetration: f32) -> f32 {
    overlap.min(approach.max(0.0) + depenetration)
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
/// thicknesses), mass-weighted, with friction on the pair's sliding; and the part of it that
/// undoes the overlap the pair began the substep with, which [`self_collide`] moves without
/// velocity (see there). `None` when the pair does not touch or the result is not finite.
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
    let approach = n.dot(prev_a.xyz() - prev_b.xyz()) - len;
    let push = limited_push(limit - len, approach, DEPENETRATION * limit);
    let old = n * ((push - approach.max(0.0)).max(0.0) * wa / w);
    let mut da = n * (push * wa / w);
    let db = -n * (push * wb / w);
    // Friction on the relative sliding of the pair during the substep.
    let slide = (a.xyz() + da - prev_a.xyz()) - (b.xyz() + db - prev_b.xyz());
    if let Some((tangential, keep)) = sliding(slide, n, push, params.friction) {
        da -= tangential * (keep * wa / w);
    }
    (da.is_finite() && old.is_finite()).then_some((da, old))
}

/// The correction of vertex `a` (with `prev_a`) from triangle `tri` (its corners in `read`,
/// `prev`; `plane` its [`Plane`] at `read`) and the side code it keeps to: when `a` is
/// over the triangle and closer than `thickness` on its side, or through it to the other side
/// (by less than 2.5 thicknesses), pushed out to `thickness` on its side along the normal (at
/// most what it closed on the triangle within the substep plus [`DEPENETRATION`] thicknesses,
/// that share only up to `meet()` from the plane when that is under the thickness: see
/// [`NearCorner::Depenetration`]; asked only of a contact that touches), its share by the
/// inverse masses (the triangle's at the point under `a`), with friction on the sliding; with
/// the barycentric weights of the point under `a`. `None` when it does not touch. (The GPU's
/// `sc_triangle` projects the same way.)
#[inline]
#[expect(clippy::too_many_arguments)]
pub(super) fn triangle_correction(
    a: Vec4,
    prev_a: Vec4,
    plane: &Plane,
    tri: [u32; 3],
    read: &[Vec4],
    prev: &[Vec4],
    code: u32,
    params: SelfCollision,
    meet: impl FnOnce() -> f32,
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
    let meet = meet();
    let depenetration = if meet < thickness {
        (DEPENETRATION * thickness).min((meet - ds).max(0.0))
    } else {
        DEPENETRATION * thickness
    };
    let push = limited_push(thickness - ds, approach, depenetration);
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
    unmoving: &'a mut [Vec3],
    touching: &'a mut [u32],
}

/// Per vertex, the thickness it keeps from other vertices and from triangles over the
/// cloth's ([`Topology::self_collision_scales`](crate::solver::Topology::self_collision_scales)
/// and [`Topology::self_collision_triangle_scales`](crate::solver::Topology::self_collision_triangle_scales));
/// empty: the cloth's; and the rest positions, with what they limit of a contact against a
/// triangle with a corner resting near the vertex (`near_corner`; empty: nothing).
#[derive(Clone, Copy, Default)]
pub(crate) struct Scales<'a> {
    pub vertices: &'a [f32],
    pub triangles: &'a [f32],
    pub rest: &'a [Vec3],
    pub near_corner: NearCorner,
}

/// What a vertex–triangle contact keeps to where a corner of the triangle rests nearer the
/// vertex than the thickness divided by [`NEAR_CORNER_THICKNESS`]: no vertex gets farther from
/// a plane through a corner than from that corner, so the whole thickness cannot be met there.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum NearCorner {
    /// The whole thickness (a cloth of uneven edges).
    #[default]
    Thickness,
    /// A closed cloth ([`Topology::is_closed`](crate::solver::Topology::is_closed)): the
    /// thickness capped at [`NEAR_CORNER_THICKNESS`] times the rest distance from the
    /// triangle's nearest corner ([`triangle_cap`]).
    Capped,
    /// An open cloth of even edges: the whole thickness against what the pair closed within
    /// the substep, but an overlap older than the substep undone only up to
    /// [`NEAR_CORNER_THICKNESS`] times that rest distance from the plane. The contact keeps a
    /// fold that closes from closing through (what opens a crumpled sheet's tight folds) but
    /// does not push on a fold held shut (a cloth wrapped over a collider), which it did every
    /// substep for ever: draped over a ball, box or capsule, a cloth with self-collision never
    /// came to rest (docs/experiments.md).
    Depenetration,
}

/// Whether an open cloth of `topology` takes [`NearCorner::Depenetration`]: its edges are even
/// ([`EVEN_EDGE_SPREAD`](crate::solver::limits::EVEN_EDGE_SPREAD)). On uneven meshes (per-vertex
/// thicknesses) the crumpled cloths of `tests/self_collision.rs` crossed more with it. The
/// GPU's `FLAG_EVEN`.
pub(crate) fn limits_depenetration(topology: &crate::solver::mesh::Topology) -> bool {
    topology.rest_edge_spread() <= crate::solver::limits::EVEN_EDGE_SPREAD
}

/// The [`NearCorner`] rule of a cloth of `topology`.
pub(crate) fn near_corner_rule(topology: &crate::solver::mesh::Topology) -> NearCorner {
    if topology.is_closed() {
        NearCorner::Capped
    } else if limits_depenetration(topology) {
        NearCorner::Depenetration
    } else {
        NearCorner::Thickness
    }
}

/// [`NEAR_CORNER_THICKNESS`] times the rest distance from vertex `i` to triangle `tri`'s
/// nearest corner (`rest`: the rest positions); `None` without them.
#[inline]
fn near_corner_reach(rest: &[Vec3], i: usize, tri: [u32; 3]) -> Option<f32> {
    let &rest_i = rest.get(i)?;
    let mut near2 = f32::INFINITY;
    for k in tri {
        let &c = rest.get(k as usize)?;
        near2 = near2.min((c - rest_i).length_squared());
    }
    Some(NEAR_CORNER_THICKNESS * near2.sqrt())
}

/// [`NEAR_CORNER_THICKNESS`] times the rest distance from vertex `i` to triangle `tri` (to
/// its nearest point, `rest`: the rest positions); `None` without them. At most
/// [`near_corner_reach`]: the nearest point may lie on an edge or inside the triangle.
#[inline]
fn rest_triangle_reach(rest: &[Vec3], i: usize, tri: [u32; 3]) -> Option<f32> {
    let &rest_i = rest.get(i)?;
    let corners = [
        *rest.get(tri[0] as usize)?,
        *rest.get(tri[1] as usize)?,
        *rest.get(tri[2] as usize)?,
    ];
    let d = closest_point_on_triangle(rest_i, &corners) - rest_i;
    Some(NEAR_CORNER_THICKNESS * d.dot(d).sqrt())
}

/// The most vertex `i` of a closed cloth (`rest`: its rest positions) keeps off triangle
/// `tri` (its thickness there is the smaller of this and its own): [`NEAR_CORNER_THICKNESS`]
/// times its rest distance from the triangle's nearest corner, or from the triangle itself
/// ([`rest_triangle_reach`]) where an edge joins `i` to each of its corners (`joined`);
/// infinite without `rest`. The GPU's `sc_capped_thickness`, which takes the smaller.
///
/// No vertex gets farther from a plane through a corner than from that corner. Where edges
/// join the vertex to all three corners, the four are as rigid as a tetrahedron and the
/// vertex stays about as far from the triangle as it rests: a cone's tip (joined to every
/// vertex of its base) rests 0.5 m over the base's triangles of a 0.5 m Bevy `Cone`, and held
/// 0.9 of its distance from their nearest corner (0.52 m) off them, it was pushed up every
/// substep and pulled back by its edges: with self-collision the cone flew about the floor at
/// 11–28 m/s (docs/experiments.md). From the triangle everywhere, creases of the closed
/// cube and torus of `tests/self_collision.rs` ended crossed or kept moving more often.
///
/// It depends on the mesh alone, so a step makes it once per listed triangle
/// ([`fill_caps`]): made in every pass, it and the joined test were a third of a crumpled
/// closed cube's self-collision (docs/performance.md).
#[inline]
pub(super) fn triangle_cap(rest: &[Vec3], i: usize, tri: [u32; 3], joined: bool) -> f32 {
    let reach = if joined {
        rest_triangle_reach(rest, i, tri)
    } else {
        near_corner_reach(rest, i, tri)
    };
    reach.unwrap_or(f32::INFINITY)
}

/// Every listed triangle's [`triangle_cap`] into `scratch.caps` (slot for slot), unless the
/// current lists' are there already; runs of vertices in parallel.
fn fill_caps(
    scratch: &mut SelfCollisionScratch,
    rest: &[Vec3],
    triangles: &[[u32; 3]],
    par: &impl Parallel,
) {
    if scratch.caps_ready {
        return;
    }
    let n = scratch.triangle_count.len();
    scratch.caps.resize(n * MAX_SELF_TRIANGLES, f32::INFINITY);
    let (tc, tl, mesh) = (&scratch.triangle_count, &scratch.triangles, &scratch.mesh);
    let chunk = chunk_for(n, par.threads());
    let mut runs: Vec<(usize, &mut [f32])> = scratch
        .caps
        .chunks_mut(chunk * MAX_SELF_TRIANGLES)
        .enumerate()
        .map(|(k, caps)| (k * chunk, caps))
        .collect();
    par.for_each_mut(&mut runs, |(first, caps)| {
        for (k, caps) in caps.chunks_mut(MAX_SELF_TRIANGLES).enumerate() {
            let i = *first + k;
            let count = tc[i] as usize;
            let slots = &tl[i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count];
            for (cap, &slot) in caps.iter_mut().zip(slots) {
                let t = ((slot & !BESIDE) >> 2) as usize;
                *cap = triangles.get(t).map_or(f32::INFINITY, |&tri| {
                    triangle_cap(rest, i, tri, mesh.joined_to_all(i, tri))
                });
            }
        }
    });
    scratch.caps_ready = true;
}

/// One self-collision pass (Jacobi): every vertex sums its corrections from its touching
/// neighbours and triangles against the positions before the pass; each triangle it is over
/// (listed so at the step's start) takes the reaction of its correction at its corners
/// ([`reaction`], summed per corner in [`Reactions`]); every vertex then moves by the mean
/// of its corrections and reactions, all at once (`prev`: positions at the substep's start).
/// The vertices run in parallel; the result does not depend on how they are split.
///
/// What its vertex–vertex contacts push out of an overlap the pair began the substep with
/// moves `prev` too (by the same share of the mean), so it gives the vertex no velocity: the
/// two vertices are put apart, not thrown apart (as in Macklin et al., *Unified particle
/// physics for real-time applications*, 2014, §4.4). Turned into velocity, those pushes
/// kept a cloth draped over a ball trembling where its layers touch (of six drapes, three
/// still trembled after 20 s and one was awake after 30 s; docs/experiments.md).
/// Vertex–triangle contacts keep theirs:
/// moved without velocity too, a crumpled cloth's folds stayed shut and crossed (7 of 15 runs
/// instead of 1).
pub(crate) fn self_collide(
    pos: &mut [Vec4],
    prev: &mut [Vec4],
    triangles: &[[u32; 3]],
    scales: Scales<'_>,
    params: SelfCollision,
    scratch: &mut SelfCollisionScratch,
    par: &impl Parallel,
) {
    let Scales {
        vertices: scales,
        triangles: triangle_scales,
        rest,
        near_corner,
    } = scales;
    let n = pos.len();
    if scratch.neighbour_count.len() != n || scratch.triangle_count.len() != n {
        return;
    }
    if near_corner == NearCorner::Capped {
        fill_caps(scratch, rest, triangles, par);
    }
    let read: &[Vec4] = pos;
    let before: &[Vec4] = prev;
    scratch
        .listed
        .planes(triangles, read, &mut scratch.pass_planes, par);
    scratch.reactions.reset(n);
    let listed = &scratch.listed;
    let caps = &scratch.caps;
    let planes = &scratch.pass_planes;
    let active = &scratch.active;
    let reactions = &scratch.reactions;
    scratch.corrections.clear();
    scratch.corrections.resize(active.len(), Vec3::ZERO);
    scratch.touching.clear();
    scratch.touching.resize(active.len(), 0);
    scratch.unmoving.clear();
    scratch.unmoving.resize(active.len(), Vec3::ZERO);
    let (nc, nl) = (&scratch.neighbour_count, &scratch.neighbours);
    let (tc, tl) = (&scratch.triangle_count, &scratch.triangles);
    let chunk = chunk_for(active.len(), par.threads());
    let mut chunks: Vec<PassChunk> = active
        .chunks(chunk)
        .zip(scratch.corrections.chunks_mut(chunk))
        .zip(scratch.touching.chunks_mut(chunk))
        .zip(scratch.unmoving.chunks_mut(chunk))
        .map(|(((active, corrections), touching), unmoving)| PassChunk {
            active,
            corrections,
            unmoving,
            touching,
        })
        .collect();
    par.for_each_mut(&mut chunks, |c| {
        let outs = (c.corrections.iter_mut())
            .zip(c.touching.iter_mut())
            .zip(c.unmoving.iter_mut());
        for (&i, ((out, out_touching), out_unmoving)) in c.active.iter().zip(outs) {
            let i = i as usize;
            let (a, prev_a) = (read[i], before[i]);
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
            let mut unmoving = Vec3::ZERO;
            let mut touching = 0u32;
            let count = nc[i] as usize;
            for &j in &nl[i * MAX_SELF_NEIGHBOURS..i * MAX_SELF_NEIGHBOURS + count] {
                let j = j as usize;
                if let Some((da, old)) = pair_correction(a, prev_a, read[j], before[j], params) {
                    sum += da;
                    unmoving += old;
                    touching += 1;
                }
            }
            let count = tc[i] as usize;
            let slots = i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count;
            for (&slot, s) in tl[slots.clone()].iter().zip(slots) {
                let t = ((slot & !BESIDE) >> 2) as usize;
                let (Some(&tri), Some(plane)) =
                    (triangles.get(t), listed.rank(t).and_then(|k| planes.get(k)))
                else {
                    continue;
                };
                let code = slot & 3;
                let thickness = match near_corner {
                    NearCorner::Capped => triangle_params
                        .thickness
                        .min(caps.get(s).copied().unwrap_or(f32::INFINITY)),
                    NearCorner::Thickness | NearCorner::Depenetration => triangle_params.thickness,
                };
                let meet = || match near_corner {
                    NearCorner::Depenetration => {
                        near_corner_reach(rest, i, tri).unwrap_or(thickness)
                    }
                    NearCorner::Thickness | NearCorner::Capped => thickness,
                };
                let triangle_params = SelfCollision {
                    thickness,
                    ..triangle_params
                };
                if let Some((da, bary)) = triangle_correction(
                    a,
                    prev_a,
                    plane,
                    tri,
                    read,
                    before,
                    code,
                    triangle_params,
                    meet,
                ) {
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
            *out_unmoving = unmoving;
            *out_touching = touching;
        }
    });
    drop(chunks);
    // All move at once, by runs of vertices in parallel (`active` rises): each by the mean of
    // its own corrections and its reactions, and its substep start by the same share of what
    // its pairs pushed out of an old overlap.
    let (corrections, touching) = (&scratch.corrections, &scratch.touching);
    let unmoving = &scratch.unmoving;
    let mut runs: Vec<(usize, &mut [Vec4], &mut [Vec4])> = (pos.chunks_mut(4 * CHUNK))
        .zip(prev.chunks_mut(4 * CHUNK))
        .enumerate()
        .map(|(k, (xs, ps))| (k * 4 * CHUNK, xs, ps))
        .collect();
    par.for_each_mut(&mut runs, |(first, xs, ps)| {
        let first = *first;
        let mut k = active.partition_point(|&i| (i as usize) < first);
        for (v, (x, p)) in xs.iter_mut().zip(ps.iter_mut()).enumerate() {
            let v = first + v;
            let (mut sum, mut count) = reactions.take(v);
            let mut old = Vec3::ZERO;
            if active.get(k).is_some_and(|&i| i as usize == v) {
                sum += corrections[k];
                old = unmoving[k];
                count += touching[k];
                k += 1;
            }
            if count > 0 && x.w > 0.0 {
                *x += (sum / count as f32).extend(0.0);
                if old != Vec3::ZERO {
                    *p += (old / count as f32).extend(0.0);
                }
            }
        }
    });
}
