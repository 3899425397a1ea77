//! Cloth at rest costs almost nothing: a cloth whose kinetic energy stays low for a while
//! stops being stepped until something that could move it changes.
//!
//! After each step the solver measures the cloth's mean kinetic energy per kilogram,
//! `½ Σ mᵢ|vᵢ|² / Σ mᵢ` over its free vertices. When it stays below [`Sleep::energy`] for
//! [`Sleep::steps`] steps in a row, or when the cloth stays *still* for as many steps (its
//! mass-weighted rms distance from where it was when they began no more than the distance
//! its rms speed at [`Sleep::energy`] covers in [`Sleep::steps`] steps: 1.6 mm at the
//! defaults and 60 Hz), the cloth falls asleep: its velocities are zeroed and
//! [`Simulation::step_in`](super::Simulation::step_in) returns at once, leaving positions
//! exactly as they were.
//!
//! The second rule is for a pile of cloth with self-collision: where the contacts and the
//! constraints fight (a fold tighter than the thickness allows), vertices shake by a
//! millimetre or so from substep to substep and step to step without going anywhere, so
//! their energy never falls below [`Sleep::energy`]; by the still rule a crumpled pile
//! sleeps within a few seconds, as it does without self-collision
//! (docs/experiments.md, *A pile with self-collision never fell asleep*). A cloth that
//! moves, however slowly, at more than that rms speed leaves the distance and stays awake.
//! A run of still steps begins only at a step whose energy is under a thousand times
//! [`Sleep::energy`], so a moving cloth does not copy its positions every step.
//!
//! What it remembers when it falls asleep decides when it wakes (in the step where the
//! change is seen, before that step is taken):
//!
//! - a pin is added, removed, or its target moves by more than [`WAKE_DISTANCE`];
//! - a collider whose bounding ball reaches the cloth's bounds within the step (one that
//!   flies through them between its start and end poses counts) appears, disappears, moves
//!   (by more than [`WAKE_DISTANCE`] or turns), or changes shape, thickness or friction;
//! - the air at the cloth (sampled at the centre and the 8 corners of its bounds) changes by
//!   more than [`WAKE_AIR_SPEED`], for a cloth that feels the air;
//! - its settings or features change, it is reset, or [`Simulation::wake`] is called
//!   (moving vertices through `state_mut` alone does not wake it).
//!
//! While asleep a step costs the comparison above: the pins, the colliders and nine wind
//! samples, nothing per vertex.
//!
//! [`Simulation::wake`]: super::Simulation::wake

use std::sync::Arc;

use glam::{Vec3, Vec4, Vec4Swizzles};

use super::state::Pin;
use crate::solver::air::WindField;
use crate::solver::collision::{Collider, Pose, Shape};

/// A pin target or a collider moving more than this (metres) wakes a sleeping cloth.
pub const WAKE_DISTANCE: f32 = 1e-4;

/// The air at a sleeping cloth changing by more than this (m/s) wakes it.
pub const WAKE_AIR_SPEED: f32 = 0.05;

/// When a cloth at rest stops being stepped (see [`SolverParams::sleep`](super::SolverParams::sleep)).
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sleep {
    /// Mean kinetic energy per kilogram, J/kg (= m²/s²), below which a step counts as quiet:
    /// `½ v²` of the mass-weighted mean squared speed. The default, `5e-6`, is an rms speed
    /// of about 3 mm/s. `0` never sleeps.
    pub energy: f32,
    /// Quiet (or still) steps in a row after which the cloth sleeps (default 30: half a
    /// second at 60 Hz). A step is *still* when the cloth's rms distance from where it was
    /// when the run began is at most `√(2·energy) · steps · dt`: a cloth that shakes in place
    /// (a pile of cloth with self-collision) sleeps too.
    pub steps: u32,
}

impl Sleep {
    /// Never sleeps.
    pub const NEVER: Sleep = Sleep {
        energy: 0.0,
        steps: 0,
    };

    /// Whether this setting can ever put a cloth to sleep.
    #[must_use]
    pub fn enabled(&self) -> bool {
        self.energy > 0.0 && self.steps > 0
    }
}

impl Default for Sleep {
    fn default() -> Self {
        Self {
            energy: 5e-6,
            steps: 30,
        }
    }
}

/// A run of still steps (see [`Sleep::steps`]) begins only at a step whose kinetic energy is
/// under this many times [`Sleep::energy`] (an rms speed of about 10 cm/s at the default),
/// so that a moving cloth does not copy its positions every step for a run that cannot last.
pub(crate) const STILL_START_ENERGY: f32 = 1000.0;

/// What a sleeping cloth remembers, to notice what would wake it.
#[derive(Clone, Debug, Default)]
pub(crate) struct SleepState {
    /// Quiet steps in a row so far.
    pub quiet: u32,
    /// Where the cloth was when its current run of still steps began (empty: no run).
    anchor: Vec<Vec4>,
    /// Still steps in a row so far: the cloth stayed near `anchor`.
    still: u32,
    pub asleep: bool,
    pins: Vec<Pin>,
    /// The cloth's bounds when it fell asleep.
    lo: Vec3,
    hi: Vec3,
    colliders: Vec<Collider>,
    /// Air velocity at the bounds' centre and corners (zero where no wind is felt).
    air: [Vec3; 9],
}

/// The mass-weighted rms distance of the free vertices (`w > 0`) of `positions` from
/// `anchor` (0 with none free).
fn rms_distance(positions: &[Vec4], anchor: &[Vec4]) -> f32 {
    let (mut sum, mut mass) = (0.0f64, 0.0f64);
    for (p, a) in positions.iter().zip(anchor) {
        if p.w > 0.0 {
            let m = 1.0 / f64::from(p.w);
            sum += m * f64::from(p.xyz().distance_squared(a.xyz()));
            mass += m;
        }
    }
    if mass > 0.0 {
        (sum / mass).sqrt() as f32
    } else {
        0.0
    }
}

fn pose_moved(a: &Pose, b: &Pose) -> bool {
    a.translation.distance(b.translation) > WAKE_DISTANCE
        || a.rotation.dot(b.rotation).abs() < 1.0 - 1e-7
}

fn same_collider(a: &Collider, b: &Collider) -> bool {
    let shape = match (&a.shape, &b.shape) {
        (Shape::Mesh(x), Shape::Mesh(y)) => Arc::ptr_eq(x, y),
        (x, y) => x == y,
    };
    shape
        && a.thickness == b.thickness
        && a.friction == b.friction
        && !pose_moved(&a.start, &b.start)
        && !pose_moved(&a.end, &b.end)
}

impl SleepState {
    /// The colliders of `all` whose bounding ball may reach the box `lo..hi` within the step:
    /// the box around the ball at its start and end poses overlaps it (a collider that flies
    /// through the cloth within one step, neither end near it, counts).
    fn touching(lo: Vec3, hi: Vec3, all: &[Collider]) -> impl Iterator<Item = &Collider> {
        all.iter().filter(move |c| {
            let r = c.shape.bounding_radius() + c.thickness + WAKE_DISTANCE;
            let (a, b) = (c.start.translation, c.end.translation);
            let (sweep_lo, sweep_hi) = (a.min(b) - Vec3::splat(r), a.max(b) + Vec3::splat(r));
            !(r.is_finite() && sweep_lo.is_finite() && sweep_hi.is_finite())
                || (sweep_lo.cmple(hi).all() && sweep_hi.cmpge(lo).all())
        })
    }

    /// The air's velocity at the centre and the 8 corners of `lo..hi` (zero without wind).
    fn air_samples(lo: Vec3, hi: Vec3, wind: Option<&WindField>, t: f64) -> [Vec3; 9] {
        let Some(wind) = wind else {
            return [Vec3::ZERO; 9];
        };
        core::array::from_fn(|k| {
            let p = match k {
                8 => 0.5 * (lo + hi),
                k => Vec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                ),
            };
            wind.velocity_at(p, t)
        })
    }

    /// Puts the cloth to sleep, remembering what would wake it.
    pub fn fall_asleep(
        &mut self,
        positions: &[Vec4],
        pins: &[Pin],
        colliders: &[Collider],
        wind: Option<&WindField>,
        t: f64,
    ) {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for p in positions {
            lo = lo.min(p.xyz());
            hi = hi.max(p.xyz());
        }
        self.asleep = true;
        self.quiet = 0;
        self.forget_still();
        self.lo = lo;
        self.hi = hi;
        self.pins.clear();
        self.pins.extend_from_slice(pins);
        self.colliders.clear();
        self.colliders
            .extend(Self::touching(lo, hi, colliders).cloned());
        self.air = Self::air_samples(lo, hi, wind, t);
    }

    /// Whether anything that could move the sleeping cloth changed.
    pub fn should_wake(
        &self,
        pins: &[Pin],
        colliders: &[Collider],
        wind: Option<&WindField>,
        t: f64,
    ) -> bool {
        if pins.len() != self.pins.len()
            || pins
                .iter()
                .zip(&self.pins)
                .any(|(a, b)| a.vertex != b.vertex || a.target.distance(b.target) > WAKE_DISTANCE)
        {
            return true;
        }
        let mut now = Self::touching(self.lo, self.hi, colliders);
        let mut then = self.colliders.iter();
        loop {
            match (now.next(), then.next()) {
                (None, None) => break,
                (Some(a), Some(b)) if same_collider(a, b) => {}
                _ => return true,
            }
        }
        Self::air_samples(self.lo, self.hi, wind, t)
            .iter()
            .zip(&self.air)
            .any(|(a, b)| a.distance(*b) > WAKE_AIR_SPEED)
    }

    /// Wakes the cloth (or keeps it awake) and starts counting quiet steps again.
    pub fn wake(&mut self) {
        self.asleep = false;
        self.quiet = 0;
        self.forget_still();
    }

    /// Ends any run of still steps.
    pub fn forget_still(&mut self) {
        self.anchor.clear();
        self.still = 0;
    }

    /// Counts the step just taken (of length `dt`, leaving the cloth at `positions` with
    /// kinetic energy `energy` J/kg) as quiet or not, and returns whether the cloth has come to
    /// rest by either rule of [`Sleep`]: `steps` quiet steps in a row (energy under
    /// [`Sleep::energy`]), or `steps` still steps in a row (the cloth's mass-weighted rms
    /// distance from where it was when they began at most the distance its rms speed at
    /// [`Sleep::energy`] covers in `steps` steps).
    pub fn count(&mut self, positions: &[Vec4], energy: f32, sleep: Sleep, dt: f32) -> bool {
        self.quiet = if energy < sleep.energy {
            self.quiet + 1
        } else {
            0
        };
        if self.anchor.len() == positions.len() {
            let reach = (2.0 * sleep.energy).sqrt() * sleep.steps as f32 * dt;
            if rms_distance(positions, &self.anchor) <= reach {
                self.still += 1;
            } else {
                self.forget_still();
            }
        } else {
            self.forget_still();
        }
        if self.anchor.is_empty() && energy < STILL_START_ENERGY * sleep.energy {
            self.anchor.extend_from_slice(positions);
        }
        self.quiet >= sleep.steps || self.still >= sleep.steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::{
        Environment, Grid, MassDistribution, Serial, Simulation, SolverParams, TopologyOptions,
        WindParams,
    };

    const DT: f32 = 1.0 / 60.0;

    /// Settings of the test cloths: damped enough to come to rest within seconds (at the
    /// default 0.1/s a cloth hanging from two corners swings for a minute).
    fn params() -> SolverParams {
        SolverParams {
            damping: 2.0,
            ..SolverParams::default()
        }
    }

    /// A 12² cloth of 0.5 m, pinned at two corners, hanging from rest.
    fn hanging() -> (Simulation, Grid) {
        hanging_square(12, 0.5, 0.2)
    }

    /// An `n`² cloth `size` metres square of `mass` kg, pinned at two corners of one edge.
    fn hanging_square(n: u32, size: f32, mass: f32) -> (Simulation, Grid) {
        let grid = Grid::new(n, n, size, size);
        let topology = grid.topology(TopologyOptions::default()).unwrap();
        let masses = topology.masses(mass, MassDistribution::Uniform);
        let mut sim = Simulation::new(topology, &masses, params()).unwrap();
        let rest = grid.positions();
        sim.state_mut()
            .set_pins([grid.index(0, 0), grid.index(n - 1, 0)].map(|v| Pin {
                vertex: v,
                target: rest[v as usize],
            }))
            .unwrap();
        (sim, grid)
    }

    /// Steps until the cloth sleeps; the step count.
    fn until_asleep(sim: &mut Simulation, env: &Environment<'_>, limit: usize) -> usize {
        for i in 0..limit {
            sim.step_in(DT, env, &Serial);
            if sim.is_sleeping() {
                return i + 1;
            }
        }
        panic!(
            "not asleep after {limit} steps: energy {} J/kg",
            sim.state().kinetic_energy_per_kg()
        );
    }

    fn asleep_after_step(sim: &mut Simulation, env: &Environment<'_>) -> bool {
        let before = sim.state().positions.clone();
        let report = sim.step_in(DT, env, &Serial);
        assert_eq!(report.asleep, sim.is_sleeping());
        if report.asleep {
            // Bit for bit: nothing moved.
            assert_eq!(before, sim.state().positions);
        }
        report.asleep
    }

    #[test]
    fn a_hanging_cloth_comes_to_rest_and_sleeps_without_moving() {
        let (mut sim, _) = hanging();
        let env = Environment::default();
        let steps = until_asleep(&mut sim, &env, 1200);
        // It swings for a while first (it starts flat and falls).
        assert!(steps > 60, "asleep after {steps} steps");
        let energy = sim.state().kinetic_energy_per_kg();
        assert_eq!(energy, 0.0);
        for _ in 0..100 {
            assert!(asleep_after_step(&mut sim, &env));
        }
        // Never: the same cloth stays awake.
        let (mut awake, _) = hanging();
        awake
            .set_params(SolverParams {
                sleep: Sleep::NEVER,
                ..params()
            })
            .unwrap();
        for _ in 0..steps + 100 {
            awake.step_in(DT, &env, &Serial);
            assert!(!awake.is_sleeping());
        }
    }

    /// Tethers hold the span below the pins, which a fine cloth stretches at rest: such
    /// hard limits made the hierarchical and chain solvers cycle forever (`docs/experiments.md`, "Tried for
    /// stretch"); a tethered cloth must still come to rest. At 128² it does where the plain
    /// solver keeps moving (it hangs stretched many times over, and slides).
    #[test]
    fn a_tethered_fine_cloth_comes_to_rest_where_the_plain_one_keeps_moving() {
        let make = |tethers: bool| {
            let (mut sim, _) = hanging_square(128, 1.0, 1.0);
            if tethers {
                sim.set_features(crate::solver::Features {
                    tethers: Some(crate::solver::TetherParams::default()),
                    ..Default::default()
                })
                .unwrap();
            }
            sim
        };
        let env = Environment::default();
        let steps = 900;
        let mut tethered = make(true);
        let slept = until_asleep(&mut tethered, &env, steps);
        let strain = tethered.strain().max;
        assert!(strain < 0.2, "tethered max strain {strain}");
        let mut plain = make(false);
        for _ in 0..steps {
            plain.step_in(DT, &env, &Serial);
        }
        assert!(
            !plain.is_sleeping() && plain.strain().max > 10.0 * strain,
            "the plain cloth: asleep {}, max strain {} (tethered: asleep after {slept} \
             steps, {strain})",
            plain.is_sleeping(),
            plain.strain().max
        );
    }

    /// A cloth stepped elsewhere (the GPU backend's path): its states, counted after each
    /// step by [`Simulation::count_rest`], come to rest in the same step as the cloth that
    /// steps itself; [`Simulation::sleep_in`] then puts it to sleep as that one sleeps, and
    /// [`Simulation::stays_asleep_in`] wakes it for a moved pin as `step_in` would.
    #[test]
    fn a_cloth_stepped_elsewhere_counts_its_rest_as_one_that_steps_itself() {
        let (mut own, _) = hanging();
        let (mut stepper, _) = hanging();
        stepper
            .set_params(SolverParams {
                sleep: Sleep::NEVER,
                ..params()
            })
            .unwrap();
        let (mut elsewhere, _) = hanging();
        let env = Environment::default();
        let steps = until_asleep(&mut own, &env, 1200);
        for k in 1..=steps {
            stepper.step_in(DT, &env, &Serial);
            let (p, v) = (&stepper.state().positions, &stepper.state().velocities);
            let speed2 = stepper.state().max_free_speed_squared();
            assert!(speed2 >= 2.0 * stepper.state().kinetic_energy_per_kg());
            let s = elsewhere.state_mut();
            s.positions.clone_from(p);
            s.velocities.clone_from(v);
            let rest = elsewhere.count_rest(1, DT);
            assert_eq!(rest, k == steps, "step {k} of {steps}");
            if !elsewhere.may_be_at_rest(speed2) {
                assert!(k < steps, "the last step was too fast to read back");
            }
        }
        elsewhere.sleep_in(&env, DT);
        assert!(elsewhere.is_sleeping());
        assert_eq!(elsewhere.state().positions, own.state().positions);
        assert_eq!(elsewhere.state().velocities, own.state().velocities);
        assert!(elsewhere.stays_asleep_in(&env, DT));
        let pins = elsewhere.state().pins.clone();
        elsewhere
            .state_mut()
            .set_pin_targets(pins.iter().map(|p| p.target + Vec3::new(0.0, 0.0, 0.05)));
        assert!(!elsewhere.stays_asleep_in(&env, DT));
        assert!(!elsewhere.is_sleeping());
        // Switched off, it neither counts nor sleeps.
        let mut never = stepper.clone();
        assert!(!never.count_rest(1000, DT));
        never.sleep_in(&env, DT);
        assert!(!never.is_sleeping());
        assert!(!never.may_be_at_rest(0.0));
    }

    /// The backend's two measures of a cloth that may be coming to rest: its fastest vertex
    /// (what the GPU measures each frame) and the mean energy of a state read back. A few
    /// vertices trembling fast in a cloth at rest pass the second and not the first; a whole
    /// cloth moving at 0.2 m/s passes neither; pinned vertices do not count; a NaN is no rest.
    #[test]
    fn a_few_fast_vertices_leave_a_read_back_cloth_coming_to_rest() {
        let (sim, grid) = hanging();
        let (positions, mut velocities) = (
            sim.state().positions.clone(),
            sim.state().velocities.clone(),
        );
        let fastest = |v: &[Vec4]| {
            v.iter()
                .map(|v| v.xyz().length_squared())
                .fold(0.0, f32::max)
        };
        // Two of 144 vertices at 0.5 m/s: mean ½v² = 0.25 · 2 / 144 / 2 ≈ 1.7e-3 J/kg, under
        // the 5e-3 at which a still run may begin.
        for v in [grid.index(5, 5), grid.index(6, 9)] {
            velocities[v as usize].x = 0.5;
        }
        assert!(!sim.may_be_at_rest(fastest(&velocities)));
        assert!(sim.may_be_at_rest_in(&positions, &velocities));
        // All at 0.2 m/s: ½v² = 0.02 J/kg.
        for v in &mut velocities {
            v.x = 0.2;
        }
        assert!(!sim.may_be_at_rest_in(&positions, &velocities));
        // Only the pinned corners move (w = 0): nothing free does.
        for (p, v) in positions.iter().zip(&mut velocities) {
            v.x = if p.w == 0.0 { 3.0 } else { 0.0 };
        }
        assert!(sim.may_be_at_rest_in(&positions, &velocities));
        // A non-finite velocity is no rest.
        velocities[grid.index(3, 3) as usize].y = f32::NAN;
        assert!(!sim.may_be_at_rest_in(&positions, &velocities));
    }

    #[test]
    fn a_moved_pin_wakes_it_and_a_pin_on_its_target_does_not() {
        let (mut sim, grid) = hanging();
        let env = Environment::default();
        until_asleep(&mut sim, &env, 1200);
        let pins = sim.state().pins.clone();
        // The plugin sets every target every step: unchanged targets keep it asleep.
        sim.state_mut()
            .set_pin_targets(pins.iter().map(|p| p.target));
        assert!(asleep_after_step(&mut sim, &env));
        let far = grid.index(11, 11) as usize;
        let y = sim.state().positions[far].y;
        sim.state_mut()
            .set_pin_targets(pins.iter().map(|p| p.target + Vec3::new(0.0, 0.0, 0.05)));
        assert!(!asleep_after_step(&mut sim, &env));
        sim.step_in(DT, &env, &Serial);
        assert_ne!(sim.state().positions[far].y, y);
        // A pin let go also wakes it.
        let steps = until_asleep(&mut sim, &env, 1200);
        assert!(steps > 1);
        sim.state_mut().set_pins([pins[0]]).unwrap();
        assert!(!asleep_after_step(&mut sim, &env));
    }

    #[test]
    fn colliders_near_it_wake_it_and_colliders_far_away_do_not() {
        let (mut sim, _) = hanging();
        let far = Collider::fixed(
            Shape::Sphere { radius: 0.2 },
            Pose::at(Vec3::new(10.0, 0.0, 0.0)),
            0.01,
            0.5,
        );
        let colliders = [far.clone()];
        let env = Environment {
            colliders: &colliders,
            ..Default::default()
        };
        until_asleep(&mut sim, &env, 1200);
        // Far away: moving it, adding another far one changes nothing.
        let moved_far = [Collider::fixed(
            Shape::Sphere { radius: 0.2 },
            Pose::at(Vec3::new(12.0, 0.0, 0.0)),
            0.01,
            0.5,
        )];
        let env_far = Environment {
            colliders: &moved_far,
            ..Default::default()
        };
        assert!(asleep_after_step(&mut sim, &env_far));
        // A ball pushed into the cloth from the side wakes it.
        let near = [
            far.clone(),
            Collider::fixed(
                Shape::Sphere { radius: 0.1 },
                Pose::at(Vec3::new(0.0, -0.3, 0.3)),
                0.01,
                0.5,
            ),
        ];
        let env_near = Environment {
            colliders: &near,
            ..Default::default()
        };
        assert!(!asleep_after_step(&mut sim, &env_near));
        // Resting on it, it sleeps again; taking the ball away wakes it.
        until_asleep(&mut sim, &env_near, 1200);
        assert!(asleep_after_step(&mut sim, &env_near));
        assert!(!asleep_after_step(&mut sim, &env));
        // A ball flying through it within one step, from well in front of it to well behind
        // (neither end within reach of its bounds), wakes it too.
        until_asleep(&mut sim, &env, 1200);
        let through = [
            far.clone(),
            Collider {
                shape: Shape::Sphere { radius: 0.1 },
                start: Pose::at(Vec3::new(0.0, -0.3, -3.0)),
                end: Pose::at(Vec3::new(0.0, -0.3, 3.0)),
                thickness: 0.01,
                friction: 0.5,
            },
        ];
        let env_through = Environment {
            colliders: &through,
            ..Default::default()
        };
        assert!(!asleep_after_step(&mut sim, &env_through));
    }

    #[test]
    fn wind_wakes_a_cloth_that_feels_the_air() {
        let (mut sim, _) = hanging();
        let calm = Environment::default();
        until_asleep(&mut sim, &calm, 1200);
        let breeze = WindField::new([(
            WindParams {
                velocity: Vec3::new(0.0, 0.0, 4.0),
                ..WindParams::default()
            },
            None,
        )]);
        let windy = Environment {
            wind: Some(&breeze),
            ..Default::default()
        };
        let z = sim.state().positions[100].z;
        assert!(!asleep_after_step(&mut sim, &windy));
        for _ in 0..10 {
            sim.step_in(DT, &windy, &Serial);
        }
        assert!(sim.state().positions[100].z > z + 1e-3);
        // In a vacuum the same wind does nothing and does not wake it.
        let (mut vacuum, _) = hanging();
        vacuum
            .set_params(SolverParams {
                air: crate::solver::Aerodynamics::NONE,
                ..params()
            })
            .unwrap();
        until_asleep(&mut vacuum, &calm, 1200);
        assert!(asleep_after_step(&mut vacuum, &windy));
    }

    #[test]
    fn changed_settings_wake_it_and_unchanged_ones_do_not() {
        let (mut sim, _) = hanging();
        let env = Environment::default();
        until_asleep(&mut sim, &env, 1200);
        let params = *sim.params();
        sim.set_params(params).unwrap();
        sim.set_features(*sim.features()).unwrap();
        assert!(asleep_after_step(&mut sim, &env));
        sim.set_params(SolverParams {
            gravity: Vec3::new(0.0, -9.81, 3.0),
            ..params
        })
        .unwrap();
        assert!(!sim.is_sleeping());
        assert!(!asleep_after_step(&mut sim, &env));
        until_asleep(&mut sim, &env, 1200);
        sim.wake();
        assert!(!asleep_after_step(&mut sim, &env));
    }

    /// The still rule: a cloth that shakes in place (energy above the threshold, every step
    /// within the distance of where it was) sleeps after `steps` steps; one that drifts
    /// faster than the threshold's speed, or moves too fast for a run to begin, never does.
    #[test]
    fn a_cloth_shaking_in_place_sleeps_and_a_drifting_one_does_not() {
        let sleep = Sleep::default();
        let reach = (2.0 * sleep.energy).sqrt() * sleep.steps as f32 * DT;
        let at = |offsets: &[Vec3]| -> Vec<Vec4> {
            let rest = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE];
            rest.iter()
                .zip(offsets.iter().cycle())
                .map(|(p, o)| (*p + *o).extend(1.0))
                .collect()
        };
        // Shaking: every vertex a little under the reach off, one way then the other, with
        // ten times the energy of the threshold.
        let mut state = SleepState::default();
        let shake = 0.9 * reach;
        let energy = 10.0 * sleep.energy;
        let calls: Vec<bool> = (0..=sleep.steps)
            .map(|k| {
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                state.count(&at(&[Vec3::X * 0.5 * shake * sign]), energy, sleep, DT)
            })
            .collect();
        assert!(
            calls[..sleep.steps as usize].iter().all(|&c| !c),
            "{calls:?}"
        );
        assert!(
            calls[sleep.steps as usize],
            "asleep after {} still steps",
            sleep.steps
        );
        assert_eq!(state.quiet, 0, "the energy rule counted nothing");

        // Drifting at twice the threshold's speed: never still for `steps` steps.
        let speed = 2.0 * (2.0 * sleep.energy).sqrt();
        let mut state = SleepState::default();
        for k in 0..10 * sleep.steps {
            let offset = Vec3::Z * speed * DT * k as f32;
            assert!(
                !state.count(&at(&[offset]), energy, sleep, DT),
                "asleep at step {k}"
            );
        }

        // Shaking in place but too energetic for a run to begin.
        let mut state = SleepState::default();
        for k in 0..10 * sleep.steps {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            let offsets = [Vec3::X * 0.5 * shake * sign];
            assert!(!state.count(&at(&offsets), STILL_START_ENERGY * sleep.energy, sleep, DT));
        }

        // Pinned vertices (w = 0) do not count: a cloth whose free vertices stay put is still
        // while its pins swing.
        let mut state = SleepState::default();
        let slept = (0..=sleep.steps).any(|k| {
            let mut p = at(&[Vec3::ZERO]);
            p[0] = (Vec3::Y * k as f32).extend(0.0);
            state.count(&p, energy, sleep, DT)
        });
        assert!(slept);
    }

    #[test]
    fn sleep_energy_out_of_range_is_refused() {
        for energy in [-1.0, f32::NAN, 2.0] {
            let p = SolverParams {
                sleep: Sleep { energy, steps: 30 },
                ..SolverParams::default()
            };
            assert!(p.validate().is_err(), "{energy}");
        }
    }
}
