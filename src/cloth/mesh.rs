//! Reading a Bevy [`Mesh`] into solver input, and building cloth meshes.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;

use crate::solver::Grid;

use super::ClothError;

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
    /// Triangle-list indices.
    pub indices: Vec<u32>,
    /// Whether the mesh stores its indices as `u16` (rewritten in the same format).
    pub u16_indices: bool,
}

impl MeshData {
    /// The optional attributes, as the solver's welding takes them.
    #[must_use]
    pub fn attributes(&self) -> crate::solver::MeshAttributes<'_> {
        crate::solver::MeshAttributes {
            normals: self.normals.as_deref(),
            uvs: self.uvs.as_deref(),
            tangents: self.tangents.as_deref(),
        }
    }
}

/// Reads what the solver needs from `mesh`.
///
/// # Errors
/// [`ClothError`] if the mesh is not a triangle list, its data has been moved to the render
/// world, or it lacks `Float32x3` positions or indices.
pub fn read_mesh(mesh: &Mesh) -> Result<MeshData, ClothError> {
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(ClothError::NotTriangleList(format!(
            "{:?}",
            mesh.primitive_topology()
        )));
    }
    let positions: Vec<Vec3> = match mesh.try_attribute_option(Mesh::ATTRIBUTE_POSITION) {
        Err(_) => return Err(ClothError::MeshNotInMainWorld),
        Ok(None) => return Err(ClothError::NoPositions),
        Ok(Some(VertexAttributeValues::Float32x3(p))) => p.iter().map(|&v| Vec3::from(v)).collect(),
        Ok(Some(other)) => {
            let format = bevy::mesh::VertexFormat::from(other);
            return Err(ClothError::PositionFormat(format!("{format:?}")));
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
        Err(_) => return Err(ClothError::MeshNotInMainWorld),
        Ok(None) => return Err(ClothError::NoIndices),
        Ok(Some(Indices::U16(i))) => (i.iter().map(|&v| u32::from(v)).collect(), true),
        Ok(Some(Indices::U32(i))) => (i.clone(), false),
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

/// A mesh for `grid`: positions, +Y normals, UVs, +X tangents, `u32` indices; kept in the main
/// world so the cloth plugin can read and rewrite it.
#[must_use]
pub fn grid_mesh(grid: &Grid) -> Mesh {
    let positions: Vec<[f32; 3]> = grid.positions().iter().map(|p| p.to_array()).collect();
    let n = positions.len();
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; n])
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_UV_0,
        grid.uvs()
            .iter()
            .map(|uv| uv.to_array())
            .collect::<Vec<_>>(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_TANGENT, vec![[1.0f32, 0.0, 0.0, 1.0]; n])
    .with_inserted_indices(Indices::U32(grid.indices()))
}

/// The cloth's own copy of its source mesh: main-world data kept, normals (and tangents when
/// there are UVs or tangents to follow) present so write-back can fill them.
pub(crate) fn cloth_mesh(source: &Mesh, data: &MeshData) -> Mesh {
    let mut mesh = source.clone();
    mesh.asset_usage = RenderAssetUsages::default();
    let n = data.positions.len();
    if !matches!(
        mesh.try_attribute_option(Mesh::ATTRIBUTE_NORMAL),
        Ok(Some(VertexAttributeValues::Float32x3(v))) if v.len() == n
    ) {
        mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; n]);
    }
    if (data.uvs.is_some() || data.tangents.is_some())
        && !matches!(
            mesh.try_attribute_option(Mesh::ATTRIBUTE_TANGENT),
            Ok(Some(VertexAttributeValues::Float32x4(v))) if v.len() == n
        )
    {
        mesh.insert_attribute(Mesh::ATTRIBUTE_TANGENT, vec![[1.0f32, 0.0, 0.0, 1.0]; n]);
    }
    mesh
}
