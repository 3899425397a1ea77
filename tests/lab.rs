//! Seed 000's lab rule, checked against an independent implementation written here from the
//! lab sheet (its own mesh, edge list and update loop; nothing shared with the solver), in f32
//! like the lab's Unity code.

#![expect(
    clippy::needless_range_loop,
    reason = "the reference is written index by index, like the lab sheet"
)]

use bevy_cloth::solver::{
    Pin, Serial, Simulation, Solver, SolverParams, Topology, TopologyOptions,
};
use glam::{Vec2, Vec3};

const N: usize = 21;
const DT: f32 = 0.0333;

/// The lab's mesh: vertex `j·21+i` at `(5 − 10i/20, 0, 5 − 10j/20)`, quads split into
/// `(a, a+1, a+22)` and `(a, a+22, a+21)`.
fn lab_mesh() -> (Vec<[f32; 3]>, Vec<usize>) {
    let mut x = Vec::new();
    for j in 0..N {
        for i in 0..N {
            x.push([
                5.0 - 10.0 * i as f32 / 20.0,
                0.0,
                5.0 - 10.0 * j as f32 / 20.0,
            ]);
        }
    }
    let mut t = Vec::new();
    for j in 0..N - 1 {
        for i in 0..N - 1 {
            let a = j * N + i;
            t.extend_from_slice(&[a, a + 1, a + 22, a, a + 22, a + 21]);
        }
    }
    (x, t)
}

/// The lab sheet's loop.
struct Reference {
    x: Vec<[f32; 3]>,
    v: Vec<[f32; 3]>,
    e: Vec<(usize, usize, f32)>,
}

impl Reference {
    fn new() -> Self {
        let (x, t) = lab_mesh();
        let mut e: Vec<(usize, usize)> = t
            .chunks(3)
            .flat_map(|c| [(c[0], c[1]), (c[1], c[2]), (c[2], c[0])])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        e.sort();
        e.dedup();
        let e = e
            .into_iter()
            .map(|(a, b)| {
                let d = ((x[a][0] - x[b][0]).powi(2)
                    + (x[a][1] - x[b][1]).powi(2)
                    + (x[a][2] - x[b][2]).powi(2))
                .sqrt();
                (a, b, d)
            })
            .collect();
        Self {
            v: vec![[0.0; 3]; x.len()],
            x,
            e,
        }
    }

    fn update(&mut self) {
        for i in 0..self.x.len() {
            if i == 0 || i == 20 {
                continue;
            }
            for k in 0..3 {
                self.v[i][k] *= 0.99;
            }
            self.v[i][1] -= 9.8 * DT;
            for k in 0..3 {
                self.x[i][k] += self.v[i][k] * DT;
            }
        }
        for _ in 0..32 {
            let mut sum_x = vec![[0.0f32; 3]; self.x.len()];
            let mut sum_n = vec![0.0f32; self.x.len()];
            for &(i, j, l) in &self.e {
                let d: Vec<f32> = (0..3).map(|k| self.x[i][k] - self.x[j][k]).collect();
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                for k in 0..3 {
                    let dir = d[k] / len;
                    sum_x[i][k] += 0.5 * (self.x[i][k] + self.x[j][k] + l * dir);
                    sum_x[j][k] += 0.5 * (self.x[i][k] + self.x[j][k] - l * dir);
                }
                sum_n[i] += 1.0;
                sum_n[j] += 1.0;
            }
            for i in 0..self.x.len() {
                if i == 0 || i == 20 {
                    continue;
                }
                for k in 0..3 {
                    let new = (0.2 * self.x[i][k] + sum_x[i][k]) / (0.2 + sum_n[i]);
                    self.v[i][k] += (new - self.x[i][k]) / DT;
                    self.x[i][k] = new;
                }
            }
        }
    }
}

fn solver() -> Simulation {
    let (x, t) = lab_mesh();
    let pos: Vec<Vec3> = x.iter().map(|p| Vec3::from(*p)).collect();
    let idx: Vec<u32> = t.iter().map(|&i| i as u32).collect();
    let uvs: Vec<Vec2> = (0..N * N)
        .map(|k| Vec2::new((k % N) as f32 / 20.0, (k / N) as f32 / 20.0))
        .collect();
    let topo =
        Topology::from_triangles(&pos, Some(&uvs), &idx, TopologyOptions::default()).unwrap();
    let mut sim = Simulation::new(
        topo,
        &vec![1.0; N * N],
        SolverParams {
            solver: Solver::LAB,
            substeps: 1,
            iterations: 32,
            gravity: Vec3::new(0.0, -9.8, 0.0),
            damping: 0.0,
            ..Default::default()
        },
    )
    .unwrap();
    sim.state_mut()
        .set_pins([0u32, 20].map(|v| Pin {
            vertex: v,
            target: pos[v as usize],
        }))
        .unwrap();
    sim
}

#[test]
fn lab_solver_matches_the_lab_sheet() {
    let mut reference = Reference::new();
    let mut sim = solver();
    let mut worst = 0.0f32;
    for step in 1..=150 {
        reference.update();
        sim.step(DT, &Serial);
        for (i, r) in reference.x.iter().enumerate() {
            worst = worst.max(sim.state().position(i).distance(Vec3::from(*r)));
        }
        // Same arithmetic in the same order: only fused or reordered operations could differ.
        assert!(worst < 1e-4, "step {step}: {worst} m from the reference");
    }
    // Not vacuous: the cloth fell a long way, and its pins did not move.
    let (x, _) = lab_mesh();
    let lowest = reference.x.iter().map(|p| p[1]).fold(f32::MAX, f32::min);
    assert!(lowest < -5.0, "{lowest}");
    assert_eq!(sim.state().position(0), Vec3::from(x[0]));
    assert_eq!(sim.state().position(20), Vec3::from(x[20]));
}

#[test]
fn lab_update_rule_for_one_iteration_by_hand() {
    // A single free vertex between two pinned ones, one iteration, no gravity: check the
    // average (0.2·x + Σx)/(0.2 + n) and the velocity change against numbers worked by hand.
    let pos = [
        Vec3::ZERO,
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
    ];
    let topo =
        Topology::from_triangles(&pos, None, &[0, 1, 2], TopologyOptions::default()).unwrap();
    let mut sim = Simulation::new(
        topo,
        &[1.0; 3],
        SolverParams {
            solver: Solver::LAB,
            substeps: 1,
            iterations: 1,
            gravity: Vec3::ZERO,
            damping: 0.0,
            ..Default::default()
        },
    )
    .unwrap();
    sim.state_mut()
        .set_pins([0u32, 1].map(|v| Pin {
            vertex: v,
            target: pos[v as usize],
        }))
        .unwrap();
    // Rest lengths are √2 for both edges to vertex 2; move it to (1, 2, 0) so each is √5.
    sim.state_mut()
        .reset(&[pos[0], pos[1], Vec3::new(1.0, 2.0, 0.0)]);
    sim.step(0.5, &Serial);
    // Edge (0,2): projection of x2 = ½(x0 + x2 − √2·(x0 − x2)/√5).
    let x2 = Vec3::new(1.0, 2.0, 0.0);
    let s = 2f32.sqrt() / 5f32.sqrt();
    let from0 = 0.5 * (pos[0] + x2 - s * (pos[0] - x2));
    let from1 = 0.5 * (pos[1] + x2 - s * (pos[1] - x2));
    let expect = (0.2 * x2 + from0 + from1) / 2.2;
    let got = sim.state().position(2);
    assert!((got - expect).length() < 1e-6, "{got} vs {expect}");
    // v = (x_new − x)/Δt from rest.
    assert!((sim.state().velocity(2) - (expect - x2) / 0.5).length() < 1e-5);
}
