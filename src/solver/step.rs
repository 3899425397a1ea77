//! One simulation step: integrate, project, update velocities, over substeps.
//!
//! For PBD and XPBD, each of the `S` substeps of length `h = Δt/S` does:
//!
//! 1. pins move to their interpolated targets;
//! 2. every unpinned vertex: `x_prev ← x`, `v ← v/(1 + damping·h) + g·h`, `x ← x + v·h`;
//! 3. `iterations` times: each part's constraints (in parallel), then the boundary's;
//! 4. `v ← (x − x_prev)/h` (done at the start of the next substep, or at the end).
//!
//! Step 2 and the first iteration of step 3 share one parallel region, so a substep with one
//! iteration costs one fork–join.
//!
//! Bending is projected in every substep, together with the distances. Solving it less often
//! (every `k` substeps, as an impulse or as a positional correction over the window) was tried
//! and rejected: with stiff bending both inject energy and blow up.

use glam::{Vec3, Vec4, Vec4Swizzles};

use super::batches::{ConstraintBatches, Mode, Part};
use super::lab::{LabScratch, lab_step};
use super::parallel::Parallel;
use super::params::{Solver, SolverParams};
use super::state::ClothState;
use super::topology::Topology;

/// Scratch memory a step reuses (no allocation per step after the first).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepScratch {
    pin_start: Vec<Vec3>,
    lab: LabScratch,
}

/// A part's constraints and its slice of the vertex arrays.
struct Work<'a> {
    part: &'a mut Part,
    pos: &'a mut [Vec4],
    prev: &'a mut [Vec4],
    vel: &'a mut [Vec4],
}

fn split<'a>(
    parts: &'a mut [Part],
    mut pos: &'a mut [Vec4],
    mut prev: &'a mut [Vec4],
    mut vel: &'a mut [Vec4],
) -> Vec<Work<'a>> {
    let mut out = Vec::with_capacity(parts.len());
    for part in parts {
        let n = part.range.len();
        let (p, rest_p) = pos.split_at_mut(n);
        let (q, rest_q) = prev.split_at_mut(n);
        let (v, rest_v) = vel.split_at_mut(n);
        pos = rest_p;
        prev = rest_q;
        vel = rest_v;
        out.push(Work {
            part,
            pos: p,
            prev: q,
            vel: v,
        });
    }
    out
}

/// What a parallel region does to each part, in this order.
#[derive(Clone, Copy, Default)]
struct Phase {
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
    damp: f32,
    gravity: Vec3,
    mode: Mode,
    bending: bool,
    /// XPBD with several iterations: multipliers carry over between iterations.
    accumulate: bool,
}

fn run_part(w: &mut Work<'_>, phase: Phase, c: Consts) {
    if phase.finish_velocity {
        for ((v, x), p) in w.vel.iter_mut().zip(w.pos.iter()).zip(w.prev.iter()) {
            // Unpinned vertices have the same inverse mass in x and x_prev: w − w = 0.
            if x.w > 0.0 {
                *v = (*x - *p) * c.inv_h;
            }
        }
    }
    if phase.integrate {
        let gh = c.gravity.extend(0.0) * c.h;
        for ((v, x), p) in w
            .vel
            .iter_mut()
            .zip(w.pos.iter_mut())
            .zip(w.prev.iter_mut())
        {
            if x.w > 0.0 {
                *p = *x;
                *v = *v * c.damp + gh;
                *x += *v * c.h;
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
/// ([`SolverParams::validate`]); a non-positive or non-finite `dt` does nothing.
pub fn step(
    state: &mut ClothState,
    topology: &Topology,
    batches: &mut ConstraintBatches,
    params: &SolverParams,
    dt: f32,
    scratch: &mut StepScratch,
    par: &impl Parallel,
) {
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
        }
        return;
    }

    let c = Consts {
        h,
        inv_h: 1.0 / h,
        damp: 1.0 / (1.0 + params.damping * h),
        gravity: params.gravity,
        mode: batches.mode(h),
        bending: batches.bending,
        accumulate: batches.mode_is_xpbd && params.iterations > 1,
    };
    for s in 0..substeps {
        // Pins: finish their velocity for the previous substep, then move.
        for pin in &state.pins {
            let i = pin.vertex as usize;
            if s > 0 {
                state.velocities[i] =
                    ((state.positions[i].xyz() - state.prev[i].xyz()) * c.inv_h).extend(0.0);
            }
            state.prev[i] = state.positions[i];
        }
        state.place_pins(&scratch.pin_start, s, substeps);

        for it in 0..params.iterations.max(1) {
            let phase = Phase {
                finish_velocity: it == 0 && s > 0,
                integrate: it == 0,
                project: true,
            };
            let mut work = split(
                &mut batches.parts,
                &mut state.positions,
                &mut state.prev,
                &mut state.velocities,
            );
            par.for_each_mut(&mut work, |w| run_part(w, phase, c));
            if it == 0 && c.accumulate {
                batches.boundary.reset_lambda();
            }
            batches
                .boundary
                .project(&mut state.positions, c.mode, c.bending, c.accumulate);
        }
    }
    let phase = Phase {
        finish_velocity: true,
        ..Default::default()
    };
    let mut work = split(
        &mut batches.parts,
        &mut state.positions,
        &mut state.prev,
        &mut state.velocities,
    );
    par.for_each_mut(&mut work, |w| run_part(w, phase, c));
    for pin in &state.pins {
        let i = pin.vertex as usize;
        state.velocities[i] =
            ((state.positions[i].xyz() - state.prev[i].xyz()) * c.inv_h).extend(0.0);
    }
}
