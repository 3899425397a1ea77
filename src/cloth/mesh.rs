//! The cloth's own copy of the mesh it was built from.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use crate::foundation::MeshData;

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
