// Writes a cloth's simulated positions and normals into its mesh's vertex slab (the mesh
// allocator's buffer, bound as raw f32s), in the entity's local space: the GPU twin of
// `cloth::writeback` with `MeshShading::update` (normals summed per normal group over the
// drawn mesh triangles, so hard edges stay hard and welded seams stay smooth).
//
// `topo` (binding 2): [particle of each mesh vertex (m) | normal group of each mesh vertex (m)
// | per group the offsets into the incident list (groups + 1) | incident mesh triangles |
// mesh triangles, 3 mesh vertices each] and, with tangents: [per mesh vertex the offsets into
// its incident list (m + 1) | incident drawn triangles | per drawn triangle its corner UVs
// (6 f32 as bits) | with source handedness: per mesh vertex ±1 (f32 bits)] and, for a
// tearing cloth, per drawn triangle its cloth triangle (from `cloth_tri_at`): with the
// world's dead-triangle flags bound (`dead_at`), torn triangles are left out as the CPU's
// tear leaves them out, before the host has read the tear back.
//
// Tangents are `MeshShading::update`'s: per vertex the UV tangents and bitangents of its
// drawn triangles summed (`shading::triangle_tangent`), made orthogonal to the normal and
// given a handedness (`shading::finish_tangent`), then taken to local space.

struct MeshParams {
    // world → local (columns of an affine map: x, y, z axes and translation)
    to_local: mat4x4<f32>,
    // world normal → local normal (transpose of the linear part), w unused
    normal_x: vec4<f32>,
    normal_y: vec4<f32>,
    normal_z: vec4<f32>,
    // the velocity of the motion carried into the step (`CarriedVelocity`: columns of
    // `turn`, the carried pivot, `along`), added to each vertex's own when it is drawn along
    // its velocity; all zero for none
    carry_x: vec4<f32>,
    carry_y: vec4<f32>,
    carry_z: vec4<f32>,
    carry_pivot: vec4<f32>,
    carry_along: vec4<f32>,
    // first float of this mesh in the slab, floats per vertex, float offset of the normal
    base: u32,
    stride: u32,
    normal_offset: u32,
    vertices: u32,
    groups_at: u32,
    offsets_at: u32,
    triangles_at: u32,
    // ±1: a mirrored entity turns the winding around
    flip: f32,
    // float offset of the tangent from the position; 0xffffffff: no tangents
    tangent_offset: u32,
    vertex_offsets_at: u32,
    uvs_at: u32,
    // 0: handedness from the UVs
    handedness_at: u32,
    // the cloth's first particle in `particles` (a world holds several cloths)
    particle_base: u32,
    // a tearing cloth: per drawn triangle its cloth triangle, in `topo`
    cloth_tri_at: u32,
    // its first dead-triangle flag in `dead_flags` (the world's scratch); 0xffffffff: none
    dead_at: u32,
    // the cloth's first velocity in `particles` (the state buffer's velocity region)
    velocity_base: u32,
    // seconds along its velocity each vertex is drawn (`ClothSmoothing`); 0: as stepped
    shift: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> M: MeshParams;
@group(0) @binding(1) var<storage, read> particles: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> topo: array<u32>;
@group(0) @binding(3) var<storage, read_write> slab: array<f32>;
@group(0) @binding(4) var<storage, read> dead_flags: array<u32>;

// Whether drawn triangle `d` tore (the GPU let go of one of its edges): it no longer counts
// in the shading, as the CPU's tear removes it from the drawn triangles.
fn torn(d: u32) -> bool {
    return M.dead_at != 0xffffffffu && dead_flags[M.dead_at + topo[M.cloth_tri_at + d]] != 0u;
}

// Where particle `topo[v]` is drawn: its position, or `x + shift·v` (`ClothSmoothing::place`),
// `v` its velocity plus the carried motion's at `x` (`CarriedVelocity::at`).
fn at(v: u32) -> vec3<f32> {
    let p = particles[M.particle_base + topo[v]].xyz;
    if M.shift == 0.0 {
        return p;
    }
    let d = p - M.carry_pivot.xyz;
    let carried = M.carry_x.xyz * d.x + M.carry_y.xyz * d.y + M.carry_z.xyz * d.z + M.carry_along.xyz;
    return p + (particles[M.velocity_base + topo[v]].xyz + carried) * M.shift;
}

fn uv(t: u32, corner: u32) -> vec2<f32> {
    let o = M.uvs_at + 6u * t + 2u * corner;
    return vec2<f32>(bitcast<f32>(topo[o]), bitcast<f32>(topo[o + 1u]));
}

// `Vec3::try_normalize(..).unwrap_or(fallback)`
fn normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let r = 1.0 / length(v);
    if r > 0.0 && r < 3.0e38 {
        return v * r;
    }
    return fallback;
}

// glam's `Vec3::any_orthonormal_vector`
fn any_orthonormal(n: vec3<f32>) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return vec3<f32>(b, sign + n.y * n.y * a, -n.y);
}

// The world-space tangent with handedness of mesh vertex `v` with world normal `n`.
fn tangent(v: u32, n: vec3<f32>) -> vec4<f32> {
    var tan = vec3<f32>(0.0);
    var bit = vec3<f32>(0.0);
    for (var k = topo[M.vertex_offsets_at + v]; k < topo[M.vertex_offsets_at + v + 1u]; k++) {
        let d = topo[k];
        if torn(d) {
            continue;
        }
        let t = M.triangles_at + 3u * d;
        let p0 = at(topo[t]);
        let q0 = at(topo[t + 1u]) - p0;
        let q1 = at(topo[t + 2u]) - p0;
        let uv0 = uv(d, 0u);
        let uv1 = uv(d, 1u);
        let uv2 = uv(d, 2u);
        let det = (uv1.x - uv0.x) * (uv2.y - uv0.y) - (uv1.y - uv0.y) * (uv2.x - uv0.x);
        if abs(det) < 1e-20 {
            continue;
        }
        let r = 1.0 / det;
        let tp = ((uv2.y - uv0.y) * q0 + (uv0.y - uv1.y) * q1) * r;
        let bp = ((uv0.x - uv2.x) * q0 + (uv1.x - uv0.x) * q1) * r;
        if all(abs(tp) < vec3<f32>(3.0e38)) && all(abs(bp) < vec3<f32>(3.0e38)) {
            tan += tp;
            bit += bp;
        }
    }
    let t = normalize_or(tan - n * dot(n, tan), any_orthonormal(n));
    var w = 1.0;
    if M.handedness_at != 0u {
        w = bitcast<f32>(topo[M.handedness_at + v]);
    } else if dot(cross(n, t), bit) < 0.0 {
        w = -1.0;
    }
    return vec4<f32>(t, w);
}

// The linear index (in x) of an invocation of a 64-wide kernel dispatched over `groups`
// workgroups: y and z > 1 only where x alone would pass the adapter's per-dimension limit
// (`kernels::flat_groups`).
fn flat_id(gid: vec3<u32>, groups: vec3<u32>) -> vec3<u32> {
    return vec3<u32>(gid.x + (gid.y + gid.z * groups.y) * groups.x * 64u, 0u, 0u);
}

@compute @workgroup_size(64)
fn write_mesh(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let v = id.x;
    if v >= M.vertices {
        return;
    }
    let p = (M.to_local * vec4<f32>(at(v), 1.0)).xyz;
    let g = topo[M.groups_at + v];
    var sum = vec3<f32>(0.0);
    for (var k = topo[M.offsets_at + g]; k < topo[M.offsets_at + g + 1u]; k++) {
        if torn(topo[k]) {
            continue;
        }
        let t = M.triangles_at + 3u * topo[k];
        let a = at(topo[t]);
        let b = at(topo[t + 1u]);
        let c = at(topo[t + 2u]);
        let face = cross(b - a, c - a);
        if all(abs(face) < vec3<f32>(3.0e38)) {
            sum += face;
        }
    }
    if M.tangent_offset != 0xffffffffu {
        let tw = tangent(v, normalize_or(sum, vec3<f32>(0.0, 1.0, 0.0)));
        let local_t = normalize_or((M.to_local * vec4<f32>(tw.xyz, 0.0)).xyz, vec3<f32>(1.0, 0.0, 0.0));
        let o = M.base + v * M.stride + M.tangent_offset;
        slab[o] = local_t.x;
        slab[o + 1u] = local_t.y;
        slab[o + 2u] = local_t.z;
        slab[o + 3u] = tw.w;
    }
    let world = sum * M.flip;
    let local = M.normal_x.xyz * world.x + M.normal_y.xyz * world.y + M.normal_z.xyz * world.z;
    let o = M.base + v * M.stride;
    let q = o + M.normal_offset;
    // Where no triangle is left (a torn-off vertex), last frame's normal stays, as on the
    // CPU (`MeshShading::update`); (0, 1, 0) where there is none.
    var n = vec3<f32>(slab[q], slab[q + 1u], slab[q + 2u]);
    let old = length(n);
    if !(old > 0.0 && old < 3.0e38) {
        n = vec3<f32>(0.0, 1.0, 0.0);
    }
    let len = length(local);
    if len > 0.0 && len < 3.0e38 {
        n = local / len;
    }
    slab[o] = p.x;
    slab[o + 1u] = p.y;
    slab[o + 2u] = p.z;
    slab[q] = n.x;
    slab[q + 1u] = n.y;
    slab[q + 2u] = n.z;
}
