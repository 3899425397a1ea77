//! [`Simulation`]: one cloth ready to step — its topology, state, constraint batches,
//! parameters and optional features — and what a step reports.

use glam::{Vec3, Vec4};

use super::inertia::{CarriedVelocity, Carry};
use super::params::{Features, SolverParams};
use super::sleep::{STILL_START_ENERGY, SleepState};
use super::state::{ClothState, StateError, kinetic_energy_per_kg};
use super::substeps::{StepInput, StepScratch, step};
use super::tear::overstretched_edges;
use crate::solver::air::{AirGrid, WindField};
use crate::solver::collision::{Collider, ContactImpulse, count_self_crossings};
use crate::solver::constraints::{
    ConstraintBatches, ImplicitBending, MotionConstraints, Solver, Tethers, default_part_count,
};
use crate::solver::limits::{MAX_SELF_COLLISION_EDGES, ParamError, within_range};
use crate::solver::mesh::{BendingModel, Edge, Topology, TopologyError};
use crate::solver::metrics::{StrainStats, edge_strain};
use crate::solver::parallel::Parallel;

/// Anything that stops a cloth from being simulated.
#[derive(Clone, Debug, PartialEq)]
pub enum SolverError {
    /// The mesh cannot be turned into constraints.
    Topology(TopologyError),
    /// Masses, positions or pins are invalid.
    State(StateError),
    /// A solver parameter is out of range.
    Params(ParamError),
}

impl core::fmt::Display for SolverError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SolverError::Topology(e) => e.fmt(f),
            SolverError::State(e) => e.fmt(f),
            SolverError::Params(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for SolverError {}

impl From<TopologyError> for SolverError {
    fn from(e: TopologyError) -> Self {
        SolverError::Topology(e)
    }
}

impl From<StateError> for SolverError {
    fn from(e: StateError) -> Self {
        SolverError::State(e)
    }
}

impl From<ParamError> for SolverError {
    fn from(e: ParamError) -> Self {
        SolverError::Params(e)
    }
}

/// A topology, its state, its constraint batches and parameters: one cloth, ready to step.
#[derive(Clone, Debug)]
pub struct Simulation {
    topology: Topology,
    state: ClothState,
    batches: ConstraintBatches,
    params: SolverParams,
    features: Features,
    tethers: Option<(Vec<u32>, Tethers)>,
    scratch: StepScratch,
    /// Steps left in which a settings change settles (see [`Simulation::set_params`]).
    settling: u32,
    /// Speed of every vertex when the settings changed.
    settle_speed: Vec<f32>,
    /// Largest strain after the last settling step.
    settle_strain: f32,
    air_grid: AirGrid,
    air_velocities: Vec<Vec4>,
    sleep: SleepState,
    motion: Option<Motion>,
    /// The motion carried into the coming step ([`Simulation::carry`]), not yet stepped.
    carried: Option<Carry>,
    /// The velocity of the motion carried into the last step.
    carried_velocity: Option<CarriedVelocity>,
}

/// A cloth's motion targets (see [`Simulation::set_motion_targets`]).
#[derive(Clone, Debug, Default)]
struct Motion {
    start: Vec<Vec4>,
    end: Vec<Vec4>,
    backstop: Vec<Vec4>,
    radius: f32,
}

impl Motion {
    fn constraints(&self) -> MotionConstraints<'_> {
        MotionConstraints {
            start: &self.start,
            end: &self.end,
            backstop: &self.backstop,
            backstop_radius: self.radius,
        }
    }
}

/// Steps over which a change of solver settings settles at least (see
/// [`Simulation::set_params`]); it goes on while the stretch keeps shrinking by more than 1 %
/// per step, up to [`MAX_SETTLE_STEPS`].
pub const SETTLE_STEPS: u32 = 8;

/// Most steps a change of solver settings settles over.
pub const MAX_SETTLE_STEPS: u32 = 60;

/// Speed (m/s) a vertex may have in a settling step beyond its speed when the settings changed.
pub const SETTLE_SPEED: f32 = 0.25;

/// The world a step happens in.
#[derive(Clone, Copy, Debug, Default)]
pub struct Environment<'a> {
    /// Shapes the cloth collides with.
    pub colliders: &'a [Collider],
    /// Wind, if any.
    pub wind: Option<&'a WindField>,
    /// Time in seconds at the start of the step (drives gusts and turbulence); `f64` so that
    /// hours of play keep full precision.
    pub time: f64,
}

/// What a step did that the caller may want to act on.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Edges (vertex pairs) that left the cloth during the step: those stretched past the
    /// tear threshold and those that lost every triangle with them.
    pub torn: Vec<[u32; 2]>,
    /// The state went bad (a NaN or infinite position or velocity, e.g. from a collider or
    /// wind with non-finite input) and was reset to the rest pose, at rest, pins on their
    /// targets. The caller should warn; nothing non-finite is left in the state.
    pub recovered: bool,
    /// The cloth slept through the step: nothing moved (see [`Sleep`](crate::solver::Sleep)).
    pub asleep: bool,
}

impl Simulation {
    /// A cloth at its rest positions with the given per-vertex masses.
    ///
    /// # Errors
    /// [`SolverError`] if the masses or parameters are invalid.
    pub fn new(
        topology: Topology,
        masses: &[f32],
        params: SolverParams,
    ) -> Result<Self, SolverError> {
        let positions = topology.rest_positions().to_vec();
        Self::with_positions(topology, &positions, masses, params)
    }

    /// A cloth starting at `positions` (e.g. the rest shape moved into world space).
    ///
    /// # Errors
    /// [`SolverError`] if the positions, masses or parameters are invalid or their lengths do
    /// not match the topology.
    pub fn with_positions(
        topology: Topology,
        positions: &[Vec3],
        masses: &[f32],
        params: SolverParams,
    ) -> Result<Self, SolverError> {
        params.validate()?;
        if positions.len() != topology.vertex_count() {
            return Err(SolverError::State(StateError::LengthMismatch {
                positions: positions.len(),
                masses: topology.vertex_count(),
            }));
        }
        let state = ClothState::new(positions, masses)?;
        let batches = ConstraintBatches::new(
            &topology,
            params.solver,
            default_part_count(topology.vertex_count()),
        );
        Ok(Self {
            topology,
            state,
            batches,
            params,
            features: Features::default(),
            tethers: None,
            scratch: StepScratch::default(),
            settling: 0,
            settle_speed: Vec::new(),
            settle_strain: f32::INFINITY,
            air_grid: AirGrid::default(),
            air_velocities: Vec::new(),
            sleep: SleepState::default(),
            motion: None,
            carried: None,
            carried_velocity: None,
        })
    }

    /// Rebuilds the batches with `parts` vertex ranges (see [`default_part_count`]).
    pub fn set_part_count(&mut self, parts: usize) {
        self.sleep.wake();
        self.rebuild_batches(parts);
    }

    /// Rebuilds the batches from the topology with `parts` parts, keeping their sweep order:
    /// a closed cloth torn open or split otherwise sweeps both ways as before
    /// (`ConstraintBatches::sweep_symmetrically`).
    fn rebuild_batches(&mut self, parts: usize) {
        let symmetric = self.batches.symmetric_sweeps();
        self.batches = ConstraintBatches::new(&self.topology, self.params.solver, parts);
        if symmetric {
            self.batches.sweep_symmetrically();
        }
    }

    /// Advances by `dt` seconds, alone in the world (no colliders, no wind).
    pub fn step(&mut self, dt: f32, par: &impl Parallel) -> StepReport {
        self.step_in(dt, &Environment::default(), par)
    }

    /// Advances by `dt` seconds among `env`'s colliders and wind, with this cloth's
    /// [`Features`]; tears edges afterwards if tearing is on.
    pub fn step_in(&mut self, dt: f32, env: &Environment<'_>, par: &impl Parallel) -> StepReport {
        let felt_wind = self.felt_wind(env);
        let held = self.motion.is_some();
        // Carried through the air, a cloth with aerodynamics feels the air move past it.
        let carried_through_air = self.carried.is_some() && !self.params.air.is_none();
        if held || carried_through_air {
            self.sleep.wake();
        }
        if self.sleep.asleep {
            let t = env.time + 0.5 * f64::from(dt);
            if !self
                .sleep
                .should_wake(&self.state.pins, env.colliders, felt_wind, t)
            {
                // Asleep, it met no air (a carry with aerodynamics wakes it): nothing carried
                // is kept for the air or the drawing.
                self.carried = None;
                self.carried_velocity = None;
                return StepReport {
                    asleep: true,
                    ..Default::default()
                };
            }
            self.sleep.wake();
        }
        self.prepare_tethers();
        if self.settling == MAX_SETTLE_STEPS {
            // The speeds the cloth had when the settings changed.
            self.settle_speed.clear();
            self.settle_speed
                .extend(self.state.velocities.iter().map(|v| v.length()));
        }
        let mut air = core::mem::take(&mut self.air_velocities);
        self.step_air(env.wind, env.time + 0.5 * f64::from(dt), dt, &mut air);
        self.air_velocities = air;
        step(
            &mut self.state,
            &self.topology,
            &mut self.batches,
            &self.params,
            dt,
            StepInput {
                colliders: env.colliders,
                air_velocities: &self.air_velocities,
                self_collision: self.features.self_collision,
                tethers: self.tethers.as_ref().map(|(_, t)| t),
                motion: self
                    .motion
                    .as_ref()
                    .map_or_else(MotionConstraints::default, Motion::constraints),
            },
            &mut self.scratch,
            par,
        );
        if self.settling > 0 {
            // Settle at least SETTLE_STEPS steps, then as long as the stretch still shrinks.
            let strain = self.strain().max;
            self.settling = if self.settling > MAX_SETTLE_STEPS - SETTLE_STEPS + 1 {
                self.settling - 1
            } else if strain < self.settle_strain - 0.01 {
                self.settling.saturating_sub(1).max(1)
            } else {
                0
            };
            self.settle_strain = strain;
            // The settling cloth keeps the speeds it had, and a little: it is not flung by the
            // stretch the old settings let it have.
            let slack = SETTLE_SPEED;
            let free = self.state.positions.iter().map(|p| p.w > 0.0);
            for ((v, before), free) in self
                .state
                .velocities
                .iter_mut()
                .zip(&self.settle_speed)
                .zip(free)
            {
                if !free {
                    continue;
                }
                let limit = before + slack;
                let speed = v.length();
                if speed > limit {
                    *v *= limit / speed;
                }
            }
        }
        let mut report = StepReport {
            torn: self.tear(),
            ..Default::default()
        };
        if !self.state.is_finite() {
            self.reset_to_rest();
            report.recovered = true;
        }
        if self.motion.is_some() {
            self.motion_step_taken();
        } else {
            self.count_quiet_step(env, felt_wind, dt);
        }
        report
    }

    /// Tears every edge stretched past [`Features::tear_threshold`] now: the topology loses
    /// them (and the triangles and hinges they were part of) and the constraints are rebuilt.
    /// Returns every edge that left, not only those past the threshold (an edge whose
    /// triangles all went with their torn neighbours no longer holds anything). The step does
    /// this at its end; the GPU backend calls it on the state it reads back.
    pub fn tear(&mut self) -> Vec<[u32; 2]> {
        let Some(threshold) = self.features.tear_threshold else {
            return Vec::new();
        };
        let over = overstretched_edges(&self.state.positions, self.topology.edges(), threshold);
        self.tear_edges(&over)
    }

    /// Tears `edges` (vertex pairs, either order; pairs that are not edges of the topology
    /// are ignored) as [`Self::tear`] tears the edges past the threshold, and returns every
    /// edge that left. The GPU backend calls it with the edges its tear check found, which
    /// it reads back a few frames after the GPU let go of them.
    pub fn tear_edges(&mut self, edges: &[[u32; 2]]) -> Vec<[u32; 2]> {
        if edges.is_empty() {
            return Vec::new();
        }
        let torn = self.topology.without_edges(edges);
        if torn.triangles().len() == self.topology.triangles().len()
            && torn.edges().len() == self.topology.edges().len()
        {
            return Vec::new();
        }
        let gone = vanished_edges(self.topology.edges(), torn.edges());
        self.take_topology(torn);
        gone
    }

    /// Makes the tethers current: built for the pinned vertices now where they were built for
    /// others (or not yet), none without [`Features::tethers`]. Each step does it; the GPU
    /// backend before it uploads the cloth, so that it takes them from here
    /// ([`Self::current_tethers`]) instead of building its own.
    pub(crate) fn prepare_tethers(&mut self) {
        match self.features.tethers {
            Some(params) => {
                if self.current_tethers().is_none() {
                    let pins: Vec<u32> = self.state.pins().iter().map(|p| p.vertex).collect();
                    let t = Tethers::build(&self.topology, &pins, params);
                    self.tethers = Some((pins, t));
                }
            }
            None => self.tethers = None,
        }
    }

    /// The tethers for the pinned vertices now, where [`Self::prepare_tethers`] made them
    /// (`None`: not made, made for other pins, or no tethers).
    pub(crate) fn current_tethers(&self) -> Option<&Tethers> {
        let (pins, t) = self.tethers.as_ref()?;
        let now = self.state.pins().iter().map(|p| p.vertex);
        (self.features.tethers.is_some() && pins.iter().copied().eq(now)).then_some(t)
    }

    /// Makes `topology` (the same vertices) the cloth's: its constraints rebuilt with the same
    /// part count, its implicit bending's factorisation and its tethers made again.
    fn take_topology(&mut self, topology: Topology) {
        self.topology = topology;
        self.scratch.implicit.invalidate();
        self.rebuild_batches(self.batches.part_count());
        self.tethers = None;
    }

    /// `Ok` when `topology` has this cloth's vertex count.
    fn same_vertices(&self, topology: &Topology) -> Result<(), SolverError> {
        if topology.vertex_count() == self.topology.vertex_count() {
            Ok(())
        } else {
            Err(SolverError::State(StateError::LengthMismatch {
                positions: topology.vertex_count(),
                masses: self.topology.vertex_count(),
            }))
        }
    }

    /// Takes `topology` and `masses` (one per vertex) as the cloth's, keeping its state
    /// (positions, velocities, pins): a change of mass, bending model or bend rest made to a
    /// running cloth. The constraints are rebuilt (same part count), tethers on the next step.
    ///
    /// # Errors
    /// [`SolverError::State`] if `topology` or `masses` have another vertex count or a mass is
    /// not valid (nothing changes).
    pub fn set_topology_and_masses(
        &mut self,
        topology: Topology,
        masses: &[f32],
    ) -> Result<(), SolverError> {
        self.same_vertices(&topology)?;
        self.state.set_masses(masses)?;
        self.set_rest_shape(topology)
    }

    /// Takes `topology` as the cloth's rest shape, keeping its state: the same vertices and
    /// triangles with other rest positions (its entity was scaled, see
    /// [`Stretch`](crate::solver::Stretch)). The constraints are rebuilt from it (same part
    /// count). The tethers are scaled where `topology` is the same mesh scaled evenly (an
    /// entity grown in by its scale), otherwise made again on the next step.
    ///
    /// # Errors
    /// [`SolverError::State`] if `topology` has another vertex count (nothing changes).
    pub fn set_rest_shape(&mut self, topology: Topology) -> Result<(), SolverError> {
        self.same_vertices(&topology)?;
        let was = &self.topology;
        let same_mesh = was.triangles() == topology.triangles()
            && was
                .edges()
                .iter()
                .map(|e| e.v)
                .eq(topology.edges().iter().map(|e| e.v));
        // The same mesh scaled evenly (an entity grown in by its scale): its tethers scaled
        // with it instead of searched for again at every frame of the growth.
        let tethers = self
            .tethers
            .take()
            .filter(|_| same_mesh)
            .and_then(|(pins, t)| Some((pins, t.rescaled(&topology)?)));
        if self.batches.built_from(&topology) {
            // The same constraints at other rest values: measured again, not partitioned and
            // coloured again.
            self.topology = topology;
            self.scratch.implicit.invalidate();
            self.batches.remeasure(&self.topology, self.params.solver);
        } else {
            self.take_topology(topology);
        }
        self.tethers = tethers;
        self.sleep.wake();
        Ok(())
    }

    /// After a step: counts it as quiet or not and puts the cloth to sleep after enough quiet
    /// steps in a row.
    fn count_quiet_step(&mut self, env: &Environment<'_>, wind: Option<&WindField>, dt: f32) {
        let sleep = self.params.sleep;
        if !sleep.enabled() || self.settling > 0 {
            self.reset_rest_count();
            return;
        }
        let energy = self.state.kinetic_energy_per_kg();
        if self.sleep.count(&self.state.positions, energy, sleep, dt) {
            self.fall_asleep_in(env, wind, dt);
        }
    }

    /// Puts the cloth to sleep as it is, its free vertices still, remembering what in `env`
    /// (and `wind`, the air it feels) would wake it after a step of `dt` seconds.
    fn fall_asleep_in(&mut self, env: &Environment<'_>, wind: Option<&WindField>, dt: f32) {
        for (v, x) in self.state.velocities.iter_mut().zip(&self.state.positions) {
            if x.w > 0.0 {
                *v = Vec4::ZERO;
            }
        }
        // The air sampled as `should_wake` samples it: at the middle of a step.
        let t = env.time + 0.5 * f64::from(dt);
        self.sleep.fall_asleep(
            &self.state.positions,
            &self.state.pins,
            env.colliders,
            wind,
            t,
        );
    }

    /// The air each vertex meets over the coming step of `dt` seconds, into `out` (the GPU
    /// backend's air input; empty for still air met by nothing carried, or a cloth without
    /// aerodynamics): the wind sampled at time `t` (seconds) from `field` around the
    /// positions the cloth has now, less the velocity of the motion carried into the step
    /// ([`Self::carry`]), which the cloth does not feel as inertia but is moved through the
    /// air by (a flag on a car, glued to it by `ClothInertia`, still streams in the car's
    /// airflow). Takes the carried motion; its velocity stays readable
    /// ([`Self::carried_velocity`]).
    pub(crate) fn step_air(
        &mut self,
        field: Option<&WindField>,
        t: f64,
        dt: f32,
        out: &mut Vec<Vec4>,
    ) {
        let carried = self.carried.take().and_then(|c| c.velocity(dt));
        self.carried_velocity = carried;
        out.clear();
        if self.params.air.is_none() {
            return;
        }
        let positions = &self.state.positions;
        if let Some(field) = field.filter(|w| !w.is_empty()) {
            // The air around the cloth at the middle of the step, on a coarse grid.
            self.air_grid.air_velocities(field, positions, t, out);
        }
        if let Some(v) = carried {
            if out.is_empty() {
                out.resize(positions.len(), Vec4::ZERO);
            }
            for (a, p) in out.iter_mut().zip(positions) {
                *a -= v.at(p.truncate()).extend(0.0);
            }
        }
    }

    /// Moves the whole cloth by `carry` (see [`ClothState::carry`]): motion it does not feel
    /// as inertia. Its air in the coming step moves against that motion (see
    /// [`Self::carried_velocity`]).
    pub fn carry(&mut self, carry: &Carry) {
        self.state.carry(carry);
        self.carried = carry.is_finite().then_some(*carry);
    }

    /// The velocity of the motion carried into the last step ([`Self::carry`]): each vertex
    /// moved that fast besides its own velocity (what a cloth drawn along its velocities adds
    /// to them). `None` when nothing was carried.
    #[must_use]
    pub fn carried_velocity(&self) -> Option<CarriedVelocity> {
        self.carried_velocity
    }

    /// Whether the cloth is asleep: at rest, and skipped by [`Self::step_in`] until something
    /// that could move it changes (see [`Sleep`](crate::solver::Sleep)).
    #[must_use]
    pub fn is_sleeping(&self) -> bool {
        self.sleep.asleep
    }

    /// Wakes the cloth: the next step runs, and it needs [`Sleep::steps`](crate::solver::Sleep::steps) quiet steps again
    /// before it can sleep.
    pub fn wake(&mut self) {
        self.sleep.wake();
    }

    /// For a backend that steps the cloth elsewhere (the GPU) and found it at rest: puts the
    /// cloth to sleep as its state is now (read back from that backend), its free vertices'
    /// velocities zeroed, remembering what in `env` would wake it, as [`Self::step_in`] does
    /// when a step of `dt` seconds brings it to rest. Nothing happens with sleeping switched
    /// off ([`Sleep::enabled`](crate::solver::Sleep::enabled)) or while a settings change
    /// settles.
    pub fn sleep_in(&mut self, env: &Environment<'_>, dt: f32) {
        if !self.may_sleep_now() {
            return;
        }
        self.fall_asleep_in(env, self.felt_wind(env), dt);
    }

    /// For a backend that steps the cloth elsewhere (the GPU), which measures the largest
    /// squared speed a free vertex ends its steps with: whether the cloth may be coming to
    /// rest, so that its state is worth reading back for [`Self::count_rest`] (it can sleep,
    /// nothing holds it, and no vertex is faster than the rms speed at which a run of still
    /// steps may begin, 0.1 m/s at the default [`Sleep`](crate::solver::Sleep)).
    #[must_use]
    pub fn may_be_at_rest(&self, max_speed_squared: f32) -> bool {
        self.may_sleep_now()
            && max_speed_squared < 2.0 * STILL_START_ENERGY * self.params.sleep.energy
    }

    /// For a backend that steps the cloth elsewhere, with a state of the cloth read back
    /// from it (`positions` and `velocities` laid out as [`ClothState`]'s): whether the cloth
    /// may be coming to rest, so that its state is worth reading back for [`Self::count_rest`]
    /// (it can sleep, nothing holds it, and its mean kinetic energy is under that at which a
    /// run of still steps may begin: an rms speed of 0.1 m/s at the default
    /// [`Sleep`](crate::solver::Sleep)). Unlike [`Self::may_be_at_rest`] a few vertices
    /// trembling faster (a pile of cloth with self-collision) leave it coming to rest.
    #[must_use]
    pub fn may_be_at_rest_in(&self, positions: &[Vec4], velocities: &[Vec4]) -> bool {
        self.may_sleep_now()
            && kinetic_energy_per_kg(positions, velocities)
                < STILL_START_ENERGY * self.params.sleep.energy
    }

    /// Whether the cloth may fall asleep now: sleeping is on, no settings change settles and
    /// no skin holds it.
    fn may_sleep_now(&self) -> bool {
        self.params.sleep.enabled() && self.settling == 0 && self.motion.is_none()
    }

    /// For a backend that steps the cloth elsewhere: counts `steps` steps of `dt` seconds that
    /// ended in the state the cloth has now (read back from it) by the rules of
    /// [`Sleep`](crate::solver::Sleep), as [`Self::step_in`] counts its own; returns whether
    /// the cloth has come to rest ([`Self::sleep_in`] then puts it to sleep).
    pub fn count_rest(&mut self, steps: u32, dt: f32) -> bool {
        if !self.may_sleep_now() {
            self.reset_rest_count();
            return false;
        }
        let sleep = self.params.sleep;
        let energy = self.state.kinetic_energy_per_kg();
        let mut rest = false;
        for _ in 0..steps {
            rest |= self.sleep.count(&self.state.positions, energy, sleep, dt);
        }
        rest
    }

    /// For a backend that steps the cloth elsewhere: its steps since the last count were not
    /// at rest (a run of quiet or still steps begins again).
    pub fn reset_rest_count(&mut self) {
        self.sleep.quiet = 0;
        self.sleep.forget_still();
    }

    /// For a backend that steps the cloth elsewhere, before each step while the cloth sleeps:
    /// wakes it if anything in `env` (its pins, the colliders near it, the air at it) changed
    /// as [`Self::step_in`] would, and returns whether it still sleeps.
    pub fn stays_asleep_in(&mut self, env: &Environment<'_>, dt: f32) -> bool {
        if !self.sleep.asleep {
            return false;
        }
        let t = env.time + 0.5 * f64::from(dt);
        if self
            .sleep
            .should_wake(&self.state.pins, env.colliders, self.felt_wind(env), t)
        {
            self.sleep.wake();
            return false;
        }
        true
    }

    /// The wind of `env` this cloth feels (none without aerodynamics or wind).
    fn felt_wind<'a>(&self, env: &Environment<'a>) -> Option<&'a WindField> {
        env.wind
            .filter(|w| !w.is_empty() && !self.params.air.is_none())
    }

    /// Puts every vertex back at its rest position with zero velocity, pins on their targets,
    /// and forgets accumulated multipliers: a clean start.
    pub fn reset_to_rest(&mut self) {
        let rest = self.topology.rest_positions().to_vec();
        self.reset_to(&rest);
    }

    /// Like [`Self::reset_to_rest`] at the given positions (e.g. the rest shape placed where
    /// the cloth's entity is now). Non-finite entries fall back to the rest position.
    ///
    /// # Panics
    /// If `positions` has a different length from the cloth.
    pub fn reset_to(&mut self, positions: &[Vec3]) {
        self.sleep.wake();
        let rest = self.topology.rest_positions();
        let clean: Vec<Vec3> = positions
            .iter()
            .zip(rest)
            .map(|(p, r)| if p.is_finite() { *p } else { *r })
            .collect();
        self.state.reset(&clean);
        self.state.snap_pins();
    }

    /// Sets the optional capabilities (cheap; tethers are rebuilt on the next step). Tethers
    /// added to a running cloth pull it back within one step where it is stretched past
    /// them: [`Self::settle`] then keeps that pull from flinging it (the plugin does).
    ///
    /// # Errors
    /// [`ParamError`] if a thickness, friction, slack or tear threshold is out of range, or
    /// the self-collision thickness is more than [`MAX_SELF_COLLISION_EDGES`] times the
    /// cloth's mean rest edge.
    pub fn set_features(&mut self, features: Features) -> Result<(), ParamError> {
        features.validate()?;
        if let Some(sc) = features.self_collision {
            let mean = self.topology.mean_rest_edge();
            let most = self.topology.thickest_self_collision();
            if mean > 0.0 && sc.thickness > most {
                return Err(ParamError {
                    name: "self_collision.thickness",
                    reason: format!(
                        "{} m is {:.1} times the cloth's mean rest edge ({mean} m); at most \
                         {MAX_SELF_COLLISION_EDGES} times ({most} m): layers thicker than an \
                         edge pass through each other where the cloth crumples (use a thinner \
                         layer, a coarser mesh, or no thickness for the mean edge)",
                        sc.thickness,
                        sc.thickness / mean
                    ),
                });
            }
        }
        if features != self.features {
            self.sleep.wake();
        }
        if features.tethers != self.features.tethers {
            self.tethers = None;
        }
        self.features = features;
        Ok(())
    }

    /// Holds every vertex near where something else puts it for the next step (skinned
    /// clothing; see [`MotionConstraints`]): `targets[i]` is vertex `i`'s target at the end of
    /// the step (xyz) and its max distance (`w`: 0 follows the target, negative is free);
    /// `backstop` (empty, or one per vertex) the skin's outward normal there (xyz) and how
    /// far behind the target the surface of a sphere of `backstop_radius` lies (`w`, negative:
    /// none). Over the step each target moves linearly from where the previous call put it
    /// (the first call, or `snap`: from where this one does). Targets not set again before a
    /// step stay where they are. A cloth held this way does not sleep.
    ///
    /// # Errors
    /// [`StateError::MotionLengthMismatch`] unless there is one target (and none or one
    /// backstop) per vertex; [`StateError::NonFiniteMotionTarget`] for a target or normal
    /// that is not finite or out of range, or a backstop radius that is not finite. The
    /// previous targets stay.
    pub fn set_motion_targets(
        &mut self,
        targets: &[Vec4],
        backstop: &[Vec4],
        backstop_radius: f32,
        snap: bool,
    ) -> Result<(), StateError> {
        let n = self.state.len();
        for len in [
            targets.len(),
            if backstop.is_empty() {
                n
            } else {
                backstop.len()
            },
        ] {
            if len != n {
                return Err(StateError::MotionLengthMismatch {
                    targets: len,
                    vertex_count: n,
                });
            }
        }
        let bad = targets
            .iter()
            .position(|t| !within_range(t.truncate()))
            .or_else(|| backstop.iter().position(|b| !b.truncate().is_finite()))
            .or_else(|| (!backstop_radius.is_finite()).then_some(0));
        if let Some(vertex) = bad {
            return Err(StateError::NonFiniteMotionTarget { vertex });
        }
        let fresh = snap || self.motion.is_none();
        let m = self.motion.get_or_insert_with(Motion::default);
        m.end.clear();
        m.end.extend_from_slice(targets);
        if fresh {
            m.start.clone_from(&m.end);
        }
        m.backstop.clear();
        m.backstop.extend_from_slice(backstop);
        m.radius = backstop_radius;
        self.sleep.wake();
        Ok(())
    }

    /// Lets every vertex go: no motion targets from the next step on.
    pub fn clear_motion_targets(&mut self) {
        self.motion = None;
    }

    /// Whether motion targets hold the cloth (see [`Self::set_motion_targets`]).
    #[must_use]
    pub fn has_motion_targets(&self) -> bool {
        self.motion.is_some()
    }

    /// The motion constraints the next step applies, if any.
    #[must_use]
    pub fn motion_targets(&self) -> Option<MotionConstraints<'_>> {
        self.motion.as_ref().map(Motion::constraints)
    }

    /// After a step taken elsewhere (the GPU): the targets' end becomes the next step's
    /// start, as [`Self::step_in`] does.
    pub fn motion_step_taken(&mut self) {
        if let Some(m) = &mut self.motion {
            // Targets not updated before the next step stay where they are.
            m.start.clone_from(&m.end);
        }
    }

    /// The optional capabilities in use.
    #[must_use]
    pub fn features(&self) -> &Features {
        &self.features
    }

    /// Impulse the cloth gave each collider of the last [`Self::step_in`], in N·s.
    #[must_use]
    pub fn impulses(&self) -> &[ContactImpulse] {
        self.scratch.impulses()
    }

    /// Changes the solver parameters (cheap: no rebuild).
    ///
    /// A change of solver, material, substeps or iterations *settles* over the next
    /// [`SETTLE_STEPS`] steps or more (while the stretch keeps shrinking): constraint
    /// corrections still move the cloth to its new shape, but no free vertex gets faster than
    /// it was when the settings changed (plus [`SETTLE_SPEED`]). Without that, stretch that the
    /// old settings tolerated (a cloth at 2 substeps hangs 500 % longer than at 20) springs
    /// back as a burst of speed (measured: 100 m/s on a 24² cloth; settled: no faster than
    /// before the change).
    ///
    /// # Errors
    /// [`ParamError`] if a parameter is out of range; the old parameters are kept.
    pub fn set_params(&mut self, params: SolverParams) -> Result<(), ParamError> {
        params.validate()?;
        if params != self.params {
            self.sleep.wake();
        }
        if (params.solver, params.substeps, params.iterations)
            != (
                self.params.solver,
                self.params.substeps,
                self.params.iterations,
            )
        {
            self.settling = MAX_SETTLE_STEPS;
            self.settle_strain = f32::INFINITY;
        }
        self.params = params;
        self.batches.set_solver(&self.topology, params.solver);
        Ok(())
    }

    /// Steps left in which the last settings change settles (0: none; [`MAX_SETTLE_STEPS`]
    /// before its first step) and the largest strain after its last settling step (infinite
    /// before it): what a GPU world starts the settle from (`gpu::GpuWorld`).
    #[must_use]
    pub fn settle_state(&self) -> (u32, f32) {
        (self.settling, self.settle_strain)
    }

    /// Starts a *settle* as a change of solver does ([`Self::set_params`]): for the next steps
    /// the cloth moves to the shape its constraints now want without getting faster than it
    /// is now (plus [`SETTLE_SPEED`]). For a change that tightens a running cloth, such as
    /// tethers added to a cloth stretched past them (measured: its fastest vertex at 28 m/s
    /// in the next second, against 2.7 while it fell, on a 24² cloth at 24 % strain).
    pub fn settle(&mut self) {
        self.settling = MAX_SETTLE_STEPS;
        self.settle_strain = f32::INFINITY;
    }

    /// Ends a settle in progress (the GPU backend took it over with its upload).
    pub(crate) fn stop_settling(&mut self) {
        self.settling = 0;
    }

    /// The solver parameters.
    #[must_use]
    pub fn params(&self) -> &SolverParams {
        &self.params
    }

    /// How far the last step's bending was beyond what one projection per substep carries:
    /// the largest `B h² Σ w_i a_i²` over the hinges (see [`BendingSolve`](crate::solver::BendingSolve)). Below about 0.5
    /// projected bending is the bending that was set; above it, unless the step solved it
    /// implicitly ([`Self::implicit_bending`]), the cloth is softer than set. Zero without
    /// XPBD isometric bending.
    #[must_use]
    pub fn bending_saturation(&self) -> f32 {
        self.scratch.implicit.saturation()
    }

    /// Whether steps of `dt` seconds would want bending solved implicitly (see
    /// [`BendingSolve`](crate::solver::BendingSolve)): isometric XPBD bending too stiff to project per substep.
    #[must_use]
    pub fn wants_implicit_bending(&self, dt: f32) -> bool {
        let Solver::Xpbd { bending, .. } = self.params.solver else {
            return false;
        };
        let h = dt / self.params.substeps.max(1) as f32;
        self.batches.bending
            && self.topology.options().effective_bending() == BendingModel::Isometric
            && ImplicitBending::wanted(
                &self.topology,
                &self.state.positions,
                1.0 / bending,
                h,
                (self.params.bending_solve, self.params.gravity.length()),
            )
    }

    /// Whether the last step solved bending implicitly (see [`BendingSolve`](crate::solver::BendingSolve)).
    #[must_use]
    pub fn implicit_bending(&self) -> bool {
        self.scratch.implicit.active()
    }

    /// The topology.
    #[must_use]
    pub fn topology(&self) -> &Topology {
        &self.topology
    }

    /// The constraint batches.
    #[must_use]
    pub fn batches(&self) -> &ConstraintBatches {
        &self.batches
    }

    /// The state.
    #[must_use]
    pub fn state(&self) -> &ClothState {
        &self.state
    }

    /// The state, to move pins or vertices.
    pub fn state_mut(&mut self) -> &mut ClothState {
        &mut self.state
    }

    /// Strain over every edge now.
    #[must_use]
    pub fn strain(&self) -> StrainStats {
        edge_strain(&self.state.positions, self.topology.edges())
    }

    /// How many (edge, triangle) pairs of the cloth cross each other now
    /// ([`count_self_crossings`]): 0 for a cloth that has not passed through itself.
    #[must_use]
    pub fn self_crossings(&self) -> usize {
        let edges: Vec<[u32; 2]> = self.topology.edges().iter().map(|e| e.v).collect();
        count_self_crossings(&self.state.positions, self.topology.triangles(), &edges)
    }
}

/// Edges of `before` that are not in `after` (both sorted by vertex pair, as topologies keep
/// them).
fn vanished_edges(before: &[Edge], after: &[Edge]) -> Vec<[u32; 2]> {
    let mut out = Vec::new();
    let mut j = 0;
    for e in before {
        while j < after.len() && after[j].v < e.v {
            j += 1;
        }
        if after.get(j).is_none_or(|a| a.v != e.v) {
            out.push(e.v);
        }
    }
    out
}
