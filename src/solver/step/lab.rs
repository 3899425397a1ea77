//! The lab solver of seed 000: Jacobi averaging of edge projections.
//!
//! Each step: `v ← velocity_keep·v`, `v ← v + g·Δt`, `x ← x + v·Δt` for unpinned vertices;
//! then, per iteration, every edge `(i, j)` with rest length `L` adds
//! `½(x_i + x_j + L·(x_i − x_j)/|x_i − x_j|)` to `Σx_i` and `½(x_i + x_j − L·(x_i − x_j)/|x_i − x_j|)`
//! to `Σx_j` (and one to each count), and every unpinned vertex moves to
//! `x_new = (0.2·x + Σx)/(0.2 + n)` with `v ← v + (x_new − x)/Δt`.

use glam::{Vec3, Vec4Swizzles};

use super::state::ClothState;
use crate::solver::constraints::LAB_WEIGHT;
use crate::solver::mesh::Edge;

/// Scratch arrays reused across steps.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LabScratch {
    sum_x: Vec<Vec3>,
    sum_n: Vec<u32>,
}

/// One lab step of `dt` seconds with `iterations` Jacobi iterations.
pub fn lab_step(
    state: &mut ClothState,
    edges: &[Edge],
    scratch: &mut LabScratch,
    velocity_keep: f32,
    gravity: Vec3,
    dt: f32,
    iterations: u32,
) {
    let n = state.len();
    for (x, v) in state.positions.iter_mut().zip(&mut state.velocities) {
        if x.w == 0.0 {
            continue;
        }
        let mut vel = v.xyz() * velocity_keep;
        vel += gravity * dt;
        *v = vel.extend(0.0);
        let p = x.xyz() + vel * dt;
        *x = p.extend(x.w);
    }
    scratch.sum_x.resize(n, Vec3::ZERO);
    scratch.sum_n.resize(n, 0);
    for _ in 0..iterations {
        scratch.sum_x.fill(Vec3::ZERO);
        scratch.sum_n.fill(0);
        for e in edges {
            let (i, j) = (e.v[0] as usize, e.v[1] as usize);
            let (xi, xj) = (state.positions[i].xyz(), state.positions[j].xyz());
            let d = xi - xj;
            let len = d.length();
            let dir = if len > 0.0 { d / len } else { Vec3::ZERO };
            scratch.sum_x[i] += 0.5 * (xi + xj + e.rest * dir);
            scratch.sum_n[i] += 1;
            scratch.sum_x[j] += 0.5 * (xi + xj - e.rest * dir);
            scratch.sum_n[j] += 1;
        }
        for i in 0..n {
            let x = state.positions[i];
            if x.w == 0.0 {
                continue;
            }
            let new =
                (LAB_WEIGHT * x.xyz() + scratch.sum_x[i]) / (LAB_WEIGHT + scratch.sum_n[i] as f32);
            state.velocities[i] += ((new - x.xyz()) / dt).extend(0.0);
            state.positions[i] = new.extend(x.w);
        }
    }
    for (p, x) in state.prev.iter_mut().zip(&state.positions) {
        *p = *x;
    }
}
