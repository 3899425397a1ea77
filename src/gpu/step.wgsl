// The cloth step on the GPU: one entry point per stage of `solver::step`, reading the layouts
// that `gpu::data` builds from the CPU solver's own `ConstraintBatches`, `Topology` and pins.
// Each function says which CPU function it mirrors; `tests/gpu_parity.rs` runs both.
//
// State (binding 2) is one array of vec4, in regions of `n` vertices:
//   [0, n) positions (w: inverse mass, 0 when pinned) | [n, 2n) positions at the substep's
//   start | [2n, 3n) velocities | [3n, 4n) area vectors | [4n, 5n) air velocity |
//   [5n, 5n + pins) pinned positions at the step's start.

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
}

// One substep (binding 1, a dynamic offset per substep).
struct Substep {
    substep: u32,
    pin_base: u32,
    pose_base: u32,
    _pad0: u32,
    t: f32,
    _pad1: f32,
    _pad2: f32,
    _pad3: f32,
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
    // 1 box, 2 capsule, 3 plane)
    misc: vec4<f32>,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<uniform> S: Substep;
@group(0) @binding(2) var<storage, read_write> state: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> distances: array<Distance>;
@group(0) @binding(4) var<storage, read> bends: array<Bend>;
@group(0) @binding(5) var<storage, read_write> lambda: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> pins: array<Pin>;
@group(0) @binding(7) var<storage, read> colliders: array<Collider>;
@group(0) @binding(8) var<uniform> R: Range;
@group(0) @binding(9) var<storage, read> topo: array<u32>;

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

// Start of a step: where the pins start from (`ClothState::pin_starts`).
@compute @workgroup_size(64)
fn pins_begin(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= P.pins {
        return;
    }
    state[5u * P.n + i] = state[pins[S.pin_base + i].vertex];
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
        l = lambda[i].x;
    }
    let wa = pa.w;
    let wb = pb.w;
    let d = pa.xyz - pb.xyz;
    let len = sqrt(dot(d, d));
    var s = ak.y * (-(len - c.rest) - ak.x * l) / (wa + wb + ak.x);
    var inv = 0.0;
    if len > MIN_LENGTH {
        inv = 1.0 / len;
    } else {
        s = 0.0;
    }
    if !(wa + wb > 0.0) {
        s = 0.0;
    }
    let nrm = d * inv;
    state[c.a] = vec4<f32>(pa.xyz + nrm * (wa * s), wa);
    state[c.b] = vec4<f32>(pb.xyz + nrm * (-(wb * s)), wb);
    if P.accumulate != 0u {
        lambda[i].x = l + s;
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
        l = lambda[P.distances + j].xyz;
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
        lambda[P.distances + j] = vec4<f32>(l + dl, 0.0);
    }
}

// Start of a substep with several iterations: the multipliers start from zero
// (`Part::reset_lambda`).
@compute @workgroup_size(64)
fn lambda_clear(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < P.lambdas {
        lambda[id.x] = vec4<f32>(0.0);
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
        project_bend(R.first + id.x);
    }
}

@compute @workgroup_size(1)
fn bend_serial(@builtin(global_invocation_id) id: vec3<u32>) {
    for (var i = 0u; i < R.count; i++) {
        project_bend(R.first + i);
    }
}

// `collide::collide_vertex` (without the impulse sums).
@compute @workgroup_size(64)
fn collide(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let n = P.n;
    if i >= n {
        return;
    }
    var x = state[i];
    if x.w <= 0.0 {
        return;
    }
    let prev = state[n + i].xyz;
    for (var k = 0u; k < P.colliders; k++) {
        let c = colliders[S.pose_base + k];
        let p = x.xyz;
        let off = p - c.to_t.xyz;
        if dot(off, off) > c.misc.z {
            continue;
        }
        let local = pose_inverse_apply(c.to_t, c.to_r, p);
        let dn = shape_distance(u32(c.misc.w), c.shape, local);
        let d = dn.w * c.to_t.w;
        let thickness = c.misc.x;
        if !(d < thickness) {
            continue;
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
            continue;
        }
        x = vec4<f32>(corrected, x.w);
    }
    state[i] = x;
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
