//! The cloth's own copy of the mesh it was built from.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use crate::foundation::MeshData;

/// The cloth's own copy of its source mesh: main-world data kept, normals (and tangents when
/// there are UVs or tangents to follow) present so write-back can fill them. Morph targets
/// (shape keys) are left out: the renderer would add their displacements to the simulated
/// positions, so the cloth would be drawn away from where it is.
pub(crate) fn cloth_mesh(source: &Mesh, data: &MeshData) -> Mesh {
    let mut mesh = if source.try_has_morph_targets().unwrap_or(false) {
        let mut copy = Mesh::new(source.primitive_topology(), RenderAssetUsages::default());
        for (attribute, values) in source.attributes() {
            copy.insert_attribute(*attribute, values.clone());
        }
        if let Some(indices) = source.indices() {
            copy.insert_indices(indices.clone());
        }
        copy
    } else {
        source.clone()
    };
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
