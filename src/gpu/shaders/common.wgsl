// Shared by every cloth kernel: the world's layout, the bindings, and the arithmetic the CPU
// solver does the same way (each function names its CPU twin). The kernels are
// `step_begin.wgsl` (once per step), `solve.wgsl` (the constraints, per substep),
// `contact.wgsl` (tethers, self-collision, colliders, per substep), `step_end.wgsl` and
// `lab.wgsl`; `gpu/kernels.rs` puts them together into one module.
//
// A *world* holds every cloth that steps with the same substeps and iterations, packed in
// shared buffers: cloth `c` owns the vertices `[vbase, vbase + n)` of every per-vertex region.
//
// `state` (vec4): positions (w: inverse mass, 0 when pinned) | substep starts | velocities |
// area vectors | air velocities | [self-collision: corrections | rest positions | the
// corrections' old-overlap parts from vertex–vertex contacts] | each pin's
// position at the step's start | per cloth its status (x: 1 once a position or velocity went
// NaN or infinite, y: 1 once an edge was stretched past the tear threshold, z: steps left in
// which a settings change settles, w: the largest strain after its last settling step) |
// [the XPBD multipliers with several iterations: distances, then hinges].
//
// `cons` (vec4<u32>): distance constraints (a, b: vertices local to their group; rest length
// and material parameter as f32 bits), then hinges, three vec4 each (four local vertices;
// four weights, or the rest angle in the first; the material parameter in the first and, for
// a tearing cloth, the hinge's two triangles (global) in the second and third).
//
// `topo` (u32): per cloth its record (`CLOTH_WORDS`) | per vertex its cloth | per vertex its
// pin (NO_PIN: none) | per group its record (`GROUP_WORDS`) and colour bounds | per vertex
// the triangles it belongs to (offsets, list) and the triangles | with self-collision, per
// vertex the thickness it keeps from triangles over its cloth's (f32 bits), then per vertex
// the triangles whose first corner it is (offsets, list) | tethers | the lab solver's
// edges | the tearing cloths' edges (a, b: global vertices; rest length bits; the slot of
// the edge's distance constraint in `cons`, or `NO_PIN`), then per tearing edge its
// triangles (offsets, list) | the edges of the cloths that settle a settings change (a, b:
// global vertices; rest length bits).
//
// `scratch` (atomic u32): per cloth the fastest squared speed of the step's start (bits) |
// self-collision: hash heads (2 per vertex of the cloth), the next vertex in each bucket, per
// vertex its neighbour count and `SC_MAX` neighbours, per vertex its triangle count and
// `SC_TRI_MAX` triangles (`triangle << 2 | side`) | with tearing, per distance constraint 1
// once `tear_check` found its edge past the threshold, 2 once `tear_release` found its edge
// left without a triangle (either way the constraint holds nothing), then per triangle 1 once
// an edge of it tore, then per cloth 1 once an edge of a closed cloth tore | while a cloth
// settles a settings change, per vertex its speed when the change was made (bits), then per
// cloth the step's largest strain (bits) | per cloth the largest squared speed (bits) a free
// vertex of a cloth that may sleep ended a step of the frame with | the colliders' impulse
// slots.
//
// `frame` (vec4): per step every pin's target | per step and cloth a record (xyz: teleport
// offset; w: 0 not stepped, else 1 + 2 teleporting + 4 carried + 8 held by motion targets
// + 16 stretched; three more vec4 for a carry) | [per step the motion targets, 3 per vertex
// of the world].

struct World {
    h: f32,
    inv_h: f32,
    inv_h2: f32,
    dt: f32,
    n: u32,
    cloths: u32,
    pins: u32,
    steps: u32,
    prev_at: u32,
    vel_at: u32,
    area_at: u32,
    air_at: u32,
    corr_at: u32,
    rest_at: u32,
    pin_start_at: u32,
    status_at: u32,
    lambda_at: u32,
    lambda_bend_at: u32,
    cloth_at: u32,
    vertex_cloth_at: u32,
    vertex_pin_at: u32,
    group_at: u32,
    tri_offsets_at: u32,
    tri_at: u32,
    tether_at: u32,
    lab_at: u32,
    edges_at: u32,
    edges: u32,
    bend_at: u32,
    speed_at: u32,
    head_at: u32,
    next_at: u32,
    ncount_at: u32,
    nlist_at: u32,
    impulse_at: u32,
    impulse_slots: u32,
    collider_slots: u32,
    cloth_step_at: u32,
    tcount_at: u32,
    tlist_at: u32,
    first_tri_at: u32,
    torn_at: u32,
    edge_tris_at: u32,
    dead_at: u32,
    settle_speed_at: u32,
    settle_strain_at: u32,
    settle_edges_at: u32,
    settle_edges: u32,
    sc_triangle_scale_at: u32,
    // Per vertex, four atomics: the reactions of the self-collision contacts it is a corner
    // of (x, y, z in SC_REACTION_UNITS, and their number).
    react_at: u32,
    // Per cloth, 1 once an edge of a closed cloth tore (with tearing): it is closed no more.
    opened_at: u32,
    // With self-collision, per vertex the part of its vertex–vertex corrections that undoes
    // an old overlap (`sc_collide`), moved without velocity (`finish_substep`).
    unmoving_at: u32,
    // Per cloth that may sleep, the largest squared speed (bits) a free vertex ended a step
    // of this frame with (`note_speed`; the host zeroes it before each frame and reads it back).
    frame_speed_at: u32,
    // With these the uniform's size is a multiple of 16 bytes.
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// One substep of one step (binding 1, a dynamic offset per substep).
struct Substep {
    step: u32,
    substep: u32,
    t: f32,
    // first collider of this substep in `colliders`, and how many the step has
    pose_at: u32,
    colliders: u32,
    // this step's pin targets in `frame`
    pin_at: u32,
    // this step's cloth records in `frame`
    cloth_step_at: u32,
    // this step's motion targets in `frame`: per vertex of the world its start (w: backstop
    // radius), then its end (w: max distance), then its backstop normal (w: distance)
    motion_at: u32,
}

// The groups one `solve` dispatch projects (binding 2, a dynamic offset per level).
struct Level {
    first: u32,
    count: u32,
    // bit 0: integrate the groups' vertices first (the parts, first iteration); bit 1: the
    // first iteration (multipliers start from zero)
    flags: u32,
    _pad: u32,
}

struct Collider {
    // translation in xyz, scale in w
    from_t: vec4<f32>,
    from_r: vec4<f32>,
    to_t: vec4<f32>,
    to_r: vec4<f32>,
    // sphere: radius | box: half extents | capsule: half length, radius
    shape: vec4<f32>,
    // thickness, friction, squared reach (bounding ball + thickness), kind (0 sphere,
    // 1 box, 2 capsule, 3 plane, 4 baked SDF grid: origin in shape.xyz, cell in shape.w)
    misc: vec4<f32>,
    // SDF grid: samples along x, y, z and the first sample's index in `sdf`
    grid: vec4<u32>,
    // x: the collider's impulse slot in the frame
    slot: vec4<u32>,
}

// A cloth's record in `topo`, read into registers.
struct Cloth {
    vbase: u32,
    n: u32,
    pin_base: u32,
    pins: u32,
    flags: u32,
    gravity_h: vec3<f32>,
    damp: f32,
    max_speed: f32,
    air: vec3<f32>,
    sc_thickness: f32,
    sc_friction: f32,
    tear: f32,
    status: u32,
    head_base: u32,
    // 1.25 × the longest rest edge (`self_collision::first_corner_reach`; capped per vertex
    // at 4 of its thicknesses), and the thickest vertex's thickness.
    sc_tri_reach: f32,
    sc_thickest: f32,
}

const CLOTH_WORDS: u32 = 20u;
const GROUP_WORDS: u32 = 16u;
const NO_PIN: u32 = 0xffffffffu;
const SC_MAX: u32 = 32u;
const SC_TRI_MAX: u32 = 64u;
const SIDE_FRONT: u32 = 0u;
const SIDE_BACK: u32 = 1u;
const SIDE_FREE: u32 = 2u;
const BESIDE: u32 = 0x80000000u;

const FLAG_AIR: u32 = 1u;
const FLAG_XPBD: u32 = 2u;
const FLAG_DIHEDRAL: u32 = 4u;
const FLAG_ACCUMULATE: u32 = 8u;
const FLAG_SC: u32 = 16u;
const FLAG_TETHERS: u32 = 32u;
const FLAG_TEARING: u32 = 64u;
const FLAG_SYMMETRIC: u32 = 128u;
const FLAG_CLOSED: u32 = 256u;
const FLAG_EVEN: u32 = 512u;
const FLAG_SLEEP: u32 = 1024u;

// Whether triangle `t` (global) of a cloth with record `flags` lost an edge to a tear
// (`tear_check` flags it dead): until the host's tear removes it from the topology it counts
// in nothing (air, self-collision, the drawn mesh), as on the CPU, whose tear removes it at
// once.
fn triangle_torn(t: u32, flags: u32) -> bool {
    return (flags & FLAG_TEARING) != 0u && atomicLoad(&scratch[P.dead_at + t]) != 0u;
}

// Whether cloth `c` with record `flags` is closed (`Topology::is_closed`): built closed and no
// edge of it torn since (`tear_check` marks it), as on the CPU, whose tear opens the topology
// at once, until the host's tear rebuilds the cloth's record without `FLAG_CLOSED`.
fn cloth_closed(c: u32, flags: u32) -> bool {
    return (flags & FLAG_CLOSED) != 0u
        && ((flags & FLAG_TEARING) == 0u || atomicLoad(&scratch[P.opened_at + c]) == 0u);
}

@group(0) @binding(0) var<uniform> P: World;
@group(0) @binding(1) var<uniform> S: Substep;
@group(0) @binding(2) var<uniform> L: Level;
@group(0) @binding(3) var<storage, read_write> state: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> cons: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> scratch: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read> frame: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> colliders: array<Collider>;
@group(0) @binding(8) var<storage, read> topo: array<u32>;
@group(0) @binding(9) var<storage, read> sdf: array<f32>;

fn f32_at(i: u32) -> f32 {
    return bitcast<f32>(topo[i]);
}

fn cloth_of(c: u32) -> Cloth {
    let b = P.cloth_at + c * CLOTH_WORDS;
    var r: Cloth;
    r.vbase = topo[b];
    r.n = topo[b + 1u];
    r.pin_base = topo[b + 2u];
    r.pins = topo[b + 3u];
    r.flags = topo[b + 4u];
    r.gravity_h = vec3<f32>(f32_at(b + 5u), f32_at(b + 6u), f32_at(b + 7u));
    r.damp = f32_at(b + 8u);
    r.max_speed = f32_at(b + 9u);
    r.air = vec3<f32>(f32_at(b + 10u), f32_at(b + 11u), f32_at(b + 12u));
    r.sc_thickness = f32_at(b + 13u);
    r.sc_friction = f32_at(b + 14u);
    r.tear = f32_at(b + 15u);
    r.status = topo[b + 16u];
    r.head_base = topo[b + 17u];
    r.sc_tri_reach = f32_at(b + 18u);
    r.sc_thickest = f32_at(b + 19u);
    return r;
}

fn vertex_cloth(i: u32) -> u32 {
    return topo[P.vertex_cloth_at + i];
}

fn vertex_pin(i: u32) -> u32 {
    return topo[P.vertex_pin_at + i];
}

// `vec4`s of a cloth's record per step in `frame` (`world.rs`'s `CLOTH_STEP_VEC4S`): flags
// (w: 1 takes the step, + 2 teleports, + 4 is carried, + 8 held by motion targets, + 16 its
// carry stretches; 0 sits it out) with the teleport
// offset (xyz), then the carried motion's matrix columns with its offset in their w.
const CLOTH_STEP_VEC4S: u32 = 4u;

// Cloth `c`'s record in this step.
fn cloth_step(c: u32) -> u32 {
    return S.cloth_step_at + CLOTH_STEP_VEC4S * c;
}

// Whether cloth `c` takes part in this step.
fn cloth_active(c: u32) -> bool {
    return frame[cloth_step(c)].w > 0.5;
}

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

// `limits::within_range`
fn within_range(p: vec3<f32>) -> bool {
    return finite3(p) && max(max(abs(p.x), abs(p.y)), abs(p.z)) <= MAX_COORDINATE;
}

// The end of a step for a free vertex (velocity `v`) of cloth `c` with flags `flags`: a
// cloth that may sleep takes its squared speed into the frame's largest (non-negative floats
// order as their bits do; CPU twin: `ClothState::max_free_speed_squared`, the same maximum).
// Every vertex of a cloth writes the same word: one slower than the largest so far only reads
// it, so that few of them queue for the atomic.
fn note_speed(c: u32, flags: u32, v: vec3<f32>) {
    if (flags & FLAG_SLEEP) != 0u {
        var bits = bitcast<u32>(dot(v, v));
        if !finite(bitcast<f32>(bits)) {
            bits = 0x7f800000u;
        }
        let at = P.frame_speed_at + c;
        if bits > atomicLoad(&scratch[at]) {
            atomicMax(&scratch[at], bits);
        }
    }
}

// `step::substeps::clamp_speed`
fn clamp_speed(v: vec4<f32>, m: f32) -> vec4<f32> {
    let s2 = dot(v, v);
    if s2 > m * m {
        return v * (m / sqrt(s2));
    }
    return v;
}

// `batches::Mode::lanes`: (α̃, k)
fn alpha_k(param: f32, xpbd: bool) -> vec2<f32> {
    if xpbd {
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

// `air::air_force` (air: drag, lift, friction)
fn air_force(area: vec3<f32>, v_rel: vec3<f32>, air: vec3<f32>) -> vec3<f32> {
    let a = length(area);
    let s2 = dot(v_rel, v_rel);
    if !(a > 0.0 && s2 > 0.0 && finite(a) && finite(s2)) {
        return vec3<f32>(0.0);
    }
    let n = area / a;
    let s = sqrt(s2);
    let dir = v_rel / s;
    let c = dot(dir, n);
    let pressure = (-air.x * abs(c)) * dir + (air.y * c) * (c * dir - n);
    let tangential = v_rel - dot(v_rel, n) * n;
    return a * (s2 * pressure - (air.z * s) * tangential);
}

// `air::air_velocity_change`
fn air_velocity_change(area: vec3<f32>, v_rel: vec3<f32>, inv_mass: f32, h: f32, air: vec3<f32>) -> vec3<f32> {
    let dv = air_force(area, v_rel, air) * (h * inv_mass);
    let s = length(v_rel);
    let m = length(dv);
    if !(m > 0.0 && finite(m)) {
        return vec3<f32>(0.0);
    }
    return dv / (1.0 + m / s);
}

// The linear index (in x) of an invocation of a 64-wide kernel dispatched over `groups`
// workgroups: y and z > 1 only where x alone would pass the adapter's per-dimension limit
// (`kernels::flat_groups`).
fn flat_id(gid: vec3<u32>, groups: vec3<u32>) -> vec3<u32> {
    return vec3<u32>(gid.x + (gid.y + gid.z * groups.y) * groups.x * 64u, 0u, 0u);
}
