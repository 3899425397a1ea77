// Once per step, after its substeps, and when a world is rebuilt.

// The end of a step for every vertex: velocities (free vertices: `run_part` with
// `finish_velocity`, clamped; pins: `finish_pin_velocities`), the frame's largest speed
// (`note_speed`), the NaN guard
// (`ClothState::is_finite`: the cloth's status flags it, the host resets the cloth as the CPU
// does), and the self-collision hash emptied for the next step.
@compute @workgroup_size(64)
fn step_end(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let i = id.x;
    if i >= P.n {
        return;
    }
    let c = vertex_cloth(i);
    if !cloth_active(c) {
        return;
    }
    let cl = cloth_of(c);
    let x = state[i];
    let prev = state[P.prev_at + i];
    var v = state[P.vel_at + i];
    if x.w > 0.0 {
        v = clamp_speed((x - prev) * P.inv_h, cl.max_speed);
        state[P.vel_at + i] = v;
        note_speed(c, cl.flags, v.xyz);
    } else if vertex_pin(i) != NO_PIN {
        v = vec4<f32>((x.xyz - prev.xyz) * P.inv_h, 0.0);
        state[P.vel_at + i] = v;
    }
    if !(finite3(x.xyz) && finite(x.w) && finite3(v.xyz) && finite(v.w)) {
        state[P.status_at + cl.status].x = 1.0;
    }
    if (cl.flags & FLAG_SC) != 0u {
        let local = i - cl.vbase;
        atomicStore(&scratch[P.head_at + cl.head_base + 2u * local], 0u);
        atomicStore(&scratch[P.head_at + cl.head_base + 2u * local + 1u], 0u);
        if local == 0u {
            atomicStore(&scratch[P.speed_at + c], 0u);
        }
    }
}

// End of a step: flags a cloth with an edge stretched past its tear threshold
// (`tear::overstretched_edges`, over the edges not torn yet), and the edge torn: its distance
// constraint holds nothing from the next step on and its triangles are dead, as the CPU's
// tear (`Topology::without_edges`) would have them; `tear_release` then lets go of the edges
// left without a triangle. The host reads the state back and tears on the CPU, which
// rebuilds the topology and uploads it again. The tearing cloths' edges: (a, b, rest bits,
// constraint slot), global vertices.
@compute @workgroup_size(64)
fn tear_check(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let e = id.x;
    if e >= P.edges {
        return;
    }
    let at = P.edges_at + 4u * e;
    let c = vertex_cloth(topo[at]);
    if !cloth_active(c) {
        return;
    }
    let slot = topo[at + 3u];
    if slot != NO_PIN && atomicLoad(&scratch[P.torn_at + slot]) != 0u {
        return;
    }
    let cl = cloth_of(c);
    let rest = bitcast<f32>(topo[at + 2u]);
    let d = state[topo[at]].xyz - state[topo[at + 1u]].xyz;
    if rest > 0.0 && cl.tear > 1.0 && length(d) > cl.tear * rest {
        state[P.status_at + cl.status].y = 1.0;
        if (cl.flags & FLAG_CLOSED) != 0u {
            atomicStore(&scratch[P.opened_at + c], 1u);
        }
        if slot != NO_PIN {
            atomicStore(&scratch[P.torn_at + slot], 1u);
            let end = topo[P.edge_tris_at + e + 1u];
            for (var k = topo[P.edge_tris_at + e]; k < end; k++) {
                atomicStore(&scratch[P.dead_at + topo[k]], 1u);
            }
        }
    }
}

// After `tear_check`: an edge whose triangles all died holds nothing from the next step on
// (the CPU's rebuilt topology keeps no edge without a triangle).
@compute @workgroup_size(64)
fn tear_release(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let e = id.x;
    if e >= P.edges {
        return;
    }
    let at = P.edges_at + 4u * e;
    let slot = topo[at + 3u];
    if slot == NO_PIN || !cloth_active(vertex_cloth(topo[at])) {
        return;
    }
    if atomicLoad(&scratch[P.torn_at + slot]) != 0u {
        return;
    }
    let first = topo[P.edge_tris_at + e];
    let end = topo[P.edge_tris_at + e + 1u];
    if first == end {
        return;
    }
    for (var k = first; k < end; k++) {
        if atomicLoad(&scratch[P.dead_at + topo[k]]) == 0u {
            return;
        }
    }
    atomicStore(&scratch[P.torn_at + slot], 2u);
}

// After a rebuild, for a cloth that goes on from an earlier world (its vertices `L.first`,
// `L.count` of them): its earlier positions were copied into the substep-start region; it
// takes them with this world's inverse masses (its pins).
@compute @workgroup_size(64)
fn carry(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    if id.x >= L.count {
        return;
    }
    let i = L.first + id.x;
    state[i] = vec4<f32>(state[P.prev_at + i].xyz, state[i].w);
}

// A change of solver, substeps or iterations *settles* (CPU twin: `Simulation::step_in` after
// `Simulation::set_params`): for at least `SETTLE_STEPS` steps, then while the cloth's largest
// strain still shrinks by more than 0.01 a step, up to `SETTLE_MAX`, no free vertex ends a
// step faster than it was when the change was made, plus `SETTLE_SPEED` (m/s). The cloth's
// status counts the steps left (z) and keeps the last strain (w). Dispatched in the steps
// after a world is built with a settling cloth: `settle_begin` after `step_begin`,
// `settle_end` and `settle_update` after `step_end` (or `lab_guard`).
const SETTLE_MAX: f32 = 60.0;
const SETTLE_STEPS: u32 = 8u;
const SETTLE_SPEED: f32 = 0.25;

fn settling(c: u32) -> f32 {
    return state[P.status_at + cloth_of(c).status].z;
}

// The first settling step keeps each vertex's speed at its start.
@compute @workgroup_size(64)
fn settle_begin(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let i = id.x;
    if i >= P.n {
        return;
    }
    let c = vertex_cloth(i);
    if cloth_active(c) && settling(c) == SETTLE_MAX {
        atomicStore(&scratch[P.settle_speed_at + i], bitcast<u32>(length(state[P.vel_at + i])));
    }
}

// A settling step's end: invocation `k` limits vertex `k`'s speed (free vertices) and takes
// the strain of settle edge `k` into its cloth's largest (`metrics::edge_strain`).
@compute @workgroup_size(64)
fn settle_end(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let k = id.x;
    if k < P.n {
        let c = vertex_cloth(k);
        if cloth_active(c) && settling(c) > 0.0 && state[k].w > 0.0 {
            let v = state[P.vel_at + k];
            let limit = bitcast<f32>(atomicLoad(&scratch[P.settle_speed_at + k])) + SETTLE_SPEED;
            let speed = length(v);
            if speed > limit {
                state[P.vel_at + k] = v * (limit / speed);
            }
        }
    }
    if k < P.settle_edges {
        let at = P.settle_edges_at + 3u * k;
        let a = topo[at];
        let c = vertex_cloth(a);
        let rest = bitcast<f32>(topo[at + 2u]);
        if cloth_active(c) && settling(c) > 0.0 && rest > 1.1920929e-7 {
            let len = distance(state[a].xyz, state[topo[at + 1u]].xyz);
            let strain = abs(len - rest) / rest;
            if finite(strain) {
                atomicMax(&scratch[P.settle_strain_at + c], bitcast<u32>(strain));
            }
        }
    }
}

// After `settle_end`, one invocation per cloth: the steps left and the strain kept.
@compute @workgroup_size(64)
fn settle_update(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let c = id.x;
    if c >= P.cloths || !cloth_active(c) {
        return;
    }
    let at = P.status_at + cloth_of(c).status;
    let left = state[at].z;
    if left <= 0.0 {
        return;
    }
    let strain = bitcast<f32>(atomicExchange(&scratch[P.settle_strain_at + c], 0u));
    let s = u32(left);
    var next = 0u;
    if s > u32(SETTLE_MAX) - SETTLE_STEPS + 1u {
        next = s - 1u;
    } else if strain < state[at].w - 0.01 {
        next = max(s - 1u, 1u);
    }
    state[at].z = f32(next);
    state[at].w = strain;
}
