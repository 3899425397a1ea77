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

use glam::{Vec3, Vec4, Vec4Swizzles};

use super::topology::Topology;

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

/// Each tethered vertex, the pin it hangs from, and the longest distance allowed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tethers {
    vertex: Vec<u32>,
    pin: Vec<u32>,
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
        let mut t = Tethers::default();
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
                    t.vertex.push(v as u32);
                    t.pin.push(src);
                    t.max_len.push(d * (1.0 + params.slack.max(0.0)));
                }
            }
        }
        t
    }

    /// Number of tethers (a vertex may have several).
    #[must_use]
    pub fn len(&self) -> usize {
        self.vertex.len()
    }

    /// Whether nothing is tethered.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.vertex.is_empty()
    }

    /// Pulls every over-stretched vertex back onto its tether's sphere.
    /// Every attachment as `(vertex, pin, max_len)`, grouped by vertex in ascending order
    /// (the order [`Self::project`] applies them; the GPU twin's layout).
    pub(crate) fn entries(&self) -> impl Iterator<Item = (u32, u32, f32)> + Clone + '_ {
        self.vertex
            .iter()
            .zip(&self.pin)
            .zip(&self.max_len)
            .map(|((&v, &p), &l)| (v, p, l))
    }

    pub(crate) fn project(&self, pos: &mut [Vec4]) {
        for ((&v, &p), &max_len) in self.vertex.iter().zip(&self.pin).zip(&self.max_len) {
            let anchor: Vec3 = pos[p as usize].xyz();
            let x = &mut pos[v as usize];
            if x.w <= 0.0 {
                continue;
            }
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
    use crate::solver::{Grid, TopologyOptions};

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
        let k = tethers
            .vertex
            .iter()
            .position(|&v| v == g.index(1, 0))
            .unwrap();
        assert_eq!(tethers.pin[k], g.index(0, 0));
        assert!((tethers.max_len[k] - 1.0).abs() < 1e-6);
        // (1, 2) from pin (0, 0): the flat rest distance √5, not a path along edges.
        let k = tethers
            .vertex
            .iter()
            .position(|&v| v == g.index(1, 2))
            .unwrap();
        assert!((tethers.max_len[k] - 5f32.sqrt()).abs() < 1e-5);
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
        let k = tf.vertex.iter().position(|&v| v == g.index(0, 2)).unwrap();
        // Down the folded column: 1 m along z to the fold, then 1 m down; straight: √2.
        assert!((tf.max_len[k] - 2.0).abs() < 1e-5, "{}", tf.max_len[k]);
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
}
