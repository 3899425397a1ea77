//! Constraints: which solver projects them ([`Solver`]), the projections themselves (distance,
//! dihedral and isometric bending, written once over scalar and SIMD lanes), implicit bending,
//! tethers, and their layout for projection ([`ConstraintBatches`]: partitioned, coloured,
//! structure-of-arrays).

pub(crate) mod batches;
mod dihedral;
mod distance;
mod implicit;
mod isometric;
mod lanes;
mod motion;
mod solver;
mod tether;

pub use batches::{ConstraintBatches, SYMMETRIC_SWEEP_DEGREE, default_part_count};
pub(crate) use batches::{Mode, Part};
pub(crate) use implicit::ImplicitBending;
pub use implicit::{
    IMPLICIT_BENDING_AUTO_WORK, IMPLICIT_BENDING_GRAVITY_NUMBER, IMPLICIT_BENDING_MAX_SATURATION,
    IMPLICIT_BENDING_MAX_WORK, IMPLICIT_BENDING_SATURATION,
};
pub use motion::MotionConstraints;
pub use solver::{BendingSolve, DEFAULT_BENDING_COMPLIANCE, LAB_WEIGHT, Solver};
pub use tether::{TetherParams, Tethers};
