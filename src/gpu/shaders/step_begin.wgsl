// Once per step, before its substeps.

// `m·p` column by column, in the order of the CPU twin (`solver::Carry`).
fn carried(at: u32, p: vec3<f32>) -> vec3<f32> {
    return frame[at + 1u].xyz * p.x + frame[at + 2u].xyz * p.y + frame[at + 3u].xyz * p.z;
}

// The start of a step for the cloths carried or teleporting in it. Carried (`ClothInertia`,
// or a change of its entity's scale, flag 16): every vertex moves by the motion `m·x + b` and
// its velocity turns with it, no faster where it was stretched (CPU twin:
// `ClothState::carry`). Then the teleport rule: every vertex moves by the cloth's offset and
// the pins land on their targets at rest (CPU twin: `ClothState::teleport`). Dispatched only
// in steps where a cloth is carried or teleports.
@compute @workgroup_size(64)
fn teleport(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let i = id.x;
    if i >= P.n {
        return;
    }
    let c = vertex_cloth(i);
    let at = cloth_step(c);
    let rec = frame[at];
    let flags = u32(rec.w + 0.5);
    if (flags & 4u) != 0u {
        let b = vec3<f32>(frame[at + 1u].w, frame[at + 2u].w, frame[at + 3u].w);
        let x = state[i];
        let q = state[P.prev_at + i];
        let v = state[P.vel_at + i];
        state[i] = vec4<f32>(carried(at, x.xyz) + b, x.w);
        state[P.prev_at + i] = vec4<f32>(carried(at, q.xyz) + b, q.w);
        var turned = carried(at, v.xyz);
        if (flags & 16u) != 0u {
            // `solver::step::inertia::no_faster`: no faster than before the stretch, and at
            // rest where the stretch overflowed it.
            let kept = clamp_speed(vec4<f32>(turned, 0.0), length(v.xyz)).xyz;
            turned = select(vec3<f32>(0.0), kept, finite3(kept));
        }
        state[P.vel_at + i] = vec4<f32>(turned, v.w);
    }
    if (flags & 2u) == 0u {
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

// `air::vertex_area_vectors` for vertex `i` of a cloth with record `flags`, over its
// triangles in triangle order (the CPU's summation order), torn ones left out.
fn area_vector(i: u32, flags: u32) -> vec3<f32> {
    var acc = vec3<f32>(0.0);
    for (var k = topo[P.tri_offsets_at + i]; k < topo[P.tri_offsets_at + i + 1u]; k++) {
        if triangle_torn(topo[k], flags) {
            continue;
        }
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
    let h = sc_fmix(sc_fmix(sc_fmix(bitcast<u32>(c.z)) + bitcast<u32>(c.y)) + bitcast<u32>(c.x));
    return h % size;
}

// MurmurHash3's 32-bit finaliser (`self_collision::grid::fmix`).
fn sc_fmix(x: u32) -> u32 {
    var h = x ^ (x >> 16u);
    h *= 0x85ebca6bu;
    h ^= h >> 13u;
    h *= 0xc2b2ae35u;
    return h ^ (h >> 16u);
}

// Cells of the self-collision hash: as wide as the farthest a query reaches (2.5 thicknesses
// and the triangle reach), so the hash needs no step-wide maximum first. (The CPU's grid,
// `self_collision::Grid`, is laid out for its vector units; both find the same vertices.)
fn sc_cell_size(cl: Cloth) -> f32 {
    return 2.5 * cl.sc_thickest + min(cl.sc_tri_reach, 4.0 * cl.sc_thickest);
}

// The start of a step for every vertex: where pins start from (`ClothState::pin_starts`),
// the area vectors (air), and with self-collision the fastest speed of the cloth and the
// vertex put into its cloth's hash (a bucket list: heads hold vertex + 1, 0 ends a list).
// Nothing here writes a position, so every vertex reads its neighbours as the step found them.
@compute @workgroup_size(64)
fn step_begin(
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
    let p = vertex_pin(i);
    if p != NO_PIN {
        state[P.pin_start_at + p] = x;
    }
    if (cl.flags & FLAG_AIR) != 0u {
        state[P.area_at + i] = vec4<f32>(area_vector(i, cl.flags), 0.0);
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
fn impulse_clear(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    if id.x < P.impulse_slots {
        atomicStore(&scratch[P.impulse_at + id.x], 0u);
    }
}
