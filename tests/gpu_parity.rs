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
use bevy_cloth::solver::{
    Collider, Pin, Pose, Serial, Shape, Simulation, Solver, SolverParams, StepInput, StepScratch,
    TopologyOptions, step,
};

const DT: f32 = 1.0 / 60.0;

/// A `n`×`n` grid one metre wide, `place`d, 1 g per vertex.
fn sim(n: u32, params: SolverParams, place: impl Fn(Vec3) -> Vec3) -> Simulation {
    let g = Grid::new(n, n, 1.0, 1.0);
    let positions: Vec<Vec3> = g.positions().into_iter().map(place).collect();
    let t = bevy_cloth::solver::Topology::from_triangles(
        &positions,
        Some(&g.uvs()),
        &g.indices(),
        TopologyOptions::default(),
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
    let (device, queue, kernels) = gpu;
    let mut cloth = GpuCloth::new(device, kernels, sim).expect("supported");
    cloth.upload_state(queue, sim);
    let mut state = sim.state().clone();
    let topology = sim.topology().clone();
    let mut batches = sim.batches().clone();
    let params = *sim.params();
    let mut scratch = StepScratch::default();
    let mut errors = Vec::new();
    let start = state.positions.clone();
    let mut k = 0;
    for _ in 0..frames {
        let mut pin_targets = Vec::new();
        let (colliders, air) = world(k);
        for _ in 0..steps_per_frame {
            let t = targets(k);
            state.set_pin_targets(t.iter().copied());
            step(
                &mut state,
                &topology,
                &mut batches,
                &params,
                DT,
                StepInput {
                    colliders: &colliders,
                    air_velocities: &air,
                    ..Default::default()
                },
                &mut scratch,
                &Serial,
            );
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
/// a wind that varies over the cloth. 70² vertices: two parts, so the merged part colours and
/// the boundary run too.
#[test]
fn hanging_cloth_in_wind_matches_the_cpu() {
    let Some(g) = gpu("hanging_cloth_in_wind_matches_the_cpu") else {
        return;
    };
    let n = 70;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    assert_eq!(s.batches().part_count(), 2);
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
    eprintln!("hanging cloth, worst per frame: {errors:?}");
    assert!(errors[0] < 2e-5, "first step: {}", errors[0]);
    let worst = errors.iter().copied().fold(0.0, f32::max);
    assert!(worst < 2e-3, "worst {worst}");
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
                    half_height: 0.3,
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
    eprintln!("colliders, worst per frame: {errors:?}");
    assert!(errors[0] < 2e-5, "first step: {}", errors[0]);
    let worst = errors.iter().copied().fold(0.0, f32::max);
    assert!(worst < 5e-3, "worst {worst}");
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
    let errors = compare(
        &g,
        &mut s,
        10,
        3,
        |k| {
            start
                .iter()
                .map(|p| *p + Vec3::X * (0.01 * k as f32))
                .collect()
        },
        |_| (Vec::new(), Vec::new()),
    );
    eprintln!("iterations, worst per frame: {errors:?}");
    let worst = errors.iter().copied().fold(0.0, f32::max);
    assert!(worst < 2e-3, "worst {worst}");
    assert!(errors[0] < 5e-5, "first frame: {}", errors[0]);
}

/// What the GPU cannot run is refused with a reason, before any buffer is made.
#[test]
fn unsupported_settings_are_refused_with_a_reason() {
    let mut s = sim(8, SolverParams::default(), |p| p);
    assert!(GpuCloth::supports(&s).is_ok());
    let mut f = *s.features();
    f.tear_threshold = Some(1.5);
    s.set_features(f).unwrap();
    let e = GpuCloth::supports(&s).unwrap_err();
    assert!(e.0.contains("tearing"), "{e}");
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
    assert!(GpuCloth::supports(&lab).unwrap_err().0.contains("lab"));
}
