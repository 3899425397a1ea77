//! The GPU backend: the cloth step as WGSL compute kernels.
//!
//! [`kernels`] runs the CPU solver's step on any `wgpu` device, from the same constraint
//! layouts ([`ConstraintBatches`](crate::solver::ConstraintBatches)), pins and colliders; its
//! results match the CPU's within f32 rounding (`tests/gpu_parity.rs`).

pub mod kernels;

pub use kernels::{GpuCloth, GpuKernels, GpuStepInput, GpuUnsupported};
