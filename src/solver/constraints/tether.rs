//! Long-range attachments ("tethers", Kim et al. 2012): each free vertex may not get farther
//! from its nearest pins than its rest distance to them.
//!
//! Local distance constraints pass a correction about one edge per projection, so a cape or
//! banner hanging from a few pins stretches near them when iterations are few. A tether is a
//! one-sided constraint per vertex and pin, `|x − x_pin| ≤ (1 + slack)·d_rest`. The nearest
//! pins are found along the cloth: a Dijkstra search from all pins at once over the rest edges
//! and, across each pair of triangles, the unfolded straight path between their far corners.
//! Such paths overestimate the distance over the surface by up to 8 % on a grid, which would
//! leave that much stretch free; so where the path is within 9 % of the straight rest distance
//! (flat rest shape), `d_rest` is the straight distance, and elsewhere (curved) the path. A
//! tether moves only the free vertex, costs one pass per substep, and bounds stretch whatever
//! the resolution.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use core::ops::Range;

use bytemuck::cast;
use glam::{Vec3, Vec4, Vec4Swizzles};
use wide::{CmpGt, f32x4};

use crate::solver::mesh::Topology;

/// How unevenly (relative to each length) the edges and tethered distances of a rest shape
/// may have been scaled, beyond the rounding of its positions, for
/// [`Tethers::rescaled`] to scale the limits instead of building them again: a tenth of
/// the smallest change of an entity's scale the plugin follows with the rest shape.
pub(crate) const RESCALE_TOLERANCE: f32 = 1e-5;

/// Tether settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetherParams {
    /// Allowed stretch beyond the rest distance (0.02 = 2 %).
    pub slack: f32,
    /// Each vertex is tethered to this many of its nearest pins (at least 1). One bounds the
    /// distance to the nearest pin; two or more also bound sideways stretch between pins.
    pub pins_per_vertex: usize,
}

impl Default for TetherParams {
    fn default() -> Self {
        Self {
            slack: 0.0,
            pins_per_vertex: 2,
        }
    }
}

/// Each tethered vertex's pins and the longest distance allowed from each.
///
/// Stored in rounds: round `r` holds, for every vertex, its `r`-th nearest pin (as a slot in
/// a list of the pinned vertices) and the limit, `+∞` where a vertex has fewer tethers. So
/// eight neighbouring vertices are projected together in SIMD lanes, and a vertex range (a
/// part) alone, in parallel with the others.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tethers {
    /// The pinned vertex of each anchor slot.
    anchors: Vec<u32>,
    /// Vertex count.
    n: usize,
    /// Rounds stored (the most tethers any vertex has).
    rounds: usize,
    /// `rounds × n`: the anchor slot of each vertex's tether in each round.
    slot: Vec<u32>,
    /// `rounds × n`: the longest distance allowed (`+∞`: no tether).
    max_len: Vec<f32>,
    /// The rest positions the limits were measured on and the limits there: `max_len` is
    /// them times the uniform scale the rest shape has taken since (see [`Self::rescaled`]).
    measured: Measured,
}

/// What a search of the mesh measured (see [`Tethers::rescaled`]).
#[derive(Clone, Debug, Default, PartialEq)]
struct Measured {
    rest: Vec<Vec3>,
    max_len: Vec<f32>,
}

impl Tethers {
    /// Tethers every vertex connected to a pin to its `pins_per_vertex` nearest pins (along
    /// the rest mesh): a Dijkstra search from all pins at once in which each vertex settles
    /// up to that many distinct sources.
    #[must_use]
    pub fn build(topology: &Topology, pins: &[u32], params: TetherParams) -> Self {
        let n = topology.vertex_count();
        let k = params.pins_per_vertex.max(1);
        let rest = topology.rest_positions();
        let mut adjacency: Vec<Vec<(u32, f32)>> = vec![Vec::new(); n];
        for e in topology.edges() {
            adjacency[e.v[0] as usize].push((e.v[1], e.rest));
            adjacency[e.v[1] as usize].push((e.v[0], e.rest));
        }
        // Across every pair of triangles, the straight path between the two opposite vertices
        // with the pair unfolded flat: on a grid this adds the quads' missing diagonals.
        for b in topology.bends() {
            let [a, bb, c, d] = b.v.map(|i| rest[i as usize]);
            let axis = (bb - a).normalize_or_zero();
            let along = |p: Vec3| (p - a).dot(axis);
            let off = |p: Vec3| ((p - a) - axis * along(p)).length();
            let len = (along(c) - along(d)).hypot(off(c) + off(d));
            if len.is_finite() && len > 0.0 {
                adjacency[b.v[2] as usize].push((b.v[3], len));
                adjacency[b.v[3] as usize].push((b.v[2], len));
            }
        }
        // settled[v]: the (source, distance) pairs found for v, nearest first.
        let mut settled: Vec<Vec<(u32, f32)>> = vec![Vec::new(); n];
        let mut heap = BinaryHeap::new();
        for &p in pins {
            if (p as usize) < n {
                heap.push(Reverse((Ordered(0.0), p, p)));
            }
        }
        while let Some(Reverse((Ordered(d), v, src))) = heap.pop() {
            let s = &mut settled[v as usize];
            if s.len() >= k || s.iter().any(|&(x, _)| x == src) {
                continue;
            }
            s.push((src, d));
            for &(u, w) in &adjacency[v as usize] {
                let su = &settled[u as usize];
                if su.len() < k && !su.iter().any(|&(x, _)| x == src) {
                    heap.push(Reverse((Ordered(d + w), u, src)));
                }
            }
        }
        let pinned: std::collections::HashSet<u32> = pins.iter().copied().collect();
        let mut anchors: Vec<u32> = Vec::new();
        let mut slot_of = std::collections::HashMap::new();
        let mut lists: Vec<Vec<(u32, f32)>> = vec![Vec::new(); n];
        for (v, list) in settled.iter().enumerate() {
            if pinned.contains(&(v as u32)) {
                continue;
            }
            for &(src, path) in list {
                let straight = rest[v].distance(rest[src as usize]);
                // Paths along a flat grid's edges and diagonals are at most 8.3 % longer than
                // the straight line: within 9 %, the rest shape is taken as flat between the
                // two and the straight distance is exact; beyond, it is curved and the path is
                // the better (slightly long) estimate of the distance over the surface.
                let d = if path <= 1.09 * straight {
                    straight
                } else {
                    path
                };
                if d > 0.0 && d.is_finite() {
                    let slot = *slot_of.entry(src).or_insert_with(|| {
                        anchors.push(src);
                        anchors.len() as u32 - 1
                    });
                    lists[v].push((slot, d * (1.0 + params.slack.max(0.0))));
                }
            }
        }
        let rounds = lists.iter().map(Vec::len).max().unwrap_or(0);
        let mut t = Tethers {
            anchors,
            n,
            rounds,
            slot: vec![0; rounds * n],
            max_len: vec![f32::INFINITY; rounds * n],
            measured: Measured::default(),
        };
        for (v, list) in lists.iter().enumerate() {
            for (r, &(slot, max_len)) in list.iter().enumerate() {
                t.slot[r * n + v] = slot;
                t.max_len[r * n + v] = max_len;
            }
        }
        t.measured = Measured {
            rest: rest.to_vec(),
            max_len: t.max_len.clone(),
        };
        t
    }

    /// These tethers for `topology`, the mesh they were built on (the same vertices, edges
    /// and triangles) with its rest shape scaled evenly, moved or turned, as an entity grown
    /// in by its scale is (see [`Simulation::set_rest_shape`](crate::solver::Simulation::set_rest_shape)): every limit
    /// times the scale, without searching the mesh again. The same limits as
    /// [`Self::build`] on `topology` up to the rounding of the rest positions, the same pins
    /// unless two were equally near.
    ///
    /// Measured against the rest shape the tethers were built on, not the last one, so a
    /// scale animated over many frames does not gather rounding or a slight unevenness.
    /// `None` (build them again) where `topology` has another vertex count or its rest shape
    /// is not the measured one scaled evenly as far as the limits can tell: an edge, or a
    /// tethered vertex's straight distance to its pin, scaled by another factor than the
    /// edges' mean beyond the rounding of the positions and [`RESCALE_TOLERANCE`].
    #[must_use]
    pub(crate) fn rescaled(&self, topology: &Topology) -> Option<Self> {
        let was = &self.measured.rest;
        let now = topology.rest_positions();
        if was.len() != self.n || now.len() != self.n {
            return None;
        }
        let length = |p: &[Vec3], a: u32, b: u32| p[a as usize].distance(p[b as usize]);
        let pairs = topology.edges().iter().map(|e| (e.v[0], e.v[1]));
        let (sum_was, sum_now) = pairs.clone().fold((0.0f64, 0.0f64), |(w, n), (a, b)| {
            (
                w + f64::from(length(was, a, b)),
                n + f64::from(length(now, a, b)),
            )
        });
        let scale = (sum_now / sum_was) as f32;
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        // Beyond the tolerance, or the rounding of positions as far from the origin as the
        // pair's ends (a few ulps of each end, before and after).
        let even = |a: u32, b: u32| {
            let far = |p: &[Vec3]| p[a as usize].abs().max(p[b as usize].abs()).max_element();
            let rounding = 8.0 * f32::EPSILON * (far(now) + scale * far(was));
            let expected = scale * length(was, a, b);
            (length(now, a, b) - expected).abs() <= RESCALE_TOLERANCE * expected + rounding
        };
        let tethered = self.entries().map(|(v, pin, _)| (v, pin));
        if !(pairs.clone().all(|(a, b)| even(a, b)) && tethered.clone().all(|(v, p)| even(v, p))) {
            return None;
        }
        let mut t = self.clone();
        for (l, m) in t.max_len.iter_mut().zip(&self.measured.max_len) {
            *l = m * scale;
        }
        Some(t)
    }

    /// Number of tethers (a vertex may have several).
    #[must_use]
    pub fn len(&self) -> usize {
        self.max_len.iter().filter(|l| **l < f32::INFINITY).count()
    }

    /// Whether nothing is tethered.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.max_len.iter().all(|l| *l == f32::INFINITY)
    }

    /// The vertex count the tethers were built for.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.n
    }

    /// The pinned vertex of each anchor slot: [`Self::project_range`] takes their positions in
    /// this order.
    pub(crate) fn anchors(&self) -> &[u32] {
        &self.anchors
    }

    /// Every attachment as `(vertex, pin, max_len)`, grouped by vertex in ascending order,
    /// nearest pin first (the order [`Self::project_range`] applies each vertex's tethers
    /// in; the GPU twin's layout).
    pub(crate) fn entries(&self) -> impl Iterator<Item = (u32, u32, f32)> + Clone + '_ {
        (0..self.n).flat_map(move |v| {
            (0..self.rounds).filter_map(move |r| {
                let i = r * self.n + v;
                let max_len = self.max_len[i];
                (max_len < f32::INFINITY)
                    .then(|| (v as u32, self.anchors[self.slot[i] as usize], max_len))
            })
        })
    }

    /// Pulls every over-stretched vertex back onto its tethers' spheres, reading the pins
    /// where they are in `pos` (the step projects part by part with [`Self::project_range`]).
    #[cfg(test)]
    pub(crate) fn project(&self, pos: &mut [Vec4]) {
        let anchors: Vec<Vec4> = self
            .anchors
            .iter()
            .map(|&p| pos.get(p as usize).copied().unwrap_or(Vec4::ZERO))
            .collect();
        let n = self.n.min(pos.len());
        self.project_range(0..n, &mut pos[..n], &anchors);
    }

    /// The tethers' projection for the vertices of `range` only, whose positions are `pos`
    /// (`pos[0]` is vertex `range.start`), with the pins at `anchors` (one per slot of
    /// [`Self::anchors`]). Ranges that do not overlap may be projected in parallel. Each
    /// vertex's tethers apply nearest pin first; eight vertices go at once in SIMD lanes
    /// (then four, then one by one), with the same arithmetic as one at a time.
    pub(crate) fn project_range(&self, range: Range<usize>, pos: &mut [Vec4], anchors: &[Vec4]) {
        assert!(
            pos.len() == range.len() && range.end <= self.n && anchors.len() == self.anchors.len(),
            "tether range, positions and anchors disagree"
        );
        // Groups of eight (two sets of lanes, so one set's square root and division overlap
        // the other's), then of four, then one by one.
        let eights = range.len() / 8 * 8;
        for (c, chunk) in pos[..eights].chunks_exact_mut(8).enumerate() {
            self.project_lanes::<2>(range.start + 8 * c, chunk, anchors);
        }
        let simd = range.len() / 4 * 4;
        if simd > eights {
            self.project_lanes::<1>(range.start + eights, &mut pos[eights..simd], anchors);
        }
        for (k, x) in pos.iter_mut().enumerate().skip(simd) {
            let v = range.start + k;
            if x.w <= 0.0 {
                continue;
            }
            for r in 0..self.rounds {
                let i = r * self.n + v;
                let max_len = self.max_len[i];
                let anchor = anchors[self.slot[i] as usize].xyz();
                let d = x.xyz() - anchor;
                let len2 = d.length_squared();
                if len2 > max_len * max_len {
                    let pulled = anchor + d * (max_len / len2.sqrt());
                    if pulled.is_finite() {
                        *x = pulled.extend(x.w);
                    }
                }
            }
        }
    }

    /// Projects the tethers of `4·G` consecutive vertices from `v` (`chunk` their positions)
    /// in `G` sets of four lanes.
    #[inline(always)]
    fn project_lanes<const G: usize>(&self, v: usize, chunk: &mut [Vec4], anchors: &[Vec4]) {
        let mut x = [[f32x4::ZERO; 4]; G];
        for (g, x) in x.iter_mut().enumerate() {
            let c = &chunk[4 * g..4 * g + 4];
            *x = f32x4::transpose([cast(c[0]), cast(c[1]), cast(c[2]), cast(c[3])]);
        }
        let free = x.map(|x| x[3].cmp_gt(f32x4::ZERO));
        for r in 0..self.rounds {
            for (g, x) in x.iter_mut().enumerate() {
                let i = r * self.n + v + 4 * g;
                let slot = &self.slot[i..i + 4];
                let max_len = &self.max_len[i..i + 4];
                let max_len = f32x4::new([max_len[0], max_len[1], max_len[2], max_len[3]]);
                let [ax, ay, az, _] = f32x4::transpose([
                    cast(anchors[slot[0] as usize]),
                    cast(anchors[slot[1] as usize]),
                    cast(anchors[slot[2] as usize]),
                    cast(anchors[slot[3] as usize]),
                ]);
                let (dx, dy, dz) = (x[0] - ax, x[1] - ay, x[2] - az);
                let len2 = dx * dx + dy * dy + dz * dz;
                let s = max_len / len2.sqrt();
                let (px, py, pz) = (ax + dx * s, ay + dy * s, az + dz * s);
                let pull = len2.cmp_gt(max_len * max_len)
                    & free[g]
                    & px.is_finite()
                    & py.is_finite()
                    & pz.is_finite();
                x[0] = pull.blend(px, x[0]);
                x[1] = pull.blend(py, x[1]);
                x[2] = pull.blend(pz, x[2]);
            }
        }
        for (g, x) in x.into_iter().enumerate() {
            let rows = f32x4::transpose(x);
            for (out, row) in chunk[4 * g..4 * g + 4].iter_mut().zip(rows) {
                *out = cast(row);
            }
        }
    }
}

/// `f32` ordered for the heap (distances are finite and non-negative).
#[derive(Clone, Copy, PartialEq)]
struct Ordered(f32);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<core::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> core::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::{Grid, TopologyOptions};

    #[test]
    fn tethers_use_path_length_to_the_nearest_pin() {
        let g = Grid::new(5, 3, 4.0, 2.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let pins = [g.index(0, 0), g.index(4, 0)];
        let tethers = Tethers::build(
            &t,
            &pins,
            TetherParams {
                slack: 0.0,
                pins_per_vertex: 1,
            },
        );
        assert_eq!(tethers.len(), 15 - 2);
        let both = Tethers::build(
            &t,
            &pins,
            TetherParams {
                slack: 0.0,
                pins_per_vertex: 2,
            },
        );
        assert_eq!(both.len(), 2 * (15 - 2));
        let of = |t: &Tethers, v: u32| t.entries().find(|e| e.0 == v).unwrap();
        let (_, pin, max_len) = of(&tethers, g.index(1, 0));
        assert_eq!(pin, g.index(0, 0));
        assert!((max_len - 1.0).abs() < 1e-6);
        // (1, 2) from pin (0, 0): the flat rest distance √5, not a path along edges.
        let (_, _, max_len) = of(&tethers, g.index(1, 2));
        assert!((max_len - 5f32.sqrt()).abs() < 1e-5);
        // A curved rest shape (the strip folded 90° along its middle row) keeps the longer
        // path: the straight line would cut the corner.
        let folded: Vec<Vec3> = g
            .positions()
            .iter()
            .map(|p| {
                if p.z < 0.0 {
                    Vec3::new(p.x, p.z, 0.0)
                } else {
                    *p
                }
            })
            .collect();
        let ft = crate::solver::Topology::from_triangles(
            &folded,
            None,
            &g.indices(),
            TopologyOptions::default(),
        )
        .unwrap();
        let tf = Tethers::build(&ft, &[g.index(0, 0)], TetherParams::default());
        let (_, _, max_len) = of(&tf, g.index(0, 2));
        // Down the folded column: 1 m along z to the fold, then 1 m down; straight: √2.
        assert!((max_len - 2.0).abs() < 1e-5, "{max_len}");
    }

    /// The lane projection against the plain one, tether by tether in `entries` order, on a
    /// crumpled, over-stretched 9 × 5 grid (45 vertices: five groups of eight, one of four,
    /// one alone) with three pins and a NaN vertex: the same bits.
    #[test]
    fn lanes_match_one_tether_at_a_time() {
        let g = Grid::new(9, 5, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let pins = [g.index(0, 0), g.index(8, 0), g.index(4, 4)];
        let tethers = Tethers::build(&t, &pins, TetherParams::default());
        assert_eq!(tethers.len(), 2 * (45 - 3));
        let mut pos: Vec<Vec4> = g
            .positions()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let k = i as f32;
                (*p * 1.7 + Vec3::new((k * 1.3).sin(), (k * 0.7).cos(), (k * 2.1).sin()))
                    .extend(1.0)
            })
            .collect();
        for &p in &pins {
            pos[p as usize].w = 0.0;
        }
        pos[11] = Vec4::new(f32::NAN, 0.0, 0.0, 1.0);
        let mut expected = pos.clone();
        for (v, p, max_len) in tethers.entries() {
            let anchor = expected[p as usize].xyz();
            let x = &mut expected[v as usize];
            let d = x.xyz() - anchor;
            let len2 = d.length_squared();
            if x.w > 0.0 && len2 > max_len * max_len {
                let pulled = anchor + d * (max_len / len2.sqrt());
                if pulled.is_finite() {
                    *x = pulled.extend(x.w);
                }
            }
        }
        let moved = expected.iter().zip(&pos).filter(|(a, b)| a != b).count();
        assert!(moved > 30, "only {moved} vertices were over-stretched");
        tethers.project(&mut pos);
        for (i, (a, b)) in pos.iter().zip(&expected).enumerate() {
            assert!(
                a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits),
                "vertex {i}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn projection_pulls_back_only_beyond_the_limit() {
        let g = Grid::new(3, 2, 2.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let tethers = Tethers::build(
            &t,
            &[0],
            TetherParams {
                slack: 0.0,
                pins_per_vertex: 1,
            },
        );
        let mut pos: Vec<Vec4> = g.positions().iter().map(|p| p.extend(1.0)).collect();
        pos[0].w = 0.0;
        pos[2] += Vec4::new(3.0, 0.0, 0.0, 0.0); // 5 m from the pin, limit 2
        pos[1] += Vec4::new(-0.1, 0.0, 0.0, 0.0); // 0.9 m from the pin: within its 1 m
        let before = pos[1];
        tethers.project(&mut pos);
        assert!((pos[2].xyz().distance(pos[0].xyz()) - 2.0).abs() < 1e-5);
        assert_eq!(pos[1], before);
    }

    /// A curved 9 × 7 sheet (both kinds of limits: straight where it is flat enough, the path
    /// where it is not) with three pins placed unevenly (no two equally near a vertex).
    fn curved() -> (Vec<Vec3>, Vec<u32>, [u32; 3]) {
        let g = Grid::new(9, 7, 2.0, 1.5);
        let rest = g
            .positions()
            .iter()
            .map(|p| Vec3::new(p.x, 0.4 * (2.0 * p.x).sin() + 0.3 * p.z * p.z, p.z))
            .collect();
        (
            rest,
            g.indices(),
            [g.index(0, 0), g.index(8, 1), g.index(3, 6)],
        )
    }

    fn topology(rest: &[Vec3], indices: &[u32]) -> Topology {
        Topology::from_triangles(rest, None, indices, TopologyOptions::default()).unwrap()
    }

    /// Every tether of `a` is one of `b`'s (same vertex, same pin, in the same order) with a
    /// limit within the rounding of positions as far as `far` from the origin: a limit is a
    /// sum of up to a dozen lengths along the mesh, each a few ulps of `far` off.
    fn assert_same_limits(a: &Tethers, b: &Tethers, far: f32) {
        assert_eq!(a.len(), b.len());
        for ((va, pa, la), (vb, pb, lb)) in a.entries().zip(b.entries()) {
            assert_eq!((va, pa), (vb, pb));
            let tolerance = 64.0 * f32::EPSILON * (lb + far);
            assert!((la - lb).abs() <= tolerance, "vertex {va}: {la} vs {lb}");
        }
    }

    #[test]
    fn an_evenly_scaled_rest_shape_scales_the_limits_as_a_search_finds_them() {
        let (rest, indices, pins) = curved();
        let params = TetherParams {
            slack: 0.05,
            pins_per_vertex: 2,
        };
        let tethers = Tethers::build(&topology(&rest, &indices), &pins, params);
        assert!(tethers.len() > 100, "{}", tethers.len());
        // Grown 2.5 times, turned and moved, then shrunk to 0.3 of its first size far from
        // the origin: each time as a search of the new shape finds, measured from the first.
        let turn = glam::Quat::from_rotation_y(0.7) * glam::Quat::from_rotation_x(-0.3);
        let mut last = tethers.clone();
        for (scale, offset) in [(2.5, Vec3::new(3.0, 2.0, -1.0)), (0.3, Vec3::splat(200.0))] {
            let moved: Vec<Vec3> = rest.iter().map(|p| turn * (*p * scale) + offset).collect();
            let shape = topology(&moved, &indices);
            let scaled = last.rescaled(&shape).expect("an even scale");
            let searched = Tethers::build(&shape, &pins, params);
            assert_same_limits(&scaled, &searched, offset.length() + 3.0 * scale);
            // Not merely the limits it had: they changed by the scale.
            let (_, _, first) = tethers.entries().next().unwrap();
            let (_, _, now) = scaled.entries().next().unwrap();
            assert!((now / first - scale).abs() < 1e-5, "{now} / {first}");
            last = scaled;
        }
    }

    #[test]
    fn an_uneven_scale_or_another_shape_is_searched_again() {
        let (rest, indices, pins) = curved();
        let tethers = Tethers::build(&topology(&rest, &indices), &pins, TetherParams::default());
        // Wider than deep, by a hundredth and by a thousandth (beyond the tolerance, 1e-5).
        for widen in [1.01, 1.001] {
            let wide: Vec<Vec3> = rest
                .iter()
                .map(|p| *p * Vec3::new(widen, 1.0, 1.0))
                .collect();
            assert!(
                tethers.rescaled(&topology(&wide, &indices)).is_none(),
                "{widen}"
            );
        }
        // One vertex moved: its edges no longer scale with the others.
        let mut bent = rest.clone();
        bent[30].y += 0.05;
        assert!(tethers.rescaled(&topology(&bent, &indices)).is_none());
        // Another vertex count.
        let g = Grid::new(4, 4, 1.0, 1.0);
        let small = g.topology(TopologyOptions::default()).unwrap();
        assert!(tethers.rescaled(&small).is_none());
        // Collapsed to a point: no scale to take.
        let point = vec![Vec3::ZERO; rest.len()];
        let collapsed =
            Topology::from_triangles(&point, None, &indices, TopologyOptions::default());
        if let Ok(collapsed) = collapsed {
            assert!(tethers.rescaled(&collapsed).is_none());
        }
        // A flat sheet scaled across its plane only is the same shape: kept as it was.
        let g = Grid::new(6, 5, 1.0, 1.0);
        let flat = g.topology(TopologyOptions::default()).unwrap();
        let t = Tethers::build(&flat, &[0, 5], TetherParams::default());
        let thick: Vec<Vec3> = g
            .positions()
            .iter()
            .map(|p| *p * Vec3::new(1.0, 3.0, 1.0))
            .collect();
        let same = t
            .rescaled(&topology(&thick, &g.indices()))
            .expect("the same shape");
        assert_eq!(same.max_len, t.max_len);
    }
}
