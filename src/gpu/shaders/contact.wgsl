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

// `self_collision::reach_of`: a vertex's query distance (its thickness plus a margin for the
// fastest vertex's travel over the step, at most 1.5 thicknesses).
fn sc_reach(c: u32, thickness: f32) -> f32 {
    let fastest = sqrt(bitcast<f32>(atomicLoad(&scratch[P.speed_at + c])));
    return thickness + min(2.0 * fastest * P.dt, 1.5 * thickness);
}

// `Topology::self_collision_scales`: vertex `i`'s own thickness (its scale rides in its rest
// position's w).
fn sc_thickness_of(i: u32, cl: Cloth) -> f32 {
    return cl.sc_thickness * state[P.rest_at + i].w;
}

// `Topology::self_collision_triangle_scales`: the thickness vertex `i` keeps from triangles.
fn sc_triangle_thickness_of(i: u32, cl: Cloth) -> f32 {
    return cl.sc_thickness * bitcast<f32>(topo[P.sc_triangle_scale_at + i]);
}

// `self_collision::NEAR_CORNER_THICKNESS`.
const SC_NEAR_CORNER_THICKNESS: f32 = 0.9;

// `self_collision::near_corner_reach`: SC_NEAR_CORNER_THICKNESS times the rest distance from
// vertex `i` to the nearest of the corners `k0`, `k1`, `k2`.
fn sc_near_corner_reach(i: u32, k0: u32, k1: u32, k2: u32) -> f32 {
    let r = state[P.rest_at + i].xyz;
    let d0 = state[P.rest_at + k0].xyz - r;
    let d1 = state[P.rest_at + k1].xyz - r;
    let d2 = state[P.rest_at + k2].xyz - r;
    let near2 = min(min(dot(d0, d0), dot(d1, d1)), dot(d2, d2));
    return SC_NEAR_CORNER_THICKNESS * sqrt(near2);
}

// `self_collision::rest_triangle_reach`: SC_NEAR_CORNER_THICKNESS times the rest distance
// from vertex `i` to the triangle of corners `k0`, `k1`, `k2` (to its nearest point).
fn sc_rest_triangle_reach(i: u32, k0: u32, k1: u32, k2: u32) -> f32 {
    let r = state[P.rest_at + i].xyz;
    let d = sc_closest(r, state[P.rest_at + k0].xyz, state[P.rest_at + k1].xyz, state[P.rest_at + k2].xyz) - r;
    return SC_NEAR_CORNER_THICKNESS * sqrt(dot(d, d));
}

// `MeshLists::joined_to_all`: whether an edge joins vertex `i` to each of the corners `k0`,
// `k1`, `k2`, none of which is `i` (over the triangles through `i`; a closed cloth has none
// torn).
fn sc_joined_to_all(i: u32, k0: u32, k1: u32, k2: u32) -> bool {
    var f0 = false;
    var f1 = false;
    var f2 = false;
    for (var k = topo[P.tri_offsets_at + i]; k < topo[P.tri_offsets_at + i + 1u]; k++) {
        let t = P.tri_at + 3u * topo[k];
        let a = topo[t];
        let b = topo[t + 1u];
        let c = topo[t + 2u];
        f0 = f0 || a == k0 || b == k0 || c == k0;
        f1 = f1 || a == k1 || b == k1 || c == k1;
        f2 = f2 || a == k2 || b == k2 || c == k2;
    }
    return f0 && f1 && f2 && i != k0 && i != k1 && i != k2;
}

// `thickness.min(self_collision::triangle_cap(..))`: the thickness vertex `i` of a closed
// cloth keeps from the triangle of corners `k0`, `k1`, `k2`: `thickness`, at most
// `SC_NEAR_CORNER_THICKNESS` times its rest distance from the nearest corner, or from the
// triangle itself where an edge joins `i` to each corner.
fn sc_capped_thickness(thickness: f32, i: u32, k0: u32, k1: u32, k2: u32) -> f32 {
    if sc_joined_to_all(i, k0, k1, k2) {
        return min(thickness, sc_rest_triangle_reach(i, k0, k1, k2));
    }
    return min(thickness, sc_near_corner_reach(i, k0, k1, k2));
}

// `sdf::closest_point_on_triangle` (Ericson 5.1.5).
fn sc_closest(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if abs(denom) < 1.17549435e-38 {
        // Degenerate: the nearest corner, the first of equals.
        var best = a;
        if dot(b - p, b - p) < dot(best - p, best - p) {
            best = b;
        }
        if dot(c - p, c - p) < dot(best - p, best - p) {
            best = c;
        }
        return best;
    }
    return a + ab * (vb / denom) + ac * (vc / denom);
}

// `self_collision::project`: the unit normal and signed distance of `p` from the triangle's
// plane, the projection's barycentric weights and twice the area; `ok` false for a degenerate
// triangle.
struct Projection {
    n: vec3<f32>,
    d: f32,
    bary: vec3<f32>,
    area2: f32,
    ok: bool,
}

fn sc_project(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> Projection {
    var r: Projection;
    r.ok = false;
    let e1 = b - a;
    let e2 = c - a;
    let nn = cross(e1, e2);
    let len = length(nn);
    if !(len > 1e-12) {
        return r;
    }
    r.n = nn / len;
    let ap = p - a;
    r.d = dot(ap, r.n);
    let d00 = dot(e1, e1);
    let d01 = dot(e1, e2);
    let d11 = dot(e2, e2);
    let d20 = dot(ap, e1);
    let d21 = dot(ap, e2);
    let denom = d00 * d11 - d01 * d01;
    if !(denom > 0.0) {
        return r;
    }
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    r.bary = vec3<f32>(1.0 - v - w, v, w);
    r.area2 = len;
    r.ok = true;
    return r;
}

fn sc_min3(v: vec3<f32>) -> f32 {
    return min(v.x, min(v.y, v.z));
}

// What a vertex's query knows of it and of the step.
struct ScVertex {
    p: vec3<f32>,
    rest_i: vec3<f32>,
    vel_i: vec3<f32>,
    reach: f32,
    margin: f32,
    skip2: f32,
    tri_skip2: f32,
    thickness: f32,
    // its cloth's record flags
    flags: u32,
}

// The triangles whose first corner is `j` (at `q`, resting `rest2` from the vertex) that the
// vertex is over, or beside by no more than it can slide over in the step, into its sorted
// list (CPU twin: `self_collision::Query::triangles_through`).
fn sc_triangles_of(v: ScVertex, j: u32, q: vec3<f32>, rest2: f32, tlist: ptr<function, array<u32, 64>>, tcount: ptr<function, u32>) {
    let r2 = v.reach * v.reach;
    for (var m = topo[P.first_tri_at + j]; m < topo[P.first_tri_at + j + 1u]; m++) {
        let t = topo[m];
        if triangle_torn(t, v.flags) {
            continue;
        }
        let tb = P.tri_at + 3u * t;
        let k1 = topo[tb + 1u];
        let k2 = topo[tb + 2u];
        let r1 = state[P.rest_at + k1].xyz - v.rest_i;
        let r2b = state[P.rest_at + k2].xyz - v.rest_i;
        if !(dot(r1, r1) > v.tri_skip2 && dot(r2b, r2b) > v.tri_skip2) {
            continue;
        }
        let b = state[k1].xyz;
        let cc = state[k2].xyz;
        if !(finite3(b) && finite3(cc)) {
            continue;
        }
        // Over the triangle, or beside it by no more than it can slide over in the step.
        let pr = sc_project(v.p, q, b, cc);
        if !pr.ok || !(abs(pr.d) < v.reach) {
            continue;
        }
        var code = SIDE_FREE;
        if sc_min3(pr.bary) >= 0.0 {
            code = select(SIDE_BACK, SIDE_FRONT, pr.d >= 0.0);
        } else {
            // How far it can slide over the triangle in the step (CPU twin: the same rule).
            var slide = v.margin;
            if !(rest2 > v.skip2) {
                let v0 = state[P.vel_at + j].xyz - v.vel_i;
                let v1 = state[P.vel_at + k1].xyz - v.vel_i;
                let v2 = state[P.vel_at + k2].xyz - v.vel_i;
                let rel = max(max(max(0.0, dot(v0, v0)), dot(v1, v1)), dot(v2, v2));
                slide = min(2.0 * P.dt * sqrt(rel) + 0.25 * v.thickness, v.margin);
            }
            // At least −(the negative weight) altitudes away.
            let longest2 = max(max(dot(b - q, b - q), dot(cc - b, cc - b)), dot(q - cc, q - cc));
            let below = -sc_min3(pr.bary) * pr.area2 / sqrt(longest2);
            if below > slide {
                continue;
            }
            let near = sc_closest(v.p, q, b, cc) - v.p;
            let near2 = dot(near, near);
            if !(near2 < r2 && near2 - pr.d * pr.d <= slide * slide) {
                continue;
            }
        }
        // `self_collision::slot`: triangles it is over sort first.
        let slot = select(0u, BESIDE, code == SIDE_FREE) | (t << 2u) | code;
        if *tcount < SC_TRI_MAX || slot < (*tlist)[SC_TRI_MAX - 1u] {
            var k = min(*tcount, SC_TRI_MAX - 1u);
            while k > 0u && (*tlist)[k - 1u] > slot {
                (*tlist)[k] = (*tlist)[k - 1u];
                k -= 1u;
            }
            (*tlist)[k] = slot;
            *tcount = min(*tcount + 1u, SC_TRI_MAX);
        }
    }
}

// Vertices of the own neighbourhood a query holds back until it knows whether the
// neighbourhood folded; past that many it walks the cells again for the rest.
const SC_PEND: u32 = 32u;

// Once per step, from the step's start (CPU twin: `self_collision::Query::vertex`, the same
// rules): every other vertex of the same cloth closer than the reach that rests farther than
// 2.5 thicknesses away, the `SC_MAX` lowest-numbered ones in increasing order; and every
// triangle within the reach none of whose corners rests within half a thickness, that the
// vertex is over or can slide over in the step, found through its first corner (one resting
// within 2.5 thicknesses only where the neighbourhood folded: `self_collision::NEAR_FOLDED2`,
// `AHEAD`), the `SC_TRI_MAX` lowest-numbered ones with their side codes. The lists are sorted,
// so the order vertices are met in does not matter.
@compute @workgroup_size(64)
fn sc_query(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
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
    var tlist: array<u32, 64>;
    var tcount = 0u;
    let p = state[i].xyz;
    if finite3(p) {
        let thickness = sc_thickness_of(i, cl);
        let reach = sc_reach(c, thickness);
        let radius = reach + min(cl.sc_tri_reach, 4.0 * thickness);
        let inv = 1.0 / sc_cell_size(cl);
        let r2 = reach * reach;
        let big2 = radius * radius;
        let skip = 2.5 * thickness;
        let tri_skip = 0.5 * thickness;
        var v: ScVertex;
        v.p = p;
        v.rest_i = state[P.rest_at + i].xyz;
        v.vel_i = state[P.vel_at + i].xyz;
        v.reach = reach;
        v.margin = reach - thickness;
        v.skip2 = skip * skip;
        v.tri_skip2 = tri_skip * tri_skip;
        v.thickness = thickness;
        v.flags = cl.flags;
        let size = 2u * cl.n;
        let lo = sc_cell(p - vec3<f32>(radius), inv);
        let hi = sc_cell(p + vec3<f32>(radius), inv);
        // The own neighbourhood has folded when a vertex of it within the radius is now, or
        // two steps on, at 97 % of its rest distance or closer; until then its vertices wait.
        let ahead = 2.0 * P.dt;
        let pa = p + v.vel_i * ahead;
        var folded = false;
        var pend: array<u32, SC_PEND>;
        var npend = 0u;
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
                        let d2 = dot(d, d);
                        if !(d2 < big2) || j == i || any(sc_cell(q, inv) != cell) {
                            continue;
                        }
                        let r = state[P.rest_at + j].xyz - v.rest_i;
                        let rest2 = dot(r, r);
                        if !(rest2 > v.tri_skip2) {
                            continue;
                        }
                        // Keep the SC_MAX smallest indices, sorted.
                        if d2 < r2 && rest2 > v.skip2 && (count < SC_MAX || j < list[SC_MAX - 1u]) {
                            var k = min(count, SC_MAX - 1u);
                            while k > 0u && list[k - 1u] > j {
                                list[k] = list[k - 1u];
                                k -= 1u;
                            }
                            list[k] = j;
                            count = min(count + 1u, SC_MAX);
                        }
                        if rest2 > v.skip2 {
                            // Beyond 2.5 thicknesses at rest, only where the cloth came closer
                            // to itself than at rest.
                            if !(d2 < 0.81 * rest2) {
                                continue;
                            }
                        } else if !folded {
                            let f2 = 0.9409 * rest2;
                            let a = (q + state[P.vel_at + j].xyz * ahead) - pa;
                            if d2 < f2 || dot(a, a) < f2 {
                                folded = true;
                            } else {
                                if npend < SC_PEND {
                                    pend[npend] = j;
                                }
                                npend += 1u;
                                continue;
                            }
                        }
                        sc_triangles_of(v, j, q, rest2, &tlist, &tcount);
                    }
                }
            }
        }
        if folded {
            // The neighbourhood's vertices met before it was known to have folded.
            for (var k = 0u; k < min(npend, SC_PEND); k++) {
                let j = pend[k];
                let r = state[P.rest_at + j].xyz - v.rest_i;
                sc_triangles_of(v, j, state[j].xyz, dot(r, r), &tlist, &tcount);
            }
            // More of them than were held: the same walk again for the ones past SC_PEND (the
            // walk meets them in the same order).
            if npend > SC_PEND {
                var seen = 0u;
                for (var z = lo.z; z <= hi.z; z++) {
                    for (var y = lo.y; y <= hi.y; y++) {
                        for (var x = lo.x; x <= hi.x; x++) {
                            let cell = vec3<i32>(x, y, z);
                            var e = atomicLoad(&scratch[P.head_at + cl.head_base + sc_hash(cell, size)]);
                            while e != 0u && seen < npend {
                                let j = e - 1u;
                                e = atomicLoad(&scratch[P.next_at + j]);
                                let q = state[j].xyz;
                                let d = q - p;
                                if !(dot(d, d) < big2) || j == i || any(sc_cell(q, inv) != cell) {
                                    continue;
                                }
                                let r = state[P.rest_at + j].xyz - v.rest_i;
                                let rest2 = dot(r, r);
                                if !(rest2 > v.tri_skip2) || rest2 > v.skip2 {
                                    continue;
                                }
                                if seen >= SC_PEND {
                                    sc_triangles_of(v, j, q, rest2, &tlist, &tcount);
                                }
                                seen += 1u;
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
    for (var k = 0u; k < tcount; k++) {
        atomicStore(&scratch[P.tlist_at + i * SC_TRI_MAX + k], tlist[k]);
    }
    atomicStore(&scratch[P.tcount_at + i], tcount);
}

// `self_collision::DEPENETRATION`: of an overlap a contact began the substep with, the
// thicknesses it undoes in one substep (all of what the pair closed within the substep besides).
const SC_DEPENETRATION: f32 = 0.35;

// `self_collision::limited_push`: the overlap, but of it at most what the pair closed within
// the substep plus `depenetration` (usually SC_DEPENETRATION thicknesses).
fn sc_limited_push(overlap: f32, approach: f32, depenetration: f32) -> f32 {
    return min(overlap, max(approach, 0.0) + depenetration);
}

// A vertex–vertex contact: the vertex's correction (w = 1 when it touches, 0 when not) and
// the part of it that undoes the overlap the pair began the substep with (moved without
// velocity by `finish_substep`).
struct ScPair {
    da: vec4<f32>,
    old: vec3<f32>,
}

// `self_collision::pair_correction`: vertex a's share.
fn sc_pair(a: vec4<f32>, prev_a: vec3<f32>, b: vec4<f32>, prev_b: vec3<f32>, thickness: f32, friction: f32) -> ScPair {
    let none = ScPair(vec4<f32>(0.0), vec3<f32>(0.0));
    let limit = thickness;
    let wa = a.w;
    let wb = b.w;
    let w = wa + wb;
    if w <= 0.0 {
        return none;
    }
    let d = a.xyz - b.xyz;
    let len = length(d);
    if len >= limit || len <= 1e-9 {
        return none;
    }
    let nrm = d / len;
    let approach = dot(nrm, prev_a - prev_b) - len;
    let push = sc_limited_push(limit - len, approach, SC_DEPENETRATION * limit);
    let old = nrm * (max(push - max(approach, 0.0), 0.0) * wa / w);
    var da = nrm * (push * wa / w);
    let db = -nrm * (push * wb / w);
    let slide = (a.xyz + da - prev_a) - (b.xyz + db - prev_b);
    let tangential = slide - nrm * dot(nrm, slide);
    let t_len = length(tangential);
    if t_len > 0.0 {
        let keep = min(friction * push / t_len, 1.0);
        da -= tangential * (keep * wa / w);
    }
    if !(finite3(da) && finite3(old)) {
        return none;
    }
    return ScPair(vec4<f32>(da, 1.0), old);
}

// A vertex–triangle contact: the vertex's correction (w = 1 when it touches, 0 when not)
// and the weights of the point under it.
struct ScContact {
    da: vec4<f32>,
    bary: vec3<f32>,
}

// `self_collision::triangle_correction`: vertex a's correction from a triangle it keeps to
// the side `code` of, with the weights of the point under it. With `near_corner`, an overlap
// older than the substep is undone only up to `sc_near_corner_reach` from the plane where
// that is under the thickness (`i`: the vertex, `k`: the corners; asked only of a contact
// that touches).
fn sc_triangle(a: vec4<f32>, prev_a: vec3<f32>, x0: vec4<f32>, x1: vec4<f32>, x2: vec4<f32>, p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, code: u32, thickness: f32, friction: f32, near_corner: bool, i: u32, k: vec3<u32>) -> ScContact {
    let wa = a.w;
    if !(wa > 0.0) {
        return ScContact(vec4<f32>(0.0), vec3<f32>(0.0));
    }
    let r = sc_project(a.xyz, x0.xyz, x1.xyz, x2.xyz);
    if !r.ok || sc_min3(r.bary) < 0.0 {
        return ScContact(vec4<f32>(0.0), vec3<f32>(0.0));
    }
    var side = 1.0;
    if code == SIDE_BACK || (code == SIDE_FREE && !(r.d >= 0.0)) {
        side = -1.0;
    }
    let ds = side * r.d;
    if ds >= thickness || ds <= -2.5 * thickness {
        return ScContact(vec4<f32>(0.0), vec3<f32>(0.0));
    }
    let bary = r.bary;
    let wt = bary.x * x0.w + bary.y * x1.w + bary.z * x2.w;
    let share = wa / (wa + wt);
    let q = x0.xyz * bary.x + x1.xyz * bary.y + x2.xyz * bary.z;
    let q_prev = p0 * bary.x + p1 * bary.y + p2 * bary.z;
    let approach = side * dot(r.n, (prev_a - q_prev) - (a.xyz - q));
    var depenetration = SC_DEPENETRATION * thickness;
    if near_corner {
        let meet = sc_near_corner_reach(i, k.x, k.y, k.z);
        if meet < thickness {
            depenetration = min(depenetration, max(meet - ds, 0.0));
        }
    }
    let push = sc_limited_push(thickness - ds, approach, depenetration);
    var da = r.n * (side * push * share);
    let slide = (a.xyz + da - prev_a) - (q - q_prev);
    let tangential = slide - r.n * dot(r.n, slide);
    let t_len = length(tangential);
    if t_len > 0.0 {
        let keep = min(friction * push / t_len, 1.0);
        da -= tangential * (keep * share);
    }
    if !finite3(da) {
        return ScContact(vec4<f32>(0.0), vec3<f32>(0.0));
    }
    return ScContact(vec4<f32>(da, 1.0), bary);
}

// A vertex as the self-collision pass reads it: tethered first when the cloth has tethers.
fn sc_read(i: u32, tethers: bool) -> vec4<f32> {
    if tethers {
        return tethered(i, state[i]);
    }
    return state[i];
}

// Self-collision (Jacobi, CPU twin: `self_collision::self_collide`): vertex `i`'s
// correction, the mean of its touching pairs' and triangles' corrections against the tethered
// positions (each vertex tethers itself and the vertices it reads on the fly, so no pass has
// to come between).
@compute @workgroup_size(64)
fn sc_collide(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
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
    let a = sc_read(i, tethers);
    let prev_a = state[P.prev_at + i].xyz;
    // The vertex keeps its own thickness from the others, and from triangles at most its
    // triangle thickness.
    let thickness = sc_thickness_of(i, cl);
    let triangle_thickness = sc_triangle_thickness_of(i, cl);
    let closed = cloth_closed(c, cl.flags);
    let even = (cl.flags & FLAG_EVEN) != 0u;
    var sum = vec3<f32>(0.0);
    var unmoving = vec3<f32>(0.0);
    var touching = 0.0;
    let count = atomicLoad(&scratch[P.ncount_at + i]);
    for (var k = 0u; k < count; k++) {
        let j = atomicLoad(&scratch[P.nlist_at + i * SC_MAX + k]);
        let b = sc_read(j, tethers);
        let r = sc_pair(a, prev_a, b, state[P.prev_at + j].xyz, thickness, cl.sc_friction);
        sum += r.da.xyz;
        unmoving += r.old;
        touching += r.da.w;
    }
    let tcount = atomicLoad(&scratch[P.tcount_at + i]);
    for (var k = 0u; k < tcount; k++) {
        let slot = atomicLoad(&scratch[P.tlist_at + i * SC_TRI_MAX + k]);
        let tb = P.tri_at + 3u * ((slot & ~BESIDE) >> 2u);
        let k0 = topo[tb];
        let k1 = topo[tb + 1u];
        let k2 = topo[tb + 2u];
        let x0 = sc_read(k0, tethers);
        let x1 = sc_read(k1, tethers);
        let x2 = sc_read(k2, tethers);
        // `self_collision::NearCorner`: capped on a closed cloth, the old overlap limited on
        // an open one of even edges.
        var tt = triangle_thickness;
        if closed {
            tt = sc_capped_thickness(tt, i, k0, k1, k2);
        }
        let contact = sc_triangle(
            a, prev_a, x0, x1, x2,
            state[P.prev_at + k0].xyz, state[P.prev_at + k1].xyz, state[P.prev_at + k2].xyz,
            slot & 3u, tt, cl.sc_friction, even && !closed, i, vec3<u32>(k0, k1, k2),
        );
        let r = contact.da;
        sum += r.xyz;
        touching += r.w;
        // A triangle the vertex was over when the step began takes the reaction at its
        // corners (`self_collision::self_collide`).
        if r.w > 0.0 && (slot & BESIDE) == 0u {
            sc_react(k0, x0.w, contact.bary.x, r.xyz, a.w);
            sc_react(k1, x1.w, contact.bary.y, r.xyz, a.w);
            sc_react(k2, x2.w, contact.bary.z, r.xyz, a.w);
        }
    }
    // The sum and the count: `finish_substep` adds the reactions and takes the mean.
    state[P.corr_at + i] = vec4<f32>(sum, touching);
    state[P.unmoving_at + i] = vec4<f32>(unmoving, 0.0);
}

// `self_collision::REACTION_UNITS`: fixed-point units a metre of the reactions' sums, whose
// order then does not matter.
const SC_REACTION_UNITS: f32 = 67108864.0;

// `self_collision::to_fixed`.
fn sc_fixed(x: f32) -> u32 {
    return bitcast<u32>(i32(round(clamp(x * SC_REACTION_UNITS, -2.0e9, 2.0e9))));
}

// Corner `v` (inverse mass `wc`, weight `b` at the point under the vertex) of a triangle that
// moved a vertex of inverse mass `wa` by `da` takes the reaction (`self_collision::reaction`).
fn sc_react(v: u32, wc: f32, b: f32, da: vec3<f32>, wa: f32) {
    let r = -da * (wc * b / wa);
    if !(wc > 0.0 && b > 0.0 && finite3(r)) {
        return;
    }
    let at = P.react_at + 4u * v;
    atomicAdd(&scratch[at], sc_fixed(r.x));
    atomicAdd(&scratch[at + 1u], sc_fixed(r.y));
    atomicAdd(&scratch[at + 2u], sc_fixed(r.z));
    atomicAdd(&scratch[at + 3u], 1u);
}

// Vertex `i`'s self-collision correction: the mean of its own contacts' corrections (summed
// in `corr_at` by `sc_collide`) and the reactions it took as a corner, which it leaves at zero
// (`self_collision::Reactions::take`); w: how many they are.
fn sc_correction(i: u32) -> vec4<f32> {
    let own = state[P.corr_at + i];
    let at = P.react_at + 4u * i;
    var sum = own.xyz;
    var count = own.w;
    let n = atomicLoad(&scratch[at + 3u]);
    if n != 0u {
        let x = bitcast<i32>(atomicExchange(&scratch[at], 0u));
        let y = bitcast<i32>(atomicExchange(&scratch[at + 1u], 0u));
        let z = bitcast<i32>(atomicExchange(&scratch[at + 2u], 0u));
        atomicStore(&scratch[at + 3u], 0u);
        sum = vec3<f32>(f32(x), f32(y), f32(z)) / SC_REACTION_UNITS + own.xyz;
        count += f32(n);
    }
    if count > 0.0 {
        return vec4<f32>(sum / count, count);
    }
    return vec4<f32>(0.0);
}

// One vertex against one collider (`collider::touch`, after `collide_vertices`' reach test):
// the corrected position in xyz, w = 1 when it was pushed.
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

// `MotionConstraints::constrain` for free vertex `i` at `x` after this substep: within its max
// distance of its target (moved linearly over the step), then out of its backstop sphere.
fn motion_held(i: u32, x: vec4<f32>) -> vec4<f32> {
    let a = frame[S.motion_at + i];
    let b = frame[S.motion_at + P.n + i];
    let target_pos = a.xyz + (b.xyz - a.xyz) * S.t;
    if !finite3(target_pos) {
        return x;
    }
    var q = x.xyz;
    let r = b.w;
    if finite(r) && r >= 0.0 {
        let d = q - target_pos;
        let l2 = dot(d, d);
        if l2 > r * r {
            q = target_pos + d * (r / sqrt(l2));
        }
    }
    let radius = a.w;
    let nb = frame[S.motion_at + 2u * P.n + i];
    if finite(radius) && radius > 0.0 && finite(nb.w) && nb.w >= 0.0 && finite3(nb.xyz) {
        let centre = target_pos - nb.xyz * (radius + nb.w);
        let d = q - centre;
        let l2 = dot(d, d);
        if l2 < radius * radius {
            let l = sqrt(l2);
            if l > 1e-12 {
                q = centre + d * (radius / l);
            } else {
                q = centre + nb.xyz * radius;
            }
        }
    }
    if finite3(q) {
        return vec4<f32>(q, x.w);
    }
    return x;
}

var<workgroup> imp_lin: array<vec3<f32>, 64>;
var<workgroup> imp_ang: array<vec3<f32>, 64>;

// The end of a substep for every vertex: tethers, the self-collision correction, the motion
// targets (skinned clothing), then the colliders (`collider::collide_vertices`). Each
// workgroup also sums the momentum its vertices gave each collider (−m·Δx/h, and its moment about the collider's origin) into its own slot
// (by the collider's frame slot), over every substep and step of the frame; the host adds the
// slots up after reading them back. Every invocation reaches every barrier.
@compute @workgroup_size(64)
fn finish_substep(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let i = flat_id(gid, groups).x;
    // This workgroup's impulse slots; a workgroup past the vertices (a dispatch split over more
    // dimensions rounds up) has none and writes nothing, nor does any where the frame's
    // impulses did not fit the device (no slots).
    let group = wid.x + (wid.y + wid.z * groups.y) * groups.x;
    let has_slots = group * 64u < P.n && P.collider_slots > 0u;
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
                let correction = sc_correction(i);
                x = vec4<f32>(x.xyz + correction.xyz, x.w);
                // The same share of what its pairs pushed out of an old overlap moves the
                // substep's start too: no velocity from it (`self_collision::self_collide`).
                let old = state[P.unmoving_at + i].xyz;
                if any(old != vec3<f32>(0.0)) && correction.w > 0.0 {
                    prev = prev + old / correction.w;
                    state[P.prev_at + i] = vec4<f32>(prev, state[P.prev_at + i].w);
                }
            }
            if (u32(frame[cloth_step(c)].w + 0.5) & 8u) != 0u {
                x = motion_held(i, x);
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
        if lid.x == 0u && has_slots {
            let slot = P.impulse_at + 6u * (group * P.collider_slots + c.slot.x);
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
