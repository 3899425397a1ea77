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
pub(crate) use plugin::{ClothLeavingGpu, forget_gpu_cloth};
