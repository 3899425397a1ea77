//! Writes simulated positions, normals and tangents into the cloth's mesh.
//!
//! Runs once per rendered frame, after transform propagation, and only for cloths that moved
//! since the last write. The simulation is in world space; the mesh is in the entity's local
//! space, so positions go through the inverse of its [`GlobalTransform`], normals through its
//! transpose (inverse-transpose of world-to-local) and tangents through its inverse.

use bevy::mesh::{Indices, VertexAttributeValues};
use bevy::prelude::*;

use super::ClothSim;

pub(crate) fn write_back(
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut cloths: Query<(&mut ClothSim, &GlobalTransform)>,
) {
    let Some(meshes) = meshes.as_deref_mut() else {
        return;
    };
    for (cloth, gt) in &mut cloths {
        if !cloth.dirty {
            continue;
        }
        let cloth = cloth.into_inner();
        cloth.dirty = false;
        cloth.sim.update_shading();
        let sim = &cloth.sim;
        let Some(mut mesh) = meshes.get_mut(&cloth.mesh) else {
            continue;
        };
        if core::mem::take(&mut cloth.indices_dirty) {
            // Torn triangles leave the index buffer; the vertex buffer keeps its size.
            let indices: Vec<u32> = sim
                .topology()
                .triangles()
                .iter()
                .flatten()
                .copied()
                .collect();
            mesh.insert_indices(Indices::U32(indices));
        }
        let affine = gt.affine();
        let to_local = affine.inverse();
        let linear = affine.matrix3;
        let normal_to_local = linear.transpose();
        let tangent_to_local = to_local.matrix3;

        if let Ok(VertexAttributeValues::Float32x3(out)) =
            mesh.try_attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            for (o, p) in out.iter_mut().zip(&sim.state().positions) {
                *o = to_local.transform_point3(p.truncate()).to_array();
            }
        }
        if let Ok(VertexAttributeValues::Float32x3(out)) =
            mesh.try_attribute_mut(Mesh::ATTRIBUTE_NORMAL)
        {
            for (o, n) in out.iter_mut().zip(sim.normals()) {
                *o = (normal_to_local * *n).normalize_or(Vec3::Y).to_array();
            }
        }
        if !sim.tangents().is_empty()
            && let Ok(VertexAttributeValues::Float32x4(out)) =
                mesh.try_attribute_mut(Mesh::ATTRIBUTE_TANGENT)
        {
            for (o, t) in out.iter_mut().zip(sim.tangents()) {
                let local = (tangent_to_local * t.truncate()).normalize_or(Vec3::X);
                *o = local.extend(t.w).to_array();
            }
        }
    }
}
