//! The GPU kernels (`src/gpu/shaders/`) against their CPU twin, `solver::step` on the GPU's
//! own constraint batches (`gpu_part_count`) with self-collision in its parallel form, on a
//! real wgpu adapter (llvmpipe in CI; `CLOTH_REQUIRE_GPU=1` fails instead of skipping).
//!
//! What the tests compare, so that they mean the same on every GPU:
//!
//! - **One frame from the same state.** Before every frame the CPU's state is uploaded to the
//!   GPU, so what is compared is one frame's arithmetic, never chaos grown over many frames.
//!   The two sides run the same operations in the same constraint order; they differ by f32
//!   rounding (a GPU may fuse multiply–adds, and computes `sqrt` and division to within a few
//!   ulp). [`rounding_bound`] derives the most that can be from the quantities involved:
//!   every substep and iteration a vertex's position is rewritten once by its integration,
//!   once by its contacts and once per constraint it belongs to, each rewrite rounding to
//!   ε = 2⁻²³ of the coordinate (the correction itself is computed from differences a few
//!   ulp of an edge long, far smaller), and a neighbour's difference reaches the vertex
//!   through the constraint they share (a factor of 4 for that spread within one frame). A
//!   wrong kernel — a sign, an index, a missed colour — misses it by orders of magnitude.
//! - **Whole runs in what does not diverge chaotically**: strain, the centroid, penetration,
//!   the frame a tear starts (`whole_runs_agree_in_what_does_not_diverge`,
//!   `the_gpu_stretches_no_more_than_the_cpu_backend`).
//! - **Bit for bit on llvmpipe**, where it still holds and only there (no fused arithmetic,
//!   the same summation order): named so in each test that checks it.

mod common;

use std::sync::Arc;

use bevy::math::{Mat3, Quat, Vec3, Vec4};
use bevy_cloth::gpu::{
    ClothFrame, GpuFrame, GpuKernels, GpuWorld, MotionTargets, StepColliders, gpu_part_count,
};
use bevy_cloth::solver::{
    BendingModel, BendingSolve, Carry, ClothState, Collider, ConstraintBatches, ContactImpulse,
    Features, Grid, HangingCloth, Pose, SdfGrid, SelfCollision, Serial, Shape, Simulation, Solver,
    SolverParams, StepInput, StepScratch, TetherParams, Tethers, Topology, TopologyOptions,
    edge_strain, step,
};

const DT: f32 = 1.0 / 60.0;

/// A device, its kernels, and whether it is llvmpipe (where bit identity holds).
struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    kernels: GpuKernels,
    llvmpipe: bool,
}

fn gpu(test: &str) -> Option<Gpu> {
    gpu_with_limits(test, wgpu::Limits::default())
}

/// [`gpu`] on a device that allows no more than `limits`.
fn gpu_with_limits(test: &str, limits: wgpu::Limits) -> Option<Gpu> {
    let (adapter, device, queue, kernels) = common::gpu_kernels_with_limits_or_skip(test, limits)?;
    let name = adapter.get_info().name;
    eprintln!("adapter: {name:?}");
    Some(Gpu {
        device,
        queue,
        kernels,
        llvmpipe: name.contains("llvmpipe"),
    })
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
    let t = Topology::from_triangles(&positions, Some(&g.uvs()), &g.indices(), options).unwrap();
    let masses = vec![0.001; positions.len()];
    Simulation::new(t, &masses, params).unwrap()
}

/// Pins the two corners of row 0; returns their positions.
fn corners(sim: &mut Simulation, n: u32) -> Vec<Vec3> {
    let s = sim.state_mut();
    let pins: Vec<bevy_cloth::solver::Pin> = [0, n - 1]
        .iter()
        .map(|&v| bevy_cloth::solver::Pin {
            vertex: v,
            target: s.position(v as usize),
        })
        .collect();
    s.set_pins(pins).unwrap();
    s.pins().iter().map(|p| p.target).collect()
}

/// Pin targets that slide from `start` by `per_step` every step.
fn sliding(start: Vec<Vec3>, per_step: Vec3) -> Box<dyn Fn(usize) -> Vec<Vec3>> {
    Box::new(move |k| start.iter().map(|p| *p + per_step * k as f32).collect())
}

/// The most f32 rounding can part two correct implementations of `frames` steps of `sim`
/// from the same state (see the module docs): ε × the largest coordinate × the rewrites of a
/// vertex's position (substeps × iterations × (its constraints + integration + contacts),
/// plus 4 at the start of each step for a carried or teleported cloth: the carry's three
/// products and three sums round each coordinate at most about four times its ε; plus 2 a
/// substep for a cloth held by motion targets: the max distance and the backstop) × 4 for
/// the spread to neighbours.
fn rounding_bound(sim: &Simulation, steps: usize, positions: &[Vec4]) -> f32 {
    rounding_bound_with(sim, steps, positions, 0.0)
}

fn rounding_bound_with(sim: &Simulation, steps: usize, positions: &[Vec4], extra: f32) -> f32 {
    let t = sim.topology();
    let mut degree = vec![0u32; t.vertex_count()];
    // Swept forward and back, each distance rewrites its vertices twice a projection.
    let sweeps = if sim.batches().symmetric_sweeps() {
        2
    } else {
        1
    };
    for e in t.edges() {
        for v in e.v {
            degree[v as usize] += sweeps;
        }
    }
    for b in t.bends() {
        for v in b.v {
            degree[v as usize] += 1;
        }
    }
    let deg = degree.iter().copied().max().unwrap_or(0) as f32;
    let scale = positions
        .iter()
        .map(|p| p.truncate().abs().max_element())
        .fold(1.0f32, f32::max);
    let p = sim.params();
    let rewrites = steps as f32
        * ((p.substeps * p.iterations) as f32 * (deg + 4.0) + p.substeps as f32 * extra + 4.0);
    f32::EPSILON * scale * rewrites * 4.0
}

/// The CPU twin of one GPU cloth: `solver::step` on the GPU's batches.
#[derive(Clone)]
struct Twin {
    sim: Simulation,
    state: ClothState,
    topology: Topology,
    batches: ConstraintBatches,
    params: SolverParams,
    tethers: Option<Tethers>,
    scratch: StepScratch,
}

impl Twin {
    fn new(sim: &Simulation) -> Self {
        let parts = gpu_part_count(sim);
        let topology = sim.topology().clone();
        let tethers = sim.features().tethers.map(|p| {
            let pins: Vec<u32> = sim.state().pins().iter().map(|p| p.vertex).collect();
            Tethers::build(&topology, &pins, p)
        });
        Self {
            sim: sim.clone(),
            state: sim.state().clone(),
            batches: ConstraintBatches::new(&topology, sim.params().solver, parts),
            topology,
            params: *sim.params(),
            tethers,
            scratch: StepScratch::default(),
        }
    }

    /// One step: the teleport rule first (if any), pins to `targets`, then the step.
    fn step(
        &mut self,
        targets: &[Vec3],
        jump: Vec3,
        colliders: &[Collider],
        air: &[Vec4],
    ) -> &[ContactImpulse] {
        self.step_carried(&Carry::IDENTITY, targets, jump, colliders, air, None)
    }

    /// [`Twin::step`] after carrying the cloth by `carry` (as the plugin does for
    /// `ClothInertia`, before the pins).
    fn step_carried(
        &mut self,
        carry: &Carry,
        targets: &[Vec3],
        jump: Vec3,
        colliders: &[Collider],
        air: &[Vec4],
        motion: Option<&MotionTargets>,
    ) -> &[ContactImpulse] {
        if *carry != Carry::IDENTITY {
            self.state.carry(carry);
        }
        if jump != Vec3::ZERO {
            self.state.teleport(jump, targets.iter().copied());
        } else {
            self.state.set_pin_targets(targets.iter().copied());
        }
        step(
            &mut self.state,
            &self.topology,
            &mut self.batches,
            &self.params,
            DT,
            StepInput {
                colliders,
                air_velocities: air,
                tethers: self.tethers.as_ref(),
                self_collision: self.sim.features().self_collision,
                motion: motion.map(MotionTargets::constraints).unwrap_or_default(),
            },
            &mut self.scratch,
            &Serial,
        );
        self.scratch.impulses()
    }
}

/// One cloth of a comparison.
struct Case {
    sim: Simulation,
    targets: Box<dyn Fn(usize) -> Vec<Vec3>>,
    air: Box<dyn Fn(usize) -> Vec<Vec4>>,
    /// The step at whose start the cloth teleports, and by how much.
    teleport: Option<(usize, Vec3)>,
    /// The rigid motion carried at the start of each step (`ClothInertia`).
    carry: Box<dyn Fn(usize) -> Carry>,
    /// Where the skin holds each vertex in each step (skinned clothing), if anywhere.
    motion: Box<dyn Fn(usize) -> Option<MotionTargets>>,
    /// How many CPU runs of every frame, each from the frame's start nudged by a few ulp, tell
    /// whether rounding alone splits that frame beyond the bound ([`rounding_splits`]); 0:
    /// every frame is compared.
    ensemble: u32,
}

impl Case {
    fn new(sim: Simulation) -> Self {
        let pins = sim
            .state()
            .pins()
            .iter()
            .map(|p| p.target)
            .collect::<Vec<_>>();
        Self {
            sim,
            targets: Box::new(move |_| pins.clone()),
            air: Box::new(|_| Vec::new()),
            teleport: None,
            carry: Box::new(|_| Carry::IDENTITY),
            motion: Box::new(|_| None),
            ensemble: 0,
        }
    }
}

/// What a comparison found.
#[derive(Debug, Default)]
struct Outcome {
    /// Per cloth, per frame: the largest position difference over the rounding bound.
    ratios: Vec<Vec<f32>>,
    /// Per cloth, per frame: the largest position difference, metres.
    errors: Vec<Vec<f32>>,
    /// The largest relative difference of a collider's impulse over a frame, and the
    /// largest impulse.
    impulse_err: f32,
    impulse_max: f32,
    /// The final states, CPU and GPU.
    cpu: Vec<Vec<Vec4>>,
    gpu: Vec<Vec<Vec4>>,
    /// The first cloth's positions after each frame, CPU and GPU.
    frames_cpu: Vec<Vec<Vec4>>,
    frames_gpu: Vec<Vec<Vec4>>,
    /// How far the first cloth moved from its start over the run.
    moved: f32,
    /// Per cloth, the frames that rounding alone split beyond the bound on the CPU
    /// ([`rounding_splits`]): not compared beyond bit identity on llvmpipe.
    split: Vec<Vec<usize>>,
    /// The largest difference between the GPU's largest speed of a frame (`note_speed`, read
    /// back) and the CPU twin's (`ClothState::max_free_speed_squared` after each step), over
    /// what the rounding bound allows, in the frames not split.
    speed_ratio: f32,
    /// The largest speed compared, m/s.
    speed_max: f32,
}

/// How many ulp of each coordinate [`rounding_splits`] nudges a frame's start by: more than a
/// GPU's rounding of the state it is sent (none) and of one operation (a few ulp).
const NUDGE_ULP: f32 = 8.0;

/// Moves every coordinate `x` of `positions` by up to `size(x)` in a pseudo-random direction
/// (xorshift32 from `seed`: a sign and a size in [0, 1) per coordinate).
fn nudge(positions: &mut [Vec4], seed: &mut u32, size: impl Fn(f32) -> f32) {
    for p in positions {
        for axis in 0..3 {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 17;
            *seed ^= *seed << 5;
            let u = (*seed >> 8) as f32 / (1u32 << 24) as f32;
            p[axis] += (2.0 * u - 1.0) * size(p[axis]);
        }
    }
}

/// Whether rounding alone can take the frame from `start` beyond `bound` of `reference` (the
/// CPU twin's result) at some vertex: `members` CPU runs of the frame's steps, each from
/// `start` with every coordinate moved by up to [`NUDGE_ULP`] ulp in a pseudo-random
/// direction. Where contact decides discretely (a vertex over a triangle or beside it, on one
/// side of a layer or the other, touching or not) a GPU that rounds otherwise can take either
/// side, and the frame says nothing about the kernels.
#[expect(clippy::too_many_arguments)]
fn rounding_splits(
    case: &Case,
    start: &ClothState,
    first_step: usize,
    step_colliders: &[Vec<Collider>],
    jumps: &[Vec3],
    members: u32,
    bound: f32,
    reference: &[Vec4],
) -> bool {
    (1..=members).any(|m| {
        let mut twin = Twin::new(&case.sim);
        twin.state = start.clone();
        let mut seed =
            0x9e37_79b9_u32.wrapping_mul(m) ^ (first_step as u32).wrapping_mul(0x85eb_ca6b);
        nudge(&mut twin.state.positions, &mut seed, |x| {
            NUDGE_ULP * f32::EPSILON * x.abs()
        });
        for (s, cols) in step_colliders.iter().enumerate() {
            let k = first_step + s;
            twin.step_carried(
                &(case.carry)(k),
                &(case.targets)(k),
                jumps[s],
                cols,
                &(case.air)(k),
                (case.motion)(k).as_ref(),
            );
        }
        twin.state
            .positions
            .iter()
            .zip(reference)
            .any(|(a, b)| (a.truncate() - b.truncate()).length() > bound)
    })
}

/// Runs `frames` frames of `steps_per_frame` steps of every case, on the CPU (each on its
/// twin) and on the GPU (all in one world), among `colliders(step)`. With `resync` every
/// frame starts the GPU from the CPU's state (one frame's rounding is compared); without, the
/// two run apart (whole runs).
fn compare(
    g: &Gpu,
    cases: &[Case],
    frames: usize,
    steps_per_frame: usize,
    colliders: impl Fn(usize) -> Vec<Collider>,
    resync: bool,
) -> Outcome {
    let sims: Vec<&Simulation> = cases.iter().map(|c| &c.sim).collect();
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &sims).expect("supported");
    let mut twins: Vec<Twin> = cases.iter().map(|c| Twin::new(&c.sim)).collect();
    let mut out = Outcome {
        ratios: vec![Vec::new(); cases.len()],
        errors: vec![Vec::new(); cases.len()],
        split: vec![Vec::new(); cases.len()],
        ..Default::default()
    };
    let start = twins[0].state.positions.clone();
    let mut k = 0;
    for frame_index in 0..frames {
        if resync {
            for (i, t) in twins.iter().enumerate() {
                world.upload(&g.queue, i, &t.state.positions, &t.state.velocities);
            }
        }
        let before: Vec<Vec<Vec4>> = twins.iter().map(|t| t.state.positions.clone()).collect();
        let starts: Vec<Option<ClothState>> = cases
            .iter()
            .zip(&twins)
            .map(|(c, t)| (c.ensemble > 0).then(|| t.state.clone()))
            .collect();
        let step_colliders: Vec<Vec<Collider>> = (k..k + steps_per_frame).map(&colliders).collect();
        let mut targets = vec![Vec::new(); cases.len()];
        let mut jumps = vec![Vec::new(); cases.len()];
        let mut carries = vec![Vec::new(); cases.len()];
        let mut air = vec![Vec::new(); cases.len()];
        let mut motions: Vec<Vec<MotionTargets>> = vec![Vec::new(); cases.len()];
        let slots = step_colliders.first().map_or(0, Vec::len);
        let mut cpu_impulses = vec![ContactImpulse::default(); slots];
        let mut cpu_speeds = vec![0.0f32; cases.len()];
        for (s, cols) in step_colliders.iter().enumerate() {
            for (i, (case, twin)) in cases.iter().zip(&mut twins).enumerate() {
                let t = (case.targets)(k + s);
                let jump = case
                    .teleport
                    .filter(|j| j.0 == k + s)
                    .map_or(Vec3::ZERO, |j| j.1);
                let a = (case.air)(k + s);
                let carry = (case.carry)(k + s);
                let m = (case.motion)(k + s);
                let impulses = twin.step_carried(&carry, &t, jump, cols, &a, m.as_ref());
                for (sum, imp) in cpu_impulses.iter_mut().zip(impulses) {
                    sum.linear += imp.linear;
                    sum.angular += imp.angular;
                }
                cpu_speeds[i] = cpu_speeds[i].max(twin.state.max_free_speed_squared());
                motions[i].push(m.unwrap_or_default());
                targets[i].push(t);
                jumps[i].push(jump);
                carries[i].push(carry);
                air[i] = a;
            }
        }
        let frame = GpuFrame {
            dt: DT,
            steps: step_colliders
                .iter()
                .map(|c| StepColliders::new(c))
                .collect(),
            cloths: (0..cases.len())
                .map(|i| ClothFrame {
                    first_step: 0,
                    pin_targets: &targets[i],
                    teleports: &jumps[i],
                    carries: &carries[i],
                    air_velocities: &air[i],
                    motion: &motions[i],
                })
                .collect(),
        };
        common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
        k += steps_per_frame;
        let gpu_speeds = world.read_frame_speeds(&g.device, &g.queue);
        for (i, twin) in twins.iter().enumerate() {
            let (pos, vel) = world.read_state(&g.device, &g.queue, i);
            assert!(
                pos.iter().chain(&vel).all(|v| v.is_finite()),
                "cloth {i}: GPU state not finite"
            );
            assert_eq!(
                world.read_status(&g.device, &g.queue, i),
                (false, false),
                "cloth {i}: the guard flagged a finite state"
            );
            let mut worst = 0.0f32;
            for (a, b) in pos.iter().zip(&twin.state.positions) {
                assert_eq!(a.w, b.w, "cloth {i}: inverse masses differ");
                worst = worst.max((a.truncate() - b.truncate()).length());
            }
            let held = motions[i].iter().any(|m| !m.end.is_empty());
            let bound = rounding_bound_with(
                &cases[i].sim,
                steps_per_frame,
                &before[i],
                if held { 2.0 } else { 0.0 },
            );
            let split = starts[i].as_ref().is_some_and(|start| {
                rounding_splits(
                    &cases[i],
                    start,
                    k - steps_per_frame,
                    &step_colliders,
                    &jumps[i],
                    cases[i].ensemble,
                    bound,
                    &twin.state.positions,
                )
            });
            if split {
                out.split[i].push(frame_index);
            } else {
                // Velocities from positions within the bound at the step's end and start
                // (h apart), and the speed's own rounding.
                let p = cases[i].sim.params();
                let h = DT / p.substeps as f32;
                let (gs, cs) = (gpu_speeds[i].sqrt(), cpu_speeds[i].sqrt());
                let allowed = 2.0 * bound / h + 4.0 * f32::EPSILON * cs + 1e-12;
                out.speed_ratio = out.speed_ratio.max((gs - cs).abs() / allowed);
                out.speed_max = out.speed_max.max(cs);
            }
            out.errors[i].push(worst);
            out.ratios[i].push(if split { 0.0 } else { worst / bound });
            if i == 0 {
                out.frames_cpu.push(twin.state.positions.clone());
                out.frames_gpu.push(pos);
            }
        }
        if slots > 0 {
            // The frame's impulses: the GPU sums per workgroup (a tree), the CPU per part;
            // both from positions within the bound. Relative to the impulse, or to 0.1 mN·s.
            let gpu_impulses = world.read_impulses(&g.device, &g.queue);
            for (gi, ci) in gpu_impulses.iter().zip(&cpu_impulses) {
                let scale = ci.linear.length().max(1e-4);
                out.impulse_err = out
                    .impulse_err
                    .max((gi.linear - ci.linear).length() / scale);
                out.impulse_max = out.impulse_max.max(ci.linear.length());
                let ang = ci.angular.length().max(1e-4);
                out.impulse_err = out
                    .impulse_err
                    .max((gi.angular - ci.angular).length() / ang);
            }
        }
    }
    out.cpu = twins.iter().map(|t| t.state.positions.clone()).collect();
    out.gpu = (0..cases.len())
        .map(|i| world.read_state(&g.device, &g.queue, i).0)
        .collect();
    out.moved = start
        .iter()
        .zip(&twins[0].state.positions)
        .map(|(a, b)| (a.truncate() - b.truncate()).length())
        .fold(0.0, f32::max);
    out
}

/// Checks a per-frame comparison: within the rounding bound every frame, bit for bit on
/// llvmpipe if `bitwise`, and the cloth moved (else the comparison means little).
fn check(g: &Gpu, what: &str, out: &Outcome, bitwise: bool) {
    for (i, (ratios, errors)) in out.ratios.iter().zip(&out.errors).enumerate() {
        let worst = ratios.iter().copied().fold(0.0, f32::max);
        let worst_m = errors.iter().copied().fold(0.0, f32::max);
        eprintln!("{what}, cloth {i}: worst {worst_m} m, {worst} of the rounding bound");
        assert!(
            worst <= 1.0,
            "{what}, cloth {i}: {worst} × the rounding bound ({errors:?})"
        );
        if bitwise && g.llvmpipe {
            assert_eq!(
                worst_m, 0.0,
                "{what}, cloth {i}: not bit for bit on llvmpipe"
            );
        }
    }
    assert!(
        out.moved > 0.05,
        "{what}: the cloth hardly moved ({} m)",
        out.moved
    );
    eprintln!(
        "{what}: largest speed {} m/s, {} of what rounding allows",
        out.speed_max, out.speed_ratio
    );
    assert!(
        out.speed_ratio <= 1.0,
        "{what}: the frame's largest speed is {} × what rounding allows",
        out.speed_ratio
    );
    assert!(out.speed_max > 0.0, "{what}: no speed compared");
}

/// Vertical cloth, two pinned corners that move, XPBD 10×1 with isometric bending, air with
/// a wind that varies over the cloth. 80² vertices: seven parts on the GPU, so parts, both
/// seam parities and the parts' colours in workgroup memory all run. Bit for bit on llvmpipe.
#[test]
fn hanging_cloth_in_wind_matches_the_cpu() {
    let Some(g) = gpu("hanging_cloth_in_wind_matches_the_cpu") else {
        return;
    };
    let n = 80;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    assert!(gpu_part_count(&s) > 2, "parts and both seam parities");
    let start = corners(&mut s, n);
    let len = s.state().len();
    let mut case = Case::new(s);
    case.targets = Box::new(move |k| {
        let shift = Vec3::new(0.3 * (k as f32 * 0.2).sin(), 0.0, 0.01 * k as f32);
        start.iter().map(|p| *p + shift).collect()
    });
    case.air = Box::new(move |k| {
        (0..len)
            .map(|i| Vec4::new(3.0 + (i % 7) as f32 * 0.2, 0.0, 1.0 + 0.1 * k as f32, 0.0))
            .collect()
    });
    let out = compare(&g, &[case], 30, 1, |_| Vec::new(), true);
    check(&g, "hanging cloth", &out, true);
}

/// Skinned clothing: a hanging 48² cloth (three parts) held by motion targets that sway and
/// rise with the step (max distance 0 along the top row, growing to 8 cm at the hem, every
/// other row with a backstop 2 cm behind a skin facing +z, radius 0.5 m), with a sphere
/// collider in front. Bit for bit on llvmpipe.
#[test]
fn motion_targets_match_the_cpu() {
    let Some(g) = gpu("motion_targets_match_the_cpu") else {
        return;
    };
    let n = 48;
    let s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    assert!(gpu_part_count(&s) > 2, "parts and seams");
    let rest: Vec<Vec3> = s.state().positions.iter().map(|p| p.truncate()).collect();
    let skin = std::rc::Rc::new(move |k: usize| -> Vec<Vec4> {
        let t = k as f32 / 60.0;
        rest.iter()
            .enumerate()
            .map(|(i, p)| {
                let row = (i as u32 / n) as f32 / (n - 1) as f32;
                let sway = Vec3::new(0.25 * (5.0 * t).sin(), 0.05 * t, 0.1 * (3.0 * t).sin());
                (*p + sway).extend(0.08 * row)
            })
            .collect()
    });
    let mut case = Case::new(s);
    let held = skin.clone();
    case.motion = Box::new(move |k| {
        let skin = &held;
        let end = skin(k + 1);
        let backstop = (0..end.len())
            .map(|i| {
                if (i as u32 / n).is_multiple_of(2) {
                    Vec4::new(0.0, 0.0, 1.0, 0.02)
                } else {
                    Vec4::new(0.0, 0.0, 1.0, -1.0)
                }
            })
            .collect();
        Some(MotionTargets {
            start: skin(k),
            end,
            backstop,
            backstop_radius: 0.5,
        })
    });
    let sphere = |k: usize| {
        vec![Collider::fixed(
            Shape::Sphere { radius: 0.15 },
            Pose::at(Vec3::new(0.1 * (k as f32 * 0.1).sin(), 0.5, 0.2)),
            0.01,
            0.3,
        )]
    };
    let out = compare(&g, &[case], 30, 1, sphere, true);
    check(&g, "motion targets", &out, true);
    // Held: every vertex away from the sphere (which pushes last) within its max distance of
    // the skin, and the hem moved off it (simulated, not carried).
    let end = skin(30);
    let centre = Vec3::new(0.1 * (29.0f32 * 0.1).sin(), 0.5, 0.2);
    let (mut worst, mut hem) = (0.0f32, 0.0f32);
    for (i, (p, t)) in out.gpu[0].iter().zip(&end).enumerate() {
        let d = p.truncate().distance(t.truncate());
        if p.truncate().distance(centre) > 0.3 {
            worst = worst.max(d - t.w);
        }
        if i as u32 >= n * (n - 1) {
            hem = hem.max(d);
        }
    }
    assert!(worst < 1e-4, "a vertex {worst} m past its max distance");
    assert!(hem > 0.005, "the hem followed the skin rigidly ({hem} m)");
}

fn collider_shapes(k: usize) -> Vec<Collider> {
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
                radius: 0.08,
                half_length: 0.3,
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
}

/// A cloth falling onto a moving sphere, a rotated box, a capsule and the ground, PBD with
/// two iterations, friction on every collider; the impulses each collider received.
#[test]
fn cloth_on_colliders_matches_the_cpu() {
    let Some(g) = gpu("cloth_on_colliders_matches_the_cpu") else {
        return;
    };
    colliders_match(&g, 40, "colliders");
}

/// [`pbd_over_colliders`] over `collider_shapes` for `frames` frames against its CPU twin,
/// and the impulses the colliders received.
fn colliders_match(g: &Gpu, frames: usize, label: &str) {
    let cloth = Case::new(pbd_over_colliders());
    let out = compare(g, &[cloth], frames, 1, collider_shapes, true);
    check(g, label, &out, true);
    eprintln!(
        "{label}: worst relative impulse difference {}, largest impulse {} N·s",
        out.impulse_err, out.impulse_max
    );
    assert!(out.impulse_max > 1e-3, "the colliders were hardly touched");
    // The sums' order differs (a tree of 64 per workgroup on the GPU, parts in order on the
    // CPU): relative rounding of a sum of a few thousand terms, ~1e-4 at most.
    assert!(
        out.impulse_err < 1e-3,
        "impulses differ by {}",
        out.impulse_err
    );
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
    let mut case = Case::new(s);
    case.targets = sliding(start, Vec3::X * 0.01);
    let out = compare(&g, &[case], 10, 3, |_| Vec::new(), true);
    check(&g, "iterations", &out, true);
}

/// What the GPU can run (every feature, every solver) and what it refuses with a reason
/// (`BendingSolve::Implicit`), before any buffer is made; worlds hold one key.
#[test]
fn unsupported_settings_are_refused_with_a_reason() {
    let mut s = sim(8, SolverParams::default(), |p| p);
    assert!(GpuWorld::supports(&s, DT).is_ok());
    let mut f = *s.features();
    f.self_collision = Some(SelfCollision {
        thickness: 0.1,
        friction: 0.2,
    });
    f.tear_threshold = Some(1.5);
    f.tethers = Some(TetherParams::default());
    s.set_features(f).unwrap();
    assert!(GpuWorld::supports(&s, DT).is_ok(), "every feature runs");
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
    assert!(GpuWorld::supports(&auto, DT).is_ok());
    let e = GpuWorld::supports(&stiff(BendingSolve::Implicit), DT).unwrap_err();
    assert!(e.0.contains("implicit"), "{e}");
    let Some(g) = gpu("unsupported_settings_are_refused_with_a_reason") else {
        return;
    };
    let other = sim(
        8,
        SolverParams {
            substeps: 3,
            ..Default::default()
        },
        |p| p,
    );
    let e = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&s, &other]).unwrap_err();
    assert!(e.0.contains("substeps"), "{e}");
}

/// Dihedral bending (the signed-angle hinges, `atan2` on both sides) with tethers to two
/// moving pinned corners, XPBD 8×2: multipliers of dihedral hinges carried over iterations,
/// every free vertex pulled back within reach of its pins after the projections. Within the
/// rounding bound only: `atan2` is the platform's on each side.
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
    let rest = s.topology().rest_positions().to_vec();
    let bent: Vec<Vec3> = rest
        .iter()
        .map(|p| *p + Vec3::Z * (0.15 * (6.0 * p.x).sin() * (4.0 * p.y).cos()))
        .collect();
    s.reset_to(&bent);
    s.set_features(Features {
        tethers: Some(TetherParams {
            slack: 0.02,
            ..Default::default()
        }),
        ..Default::default()
    })
    .unwrap();
    let start = corners(&mut s, n);
    let mut case = Case::new(s);
    case.targets = Box::new(move |k| {
        let shift = Vec3::new(0.0, 0.4 * (k as f32 * 0.25).sin(), 0.02 * k as f32);
        start.iter().map(|p| *p + shift).collect()
    });
    let out = compare(&g, &[case], 30, 1, |_| Vec::new(), true);
    // Not bit for bit on llvmpipe: the signed angle's `atan2` is the platform's on the CPU
    // and the shader compiler's on the GPU.
    check(&g, "dihedral + tethers", &out, false);
}

/// A closed box mesh baked into an SDF grid, rotated, scaled and moving, with friction: the
/// trilinear samples and gradients, and the outside-the-grid branch, on both sides.
#[test]
fn cloth_on_a_baked_mesh_collider_matches_the_cpu() {
    let Some(g) = gpu("cloth_on_a_baked_mesh_collider_matches_the_cpu") else {
        return;
    };
    let e = Vec3::new(0.3, 0.15, 0.25);
    let corner = |i: u32| {
        Vec3::new(
            if i & 1 == 0 { -e.x } else { e.x },
            if i & 2 == 0 { -e.y } else { e.y },
            if i & 4 == 0 { -e.z } else { e.z },
        )
    };
    let positions: Vec<Vec3> = (0..8).map(corner).collect();
    let indices = [
        0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6,
        1, 3, 5, 3, 7, 5,
    ];
    let grid = Arc::new(SdfGrid::from_mesh(&positions, &indices, 16).unwrap());
    let params = SolverParams {
        substeps: 6,
        ..Default::default()
    };
    let s = sim(32, params, |p| p * 1.2 + Vec3::new(0.0, 0.35, 0.0));
    let shapes = move |k: usize| {
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
    let out = compare(&g, &[Case::new(s)], 40, 1, shapes, true);
    check(&g, "SDF collider", &out, true);
}

/// A NaN that reaches the GPU state (here through a pin target, which the plugin never sends)
/// is flagged by the step's guard for that cloth only; a fresh upload clears the flag.
#[test]
fn a_non_finite_state_is_flagged() {
    let Some(g) = gpu("a_non_finite_state_is_flagged") else {
        return;
    };
    let n = 8;
    let mut a = sim(n, SolverParams::default(), |p| p);
    let start = corners(&mut a, n);
    let b = a.clone();
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&a, &b]).unwrap();
    let run = |world: &mut GpuWorld, bad: Vec<Vec3>| {
        let targets = [vec![bad], vec![start.clone()]];
        let frame = GpuFrame::uniform(DT, 1, &[], &targets);
        common::run_gpu_frame(world, &g.device, &g.queue, &g.kernels, &frame);
    };
    run(&mut world, start.clone());
    assert_eq!(world.read_status(&g.device, &g.queue, 0), (false, false));
    let mut bad = start.clone();
    bad[0].x = f32::NAN;
    run(&mut world, bad);
    assert!(
        world.read_status(&g.device, &g.queue, 0).0,
        "NaN not flagged"
    );
    assert!(
        !world.read_status(&g.device, &g.queue, 1).0,
        "the other cloth flagged"
    );
    world.upload_state(&g.queue, 0, &a);
    assert!(
        !world.read_status(&g.device, &g.queue, 0).0,
        "upload keeps the flag"
    );
}

/// A cloth folded in two dropped onto a small sphere folds onto itself on the ground: self-collision's
/// parallel hash build, the sorted neighbour lists and the per-substep pairs against the CPU
/// twin (vertex–vertex and vertex–triangle, with each triangle's side), with a sphere and the
/// ground. Bit for bit on llvmpipe: both sides keep the same lowest-numbered neighbours and
/// triangles in the same order.
#[test]
fn self_collision_matches_the_cpu_twin() {
    let Some(g) = gpu("self_collision_matches_the_cpu_twin") else {
        return;
    };
    folded_cloth_self_collides(&g, Some(1.0), false, "self-collision", 0, 0);
}

/// The same with the thickest layers a cloth takes (`MAX_SELF_COLLISION_EDGES`: one mean rest
/// edge, 1.14 grid spacings here).
///
/// Layers piled up make a frame's outcome hang on rounding: contact decides discretely (a
/// vertex over a triangle or beside it, on one side of a layer or the other, touching or not),
/// and each way differs by up to two thicknesses. On the CPU alone, a frame from a start 4 ulp
/// away ended beyond the rounding bound at 14 % of the vertex-frames of this run at 1.6
/// spacings (before such layers were refused); on an H100 (fused multiply–adds) the
/// frame-by-frame comparison failed there at 351 × the bound with every kernel right. So
/// frames that four CPU runs from starts [`NUDGE_ULP`] ulp away split beyond the bound
/// ([`rounding_splits`], the same on any machine) are compared bit for bit on llvmpipe and
/// not at all on other GPUs; the rest within the bound everywhere.
#[test]
fn self_collision_of_the_thickest_cloth_matches_the_cpu_twin() {
    let Some(g) = gpu("self_collision_of_the_thickest_cloth_matches_the_cpu_twin") else {
        return;
    };
    folded_cloth_self_collides(&g, None, false, "thickest self-collision", 4, 40);
}

/// The same on a mesh of uneven edges (the grid squeezed towards the middle both ways: the
/// 90th percentile of its edges 2.5 times the 10th, past `EVEN_EDGE_SPREAD`), where each
/// vertex keeps a thickness from its own edges: the kernels read it from the rest
/// position's w, and the thickness it keeps from triangles (at most 1.2 of its shortest edge,
/// less than its own where the squeeze makes the cells long and narrow) from `topo`. Compared as the thickest cloth is (rounding splits bit for bit on llvmpipe
/// only); more frames split here (8 of 45 when written), at least 30 are compared.
#[test]
fn self_collision_of_an_uneven_cloth_matches_the_cpu_twin() {
    let Some(g) = gpu("self_collision_of_an_uneven_cloth_matches_the_cpu_twin") else {
        return;
    };
    folded_cloth_self_collides(&g, Some(1.0), true, "uneven self-collision", 4, 30);
}

/// Frames the folded cloths are compared over.
const FOLDED_FRAMES: usize = 45;

/// A 32² cloth folded in two, thickness `spacings` × its grid spacing (the most it takes if
/// `None`; returned), over a sphere and the ground (the colliders, returned); `uneven`: its
/// grid squeezed towards the middle both ways (`u + 0.4 sin(2πu)/2π`).
fn folded_cloth(spacings: Option<f32>, uneven: bool) -> (Simulation, Vec<Collider>, f32) {
    let n = 32;
    let params = SolverParams {
        substeps: 8,
        ..Default::default()
    };
    let squeeze = |v: f32| {
        if !uneven {
            return v;
        }
        let u = v + 0.5;
        let tau = core::f32::consts::TAU;
        u + 0.4 * (tau * u).sin() / tau - 0.5
    };
    let mut s = sim(n, params, |p| {
        Vec3::new(squeeze(p.x), p.y, squeeze(p.z)) * 1.2 + Vec3::new(0.0, 0.3, 0.0)
    });
    if uneven {
        let spread = s.topology().rest_edge_spread();
        assert!(
            spread > bevy_cloth::solver::EVEN_EDGE_SPREAD + 0.5,
            "spread {spread}"
        );
        // Some vertices keep less from triangles than from vertices: both are compared.
        let topology = s.topology();
        let thinner = topology
            .self_collision_triangle_scales()
            .iter()
            .zip(topology.self_collision_scales())
            .filter(|(t, s)| t < s)
            .count();
        assert!(thinner > 50, "{thinner} vertices keep less from triangles");
    }
    let thickness = spacings.map_or(s.topology().thickest_self_collision(), |k| {
        k * 1.2 / (n - 1) as f32
    });
    common::self_colliding(&mut s, thickness);
    let shapes = vec![
        Collider::fixed(
            Shape::Sphere { radius: 0.12 },
            Pose::at(Vec3::new(0.1, 0.12, 0.0)),
            0.01,
            0.3,
        ),
        Collider::fixed(Shape::Plane, Pose::at(Vec3::ZERO), 0.005, 0.6),
    ];
    // Folded in two (the half at x > 0 laid over the other, 1.5 thicknesses up), so that
    // layers touch from the first frame.
    let folded: Vec<Vec3> = s
        .topology()
        .rest_positions()
        .iter()
        .map(|p| {
            if p.x > 0.0 {
                Vec3::new(-p.x, p.y + 1.5 * thickness, p.z)
            } else {
                *p
            }
        })
        .collect();
    s.reset_to(&folded);
    (s, shapes, thickness)
}

/// The folded cloth dropped on the sphere, [`FOLDED_FRAMES`] frames on both sides; with an
/// `ensemble`, frames that rounding alone splits on the CPU are compared bit for bit on
/// llvmpipe only, and at least `min_compared` frames must be left to compare.
fn folded_cloth_self_collides(
    g: &Gpu,
    spacings: Option<f32>,
    uneven: bool,
    label: &str,
    ensemble: u32,
    min_compared: usize,
) {
    let (s, shapes, thickness) = folded_cloth(spacings, uneven);
    let rest = s.topology().rest_positions().to_vec();
    let tris = s.topology().triangles().to_vec();
    let mut case = Case::new(s);
    case.ensemble = ensemble;
    let out = compare(g, &[case], FOLDED_FRAMES, 1, |_| shapes.clone(), true);
    check(g, label, &out, true);
    if ensemble > 0 {
        let split = &out.split[0];
        println!(
            "{label}: {} of {FOLDED_FRAMES} frames split by rounding alone (compared bit for \
             bit on llvmpipe only): {split:?}",
            split.len()
        );
        assert!(
            FOLDED_FRAMES - split.len() >= min_compared,
            "{label}: only {} frames compared",
            FOLDED_FRAMES - split.len()
        );
    }
    // The cloth ends folded layer on layer: vertices lie over triangles of other layers, so
    // the vertex–triangle contacts were compared, not only the vertex–vertex ones.
    let over = layered_contacts(&out.cpu[0], &rest, &tris, thickness);
    println!("{label}: {over} vertices over a triangle of another layer");
    assert!(over > 20, "{over}");
}

/// Vertices within 1.5 `thickness` of a triangle they are over whose corners all rest more
/// than 2.5 thicknesses away (another layer of the cloth), by brute force.
fn layered_contacts(pos: &[Vec4], rest: &[Vec3], tris: &[[u32; 3]], thickness: f32) -> usize {
    (0..pos.len())
        .filter(|&i| {
            let p = pos[i].truncate();
            tris.iter().any(|t| {
                if t.iter()
                    .any(|&k| rest[k as usize].distance(rest[i]) <= 2.5 * thickness)
                {
                    return false;
                }
                let [a, b, c] = t.map(|k| pos[k as usize].truncate());
                let n = (b - a).cross(c - a).normalize();
                let d = (p - a).dot(n);
                let q = p - n * d;
                // Inside: q on the inner side of all three edges.
                let inside = [(a, b), (b, c), (c, a)]
                    .iter()
                    .all(|&(u, v)| (v - u).cross(q - u).dot(n) >= 0.0);
                inside && d.abs() < 1.5 * thickness
            })
        })
        .count()
}

/// A closed cube (8 × 8 quads a face, 0.4 m) tilted just over the ground, 0.5 kg, with
/// self-collision at its default thickness, which the closed cap binds (its neighbours rest
/// closer than the thickness over the cap).
fn tilted_closed_cube() -> Simulation {
    let (positions, indices) = common::subdivided_cube(8, 0.4, Vec3::ZERO);
    let placed: Vec<Vec3> = positions
        .iter()
        .map(|p| Quat::from_rotation_z(0.3) * Quat::from_rotation_x(0.2) * *p + Vec3::Y * 0.32)
        .collect();
    let t = Topology::from_triangles(&placed, None, &indices, TopologyOptions::default()).unwrap();
    assert!(t.is_closed());
    let thickness = t.default_self_collision_thickness();
    assert!(bevy_cloth::solver::NEAR_CORNER_THICKNESS * t.short_rest_edge() < thickness);
    let masses = vec![0.5 / placed.len() as f32; placed.len()];
    let mut s = Simulation::new(t, &masses, SolverParams::default()).unwrap();
    common::self_colliding(&mut s, thickness);
    s
}

/// A closed cube (8 × 8 quads a face) at its default thickness (1.1 of its spacing, farther
/// than its edges let a vertex get from the triangles through its neighbours), dropped tilted
/// onto the ground: on landing its faces crease, and the thickness kept near a vertex is
/// capped at `NEAR_CORNER_THICKNESS` of its rest distance from the triangle's nearest corner
/// (a closed cloth's rule), against the CPU twin's; compared as the thickest cloth is (frames
/// that rounding alone splits on the CPU bit for bit on llvmpipe only).
#[test]
fn self_collision_of_a_closed_cloth_caps_its_thickness_as_on_the_cpu() {
    let Some(g) = gpu("self_collision_of_a_closed_cloth_caps_its_thickness_as_on_the_cpu") else {
        return;
    };
    on_the_ground_as_on_the_cpu(&g, tilted_closed_cube(), "closed cube");
}

/// `s` on a plane at y = 0 (5 mm thick, friction 0.6) for [`FOLDED_FRAMES`] frames against
/// its CPU twin, checked as the thickest cloth is (an ensemble of four CPU runs tells the
/// frames that rounding alone splits, compared bit for bit on llvmpipe only); at least 30
/// frames compared.
fn on_the_ground_as_on_the_cpu(g: &Gpu, s: Simulation, what: &str) {
    let ground = vec![Collider::fixed(
        Shape::Plane,
        Pose::at(Vec3::ZERO),
        0.005,
        0.6,
    )];
    let mut case = Case::new(s);
    case.ensemble = 4;
    let out = compare(g, &[case], FOLDED_FRAMES, 1, |_| ground.clone(), true);
    check(g, what, &out, true);
    let split = &out.split[0];
    println!(
        "{what}: {} of {FOLDED_FRAMES} frames split by rounding alone: {split:?}",
        split.len()
    );
    assert!(
        FOLDED_FRAMES - split.len() >= 30,
        "{what}: only {} frames compared",
        FOLDED_FRAMES - split.len()
    );
}

/// Bevy's `Cone` mesh (64 segments, 0.5 m tall) tilted and dropped on the ground with
/// self-collision at its default thickness: its tip, joined by an edge to every corner of the
/// base's triangles, is kept from them at most 0.9 of its rest distance from the triangles
/// themselves (not from their nearest corner, 0.58 m away: the closed cap's rule for a vertex
/// joined to all three corners), against the CPU twin's; compared as the closed cube is.
/// With the GPU's cap from the nearest corner instead, it parts from its twin on landing
/// (38 times the rounding bound, measured).
#[test]
fn self_collision_of_a_cone_caps_its_tip_from_its_base_as_on_the_cpu() {
    use bevy::math::primitives::Cone;
    use bevy::mesh::{MeshBuilder, Meshable};
    let Some(g) = gpu("self_collision_of_a_cone_caps_its_tip_from_its_base_as_on_the_cpu") else {
        return;
    };
    let mesh = Cone::new(0.3, 0.5).mesh().resolution(64).build();
    let (positions, indices) = common::welded(&mesh, Vec3::ZERO);
    let turn = Quat::from_rotation_z(0.3) * Quat::from_rotation_x(0.2);
    let placed: Vec<Vec3> = positions
        .iter()
        .map(|p| turn * *p + Vec3::Y * 0.6)
        .collect();
    let t = Topology::from_triangles(&placed, None, &indices, TopologyOptions::default()).unwrap();
    assert!(t.is_closed());
    let thickness = t.default_self_collision_thickness();
    // The premise: the tip (the highest vertex before the turn) keeps from triangles more
    // than 0.9 of the cone's height, so the cap binds there.
    let tip = (0..positions.len())
        .max_by(|&a, &b| positions[a].y.total_cmp(&positions[b].y))
        .unwrap();
    let tip_thickness = thickness * t.self_collision_triangle_scales()[tip];
    assert!(
        tip_thickness > bevy_cloth::solver::NEAR_CORNER_THICKNESS * 0.5,
        "the tip keeps {tip_thickness} m from triangles"
    );
    let masses = vec![0.2 / placed.len() as f32; placed.len()];
    let mut s = Simulation::new(t, &masses, SolverParams::default()).unwrap();
    common::self_colliding(&mut s, thickness);
    on_the_ground_as_on_the_cpu(&g, s, "cone");
}

/// A closed cloth that tears is closed no more from the step after its first tear, on the GPU
/// as on the CPU (whose tear opens the topology at once), though the GPU keeps the cloth's
/// closed record until the host's tear rebuilds it: the closed cube with self-collision
/// falls on the ground held by its lowest vertex, whose anchor then sinks into the ground
/// until its edges tear (threshold 1.5). Each step starts from the CPU's state and is compared within
/// the rounding bound (a step that rounding alone splits, as four CPU runs from starts a few
/// ulp apart tell, is compared bit for bit on llvmpipe only); the twin tears what the GPU
/// tore, as in `the_tear_check_and_the_torn_edges_match_the_cpu`. With the thickness cap
/// left on after the tear (the GPU's closed record alone) the crumpled cube parts from its
/// twin.
#[test]
fn a_closed_cloth_that_tears_self_collides_as_an_open_one_as_on_the_cpu() {
    let Some(g) = gpu("a_closed_cloth_that_tears_self_collides_as_an_open_one_as_on_the_cpu")
    else {
        return;
    };
    const PULL: usize = 40;
    const STEPS: usize = 80;
    let mut s = tilted_closed_cube();
    let placed: Vec<Vec3> = s.topology().rest_positions().to_vec();
    let mut features = *s.features();
    features.tear_threshold = Some(1.5);
    s.set_features(features).unwrap();
    let lowest = (0..placed.len() as u32)
        .min_by(|&a, &b| placed[a as usize].y.total_cmp(&placed[b as usize].y))
        .unwrap();
    let anchor = placed[lowest as usize];
    s.state_mut()
        .set_pins(vec![bevy_cloth::solver::Pin {
            vertex: lowest,
            target: anchor,
        }])
        .unwrap();
    let ground = [Collider::fixed(
        Shape::Plane,
        Pose::at(Vec3::ZERO),
        0.005,
        0.6,
    )];
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&s]).unwrap();
    let mut twin = Twin::new(&s);
    let full = twin.topology.clone();
    let mut torn: Vec<[u32; 2]> = Vec::new();
    let (mut first_tear, mut compared_open, mut split, mut worst) = (None, 0, 0, 0.0f32);
    for k in 0..STEPS {
        // After PULL steps the anchor sinks into the ground, 2 cm a step.
        let target = anchor - Vec3::Y * 0.02 * k.saturating_sub(PULL) as f32;
        world.upload(&g.queue, 0, &twin.state.positions, &twin.state.velocities);
        let bound = rounding_bound(&s, 1, &twin.state.positions);
        let start = twin.clone();
        twin.step(&[target], Vec3::ZERO, &ground, &[]);
        let targets = [vec![vec![target]]];
        let frame = GpuFrame::uniform(DT, 1, &ground, &targets);
        common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
        let (gpu_positions, _) = world.read_state(&g.device, &g.queue, 0);
        let diff = twin
            .state
            .positions
            .iter()
            .zip(&gpu_positions)
            .map(|(a, b)| (a.truncate() - b.truncate()).length())
            .fold(0.0f32, f32::max);
        if g.llvmpipe {
            assert_eq!(diff, 0.0, "step {k}: not bit for bit on llvmpipe");
        }
        // Whether rounding alone splits this step beyond the bound.
        let splits = (1..=4u32).any(|m| {
            let mut member = start.clone();
            let mut seed = 0x9e37_79b9_u32.wrapping_mul(m) ^ (k as u32).wrapping_mul(0x85eb_ca6b);
            nudge(&mut member.state.positions, &mut seed, |x| {
                NUDGE_ULP * f32::EPSILON * x.abs()
            });
            member.step(&[target], Vec3::ZERO, &ground, &[]);
            member
                .state
                .positions
                .iter()
                .zip(&twin.state.positions)
                .any(|(a, b)| (a.truncate() - b.truncate()).length() > bound)
        });
        if splits {
            split += 1;
        } else {
            assert!(
                diff <= bound,
                "step {k} ({} torn edges, twin closed: {}): positions differ by {diff} m, \
                 rounding allows {bound}",
                torn.len(),
                twin.topology.is_closed()
            );
            if !twin.topology.is_closed() {
                compared_open += 1;
                worst = worst.max(diff / bound);
            }
        }
        let mut flagged = world.read_torn_edges(&g.device, &g.queue, 0).torn;
        flagged.sort_unstable();
        if !flagged.is_empty() && first_tear.is_none() {
            first_tear = Some(k);
        }
        if flagged != torn {
            tear_twin(&mut twin, &full, &flagged);
            torn = flagged;
        }
    }
    eprintln!(
        "closed cube torn from step {first_tear:?}: {} edges; {compared_open} steps compared \
         open, worst {worst:.3} of the rounding bound; {split} of {STEPS} steps split by \
         rounding alone",
        torn.len()
    );
    assert!(
        first_tear.is_some_and(|k| k > PULL),
        "the cube must tear after its anchor pulls, not before ({first_tear:?})"
    );
    assert!(!twin.topology.is_closed());
    assert!(
        compared_open >= 20,
        "only {compared_open} steps compared after the tear"
    );
}

/// A closed cylinder whose caps are fanned from one rim vertex (as Bevy's `Cylinder` writes
/// them: that vertex joins 33 others), so its distances are swept forward and back
/// (`SYMMETRIC_SWEEP_DEGREE`), hung from that vertex on a sliding anchor and swinging: the
/// backward sweep (leftovers, then colours, last to first) against the CPU twin's, every
/// frame from the same state, within the rounding bound (which counts each distance twice).
/// Bit for bit on llvmpipe.
#[test]
fn a_cloth_with_a_hub_sweeps_back_as_on_the_cpu() {
    let Some(g) = gpu("a_cloth_with_a_hub_sweeps_back_as_on_the_cpu") else {
        return;
    };
    let (positions, indices) = common::fanned_cylinder(32, 0.3, 1.0);
    let placed: Vec<Vec3> = positions
        .iter()
        .map(|p| Quat::from_rotation_z(0.4) * *p + Vec3::Y)
        .collect();
    let t = Topology::from_triangles(&placed, None, &indices, TopologyOptions::default()).unwrap();
    assert!(t.max_vertex_degree() > bevy_cloth::solver::SYMMETRIC_SWEEP_DEGREE);
    let masses = vec![0.002; placed.len()];
    let mut s = Simulation::new(t, &masses, SolverParams::default()).unwrap();
    assert!(s.batches().symmetric_sweeps());
    let hub = bevy_cloth::solver::Pin {
        vertex: 0,
        target: s.state().position(0),
    };
    s.state_mut().set_pins(vec![hub]).unwrap();
    let mut case = Case::new(s);
    case.targets = sliding(vec![hub.target], Vec3::new(0.02, 0.0, 0.01));
    let out = compare(&g, &[case], 30, 1, |_| Vec::new(), true);
    check(&g, "cylinder with a hub", &out, true);
}

/// The teleport rule on the GPU: at step 12 the pins' anchors jump 5 m and the whole cloth
/// goes with them (translated, pins snapped to their targets), as `ClothState::teleport`.
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
    let mut case = Case::new(s);
    case.targets = Box::new(move |k| {
        let shift = Vec3::X * (0.01 * k as f32) + if k >= 12 { jump } else { Vec3::ZERO };
        start.iter().map(|p| *p + shift).collect()
    });
    case.teleport = Some((12, jump));
    let out = compare(&g, &[case], 24, 1, |_| Vec::new(), true);
    check(&g, "teleport", &out, true);
    assert!(out.cpu[0][0].x > 4.0, "the cloth went with its pins");
}

/// A cloth carried by a turning, moving anchor every step (`ClothInertia`), stretched every
/// fourth step (its entity scaled: `Stretch`), and teleported once: the `teleport` kernel's
/// carry against `ClothState::carry`, every frame from the same
/// state, within the rounding bound. Not bit for bit even on llvmpipe (its shader compiler
/// evaluates the carry's matrix product differently; 5.1e-7 m, 0.24 % of the bound, before a
/// stretched velocity kept its speed; 1.2e-6 m, 0.56 %, since: the square root and the
/// division of `clamp_speed` that bring it back), so that is not asserted.
#[test]
fn a_carried_cloth_matches_the_cpu() {
    let Some(g) = gpu("a_carried_cloth_matches_the_cpu") else {
        return;
    };
    let n = 20;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    corners(&mut s, n);
    let mut case = Case::new(s);
    case.carry = Box::new(|k| {
        let rigid = Carry {
            rotation: Quat::from_rotation_y(0.02) * Quat::from_rotation_x(0.01 * (k % 3) as f32),
            pivot: Vec3::new(0.3, 0.8, -0.1),
            translation: Vec3::new(0.01, 0.002 * k as f32, -0.005),
            stretch: None,
        };
        // Every fourth step its entity also grows along one turned axis and shrinks along
        // another (a scaled entity's `Stretch`).
        if k % 4 == 1 {
            let turn = Mat3::from_rotation_z(0.4);
            rigid.then_stretch(bevy_cloth::solver::Stretch {
                center: Vec3::new(0.1, 0.6, 0.0),
                linear: turn * Mat3::from_diagonal(Vec3::new(1.03, 0.98, 1.0)) * turn.transpose(),
            })
        } else {
            rigid
        }
    });
    case.teleport = Some((12, Vec3::new(0.0, 0.0, 3.0)));
    let out = compare(&g, &[case], 24, 2, |_| Vec::new(), true);
    check(&g, "carry", &out, false);
}

/// Several cloths in one world (one dispatch per level for all of them): different sizes,
/// solvers' materials and features — self-collision, tethers, air, dihedral bending — each
/// against its own twin.
#[test]
fn packed_cloths_match_their_twins() {
    let Some(g) = gpu("packed_cloths_match_their_twins") else {
        return;
    };
    let mut a = sim(40, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    let start_a = corners(&mut a, 40);
    a.set_features(Features {
        tethers: Some(TetherParams::default()),
        ..Default::default()
    })
    .unwrap();
    let mut b = sim_with(
        17,
        SolverParams {
            solver: Solver::Xpbd {
                stretch: 1e-6,
                shear: 1e-5,
                bending: 5.0,
            },
            ..Default::default()
        },
        TopologyOptions {
            bending: BendingModel::Dihedral,
            ..Default::default()
        },
        |p| p * 0.8 + Vec3::new(2.0, 0.6, 0.0),
    );
    b.set_features(Features {
        self_collision: Some(SelfCollision {
            thickness: 0.05,
            friction: 0.2,
        }),
        ..Default::default()
    })
    .unwrap();
    let c = sim(9, SolverParams::default(), |p| {
        p * 0.5 + Vec3::new(-2.0, 1.0, 0.0)
    });
    let len_a = a.state().len();
    let mut case_a = Case::new(a);
    case_a.targets = sliding(start_a, Vec3::Z * 0.01);
    case_a.air = Box::new(move |_| vec![Vec4::new(2.0, 0.0, 1.0, 0.0); len_a]);
    let floor = vec![Collider::fixed(
        Shape::Plane,
        Pose::at(Vec3::ZERO),
        0.01,
        0.5,
    )];
    let out = compare(
        &g,
        &[case_a, Case::new(b), Case::new(c)],
        20,
        2,
        |_| floor.clone(),
        true,
    );
    // The dihedral cloth's `atan2` differs by an ulp or two (not bit for bit anywhere).
    check(&g, "packed cloths", &out, false);
}

/// Cloths at rest (asleep, `first_step` past the frame's steps) take no step: a world whose
/// cloths all rest records no dispatch, one with a cloth awake as many as when all step (the
/// rest sit out in their invocations); the resting cloth's state stays as it was, bit for
/// bit, while the other moves.
#[test]
fn cloths_at_rest_take_no_dispatch() {
    let Some(g) = gpu("cloths_at_rest_take_no_dispatch") else {
        return;
    };
    let sims: Vec<Simulation> = (0..3)
        .map(|_| HangingCloth::new(24).build().unwrap())
        .collect();
    let refs: Vec<&Simulation> = sims.iter().collect();
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &refs).unwrap();
    let targets: Vec<Vec<Vec<Vec3>>> = sims
        .iter()
        .map(|s| vec![s.state().pins().iter().map(|p| p.target).collect(); 2])
        .collect();
    let frame = |resting: &[bool]| {
        let mut f = GpuFrame::uniform(DT, 2, &[], &targets);
        for (c, &r) in f.cloths.iter_mut().zip(resting) {
            if r {
                c.first_step = u32::MAX;
            }
        }
        f
    };
    world.prepare(&g.device, &g.queue, &g.kernels, &frame(&[false; 3]));
    let all = world.dispatches(&g.kernels);
    world.prepare(&g.device, &g.queue, &g.kernels, &frame(&[true; 3]));
    let none = world.dispatches(&g.kernels);
    assert_eq!(none.per_frame, 0, "all at rest: {none:?}");
    let start = world.read_state(&g.device, &g.queue, 0);
    let other = world.read_state(&g.device, &g.queue, 1);
    let one = frame(&[true, false, true]);
    common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &one);
    assert_eq!(world.dispatches(&g.kernels), all, "one awake");
    assert_eq!(
        world.read_state(&g.device, &g.queue, 0),
        start,
        "a resting cloth moved"
    );
    assert_ne!(
        world.read_state(&g.device, &g.queue, 1).0,
        other.0,
        "the awake one stood still"
    );
    // The resting cloths' largest speeds are not measured; the awake one's is.
    let speeds = world.read_frame_speeds(&g.device, &g.queue);
    assert_eq!((speeds[0], speeds[2]), (0.0, 0.0));
    assert!(speeds[1] > 0.0, "{speeds:?}");
}

/// A world issues a few dispatches a substep however many colours, parts and cloths it holds:
/// at most 6 for a cloth with distance, bending, tethers, colliders and self-collision, the
/// same for one cloth and for eight, for isometric and dihedral bending alike.
#[test]
fn a_substep_takes_a_few_dispatches_for_every_cloth() {
    let Some(g) = gpu("a_substep_takes_a_few_dispatches_for_every_cloth") else {
        return;
    };
    let cloth = |n: u32, bending: BendingModel| {
        let mut scene = HangingCloth::new(n);
        scene.options.bending = bending;
        scene.features = Features {
            self_collision: Some(SelfCollision {
                thickness: 0.01,
                friction: 0.2,
            }),
            tethers: Some(TetherParams::default()),
            tear_threshold: None,
        };
        scene.build().unwrap()
    };
    let ball = [Collider::fixed(
        Shape::Sphere { radius: 0.2 },
        Pose::at(Vec3::new(0.0, -0.5, 0.0)),
        0.01,
        0.3,
    )];
    let mut counts = Vec::new();
    for (cloths, n, bending) in [
        (1, 64, BendingModel::Isometric),
        (8, 64, BendingModel::Isometric),
        (1, 96, BendingModel::Dihedral),
        (8, 32, BendingModel::Dihedral),
    ] {
        let sims: Vec<Simulation> = (0..cloths).map(|_| cloth(n, bending)).collect();
        let refs: Vec<&Simulation> = sims.iter().collect();
        let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &refs).unwrap();
        let targets: Vec<Vec<Vec<Vec3>>> = sims
            .iter()
            .map(|s| vec![s.state().pins().iter().map(|p| p.target).collect()])
            .collect();
        let frame = GpuFrame::uniform(DT, 1, &ball, &targets);
        world.prepare(&g.device, &g.queue, &g.kernels, &frame);
        let d = world.dispatches(&g.kernels);
        eprintln!("{cloths} × {n}² {bending:?}: {d:?}");
        assert!(d.per_substep <= 6, "{cloths} × {n}²: {d:?}");
        counts.push(d);
    }
    // One cloth or eight, isometric or dihedral: the same dispatches (more workgroups).
    assert_eq!(counts[0], counts[1]);
    // 10 substeps: the frame is its substeps plus a handful per step.
    assert!(
        counts[0].per_frame <= 10 * counts[0].per_substep + 6,
        "{:?}",
        counts[0]
    );
    // A step in which a cloth is carried (`ClothInertia`) adds one dispatch (the `teleport`
    // kernel at the step's start), not one a substep.
    let sims: Vec<Simulation> = (0..8).map(|_| cloth(64, BendingModel::Isometric)).collect();
    let refs: Vec<&Simulation> = sims.iter().collect();
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &refs).unwrap();
    let targets: Vec<Vec<Vec<Vec3>>> = sims
        .iter()
        .map(|s| vec![s.state().pins().iter().map(|p| p.target).collect()])
        .collect();
    let carry = [Carry {
        rotation: Quat::from_rotation_y(0.1),
        pivot: Vec3::ZERO,
        translation: Vec3::X * 0.05,
        stretch: None,
    }];
    let mut frame = GpuFrame::uniform(DT, 1, &ball, &targets);
    frame.cloths[3].carries = &carry;
    world.prepare(&g.device, &g.queue, &g.kernels, &frame);
    let carried = world.dispatches(&g.kernels);
    eprintln!("8 × 64², one carried: {carried:?}");
    assert_eq!(carried.per_frame, counts[1].per_frame + 1, "{carried:?}");
    assert_eq!(carried.per_substep, counts[1].per_substep);
    // Motion targets (skinned clothing) ride in the contact dispatch: none more where a
    // collider already needs it; alone, one a substep.
    let held = |s: &Simulation| MotionTargets {
        start: s.state().positions.clone(),
        end: s.state().positions.clone(),
        ..Default::default()
    };
    let motion = [held(&sims[0])];
    let mut frame = GpuFrame::uniform(DT, 1, &ball, &targets);
    frame.cloths[0].motion = &motion;
    world.prepare(&g.device, &g.queue, &g.kernels, &frame);
    assert_eq!(world.dispatches(&g.kernels), counts[1]);
    let plain = HangingCloth::new(64).build().unwrap();
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&plain]).unwrap();
    let pins = vec![vec![
        plain.state().pins().iter().map(|p| p.target).collect(),
    ]];
    let frame = GpuFrame::uniform(DT, 1, &[], &pins);
    world.prepare(&g.device, &g.queue, &g.kernels, &frame);
    let alone = world.dispatches(&g.kernels);
    let motion = [held(&plain)];
    let mut frame = GpuFrame::uniform(DT, 1, &[], &pins);
    frame.cloths[0].motion = &motion;
    world.prepare(&g.device, &g.queue, &g.kernels, &frame);
    let with_motion = world.dispatches(&g.kernels);
    eprintln!("64², no contacts: {alone:?}; held by motion targets: {with_motion:?}");
    assert_eq!(
        with_motion.per_frame,
        alone.per_frame + 10,
        "{with_motion:?}"
    );
    assert_eq!(with_motion.per_substep, alone.per_substep + 1);
    // On the GPU a 256² cloth has 64 parts of four rows (the 64² one 4), whose seams do not
    // overlap: all of them in one dispatch, so a substep costs the same two solve dispatches.
    assert_eq!(world.part_count(0), 4);
    let big = HangingCloth::new(256).build().unwrap();
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&big]).unwrap();
    assert_eq!(world.part_count(0), 64);
    let pins = vec![vec![big.state().pins().iter().map(|p| p.target).collect()]];
    world.prepare(
        &g.device,
        &g.queue,
        &g.kernels,
        &GpuFrame::uniform(DT, 1, &[], &pins),
    );
    let big = world.dispatches(&g.kernels);
    eprintln!("256², no contacts: {big:?}");
    assert_eq!(big, alone);
    assert_eq!(alone.per_substep, 2, "parts, then seams: {alone:?}");
}

/// The standard scene (1 m², 1 kg, two corner pins, XPBD 10 × 1) stretches on the GPU no more
/// than on the CPU backend (its own part count) — within 10 % of its max strain after 60
/// frames — at 64² and 96².
#[test]
fn the_gpu_stretches_no_more_than_the_cpu_backend() {
    let Some(g) = gpu("the_gpu_stretches_no_more_than_the_cpu_backend") else {
        return;
    };
    for n in [64, 96] {
        let mut cpu = HangingCloth::new(n).build().unwrap();
        let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&cpu]).unwrap();
        let targets = vec![vec![cpu.state().pins().iter().map(|p| p.target).collect()]];
        for _ in 0..60 {
            cpu.step(DT, &Serial);
            let frame = GpuFrame::uniform(DT, 1, &[], &targets);
            common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
        }
        let (pos, _) = world.read_state(&g.device, &g.queue, 0);
        let edges = cpu.topology().edges();
        let (on_cpu, on_gpu) = (cpu.strain().max, edge_strain(&pos, edges).max);
        eprintln!("{n}²: max strain CPU backend {on_cpu}, GPU {on_gpu}");
        assert!(
            on_gpu <= 1.1 * on_cpu,
            "{n}²: GPU {on_gpu} against CPU {on_cpu}"
        );
        assert!(
            on_gpu >= 0.5 * on_cpu,
            "{n}²: the GPU cloth did not hang ({on_gpu})"
        );
    }
}

/// The GPU's own partition (`gpu_part_count`: parts of at most 1024 vertices, so many more
/// seams than the CPU backend's 16 parts) costs the standard scene at most 10 % of max strain
/// after 60 frames at 512², where parts are two rows; CPU only (the twin steps the GPU's
/// batches), since the kernels match the twin frame by frame in the tests above. 1024² (512
/// parts) measured the same way: +6.4 %.
#[test]
fn the_gpus_partition_stretches_within_10_percent_of_the_cpus() {
    let n = 512;
    let mut cpu = HangingCloth::new(n).build().unwrap();
    let mut twin = Twin::new(&cpu);
    assert!(
        twin.batches.part_count() >= 128,
        "{}",
        twin.batches.part_count()
    );
    let targets: Vec<Vec3> = cpu.state().pins().iter().map(|p| p.target).collect();
    for _ in 0..60 {
        cpu.step(DT, &Serial);
        twin.step(&targets, Vec3::ZERO, &[], &[]);
    }
    let on_cpu = cpu.strain().max;
    let on_twin = edge_strain(&twin.state.positions, cpu.topology().edges()).max;
    eprintln!(
        "{n}²: max strain CPU backend ({} parts) {on_cpu}, GPU partition ({} parts) {on_twin}",
        cpu.batches().part_count(),
        twin.batches.part_count()
    );
    assert!(
        on_twin <= 1.1 * on_cpu,
        "GPU partition {on_twin} against {on_cpu}"
    );
}

/// The same whole run as `case`'s on its CPU twin from the same start, once per `member`,
/// each frame starting with every coordinate of every vertex moved by as much as the GPU may
/// differ from the CPU in one frame ([`rounding_bound`]), in a pseudo-random direction per
/// member: what rounding alone can make of a run that diverges chaotically.
fn rounding_ensemble(
    case: &Case,
    frames: usize,
    colliders: &[Collider],
    members: u32,
) -> Vec<Vec<Vec<Vec4>>> {
    (1..=members)
        .map(|m| {
            let mut twin = Twin::new(&case.sim);
            let mut seed = 0x9e37_79b9_u32.wrapping_mul(m);
            let mut series = Vec::with_capacity(frames);
            for k in 0..frames {
                let bound = rounding_bound(&case.sim, 1, &twin.state.positions);
                nudge(&mut twin.state.positions, &mut seed, |_| bound);
                let targets = (case.targets)(k);
                twin.step_carried(
                    &(case.carry)(k),
                    &targets,
                    Vec3::ZERO,
                    colliders,
                    &(case.air)(k),
                    (case.motion)(k).as_ref(),
                );
                series.push(twin.state.positions.clone());
            }
            series
        })
        .collect()
}

/// Whole runs, apart for 60 frames from the same start: trajectories part (Gauss–Seidel
/// amplifies rounding), what they add up to does not beyond what rounding alone makes of it.
/// The largest and mean strain and the centroid of the GPU's run must lie within the range of
/// eight CPU runs nudged by one frame's rounding bound every frame, widened by that range on
/// either side (for a ninth sample of the same spread, a miss is a few standard deviations
/// out); and no vertex deeper in the floor than its thickness. On an H100 the CPU and GPU
/// runs ended 15 cm apart, max strain 0.896 against 0.944: a fixed 5 % failed.
#[test]
fn whole_runs_agree_in_what_does_not_diverge() {
    let Some(g) = gpu("whole_runs_agree_in_what_does_not_diverge") else {
        return;
    };
    let n = 40;
    let frames = 60;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    let start = corners(&mut s, n);
    let len = s.state().len();
    let edges = s.topology().edges().to_vec();
    let mut case = Case::new(s);
    case.targets = Box::new(move |k| {
        let shift = Vec3::new(0.2 * (k as f32 * 0.15).sin(), 0.0, 0.0);
        start.iter().map(|p| *p + shift).collect()
    });
    case.air = Box::new(move |k| {
        (0..len)
            .map(|i| {
                Vec4::new(
                    4.0 + (i % 5) as f32 * 0.3,
                    0.0,
                    2.0 * (k as f32 * 0.1).cos(),
                    0.0,
                )
            })
            .collect()
    });
    let floor = vec![Collider::fixed(
        Shape::Plane,
        Pose::at(Vec3::new(0.0, -0.3, 0.0)),
        0.01,
        0.5,
    )];
    let cases = [case];
    let out = compare(&g, &cases, frames, 1, |_| floor.clone(), false);
    let mut runs = rounding_ensemble(&cases[0], frames, &floor, 8);
    runs.push(out.frames_cpu.clone());
    let centroid = |p: &[Vec4]| p.iter().map(|v| v.truncate()).sum::<Vec3>() / p.len() as f32;
    let depth = |p: &[Vec4]| p.iter().map(|v| (-0.3 - v.y).max(0.0)).fold(0.0, f32::max);
    // Averaged over the run: the frames before the runs part weigh in.
    let stats = |series: &[Vec<Vec4>]| {
        let mut sum = [0.0f64; 5];
        for p in series {
            let e = edge_strain(p, &edges);
            let c = centroid(p);
            for (s, x) in sum.iter_mut().zip([e.max, e.mean, c.x, c.y, c.z]) {
                *s += f64::from(x);
            }
        }
        sum.map(|s| (s / series.len() as f64) as f32)
    };
    let names = [
        "max strain",
        "mean strain",
        "centroid x",
        "centroid y",
        "centroid z",
    ];
    let on_gpu = stats(&out.frames_gpu);
    let ensemble: Vec<[f32; 5]> = runs.iter().map(|r| stats(r)).collect();
    let gpu_pos = out.frames_gpu.last().expect("frames");
    let apart = out
        .frames_cpu
        .last()
        .expect("frames")
        .iter()
        .zip(gpu_pos)
        .map(|(a, b)| (a.truncate() - b.truncate()).length())
        .fold(0.0, f32::max);
    eprintln!("whole run: trajectories {apart} m apart at the end; averaged over the run:");
    for (q, name) in names.iter().enumerate() {
        let lo = ensemble.iter().map(|s| s[q]).fold(f32::INFINITY, f32::min);
        let hi = ensemble
            .iter()
            .map(|s| s[q])
            .fold(f32::NEG_INFINITY, f32::max);
        // The range, and a floor of a few roundings of the quantity for runs that do not part.
        let w = (hi - lo).max(8.0 * f32::EPSILON * lo.abs().max(hi.abs()));
        eprintln!(
            "{name}: GPU {} CPU {}, rounding ensemble {lo} … {hi}",
            on_gpu[q],
            ensemble.last().expect("the CPU run")[q]
        );
        assert!(
            on_gpu[q] >= lo - w && on_gpu[q] <= hi + w,
            "{name}: GPU {} outside {lo} … {hi} widened by {w}",
            on_gpu[q]
        );
    }
    assert!(
        depth(gpu_pos) <= 0.01 + 1e-4,
        "a GPU vertex sank into the floor"
    );
}

/// The mesh kernel (`mesh.wgsl`) against the CPU write-back (`MeshBinding::update_shading`
/// and `cloth::writeback`'s world → local): a folded sheet with a hard crease (copies with
/// different normals: two normal groups) and a UV seam (copies with the same normal: one
/// group), read from behind another cloth's particles and written from vertex 5 of a slab, through a rotated, scaled, moved transform and a
/// mirrored one; and drawn along its velocities (`ClothSmoothing`: `ClothSmoothing::place`
/// with a shift back and one ahead, and with a carried motion's velocity added).
#[test]
fn the_mesh_kernel_matches_the_cpu_write_back() {
    use bevy::math::{Affine3A, Vec2};
    use bevy_cloth::cloth::ClothSmoothing;
    use bevy_cloth::gpu::mesh::{DrawShift, MeshKernel, MeshWriter, TangentSource, VertexLayout};
    use bevy_cloth::solver::{MeshAttributes, MeshBinding};
    use wgpu::util::DeviceExt;
    let Some(Gpu { device, queue, .. }) = gpu("the_mesh_kernel_matches_the_cpu_write_back") else {
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
    // Behind another cloth's particles in the state buffer: the writer reads from its base.
    let base = 7u32;
    let particles: Vec<Vec4> = weld
        .gather(&positions)
        .iter()
        .map(|p| (*p + Vec3::Y * (0.03 * (9.0 * p.x + 5.0 * p.z).sin())).extend(1.0))
        .collect();
    // Velocities after the particles (a velocity region), swirling at up to 2 m/s.
    let velocities: Vec<Vec4> = particles
        .iter()
        .map(|p| Vec3::new(2.0 * (7.0 * p.z).cos(), -1.5, 1.0 * (4.0 * p.x).sin()).extend(0.0))
        .collect();
    let drawn: Vec<u32> = binding.drawn_indices().collect();
    let mut buffer = vec![Vec4::splat(f32::NAN); base as usize];
    buffer.extend_from_slice(&particles);
    let velocity_base = buffer.len() as u32;
    buffer.extend_from_slice(&velocities);
    let state = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&buffer),
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
    let writer = MeshWriter::new(&device, &weld, &drawn, layout, Some(&source), None)
        .expect("a small mesh fits");
    let first = 5u32;
    let m = positions.len();
    let bytes = u64::from(layout.stride) * (u64::from(first) + m as u64);
    let turned = Affine3A::from_scale_rotation_translation(
        Vec3::new(1.5, 0.7, 1.1),
        Quat::from_euler(bevy::math::EulerRot::XYZ, 0.3, -0.8, 0.2),
        Vec3::new(2.0, -1.0, 0.5),
    );
    let mirrored = Affine3A::from_scale_rotation_translation(
        Vec3::new(-1.0, 1.0, 1.0),
        Quat::from_rotation_y(0.4),
        Vec3::new(-3.0, 0.0, 1.0),
    );
    // Shifts as `ClothSmoothing` gives them at a 60 Hz step: interpolated 0.3 of the way
    // (0.7 of a step back), extrapolated 0.6 of a step ahead.
    let step = 1.0 / 60.0;
    let back = ClothSmoothing::Interpolate.shift(step, 0.3);
    let ahead = ClothSmoothing::Extrapolate.shift(step, 0.6);
    assert!(back < 0.0 && ahead > 0.0);
    // A motion carried into the step (`ClothInertia`): a turn about a point and a move.
    let carried = bevy_cloth::solver::Carry::unfelt(
        (Vec3::new(0.3, 0.0, 0.3), Quat::IDENTITY),
        (Vec3::new(0.35, 0.02, 0.28), Quat::from_rotation_y(0.05)),
        0.0,
        0.0,
    )
    .and_then(|c| c.velocity(step));
    assert!(carried.is_some());
    for (transform, shift, carried) in [
        (turned, 0.0, None),
        (mirrored, 0.0, None),
        (turned, back, None),
        (mirrored, ahead, None),
        (turned, back, carried),
    ] {
        let drawn_particles: Vec<Vec4> = particles
            .iter()
            .zip(&velocities)
            .map(|(p, v)| {
                let v = *v
                    + carried
                        .map_or(Vec3::ZERO, |c| c.at(p.truncate()))
                        .extend(0.0);
                ClothSmoothing::place(*p, v, shift)
            })
            .collect();
        binding.update_shading(&drawn_particles);
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
            base,
            &slab,
            first,
            transform,
            (shift != 0.0).then_some(DrawShift {
                velocity_base,
                seconds: shift,
                carried,
            }),
            None,
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
                to_local.transform_point3(drawn_particles[weld.particles()[v] as usize].truncate());
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
            "mesh kernel, shift {shift} s: worst position {worst_p} m, worst normal {worst_n}, \
             worst tangent {worst_t}"
        );
        // f32 rounding of a 4×4 product against glam's affine (a few ulp of ~3 m) and of a
        // normalised sum of face normals.
        assert!(worst_p < 1e-5, "positions differ by {worst_p} m");
        assert!(worst_n < 1e-4, "normals differ by {worst_n}");
        assert!(worst_t < 1e-4, "tangents differ by {worst_t}");
    }
}

/// The tear check (`tear_check`, `tear_release`) against `tear::overstretched_edges` and
/// `Topology::without_edges`, and what a torn edge does against its CPU twin
/// (`ConstraintBatches::release_edges`): a cloth with air drag and self-collision pulled by
/// its corners, threshold 1.6. The GPU's flag rises in the frame the CPU first finds an edge
/// past it; the edges it tears are the CPU's, but for an edge within rounding of the
/// threshold, and the edges it lets go of are exactly those the CPU's torn topology no longer
/// has; from the next step on, their distance constraints hold nothing on both sides
/// (neither rebuilds its constraints here: the plugin does that on the CPU), the torn
/// triangles count in neither the air's areas nor self-collision (the twin steps on the torn
/// topology; with them left in on the GPU the positions part by 2 mm and 3 cm), and the
/// positions agree within rounding while the tear runs through the cloth. Each frame starts
/// from the CPU's state, so the frame compared is one step's.
#[test]
fn the_tear_check_and_the_torn_edges_match_the_cpu() {
    let Some(g) = gpu("the_tear_check_and_the_torn_edges_match_the_cpu") else {
        return;
    };
    let n = 16;
    let threshold = 1.6;
    let mut s = sim(n, SolverParams::default(), |p| {
        Vec3::new(p.x, 1.0 - (p.z + 0.5), 0.0)
    });
    s.set_features(Features {
        tear_threshold: Some(threshold),
        self_collision: Some(SelfCollision {
            thickness: 1.0 / (n - 1) as f32,
            friction: 0.2,
        }),
        ..Default::default()
    })
    .unwrap();
    let start = corners(&mut s, n);
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&s]).unwrap();
    let mut twin = Twin::new(&s);
    // The twin steps on the topology without the torn triangles (the air's areas leave them
    // out, as the GPU's do); the edges keep their slots in the full one.
    let full = twin.topology.clone();
    let edge_index: std::collections::HashMap<[u32; 2], u32> = full
        .edges()
        .iter()
        .enumerate()
        .map(|(i, e)| (e.v, i as u32))
        .collect();
    let (mut cpu_first, mut gpu_first) = (None, None);
    let (mut torn_frames, mut worst) = (0, 0.0f32);
    let mut torn: Vec<[u32; 2]> = Vec::new();
    let mut released: Vec<[u32; 2]> = Vec::new();
    let mut released_hinges = 0;
    for k in 0..60 {
        // The corners move apart 2 cm a step.
        let t: Vec<Vec3> = start
            .iter()
            .enumerate()
            .map(|(i, p)| *p + Vec3::X * (0.02 * k as f32 * if i == 0 { -1.0 } else { 1.0 }))
            .collect();
        world.upload(&g.queue, 0, &twin.state.positions, &twin.state.velocities);
        let bound = rounding_bound(&s, 1, &twin.state.positions);
        twin.step(&t, Vec3::ZERO, &[], &[]);
        let targets = [vec![t]];
        let frame = GpuFrame::uniform(DT, 1, &[], &targets);
        common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
        let cpu = &twin.state.positions;
        let (gpu_positions, _) = world.read_state(&g.device, &g.queue, 0);
        let diff = cpu
            .iter()
            .zip(&gpu_positions)
            .map(|(a, b)| (a.truncate() - b.truncate()).abs().max_element())
            .fold(0.0f32, f32::max);
        assert!(
            diff <= bound,
            "step {k} ({} torn edges): positions differ by {diff} m, rounding allows {bound}",
            torn.len()
        );
        if !torn.is_empty() {
            torn_frames += 1;
            worst = worst.max(diff / bound);
        }
        // What the tear check tears: the CPU's overstretched edges among those not let go of
        // yet (torn edges stay torn), but for an edge within rounding of the threshold.
        let mut over = bevy_cloth::solver::overstretched_edges(cpu, full.edges(), threshold);
        over.retain(|e| !released.contains(e));
        over.extend(torn.iter().copied());
        over.sort_unstable();
        let gpu_torn = world.read_torn_edges(&g.device, &g.queue, 0);
        let mut flagged = gpu_torn.torn.clone();
        flagged.sort_unstable();
        for e in symmetric_difference(&over, &flagged) {
            let rest = full.edges()[edge_index[&e] as usize].rest;
            let len = cpu[e[0] as usize]
                .truncate()
                .distance(cpu[e[1] as usize].truncate());
            // Each end may differ by the rounding bound, so the length by twice it (plus the
            // length's and the threshold's own rounding, a few ε of them).
            let limit = threshold * rest;
            let slack = 2.0 * bound + 4.0 * f32::EPSILON * limit;
            assert!(
                (len - limit).abs() <= slack,
                "step {k}: edge {e:?} is {len} m against {limit} m (±{slack}), flagged on one \
                 side only"
            );
        }
        if !over.is_empty() && cpu_first.is_none() {
            cpu_first = Some(k);
        }
        if world.read_status(&g.device, &g.queue, 0).1 && gpu_first.is_none() {
            gpu_first = Some(k);
        }
        // What lets go: the torn edges and those the torn topology has no more. The twin
        // holds what the GPU tore (the two stay in step where an edge sits on the threshold
        // itself).
        let (cpu_released, hinges) = tear_twin(&mut twin, &full, &flagged);
        let mut gpu_released = gpu_torn.released;
        gpu_released.sort_unstable();
        assert_eq!(gpu_released, cpu_released, "step {k}: edges let go of");
        torn = flagged;
        released = gpu_released;
        released_hinges = hinges;
    }
    eprintln!(
        "first overstretched step: CPU {cpu_first:?}, GPU {gpu_first:?}; {} edges torn, {} let go \
         of, {released_hinges} hinges; {torn_frames} steps compared with torn edges, worst \
         {worst:.3} of the rounding bound",
        torn.len(),
        released.len()
    );
    assert!(released_hinges > 0, "a tear must take hinges with it");
    assert!(
        cpu_first.is_some_and(|k| k > 5),
        "the scene must start untorn"
    );
    assert_eq!(gpu_first, cpu_first);
    assert!(
        torn.len() >= 4 && torn_frames > 10,
        "the tear must run through the cloth: {} edges in {torn_frames} steps",
        torn.len()
    );
}

/// Tears `twin` as the GPU tears its cloth until the host rebuilds it: from `full` (the
/// topology the GPU was built with) the sorted edges `torn` and the triangles they bound leave
/// the twin's topology, and their distance constraints and hinges hold nothing (the
/// constraints keep their slots in `full`). Returns the edges let go of (sorted: the torn ones
/// and those left without a triangle) and the number of hinges let go of.
fn tear_twin(twin: &mut Twin, full: &Topology, torn: &[[u32; 2]]) -> (Vec<[u32; 2]>, usize) {
    let kept = full.without_edges(torn);
    let mut released: Vec<[u32; 2]> = full
        .edges()
        .iter()
        .map(|e| e.v)
        .filter(|v| !kept.edges().iter().any(|k| k.v == *v))
        .collect();
    released.sort_unstable();
    let slots: Vec<u32> = (0..full.edges().len() as u32)
        .filter(|&i| released.binary_search(&full.edges()[i as usize].v).is_ok())
        .collect();
    twin.batches.release_edges(&slots);
    // And the hinges that lost a triangle to a torn edge.
    let has_torn_edge = |t: [u32; 3]| {
        (0..3).any(|k| {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            torn.binary_search(&[a.min(b), a.max(b)]).is_ok()
        })
    };
    let hinges: Vec<u32> = (0..full.bends().len() as u32)
        .filter(|&i| {
            let v = full.bends()[i as usize].v;
            has_torn_edge([v[0], v[1], v[2]]) || has_torn_edge([v[0], v[1], v[3]])
        })
        .collect();
    twin.batches.release_bends(&hinges);
    twin.topology = kept;
    (released, hinges.len())
}

/// The vertex pairs in one sorted list and not the other.
fn symmetric_difference(a: &[[u32; 2]], b: &[[u32; 2]]) -> Vec<[u32; 2]> {
    let mut out: Vec<[u32; 2]> = a
        .iter()
        .filter(|e| b.binary_search(e).is_err())
        .chain(b.iter().filter(|e| a.binary_search(e).is_err()))
        .copied()
        .collect();
    out.sort_unstable();
    out
}

/// A 40² PBD cloth (six substeps of two iterations) over `collider_shapes`.
fn pbd_over_colliders() -> Simulation {
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
    sim(40, params, |p| p * 1.5 + Vec3::new(0.0, 0.45, 0.0))
}

/// A 21² cloth on the lab solver (two substeps, 32 iterations) whose two pinned corners
/// slide along x.
fn lab_sliding() -> Case {
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
    let mut case = Case::new(s);
    case.targets = sliding(start, Vec3::X * 0.005);
    case
}

/// The lab solver (seed 000's Jacobi averaging: velocity keep, 32 iterations of averaged edge
/// projections) against the CPU's `lab_step`, two substeps per step, two moving pins. Bit for
/// bit on llvmpipe.
#[test]
fn the_lab_solver_matches_the_cpu() {
    let Some(g) = gpu("the_lab_solver_matches_the_cpu") else {
        return;
    };
    let out = compare(&g, &[lab_sliding()], 40, 1, |_| Vec::new(), true);
    check(&g, "lab", &out, true);
}

/// A device that allows four workgroups per dimension (WebGPU allows 65 535, which a world of
/// 4.2 million vertices, or 1.4 million with tearing, passes): every dispatch of more than four
/// workgroups is split over y and z (`flat_groups`) and each kernel takes its linear index
/// from all three (`flat_id`); the world's vertices, constraint groups and impulse slots
/// must come out as with one row, so the cloths on colliders (impulses summed per
/// workgroup), folded onto themselves (self-collision) and on the lab solver match their CPU
/// twins as in the tests above (bit for bit on llvmpipe). A dispatch left unsplit fails
/// wgpu's validation.
#[test]
fn kernels_dispatched_over_three_dimensions_match_the_cpu() {
    let limits = wgpu::Limits {
        max_compute_workgroups_per_dimension: 4,
        ..wgpu::Limits::default()
    };
    let Some(g) = gpu_with_limits(
        "kernels_dispatched_over_three_dimensions_match_the_cpu",
        limits,
    ) else {
        return;
    };
    assert_eq!(g.device.limits().max_compute_workgroups_per_dimension, 4);
    // 1 600 vertices: 25 workgroups, dispatched as 4 × 4 × 2.
    colliders_match(&g, 20, "colliders, split dispatches");
    folded_cloth_self_collides(
        &g,
        Some(1.0),
        false,
        "self-collision, split dispatches",
        0,
        0,
    );
    let out = compare(&g, &[lab_sliding()], 40, 1, |_| Vec::new(), true);
    check(&g, "lab, split dispatches", &out, true);
}

/// A device that binds at most 1 MiB: a frame whose mesh collider's SDF grid (72³ samples,
/// 1.4 MiB) does not fit takes no step and says why, with no validation error (a raw wgpu
/// device panics on one); the next frame, without that collider, steps.
#[test]
fn a_frame_whose_inputs_do_not_fit_the_device_takes_no_step() {
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 1 << 20,
        ..wgpu::Limits::default()
    };
    let Some(g) = gpu_with_limits(
        "a_frame_whose_inputs_do_not_fit_the_device_takes_no_step",
        limits,
    ) else {
        return;
    };
    let n = 12;
    let mut s = sim(n, SolverParams::default(), |p| p + Vec3::Y);
    let start = corners(&mut s, n);
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&s]).expect("it fits");
    let (positions, indices) = common::subdivided_cube(1, 0.4, Vec3::ZERO);
    let grid = Arc::new(SdfGrid::from_mesh(&positions, &indices, 72).unwrap());
    assert!(
        grid.values().len() * 4 > 1 << 20,
        "the grid passes the limit"
    );
    let big = vec![Collider {
        shape: Shape::Mesh(grid),
        start: Pose::default(),
        end: Pose::default(),
        thickness: 0.01,
        friction: 0.0,
    }];
    let targets = vec![vec![start]];
    let y = |world: &GpuWorld| -> f32 {
        let (p, _) = world.read_state(&g.device, &g.queue, 0);
        p.iter().map(|p| p.y).sum::<f32>() / p.len() as f32
    };
    let before = y(&world);
    let frame = GpuFrame::uniform(DT, 1, &big, &targets);
    common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
    assert_eq!(world.steps(), 0, "a frame that does not fit takes no step");
    let why = world.inputs_too_large().expect("it says why");
    assert!(why.contains("SDF grids"), "{why}");
    assert_eq!(y(&world), before, "the cloth held still");
    let frame = GpuFrame::uniform(DT, 1, &[], &targets);
    common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
    assert_eq!(world.steps(), 1);
    assert!(world.inputs_too_large().is_none());
    assert!(y(&world) < before, "the cloth fell a step");
}

/// The torn triangles a GPU cloth hides (`hide.wgsl`) against its CPU twin
/// (`hide_torn_triangles`) and against what the CPU's tear removes from the drawn mesh
/// (`Topology::without_edges`, `MeshBinding::retain`): a cloth pulled apart (and out of its
/// plane) by its corners on the GPU alone, drawn through a mesh whose triangles are listed
/// backwards with their corners turned (so the writer's map from drawn to cloth triangles is
/// not the identity), held in a 32-bit and a 16-bit index slab from an odd index on, between
/// sentinels. Every frame the slabs must equal the twin's lists bit for bit, their drawn
/// triangles must be the CPU's after tearing what the GPU tore, and the sentinels (another
/// mesh's indices, one sharing a word with the first 16-bit index) must stay; the mesh
/// kernel's normals, with the dead-triangle flags, must be the CPU shading's of what it
/// still draws (within the rounding the mesh kernel's own test allows; with the torn
/// triangles left in they differ by 0.07 from the first torn frame). A slab that already
/// holds the host's new list is left as it is.
#[test]
fn torn_triangles_leave_the_drawn_mesh_as_on_the_cpu() {
    use bevy_cloth::gpu::mesh::{
        MeshKernel, MeshWriter, VertexLayout, drawn_cloth_triangles, hide_torn_triangles,
    };
    use bevy_cloth::solver::{MeshAttributes, MeshBinding};
    use wgpu::util::DeviceExt;
    let Some(g) = gpu("torn_triangles_leave_the_drawn_mesh_as_on_the_cpu") else {
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
    let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&s]).unwrap();
    // The mesh: the grid's triangles backwards, each one's corners turned.
    let grid = Grid::new(n, n, 1.0, 1.0);
    let positions: Vec<Vec3> = s.state().positions.iter().map(|p| p.truncate()).collect();
    let indices: Vec<u32> = grid
        .indices()
        .chunks_exact(3)
        .rev()
        .flat_map(|t| [t[1], t[2], t[0]])
        .collect();
    let mut binding = MeshBinding::new(
        &positions,
        MeshAttributes {
            normals: None,
            uvs: None,
            tangents: None,
        },
        &indices,
        1e-6,
    )
    .unwrap();
    let drawn: Vec<u32> = binding.drawn_indices().collect();
    let cloth_triangles = drawn_cloth_triangles(binding.weld(), &drawn, s.topology().triangles());
    assert!(
        cloth_triangles.iter().all(|&t| t != u32::MAX),
        "every drawn triangle is a cloth triangle"
    );
    assert_ne!(
        cloth_triangles,
        (0..cloth_triangles.len() as u32).collect::<Vec<_>>(),
        "the map must not be the identity"
    );
    let kernel = MeshKernel::new(&g.device);
    let layout = VertexLayout {
        stride: 24,
        position: 0,
        normal: 12,
        tangent: None,
    };
    let writer = MeshWriter::new(
        &g.device,
        binding.weld(),
        &drawn,
        layout,
        None,
        Some(&cloth_triangles),
    )
    .expect("a small mesh fits");
    // The vertex slab the writer writes its positions and normals into.
    let vertex_bytes = u64::from(layout.stride) * positions.len() as u64;
    let vertex_slab = g.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: vertex_bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut worst_normal = 0.0f32;
    // Slabs: 7 indices of another mesh, this mesh's, then 5 more.
    let first = 7usize;
    let sentinel = |i: usize| 0x1234 + i as u32;
    let mut list: Vec<u32> = (0..first).map(sentinel).collect();
    list.extend_from_slice(&drawn);
    list.extend((0..5).map(|i| sentinel(100 + i)));
    let make = |bytes: &[u8]| {
        g.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::INDEX
                    | wgpu::BufferUsages::COPY_SRC,
            })
    };
    let u16_list: Vec<u16> = list.iter().map(|&i| i as u16).collect();
    let mut u16_bytes: Vec<u8> = bytemuck::cast_slice(&u16_list).to_vec();
    u16_bytes.resize(u16_bytes.len().div_ceil(4) * 4, 0);
    let slab32 = make(bytemuck::cast_slice(&list));
    let slab16 = make(&u16_bytes);
    let read = |buffer: &wgpu::Buffer| -> Vec<u8> {
        let staging = g.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: buffer.size(),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = g.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
        g.queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, .., |_| {});
        let _ = g.device.poll(wgpu::PollType::wait_indefinitely());
        staging.get_mapped_range(..).to_vec()
    };
    let dead_at = world
        .dead_triangle_flags(0)
        .expect("a tearing cloth has dead flags");
    // The hiding pass into `slab`, one submission each (a record writes the writer's
    // parameters through the queue).
    let hide = |world: &GpuWorld, slab: &wgpu::Buffer, u16_indices: bool| {
        let mut encoder = g.device.create_command_encoder(&Default::default());
        writer.record_hide_torn(
            &g.device,
            &g.queue,
            &kernel,
            &mut encoder,
            world.scratch_buffer(),
            dead_at,
            slab,
            first as u32,
            u16_indices,
        );
        g.queue.submit([encoder.finish()]);
    };
    let mut twin = list.clone();
    let (mut hidden, mut torn_frames) = (0, 0);
    for k in 0..60 {
        let t: Vec<Vec3> = start
            .iter()
            .enumerate()
            .map(|(i, p)| {
                // Apart, and one corner forward: the cloth leaves its plane.
                let forward = if i == 0 {
                    Vec3::Z * (0.01 * k as f32)
                } else {
                    Vec3::ZERO
                };
                *p + Vec3::X * (0.02 * k as f32 * if i == 0 { -1.0 } else { 1.0 }) + forward
            })
            .collect();
        let targets = [vec![t]];
        let frame = GpuFrame::uniform(DT, 1, &[], &targets);
        world.prepare(&g.device, &g.queue, &g.kernels, &frame);
        let mut encoder = g.device.create_command_encoder(&Default::default());
        world.record(&mut encoder, &g.kernels);
        writer.record(
            &g.device,
            &g.queue,
            &kernel,
            &mut encoder,
            world.state_buffer(),
            world.vertex_base(0),
            &vertex_slab,
            0,
            bevy::math::Affine3A::IDENTITY,
            None,
            Some((world.scratch_buffer(), dead_at)),
        );
        g.queue.submit([encoder.finish()]);
        hide(&world, &slab32, false);
        hide(&world, &slab16, true);
        // The twin: the triangles with an edge the GPU tore are dead.
        let torn = world.read_torn_edges(&g.device, &g.queue, 0).torn;
        let dead: Vec<u32> = s
            .topology()
            .triangles()
            .iter()
            .map(|t| {
                u32::from((0..3).any(|c| {
                    let (a, b) = (t[c], t[(c + 1) % 3]);
                    torn.contains(&[a.min(b), a.max(b)])
                }))
            })
            .collect();
        hide_torn_triangles(&mut twin[first..], &drawn, &cloth_triangles, &dead);
        let got32: Vec<u32> = bytemuck::pod_collect_to_vec(&read(&slab32));
        let got16: Vec<u16> = bytemuck::pod_collect_to_vec(&read(&slab16));
        let differ = |a: &[u32], b: &[u32]| a.iter().zip(b).position(|(x, y)| x != y);
        assert!(
            got32 == twin,
            "frame {k}: the 32-bit slab differs from the twin from index {:?} on",
            differ(&got32, &twin)
        );
        let got16: Vec<u32> = got16[..twin.len()].iter().map(|&i| u32::from(i)).collect();
        assert!(
            got16 == twin,
            "frame {k}: the 16-bit slab differs from the twin from index {:?} on",
            differ(&got16, &twin)
        );
        // What the CPU's tear leaves drawn is what the GPU still draws.
        binding.retain(&s.topology().without_edges(&torn));
        let kept: Vec<u32> = twin[first..first + drawn.len()]
            .chunks_exact(3)
            .filter(|t| *t != [0, 0, 0])
            .flatten()
            .copied()
            .collect();
        assert_eq!(
            kept,
            binding.drawn_indices().collect::<Vec<_>>(),
            "frame {k}: drawn triangles against the CPU's tear"
        );
        // The normals leave the torn triangles out, as the CPU's shading of what it draws.
        let (particles, _) = world.read_state(&g.device, &g.queue, 0);
        binding.update_shading(&particles);
        let written: Vec<f32> = bytemuck::pod_collect_to_vec(&read(&vertex_slab));
        let floats = (layout.stride / 4) as usize;
        for (v, want) in binding.shading().normals().iter().enumerate() {
            let n = Vec3::from_slice(&written[v * floats + 3..v * floats + 6]);
            worst_normal = worst_normal.max((n - *want).length());
        }
        // Rounding of a normalised sum of a few face normals (as in the mesh kernel's test);
        // a torn triangle left in would turn a normal by far more.
        assert!(
            worst_normal < 1e-4,
            "frame {k}: normals differ from the CPU's by {worst_normal}"
        );
        hidden = drawn.len() / 3 - binding.drawn_count();
        torn_frames += usize::from(!torn.is_empty());
    }
    eprintln!(
        "{hidden} of {} triangles hidden; {torn_frames} frames with torn edges; worst normal \
         {worst_normal}",
        drawn.len() / 3
    );
    assert!(
        hidden >= 4 && hidden < drawn.len() / 3 && torn_frames > 10,
        "the tear must run through the cloth: {hidden} triangles hidden in {torn_frames} frames"
    );
    // A slab that already holds the host's new list (the torn triangles gone) is not touched.
    let mut replaced: Vec<u32> = (0..first).map(sentinel).collect();
    replaced.extend(binding.drawn_indices());
    replaced.resize(list.len(), 0);
    let slab = make(bytemuck::cast_slice(&replaced));
    hide(&world, &slab, false);
    let got: Vec<u32> = bytemuck::pod_collect_to_vec(&read(&slab));
    assert_eq!(got, replaced, "a replaced index list must stay as it is");
}

/// A change of solver or substeps *settles* on the GPU as on the CPU (`settle_*` in
/// `step_end.wgsl` against `Simulation::step_in`): a 24² cloth hung for a second at the old
/// settings, changed, then one step a frame from the CPU's state (an upload leaves the GPU's
/// settle going). After every step both have the same steps left, the same largest strain and
/// the same velocities, within what rounding allows (the strain: two positions' bound over the
/// shortest rest edge; a velocity: two positions' bound over the substep). A frame whose CPU
/// decision lies within that of the threshold (0.01 less strain than the step before) ends
/// the comparison of the counters. At the sixth frame the cloth moves into a world rebuilt
/// around the same upload with another cloth (`record_carry` with its settle): the settle goes
/// on where it was instead of starting again. Without the settle kernels the GPU's steps left
/// stay at 60 and its vertices are not held back (the first frame fails).
#[test]
fn a_settings_change_settles_as_on_the_cpu() {
    let Some(g) = gpu("a_settings_change_settles_as_on_the_cpu") else {
        return;
    };
    let coarse = SolverParams {
        substeps: 2,
        ..Default::default()
    };
    let fine = SolverParams {
        substeps: 20,
        ..Default::default()
    };
    let lab = SolverParams {
        solver: Solver::LAB,
        substeps: 1,
        iterations: 32,
        ..Default::default()
    };
    for (from, to) in [
        (coarse, fine),
        (lab, SolverParams::default()),
        (SolverParams::default(), lab),
    ] {
        let what = format!(
            "{} {}×{} → {} {}×{}",
            from.solver.name(),
            from.substeps,
            from.iterations,
            to.solver.name(),
            to.substeps,
            to.iterations
        );
        let n = 24;
        let mut cpu = sim(n, from, |p| p + Vec3::Y);
        let targets = corners(&mut cpu, n);
        for _ in 0..60 {
            cpu.step(DT, &Serial);
        }
        cpu.set_params(to).unwrap();
        let upload = cpu.clone();
        let other = sim(6, to, |p| p + 3.0 * Vec3::Y);
        let mut world = GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&upload]).unwrap();
        cpu.set_part_count(world.part_count(0));
        let shortest = cpu
            .topology()
            .edges()
            .iter()
            .map(|e| e.rest)
            .fold(f32::INFINITY, f32::min);
        let h = DT / to.substeps as f32;
        let (mut frames, mut worst_v) = (0, 0.0f32);
        let mut counting = true;
        loop {
            if frames == 5 {
                let mut rebuilt =
                    GpuWorld::new(&g.device, &g.queue, &g.kernels, &[&upload, &other]).unwrap();
                assert_eq!(rebuilt.part_count(0), world.part_count(0));
                let mut encoder = g.device.create_command_encoder(&Default::default());
                rebuilt.record_carry(&mut encoder, &world, 0, 0, true);
                g.queue.submit([encoder.finish()]);
                world = rebuilt;
            }
            let cloths = world.cloths();
            world.upload(&g.queue, 0, &cpu.state().positions, &cpu.state().velocities);
            let before = cpu.state().positions.clone();
            let last_strain = cpu.settle_state().1;
            let mut pins = vec![vec![targets.clone()]];
            pins.resize(cloths, vec![Vec::new()]);
            let frame = GpuFrame::uniform(DT, 1, &[], &pins);
            common::run_gpu_frame(&mut world, &g.device, &g.queue, &g.kernels, &frame);
            cpu.step(DT, &Serial);
            frames += 1;
            let (pos, vel) = world.read_state(&g.device, &g.queue, 0);
            let bound = rounding_bound(&upload, 1, &before);
            let s = cpu.state();
            for (a, b) in pos.iter().zip(&s.positions) {
                let e = (a.truncate() - b.truncate()).length();
                assert!(e <= bound, "{what}, frame {frames}: a position {e} m off");
            }
            for (a, b) in vel.iter().zip(&s.velocities) {
                let e = (*a - *b).length();
                let allowed = 2.0 * bound / h + 4.0 * f32::EPSILON * b.length();
                worst_v = worst_v.max(e / allowed);
                assert!(
                    e <= allowed,
                    "{what}, frame {frames}: a velocity {e} m/s off (allowed {allowed}): {a} against {b}"
                );
            }
            let (left, strain) = world.read_settle(&g.device, &g.queue, 0);
            let (cpu_left, cpu_strain) = cpu.settle_state();
            let strain_bound = 2.0 * bound / shortest;
            if counting {
                if (cpu_strain - (last_strain - 0.01)).abs() <= strain_bound {
                    eprintln!("{what}, frame {frames}: the decision is within rounding");
                    counting = false;
                } else {
                    assert_eq!(left, cpu_left, "{what}, frame {frames}: steps left");
                }
            }
            if cpu_left > 0 || left > 0 {
                assert!(
                    (strain - cpu_strain).abs() <= strain_bound,
                    "{what}, frame {frames}: strain {strain} against {cpu_strain}"
                );
            }
            if cpu_left == 0 && left == 0 {
                break;
            }
            assert!(
                frames <= bevy_cloth::solver::MAX_SETTLE_STEPS,
                "{what}: still settling after {frames} steps ({left} left on the GPU)"
            );
        }
        eprintln!(
            "{what}: settled in {frames} steps, velocities within {worst_v} of the rounding bound"
        );
        assert!(frames >= bevy_cloth::solver::SETTLE_STEPS, "{what}");
    }
}
