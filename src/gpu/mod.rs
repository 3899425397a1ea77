//! The GPU backend: the cloth step as WGSL compute kernels, run in Bevy's render graph by
//! [`ClothGpuPlugin`], writing the mesh's vertex slab in place.
//!
//! Every GPU cloth that steps with the same substeps and iterations lives in one
//! [`GpuWorld`]: shared buffers, per-cloth ranges, a few dispatches per substep for all of
//! them ([`GpuWorld::dispatches`]). Its results match the CPU solver's within f32 rounding
//! (`tests/gpu_parity.rs`).
//!
//! - `layout.rs`: how a world lies in the buffers (built on the CPU; no `wgpu`).
//! - `world.rs`: [`GpuWorld`]: the buffers, a frame's inputs, the dispatches, readback.
//! - `kernels.rs`: [`GpuKernels`]: the pipelines of `shaders/*.wgsl`, one file per stage.
//! - `mesh.rs` / `mesh.wgsl`: a cloth's positions, normals and tangents into its mesh slab.
//! - `backend.rs`: the main world (backend choice, the queued steps, what comes back);
//!   `render.rs`: the render world; `plugin.rs`: [`ClothGpuPlugin`].

mod backend;
pub mod kernels;
mod layout;
pub mod mesh;
mod plugin;
mod render;
mod world;

pub use backend::{ClothBackend, ClothBackendInUse, ClothGpuSupport, ClothOnGpu, ClothReadback};
pub use kernels::{GpuKernels, GpuUnsupported, TILE};
pub use layout::{WorldKey, gpu_part_count};
pub use plugin::{ClothGpuPlugin, renderer_instance_kept};
pub use world::{
    ClothFrame, DispatchCount, GpuFrame, GpuStage, GpuWorld, MotionTargets, StepColliders,
    TornEdges, TornFlags, sum_impulses,
};

/// Appends per-owner lists to a `u32` table (how the kernels find a vertex's triangles, edges,
/// tethers): `owners + 1` absolute offsets, then each owner's records of `K` words in the
/// order `items` gives them. Returns where the offsets start; the records of owner `o` are
/// `table[table[start + o]..table[start + o + 1]]`.
pub(crate) fn append_lists<const K: usize, I>(table: &mut Vec<u32>, owners: usize, items: I) -> u32
where
    I: IntoIterator<Item = (u32, [u32; K])>,
    I::IntoIter: Clone,
{
    let items = items.into_iter();
    let start = table.len() as u32;
    let mut count = vec![0u32; owners];
    for (o, _) in items.clone() {
        count[o as usize] += 1;
    }
    let mut at = start + owners as u32 + 1;
    for c in &count {
        table.push(at);
        at += K as u32 * c;
    }
    table.push(at);
    let mut fill: Vec<u32> = table[start as usize..start as usize + owners].to_vec();
    table.resize(at as usize, 0);
    for (o, record) in items {
        let k = fill[o as usize] as usize;
        table[k..k + K].copy_from_slice(&record);
        fill[o as usize] += K as u32;
    }
    start
}
