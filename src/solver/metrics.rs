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
