//! The GPU kernels (`src/gpu/step.wgsl`) against their CPU twin, `solver::step`, on the same
//! input, on a real wgpu adapter (llvmpipe in CI; `CLOTH_REQUIRE_GPU=1` fails instead of
//! skipping).
//!
//! Tolerances: both sides run the same operations in the same constraint order, so they
//! differ only by f32 rounding (the GPU may fuse multiply–adds and computes `sqrt` and
//! division to within a few ulp). One step of a cloth a metre wide moves every vertex by
//! at most a few ulp of its coordinate (~1e-7 m); Gauss–Seidel then spreads and amplifies
//! those differences from step to step, the more the stiffer the constraints and the more
//! contacts there are. The bounds below are a few times what was measured on llvmpipe and
//! far below anything visible (a millimetre over a metre-wide cloth after a second of
//! motion); a wrong kernel (a sign, an index, a missed colour) misses them by orders of
//! magnitude.

mod common;

use bevy::math::{Quat, Vec3, Vec4};
use bevy_cloth::gpu::{GpuCloth, GpuKernels, GpuStepInput};
use bevy_cloth::prelude::Grid;
use std::sync::Arc;

use bevy_cloth::solver::{
    BendingModel, BendingSolve, Collider, ContactImpulse, Features, Pin, Pose, SdfGrid,
    SelfCollision, Serial, Shape, Simulation, Solver, SolverParams, StepInput, StepScratch,
    TetherParams, Tethers, TopologyOptions, step,
};

const DT: f32 = 1.0 / 60.0;

thread_local! {
    /// Worst relative difference of a collider's linear impulse seen by this test's thread,
    /// and the largest impulse (N·s) the CPU reported.
    static IMPULSE_ERR: core::cell::Cell<f32> = const { core::cell::Cell::new(0.0) };
    static IMPULSE_MAX: core::cell::Cell<f32> = const { core::cell::Cell::new(0.0) };
}

/// A `n`×`n` grid one metre wide, `place`d, 1 g per vertex.
fn sim(n: u32, params: SolverParams, place: impl Fn(Vec3) -> Vec3) -> Simulation {
    sim_with(n, params, TopologyOptions::default(), place)
}

fn sim_with(
    n: u32,
    params: SolverParams,
    options: TopologyOptions,
    place: impl Fn(Vec3) -> Vec3,
) -> Simulation {
    let g = Grid::new(n, n, 1.0, 1.0);
    let positions: Vec<Vec3> = g.positions().into_iter().map(place).collect();
    let t = bevy_cloth::solver::Topology::from_triangles(
        &positions,
        Some(&g.uvs()),
        &g.indices(),
        options,
    )
    .unwrap();
    let masses = vec![0.001; positions.len()];
    Simulation::new(t, &masses, params).unwrap()
}

/// Runs `frames` frames of `steps_per_frame` steps on the CPU (`solver::step`, serial) and on
/// the GPU from the same start, with pins following `targets(step)` and the colliders and air
/// of `world(step)`. Returns the largest position difference after each frame (metres).
fn compare(
    gpu: &(wgpu::Device, wgpu::Queue, GpuKernels),
    sim: &mut Simulation,
    frames: usize,
    steps_per_frame: usize,
    targets: impl Fn(usize) -> Vec<Vec3>,
    world: impl Fn(usize) -> (Vec<Collider>, Vec<Vec4>),
) -> Vec<f32> {
    compare_with_teleport(gpu, sim, frames, steps_per_frame, targets, world, None)
}

/// [`compare`], with the whole cloth teleported by `teleport.1` at the start of step
/// `teleport.0` (the plugin's teleport rule: translate, then snap the pins to their targets).
fn compare_with_teleport(
    gpu: &(wgpu::Device, wgpu::Queue, GpuKernels),
    sim: &mut Simulation,
    frames: usize,
    steps_per_frame: usize,
    targets: impl Fn(usize) -> Vec<Vec3>,
    world: impl Fn(usize) -> (Vec<Collider>, Vec<Vec4>),
    teleport: Option<(usize, Vec3)>,
) -> Vec<f32> {
    let (device, queue, kernels) = gpu;
    let mut cloth = GpuCloth::new(device, kernels, sim).expect("supported");
    cloth.upload_state(queue, sim);
    let mut state = sim.state().clone();
    let topology = sim.topology().clone();
    let mut batches = sim.batches().clone();
    let params = *sim.params();
    let mut scratch = StepScratch::default();
    // The CPU's tethers as `Simulation` builds them: from the pinned vertices.
    let tethers = sim.features().tethers.map(|p| {
        let pins: Vec<u32> = state.pins().iter().map(|p| p.vertex).collect();
        Tethers::build(&topology, &pins, p)
    });
    let mut errors = Vec::new();
    let start = state.positions.clone();
    let mut k = 0;
    for _ in 0..frames {
        let mut pin_targets = Vec::new();
        let mut jumps = Vec::new();
        let (colliders, air) = world(k);
        let mut cpu_impulses = vec![ContactImpulse::default(); colliders.len()];
        for _ in 0..steps_per_frame {
            let t = targets(k);
            let jump = teleport.filter(|j| j.0 == k).map(|j| j.1);
            if let Some(offset) = jump {
                state.translate(offset);
            }
            state.set_pin_targets(t.iter().copied());
            if jump.is_some() {
                state.snap_pins();
            }
            jumps.push(jump.unwrap_or(Vec3::ZERO));
            step(
                &mut state,
                &topology,
                &mut batches,
                &params,
                DT,
                StepInput {
                    colliders: &colliders,
                    air_velocities: &air,
                    tethers: tethers.as_ref(),
                    // The GPU's form of self-collision (its CPU twin).
                    self_collision: sim.features().self_collision,
                    parallel_self_collision: true,
                },
                &mut scratch,
                &Serial,
            );
            for (sum, i) in cpu_impulses.iter_mut().zip(scratch.impulses()) {
                sum.linear += i.linear;
                sum.angular += i.angular;
            }
            pin_targets.push(t);
            k += 1;
        }
        cloth.prepare(
            device,
            queue,
            kernels,
            sim,
            DT,
            &pin_targets,
            GpuStepInput {
                colliders: &colliders,
                air_velocities: &air,
                teleports: &jumps,
            },
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        cloth.record(&mut encoder, kernels);
        queue.submit([encoder.finish()]);
        let (pos, vel) = cloth.read_state(device, queue);
        assert!(
            pos.iter().chain(&vel).all(|v| v.is_finite()),
            "GPU state not finite"
        );
        assert!(
            !cloth.read_failed(device, queue),
            "the guard flagged a finite state"
        );
        // The impulses the cloth gave the colliders over the frame: the GPU sums them per
        // workgroup (a tree) and the CPU per part, in order; both from positions that differ
        // by the bound below.
        let gpu_impulses = cloth.read_impulses(device, queue);
        assert_eq!(gpu_impulses.len(), colliders.len());
        for (c, (g, w)) in colliders.iter().zip(gpu_impulses.iter().zip(&cpu_impulses)) {
            // Relative to the impulse, or to 0.1 mN·s for tiny ones. Measured on llvmpipe:
            // 3e-6; the bound leaves room for other summation orders and fused arithmetic.
            let scale = w.linear.length().max(1e-4);
            let err = (g.linear - w.linear).length() / scale;
            IMPULSE_ERR.with(|e| e.set(e.get().max(err)));
            IMPULSE_MAX.with(|e| e.set(e.get().max(w.linear.length())));
            assert!(
                err < 1e-3,
                "frame {k}: impulse on {:?}: GPU {:?}, CPU {:?}",
                c.shape,
                g.linear,
                w.linear
            );
            let ang_scale = w.angular.length().max(1e-4);
            assert!(
                (g.angular - w.angular).length() / ang_scale < 1e-3,
                "frame {k}: angular impulse: GPU {:?}, CPU {:?}",
                g.angular,
                w.angular
            );
        }
        let mut worst = 0.0f32;
        for (g, c) in pos.iter().zip(&state.positions) {
            assert_eq!(g.w, c.w, "inverse masses differ");
            worst = worst.max((g.truncate() - c.truncate()).length());
        }
        errors.push(worst);
    }
    // The comparison means something only if the cloth moved.
    let moved = start
        .iter()
        .zip(&state.positions)
        .map(|(a, b)| (a.truncate() - b.truncate()).length())
        .fold(0.0, f32::max);
    assert!(moved > 0.05, "the cloth hardly moved ({moved} m)");
    errors
}

/// Checks a run's worst position difference per frame: the first frame's (rounding only)
/// against `first`, if given, and every frame's against `worst`.
fn within(errors: &[f32], what: &str, first: Option<f32>, worst: f32) {
    eprintln!("{what}, worst per frame: {errors:?}");
    if let Some(first) = first {
        assert!(errors[0] < first, "{what}, first frame: {}", errors[0]);
    }
    let most = errors.iter().copied().fold(0.0, f32::max);
    assert!(most < worst, "{what}, worst {most}");
}

/// Pin targets that slide from `start` by `per_step` every step.
fn sliding(start: Vec<Vec3>, per_step: Vec3) -> impl Fn(usize) -> Vec<Vec3> {
    move |k| start.iter().map(|p| *p + per_step * k as f32).collect()
}

fn gpu(test: &str) -> Option<(wgpu::Device, wgpu::Queue, GpuKernels)> {
    let (adapter, device, queue) = common::gpu_or_skip(test)?;
    eprintln!("adapter: {:?}", adapter.get_info().name);
    GpuKernels::check_limits(&device.limits()).expect("llvmpipe has the limits");
    let kernels = GpuKernels::new(&device);
    Some((device, queue, kernels))
}

fn corners(sim: &mut Simulation, n: u32) -> Vec<Vec3> {
    let a = 0;
    let b = n - 1;
    let s = sim.state_mut();
    let pins: Vec<Pin> = [a, b]
        .iter()
        .map(|&v| Pin {
            vertex: v,
            target: s.position(v as usize),
        })
        .collect();
    s.set_pins(pins).unwrap();
    s.pins().iter().map(|p| p.target).collect()
}

/// Vertical cloth, two pinned corners that move, XPBD 10×1 with isometric bending, air with
/// a wind that varies over the cloth. 80² vertices: three parts, so the merged part colours
/// and both seam parities (the constraints between neighbouring parts) run too.
#[test]
fn hanging_cloth_in_wind_matches_the_cpu() {
    let Some(g) = gpu("hanging_cloth_in_wind_matches_the_cpu") else {
        return;
    };
    let n = 80;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    assert_eq!(s.batches().part_count(), 3);
    let start = corners(&mut s, n);
    let len = s.state().len();
    let errors = compare(
        &g,
        &mut s,
        30,
        1,
        |k| {
            let shift = Vec3::new(0.3 * (k as f32 * 0.2).sin(), 0.0, 0.01 * k as f32);
            start.iter().map(|p| *p + shift).collect()
        },
        |k| {
            let air = (0..len)
                .map(|i| Vec4::new(3.0 + (i % 7) as f32 * 0.2, 0.0, 1.0 + 0.1 * k as f32, 0.0))
                .collect();
            (Vec::new(), air)
        },
    );
    within(&errors, "hanging cloth", Some(2e-5), 2e-3);
}

/// A cloth falling onto a moving sphere, a rotated box, a capsule and the ground, PBD with
/// two iterations, friction on every collider.
#[test]
fn cloth_on_colliders_matches_the_cpu() {
    let Some(g) = gpu("cloth_on_colliders_matches_the_cpu") else {
        return;
    };
    let params = SolverParams {
        solver: Solver::Pbd {
            stretch: 1.0,
            shear: 0.5,
            bending: 0.1,
        },
        substeps: 6,
        iterations: 2,
        ..Default::default()
    };
    let n = 40;
    let mut s = sim(n, params, |p| p * 1.5 + Vec3::new(0.0, 0.45, 0.0));
    let shapes = |k: usize| {
        let x = 0.2 * (k as f32 * 0.1).sin();
        vec![
            Collider {
                shape: Shape::Sphere { radius: 0.25 },
                start: Pose::at(Vec3::new(x, 0.1, 0.0)),
                end: Pose::at(Vec3::new(x + 0.02, 0.1, 0.0)),
                thickness: 0.01,
                friction: 0.5,
            },
            Collider::fixed(
                Shape::Cuboid {
                    half_extents: Vec3::new(0.15, 0.2, 0.1),
                },
                Pose {
                    translation: Vec3::new(-0.45, 0.0, 0.3),
                    rotation: Quat::from_rotation_y(0.6) * Quat::from_rotation_x(0.3),
                    scale: 1.2,
                },
                0.005,
                0.3,
            ),
            Collider::fixed(
                Shape::Capsule {
                    half_length: 0.3,
                    radius: 0.08,
                },
                Pose {
                    translation: Vec3::new(0.45, 0.1, -0.3),
                    rotation: Quat::from_rotation_z(1.2),
                    scale: 1.0,
                },
                0.01,
                1.0,
            ),
            Collider::fixed(Shape::Plane, Pose::at(Vec3::new(0.0, -0.2, 0.0)), 0.0, 0.8),
        ]
    };
    let errors = compare(
        &g,
        &mut s,
        40,
        1,
        |_| Vec::new(),
        |k| (shapes(k), Vec::new()),
    );
    eprintln!(
        "colliders, worst relative impulse difference: {}",
        IMPULSE_ERR.with(|e| e.get())
    );
    let most = IMPULSE_MAX.with(|e| e.get());
    assert!(
        most > 1e-3,
        "the colliders were hardly touched ({most} N·s)"
    );
    within(&errors, "colliders", Some(2e-5), 5e-3);
}

/// XPBD with three iterations (multipliers carried across iterations), three steps recorded
/// per frame as a frame with three fixed steps does.
#[test]
fn several_iterations_and_steps_per_frame_match_the_cpu() {
    let Some(g) = gpu("several_iterations_and_steps_per_frame_match_the_cpu") else {
        return;
    };
    let params = SolverParams {
        substeps: 4,
        iterations: 3,
        ..Default::default()
    };
    let n = 24;
    let mut s = sim(n, params, |p| Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.2 * p.x));
    let start = corners(&mut s, n);
    let errors = compare(&g, &mut s, 10, 3, sliding(start, Vec3::X * 0.01), |_| {
        (Vec::new(), Vec::new())
    });
    within(&errors, "iterations", Some(5e-5), 2e-3);
}

/// What the GPU can run (every feature, every solver) and what it refuses with a reason
/// (`BendingSolve::Implicit`), before any buffer is made.
#[test]
fn unsupported_settings_are_refused_with_a_reason() {
    let mut s = sim(8, SolverParams::default(), |p| p);
    assert!(GpuCloth::supports(&s, DT).is_ok());
    let mut f = *s.features();
    f.self_collision = Some(SelfCollision {
        thickness: 0.1,
        friction: 0.2,
    });
    s.set_features(f).unwrap();
    assert!(GpuCloth::supports(&s, DT).is_ok(), "self-collision runs");
    f.tear_threshold = Some(1.5);
    f.tethers = Some(TetherParams::default());
    s.set_features(f).unwrap();
    assert!(GpuCloth::supports(&s, DT).is_ok(), "every feature runs");
    let lab = sim(
        8,
        SolverParams {
            solver: Solver::Lab {
                velocity_keep: 0.99,
            },
            ..Default::default()
        },
        |p| p,
    );
    assert!(GpuCloth::supports(&lab, DT).is_ok(), "the lab solver runs");
    // Isometric bending this stiff: the CPU solves it implicitly where `Auto` lets it (the
    // GPU projects it instead), and the GPU refuses a cloth that asks for the implicit solve.
    let stiff = |solve| {
        sim(
            16,
            SolverParams {
                solver: Solver::Xpbd {
                    stretch: 0.0,
                    shear: 1e-6,
                    bending: 1e-3,
                },
                bending_solve: solve,
                ..Default::default()
            },
            |p| p,
        )
    };
    let auto = stiff(BendingSolve::Auto);
    assert!(auto.wants_implicit_bending(DT));
    assert!(GpuCloth::supports(&auto, DT).is_ok());
    let e = GpuCloth::supports(&stiff(BendingSolve::Implicit), DT).unwrap_err();
    assert!(e.0.contains("implicit"), "{e}");
}

/// Dihedral bending (the signed-angle hinges, `atan2` on both sides) with tethers to two
/// moving pinned corners, XPBD 8×2: multipliers of dihedral hinges carried over iterations,
/// and every free vertex pulled back within reach of its pins after the projections.
#[test]
fn dihedral_bending_and_tethers_match_the_cpu() {
    let Some(g) = gpu("dihedral_bending_and_tethers_match_the_cpu") else {
        return;
    };
    let params = SolverParams {
        solver: Solver::Xpbd {
            stretch: 1e-5,
            shear: 1e-4,
            bending: 2.0,
        },
        substeps: 8,
        iterations: 2,
        ..Default::default()
    };
    let options = TopologyOptions {
        bending: BendingModel::Dihedral,
        ..Default::default()
    };
    let n = 30;
    let mut s = sim_with(n, params, options, |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.1 * p.x)
    });
    // Flat at rest, bent at the start: the hinges work from the first step. (A cloth that
    // starts exactly flat picks the side each hinge folds to from rounding noise, so the two
    // sides fold apart within a few frames: a bifurcation, not a kernel difference.)
    let rest = s.topology().rest_positions().to_vec();
    let bent: Vec<Vec3> = rest
        .iter()
        .map(|p| *p + Vec3::Z * (0.15 * (6.0 * p.x).sin() * (4.0 * p.y).cos()))
        .collect();
    s.reset_to(&bent);
    assert_eq!(
        s.topology().options().effective_bending(),
        BendingModel::Dihedral
    );
    s.set_features(Features {
        tethers: Some(TetherParams {
            slack: 0.02,
            ..Default::default()
        }),
        ..Default::default()
    })
    .unwrap();
    let start = corners(&mut s, n);
    let errors = compare(
        &g,
        &mut s,
        30,
        1,
        |k| {
            let shift = Vec3::new(0.0, 0.4 * (k as f32 * 0.25).sin(), 0.02 * k as f32);
            start.iter().map(|p| *p + shift).collect()
        },
        |_| (Vec::new(), Vec::new()),
    );
    within(&errors, "dihedral + tethers", Some(2e-5), 2e-3);
}

/// A closed box mesh baked into an SDF grid, rotated, scaled and moving, with friction: the
/// trilinear samples and gradients, and the outside-the-grid branch for the vertices far
/// from it, on both sides.
#[test]
fn cloth_on_a_baked_mesh_collider_matches_the_cpu() {
    let Some(g) = gpu("cloth_on_a_baked_mesh_collider_matches_the_cpu") else {
        return;
    };
    let e = Vec3::new(0.3, 0.15, 0.25);
    let corners_of = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { -e.x } else { e.x },
            if i & 2 == 0 { -e.y } else { e.y },
            if i & 4 == 0 { -e.z } else { e.z },
        )
    };
    let positions: Vec<Vec3> = (0..8).map(corners_of).collect();
    let indices = [
        0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6,
        1, 3, 5, 3, 7, 5,
    ];
    let grid = Arc::new(SdfGrid::from_mesh(&positions, &indices, 16).unwrap());
    let params = SolverParams {
        substeps: 6,
        ..Default::default()
    };
    let mut s = sim(32, params, |p| p * 1.2 + Vec3::new(0.0, 0.35, 0.0));
    let shapes = |k: usize| {
        let x = 0.1 * (k as f32 * 0.15).sin();
        vec![Collider {
            shape: Shape::Mesh(grid.clone()),
            start: Pose {
                translation: Vec3::new(x, 0.0, 0.0),
                rotation: Quat::from_rotation_y(0.4),
                scale: 1.1,
            },
            end: Pose {
                translation: Vec3::new(x + 0.01, 0.0, 0.0),
                rotation: Quat::from_rotation_y(0.42),
                scale: 1.1,
            },
            thickness: 0.01,
            friction: 0.4,
        }]
    };
    let errors = compare(
        &g,
        &mut s,
        40,
        1,
        |_| Vec::new(),
        |k| (shapes(k), Vec::new()),
    );
    within(&errors, "SDF collider", Some(2e-5), 5e-3);
}

/// A NaN that reaches the GPU state (here through a pin target, which the plugin never sends)
/// is flagged by the guard kernel at the end of the step; a fresh upload clears the flag.
#[test]
fn a_non_finite_state_is_flagged() {
    let Some((device, queue, kernels)) = gpu("a_non_finite_state_is_flagged") else {
        return;
    };
    let n = 8;
    let mut s = sim(n, SolverParams::default(), |p| p);
    let start = corners(&mut s, n);
    let mut cloth = GpuCloth::new(&device, &kernels, &s).unwrap();
    cloth.upload_state(&queue, &s);
    let run = |cloth: &mut GpuCloth, targets: Vec<Vec3>| {
        cloth.prepare(
            &device,
            &queue,
            &kernels,
            &s,
            DT,
            &[targets],
            GpuStepInput::default(),
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        cloth.record(&mut encoder, &kernels);
        queue.submit([encoder.finish()]);
    };
    run(&mut cloth, start.clone());
    assert!(!cloth.read_failed(&device, &queue));
    let mut bad = start.clone();
    bad[0].x = f32::NAN;
    run(&mut cloth, bad);
    assert!(cloth.read_failed(&device, &queue), "NaN not flagged");
    cloth.upload_state(&queue, &s);
    assert!(!cloth.read_failed(&device, &queue), "upload keeps the flag");
}

/// A cloth dropped onto a small sphere folds onto itself on the ground: self-collision's hash,
/// neighbour lists and per-substep pairs against the CPU twin (the same Jacobi form; the GPU
/// lists each vertex's neighbours in the order its atomics filled the hash, so sums differ
/// by rounding), with a sphere and the ground.
#[test]
fn self_collision_matches_the_cpu_twin() {
    let Some(g) = gpu("self_collision_matches_the_cpu_twin") else {
        return;
    };
    let n = 32;
    let params = SolverParams {
        substeps: 8,
        ..Default::default()
    };
    let mut s = sim(n, params, |p| p * 1.2 + Vec3::new(0.0, 0.3, 0.0));
    s.set_features(Features {
        self_collision: Some(SelfCollision {
            thickness: 1.2 / (n - 1) as f32,
            friction: 0.3,
        }),
        ..Default::default()
    })
    .unwrap();
    let shapes = vec![
        Collider::fixed(
            Shape::Sphere { radius: 0.12 },
            Pose::at(Vec3::new(0.1, 0.12, 0.0)),
            0.01,
            0.3,
        ),
        Collider::fixed(Shape::Plane, Pose::at(Vec3::ZERO), 0.005, 0.6),
    ];
    let errors = compare(
        &g,
        &mut s,
        45,
        1,
        |_| Vec::new(),
        |_| (shapes.clone(), Vec::new()),
    );
    within(&errors, "self-collision", Some(2e-5), 5e-3);
}

/// The teleport rule on the GPU: at step 12 the pins' anchors jump 5 m and the whole cloth
/// goes with them (translated, pins snapped to their targets), as the CPU does.
#[test]
fn a_teleport_matches_the_cpu() {
    let Some(g) = gpu("a_teleport_matches_the_cpu") else {
        return;
    };
    let n = 20;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    let start = corners(&mut s, n);
    let jump = Vec3::new(5.0, 0.5, -2.0);
    let errors = compare_with_teleport(
        &g,
        &mut s,
        24,
        1,
        |k| {
            let shift = Vec3::X * (0.01 * k as f32) + if k >= 12 { jump } else { Vec3::ZERO };
            start.iter().map(|p| *p + shift).collect()
        },
        |_| (Vec::new(), Vec::new()),
        Some((12, jump)),
    );
    within(&errors, "teleport", None, 2e-3);
}

/// The mesh kernel (`mesh.wgsl`) against the CPU write-back (`MeshBinding::update_shading`
/// and `cloth::writeback`'s world → local): a folded sheet with a hard crease (copies with
/// different normals: two normal groups) and a UV seam (copies with the same normal: one
/// group), written from vertex 5 of a slab, through a rotated, scaled, moved transform and a
/// mirrored one.
#[test]
fn the_mesh_kernel_matches_the_cpu_write_back() {
    use bevy::math::{Affine3A, Vec2};
    use bevy_cloth::gpu::mesh::{MeshKernel, MeshWriter, TangentSource, VertexLayout};
    use bevy_cloth::solver::{MeshAttributes, MeshBinding};
    use wgpu::util::DeviceExt;
    let Some((device, queue, _)) = gpu("the_mesh_kernel_matches_the_cpu_write_back") else {
        return;
    };
    // Columns 0..=3 form the left roof, 3..=6 the right one; column 3 is stored twice (the
    // crease), and row 3 twice (a seam in the UVs).
    let (cols, rows) = (7u32, 7u32);
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    let mut index = std::collections::HashMap::new();
    let left_n = Vec3::new(-0.5, 1.0, 0.0).normalize();
    let right_n = Vec3::new(0.5, 1.0, 0.0).normalize();
    for side in 0..2u32 {
        for copy in 0..2u32 {
            for r in 0..rows {
                for c in 0..cols {
                    let on_side = if side == 0 { c <= 3 } else { c >= 3 };
                    let on_copy = if copy == 0 { r <= 3 } else { r >= 3 };
                    if !on_side || !on_copy {
                        continue;
                    }
                    let x = c as f32 * 0.1;
                    let y = 0.05 * (3.0 - (c as f32 - 3.0).abs());
                    index.insert((side, copy, r, c), positions.len() as u32);
                    positions.push(Vec3::new(x, y, r as f32 * 0.1));
                    normals.push(if side == 0 { left_n } else { right_n });
                    uvs.push(Vec2::new(c as f32 / 6.0, r as f32 / 6.0 + copy as f32));
                }
            }
        }
    }
    let mut indices = Vec::new();
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let side = u32::from(c >= 3);
            let copy = u32::from(r >= 3);
            let v = |rr, cc| index[&(side, copy, rr, cc)];
            indices.extend([v(r, c), v(r + 1, c), v(r, c + 1)]);
            indices.extend([v(r, c + 1), v(r + 1, c), v(r + 1, c + 1)]);
        }
    }
    let mut binding = MeshBinding::new(
        &positions,
        MeshAttributes {
            normals: Some(&normals),
            uvs: Some(&uvs),
            tangents: None,
        },
        &indices,
        1e-6,
    )
    .unwrap();
    let weld = binding.weld().clone();
    let (_, groups) = weld.normal_groups();
    assert!(
        weld.particle_count() < positions.len(),
        "the seam and crease weld"
    );
    assert!(
        groups > weld.particle_count(),
        "the crease keeps two normal groups"
    );
    // The simulated particles: the rest shape, rippled.
    let particles: Vec<Vec4> = weld
        .gather(&positions)
        .iter()
        .map(|p| (*p + Vec3::Y * (0.03 * (9.0 * p.x + 5.0 * p.z).sin())).extend(1.0))
        .collect();
    let drawn: Vec<u32> = binding.drawn_indices().collect();
    let state = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&particles),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let kernel = MeshKernel::new(&device);
    // Bevy's order: position, normal, UV, tangent.
    let layout = VertexLayout {
        stride: 48,
        position: 0,
        normal: 12,
        tangent: Some(32),
    };
    let corner_uvs = binding.shading().corner_uvs().expect("UVs give tangents");
    let source = TangentSource {
        corner_uvs: binding
            .drawn_triangles()
            .iter()
            .map(|&t| corner_uvs[t as usize])
            .collect(),
        handedness: None,
    };
    let writer = MeshWriter::new(&device, &weld, &drawn, layout, Some(&source));
    let first = 5u32;
    let m = positions.len();
    let bytes = u64::from(layout.stride) * (u64::from(first) + m as u64);
    binding.update_shading(&particles);
    for transform in [
        Affine3A::from_scale_rotation_translation(
            Vec3::new(1.5, 0.7, 1.1),
            Quat::from_euler(bevy::math::EulerRot::XYZ, 0.3, -0.8, 0.2),
            Vec3::new(2.0, -1.0, 0.5),
        ),
        Affine3A::from_scale_rotation_translation(
            Vec3::new(-1.0, 1.0, 1.0),
            Quat::from_rotation_y(0.4),
            Vec3::new(-3.0, 0.0, 1.0),
        ),
    ] {
        let slab = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        writer.record(
            &device,
            &queue,
            &kernel,
            &mut encoder,
            &state,
            &slab,
            first,
            transform,
        );
        encoder.copy_buffer_to_buffer(&slab, 0, &staging, 0, bytes);
        queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, .., |_| {});
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let out: Vec<f32> = bytemuck::pod_collect_to_vec(&staging.get_mapped_range(..));
        // The CPU write-back's formulas.
        let to_local = transform.inverse();
        let linear = transform.matrix3;
        let flip = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let floats = (layout.stride / 4) as usize;
        let (mut worst_p, mut worst_n, mut worst_t) = (0.0f32, 0.0f32, 0.0f32);
        for v in 0..m {
            let o = (first as usize + v) * floats;
            let p = Vec3::from_slice(&out[o..o + 3]);
            let n = Vec3::from_slice(&out[o + 3..o + 6]);
            let want_p =
                to_local.transform_point3(particles[weld.particles()[v] as usize].truncate());
            let want_n = (linear.transpose() * (binding.shading().normals()[v] * flip))
                .normalize_or(Vec3::Y);
            worst_p = worst_p.max((p - want_p).length());
            worst_n = worst_n.max((n - want_n).length());
            let t = Vec4::from_slice(&out[o + 8..o + 12]);
            let want = binding.shading().tangents()[v];
            let want_t = (to_local.matrix3 * want.truncate()).normalize_or(Vec3::X);
            assert_eq!(t.w, want.w, "handedness of vertex {v}");
            worst_t = worst_t.max((t.truncate() - want_t).length());
        }
        assert!(
            out[..(first as usize * floats)].iter().all(|x| *x == 0.0),
            "wrote before `first`"
        );
        eprintln!(
            "mesh kernel: worst position {worst_p} m, worst normal {worst_n}, worst tangent {worst_t}"
        );
        // f32 rounding of a 4×4 product against glam's affine (a few ulp of ~3 m) and of a
        // normalised sum of face normals.
        assert!(worst_p < 1e-5, "positions differ by {worst_p} m");
        assert!(worst_n < 1e-4, "normals differ by {worst_n}");
        assert!(worst_t < 1e-4, "tangents differ by {worst_t}");
    }
}

/// The tear check (`tear_check`) against `tear::overstretched_edges`: a cloth pulled by its
/// corners, threshold 1.6; the GPU's flag rises in the frame the CPU first finds an edge past
/// it (neither side tears here: the plugin tears on the CPU).
#[test]
fn the_tear_check_matches_the_cpu() {
    let Some((device, queue, kernels)) = gpu("the_tear_check_matches_the_cpu") else {
        return;
    };
    let n = 16;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    s.set_features(Features {
        tear_threshold: Some(1.6),
        ..Default::default()
    })
    .unwrap();
    let start = corners(&mut s, n);
    let mut cloth = GpuCloth::new(&device, &kernels, &s).unwrap();
    cloth.upload_state(&queue, &s);
    let mut state = s.state().clone();
    let topology = s.topology().clone();
    let mut batches = s.batches().clone();
    let params = *s.params();
    let mut scratch = StepScratch::default();
    let (mut cpu_first, mut gpu_first) = (None, None);
    for k in 0..60 {
        // The corners move apart 1 cm a step.
        let t: Vec<Vec3> = start
            .iter()
            .enumerate()
            .map(|(i, p)| *p + Vec3::X * (0.02 * k as f32 * if i == 0 { -1.0 } else { 1.0 }))
            .collect();
        state.set_pin_targets(t.iter().copied());
        step(
            &mut state,
            &topology,
            &mut batches,
            &params,
            DT,
            StepInput::default(),
            &mut scratch,
            &Serial,
        );
        cloth.prepare(
            &device,
            &queue,
            &kernels,
            &s,
            DT,
            &[t],
            GpuStepInput::default(),
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        cloth.record(&mut encoder, &kernels);
        queue.submit([encoder.finish()]);
        let over =
            !bevy_cloth::solver::overstretched_edges(&state.positions, topology.edges(), 1.6)
                .is_empty();
        if over && cpu_first.is_none() {
            cpu_first = Some(k);
        }
        if cloth.read_torn(&device, &queue) && gpu_first.is_none() {
            gpu_first = Some(k);
        }
    }
    eprintln!("first overstretched step: CPU {cpu_first:?}, GPU {gpu_first:?}");
    assert!(
        cpu_first.is_some_and(|k| k > 5),
        "the scene must start untorn"
    );
    assert_eq!(gpu_first, cpu_first);
}

/// The lab solver (seed 000's Jacobi averaging: velocity keep, 32 iterations of averaged edge
/// projections) against the CPU's `lab_step`, two substeps per step, two moving pins.
#[test]
fn the_lab_solver_matches_the_cpu() {
    let Some(g) = gpu("the_lab_solver_matches_the_cpu") else {
        return;
    };
    let params = SolverParams {
        solver: Solver::Lab {
            velocity_keep: 0.99,
        },
        substeps: 2,
        iterations: 32,
        ..Default::default()
    };
    let n = 21;
    let mut s = sim(n, params, |p| p + Vec3::Y);
    let start = corners(&mut s, n);
    let errors = compare(&g, &mut s, 40, 1, sliding(start, Vec3::X * 0.005), |_| {
        (Vec::new(), Vec::new())
    });
    within(&errors, "lab", Some(2e-5), 2e-3);
}
