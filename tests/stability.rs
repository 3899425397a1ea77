//! Stability at the extremes: every solver, with collisions, wind, tearing and self-collision,
//! across time steps, counts, stiffnesses, masses, scales, broken meshes and violent
//! disturbances. Nothing non-finite may leave the solver, the kinetic energy stays under its
//! bound `½·M·max_speed²` (M: total free mass), and the cloth settles when the disturbance
//! stops.
//!
//! Property tests sample the ranges; named tests pin the corners and every case the property
//! tests ever found (see `regression_*`). The `*_on_the_gpu` tests run the same scenarios on
//! the GPU backend's kernels (llvmpipe in CI; skipped with a message without an adapter,
//! failing with `CLOTH_REQUIRE_GPU=1`): the same invariants, read back after every step.

use std::sync::Arc;

mod common;

use bevy_cloth::gpu::{ClothFrame, GpuFrame, GpuKernels, GpuWorld, StepColliders};
use bevy_cloth::solver::{
    AirGrid, Collider, Environment, Features, Grid, MeshShading, Pin, Pose, SYMMETRIC_SWEEP_DEGREE,
    SdfGrid, SelfCollision, Serial, Shape, Simulation, Solver, SolverParams, TetherParams,
    Topology, TopologyError, TopologyOptions, WindField, WindParams,
};
use glam::{Quat, Vec2, Vec3};
use proptest::prelude::*;

/// Which solver, with a stiffness knob `s` in [0, 1] (0 = softest, 1 = rigid).
#[derive(Clone, Copy, Debug)]
enum Kind {
    Lab,
    Pbd,
    Xpbd,
}

fn solver(kind: Kind, s: f32, compliance: f32, soft_bending: bool) -> Solver {
    match kind {
        Kind::Lab => Solver::Lab { velocity_keep: s },
        Kind::Pbd => Solver::Pbd {
            stretch: s,
            shear: s,
            bending: if soft_bending { 0.1 } else { s },
        },
        Kind::Xpbd => Solver::Xpbd {
            stretch: compliance,
            shear: compliance,
            bending: if soft_bending { 1e-3 } else { compliance },
        },
    }
}

/// How the cloth is held.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Pins {
    None,
    TwoCorners,
    All,
}

/// A disturbance applied during the first part of the run, then stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Disturbance {
    Nothing,
    /// A ball moving through the cloth at this speed (m/s).
    FastCollider(f32),
    /// A ball of 20× the cloth's size around it.
    SwallowingCollider,
    /// Wind at this speed (m/s) with gusts and turbulence.
    Wind(f32),
    /// One pin jumps this far (m) once.
    PinTeleport(f32),
}

#[derive(Clone, Debug)]
struct Scenario {
    kind: Kind,
    stiffness: f32,
    compliance: f32,
    /// A cloth-like bending stiffness instead of `stiffness`/`compliance`.
    soft_bending: bool,
    dt: f32,
    substeps: u32,
    iterations: u32,
    damping: f32,
    /// Heaviest / lightest vertex.
    mass_ratio: f32,
    /// Cloth side in metres.
    size: f32,
    /// Vertices per side.
    n: u32,
    pins: Pins,
    disturbance: Disturbance,
    self_collision: bool,
    tethers: bool,
    /// Tear threshold (`Some(1.0001)` tears nearly everything).
    tear: Option<f32>,
    /// A floor collider under the cloth.
    floor: bool,
    /// Steps with the disturbance on, then steps without it.
    steps: (usize, usize),
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            kind: Kind::Xpbd,
            stiffness: 1.0,
            compliance: 0.0,
            soft_bending: false,
            dt: 1.0 / 60.0,
            substeps: 10,
            iterations: 1,
            damping: 0.1,
            mass_ratio: 1.0,
            size: 1.0,
            n: 8,
            pins: Pins::TwoCorners,
            disturbance: Disturbance::Nothing,
            self_collision: false,
            tethers: false,
            tear: None,
            floor: false,
            steps: (30, 30),
        }
    }
}

#[derive(Debug)]
struct Outcome {
    /// Highest kinetic energy seen (J).
    max_energy: f64,
    /// The bound `½·M·max_speed²` (J).
    bound: f64,
    /// Kinetic energy right after the disturbance stopped, and at the end (J).
    energy_after_disturbance: f64,
    final_energy: f64,
    /// Steps whose state had to be reset (a NaN was produced inside the solver).
    recoveries: usize,
    /// Non-finite components ever seen in positions, velocities, normals or tangents.
    non_finite: usize,
    /// Largest distance of any vertex from the cloth's start (m).
    max_travel: f32,
}

impl Outcome {
    /// Nothing seen yet, for a cloth of `sim`'s masses and speed limit.
    fn of(sim: &Simulation) -> Self {
        let free_mass: f64 = sim
            .state()
            .positions
            .iter()
            .filter(|p| p.w > 0.0)
            .map(|p| 1.0 / f64::from(p.w))
            .sum();
        let max_speed = f64::from(sim.params().max_speed);
        Self {
            max_energy: 0.0,
            bound: 0.5 * free_mass * max_speed * max_speed,
            energy_after_disturbance: 0.0,
            final_energy: 0.0,
            recoveries: 0,
            non_finite: 0,
            max_travel: 0.0,
        }
    }

    /// The kinetic energy `e` and `positions` after step `step` of a run whose disturbance
    /// lasts `on` steps (`start`: where the vertices began).
    fn record(&mut self, step: usize, on: usize, e: f64, positions: &[glam::Vec4], start: &[Vec3]) {
        self.max_energy = self.max_energy.max(e);
        if step + 1 == on {
            self.energy_after_disturbance = e;
        }
        self.final_energy = e;
        for (p, s0) in positions.iter().zip(start) {
            self.max_travel = self.max_travel.max(p.truncate().distance(*s0));
        }
    }
}

/// A `n × n` grid in the xz plane of side `size`, centred at height `size`.
fn grid_mesh(n: u32, size: f32) -> (Vec<Vec3>, Vec<Vec2>, Vec<u32>) {
    let g = Grid::new(n, n, size, size);
    let pos = g
        .positions()
        .into_iter()
        .map(|p| p + Vec3::Y * size)
        .collect();
    (pos, g.uvs(), g.indices())
}

fn simulation(s: &Scenario, pos: &[Vec3], uvs: Option<&[Vec2]>, idx: &[u32]) -> Simulation {
    let topology = Topology::from_triangles(pos, uvs, idx, TopologyOptions::default())
        .expect("the scenario's mesh is valid");
    let count = pos.len();
    // Masses from 1 to `mass_ratio`, spread geometrically over the vertices, 1 kg in all.
    let raw: Vec<f32> = (0..count)
        .map(|i| s.mass_ratio.powf(i as f32 / (count.max(2) - 1) as f32))
        .collect();
    let sum: f32 = raw.iter().sum();
    let masses: Vec<f32> = raw.iter().map(|m| m / sum).collect();
    let params = SolverParams {
        solver: solver(s.kind, s.stiffness, s.compliance, s.soft_bending),
        substeps: s.substeps,
        iterations: s.iterations,
        damping: s.damping,
        ..Default::default()
    };
    let mut sim = Simulation::new(topology, &masses, params).expect("valid parameters");
    sim.set_features(Features {
        self_collision: s.self_collision.then_some(SelfCollision {
            thickness: s.size / s.n as f32,
            friction: 0.3,
        }),
        tethers: s.tethers.then(TetherParams::default),
        tear_threshold: s.tear,
    })
    .expect("valid features");
    let pinned: Vec<u32> = match s.pins {
        Pins::None => vec![],
        Pins::TwoCorners => vec![0, s.n - 1],
        Pins::All => (0..count as u32).collect(),
    };
    let pinned: Vec<u32> = pinned
        .into_iter()
        .filter(|&v| (v as usize) < count)
        .collect();
    sim.state_mut()
        .set_pins(pinned.iter().map(|&v| Pin {
            vertex: v,
            target: pos[v as usize],
        }))
        .unwrap();
    sim
}

fn run(s: &Scenario) -> Outcome {
    let (pos, uvs, idx) = grid_mesh(s.n, s.size);
    run_mesh(s, &pos, Some(&uvs), &idx)
}

fn run_mesh(s: &Scenario, pos: &[Vec3], uvs: Option<&[Vec2]>, idx: &[u32]) -> Outcome {
    let mut sim = simulation(s, pos, uvs, idx);
    let start: Vec<Vec3> = pos.to_vec();
    let centre = start.iter().copied().sum::<Vec3>() / start.len() as f32;
    let mut out = Outcome::of(&sim);
    let wind_field = wind_field(s);
    let (on, off) = s.steps;
    let mut time = 0.0f32;
    for step in 0..on + off {
        let disturbing = step < on;
        let colliders = colliders_at(s, step, time, centre);
        if let Some(targets) = pin_targets_at(s, step, sim.state().pins(), &start) {
            sim.state_mut().set_pin_targets(targets);
        }
        let env = Environment {
            colliders: &colliders,
            wind: if disturbing {
                wind_field.as_ref()
            } else {
                None
            },
            time: time.into(),
        };
        let report = sim.step_in(s.dt, &env, &Serial);
        time += s.dt;
        let shading = MeshShading::of_particles(sim.topology(), &sim.state().positions);
        out.recoveries += usize::from(report.recovered);
        out.non_finite += sim.state().non_finite_count();
        out.non_finite += shading.normals().iter().filter(|n| !n.is_finite()).count();
        out.non_finite += shading.tangents().iter().filter(|t| !t.is_finite()).count();
        let e = sim.state().kinetic_energy();
        out.record(step, on, e, &sim.state().positions, &start);
    }
    out
}

/// The floor under a scenario's cloth, when it has one.
fn floor_of(s: &Scenario) -> Option<Collider> {
    s.floor.then(|| {
        Collider::fixed(
            Shape::Plane,
            Pose::at(Vec3::new(0.0, -0.5 * s.size, 0.0)),
            0.01 * s.size,
            0.5,
        )
    })
}

/// The wind of a [`Disturbance::Wind`] scenario.
fn wind_field(s: &Scenario) -> Option<WindField> {
    match s.disturbance {
        Disturbance::Wind(speed) => Some(WindField::new([(
            WindParams {
                velocity: Vec3::new(speed, 0.2 * speed, 0.1 * speed),
                gust_amplitude: 0.5,
                turbulence: 0.5,
                ..Default::default()
            },
            None,
        )])),
        _ => None,
    }
}

/// The colliders of step `step` (at `time` seconds; `centre`: the cloth's centre at the
/// start): the floor, and a ball while the disturbance is on.
fn colliders_at(s: &Scenario, step: usize, time: f32, centre: Vec3) -> Vec<Collider> {
    let mut colliders: Vec<Collider> = floor_of(s).into_iter().collect();
    if step >= s.steps.0 {
        return colliders;
    }
    match s.disturbance {
        Disturbance::FastCollider(speed) => {
            // Along x through the cloth's centre, from one side to the other.
            let x0 = -s.size + speed * time;
            colliders.push(Collider {
                shape: Shape::Sphere {
                    radius: 0.2 * s.size,
                },
                start: Pose::at(Vec3::new(x0, s.size, centre.z)),
                end: Pose::at(Vec3::new(x0 + speed * s.dt, s.size, centre.z)),
                thickness: 0.01 * s.size,
                friction: 0.5,
            });
        }
        Disturbance::SwallowingCollider => colliders.push(Collider::fixed(
            Shape::Sphere {
                radius: 20.0 * s.size,
            },
            Pose::at(centre),
            0.01 * s.size,
            0.5,
        )),
        _ => {}
    }
    colliders
}

/// The pins' new targets at step `step` of a [`Disturbance::PinTeleport`] scenario (`pins`:
/// the pins now, `start`: the mesh's positions): the first pin jumps at step 1 and every pin
/// is back home at the disturbance's last step; `None` when they stay.
fn pin_targets_at(s: &Scenario, step: usize, pins: &[Pin], start: &[Vec3]) -> Option<Vec<Vec3>> {
    let Disturbance::PinTeleport(d) = s.disturbance else {
        return None;
    };
    if step >= s.steps.0 {
        return None;
    }
    if step == 1 {
        Some(
            pins.iter()
                .enumerate()
                .map(|(k, p)| p.target + if k == 0 { Vec3::X * d } else { Vec3::ZERO })
                .collect(),
        )
    } else if step + 1 == s.steps.0 {
        // The pin comes back home: the disturbance stops.
        Some(pins.iter().map(|p| start[p.vertex as usize]).collect())
    } else {
        None
    }
}

/// The invariants every run keeps, whatever it was given.
fn check(s: &Scenario, o: &Outcome) {
    assert_eq!(
        o.non_finite, 0,
        "non-finite values left the solver: {s:?} {o:?}"
    );
    assert_eq!(
        o.recoveries, 0,
        "the solver produced a NaN and had to reset: {s:?} {o:?}"
    );
    assert!(
        o.max_energy <= o.bound * (1.0 + 1e-4),
        "kinetic energy over its bound: {s:?} {o:?}"
    );
}

fn kind() -> impl Strategy<Value = Kind> {
    prop_oneof![Just(Kind::Lab), Just(Kind::Pbd), Just(Kind::Xpbd)]
}

/// Log-uniform in `[lo, hi]`.
fn log_range(lo: f32, hi: f32) -> impl Strategy<Value = f32> {
    (0.0f32..=1.0).prop_map(move |t| lo * (hi / lo).powf(t))
}

fn disturbance() -> impl Strategy<Value = Disturbance> {
    prop_oneof![
        Just(Disturbance::Nothing),
        log_range(1.0, 100.0).prop_map(Disturbance::FastCollider),
        Just(Disturbance::SwallowingCollider),
        log_range(1.0, 100.0).prop_map(Disturbance::Wind),
        log_range(1.0, 1000.0).prop_map(Disturbance::PinTeleport),
    ]
}

fn scenario() -> impl Strategy<Value = Scenario> {
    (
        (
            kind(),
            0.0f32..=1.0,
            prop_oneof![Just(0.0f32), log_range(1e-9, 1e3)],
            log_range(1e-4, 0.1),
            1u32..=64,
            log_range(1.0, 500.0),
            0.0f32..=1.0,
        ),
        (
            log_range(1.0, 1e4),
            log_range(1e-3, 100.0),
            3u32..=10,
            prop_oneof![Just(Pins::None), Just(Pins::TwoCorners), Just(Pins::All)],
            disturbance(),
        ),
        (
            any::<bool>(),
            any::<bool>(),
            prop_oneof![
                Just(None),
                Just(Some(1.0001f32)),
                (1.01f32..3.0).prop_map(Some)
            ],
            any::<bool>(),
        ),
    )
        .prop_map(
            |(
                (kind, stiffness, compliance, dt, substeps, iterations, damping),
                (mass_ratio, size, n, pins, disturbance),
                (self_collision, tethers, tear, floor),
            )| {
                // Keep a case under about 3·10⁵ projections a step so the suite stays quick;
                // the named tests below take the full counts.
                let iterations = (iterations as u32).clamp(1, (2000 / substeps).max(1));
                Scenario {
                    kind,
                    stiffness,
                    compliance,
                    soft_bending: false,
                    dt,
                    substeps,
                    iterations,
                    damping,
                    mass_ratio,
                    size,
                    n,
                    pins,
                    disturbance,
                    self_collision,
                    tethers,
                    tear,
                    floor,
                    steps: (20, 10),
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 192, ..ProptestConfig::default() })]

    /// Any combination of the ranges: finite, bounded energy, no internal resets.
    #[test]
    fn any_scenario_stays_finite_and_bounded(s in scenario()) {
        let o = run(&s);
        check(&s, &o);
    }
}

/// The GPU backend's kernels on a device shared by the tests of this file (`None`: no
/// adapter, the test skipped).
fn gpu() -> Option<&'static (wgpu::Device, wgpu::Queue, GpuKernels)> {
    static GPU: std::sync::OnceLock<Option<(wgpu::Device, wgpu::Queue, GpuKernels)>> =
        std::sync::OnceLock::new();
    GPU.get_or_init(|| {
        let (_, device, queue, kernels) = common::gpu_kernels_or_skip("stability on the GPU")?;
        Some((device, queue, kernels))
    })
    .as_ref()
}

/// [`run`] on the GPU backend's kernels, one step a frame, the state read back after each:
/// the same cloth, colliders, pins and wind (sampled as the CPU backend samples it for the
/// GPU). `recoveries` counts the steps the GPU's guard flagged a non-finite state. `None`
/// when the GPU backend does not run the scenario's settings.
fn run_on_gpu(s: &Scenario, gpu: &(wgpu::Device, wgpu::Queue, GpuKernels)) -> Option<Outcome> {
    let (pos, uvs, idx) = grid_mesh(s.n, s.size);
    run_mesh_on_gpu(s, &pos, Some(&uvs), &idx, gpu)
}

/// [`run_on_gpu`] on a mesh of its own.
fn run_mesh_on_gpu(
    s: &Scenario,
    pos: &[Vec3],
    uvs: Option<&[Vec2]>,
    idx: &[u32],
    gpu: &(wgpu::Device, wgpu::Queue, GpuKernels),
) -> Option<Outcome> {
    let (device, queue, kernels) = gpu;
    let sim = simulation(s, pos, uvs, idx);
    if let Err(e) = GpuWorld::supports(&sim, s.dt) {
        eprintln!("not on the GPU ({e}): {s:?}");
        return None;
    }
    let mut world = GpuWorld::new(device, queue, kernels, &[&sim]).expect("supported");
    let centre = pos.iter().copied().sum::<Vec3>() / pos.len() as f32;
    let mut out = Outcome::of(&sim);
    let wind = wind_field(s);
    let mut air_grid = AirGrid::default();
    let mut air = Vec::new();
    let mut pins: Vec<Pin> = sim.state().pins().to_vec();
    let mut positions = sim.state().positions.clone();
    let (on, off) = s.steps;
    for step in 0..on + off {
        let time = step as f32 * s.dt;
        let colliders = colliders_at(s, step, time, centre);
        if let Some(targets) = pin_targets_at(s, step, &pins, pos) {
            for (p, t) in pins.iter_mut().zip(targets) {
                p.target = t;
            }
        }
        air.clear();
        if let Some(field) = wind
            .as_ref()
            .filter(|_| step < on && !sim.params().air.is_none())
        {
            let t = f64::from(time) + 0.5 * f64::from(s.dt);
            air_grid.air_velocities(field, &positions, t, &mut air);
        }
        let targets = [pins.iter().map(|p| p.target).collect::<Vec<Vec3>>()];
        let frame = GpuFrame {
            dt: s.dt,
            steps: vec![StepColliders::new(&colliders)],
            cloths: vec![ClothFrame {
                pin_targets: &targets,
                air_velocities: &air,
                ..Default::default()
            }],
        };
        common::run_gpu_frame(&mut world, device, queue, kernels, &frame);
        let (p, v) = world.read_state(device, queue, 0);
        out.recoveries += usize::from(world.read_status(device, queue, 0).0);
        out.non_finite += p.iter().chain(&v).filter(|x| !x.is_finite()).count();
        let e: f64 = v
            .iter()
            .zip(&p)
            .filter(|(_, p)| p.w > 0.0)
            .map(|(v, p)| 0.5 * f64::from(v.truncate().length_squared()) / f64::from(p.w))
            .sum();
        out.record(step, on, e, &p, pos);
        positions = p;
    }
    Some(out)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    /// The same ranges on the GPU backend's kernels (llvmpipe in CI): nothing non-finite, the
    /// guard never trips, the energy under the same bound. At most 100 projections a step
    /// (a software GPU takes about a second a case then, 40 s at 2 000);
    /// `counts_up_to_64_substeps_and_500_iterations` takes the high counts on the CPU.
    #[test]
    fn any_scenario_stays_finite_and_bounded_on_the_gpu(
        s in scenario().prop_map(|s| Scenario {
            iterations: s.iterations.min((100 / s.substeps).max(1)),
            ..s
        })
    ) {
        if let Some(o) = gpu().and_then(|gpu| run_on_gpu(&s, gpu)) {
            check(&s, &o);
        }
    }
}

// ---- corners of the ranges, one at a time ----

fn each_solver(base: Scenario) {
    each_solver_with(base, |s| Some(run(s)));
}

/// [`each_solver`] with `run` (`None`: that case does not run there).
fn each_solver_with(base: Scenario, run: impl Fn(&Scenario) -> Option<Outcome>) {
    for (kind, stiffness, compliance) in [
        (Kind::Lab, 0.99, 0.0),
        (Kind::Pbd, 1.0, 0.0),
        (Kind::Pbd, 0.0, 0.0),
        (Kind::Xpbd, 1.0, 0.0),
        (Kind::Xpbd, 1.0, 1e3),
    ] {
        let s = Scenario {
            kind,
            stiffness,
            compliance,
            ..base.clone()
        };
        if let Some(o) = run(&s) {
            check(&s, &o);
        }
    }
}

#[test]
fn time_steps_from_tenth_of_a_millisecond_to_a_tenth_of_a_second() {
    for dt in [1e-4, 1e-3, 1.0 / 60.0, 0.05, 0.1] {
        each_solver(Scenario {
            dt,
            ..Default::default()
        });
    }
}

#[test]
fn counts_up_to_64_substeps_and_500_iterations() {
    for (substeps, iterations) in [(1, 1), (64, 1), (1, 500), (64, 500)] {
        each_solver(Scenario {
            substeps,
            iterations,
            n: 5,
            steps: (5, 5),
            ..Default::default()
        });
    }
}

#[test]
fn damping_from_none_to_one() {
    for damping in [0.0, 0.5, 1.0] {
        each_solver(Scenario {
            damping,
            ..Default::default()
        });
    }
}

#[test]
fn mass_ratio_of_ten_thousand() {
    each_solver(Scenario {
        mass_ratio: 1e4,
        floor: true,
        ..Default::default()
    });
}

#[test]
fn cloth_from_a_millimetre_to_a_hundred_metres() {
    for size in [1e-3, 1.0, 100.0] {
        each_solver(Scenario {
            size,
            floor: true,
            ..Default::default()
        });
    }
}

#[test]
fn all_pinned_and_none_pinned() {
    for pins in [Pins::All, Pins::None] {
        each_solver(Scenario {
            pins,
            floor: true,
            ..Default::default()
        });
    }
}

#[test]
fn every_feature_on_under_every_disturbance() {
    for s in every_feature_under_every_disturbance() {
        each_solver(s);
    }
}

/// Every feature on (self-collision, tethers, tearing, a floor) under each of the strongest
/// disturbances.
fn every_feature_under_every_disturbance() -> impl Iterator<Item = Scenario> {
    [
        Disturbance::FastCollider(100.0),
        Disturbance::SwallowingCollider,
        Disturbance::Wind(100.0),
        Disturbance::PinTeleport(1000.0),
    ]
    .into_iter()
    .map(|disturbance| Scenario {
        disturbance,
        self_collision: true,
        tethers: true,
        tear: Some(3.0),
        floor: true,
        ..Default::default()
    })
}

/// [`run_on_gpu`] on `gpu`, for a scenario the GPU backend must run.
fn on_the_gpu(
    gpu: &(wgpu::Device, wgpu::Queue, GpuKernels),
) -> impl Fn(&Scenario) -> Option<Outcome> + '_ {
    move |s| {
        let o = run_on_gpu(s, gpu);
        assert!(o.is_some(), "the GPU runs it: {s:?}");
        o
    }
}

/// [`every_feature_on_under_every_disturbance`] on the GPU backend's kernels.
#[test]
fn every_feature_on_under_every_disturbance_on_the_gpu() {
    let Some(gpu) = gpu() else {
        return;
    };
    for s in every_feature_under_every_disturbance() {
        each_solver_with(s, on_the_gpu(gpu));
    }
}

/// The corners above (time steps, damping, mass ratio, size, pins) on the GPU backend's
/// kernels, each solver at each (with a floor where the CPU's test has one).
#[test]
fn the_corners_on_the_gpu() {
    let Some(gpu) = gpu() else {
        return;
    };
    let corners: [fn(&mut Scenario); 9] = [
        |s| s.dt = 1e-4,
        |s| s.dt = 0.1,
        |s| s.damping = 0.0,
        |s| s.damping = 1.0,
        |s| s.mass_ratio = 1e4,
        |s| s.size = 1e-3,
        |s| s.size = 100.0,
        |s| s.pins = Pins::All,
        |s| s.pins = Pins::None,
    ];
    for (k, corner) in corners.into_iter().enumerate() {
        let mut s = Scenario {
            floor: k >= 4,
            ..Default::default()
        };
        corner(&mut s);
        each_solver_with(s, on_the_gpu(gpu));
    }
}

#[test]
fn every_edge_torn() {
    for kind in [Kind::Lab, Kind::Pbd, Kind::Xpbd] {
        let s = Scenario {
            kind,
            stiffness: if matches!(kind, Kind::Lab) { 0.99 } else { 1.0 },
            tear: Some(1.0001),
            disturbance: Disturbance::Wind(100.0),
            floor: true,
            ..Default::default()
        };
        let (pos, uvs, idx) = grid_mesh(s.n, s.size);
        let mut sim = simulation(&s, &pos, Some(&uvs), &idx);
        // Pull the free corner far away: the edges on the way tear, and the rest follow as
        // the pieces fall; keep going until nothing is left to tear.
        let far = sim.state().len() - 1;
        let mut torn = 0;
        for _ in 0..400 {
            sim.state_mut().positions[far] += glam::Vec4::new(0.0, -1.0, 0.0, 0.0);
            torn += sim.step(s.dt, &Serial).torn.len();
            let shading = MeshShading::of_particles(sim.topology(), &sim.state().positions);
            assert_eq!(sim.state().non_finite_count(), 0);
            assert!(shading.normals().iter().all(|n| n.is_finite()));
        }
        assert!(torn > 0, "{kind:?}: nothing tore");
        for t in sim.topology().triangles() {
            assert!(t.iter().all(|&v| (v as usize) < sim.state().len()));
        }
        let o = run(&s);
        check(&s, &o);
    }
}

// ---- broken geometry ----

/// A mesh with a zero-length edge, coincident vertices, a zero-area triangle and a sliver.
fn broken_mesh() -> (Vec<Vec3>, Vec<u32>) {
    let pos = vec![
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(0.0, 1.0, 1.0),
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(1.0, 1.0, 1.0), // coincident with 3
        Vec3::new(2.0, 1.0, 0.0),
        Vec3::new(3.0, 1.0, 0.0), // 5, 6, 7 collinear: a zero-area triangle
        Vec3::new(4.0, 1.0, 0.0),
        Vec3::new(2.0, 1.0, 1e-6), // a sliver with 5 and 6
    ];
    let idx = vec![
        0, 2, 1, //
        1, 2, 3, //
        1, 3, 4, // zero-length edge 3–4
        1, 4, 5, //
        5, 6, 7, // zero area
        5, 8, 6, // sliver
        3, 3, 4, // repeated index
    ];
    (pos, idx)
}

#[test]
fn zero_length_edges_coincident_vertices_zero_area_triangles_and_slivers() {
    let (pos, idx) = broken_mesh();
    for disturbance in [
        Disturbance::Nothing,
        Disturbance::Wind(100.0),
        Disturbance::FastCollider(100.0),
    ] {
        for (kind, stiffness, compliance) in [
            (Kind::Lab, 0.99, 0.0),
            (Kind::Pbd, 1.0, 0.0),
            (Kind::Xpbd, 0.0, 0.0),
            (Kind::Xpbd, 0.0, 1e-3),
        ] {
            let s = Scenario {
                kind,
                stiffness,
                compliance,
                disturbance,
                self_collision: true,
                tethers: true,
                floor: true,
                ..Default::default()
            };
            let o = run_mesh(&s, &pos, None, &idx);
            check(&s, &o);
        }
    }
}

/// Random vertex soups: positions snapped to a coarse lattice so that coincident vertices,
/// zero-length edges and degenerate triangles are common.
fn soup() -> impl Strategy<Value = (Vec<Vec3>, Vec<u32>)> {
    (3usize..24).prop_flat_map(|n| {
        (
            prop::collection::vec((0i8..4, 0i8..2, 0i8..4), n),
            prop::collection::vec(0..n as u32, 3..60),
        )
            .prop_map(|(p, mut idx)| {
                idx.truncate(idx.len() / 3 * 3);
                let pos = p
                    .into_iter()
                    .map(|(x, y, z)| Vec3::new(f32::from(x), f32::from(y), f32::from(z)) * 0.25)
                    .collect();
                (pos, idx)
            })
    })
}

/// What a soup runs with: every feature on, a floor, `kind` and `disturbance`.
fn soup_scenario(kind: Kind, disturbance: Disturbance) -> Scenario {
    Scenario {
        kind,
        stiffness: 0.9,
        disturbance,
        self_collision: true,
        tethers: true,
        tear: Some(2.0),
        floor: true,
        steps: (15, 5),
        ..Default::default()
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    /// Broken meshes: the solver accepts any triangle soup with in-range indices and stays sane.
    #[test]
    fn any_triangle_soup_stays_finite((pos, idx) in soup(), k in kind(), d in disturbance()) {
        let s = soup_scenario(k, d);
        match Topology::from_triangles(&pos, None, &idx, TopologyOptions::default()) {
            // A soup whose triangles are all degenerate (or that has none) is refused with a
            // typed error; anything else must simulate.
            Err(e) => prop_assert!(
                matches!(e, TopologyError::NoTriangles | TopologyError::ZeroArea),
                "{e}"
            ),
            Ok(_) => check(&s, &run_mesh(&s, &pos, None, &idx)),
        }
    }

    /// [`any_triangle_soup_stays_finite`] on the GPU backend's kernels.
    #[test]
    fn any_triangle_soup_stays_finite_on_the_gpu(
        (pos, idx) in soup(),
        k in kind(),
        d in disturbance(),
    ) {
        let s = soup_scenario(k, d);
        let gpu = gpu();
        if gpu.is_some() && Topology::from_triangles(&pos, None, &idx, TopologyOptions::default()).is_ok() {
            let o = gpu.and_then(|gpu| run_mesh_on_gpu(&s, &pos, None, &idx, gpu));
            prop_assert!(o.is_some(), "the GPU runs it: {:?}", s);
            if let Some(o) = o {
                check(&s, &o);
            }
        }
    }
}

/// Found by `any_triangle_soup_stays_finite`: three coincident vertices and the single
/// triangle `(1, 0, 0)`. Nothing is left to simulate; the mesh is refused, not simulated.
#[test]
fn regression_soup_of_only_degenerate_triangles_is_refused() {
    let pos = [Vec3::ZERO; 3];
    let err = Topology::from_triangles(&pos, None, &[1, 0, 0], TopologyOptions::default())
        .expect_err("no triangle with an area");
    assert_eq!(err, TopologyError::NoTriangles);
    assert!(err.to_string().contains("triangle"), "{err}");
}

// ---- coming back to rest ----

/// After each disturbance stops, the cloth calms down: its kinetic energy falls far below
/// what the disturbance gave it.
#[test]
fn cloth_comes_back_to_rest_after_each_disturbance() {
    for s in settling_scenarios() {
        let o = run(&s);
        check_settled(&s, &o);
    }
}

/// [`cloth_comes_back_to_rest_after_each_disturbance`] on the GPU backend's kernels (which
/// never put a cloth to sleep: it must come to rest by its damping alone).
#[test]
fn cloth_comes_back_to_rest_after_each_disturbance_on_the_gpu() {
    let Some(gpu) = gpu() else {
        return;
    };
    for s in settling_scenarios() {
        let o = on_the_gpu(gpu)(&s).expect("the GPU runs it");
        check_settled(&s, &o);
    }
}

/// PBD and XPBD under each disturbance for a second, with damping 1 /s and tethers, then
/// twenty seconds of calm.
fn settling_scenarios() -> impl Iterator<Item = Scenario> {
    [
        Disturbance::FastCollider(100.0),
        Disturbance::Wind(100.0),
        Disturbance::PinTeleport(1000.0),
        Disturbance::SwallowingCollider,
    ]
    .into_iter()
    .flat_map(|disturbance| {
        [Kind::Pbd, Kind::Xpbd].map(|kind| Scenario {
            kind,
            disturbance,
            damping: 1.0,
            tethers: true,
            // One second of disturbance, then twenty of calm.
            steps: (60, 1200),
            ..Default::default()
        })
    })
}

/// [`check`], and the run ended at rest: under 1 mJ and a hundredth of its most.
fn check_settled(s: &Scenario, o: &Outcome) {
    check(s, o);
    assert!(
        o.final_energy < 1e-3 && o.final_energy < 0.01 * o.max_energy.max(1e-9),
        "did not settle: {s:?} {o:?}"
    );
}

// ---- colliders given as SDFs of broken meshes ----

#[test]
fn sdf_of_a_broken_mesh_is_finite_and_safe_to_collide_with() {
    let (pos, idx) = broken_mesh();
    let grid = SdfGrid::from_mesh(&pos, &idx, 16).expect("bakes");
    let s = Scenario::default();
    let (cpos, uvs, cidx) = grid_mesh(s.n, s.size);
    let mut sim = simulation(&s, &cpos, Some(&uvs), &cidx);
    let colliders = [Collider::fixed(
        Shape::Mesh(Arc::new(grid)),
        Pose {
            translation: Vec3::new(0.0, 0.5, 0.0),
            rotation: Quat::from_rotation_y(0.3),
            scale: 1.0,
        },
        0.01,
        0.5,
    )];
    for _ in 0..60 {
        let r = sim.step_in(
            1.0 / 60.0,
            &Environment {
                colliders: &colliders,
                ..Default::default()
            },
            &Serial,
        );
        assert!(!r.recovered);
        assert_eq!(sim.state().non_finite_count(), 0);
    }
}

/// The fastest vertex relative to the cloth's mean velocity.
fn fastest_relative(sim: &Simulation) -> f32 {
    let s = sim.state();
    let mean = (0..s.len()).map(|i| s.velocity(i)).sum::<Vec3>() / s.len() as f32;
    (0..s.len())
        .map(|i| (s.velocity(i) - mean).length())
        .fold(0.0, f32::max)
}

/// A closed cylinder with its caps fanned from one rim vertex (Bevy's `Cylinder` mesh: that
/// vertex joins 33 others) falling freely under XPBD at the default settings and under PBD's
/// distances. Swept forward only, a textbook Gauss–Seidel loop shakes it apart within a second
/// (35–100 m/s between its vertices, edges at two to six times their length, measured);
/// swept forward and back it falls as one piece. A grid keeps the one forward sweep.
#[test]
fn a_closed_cylinder_with_a_hub_falls_in_one_piece() {
    let (positions, indices) = common::fanned_cylinder(32, 0.3, 1.0);
    let t =
        Topology::from_triangles(&positions, None, &indices, TopologyOptions::default()).unwrap();
    assert!(t.max_vertex_degree() > SYMMETRIC_SWEEP_DEGREE);
    for solver in [
        Solver::default(),
        // PBD's distances alone: with its dihedral bending and a flat rest, a closed shape
        // spins up whichever way the distances are swept (docs/experiments.md).
        Solver::Pbd {
            stretch: 1.0,
            shear: 1.0,
            bending: 0.0,
        },
    ] {
        let params = SolverParams {
            solver,
            ..SolverParams::default()
        };
        let masses = t.masses(0.5, bevy_cloth::solver::MassDistribution::Area);
        let mut sim = Simulation::new(t.clone(), &masses, params).unwrap();
        let mut worst = (0.0f32, 0.0f32);
        for _ in 0..120 {
            sim.step(1.0 / 60.0, &Serial);
            worst.0 = worst.0.max(fastest_relative(&sim));
            worst.1 = worst.1.max(sim.strain().max);
        }
        assert!(
            worst.0 < 2.0 && worst.1 < 0.05,
            "{solver:?}: vertices {} m/s apart, edges {} longer",
            worst.0,
            worst.1
        );
        assert!(sim.batches().symmetric_sweeps());
    }
    let (pos, uvs, idx) = grid_mesh(16, 1.0);
    let grid =
        Topology::from_triangles(&pos, Some(&uvs), &idx, TopologyOptions::default()).unwrap();
    let sim = Simulation::new(grid, &vec![0.001; pos.len()], SolverParams::default()).unwrap();
    assert!(!sim.batches().symmetric_sweeps(), "a grid sweeps once");
}

/// Closed shapes without a hub sweep both ways too: Bevy's default `Sphere` mesh (an ico
/// sphere), a coarser ico sphere and its `Torus`, held in zero gravity with the default
/// settings (XPBD, isometric bending with a flat rest). Swept forward only, rounding grew
/// about 1.3-fold a step under the bending that cannot flatten them, and their vertices moved
/// at 0.5–2 m/s against each other for as long as they ran (a ball on the ground never came
/// to rest in air); swept both ways they hold still, but for a jitter of millimetres a
/// second. Awake throughout (a sleeping cloth's velocities are zero).
#[test]
fn closed_shapes_without_a_hub_hold_still_in_zero_gravity() {
    use bevy::math::primitives::{Sphere, Torus};
    use bevy::mesh::{Mesh, Meshable};
    for (name, mesh) in [
        ("default sphere", Mesh::from(Sphere::new(0.5))),
        ("ico sphere 3", Sphere::new(0.5).mesh().ico(3).unwrap()),
        ("torus", Mesh::from(Torus::default())),
    ] {
        let (positions, indices) = common::welded(&mesh, Vec3::ZERO);
        let t = Topology::from_triangles(&positions, None, &indices, TopologyOptions::default())
            .unwrap();
        assert!(t.is_closed(), "{name} is closed");
        assert!(
            t.max_vertex_degree() <= SYMMETRIC_SWEEP_DEGREE,
            "{name} has no hub"
        );
        let params = SolverParams {
            gravity: Vec3::ZERO,
            air: bevy_cloth::solver::Aerodynamics::NONE,
            sleep: bevy_cloth::solver::Sleep::NEVER,
            ..SolverParams::default()
        };
        let masses = t.masses(0.5, bevy_cloth::solver::MassDistribution::Area);
        let mut sim = Simulation::new(t, &masses, params).unwrap();
        assert!(sim.batches().symmetric_sweeps(), "{name} sweeps both ways");
        let mut worst = 0.0f32;
        for k in 0..300 {
            sim.step(1.0 / 60.0, &Serial);
            // After the first second, in which the bending settles the shape.
            if k >= 60 {
                worst = worst.max(fastest_relative(&sim));
            }
        }
        println!("{name}: {worst} m/s between vertices at most after 1 s");
        // Forward only: 0.5–2 m/s. Both ways: 1–2 mm/s where the flat rest's bending and the
        // distances meet within a substep (the same over 50 s).
        assert!(worst < 0.01, "{name}: vertices {worst} m/s apart");
    }
}

/// The same shapes as cloths a game drops: Bevy's default `Sphere` mesh and its `Torus`, with
/// the default settings (air included), dropped tilted onto the ground. Swept forward only,
/// neither came to rest (their vertices still 0.65 and 0.92 m/s apart after five seconds,
/// measured); swept both ways both lie still within a few seconds (0.03 and 0.00).
#[test]
fn a_closed_ball_and_ring_dropped_in_air_come_to_rest() {
    use bevy::math::primitives::{Sphere, Torus};
    use bevy::mesh::Mesh;
    let floor = [Collider::fixed(
        Shape::Plane,
        Pose::at(Vec3::ZERO),
        0.005,
        0.6,
    )];
    for (name, mesh) in [
        ("default sphere", Mesh::from(Sphere::new(0.5))),
        ("torus", Mesh::from(Torus::default())),
    ] {
        let (positions, indices) = common::welded(&mesh, Vec3::ZERO);
        let placed: Vec<Vec3> = positions
            .iter()
            .map(|p| Quat::from_rotation_z(0.3) * *p + Vec3::Y * 1.5)
            .collect();
        let t =
            Topology::from_triangles(&placed, None, &indices, TopologyOptions::default()).unwrap();
        let masses = t.masses(0.5, bevy_cloth::solver::MassDistribution::Area);
        let mut sim = Simulation::new(t, &masses, SolverParams::default()).unwrap();
        let mut late = 0.0f32;
        for k in 0..480 {
            let env = Environment {
                colliders: &floor,
                wind: None,
                time: f64::from(k) / 60.0,
            };
            sim.step_in(1.0 / 60.0, &env, &Serial);
            // From the sixth second.
            if k >= 300 {
                late = late.max(fastest_relative(&sim));
            }
        }
        println!("{name}: {late} m/s between vertices at most after 5 s");
        assert!(late < 0.1, "{name}: vertices {late} m/s apart after 5 s");
    }
}
