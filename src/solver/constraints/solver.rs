//! Which constraint solver projects a cloth ([`Solver`]: the lab's Jacobi rule, PBD or XPBD,
//! with their material) and how XPBD solves isometric bending ([`BendingSolve`]).

use crate::solver::limits::{self, ParamError};

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
    /// [`SolverParams::damping`](crate::solver::SolverParams::damping) is not used by this solver.
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
    /// (implicitly where a projection could not, see [`BendingSolve`] and `docs/experiments.md`'s
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

/// How XPBD solves isometric bending (see "Stiffness" in `docs/experiments.md`).
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BendingSolve {
    /// Projected while a substep can carry the stiffness or the cloth's weight shapes it
    /// more than its bending does; implicit where a substep cannot (the cloth's saturation
    /// above [`IMPLICIT_BENDING_SATURATION`]), its bending matters against its weight (its
    /// gravity number `ρ g L³ / B` under [`IMPLICIT_BENDING_GRAVITY_NUMBER`]: stiff
    /// materials, small pieces, no gravity) and the solve is affordable (up to
    /// [`IMPLICIT_BENDING_AUTO_WORK`], a 64 × 64 grid). At the default `B` (1e-4 N·m) and
    /// 0.2 kg/m², a cloth longer than about 25 cm is projected at any resolution: the implicit
    /// solve costs 2.5–9 times the projected step and changes its drape by under 1.3 %.
    ///
    /// [`IMPLICIT_BENDING_SATURATION`]: super::IMPLICIT_BENDING_SATURATION
    /// [`IMPLICIT_BENDING_GRAVITY_NUMBER`]: super::IMPLICIT_BENDING_GRAVITY_NUMBER
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
