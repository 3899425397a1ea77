//! Solver settings: which solver, how many substeps and iterations, the material
//! ([`SolverParams`]), and the optional capabilities of a cloth ([`Features`]).
//!
//! These are plain data; the Bevy plugin uses [`SolverParams`] itself as the cloth's
//! `ClothConfig` component, and tests and headless tools use it directly.

use glam::Vec3;

use super::sleep::Sleep;
use crate::solver::air::Aerodynamics;
use crate::solver::collision::SelfCollision;
use crate::solver::constraints::{BendingSolve, Solver, TetherParams};
use crate::solver::limits::{self, ParamError};

/// Everything a step needs to know about how to solve, apart from the cloth itself.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverParams {
    /// The solver and its material.
    pub solver: Solver,
    /// Substeps per step: each integrates and projects once per iteration. For PBD and XPBD,
    /// prefer substeps over iterations (Macklin et al., "Small Steps in Physics Simulation").
    pub substeps: u32,
    /// Projection iterations per substep.
    pub iterations: u32,
    /// Gravity acceleration in m/s².
    pub gravity: Vec3,
    /// Linear velocity damping in 1/s (PBD and XPBD): `v ← v / (1 + damping·h)` each substep.
    pub damping: f32,
    /// Speed limit for free vertices in m/s (default 100): a vertex's velocity is clamped to
    /// it at the end of each substep, so the kinetic energy of a cloth of mass `M` never
    /// exceeds `½·M·max_speed²`, whatever a hitch, a collider or the wind does to it. Pins are
    /// kinematic and not limited.
    pub max_speed: f32,
    /// How the cloth meets the air it moves through, with or without wind (PBD and XPBD; the
    /// lab solver has no air). [`Aerodynamics::NONE`] simulates a vacuum.
    pub air: Aerodynamics,
    /// How XPBD solves isometric bending: projected or implicit (PBD, the lab solver and
    /// dihedral bending always project).
    pub bending_solve: BendingSolve,
    /// When the cloth at rest stops being stepped ([`Sleep::NEVER`] keeps it always awake).
    pub sleep: Sleep,
}

impl Default for SolverParams {
    fn default() -> Self {
        Self {
            solver: Solver::default(),
            substeps: 10,
            iterations: 1,
            gravity: Vec3::new(0.0, -9.81, 0.0),
            damping: 0.1,
            max_speed: 100.0,
            air: Aerodynamics::default(),
            bending_solve: BendingSolve::Auto,
            sleep: Sleep::default(),
        }
    }
}

impl SolverParams {
    /// Largest accepted substep and iteration counts: enough for any converged reference.
    pub const MAX_COUNT: u32 = limits::SUBSTEPS.max as u32;
    /// Largest accepted gravity, m/s² (about 10 000 g).
    pub const MAX_GRAVITY: f32 = limits::GRAVITY.max;
    /// Largest accepted speed limit, m/s (ten times the speed of sound in air: nothing a cloth
    /// survives).
    pub const MAX_SPEED: f32 = limits::MAX_SPEED.max;
    /// Largest accepted [`Sleep::energy`], J/kg (an rms speed of about 1.4 m/s: a cloth
    /// moving that fast is not at rest).
    pub const MAX_SLEEP_ENERGY: f32 = limits::SLEEP_ENERGY.max;

    /// Checks every parameter against its [`limits`] entry and says which one is wrong.
    ///
    /// # Errors
    /// A [`ParamError`] naming the first parameter out of range: substeps or iterations
    /// outside [`limits::SUBSTEPS`], gravity not finite or longer than
    /// [`limits::GRAVITY`], damping, speed limit, air coefficients, sleep energy or steps, or
    /// a solver's stiffness or compliance outside its limit (infinite bending compliance is
    /// allowed: it means no bending).
    pub fn validate(&self) -> Result<(), ParamError> {
        limits::SUBSTEPS.check_count(self.substeps)?;
        limits::ITERATIONS.check_count(self.iterations)?;
        limits::GRAVITY.check_length(self.gravity)?;
        limits::DAMPING.check(self.damping)?;
        limits::MAX_SPEED.check(self.max_speed)?;
        self.air.validate()?;
        limits::SLEEP_ENERGY.check(self.sleep.energy)?;
        limits::SLEEP_STEPS.check_count(self.sleep.steps)?;
        self.solver.validate()
    }
}

/// Optional per-cloth capabilities; each costs nothing while `None`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Features {
    /// Keep the cloth from passing through itself.
    pub self_collision: Option<SelfCollision>,
    /// Long-range attachments from every vertex to its nearest pin.
    pub tethers: Option<TetherParams>,
    /// Tear edges stretched past this factor of their rest length (> 1).
    pub tear_threshold: Option<f32>,
}

impl Features {
    /// Checks every setting against its [`limits`] entry.
    ///
    /// # Errors
    /// [`ParamError`] naming the first setting out of range: self-collision thickness or
    /// friction, tether slack or pins per vertex, tear threshold.
    pub fn validate(&self) -> Result<(), ParamError> {
        if let Some(sc) = self.self_collision {
            limits::SELF_COLLISION_THICKNESS.check(sc.thickness)?;
            limits::SELF_COLLISION_FRICTION.check(sc.friction)?;
        }
        if let Some(t) = self.tethers {
            limits::TETHER_SLACK.check(t.slack)?;
            // Pins per vertex are far below 2^24: the conversion is exact.
            limits::TETHER_PINS.check(t.pins_per_vertex as f32)?;
        }
        if let Some(t) = self.tear_threshold {
            limits::TEAR_THRESHOLD.check(t)?;
        }
        Ok(())
    }
}
