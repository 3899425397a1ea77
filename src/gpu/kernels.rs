//! The compiled cloth kernels ([`GpuKernels`]): one WGSL module put together from the
//! stage files in `shaders/`, one pipeline per entry point, one bind group layout.

use core::num::NonZeroU64;

use super::world::{LevelEntry, SubstepEntry, WorldUniform};

/// The WGSL of every step kernel, in one module: the shared layout and arithmetic, then the
/// stages in step order.
pub const STEP_WGSL: &str = concat!(
    include_str!("shaders/common.wgsl"),
    include_str!("shaders/step_begin.wgsl"),
    include_str!("shaders/solve.wgsl"),
    include_str!("shaders/contact.wgsl"),
    include_str!("shaders/step_end.wgsl"),
    include_str!("shaders/lab.wgsl"),
);

/// Invocations per workgroup of the per-vertex kernels.
pub(crate) const WORKGROUP: u32 = 64;

/// Invocations per workgroup of `solve` (one workgroup per group of constraints).
pub(crate) const SOLVE_WORKGROUP: u32 = 256;

/// Vertices a part may have to be projected in workgroup memory (`solve.wgsl`'s `TILE`:
/// 16 KiB of `vec4<f32>`, WebGPU's default workgroup storage).
pub const TILE: usize = 1024;

/// Stride of the dynamic-offset uniform tables (the largest alignment WebGPU allows).
pub(crate) const TABLE_STRIDE: u64 = 256;

/// Storage buffers the kernels bind at once (WebGPU's default limit is 8).
pub const STORAGE_BUFFERS: u32 = 7;

/// Why a cloth cannot run on the GPU backend (it stays on the CPU).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GpuUnsupported(pub String);

impl core::fmt::Display for GpuUnsupported {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GpuUnsupported {}

/// The compiled step kernels for one device. Build once, share between worlds.
#[derive(Debug)]
pub struct GpuKernels {
    pub(crate) layout: wgpu::BindGroupLayout,
    pub(crate) teleport: wgpu::ComputePipeline,
    pub(crate) step_begin: wgpu::ComputePipeline,
    pub(crate) impulse_clear: wgpu::ComputePipeline,
    pub(crate) solve: wgpu::ComputePipeline,
    pub(crate) sc_query: wgpu::ComputePipeline,
    pub(crate) sc_collide: wgpu::ComputePipeline,
    pub(crate) finish_substep: wgpu::ComputePipeline,
    pub(crate) step_end: wgpu::ComputePipeline,
    pub(crate) tear_check: wgpu::ComputePipeline,
    pub(crate) tear_release: wgpu::ComputePipeline,
    pub(crate) carry: wgpu::ComputePipeline,
    pub(crate) settle_begin: wgpu::ComputePipeline,
    pub(crate) settle_end: wgpu::ComputePipeline,
    pub(crate) settle_update: wgpu::ComputePipeline,
    pub(crate) lab_begin: wgpu::ComputePipeline,
    pub(crate) lab_gather: wgpu::ComputePipeline,
    pub(crate) lab_apply: wgpu::ComputePipeline,
    pub(crate) lab_finish: wgpu::ComputePipeline,
    pub(crate) lab_guard: wgpu::ComputePipeline,
}

pub(super) fn uniform_entry(binding: u32, dynamic: bool, size: u64) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: NonZeroU64::new(size),
        },
        count: None,
    }
}

pub(super) fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

impl GpuKernels {
    /// Whether `limits` allow the kernels: storage buffers per stage, workgroup size and
    /// memory, uniform offset alignment.
    ///
    /// # Errors
    /// The first limit that is too small, in words.
    pub fn check_limits(limits: &wgpu::Limits) -> Result<(), GpuUnsupported> {
        if limits.max_storage_buffers_per_shader_stage < STORAGE_BUFFERS {
            return Err(GpuUnsupported(format!(
                "the adapter allows {} storage buffers per shader stage, the cloth kernels need {STORAGE_BUFFERS}",
                limits.max_storage_buffers_per_shader_stage
            )));
        }
        if limits.max_compute_invocations_per_workgroup < SOLVE_WORKGROUP
            || limits.max_compute_workgroup_size_x < SOLVE_WORKGROUP
        {
            return Err(GpuUnsupported(format!(
                "the adapter's workgroups are smaller than the {SOLVE_WORKGROUP} invocations the cloth kernels use"
            )));
        }
        // `solve`'s tile (the largest of any kernel's workgroup memory).
        let workgroup_bytes = 16 * TILE as u32;
        if limits.max_compute_workgroup_storage_size < workgroup_bytes {
            return Err(GpuUnsupported(format!(
                "the adapter allows {} bytes of workgroup memory, the cloth kernels need {workgroup_bytes}",
                limits.max_compute_workgroup_storage_size
            )));
        }
        if limits.min_uniform_buffer_offset_alignment as u64 > TABLE_STRIDE {
            return Err(GpuUnsupported(format!(
                "the adapter aligns uniform offsets to {} bytes, more than {TABLE_STRIDE}",
                limits.min_uniform_buffer_offset_alignment
            )));
        }
        Ok(())
    }

    /// Compiles the kernels on `device`.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("cloth_step"),
            source: wgpu::ShaderSource::Wgsl(STEP_WGSL.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cloth_step"),
            entries: &[
                uniform_entry(0, false, size_of::<WorldUniform>() as u64),
                uniform_entry(1, true, size_of::<SubstepEntry>() as u64),
                uniform_entry(2, true, size_of::<LevelEntry>() as u64),
                storage_entry(3, false),
                storage_entry(4, true),
                storage_entry(5, false),
                storage_entry(6, true),
                storage_entry(7, true),
                storage_entry(8, true),
                storage_entry(9, true),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("cloth_step"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        Self {
            teleport: pipeline("teleport"),
            step_begin: pipeline("step_begin"),
            impulse_clear: pipeline("impulse_clear"),
            solve: pipeline("solve"),
            sc_query: pipeline("sc_query"),
            sc_collide: pipeline("sc_collide"),
            finish_substep: pipeline("finish_substep"),
            step_end: pipeline("step_end"),
            tear_check: pipeline("tear_check"),
            tear_release: pipeline("tear_release"),
            carry: pipeline("carry"),
            settle_begin: pipeline("settle_begin"),
            settle_end: pipeline("settle_end"),
            settle_update: pipeline("settle_update"),
            lab_begin: pipeline("lab_begin"),
            lab_gather: pipeline("lab_gather"),
            lab_apply: pipeline("lab_apply"),
            lab_finish: pipeline("lab_finish"),
            lab_guard: pipeline("lab_guard"),
            layout,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::STEP_WGSL;
    use crate::solver::{MAX_SETTLE_STEPS, SETTLE_SPEED, SETTLE_STEPS};

    /// The settle kernels' constants are the CPU's.
    #[test]
    fn the_settle_constants_are_the_cpus() {
        for line in [
            format!("const SETTLE_MAX: f32 = {MAX_SETTLE_STEPS}.0;"),
            format!("const SETTLE_STEPS: u32 = {SETTLE_STEPS}u;"),
            format!("const SETTLE_SPEED: f32 = {SETTLE_SPEED:?};"),
            format!("rest > {:?}", f32::EPSILON),
        ] {
            assert!(STEP_WGSL.contains(&line), "{line}");
        }
    }
}
