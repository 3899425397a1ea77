//! Accuracy measures used by tests, examples and the trade-off benchmark.

use glam::{Vec4, Vec4Swizzles};

use crate::solver::mesh::Edge;

/// Edge strain `|length − rest|/rest` over a set of edges.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StrainStats {
    /// Largest strain (0.1 = 10 % longer or shorter than at rest).
    pub max: f32,
    /// Mean strain.
    pub mean: f32,
}

/// Strain of every edge with a non-zero rest length.
#[must_use]
pub fn edge_strain(positions: &[Vec4], edges: &[Edge]) -> StrainStats {
    let mut max = 0.0f32;
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for e in edges {
        if e.rest <= f32::EPSILON {
            continue;
        }
        let len = positions[e.v[0] as usize]
            .xyz()
            .distance(positions[e.v[1] as usize].xyz());
        let strain = (len - e.rest).abs() / e.rest;
        max = max.max(strain);
        sum += f64::from(strain);
        count += 1;
    }
    StrainStats {
        max,
        mean: if count == 0 {
            0.0
        } else {
            (sum / count as f64) as f32
        },
    }
}

/// The largest stretch `length / rest − 1` among the edges at least `min_rest` long at rest
/// (0 when none is longer than at rest; edges with a non-finite end are left out): how far
/// the cloth's visible edges are pulled. A modelling tool's mesh often has detail edges a
/// hundred times shorter than the rest, whose strain says little about how the cloth looks;
/// `min_rest` leaves them out.
#[must_use]
pub fn max_stretch(positions: &[Vec4], edges: &[Edge], min_rest: f32) -> f32 {
    stretch_over(positions, edges, min_rest, |e| e.rest)
}

/// [`max_stretch`] against the longer of each edge's rest length and its length in
/// `reference` (a skin's targets, which an animation may stretch): how far the cloth is
/// pulled beyond what it is made to follow. A `reference` of another length than
/// `positions` is not one: plain [`max_stretch`].
#[must_use]
pub fn max_stretch_beyond(
    positions: &[Vec4],
    reference: &[Vec4],
    edges: &[Edge],
    min_rest: f32,
) -> f32 {
    if reference.len() != positions.len() {
        return max_stretch(positions, edges, min_rest);
    }
    stretch_over(positions, edges, min_rest, |e| {
        let skin = length(reference, e);
        // Not `max`: a skin length that is not finite leaves the rest length.
        if skin > e.rest { skin } else { e.rest }
    })
}

/// The length of `e` in `positions`.
fn length(positions: &[Vec4], e: &Edge) -> f32 {
    positions[e.v[0] as usize]
        .xyz()
        .distance(positions[e.v[1] as usize].xyz())
}

/// The largest `length / against(edge) − 1` over the edges resting at least `min_rest` (and
/// longer than `f32::EPSILON`) whose length is finite; 0 when none is stretched.
fn stretch_over(
    positions: &[Vec4],
    edges: &[Edge],
    min_rest: f32,
    against: impl Fn(&Edge) -> f32,
) -> f32 {
    edges
        .iter()
        .filter(|e| e.rest > f32::EPSILON && e.rest >= min_rest)
        .filter_map(|e| {
            let len = length(positions, e);
            len.is_finite().then(|| len / against(e) - 1.0)
        })
        .fold(0.0, f32::max)
}

/// Mean and largest distance between two sets of positions of the same length.
#[must_use]
pub fn position_distance(a: &[Vec4], b: &[Vec4]) -> (f32, f32) {
    let mut max = 0.0f32;
    let mut sum = 0.0f64;
    for (p, q) in a.iter().zip(b) {
        let d = p.xyz().distance(q.xyz());
        max = max.max(d);
        sum += f64::from(d);
    }
    ((sum / a.len().max(1) as f64) as f32, max)
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::solver::mesh::EdgeKind;

    fn edge(a: u32, b: u32, rest: f32) -> Edge {
        Edge {
            v: [a, b],
            rest,
            kind: EdgeKind::Stretch,
        }
    }

    /// Against a skin that stretches an edge, only what the cloth is pulled beyond the skin
    /// counts; a skin shorter than the rest (or not finite) leaves the rest length.
    #[test]
    fn max_stretch_beyond_a_skin_counts_what_the_skin_does_not_stretch() {
        let p = |x: f32| Vec3::new(x, 0.0, 0.0).extend(0.0);
        let edges = [edge(0, 1, 1.0), edge(1, 2, 1.0)];
        // Now 3 and 1.5 long.
        let positions = [p(0.0), p(3.0), p(4.5)];
        // The skin: the first edge 3 long (as the cloth), the second 0.5.
        let skin = [p(0.0), p(3.0), p(3.5)];
        assert!((max_stretch(&positions, &edges, 0.0) - 2.0).abs() < 1e-6);
        assert!((max_stretch_beyond(&positions, &skin, &edges, 0.0) - 0.5).abs() < 1e-6);
        // The skin stretched as far as the cloth: nothing beyond it.
        let skin = [p(0.0), p(3.0), p(4.5)];
        assert_eq!(max_stretch_beyond(&positions, &skin, &edges, 0.0), 0.0);
        // A skin that is not one, or not finite, is the rest.
        let nan = [p(0.0), p(f32::NAN), p(4.5)];
        assert!((max_stretch_beyond(&positions, &nan, &edges, 0.0) - 2.0).abs() < 1e-6);
        assert!((max_stretch_beyond(&positions, &skin[..2], &edges, 0.0) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn max_stretch_reads_the_longest_pull_among_edges_long_enough() {
        let p = |x: f32| Vec3::new(x, 0.0, 0.0).extend(0.0);
        // 0–1 rest 1, now 2.5 apart (1.5); 1–2 rest 0.01, now 0.5 apart (49, a detail edge);
        // 2–3 rest 1, now 0.2 apart (squeezed: no stretch).
        let positions = [p(0.0), p(2.5), p(3.0), p(3.2)];
        let edges = [edge(0, 1, 1.0), edge(1, 2, 0.01), edge(2, 3, 1.0)];
        assert!((max_stretch(&positions, &edges, 0.0) - 49.0).abs() < 1e-3);
        assert_eq!(max_stretch(&positions, &edges, 0.5), 1.5);
        assert_eq!(max_stretch(&positions, &edges[2..], 0.5), 0.0);
        // A non-finite end is left out, and so are zero-length edges.
        let bad = [p(0.0), Vec4::new(f32::NAN, 0.0, 0.0, 0.0), p(0.0)];
        assert_eq!(
            max_stretch(&bad, &[edge(0, 1, 1.0), edge(0, 2, 0.0)], 0.0),
            0.0
        );
    }
}
