// Hides a tearing GPU cloth's torn triangles from its drawn mesh in the frames between the
// GPU's tear and the host's: the GPU lets go of a torn edge at once (`tear_check`), and the
// host removes its triangles from the index buffer when it has read the tear back, a few
// frames later. Until then each drawn triangle whose cloth triangle is dead (the scratch
// buffer's dead-triangle flags) becomes (0, 0, 0) in the mesh's index slab, which draws
// nothing. The CPU twin is `gpu::mesh::hide_torn_triangles`; the CPU backend removes the
// triangles in the step that tears them (`MeshBinding::retain`).
//
// `topo` (the mesh writer's table): the drawn triangles' mesh vertices (3 each, from
// `drawn_at`), and per drawn triangle its cloth triangle (from `cloth_tri_at`; 0xffffffff:
// none). A triangle is cleared only where the slab still holds the vertices this writer
// knows, so an index list the host has already replaced is never touched.

struct HideParams {
    // first index of this mesh in the bound range of the index slab, in indices
    index_base: u32,
    // drawn triangles
    triangles: u32,
    // 1: the slab holds 16-bit indices, two a word
    u16_indices: u32,
    drawn_at: u32,
    cloth_tri_at: u32,
    // the cloth's first dead-triangle flag in `scratch`
    dead_at: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> H: HideParams;
@group(0) @binding(1) var<storage, read> topo: array<u32>;
@group(0) @binding(2) var<storage, read> scratch: array<u32>;
@group(0) @binding(3) var<storage, read_write> indices: array<atomic<u32>>;

fn index_at(e: u32) -> u32 {
    if H.u16_indices == 0u {
        return atomicLoad(&indices[e]);
    }
    let w = atomicLoad(&indices[e >> 1u]);
    return (w >> (16u * (e & 1u))) & 0xffffu;
}

// Sets index `e` to 0 (a 16-bit index shares its word with a neighbour another invocation
// may clear at the same time: the atomic `and` keeps the other half).
fn clear(e: u32) {
    if H.u16_indices == 0u {
        atomicStore(&indices[e], 0u);
        return;
    }
    atomicAnd(&indices[e >> 1u], select(0xffff0000u, 0x0000ffffu, (e & 1u) == 1u));
}

// The linear index (in x) of an invocation of a 64-wide kernel dispatched over `groups`
// workgroups: y and z > 1 only where x alone would pass the adapter's per-dimension limit
// (`kernels::flat_groups`).
fn flat_id(gid: vec3<u32>, groups: vec3<u32>) -> vec3<u32> {
    return vec3<u32>(gid.x + (gid.y + gid.z * groups.y) * groups.x * 64u, 0u, 0u);
}

@compute @workgroup_size(64)
fn hide_torn(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = flat_id(gid, groups);
    let t = id.x;
    if t >= H.triangles {
        return;
    }
    let c = topo[H.cloth_tri_at + t];
    if c == 0xffffffffu || scratch[H.dead_at + c] == 0u {
        return;
    }
    let e = H.index_base + 3u * t;
    let d = H.drawn_at + 3u * t;
    if index_at(e) != topo[d] || index_at(e + 1u) != topo[d + 1u] || index_at(e + 2u) != topo[d + 2u] {
        return;
    }
    clear(e);
    clear(e + 1u);
    clear(e + 2u);
}
