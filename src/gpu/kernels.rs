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
    /// The device's limits the worlds are sized and dispatched by.
    pub(crate) limits: DeviceSizeLimits,
}

/// What a device allows a world or mesh writer: the largest storage buffer binding and the
/// most workgroups a dispatch may have in one dimension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct DeviceSizeLimits {
    pub storage_binding: u64,
    pub buffer: u64,
    pub groups_per_dimension: u32,
    /// The alignment of a storage binding's offset, in bytes.
    pub offset_alignment: u64,
}

impl DeviceSizeLimits {
    pub fn of(device: &wgpu::Device) -> Self {
        let l = device.limits();
        Self {
            storage_binding: l.max_storage_buffer_binding_size,
            buffer: l.max_buffer_size,
            groups_per_dimension: l.max_compute_workgroups_per_dimension.max(1),
            offset_alignment: u64::from(l.min_storage_buffer_offset_alignment.max(4)),
        }
    }

    /// Whether a storage buffer of `bytes` can be made and bound whole.
    pub fn binds(&self, bytes: u64) -> bool {
        bytes <= self.storage_binding.min(self.buffer)
    }

    /// Whether `groups` workgroups fit one dispatch split over three dimensions
    /// ([`flat_groups`]).
    pub fn dispatches(&self, groups: u64) -> bool {
        groups <= u64::from(self.groups_per_dimension).pow(3)
    }
}

/// The workgroups of a dispatch over `groups` 64-wide (or one-per-group) workgroups, within
/// `max` per dimension: `(groups, 1, 1)` when that fits, else split over y (and z) so that
/// x·y·z ≥ groups; the kernels take their linear index with `flat_id` and return past the
/// end, as they do for the last workgroup's tail.
#[must_use]
pub(crate) fn flat_groups(groups: u32, max: u32) -> [u32; 3] {
    let max = max.max(1);
    if groups <= max {
        return [groups, 1, 1];
    }
    let plane = max.saturating_mul(max);
    let z = groups.div_ceil(plane);
    let rest = groups.div_ceil(z);
    let y = rest.div_ceil(max);
    [rest.div_ceil(y), y, z]
}

/// Dispatches `groups` workgroups split by [`flat_groups`].
pub(crate) fn dispatch_flat(pass: &mut wgpu::ComputePass<'_>, groups: u32, max: u32) {
    let [x, y, z] = flat_groups(groups, max);
    pass.dispatch_workgroups(x, y, z);
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
            limits: DeviceSizeLimits::of(device),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{STEP_WGSL, flat_groups};
    use crate::solver::{MAX_SETTLE_STEPS, SETTLE_SPEED, SETTLE_STEPS};

    /// A dispatch split by `flat_groups` stays within the limit in every dimension, covers
    /// every workgroup, wastes less than one row of x·y, and is `(groups, 1, 1)` when that fits.
    #[test]
    fn split_dispatches_cover_every_group_within_the_limit() {
        let mut counts: Vec<u32> = (0..300).collect();
        counts.extend([
            65_535,
            65_536,
            65_537,
            131_071,
            1 << 20,
            4_194_303,
            u32::MAX / 64,
        ]);
        for max in [1, 2, 3, 4, 8, 65_535] {
            for &groups in &counts {
                let [x, y, z] = flat_groups(groups, max);
                let limit = u64::from(max);
                if u64::from(groups) > limit.pow(3) {
                    continue;
                }
                assert!(
                    x <= max && y <= max && z <= max,
                    "{groups} in {max}: {x} {y} {z}"
                );
                let covered = u64::from(x) * u64::from(y) * u64::from(z);
                assert!(
                    covered >= u64::from(groups),
                    "{groups} in {max}: {x} {y} {z}"
                );
                assert!(
                    covered < u64::from(groups) + u64::from(x) * u64::from(y) || groups == 0,
                    "{groups} in {max}: {x} {y} {z} wastes a plane"
                );
                if groups <= max {
                    assert_eq!([x, y, z], [groups, 1, 1]);
                }
            }
        }
    }

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
