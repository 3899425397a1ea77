//! Constraints laid out for projection: partitioned, coloured, structure-of-arrays.
//!
//! Built once per topology (no allocation, hashing or sorting while stepping):
//!
//! 1. **Partition.** The vertices are cut into `K` contiguous index ranges (row strips on a
//!    grid). A constraint whose vertices all lie in one range belongs to that *part*; the
//!    others straddle parts. Parts touch disjoint vertices, so they are projected on
//!    different threads with no locks. A straddling constraint whose vertices lie in two
//!    neighbouring parts `s` and `s + 1` belongs to *seam* `s`, which spans the vertices from
//!    the first to the last its constraints touch. Where no two seams overlap (parts more
//!    than a few grid rows deep), every seam runs in parallel after the parts; otherwise
//!    every even seam, then every odd one (those never overlap). What is left (constraints across more than two parts, on a
//!    mesh whose vertex order jumps) is the *boundary*, projected last on one thread. `K`
//!    depends only on the vertex count, never on the thread count, so results are
//!    bit-identical however many threads run.
//! 2. **Colouring.** Inside each part (and the boundary), constraints are greedily coloured so
//!    that no two of one colour share a vertex. A colour is projected four constraints at a
//!    time with SIMD lanes; the GPU backend projects a colour per workgroup barrier. Constraints
//!    that find no free colour among 128 go to a last batch projected one by one. A mesh with
//!    a hub (a vertex in more than [`SYMMETRIC_SWEEP_DEGREE`] distances) or a closed one
//!    ([`Topology::is_closed`]) has its distances swept back too, the leftovers and then the
//!    colours in reverse, every projection.
//! 3. **Layout.** Each set stores its constraints colour by colour in parallel arrays
//!    (indices, rest values, material parameter, XPBD multiplier λ).
//!
//! The SIMD loops gather and scatter positions without bounds checks (they cost 13 % of a
//! step at 256²): a set's vertex indices are private to this module, checked against the
//! set's vertex count when it is built and never changed after, and each projection first
//! checks that the positions it is given are at least that long. This and
//! `parallel/workers.rs` are the only modules with `unsafe` code.

// See the last paragraph above.
#![allow(unsafe_code)]

use core::ops::Range;

use bytemuck::cast;
use glam::Vec4;

use super::dihedral::bend_correction;
use super::distance::distance_correction;
use super::isometric::iso_correction;
use wide::f32x4;

use super::lanes::{Real, V3, add1, idx, lanes, load1};
use super::solver::Solver;
use crate::solver::mesh::{BendingModel, EdgeKind, Topology};

/// Most distance constraints a vertex may have before its cloth's distances are swept forward
/// and back (symmetric Gauss–Seidel) at each projection instead of forward only.
///
/// One forward sweep a substep is unstable on a stiff closed shape with a hub: Bevy's capped
/// `Cylinder` (its caps fanned from one rim vertex, which joins 13 to 33 others at 12 to 32
/// sides) and its `Cone` and `ConicalFrustum` shook themselves apart at 35–100 m/s within a
/// second, in free fall, as did a textbook Gauss–Seidel loop on the same mesh; the sweep's
/// matrix is not symmetric, and its complex eigenvalues feed the velocity update. Forward
/// then back makes it symmetric, and those shapes fall and settle like any other. Closed
/// meshes without a hub are swept both ways too: Bevy's ico spheres (its default `Sphere`
/// mesh) and its torus, held in zero gravity, shook at 0.5–2 m/s between their vertices for
/// as long as they ran, from rounding grown about 1.3-fold a step under the flat rest's
/// bending; swept both ways they hold still. The backward sweep doubles the distance work, so
/// only such cloths pay it: open grids (6 a vertex) and the open meshes modelling tools make
/// (mostly 4 to 8) do not.
pub const SYMMETRIC_SWEEP_DEGREE: usize = 8;

/// Largest `α̃` used: keeps `α̃·λ` finite for absurd compliances.
const MAX_ALPHA_TILDE: f32 = 1e30;

/// How a projection pass turns the stored material parameter into `(α̃, k)`.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Mode {
    /// Stored parameter is a stiffness in `[0, 1]`: `α̃ = 0`, `k = param`.
    Pbd,
    /// Stored parameter is a compliance: `α̃ = param/h²`, `k = 1`.
    Xpbd { inv_h2: f32 },
}

impl Mode {
    #[inline(always)]
    fn lanes<T: Real>(self, param: T) -> (T, T) {
        match self {
            Mode::Pbd => (T::splat(0.0), param),
            Mode::Xpbd { inv_h2 } => (
                (param * T::splat(inv_h2)).min(T::splat(MAX_ALPHA_TILDE)),
                T::splat(1.0),
            ),
        }
    }
}

/// Colour ranges of a coloured constraint list.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Colours {
    /// Each range holds constraints that share no vertex.
    pub independent: Vec<Range<usize>>,
    /// Constraints left over after 128 colours, to be projected sequentially.
    pub sequential: Range<usize>,
}

/// Greedy colouring: returns the order in which to store the constraints and their colours.
fn colour<const N: usize>(constraints: &[[u32; N]], vertex_count: usize) -> (Vec<usize>, Colours) {
    let mut used = vec![0u128; vertex_count];
    let mut colour_of = Vec::with_capacity(constraints.len());
    let mut count = [0usize; 129];
    for c in constraints {
        let busy = c.iter().fold(0u128, |m, &v| m | used[v as usize]);
        let k = (!busy).trailing_zeros() as usize; // 128 when all are taken
        if k < 128 {
            for &v in c {
                used[v as usize] |= 1 << k;
            }
        }
        colour_of.push(k);
        count[k] += 1;
    }
    let mut start = [0usize; 130];
    for k in 0..129 {
        start[k + 1] = start[k] + count[k];
    }
    let mut order = vec![0; constraints.len()];
    let mut fill = start;
    for (i, &k) in colour_of.iter().enumerate() {
        order[fill[k]] = i;
        fill[k] += 1;
    }
    let independent = (0..128)
        .filter(|&k| count[k] > 0)
        .map(|k| start[k]..start[k + 1])
        .collect();
    (
        order,
        Colours {
            independent,
            sequential: start[128]..start[129],
        },
    )
}

/// Panics unless every index is below `vertex_count`; returns `vertex_count`, the bound the
/// unchecked gathers rely on.
fn checked_bound<'a>(indices: impl Iterator<Item = &'a u32>, vertex_count: usize) -> usize {
    for &v in indices {
        assert!(
            (v as usize) < vertex_count,
            "constraint vertex {v} outside its range"
        );
    }
    vertex_count
}

/// Gathers four vertices into lanes `(xyz, w)` with one 4×4 transpose.
///
/// # Safety
/// Every index in `i` is below `pos.len()`.
#[inline(always)]
unsafe fn load4(pos: &[Vec4], i: [u32; 4]) -> (V3<f32x4>, f32x4) {
    // SAFETY: the caller guarantees every index is in bounds.
    let at = |k: usize| cast(unsafe { *pos.get_unchecked(i[k] as usize) });
    let [x, y, z, w] = f32x4::transpose([at(0), at(1), at(2), at(3)]);
    (V3 { x, y, z }, w)
}

/// Adds four lane deltas back to their vertices (the four must be distinct).
///
/// # Safety
/// Every index in `i` is below `pos.len()`.
#[inline(always)]
unsafe fn add4(pos: &mut [Vec4], i: [u32; 4], d: V3<f32x4>) {
    let rows = f32x4::transpose([d.x, d.y, d.z, f32x4::splat(0.0)]);
    for (k, row) in rows.into_iter().enumerate() {
        // SAFETY: the caller guarantees every index is in bounds.
        unsafe { *pos.get_unchecked_mut(i[k] as usize) += cast::<f32x4, Vec4>(row) };
    }
}

/// Distance constraints of one part or of the boundary.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct DistanceSet {
    /// Vertex indices, all below `bound` (private: the unchecked gathers rely on it).
    a: Vec<u32>,
    b: Vec<u32>,
    /// The vertex count the indices were checked against.
    bound: usize,
    pub rest: Vec<f32>,
    pub param: Vec<f32>,
    pub lambda: Vec<f32>,
    /// Index into [`Topology::edges`].
    pub edge: Vec<u32>,
    pub colours: Colours,
    /// Sweep back after the forward sweep ([`SYMMETRIC_SWEEP_DEGREE`]).
    pub symmetric: bool,
}

/// Bending constraints of one part or of the boundary, in one of the two models.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct BendSet {
    /// Vertex indices, all below `bound` (private: the unchecked gathers rely on it).
    v: [Vec<u32>; 4],
    /// The vertex count the indices were checked against.
    bound: usize,
    /// Isometric model (`a` holds each hinge's weights) or dihedral (`rest`, `weight`).
    pub iso: bool,
    pub a: [Vec<f32>; 4],
    pub rest: Vec<f32>,
    /// Dihedral hinges' geometric weights (the compliance is divided by them).
    pub weight: Vec<f32>,
    pub param: Vec<f32>,
    /// Multipliers: one per hinge (dihedral) or three, `x` here and `y`, `z` in `lambda_yz`.
    pub lambda: Vec<f32>,
    pub lambda_yz: [Vec<f32>; 2],
    /// Index into [`Topology::bends`].
    pub bend: Vec<u32>,
    pub colours: Colours,
}

impl DistanceSet {
    fn build(topology: &Topology, edges: &[u32], base: u32, vertex_count: usize) -> Self {
        let local: Vec<[u32; 2]> = edges
            .iter()
            .map(|&e| topology.edges()[e as usize].v.map(|v| v - base))
            .collect();
        let (order, colours) = colour(&local, vertex_count);
        let mut s = DistanceSet {
            colours,
            ..Default::default()
        };
        for i in order {
            let e = edges[i];
            s.a.push(local[i][0]);
            s.b.push(local[i][1]);
            s.rest.push(topology.edges()[e as usize].rest);
            s.edge.push(e);
        }
        s.param = vec![0.0; s.a.len()];
        s.lambda = vec![0.0; s.a.len()];
        s.bound = checked_bound(s.a.iter().chain(&s.b), vertex_count);
        s
    }

    /// First vertex of each constraint (local to the set's range).
    pub(crate) fn a(&self) -> &[u32] {
        &self.a
    }

    /// Second vertex of each constraint (local to the set's range).
    pub(crate) fn b(&self) -> &[u32] {
        &self.b
    }

    fn set_params(&mut self, topology: &Topology, stretch: f32, shear: f32) {
        for (p, &e) in self.param.iter_mut().zip(&self.edge) {
            *p = match topology.edges()[e as usize].kind {
                EdgeKind::Stretch => stretch,
                EdgeKind::Shear => shear,
            };
        }
    }

    /// Projects every constraint once, colour by colour. `ACC`: read and accumulate the XPBD
    /// multipliers (only needed with more than one iteration; otherwise they stay zero).
    pub(crate) fn project<const ACC: bool>(&mut self, pos: &mut [Vec4], mode: Mode) {
        assert!(
            pos.len() >= self.bound,
            "positions shorter than the constraints' range"
        );
        for c in 0..self.colours.independent.len() {
            self.project_colour::<ACC>(pos, mode, c);
        }
        self.project_one_by_one::<ACC>(pos, mode, self.colours.sequential.clone());
        if self.symmetric {
            // The same constraints in the opposite order: the leftovers last to first, then
            // the colours (within a colour no two share a vertex, so their order is moot).
            for i in self.colours.sequential.clone().rev() {
                self.project_one_by_one::<ACC>(pos, mode, i..i + 1);
            }
            for c in (0..self.colours.independent.len()).rev() {
                self.project_colour::<ACC>(pos, mode, c);
            }
        }
    }

    /// Projects colour `c`, four constraints at a time. Only [`Self::project`] calls it,
    /// after checking that `pos` covers the set's `bound`.
    fn project_colour<const ACC: bool>(&mut self, pos: &mut [Vec4], mode: Mode, c: usize) {
        let r = self.colours.independent[c].clone();
        let simd_end = r.start + r.len() / 4 * 4;
        let chunks = self.a[r.start..simd_end]
            .chunks_exact(4)
            .zip(self.b[r.start..simd_end].chunks_exact(4))
            .zip(self.rest[r.start..simd_end].chunks_exact(4))
            .zip(self.param[r.start..simd_end].chunks_exact(4))
            .zip(self.lambda[r.start..simd_end].chunks_exact_mut(4));
        for ((((a, b), rest), param), lambda) in chunks {
            let (ia, ib) = (idx(a), idx(b));
            // SAFETY (all four here): indices < `self.bound` <= `pos.len()` (checked by
            // `project`, the only caller).
            let (xa, wa) = unsafe { load4(pos, ia) };
            let (xb, wb) = unsafe { load4(pos, ib) };
            let (alpha, k) = mode.lanes(lanes(param));
            let l = if ACC { lanes(lambda) } else { f32x4::ZERO };
            let (da, db, dl) = distance_correction(xa, wa, xb, wb, lanes(rest), alpha, k, l);
            unsafe { add4(pos, ia, da) };
            unsafe { add4(pos, ib, db) };
            if ACC {
                lambda.copy_from_slice(&(l + dl).to_array());
            }
        }
        self.project_one_by_one::<ACC>(pos, mode, simd_end..r.end);
    }

    fn project_one_by_one<const ACC: bool>(
        &mut self,
        pos: &mut [Vec4],
        mode: Mode,
        r: Range<usize>,
    ) {
        for i in r {
            let (a, b) = (self.a[i] as usize, self.b[i] as usize);
            let (xa, wa) = load1(pos[a]);
            let (xb, wb) = load1(pos[b]);
            let (alpha, k) = mode.lanes(self.param[i]);
            let l = if ACC { self.lambda[i] } else { 0.0 };
            let (da, db, dl) = distance_correction(xa, wa, xb, wb, self.rest[i], alpha, k, l);
            add1(&mut pos[a], da);
            add1(&mut pos[b], db);
            if ACC {
                self.lambda[i] = l + dl;
            }
        }
    }
}

impl BendSet {
    fn build(topology: &Topology, bends: &[u32], base: u32, vertex_count: usize) -> Self {
        let local: Vec<[u32; 4]> = bends
            .iter()
            .map(|&b| topology.bends()[b as usize].v.map(|v| v - base))
            .collect();
        let (order, colours) = colour(&local, vertex_count);
        let mut s = BendSet {
            colours,
            iso: topology.options().effective_bending() == BendingModel::Isometric,
            ..Default::default()
        };
        for i in order {
            let b = bends[i];
            let bend = &topology.bends()[b as usize];
            for (column, &v) in s.v.iter_mut().zip(&local[i]) {
                column.push(v);
            }
            if s.iso {
                for (column, &a) in s.a.iter_mut().zip(&bend.coeffs) {
                    column.push(a);
                }
            } else {
                s.rest.push(bend.rest_angle);
                s.weight.push(bend.weight);
            }
            s.bend.push(b);
        }
        let n = s.bend.len();
        s.bound = checked_bound(s.v.iter().flatten(), vertex_count);
        s.param = vec![0.0; n];
        s.lambda = vec![0.0; n];
        if s.iso {
            s.lambda_yz = [vec![0.0; n], vec![0.0; n]];
        }
        s
    }

    /// Loads the material: a PBD stiffness as it is; an XPBD compliance divided by each
    /// dihedral hinge's weight (isometric weights are already in `a`).
    fn set_params(&mut self, value: f32, xpbd: bool) {
        if self.iso || !xpbd {
            self.param.fill(value);
        } else {
            for (p, w) in self.param.iter_mut().zip(&self.weight) {
                *p = if *w > 0.0 { value / w } else { f32::INFINITY };
            }
        }
    }

    /// The four vertices of each hinge (local to the set's range), one column per vertex.
    pub(crate) fn v(&self) -> &[Vec<u32>; 4] {
        &self.v
    }

    /// Zeroes the multipliers.
    fn reset_lambda(&mut self) {
        self.lambda.fill(0.0);
        for l in &mut self.lambda_yz {
            l.fill(0.0);
        }
    }

    /// Projects every constraint once, colour by colour (`ACC` as for distances).
    pub(crate) fn project<const ACC: bool>(&mut self, pos: &mut [Vec4], mode: Mode) {
        if self.iso {
            self.project_iso::<ACC>(pos, mode);
        } else {
            self.project_dihedral::<ACC>(pos, mode);
        }
    }

    fn project_iso<const ACC: bool>(&mut self, pos: &mut [Vec4], mode: Mode) {
        assert!(
            pos.len() >= self.bound,
            "positions shorter than the constraints' range"
        );
        for c in 0..self.colours.independent.len() {
            let r = self.colours.independent[c].clone();
            let e = r.start + r.len() / 4 * 4;
            let [v0, v1, v2, v3] = &self.v;
            let [a0, a1, a2, a3] = &self.a;
            let [ly, lz] = &mut self.lambda_yz;
            // Explicit zips, not `[0, 1, 2, 3].map(..)`: the array maps were not inlined and
            // cost a third of the pass in calls and store-forwarding stalls.
            let chunks = v0[r.start..e]
                .chunks_exact(4)
                .zip(v1[r.start..e].chunks_exact(4))
                .zip(v2[r.start..e].chunks_exact(4))
                .zip(v3[r.start..e].chunks_exact(4))
                .zip(a0[r.start..e].chunks_exact(4))
                .zip(a1[r.start..e].chunks_exact(4))
                .zip(a2[r.start..e].chunks_exact(4))
                .zip(a3[r.start..e].chunks_exact(4))
                .zip(self.param[r.start..e].chunks_exact(4))
                .zip(self.lambda[r.start..e].chunks_exact_mut(4))
                .zip(ly[r.start..e].chunks_exact_mut(4))
                .zip(lz[r.start..e].chunks_exact_mut(4));
            for (((((((((((i0, i1), i2), i3), a0), a1), a2), a3), param), lx), ly), lz) in chunks {
                let (i0, i1, i2, i3) = (idx(i0), idx(i1), idx(i2), idx(i3));
                // SAFETY (all eight here): indices < `self.bound` <= `pos.len()`.
                let (x0, w0) = unsafe { load4(pos, i0) };
                let (x1, w1) = unsafe { load4(pos, i1) };
                let (x2, w2) = unsafe { load4(pos, i2) };
                let (x3, w3) = unsafe { load4(pos, i3) };
                let a = [lanes(a0), lanes(a1), lanes(a2), lanes(a3)];
                let (alpha, k) = mode.lanes(lanes(param));
                let l = if ACC {
                    V3 {
                        x: lanes(lx),
                        y: lanes(ly),
                        z: lanes(lz),
                    }
                } else {
                    V3 {
                        x: f32x4::ZERO,
                        y: f32x4::ZERO,
                        z: f32x4::ZERO,
                    }
                };
                let (dx, dl) = iso_correction([x0, x1, x2, x3], [w0, w1, w2, w3], a, alpha, k, l);
                unsafe { add4(pos, i0, dx[0]) };
                unsafe { add4(pos, i1, dx[1]) };
                unsafe { add4(pos, i2, dx[2]) };
                unsafe { add4(pos, i3, dx[3]) };
                if ACC {
                    lx.copy_from_slice(&(l.x + dl.x).to_array());
                    ly.copy_from_slice(&(l.y + dl.y).to_array());
                    lz.copy_from_slice(&(l.z + dl.z).to_array());
                }
            }
            self.project_iso_one_by_one::<ACC>(pos, mode, e..r.end);
        }
        self.project_iso_one_by_one::<ACC>(pos, mode, self.colours.sequential.clone());
    }

    fn project_iso_one_by_one<const ACC: bool>(
        &mut self,
        pos: &mut [Vec4],
        mode: Mode,
        r: Range<usize>,
    ) {
        for i in r {
            let ix = [0, 1, 2, 3].map(|k| self.v[k][i] as usize);
            let (x0, w0) = load1(pos[ix[0]]);
            let (x1, w1) = load1(pos[ix[1]]);
            let (x2, w2) = load1(pos[ix[2]]);
            let (x3, w3) = load1(pos[ix[3]]);
            let (alpha, k) = mode.lanes(self.param[i]);
            let l = if ACC {
                V3 {
                    x: self.lambda[i],
                    y: self.lambda_yz[0][i],
                    z: self.lambda_yz[1][i],
                }
            } else {
                V3 {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                }
            };
            let a = [0, 1, 2, 3].map(|k| self.a[k][i]);
            let (dx, dl) = iso_correction([x0, x1, x2, x3], [w0, w1, w2, w3], a, alpha, k, l);
            for v in 0..4 {
                add1(&mut pos[ix[v]], dx[v]);
            }
            if ACC {
                self.lambda[i] += dl.x;
                self.lambda_yz[0][i] += dl.y;
                self.lambda_yz[1][i] += dl.z;
            }
        }
    }

    fn project_dihedral<const ACC: bool>(&mut self, pos: &mut [Vec4], mode: Mode) {
        assert!(
            pos.len() >= self.bound,
            "positions shorter than the constraints' range"
        );
        for c in 0..self.colours.independent.len() {
            let r = self.colours.independent[c].clone();
            let e = r.start + r.len() / 4 * 4;
            let [v0, v1, v2, v3] = &self.v;
            let chunks = v0[r.start..e]
                .chunks_exact(4)
                .zip(v1[r.start..e].chunks_exact(4))
                .zip(v2[r.start..e].chunks_exact(4))
                .zip(v3[r.start..e].chunks_exact(4))
                .zip(self.rest[r.start..e].chunks_exact(4))
                .zip(self.param[r.start..e].chunks_exact(4))
                .zip(self.lambda[r.start..e].chunks_exact_mut(4));
            for ((((((i0, i1), i2), i3), rest), param), lambda) in chunks {
                let (i0, i1, i2, i3) = (idx(i0), idx(i1), idx(i2), idx(i3));
                // SAFETY (all eight here): indices < `self.bound` <= `pos.len()`.
                let (x0, w0) = unsafe { load4(pos, i0) };
                let (x1, w1) = unsafe { load4(pos, i1) };
                let (x2, w2) = unsafe { load4(pos, i2) };
                let (x3, w3) = unsafe { load4(pos, i3) };
                let (alpha, k) = mode.lanes(lanes(param));
                let l = if ACC { lanes(lambda) } else { f32x4::ZERO };
                let (dx, dl) =
                    bend_correction([x0, x1, x2, x3], [w0, w1, w2, w3], lanes(rest), alpha, k, l);
                unsafe { add4(pos, i0, dx[0]) };
                unsafe { add4(pos, i1, dx[1]) };
                unsafe { add4(pos, i2, dx[2]) };
                unsafe { add4(pos, i3, dx[3]) };
                if ACC {
                    lambda.copy_from_slice(&(l + dl).to_array());
                }
            }
            self.project_dihedral_one_by_one::<ACC>(pos, mode, e..r.end);
        }
        self.project_dihedral_one_by_one::<ACC>(pos, mode, self.colours.sequential.clone());
    }

    fn project_dihedral_one_by_one<const ACC: bool>(
        &mut self,
        pos: &mut [Vec4],
        mode: Mode,
        r: Range<usize>,
    ) {
        for i in r {
            let ix = [
                self.v[0][i] as usize,
                self.v[1][i] as usize,
                self.v[2][i] as usize,
                self.v[3][i] as usize,
            ];
            let (x0, w0) = load1(pos[ix[0]]);
            let (x1, w1) = load1(pos[ix[1]]);
            let (x2, w2) = load1(pos[ix[2]]);
            let (x3, w3) = load1(pos[ix[3]]);
            let (alpha, k) = mode.lanes(self.param[i]);
            let (dx, dl) = bend_correction(
                [x0, x1, x2, x3],
                [w0, w1, w2, w3],
                self.rest[i],
                alpha,
                k,
                if ACC { self.lambda[i] } else { 0.0 },
            );
            for v in 0..4 {
                add1(&mut pos[ix[v]], dx[v]);
            }
            if ACC {
                self.lambda[i] += dl;
            }
        }
    }
}

/// The constraints of one vertex range: a part, a seam (two neighbouring parts' ranges), or
/// the boundary (range `0..n`). Indices are relative to the range's start.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Part {
    pub range: Range<usize>,
    pub distance: DistanceSet,
    pub bending: BendSet,
}

impl Part {
    /// Zeroes the XPBD multipliers (start of a substep).
    pub(crate) fn reset_lambda(&mut self) {
        self.distance.lambda.fill(0.0);
        self.bending.reset_lambda();
    }

    /// Like [`Self::project`] but one constraint at a time (the SIMD path's reference).
    #[cfg(test)]
    pub(crate) fn project_scalar(&mut self, pos: &mut [Vec4], mode: Mode, bending: bool) {
        let d = &mut self.distance;
        for r in d.colours.independent.clone() {
            d.project_one_by_one::<false>(pos, mode, r);
        }
        d.project_one_by_one::<false>(pos, mode, d.colours.sequential.clone());
        if d.symmetric {
            for i in d.colours.sequential.clone().rev() {
                d.project_one_by_one::<false>(pos, mode, i..i + 1);
            }
            for r in d.colours.independent.clone().into_iter().rev() {
                d.project_one_by_one::<false>(pos, mode, r);
            }
        }
        if bending {
            let b = &mut self.bending;
            for r in b.colours.independent.clone() {
                if b.iso {
                    b.project_iso_one_by_one::<false>(pos, mode, r);
                } else {
                    b.project_dihedral_one_by_one::<false>(pos, mode, r);
                }
            }
        }
    }

    /// Projects distance then (if on) bending constraints once; `accumulate` keeps XPBD
    /// multipliers across iterations.
    pub(crate) fn project(
        &mut self,
        pos: &mut [Vec4],
        mode: Mode,
        bending: bool,
        accumulate: bool,
    ) {
        if accumulate {
            self.distance.project::<true>(pos, mode);
            if bending {
                self.bending.project::<true>(pos, mode);
            }
        } else {
            self.distance.project::<false>(pos, mode);
            if bending {
                self.bending.project::<false>(pos, mode);
            }
        }
    }
}

/// `true` at each listed index.
fn mask(indices: &[u32]) -> Vec<bool> {
    let mut out = vec![false; indices.iter().map(|&i| i as usize + 1).max().unwrap_or(0)];
    for &i in indices {
        out[i as usize] = true;
    }
    out
}

/// Number of parts for `n` vertices: about 2048 vertices a part, at most 16.
#[must_use]
pub fn default_part_count(n: usize) -> usize {
    (n / 2048).clamp(1, 16)
}

/// All constraints of a cloth, partitioned and coloured for projection.
///
/// Build it with [`ConstraintBatches::new`] and keep it beside the
/// [`ClothState`](crate::solver::ClothState); call [`ConstraintBatches::set_solver`] when the material
/// changes.
#[derive(Clone, Debug, PartialEq)]
pub struct ConstraintBatches {
    pub(crate) parts: Vec<Part>,
    /// Seams between neighbouring parts, each in vertex order and sharing no vertex with
    /// another of its list: `[all, empty]` when no two seams overlap, else `[even, odd]`.
    pub(crate) seams: [Vec<Part>; 2],
    pub(crate) boundary: Part,
    pub(crate) bending: bool,
    pub(crate) mode_is_xpbd: bool,
}

impl ConstraintBatches {
    /// Partitions `topology` into `parts` vertex ranges (see [`default_part_count`]),
    /// colours each, and loads the material of `solver`.
    #[must_use]
    pub fn new(topology: &Topology, solver: Solver, parts: usize) -> Self {
        let n = topology.vertex_count();
        let k = parts.clamp(1, n.max(1));
        let ranges: Vec<Range<usize>> = (0..k).map(|p| p * n / k..(p + 1) * n / k).collect();
        let part_of = |v: u32| -> usize {
            // Ranges are equal-sized up to rounding: guess, then step to the right one.
            let v = v as usize;
            let mut p = (v * k / n.max(1)).min(k - 1);
            while v < ranges[p].start {
                p -= 1;
            }
            while v >= ranges[p].end {
                p += 1;
            }
            p
        };
        // Where a constraint goes: its part, seam `k + s`, or the boundary `2k − 1`.
        let home = |v: &[u32]| -> usize {
            let (lo, hi) = v.iter().fold((usize::MAX, 0), |(lo, hi), &v| {
                let p = part_of(v);
                (lo.min(p), hi.max(p))
            });
            match hi - lo {
                0 => lo,
                1 => k + lo,
                _ => 2 * k - 1,
            }
        };
        let mut edges = vec![Vec::new(); 2 * k];
        for (i, e) in topology.edges().iter().enumerate() {
            edges[home(&e.v)].push(i as u32);
        }
        let mut bends = vec![Vec::new(); 2 * k];
        for (i, b) in topology.bends().iter().enumerate() {
            bends[home(&b.v)].push(i as u32);
        }
        let build = |range: Range<usize>, slot: usize| Part {
            distance: DistanceSet::build(topology, &edges[slot], range.start as u32, range.len()),
            bending: BendSet::build(topology, &bends[slot], range.start as u32, range.len()),
            range,
        };
        let parts = ranges
            .iter()
            .enumerate()
            .map(|(p, r)| build(r.clone(), p))
            .collect();
        // A seam's vertices: from the first to the last its constraints touch (within its
        // two parts); empty where it has none.
        let seam_range = |s: usize| -> Range<usize> {
            let slot = k + s;
            let vertices = edges[slot]
                .iter()
                .flat_map(|&e| topology.edges()[e as usize].v)
                .chain(
                    bends[slot]
                        .iter()
                        .flat_map(|&b| topology.bends()[b as usize].v),
                );
            let (lo, hi) = vertices.fold((usize::MAX, 0), |(lo, hi), v| {
                (lo.min(v as usize), hi.max(v as usize + 1))
            });
            if lo < hi {
                lo..hi
            } else {
                ranges[s].end..ranges[s].end
            }
        };
        let seam_ranges: Vec<Range<usize>> = (0..k - 1).map(seam_range).collect();
        // Seams whose vertices do not overlap (parts more than a few rows deep) all run at
        // once: one parallel region (one GPU level) instead of two. Otherwise even seams,
        // then odd ones, which never share a vertex. Either way no two seams of one list
        // share a vertex, so the order within a list changes nothing.
        let disjoint = seam_ranges.windows(2).all(|w| w[0].end <= w[1].start);
        let mut seams = [Vec::new(), Vec::new()];
        for (s, r) in seam_ranges.into_iter().enumerate() {
            let list = if disjoint { 0 } else { s % 2 };
            seams[list].push(build(r, k + s));
        }
        let boundary = build(0..n, 2 * k - 1);
        let symmetric =
            topology.max_vertex_degree() > SYMMETRIC_SWEEP_DEGREE || topology.is_closed();
        let mut batches = Self {
            parts,
            seams,
            boundary,
            bending: false,
            mode_is_xpbd: false,
        };
        for part in batches.all_parts_mut() {
            part.distance.symmetric = symmetric;
        }
        batches.set_solver(topology, solver);
        batches
    }

    /// Whether these batches were built from `topology`'s edges and bending pairs, as they are
    /// in it (the same vertices, in the same order, and bending model), so that
    /// [`Self::remeasure`] with it gives what [`Self::new`] would build.
    pub(crate) fn built_from(&self, topology: &Topology) -> bool {
        let (edges, bends) = (topology.edges(), topology.bends());
        let iso = topology.options().effective_bending() == BendingModel::Isometric;
        let (mut distances, mut hinges) = (0, 0);
        let same = self.all_parts().all(|part| {
            let base = part.range.start as u32;
            let d = &part.distance;
            let b = &part.bending;
            distances += d.edge.len();
            hinges += b.bend.len();
            let same_edges = d.edge.iter().enumerate().all(|(i, &e)| {
                edges
                    .get(e as usize)
                    .is_some_and(|e| e.v == [d.a[i] + base, d.b[i] + base])
            });
            let same_hinges = b.bend.iter().enumerate().all(|(k, &h)| {
                bends
                    .get(h as usize)
                    .is_some_and(|h| (0..4).all(|c| h.v[c] == b.v[c][k] + base))
            });
            same_edges && same_hinges && b.iso == iso
        });
        same && distances == edges.len()
            && hinges == bends.len()
            && self.boundary.range.end == topology.vertex_count()
    }

    /// Takes the rest lengths, angles and weights of `topology`, whose edges and bending pairs
    /// are the ones these batches were built from (its rest shape measured again:
    /// [`Topology::reshaped`]), and loads the material of `solver`: what [`Self::new`] builds
    /// from it (with the part count and sweeps these have), without partitioning and colouring
    /// again.
    pub(crate) fn remeasure(&mut self, topology: &Topology, solver: Solver) {
        let (edges, bends) = (topology.edges(), topology.bends());
        for part in self.all_parts_mut() {
            let d = &mut part.distance;
            for (rest, &e) in d.rest.iter_mut().zip(&d.edge) {
                *rest = edges[e as usize].rest;
            }
            d.lambda.fill(0.0);
            let b = &mut part.bending;
            for (k, &h) in b.bend.iter().enumerate() {
                let bend = &bends[h as usize];
                if b.iso {
                    for (column, &a) in b.a.iter_mut().zip(&bend.coeffs) {
                        column[k] = a;
                    }
                } else {
                    b.rest[k] = bend.rest_angle;
                    b.weight[k] = bend.weight;
                }
            }
            b.reset_lambda();
        }
        self.set_solver(topology, solver);
    }

    /// Whether the distances are swept forward and back at each projection: the mesh has a
    /// vertex with more than [`SYMMETRIC_SWEEP_DEGREE`] of them or is closed
    /// ([`Topology::is_closed`]), or [`Self::sweep_symmetrically`] said so.
    #[must_use]
    pub fn symmetric_sweeps(&self) -> bool {
        self.boundary.distance.symmetric
    }

    /// Sweeps the distances forward and back at each projection from now on, whatever the
    /// topology they were built from: a closed cloth torn open keeps the sweep it was built
    /// with (the rest of it is as stiff as before), and the GPU's batches take the CPU's.
    pub fn sweep_symmetrically(&mut self) {
        for part in self.all_parts_mut() {
            part.distance.symmetric = true;
        }
    }

    /// Loads the material of `solver` (stiffness or compliance per constraint). Cheap: no
    /// rebuild, no allocation.
    pub fn set_solver(&mut self, topology: &Topology, solver: Solver) {
        let (stretch, shear, bending) = match solver {
            Solver::Lab { .. } => (1.0, 1.0, 0.0),
            Solver::Pbd {
                stretch,
                shear,
                bending,
            }
            | Solver::Xpbd {
                stretch,
                shear,
                bending,
            } => (stretch, shear, bending),
        };
        self.bending = solver.bending_enabled();
        self.mode_is_xpbd = matches!(solver, Solver::Xpbd { .. });
        let xpbd = self.mode_is_xpbd;
        for part in self.all_parts_mut() {
            part.distance.set_params(topology, stretch, shear);
            part.bending.set_params(bending, xpbd);
        }
    }

    /// Number of vertex ranges projected in parallel.
    #[must_use]
    pub fn part_count(&self) -> usize {
        self.parts.len()
    }

    /// Constraints (distance + bending) that straddle parts and run after them (on the
    /// seams between neighbouring parts and on the boundary).
    #[must_use]
    pub fn boundary_len(&self) -> usize {
        self.after_parts()
            .map(|p| p.distance.a.len() + p.bending.bend.len())
            .sum()
    }

    /// The seams (even, then odd) and the boundary, in the order they are projected.
    pub(crate) fn after_parts(&self) -> impl Iterator<Item = &Part> {
        self.seams[0]
            .iter()
            .chain(&self.seams[1])
            .chain(core::iter::once(&self.boundary))
    }

    /// Every part, seam and the boundary, in projection order.
    fn all_parts(&self) -> impl Iterator<Item = &Part> {
        self.parts.iter().chain(self.after_parts())
    }

    /// [`Self::all_parts`], to change.
    fn all_parts_mut(&mut self) -> impl Iterator<Item = &mut Part> {
        self.parts
            .iter_mut()
            .chain(self.seams.iter_mut().flatten())
            .chain(core::iter::once(&mut self.boundary))
    }

    /// Makes the distance constraints of `edges` (indices into the topology's edges) hold
    /// nothing from now on: each one's second end becomes its first, so it has no length to
    /// correct. What an edge flagged torn does on the GPU between its tear check and the
    /// host's tear (the CPU tears at once, removing the edge from the topology); its hinges
    /// and triangles stay until then.
    pub fn release_edges(&mut self, edges: &[u32]) {
        let listed = mask(edges);
        for part in self.all_parts_mut() {
            let d = &mut part.distance;
            for (i, &e) in d.edge.iter().enumerate() {
                if listed.get(e as usize).copied().unwrap_or(false) {
                    d.b[i] = d.a[i];
                }
            }
        }
    }

    /// Makes the hinges of `bends` (indices into the topology's bends) hold nothing from now
    /// on: an isometric hinge's weights become zero, a dihedral hinge's four vertices one, so
    /// it has no shape to correct. What a hinge that lost a triangle to a tear does on the GPU
    /// between its tear check and the host's tear (the CPU's tear removes it at once).
    pub fn release_bends(&mut self, bends: &[u32]) {
        let listed = mask(bends);
        for part in self.all_parts_mut() {
            let b = &mut part.bending;
            for i in 0..b.bend.len() {
                if !listed.get(b.bend[i] as usize).copied().unwrap_or(false) {
                    continue;
                }
                if b.iso {
                    for a in &mut b.a {
                        a[i] = 0.0;
                    }
                } else {
                    let first = b.v[0][i];
                    for v in &mut b.v[1..] {
                        v[i] = first;
                    }
                }
            }
        }
    }

    /// Every distance constraint's vertices in global indices, colour by colour:
    /// `(part, colour) → [(a, b)]`. Used to check colourings.
    #[must_use]
    pub fn distance_colours(&self) -> Vec<Vec<[u32; 2]>> {
        let mut out = Vec::new();
        for part in self.all_parts() {
            let base = part.range.start as u32;
            let s = &part.distance;
            for r in &s.colours.independent {
                out.push(r.clone().map(|i| [s.a[i] + base, s.b[i] + base]).collect());
            }
        }
        out
    }

    /// Every bending constraint's vertices in global indices, colour by colour.
    #[must_use]
    pub fn bending_colours(&self) -> Vec<Vec<[u32; 4]>> {
        let mut out = Vec::new();
        for part in self.all_parts() {
            let base = part.range.start as u32;
            let s = &part.bending;
            for r in &s.colours.independent {
                out.push(
                    r.clone()
                        .map(|i| [0, 1, 2, 3].map(|k| s.v[k][i] + base))
                        .collect(),
                );
            }
        }
        out
    }

    pub(crate) fn mode(&self, h: f32) -> Mode {
        if self.mode_is_xpbd {
            Mode::Xpbd {
                inv_h2: 1.0 / (h * h),
            }
        } else {
            Mode::Pbd
        }
    }
}

/// Scalar and SIMD paths agree (they share the math; only lane grouping differs).
#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::{BendRest, Grid, TopologyOptions};
    use glam::Vec3;
    use std::collections::HashSet;

    fn batches(n: u32, parts: usize) -> (Topology, ConstraintBatches) {
        let t = Grid::new(n, n, 1.0, 1.0)
            .topology(TopologyOptions::default())
            .unwrap();
        let b = ConstraintBatches::new(&t, Solver::default(), parts);
        (t, b)
    }

    /// The grid's rest positions with vertex `v` moved by `by`.
    fn moved(g: &Grid, v: u32, by: Vec3) -> Vec<Vec4> {
        let mut pos: Vec<Vec4> = g.positions().iter().map(|p| p.extend(1.0)).collect();
        pos[v as usize] += by.extend(0.0);
        pos
    }

    /// `from` after one projection of every part's distances (`bending`: hinges instead).
    fn project_once(b: &mut ConstraintBatches, from: &[Vec4], bending: bool) -> Vec<Vec4> {
        let mut pos = from.to_vec();
        let mode = b.mode(1.0 / 60.0);
        for p in b.all_parts_mut() {
            // A part's indices are local to its range.
            let pos = &mut pos[p.range.clone()];
            if bending {
                p.bending.project::<false>(pos, mode);
            } else {
                p.distance.project::<false>(pos, mode);
            }
        }
        pos
    }

    /// Batches measured again for a new rest shape ([`ConstraintBatches::remeasure`]) are the
    /// batches built anew from it, multipliers zeroed: both bending models, one part and
    /// four, PBD and XPBD, swept both ways or not.
    #[test]
    fn remeasured_batches_are_the_ones_built_anew() {
        let g = Grid::new(12, 12, 1.0, 1.0);
        // Stretched unevenly and curved.
        let shaped: Vec<Vec3> = g
            .positions()
            .iter()
            .map(|p| Vec3::new(p.x * (1.0 + p.z * p.z), 0.2 * (3.0 * p.x).sin(), 1.3 * p.z))
            .collect();
        let solvers = [
            Solver::default(),
            Solver::Pbd {
                stretch: 0.9,
                shear: 0.7,
                bending: 0.1,
            },
        ];
        for bend_rest in [BendRest::Flat, BendRest::RestShape] {
            let options = TopologyOptions {
                bend_rest,
                ..TopologyOptions::default()
            };
            let t = g.topology(options).unwrap();
            let now = t.reshaped(&shaped).unwrap();
            for solver in solvers {
                for (parts, symmetric) in [(1, false), (4, false), (4, true)] {
                    let mut b = ConstraintBatches::new(&t, solver, parts);
                    let mut fresh = ConstraintBatches::new(&now, solver, parts);
                    if symmetric {
                        b.sweep_symmetrically();
                        fresh.sweep_symmetrically();
                    }
                    assert_ne!(b, fresh);
                    for p in b.all_parts_mut() {
                        p.distance.lambda.fill(0.5);
                        p.bending.lambda.fill(0.5);
                    }
                    b.remeasure(&now, solver);
                    assert_eq!(b, fresh, "{bend_rest:?} {solver:?} {parts} {symmetric}");
                }
            }
        }
    }

    #[test]
    fn released_edges_hold_nothing_and_the_others_still_hold() {
        // Four parts, so that the released edges lie in parts, seams and the boundary.
        let g = Grid::new(8, 8, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let v = g.index(3, 4);
        let pulled = moved(&g, v, Vec3::X * 0.5);
        let project = |b: &mut ConstraintBatches| project_once(b, &pulled, false);
        let mut b = ConstraintBatches::new(&t, Solver::default(), 4);
        assert_ne!(project(&mut b)[v as usize], pulled[v as usize]);
        let at_v: Vec<u32> = (0..t.edges().len() as u32)
            .filter(|&e| t.edges()[e as usize].v.contains(&v))
            .collect();
        b.release_edges(&at_v);
        let pos = project(&mut b);
        assert_eq!(pos[v as usize], pulled[v as usize]);
        // Those and no others.
        let released: usize = b
            .all_parts()
            .map(|p| {
                p.distance
                    .a
                    .iter()
                    .zip(&p.distance.b)
                    .filter(|(a, b)| a == b)
                    .count()
            })
            .sum();
        assert_eq!(released, at_v.len());
    }

    #[test]
    fn released_hinges_hold_nothing_in_either_model() {
        for model in [BendingModel::Isometric, BendingModel::Dihedral] {
            let g = Grid::new(8, 8, 1.0, 1.0);
            let options = TopologyOptions {
                bending: model,
                ..Default::default()
            };
            let t = g.topology(options).unwrap();
            let v = g.index(3, 4);
            // v lifted out of the plane: the hinges around it bend.
            let lifted = moved(&g, v, Vec3::Y * 0.1);
            let project = |b: &mut ConstraintBatches| project_once(b, &lifted, true);
            let mut b = ConstraintBatches::new(&t, Solver::default(), 4);
            assert_ne!(project(&mut b), lifted, "{model:?}");
            let at_v: Vec<u32> = (0..t.bends().len() as u32)
                .filter(|&i| t.bends()[i as usize].v.contains(&v))
                .collect();
            // All but one of them released: that one still acts; then none does (the other
            // hinges are flat).
            let (last, rest) = at_v.split_last().unwrap();
            b.release_bends(rest);
            assert_ne!(
                project(&mut b),
                lifted,
                "{model:?}: hinge {last} still acts"
            );
            b.release_bends(&[*last]);
            assert_eq!(project(&mut b), lifted, "{model:?}: nothing holds");
        }
    }

    #[test]
    fn parts_follow_the_vertex_count_and_never_the_machine() {
        // (grid side, parts): about 2048 vertices a part, at most 16. A step then runs on
        // min(parts, threads) threads (`Workers` seats one helper per part beyond the first),
        // so a 64² cloth uses two threads on a 16-core machine and results are the same on
        // any thread count.
        for (side, parts) in [
            (16, 1),
            (32, 1),
            (45, 1),
            (64, 2),
            (90, 3),
            (128, 8),
            (181, 15),
            (256, 16),
            (512, 16),
            (1024, 16),
        ] {
            assert_eq!(default_part_count(side * side), parts, "{side}²");
        }
        let (_, b) = batches(64, default_part_count(64 * 64));
        assert_eq!(b.part_count(), 2);
    }

    #[test]
    fn colours_share_no_vertex_and_cover_everything() {
        for parts in [1, 3, 7] {
            let (t, b) = batches(17, parts);
            let mut seen = 0;
            for colour in b.distance_colours() {
                let mut verts = HashSet::new();
                for c in &colour {
                    assert!(verts.insert(c[0]) && verts.insert(c[1]), "shared vertex");
                }
                seen += colour.len();
            }
            let seq: usize = b
                .all_parts()
                .map(|p| p.distance.colours.sequential.len())
                .sum();
            assert_eq!(seen + seq, t.edges().len());
            let mut seen = 0;
            for colour in b.bending_colours() {
                let mut verts = HashSet::new();
                for c in &colour {
                    for v in c {
                        assert!(verts.insert(*v), "shared vertex");
                    }
                }
                seen += colour.len();
            }
            assert_eq!(seen, t.bends().len());
        }
    }

    #[test]
    fn a_grid_needs_few_colours() {
        let (_, b) = batches(32, 1);
        let d = b.distance_colours().len();
        let bend = b.bending_colours().len();
        assert!(d <= 8, "{d} distance colours");
        assert!(bend <= 16, "{bend} bending colours");
    }

    #[test]
    fn parts_only_hold_their_own_vertices() {
        let (t, b) = batches(20, 4);
        assert_eq!(b.part_count(), 4);
        // Parts of five rows: the seams (rows 3–6 of each pair of parts) do not overlap and
        // run at once.
        assert_eq!((b.seams[0].len(), b.seams[1].len()), (3, 0));
        for p in b.all_parts() {
            for (&a, &bb) in p.distance.a.iter().zip(&p.distance.b) {
                assert!((a as usize) < p.range.len() && (bb as usize) < p.range.len());
            }
            for v in &p.bending.v {
                assert!(v.iter().all(|&v| (v as usize) < p.range.len()));
            }
        }
        // Each seam lies within its two parts: the last two rows of one, the first two of
        // the next.
        for (s, seam) in b.seams[0].iter().enumerate() {
            assert_eq!(
                seam.range,
                b.parts[s].range.end - 40..b.parts[s + 1].range.start + 40
            );
        }
        let count =
            |it: &mut dyn Iterator<Item = &Part>| -> usize { it.map(|p| p.distance.a.len()).sum() };
        let inside = count(&mut b.parts.iter());
        let seams = count(&mut b.seams.iter().flatten());
        assert!(seams > 0);
        // On a grid in row order every straddling constraint joins neighbouring parts.
        assert_eq!(
            b.boundary.distance.a.len() + b.boundary.bending.bend.len(),
            0
        );
        assert_eq!(inside + seams, t.edges().len());
        // Row strips: the seams are a few rows' worth, not the whole cloth.
        assert!(b.boundary_len() > 0);
        assert!(b.boundary_len() < (t.edges().len() + t.bends().len()) / 4);
    }

    #[test]
    fn overlapping_seams_take_turns_and_none_shares_a_vertex_in_its_list() {
        // A seam spans four rows (hinges reach a row past the two its edges join): parts of
        // two or three rows make neighbouring seams overlap, and they run as even, then odd.
        for (rows, parts, split) in [
            (20, 10, true),
            (21, 7, true),
            (20, 5, false),
            (64, 16, false),
        ] {
            let (_, b) = batches(rows, parts);
            let [even, odd] = &b.seams;
            assert_eq!(
                !odd.is_empty(),
                split,
                "{rows} rows in {parts} parts: {} and {} seams",
                even.len(),
                odd.len()
            );
            assert_eq!(even.len() + odd.len(), parts - 1);
            for list in &b.seams {
                for w in list.windows(2) {
                    assert!(w[0].range.end <= w[1].range.start, "{rows}/{parts}");
                }
                for seam in list {
                    for (&a, &bb) in seam.distance.a.iter().zip(&seam.distance.b) {
                        assert!((a as usize) < seam.range.len());
                        assert!((bb as usize) < seam.range.len());
                    }
                    for v in &seam.bending.v {
                        assert!(v.iter().all(|&v| (v as usize) < seam.range.len()));
                    }
                }
            }
        }
    }

    #[test]
    fn seams_at_once_move_the_cloth_as_even_then_odd_seams_do() {
        let (t, b) = batches(64, 16);
        assert!(
            b.seams[1].is_empty(),
            "a 64² grid in 16 parts has its seams at once"
        );
        // Every vertex off its rest place: every seam constraint corrects something.
        let start: Vec<Vec4> = t
            .rest_positions()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let k = i as f32;
                let jitter = glam::Vec3::new((k * 0.37).sin(), (k * 0.11).cos(), (k * 0.73).sin());
                (*p + jitter * 0.004).extend(1.0)
            })
            .collect();
        let mode = Mode::Xpbd { inv_h2: 360_000.0 };
        let project = |order: &[usize]| {
            let mut pos = start.clone();
            let mut seams = b.seams[0].clone();
            for &s in order {
                let seam = &mut seams[s];
                seam.project(&mut pos[seam.range.clone()], mode, true, false);
            }
            pos
        };
        let count = b.seams[0].len();
        let at_once = project(&(0..count).collect::<Vec<_>>());
        let even_then_odd: Vec<usize> =
            (0..count).step_by(2).chain((1..count).step_by(2)).collect();
        assert_eq!(at_once, project(&even_then_odd));
        let reversed: Vec<usize> = (0..count).rev().collect();
        assert_eq!(at_once, project(&reversed));
        assert_ne!(at_once, start);
    }

    #[test]
    fn jumbled_vertex_order_puts_far_constraints_on_the_boundary() {
        // A grid whose vertex order jumps (v → 7v mod n): many constraints join parts that
        // are not neighbours; every constraint is still projected exactly once.
        let g = Grid::new(12, 12, 1.0, 1.0);
        let n = g.vertex_count() as u32;
        let map = |v: u32| v * 7 % n;
        let mut pos = vec![glam::Vec3::ZERO; n as usize];
        for (v, p) in g.positions().into_iter().enumerate() {
            pos[map(v as u32) as usize] = p;
        }
        let idx: Vec<u32> = g.indices().into_iter().map(map).collect();
        let t = Topology::from_triangles(&pos, None, &idx, TopologyOptions::default()).unwrap();
        let b = ConstraintBatches::new(&t, Solver::default(), 4);
        assert!(!b.boundary.distance.a.is_empty() && !b.boundary.bending.bend.is_empty());
        let edges: usize = b.all_parts().map(|p| p.distance.a.len()).sum();
        let bends: usize = b.all_parts().map(|p| p.bending.bend.len()).sum();
        assert_eq!((edges, bends), (t.edges().len(), t.bends().len()));
        // The seams still only hold constraints of their two parts.
        for seam in b.seams.iter().flatten() {
            for (&a, &bb) in seam.distance.a.iter().zip(&seam.distance.b) {
                assert!((a as usize) < seam.range.len() && (bb as usize) < seam.range.len());
            }
        }
    }

    #[test]
    #[should_panic(expected = "positions shorter")]
    fn projecting_too_few_positions_panics_instead_of_reading_past_them() {
        let (_, mut b) = batches(8, 1);
        let mut pos = vec![Vec4::ZERO; 63];
        b.parts[0].project(&mut pos, Mode::Pbd, true, false);
    }

    #[test]
    fn overfull_vertices_fall_back_to_sequential() {
        // A fan of 200 triangles around vertex 0: 200 spokes share it, so 72 cannot be coloured.
        let mut pos = vec![glam::Vec3::ZERO];
        let mut idx = Vec::new();
        for i in 0..200u32 {
            let a = i as f32 / 200.0 * core::f32::consts::TAU;
            pos.push(glam::Vec3::new(a.cos(), 0.0, a.sin()));
            idx.extend_from_slice(&[0, 1 + i, 1 + (i + 1) % 200]);
        }
        let t = Topology::from_triangles(&pos, None, &idx, TopologyOptions::default()).unwrap();
        let b = ConstraintBatches::new(&t, Solver::default(), 1);
        assert_eq!(b.parts[0].distance.colours.sequential.len(), 72);
    }
}
