// Writes a cloth's simulated positions and normals into its mesh's vertex slab (the mesh
// allocator's buffer, bound as raw f32s), in the entity's local space: the GPU twin of
// `cloth::writeback` with `MeshShading::update` (normals summed per normal group over the
// drawn mesh triangles, so hard edges stay hard and welded seams stay smooth).
//
// `topo` (binding 2): [particle of each mesh vertex (m) | normal group of each mesh vertex (m)
// | per group the offsets into the incident list (groups + 1) | incident mesh triangles |
// mesh triangles, 3 mesh vertices each].

struct MeshParams {
    // world → local (columns of an affine map: x, y, z axes and translation)
    to_local: mat4x4<f32>,
    // world normal → local normal (transpose of the linear part), w unused
    normal_x: vec4<f32>,
    normal_y: vec4<f32>,
    normal_z: vec4<f32>,
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
}

@group(0) @binding(0) var<uniform> M: MeshParams;
@group(0) @binding(1) var<storage, read> particles: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> topo: array<u32>;
@group(0) @binding(3) var<storage, read_write> slab: array<f32>;

fn at(v: u32) -> vec3<f32> {
    return particles[topo[v]].xyz;
}

@compute @workgroup_size(64)
fn write_mesh(@builtin(global_invocation_id) id: vec3<u32>) {
    let v = id.x;
    if v >= M.vertices {
        return;
    }
    let p = (M.to_local * vec4<f32>(at(v), 1.0)).xyz;
    let g = topo[M.groups_at + v];
    var sum = vec3<f32>(0.0);
    for (var k = topo[M.offsets_at + g]; k < topo[M.offsets_at + g + 1u]; k++) {
        let t = M.triangles_at + 3u * topo[k];
        let a = at(topo[t]);
        let b = at(topo[t + 1u]);
        let c = at(topo[t + 2u]);
        let face = cross(b - a, c - a);
        if all(abs(face) < vec3<f32>(3.0e38)) {
            sum += face;
        }
    }
    let world = sum * M.flip;
    let local = M.normal_x.xyz * world.x + M.normal_y.xyz * world.y + M.normal_z.xyz * world.z;
    var n = vec3<f32>(0.0, 1.0, 0.0);
    let len = length(local);
    if len > 0.0 && len < 3.0e38 {
        n = local / len;
    }
    let o = M.base + v * M.stride;
    slab[o] = p.x;
    slab[o + 1u] = p.y;
    slab[o + 2u] = p.z;
    let q = o + M.normal_offset;
    slab[q] = n.x;
    slab[q + 1u] = n.y;
    slab[q + 2u] = n.z;
}
