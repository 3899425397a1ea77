// The constraints, per substep: one workgroup per *group* of constraints — a part of a cloth
// (a range of its vertices), a seam between two neighbouring parts, or what joins parts
// further apart — every colour of the group in turn with a barrier between colours, so a
// substep costs a few dispatches whatever the colour count and however many cloths the world
// holds. Groups of one dispatch share no vertex. The CPU twin is `solver::step` with the same
// `ConstraintBatches` (`Part::project`): parts, then seams (all, or even then odd ones where
// neighbouring seams overlap), the boundary.
//
// A part of at most `TILE` vertices is projected in workgroup memory (loaded, projected,
// stored); larger parts, seams and the boundary are projected in place with storage barriers.

const TILE: u32 = 1024u;
const SOLVE_GROUP: u32 = 256u;

var<workgroup> xs: array<vec4<f32>, TILE>;

// Group-local vertex `k` of a group based at global vertex `base`.
fn getp(shared_mem: bool, base: u32, k: u32) -> vec4<f32> {
    if shared_mem {
        return xs[k];
    }
    return state[base + k];
}

fn setp(shared_mem: bool, base: u32, k: u32, v: vec4<f32>) {
    if shared_mem {
        xs[k] = v;
    } else {
        state[base + k] = v;
    }
}

// `distance::distance_correction` applied to constraint `i`.
fn project_distance(i: u32, base: u32, shared_mem: bool, flags: u32, first_iteration: bool) {
    // A torn edge holds nothing from the step after `tear_check` found it, as on the CPU,
    // which tears at once, until the host's tear removes it from the topology.
    if (flags & FLAG_TEARING) != 0u && atomicLoad(&scratch[P.torn_at + i]) != 0u {
        return;
    }
    let c = cons[i];
    let pa = getp(shared_mem, base, c.x);
    let pb = getp(shared_mem, base, c.y);
    let rest = bitcast<f32>(c.z);
    let ak = alpha_k(bitcast<f32>(c.w), (flags & FLAG_XPBD) != 0u);
    let accumulate = (flags & FLAG_ACCUMULATE) != 0u;
    var l = 0.0;
    if accumulate && !first_iteration {
        l = state[P.lambda_at + i].x;
    }
    let wa = pa.w;
    let wb = pb.w;
    let d = pa.xyz - pb.xyz;
    let len = sqrt(dot(d, d));
    // One division: f = Δλ/len scales the unnormalised direction d (CPU twin:
    // solver::constraints::distance::distance_correction).
    var f = ak.y * (-(len - rest) - ak.x * l) / ((wa + wb + ak.x) * len);
    if !(len > MIN_LENGTH) || !(wa + wb > 0.0) {
        f = 0.0;
    }
    setp(shared_mem, base, c.x, vec4<f32>(pa.xyz + d * (wa * f), wa));
    setp(shared_mem, base, c.y, vec4<f32>(pb.xyz + d * (-(wb * f)), wb));
    if accumulate {
        state[P.lambda_at + i] = vec4<f32>(l + f * len, 0.0, 0.0, 0.0);
    }
}

// Whether hinge `j` of a tearing cloth lost a triangle to a tear: it then holds nothing, as
// on the CPU, whose tear removes it, until the host's tear removes it here too.
fn hinge_torn(j: u32, flags: u32) -> bool {
    if (flags & FLAG_TEARING) == 0u {
        return false;
    }
    let t = cons[P.bend_at + 3u * j + 2u];
    return (t.y != NO_PIN && triangle_torn(t.y, flags)) || (t.z != NO_PIN && triangle_torn(t.z, flags));
}

// `isometric::iso_correction` applied to hinge `j`.
fn project_iso(j: u32, base: u32, shared_mem: bool, flags: u32, first_iteration: bool) {
    if hinge_torn(j, flags) {
        return;
    }
    let v = cons[P.bend_at + 3u * j];
    let a = bitcast<vec4<f32>>(cons[P.bend_at + 3u * j + 1u]);
    let param = bitcast<f32>(cons[P.bend_at + 3u * j + 2u].x);
    let x0 = getp(shared_mem, base, v.x);
    let x1 = getp(shared_mem, base, v.y);
    let x2 = getp(shared_mem, base, v.z);
    let x3 = getp(shared_mem, base, v.w);
    let ak = alpha_k(param, (flags & FLAG_XPBD) != 0u);
    let accumulate = (flags & FLAG_ACCUMULATE) != 0u;
    var l = vec3<f32>(0.0);
    if accumulate && !first_iteration {
        l = state[P.lambda_bend_at + j].xyz;
    }
    let cc = x0.xyz * a.x + x1.xyz * a.y + x2.xyz * a.z + x3.xyz * a.w;
    let g = x0.w * a.x * a.x + x1.w * a.y * a.y + x2.w * a.z * a.z + x3.w * a.w * a.w;
    var scale = 0.0;
    if g > 1e-20 {
        scale = -ak.y / (g + ak.x);
    }
    let dl = (cc + l * ak.x) * scale;
    setp(shared_mem, base, v.x, vec4<f32>(x0.xyz + dl * (x0.w * a.x), x0.w));
    setp(shared_mem, base, v.y, vec4<f32>(x1.xyz + dl * (x1.w * a.y), x1.w));
    setp(shared_mem, base, v.z, vec4<f32>(x2.xyz + dl * (x2.w * a.z), x2.w));
    setp(shared_mem, base, v.w, vec4<f32>(x3.xyz + dl * (x3.w * a.w), x3.w));
    if accumulate {
        state[P.lambda_bend_at + j] = vec4<f32>(l + dl, 0.0);
    }
}

// `dihedral::bend_correction` applied to hinge `j` (signed angle, rest angle in the first
// weight).
fn project_dihedral(j: u32, base: u32, shared_mem: bool, flags: u32, first_iteration: bool) {
    if hinge_torn(j, flags) {
        return;
    }
    let v = cons[P.bend_at + 3u * j];
    let rest = bitcast<f32>(cons[P.bend_at + 3u * j + 1u].x);
    let param = bitcast<f32>(cons[P.bend_at + 3u * j + 2u].x);
    let x0 = getp(shared_mem, base, v.x);
    let x1 = getp(shared_mem, base, v.y);
    let x2 = getp(shared_mem, base, v.z);
    let x3 = getp(shared_mem, base, v.w);
    let ak = alpha_k(param, (flags & FLAG_XPBD) != 0u);
    let accumulate = (flags & FLAG_ACCUMULATE) != 0u;
    var l = 0.0;
    if accumulate && !first_iteration {
        l = state[P.lambda_bend_at + j].x;
    }
    let eps = 1e-12;
    let p2 = x1.xyz - x0.xyz;
    let p3 = x2.xyz - x0.xyz;
    let p4 = x3.xyz - x0.xyz;
    let c23 = cross(p2, p3);
    let c24 = cross(p2, p4);
    let l23 = sqrt(dot(c23, c23));
    let l24 = sqrt(dot(c24, c24));
    let inv23 = select(0.0, 1.0 / max(l23, eps), l23 > eps);
    let inv24 = select(0.0, 1.0 / max(l24, eps), l24 > eps);
    let n1 = c23 * inv23;
    let n2 = c24 * inv24;
    let d = min(max(dot(n1, n2), -1.0), 1.0);
    let p2n1 = cross(p2, n1);
    let p2n2 = cross(p2, n2);
    let q3 = (p2n2 - p2n1 * d) * inv23;
    let q4 = (p2n1 - p2n2 * d) * inv24;
    let q2 = -((cross(p3, n2) + cross(n1, p3) * d) * inv23)
        - (cross(p4, n1) + cross(n2, p4) * d) * inv24;
    let q1 = -(q2 + q3 + q4);
    let n12 = cross(n1, n2);
    let s = sqrt(dot(n12, n12));
    let sigma = select(-1.0, 1.0, dot(n12, p2) > 0.0);
    let psi = sigma * atan2(s, -d);
    let cc = psi - rest;
    let g = x0.w * dot(q1, q1) + x1.w * dot(q2, q2) + x2.w * dot(q3, q3) + x3.w * dot(q4, q4);
    let s2 = s * s;
    var base_f = ak.y * (-cc - ak.x * l) / (g + ak.x * s2);
    if !(g > 1e-20) || !(l23 > eps) || !(l24 > eps) {
        base_f = 0.0;
    }
    let f = -(sigma * s * base_f);
    setp(shared_mem, base, v.x, vec4<f32>(x0.xyz + q1 * (x0.w * f), x0.w));
    setp(shared_mem, base, v.y, vec4<f32>(x1.xyz + q2 * (x1.w * f), x1.w));
    setp(shared_mem, base, v.z, vec4<f32>(x2.xyz + q3 * (x2.w * f), x2.w));
    setp(shared_mem, base, v.w, vec4<f32>(x3.xyz + q4 * (x3.w * f), x3.w));
    if accumulate {
        state[P.lambda_bend_at + j] = vec4<f32>(l + s2 * base_f, 0.0, 0.0, 0.0);
    }
}

fn project_hinge(j: u32, base: u32, shared_mem: bool, flags: u32, first_iteration: bool) {
    if (flags & FLAG_DIHEDRAL) != 0u {
        project_dihedral(j, base, shared_mem, flags, first_iteration);
    } else {
        project_iso(j, base, shared_mem, flags, first_iteration);
    }
}

// The start of a substep for vertex `v` of cloth `cl`, returning its new position: a pin
// finishes its velocity for the previous substep and moves toward its target
// (`finish_pin_velocities`, `ClothState::place_pins`); a free vertex finishes its velocity
// (`step::substeps::run_part`: clamped) and integrates gravity, damping and the air.
fn begin_substep(v: u32, cl: Cloth) -> vec4<f32> {
    let x = state[v];
    let prev = state[P.prev_at + v];
    let p = vertex_pin(v);
    if p != NO_PIN {
        if S.substep > 0u {
            state[P.vel_at + v] = vec4<f32>((x.xyz - prev.xyz) * P.inv_h, 0.0);
        }
        state[P.prev_at + v] = x;
        let a = state[P.pin_start_at + p].xyz;
        let target_pos = frame[S.pin_at + p].xyz;
        return vec4<f32>(a * (1.0 - S.t) + target_pos * S.t, 0.0);
    }
    if !(x.w > 0.0) {
        return x;
    }
    var vel = state[P.vel_at + v];
    if S.substep > 0u {
        vel = clamp_speed((x - prev) * P.inv_h, cl.max_speed);
    }
    state[P.prev_at + v] = x;
    var u = vel * cl.damp + vec4<f32>(cl.gravity_h, 0.0);
    if (cl.flags & FLAG_AIR) != 0u {
        let wind = state[P.air_at + v].xyz;
        u += vec4<f32>(air_velocity_change(state[P.area_at + v].xyz, u.xyz - wind, x.w, P.h, cl.air), 0.0);
    }
    state[P.vel_at + v] = u;
    return x + u * P.h;
}

fn solve_barrier(shared_mem: bool) {
    if shared_mem {
        workgroupBarrier();
    } else {
        storageBarrier();
    }
}

// One group per workgroup (`L.first + workgroup`): its vertices integrated when this is the
// parts' first iteration, then its distance colours and its hinge colours in order, each
// colour's constraints in parallel, the colouring's leftovers one by one.
@compute @workgroup_size(256)
fn solve(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    // One workgroup a group of the level (`kernels::flat_groups` may split them over more
    // dimensions and round up: the whole workgroup past the level's groups returns).
    let nth = wid.x + (wid.y + wid.z * groups.y) * groups.x;
    if nth >= L.count {
        return;
    }
    let g = L.first + nth;
    // The group's record: read-only storage at a workgroup-uniform index, so every value
    // below is uniform across the workgroup (the colour loops' barriers need that).
    var hdr: array<u32, 16>;
    for (var w = 0u; w < GROUP_WORDS; w++) {
        hdr[w] = topo[P.group_at + g * GROUP_WORDS + w];
    }
    if !cloth_active(hdr[0]) {
        return;
    }
    let cl = cloth_of(hdr[0]);
    let base = hdr[1];
    let len = hdr[2];
    let shared_mem = hdr[3] != 0u;
    let flags = cl.flags;
    let first_iteration = (L.flags & 2u) != 0u;
    if (L.flags & 1u) != 0u {
        for (var k = li; k < len; k += SOLVE_GROUP) {
            let x = begin_substep(base + k, cl);
            setp(shared_mem, base, k, x);
        }
    } else if shared_mem {
        for (var k = li; k < len; k += SOLVE_GROUP) {
            xs[k] = state[base + k];
        }
    }
    solve_barrier(shared_mem);
    // Distances: colour bounds at hdr[6] (colours + 1 entries), leftovers hdr[7]..+hdr[8].
    for (var col = 0u; col < hdr[5]; col++) {
        let first = topo[hdr[6] + col];
        let end = topo[hdr[6] + col + 1u];
        for (var i = first + li; i < end; i += SOLVE_GROUP) {
            project_distance(i, base, shared_mem, flags, first_iteration);
        }
        solve_barrier(shared_mem);
    }
    if hdr[8] > 0u {
        if li == 0u {
            for (var i = hdr[7]; i < hdr[7] + hdr[8]; i++) {
                project_distance(i, base, shared_mem, flags, first_iteration);
            }
        }
        solve_barrier(shared_mem);
    }
    // A cloth with a hub (`SYMMETRIC_SWEEP_DEGREE`): the same constraints back, the
    // leftovers last to first, then the colours last to first (as `DistanceSet::project`).
    if (flags & FLAG_SYMMETRIC) != 0u {
        if hdr[8] > 0u {
            if li == 0u {
                for (var i = hdr[7] + hdr[8]; i > hdr[7]; i--) {
                    project_distance(i - 1u, base, shared_mem, flags, first_iteration);
                }
            }
            solve_barrier(shared_mem);
        }
        for (var col = hdr[5]; col > 0u; col--) {
            let first = topo[hdr[6] + col - 1u];
            let end = topo[hdr[6] + col];
            for (var i = first + li; i < end; i += SOLVE_GROUP) {
                project_distance(i, base, shared_mem, flags, first_iteration);
            }
            solve_barrier(shared_mem);
        }
    }
    for (var col = 0u; col < hdr[10]; col++) {
        let first = topo[hdr[11] + col];
        let end = topo[hdr[11] + col + 1u];
        for (var j = first + li; j < end; j += SOLVE_GROUP) {
            project_hinge(j, base, shared_mem, flags, first_iteration);
        }
        solve_barrier(shared_mem);
    }
    if hdr[13] > 0u {
        if li == 0u {
            for (var j = hdr[12]; j < hdr[12] + hdr[13]; j++) {
                project_hinge(j, base, shared_mem, flags, first_iteration);
            }
        }
        solve_barrier(shared_mem);
    }
    if shared_mem {
        for (var k = li; k < len; k += SOLVE_GROUP) {
            state[base + k] = xs[k];
        }
    }
}
