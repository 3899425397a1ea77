//! Whole-step tests of the solver: physics against analytic answers, determinism, pins.

use super::*;
use glam::Vec4Swizzles;
use glam::{Vec3, Vec4};

/// A triangle hanging from its two pinned top corners: A(−½,0,0), B(½,0,0), C(0,−½,0).
fn hanging_triangle(params: SolverParams) -> Simulation {
    let p = [
        Vec3::new(-0.5, 0.0, 0.0),
        Vec3::new(0.5, 0.0, 0.0),
        Vec3::new(0.0, -0.5, 0.0),
    ];
    let t = Topology::from_triangles(&p, None, &[0, 1, 2], TopologyOptions::default()).unwrap();
    let mut sim = Simulation::new(t, &[1.0, 1.0, 1.0], params).unwrap();
    sim.state_mut()
        .set_pins([0, 1].map(|v| Pin {
            vertex: v,
            target: p[v as usize],
        }))
        .unwrap();
    sim
}

/// Static equilibrium of the hanging triangle's free vertex with springs of compliance α:
/// `2·(L − L0)/α · (−y/L) = m·g`, solved by bisection.
fn triangle_equilibrium(alpha: f64, g: f64) -> f64 {
    let l0 = (0.5f64).hypot(0.5);
    let f = |y: f64| {
        let l = (0.5f64).hypot(y);
        2.0 * (l - l0) / alpha * (-y / l) - g
    };
    let (mut lo, mut hi) = (-10.0, -0.5); // f(lo) > 0, f(hi) < 0
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

fn settle(sim: &mut Simulation, seconds: f32, dt: f32) {
    for _ in 0..(seconds / dt).round() as usize {
        sim.step(dt, &Serial);
    }
}

#[test]
fn xpbd_equilibrium_is_independent_of_iterations_and_time_step() {
    let alpha = 0.01;
    let expect = triangle_equilibrium(alpha as f64, 9.81) as f32;
    for (substeps, iterations, dt) in [
        (1, 1, 1.0 / 60.0),
        (10, 1, 1.0 / 60.0),
        (2, 20, 1.0 / 60.0),
        (5, 3, 1.0 / 240.0),
    ] {
        let mut sim = hanging_triangle(SolverParams {
            solver: Solver::Xpbd {
                stretch: alpha,
                shear: alpha,
                bending: f32::INFINITY,
            },
            substeps,
            iterations,
            damping: 2.0,
            // The equilibrium itself: a cloth creeping towards it by less than sleep's
            // rms speed (about 3 mm/s) may fall asleep a millimetre or two short of it.
            sleep: Sleep::NEVER,
            ..Default::default()
        });
        settle(&mut sim, 20.0, dt);
        let y = sim.state().position(2).y;
        let sag = expect + 0.5;
        assert!(
            (y - expect).abs() < 0.02 * sag.abs(),
            "{substeps}×{iterations} dt {dt}: y = {y}, analytic {expect}"
        );
    }
}

#[test]
fn pbd_stiffness_depends_on_iterations() {
    // The contrast that makes the XPBD test meaningful: same PBD stiffness, different counts.
    let run = |iterations| {
        let mut sim = hanging_triangle(SolverParams {
            solver: Solver::Pbd {
                stretch: 0.01,
                shear: 0.01,
                bending: 0.0,
            },
            substeps: 2,
            iterations,
            damping: 2.0,
            ..Default::default()
        });
        settle(&mut sim, 20.0, 1.0 / 60.0);
        sim.state().position(2).y + 0.5
    };
    let (few, many) = (run(1), run(20));
    assert!(
        few < 1.5 * many,
        "sag {few} with 1 iteration, {many} with 20"
    );
}

#[test]
fn free_fall_follows_gravity() {
    let g = Grid::new(4, 4, 1.0, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let m = t.masses(1.0, MassDistribution::Area);
    let mut sim = Simulation::new(
        t,
        &m,
        SolverParams {
            damping: 0.0,
            substeps: 20,
            air: Aerodynamics::NONE,
            ..Default::default()
        },
    )
    .unwrap();
    settle(&mut sim, 1.0, 1.0 / 60.0);
    // Symplectic Euler over n = 1200 substeps of h: y = −g·h²·n(n+1)/2. PBD recovers the
    // velocity as (x − x_prev)/h, which in f32 loses about ulp(x)/h per substep: allow 0.2 %.
    let (n, h) = (1200.0f32, 1.0f32 / 1200.0);
    let expect = -9.81 * h * h * n * (n + 1.0) / 2.0;
    for i in 0..16 {
        let y = sim.state().position(i).y;
        assert!((y - expect).abs() < 2e-3 * expect.abs(), "{y} vs {expect}");
    }
    assert!(sim.strain().max < 1e-4);
}

#[test]
fn pins_reach_their_targets_and_drag_the_cloth() {
    let g = Grid::new(8, 8, 1.0, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let m = t.masses(1.0, MassDistribution::Area);
    let v = g.index(0, 0);
    let start = g.positions()[v as usize];
    let run = |speed: f32| {
        let mut sim = Simulation::new(t.clone(), &m, SolverParams::default()).unwrap();
        sim.state_mut()
            .set_pins([Pin {
                vertex: v,
                target: start,
            }])
            .unwrap();
        for k in 1..=30 {
            let target = start + Vec3::X * speed / 60.0 * k as f32;
            sim.state_mut().set_pin_targets([target]);
            sim.step(1.0 / 60.0, &Serial);
            assert_eq!(sim.state().position(v as usize), target);
        }
        sim
    };
    let (moving, still) = (run(1.2), run(0.0));
    // The pin moved at 1.2 m/s along x: it has that velocity, and the cloth followed it.
    assert!((moving.state().velocity(v as usize).x - 1.2).abs() < 1e-3);
    let mean_x = |s: &Simulation| (0..64).map(|i| s.state().position(i).x).sum::<f32>() / 64.0;
    assert!(
        mean_x(&moving) > mean_x(&still) + 0.3,
        "{} vs {}",
        mean_x(&moving),
        mean_x(&still)
    );
}

/// Runs items back to front: any dependence between parts would change the result.
struct Reversed;

impl Parallel for Reversed {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        items.iter_mut().rev().for_each(f);
    }
}

#[test]
fn parts_are_independent_so_results_do_not_depend_on_scheduling() {
    let g = Grid::new(40, 40, 1.0, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let m = t.masses(1.0, MassDistribution::Uniform);
    let make = || {
        let mut s = Simulation::new(t.clone(), &m, SolverParams::default()).unwrap();
        s.set_part_count(5);
        s.state_mut()
            .set_pins([0, 39].map(|v| Pin {
                vertex: v,
                target: g.positions()[v as usize],
            }))
            .unwrap();
        s
    };
    let (mut a, mut b) = (make(), make());
    for _ in 0..30 {
        a.step(1.0 / 60.0, &Serial);
        b.step(1.0 / 60.0, &Reversed);
    }
    assert_eq!(a.batches().part_count(), 5);
    assert!(a.batches().boundary_len() > 0);
    let bits = |s: &Simulation| -> Vec<u32> {
        s.state()
            .positions
            .iter()
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
}

#[test]
fn partitioning_changes_little() {
    // Different part counts reorder Gauss–Seidel sweeps; the drape must stay the same shape.
    let g = Grid::new(32, 32, 1.0, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let m = t.masses(1.0, MassDistribution::Uniform);
    let run = |parts| {
        let mut s = Simulation::new(t.clone(), &m, SolverParams::default()).unwrap();
        s.set_part_count(parts);
        s.state_mut()
            .set_pins([0, 31].map(|v| Pin {
                vertex: v,
                target: g.positions()[v as usize],
            }))
            .unwrap();
        settle(&mut s, 1.0, 1.0 / 60.0);
        s.state().positions.clone()
    };
    let (mean, _) = position_distance(&run(1), &run(8));
    assert!(mean < 0.02, "mean distance {mean}");
}

#[test]
fn bending_resists_folding() {
    // A strip pinned along one short edge, held horizontal: stiff bending sags less.
    let g = Grid::new(4, 16, 0.3, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let m = t.masses(0.1, MassDistribution::Area);
    let tip = |bending: f32| {
        let mut s = Simulation::new(
            t.clone(),
            &m,
            SolverParams {
                solver: Solver::Xpbd {
                    stretch: 0.0,
                    shear: 0.0,
                    bending,
                },
                damping: 1.0,
                ..Default::default()
            },
        )
        .unwrap();
        s.state_mut()
            .set_pins((0..4).chain(4..8).map(|v| Pin {
                vertex: v,
                target: g.positions()[v as usize],
            }))
            .unwrap();
        settle(&mut s, 3.0, 1.0 / 60.0);
        s.state().position(g.index(2, 15) as usize).y
    };
    let (stiff, soft, off) = (tip(1e-5), tip(1.0), tip(f32::INFINITY));
    assert!(stiff > soft + 0.1, "stiff {stiff} soft {soft}");
    assert!(soft > off + 0.05, "soft {soft} off {off}");
}

#[test]
fn zero_bending_stiffness_skips_the_pass() {
    let g = Grid::new(6, 6, 1.0, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let params = SolverParams {
        solver: Solver::Pbd {
            stretch: 1.0,
            shear: 1.0,
            bending: 0.0,
        },
        ..Default::default()
    };
    let b = ConstraintBatches::new(&t, params.solver, 1);
    assert!(!b.bending);
    assert!(
        !Solver::Xpbd {
            stretch: 0.0,
            shear: 0.0,
            bending: f32::INFINITY
        }
        .bending_enabled()
    );
}

#[test]
fn coincident_and_degenerate_geometry_stays_finite() {
    // Every vertex at the same point, and a sliver: the solver must not produce NaN.
    let g = Grid::new(5, 5, 1.0, 1.0);
    let uvs = g.uvs();
    let idx = g.indices();
    for squash in [0.0f32, 1e-7] {
        let pos: Vec<Vec3> = g
            .positions()
            .iter()
            .map(|p| *p * Vec3::new(squash, 1.0, 1.0))
            .collect();
        let t = match Topology::from_triangles(&pos, Some(&uvs), &idx, TopologyOptions::default()) {
            // All on one line: nothing to simulate, refused with a typed error.
            Err(e) if squash == 0.0 => {
                assert_eq!(e, TopologyError::ZeroArea);
                continue;
            }
            t => t.unwrap(),
        };
        for solver in [
            Solver::LAB,
            Solver::default(),
            Solver::Pbd {
                stretch: 1.0,
                shear: 1.0,
                bending: 1.0,
            },
        ] {
            let mut s = Simulation::new(
                t.clone(),
                &t.masses(1.0, MassDistribution::Area),
                SolverParams {
                    solver,
                    ..Default::default()
                },
            )
            .unwrap();
            s.state_mut().reset(&vec![Vec3::ONE; 25]);
            settle(&mut s, 0.5, 1.0 / 60.0);
            let shading = MeshShading::of_particles(s.topology(), &s.state().positions);
            assert_eq!(
                s.state().non_finite_count(),
                0,
                "{solver:?} squash {squash}"
            );
            assert!(shading.normals().iter().all(|n| n.is_finite()));
            assert!(shading.tangents().iter().all(|t| t.is_finite()));
        }
    }
}

#[test]
fn simd_and_scalar_projection_agree() {
    // Project the same perturbed grid through 4-wide batches and one constraint at a time.
    let g = Grid::new(24, 24, 1.0, 1.0);
    let t = g.topology(TopologyOptions::default()).unwrap();
    let params = SolverParams::default();
    let mut pos: Vec<Vec4> = g
        .positions()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let k = i as f32;
            (*p + Vec3::new((k * 0.37).sin(), (k * 0.11).cos(), (k * 0.73).sin()) * 0.01)
                .extend(1.0)
        })
        .collect();
    let mut simd = ConstraintBatches::new(&t, params.solver, 1);
    let mut scalar = simd.clone();
    let mode = simd.mode(1.0 / 600.0);
    let mut pos2 = pos.clone();
    simd.parts[0].project(&mut pos, mode, true, false);
    scalar.parts[0].project_scalar(&mut pos2, mode, true);
    let mut worst = 0.0f32;
    for (a, b) in pos.iter().zip(&pos2) {
        worst = worst.max((a.xyz() - b.xyz()).length());
    }
    assert!(worst < 1e-5, "{worst}");
    // And they did something.
    let (moved, _) = position_distance(
        &pos,
        &g.positions()
            .iter()
            .map(|p| p.extend(1.0))
            .collect::<Vec<_>>(),
    );
    assert!(moved > 1e-3);
}

/// Runs items on scoped OS threads, several at once.
struct Threads;

impl Parallel for Threads {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        let f = &f;
        std::thread::scope(|s| {
            for chunk in items.chunks_mut(3) {
                s.spawn(move || chunk.iter_mut().for_each(f));
            }
        });
    }

    fn threads(&self) -> usize {
        4
    }
}

#[test]
fn step_many_gives_each_cloth_what_stepping_it_alone_gives() {
    // Small cloths and one big enough to be cut into parts, pinned differently.
    let make = |n: u32, pinned: u32| {
        let grid = Grid::new(n, n, 1.0, 1.0);
        let topology = grid.topology(TopologyOptions::default()).unwrap();
        let masses = topology.masses(1.0, MassDistribution::Uniform);
        let mut sim = Simulation::new(topology, &masses, SolverParams::default()).unwrap();
        let rest = grid.positions();
        sim.state_mut()
            .set_pins((0..pinned).map(|i| {
                let v = grid.index(i * (n - 1) / pinned.max(2).saturating_sub(1).max(1), 0);
                Pin {
                    vertex: v,
                    target: rest[v as usize],
                }
            }))
            .unwrap();
        sim
    };
    let sizes = [(70, 2), (8, 1), (12, 2), (16, 3), (9, 2), (20, 2), (8, 2)];
    let mut together: Vec<Simulation> = sizes.iter().map(|&(n, p)| make(n, p)).collect();
    let mut alone = together.clone();
    assert!(together[0].batches().part_count() > 1);
    let sphere = [Collider::fixed(
        Shape::Sphere { radius: 0.3 },
        Pose::at(Vec3::new(0.0, -0.6, 0.0)),
        0.01,
        0.3,
    )];
    let env = Environment {
        colliders: &sphere,
        ..Default::default()
    };
    for _ in 0..20 {
        let mut items = ManyItem::each(&mut together);
        step_many(&mut items, 1.0 / 60.0, &env, &Threads);
        for sim in &mut alone {
            sim.step_in(1.0 / 60.0, &env, &Serial);
        }
    }
    for (i, (a, b)) in together.iter().zip(&alone).enumerate() {
        assert_eq!(a.state().positions, b.state().positions, "cloth {i}");
        // And they moved.
        let moved = a
            .state()
            .positions
            .iter()
            .zip(a.topology().rest_positions())
            .any(|(p, r)| p.xyz().distance(*r) > 0.01);
        assert!(moved, "cloth {i}");
    }
}

#[test]
fn motion_targets_hold_the_cloth_and_refuse_bad_input() {
    use crate::solver::{HangingCloth, StateError};
    let mut sim = HangingCloth::new(8).build().expect("valid");
    let n = sim.state().len();
    let rest: Vec<Vec4> = sim.state().positions.clone();
    // Every vertex within 1 cm of its rest position, the targets rising 1 cm a step.
    for k in 0..30 {
        let targets: Vec<Vec4> = rest
            .iter()
            .map(|p| (p.truncate() + Vec3::Y * 0.01 * (k + 1) as f32).extend(0.01))
            .collect();
        sim.set_motion_targets(&targets, &[], 0.0, false)
            .expect("valid targets");
        sim.step(1.0 / 60.0, &Serial);
        // Pinned vertices follow their pins, not the targets.
        for (p, t) in sim
            .state()
            .positions
            .iter()
            .zip(&targets)
            .filter(|(p, _)| p.w > 0.0)
        {
            let d = p.truncate().distance(t.truncate());
            assert!(d <= 0.01 + 1e-5, "step {k}: {d} m from the target");
        }
    }
    assert!(sim.has_motion_targets());
    // Bad input is refused and the targets stay.
    let before = sim.motion_targets().map(|m| m.end.to_vec());
    assert_eq!(
        sim.set_motion_targets(&rest[..n - 1], &[], 0.0, false),
        Err(StateError::MotionLengthMismatch {
            targets: n - 1,
            vertex_count: n
        })
    );
    assert_eq!(
        sim.set_motion_targets(&rest, &rest[..3], 0.5, false),
        Err(StateError::MotionLengthMismatch {
            targets: 3,
            vertex_count: n
        })
    );
    let mut nan = rest.clone();
    nan[5].y = f32::NAN;
    assert_eq!(
        sim.set_motion_targets(&nan, &[], 0.0, false),
        Err(StateError::NonFiniteMotionTarget { vertex: 5 })
    );
    assert_eq!(
        sim.set_motion_targets(&rest, &rest, f32::INFINITY, false),
        Err(StateError::NonFiniteMotionTarget { vertex: 0 })
    );
    assert_eq!(sim.motion_targets().map(|m| m.end.to_vec()), before);
    // Let go: the cloth falls again, and a held cloth never fell asleep.
    sim.clear_motion_targets();
    let y = sim.state().positions[n - 1].y;
    for _ in 0..60 {
        sim.step(1.0 / 60.0, &Serial);
    }
    let now = sim.state().positions[n - 1].y;
    assert!(now < y - 0.1, "{y} → {now}");
}

/// How uneven a mesh's edges are: √2 for a grid of squares (sides and diagonals), 1 for a
/// triangle of equal sides, and over [`EVEN_EDGE_SPREAD`] for a grid squeezed towards its
/// middle (the mesh self-collision was measured to cross on).
#[test]
fn the_edge_spread_tells_even_meshes_from_uneven_ones() {
    let g = Grid::new(30, 30, 1.0, 1.0);
    let even = Topology::from_triangles(
        &g.positions(),
        None,
        &g.indices(),
        TopologyOptions::default(),
    )
    .unwrap();
    assert!(
        (even.rest_edge_spread() - 2f32.sqrt()).abs() < 1e-4,
        "{}",
        even.rest_edge_spread()
    );
    let squeezed: Vec<Vec3> = g
        .positions()
        .iter()
        .map(|p| {
            let t = 2.0 * p.x;
            Vec3::new(0.5 * (0.5 * t + 0.5 * t * t * t), p.y, p.z)
        })
        .collect();
    let uneven =
        Topology::from_triangles(&squeezed, None, &g.indices(), TopologyOptions::default())
            .unwrap();
    assert!(
        uneven.rest_edge_spread() > EVEN_EDGE_SPREAD,
        "{}",
        uneven.rest_edge_spread()
    );
    let h = 3f32.sqrt() / 2.0;
    let equal = Topology::from_triangles(
        &[Vec3::ZERO, Vec3::X, Vec3::new(0.5, 0.0, h)],
        None,
        &[0, 1, 2],
        TopologyOptions::default(),
    )
    .unwrap();
    assert!((equal.rest_edge_spread() - 1.0).abs() < 1e-5);
}

/// A self-collision thickness up to [`MAX_SELF_COLLISION_EDGES`] mean rest edges is taken; a
/// thicker one is refused with a reason that names the ratio, and the features stay.
#[test]
fn a_self_collision_thicker_than_an_edge_is_refused() {
    let mut sim = HangingCloth::on(Grid::new(11, 11, 1.0, 1.0))
        .build()
        .unwrap();
    let edges = sim.topology().edges();
    let mean = edges.iter().map(|e| f64::from(e.rest)).sum::<f64>() as f32 / edges.len() as f32;
    let with = |thickness: f32| Features {
        self_collision: Some(SelfCollision {
            thickness,
            friction: 0.2,
        }),
        ..Features::default()
    };
    let thick = 0.99 * MAX_SELF_COLLISION_EDGES * mean;
    sim.set_features(with(thick)).unwrap();
    let err = sim
        .set_features(with(1.01 * MAX_SELF_COLLISION_EDGES * mean))
        .unwrap_err();
    assert_eq!(err.name, "self_collision.thickness");
    assert!(err.reason.contains("1.0 times"), "{err}");
    assert_eq!(sim.features().self_collision.unwrap().thickness, thick);
}

/// [`Threads`], remembering the most items one call was given.
#[derive(Default)]
struct Recording {
    most: std::sync::atomic::AtomicUsize,
}

impl Parallel for Recording {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        self.most
            .fetch_max(items.len(), std::sync::atomic::Ordering::Relaxed);
        Threads.for_each_mut(items, f);
    }

    fn threads(&self) -> usize {
        Threads.threads()
    }
}

/// A cloth too small to be cut into parts, with self-collision and far more work than the
/// two small cloths beside it, is stepped first by `step_many` and hands its self-collision
/// to the threads in chunks of vertices (it was stepped with `Serial` beside the others: one
/// core busy); every cloth comes out as stepped alone on one thread, bit for bit.
#[test]
fn a_lone_self_colliding_cloth_spreads_its_self_collision_over_the_threads() {
    let mut scene = HangingCloth::on(Grid::new(24, 24, 1.0, 1.0));
    scene.pins.truncate(1);
    scene.features = Features {
        self_collision: Some(SelfCollision {
            thickness: 0.03,
            friction: 0.3,
        }),
        ..Features::default()
    };
    let small = |n| HangingCloth::on(Grid::new(n, n, 0.3, 0.3)).build().unwrap();
    let mut together = [scene.build().unwrap(), small(6), small(8)];
    assert_eq!(together[0].batches().part_count(), 1);
    let mut alone = together.clone();
    // A floor under the pinned corner's height: the cloth swings down and piles on it.
    let floor = [Collider::fixed(
        Shape::Plane,
        Pose::at(Vec3::new(0.0, -0.6, 0.0)),
        0.01,
        0.5,
    )];
    let env = Environment {
        colliders: &floor,
        ..Default::default()
    };
    let par = Recording::default();
    for _ in 0..90 {
        step_many(&mut ManyItem::each(&mut together), 1.0 / 60.0, &env, &par);
        for sim in &mut alone {
            sim.step_in(1.0 / 60.0, &env, &Serial);
        }
    }
    for (a, b) in together.iter().zip(&alone) {
        assert_eq!(a.state().positions, b.state().positions);
    }
    // Stepped beside the two others, the calls had at most three items (the three cloths).
    let most = par.most.load(std::sync::atomic::Ordering::Relaxed);
    assert!(most >= 4, "at most {most} items a call");
    // It piled up: some of it lies on the floor, folded over itself.
    let low = alone[0]
        .state()
        .positions
        .iter()
        .filter(|p| p.y < -0.5)
        .count();
    assert!(low > 100, "{low} vertices near the floor");
}

/// [`Serial`], counting its calls (the parallel regions a step forks and joins).
#[derive(Default)]
struct Counting {
    calls: std::sync::atomic::AtomicUsize,
}

impl Parallel for Counting {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        self.calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Serial.for_each_mut(items, f);
    }
}

/// Colliders, tethers and a skin's motion constraints run at the start of the next region
/// over the parts: a step with all three forks and joins as often as the cloth alone (one
/// region more a substep before they were merged), and the cloth does meet them.
#[test]
fn colliders_tethers_and_a_skin_add_no_parallel_region() {
    let mut scene = HangingCloth::new(40);
    scene.params.sleep = Sleep::NEVER;
    let alone = scene.build().unwrap();
    scene.features.tethers = Some(TetherParams::default());
    let mut with = scene.build().unwrap();
    let ball = [Collider::fixed(
        Shape::Sphere { radius: 0.1 },
        Pose::at(Vec3::new(0.0, 0.0, 0.0)),
        0.01,
        0.4,
    )];
    let targets: Vec<Vec4> = with
        .state()
        .positions
        .iter()
        .map(|p| p.xyz().extend(0.2))
        .collect();
    with.set_motion_targets(&targets, &[], 0.0, true).unwrap();
    let mut alone = alone;
    for sim in [&mut alone, &mut with] {
        sim.set_part_count(3);
        assert_eq!(sim.batches().part_count(), 3);
    }
    let env = Environment {
        colliders: &ball,
        ..Default::default()
    };
    let count = |sim: &mut Simulation, env: &Environment<'_>| {
        let par = Counting::default();
        for _ in 0..3 {
            sim.step_in(1.0 / 60.0, env, &par);
        }
        par.calls.load(std::sync::atomic::Ordering::Relaxed)
    };
    let plain = count(&mut alone, &Environment::default());
    let busy = count(&mut with, &env);
    assert_eq!(busy, plain, "regions with colliders, tethers and a skin");
    // The ball was in the way: it took momentum from the cloth.
    assert!(
        with.impulses()[0].linear.length() > 0.0,
        "{:?}",
        with.impulses()
    );
}

/// `topology`'s triangles as an index list (what a mesh gives [`Topology::from_triangles`]).
fn triangle_indices(topology: &Topology) -> Vec<u32> {
    topology.triangles().iter().flatten().copied().collect()
}

/// A cloth's rest shape scaled evenly (an entity grown in by its scale) keeps its tethers,
/// scaled: within rounding the limits a search of the new shape finds, and the steps after
/// keep them. Scaled unevenly, or given another mesh's rest shape, they are
/// searched for again on the next step.
#[test]
fn tethers_follow_an_even_scale_of_the_rest_shape_and_are_searched_again_otherwise() {
    let mut scene = HangingCloth::new(12);
    scene.features.tethers = Some(TetherParams::default());
    let mut sim = scene.build().unwrap();
    let dt = 1.0 / 60.0;
    sim.step(dt, &Serial);
    let pins: Vec<u32> = sim.state().pins().iter().map(|p| p.vertex).collect();
    let params = TetherParams::default();
    let indices = triangle_indices(sim.topology());
    let rest = sim.topology().rest_positions().to_vec();
    let options = sim.topology().options();
    let shaped = |f: &dyn Fn(Vec3) -> Vec3| {
        let moved: Vec<Vec3> = rest.iter().map(|p| f(*p)).collect();
        Topology::from_triangles(&moved, None, &indices, options).unwrap()
    };
    let first = sim.current_tethers().unwrap().clone();
    // Grown threefold about a point: kept, scaled.
    let grown = shaped(&|p| (p - Vec3::Y) * 3.0 + Vec3::Y);
    let searched = Tethers::build(&grown, &pins, params);
    sim.set_rest_shape(grown).unwrap();
    let kept = sim
        .current_tethers()
        .expect("kept through an even scale")
        .clone();
    assert_eq!(kept.len(), searched.len());
    for ((v, p, a), (w, q, b), (_, _, was)) in kept
        .entries()
        .zip(searched.entries())
        .zip(first.entries())
        .map(|((x, y), z)| (x, y, z))
    {
        assert_eq!((v, p), (w, q));
        assert!(
            (a - b).abs() <= 64.0 * f32::EPSILON * (b + 4.0),
            "{v}: {a} vs {b}"
        );
        assert!(
            (a - 3.0 * was).abs() <= 64.0 * f32::EPSILON * a,
            "{v}: {a} vs 3 × {was}"
        );
    }
    sim.step(dt, &Serial);
    assert_eq!(sim.current_tethers(), Some(&kept), "kept by the step");
    // Widened along x only: searched for again, on the next step.
    let wide = shaped(&|p| p * Vec3::new(1.5, 1.0, 1.0));
    let searched = Tethers::build(&wide, &pins, params);
    sim.set_rest_shape(wide).unwrap();
    assert!(sim.current_tethers().is_none());
    sim.step(dt, &Serial);
    assert_eq!(sim.current_tethers(), Some(&searched));
    // The same positions, other triangles (each turned over): another mesh, searched again.
    let flipped: Vec<u32> = indices.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
    let other = Topology::from_triangles(&rest, None, &flipped, options).unwrap();
    sim.set_rest_shape(other).unwrap();
    assert!(sim.current_tethers().is_none());
}

/// A new rest shape gives the cloth the constraints built from it: measured again where it is
/// the same mesh (other rest lengths, angles and weights in the same partition), built anew
/// for another mesh; the steps after stay finite.
#[test]
fn a_new_rest_shape_gives_the_constraints_built_from_it() {
    let mut sim = HangingCloth::new(12).build().unwrap();
    let dt = 1.0 / 60.0;
    sim.step(dt, &Serial);
    let solver = sim.params().solver;
    let parts = sim.batches().part_count();
    let built = |t: &Topology| ConstraintBatches::new(t, solver, parts);
    let rest = sim.topology().rest_positions().to_vec();
    let indices = triangle_indices(sim.topology());
    // The same mesh widened and curved: measured again.
    let shaped: Vec<Vec3> = rest
        .iter()
        .map(|p| Vec3::new(1.5 * p.x, p.y, p.z + 0.1 * (4.0 * p.x).sin()))
        .collect();
    let wide = sim.topology().reshaped(&shaped).unwrap();
    let was = sim.batches().clone();
    sim.set_rest_shape(wide.clone()).unwrap();
    assert_ne!(sim.batches(), &was);
    assert_eq!(sim.batches(), &built(&wide));
    sim.step(dt, &Serial);
    // Another mesh (each triangle turned over): built anew.
    let flipped: Vec<u32> = indices.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
    let other = Topology::from_triangles(&shaped, None, &flipped, wide.options()).unwrap();
    sim.set_rest_shape(other.clone()).unwrap();
    assert_eq!(sim.batches(), &built(&other));
    for _ in 0..30 {
        sim.step(dt, &Serial);
    }
    assert!(sim.state().positions.iter().all(|p| p.is_finite()));
}
