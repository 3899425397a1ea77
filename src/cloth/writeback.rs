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

use bevy::math::Affine3A;
use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use super::{ClothSim, ClothSmoothing, ClothSteppedElsewhere};
use crate::foundation::{ClothSchedule, ClothWorkers};
use crate::solver::ClothState;
use crate::solver::parallel::{Parallel, map_chunks};

/// A cloth's vertices in its entity's local space, as the write-back last computed them
/// (working space, kept between frames so that no frame allocates).
#[derive(Debug, Default)]
pub(super) struct LocalVertices {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    tangents: Vec<[f32; 4]>,
}

/// A moved cloth this frame's write-back draws anew.
struct Moved<'a> {
    cloth: &'a mut ClothSim,
    affine: Affine3A,
    shift: f32,
    /// Whether its vertices were placed in the entity's space: a zero scale cannot be
    /// inverted, and the mesh then keeps its last shape rather than take non-finite positions.
    placed: bool,
}

/// Copies the moved cloths' state into their meshes (torn triangles leave the index buffer,
/// kept in the mesh's own index format; the vertex buffer keeps its size). Cloths stepped
/// elsewhere write their own mesh. The normals, tangents and local-space vertices of the
/// cloths are computed in parallel with each other on [`ClothWorkers`] (each cloth's the same
/// whatever the threads), then copied into the meshes one after another.
pub(super) fn write_back(
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut cloths: Query<
        (&mut ClothSim, &GlobalTransform, Option<&ClothSmoothing>),
        Without<ClothSteppedElsewhere>,
    >,
    schedule: Option<Res<ClothSchedule>>,
    fixed: Option<Res<Time<Fixed>>>,
    workers: Option<Res<ClothWorkers>>,
) {
    let Some(meshes) = meshes.as_deref_mut() else {
        return;
    };
    let overstep = ClothSchedule::overstep(schedule.as_deref(), fixed.as_deref());
    let mut moved: Vec<Moved<'_>> = Vec::new();
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
        moved.push(Moved {
            cloth,
            affine: gt.affine(),
            shift,
            placed: false,
        });
    }
    let par = ClothWorkers::or_serial(workers.as_deref());
    let alone = moved.len() == 1;
    par.for_each_mut(&mut moved, |m| {
        m.placed = shade(m.cloth, m.affine, m.shift, par, alone);
    });
    for Moved { cloth, placed, .. } in moved {
        let Some(mut mesh) = meshes.get_mut(&cloth.mesh) else {
            continue;
        };
        cloth.write_indices(&mut mesh);
        if !placed {
            continue;
        }
        let local = &cloth.local;
        if let Ok(VertexAttributeValues::Float32x3(out)) =
            mesh.try_attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            copy_into(out, &local.positions);
        }
        if let Ok(VertexAttributeValues::Float32x3(out)) =
            mesh.try_attribute_mut(Mesh::ATTRIBUTE_NORMAL)
        {
            copy_into(out, &local.normals);
        }
        if !local.tangents.is_empty()
            && let Ok(VertexAttributeValues::Float32x4(out)) =
                mesh.try_attribute_mut(Mesh::ATTRIBUTE_TANGENT)
        {
            copy_into(out, &local.tangents);
        }
    }
}

/// `from` over the start of `out` (as many as both have).
fn copy_into<T: Copy>(out: &mut [T], from: &[T]) {
    let n = out.len().min(from.len());
    out[..n].copy_from_slice(&from[..n]);
}

/// Recomputes a moved cloth's normals and tangents and its vertices in the local space of an
/// entity placed by `affine`, drawn `shift` seconds along their velocities. The vertices are
/// mapped in chunks on `par` (serially when called from inside another of its regions, as for
/// several cloths at once); a cloth drawn `alone` gathers its normals' and tangents' sums on
/// `par` too, the others scatter them on their own thread (the same values either way).
/// Returns whether the vertices were placed (`affine` could be inverted).
fn shade(
    cloth: &mut ClothSim,
    affine: Affine3A,
    shift: f32,
    par: &impl Parallel,
    alone: bool,
) -> bool {
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
    let particles = drawn(cloth.sim.state(), &cloth.drawn, shift);
    if alone {
        cloth.binding.update_shading_in(particles, par);
    } else {
        cloth.binding.update_shading(particles);
    }
    let to_local = affine.inverse();
    if !to_local.is_finite() {
        return false;
    }
    let local = &mut cloth.local;
    let linear = affine.matrix3;
    let flip = if linear.determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let normal_to_local = linear.transpose();
    let tangent_to_local = to_local.matrix3;
    let welded = cloth.binding.weld().particles();
    map_chunks(par, &mut local.positions, welded.len(), |i| {
        to_local
            .transform_point3(particles[welded[i] as usize].truncate())
            .to_array()
    });
    let shading = cloth.binding.shading();
    let normals = shading.normals();
    map_chunks(par, &mut local.normals, normals.len(), |i| {
        (normal_to_local * (normals[i] * flip))
            .normalize_or(Vec3::Y)
            .to_array()
    });
    let tangents = shading.tangents();
    map_chunks(par, &mut local.tangents, tangents.len(), |i| {
        let t = tangents[i];
        let v = (tangent_to_local * t.truncate()).normalize_or(Vec3::X);
        v.extend(t.w).to_array()
    });
    true
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
