//! Tearing: edges stretched past `threshold × rest length` break.
//!
//! After a step, [`overstretched_edges`] lists the edges to break; the cloth's topology is then
//! rebuilt without them ([`Topology::without_edges`](crate::solver::Topology::without_edges)): the
//! triangles that used a torn edge disappear (from the constraints and from the rendered index
//! buffer), and so do the edges and bending pairs no remaining triangle supports. Normals are
//! recomputed from the remaining triangles, so they stay right along the tear.

use glam::{Vec4, Vec4Swizzles};

use crate::solver::mesh::Edge;

/// Edges (vertex pairs) longer than `threshold` times their rest length. A threshold that is
/// not finite or not above 1 tears nothing.
#[must_use]
pub fn overstretched_edges(positions: &[Vec4], edges: &[Edge], threshold: f32) -> Vec<[u32; 2]> {
    if !(threshold.is_finite() && threshold > 1.0) {
        return Vec::new();
    }
    edges
        .iter()
        .filter(|e| {
            let len = positions[e.v[0] as usize]
                .xyz()
                .distance(positions[e.v[1] as usize].xyz());
            e.rest > 0.0 && len > threshold * e.rest
        })
        .map(|e| e.v)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::{Grid, Topology, TopologyOptions};
    use std::collections::HashSet;

    fn check_consistent(t: &Topology) {
        let edges: HashSet<[u32; 2]> = t.edges().iter().map(|e| e.v).collect();
        let n = t.vertex_count() as u32;
        for tri in t.triangles() {
            assert!(tri.iter().all(|&v| v < n));
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                assert!(
                    edges.contains(&[a.min(b), a.max(b)]),
                    "triangle edge missing"
                );
            }
        }
        // Every edge belongs to a remaining triangle; every bend spans two of them.
        for e in t.edges() {
            assert!(
                t.triangles()
                    .iter()
                    .any(|tri| tri.contains(&e.v[0]) && tri.contains(&e.v[1]))
            );
        }
        for b in t.bends() {
            assert_eq!(t.edges()[b.edge as usize].v, [b.v[0], b.v[1]]);
            for opp in [b.v[2], b.v[3]] {
                assert!(t.triangles().iter().any(|tri| {
                    tri.contains(&b.v[0]) && tri.contains(&b.v[1]) && tri.contains(&opp)
                }));
            }
        }
    }

    #[test]
    fn tearing_keeps_topology_consistent_at_boundary_interior_and_everywhere() {
        let g = Grid::new(6, 6, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        // Boundary edge: one triangle goes.
        let boundary = [g.index(0, 0), g.index(1, 0)];
        let b = t.without_edges(&[boundary]);
        assert_eq!(b.triangles().len(), t.triangles().len() - 1);
        check_consistent(&b);
        // Interior edge: both triangles go, and the edge with them.
        let interior = [g.index(2, 2), g.index(3, 2)];
        let i = t.without_edges(&[interior]);
        assert_eq!(i.triangles().len(), t.triangles().len() - 2);
        assert!(i.edges().iter().all(|e| e.v != interior));
        check_consistent(&i);
        // Every edge: nothing left but free vertices.
        let all: Vec<[u32; 2]> = t.edges().iter().map(|e| e.v).collect();
        let none = t.without_edges(&all);
        assert!(none.triangles().is_empty() && none.edges().is_empty() && none.bends().is_empty());
        assert_eq!(none.vertex_count(), 36);
        check_consistent(&none);
    }

    #[test]
    fn tearing_given_edges_tears_as_the_threshold_does_and_ignores_non_edges() {
        use crate::solver::{Features, Simulation, SolverParams};
        let g = Grid::new(6, 6, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let mut a = Simulation::new(t, &[0.01; 36], SolverParams::default()).unwrap();
        a.set_features(Features {
            tear_threshold: Some(1.5),
            ..Default::default()
        })
        .unwrap();
        let mut b = a.clone();
        for s in [&mut a, &mut b] {
            s.state_mut().positions[g.index(2, 2) as usize].x += 0.4;
        }
        let over = overstretched_edges(&a.state().positions, a.topology().edges(), 1.5);
        assert!(!over.is_empty());
        let by_threshold = a.tear();
        // The same edges given, either way round, with a pair that is no edge.
        let mut given: Vec<[u32; 2]> = over.iter().map(|e| [e[1], e[0]]).collect();
        given.push([g.index(0, 0), g.index(5, 5)]);
        assert_eq!(b.tear_edges(&given), by_threshold);
        assert_eq!(b.topology().triangles(), a.topology().triangles());
        assert!(by_threshold.len() >= over.len());
        // Nothing that is an edge: nothing tears, the topology stays.
        let before = b.topology().triangles().len();
        assert!(b.tear_edges(&[[g.index(0, 0), g.index(5, 5)]]).is_empty());
        assert_eq!(b.topology().triangles().len(), before);
    }

    #[test]
    fn a_closed_cloth_torn_open_keeps_sweeping_both_ways() {
        use crate::solver::{Simulation, SolverParams};
        let p = [
            glam::Vec3::ZERO,
            glam::Vec3::X,
            glam::Vec3::Y,
            glam::Vec3::Z,
        ];
        let o = TopologyOptions::default();
        let tet =
            Topology::from_triangles(&p, None, &[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], o).unwrap();
        let mut s = Simulation::new(tet, &[0.01; 4], SolverParams::default()).unwrap();
        assert!(
            s.batches().symmetric_sweeps(),
            "a closed cloth sweeps both ways"
        );
        assert!(!s.tear_edges(&[[0, 1]]).is_empty());
        assert!(!s.topology().is_closed());
        assert!(
            s.batches().symmetric_sweeps(),
            "and keeps doing so once torn open"
        );
        s.set_part_count(1);
        assert!(s.batches().symmetric_sweeps(), "and with other parts");
        // An open cloth built so sweeps forward only.
        let open = Topology::from_triangles(&p, None, &[0, 2, 1, 0, 1, 3, 0, 3, 2], o).unwrap();
        let s = Simulation::new(open, &[0.01; 4], SolverParams::default()).unwrap();
        assert!(!s.batches().symmetric_sweeps());
    }

    #[test]
    fn only_edges_past_the_threshold_tear() {
        let g = Grid::new(3, 2, 2.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let mut pos: Vec<Vec4> = g.positions().iter().map(|p| p.extend(1.0)).collect();
        pos[2].x += 0.6; // edge (1, 2) is 1.6 long, rest 1; (2, 5) diagonal stretched too
        let torn = overstretched_edges(&pos, t.edges(), 1.5);
        assert!(torn.contains(&[1, 2]));
        assert!(!torn.contains(&[0, 1]));
        assert!(overstretched_edges(&pos, t.edges(), f32::NAN).is_empty());
        assert!(overstretched_edges(&pos, t.edges(), 1.0).is_empty());
    }
}
