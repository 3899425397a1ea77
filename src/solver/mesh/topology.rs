//! Cloth topology: rest geometry, distance edges, bending pairs, triangles.
//!
//! Built once from a rectangular grid ([`Grid`](super::Grid)) or from any indexed triangle mesh
//! ([`Topology::from_triangles`]). Edges are the unique triangle edges, classified as
//! *stretch* (warp and weft, aligned with a UV axis) or *shear* (diagonal in UV space); on a
//! grid this gives the report's six edges per interior vertex. Every interior edge shared by
//! two triangles gives a dihedral bending pair.

use glam::{Vec2, Vec3};

use super::hinge::{bend_angle, dihedral_weight, hinge_coefficients};
use crate::solver::limits::{
    DEFAULT_SHORT_EDGE_THICKNESS, EVEN_EDGE_SPREAD, MAX_COORDINATE, MAX_TRIANGLES, MAX_VERTICES,
    REST_GAP_IGNORED, REST_GAP_THICKNESS, SHORT_EDGE_THICKNESS,
};

/// What a distance edge resists.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EdgeKind {
    /// Warp/weft edge (axis-aligned in UV space, or any edge when the mesh has no UVs).
    Stretch,
    /// Diagonal edge in UV space.
    Shear,
}

/// A distance constraint between two vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    /// Vertex indices, `v[0] < v[1]`.
    pub v: [u32; 2],
    /// Rest length in metres.
    pub rest: f32,
    /// Stretch or shear.
    pub kind: EdgeKind,
}

/// A bending constraint (a *hinge*) over two triangles `(v0, v1, v2)` and `(v0, v1, v3)` that
/// share the edge `v0–v1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bend {
    /// `[shared0, shared1, opposite0, opposite1]`.
    pub v: [u32; 4],
    /// Signed rest bend angle ψ0 in radians: 0 for a flat pair (the report's φ0 = π), the
    /// modelled fold with its direction for [`BendRest::RestShape`] (see
    /// [`bend_angle`]).
    pub rest_angle: f32,
    /// Index of the shared edge in [`Topology::edges`].
    pub edge: u32,
    /// Isometric bending weights `a_i` from the rest shape (see
    /// [`hinge_coefficients`]).
    pub coeffs: [f32; 4],
    /// Dihedral bending weight from the rest shape (see
    /// [`dihedral_weight`]).
    pub weight: f32,
}

/// Rest angle of the bending constraints.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BendRest {
    /// ψ0 = 0: the cloth wants to be flat (the report's φ0 = π).
    #[default]
    Flat,
    /// ψ0 = the signed bend angle of the rest mesh: the cloth keeps its modelled folds, in
    /// size and direction (uses the dihedral model).
    RestShape,
}

/// How bending is measured. Both take the same material parameter (a compliance `1/B`, `B`
/// the flexural rigidity in N·m) and weigh each hinge by its rest geometry, so a setting means
/// the same cloth at any resolution.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BendingModel {
    /// Quadratic isometric bending (Bergou et al. 2006): the hinge's curvature vector is
    /// linear in the positions, so a projection is exact and cheap. For cloth that is flat at
    /// rest; with [`BendRest::RestShape`] the dihedral model is used.
    #[default]
    Isometric,
    /// The report's dihedral angle (Müller et al. 2006), signed: the angle itself is
    /// constrained, also for curved rest shapes; about four times the work per hinge.
    Dihedral,
}

/// How vertex masses are spread over the cloth.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MassDistribution {
    /// Each vertex gets a third of the area of its triangles (lumped mass): physically right.
    #[default]
    Area,
    /// Every vertex gets the same mass.
    Uniform,
}

/// Options for building a [`Topology`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TopologyOptions {
    /// Rest angle of bending pairs.
    pub bend_rest: BendRest,
    /// Bending model.
    pub bending: BendingModel,
}

impl TopologyOptions {
    /// The model actually used: rest-shape bending needs the dihedral angle.
    #[must_use]
    pub fn effective_bending(&self) -> BendingModel {
        match self.bend_rest {
            BendRest::RestShape => BendingModel::Dihedral,
            BendRest::Flat => self.bending,
        }
    }
}

/// Why a mesh cannot be simulated.
#[derive(Clone, Debug, PartialEq)]
pub enum TopologyError {
    /// The mesh has no vertices.
    NoVertices,
    /// The index count is not a multiple of three (not a triangle list).
    NotTriangles {
        /// Number of indices.
        index_count: usize,
    },
    /// An index names a vertex that does not exist.
    IndexOutOfRange {
        /// Position in the index buffer.
        position: usize,
        /// The index.
        index: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// A vertex position is NaN or infinite.
    NonFinitePosition {
        /// Vertex index.
        vertex: usize,
    },
    /// A vertex lies farther than [`MAX_COORDINATE`] from the origin along some axis: `f32`
    /// has no precision left there for cloth, and squared lengths would overflow.
    PositionTooFar {
        /// Vertex index.
        vertex: usize,
        /// Its position.
        position: Vec3,
    },
    /// A new rest shape ([`Topology::reshaped`]) has another vertex count than the topology.
    VertexCount {
        /// The topology's vertex count.
        expected: usize,
        /// Number of positions given.
        positions: usize,
    },
    /// The UV array has a different length from the positions.
    UvCount {
        /// Number of UVs.
        uvs: usize,
        /// Number of positions.
        positions: usize,
    },
    /// No triangle with three distinct vertices is left.
    NoTriangles,
    /// Every triangle has zero area: the mesh has no size (all vertices on one point or one
    /// line).
    ZeroArea,
    /// More vertices or triangles than a cloth may have ([`MAX_VERTICES`],
    /// [`MAX_TRIANGLES`]).
    TooLarge {
        /// Number of vertices asked for.
        vertices: u64,
        /// Number of triangles asked for.
        triangles: u64,
    },
    /// A grid needs at least 2×2 vertices and a positive, finite size.
    BadGrid {
        /// What is wrong.
        reason: String,
    },
}

impl core::fmt::Display for TopologyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TopologyError::NoVertices => write!(f, "the mesh has no vertices"),
            TopologyError::NotTriangles { index_count } => write!(
                f,
                "{index_count} indices is not a multiple of 3: not a triangle list"
            ),
            TopologyError::IndexOutOfRange {
                position,
                index,
                vertex_count,
            } => write!(
                f,
                "index {index} at position {position} is out of range for {vertex_count} vertices"
            ),
            TopologyError::NonFinitePosition { vertex } => {
                write!(f, "vertex {vertex} has a NaN or infinite position")
            }
            TopologyError::UvCount { uvs, positions } => {
                write!(f, "{uvs} UVs for {positions} positions")
            }
            TopologyError::VertexCount {
                expected,
                positions,
            } => write!(
                f,
                "a rest shape of {positions} positions for a topology of {expected} vertices"
            ),
            TopologyError::PositionTooFar { vertex, position } => write!(
                f,
                "vertex {vertex} at {position} is over {MAX_COORDINATE} m from the origin"
            ),
            TopologyError::NoTriangles => {
                write!(f, "no triangle with three distinct vertices")
            }
            TopologyError::ZeroArea => {
                write!(f, "every triangle has zero area (the mesh has no size)")
            }
            TopologyError::TooLarge {
                vertices,
                triangles,
            } => write!(
                f,
                "{vertices} vertices and {triangles} triangles: a cloth may have at most \
                 {MAX_VERTICES} vertices and {MAX_TRIANGLES} triangles"
            ),
            TopologyError::BadGrid { reason } => write!(f, "bad grid: {reason}"),
        }
    }
}

impl std::error::Error for TopologyError {}

/// Rest geometry and constraint lists of a cloth.
#[derive(Clone, Debug, PartialEq)]
pub struct Topology {
    rest_positions: Vec<Vec3>,
    uvs: Option<Vec<Vec2>>,
    triangles: Vec<[u32; 3]>,
    /// UVs of each triangle's corners (they may differ from `uvs` along seams of a welded
    /// mesh): they tell stretch from shear edges.
    corner_uvs: Option<Vec<[Vec2; 3]>>,
    edges: Vec<Edge>,
    bends: Vec<Bend>,
    /// The mean rest length of `edges`.
    mean_edge: f32,
    /// The 90th over the 10th percentile of the edges' rest lengths.
    edge_spread: f32,
    /// The 10th percentile of the edges' rest lengths.
    short_edge: f32,
    /// Per vertex, its self-collision thickness over the cloth's; empty on even edges.
    self_collision_scales: Vec<f32>,
    /// Per vertex, the thickness it keeps from triangles over the cloth's; empty on even
    /// edges.
    self_collision_triangle_scales: Vec<f32>,
    skipped_triangles: usize,
    /// Every edge lies between exactly two triangles.
    closed: bool,
    options: TopologyOptions,
    /// [`RestGaps`] of the rest shape, made when first asked for.
    rest_gaps: LazyGaps,
}

/// The narrowest gaps across a rest shape ([`Topology::narrowest_rest_gap`]): as they are,
/// and each over its vertex's triangle scale (what the default thickness is capped by).
#[derive(Clone, Copy, Debug, PartialEq)]
struct RestGaps {
    narrowest: f32,
    scaled: f32,
}

/// [`RestGaps`], made once when first asked for: they depend on the rest shape alone, which
/// the other fields already say, so two topologies compare equal whether or not either has
/// made them.
#[derive(Clone, Debug, Default)]
struct LazyGaps(std::sync::OnceLock<RestGaps>);

impl PartialEq for LazyGaps {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Topology {
    /// Builds the topology of an indexed triangle list.
    ///
    /// Triangles that repeat a vertex (`[a, a, b]`, as a torn triangle is written) are skipped
    /// and counted in [`Self::skipped_triangles`]. Edges shared by more than two triangles
    /// (non-manifold) get distance constraints but no bending.
    ///
    /// # Errors
    /// [`TopologyError`] for an empty mesh, an index count that is not a multiple of three,
    /// an out-of-range index, a NaN/infinite position, a UV count that does not match, or no
    /// usable triangle.
    pub fn from_triangles(
        positions: &[Vec3],
        uvs: Option<&[Vec2]>,
        indices: &[u32],
        options: TopologyOptions,
    ) -> Result<Self, TopologyError> {
        Self::from_triangles_with_corner_uvs(positions, uvs, None, indices, options)
    }

    /// Like [`Self::from_triangles`], with the UVs of every triangle's corners given apart
    /// from the per-vertex `uvs` (a welded mesh, whose particles have several UVs along its
    /// seams): `corner_uvs[t]` are triangle `t`'s, and tell its edges' kinds.
    ///
    /// # Errors
    /// As [`Self::from_triangles`], and [`TopologyError::UvCount`] if `corner_uvs` does not
    /// have one entry per triangle.
    pub fn from_triangles_with_corner_uvs(
        positions: &[Vec3],
        uvs: Option<&[Vec2]>,
        corner_uvs: Option<&[[Vec2; 3]]>,
        indices: &[u32],
        options: TopologyOptions,
    ) -> Result<Self, TopologyError> {
        let n = positions.len();
        if n == 0 {
            return Err(TopologyError::NoVertices);
        }
        if n > MAX_VERTICES || indices.len() / 3 > MAX_TRIANGLES {
            return Err(TopologyError::TooLarge {
                vertices: n as u64,
                triangles: (indices.len() / 3) as u64,
            });
        }
        if !indices.len().is_multiple_of(3) {
            return Err(TopologyError::NotTriangles {
                index_count: indices.len(),
            });
        }
        check_positions(positions)?;
        if let Some(uvs) = uvs
            && uvs.len() != n
        {
            return Err(TopologyError::UvCount {
                uvs: uvs.len(),
                positions: n,
            });
        }
        if let Some((position, &index)) =
            indices.iter().enumerate().find(|(_, i)| **i as usize >= n)
        {
            return Err(TopologyError::IndexOutOfRange {
                position,
                index,
                vertex_count: n,
            });
        }
        if let Some(c) = corner_uvs
            && c.len() != indices.len() / 3
        {
            return Err(TopologyError::UvCount {
                uvs: c.len() * 3,
                positions: indices.len(),
            });
        }
        let mut triangles = Vec::with_capacity(indices.len() / 3);
        let mut corners = Vec::new();
        let mut skipped = 0;
        for (k, t) in indices.chunks_exact(3).enumerate() {
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                skipped += 1;
            } else {
                let tri = [t[0], t[1], t[2]];
                triangles.push(tri);
                match (corner_uvs, uvs) {
                    (Some(c), _) => corners.push(c[k]),
                    (None, Some(uv)) => corners.push(tri.map(|v| uv[v as usize])),
                    (None, None) => {}
                }
            }
        }
        if triangles.is_empty() {
            return Err(TopologyError::NoTriangles);
        }
        if !has_area(positions, &triangles) {
            return Err(TopologyError::ZeroArea);
        }
        let corners = (corner_uvs.is_some() || uvs.is_some()).then_some(corners);
        let mut t = Self::build(
            positions.to_vec(),
            uvs.map(<[Vec2]>::to_vec),
            triangles,
            corners,
            options,
        );
        t.skipped_triangles = skipped;
        Ok(t)
    }

    /// Edges and bending pairs of valid triangles (which may be none, after tearing).
    fn build(
        positions: Vec<Vec3>,
        uvs: Option<Vec<Vec2>>,
        triangles: Vec<[u32; 3]>,
        corner_uvs: Option<Vec<[Vec2; 3]>>,
        options: TopologyOptions,
    ) -> Self {
        // (min, max, opposite vertex, triangle, corner) for every triangle edge, sorted: equal
        // keys are adjacent, and the unique edges come out sorted as in seed 000.
        let mut half: Vec<(u32, u32, u32, u32, u8)> = Vec::with_capacity(triangles.len() * 3);
        for (ti, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                half.push((a.min(b), a.max(b), c, ti as u32, k as u8));
            }
        }
        half.sort_unstable_by_key(|&(a, b, c, t, _)| (a, b, c, t));
        let closed = !half.is_empty()
            && half
                .chunk_by(|x, y| (x.0, x.1) == (y.0, y.1))
                .all(|sides| sides.len() == 2);

        // Warp/weft edges run along a UV axis; the triangle's own corners decide (a welded
        // seam vertex has different UVs in the triangles on either side).
        let uv_kind = |t: u32, k: u8| -> EdgeKind {
            let Some(corners) = &corner_uvs else {
                return EdgeKind::Stretch;
            };
            let c = corners[t as usize];
            let d = (c[k as usize] - c[(k as usize + 1) % 3]).abs();
            if d.min_element() <= 1e-3 * d.max_element() {
                EdgeKind::Stretch
            } else {
                EdgeKind::Shear
            }
        };

        let mut edges = Vec::new();
        let mut bends = Vec::new();
        let mut i = 0;
        while i < half.len() {
            let (a, b, _, t, k) = half[i];
            let mut j = i;
            while j < half.len() && half[j].0 == a && half[j].1 == b {
                j += 1;
            }
            let edge_index = edges.len() as u32;
            edges.push(Edge {
                v: [a, b],
                rest: 0.0,
                kind: uv_kind(t, k),
            });
            if j - i == 2 {
                let (c, d) = (half[i].2, half[i + 1].2);
                if c != d {
                    bends.push(Bend {
                        v: [a, b, c, d],
                        rest_angle: 0.0,
                        edge: edge_index,
                        coeffs: [0.0; 4],
                        weight: 0.0,
                    });
                }
            }
            i = j;
        }

        let mut topology = Self {
            rest_positions: positions,
            uvs,
            triangles,
            corner_uvs,
            edges,
            bends,
            mean_edge: 0.0,
            edge_spread: 0.0,
            short_edge: 0.0,
            self_collision_scales: Vec::new(),
            self_collision_triangle_scales: Vec::new(),
            skipped_triangles: 0,
            closed,
            options,
            rest_gaps: LazyGaps::default(),
        };
        topology.measure();
        topology
    }

    /// Measures everything that depends on the rest positions (the edges' rest lengths, the
    /// hinges' rest angles and weights, the edge statistics and self-collision scales) from
    /// [`Self::rest_positions`]; the gaps across the rest shape are made again when asked for.
    fn measure(&mut self) {
        let positions = &self.rest_positions;
        for e in &mut self.edges {
            let [a, b] = e.v;
            e.rest = positions[a as usize].distance(positions[b as usize]);
        }
        for bend in &mut self.bends {
            let x = bend.v.map(|k| positions[k as usize]);
            bend.rest_angle = match self.options.bend_rest {
                BendRest::Flat => 0.0,
                BendRest::RestShape => bend_angle(x),
            };
            bend.coeffs = hinge_coefficients(x);
            bend.weight = dihedral_weight(x);
        }
        let edges = &self.edges;
        self.mean_edge = edges.iter().map(|e| e.rest).sum::<f32>() / edges.len().max(1) as f32;
        (self.edge_spread, self.short_edge) = edge_spread(edges);
        (
            self.self_collision_scales,
            self.self_collision_triangle_scales,
        ) = if self.edge_spread > EVEN_EDGE_SPREAD {
            edge_scales(positions, &self.triangles)
        } else {
            (Vec::new(), Vec::new())
        };
        self.rest_gaps = LazyGaps::default();
    }

    /// [`Self::reshaped`] for `positions` that are this rest shape turned, moved and scaled
    /// evenly by `scale` (the caller's word: an entity's even scale changed): the gaps across
    /// the rest shape, where made, are this one's times `scale` instead of searched for again
    /// (the search, on one thread, takes longer than measuring the rest of the topology).
    ///
    /// # Errors
    /// As [`Self::reshaped`].
    pub(crate) fn reshaped_evenly(
        &self,
        positions: &[Vec3],
        scale: f32,
    ) -> Result<Self, TopologyError> {
        let topology = self.reshaped(positions)?;
        if let Some(gaps) = self.rest_gaps.0.get()
            && scale.is_finite()
            && scale > 0.0
        {
            let _ = topology.rest_gaps.0.set(RestGaps {
                narrowest: gaps.narrowest * scale,
                scaled: gaps.scaled * scale,
            });
        }
        Ok(topology)
    }

    /// This topology with its rest shape at `positions` (one per vertex): the same triangles,
    /// UVs, edges and bending pairs, with their rest lengths, angles and weights measured
    /// again. The same as [`Self::from_triangles_with_corner_uvs`] of `positions` and this
    /// topology's triangles and UVs, without finding the edges and hinges again: the rest
    /// shape of a cloth whose entity is being scaled, at each frame of the scaling.
    ///
    /// # Errors
    /// [`TopologyError::NonFinitePosition`], [`TopologyError::PositionTooFar`] or
    /// [`TopologyError::ZeroArea`] as [`Self::from_triangles`];
    /// [`TopologyError::VertexCount`] for another vertex count.
    pub fn reshaped(&self, positions: &[Vec3]) -> Result<Self, TopologyError> {
        let n = self.vertex_count();
        if positions.len() != n {
            return Err(TopologyError::VertexCount {
                expected: n,
                positions: positions.len(),
            });
        }
        check_positions(positions)?;
        if !has_area(positions, &self.triangles) {
            return Err(TopologyError::ZeroArea);
        }
        let mut topology = Self {
            rest_positions: positions.to_vec(),
            ..self.clone()
        };
        topology.measure();
        Ok(topology)
    }

    /// The topology left after tearing `torn` edges (vertex pairs, either order): every
    /// triangle that uses a torn edge is removed, and with it every edge and bending pair that
    /// no remaining triangle supports. Vertices stay (a fully torn cloth is free particles).
    #[must_use]
    pub fn without_edges(&self, torn: &[[u32; 2]]) -> Self {
        let mut cut: Vec<(u32, u32)> = torn
            .iter()
            .map(|e| (e[0].min(e[1]), e[0].max(e[1])))
            .collect();
        cut.sort_unstable();
        let is_cut = |a: u32, b: u32| cut.binary_search(&(a.min(b), a.max(b))).is_ok();
        let keep: Vec<bool> = self
            .triangles
            .iter()
            .map(|t| !(is_cut(t[0], t[1]) || is_cut(t[1], t[2]) || is_cut(t[2], t[0])))
            .collect();
        let triangles = self
            .triangles
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(t, _)| *t)
            .collect();
        let corner_uvs = self.corner_uvs.as_ref().map(|c| {
            c.iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(c, _)| *c)
                .collect()
        });
        let mut t = Self::build(
            self.rest_positions.clone(),
            self.uvs.clone(),
            triangles,
            corner_uvs,
            self.options,
        );
        t.skipped_triangles = self.skipped_triangles;
        // Removing triangles only widens the gaps across the rest shape, so the ones made
        // before the tear still bound the thickness (a cloth tearing every frame would
        // otherwise make them again every frame).
        if let Some(&gaps) = self.rest_gaps.0.get() {
            let _ = t.rest_gaps.0.set(gaps);
        }
        t
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.rest_positions.len()
    }

    /// The options it was built with.
    #[must_use]
    pub fn options(&self) -> TopologyOptions {
        self.options
    }

    /// Rest positions, in the mesh's own space.
    #[must_use]
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest_positions
    }

    /// Texture coordinates, when the mesh has them.
    #[must_use]
    pub fn uvs(&self) -> Option<&[Vec2]> {
        self.uvs.as_deref()
    }

    /// Triangles with three distinct vertices.
    #[must_use]
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The mean rest length of the edges (0 without edges): the default self-collision
    /// thickness.
    #[must_use]
    pub fn mean_rest_edge(&self) -> f32 {
        self.mean_edge
    }

    /// How uneven the edges are: the 90th percentile of their rest lengths over the 10th (1 for
    /// equal edges, √2 for a grid of squares with a diagonal each, 1 without edges). Self-
    /// collision keeps one thickness for the whole cloth up to
    /// [`EVEN_EDGE_SPREAD`], and a thickness per
    /// vertex above ([`Topology::self_collision_scales`]).
    #[must_use]
    pub fn rest_edge_spread(&self) -> f32 {
        self.edge_spread
    }

    /// The 10th percentile of the edges' rest lengths (0 without edges): the mesh's short
    /// spacing.
    #[must_use]
    pub fn short_rest_edge(&self) -> f32 {
        self.short_edge
    }

    /// Each vertex's self-collision thickness over the cloth's, on a mesh whose edges are more
    /// uneven than [`EVEN_EDGE_SPREAD`]: the mean rest length of the edges of the triangles at
    /// it (each counted once per triangle) over the mean of every triangle's edges, a quarter
    /// to four times (1 for a vertex in no triangle): layers farther apart where the mesh is
    /// coarser, closer where it is finer. Empty on even edges, where every vertex keeps the
    /// cloth's thickness. Both backends read these numbers.
    #[must_use]
    pub fn self_collision_scales(&self) -> &[f32] {
        &self.self_collision_scales
    }

    /// Each vertex's thickness from the cloth's triangles over the cloth's thickness, on a
    /// mesh whose edges are more uneven than [`EVEN_EDGE_SPREAD`]: its
    /// [`self_collision_scales`](Self::self_collision_scales), at most
    /// [`SHORT_EDGE_THICKNESS`] times its shortest rest edge over the mean of every
    /// triangle's edges (and at least a quarter). Where a mesh is finer one way than the other
    /// (a skirt's tube, finer around than along), a vertex held a whole thickness off the
    /// triangles one short edge beyond its own would be held farther than its edges reach,
    /// and the cloth tears itself apart; from other vertices it keeps its whole thickness.
    /// Empty on even edges. Both backends read these numbers.
    #[must_use]
    pub fn self_collision_triangle_scales(&self) -> &[f32] {
        &self.self_collision_triangle_scales
    }

    /// The self-collision thickness the plugin uses when none is set
    /// (`ClothSelfCollision::thickness` `None`): the mean rest edge, and on a mesh of even
    /// edges (a spread up to [`EVEN_EDGE_SPREAD`]) at most
    /// [`DEFAULT_SHORT_EDGE_THICKNESS`]
    /// short edges. A mesh of uneven edges keeps its mean edge: each vertex scales it
    /// ([`Self::self_collision_scales`]). 0 without edges.
    ///
    /// An open mesh's is also at most [`REST_GAP_THICKNESS`] of the narrowest gap across its
    /// rest shape ([`Self::narrowest_rest_gap`]; on uneven meshes each vertex's gap over its
    /// triangle scale), so that at rest it touches none of its own layers: a sleeve or a
    /// low-poly model's part whose walls or creases rest closer than its edges are long gets
    /// a thinner layer; a flat sheet keeps the edge rule. So does a closed mesh: its contacts
    /// are capped pair by pair from the rest shape instead
    /// ([`NEAR_CORNER_THICKNESS`](crate::solver::NEAR_CORNER_THICKNESS)).
    #[must_use]
    pub fn default_self_collision_thickness(&self) -> f32 {
        self.edge_thickness()
            .min(REST_GAP_THICKNESS * self.rest_clearance())
    }

    /// The default thickness from the edges alone (before the rest-gap cap).
    fn edge_thickness(&self) -> f32 {
        if self.edge_spread > EVEN_EDGE_SPREAD {
            self.mean_edge
        } else {
            self.mean_edge
                .min(DEFAULT_SHORT_EDGE_THICKNESS * self.short_edge)
        }
    }

    /// The narrowest gap across the rest shape that bounds the default self-collision
    /// thickness: the smallest rest distance from a vertex to the plane of a triangle it rests
    /// over (its projection inside the triangle or on its edges, the vertex not one of its
    /// corners: the far wall of a sleeve, the side beyond a crease folded to a right angle or
    /// tighter), among those that could bound it (under twice the edges' default thickness,
    /// times the largest [triangle scale](Self::self_collision_triangle_scales) on uneven
    /// meshes); infinite where there is none (a flat or gently curved sheet). Gaps under
    /// [`REST_GAP_IGNORED`] of that thickness are left out (a vertex on the triangle: a
    /// T-junction or a face modelled twice). Made the first time it is asked for, from a
    /// spatial hash of the vertices on one thread (18 ms for a 256² grid on this project's
    /// 2-core machine, half what building its topology takes), and kept through tears.
    #[must_use]
    pub fn narrowest_rest_gap(&self) -> f32 {
        self.rest_gaps().narrowest
    }

    /// How far an open mesh's rest shape keeps its vertices from the layers they lie over:
    /// the narrowest gap across it ([`Self::narrowest_rest_gap`]), on uneven meshes each
    /// vertex's gap over its [triangle scale](Self::self_collision_triangle_scales). Infinite
    /// for a closed mesh (its contacts are capped pair by pair from the rest shape) and where
    /// no gap counts. The default thickness ([`Self::default_self_collision_thickness`]) is at
    /// most [`REST_GAP_THICKNESS`] of it, and the plugin warns about a thickness set wider than
    /// that: the walls or creases of the mesh then push each other apart every step, so that a
    /// low-poly model's part may never come to rest.
    #[must_use]
    pub fn rest_clearance(&self) -> f32 {
        if self.closed {
            return f32::INFINITY;
        }
        self.rest_gaps().scaled
    }

    /// [`RestGaps`], made the first time they are asked for.
    fn rest_gaps(&self) -> RestGaps {
        *self.rest_gaps.0.get_or_init(|| {
            let edges = self.edge_thickness();
            let scales = &self.self_collision_triangle_scales;
            let most_scale = scales.iter().copied().fold(1.0f32, f32::max);
            rest_gaps(
                &self.rest_positions,
                &self.triangles,
                scales,
                REST_GAP_IGNORED * edges,
                edges * most_scale / REST_GAP_THICKNESS,
            )
        })
    }

    /// The thickest self-collision this cloth takes:
    /// [`MAX_SELF_COLLISION_EDGES`](crate::solver::limits::MAX_SELF_COLLISION_EDGES) mean rest
    /// edges.
    #[must_use]
    pub fn thickest_self_collision(&self) -> f32 {
        crate::solver::limits::MAX_SELF_COLLISION_EDGES * self.mean_edge
    }

    /// Unique triangle edges, sorted by `(v[0], v[1])`.
    #[must_use]
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// Whether the mesh is closed: every edge lies between exactly two triangles (a sphere, a
    /// cube, a torus; welded along its UV seams, as the plugin welds). Self-collision caps the
    /// thickness a closed cloth keeps near its own vertices (see
    /// [`NEAR_CORNER_THICKNESS`](crate::solver::NEAR_CORNER_THICKNESS)). A tear opens it.
    #[must_use]
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// The most edges any one vertex has (6 inside a [`Grid`](crate::solver::Grid); the
    /// sides' count at the tip of a cone or the hub of a fan-triangulated cap).
    #[must_use]
    pub fn max_vertex_degree(&self) -> usize {
        let mut degree = vec![0usize; self.vertex_count()];
        for e in &self.edges {
            degree[e.v[0] as usize] += 1;
            degree[e.v[1] as usize] += 1;
        }
        degree.into_iter().max().unwrap_or(0)
    }

    /// The pieces of the mesh (vertices joined by edges) that hold none of the `pinned`
    /// vertices, when one is pinned at all: their count and their vertices'. Such a piece falls
    /// on its own (a glTF curtain's separate hooks, a cape's loose clasp). Vertices in no
    /// edge, and out-of-range pins, are left out; `(0, 0)` when nothing is pinned.
    #[must_use]
    pub fn loose_pieces(&self, pinned: impl IntoIterator<Item = u32>) -> (usize, usize) {
        let n = self.vertex_count();
        // Union–find over the edges, each root the smallest vertex of its piece.
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn root(parent: &mut [u32], mut v: u32) -> u32 {
            while parent[v as usize] != v {
                let up = parent[parent[v as usize] as usize];
                parent[v as usize] = up;
                v = up;
            }
            v
        }
        let mut in_edge = vec![false; n];
        for e in &self.edges {
            let (a, b) = (root(&mut parent, e.v[0]), root(&mut parent, e.v[1]));
            parent[a.max(b) as usize] = a.min(b);
            in_edge[e.v[0] as usize] = true;
            in_edge[e.v[1] as usize] = true;
        }
        let mut held = vec![false; n];
        let mut any = false;
        for p in pinned {
            if (p as usize) < n {
                held[root(&mut parent, p) as usize] = true;
                any = true;
            }
        }
        if !any {
            return (0, 0);
        }
        let (mut pieces, mut vertices) = (0, 0);
        for v in 0..n as u32 {
            if !in_edge[v as usize] {
                continue;
            }
            let r = root(&mut parent, v);
            if !held[r as usize] {
                vertices += 1;
                pieces += usize::from(r == v);
            }
        }
        (pieces, vertices)
    }

    /// Dihedral bending pairs, one per interior manifold edge.
    #[must_use]
    pub fn bends(&self) -> &[Bend] {
        &self.bends
    }

    /// Triangles dropped because they repeat a vertex.
    #[must_use]
    pub fn skipped_triangles(&self) -> usize {
        self.skipped_triangles
    }

    /// Per-vertex masses (kg) adding up to `total`.
    ///
    /// With [`MassDistribution::Area`], a vertex in no triangle or in only zero-area ones gets
    /// the mean vertex mass, so every mass is positive and finite for a positive `total`.
    #[must_use]
    pub fn masses(&self, total: f32, distribution: MassDistribution) -> Vec<f32> {
        let n = self.vertex_count();
        let uniform = total / n as f32;
        match distribution {
            MassDistribution::Uniform => vec![uniform; n],
            MassDistribution::Area => {
                let mut area = vec![0.0f64; n];
                for t in &self.triangles {
                    let [a, b, c] = t.map(|i| self.rest_positions[i as usize]);
                    let third = f64::from((b - a).cross(c - a).length()) / 6.0;
                    for &i in t {
                        area[i as usize] += third;
                    }
                }
                let sum: f64 = area.iter().sum();
                let with_area = area.iter().filter(|a| **a > 0.0).count();
                if sum.is_nan() || sum <= 0.0 || !sum.is_finite() {
                    return vec![uniform; n];
                }
                // Vertices without area get the mean mass; the rest share what is left by area.
                let orphans = n - with_area;
                let share = f64::from(total) * (with_area as f64 / n as f64);
                area.iter()
                    .map(|&a| {
                        if a > 0.0 && orphans < n {
                            (share * a / sum) as f32
                        } else {
                            uniform
                        }
                    })
                    .collect()
            }
        }
    }
}

/// Bounds of a vertex's self-collision thickness over the cloth's ([`edge_scales`]).
const MIN_THICKNESS_SCALE: f32 = 0.25;
const MAX_THICKNESS_SCALE: f32 = 4.0;

/// The narrowest gaps across a rest shape (see [`Topology::narrowest_rest_gap`]): over every
/// vertex resting over a triangle it is not a corner of, more than `ignore` and less than
/// `limit` off its plane, the least distance, and the least over the vertex's `scales` (none:
/// 1). Vertices are hashed into cells `limit` wide, and each triangle tests those in the cells
/// of its box widened along its normal; a triangle spanning more than [`GAP_CELLS`] cells
/// (much longer than the gaps that matter) is left out. Infinite when no pair counts.
fn rest_gaps(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    scales: &[f32],
    ignore: f32,
    limit: f32,
) -> RestGaps {
    let mut gaps = RestGaps {
        narrowest: f32::INFINITY,
        scaled: f32::INFINITY,
    };
    if !(limit.is_finite() && limit > 0.0) {
        return gaps;
    }
    let cell = |p: Vec3| {
        let c = (p / limit).floor();
        (c.x as i32, c.y as i32, c.z as i32)
    };
    let mut cells: std::collections::HashMap<
        (i32, i32, i32),
        Vec<u32>,
        core::hash::BuildHasherDefault<CellHasher>,
    > = std::collections::HashMap::default();
    for (i, &p) in positions.iter().enumerate() {
        cells.entry(cell(p)).or_default().push(i as u32);
    }
    for tri in triangles {
        let [a, b, c] = tri.map(|k| positions[k as usize]);
        let Some(plane) = RestPlane::of(a, b, c) else {
            continue;
        };
        // A vertex over the triangle less than `limit` off its plane lies within the
        // triangle's box widened by `limit` times the normal along each axis, and by the
        // slack along its edges (four times it along the box's diagonal: two weights can be
        // out by it at a corner): a flat sheet's triangles look only above and below.
        let (lo_t, hi_t) = (a.min(b).min(c), a.max(b).max(c));
        let widen =
            plane.n.abs() * limit + Vec3::splat((hi_t - lo_t).length() * 4.0 * GAP_EDGE_SLACK);
        let (lo, hi) = (cell(lo_t - widen), cell(hi_t + widen));
        let span = |l: i32, h: i32| (i64::from(h) - i64::from(l) + 1).max(0);
        if span(lo.0, hi.0) * span(lo.1, hi.1) * span(lo.2, hi.2) > GAP_CELLS {
            continue;
        }
        let mut look_in = |cell| {
            for &i in cells.get(&cell).map_or(&[][..], Vec::as_slice) {
                if !tri.contains(&i)
                    && let Some(gap) = plane.gap_over(positions[i as usize], ignore, limit)
                {
                    let scale = scales.get(i as usize).copied().unwrap_or(1.0);
                    gaps.narrowest = gaps.narrowest.min(gap);
                    gaps.scaled = gaps.scaled.min(gap / scale);
                }
            }
        };
        for x in lo.0..=hi.0 {
            for y in lo.1..=hi.1 {
                (lo.2..=hi.2).for_each(|z| look_in((x, y, z)));
            }
        }
    }
    gaps
}

/// A rest triangle's plane, for [`rest_gaps`].
struct RestPlane {
    a: Vec3,
    e1: Vec3,
    e2: Vec3,
    n: Vec3,
    d00: f32,
    d01: f32,
    d11: f32,
    denom: f32,
}

impl RestPlane {
    /// The plane of `[a, b, c]`; `None` for a degenerate triangle or a sliver thinner than
    /// [`GAP_SLIVER`] of its length, which is a line: its plane and weights are rounding (one
    /// in Bevy's `faces.glb` gave a 3 mm gap that is not there).
    fn of(a: Vec3, b: Vec3, c: Vec3) -> Option<Self> {
        let (e1, e2) = (b - a, c - a);
        let normal = e1.cross(e2);
        let len = normal.length();
        let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let denom = d00 * d11 - d01 * d01;
        let longest2 = d00.max(d11).max((c - b).length_squared());
        (len > GAP_SLIVER * longest2 && len.is_finite() && denom > 0.0 && denom.is_finite()).then(
            || Self {
                a,
                e1,
                e2,
                n: normal / len,
                d00,
                d01,
                d11,
                denom,
            },
        )
    }

    /// How far `p` lies off the plane, where that is more than `ignore` and less than
    /// `limit` and `p` lies over the triangle (its projection inside, or out by no more than
    /// [`GAP_EDGE_SLACK`] in a barycentric weight). The distance first: most vertices near a
    /// sheet's triangle lie in its plane.
    fn gap_over(&self, p: Vec3, ignore: f32, limit: f32) -> Option<f32> {
        let ap = p - self.a;
        let gap = ap.dot(self.n).abs();
        if !(gap > ignore && gap < limit) {
            return None;
        }
        let (d20, d21) = (ap.dot(self.e1), ap.dot(self.e2));
        let v = (self.d11 * d20 - self.d01 * d21) / self.denom;
        let w = (self.d00 * d21 - self.d01 * d20) / self.denom;
        (v >= -GAP_EDGE_SLACK && w >= -GAP_EDGE_SLACK && v + w <= 1.0 + GAP_EDGE_SLACK)
            .then_some(gap)
    }
}

/// How far beyond a triangle's edges (in its barycentric weights) a vertex still counts as
/// resting over it in [`rest_gaps`]: a tube's rings line up, so a vertex projects onto the
/// edge or corner across from it, and one a little way from a right-angled crease onto the
/// edge of the side beyond it (held a thickness off that side, it would push against the
/// crease); rounding puts either just outside.
const GAP_EDGE_SLACK: f32 = 0.01;

/// Twice a triangle's area over its longest edge squared under which [`rest_gaps`] leaves it
/// out (a sliver: its normal and barycentric weights are rounding).
const GAP_SLIVER: f32 = 1e-4;

/// A hasher for [`rest_gaps`]'s cells (std's default, built against collision attacks, was
/// most of its time; cell keys are not chosen by anyone).
#[derive(Default)]
struct CellHasher(u64);

impl core::hash::Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u32(u32::from(b));
        }
    }

    fn write_u32(&mut self, i: u32) {
        self.0 = (self.0.rotate_left(5) ^ u64::from(i)).wrapping_mul(0x517c_c1b7_2722_0a95);
    }

    fn write_i32(&mut self, i: i32) {
        self.write_u32(i.cast_unsigned());
    }
}

/// The most cells around one triangle [`rest_gaps`] looks in.
const GAP_CELLS: i64 = 4096;

/// `Ok` when every position is finite and within [`MAX_COORDINATE`] of the origin.
fn check_positions(positions: &[Vec3]) -> Result<(), TopologyError> {
    if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
        return Err(TopologyError::NonFinitePosition { vertex });
    }
    if let Some(vertex) = positions
        .iter()
        .position(|p| p.abs().max_element() > MAX_COORDINATE)
    {
        return Err(TopologyError::PositionTooFar {
            vertex,
            position: positions[vertex],
        });
    }
    Ok(())
}

/// Whether some triangle has an area at `positions`.
fn has_area(positions: &[Vec3], triangles: &[[u32; 3]]) -> bool {
    triangles.iter().any(|t| {
        let [a, b, c] = t.map(|v| positions[v as usize]);
        (b - a).cross(c - a).length_squared() > 0.0
    })
}

/// [`Topology::self_collision_scales`] and
/// [`Topology::self_collision_triangle_scales`] of an uneven mesh.
fn edge_scales(positions: &[Vec3], triangles: &[[u32; 3]]) -> (Vec<f32>, Vec<f32>) {
    let n = positions.len();
    let mut sum = vec![0.0f64; n];
    let mut count = vec![0u32; n];
    let mut shortest = vec![f64::INFINITY; n];
    let (mut total, mut incidences) = (0.0f64, 0u64);
    for t in triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let l = f64::from(positions[a as usize].distance(positions[b as usize]));
            for v in [a, b] {
                sum[v as usize] += l;
                count[v as usize] += 1;
                shortest[v as usize] = shortest[v as usize].min(l);
            }
            total += l;
            incidences += 1;
        }
    }
    let mean = total / incidences.max(1) as f64;
    (0..n)
        .map(|i| {
            if count[i] == 0 || mean.is_nan() || mean <= 0.0 {
                return (1.0, 1.0);
            }
            let s = (sum[i] / f64::from(count[i]) / mean) as f32;
            let s = s.clamp(MIN_THICKNESS_SCALE, MAX_THICKNESS_SCALE);
            // Not `min`: a NaN (a non-finite edge) stays, as in `s`.
            let short = SHORT_EDGE_THICKNESS * (shortest[i] / mean) as f32;
            let t = if short < s { short } else { s };
            (s, t.clamp(MIN_THICKNESS_SCALE, MAX_THICKNESS_SCALE))
        })
        .unzip()
}

/// The 90th over the 10th percentile of `edges`' rest lengths (1 without edges or with a
/// zero 10th percentile's edge: degenerate edges are the solver's concern, not this ratio's),
/// and the 10th percentile (0 without edges).
fn edge_spread(edges: &[Edge]) -> (f32, f32) {
    if edges.is_empty() {
        return (1.0, 0.0);
    }
    let mut lengths: Vec<f32> = edges.iter().map(|e| e.rest).collect();
    let last = lengths.len() - 1;
    let (lo, hi) = (last / 10, last * 9 / 10);
    let p10 = *lengths.select_nth_unstable_by(lo, f32::total_cmp).1;
    let p90 = *lengths.select_nth_unstable_by(hi, f32::total_cmp).1;
    let spread = p90 / p10;
    if spread.is_finite() && spread >= 1.0 {
        (spread, p10)
    } else {
        (1.0, p10)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::Grid;

    /// Two 3 × 3 sheets side by side and a lone triangle: pinning one sheet leaves the other
    /// sheet and the triangle loose; pinning nothing, or a vertex of each, leaves none.
    #[test]
    fn loose_pieces_are_the_ones_no_pin_holds() {
        let grid = Grid::new(3, 3, 1.0, 1.0);
        let mut positions = grid.positions();
        let mut indices = grid.indices();
        let shift = |d: f32| move |p: &Vec3| *p + Vec3::new(d, 0.0, 0.0);
        positions.extend(grid.positions().iter().map(shift(5.0)));
        indices.extend(grid.indices().iter().map(|i| i + 9));
        positions.extend([
            Vec3::new(9.0, 0.0, 0.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(9.0, 0.0, 1.0),
        ]);
        indices.extend([18, 19, 20]);
        // A vertex in no triangle is no piece.
        positions.push(Vec3::splat(20.0));
        let t = Topology::from_triangles(&positions, None, &indices, TopologyOptions::default())
            .unwrap();
        assert_eq!(t.loose_pieces([0, 2]), (2, 12));
        assert_eq!(t.loose_pieces([4, 13]), (1, 3));
        assert_eq!(t.loose_pieces([0, 9, 20]), (0, 0));
        assert_eq!(t.loose_pieces([]), (0, 0));
        // A pin on the vertex in no triangle holds nothing; one out of range is left out.
        assert_eq!(t.loose_pieces([21, 99]), (3, 21));
        assert_eq!(t.loose_pieces([99]), (0, 0));
    }

    /// A rest shape measured again ([`Topology::reshaped`]) is the topology built from its
    /// positions: for each bending model and rest angle, on a sheet whose edges become uneven
    /// (self-collision scales appear), curved, with UVs, a skipped triangle and a tear.
    #[test]
    fn a_reshaped_topology_is_the_one_built_from_its_positions() {
        let grid = Grid::new(14, 11, 1.2, 0.9);
        let mut indices = grid.indices();
        indices.extend([0, 0, 1]);
        let uvs = grid.uvs();
        let flat = grid.positions();
        // Squeezed along x towards the middle (edges up to 2.3 times longer at the sides)
        // and rolled about z into a spiral of 1.3 turns (its layers 6 cm apart).
        let shaped: Vec<Vec3> = flat
            .iter()
            .map(|p| {
                let u = p.x / 1.2 + 0.5;
                let u = u + 0.4 * (core::f32::consts::TAU * u).sin() / core::f32::consts::TAU;
                let angle = 1.3 * core::f32::consts::TAU * u;
                let r = 0.12 + 0.06 * angle / core::f32::consts::TAU;
                Vec3::new(r * angle.sin(), r * angle.cos(), p.z)
            })
            .collect();
        let cut = [
            [grid.index(3, 4), grid.index(4, 4)],
            [grid.index(7, 2), grid.index(7, 3)],
        ];
        for bend_rest in [BendRest::Flat, BendRest::RestShape] {
            for bending in [BendingModel::Isometric, BendingModel::Dihedral] {
                let options = TopologyOptions { bend_rest, bending };
                let built = |positions: &[Vec3]| {
                    Topology::from_triangles(positions, Some(&uvs), &indices, options).unwrap()
                };
                let (before, after) = (built(&flat), built(&shaped));
                assert!(after.rest_edge_spread() > EVEN_EDGE_SPREAD);
                // The flat sheet's gaps made (none: infinite) before it is reshaped.
                assert_eq!(before.narrowest_rest_gap(), f32::INFINITY);
                let reshaped = before.reshaped(&shaped).unwrap();
                assert_eq!(reshaped, after, "{options:?}");
                assert_eq!(reshaped.skipped_triangles(), 1);
                // The gaps across the rest shape are the new shape's (not compared by `==`).
                let gap = reshaped.narrowest_rest_gap();
                assert!(gap < 0.1, "{gap}");
                assert_eq!(gap, after.narrowest_rest_gap());
                // Torn, then reshaped: the torn topology of the new shape.
                let torn = before.without_edges(&cut).reshaped(&shaped).unwrap();
                assert_eq!(torn, after.without_edges(&cut));
                assert!(torn.triangles().len() < after.triangles().len());
            }
        }
        let t =
            Topology::from_triangles(&flat, None, &indices, TopologyOptions::default()).unwrap();
        assert_eq!(
            t.reshaped(&flat[1..]),
            Err(TopologyError::VertexCount {
                expected: flat.len(),
                positions: flat.len() - 1,
            })
        );
        let mut bad = flat.clone();
        bad[5].y = f32::NAN;
        assert_eq!(
            t.reshaped(&bad),
            Err(TopologyError::NonFinitePosition { vertex: 5 })
        );
        bad[5] = Vec3::splat(2.0 * MAX_COORDINATE);
        assert!(matches!(
            t.reshaped(&bad),
            Err(TopologyError::PositionTooFar { vertex: 5, .. })
        ));
        let on_a_line: Vec<Vec3> = flat.iter().map(|p| Vec3::X * p.x).collect();
        assert_eq!(t.reshaped(&on_a_line), Err(TopologyError::ZeroArea));
    }

    /// A rest shape turned, moved and scaled evenly keeps the gaps across the old one scaled
    /// (within rounding of what a search of the new shape finds); where the old ones were
    /// not made, they are searched for when asked.
    #[test]
    fn an_even_scale_carries_the_gaps_across_the_rest_shape() {
        let grid = Grid::new(14, 11, 1.2, 0.9);
        let indices = grid.indices();
        // Rolled into a spiral of 1.3 turns, its layers 6 cm apart.
        let rolled: Vec<Vec3> = grid
            .positions()
            .iter()
            .map(|p| {
                let angle = 1.3 * core::f32::consts::TAU * (p.x / 1.2 + 0.5);
                let r = 0.12 + 0.06 * angle / core::f32::consts::TAU;
                Vec3::new(r * angle.sin(), r * angle.cos(), p.z)
            })
            .collect();
        let turn = glam::Quat::from_euler(glam::EulerRot::YXZ, 0.4, 1.1, -0.3);
        let placed = |by: f32| -> Vec<Vec3> {
            rolled
                .iter()
                .map(|p| turn * (*p * by) + Vec3::new(3.0, -2.0, 7.0))
                .collect()
        };
        let options = TopologyOptions::default();
        let built = |p: &[Vec3]| Topology::from_triangles(p, None, &indices, options).unwrap();
        let t = built(&rolled);
        let gap = t.narrowest_rest_gap();
        assert!(gap < 0.1, "{gap}");
        for by in [0.05, 0.7, 2.5] {
            let searched = built(&placed(by)).narrowest_rest_gap();
            let carried = t.reshaped_evenly(&placed(by), by).unwrap();
            assert_eq!(carried, t.reshaped(&placed(by)).unwrap());
            assert_eq!(carried.narrowest_rest_gap(), gap * by);
            // Within the rounding of positions as far out as the moved shape's.
            let far = placed(by)
                .iter()
                .fold(0.0f32, |m, p| m.max(p.abs().max_element()));
            assert!(
                (searched - gap * by).abs() <= 1e-5 * searched + 8.0 * f32::EPSILON * far,
                "{by}: searched {searched}, carried {}",
                gap * by
            );
        }
        // Not made before: searched for.
        let fresh = built(&rolled).reshaped_evenly(&placed(2.5), 2.5).unwrap();
        assert_eq!(
            fresh.narrowest_rest_gap(),
            built(&placed(2.5)).narrowest_rest_gap()
        );
    }

    /// Even meshes have no self-collision scales (every vertex keeps the cloth's thickness);
    /// an uneven one gives its coarse vertices more and its fine ones less.
    #[test]
    fn vertices_of_uneven_meshes_take_their_own_self_collision_thickness() {
        let grid = Grid::new(30, 30, 1.0, 1.0);
        let topology = |positions: &[Vec3]| {
            Topology::from_triangles(positions, None, &grid.indices(), TopologyOptions::default())
                .unwrap()
        };
        let even = grid.positions();
        assert!(topology(&even).self_collision_scales().is_empty());
        // Squeezed towards the middle along x: edges 2.3 times longer at the sides.
        let squeeze = |v: f32| {
            let u = v + 0.5;
            u + 0.4 * (core::f32::consts::TAU * u).sin() / core::f32::consts::TAU - 0.5
        };
        let mut uneven: Vec<Vec3> = even
            .iter()
            .map(|p| Vec3::new(squeeze(p.x), p.y, p.z))
            .collect();
        // A vertex in no triangle keeps the cloth's.
        uneven.push(Vec3::splat(9.0));
        let t = topology(&uneven);
        assert!(t.rest_edge_spread() > EVEN_EDGE_SPREAD);
        let scales = t.self_collision_scales();
        assert_eq!(scales.len(), uneven.len());
        let at = |x: u32| scales[grid.index(x, 15) as usize];
        let (side, middle) = (at(1), at(15));
        assert!(side > 1.1 && middle < 0.9, "side {side}, middle {middle}");
        assert!(
            scales
                .iter()
                .all(|s| (MIN_THICKNESS_SCALE..=MAX_THICKNESS_SCALE).contains(s))
        );
        assert_eq!(scales.last(), Some(&1.0));
    }

    /// The default self-collision thickness: the mean edge, at most 1.1 short edges on even
    /// meshes (the `cape` example's cape: 1.1 × 0.7 m / 15, under its mean edge); a grid of
    /// equilateral triangles keeps its edge; an uneven mesh keeps its mean edge.
    #[test]
    fn the_default_thickness_is_at_most_a_short_edge_and_a_tenth_on_even_meshes() {
        let of = |positions: &[Vec3], indices: &[u32]| {
            Topology::from_triangles(positions, None, indices, TopologyOptions::default()).unwrap()
        };
        let cape = Grid::new(16, 20, 0.7, 1.0);
        let t = of(&cape.positions(), &cape.indices());
        let short = 0.7 / 15.0;
        assert!(t.rest_edge_spread() <= EVEN_EDGE_SPREAD);
        assert!(t.mean_rest_edge() > 1.2 * short, "{}", t.mean_rest_edge());
        let want = DEFAULT_SHORT_EDGE_THICKNESS * short;
        let got = t.default_self_collision_thickness();
        assert!((got - want).abs() < 1e-5, "{got} against {want}");
        // Equal edges: the mean edge is the short edge, under 1.1 of it.
        let h = 3.0f32.sqrt() / 2.0;
        let strip: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new(0.5 * i as f32, if i % 2 == 0 { 0.0 } else { h }, 0.0))
            .collect();
        let indices: Vec<u32> = (0..6u32)
            .flat_map(|i| {
                if i % 2 == 0 {
                    [i, i + 1, i + 2]
                } else {
                    [i + 1, i, i + 2]
                }
            })
            .collect();
        let t = of(&strip, &indices);
        assert!((t.default_self_collision_thickness() - 1.0).abs() < 1e-5);
        // Uneven: the mean edge (each vertex scales it).
        let narrow = Grid::new(20, 20, 1.0, 0.4);
        let t = of(&narrow.positions(), &narrow.indices());
        assert!(t.rest_edge_spread() > EVEN_EDGE_SPREAD);
        assert_eq!(t.default_self_collision_thickness(), t.mean_rest_edge());
    }

    /// An open tube of `sides` flat walls (`radius` to their corners) and `rings` rings
    /// `spacing` apart along x: a sleeve.
    fn sleeve(sides: usize, rings: usize, radius: f32, spacing: f32) -> Topology {
        let positions: Vec<Vec3> = (0..rings * sides)
            .map(|v| {
                let (k, j) = (v / sides, v % sides);
                let a = core::f32::consts::TAU * (j as f32 + 0.5) / sides as f32;
                Vec3::new(k as f32 * spacing, radius * a.cos(), radius * a.sin())
            })
            .collect();
        let indices: Vec<u32> = (0..rings - 1)
            .flat_map(|k| (0..sides).map(move |j| (k, j)))
            .flat_map(|(k, j)| {
                let at = |k: usize, j: usize| (k * sides + j % sides) as u32;
                let (a, b) = (at(k, j), at(k, j + 1));
                let (c, d) = (at(k + 1, j + 1), at(k + 1, j));
                [a, b, c, a, c, d]
            })
            .collect();
        Topology::from_triangles(&positions, None, &indices, TopologyOptions::default()).unwrap()
    }

    /// The rest-gap cap: a square sleeve 0.2 m across with 0.2 m edges rests with each
    /// corner over the wall across from it, 0.2 m off, so its default thickness is half of
    /// that instead of its edges' 0.22 m; a flat sheet and a sleeve wider than its edges keep
    /// the edge rule. Fails if the cap is left out, looks only strictly inside triangles (the
    /// corner projects onto the opposite corner).
    #[test]
    fn the_default_thickness_is_at_most_half_the_narrowest_gap_across_the_rest_shape() {
        let square = sleeve(4, 6, 0.2 / 2.0f32.sqrt(), 0.2);
        assert!(square.rest_edge_spread() <= EVEN_EDGE_SPREAD);
        let gap = square.narrowest_rest_gap();
        assert!((gap - 0.2).abs() < 1e-5, "{gap}");
        assert!(
            square.edge_thickness() > 0.21,
            "{}",
            square.edge_thickness()
        );
        let got = square.default_self_collision_thickness();
        assert!((got - REST_GAP_THICKNESS * 0.2).abs() < 1e-5, "{got}");
        // Wide: 32 walls of 0.196 m around a 2 m tube, rings 0.2 m apart.
        let wide = sleeve(32, 6, 1.0, 0.2);
        assert_eq!(wide.narrowest_rest_gap(), f32::INFINITY);
        assert_eq!(
            wide.default_self_collision_thickness(),
            wide.edge_thickness()
        );
        let flat = Grid::new(20, 20, 1.0, 1.0)
            .topology(TopologyOptions::default())
            .unwrap();
        assert_eq!(flat.narrowest_rest_gap(), f32::INFINITY);
        assert_eq!(
            flat.default_self_collision_thickness(),
            flat.edge_thickness()
        );
        // A sheet bent along a crease: at a right angle the vertices a row from the crease
        // rest over the other side's edge, a row (0.2 m) off it; bent by 60° they rest
        // beside it.
        let bent = |angle: f32| {
            let grid = Grid::new(11, 11, 2.0, 2.0);
            let dir = Vec3::new(angle.cos(), angle.sin(), 0.0);
            let positions: Vec<Vec3> = grid
                .positions()
                .iter()
                .map(|p| {
                    if p.x > 0.0 {
                        Vec3::new(0.0, 0.0, p.z) + dir * p.x
                    } else {
                        *p
                    }
                })
                .collect();
            Topology::from_triangles(
                &positions,
                None,
                &grid.indices(),
                TopologyOptions::default(),
            )
            .unwrap()
        };
        let right = bent(core::f32::consts::FRAC_PI_2);
        let gap = right.narrowest_rest_gap();
        assert!((gap - 0.2).abs() < 1e-5, "{gap}");
        let open = bent(core::f32::consts::FRAC_PI_3);
        assert_eq!(open.narrowest_rest_gap(), f32::INFINITY);
        assert_eq!(
            open.default_self_collision_thickness(),
            open.edge_thickness()
        );
    }

    /// A sheet modelled twice (a second copy 1 mm over the first, under a tenth of the
    /// thickness) rests on itself, which is no gap; the same copy half an edge over it is one.
    #[test]
    fn a_face_modelled_twice_is_not_a_gap_but_a_layer_over_it_is() {
        let grid = Grid::new(6, 6, 1.0, 1.0);
        let (one, indices) = (grid.positions(), grid.indices());
        let twice = |lift: f32| {
            let positions: Vec<Vec3> = one
                .iter()
                .copied()
                .chain(one.iter().map(|p| *p + Vec3::Y * lift))
                .collect();
            let n = one.len() as u32;
            let indices: Vec<u32> = indices
                .iter()
                .chain(indices.iter())
                .enumerate()
                .map(|(k, &i)| if k < indices.len() { i } else { i + n })
                .collect();
            Topology::from_triangles(&positions, None, &indices, TopologyOptions::default())
                .unwrap()
        };
        let sheet =
            Topology::from_triangles(&one, None, &indices, TopologyOptions::default()).unwrap();
        let edges = sheet.default_self_collision_thickness();
        let doubled = twice(0.001);
        assert_eq!(doubled.narrowest_rest_gap(), f32::INFINITY);
        assert_eq!(doubled.default_self_collision_thickness(), edges);
        let layered = twice(0.1);
        assert!((layered.narrowest_rest_gap() - 0.1).abs() < 1e-6);
        let got = layered.default_self_collision_thickness();
        assert!(
            (got - REST_GAP_THICKNESS * 0.1).abs() < 1e-6,
            "{got} ({edges})"
        );
    }

    /// A grid of long narrow cells (finer along z than along x, as a skirt's tube is finer
    /// around than along): each vertex keeps from triangles at most 1.2 of its short edge,
    /// less than its thickness from vertices (the mean of its edges); where the cells are
    /// square (the squeezed grid's middle) it keeps the same from both.
    #[test]
    fn a_vertex_keeps_at_most_a_short_edge_and_a_fifth_from_triangles() {
        let (a, b) = (1.0 / 19.0f32, 0.4 / 19.0f32);
        let grid = Grid::new(20, 20, 1.0, 0.4);
        let t = Topology::from_triangles(
            &grid.positions(),
            None,
            &grid.indices(),
            TopologyOptions::default(),
        )
        .unwrap();
        assert!(t.rest_edge_spread() > EVEN_EDGE_SPREAD);
        let (scales, thin) = (
            t.self_collision_scales(),
            t.self_collision_triangle_scales(),
        );
        assert_eq!(thin.len(), scales.len());
        // The mean over every triangle's edges: a side each way and a diagonal.
        let mean = (a + b + a.hypot(b)) / 3.0;
        let inner = grid.index(10, 10) as usize;
        let want = SHORT_EDGE_THICKNESS * b / mean;
        assert!(
            (thin[inner] - want).abs() < 1e-4 * want,
            "{} against {want}",
            thin[inner]
        );
        assert!(scales[inner] > 1.5 * thin[inner], "{}", scales[inner]);
        assert!(thin.iter().zip(scales).all(|(t, s)| t <= s));
        // Square cells: the cap (1.2 sides) is over the mean edge (1.14 sides) and binds
        // nowhere inside; the squeeze of the test above makes its middle cells square.
        let square = Grid::new(30, 30, 1.0, 1.0);
        let squeeze = |v: f32| {
            let u = v + 0.5;
            u + 0.4 * (core::f32::consts::TAU * u).sin() / core::f32::consts::TAU - 0.5
        };
        let squeezed: Vec<Vec3> = square
            .positions()
            .iter()
            .map(|p| Vec3::new(squeeze(p.x), p.y, squeeze(p.z)))
            .collect();
        let t = Topology::from_triangles(
            &squeezed,
            None,
            &square.indices(),
            TopologyOptions::default(),
        )
        .unwrap();
        let middle = square.index(15, 15) as usize;
        assert_eq!(
            t.self_collision_triangle_scales()[middle],
            t.self_collision_scales()[middle]
        );
        let corner = square.index(1, 7) as usize;
        assert!(
            t.self_collision_triangle_scales()[corner] < t.self_collision_scales()[corner],
            "long narrow cells where one axis is squeezed and the other stretched"
        );
    }

    #[test]
    fn cloths_too_large_to_allocate_are_refused_before_allocating() {
        // 60 000² vertices would be tens of gigabytes: refused by the grid's own check,
        // before any position is made.
        let huge = Grid::new(60_000, 60_000, 1.0, 1.0);
        assert!(matches!(
            huge.validate(),
            Err(TopologyError::TooLarge {
                vertices: 3_600_000_000,
                ..
            })
        ));
        assert!(huge.topology(TopologyOptions::default()).is_err());
        // The limit itself is accepted (2048²), one row more is not.
        assert!(Grid::new(2048, 2048, 1.0, 1.0).validate().is_ok());
        assert!(matches!(
            Grid::new(2048, 2049, 1.0, 1.0).validate(),
            Err(TopologyError::TooLarge { .. })
        ));
        // A triangle list of more vertices than the limit, refused by count alone.
        let positions = vec![Vec3::ZERO; MAX_VERTICES + 1];
        let err =
            Topology::from_triangles(&positions, None, &[0, 1, 2], TopologyOptions::default());
        assert!(
            matches!(err, Err(TopologyError::TooLarge { .. })),
            "{err:?}"
        );
    }

    #[test]
    fn grid_has_six_edges_per_interior_vertex() {
        let g = Grid::new(5, 4, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let mut degree = vec![0; g.vertex_count()];
        for e in t.edges() {
            degree[e.v[0] as usize] += 1;
            degree[e.v[1] as usize] += 1;
        }
        for j in 1..3 {
            for i in 1..4 {
                assert_eq!(degree[g.index(i, j) as usize], 6, "vertex ({i},{j})");
            }
        }
        // (c−1)·r horizontal + c·(r−1) vertical stretch, (c−1)(r−1) diagonal shear.
        let stretch = t
            .edges()
            .iter()
            .filter(|e| e.kind == EdgeKind::Stretch)
            .count();
        let shear = t
            .edges()
            .iter()
            .filter(|e| e.kind == EdgeKind::Shear)
            .count();
        assert_eq!(stretch, 4 * 4 + 5 * 3);
        assert_eq!(shear, 4 * 3);
        for e in t.edges() {
            let expect = match e.kind {
                EdgeKind::Stretch
                    if g.positions()[e.v[0] as usize].z == g.positions()[e.v[1] as usize].z =>
                {
                    0.25
                }
                EdgeKind::Stretch => 1.0 / 3.0,
                EdgeKind::Shear => (0.25f32 * 0.25 + 1.0 / 9.0).sqrt(),
            };
            assert!((e.rest - expect).abs() < 1e-6, "{e:?}");
        }
    }

    #[test]
    fn every_interior_edge_bends_and_flat_rest_is_pi() {
        let g = Grid::new(4, 4, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let boundary = 4 * 3;
        assert_eq!(t.bends().len(), t.edges().len() - boundary);
        for b in t.bends() {
            assert_eq!(b.rest_angle, 0.0);
            let e = t.edges()[b.edge as usize];
            assert_eq!(e.v, [b.v[0], b.v[1]]);
        }
        let rest = g.topology(TopologyOptions {
            bend_rest: BendRest::RestShape,
            ..Default::default()
        });
        for b in rest.unwrap().bends() {
            assert!(b.rest_angle.abs() < 1e-3);
        }
    }

    #[test]
    fn grid_faces_up() {
        let g = Grid::new(3, 3, 2.0, 2.0);
        let p = g.positions();
        for t in g.indices().chunks(3) {
            let n =
                (p[t[1] as usize] - p[t[0] as usize]).cross(p[t[2] as usize] - p[t[0] as usize]);
            assert!(n.y > 0.0 && n.x == 0.0 && n.z == 0.0);
        }
    }

    #[test]
    fn bad_meshes_are_rejected() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let o = TopologyOptions::default();
        assert_eq!(
            Topology::from_triangles(&[], None, &[], o),
            Err(TopologyError::NoVertices)
        );
        assert_eq!(
            Topology::from_triangles(&p, None, &[0, 1], o),
            Err(TopologyError::NotTriangles { index_count: 2 })
        );
        assert!(matches!(
            Topology::from_triangles(&p, None, &[0, 1, 3], o),
            Err(TopologyError::IndexOutOfRange {
                index: 3,
                position: 2,
                ..
            })
        ));
        assert_eq!(
            Topology::from_triangles(&[Vec3::ZERO, Vec3::NAN, Vec3::Y], None, &[0, 1, 2], o),
            Err(TopologyError::NonFinitePosition { vertex: 1 })
        );
        assert_eq!(
            Topology::from_triangles(&p, None, &[0, 0, 1], o),
            Err(TopologyError::NoTriangles)
        );
        assert!(Grid::new(1, 5, 1.0, 1.0).validate().is_err());
        assert!(Grid::new(2, 2, f32::NAN, 1.0).validate().is_err());
        assert!(Grid::new(2, 2, 1.0, -1.0).validate().is_err());
    }

    #[test]
    fn masses_sum_to_total() {
        let g = Grid::new(6, 5, 2.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        for d in [MassDistribution::Area, MassDistribution::Uniform] {
            let m = t.masses(3.0, d);
            let sum: f32 = m.iter().sum();
            assert!((sum - 3.0).abs() < 1e-4, "{d:?} {sum}");
            assert!(m.iter().all(|&x| x > 0.0));
        }
        // Interior vertices carry six triangles' thirds, corners fewer.
        let m = t.masses(1.0, MassDistribution::Area);
        assert!(m[g.index(2, 2) as usize] > m[0]);
    }

    #[test]
    fn a_tetrahedron_is_closed_a_grid_is_not_and_a_tear_opens_it() {
        let o = TopologyOptions::default();
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let tet =
            Topology::from_triangles(&p, None, &[0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], o).unwrap();
        assert!(tet.is_closed());
        // One face short: three edges in one triangle each.
        let open = Topology::from_triangles(&p, None, &[0, 2, 1, 0, 1, 3, 0, 3, 2], o).unwrap();
        assert!(!open.is_closed());
        let grid = Grid::new(4, 4, 1.0, 1.0).topology(o).unwrap();
        assert!(!grid.is_closed());
        assert!(!tet.without_edges(&[[0, 1]]).is_closed());
    }
}
