//! One simulation step: integrate, project, collide, update velocities, over substeps.
//!
//! For PBD and XPBD, each of the `S` substeps of length `h = Δt/S` does:
//!
//! 1. pins move to their interpolated targets;
//! 2. every unpinned vertex: `x_prev ← x`, `v ← v/(1 + damping·h) + g·h`, then the air's
//!    velocity change for this substep's velocity against the air's (see
//!    [`air_velocity_change`](crate::solver::air_velocity_change), four vertices at a time), then `x ← x + v·h`;
//!    If bending is solved implicitly (see [`BendingSolve`](crate::solver::BendingSolve)), one banded
//!    solve `(M + h²K) δ = −h²K x̃` follows, and the projections below skip bending;
//! 3. `iterations` times: each part's constraints (in parallel), then the seams' (in
//!    parallel; where neighbouring seams overlap, the even ones, then the odd ones), then the
//!    boundary's;
//! 4. tethers, then self-collision (if on; one pass each). Tethers move only free vertices,
//!    toward copies of the pins' positions, so they run part by part at the start of the
//!    next parallel region (before self-collision in a region of their own; otherwise in
//!    the next substep's first region or the final velocity update), which costs no extra
//!    fork–join;
//! 5. motion constraints (skinned clothing, if any: [`MotionConstraints`]), then colliders
//!    (if any), each part in parallel. Like the tethers, and after them, they run at the
//!    start of the next region over the parts, with this substep's collider poses (nothing
//!    in between moves a free vertex);
//! 6. `v ← (x − x_prev)/h` (done at the start of the next substep, or at the end).
//!
//! Step 2 and the parts' first iteration of step 3 share one parallel region, so a substep
//! with one iteration costs two fork–joins (parts, seams; three where the seams take turns;
//! a cloth of one part has no seams and costs one), with or without colliders, tethers and
//! motion constraints; self-collision adds its own. Everything a scene does not use costs
//! nothing: no collider or motion work without colliders or a skin, no tether or
//! self-collision pass unless set, no air term with [`Aerodynamics::NONE`], no bending pass
//! at zero bending stiffness. Each vertex's area vector is computed once per step, from the
//! positions at its start.
//!
//! Bending is projected in every substep, together with the distances. Solving it less often
//! (every `k` substeps, as an impulse or as a positional correction over the window) was tried
//! and rejected: with stiff bending both inject energy and blow up.

use glam::{Vec3, Vec4, Vec4Swizzles};

use super::lab::{LabScratch, lab_step};
use super::params::SolverParams;
use super::state::ClothState;
use crate::solver::air::{Aerodynamics, air_velocity_changes4, vertex_area_vectors};
use crate::solver::collision::{
    Collider, ContactImpulse, Scales, SelfCollision, SelfCollisionScratch, SubstepPose,
    collide_vertices, find_self_collision_candidates, near_corner_rule, self_collide,
    substep_poses,
};
use crate::solver::constraints::{
    ConstraintBatches, ImplicitBending, Mode, MotionConstraints, Part, Solver, Tethers,
};
use crate::solver::mesh::{BendingModel, Topology};
use crate::solver::parallel::Parallel;

/// What a step includes besides the cloth's own constraints. `StepInput::default()` is a
/// cloth alone in the world.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepInput<'a> {
    /// Shapes the cloth collides with.
    pub colliders: &'a [Collider],
    /// The air's velocity at each vertex (m/s, `w` ignored), e.g. from the wind; empty for
    /// still air.
    pub air_velocities: &'a [Vec4],
    /// Self-collision, if on.
    pub self_collision: Option<SelfCollision>,
    /// Long-range attachments to the pins, if any.
    pub tethers: Option<&'a Tethers>,
    /// Where the skin holds each vertex (skinned clothing), if anywhere: applied to free
    /// vertices after self-collision, before the colliders, every substep.
    pub motion: MotionConstraints<'a>,
}

/// Scratch memory a step reuses (no allocation per step after the first), and what a step
/// reports back.
#[derive(Clone, Debug, Default)]
pub struct StepScratch {
    pin_start: Vec<Vec3>,
    lab: LabScratch,
    poses: Vec<SubstepPose>,
    part_impulses: Vec<Vec<ContactImpulse>>,
    impulses: Vec<ContactImpulse>,
    self_collision: SelfCollisionScratch,
    areas: Vec<Vec4>,
    /// Where the tethers' pins were at the end of the substep whose tethers are due.
    anchors: Vec<Vec4>,
    pub(crate) implicit: ImplicitBending,
}

impl StepScratch {
    /// Impulse the cloth gave each collider during the last step, in the order of
    /// [`StepInput::colliders`].
    #[must_use]
    pub fn impulses(&self) -> &[ContactImpulse] {
        &self.impulses
    }
}

/// A part's constraints and its slice of the vertex arrays.
struct Work<'a> {
    part: &'a mut Part,
    pos: &'a mut [Vec4],
    prev: &'a mut [Vec4],
    vel: &'a mut [Vec4],
    /// Air velocity per vertex (empty: still air).
    air: &'a [Vec4],
    /// Area vector per vertex (empty: no air pass).
    area: &'a [Vec4],
    impulses: &'a mut Vec<ContactImpulse>,
}

fn split<'a>(
    parts: &'a mut [Part],
    mut pos: &'a mut [Vec4],
    mut prev: &'a mut [Vec4],
    mut vel: &'a mut [Vec4],
    mut air: &'a [Vec4],
    mut area: &'a [Vec4],
    impulses: &'a mut [Vec<ContactImpulse>],
) -> Vec<Work<'a>> {
    let mut out = Vec::with_capacity(parts.len());
    for (part, impulses) in parts.iter_mut().zip(impulses) {
        let n = part.range.len();
        let (p, rest_p) = pos.split_at_mut(n);
        let (q, rest_q) = prev.split_at_mut(n);
        let (v, rest_v) = vel.split_at_mut(n);
        let (a, rest_a) = air.split_at(n.min(air.len()));
        let (ar, rest_ar) = area.split_at(n.min(area.len()));
        pos = rest_p;
        prev = rest_q;
        vel = rest_v;
        air = rest_a;
        area = rest_ar;
        out.push(Work {
            part,
            pos: p,
            prev: q,
            vel: v,
            air: a,
            area: ar,
            impulses,
        });
    }
    out
}

/// Each seam of one list with the positions of its vertex range (the ranges are disjoint
/// and in order).
fn split_seams<'a>(
    seams: &'a mut [Part],
    mut pos: &'a mut [Vec4],
) -> Vec<(&'a mut Part, &'a mut [Vec4])> {
    let mut out = Vec::with_capacity(seams.len());
    let mut offset = 0;
    for seam in seams {
        let r = seam.range.clone();
        let (_, rest) = core::mem::take(&mut pos).split_at_mut(r.start - offset);
        let (p, rest) = rest.split_at_mut(r.len());
        pos = rest;
        offset = r.end;
        out.push((seam, p));
    }
    out
}

/// What a parallel region does to each part, in this order.
#[derive(Clone, Copy, Default)]
struct Phase {
    /// Pull over-stretched vertices back to their pins (the previous substep's tethers: they
    /// run first in the next region over the parts instead of in a region of their own).
    tethers: bool,
    /// The end of substep `Some(s)` (the previous one, like the tethers): bring free vertices
    /// within their motion constraints, if any, then push them out of the colliders posed
    /// for that substep, if any.
    end: Option<u32>,
    /// `v ← (x − x_prev)/h` for unpinned vertices.
    finish_velocity: bool,
    /// Integrate (and zero λ).
    integrate: bool,
    /// Project the part's constraints once.
    project: bool,
}

#[derive(Clone, Copy)]
struct Consts {
    h: f32,
    inv_h: f32,
    max_speed: f32,
    damp: f32,
    gravity: Vec3,
    air: Aerodynamics,
    mode: Mode,
    bending: bool,
    /// XPBD with several iterations: multipliers carry over between iterations.
    accumulate: bool,
    substeps: u32,
    /// Motion constraints apply to this cloth.
    motion: bool,
}

/// `v` shortened to at most `max` (w stays 0).
#[inline]
pub(super) fn clamp_speed(v: Vec4, max: f32) -> Vec4 {
    let s2 = v.length_squared();
    if s2 > max * max {
        v * (max / s2.sqrt())
    } else {
        v
    }
}

/// A pinned vertex's velocity over the substep just done (pins are moved, not integrated).
fn finish_pin_velocities(state: &mut ClothState, inv_h: f32) {
    for pin in &state.pins {
        let i = pin.vertex as usize;
        state.velocities[i] =
            ((state.positions[i].xyz() - state.prev[i].xyz()) * inv_h).extend(0.0);
    }
}

fn run_part(
    w: &mut Work<'_>,
    phase: Phase,
    c: Consts,
    colliders: &[Collider],
    poses: &[SubstepPose],
    tethers: Option<(&Tethers, &[Vec4])>,
    motion: &MotionConstraints<'_>,
) {
    if phase.tethers
        && let Some((t, anchors)) = tethers
    {
        t.project_range(w.part.range.clone(), w.pos, anchors);
    }
    if let Some(s) = phase.end {
        if c.motion {
            let first = w.part.range.start;
            for (k, x) in w.pos.iter_mut().enumerate() {
                if x.w > 0.0 {
                    motion.constrain(first + k, x, s, c.substeps);
                }
            }
        }
        collide_vertices(w.pos, w.prev, colliders, poses, w.impulses);
    }
    if phase.finish_velocity {
        for ((v, x), p) in w.vel.iter_mut().zip(w.pos.iter()).zip(w.prev.iter()) {
            // Unpinned vertices have the same inverse mass in x and x_prev: w − w = 0.
            if x.w > 0.0 {
                *v = clamp_speed((*x - *p) * c.inv_h, c.max_speed);
            }
        }
    }
    if phase.integrate {
        let gh = c.gravity.extend(0.0) * c.h;
        if w.area.is_empty() {
            let vertices = w
                .vel
                .iter_mut()
                .zip(w.pos.iter_mut())
                .zip(w.prev.iter_mut());
            for ((v, x), p) in vertices {
                if x.w > 0.0 {
                    *p = *x;
                    *v = *v * c.damp + gh;
                    *x += *v * c.h;
                }
            }
        } else {
            // Four vertices at a time through the air (each lane the same bits as one vertex
            // alone); the last group's missing lanes are zeros, computed and dropped.
            let n = w.pos.len();
            for first in (0..n).step_by(4) {
                let lanes = (n - first).min(4);
                let at = |k: usize, of: &[Vec4]| of.get(first + k).copied().unwrap_or(Vec4::ZERO);
                let u: [Vec4; 4] = core::array::from_fn(|k| at(k, w.vel) * c.damp + gh);
                let dv = air_velocity_changes4(
                    core::array::from_fn(|k| at(k, w.area).xyz()),
                    core::array::from_fn(|k| u[k].xyz() - at(k, w.air).xyz()),
                    core::array::from_fn(|k| at(k, w.pos).w),
                    c.h,
                    &c.air,
                );
                for (k, (u, dv)) in u.into_iter().zip(dv).enumerate().take(lanes) {
                    let i = first + k;
                    let x = &mut w.pos[i];
                    if x.w > 0.0 {
                        w.prev[i] = *x;
                        let u = u + dv.extend(0.0);
                        w.vel[i] = u;
                        *x += u * c.h;
                    }
                }
            }
        }
        if c.accumulate {
            w.part.reset_lambda();
        }
    }
    if phase.project {
        w.part.project(w.pos, c.mode, c.bending, c.accumulate);
    }
}

/// Advances the cloth by `dt` seconds.
///
/// `batches` must have been built from `topology`, and `params` validated
/// ([`SolverParams::validate`]); a non-positive or non-finite `dt` does nothing. The lab
/// solver reproduces seed 000 and ignores `input`. Impulses on the colliders are left in
/// [`StepScratch::impulses`].
#[expect(
    clippy::too_many_arguments,
    reason = "a step takes all it needs explicitly"
)]
pub fn step(
    state: &mut ClothState,
    topology: &Topology,
    batches: &mut ConstraintBatches,
    params: &SolverParams,
    dt: f32,
    input: StepInput<'_>,
    scratch: &mut StepScratch,
    par: &impl Parallel,
) {
    scratch.impulses.clear();
    scratch
        .impulses
        .resize(input.colliders.len(), ContactImpulse::default());
    if !(dt.is_finite() && dt > 0.0) || state.is_empty() {
        return;
    }
    let substeps = params.substeps.max(1);
    let h = dt / substeps as f32;
    scratch.pin_start.clear();
    scratch.pin_start.extend(state.pin_starts());

    if let Solver::Lab { velocity_keep } = params.solver {
        for s in 0..substeps {
            state.place_pins(&scratch.pin_start, s, substeps);
            for pin in &state.pins {
                state.velocities[pin.vertex as usize] = Vec4::ZERO;
            }
            lab_step(
                state,
                topology.edges(),
                &mut scratch.lab,
                velocity_keep,
                params.gravity,
                h,
                params.iterations.max(1),
            );
            for (v, x) in state.velocities.iter_mut().zip(&state.positions) {
                if x.w > 0.0 {
                    *v = clamp_speed(*v, params.max_speed);
                }
            }
        }
        return;
    }

    // Isometric XPBD bending too stiff for a projection per substep: one implicit solve.
    let rigidity = match params.solver {
        Solver::Xpbd { bending, .. } => 1.0 / bending,
        _ => 0.0,
    };
    let implicit = batches.bending
        && batches.mode_is_xpbd
        && topology.options().effective_bending() == BendingModel::Isometric
        && scratch.implicit.prepare(
            topology,
            &state.positions,
            rigidity,
            h,
            (params.bending_solve, params.gravity.length()),
        );
    let has_motion = input.motion.applies_to(state.len());
    let motion = if has_motion {
        input.motion
    } else {
        MotionConstraints::default()
    };
    let c = Consts {
        h,
        inv_h: 1.0 / h,
        max_speed: params.max_speed,
        damp: 1.0 / (1.0 + params.damping * h),
        gravity: params.gravity,
        air: params.air,
        mode: batches.mode(h),
        bending: batches.bending && !implicit,
        accumulate: batches.mode_is_xpbd && params.iterations > 1,
        substeps,
        motion: has_motion,
    };
    let air_velocities = if input.air_velocities.len() == state.len() {
        input.air_velocities
    } else {
        &[]
    };
    if params.air.is_none() {
        scratch.areas.clear();
    } else {
        vertex_area_vectors(&state.positions, topology.triangles(), &mut scratch.areas);
    }
    if let Some(sc) = input.self_collision {
        find_self_collision_candidates(
            &state.positions,
            &state.velocities,
            topology.rest_positions(),
            topology.triangles(),
            topology.self_collision_scales(),
            sc,
            dt,
            &mut scratch.self_collision,
            par,
        );
    }
    let colliders = input.colliders;
    scratch
        .part_impulses
        .resize(batches.parts.len(), Vec::new());
    for p in &mut scratch.part_impulses {
        p.clear();
        p.resize(colliders.len(), ContactImpulse::default());
    }
    // Tethers built for this cloth's vertices (a stale set, after a tear, waits for its
    // rebuild), and whether the last substep's tethers are still to be applied.
    let tethers = input.tethers.filter(|t| t.vertex_count() == state.len());
    let mut tethers_due = false;
    // The substep whose motion constraints and colliders are still to be applied.
    let mut end_due: Option<u32> = None;
    // Every substep's collider poses, once a step.
    if !colliders.is_empty() {
        substep_poses(colliders, substeps, &mut scratch.poses);
    }
    // One phase over every part, the parts in parallel (with this substep's collider poses
    // and the due tethers' pin copies from `scratch`).
    let run_parts =
        |parts: &mut [Part], state: &mut ClothState, scratch: &mut StepScratch, phase: Phase| {
            let mut work = split(
                parts,
                &mut state.positions,
                &mut state.prev,
                &mut state.velocities,
                air_velocities,
                &scratch.areas,
                &mut scratch.part_impulses,
            );
            // The colliders posed for the substep whose collisions are due.
            let m = colliders.len();
            let poses = phase
                .end
                .map_or(&[][..], |s| &scratch.poses[s as usize * m..][..m]);
            let anchors = &scratch.anchors[..];
            let tethers = tethers.map(|t| (t, anchors));
            par.for_each_mut(&mut work, |w| {
                run_part(w, phase, c, colliders, poses, tethers, &motion);
            });
        };
    for s in 0..substeps {
        // Pins: finish their velocity for the previous substep, then move.
        if s > 0 {
            finish_pin_velocities(state, c.inv_h);
        }
        for pin in &state.pins {
            let i = pin.vertex as usize;
            state.prev[i] = state.positions[i];
        }
        state.place_pins(&scratch.pin_start, s, substeps);

        if implicit {
            let phase = Phase {
                tethers: core::mem::take(&mut tethers_due),
                end: end_due.take(),
                finish_velocity: s > 0,
                integrate: true,
                ..Default::default()
            };
            run_parts(&mut batches.parts, state, scratch, phase);
            scratch.implicit.solve(topology, &mut state.positions, h);
        }
        for it in 0..params.iterations.max(1) {
            let phase = Phase {
                tethers: core::mem::take(&mut tethers_due),
                end: end_due.take(),
                finish_velocity: it == 0 && s > 0 && !implicit,
                integrate: it == 0 && !implicit,
                project: true,
            };
            run_parts(&mut batches.parts, state, scratch, phase);
            // Then what straddles parts: the seams in parallel (all, or even then odd), the
            // rest.
            for seams in &mut batches.seams {
                let mut work = split_seams(seams, &mut state.positions);
                par.for_each_mut(&mut work, |(seam, pos)| {
                    if it == 0 && c.accumulate {
                        seam.reset_lambda();
                    }
                    seam.project(pos, c.mode, c.bending, c.accumulate);
                });
            }
            if it == 0 && c.accumulate {
                batches.boundary.reset_lambda();
            }
            batches
                .boundary
                .project(&mut state.positions, c.mode, c.bending, c.accumulate);
        }
        // Tethers: where the pins are now, applied first in the next region over the parts
        // (nothing between here and there moves a free vertex or a pin).
        if let Some(t) = tethers {
            scratch.anchors.clear();
            scratch
                .anchors
                .extend(t.anchors().iter().map(|&p| state.positions[p as usize]));
            tethers_due = true;
        }
        if let Some(sc) = input.self_collision {
            if core::mem::take(&mut tethers_due) {
                let phase = Phase {
                    tethers: true,
                    ..Default::default()
                };
                run_parts(&mut batches.parts, state, scratch, phase);
            }
            self_collide(
                &mut state.positions,
                &mut state.prev,
                topology.triangles(),
                Scales {
                    vertices: topology.self_collision_scales(),
                    triangles: topology.self_collision_triangle_scales(),
                    rest: topology.rest_positions(),
                    near_corner: near_corner_rule(topology),
                },
                sc,
                &mut scratch.self_collision,
                par,
            );
        }
        // Motion constraints and colliders: applied first in the next region over the parts
        // (nothing between here and there moves a free vertex), with this substep's poses.
        if !colliders.is_empty() || c.motion {
            end_due = Some(s);
        }
    }
    let phase = Phase {
        tethers: tethers_due,
        end: end_due,
        finish_velocity: true,
        ..Default::default()
    };
    run_parts(&mut batches.parts, state, scratch, phase);
    finish_pin_velocities(state, c.inv_h);
    // Momentum per collider: the per-part sums of −m·Δx, over h.
    for part in &scratch.part_impulses {
        for (total, p) in scratch.impulses.iter_mut().zip(part) {
            total.linear += p.linear * c.inv_h;
            total.angular += p.angular * c.inv_h;
        }
    }
}
