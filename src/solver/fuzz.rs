//! Fuzzing entry point: arbitrary bytes → mesh → topology → a few solver steps.
//!
//! [`fuzz_one`] decodes any byte string into a mesh (positions may be NaN, infinite, huge or
//! coincident; indices may be out of range or repeated), solver parameters (possibly out of
//! range), features, pins, a moving collider and wind, then builds and steps the cloth. It
//! returns what happened; it must never panic, and a cloth that was accepted must never
//! hold a non-finite value. `cargo run --release --example fuzz` drives it with random bytes
//! for a while; `tests/fuzz.rs` runs a fixed corpus and every finding as a regression test.

use std::sync::Arc;

use glam::{Quat, Vec3};

use super::air::{Aerodynamics, WindField, WindParams};
use super::collision::{Collider, Pose, SdfGrid, SelfCollision, Shape};
use super::constraints::{BendingSolve, Solver, TetherParams};
use super::mesh::{MassDistribution, MeshShading, Topology, TopologyOptions};
use super::parallel::Serial;
use super::step::{Environment, Features, Pin, Simulation, Sleep, SolverParams};

/// What one fuzz input did.
#[derive(Clone, Debug, PartialEq)]
pub enum FuzzOutcome {
    /// The mesh, masses, pins or parameters were refused with a typed error (its message).
    Refused(String),
    /// The cloth was simulated for this many steps and stayed finite.
    Simulated {
        /// Steps run.
        steps: u32,
        /// Times the state had to be reset (should stay 0).
        recoveries: u32,
    },
    /// Something non-finite left the solver: a bug.
    NonFinite {
        /// The step after which it was seen.
        step: u32,
    },
}

/// Reads bytes as numbers, yielding zeros once the input runs out.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn u8(&mut self) -> u8 {
        let b = self.bytes.get(self.at).copied().unwrap_or(0);
        self.at += 1;
        b
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }

    /// A float that is usually reasonable and sometimes anything at all (NaN, ±∞, huge).
    fn f32(&mut self, scale: f32) -> f32 {
        match self.u8() % 16 {
            0 => f32::from_bits(self.u32()),
            1 => 0.0,
            _ => (f32::from(self.u8()) / 127.5 - 1.0) * scale,
        }
    }

    fn vec3(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.f32(scale), self.f32(scale), self.f32(scale))
    }
}

/// Decodes `bytes` into a cloth scene and runs it (see the module docs). Never panics.
#[must_use]
pub fn fuzz_one(bytes: &[u8]) -> FuzzOutcome {
    let mut r = Reader { bytes, at: 0 };
    // Mesh: up to 64 vertices on a coarse lattice (so coincidences are common) or anywhere.
    // Mostly 3..64 vertices and in-range triangle lists, so most inputs get past the checks;
    // now and then none, a ragged index count or an index out of range.
    let first = r.u8();
    let n = if first == 255 {
        0
    } else {
        3 + usize::from(first % 61)
    };
    let lattice = r.u8().is_multiple_of(2);
    let scale = [1e-3, 1.0, 100.0][usize::from(r.u8() % 3)];
    let positions: Vec<Vec3> = (0..n)
        .map(|_| {
            if lattice {
                Vec3::new(
                    f32::from(r.u8() % 4),
                    f32::from(r.u8() % 2),
                    f32::from(r.u8() % 4),
                ) * 0.25
                    * scale
            } else {
                r.vec3(scale)
            }
        })
        .collect();
    let count_byte = r.u8();
    let index_count = 3 * (1 + usize::from(count_byte % 32)) - usize::from(count_byte == 255);
    let indices: Vec<u32> = (0..index_count)
        .map(|_| match r.u8() {
            b @ 0..=249 => u32::from(b) % (n as u32).max(1),
            b => n as u32 + u32::from(b),
        })
        .collect();
    let topology =
        match Topology::from_triangles(&positions, None, &indices, TopologyOptions::default()) {
            Ok(t) => t,
            Err(e) => return FuzzOutcome::Refused(e.to_string()),
        };
    let mass = r.f32(2.0).abs() + if r.u8().is_multiple_of(8) { 0.0 } else { 0.01 };
    let masses = if mass.is_finite() && mass > 0.0 {
        topology.masses(mass, MassDistribution::Area)
    } else {
        vec![mass; topology.vertex_count()]
    };
    let solver = match r.u8() % 3 {
        0 => Solver::Lab {
            velocity_keep: r.f32(1.0).abs(),
        },
        1 => Solver::Pbd {
            stretch: r.f32(1.0).abs(),
            shear: r.f32(1.0).abs(),
            bending: r.f32(1.0).abs(),
        },
        _ => Solver::Xpbd {
            stretch: r.f32(1e-3).abs(),
            shear: r.f32(1e-3).abs(),
            bending: r.f32(10.0).abs(),
        },
    };
    let params = SolverParams {
        solver,
        substeps: u32::from(r.u8() % 24),
        iterations: u32::from(r.u8() % 8),
        gravity: r.vec3(20.0),
        damping: r.f32(2.0),
        max_speed: r.f32(200.0),
        // Default air: drawing its coefficients would change what the corpus's bytes decode
        // to (the stability suite covers extreme coefficients).
        air: Aerodynamics::default(),
        // Auto: bending as compliant as 1e-3 takes the implicit path on most of these meshes.
        bending_solve: BendingSolve::Auto,
        // Default sleep: fuzzed cloths that come to rest fall asleep and must stay finite.
        sleep: Sleep::default(),
    };
    let mut sim = match Simulation::new(topology, &masses, params) {
        Ok(s) => s,
        Err(e) => return FuzzOutcome::Refused(e.to_string()),
    };
    let flags = r.u8();
    let features = Features {
        self_collision: (flags & 1 != 0).then(|| SelfCollision {
            thickness: r.f32(0.2 * scale),
            friction: r.f32(1.0),
        }),
        tethers: (flags & 2 != 0).then(|| TetherParams {
            slack: r.f32(0.1),
            pins_per_vertex: 1 + usize::from(r.u8() % 4),
        }),
        tear_threshold: (flags & 4 != 0).then(|| 1.0 + r.f32(2.0)),
    };
    if let Err(e) = sim.set_features(features) {
        return FuzzOutcome::Refused(e.to_string());
    }
    let pin_count = usize::from(r.u8() % 4);
    let pins: Vec<Pin> = (0..pin_count)
        .map(|_| {
            let vertex = u32::from(r.u8()) % (sim.state().len() as u32 + 1);
            Pin {
                vertex,
                target: r.vec3(scale),
            }
        })
        .collect();
    if let Err(e) = sim.state_mut().set_pins(pins) {
        return FuzzOutcome::Refused(e.to_string());
    }
    // Environment: a ball moving at up to 100 m/s, maybe an SDF of the mesh itself, wind.
    let ball_from = r.vec3(scale);
    let ball_velocity = r.vec3(100.0);
    let mut colliders = Vec::new();
    if flags & 8 != 0 {
        colliders.push(Collider {
            shape: Shape::Sphere {
                radius: r.f32(scale).abs(),
            },
            start: Pose::at(ball_from),
            end: Pose::at(ball_from + ball_velocity / 60.0),
            thickness: r.f32(0.01 * scale).abs(),
            friction: r.f32(1.0).abs(),
        });
    }
    if flags & 16 != 0
        && let Ok(sdf) = SdfGrid::from_mesh(sim.topology().rest_positions(), &indices, 8)
    {
        colliders.push(Collider::fixed(
            Shape::Mesh(Arc::new(sdf)),
            Pose {
                translation: r.vec3(scale),
                rotation: Quat::from_rotation_y(r.f32(3.0)),
                scale: 1.0,
            },
            0.01 * scale,
            0.3,
        ));
    }
    let wind_params = WindParams {
        velocity: r.vec3(100.0),
        ..Default::default()
    };
    // Wind the plugin would refuse (NaN velocity) is not passed on.
    let wind = (flags & 32 != 0 && wind_params.validate().is_ok())
        .then(|| WindField::new([(wind_params, None)]));
    // Colliders the plugin would refuse are not passed on.
    colliders.retain(|c| c.validate().is_ok());
    let steps = 1 + u32::from(r.u8() % 12);
    let mut recoveries = 0;
    for step in 0..steps {
        let dt = [1e-4, 1.0 / 60.0, 0.1][usize::from(r.u8() % 3)];
        let env = Environment {
            colliders: &colliders,
            wind: wind.as_ref(),
            time: f64::from(step) * f64::from(dt),
        };
        let report = sim.step_in(dt, &env, &Serial);
        recoveries += u32::from(report.recovered);
        let shading = MeshShading::of_particles(sim.topology(), &sim.state().positions);
        if sim.state().non_finite_count() > 0
            || shading.normals().iter().any(|n| !n.is_finite())
            || shading.tangents().iter().any(|t| !t.is_finite())
        {
            return FuzzOutcome::NonFinite { step };
        }
    }
    FuzzOutcome::Simulated { steps, recoveries }
}
