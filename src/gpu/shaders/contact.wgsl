// Per substep after the constraints: tethers, self-collision and colliders, in the CPU's
// order (`solver::step`: tethers, then the self-collision pass on the tethered positions, then
// the colliders), and once per step the self-collision neighbour lists.

// `Tethers::project` for vertex `i` at `x`: pulled back within reach of each of its pins in
// turn (the anchors are pinned: nothing after the constraints moves them).
fn tethered(i: u32, x: vec4<f32>) -> vec4<f32> {
    if !(x.w > 0.0) {
        return x;
    }
    var out = x;
    let b = P.tether_at;
    for (var k = topo[b + i]; k < topo[b + i + 1u]; k += 2u) {
        let anchor = state[topo[k]].xyz;
        let max_len = bitcast<f32>(topo[k + 1u]);
        let d = out.xyz - anchor;
        let len2 = dot(d, d);
        if len2 > max_len * max_len {
            let pulled = anchor + d * (max_len / sqrt(len2));
            if finite3(pulled) {
                out = vec4<f32>(pulled, out.w);
            }
        }
    }
    return out;
}

// `self_collision::reach_and_skip`: the query distance (thickness plus a margin for the
// fastest vertex's travel over the step).
fn sc_reach(c: u32, cl: Cloth) -> f32 {
    let fastest = sqrt(bitcast<f32>(atomicLoad(&scratch[P.speed_at + c])));
    return cl.sc_thickness + min(2.0 * fastest * P.dt, 1.5 * cl.sc_thickness);
}

// Once per step, from the step's start: every other vertex of the same cloth closer than the
// reach that rests farther than 2.5 thicknesses away, the `SC_MAX` lowest-numbered ones in
// increasing order (CPU twin: `self_collision::find_neighbours`, the same rule).
@compute @workgroup_size(64)
fn sc_query(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let c = vertex_cloth(i);
    let cl = cloth_of(c);
    if (cl.flags & FLAG_SC) == 0u || !cloth_active(c) {
        return;
    }
    var list: array<u32, 32>;
    var count = 0u;
    let p = state[i].xyz;
    if finite3(p) {
        let reach = sc_reach(c, cl);
        let inv = 1.0 / sc_cell_size(cl);
        let r2 = reach * reach;
        let skip = 2.5 * cl.sc_thickness;
        let skip2 = skip * skip;
        let rest_i = state[P.rest_at + i].xyz;
        let size = 2u * cl.n;
        let lo = sc_cell(p - vec3<f32>(reach), inv);
        let hi = sc_cell(p + vec3<f32>(reach), inv);
        for (var z = lo.z; z <= hi.z; z++) {
            for (var y = lo.y; y <= hi.y; y++) {
                for (var x = lo.x; x <= hi.x; x++) {
                    let cell = vec3<i32>(x, y, z);
                    var e = atomicLoad(&scratch[P.head_at + cl.head_base + sc_hash(cell, size)]);
                    while e != 0u {
                        let j = e - 1u;
                        e = atomicLoad(&scratch[P.next_at + j]);
                        let q = state[j].xyz;
                        let d = q - p;
                        let r = state[P.rest_at + j].xyz - rest_i;
                        if j != i && all(sc_cell(q, inv) == cell) && dot(d, d) < r2
                            && dot(r, r) > skip2 {
                            // Keep the SC_MAX smallest indices, sorted.
                            if count < SC_MAX || j < list[SC_MAX - 1u] {
                                var k = min(count, SC_MAX - 1u);
                                while k > 0u && list[k - 1u] > j {
                                    list[k] = list[k - 1u];
                                    k -= 1u;
                                }
                                list[k] = j;
                                count = min(count + 1u, SC_MAX);
                            }
                        }
                    }
                }
            }
        }
    }
    for (var k = 0u; k < count; k++) {
        atomicStore(&scratch[P.nlist_at + i * SC_MAX + k], list[k]);
    }
    atomicStore(&scratch[P.ncount_at + i], count);
}

// `self_collision::pair_correction`: vertex a's share; w = 0 when the pair does not touch.
fn sc_pair(a: vec4<f32>, prev_a: vec3<f32>, b: vec4<f32>, prev_b: vec3<f32>, thickness: f32, friction: f32) -> vec4<f32> {
    let limit = thickness;
    let wa = a.w;
    let wb = b.w;
    let w = wa + wb;
    if w <= 0.0 {
        return vec4<f32>(0.0);
    }
    let d = a.xyz - b.xyz;
    let len = length(d);
    if len >= limit || len <= 1e-9 {
        return vec4<f32>(0.0);
    }
    let nrm = d / len;
    let push = limit - len;
    var da = nrm * (push * wa / w);
    var db = -nrm * (push * wb / w);
    let slide = (a.xyz + da - prev_a) - (b.xyz + db - prev_b);
    let tangential = slide - nrm * dot(nrm, slide);
    let t_len = length(tangential);
    if t_len > 0.0 {
        let keep = min(friction * push / t_len, 1.0);
        da -= tangential * (keep * wa / w);
        db += tangential * (keep * wb / w);
    }
    if !(finite3(da) && finite3(db)) {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(da, 1.0);
}

// Self-collision (Jacobi, CPU twin: `self_collision::self_collide_parallel`): vertex `i`'s
// correction, the mean of its touching pairs' corrections against the tethered positions
// (each vertex tethers itself and its neighbours on the fly, so no pass has to come between).
@compute @workgroup_size(64)
fn sc_collide(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let c = vertex_cloth(i);
    let cl = cloth_of(c);
    if (cl.flags & FLAG_SC) == 0u || !cloth_active(c) {
        return;
    }
    let tethers = (cl.flags & FLAG_TETHERS) != 0u;
    var a = state[i];
    if tethers {
        a = tethered(i, a);
    }
    let prev_a = state[P.prev_at + i].xyz;
    var sum = vec3<f32>(0.0);
    var touching = 0.0;
    let count = atomicLoad(&scratch[P.ncount_at + i]);
    for (var k = 0u; k < count; k++) {
        let j = atomicLoad(&scratch[P.nlist_at + i * SC_MAX + k]);
        var b = state[j];
        if tethers {
            b = tethered(j, b);
        }
        let r = sc_pair(a, prev_a, b, state[P.prev_at + j].xyz, cl.sc_thickness, cl.sc_friction);
        sum += r.xyz;
        touching += r.w;
    }
    var corr = vec3<f32>(0.0);
    if touching > 0.0 {
        corr = sum / touching;
    }
    state[P.corr_at + i] = vec4<f32>(corr, 0.0);
}

// One vertex against one collider (`collide::collide_vertex`'s loop body): the corrected
// position in xyz, w = 1 when it was pushed.
fn collide_one(c: Collider, p: vec3<f32>, prev: vec3<f32>) -> vec4<f32> {
    let off = p - c.to_t.xyz;
    if dot(off, off) > c.misc.z {
        return vec4<f32>(p, 0.0);
    }
    let local = pose_inverse_apply(c.to_t, c.to_r, p);
    let kind = u32(c.misc.w);
    var dn: vec4<f32>;
    if kind == 4u {
        dn = sdf_sample(c.shape.xyz, c.shape.w, c.grid, local);
    } else {
        dn = shape_distance(kind, c.shape, local);
    }
    let d = dn.w * c.to_t.w;
    let thickness = c.misc.x;
    if !(d < thickness) {
        return vec4<f32>(p, 0.0);
    }
    let nrm = rotate(c.to_r, dn.xyz);
    let push = thickness - d;
    var corrected = p + nrm * push;
    let surface = pose_apply(c.to_t, c.to_r, local) - pose_apply(c.from_t, c.from_r, local);
    let slide = (corrected - prev) - surface;
    let tangential = slide - nrm * dot(nrm, slide);
    let t_len = length(tangential);
    let limit = c.misc.y * push;
    if t_len > 0.0 {
        if t_len <= limit {
            corrected -= tangential;
        } else {
            corrected -= tangential * (limit / t_len);
        }
    }
    if !within_range(corrected) {
        return vec4<f32>(p, 0.0);
    }
    return vec4<f32>(corrected, 1.0);
}

var<workgroup> imp_lin: array<vec3<f32>, 64>;
var<workgroup> imp_ang: array<vec3<f32>, 64>;

// The end of a substep for every vertex: tethers, the self-collision correction, then the
// colliders (`collide::collide_vertex`). Each workgroup also sums the momentum its vertices
// gave each collider (−m·Δx/h, and its moment about the collider's origin) into its own slot
// (by the collider's frame slot), over every substep and step of the frame; the host adds the
// slots up after reading them back. Every invocation reaches every barrier.
@compute @workgroup_size(64)
fn finish_substep(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
) {
    let i = id.x;
    var x = vec4<f32>(0.0);
    var prev = vec3<f32>(0.0);
    var free = false;
    if i < P.n {
        let c = vertex_cloth(i);
        let cl = cloth_of(c);
        x = state[i];
        prev = state[P.prev_at + i].xyz;
        free = cloth_active(c) && x.w > 0.0;
        if free {
            if (cl.flags & FLAG_TETHERS) != 0u {
                x = tethered(i, x);
            }
            if (cl.flags & FLAG_SC) != 0u {
                x = vec4<f32>(x.xyz + state[P.corr_at + i].xyz, x.w);
            }
        }
    }
    for (var k = 0u; k < S.colliders; k++) {
        let c = colliders[S.pose_at + k];
        var dp = vec3<f32>(0.0);
        var arm = vec3<f32>(0.0);
        if free {
            let p = x.xyz;
            let r = collide_one(c, p, prev);
            if r.w != 0.0 {
                dp = (r.xyz - p) / x.w;
                arm = p - c.to_t.xyz;
                x = vec4<f32>(r.xyz, x.w);
            }
        }
        imp_lin[lid.x] = -dp;
        imp_ang[lid.x] = -cross(arm, dp);
        workgroupBarrier();
        for (var s = 32u; s > 0u; s >>= 1u) {
            if lid.x < s {
                imp_lin[lid.x] += imp_lin[lid.x + s];
                imp_ang[lid.x] += imp_ang[lid.x + s];
            }
            workgroupBarrier();
        }
        if lid.x == 0u {
            let slot = P.impulse_at + 6u * (wid.x * P.collider_slots + c.slot.x);
            var add = array<f32, 6>(
                imp_lin[0].x, imp_lin[0].y, imp_lin[0].z,
                imp_ang[0].x, imp_ang[0].y, imp_ang[0].z,
            );
            for (var j = 0u; j < 6u; j++) {
                let old = bitcast<f32>(atomicLoad(&scratch[slot + j]));
                atomicStore(&scratch[slot + j], bitcast<u32>(old + add[j] * P.inv_h));
            }
        }
        workgroupBarrier();
    }
    if free {
        state[i] = x;
    }
}
