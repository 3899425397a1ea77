//! The cloth solver core: pure math, no Bevy.
//!
//! Data enters as a triangle mesh or a [`Grid`] → [`Topology`] (edges, bending pairs) →
//! [`ConstraintBatches`] (partitioned, coloured) plus a [`ClothState`] (positions, velocities,
//! pins). [`step`] advances them by a time step with the chosen [`Solver`]; [`vertex_normals`]
//! and [`vertex_tangents`] produce shading data; [`edge_strain`] measures accuracy. Everything
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

mod batches;
mod bending;
mod distance;
mod lab;
mod lanes;
mod metrics;
mod parallel;
mod params;
mod shading;
mod state;
mod step;
mod topology;

pub use batches::{ConstraintBatches, default_part_count};
pub use bending::dihedral_angle;
pub use lab::{LabScratch, lab_step};
pub use metrics::{StrainStats, edge_strain, position_distance};
pub use parallel::{Parallel, Serial};
pub use params::{LAB_WEIGHT, ParamError, Solver, SolverParams};
pub use shading::{vertex_normals, vertex_tangents};
pub use state::{ClothState, Pin, StateError};
pub use step::{StepScratch, step};
pub use topology::{
    Bend, BendRest, Edge, EdgeKind, Grid, MassDistribution, Topology, TopologyError,
    TopologyOptions,
};

use glam::{Vec3, Vec4};

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
    scratch: StepScratch,
    normals: Vec<Vec3>,
    tangents: Vec<Vec4>,
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
            &params,
            default_part_count(topology.vertex_count()),
        );
        let mut sim = Self {
            topology,
            state,
            batches,
            params,
            scratch: StepScratch::default(),
            normals: Vec::new(),
            tangents: Vec::new(),
        };
        sim.update_shading();
        Ok(sim)
    }

    /// Rebuilds the batches with `parts` vertex ranges (see [`default_part_count`]).
    pub fn set_part_count(&mut self, parts: usize) {
        self.batches = ConstraintBatches::new(&self.topology, &self.params, parts);
    }

    /// Advances by `dt` seconds.
    pub fn step(&mut self, dt: f32, par: &impl Parallel) {
        step(
            &mut self.state,
            &self.topology,
            &mut self.batches,
            &self.params,
            dt,
            &mut self.scratch,
            par,
        );
    }

    /// Changes the solver parameters (cheap: no rebuild).
    ///
    /// # Errors
    /// [`ParamError`] if a parameter is out of range; the old parameters are kept.
    pub fn set_params(&mut self, params: SolverParams) -> Result<(), ParamError> {
        params.validate()?;
        self.params = params;
        self.batches.set_params(&self.topology, &params);
        Ok(())
    }

    /// Recomputes [`Self::normals`] and [`Self::tangents`] from the current positions.
    pub fn update_shading(&mut self) {
        vertex_normals(
            &self.state.positions,
            self.topology.triangles(),
            &mut self.normals,
        );
        if let Some(uvs) = self.topology.uvs() {
            vertex_tangents(
                &self.state.positions,
                uvs,
                &self.normals,
                self.topology.triangles(),
                &mut self.tangents,
            );
        }
    }

    /// The solver parameters.
    #[must_use]
    pub fn params(&self) -> &SolverParams {
        &self.params
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

    /// Unit vertex normals as of the last [`Self::update_shading`].
    #[must_use]
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// Unit tangents with handedness as of the last [`Self::update_shading`]; empty without UVs.
    #[must_use]
    pub fn tangents(&self) -> &[Vec4] {
        &self.tangents
    }

    /// Strain over every edge now.
    #[must_use]
    pub fn strain(&self) -> StrainStats {
        edge_strain(&self.state.positions, self.topology.edges())
    }
}

#[cfg(test)]
mod tests;
