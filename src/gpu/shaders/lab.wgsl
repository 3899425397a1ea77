// The lab solver of seed 000 (`lab::lab_step`, one per substep): keep a share of the
// velocity, add gravity, move; then per iteration every vertex gathers its edges' projections
// (in edge order, as the CPU sums them) and moves to their average with its own position. A
// world of lab cloths runs these instead of `solve` and `contact` (the lab solver has no air,
// colliders, tethers or self-collision, as on the CPU).

// Pins to their place at this substep with no velocity; free vertices keep a share of their
// velocity (the cloth's `damp`) and fall.
@compute @workgroup_size(64)
fn lab_begin(
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
    let p = vertex_pin(i);
    if p != NO_PIN {
        let a = state[P.pin_start_at + p].xyz;
        let target_pos = frame[S.pin_at + p].xyz;
        state[i] = vec4<f32>(a * (1.0 - S.t) + target_pos * S.t, 0.0);
        state[P.vel_at + i] = vec4<f32>(0.0);
        return;
    }
    let x = state[i];
    if x.w == 0.0 {
        return;
    }
    let cl = cloth_of(c);
    let v = state[P.vel_at + i].xyz * cl.damp + cl.gravity_h;
    state[P.vel_at + i] = vec4<f32>(v, 0.0);
    state[i] = vec4<f32>(x.xyz + v * P.h, x.w);
}

// The averaged position, into the substep-start region (free during the lab step).
@compute @workgroup_size(64)
fn lab_gather(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let i = id.x;
    if i >= P.n || !cloth_active(vertex_cloth(i)) {
        return;
    }
    let x = state[i];
    let b = P.lab_at;
    var sum = vec3<f32>(0.0);
    var count = 0.0;
    for (var k = topo[b + i]; k < topo[b + i + 1u]; k += 2u) {
        let xi = x.xyz;
        let xj = state[topo[k]].xyz;
        let rest = bitcast<f32>(topo[k + 1u]);
        let d = xi - xj;
        let len = length(d);
        var dir = vec3<f32>(0.0);
        if len > 0.0 {
            dir = d / len;
        }
        sum += 0.5 * (xi + xj + rest * dir);
        count += 1.0;
    }
    let weight = 0.2;
    state[P.prev_at + i] = vec4<f32>((weight * x.xyz + sum) / (weight + count), x.w);
}

@compute @workgroup_size(64)
fn lab_apply(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let i = id.x;
    if i >= P.n || !cloth_active(vertex_cloth(i)) {
        return;
    }
    let x = state[i];
    if x.w == 0.0 {
        return;
    }
    let moved = state[P.prev_at + i].xyz;
    state[P.vel_at + i] += vec4<f32>((moved - x.xyz) / P.h, 0.0);
    state[i] = vec4<f32>(moved, x.w);
}

// End of a lab substep: free vertices' speeds clamped, substep starts = positions.
@compute @workgroup_size(64)
fn lab_finish(
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
    let x = state[i];
    if x.w > 0.0 {
        state[P.vel_at + i] = clamp_speed(state[P.vel_at + i], cloth_of(c).max_speed);
    }
    state[P.prev_at + i] = x;
}

// End of a lab step: the frame's largest speed and the NaN guard (the lab step keeps its
// own velocities).
@compute @workgroup_size(64)
fn lab_guard(
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
    let x = state[i];
    let v = state[P.vel_at + i];
    if x.w > 0.0 {
        note_speed(c, cloth_of(c).flags, v.xyz);
    }
    if !(finite3(x.xyz) && finite(x.w) && finite3(v.xyz) && finite(v.w)) {
        state[P.status_at + cloth_of(c).status].x = 1.0;
    }
}
