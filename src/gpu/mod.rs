//! The GPU backend: the cloth step as WGSL compute kernels, run in Bevy's render graph by
//! [`ClothGpuPlugin`], writing the mesh's vertex slab in place.
//!
//! [`kernels`] runs the CPU solver's step on any `wgpu` device, from the same constraint
//! layouts ([`ConstraintBatches`](crate::solver::ConstraintBatches)), pins and colliders; its
//! results match the CPU's within f32 rounding (`tests/gpu_parity.rs`).

pub mod kernels;
pub mod mesh;
mod plugin;

pub use kernels::{GpuCloth, GpuKernels, GpuStage, GpuStepInput, GpuUnsupported, sum_impulses};
pub use plugin::{
    ClothBackend, ClothBackendInUse, ClothGpuPlugin, ClothGpuSupport, ClothOnGpu, ClothReadback,
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
