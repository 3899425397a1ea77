//! Solver settings: which solver, how many substeps and iterations, and the material.
//!
//! These are plain data. The Bevy component [`ClothConfig`](crate::cloth::ClothConfig)
//! mirrors them and converts with `into()`; tests and headless tools use them directly.

use glam::Vec3;

use super::air::Aerodynamics;
use super::limits;
use super::sleep::Sleep;

/// Relaxation weight of the lab rule (seed 000): `x ← (0.2·x + Σx)/(0.2 + n)`.
pub const LAB_WEIGHT: f32 = 0.2;

/// Default XPBD bending compliance, 1/(N·m): `B` = 1e-4 N·m, a heavy fabric.
pub const DEFAULT_BENDING_COMPLIANCE: f32 = 1.0e4;

/// Which constraint solver projects the cloth, with its material parameters.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solver {
    /// Seed 000's Jacobi averaging: every edge projection is summed per vertex, then
    /// `x ← (0.2·x + Σx)/(0.2 + n)` and `v ← v + (x_new − x)/Δt` each iteration.
    ///
    /// Every triangle edge is a rigid distance constraint; there is no bending. Velocities are
    /// multiplied by `velocity_keep` once per step, before gravity (the lab uses 0.99).
    /// [`SolverParams::damping`] is not used by this solver.
    Lab {
        /// Fraction of the velocity kept at the start of each step (seed 000: 0.99).
        velocity_keep: f32,
    },
    /// Gauss–Seidel Position Based Dynamics (Müller et al. 2006). Stiffnesses are in `[0, 1]`:
    /// the fraction of each constraint's error removed per projection. The effective stiffness
    /// grows with iterations and substeps.
    Pbd {
        /// Stiffness of warp/weft (stretch) edges, `[0, 1]`.
        stretch: f32,
        /// Stiffness of diagonal (shear) edges, `[0, 1]`.
        shear: f32,
        /// Dihedral bending stiffness, `[0, 1]`; `0` switches the bending pass off.
        bending: f32,
    },
    /// Extended PBD (Macklin et al. 2016): compliances (inverse stiffnesses) in physical
    /// units. At the default 10 substeps × 1 iteration, stretch and shear are enforced only
    /// as far as one Gauss–Seidel sweep per substep carries them (a fine mesh stretches);
    /// isometric bending is enforced at any resolution and substep count within ±9 %
    /// (implicitly where a projection could not, see [`BendingSolve`] and the README's
    /// "Stiffness" section for what was measured).
    Xpbd {
        /// Compliance of stretch edges in m/N; `0` is inextensible.
        stretch: f32,
        /// Compliance of shear edges in m/N.
        shear: f32,
        /// Bending compliance `1/B` in 1/(N·m), `B` the flexural rigidity per unit width
        /// (woven fabrics: `B` ≈ 1e-6 to 1e-4 N·m, so 1e4 to 1e6). With the isometric model
        /// it is a material constant: the same cloth at any mesh resolution (tested on a
        /// cantilever, `tests/stiffness.rs`). `f32::INFINITY` switches bending off.
        bending: f32,
    },
}

impl Solver {
    /// Seed 000's lab solver with its damping of 0.99.
    pub const LAB: Solver = Solver::Lab {
        velocity_keep: 0.99,
    };

    /// Short lower-case name: `lab`, `pbd` or `xpbd`.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Solver::Lab { .. } => "lab",
            Solver::Pbd { .. } => "pbd",
            Solver::Xpbd { .. } => "xpbd",
        }
    }

    /// Whether this solver projects bending constraints at all with these parameters.
    #[must_use]
    pub fn bending_enabled(&self) -> bool {
        match *self {
            Solver::Lab { .. } => false,
            Solver::Pbd { bending, .. } => bending > 0.0,
            Solver::Xpbd { bending, .. } => bending.is_finite(),
        }
    }
}

impl Default for Solver {
    /// XPBD with inextensible stretch, slightly compliant shear and the bending of a heavy
    /// fabric (`B` = 1e-4 N·m): a flag hangs in calm air and flutters in wind, a curtain
    /// folds.
    fn default() -> Self {
        Solver::Xpbd {
            stretch: 0.0,
            shear: 1e-6,
            bending: DEFAULT_BENDING_COMPLIANCE,
        }
    }
}

/// How XPBD solves isometric bending (see the README's "Stiffness" section).
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BendingSolve {
    /// Projected while a substep can carry the stiffness, implicit where it cannot (the
    /// cloth's saturation above [`IMPLICIT_BENDING_SATURATION`]) and the solve is affordable
    /// (up to [`IMPLICIT_BENDING_AUTO_WORK`], a 64 × 64 grid).
    ///
    /// [`IMPLICIT_BENDING_SATURATION`]: super::IMPLICIT_BENDING_SATURATION
    /// [`IMPLICIT_BENDING_AUTO_WORK`]: super::IMPLICIT_BENDING_AUTO_WORK
    #[default]
    Auto,
    /// Hinge by hinge, in the same sweep as the distances: cheapest, softer than set when the
    /// saturation is above about 0.5.
    Projected,
    /// One sparse linear solve per substep (implicit Euler on the bending energy): the set
    /// stiffness at any resolution, up to [`IMPLICIT_BENDING_MAX_WORK`].
    ///
    /// [`IMPLICIT_BENDING_MAX_WORK`]: super::IMPLICIT_BENDING_MAX_WORK
    Implicit,
}

/// Everything a step needs to know about how to solve, apart from the cloth itself.
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

/// A solver parameter that is out of its range.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    /// The parameter's name, e.g. `"substeps"`.
    pub name: &'static str,
    /// Why it is rejected.
    pub reason: String,
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "invalid solver parameter `{}`: {}",
            self.name, self.reason
        )
    }
}

impl std::error::Error for ParamError {}

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

impl Solver {
    /// Checks the material parameters against their [`limits`].
    ///
    /// # Errors
    /// A [`ParamError`] naming the first parameter out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        match *self {
            Solver::Lab { velocity_keep } => limits::LAB_VELOCITY_KEEP.check(velocity_keep),
            Solver::Pbd {
                stretch,
                shear,
                bending,
            } => {
                limits::PBD_STIFFNESS.named("stretch").check(stretch)?;
                limits::PBD_STIFFNESS.named("shear").check(shear)?;
                limits::PBD_STIFFNESS.named("bending").check(bending)
            }
            Solver::Xpbd {
                stretch,
                shear,
                bending,
            } => {
                limits::XPBD_COMPLIANCE.named("stretch").check(stretch)?;
                limits::XPBD_COMPLIANCE.named("shear").check(shear)?;
                if bending == f32::INFINITY {
                    Ok(())
                } else {
                    limits::XPBD_BENDING_COMPLIANCE.check(bending)
                }
            }
        }
    }
}
