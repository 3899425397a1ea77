//! [`HangingCloth`]: the scene the benchmarks, the trade-off example and many tests are built
//! on, in one place.

use glam::{Quat, Vec3};

use super::mesh::{Grid, MassDistribution, TopologyOptions};
use super::step::{Features, Pin, Simulation, SolverError, SolverParams};

/// A grid cloth hanging from pins, ready to step: by default the *standard scene* of the
/// benchmarks (a 1 m × 1 m sheet of `n × n` vertices, 1 kg spread uniformly, pinned at the
/// two corners of row 0, lying flat in the XZ plane at the origin, default solver settings).
/// Change any field before [`HangingCloth::build`].
///
/// ```
/// use bevy_cloth::solver::{HangingCloth, Serial, SolverParams};
///
/// let mut scene = HangingCloth::new(32);
/// scene.params = SolverParams { substeps: 20, ..Default::default() };
/// let mut sim = scene.build().unwrap();
/// for _ in 0..60 {
///     sim.step(1.0 / 60.0, &Serial);
/// }
/// assert!(sim.strain().max < 1.0);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct HangingCloth {
    /// The sheet.
    pub grid: Grid,
    /// Total mass in kilograms.
    pub mass: f32,
    /// How the mass is spread.
    pub mass_distribution: MassDistribution,
    /// Turns the grid about its centre (rest shape included).
    pub rotation: Quat,
    /// Where the grid's centre is (rest shape included).
    pub offset: Vec3,
    /// Bending model and rest angle.
    pub options: TopologyOptions,
    /// Solver settings.
    pub params: SolverParams,
    /// Optional capabilities (checked by [`HangingCloth::build`]).
    pub features: Features,
    /// Pinned vertices, held where they are at rest.
    pub pins: Vec<u32>,
}

impl HangingCloth {
    /// The standard scene at `n × n` vertices.
    #[must_use]
    pub fn new(n: u32) -> Self {
        Self::on(Grid::new(n, n, 1.0, 1.0))
    }

    /// `grid` as the sheet, 1 kg, pinned at the two corners of its row 0.
    #[must_use]
    pub fn on(grid: Grid) -> Self {
        Self {
            pins: Self::corners(&grid).to_vec(),
            grid,
            mass: 1.0,
            mass_distribution: MassDistribution::Uniform,
            rotation: Quat::IDENTITY,
            offset: Vec3::ZERO,
            options: TopologyOptions::default(),
            params: SolverParams::default(),
            features: Features::default(),
        }
    }

    /// The two corners of `grid`'s row 0.
    #[must_use]
    pub fn corners(grid: &Grid) -> [u32; 2] {
        [grid.index(0, 0), grid.index(grid.columns - 1, 0)]
    }

    /// Where vertex `v` is at rest (turned and placed).
    #[must_use]
    pub fn rest_position(&self, v: u32) -> Vec3 {
        self.rotation * self.grid.positions()[v as usize] + self.offset
    }

    /// The simulation, at rest, its pins on their rest positions.
    ///
    /// # Errors
    /// [`SolverError`] if the grid, the settings, the features or a pinned vertex is invalid.
    pub fn build(&self) -> Result<Simulation, SolverError> {
        self.grid.validate()?;
        let positions: Vec<Vec3> = self
            .grid
            .positions()
            .into_iter()
            .map(|p| self.rotation * p + self.offset)
            .collect();
        let topology = super::mesh::Topology::from_triangles(
            &positions,
            Some(&self.grid.uvs()),
            &self.grid.indices(),
            self.options,
        )?;
        let masses = topology.masses(self.mass, self.mass_distribution);
        let mut sim = Simulation::new(topology, &masses, self.params)?;
        sim.set_features(self.features)?;
        let pins: Vec<Pin> = self
            .pins
            .iter()
            .map(|&vertex| Pin {
                vertex,
                target: positions
                    .get(vertex as usize)
                    .copied()
                    .unwrap_or(Vec3::ZERO),
            })
            .collect();
        sim.state_mut().set_pins(pins)?;
        Ok(sim)
    }
}
