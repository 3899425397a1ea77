//! Reading a Bevy [`Mesh`] into solver input ([`read_mesh`], for cloths and mesh colliders),
//! and building a mesh for a [`Grid`].

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;

use crate::solver::{Grid, MeshAttributes, TopologyError};

/// Why a mesh cannot be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MeshError {
    /// The mesh is neither a triangle list nor a triangle strip (the topology found is given).
    NotTriangleList(String),
    /// The mesh has no `POSITION` attribute.
    NoPositions,
    /// The positions are not `Float32x3` (the format found is given).
    PositionFormat(String),
    /// The mesh has no index buffer and its vertex count (given) is not a multiple of three,
    /// so it is not a list of whole triangles.
    PartialTriangle(usize),
    /// The mesh's vertex data lives only in the render world (`RenderAssetUsages::RENDER_WORLD`):
    /// the CPU cannot read it.
    NotInMainWorld,
}

impl core::fmt::Display for MeshError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MeshError::NotTriangleList(t) => {
                write!(f, "mesh topology is {t}, not a triangle list or strip")
            }
            MeshError::NoPositions => write!(f, "mesh has no POSITION attribute"),
            MeshError::PositionFormat(t) => write!(f, "mesh positions are {t}, not Float32x3"),
            MeshError::PartialTriangle(n) => write!(
                f,
                "mesh has no indices and {n} vertices, not a multiple of 3: not whole triangles"
            ),
            MeshError::NotInMainWorld => write!(
                f,
                "mesh data is only in the render world; create it with RenderAssetUsages::MAIN_WORLD"
            ),
        }
    }
}

impl std::error::Error for MeshError {}

/// What the cloth needs from a mesh: positions, indices and the optional attributes that
/// shape welding and shading.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshData {
    /// Vertex positions in mesh space.
    pub positions: Vec<Vec3>,
    /// `UV_0`, if present as `Float32x2`.
    pub uvs: Option<Vec<Vec2>>,
    /// `NORMAL`, if present as `Float32x3` (tells hard edges from UV seams when welding).
    pub normals: Option<Vec<Vec3>>,
    /// `TANGENT`, if present as `Float32x4`.
    pub tangents: Option<Vec<Vec4>>,
    /// Triangle-list indices (`0, 1, 2, 3, …` for a mesh without an index buffer).
    pub indices: Vec<u32>,
    /// Whether the mesh stores its indices as `u16` (rewritten in the same format).
    pub u16_indices: bool,
}

impl MeshData {
    /// The optional attributes, as the solver's welding takes them.
    #[must_use]
    pub fn attributes(&self) -> MeshAttributes<'_> {
        MeshAttributes {
            normals: self.normals.as_deref(),
            uvs: self.uvs.as_deref(),
            tangents: self.tangents.as_deref(),
        }
    }
}

/// Reads what the solver needs from `mesh`. A triangle strip is read as the list of its
/// triangles ([`strip_triangles`]).
///
/// # Errors
/// [`MeshError`] if the mesh is neither a triangle list nor a triangle strip, its data has
/// been moved to the render world, it lacks `Float32x3` positions, or it is a list with no
/// indices and a vertex count that is not a multiple of three.
pub fn read_mesh(mesh: &Mesh) -> Result<MeshData, MeshError> {
    let strip = match mesh.primitive_topology() {
        PrimitiveTopology::TriangleList => false,
        PrimitiveTopology::TriangleStrip => true,
        other => return Err(MeshError::NotTriangleList(format!("{other:?}"))),
    };
    let positions: Vec<Vec3> = match mesh.try_attribute_option(Mesh::ATTRIBUTE_POSITION) {
        Err(_) => return Err(MeshError::NotInMainWorld),
        Ok(None) => return Err(MeshError::NoPositions),
        Ok(Some(VertexAttributeValues::Float32x3(p))) => p.iter().map(|&v| Vec3::from(v)).collect(),
        Ok(Some(other)) => {
            let format = bevy::mesh::VertexFormat::from(other);
            return Err(MeshError::PositionFormat(format!("{format:?}")));
        }
    };
    let uvs = match mesh.try_attribute_option(Mesh::ATTRIBUTE_UV_0) {
        Ok(Some(VertexAttributeValues::Float32x2(uv))) => {
            Some(uv.iter().map(|&v| Vec2::from(v)).collect())
        }
        _ => None,
    };
    let normals = match mesh.try_attribute_option(Mesh::ATTRIBUTE_NORMAL) {
        Ok(Some(VertexAttributeValues::Float32x3(n))) if n.len() == positions.len() => {
            Some(n.iter().map(|&v| Vec3::from(v)).collect())
        }
        _ => None,
    };
    let tangents = match mesh.try_attribute_option(Mesh::ATTRIBUTE_TANGENT) {
        Ok(Some(VertexAttributeValues::Float32x4(t))) if t.len() == positions.len() => {
            Some(t.iter().map(|&v| Vec4::from(v)).collect())
        }
        _ => None,
    };
    let (indices, u16_indices) = match mesh.try_indices_option() {
        Err(_) => return Err(MeshError::NotInMainWorld),
        // No index buffer (glTF allows it; Bevy's Fox has none): every three vertices are a
        // triangle. Welding then joins the copies each triangle has of its corners.
        Ok(None) if !strip && !positions.len().is_multiple_of(3) => {
            return Err(MeshError::PartialTriangle(positions.len()));
        }
        Ok(None) => (
            (0..positions.len() as u32).collect(),
            positions.len() <= usize::from(u16::MAX) + 1,
        ),
        Ok(Some(Indices::U16(i))) => (i.iter().map(|&v| u32::from(v)).collect(), true),
        Ok(Some(Indices::U32(i))) => (i.clone(), false),
    };
    let indices = if strip {
        // The restart index of the buffer's format (all ones) begins a new strip.
        let restart = match mesh.indices() {
            Some(Indices::U16(_)) => u32::from(u16::MAX),
            Some(Indices::U32(_)) => u32::MAX,
            None => u32::MAX,
        };
        strip_triangles(&indices, restart)
    } else {
        indices
    };
    Ok(MeshData {
        positions,
        uvs,
        normals,
        tangents,
        indices,
        u16_indices,
    })
}

/// The triangles of a triangle strip as a list, three indices a triangle, facing the way the
/// GPU draws the strip: triangle `k` of a run is `(s[k], s[k+1], s[k+2])` for even `k` and
/// `(s[k+1], s[k], s[k+2])` for odd `k`. `restart` (the index format's all-ones value) begins
/// a new run; triangles with a repeated index (how strips are joined) are left out.
#[must_use]
pub fn strip_triangles(strip: &[u32], restart: u32) -> Vec<u32> {
    let mut out = Vec::with_capacity(3 * strip.len().saturating_sub(2));
    for run in strip.split(|&i| i == restart) {
        for (k, w) in run.windows(3).enumerate() {
            let t = if k % 2 == 0 {
                [w[0], w[1], w[2]]
            } else {
                [w[1], w[0], w[2]]
            };
            if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                out.extend(t);
            }
        }
    }
    out
}

/// The box around the finite ones of `positions` (lowest corner, highest corner); `None`
/// when none is finite.
pub(crate) fn finite_bounds(positions: impl IntoIterator<Item = Vec3>) -> Option<(Vec3, Vec3)> {
    let (lo, hi) = positions.into_iter().filter(|p| p.is_finite()).fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p), hi.max(p)),
    );
    lo.cmple(hi).all().then_some((lo, hi))
}

/// A hash of everything in `mesh` (topology, every attribute, indices): an asset event that
/// leaves it the same (the engine touching an asset it did not change) rebuilds nothing.
pub(crate) fn mesh_fingerprint(mesh: &Mesh) -> u64 {
    use core::hash::{Hash, Hasher};
    let mut h = std::hash::DefaultHasher::new();
    mesh.primitive_topology().hash(&mut h);
    for (attribute, values) in mesh.attributes() {
        attribute.id.hash(&mut h);
        values.get_bytes().hash(&mut h);
    }
    match mesh.indices() {
        Some(Indices::U16(i)) => i.hash(&mut h),
        Some(Indices::U32(i)) => i.hash(&mut h),
        None => 0u8.hash(&mut h),
    }
    h.finish()
}

/// The meshes whose asset changed since `events` last read (reloaded from disk, or edited
/// through `Assets::get_mut`).
pub(crate) fn modified_meshes(events: &mut MessageReader<AssetEvent<Mesh>>) -> Vec<AssetId<Mesh>> {
    events
        .read()
        .filter_map(|e| match e {
            AssetEvent::Modified { id } => Some(*id),
            _ => None,
        })
        .collect()
}

/// A mesh for `grid`: positions, +Y normals, UVs, +X tangents, `u32` indices; kept in the main
/// world so the cloth plugin can read and rewrite it.
///
/// The grid lies in the entity's XZ plane, centred on its origin, front face +Y: vertex
/// [`grid.index(i, j)`](Grid::index) is column `i` (x grows with `i`) of row `j`, and row 0
/// is the edge at `z = +height/2`. Turned by −90° about X
/// (`Transform::from_rotation(Quat::from_rotation_x(-FRAC_PI_2))`) the grid stands up like a
/// curtain with row 0 at the top and its front face towards −Z: pin `grid.index(i, 0)` to
/// hang it.
///
/// A grid that fails [`Grid::validate`] (fewer than 2×2 vertices, a size that is not finite
/// and positive, more vertices than a cloth may have) logs why and gives an empty mesh, which
/// a `Cloth` then reports as invalid; nothing is allocated for it. [`try_grid_mesh`] returns
/// the error instead.
#[must_use]
pub fn grid_mesh(grid: &Grid) -> Mesh {
    try_grid_mesh(grid).unwrap_or_else(|e| {
        error!("grid_mesh: {e}; the mesh is left empty");
        triangle_list_mesh(Vec::new(), Vec::new(), Vec::new())
    })
}

/// [`grid_mesh`], or why the grid cannot be made (checked by [`Grid::validate`] before
/// anything is allocated).
///
/// # Errors
/// [`TopologyError::BadGrid`] or [`TopologyError::TooLarge`] from [`Grid::validate`].
pub fn try_grid_mesh(grid: &Grid) -> Result<Mesh, TopologyError> {
    grid.validate()?;
    let positions: Vec<[f32; 3]> = grid.positions().iter().map(|p| p.to_array()).collect();
    let uvs = grid.uvs().iter().map(|uv| uv.to_array()).collect();
    Ok(triangle_list_mesh(positions, uvs, grid.indices()))
}

/// A main-world triangle list of `positions` with +Y normals, `uvs`, +X tangents and `u32`
/// `indices`.
fn triangle_list_mesh(positions: Vec<[f32; 3]>, uvs: Vec<[f32; 2]>, indices: Vec<u32>) -> Mesh {
    let n = positions.len();
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; n])
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
    .with_inserted_attribute(Mesh::ATTRIBUTE_TANGENT, vec![[1.0f32, 0.0, 0.0, 1.0]; n])
    .with_inserted_indices(Indices::U32(indices))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle_list(vertices: usize) -> Mesh {
        let positions: Vec<[f32; 3]> = (0..vertices).map(|i| [i as f32, 0.0, 0.0]).collect();
        Mesh::new(
            PrimitiveTopology::TriangleList,
            RenderAssetUsages::default(),
        )
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    }

    /// A strip's triangles alternate their corner order so that all face one way (as
    /// Vulkan draws a strip); a restart index begins a new strip; the degenerate triangles
    /// that join strips are left out. Expected lists written by hand.
    #[test]
    fn a_strip_is_read_as_its_triangles() {
        assert_eq!(
            strip_triangles(&[0, 1, 2, 3, 4], u32::MAX),
            [0, 1, 2, 2, 1, 3, 2, 3, 4]
        );
        assert_eq!(
            strip_triangles(&[0, 1, 2, 0xFFFF, 3, 4, 5, 6], 0xFFFF),
            [0, 1, 2, 3, 4, 5, 5, 4, 6]
        );
        // Two strips joined by repeating 3 and 4: the four triangles with a repeat go.
        assert_eq!(
            strip_triangles(&[0, 1, 2, 3, 3, 4, 4, 5, 6], u32::MAX),
            [0, 1, 2, 2, 1, 3, 4, 5, 6]
        );
        assert!(strip_triangles(&[0, 1], u32::MAX).is_empty());
        // A mesh with a strip topology (no index buffer: 0, 1, 2, …) reads as that list;
        // lines are still refused.
        let with = |topology, n: usize| {
            let positions: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, 0.0, 0.0]).collect();
            Mesh::new(topology, RenderAssetUsages::default())
                .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        };
        let strip = with(PrimitiveTopology::TriangleStrip, 5);
        assert_eq!(
            read_mesh(&strip).unwrap().indices,
            [0, 1, 2, 2, 1, 3, 2, 3, 4]
        );
        let lines = with(PrimitiveTopology::LineList, 4);
        assert!(matches!(
            read_mesh(&lines),
            Err(MeshError::NotTriangleList(_))
        ));
    }

    #[test]
    fn a_mesh_without_indices_is_read_as_consecutive_triangles() {
        let data = read_mesh(&triangle_list(6)).unwrap();
        assert_eq!(data.indices, [0, 1, 2, 3, 4, 5]);
        assert!(data.u16_indices);
        assert!(!read_mesh(&triangle_list(70_002)).unwrap().u16_indices);
        assert_eq!(
            read_mesh(&triangle_list(4)),
            Err(MeshError::PartialTriangle(4))
        );
    }

    fn vertex_count(mesh: &Mesh) -> usize {
        mesh.attribute(Mesh::ATTRIBUTE_POSITION)
            .map_or(usize::MAX, VertexAttributeValues::len)
    }

    #[test]
    fn a_grid_that_cannot_be_made_gives_an_error_or_an_empty_mesh_without_allocating_it() {
        // 10^10 vertices: making them would need 120 GB for the positions alone.
        let huge = Grid::new(100_000, 100_000, 1.0, 1.0);
        assert!(matches!(
            try_grid_mesh(&huge),
            Err(TopologyError::TooLarge {
                vertices: 10_000_000_000,
                ..
            })
        ));
        assert_eq!(vertex_count(&grid_mesh(&huge)), 0);
        for bad in [
            Grid::new(1, 32, 1.0, 1.0),
            Grid::new(4, 4, 0.0, 1.0),
            Grid::new(4, 4, 1.0, f32::NAN),
        ] {
            assert!(matches!(
                try_grid_mesh(&bad),
                Err(TopologyError::BadGrid { .. })
            ));
            assert_eq!(vertex_count(&grid_mesh(&bad)), 0);
        }
        let good = grid_mesh(&Grid::new(3, 2, 1.0, 1.0));
        assert_eq!(vertex_count(&good), 6);
        assert_eq!(good.indices().map(Indices::len), Some(12));
    }
}
