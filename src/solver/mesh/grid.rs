//! [`Grid`]: a rectangular sheet of vertices, the simplest cloth mesh.

use glam::{Vec2, Vec3};

use super::topology::{Topology, TopologyError, TopologyOptions};
use crate::solver::limits::MAX_VERTICES;

/// A rectangular grid of `columns × rows` vertices in the XZ plane, centred on the origin,
/// front face towards +Y.
///
/// Vertex `j·columns + i` sits at column `i` (x grows with `i`) and row `j` (z shrinks with
/// `j`), with UV `(i/(columns−1), j/(rows−1))`. Each quad `a = j·columns + i` is split into the
/// triangles `(a, a+1, a+columns+1)` and `(a, a+columns+1, a+columns)`, the pattern of seed 000
/// and of the report (six edges per interior vertex).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Vertices along x (at least 2).
    pub columns: u32,
    /// Vertices along z (at least 2).
    pub rows: u32,
    /// Extent along x in metres.
    pub width: f32,
    /// Extent along z in metres.
    pub height: f32,
}

impl Grid {
    /// A `columns × rows` grid of `width × height` metres.
    #[must_use]
    pub fn new(columns: u32, rows: u32, width: f32, height: f32) -> Self {
        Self {
            columns,
            rows,
            width,
            height,
        }
    }

    /// Checks the grid is at least 2×2 with a positive, finite size and at most
    /// [`MAX_VERTICES`] vertices.
    ///
    /// # Errors
    /// [`TopologyError::BadGrid`] saying what is wrong; [`TopologyError::TooLarge`] past the
    /// vertex limit.
    pub fn validate(&self) -> Result<(), TopologyError> {
        if self.columns < 2 || self.rows < 2 {
            return Err(TopologyError::BadGrid {
                reason: format!(
                    "{}×{} vertices; at least 2×2 are needed",
                    self.columns, self.rows
                ),
            });
        }
        let vertices = u64::from(self.columns) * u64::from(self.rows);
        if vertices > MAX_VERTICES as u64 {
            return Err(TopologyError::TooLarge {
                vertices,
                triangles: 2 * u64::from(self.columns - 1) * u64::from(self.rows - 1),
            });
        }
        for (name, v) in [("width", self.width), ("height", self.height)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(TopologyError::BadGrid {
                    reason: format!("{name} {v} must be finite and positive"),
                });
            }
        }
        Ok(())
    }

    /// Vertex index of column `i`, row `j`.
    #[must_use]
    pub fn index(&self, i: u32, j: u32) -> u32 {
        j * self.columns + i
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.columns as usize * self.rows as usize
    }

    /// Vertex positions.
    #[must_use]
    pub fn positions(&self) -> Vec<Vec3> {
        let (c, r) = (self.columns.max(2), self.rows.max(2));
        let mut out = Vec::with_capacity(self.vertex_count());
        for j in 0..self.rows {
            for i in 0..self.columns {
                let x = self.width * (i as f32 / (c - 1) as f32 - 0.5);
                let z = self.height * (0.5 - j as f32 / (r - 1) as f32);
                out.push(Vec3::new(x, 0.0, z));
            }
        }
        out
    }

    /// Texture coordinates.
    #[must_use]
    pub fn uvs(&self) -> Vec<Vec2> {
        let (c, r) = (self.columns.max(2), self.rows.max(2));
        let mut out = Vec::with_capacity(self.vertex_count());
        for j in 0..self.rows {
            for i in 0..self.columns {
                out.push(Vec2::new(
                    i as f32 / (c - 1) as f32,
                    j as f32 / (r - 1) as f32,
                ));
            }
        }
        out
    }

    /// Triangle indices.
    #[must_use]
    pub fn indices(&self) -> Vec<u32> {
        let c = self.columns;
        let mut out = Vec::with_capacity(
            6 * (self.columns.max(1) - 1) as usize * (self.rows.max(1) - 1) as usize,
        );
        for j in 0..self.rows.saturating_sub(1) {
            for i in 0..c.saturating_sub(1) {
                let a = j * c + i;
                out.extend_from_slice(&[a, a + 1, a + c + 1, a, a + c + 1, a + c]);
            }
        }
        out
    }

    /// The grid's topology.
    ///
    /// # Errors
    /// [`TopologyError::BadGrid`] if [`Self::validate`] fails.
    pub fn topology(&self, options: TopologyOptions) -> Result<Topology, TopologyError> {
        self.validate()?;
        let uvs = self.uvs();
        Topology::from_triangles(&self.positions(), Some(&uvs), &self.indices(), options)
    }
}
