//! The cloth solver core: pure math, no Bevy.
//!
//! Its folders, each importing only from those listed before it:
//! - `limits` (the accepted range of every setting, [`ParamError`]) and `parallel` (how work
//!   is spread over threads: [`Parallel`], [`Serial`], [`Workers`]);
//! - `mesh`: [`Topology`], [`Grid`], welding ([`MeshBinding`]), hinge geometry, normals and
//!   tangents;
//! - `constraints`: [`Solver`], the distance and bending projections, implicit bending,
//!   tethers, [`ConstraintBatches`];
//! - `collision`: [`Shape`], [`Collider`], signed distance fields, self-collision, ray queries;
//! - `air`: [`Aerodynamics`] and [`WindField`];
//! - `step`: [`SolverParams`], [`ClothState`], [`step()`], [`Simulation`], sleeping, tearing,
//!   teleports, [`step_many`];
//! - `metrics` (strain and distances), `scene` ([`HangingCloth`], the scene benchmarks and
//!   tests are built on) and `fuzz` (the fuzz target) use them.
//!
//! Everything is re-exported here, so users write `bevy_cloth::solver::Simulation`.
//!
//! Data enters as a triangle mesh or a [`Grid`] → [`Topology`] (edges, bending pairs) →
//! [`ConstraintBatches`] (partitioned, coloured) plus a [`ClothState`] (positions, velocities,
//! pins). [`step()`] advances them by a time step with the chosen [`Solver`]; [`MeshShading`]
//! produces shading data for the user's mesh; [`edge_strain`] measures accuracy. Everything
//! a step needs is passed in explicitly, so the same code runs in the Bevy plugin, in tests
//! and in the benchmark, and every GPU kernel has its reference here.
//!
//! [`Simulation`] bundles these pieces for the common case.
//!
//! # Example
//! ```
//! use bevy_cloth::solver::{Grid, MassDistribution, Pin, Serial, Simulation, SolverParams, TopologyOptions};
//!
//! let grid = Grid::new(16, 16, 1.0, 1.0);
//! let topology = grid.topology(TopologyOptions::default()).unwrap();
//! let masses = topology.masses(1.0, MassDistribution::Uniform);
//! let mut sim = Simulation::new(topology, &masses, SolverParams::default()).unwrap();
//! let corners = [grid.index(0, 0), grid.index(15, 0)];
//! sim.state_mut()
//!     .set_pins(corners.map(|v| Pin { vertex: v, target: grid.positions()[v as usize] }))
//!     .unwrap();
//! let mut lowest = 0.0f32;
//! for _ in 0..60 {
//!     sim.step(1.0 / 60.0, &Serial);
//!     lowest = (0..256).map(|i| sim.state().position(i).y).fold(lowest, f32::min);
//! }
//! assert!(lowest < -0.9); // it swung down like a pendulum from its corners,
//! assert_eq!(sim.state().position(0), grid.positions()[0]); // which stayed put
//! ```

pub(crate) mod air;
pub(crate) mod collision;
pub(crate) mod constraints;
pub mod fuzz;
pub mod limits;
pub(crate) mod mesh;
pub(crate) mod metrics;
pub(crate) mod parallel;
mod scene;
pub(crate) mod step;

pub use air::{
    Aerodynamics, AirGrid, WindField, WindParams, WindRegion, air_force, air_velocity_change,
    vertex_area_vectors,
};
pub use collision::{
    Collider, ContactImpulse, MAX_SELF_NEIGHBOURS, MAX_SELF_TRIANGLES, NEAR_CORNER_THICKNESS, Pose,
    RayHit, SdfError, SdfGrid, SelfCollision, SelfCollisionScratch, Shape, count_self_crossings,
    point_triangle_distance, ray_hit, ray_shape, triangle_reach,
};
pub use constraints::{
    BendingSolve, ConstraintBatches, DEFAULT_BENDING_COMPLIANCE, IMPLICIT_BENDING_AUTO_WORK,
    IMPLICIT_BENDING_GRAVITY_NUMBER, IMPLICIT_BENDING_MAX_SATURATION, IMPLICIT_BENDING_MAX_WORK,
    IMPLICIT_BENDING_SATURATION, LAB_WEIGHT, MotionConstraints, SYMMETRIC_SWEEP_DEGREE, Solver,
    TetherParams, Tethers, default_part_count,
};
pub use limits::{
    DEFAULT_SHORT_EDGE_THICKNESS, EVEN_EDGE_SPREAD, MAX_COORDINATE, MAX_SELF_COLLISION_EDGES,
    MAX_TRIANGLES, MAX_VERTEX_MASS, MAX_VERTICES, ParamError, REST_GAP_IGNORED, REST_GAP_THICKNESS,
    SHORT_EDGE_THICKNESS,
};
pub use mesh::{
    Bend, BendRest, BendingModel, Edge, EdgeKind, Grid, HARD_EDGE_COS, MassDistribution,
    MeshAttributes, MeshBinding, MeshShading, Topology, TopologyError, TopologyOptions, Weld,
    bend_angle, dihedral_angle, dihedral_weight, hinge_coefficients, hinge_curvature,
};
pub use metrics::{StrainStats, edge_strain, max_stretch, max_stretch_beyond, position_distance};
pub use parallel::{Parallel, Serial, Workers};
pub use scene::HangingCloth;
pub use step::{
    CarriedVelocity, Carry, ClothState, DEFAULT_TELEPORT_DISTANCE, Environment, Features,
    LabScratch, MAX_SETTLE_STEPS, ManyItem, Pin, SETTLE_SPEED, SETTLE_STEPS, Simulation, Sleep,
    SolverError, SolverParams, StateError, StepInput, StepReport, StepScratch, Stretch,
    WAKE_AIR_SPEED, WAKE_DISTANCE, is_teleport, lab_step, overstretched_edges, step, step_many,
    teleport_offset,
};

#[cfg(test)]
mod tests;
