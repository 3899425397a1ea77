// Once per step, before its substeps.

// The teleport rule at the start of a step, for the cloths that teleport in it: every vertex
// moves by the cloth's offset and the pins land on their targets at rest (CPU twin:
// `ClothState::teleport`). Dispatched only in steps where a cloth teleports.
@compute @workgroup_size(64)
fn teleport(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let c = vertex_cloth(i);
    let rec = frame[S.cloth_step_at + c];
    if rec.w < 2.5 {
        return;
    }
    let p = vertex_pin(i);
    if p != NO_PIN {
        let at = vec4<f32>(frame[S.pin_at + p].xyz, 0.0);
        state[i] = at;
        state[P.prev_at + i] = at;
        state[P.vel_at + i] = vec4<f32>(0.0);
    } else {
        let o = vec4<f32>(rec.xyz, 0.0);
        state[i] += o;
        state[P.prev_at + i] += o;
    }
}

// `air::vertex_area_vectors` for vertex `i`, over its triangles in triangle order (the CPU's
// summation order).
fn area_vector(i: u32) -> vec3<f32> {
    var acc = vec3<f32>(0.0);
    for (var k = topo[P.tri_offsets_at + i]; k < topo[P.tri_offsets_at + i + 1u]; k++) {
        let t = P.tri_at + 3u * topo[k];
        let a = state[topo[t]].xyz;
        let b = state[topo[t + 1u]].xyz;
        let c = state[topo[t + 2u]].xyz;
        let third = cross(b - a, c - a) / 6.0;
        if finite3(third) {
            acc += third;
        }
    }
    return acc;
}

// `self_collision::cell_of`
fn sc_cell(p: vec3<f32>, inv: f32) -> vec3<i32> {
    return vec3<i32>(floor(p * inv));
}

// `self_collision::hash`, over a cloth's `size` buckets.
fn sc_hash(c: vec3<i32>, size: u32) -> u32 {
    let h = (c.x * 92837111) ^ (c.y * 689287499) ^ (c.z * 283923481);
    return bitcast<u32>(select(h, -h, h < 0)) % size;
}

// Cells of the self-collision hash: 2.5 thicknesses, the farthest any query reaches
// (`self_collision::reach_and_skip`), so the hash needs no step-wide maximum first.
fn sc_cell_size(cl: Cloth) -> f32 {
    return 2.5 * cl.sc_thickness;
}

// The start of a step for every vertex: where pins start from (`ClothState::pin_starts`),
// the area vectors (air), and with self-collision the fastest speed of the cloth and the
// vertex put into its cloth's hash (a bucket list: heads hold vertex + 1, 0 ends a list).
// Nothing here writes a position, so every vertex reads its neighbours as the step found them.
@compute @workgroup_size(64)
fn step_begin(@builtin(global_invocation_id) id: vec3<u32>) {
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
    let p = vertex_pin(i);
    if p != NO_PIN {
        state[P.pin_start_at + p] = x;
    }
    if (cl.flags & FLAG_AIR) != 0u {
        state[P.area_at + i] = vec4<f32>(area_vector(i), 0.0);
    }
    if (cl.flags & FLAG_SC) != 0u {
        let v = state[P.vel_at + i].xyz;
        let s2 = dot(v, v);
        if finite(s2) {
            atomicMax(&scratch[P.speed_at + c], bitcast<u32>(s2));
        }
        if finite3(x.xyz) {
            let size = 2u * cl.n;
            let bucket = sc_hash(sc_cell(x.xyz, 1.0 / sc_cell_size(cl)), size);
            let next = atomicExchange(&scratch[P.head_at + cl.head_base + bucket], i + 1u);
            atomicStore(&scratch[P.next_at + i], next);
        }
    }
}

// Start of a frame: the impulse slots start from zero.
@compute @workgroup_size(64)
fn impulse_clear(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < P.impulse_slots {
        atomicStore(&scratch[P.impulse_at + id.x], 0u);
    }
}
