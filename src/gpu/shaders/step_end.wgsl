// Once per step, after its substeps, and when a world is rebuilt.

// The end of a step for every vertex: velocities (free vertices: `run_part` with
// `finish_velocity`, clamped; pins: `finish_pin_velocities`), the NaN guard
// (`ClothState::is_finite`: the cloth's status flags it, the host resets the cloth as the CPU
// does), and the self-collision hash emptied for the next step.
@compute @workgroup_size(64)
fn step_end(@builtin(global_invocation_id) id: vec3<u32>) {
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
// (`tear::overstretched_edges`); the host reads the state back and tears on the CPU, which
// rebuilds the topology and uploads it again. The tearing cloths' edges: (a, b, rest bits,
// cloth), global vertices.
@compute @workgroup_size(64)
fn tear_check(@builtin(global_invocation_id) id: vec3<u32>) {
    let e = id.x;
    if e >= P.edges {
        return;
    }
    let at = P.edges_at + 4u * e;
    let c = topo[at + 3u];
    if !cloth_active(c) {
        return;
    }
    let cl = cloth_of(c);
    let rest = bitcast<f32>(topo[at + 2u]);
    let d = state[topo[at]].xyz - state[topo[at + 1u]].xyz;
    if rest > 0.0 && cl.tear > 1.0 && length(d) > cl.tear * rest {
        state[P.status_at + cl.status].y = 1.0;
    }
}

// After a rebuild, for a cloth that goes on from an earlier world (its vertices `L.first`,
// `L.count` of them): its earlier positions were copied into the substep-start region; it
// takes them with this world's inverse masses (its pins).
@compute @workgroup_size(64)
fn carry(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= L.count {
        return;
    }
    let i = L.first + id.x;
    state[i] = vec4<f32>(state[P.prev_at + i].xyz, state[i].w);
}
