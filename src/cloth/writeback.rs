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
//!
//! With [`ClothSmoothing`], each vertex is drawn `x + s·v` (see [`ClothSmoothing::shift`]),
//! written every frame the shift changes; the GPU's `mesh.wgsl` draws the same.

use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use super::{ClothSim, ClothSmoothing, ClothSteppedElsewhere};
use crate::foundation::ClothSchedule;
use crate::solver::ClothState;

/// Copies the moved cloths' state into their meshes (torn triangles leave the index buffer,
/// kept in the mesh's own index format; the vertex buffer keeps its size). Cloths stepped
/// elsewhere write their own mesh.
pub(super) fn write_back(
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut cloths: Query<
        (&mut ClothSim, &GlobalTransform, Option<&ClothSmoothing>),
        Without<ClothSteppedElsewhere>,
    >,
    schedule: Option<Res<ClothSchedule>>,
    fixed: Option<Res<Time<Fixed>>>,
) {
    let Some(meshes) = meshes.as_deref_mut() else {
        return;
    };
    let overstep = ClothSchedule::overstep(schedule.as_deref(), fixed.as_deref());
    for (cloth, gt, smoothing) in &mut cloths {
        // A sleeping cloth's velocities are zero: no shift to draw.
        let shift = match (smoothing, overstep) {
            (Some(s), Some((step, fraction))) if !cloth.sim.is_sleeping() => {
                s.shift(step, fraction)
            }
            _ => 0.0,
        };
        if !cloth.dirty && shift == cloth.drawn_shift {
            continue;
        }
        let cloth = cloth.into_inner();
        cloth.dirty = false;
        cloth.drawn_shift = shift;
        let state = cloth.sim.state();
        if shift != 0.0 {
            // Each vertex's velocity with the motion carried into the step (`ClothInertia`),
            // which moved it too.
            let carried = cloth.sim.carried_velocity();
            cloth.drawn.clear();
            cloth
                .drawn
                .extend(state.positions.iter().zip(&state.velocities).map(|(p, v)| {
                    let v = match carried {
                        Some(c) => *v + c.at(p.truncate()).extend(0.0),
                        None => *v,
                    };
                    ClothSmoothing::place(*p, v, shift)
                }));
        }
        cloth
            .binding
            .update_shading(drawn(cloth.sim.state(), &cloth.drawn, shift));
        let Some(mut mesh) = meshes.get_mut(&cloth.mesh) else {
            continue;
        };
        cloth.write_indices(&mut mesh);
        let particles = drawn(cloth.sim.state(), &cloth.drawn, shift);
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

/// The particles a cloth is drawn from: its state's positions, or with a shift the shifted
/// ones the write-back made (`shifted`).
fn drawn<'a>(state: &'a ClothState, shifted: &'a [Vec4], shift: f32) -> &'a [Vec4] {
    if shift == 0.0 {
        &state.positions
    } else {
        shifted
    }
}
