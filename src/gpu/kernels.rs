//! The cloth step as WGSL compute kernels on any `wgpu` device (`step.wgsl`).
//!
//! [`GpuKernels`] holds the compiled pipelines (one per stage of [`solver::step`]); a
//! [`GpuCloth`] holds one cloth's buffers, built from the CPU solver's own
//! [`Simulation`]: the same partitioned, coloured constraints, the same pins and colliders.
//! [`GpuCloth::record`] records `k` steps into a command encoder: per step the pins' start,
//! the area vectors, then per substep pins, integration, every colour of every part and of
//! the boundary (`iterations` times), the colliders; the velocities at the end.
//!
//! Constraints of one colour share no vertex, so each colour is one dispatch with one
//! invocation per constraint; colour `c` of every part goes in one dispatch, because parts
//! share no vertex either. Constraints the colouring left over run in one invocation, in
//! order. The result is the CPU's Gauss–Seidel order colour for colour: the two differ only
//! by f32 rounding (fused multiply–adds, `sqrt`, division), which `tests/gpu_parity.rs`
//! bounds.
//!
//! Self-collision is the exception: the CPU projects contact pairs one by one, which needs an
//! order; here every vertex sums its contacts' corrections against the positions before the
//! pass and moves by their mean (Jacobi), the form `solver::step` runs with
//! `StepInput::parallel_self_collision`, its CPU twin.
//!
//! Tearing is checked, not done, here: a step that leaves an edge past the threshold raises a
//! flag in the status; the plugin reads the state back and tears on the CPU (a new topology,
//! new buffers, the GPU state carried over), a few frames after the GPU saw the stretch.
//!
//! The lab solver (seed 000's Jacobi averaging) is a gather per vertex over its edges in edge
//! order, so it matches the CPU's sums bit for bit where the arithmetic is the same.
//!
//! What runs on the GPU is what [`GpuCloth::supports`] accepts: everything but an explicitly
//! implicit bending solve, which stays on the CPU backend (it says why when it keeps a
//! cloth).
//!
//! [`solver::step`]: crate::solver::step

use core::num::NonZeroU64;

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use wgpu::util::DeviceExt;

use std::sync::Arc;

use super::append_lists;
use crate::solver::collision::substep_poses;
use crate::solver::constraints::{ConstraintBatches, Part};
use crate::solver::{
    Collider, MAX_SELF_NEIGHBOURS, SdfGrid, Shape, Simulation, Solver, SolverParams, Tethers,
};

/// The WGSL of every kernel.
pub const STEP_WGSL: &str = include_str!("step.wgsl");

/// Invocations per workgroup of the per-vertex and per-constraint kernels.
const WORKGROUP: u32 = 64;

/// Invocations of the self-collision hash's prefix-sum kernel (one workgroup).
const SCAN_WORKGROUP: u32 = 256;

/// Stride of the dynamic-offset uniform tables (the largest alignment WebGPU allows).
const TABLE_STRIDE: u64 = 256;

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct Params {
    gravity_h: [f32; 4],
    inv_h: f32,
    damp: f32,
    max_speed: f32,
    inv_h2: f32,
    air: [f32; 4],
    n: u32,
    pins: u32,
    colliders: u32,
    accumulate: u32,
    xpbd: u32,
    distances: u32,
    tri_base: u32,
    lambdas: u32,
    tether_base: u32,
    status: u32,
    dihedral: u32,
    lambda_base: u32,
    rest_base: u32,
    corr_base: u32,
    sc_size: u32,
    sc_max: u32,
    sc_counts: u32,
    sc_starts: u32,
    sc_cursor: u32,
    sc_entries: u32,
    sc_ncount: u32,
    sc_nlist: u32,
    impulses: u32,
    impulse_base: u32,
    impulse_slots: u32,
    lab_base: u32,
    _pad: [u32; 2],
    sc: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct SubstepEntry {
    substep: u32,
    pin_base: u32,
    pose_base: u32,
    /// 1 in a step's first substep when the cloth teleports at the step's start.
    snap: u32,
    t: f32,
    /// The teleport's offset.
    offset: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct RangeEntry {
    first: u32,
    count: u32,
    _pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct GpuDistance {
    a: u32,
    b: u32,
    rest: f32,
    param: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct GpuBend {
    v: [u32; 4],
    a: [f32; 4],
    param: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct GpuPin {
    vertex: u32,
    _pad: [u32; 3],
    target: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct GpuCollider {
    from_t: [f32; 4],
    from_r: [f32; 4],
    to_t: [f32; 4],
    to_r: [f32; 4],
    shape: [f32; 4],
    misc: [f32; 4],
    grid: [u32; 4],
}

/// Which kernel a pass of the projection runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PassKind {
    DistanceColour,
    DistanceSerial,
    BendColour,
    BendSerial,
}

#[derive(Clone, Copy, Debug)]
struct Pass {
    kind: PassKind,
    first: u32,
    count: u32,
}

/// A stage of the GPU step, as [`GpuCloth::record_profiled`] times it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum GpuStage {
    /// Pins' start positions and the air's area vectors, once per step.
    Begin,
    /// Pins moved and vertices integrated, per substep.
    Integrate,
    /// Stretch and shear constraints.
    Distance,
    /// Bending hinges.
    Bending,
    /// Tethers.
    Tethers,
    /// Self-collision: the spatial hash and neighbour lists once per step, the pairs per
    /// substep.
    SelfCollision,
    /// Colliders.
    Collide,
    /// End-of-step velocities and the NaN guard.
    Finish,
}

impl GpuStage {
    /// Every stage, in step order.
    pub const ALL: [GpuStage; 8] = [
        GpuStage::Begin,
        GpuStage::Integrate,
        GpuStage::Distance,
        GpuStage::Bending,
        GpuStage::Tethers,
        GpuStage::SelfCollision,
        GpuStage::Collide,
        GpuStage::Finish,
    ];

    /// A short lowercase name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            GpuStage::Begin => "begin",
            GpuStage::Integrate => "integrate",
            GpuStage::Distance => "distance",
            GpuStage::Bending => "bending",
            GpuStage::Tethers => "tethers",
            GpuStage::SelfCollision => "self_collision",
            GpuStage::Collide => "collide",
            GpuStage::Finish => "finish",
        }
    }
}

/// One recorded command of a step.
enum Cmd<'k> {
    /// A run of one stage starts (a pass boundary when profiling).
    Stage(GpuStage),
    /// Bind with these dynamic offsets (substep, range).
    Bind([u32; 2]),
    /// Dispatch a pipeline over this many workgroups.
    Run(&'k wgpu::ComputePipeline, u32),
}

/// Replays `cmds` into `pass` with the cloth's bind group `group`.
fn replay(pass: &mut wgpu::ComputePass<'_>, group: &wgpu::BindGroup, cmds: &[Cmd<'_>]) {
    for c in cmds {
        match c {
            Cmd::Stage(_) => {}
            Cmd::Bind(offsets) => pass.set_bind_group(0, group, offsets),
            Cmd::Run(pipeline, groups) => {
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups(*groups, 1, 1);
            }
        }
    }
}

/// Adds up impulse slots read back from [`GpuCloth::impulse_region`] (6 words per collide
/// workgroup and collider, f32 bits) into one impulse per collider.
#[must_use]
pub fn sum_impulses(words: &[u32], colliders: usize) -> Vec<crate::solver::ContactImpulse> {
    let mut out = vec![crate::solver::ContactImpulse::default(); colliders];
    if colliders == 0 {
        return out;
    }
    for (i, slot) in words.chunks_exact(6).enumerate() {
        let f = |j: usize| f32::from_bits(slot[j]);
        let imp = &mut out[i % colliders];
        imp.linear += Vec3::new(f(0), f(1), f(2));
        imp.angular += Vec3::new(f(3), f(4), f(5));
    }
    out
}

/// Where the self-collision's parts sit in the scratch buffer (u32 indices).
#[derive(Clone, Copy, Debug, Default)]
struct ScratchLayout {
    size: u32,
    counts: u32,
    starts: u32,
    cursor: u32,
    entries: u32,
    ncount: u32,
    nlist: u32,
    len: u64,
}

impl ScratchLayout {
    /// The layout for `n` vertices (`size` 0 and one word when self-collision is off).
    fn new(n: u32, on: bool) -> Self {
        if !on || n == 0 {
            return Self {
                len: 4,
                ..Default::default()
            };
        }
        let size = 2 * n;
        let counts = 1;
        let starts = counts + size;
        let cursor = starts + size + 1;
        let entries = cursor + size;
        let ncount = entries + n;
        let nlist = ncount + n;
        Self {
            size,
            counts,
            starts,
            cursor,
            entries,
            ncount,
            nlist,
            len: u64::from(nlist) + u64::from(n) * MAX_SELF_NEIGHBOURS as u64,
        }
    }
}

/// Why a cloth cannot run on the GPU backend (it stays on the CPU).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GpuUnsupported(pub String);

impl core::fmt::Display for GpuUnsupported {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GpuUnsupported {}

/// The compiled step kernels for one device. Build once, share between cloths.
#[derive(Debug)]
pub struct GpuKernels {
    layout: wgpu::BindGroupLayout,
    pins_begin: wgpu::ComputePipeline,
    areas: wgpu::ComputePipeline,
    pins_substep: wgpu::ComputePipeline,
    integrate: wgpu::ComputePipeline,
    lambda_clear: wgpu::ComputePipeline,
    distance_colour: wgpu::ComputePipeline,
    distance_serial: wgpu::ComputePipeline,
    bend_colour: wgpu::ComputePipeline,
    bend_serial: wgpu::ComputePipeline,
    collide: wgpu::ComputePipeline,
    impulse_clear: wgpu::ComputePipeline,
    tethers: wgpu::ComputePipeline,
    teleport: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
    pins_finish: wgpu::ComputePipeline,
    guard: wgpu::ComputePipeline,
    tear_check: wgpu::ComputePipeline,
    carry: wgpu::ComputePipeline,
    lab_pins: wgpu::ComputePipeline,
    lab_integrate: wgpu::ComputePipeline,
    lab_gather: wgpu::ComputePipeline,
    lab_apply: wgpu::ComputePipeline,
    lab_finish: wgpu::ComputePipeline,
    sc_clear: wgpu::ComputePipeline,
    sc_speed: wgpu::ComputePipeline,
    sc_count: wgpu::ComputePipeline,
    sc_scan: wgpu::ComputePipeline,
    sc_scatter: wgpu::ComputePipeline,
    sc_query: wgpu::ComputePipeline,
    sc_collide: wgpu::ComputePipeline,
    sc_apply: wgpu::ComputePipeline,
}

/// Storage buffers the kernels bind at once (WebGPU's default limit is 8).
pub const STORAGE_BUFFERS: u32 = 8;

fn uniform_entry(binding: u32, dynamic: bool, size: u64) -> wgpu::BindGroupLayoutEntry {
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

fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
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
    /// Whether `limits` allow the kernels: storage buffers per stage, workgroup size.
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
        if limits.max_compute_invocations_per_workgroup < SCAN_WORKGROUP
            || limits.max_compute_workgroup_size_x < SCAN_WORKGROUP
        {
            return Err(GpuUnsupported(format!(
                "the adapter's workgroups are smaller than the {SCAN_WORKGROUP} invocations the cloth kernels use"
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
                uniform_entry(0, false, size_of::<Params>() as u64),
                uniform_entry(1, true, size_of::<SubstepEntry>() as u64),
                storage_entry(2, false),
                storage_entry(3, true),
                storage_entry(4, true),
                storage_entry(5, false),
                storage_entry(6, true),
                storage_entry(7, true),
                uniform_entry(8, true, size_of::<RangeEntry>() as u64),
                storage_entry(9, true),
                storage_entry(10, true),
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
            pins_begin: pipeline("pins_begin"),
            areas: pipeline("areas"),
            pins_substep: pipeline("pins_substep"),
            integrate: pipeline("integrate"),
            lambda_clear: pipeline("lambda_clear"),
            distance_colour: pipeline("distance_colour"),
            distance_serial: pipeline("distance_serial"),
            bend_colour: pipeline("bend_colour"),
            bend_serial: pipeline("bend_serial"),
            collide: pipeline("collide"),
            impulse_clear: pipeline("impulse_clear"),
            tethers: pipeline("tethers"),
            teleport: pipeline("teleport"),
            finish: pipeline("finish"),
            pins_finish: pipeline("pins_finish"),
            guard: pipeline("guard"),
            tear_check: pipeline("tear_check"),
            carry: pipeline("carry"),
            lab_pins: pipeline("lab_pins"),
            lab_integrate: pipeline("lab_integrate"),
            lab_gather: pipeline("lab_gather"),
            lab_apply: pipeline("lab_apply"),
            lab_finish: pipeline("lab_finish"),
            sc_clear: pipeline("sc_clear"),
            sc_speed: pipeline("sc_speed"),
            sc_count: pipeline("sc_count"),
            sc_scan: pipeline("sc_scan"),
            sc_scatter: pipeline("sc_scatter"),
            sc_query: pipeline("sc_query"),
            sc_collide: pipeline("sc_collide"),
            sc_apply: pipeline("sc_apply"),
            layout,
        }
    }
}

/// What one frame's steps feel besides the cloth itself: the same inputs the CPU step takes.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuStepInput<'a> {
    /// Shapes the cloth collides with (every shape, baked SDF grids included).
    pub colliders: &'a [Collider],
    /// The air's velocity at each vertex (`w` ignored); empty for still air.
    pub air_velocities: &'a [Vec4],
    /// Per step, how far the whole cloth jumps at the step's start, its pins snapping to their
    /// targets (the teleport rule: `ClothState::translate`, then `ClothState::snap_pins`);
    /// empty or zero for none.
    pub teleports: &'a [Vec3],
}

/// One cloth's buffers on the GPU.
#[derive(Debug)]
pub struct GpuCloth {
    n: u32,
    pins: u32,
    substeps: u32,
    iterations: u32,
    passes: Vec<Pass>,
    lambdas: u32,
    distances: u32,
    tri_base: u32,
    tether_base: u32,
    /// The lab solver's per-vertex edge lists in `topo` (0: another solver).
    lab_base: u32,
    dihedral: bool,
    /// Where the regions after the pins' starts begin in the state buffer (vec4 indices).
    lambda_base: u32,
    rest_base: u32,
    corr_base: u32,
    /// Self-collision: hash buckets (0: off) and the scratch layout.
    sc: ScratchLayout,
    /// Rest positions (uploaded with the state when self-collision is on).
    rest: Vec<Vec4>,
    params: wgpu::Buffer,
    substep_table: wgpu::Buffer,
    substep_capacity: u32,
    range_table: wgpu::Buffer,
    state: wgpu::Buffer,
    distance_buf: wgpu::Buffer,
    bend_buf: wgpu::Buffer,
    scratch: wgpu::Buffer,
    /// Words the scratch buffer holds (self-collision, then the impulse slots).
    scratch_capacity: u64,
    /// Words of impulse slots the last [`GpuCloth::prepare`] laid out (6 per collide
    /// workgroup and collider), after the self-collision part.
    impulse_slots: u32,
    pin_buf: wgpu::Buffer,
    pin_capacity: u32,
    collider_buf: wgpu::Buffer,
    collider_capacity: u32,
    topo: wgpu::Buffer,
    /// Every baked grid the colliders use, back to back, and the grids it holds.
    sdf_buf: wgpu::Buffer,
    sdf_grids: Vec<Arc<SdfGrid>>,
    bind_group: Option<wgpu::BindGroup>,
    /// Steps and colliders the last [`GpuCloth::prepare`] wrote for.
    prepared: (u32, u32),
    /// Whether the air acts (area vectors are needed).
    air_on: bool,
    /// Per prepared step, whether the cloth teleports at its start.
    teleports: Vec<bool>,
    /// Whether edges are checked against a tear threshold.
    tearing: bool,
}

/// Appends a part's or the boundary's distance constraints (global vertex indices).
fn push_distances(part: &Part, range: core::ops::Range<usize>, out: &mut Vec<GpuDistance>) {
    let base = part.range.start as u32;
    let d = &part.distance;
    for i in range {
        out.push(GpuDistance {
            a: d.a()[i] + base,
            b: d.b()[i] + base,
            rest: d.rest[i],
            param: d.param[i],
        });
    }
}

/// Appends hinges: isometric ones with their four weights, dihedral ones with their rest
/// angle in `a[0]`.
fn push_bends(part: &Part, range: core::ops::Range<usize>, out: &mut Vec<GpuBend>) {
    let base = part.range.start as u32;
    let b = &part.bending;
    for i in range {
        out.push(GpuBend {
            v: [0, 1, 2, 3].map(|k| b.v()[k][i] + base),
            a: if b.iso {
                [0, 1, 2, 3].map(|k| b.a[k][i])
            } else {
                [b.rest[i], 0.0, 0.0, 0.0]
            },
            param: [b.param[i], 0.0, 0.0, 0.0],
        });
    }
}

/// Appends the passes of a group of parts that share no vertex (the parts, the seams of
/// one parity, or the boundary alone): colour `c` of every member in one pass; each
/// member's distances before its bending, as on the CPU.
fn push_group(
    parts: &[Part],
    bending: bool,
    dist: &mut Vec<GpuDistance>,
    bend: &mut Vec<GpuBend>,
    passes: &mut Vec<Pass>,
) {
    let pass = |kind, first: usize, end: usize, passes: &mut Vec<Pass>| {
        if end > first {
            passes.push(Pass {
                kind,
                first: first as u32,
                count: (end - first) as u32,
            });
        }
    };
    let colours = parts
        .iter()
        .map(|p| p.distance.colours.independent.len())
        .max()
        .unwrap_or(0);
    for c in 0..colours {
        let first = dist.len();
        for p in parts {
            if let Some(r) = p.distance.colours.independent.get(c) {
                push_distances(p, r.clone(), dist);
            }
        }
        pass(PassKind::DistanceColour, first, dist.len(), passes);
    }
    let first = dist.len();
    for p in parts {
        push_distances(p, p.distance.colours.sequential.clone(), dist);
    }
    pass(PassKind::DistanceSerial, first, dist.len(), passes);
    if bending {
        let colours = parts
            .iter()
            .map(|p| p.bending.colours.independent.len())
            .max()
            .unwrap_or(0);
        for c in 0..colours {
            let first = bend.len();
            for p in parts {
                if let Some(r) = p.bending.colours.independent.get(c) {
                    push_bends(p, r.clone(), bend);
                }
            }
            pass(PassKind::BendColour, first, bend.len(), passes);
        }
        let first = bend.len();
        for p in parts {
            push_bends(p, p.bending.colours.sequential.clone(), bend);
        }
        pass(PassKind::BendSerial, first, bend.len(), passes);
    }
}

/// Constraints in GPU order and the passes of one iteration.
fn flatten(
    batches: &ConstraintBatches,
    bending: bool,
) -> (Vec<GpuDistance>, Vec<GpuBend>, Vec<Pass>) {
    let mut dist = Vec::new();
    let mut bend = Vec::new();
    let mut passes = Vec::new();
    // The parts, then the even seams, the odd seams and the boundary, as on the CPU.
    push_group(&batches.parts, bending, &mut dist, &mut bend, &mut passes);
    for seams in &batches.seams {
        push_group(seams, bending, &mut dist, &mut bend, &mut passes);
    }
    push_group(
        core::slice::from_ref(&batches.boundary),
        bending,
        &mut dist,
        &mut bend,
        &mut passes,
    );
    (dist, bend, passes)
}

/// Per vertex the triangles it belongs to, in triangle order, then the triangles:
/// `[offsets (n + 1) | incident triangles | 3 vertices per triangle]` and the triangles' start.
fn incidence(n: usize, triangles: &[[u32; 3]]) -> (Vec<u32>, u32) {
    let mut out = Vec::with_capacity(n + 1 + 6 * triangles.len());
    append_lists(
        &mut out,
        n,
        triangles
            .iter()
            .enumerate()
            .flat_map(|(i, t)| t.map(|v| (v, [i as u32]))),
    );
    let tri_base = out.len() as u32;
    out.extend(triangles.iter().flatten());
    (out, tri_base)
}

/// Appends the lab solver's edges to `topo`: per vertex, per incident edge in edge order,
/// `(other end, rest length bits)`. Returns where the offsets start.
fn append_lab_edges(topo: &mut Vec<u32>, n: usize, edges: &[crate::solver::Edge]) -> u32 {
    append_lists(
        topo,
        n,
        edges.iter().flat_map(|e| {
            let rest = e.rest.to_bits();
            [(e.v[0], [e.v[1], rest]), (e.v[1], [e.v[0], rest])]
        }),
    )
}

/// Appends the tethers to `topo`: per vertex `(pin, max length bits)` per attachment, in the
/// CPU's order. Returns where the offsets start.
fn append_tethers(topo: &mut Vec<u32>, n: usize, tethers: &Tethers) -> u32 {
    append_lists(
        topo,
        n,
        tethers
            .entries()
            .map(|(v, pin, max_len)| (v, [pin, max_len.to_bits()])),
    )
}

fn storage(
    device: &wgpu::Device,
    label: &str,
    bytes: &[u8],
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    // Bindings may not be empty: at least one 16-byte element.
    let zero = [0u8; 16];
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: if bytes.is_empty() { &zero } else { bytes },
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
    })
}

fn empty(device: &wgpu::Device, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

fn pose_t(p: &crate::solver::Pose) -> [f32; 4] {
    p.translation.extend(p.scale).to_array()
}

fn gpu_collider(
    c: &Collider,
    from: &crate::solver::Pose,
    to: &crate::solver::Pose,
    reach2: f32,
    grid: [u32; 4],
) -> GpuCollider {
    let (kind, shape) = match &c.shape {
        Shape::Sphere { radius } => (0.0, [*radius, 0.0, 0.0, 0.0]),
        Shape::Cuboid { half_extents } => (1.0, half_extents.extend(0.0).to_array()),
        Shape::Capsule {
            half_length,
            radius,
        } => (2.0, [*half_length, *radius, 0.0, 0.0]),
        Shape::Plane => (3.0, [0.0; 4]),
        Shape::Mesh(g) => (4.0, g.origin().extend(g.cell()).to_array()),
    };
    GpuCollider {
        from_t: pose_t(from),
        from_r: from.rotation.to_array(),
        to_t: pose_t(to),
        to_r: to.rotation.to_array(),
        shape,
        // An infinite reach (a plane) as the largest finite one: GPUs need not honour ∞.
        misc: [c.thickness, c.friction, reach2.min(f32::MAX), kind],
        grid,
    }
}

fn whole(b: &wgpu::Buffer) -> wgpu::BindingResource<'_> {
    b.as_entire_binding()
}

fn table(b: &wgpu::Buffer, size: usize) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer: b,
        offset: 0,
        size: NonZeroU64::new(size as u64),
    })
}

impl GpuCloth {
    /// Whether `sim`, with its current settings and features, can run on the GPU kernels in
    /// steps of `dt` seconds.
    ///
    /// The GPU projects bending. Where the CPU would solve it implicitly
    /// ([`BendingSolve::Auto`](crate::solver::BendingSolve::Auto) with bending too stiff to
    /// project per substep), the GPU still projects it: the cloth bends more easily than asked
    /// (see `Simulation::bending_saturation`). A cloth that asks for
    /// [`BendingSolve::Implicit`](crate::solver::BendingSolve::Implicit) stays on the CPU.
    ///
    /// # Errors
    /// What keeps it on the CPU, in words.
    pub fn supports(sim: &Simulation, dt: f32) -> Result<(), GpuUnsupported> {
        Self::supports_model(sim)?;
        if sim.params().bending_solve == crate::solver::BendingSolve::Implicit
            && sim.wants_implicit_bending(dt)
        {
            return Err(GpuUnsupported(
                "implicit bending (BendingSolve::Implicit) runs on the CPU only".to_owned(),
            ));
        }
        Ok(())
    }

    /// [`Self::supports`] without the step length: what the kernels can run at all (every
    /// solver and feature; an empty cloth too).
    fn supports_model(_sim: &Simulation) -> Result<(), GpuUnsupported> {
        Ok(())
    }

    /// Uploads `sim`'s constraints and state. Check [`GpuCloth::supports`] first: bending
    /// the CPU would solve implicitly is projected here.
    ///
    /// # Errors
    /// What the kernels cannot run at all (as [`GpuCloth::supports`]).
    pub fn new(
        device: &wgpu::Device,
        kernels: &GpuKernels,
        sim: &Simulation,
    ) -> Result<Self, GpuUnsupported> {
        Self::supports_model(sim)?;
        let n = sim.state().len();
        let batches = sim.batches();
        let (dist, bend, passes) = flatten(batches, batches.bending);
        let (mut topo, tri_base) = incidence(n, sim.topology().triangles());
        let pins = sim.state().pins().len() as u32;
        let tether_base = match sim.features().tethers {
            Some(params) => {
                let pinned: Vec<u32> = sim.state().pins().iter().map(|p| p.vertex).collect();
                let tethers = Tethers::build(sim.topology(), &pinned, params);
                if tethers.is_empty() {
                    0
                } else {
                    append_tethers(&mut topo, n, &tethers)
                }
            }
            None => 0,
        };
        let lab_base = if matches!(sim.params().solver, Solver::Lab { .. }) {
            append_lab_edges(&mut topo, n, sim.topology().edges())
        } else {
            0
        };
        let usage_uniform = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        let range_entries: Vec<u8> = passes
            .iter()
            .flat_map(|p| {
                let mut e = vec![0u8; TABLE_STRIDE as usize];
                e[..size_of::<RangeEntry>()].copy_from_slice(bytemuck::bytes_of(&RangeEntry {
                    first: p.first,
                    count: p.count,
                    _pad: [0; 2],
                }));
                e
            })
            .collect();
        let range_table = if range_entries.is_empty() {
            empty(device, "cloth_ranges", TABLE_STRIDE, usage_uniform)
        } else {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("cloth_ranges"),
                contents: &range_entries,
                usage: usage_uniform,
            })
        };
        let lambdas = (dist.len() + bend.len()) as u32;
        // The regions, the status, the multipliers, then with self-collision the rest
        // positions and the corrections.
        let self_collision = sim.features().self_collision.is_some();
        let lambda_base = 5 * n as u32 + pins + 1;
        let rest_base = lambda_base + lambdas;
        let corr_base = rest_base + n as u32;
        let state_len = u64::from(if self_collision {
            corr_base + n as u32
        } else {
            rest_base
        }) * 16;
        let sc = ScratchLayout::new(n as u32, self_collision);
        let limit = device.limits().max_storage_buffer_binding_size;
        if state_len > limit || sc.len * 4 > limit {
            return Err(GpuUnsupported(format!(
                "a cloth of {n} vertices needs storage buffers of {} MB, the adapter allows {} MB",
                state_len.max(sc.len * 4) >> 20,
                limit >> 20
            )));
        }
        let params = sim.params();
        let mut cloth = Self {
            n: n as u32,
            pins,
            substeps: params.substeps.max(1),
            iterations: params.iterations.max(1),
            lambdas,
            distances: dist.len() as u32,
            tri_base,
            tether_base,
            lab_base,
            dihedral: batches.bending && !batches.boundary.bending.iso,
            lambda_base,
            rest_base,
            corr_base,
            sc,
            rest: if self_collision {
                sim.topology()
                    .rest_positions()
                    .iter()
                    .map(|p| p.extend(0.0))
                    .collect()
            } else {
                Vec::new()
            },
            params: empty(
                device,
                "cloth_params",
                size_of::<Params>() as u64,
                usage_uniform,
            ),
            substep_table: empty(device, "cloth_substeps", TABLE_STRIDE, usage_uniform),
            substep_capacity: 1,
            range_table,
            state: empty(
                device,
                "cloth_state",
                state_len,
                wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
            ),
            distance_buf: storage(
                device,
                "cloth_distances",
                bytemuck::cast_slice(&dist),
                wgpu::BufferUsages::empty(),
            ),
            bend_buf: storage(
                device,
                "cloth_bends",
                bytemuck::cast_slice(&bend),
                wgpu::BufferUsages::empty(),
            ),
            scratch: empty(
                device,
                "cloth_scratch",
                sc.len * 4,
                wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
            ),
            scratch_capacity: sc.len,
            impulse_slots: 0,
            sdf_buf: empty(
                device,
                "cloth_sdf",
                16,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            ),
            sdf_grids: Vec::new(),
            pin_buf: empty(
                device,
                "cloth_pins",
                32,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            ),
            pin_capacity: 0,
            collider_buf: empty(
                device,
                "cloth_colliders",
                size_of::<GpuCollider>() as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            ),
            collider_capacity: 0,
            topo: storage(
                device,
                "cloth_topology",
                bytemuck::cast_slice(&topo),
                wgpu::BufferUsages::empty(),
            ),
            bind_group: None,
            prepared: (0, 0),
            air_on: false,
            teleports: Vec::new(),
            tearing: false,
            passes,
        };
        cloth.bind(device, kernels);
        Ok(cloth)
    }

    fn bind(&mut self, device: &wgpu::Device, kernels: &GpuKernels) {
        self.bind_group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cloth_step"),
            layout: &kernels.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: whole(&self.params),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: table(&self.substep_table, size_of::<SubstepEntry>()),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: whole(&self.state),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: whole(&self.distance_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: whole(&self.bend_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: whole(&self.scratch),
                },
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: whole(&self.pin_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 7,
                    resource: whole(&self.collider_buf),
                },
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: table(&self.range_table, size_of::<RangeEntry>()),
                },
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: whole(&self.topo),
                },
                wgpu::BindGroupEntry {
                    binding: 10,
                    resource: whole(&self.sdf_buf),
                },
            ],
        }));
    }

    /// Number of vertices.
    #[must_use]
    pub fn len(&self) -> usize {
        self.n as usize
    }

    /// Whether the cloth has no vertex.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The state buffer: `[positions | substep starts | velocities | area vectors | air |
    /// pin starts | status]`, `vec4<f32>` each, [`Self::len`] per region (what a mesh-writing
    /// kernel reads). The status's `x` turns 1 at the end of a step that left a NaN or
    /// infinite position or velocity (see [`Self::status_offset`]).
    #[must_use]
    pub fn state_buffer(&self) -> &wgpu::Buffer {
        &self.state
    }

    /// Byte offset of the status `vec4` in [`Self::state_buffer`].
    #[must_use]
    pub fn status_offset(&self) -> u64 {
        (5 * u64::from(self.n) + u64::from(self.pins)) * 16
    }

    /// Replaces the GPU state with `sim`'s positions and velocities (and pins' vertices), and
    /// clears the status.
    pub fn upload_state(&self, queue: &wgpu::Queue, sim: &Simulation) {
        let s = sim.state();
        self.upload(queue, &s.positions, &s.velocities);
    }

    /// Replaces the GPU state with `positions` (`w`: inverse mass, 0 when pinned) and
    /// `velocities`, one per vertex, and clears the status.
    ///
    /// # Panics
    /// If either has not [`Self::len`] entries.
    pub fn upload(&self, queue: &wgpu::Queue, positions: &[Vec4], velocities: &[Vec4]) {
        let n = self.n as usize;
        assert!(
            positions.len() == n && velocities.len() == n,
            "one position and one velocity per vertex"
        );
        let mut data = Vec::with_capacity(3 * n);
        data.extend_from_slice(positions);
        data.extend_from_slice(positions);
        data.extend_from_slice(velocities);
        queue.write_buffer(&self.state, 0, bytemuck::cast_slice(&data));
        queue.write_buffer(&self.state, self.status_offset(), &[0u8; 16]);
        if !self.rest.is_empty() {
            queue.write_buffer(
                &self.state,
                u64::from(self.rest_base) * 16,
                bytemuck::cast_slice(&self.rest),
            );
        }
    }

    /// Writes what `steps` steps of `dt` seconds need: parameters, substeps, pin targets
    /// (`pin_targets[k]`: every pin's target at the end of step `k`, in `sim`'s pin order),
    /// collider poses and air. Grows buffers (and rebinds) when needed.
    ///
    /// # Panics
    /// If `pin_targets` does not have one entry per step with one target per pin.
    #[expect(
        clippy::too_many_arguments,
        reason = "a frame's steps take all they need explicitly"
    )]
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        kernels: &GpuKernels,
        sim: &Simulation,
        dt: f32,
        pin_targets: &[Vec<Vec3>],
        input: GpuStepInput<'_>,
    ) {
        let steps = pin_targets.len() as u32;
        assert!(
            pin_targets.iter().all(|p| p.len() == self.pins as usize),
            "one target per pin"
        );
        let params: &SolverParams = sim.params();
        let substeps = params.substeps.max(1);
        let h = dt / substeps as f32;
        // The lab solver ignores colliders and air, as on the CPU.
        let lab = match params.solver {
            Solver::Lab { velocity_keep } => Some(velocity_keep),
            _ => None,
        };
        let colliders = if lab.is_some() { &[] } else { input.colliders };
        let c = colliders.len() as u32;
        let mut rebind = self.upload_grids(device, queue, colliders);
        // Tables and per-step inputs, grown to fit.
        let sub_needed = (steps * substeps).max(1);
        if sub_needed > self.substep_capacity {
            self.substep_capacity = sub_needed.next_power_of_two();
            self.substep_table = empty(
                device,
                "cloth_substeps",
                u64::from(self.substep_capacity) * TABLE_STRIDE,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            );
            rebind = true;
        }
        let pins_needed = steps * self.pins;
        if pins_needed > self.pin_capacity {
            self.pin_capacity = pins_needed.next_power_of_two();
            self.pin_buf = empty(
                device,
                "cloth_pins",
                u64::from(self.pin_capacity) * size_of::<GpuPin>() as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            );
            rebind = true;
        }
        let colliders_needed = steps * substeps * c;
        if colliders_needed > self.collider_capacity {
            self.collider_capacity = colliders_needed.next_power_of_two();
            self.collider_buf = empty(
                device,
                "cloth_colliders",
                u64::from(self.collider_capacity) * size_of::<GpuCollider>() as u64,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            );
            rebind = true;
        }
        // Impulse slots after the self-collision words: 6 per collide workgroup and collider.
        let slots = self.n.div_ceil(WORKGROUP) * c * 6;
        let words = self.sc.len + u64::from(slots);
        if words > self.scratch_capacity {
            self.scratch_capacity = words.next_power_of_two();
            self.scratch = empty(
                device,
                "cloth_scratch",
                self.scratch_capacity * 4,
                wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
            );
            rebind = true;
        }
        if rebind || self.bind_group.is_none() {
            self.bind(device, kernels);
        }
        let (air, xpbd) = (params.air, matches!(params.solver, Solver::Xpbd { .. }));
        let air_on = !air.is_none() && lab.is_none();
        let p = Params {
            gravity_h: (params.gravity * h).extend(h).to_array(),
            inv_h: 1.0 / h,
            damp: lab.unwrap_or(1.0 / (1.0 + params.damping * h)),
            max_speed: params.max_speed,
            inv_h2: 1.0 / (h * h),
            air: [
                air.drag,
                air.lift,
                air.friction,
                if air_on { 1.0 } else { 0.0 },
            ],
            n: self.n,
            pins: self.pins,
            tether_base: self.tether_base,
            status: 5 * self.n + self.pins,
            dihedral: u32::from(self.dihedral),
            lambda_base: self.lambda_base,
            rest_base: self.rest_base,
            corr_base: self.corr_base,
            sc_size: self.sc.size,
            sc_max: MAX_SELF_NEIGHBOURS as u32,
            sc_counts: self.sc.counts,
            sc_starts: self.sc.starts,
            sc_cursor: self.sc.cursor,
            sc_entries: self.sc.entries,
            sc_ncount: self.sc.ncount,
            sc_nlist: self.sc.nlist,
            impulses: u32::from(slots > 0),
            impulse_base: self.sc.len as u32,
            impulse_slots: slots,
            lab_base: self.lab_base,
            _pad: [0; 2],
            sc: {
                let f = sim.features();
                let (thickness, friction) = f
                    .self_collision
                    .map_or((0.0, 0.0), |c| (c.thickness, c.friction));
                [thickness, friction, dt, f.tear_threshold.unwrap_or(0.0)]
            },
            colliders: c,
            accumulate: u32::from(xpbd && params.iterations > 1),
            xpbd: u32::from(xpbd),
            distances: self.distances,
            tri_base: self.tri_base,
            lambdas: self.lambdas,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&p));
        let mut table = vec![0u8; (sub_needed as u64 * TABLE_STRIDE) as usize];
        for k in 0..steps {
            for s in 0..substeps {
                let j = (k * substeps + s) as usize;
                let jump = input
                    .teleports
                    .get(k as usize)
                    .copied()
                    .filter(|o| s == 0 && *o != Vec3::ZERO && o.is_finite());
                let e = SubstepEntry {
                    substep: s,
                    pin_base: k * self.pins,
                    pose_base: (k * substeps + s) * c,
                    snap: u32::from(jump.is_some()),
                    t: (s + 1) as f32 / substeps as f32,
                    offset: jump.unwrap_or(Vec3::ZERO).to_array(),
                };
                let at = j * TABLE_STRIDE as usize;
                table[at..at + size_of::<SubstepEntry>()].copy_from_slice(bytemuck::bytes_of(&e));
            }
        }
        queue.write_buffer(&self.substep_table, 0, &table);
        let pins: Vec<GpuPin> = pin_targets
            .iter()
            .flat_map(|targets| {
                sim.state()
                    .pins()
                    .iter()
                    .zip(targets)
                    .map(|(pin, t)| GpuPin {
                        vertex: pin.vertex,
                        _pad: [0; 3],
                        target: t.extend(0.0).to_array(),
                    })
            })
            .collect();
        if !pins.is_empty() {
            queue.write_buffer(&self.pin_buf, 0, bytemuck::cast_slice(&pins));
        }
        if c > 0 {
            let grids: Vec<[u32; 4]> = colliders.iter().map(|c| self.grid_of(c)).collect();
            let mut poses = Vec::new();
            let mut out = Vec::with_capacity(colliders_needed as usize);
            for _ in 0..steps {
                for s in 0..substeps {
                    substep_poses(colliders, s, substeps, &mut poses);
                    for ((col, pose), grid) in colliders.iter().zip(&poses).zip(&grids) {
                        out.push(gpu_collider(col, &pose.from, &pose.to, pose.reach2, *grid));
                    }
                }
            }
            queue.write_buffer(&self.collider_buf, 0, bytemuck::cast_slice(&out));
        }
        let n = self.n as usize;
        let air_at = (4 * n * 16) as u64;
        if input.air_velocities.len() == n {
            queue.write_buffer(
                &self.state,
                air_at,
                bytemuck::cast_slice(input.air_velocities),
            );
        } else if n > 0 {
            queue.write_buffer(&self.state, air_at, &vec![0u8; n * 16]);
        }
        self.substeps = substeps;
        self.iterations = params.iterations.max(1);
        self.prepared = (steps, c);
        self.impulse_slots = slots;
        self.air_on = air_on;
        self.tearing = sim.features().tear_threshold.is_some_and(|t| t > 1.0);
        self.teleports = (0..steps as usize)
            .map(|k| {
                input
                    .teleports
                    .get(k)
                    .is_some_and(|o| *o != Vec3::ZERO && o.is_finite())
            })
            .collect();
    }

    /// Records taking over the positions and velocities of `from`, the state buffer of an
    /// earlier [`GpuCloth`] of the same cloth with as many vertices, keeping this one's inverse
    /// masses (its pins): how new settings go on from where the GPU cloth is. Record it after
    /// [`Self::prepare`] and before [`Self::record`].
    ///
    /// # Panics
    /// If `from` is smaller than this cloth's positions, substep starts and velocities.
    pub fn record_carry(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernels: &GpuKernels,
        from: &wgpu::Buffer,
    ) {
        let Some(bg) = &self.bind_group else {
            return;
        };
        let region = u64::from(self.n) * 16;
        assert!(from.size() >= 3 * region, "the earlier state is smaller");
        if region == 0 {
            return;
        }
        encoder.copy_buffer_to_buffer(from, 0, &self.state, region, region);
        encoder.copy_buffer_to_buffer(from, 2 * region, &self.state, 2 * region, region);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("cloth_carry"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, bg, &[0, 0]);
        pass.set_pipeline(&kernels.carry);
        pass.dispatch_workgroups(self.n.div_ceil(WORKGROUP), 1, 1);
    }

    /// Makes the SDF buffer hold every grid `colliders` use (unless it already does).
    /// Returns whether the buffer was replaced.
    fn upload_grids(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        colliders: &[Collider],
    ) -> bool {
        let mut grids: Vec<Arc<SdfGrid>> = Vec::new();
        for c in colliders {
            if let Shape::Mesh(g) = &c.shape
                && !grids.iter().any(|x| Arc::ptr_eq(x, g))
            {
                grids.push(g.clone());
            }
        }
        let same = grids.len() == self.sdf_grids.len()
            && grids
                .iter()
                .zip(&self.sdf_grids)
                .all(|(a, b)| Arc::ptr_eq(a, b));
        if same {
            return false;
        }
        let total: usize = grids.iter().map(|g| g.values().len()).sum();
        self.sdf_buf = empty(
            device,
            "cloth_sdf",
            (total * 4) as u64,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        );
        let mut at = 0u64;
        for g in &grids {
            if !g.values().is_empty() {
                queue.write_buffer(&self.sdf_buf, at, bytemuck::cast_slice(g.values()));
            }
            at += (g.values().len() * 4) as u64;
        }
        self.sdf_grids = grids;
        true
    }

    /// Where a collider's grid sits in the SDF buffer: samples along x, y, z and the first.
    fn grid_of(&self, c: &Collider) -> [u32; 4] {
        let Shape::Mesh(g) = &c.shape else {
            return [0; 4];
        };
        let mut first = 0;
        for x in &self.sdf_grids {
            if Arc::ptr_eq(x, g) {
                break;
            }
            first += x.values().len() as u32;
        }
        let d = g.dims();
        [d.x, d.y, d.z, first]
    }

    /// Records the steps [`Self::prepare`] wrote for into `encoder` (one compute pass).
    pub fn record(&self, encoder: &mut wgpu::CommandEncoder, kernels: &GpuKernels) {
        let cmds = self.commands(kernels);
        let Some(bg) = self.bind_group.as_ref().filter(|_| !cmds.is_empty()) else {
            return;
        };
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("cloth_step"),
            timestamp_writes: None,
        });
        replay(&mut pass, bg, &cmds);
    }

    /// As [`Self::record`], one compute pass per stage run, each with timestamps into
    /// `queries` (pass `i` writes queries `2i` and `2i + 1`); returns the stage of each pass.
    /// For profiling (the `tradeoff` example): the extra passes cost a little.
    ///
    /// # Panics
    /// If `queries` is smaller than twice the number of passes.
    pub fn record_profiled(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernels: &GpuKernels,
        queries: &wgpu::QuerySet,
    ) -> Vec<GpuStage> {
        let cmds = self.commands(kernels);
        let mut stages = Vec::new();
        let Some(bg) = &self.bind_group else {
            return stages;
        };
        let mut start = 0;
        while start < cmds.len() {
            let Cmd::Stage(stage) = cmds[start] else {
                unreachable!("every run starts with its stage");
            };
            let end = cmds[start + 1..]
                .iter()
                .position(|c| matches!(c, Cmd::Stage(_)))
                .map_or(cmds.len(), |p| start + 1 + p);
            let i = stages.len() as u32;
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(stage.name()),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: queries,
                    beginning_of_pass_write_index: Some(2 * i),
                    end_of_pass_write_index: Some(2 * i + 1),
                }),
            });
            replay(&mut pass, bg, &cmds[start..end]);
            stages.push(stage);
            start = end;
        }
        stages
    }

    /// The dispatches of the prepared steps, each run of one stage headed by its stage.
    fn commands<'k>(&self, kernels: &'k GpuKernels) -> Vec<Cmd<'k>> {
        let (steps, _) = self.prepared;
        let mut out = Vec::new();
        if steps == 0 || self.n == 0 || self.bind_group.is_none() {
            return out;
        }
        let groups = |count: u32| count.div_ceil(WORKGROUP);
        let vertex_groups = groups(self.n);
        let pin_groups = groups(self.pins);
        let sub_offset = |k: u32, s: u32| ((k * self.substeps + s) as u64 * TABLE_STRIDE) as u32;
        let mut stage = None;
        let mut enter = |out: &mut Vec<Cmd<'k>>, s: GpuStage, offsets: [u32; 2]| {
            if stage != Some(s) {
                out.push(Cmd::Stage(s));
                stage = Some(s);
            }
            out.push(Cmd::Bind(offsets));
        };
        if self.impulse_slots > 0 {
            enter(&mut out, GpuStage::Collide, [0, 0]);
            out.push(Cmd::Run(&kernels.impulse_clear, groups(self.impulse_slots)));
        }
        for k in 0..steps {
            let first = sub_offset(k, 0);
            enter(&mut out, GpuStage::Begin, [first, 0]);
            if self.teleports.get(k as usize).copied().unwrap_or(false) {
                out.push(Cmd::Run(&kernels.teleport, vertex_groups));
            }
            if self.pins > 0 {
                out.push(Cmd::Run(&kernels.pins_begin, pin_groups));
            }
            if self.air_on {
                out.push(Cmd::Run(&kernels.areas, vertex_groups));
            }
            if self.lab_base != 0 {
                // The lab solver: no air, colliders, tethers or self-collision (as on the CPU).
                for s in 0..self.substeps {
                    let so = sub_offset(k, s);
                    enter(&mut out, GpuStage::Integrate, [so, 0]);
                    if self.pins > 0 {
                        out.push(Cmd::Run(&kernels.pins_substep, pin_groups));
                        out.push(Cmd::Run(&kernels.lab_pins, pin_groups));
                    }
                    out.push(Cmd::Run(&kernels.lab_integrate, vertex_groups));
                    enter(&mut out, GpuStage::Distance, [so, 0]);
                    for _ in 0..self.iterations {
                        out.push(Cmd::Run(&kernels.lab_gather, vertex_groups));
                        out.push(Cmd::Run(&kernels.lab_apply, vertex_groups));
                    }
                    enter(&mut out, GpuStage::Finish, [so, 0]);
                    out.push(Cmd::Run(&kernels.lab_finish, vertex_groups));
                }
                out.push(Cmd::Run(&kernels.guard, vertex_groups));
                if self.tearing && self.distances > 0 {
                    out.push(Cmd::Run(&kernels.tear_check, groups(self.distances)));
                }
                continue;
            }
            if self.sc.size > 0 {
                enter(&mut out, GpuStage::SelfCollision, [first, 0]);
                out.push(Cmd::Run(&kernels.sc_clear, groups(self.sc.size)));
                out.push(Cmd::Run(&kernels.sc_speed, vertex_groups));
                out.push(Cmd::Run(&kernels.sc_count, vertex_groups));
                out.push(Cmd::Run(&kernels.sc_scan, 1));
                out.push(Cmd::Run(&kernels.sc_scatter, vertex_groups));
                out.push(Cmd::Run(&kernels.sc_query, vertex_groups));
            }
            for s in 0..self.substeps {
                let so = sub_offset(k, s);
                enter(&mut out, GpuStage::Integrate, [so, 0]);
                if self.pins > 0 {
                    out.push(Cmd::Run(&kernels.pins_substep, pin_groups));
                }
                out.push(Cmd::Run(&kernels.integrate, vertex_groups));
                if self.iterations > 1 && self.lambdas > 0 {
                    out.push(Cmd::Run(&kernels.lambda_clear, groups(self.lambdas)));
                }
                for _ in 0..self.iterations {
                    for (i, p) in self.passes.iter().enumerate() {
                        let ro = (i as u64 * TABLE_STRIDE) as u32;
                        let (pipeline, groups, stage) = match p.kind {
                            PassKind::DistanceColour => (
                                &kernels.distance_colour,
                                groups(p.count),
                                GpuStage::Distance,
                            ),
                            PassKind::DistanceSerial => {
                                (&kernels.distance_serial, 1, GpuStage::Distance)
                            }
                            PassKind::BendColour => {
                                (&kernels.bend_colour, groups(p.count), GpuStage::Bending)
                            }
                            PassKind::BendSerial => (&kernels.bend_serial, 1, GpuStage::Bending),
                        };
                        enter(&mut out, stage, [so, ro]);
                        out.push(Cmd::Run(pipeline, groups));
                    }
                }
                if self.tether_base != 0 {
                    enter(&mut out, GpuStage::Tethers, [so, 0]);
                    out.push(Cmd::Run(&kernels.tethers, vertex_groups));
                }
                if self.sc.size > 0 {
                    enter(&mut out, GpuStage::SelfCollision, [so, 0]);
                    out.push(Cmd::Run(&kernels.sc_collide, vertex_groups));
                    out.push(Cmd::Run(&kernels.sc_apply, vertex_groups));
                }
                if self.prepared.1 > 0 {
                    enter(&mut out, GpuStage::Collide, [so, 0]);
                    out.push(Cmd::Run(&kernels.collide, vertex_groups));
                }
            }
            let last = sub_offset(k, self.substeps - 1);
            enter(&mut out, GpuStage::Finish, [last, 0]);
            out.push(Cmd::Run(&kernels.finish, vertex_groups));
            if self.pins > 0 {
                out.push(Cmd::Run(&kernels.pins_finish, pin_groups));
            }
            out.push(Cmd::Run(&kernels.guard, vertex_groups));
            if self.tearing && self.distances > 0 {
                out.push(Cmd::Run(&kernels.tear_check, groups(self.distances)));
            }
        }
        out
    }

    /// Reads positions and velocities back (blocking: for tests and tools; the plugin reads
    /// back asynchronously).
    #[must_use]
    pub fn read_state(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> (Vec<Vec4>, Vec<Vec4>) {
        let n = self.n as usize;
        if n == 0 {
            return (Vec::new(), Vec::new());
        }
        let all = self.read(device, queue, 0, 3 * n as u64 * 16);
        (all[..n].to_vec(), all[2 * n..3 * n].to_vec())
    }

    /// Whether a step since the last upload left a NaN or infinite position or velocity
    /// (blocking, as [`Self::read_state`]).
    #[must_use]
    pub fn read_failed(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> bool {
        self.read(device, queue, self.status_offset(), 16)[0].x != 0.0
    }

    /// Where the impulse slots of the last prepared frame sit in [`Self::scratch_buffer`]:
    /// byte offset and size (0 without colliders). Sum them with [`sum_impulses`].
    #[must_use]
    pub fn impulse_region(&self) -> (u64, u64) {
        (self.sc.len * 4, u64::from(self.impulse_slots) * 4)
    }

    /// The scratch buffer (self-collision's hash and lists, then the impulse slots).
    #[must_use]
    pub fn scratch_buffer(&self) -> &wgpu::Buffer {
        &self.scratch
    }

    /// The impulse the cloth gave each collider over the last recorded frame (the sum of its
    /// steps' [`StepScratch::impulses`](crate::solver::StepScratch::impulses)), blocking, as
    /// [`Self::read_state`].
    #[must_use]
    pub fn read_impulses(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Vec<crate::solver::ContactImpulse> {
        let (offset, size) = self.impulse_region();
        if size == 0 {
            return Vec::new();
        }
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cloth_impulses"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        encoder.copy_buffer_to_buffer(&self.scratch, offset, &staging, 0, size);
        queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, .., |_| {});
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&staging.get_mapped_range(..));
        staging.unmap();
        sum_impulses(&words, self.prepared.1 as usize)
    }

    /// Whether the end of a step since the last upload had an edge stretched past the tear
    /// threshold (blocking, as [`Self::read_state`]). The GPU does not tear: the caller does,
    /// on the CPU, and uploads the torn cloth.
    #[must_use]
    pub fn read_torn(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> bool {
        self.read(device, queue, self.status_offset(), 16)[0].y != 0.0
    }

    fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        offset: u64,
        size: u64,
    ) -> Vec<Vec4> {
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cloth_readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        encoder.copy_buffer_to_buffer(&self.state, offset, &staging, 0, size);
        queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, .., |r| {
            if let Err(e) = r {
                bevy::log::error!("cloth readback failed: {e}");
            }
        });
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let all: Vec<Vec4> = bytemuck::pod_collect_to_vec(&staging.get_mapped_range(..));
        staging.unmap();
        all
    }
}
