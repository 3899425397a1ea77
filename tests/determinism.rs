//! Determinism: the CPU backend gives bit-identical results for the same inputs, across runs
//! and across thread counts (the work is split by vertex ranges that do not depend on the
//! threads, and everything shared is done in a fixed order). A run is recorded to a file and
//! replayed from it.

use std::io::{Read, Write};

use bevy::prelude::*;
use bevy_cloth::cloth::TaskPoolParallel;
use bevy_cloth::prelude::*;

mod common;
use bevy_cloth::solver::{
    Collider, Environment, Features, HangingCloth, Parallel, Pose, SelfCollision, Serial, Shape,
    Simulation, TetherParams, WindField, WindParams,
};

/// Runs items on `n` scoped threads, each taking every n-th item.
struct Threads(usize);

impl Parallel for Threads {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        let n = self.0.max(1);
        let mut buckets: Vec<Vec<&mut T>> = (0..n).map(|_| Vec::new()).collect();
        for (i, item) in items.iter_mut().enumerate() {
            buckets[i % n].push(item);
        }
        std::thread::scope(|s| {
            for bucket in buckets {
                let f = &f;
                s.spawn(move || bucket.into_iter().for_each(f));
            }
        });
    }

    /// So that the step cuts its work as it would for `n` threads (self-collision's chunks
    /// follow it: 288 vertices on 8 threads here, 512 on fewer).
    fn threads(&self) -> usize {
        self.0.max(1)
    }
}

/// Everything that drives one step from outside the cloth.
#[derive(Clone, Debug, PartialEq)]
struct StepInput {
    dt: f32,
    pin_targets: Vec<Vec3>,
    ball: Vec3,
    time: f32,
}

fn inputs(steps: usize) -> Vec<StepInput> {
    (0..steps)
        .map(|k| {
            let t = k as f32 / 60.0;
            StepInput {
                // A hitch now and then.
                dt: if k % 17 == 16 { 0.05 } else { 1.0 / 60.0 },
                pin_targets: vec![
                    Vec3::new(-0.5 + 0.2 * (2.0 * t).sin(), 2.0, 0.5),
                    Vec3::new(0.5, 2.0, 0.5),
                ],
                ball: Vec3::new(-2.0 + 3.0 * t, 1.5, 0.0),
                time: t,
            }
        })
        .collect()
}

/// A 96×96 cloth (four vertex-range parts) with every feature on.
fn scene() -> (Simulation, Vec<u32>) {
    let mut scene = HangingCloth::new(96);
    scene.offset = Vec3::Y * 2.0;
    scene.mass = 0.5;
    scene.mass_distribution = MassDistribution::Area;
    scene.params.iterations = 2;
    scene.features = Features {
        self_collision: Some(SelfCollision {
            thickness: 0.01,
            friction: 0.3,
        }),
        tethers: Some(TetherParams::default()),
        tear_threshold: Some(2.5),
    };
    (scene.build().unwrap(), scene.pins)
}

/// Runs the scene over `inputs`; returns a hash of the state after every step and the final
/// positions' bits.
fn run(inputs: &[StepInput], par: &impl Parallel) -> (Vec<u64>, Vec<u32>) {
    let (mut sim, _) = scene();
    let wind = WindField::new([(WindParams::default(), None)]);
    let mut previous_ball = inputs[0].ball;
    let mut hashes = Vec::new();
    for input in inputs {
        sim.state_mut()
            .set_pin_targets(input.pin_targets.iter().copied());
        let ball = Collider {
            shape: Shape::Sphere { radius: 0.3 },
            start: Pose::at(previous_ball),
            end: Pose::at(input.ball),
            thickness: 0.01,
            friction: 0.4,
        };
        previous_ball = input.ball;
        let env = Environment {
            colliders: std::slice::from_ref(&ball),
            wind: Some(&wind),
            time: f64::from(input.time),
        };
        sim.step_in(input.dt, &env, par);
        hashes.push(hash(&sim));
    }
    let bits = sim
        .state()
        .positions
        .iter()
        .flat_map(|p| p.to_array().map(f32::to_bits))
        .collect();
    (hashes, bits)
}

/// FNV-1a over the bits of every position and velocity.
fn hash(sim: &Simulation) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let state = sim.state();
    for v in state.positions.iter().chain(&state.velocities) {
        for c in v.to_array() {
            for b in c.to_bits().to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x100_0000_01b3);
            }
        }
    }
    h
}

#[test]
fn same_inputs_give_the_same_bits_on_any_thread_count() {
    let inputs = inputs(90);
    let serial = run(&inputs, &Serial);
    // The hashes change from step to step (the test would be empty if the cloth sat still).
    assert!(serial.0.windows(2).all(|w| w[0] != w[1]));
    assert_eq!(run(&inputs, &Serial), serial, "two serial runs differ");
    for threads in [2, 3, 8] {
        assert_eq!(
            run(&inputs, &Threads(threads)),
            serial,
            "{threads} threads differ from one"
        );
    }
}

/// The recording format: one line per step, `dt pin0 pin1 ball time hash` with every float
/// as its bit pattern in hex, so nothing is lost in printing.
fn write_recording(path: &std::path::Path, inputs: &[StepInput], hashes: &[u64]) {
    let mut f = std::fs::File::create(path).unwrap();
    for (i, h) in inputs.iter().zip(hashes) {
        let mut floats = vec![i.dt];
        for p in &i.pin_targets {
            floats.extend(p.to_array());
        }
        floats.extend(i.ball.to_array());
        floats.push(i.time);
        let words: Vec<String> = floats
            .iter()
            .map(|x| format!("{:08x}", x.to_bits()))
            .collect();
        writeln!(f, "{} {h:016x}", words.join(" ")).unwrap();
    }
}

fn read_recording(path: &std::path::Path) -> (Vec<StepInput>, Vec<u64>) {
    let mut text = String::new();
    std::fs::File::open(path)
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    let mut inputs = Vec::new();
    let mut hashes = Vec::new();
    for line in text.lines() {
        let words: Vec<&str> = line.split(' ').collect();
        let (hash, floats) = words.split_last().unwrap();
        let f: Vec<f32> = floats
            .iter()
            .map(|w| f32::from_bits(u32::from_str_radix(w, 16).unwrap()))
            .collect();
        inputs.push(StepInput {
            dt: f[0],
            pin_targets: vec![Vec3::new(f[1], f[2], f[3]), Vec3::new(f[4], f[5], f[6])],
            ball: Vec3::new(f[7], f[8], f[9]),
            time: f[10],
        });
        hashes.push(u64::from_str_radix(hash, 16).unwrap());
    }
    (inputs, hashes)
}

#[test]
fn a_recorded_run_replays_bit_for_bit() {
    let inputs = inputs(60);
    let (hashes, _) = run(&inputs, &Threads(2));
    let path =
        std::env::temp_dir().join(format!("bevy_cloth_recording_{}.txt", std::process::id()));
    write_recording(&path, &inputs, &hashes);
    let (replayed_inputs, recorded) = read_recording(&path);
    std::fs::remove_file(&path).ok();
    assert_eq!(replayed_inputs, inputs, "the recording lost input bits");
    let (replayed, _) = run(&replayed_inputs, &Serial);
    assert_eq!(replayed.len(), recorded.len());
    for (step, (a, b)) in replayed.iter().zip(&recorded).enumerate() {
        assert_eq!(a, b, "replay diverged at step {step}");
    }
}

/// The plugin's own scheduler too: Bevy task pools of one and four threads, through
/// [`TaskPoolParallel`] (what the plugin passes the solver), match the serial run.
#[test]
fn bevy_task_pools_of_any_size_match_the_serial_run() {
    let inputs = inputs(45);
    let serial = run(&inputs, &Serial);
    for threads in [1, 4] {
        let pool = bevy::tasks::TaskPoolBuilder::new()
            .num_threads(threads)
            .build();
        assert_eq!(
            run(&inputs, &TaskPoolParallel(&pool)),
            serial,
            "a pool of {threads} threads differs"
        );
    }
}
