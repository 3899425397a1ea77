//! The cloth's own copy of the mesh it was built from.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;

use crate::foundation::MeshData;

/// The cloth's own copy of its source mesh: main-world data kept, normals (and tangents when
/// there are UVs or tangents to follow) present so write-back can fill them; a triangle strip
/// made a list of its triangles. Morph targets
/// (shape keys) are left out: the renderer would add their displacements to the simulated
/// positions, so the cloth would be drawn away from where it is.
pub(crate) fn cloth_mesh(source: &Mesh, data: &MeshData) -> Mesh {
    let strip = source.primitive_topology() == PrimitiveTopology::TriangleStrip;
    let mut mesh = if strip {
        // A strip becomes the list of its triangles (as `read_mesh` read it): torn triangles
        // leave a list's index buffer.
        let mut copy = Mesh::new(
            PrimitiveTopology::TriangleList,
            RenderAssetUsages::default(),
        );
        for (attribute, values) in source.attributes() {
            copy.insert_attribute(*attribute, values.clone());
        }
        copy.insert_indices(if data.u16_indices {
            Indices::U16(data.indices.iter().map(|&i| i as u16).collect())
        } else {
            Indices::U32(data.indices.clone())
        });
        copy
    } else if source.try_has_morph_targets().unwrap_or(false) {
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
