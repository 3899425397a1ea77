//! The step and [`Simulation`]: the state of a cloth, its settings, one step of the solver
//! over its substeps, and what happens around a step (sleeping, tearing, teleports, many
//! cloths at once).
//!
//! [`step`] integrates, projects the constraints, collides and updates velocities, substep by
//! substep; [`Simulation`] bundles one cloth's pieces and adds what lives between steps:
//! settling after a change of settings, tearing, the NaN guard, sleeping. [`step_many`] steps
//! several cloths on shared threads.

mod inertia;
mod lab;
mod many;
mod params;
mod simulation;
pub(crate) mod sleep;
pub(crate) mod state;
pub(crate) mod substeps;
mod tear;
mod teleport;

pub use inertia::{CarriedVelocity, Carry, Stretch};
pub use lab::{LabScratch, lab_step};
pub use many::{ManyItem, step_many};
pub use params::{Features, SolverParams};
pub use simulation::{
    Environment, MAX_SETTLE_STEPS, SETTLE_SPEED, SETTLE_STEPS, Simulation, SolverError, StepReport,
};
pub use sleep::{Sleep, WAKE_AIR_SPEED, WAKE_DISTANCE};
pub use state::{ClothState, Pin, StateError};
pub use substeps::{StepInput, StepScratch, step};
pub use tear::overstretched_edges;
pub use teleport::{DEFAULT_TELEPORT_DISTANCE, is_teleport, teleport_offset};
