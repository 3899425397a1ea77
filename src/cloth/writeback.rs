//! Writes simulated positions, normals and tangents into the cloth's mesh.
//!
//! Runs once per rendered frame in `PostUpdate`, after transform propagation and before Bevy's
//! asset events (so the renderer picks the new vertices up in the same frame), and only for
//! cloths that moved since the last write. The simulation is in world space; the mesh is in
//! the entity's local space, so positions go through the inverse of its [`GlobalTransform`],
//! normals through its transpose (inverse-transpose of world-to-local) and tangents through
//! its inverse. Every copy of a welded vertex is written.
//!
//! A mirrored entity (negative determinant) turns the triangles' winding around in world
//! space, so normals computed there point out of the back face: they are flipped back.

use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use super::{ClothSim, ClothSteppedElsewhere};

/// Copies the moved cloths' state into their meshes (torn triangles leave the index buffer,
/// kept in the mesh's own index format; the vertex buffer keeps its size). Cloths stepped
/// elsewhere write their own mesh.
pub(super) fn write_back(
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut cloths: Query<(&mut ClothSim, &GlobalTransform), Without<ClothSteppedElsewhere>>,
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
        cloth.binding.update_shading(&cloth.sim.state().positions);
        let Some(mut mesh) = meshes.get_mut(&cloth.mesh) else {
            continue;
        };
        cloth.write_indices(&mut mesh);
        let binding = &cloth.binding;
        let affine = gt.affine();
        let to_local = affine.inverse();
        if !to_local.is_finite() {
            // A zero scale (the entity or a parent shrunk to nothing): nothing is drawn, and
            // the mesh keeps its last shape rather than take non-finite positions.
            continue;
        }
        let linear = affine.matrix3;
        let flip = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let normal_to_local = linear.transpose();
        let tangent_to_local = to_local.matrix3;
        let particles = &cloth.sim.state().positions;
        let weld = binding.weld();

        if let Ok(VertexAttributeValues::Float32x3(out)) =
            mesh.try_attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            for (o, &p) in out.iter_mut().zip(weld.particles()) {
                *o = to_local
                    .transform_point3(particles[p as usize].truncate())
                    .to_array();
            }
        }
        let shading = binding.shading();
        if let Ok(VertexAttributeValues::Float32x3(out)) =
            mesh.try_attribute_mut(Mesh::ATTRIBUTE_NORMAL)
        {
            for (o, n) in out.iter_mut().zip(shading.normals()) {
                *o = (normal_to_local * (*n * flip))
                    .normalize_or(Vec3::Y)
                    .to_array();
            }
        }
        if !shading.tangents().is_empty()
            && let Ok(VertexAttributeValues::Float32x4(out)) =
                mesh.try_attribute_mut(Mesh::ATTRIBUTE_TANGENT)
        {
            for (o, t) in out.iter_mut().zip(shading.tangents()) {
                let local = (tangent_to_local * t.truncate()).normalize_or(Vec3::X);
                *o = local.extend(t.w).to_array();
            }
        }
    }
}
