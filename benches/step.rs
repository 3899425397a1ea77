//! Criterion benchmarks of one 1/60 s solver step on the trade-off scene (1 m², 1 kg, two
//! corner pins), serial and on a task pool with one thread per core; the solvers and tethers
//! at 64²; 64 cloths of 16² against one of 128² (`step_many`); a step of a sleeping cloth;
//! and self-collision's densest case, a closed cube crumpled on the floor.
//!
//! `cargo bench --bench step`

use std::hint::black_box;

use bevy::math::{Quat, Vec3};
use bevy_cloth::solver::{
    BendingSolve, DEFAULT_BENDING_COMPLIANCE, Environment, Features, HangingCloth, ManyItem,
    Serial, Simulation, Sleep, Solver, SolverParams, TetherParams, Topology, TopologyOptions,
    Workers, step_many,
};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

#[path = "../tests/common/mod.rs"]
mod common;

fn scene(n: u32, solver: Solver, substeps: u32, bending_solve: BendingSolve) -> Simulation {
    let mut scene = HangingCloth::new(n);
    scene.params = SolverParams {
        solver,
        substeps,
        iterations: 1,
        bending_solve,
        // Measured awake; the `asleep` group measures sleeping.
        sleep: Sleep::NEVER,
        ..Default::default()
    };
    let mut sim = scene.build().unwrap();
    // Start from a hanging drape, not the flat start.
    for _ in 0..30 {
        sim.step(1.0 / 60.0, &Serial);
    }
    sim
}

fn bench(c: &mut Criterion) {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    // What the plugin steps on (`ClothWorkers`): one helper per core besides this thread.
    let par = Workers::new(threads.saturating_sub(1));
    // The default fabric (B = 1e-4 N·m): projected bending at every size here.
    let xpbd = Solver::Xpbd {
        stretch: 0.0,
        shear: 1e-6,
        bending: DEFAULT_BENDING_COMPLIANCE,
    };
    let mut g = c.benchmark_group("xpbd_10x1");
    for n in [32u32, 64, 128] {
        let mut sim = scene(n, xpbd, 10, BendingSolve::Auto);
        g.bench_with_input(BenchmarkId::new("pool", n), &n, |b, _| {
            b.iter(|| sim.step(black_box(1.0 / 60.0), &par))
        });
        let mut sim = scene(n, xpbd, 10, BendingSolve::Auto);
        g.bench_with_input(BenchmarkId::new("serial", n), &n, |b, _| {
            b.iter(|| sim.step(black_box(1.0 / 60.0), &Serial))
        });
    }
    g.finish();
    let mut g = c.benchmark_group("solver_64_10x1");
    for (name, solver) in [
        ("xpbd", xpbd),
        (
            "xpbd_no_bending",
            Solver::Xpbd {
                stretch: 0.0,
                shear: 1e-6,
                bending: f32::INFINITY,
            },
        ),
        (
            "pbd",
            Solver::Pbd {
                stretch: 1.0,
                shear: 1.0,
                bending: 0.5,
            },
        ),
    ] {
        let mut sim = scene(64, solver, 10, BendingSolve::Auto);
        g.bench_function(name, |b| b.iter(|| sim.step(black_box(1.0 / 60.0), &par)));
    }
    // XPBD with every vertex tethered to both pins: what the tether pass adds.
    let mut sim = scene(64, xpbd, 10, BendingSolve::Auto);
    sim.set_features(Features {
        tethers: Some(TetherParams::default()),
        ..Default::default()
    })
    .unwrap();
    g.bench_function("xpbd_tethers", |b| {
        b.iter(|| sim.step(black_box(1.0 / 60.0), &par))
    });
    g.finish();
    // A stiff sheet (B = 0.1 N·m, saturation far above 0.5): the implicit bending solve
    // against the projection it replaces.
    let stiff = Solver::Xpbd {
        stretch: 0.0,
        shear: 1e-6,
        bending: 10.0,
    };
    let mut g = c.benchmark_group("stiff_bending_10x1");
    for n in [32u32, 64] {
        for (name, solve) in [
            ("projected", BendingSolve::Projected),
            ("implicit", BendingSolve::Implicit),
        ] {
            let mut sim = scene(n, stiff, 10, solve);
            g.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| sim.step(black_box(1.0 / 60.0), &par))
            });
        }
    }
    g.finish();
    // The same vertex count as one cloth or as 64 small ones stepped together.
    let mut g = c.benchmark_group("many_cloths_10x1");
    for (name, n, count) in [("one_128", 128u32, 1usize), ("64_of_16", 16, 64)] {
        let mut sims: Vec<Simulation> = (0..count)
            .map(|_| scene(n, xpbd, 10, BendingSolve::Auto))
            .collect();
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut items = ManyItem::each(&mut sims);
                step_many(
                    &mut items,
                    black_box(1.0 / 60.0),
                    &Environment::default(),
                    &par,
                );
            })
        });
    }
    g.finish();
    // A 64² cloth brought to rest (damping 2/s), then asleep: what a step costs then.
    let mut g = c.benchmark_group("asleep_64");
    let mut sim = scene(64, xpbd, 10, BendingSolve::Auto);
    let params = SolverParams {
        damping: 2.0,
        sleep: Sleep::default(),
        ..*sim.params()
    };
    sim.set_params(params).unwrap();
    for _ in 0..60 * 120 {
        if sim.is_sleeping() {
            break;
        }
        sim.step(1.0 / 60.0, &par);
    }
    assert!(sim.is_sleeping(), "the 64² cloth did not come to rest");
    g.bench_function("asleep", |b| {
        b.iter(|| sim.step(black_box(1.0 / 60.0), &par))
    });
    g.finish();
    // Self-collision's densest case: a closed cube of 24 × 24 quads a face (0.8 m, 3 458
    // vertices, its default thickness) dropped tilted onto the floor, two seconds on: it lies
    // flattened in two layers a thickness apart, every vertex with a list (about 37 triangles
    // and 20 vertices).
    let mut g = c.benchmark_group("self_collision");
    g.sample_size(10);
    let (mut positions, indices) = common::subdivided_cube(24, 0.8, Vec3::ZERO);
    let tilt = Quat::from_rotation_z(0.3) * Quat::from_rotation_x(0.2);
    for p in &mut positions {
        *p = tilt * *p + Vec3::Y * 1.5;
    }
    let topology =
        Topology::from_triangles(&positions, None, &indices, TopologyOptions::default()).unwrap();
    let thickness = topology.default_self_collision_thickness();
    let n = topology.vertex_count();
    let params = SolverParams {
        sleep: Sleep::NEVER,
        ..Default::default()
    };
    let mut sim = Simulation::new(topology, &vec![0.5 / n as f32; n], params).unwrap();
    common::self_colliding(&mut sim, thickness);
    let floor = [common::floor()];
    let env = Environment {
        colliders: &floor,
        ..Environment::default()
    };
    for _ in 0..120 {
        sim.step_in(1.0 / 60.0, &env, &par);
    }
    g.bench_function("crumpled_cube_24", |b| {
        b.iter(|| sim.step_in(black_box(1.0 / 60.0), &env, &par))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
