// The cloth step on the GPU: one entry point per stage of `solver::step`, reading the layouts
// that `gpu::data` builds from the CPU solver's own `ConstraintBatches`, `Topology` and pins.
// Each function says which CPU function it mirrors; `tests/gpu_parity.rs` runs both.
//
// State (binding 2) is one array of vec4, in regions of `n` vertices:
//   [0, n) positions (w: inverse mass, 0 when pinned) | [n, 2n) positions at the substep's
//   start | [2n, 3n) velocities | [3n, 4n) area vectors | [4n, 5n) air velocity |
//   [5n, 5n + pins) pinned positions at the step's start | [5n + pins] status (x: 1 once a
//   position or velocity went NaN or infinite; y: 1 once an edge was stretched past the tear
//   threshold) | from `lambda_base`: the XPBD multipliers
//   (distances, then hinges) | with self-collision, from `rest_base`: rest positions, and
//   from `corr_base`: each vertex's self-collision correction.
//
// `scratch` (binding 5, atomics), with self-collision: [0] the fastest squared speed (bits) |
// per hash bucket its count, start (one more) and cursor | the vertices sorted by bucket |
// per vertex its neighbour count | `sc_max` neighbour slots per vertex. From `impulse_base`:
// per collide workgroup and collider, the impulse on the collider (linear, angular: 6 f32 as
// bits, each written by one invocation only).
//
// `topo` (binding 9): [per-vertex triangle offsets (n + 1) | incident triangles | triangles
// (3 each) | tethers: per-vertex record offsets (n + 1) | records (pin, max length bits) |
// lab solver: per-vertex offsets (n + 1) | per incident edge, in edge order, (other end,
// rest length bits)].

struct Params {
    // gravity·h in xyz, h in w
    gravity_h: vec4<f32>,
    inv_h: f32,
    damp: f32,
    max_speed: f32,
    inv_h2: f32,
    // ½ρC drag, lift, friction; w: 1 when the air acts
    air: vec4<f32>,
    n: u32,
    pins: u32,
    colliders: u32,
    accumulate: u32,
    xpbd: u32,
    distances: u32,
    // start of the triangle list in `topo` (the per-vertex incidence list starts at n + 1)
    tri_base: u32,
    // distance + bending multipliers
    lambdas: u32,
    // start of the tether offsets in `topo`; 0: no tethers
    tether_base: u32,
    // index of the status vec4 in `state`
    status: u32,
    // 1: bends are dihedral hinges (rest angle in `a.x`), 0: isometric
    dihedral: u32,
    lambda_base: u32,
    rest_base: u32,
    corr_base: u32,
    // hash buckets (0: no self-collision) and neighbour slots per vertex
    sc_size: u32,
    sc_max: u32,
    sc_counts: u32,
    sc_starts: u32,
    sc_cursor: u32,
    sc_entries: u32,
    sc_ncount: u32,
    sc_nlist: u32,
    // 1: sum the colliders' impulses; where their slots start in `scratch`, and how many
    // words they take (6 per collide workgroup and collider: linear, angular)
    impulses: u32,
    impulse_base: u32,
    impulse_slots: u32,
    // the lab solver: where its per-vertex edge lists start in `topo` (0: not the lab solver);
    // `damp` then holds its velocity keep
    lab_base: u32,
    _pad1: u32,
    _pad2: u32,
    // self-collision thickness, friction, the step's length; the tear threshold (0: none)
    sc: vec4<f32>,
}

// One substep (binding 1, a dynamic offset per substep).
struct Substep {
    substep: u32,
    pin_base: u32,
    pose_base: u32,
    // 1 when the cloth teleports at the start of this step (first substep only)
    snap: u32,
    t: f32,
    // the teleport's offset
    ox: f32,
    oy: f32,
    oz: f32,
}

// One range of constraints (binding 8, a dynamic offset per colour).
struct Range {
    first: u32,
    count: u32,
    _pad0: u32,
    _pad1: u32,
}

struct Distance {
    a: u32,
    b: u32,
    rest: f32,
    param: f32,
}

struct Bend {
    v: vec4<u32>,
    a: vec4<f32>,
    // x: the material parameter
    param: vec4<f32>,
}

struct Pin {
    vertex: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    target_pos: vec4<f32>,
}

struct Collider {
    // translation in xyz, scale in w
    from_t: vec4<f32>,
    from_r: vec4<f32>,
    to_t: vec4<f32>,
    to_r: vec4<f32>,
    // sphere: radius | box: half extents | capsule: half height, radius
    shape: vec4<f32>,
    // thickness, friction, squared reach (bounding ball + thickness), kind (0 sphere,
    // 1 box, 2 capsule, 3 plane, 4 baked SDF grid: origin in shape.xyz, cell in shape.w)
    misc: vec4<f32>,
    // SDF grid: samples along x, y, z and the first sample's index in `sdf`
    grid: vec4<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<uniform> S: Substep;
@group(0) @binding(2) var<storage, read_write> state: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> distances: array<Distance>;
@group(0) @binding(4) var<storage, read> bends: array<Bend>;
@group(0) @binding(5) var<storage, read_write> scratch: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read> pins: array<Pin>;
@group(0) @binding(7) var<storage, read> colliders: array<Collider>;
@group(0) @binding(8) var<uniform> R: Range;
@group(0) @binding(9) var<storage, read> topo: array<u32>;
@group(0) @binding(10) var<storage, read> sdf: array<f32>;

const MIN_LENGTH: f32 = 1e-9;
const MAX_ALPHA_TILDE: f32 = 1e30;
const MAX_COORDINATE: f32 = 1e7;

// Finite without trusting NaN comparisons (GPU compilers may assume there are none).
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn finite3(v: vec3<f32>) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

// `state::within_range`
fn within_range(p: vec3<f32>) -> bool {
    return finite3(p) && max(max(abs(p.x), abs(p.y)), abs(p.z)) <= MAX_COORDINATE;
}

// `step::clamp_speed`
fn clamp_speed(v: vec4<f32>, m: f32) -> vec4<f32> {
    let s2 = dot(v, v);
    if s2 > m * m {
        return v * (m / sqrt(s2));
    }
    return v;
}

// `batches::Mode::lanes`: (α̃, k)
fn alpha_k(param: f32) -> vec2<f32> {
    if P.xpbd != 0u {
        return vec2<f32>(min(param * P.inv_h2, MAX_ALPHA_TILDE), 1.0);
    }
    return vec2<f32>(0.0, param);
}

// glam's `Quat * Vec3`
fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let b = q.xyz;
    let b2 = dot(b, b);
    return v * (q.w * q.w - b2) + b * (dot(v, b) * 2.0) + cross(b, v) * (q.w * 2.0);
}

// `Pose::apply`
fn pose_apply(t: vec4<f32>, r: vec4<f32>, p: vec3<f32>) -> vec3<f32> {
    return t.xyz + rotate(r, p * t.w);
}

// `Pose::inverse_apply`
fn pose_inverse_apply(t: vec4<f32>, r: vec4<f32>, p: vec3<f32>) -> vec3<f32> {
    return rotate(vec4<f32>(-r.xyz, r.w), p - t.xyz) / t.w;
}

// `Vec3::try_normalize(..).unwrap_or(fallback)`
fn try_normalize(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let r = 1.0 / length(v);
    if finite(r) && r > 0.0 {
        return v * r;
    }
    return fallback;
}

fn signum(v: vec3<f32>) -> vec3<f32> {
    return select(vec3<f32>(-1.0), vec3<f32>(1.0), v >= vec3<f32>(0.0));
}

// `Shape::distance`: outward normal in xyz, signed distance in w.
fn shape_distance(kind: u32, s: vec4<f32>, p: vec3<f32>) -> vec4<f32> {
    switch kind {
        case 0u: {
            let len = length(p);
            return vec4<f32>(try_normalize(p, vec3<f32>(0.0, 1.0, 0.0)), len - s.x);
        }
        case 1u: {
            let q = abs(p) - s.xyz;
            let outside = max(q, vec3<f32>(0.0));
            if dot(outside, outside) > 0.0 {
                let o = outside * signum(p);
                return vec4<f32>(o * (1.0 / length(o)), length(outside));
            }
            var axis = vec3<f32>(0.0, 0.0, 1.0);
            if q.x >= q.y && q.x >= q.z {
                axis = vec3<f32>(1.0, 0.0, 0.0);
            } else if q.y >= q.z {
                axis = vec3<f32>(0.0, 1.0, 0.0);
            }
            return vec4<f32>(axis * signum(p), max(max(q.x, q.y), q.z));
        }
        case 2u: {
            let c = vec3<f32>(0.0, clamp(p.y, -s.x, s.x), 0.0);
            let d = p - c;
            return vec4<f32>(try_normalize(d, vec3<f32>(1.0, 0.0, 0.0)), length(d) - s.y);
        }
        default: {
            return vec4<f32>(0.0, 1.0, 0.0, p.y);
        }
    }
}

fn sdf_at(g: vec4<u32>, i: u32, j: u32, k: u32) -> f32 {
    return sdf[g.w + i + g.x * (j + g.y * k)];
}

// `SdfGrid::sample`: trilinear distance and the gradient of the interpolant (outward normal
// in xyz, signed distance in w); outside the grid, measured from the surface point nearest
// the closest border sample.
fn sdf_sample(origin: vec3<f32>, cell: f32, g: vec4<u32>, p: vec3<f32>) -> vec4<f32> {
    let top = vec3<f32>(g.xyz - vec3<u32>(1u));
    let gp = (p - origin) / cell;
    let gc = clamp(gp, vec3<f32>(0.0), top);
    let outside = (gp - gc) * cell;
    let base = max(min(floor(gc), top - vec3<f32>(1.0)), vec3<f32>(0.0));
    let f = gc - base;
    let i = u32(base.x);
    let j = u32(base.y);
    let k = u32(base.z);
    let c000 = sdf_at(g, i, j, k);
    let c100 = sdf_at(g, i + 1u, j, k);
    let c010 = sdf_at(g, i, j + 1u, k);
    let c110 = sdf_at(g, i + 1u, j + 1u, k);
    let c001 = sdf_at(g, i, j, k + 1u);
    let c101 = sdf_at(g, i + 1u, j, k + 1u);
    let c011 = sdf_at(g, i, j + 1u, k + 1u);
    let c111 = sdf_at(g, i + 1u, j + 1u, k + 1u);
    let c00 = lerp(c000, c100, f.x);
    let c10 = lerp(c010, c110, f.x);
    let c01 = lerp(c001, c101, f.x);
    let c11 = lerp(c011, c111, f.x);
    let c0 = lerp(c00, c10, f.y);
    let c1 = lerp(c01, c11, f.y);
    let d = lerp(c0, c1, f.z);
    let gx = lerp(lerp(c100 - c000, c110 - c010, f.y), lerp(c101 - c001, c111 - c011, f.y), f.z);
    let gy = lerp(lerp(c010 - c000, c110 - c100, f.x), lerp(c011 - c001, c111 - c101, f.x), f.z);
    let gz = lerp(lerp(c001 - c000, c101 - c100, f.x), lerp(c011 - c010, c111 - c110, f.x), f.y);
    let grad = vec3<f32>(gx, gy, gz);
    if dot(outside, outside) > 0.0 {
        let border = origin + gc * cell;
        let surface = border - try_normalize(grad, vec3<f32>(0.0)) * d;
        let to_p = p - surface;
        return vec4<f32>(try_normalize(to_p, vec3<f32>(0.0, 1.0, 0.0)), length(to_p));
    }
    return vec4<f32>(try_normalize(grad, vec3<f32>(0.0, 1.0, 0.0)), d);
}

// glam's `lerp` as the CPU writes it: a + (b − a)·t
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    return a + (b - a) * t;
}

// `air::air_force`
fn air_force(area: vec3<f32>, v_rel: vec3<f32>) -> vec3<f32> {
    let a = length(area);
    let s2 = dot(v_rel, v_rel);
    if !(a > 0.0 && s2 > 0.0 && finite(a) && finite(s2)) {
        return vec3<f32>(0.0);
    }
    let n = area / a;
    let s = sqrt(s2);
    let dir = v_rel / s;
    let c = dot(dir, n);
    let pressure = (-P.air.x * abs(c)) * dir + (P.air.y * c) * (c * dir - n);
    let tangential = v_rel - dot(v_rel, n) * n;
    return a * (s2 * pressure - (P.air.z * s) * tangential);
}

// `air::air_velocity_change`
fn air_velocity_change(area: vec3<f32>, v_rel: vec3<f32>, inv_mass: f32, h: f32) -> vec3<f32> {
    let dv = air_force(area, v_rel) * (h * inv_mass);
    let s = length(v_rel);
    let m = length(dv);
    if !(m > 0.0 && finite(m)) {
        return vec3<f32>(0.0);
    }
    return dv / (1.0 + m / s);
}

// The teleport rule, at the start of a step: the whole cloth moves by the pins' mean jump
// (CPU twin: `ClothState::teleport` in solver/step/teleport.rs, which the plugin calls with
// `teleport_offset`; its pin snap is `pins_begin` below).
@compute @workgroup_size(64)
fn teleport(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n || S.snap == 0u {
        return;
    }
    let o = vec4<f32>(S.ox, S.oy, S.oz, 0.0);
    state[i] += o;
    state[P.n + i] += o;
}

// Start of a step: where the pins start from (`ClothState::pin_starts`); after a teleport the
// pins first snap to their targets (`ClothState::snap_pins`).
@compute @workgroup_size(64)
fn pins_begin(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.pins {
        return;
    }
    let pin = pins[S.pin_base + i];
    if S.snap != 0u {
        let at = vec4<f32>(pin.target_pos.xyz, 0.0);
        state[pin.vertex] = at;
        state[P.n + pin.vertex] = at;
        state[2u * P.n + pin.vertex] = vec4<f32>(0.0);
    }
    state[5u * P.n + i] = state[pin.vertex];
}

// `air::vertex_area_vectors`, per vertex over its triangles in triangle order (the CPU's
// summation order).
@compute @workgroup_size(64)
fn areas(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    var acc = vec3<f32>(0.0);
    for (var k = topo[i]; k < topo[i + 1u]; k++) {
        let t = P.tri_base + 3u * topo[k];
        let a = state[topo[t]].xyz;
        let b = state[topo[t + 1u]].xyz;
        let c = state[topo[t + 2u]].xyz;
        let third = cross(b - a, c - a) / 6.0;
        if finite3(third) {
            acc += third;
        }
    }
    state[3u * P.n + i] = vec4<f32>(acc, 0.0);
}

// Pins at the start of a substep (`finish_pin_velocities`, then `ClothState::place_pins`).
@compute @workgroup_size(64)
fn pins_substep(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.pins {
        return;
    }
    let pin = pins[S.pin_base + i];
    let v = pin.vertex;
    let n = P.n;
    if S.substep > 0u {
        state[2u * n + v] = vec4<f32>((state[v].xyz - state[n + v].xyz) * P.inv_h, 0.0);
    }
    state[n + v] = state[v];
    let a = state[5u * n + i].xyz;
    state[v] = vec4<f32>(a * (1.0 - S.t) + pin.target_pos.xyz * S.t, 0.0);
}

// `step::run_part` with `finish_velocity` (after the first substep) and `integrate`.
@compute @workgroup_size(64)
fn integrate(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let x = state[i];
    if !(x.w > 0.0) {
        return;
    }
    let h = P.gravity_h.w;
    var v = state[2u * n + i];
    if S.substep > 0u {
        v = clamp_speed((x - state[n + i]) * P.inv_h, P.max_speed);
    }
    state[n + i] = x;
    var u = v * P.damp + vec4<f32>(P.gravity_h.xyz, 0.0);
    if P.air.w != 0.0 {
        let wind = state[4u * n + i].xyz;
        u += vec4<f32>(air_velocity_change(state[3u * n + i].xyz, u.xyz - wind, x.w, h), 0.0);
    }
    state[2u * n + i] = u;
    state[i] = x + u * h;
}

// `distance::distance_correction` applied to constraint `i`.
fn project_distance(i: u32) {
    let c = distances[i];
    let pa = state[c.a];
    let pb = state[c.b];
    let ak = alpha_k(c.param);
    var l = 0.0;
    if P.accumulate != 0u {
        l = state[P.lambda_base + i].x;
    }
    let wa = pa.w;
    let wb = pb.w;
    let d = pa.xyz - pb.xyz;
    let len = sqrt(dot(d, d));
    // One division: f = Δλ/len scales the unnormalised direction d (CPU twin:
    // solver::constraints::distance::distance_correction).
    var f = ak.y * (-(len - c.rest) - ak.x * l) / ((wa + wb + ak.x) * len);
    if !(len > MIN_LENGTH) || !(wa + wb > 0.0) {
        f = 0.0;
    }
    state[c.a] = vec4<f32>(pa.xyz + d * (wa * f), wa);
    state[c.b] = vec4<f32>(pb.xyz + d * (-(wb * f)), wb);
    if P.accumulate != 0u {
        state[P.lambda_base + i].x = l + f * len;
    }
}

// `isometric::iso_correction` applied to hinge `j`.
fn project_bend(j: u32) {
    let c = bends[j];
    let x0 = state[c.v.x];
    let x1 = state[c.v.y];
    let x2 = state[c.v.z];
    let x3 = state[c.v.w];
    let a = c.a;
    let ak = alpha_k(c.param.x);
    var l = vec3<f32>(0.0);
    if P.accumulate != 0u {
        l = state[P.lambda_base + P.distances + j].xyz;
    }
    let cc = x0.xyz * a.x + x1.xyz * a.y + x2.xyz * a.z + x3.xyz * a.w;
    let g = x0.w * a.x * a.x + x1.w * a.y * a.y + x2.w * a.z * a.z + x3.w * a.w * a.w;
    var scale = 0.0;
    if g > 1e-20 {
        scale = -ak.y / (g + ak.x);
    }
    let dl = (cc + l * ak.x) * scale;
    state[c.v.x] = vec4<f32>(x0.xyz + dl * (x0.w * a.x), x0.w);
    state[c.v.y] = vec4<f32>(x1.xyz + dl * (x1.w * a.y), x1.w);
    state[c.v.z] = vec4<f32>(x2.xyz + dl * (x2.w * a.z), x2.w);
    state[c.v.w] = vec4<f32>(x3.xyz + dl * (x3.w * a.w), x3.w);
    if P.accumulate != 0u {
        state[P.lambda_base + P.distances + j] = vec4<f32>(l + dl, 0.0);
    }
}

// `bending::bend_correction` applied to dihedral hinge `j` (signed angle, rest angle in `a.x`).
fn project_dihedral(j: u32) {
    let c = bends[j];
    let x0 = state[c.v.x];
    let x1 = state[c.v.y];
    let x2 = state[c.v.z];
    let x3 = state[c.v.w];
    let ak = alpha_k(c.param.x);
    var l = 0.0;
    if P.accumulate != 0u {
        l = state[P.lambda_base + P.distances + j].x;
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
    let cc = psi - c.a.x;
    let g = x0.w * dot(q1, q1) + x1.w * dot(q2, q2) + x2.w * dot(q3, q3) + x3.w * dot(q4, q4);
    let s2 = s * s;
    var base = ak.y * (-cc - ak.x * l) / (g + ak.x * s2);
    if !(g > 1e-20) || !(l23 > eps) || !(l24 > eps) {
        base = 0.0;
    }
    let f = -(sigma * s * base);
    state[c.v.x] = vec4<f32>(x0.xyz + q1 * (x0.w * f), x0.w);
    state[c.v.y] = vec4<f32>(x1.xyz + q2 * (x1.w * f), x1.w);
    state[c.v.z] = vec4<f32>(x2.xyz + q3 * (x2.w * f), x2.w);
    state[c.v.w] = vec4<f32>(x3.xyz + q4 * (x3.w * f), x3.w);
    if P.accumulate != 0u {
        state[P.lambda_base + P.distances + j] = vec4<f32>(l + s2 * base, 0.0, 0.0, 0.0);
    }
}

fn project_hinge(j: u32) {
    if P.dihedral != 0u {
        project_dihedral(j);
    } else {
        project_bend(j);
    }
}

// `Tethers::project`: each free vertex pulled back within reach of its pins, its
// attachments in order (the anchors are pinned and do not move).
@compute @workgroup_size(64)
fn tethers(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n || P.tether_base == 0u {
        return;
    }
    var x = state[i];
    if x.w <= 0.0 {
        return;
    }
    let b = P.tether_base;
    for (var k = topo[b + i]; k < topo[b + i + 1u]; k += 2u) {
        let anchor = state[topo[k]].xyz;
        let max_len = bitcast<f32>(topo[k + 1u]);
        let d = x.xyz - anchor;
        let len2 = dot(d, d);
        if len2 > max_len * max_len {
            let pulled = anchor + d * (max_len / sqrt(len2));
            if finite3(pulled) {
                x = vec4<f32>(pulled, x.w);
            }
        }
    }
    state[i] = x;
}

// Self-collision (`self_collision::find_self_collision_candidates` in parallel form and
// `self_collide_parallel`): once per step a spatial hash of the positions (counting sort:
// count, scan, scatter) and per vertex the list of vertices it may touch; per substep every
// vertex moves by the mean of its touching pairs' corrections (Jacobi).

// `self_collision::cell_of`
fn sc_cell(p: vec3<f32>, inv: f32) -> vec3<i32> {
    return vec3<i32>(floor(p * inv));
}

// `self_collision::hash`
fn sc_hash(c: vec3<i32>) -> u32 {
    let h = (c.x * 92837111) ^ (c.y * 689287499) ^ (c.z * 283923481);
    return bitcast<u32>(select(h, -h, h < 0)) % P.sc_size;
}

// `self_collision::reach_and_skip`: the query distance (thickness plus a margin for the
// fastest vertex's travel over the step).
fn sc_reach() -> f32 {
    let fastest = sqrt(bitcast<f32>(atomicLoad(&scratch[0])));
    return P.sc.x + min(2.0 * fastest * P.sc.z, 1.5 * P.sc.x);
}

@compute @workgroup_size(64)
fn sc_clear(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        atomicStore(&scratch[0], 0u);
    }
    if i < P.sc_size {
        atomicStore(&scratch[P.sc_counts + i], 0u);
    }
}

// The fastest squared speed of the step's start (positive floats order as their bits).
@compute @workgroup_size(64)
fn sc_speed(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let v = state[2u * P.n + i].xyz;
    let s2 = dot(v, v);
    if finite(s2) {
        atomicMax(&scratch[0], bitcast<u32>(s2));
    }
}

@compute @workgroup_size(64)
fn sc_count(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let p = state[i].xyz;
    if finite3(p) {
        atomicAdd(&scratch[P.sc_counts + sc_hash(sc_cell(p, 1.0 / sc_reach()))], 1u);
    }
}

var<workgroup> sc_partial: array<u32, 256>;

// Exclusive prefix sums of the bucket counts: each of 256 invocations sums a run of buckets,
// one invocation scans the 256 sums, each writes its run's starts.
@compute @workgroup_size(256)
fn sc_scan(@builtin(local_invocation_id) lid: vec3<u32>) {
    let t = lid.x;
    let size = P.sc_size;
    let run = (size + 255u) / 256u;
    let begin = min(t * run, size);
    let end = min(begin + run, size);
    var sum = 0u;
    for (var h = begin; h < end; h++) {
        sum += atomicLoad(&scratch[P.sc_counts + h]);
    }
    sc_partial[t] = sum;
    workgroupBarrier();
    if t == 0u {
        var acc = 0u;
        for (var k = 0u; k < 256u; k++) {
            let v = sc_partial[k];
            sc_partial[k] = acc;
            acc += v;
        }
    }
    workgroupBarrier();
    var acc = sc_partial[t];
    for (var h = begin; h < end; h++) {
        atomicStore(&scratch[P.sc_starts + h], acc);
        atomicStore(&scratch[P.sc_cursor + h], acc);
        acc += atomicLoad(&scratch[P.sc_counts + h]);
    }
    if t == 255u {
        atomicStore(&scratch[P.sc_starts + size], acc);
    }
}

@compute @workgroup_size(64)
fn sc_scatter(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let p = state[i].xyz;
    if finite3(p) {
        let h = sc_hash(sc_cell(p, 1.0 / sc_reach()));
        let slot = atomicAdd(&scratch[P.sc_cursor + h], 1u);
        atomicStore(&scratch[P.sc_entries + slot], i);
    }
}

// Every other vertex in the cells the query ball touches, in the same cell, closer than the
// reach and farther apart at rest than 2.5 thicknesses.
@compute @workgroup_size(64)
fn sc_query(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let p = state[i].xyz;
    var count = 0u;
    if finite3(p) {
        let reach = sc_reach();
        let inv = 1.0 / reach;
        let r2 = reach * reach;
        let skip = 2.5 * P.sc.x;
        let skip2 = skip * skip;
        let rest_i = state[P.rest_base + i].xyz;
        let lo = sc_cell(p - vec3<f32>(reach), inv);
        let hi = sc_cell(p + vec3<f32>(reach), inv);
        for (var z = lo.z; z <= hi.z; z++) {
            for (var y = lo.y; y <= hi.y; y++) {
                for (var x = lo.x; x <= hi.x; x++) {
                    let cell = vec3<i32>(x, y, z);
                    let h = sc_hash(cell);
                    let first = atomicLoad(&scratch[P.sc_starts + h]);
                    let last = atomicLoad(&scratch[P.sc_starts + h + 1u]);
                    for (var k = first; k < last; k++) {
                        let j = atomicLoad(&scratch[P.sc_entries + k]);
                        let q = state[j].xyz;
                        let d = q - p;
                        let r = state[P.rest_base + j].xyz - rest_i;
                        if j != i && all(sc_cell(q, inv) == cell) && dot(d, d) < r2
                            && dot(r, r) > skip2 && count < P.sc_max {
                            atomicStore(&scratch[P.sc_nlist + i * P.sc_max + count], j);
                            count += 1u;
                        }
                    }
                }
            }
        }
    }
    atomicStore(&scratch[P.sc_ncount + i], count);
}

// `self_collision::pair_correction`: vertex a's share; w = 0 when the pair does not touch.
fn sc_pair(a: vec4<f32>, prev_a: vec3<f32>, b: vec4<f32>, prev_b: vec3<f32>) -> vec4<f32> {
    let limit = P.sc.x;
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
        let keep = min(P.sc.y * push / t_len, 1.0);
        da -= tangential * (keep * wa / w);
        db += tangential * (keep * wb / w);
    }
    if !(finite3(da) && finite3(db)) {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(da, 1.0);
}

@compute @workgroup_size(64)
fn sc_collide(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let a = state[i];
    let prev_a = state[n + i].xyz;
    var sum = vec3<f32>(0.0);
    var touching = 0.0;
    let count = atomicLoad(&scratch[P.sc_ncount + i]);
    for (var k = 0u; k < count; k++) {
        let j = atomicLoad(&scratch[P.sc_nlist + i * P.sc_max + k]);
        let c = sc_pair(a, prev_a, state[j], state[n + j].xyz);
        sum += c.xyz;
        touching += c.w;
    }
    var corr = vec3<f32>(0.0);
    if touching > 0.0 {
        corr = sum / touching;
    }
    state[P.corr_base + i] = vec4<f32>(corr, 0.0);
}

@compute @workgroup_size(64)
fn sc_apply(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let x = state[i];
    state[i] = vec4<f32>(x.xyz + state[P.corr_base + i].xyz, x.w);
}

// End of a step: flags an edge stretched past the tear threshold (`tear::overstretched_edges`
// over the distance constraints, one per edge); the plugin reads the state back and tears on
// the CPU, which rebuilds the topology and uploads it again.
@compute @workgroup_size(64)
fn tear_check(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.distances || !(P.sc.w > 1.0) {
        return;
    }
    let c = distances[i];
    let d = state[c.a].xyz - state[c.b].xyz;
    if c.rest > 0.0 && length(d) > P.sc.w * c.rest {
        state[P.status].y = 1.0;
    }
}

// The lab solver of seed 000 (`lab::lab_step`, one per substep): keep a share of the
// velocity, add gravity, move; then per iteration every vertex gathers its edges' projections
// (in edge order, as the CPU sums them) and moves to their average with its own position.

// Pins at rest (the lab step zeroes their velocities after placing them).
@compute @workgroup_size(64)
fn lab_pins(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.pins {
        return;
    }
    state[2u * P.n + pins[S.pin_base + i].vertex] = vec4<f32>(0.0);
}

@compute @workgroup_size(64)
fn lab_integrate(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let x = state[i];
    if x.w == 0.0 {
        return;
    }
    let h = P.gravity_h.w;
    let v = state[2u * n + i].xyz * P.damp + P.gravity_h.xyz;
    state[2u * n + i] = vec4<f32>(v, 0.0);
    state[i] = vec4<f32>(x.xyz + v * h, x.w);
}

// The averaged position, into the substep-start region (free during the lab step).
@compute @workgroup_size(64)
fn lab_gather(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let x = state[i];
    let b = P.lab_base;
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
    state[n + i] = vec4<f32>((weight * x.xyz + sum) / (weight + count), x.w);
}

@compute @workgroup_size(64)
fn lab_apply(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let x = state[i];
    if x.w == 0.0 {
        return;
    }
    let moved = state[n + i].xyz;
    state[2u * n + i] += vec4<f32>((moved - x.xyz) / P.gravity_h.w, 0.0);
    state[i] = vec4<f32>(moved, x.w);
}

// End of a lab substep: free vertices' speeds clamped, substep starts = positions.
@compute @workgroup_size(64)
fn lab_finish(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let x = state[i];
    if x.w > 0.0 {
        state[2u * n + i] = clamp_speed(state[2u * n + i], P.max_speed);
    }
    state[n + i] = x;
}

// After new settings: the positions the previous buffers had (copied into the substep-start
// region) with this upload's inverse masses.
@compute @workgroup_size(64)
fn carry(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    state[i] = vec4<f32>(state[P.n + i].xyz, state[i].w);
}

// End of a step: flags a NaN or infinite position or velocity (`ClothState::is_finite`); the
// plugin reads the flag back and resets the cloth as the CPU does.
@compute @workgroup_size(64)
fn guard(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.n {
        return;
    }
    let x = state[i];
    let v = state[2u * P.n + i];
    if !(finite3(x.xyz) && finite(x.w) && finite3(v.xyz) && finite(v.w)) {
        state[P.status].x = 1.0;
    }
}

// Start of a substep with several iterations: the multipliers start from zero
// (`Part::reset_lambda`).
@compute @workgroup_size(64)
fn lambda_clear(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < P.lambdas {
        state[P.lambda_base + id.x] = vec4<f32>(0.0);
    }
}

// One colour of distance constraints: no two share a vertex, one invocation each.
@compute @workgroup_size(64)
fn distance_colour(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < R.count {
        project_distance(R.first + id.x);
    }
}

// Constraints that found no colour: one invocation, in order.
@compute @workgroup_size(1)
fn distance_serial(@builtin(global_invocation_id) id: vec3<u32>) {
    for (var i = 0u; i < R.count; i++) {
        project_distance(R.first + i);
    }
}

@compute @workgroup_size(64)
fn bend_colour(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < R.count {
        project_hinge(R.first + id.x);
    }
}

@compute @workgroup_size(1)
fn bend_serial(@builtin(global_invocation_id) id: vec3<u32>) {
    for (var i = 0u; i < R.count; i++) {
        project_hinge(R.first + i);
    }
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

// `collide::collide_vertex`. With `P.impulses`, each workgroup also sums the momentum its
// vertices gave each collider (−m·Δx/h, and its moment about the collider's origin) into its
// own slot of the impulse region, over every substep and step of the frame; the plugin adds
// the slots up after reading them back. Every invocation reaches every barrier.
@compute @workgroup_size(64)
fn collide(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
) {
    let i = id.x;
    let n = P.n;
    var x = vec4<f32>(0.0);
    var prev = vec3<f32>(0.0);
    if i < n {
        x = state[i];
        prev = state[n + i].xyz;
    }
    let free = i < n && x.w > 0.0;
    for (var k = 0u; k < P.colliders; k++) {
        let c = colliders[S.pose_base + k];
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
        if P.impulses != 0u {
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
                let slot = P.impulse_base + 6u * (wid.x * P.colliders + k);
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
    }
    if free {
        state[i] = x;
    }
}

// Start of a frame: the impulse slots start from zero.
@compute @workgroup_size(64)
fn impulse_clear(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < P.impulse_slots {
        atomicStore(&scratch[P.impulse_base + id.x], 0u);
    }
}

// End of a step: velocities of the free vertices (`run_part` with `finish_velocity`).
@compute @workgroup_size(64)
fn finish(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    let x = state[i];
    if x.w > 0.0 {
        state[2u * n + i] = clamp_speed((x - state[n + i]) * P.inv_h, P.max_speed);
    }
}

// End of a step: velocities of the pinned vertices (`finish_pin_velocities`).
@compute @workgroup_size(64)
fn pins_finish(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.pins {
        return;
    }
    let v = pins[S.pin_base + i].vertex;
    let n = P.n;
    state[2u * n + v] = vec4<f32>((state[v].xyz - state[n + v].xyz) * P.inv_h, 0.0);
}
