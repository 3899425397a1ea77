//! [`GpuWorld`]: every cloth that steps with the same substeps and iterations, packed into
//! one set of GPU buffers and stepped by a few dispatches per substep for all of them.
//!
//! A frame records, per step: `step_begin` (pins' starts, area vectors, the self-collision
//! hash; `teleport` first in a step where a cloth is carried or teleports), `sc_query` with
//! self-collision; per substep and iteration: `solve` over every cloth's parts (their
//! vertices integrated first), then over the seams (the even ones, then the odd ones, in a
//! world with a cloth whose neighbouring seams overlap) and the boundaries (each only if some
//! cloth has one); `sc_collide` with self-collision; `finish_substep`
//! (tethers, the self-collision correction, colliders) when any of those acts; per step
//! `step_end` (velocities, the NaN guard), `settle_begin` (after `step_begin`), `settle_end`
//! and `settle_update` in the steps after a world is built with a settling cloth (its solver,
//! substeps, iterations, tethers or the fixed timestep changed; up to
//! [`MAX_SETTLE_STEPS`](crate::solver::MAX_SETTLE_STEPS)), and `tear_check` and
//! `tear_release` with tearing
//! (an edge past the threshold and the edges its tear leaves without a triangle hold nothing
//! from the next step on, as on the CPU, until the host tears the topology). That is at most 6
//! dispatches a substep however many colours, parts or cloths there are
//! ([`GpuWorld::dispatches`] counts them). The lab solver has kernels of its own.
//!
//! Its CPU twin is `solver::step` with the same batches (`Simulation::set_part_count` with
//! [`GpuWorld::part_count`]); self-collision has one form on both backends. `tests/gpu_parity.rs`
//! compares the two.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};
use wgpu::util::DeviceExt;

use super::kernels::{
    DeviceSizeLimits, GpuKernels, GpuUnsupported, TABLE_STRIDE, WORKGROUP, dispatch_flat,
};
use super::layout::{BatchesCell, ClothLayout, WorldKey, WorldLayout};
use crate::solver::collision::substep_poses;
use crate::solver::{
    Carry, Collider, ContactImpulse, MAX_SELF_NEIGHBOURS, MAX_SELF_TRIANGLES, Pose, SdfGrid, Shape,
    Simulation,
};

/// A cloth's torn-edge flags in a buffer ([`GpuWorld::torn_flags`]): one `u32` per distance
/// constraint, 1 once its edge tore past the threshold, 2 once the edge was let go of for
/// want of a triangle, 0 while it holds.
#[derive(Clone, Debug)]
pub struct TornFlags {
    /// Byte offset of the first flag.
    pub at: u64,
    /// Bytes of flags (4 each).
    pub bytes: u64,
    /// The edge of each flag (the cloth's own vertex indices).
    pub edge_of: Arc<[[u32; 2]]>,
}

impl TornFlags {
    /// The edges of `flags` (the flags' bytes as read back, [`Self::bytes`] of them).
    #[must_use]
    pub fn edges(&self, flags: &[u8]) -> TornEdges {
        let flags: Vec<u32> = bytemuck::pod_collect_to_vec(&flags[..self.bytes as usize]);
        let mut out = TornEdges::default();
        for (&f, &e) in flags.iter().zip(self.edge_of.iter()) {
            if f == 1 {
                out.torn.push(e);
            }
            if f != 0 {
                out.released.push(e);
            }
        }
        out
    }
}

/// What a world's GPU tore of a cloth ([`GpuWorld::read_torn_edges`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TornEdges {
    /// The edges found past the tear threshold.
    pub torn: Vec<[u32; 2]>,
    /// The edges that hold nothing: the torn ones and those their tears left without a
    /// triangle.
    pub released: Vec<[u32; 2]>,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct WorldUniform {
    h: f32,
    inv_h: f32,
    inv_h2: f32,
    dt: f32,
    n: u32,
    cloths: u32,
    pins: u32,
    steps: u32,
    prev_at: u32,
    vel_at: u32,
    area_at: u32,
    air_at: u32,
    corr_at: u32,
    rest_at: u32,
    pin_start_at: u32,
    status_at: u32,
    lambda_at: u32,
    lambda_bend_at: u32,
    cloth_at: u32,
    vertex_cloth_at: u32,
    vertex_pin_at: u32,
    group_at: u32,
    tri_offsets_at: u32,
    tri_at: u32,
    tether_at: u32,
    lab_at: u32,
    edges_at: u32,
    edges: u32,
    bend_at: u32,
    speed_at: u32,
    head_at: u32,
    next_at: u32,
    ncount_at: u32,
    nlist_at: u32,
    impulse_at: u32,
    impulse_slots: u32,
    collider_slots: u32,
    cloth_step_at: u32,
    tcount_at: u32,
    tlist_at: u32,
    first_tri_at: u32,
    torn_at: u32,
    edge_tris_at: u32,
    dead_at: u32,
    settle_speed_at: u32,
    settle_strain_at: u32,
    settle_edges_at: u32,
    settle_edges: u32,
    sc_triangle_scale_at: u32,
    react_at: u32,
    opened_at: u32,
    unmoving_at: u32,
    frame_speed_at: u32,
    // With these the uniform's size is a multiple of 16 bytes.
    pad: [u32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct SubstepEntry {
    step: u32,
    substep: u32,
    t: f32,
    pose_at: u32,
    colliders: u32,
    pin_at: u32,
    cloth_step_at: u32,
    /// This step's motion targets in `frame` (start, end and backstop per vertex).
    motion_at: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct LevelEntry {
    first: u32,
    count: u32,
    flags: u32,
    _pad: u32,
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
    slot: [u32; 4],
}

/// A stage of the GPU step, as [`GpuWorld::record_profiled`] times it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum GpuStage {
    /// Once per step before the substeps: pins' starts, area vectors, the self-collision
    /// hash, teleports; the impulse slots cleared once a frame.
    Begin,
    /// Every part of every cloth: its vertices integrated, its constraints projected.
    Parts,
    /// The seams between parts and the boundaries.
    Seams,
    /// Self-collision: the neighbour lists once per step, the corrections per substep.
    SelfCollision,
    /// Tethers, the self-collision correction and the colliders, per substep.
    Contact,
    /// End-of-step velocities, the NaN guard, the tear check.
    Finish,
}

impl GpuStage {
    /// Every stage, in step order.
    pub const ALL: [GpuStage; 6] = [
        GpuStage::Begin,
        GpuStage::Parts,
        GpuStage::Seams,
        GpuStage::SelfCollision,
        GpuStage::Contact,
        GpuStage::Finish,
    ];

    /// A short lowercase name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            GpuStage::Begin => "begin",
            GpuStage::Parts => "parts",
            GpuStage::Seams => "seams",
            GpuStage::SelfCollision => "self_collision",
            GpuStage::Contact => "contact",
            GpuStage::Finish => "finish",
        }
    }
}

/// How many dispatches a recorded frame issues.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DispatchCount {
    /// In the whole frame (every step, for every cloth of the world).
    pub per_frame: u32,
    /// In the busiest substep (its solve, seam, self-collision and contact dispatches).
    pub per_substep: u32,
}

/// One recorded command of a frame.
enum Cmd<'k> {
    /// A run of one stage starts (a pass boundary when profiling).
    Stage(GpuStage),
    /// A substep starts (for counting).
    Substep,
    /// Bind with these dynamic offsets (substep, level).
    Bind([u32; 2]),
    /// Dispatch a pipeline over this many workgroups.
    Run(&'k wgpu::ComputePipeline, u32),
}

fn replay(
    pass: &mut wgpu::ComputePass<'_>,
    group: &wgpu::BindGroup,
    cmds: &[Cmd<'_>],
    max_groups: u32,
) {
    for c in cmds {
        match c {
            Cmd::Stage(_) | Cmd::Substep => {}
            Cmd::Bind(offsets) => pass.set_bind_group(0, group, offsets),
            Cmd::Run(pipeline, groups) => {
                pass.set_pipeline(pipeline);
                dispatch_flat(pass, *groups, max_groups);
            }
        }
    }
}

/// The colliders of one step, each with its impulse slot in the frame (an index into the
/// frame's list of colliders, so a collider keeps its slot in every step even if others come
/// and go between steps).
#[derive(Clone, Copy, Debug, Default)]
pub struct StepColliders<'a> {
    /// The step's colliders (poses at its start and end).
    pub colliders: &'a [Collider],
    /// Each collider's slot; empty: `0..colliders.len()`.
    pub slots: &'a [u32],
}

impl<'a> StepColliders<'a> {
    /// `colliders`, in slots `0..len`.
    #[must_use]
    pub fn new(colliders: &'a [Collider]) -> Self {
        Self {
            colliders,
            slots: &[],
        }
    }

    fn slot(&self, k: usize) -> u32 {
        self.slots.get(k).copied().unwrap_or(k as u32)
    }
}

/// What one cloth of a world feels in a frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothFrame<'a> {
    /// The first step of the frame the cloth takes (a cloth that joined mid-frame takes the
    /// last ones only); it takes every step from there on. The number of steps or more: it
    /// takes none (asleep, or held in the world); a frame in which no cloth takes a step
    /// records no step at all.
    pub first_step: u32,
    /// Per step it takes, every pin's target at the step's end (in the simulation's pin
    /// order).
    pub pin_targets: &'a [Vec<Vec3>],
    /// Per step it takes, how far the whole cloth jumps at the step's start (the teleport
    /// rule); empty or zero for none.
    pub teleports: &'a [Vec3],
    /// Per step it takes, the rigid motion carried at the step's start, before the teleport
    /// (the part of its `ClothInertia` anchor's motion the cloth does not feel); empty or
    /// [`Carry::IDENTITY`] for none.
    pub carries: &'a [Carry],
    /// The air's velocity at each vertex (`w` ignored); empty for still air.
    pub air_velocities: &'a [Vec4],
    /// Per step it takes, where the skin holds each vertex ([`MotionTargets`]); empty for
    /// none (or a step with an empty entry).
    pub motion: &'a [MotionTargets],
}

/// One step's motion constraints of one cloth, owned: the GPU twin of
/// [`MotionConstraints`](crate::solver::MotionConstraints) (one entry per vertex in `start`
/// and `end`, none or one in `backstop`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MotionTargets {
    /// Each vertex's target at the start of the step.
    pub start: Vec<Vec4>,
    /// Each vertex's target at the end of the step and its max distance (`w`).
    pub end: Vec<Vec4>,
    /// The skin's normal and the backstop's distance behind it per vertex; empty for none.
    pub backstop: Vec<Vec4>,
    /// Radius of every backstop sphere.
    pub backstop_radius: f32,
}

impl MotionTargets {
    /// A copy of `m`.
    #[must_use]
    pub fn of(m: &crate::solver::MotionConstraints<'_>) -> Self {
        Self {
            start: m.start.to_vec(),
            end: m.end.to_vec(),
            backstop: m.backstop.to_vec(),
            backstop_radius: m.backstop_radius,
        }
    }

    /// The borrowed form the CPU step takes.
    #[must_use]
    pub fn constraints(&self) -> crate::solver::MotionConstraints<'_> {
        crate::solver::MotionConstraints {
            start: &self.start,
            end: &self.end,
            backstop: &self.backstop,
            backstop_radius: self.backstop_radius,
        }
    }
}

/// A frame's inputs: the step length, per step the colliders, per cloth its own.
#[derive(Clone, Debug, Default)]
pub struct GpuFrame<'a> {
    /// Seconds per step.
    pub dt: f32,
    /// Per step, the colliders (one entry per step: the number of steps).
    pub steps: Vec<StepColliders<'a>>,
    /// Per cloth of the world, in the world's order.
    pub cloths: Vec<ClothFrame<'a>>,
}

impl<'a> GpuFrame<'a> {
    /// Whether some cloth has motion targets this frame.
    fn any_motion(&self) -> bool {
        self.cloths
            .iter()
            .any(|f| f.motion.iter().any(|m| !m.end.is_empty()))
    }

    /// `steps` steps of `dt` among the same `colliders`, every cloth taking every step with
    /// `pin_targets[c]` (per step) and no teleport or air.
    #[must_use]
    pub fn uniform(
        dt: f32,
        steps: usize,
        colliders: &'a [Collider],
        pin_targets: &'a [Vec<Vec<Vec3>>],
    ) -> Self {
        Self {
            dt,
            steps: vec![StepColliders::new(colliders); steps],
            cloths: pin_targets
                .iter()
                .map(|t| ClothFrame {
                    pin_targets: t,
                    ..Default::default()
                })
                .collect(),
        }
    }
}

/// Where the regions of `state` start (vec4 indices).
#[derive(Clone, Copy, Debug, Default)]
struct Regions {
    prev: u32,
    vel: u32,
    area: u32,
    air: u32,
    corr: u32,
    rest: u32,
    unmoving: u32,
    pin_start: u32,
    status: u32,
    lambda: u32,
    lambda_bend: u32,
    len: u32,
}

/// Where the parts of `scratch` start (u32 indices).
#[derive(Clone, Copy, Debug, Default)]
struct ScratchRegions {
    speed: u32,
    head: u32,
    next: u32,
    ncount: u32,
    nlist: u32,
    tcount: u32,
    tlist: u32,
    react: u32,
    torn: u32,
    dead: u32,
    opened: u32,
    settle_speed: u32,
    settle_strain: u32,
    /// Per cloth, the largest squared speed a free vertex ended a step of the frame with.
    frame_speed: u32,
    impulse: u32,
}

/// Per cloth of `layout`, the edge (its own vertices) of each of its torn-edge flags, for a
/// tearing cloth with distance constraints.
pub(crate) fn torn_edge_tables(layout: &WorldLayout) -> Vec<Option<Arc<[[u32; 2]]>>> {
    let edges = &layout.topo[layout.edges_at as usize..][..4 * layout.edges as usize];
    layout
        .cloths
        .iter()
        .map(|c| {
            if !c.tearing || c.distances.is_empty() {
                return None;
            }
            let mut table = vec![[u32::MAX; 2]; c.distances.len()];
            for e in edges.chunks_exact(4) {
                if c.distances.contains(&e[3]) {
                    table[(e[3] - c.distances.start) as usize] = [e[0] - c.vbase, e[1] - c.vbase];
                }
            }
            Some(table.into())
        })
        .collect()
}

/// Whether a world of `layout` fits the device: its largest dispatch within the workgroups
/// three dimensions reach, each of its buffers (name, bytes) made and bound whole.
///
/// # Errors
/// The first limit passed, in words, with the world's size.
fn check_sizes(
    limits: &DeviceSizeLimits,
    layout: &WorldLayout,
    buffers: &[(&str, u64)],
) -> Result<(), GpuUnsupported> {
    let limit = limits.storage_binding.min(limits.buffer);
    let what = match layout.cloths.len() {
        1 => format!("a cloth of {} vertices needs", layout.n),
        c => format!("{c} cloths of {} vertices together need", layout.n),
    };
    // The most workgroups a dispatch of the world takes (vertices, edges, the settling's
    // edges; the constraint groups of a level are fewer than the vertices).
    let items = layout.n.max(layout.edges).max(layout.settle_edges);
    if !limits.dispatches(u64::from(items.div_ceil(WORKGROUP))) {
        return Err(GpuUnsupported(format!(
            "{what} {} workgroups in one dispatch, more than the adapter's {} a dimension \
             reach",
            items.div_ceil(WORKGROUP),
            limits.groups_per_dimension
        )));
    }
    match buffers.iter().find(|(_, bytes)| !limits.binds(*bytes)) {
        None => Ok(()),
        Some((name, bytes)) => Err(GpuUnsupported(format!(
            "{what} a {name} buffer of {} MB on the GPU, more than the adapter binds ({} MB)",
            bytes.div_ceil(1 << 20),
            limit >> 20
        ))),
    }
}

/// The capacity a buffer of `needed` elements of `size` bytes grows to: the next power of
/// two, or `needed` itself where that would not bind.
fn grown(needed: u64, size: u64, limits: &DeviceSizeLimits) -> u64 {
    let doubled = needed.next_power_of_two();
    if limits.binds(doubled * size) {
        doubled
    } else {
        needed
    }
}

/// The mesh colliders' grids of `steps`, each once, in the order they first appear.
fn frame_grids<'a, 's: 'a>(
    steps: impl Iterator<Item = &'a StepColliders<'s>>,
) -> Vec<Arc<SdfGrid>> {
    let mut grids: Vec<Arc<SdfGrid>> = Vec::new();
    for c in steps.flat_map(|s| s.colliders) {
        if let Shape::Mesh(g) = &c.shape
            && !grids.iter().any(|x| Arc::ptr_eq(x, g))
        {
            grids.push(g.clone());
        }
    }
    grids
}

fn storage_init(device: &wgpu::Device, label: &str, bytes: &[u8]) -> wgpu::Buffer {
    // Bindings may not be empty: at least one 16-byte element.
    let zero = [0u8; 16];
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: if bytes.is_empty() { &zero } else { bytes },
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
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

/// `vec4`s of a cloth's record per step in `frame`: flags and teleport, then the carried
/// motion (`shaders/common.wgsl`'s `CLOTH_STEP_VEC4S`).
const CLOTH_STEP_VEC4S: u32 = 4;

/// Vec4s per vertex and step of the motion targets in `frame`: start (w: backstop radius),
/// end (w: max distance), backstop normal (w: distance behind the skin).
const MOTION_VEC4S: u32 = 3;

const RW: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_DST)
    .union(wgpu::BufferUsages::COPY_SRC);
const RO: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_DST);
const UNIFORM: wgpu::BufferUsages = wgpu::BufferUsages::UNIFORM.union(wgpu::BufferUsages::COPY_DST);

fn pose_t(p: &Pose) -> [f32; 4] {
    p.translation.extend(p.scale).to_array()
}

fn gpu_collider(
    c: &Collider,
    from: &Pose,
    to: &Pose,
    reach2: f32,
    grid: [u32; 4],
    slot: u32,
) -> GpuCollider {
    let (kind, shape) = match &c.shape {
        Shape::Sphere { radius } => (0.0, [*radius, 0.0, 0.0, 0.0]),
        Shape::Cuboid { half_extents } => (1.0, half_extents.extend(0.0).to_array()),
        Shape::Capsule {
            radius,
            half_length,
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
        slot: [slot, 0, 0, 0],
    }
}

/// Several cloths' buffers on the GPU, stepped together.
#[derive(Debug)]
pub struct GpuWorld {
    layout: WorldLayout,
    /// Per tearing cloth, the edge (its own vertices) of each of its torn-edge flags.
    torn_edge_of: Vec<Option<Arc<[[u32; 2]]>>>,
    /// A tearing cloth was carried in and the tear check has not run on its state yet (the
    /// frame of the carry may have no step).
    tear_after_carry: bool,
    regions: Regions,
    scratch_regions: ScratchRegions,
    uniform: wgpu::Buffer,
    substep_table: wgpu::Buffer,
    substep_capacity: u32,
    level_table: wgpu::Buffer,
    level_capacity: u32,
    state: wgpu::Buffer,
    cons: wgpu::Buffer,
    scratch: wgpu::Buffer,
    scratch_capacity: u64,
    frame: wgpu::Buffer,
    frame_capacity: u64,
    colliders: wgpu::Buffer,
    collider_capacity: u64,
    topo: wgpu::Buffer,
    sdf: wgpu::Buffer,
    sdf_grids: Vec<Arc<SdfGrid>>,
    bind_group: Option<wgpu::BindGroup>,
    /// What the last [`GpuWorld::prepare`] wrote for: steps, per step whether a cloth
    /// teleports and how many colliders it has; the frame's collider slots.
    steps: u32,
    teleport_steps: Vec<bool>,
    /// Whether the prepared frame holds some cloth to motion targets.
    any_motion: bool,
    step_colliders: Vec<u32>,
    collider_slots: u32,
    impulse_words: u32,
    /// The last frame's impulses did not fit the device.
    impulses_dropped: bool,
    /// Why the last frame took no step: its inputs did not fit the device.
    inputs_too_large: Option<String>,
    /// Carries recorded for this frame: (first vertex, vertices).
    carries: Vec<(u32, u32)>,
    /// Steps that still record the settle kernels (a cloth of the world settles a settings
    /// change; the kernels end it when it is over), and whether a frame with steps was
    /// recorded yet (a cloth built mid-frame sits out that frame's first steps).
    settle_left: u32,
    settle_started: bool,
}

impl GpuWorld {
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
        if sim.params().bending_solve == crate::solver::BendingSolve::Implicit
            && sim.wants_implicit_bending(dt)
        {
            return Err(GpuUnsupported(
                "implicit bending (BendingSolve::Implicit) runs on the CPU only".to_owned(),
            ));
        }
        Ok(())
    }

    /// Uploads `sims`' constraints and states as one world. They must share a
    /// [`WorldKey`] (substeps, iterations, lab solver or not); check
    /// [`GpuWorld::supports`] first.
    ///
    /// # Errors
    /// The cloths do not share a key, or need buffers larger than the device allows.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        kernels: &GpuKernels,
        sims: &[&Simulation],
    ) -> Result<Self, GpuUnsupported> {
        let cells: Vec<BatchesCell> = sims.iter().map(|_| BatchesCell::default()).collect();
        let cells: Vec<&BatchesCell> = cells.iter().collect();
        Self::with_batches(device, queue, kernels, sims, &cells)
    }

    /// [`GpuWorld::new`] with each cloth's GPU batches taken from (or made into) its upload's
    /// cell, so that a world laid out again for another cloth's change does not partition and
    /// colour this one again.
    pub(crate) fn with_batches(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        kernels: &GpuKernels,
        sims: &[&Simulation],
        cells: &[&BatchesCell],
    ) -> Result<Self, GpuUnsupported> {
        if let Some(first) = sims.first()
            && sims.iter().any(|s| WorldKey::of(s) != WorldKey::of(first))
        {
            return Err(GpuUnsupported(
                "a world's cloths share substeps, iterations and solver kind".to_owned(),
            ));
        }
        let batches: Vec<&crate::solver::ConstraintBatches> =
            sims.iter().zip(cells).map(|(s, c)| c.get(s)).collect();
        let layout = WorldLayout::build_with(sims, &batches);
        let n = layout.n;
        let c = layout.cloths.len() as u32;
        let sc = layout.any_sc;
        let mut r = Regions {
            prev: n,
            vel: 2 * n,
            area: 3 * n,
            air: 4 * n,
            ..Default::default()
        };
        let mut at = 5 * n;
        if sc {
            r.corr = at;
            r.rest = at + n;
            r.unmoving = at + 2 * n;
            at += 3 * n;
        }
        r.pin_start = at;
        at += layout.pins;
        r.status = at;
        at += c;
        if layout.any_accumulate {
            r.lambda = at;
            r.lambda_bend = at + layout.distances;
            at += layout.distances + layout.hinges;
        }
        r.len = at;
        let mut s = ScratchRegions {
            speed: 0,
            ..Default::default()
        };
        let mut words = c;
        if sc {
            s.head = words;
            s.next = s.head + layout.head_words;
            s.ncount = s.next + n;
            s.nlist = s.ncount + n;
            s.tcount = s.nlist + n * MAX_SELF_NEIGHBOURS as u32;
            s.tlist = s.tcount + n;
            s.react = s.tlist + n * MAX_SELF_TRIANGLES as u32;
            words = s.react + 4 * n;
        }
        if layout.any_tearing {
            s.torn = words;
            s.dead = s.torn + layout.distances;
            s.opened = s.dead + layout.triangles;
            words = s.opened + c;
        }
        if layout.settle_steps > 0 {
            s.settle_speed = words;
            s.settle_strain = words + n;
            words = s.settle_strain + c;
        }
        s.frame_speed = words;
        words += c;
        s.impulse = words;
        let state_bytes = u64::from(r.len) * 16;
        let scratch_bytes = u64::from(words) * 4;
        check_sizes(
            &kernels.limits,
            &layout,
            &[
                ("state", state_bytes),
                ("scratch", scratch_bytes),
                ("constraint", layout.cons.len() as u64 * 16),
                ("topology", layout.topo.len() as u64 * 4),
            ],
        )?;
        let mut world = Self {
            regions: r,
            scratch_regions: s,
            uniform: empty(
                device,
                "cloth_world",
                size_of::<WorldUniform>() as u64,
                UNIFORM,
            ),
            substep_table: empty(device, "cloth_substeps", TABLE_STRIDE, UNIFORM),
            substep_capacity: 1,
            level_table: empty(device, "cloth_levels", 8 * TABLE_STRIDE, UNIFORM),
            level_capacity: 8,
            state: empty(device, "cloth_state", state_bytes, RW),
            cons: storage_init(
                device,
                "cloth_constraints",
                bytemuck::cast_slice(&layout.cons),
            ),
            scratch: empty(device, "cloth_scratch", scratch_bytes, RW),
            scratch_capacity: u64::from(words),
            frame: empty(device, "cloth_frame", 16, RO),
            frame_capacity: 1,
            colliders: empty(
                device,
                "cloth_colliders",
                size_of::<GpuCollider>() as u64,
                RO,
            ),
            collider_capacity: 1,
            topo: storage_init(device, "cloth_topology", bytemuck::cast_slice(&layout.topo)),
            sdf: empty(device, "cloth_sdf", 16, RO),
            sdf_grids: Vec::new(),
            bind_group: None,
            steps: 0,
            teleport_steps: Vec::new(),
            any_motion: false,
            step_colliders: Vec::new(),
            collider_slots: 0,
            impulse_words: 0,
            impulses_dropped: false,
            inputs_too_large: None,
            carries: Vec::new(),
            settle_left: layout.settle_steps,
            settle_started: false,
            torn_edge_of: torn_edge_tables(&layout),
            tear_after_carry: false,
            layout,
        };
        // Zeroed scratch (empty hash) and state (status clear), then the rest positions and
        // every cloth's state.
        queue.write_buffer(&world.scratch, 0, &vec![0u8; scratch_bytes as usize]);
        queue.write_buffer(&world.state, 0, &vec![0u8; state_bytes as usize]);
        if sc {
            queue.write_buffer(
                &world.state,
                u64::from(world.regions.rest) * 16,
                bytemuck::cast_slice(&world.layout.rest),
            );
        }
        for (i, sim) in sims.iter().enumerate() {
            world.upload_state(queue, i, sim);
            // A settle in progress: the steps it has left and its last strain (the CPU's
            // infinity as the largest finite `f32`: the same comparisons).
            let (left, strain) = sim.settle_state();
            if left > 0 {
                let zw = [left as f32, strain.min(f32::MAX)];
                let at = world.status_offset(i) + 8;
                queue.write_buffer(&world.state, at, bytemuck::cast_slice(&zw));
            }
        }
        world.bind(device, kernels);
        Ok(world)
    }

    fn bind(&mut self, device: &wgpu::Device, kernels: &GpuKernels) {
        fn whole(b: &wgpu::Buffer) -> wgpu::BindingResource<'_> {
            b.as_entire_binding()
        }
        fn table(b: &wgpu::Buffer, size: usize) -> wgpu::BindingResource<'_> {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: b,
                offset: 0,
                size: core::num::NonZeroU64::new(size as u64),
            })
        }
        fn entry(binding: u32, resource: wgpu::BindingResource<'_>) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry { binding, resource }
        }
        self.bind_group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cloth_world"),
            layout: &kernels.layout,
            entries: &[
                entry(0, whole(&self.uniform)),
                entry(1, table(&self.substep_table, size_of::<SubstepEntry>())),
                entry(2, table(&self.level_table, size_of::<LevelEntry>())),
                entry(3, whole(&self.state)),
                entry(4, whole(&self.cons)),
                entry(5, whole(&self.scratch)),
                entry(6, whole(&self.frame)),
                entry(7, whole(&self.colliders)),
                entry(8, whole(&self.topo)),
                entry(9, whole(&self.sdf)),
            ],
        }));
    }

    /// Number of cloths.
    #[must_use]
    pub fn cloths(&self) -> usize {
        self.layout.cloths.len()
    }

    /// Vertices of every cloth.
    #[must_use]
    pub fn len(&self) -> usize {
        self.layout.n as usize
    }

    /// Whether the world has no vertex.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.layout.n == 0
    }

    fn cloth(&self, cloth: usize) -> &ClothLayout {
        &self.layout.cloths[cloth]
    }

    /// Vertices of cloth `cloth`.
    #[must_use]
    pub fn cloth_len(&self, cloth: usize) -> usize {
        self.cloth(cloth).n as usize
    }

    /// The first vertex of cloth `cloth` in every per-vertex region.
    #[must_use]
    pub fn vertex_base(&self, cloth: usize) -> u32 {
        self.cloth(cloth).vbase
    }

    /// How many parts the GPU projects cloth `cloth` in: its CPU twin is the simulation with
    /// `set_part_count(part_count)`.
    #[must_use]
    pub fn part_count(&self, cloth: usize) -> usize {
        self.cloth(cloth).parts
    }

    /// The key every cloth of the world shares.
    #[must_use]
    pub fn key(&self) -> WorldKey {
        WorldKey {
            substeps: self.layout.substeps,
            iterations: self.layout.iterations,
            lab: self.layout.lab,
        }
    }

    /// The state buffer: positions (`vec4`, `w` the inverse mass) of every vertex from
    /// offset 0, velocities at [`Self::velocities_range`] (what a mesh-writing kernel and a
    /// readback read).
    #[must_use]
    pub fn state_buffer(&self) -> &wgpu::Buffer {
        &self.state
    }

    /// Byte offset of cloth `cloth`'s positions in [`Self::state_buffer`], and their size.
    #[must_use]
    pub fn positions_range(&self, cloth: usize) -> (u64, u64) {
        let c = self.cloth(cloth);
        (u64::from(c.vbase) * 16, u64::from(c.n) * 16)
    }

    /// Byte offset of cloth `cloth`'s velocities in [`Self::state_buffer`], and their size.
    #[must_use]
    pub fn velocities_range(&self, cloth: usize) -> (u64, u64) {
        let c = self.cloth(cloth);
        (
            u64::from(self.regions.vel + c.vbase) * 16,
            u64::from(c.n) * 16,
        )
    }

    /// Byte offset of cloth `cloth`'s status `vec4` in [`Self::state_buffer`]: `x` turns 1
    /// at the end of a step that left a NaN or infinite position or velocity, `y` when an
    /// edge was stretched past the tear threshold.
    #[must_use]
    pub fn status_offset(&self, cloth: usize) -> u64 {
        u64::from(self.regions.status + cloth as u32) * 16
    }

    /// Replaces cloth `cloth`'s GPU state with `sim`'s positions and velocities, and clears
    /// its status flags.
    pub fn upload_state(&self, queue: &wgpu::Queue, cloth: usize, sim: &Simulation) {
        let s = sim.state();
        self.upload(queue, cloth, &s.positions, &s.velocities);
    }

    /// Replaces cloth `cloth`'s GPU state with `positions` (`w`: inverse mass, 0 when pinned)
    /// and `velocities`, one per vertex, and clears its status flags (a settle in progress
    /// goes on, as on the CPU). Edges flagged torn stay so: they belong to the world's
    /// topology, which only a rebuild changes.
    ///
    /// # Panics
    /// If either has not [`Self::cloth_len`] entries.
    pub fn upload(
        &self,
        queue: &wgpu::Queue,
        cloth: usize,
        positions: &[Vec4],
        velocities: &[Vec4],
    ) {
        let c = self.cloth(cloth);
        let n = c.n as usize;
        assert!(
            positions.len() == n && velocities.len() == n,
            "one position and one velocity per vertex"
        );
        if n == 0 {
            return;
        }
        let at = |region: u32| u64::from(region + c.vbase) * 16;
        queue.write_buffer(&self.state, at(0), bytemuck::cast_slice(positions));
        queue.write_buffer(
            &self.state,
            at(self.regions.prev),
            bytemuck::cast_slice(positions),
        );
        queue.write_buffer(
            &self.state,
            at(self.regions.vel),
            bytemuck::cast_slice(velocities),
        );
        queue.write_buffer(&self.state, self.status_offset(cloth), &[0u8; 8]);
    }

    /// Writes what the frame's steps need: the step length, per step the colliders (their
    /// poses per substep) and every cloth's pin targets and teleport, per cloth its air.
    /// Grows buffers (and rebinds) when needed.
    ///
    /// # Panics
    /// If `frame` does not have one entry per cloth, or a cloth's pin targets do not have
    /// one target per pin for each step it takes.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        kernels: &GpuKernels,
        frame: &GpuFrame<'_>,
    ) {
        let cloths = self.layout.cloths.len();
        assert_eq!(frame.cloths.len(), cloths, "one frame entry per cloth");
        // A frame in which no cloth takes a step (all asleep, or held) takes none: no
        // dispatch but the carries.
        let taken = frame
            .cloths
            .iter()
            .any(|f| (f.first_step as usize) < frame.steps.len());
        let lab = self.layout.lab;
        // Motion targets and mesh colliders' grids (each once), which the lab solver ignores
        // as the CPU's does.
        let any_motion = !lab && frame.any_motion();
        let mut grids = if taken && !lab {
            frame_grids(frame.steps.iter())
        } else {
            Vec::new()
        };
        // A frame whose inputs the device cannot bind takes no step either: its cloths hold
        // still, and `inputs_too_large` says why.
        self.inputs_too_large = None;
        if taken && let Err(why) = self.check_inputs(&kernels.limits, frame, &grids, any_motion) {
            self.inputs_too_large = Some(why);
            grids.clear();
        }
        let frame_steps: &[StepColliders<'_>] = if taken && self.inputs_too_large.is_none() {
            &frame.steps
        } else {
            &[]
        };
        let steps = frame_steps.len() as u32;
        let substeps = self.layout.substeps;
        let dt = frame.dt;
        let h = dt / substeps as f32;
        let mut rebind = false;
        // Colliders (the lab solver ignores them, as on the CPU).
        let no_colliders = StepColliders::default();
        let step_colliders: Vec<&StepColliders<'_>> = frame_steps
            .iter()
            .map(|s| if lab { &no_colliders } else { s })
            .collect();
        rebind |= self.upload_grids(device, queue, grids);
        let slots = step_colliders
            .iter()
            .flat_map(|s| (0..s.colliders.len()).map(|k| s.slot(k) + 1))
            .max()
            .unwrap_or(0);
        let total_poses: u64 = step_colliders
            .iter()
            .map(|s| (s.colliders.len() as u64) * u64::from(substeps))
            .sum();
        if total_poses > self.collider_capacity {
            self.collider_capacity = grown(
                total_poses,
                size_of::<GpuCollider>() as u64,
                &kernels.limits,
            );
            self.colliders = empty(
                device,
                "cloth_colliders",
                self.collider_capacity * size_of::<GpuCollider>() as u64,
                RO,
            );
            rebind = true;
        }
        // Impulse slots: 6 words per finish workgroup and collider slot; none where they would
        // not fit the device (the cloths then push no collider this frame).
        let workgroups = u64::from(self.layout.n.div_ceil(WORKGROUP));
        let wanted_words = workgroups * u64::from(slots) * 6;
        let limits = &kernels.limits;
        let words = u64::from(self.scratch_regions.impulse) + wanted_words;
        self.impulses_dropped = wanted_words > 0
            && (!limits.binds(words * 4)
                || !limits.dispatches(wanted_words.div_ceil(u64::from(WORKGROUP))));
        let (slots, impulse_words) = if self.impulses_dropped {
            (0, 0)
        } else {
            (slots, wanted_words as u32)
        };
        if words > self.scratch_capacity && !self.impulses_dropped {
            // Keep the hash and lists: copy the old scratch into the bigger one.
            let capacity = grown(words, 4, limits);
            let bigger = empty(device, "cloth_scratch", capacity * 4, RW);
            let mut encoder =
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            encoder.copy_buffer_to_buffer(&self.scratch, 0, &bigger, 0, self.scratch.size());
            queue.submit([encoder.finish()]);
            self.scratch = bigger;
            self.scratch_capacity = capacity;
            rebind = true;
        }
        // Tables.
        let sub_needed = (steps * substeps).max(1);
        if sub_needed > self.substep_capacity {
            self.substep_capacity = sub_needed.next_power_of_two();
            self.substep_table = empty(
                device,
                "cloth_substeps",
                u64::from(self.substep_capacity) * TABLE_STRIDE,
                UNIFORM,
            );
            rebind = true;
        }
        let levels_needed = 8 + self.carries.len() as u32;
        if levels_needed > self.level_capacity {
            self.level_capacity = levels_needed.next_power_of_two();
            self.level_table = empty(
                device,
                "cloth_levels",
                u64::from(self.level_capacity) * TABLE_STRIDE,
                UNIFORM,
            );
            rebind = true;
        }
        // `frame`: pin targets per step, then cloth records per step (`CLOTH_STEP_VEC4S`
        // each: flags and teleport, then the carried motion's matrix columns with its offset
        // in their `w`).
        let pins = self.layout.pins;
        // Motion targets: per step 3 vec4 for every vertex of the world (start with the
        // backstop radius in `w`, end with the max distance, backstop normal and distance), when
        // some cloth has them this frame (not on the lab solver, which ignores them as on the
        // CPU).
        let motion_n = if any_motion { self.layout.n } else { 0 };
        let (motion_at_vec4s, frame_vec4s) = self.frame_vec4s(steps, any_motion);
        if frame_vec4s.max(1) > self.frame_capacity {
            self.frame_capacity = grown(frame_vec4s, 16, &kernels.limits);
            self.frame = empty(device, "cloth_frame", self.frame_capacity * 16, RO);
            rebind = true;
        }
        if rebind || self.bind_group.is_none() {
            self.bind(device, kernels);
        }
        let l = &self.layout;
        let r = &self.regions;
        let s = &self.scratch_regions;
        let cloth_step_at = steps * pins;
        let motion_at = motion_at_vec4s as u32;
        let uniform = WorldUniform {
            h,
            inv_h: 1.0 / h,
            inv_h2: 1.0 / (h * h),
            dt,
            n: l.n,
            cloths: cloths as u32,
            pins,
            steps,
            prev_at: r.prev,
            vel_at: r.vel,
            area_at: r.area,
            air_at: r.air,
            corr_at: r.corr,
            rest_at: r.rest,
            pin_start_at: r.pin_start,
            status_at: r.status,
            lambda_at: r.lambda,
            lambda_bend_at: r.lambda_bend,
            cloth_at: l.cloth_at,
            vertex_cloth_at: l.vertex_cloth_at,
            vertex_pin_at: l.vertex_pin_at,
            group_at: l.group_at,
            tri_offsets_at: l.tri_offsets_at,
            tri_at: l.tri_at,
            tether_at: l.tether_at,
            lab_at: l.lab_at,
            edges_at: l.edges_at,
            edges: l.edges,
            bend_at: l.bend_at,
            speed_at: s.speed,
            head_at: s.head,
            next_at: s.next,
            ncount_at: s.ncount,
            nlist_at: s.nlist,
            impulse_at: s.impulse,
            impulse_slots: impulse_words,
            collider_slots: slots,
            cloth_step_at,
            tcount_at: s.tcount,
            tlist_at: s.tlist,
            react_at: s.react,
            first_tri_at: l.first_tri_at,
            torn_at: s.torn,
            edge_tris_at: l.edge_tris_at,
            dead_at: s.dead,
            settle_speed_at: s.settle_speed,
            settle_strain_at: s.settle_strain,
            settle_edges_at: l.settle_edges_at,
            settle_edges: l.settle_edges,
            sc_triangle_scale_at: l.sc_triangle_scale_at,
            opened_at: s.opened,
            unmoving_at: r.unmoving,
            frame_speed_at: s.frame_speed,
            pad: [0; 3],
        };
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&uniform));
        // The frame's largest speeds start from zero.
        if !l.cloths.is_empty() {
            queue.write_buffer(
                &self.scratch,
                u64::from(s.frame_speed) * 4,
                &vec![0u8; 4 * l.cloths.len()],
            );
        }
        // The per-frame words of every cloth's record: gravity·h and the damping factor (the
        // lab solver: the velocity it keeps).
        for (i, c) in l.cloths.iter().enumerate() {
            let damp = c.keep.unwrap_or(1.0 / (1.0 + c.damping * h));
            let g = c.gravity * h;
            let words = [g.x.to_bits(), g.y.to_bits(), g.z.to_bits(), damp.to_bits()];
            let at = (l.cloth_at as usize + i * super::layout::CLOTH_WORDS + 5) * 4;
            queue.write_buffer(&self.topo, at as u64, bytemuck::cast_slice(&words));
        }
        // Substeps, with each step's collider poses.
        let mut table = vec![0u8; (sub_needed as u64 * TABLE_STRIDE) as usize];
        let mut poses = Vec::new();
        let mut gpu_colliders: Vec<GpuCollider> = Vec::with_capacity(total_poses as usize);
        for (k, sc) in step_colliders.iter().enumerate() {
            let k = k as u32;
            let grids: Vec<[u32; 4]> = sc.colliders.iter().map(|c| self.grid_of(c)).collect();
            substep_poses(sc.colliders, substeps, &mut poses);
            let m = sc.colliders.len();
            for sub in 0..substeps {
                let pose_at = gpu_colliders.len() as u32;
                let at = sub as usize * m;
                for (i, ((col, pose), grid)) in sc
                    .colliders
                    .iter()
                    .zip(&poses[at..at + m])
                    .zip(&grids)
                    .enumerate()
                {
                    gpu_colliders.push(gpu_collider(
                        col,
                        &pose.from,
                        &pose.to,
                        pose.reach2,
                        *grid,
                        sc.slot(i),
                    ));
                }
                let e = SubstepEntry {
                    step: k,
                    substep: sub,
                    t: (sub + 1) as f32 / substeps as f32,
                    pose_at,
                    colliders: sc.colliders.len() as u32,
                    pin_at: k * pins,
                    cloth_step_at: cloth_step_at + k * CLOTH_STEP_VEC4S * cloths as u32,
                    motion_at: motion_at + k * MOTION_VEC4S * motion_n,
                };
                let at = ((k * substeps + sub) as u64 * TABLE_STRIDE) as usize;
                table[at..at + size_of::<SubstepEntry>()].copy_from_slice(bytemuck::bytes_of(&e));
            }
        }
        queue.write_buffer(&self.substep_table, 0, &table);
        if !gpu_colliders.is_empty() {
            queue.write_buffer(&self.colliders, 0, bytemuck::cast_slice(&gpu_colliders));
        }
        // Levels: parts, seams (or even seams), odd seams, boundaries; first iteration, then
        // later ones.
        let mut levels = vec![0u8; (self.level_capacity as u64 * TABLE_STRIDE) as usize];
        let mut put = |i: usize, e: LevelEntry| {
            let at = i * TABLE_STRIDE as usize;
            levels[at..at + size_of::<LevelEntry>()].copy_from_slice(bytemuck::bytes_of(&e));
        };
        for (k, lr) in l.levels.iter().enumerate() {
            for (it, flags) in [(0, 2 | u32::from(k == 0)), (1, 0)] {
                put(
                    it * 4 + k,
                    LevelEntry {
                        first: lr.first,
                        count: lr.count,
                        flags,
                        _pad: 0,
                    },
                );
            }
        }
        for (i, &(first, count)) in self.carries.iter().enumerate() {
            put(
                8 + i,
                LevelEntry {
                    first,
                    count,
                    flags: 0,
                    _pad: 0,
                },
            );
        }
        queue.write_buffer(&self.level_table, 0, &levels);
        // Pin targets and cloth records per step.
        let mut data = vec![Vec4::ZERO; frame_vec4s as usize];
        let mut teleport_steps = vec![false; steps as usize];
        for (ci, (c, f)) in l.cloths.iter().zip(&frame.cloths).enumerate() {
            for k in 0..steps {
                let Some(local) = k.checked_sub(f.first_step) else {
                    continue;
                };
                let local = local as usize;
                // A step whose targets are not one per pin (queued for other pins; the main
                // world does not send such steps) is sat out rather than misread.
                let targets = f
                    .pin_targets
                    .get(local)
                    .filter(|t| t.len() == c.pins as usize);
                if let Some(t) = targets {
                    for (p, target) in t.iter().enumerate() {
                        data[(k * pins + c.pin_base) as usize + p] = target.extend(0.0);
                    }
                }
                let jump = f
                    .teleports
                    .get(local)
                    .copied()
                    .filter(|o| *o != Vec3::ZERO && o.is_finite());
                let carry = f
                    .carries
                    .get(local)
                    .copied()
                    .filter(|c| *c != Carry::IDENTITY && c.is_finite());
                teleport_steps[k as usize] |= jump.is_some() || carry.is_some();
                // Flags: 1 takes the step, + 2 teleports, + 4 is carried, + 8 held by motion
                // targets, + 16 its carry stretches (velocities no faster); 0 sits it out (no
                // targets for this step).
                let motion = f
                    .motion
                    .get(local)
                    .filter(|m| any_motion && m.constraints().applies_to(c.n as usize));
                let flag = if targets.is_none() && c.pins > 0 {
                    0.0
                } else {
                    1.0 + if jump.is_some() { 2.0 } else { 0.0 }
                        + if carry.is_some() { 4.0 } else { 0.0 }
                        + if motion.is_some() { 8.0 } else { 0.0 }
                        + if carry.is_some_and(|c| c.stretch.is_some()) {
                            16.0
                        } else {
                            0.0
                        }
                };
                if let Some(m) = motion {
                    let base = (motion_at + k * MOTION_VEC4S * motion_n + c.vbase) as usize;
                    let n = motion_n as usize;
                    let radius = if m.backstop.len() == c.n as usize {
                        m.backstop_radius
                    } else {
                        0.0
                    };
                    for v in 0..c.n as usize {
                        data[base + v] = m.start[v].truncate().extend(radius);
                        data[base + n + v] = m.end[v];
                        data[base + 2 * n + v] = m.backstop.get(v).copied().unwrap_or(Vec4::ZERO);
                    }
                }
                let at =
                    (cloth_step_at + (k * cloths as u32 + ci as u32) * CLOTH_STEP_VEC4S) as usize;
                data[at] = jump.unwrap_or(Vec3::ZERO).extend(flag);
                if let Some(carry) = carry {
                    let (m, b) = carry.affine();
                    data[at + 1] = m.x_axis.extend(b.x);
                    data[at + 2] = m.y_axis.extend(b.y);
                    data[at + 3] = m.z_axis.extend(b.z);
                }
            }
        }
        if !data.is_empty() {
            queue.write_buffer(&self.frame, 0, bytemuck::cast_slice(&data));
        }
        // Air.
        for (c, f) in l.cloths.iter().zip(&frame.cloths) {
            let at = u64::from(r.air + c.vbase) * 16;
            if f.air_velocities.len() == c.n as usize {
                queue.write_buffer(&self.state, at, bytemuck::cast_slice(f.air_velocities));
            } else if c.n > 0 {
                queue.write_buffer(&self.state, at, &vec![0u8; c.n as usize * 16]);
            }
        }
        self.steps = steps;
        self.teleport_steps = teleport_steps;
        self.any_motion = any_motion;
        self.step_colliders = step_colliders
            .iter()
            .map(|s| s.colliders.len() as u32)
            .collect();
        self.collider_slots = slots;
        self.impulse_words = impulse_words;
    }

    /// Makes the SDF buffer hold `grids`, those the frame's colliders use (unless it already
    /// does). Returns whether the buffer was replaced.
    fn upload_grids(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        grids: Vec<Arc<SdfGrid>>,
    ) -> bool {
        let same = grids.len() == self.sdf_grids.len()
            && grids
                .iter()
                .zip(&self.sdf_grids)
                .all(|(a, b)| Arc::ptr_eq(a, b));
        if same {
            return false;
        }
        let total: usize = grids.iter().map(|g| g.values().len()).sum();
        self.sdf = empty(device, "cloth_sdf", (total * 4) as u64, RO);
        let mut at = 0u64;
        for g in &grids {
            if !g.values().is_empty() {
                queue.write_buffer(&self.sdf, at, bytemuck::cast_slice(g.values()));
            }
            at += (g.values().len() * 4) as u64;
        }
        self.sdf_grids = grids;
        true
    }

    /// Vec4s of the frame buffer for `steps` steps: where the motion targets start (after
    /// each step's pin targets and cloth records), and in all.
    fn frame_vec4s(&self, steps: u32, any_motion: bool) -> (u64, u64) {
        let cloths = self.layout.cloths.len() as u64;
        let per_step = u64::from(self.layout.pins) + u64::from(CLOTH_STEP_VEC4S) * cloths;
        let motion_at = u64::from(steps) * per_step;
        let motion_n = if any_motion { self.layout.n } else { 0 };
        let motion = u64::from(steps) * u64::from(MOTION_VEC4S) * u64::from(motion_n);
        (motion_at, motion_at + motion)
    }

    /// Whether the device binds what `frame`'s steps bring: the colliders' poses, their
    /// meshes' SDF `grids`, the pins' targets and (with `any_motion`) the motion targets.
    ///
    /// # Errors
    /// The first input too large, in words.
    fn check_inputs(
        &self,
        limits: &DeviceSizeLimits,
        frame: &GpuFrame<'_>,
        grids: &[Arc<SdfGrid>],
        any_motion: bool,
    ) -> Result<(), String> {
        let steps = frame.steps.len() as u32;
        let colliders = if self.layout.lab {
            0
        } else {
            frame.steps.iter().map(|s| s.colliders.len() as u64).sum()
        };
        let poses = colliders * u64::from(self.layout.substeps);
        let grids: u64 = grids.iter().map(|g| g.values().len() as u64 * 4).sum();
        let (_, vec4s) = self.frame_vec4s(steps, any_motion);
        let inputs = [
            ("collider poses", poses * size_of::<GpuCollider>() as u64),
            ("mesh colliders' SDF grids", grids),
            ("pin and motion targets", vec4s * 16),
        ];
        match inputs.iter().find(|(_, bytes)| !limits.binds(*bytes)) {
            None => Ok(()),
            Some((what, bytes)) => Err(format!(
                "a frame of {steps} steps for {} GPU cloth vertices needs {} MB of {what}, \
                 more than the adapter binds ({} MB)",
                self.layout.n,
                bytes.div_ceil(1 << 20),
                limits.storage_binding.min(limits.buffer) >> 20
            )),
        }
    }

    /// Why the last prepared frame took no step though its cloths were to: its inputs did
    /// not fit the device's buffers (`None` when they did).
    #[must_use]
    pub fn inputs_too_large(&self) -> Option<&str> {
        self.inputs_too_large.as_deref()
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

    /// Records taking over the positions and velocities of cloth `from_cloth` of `from` (an
    /// earlier world holding the same cloth with as many vertices) for cloth `cloth` of this
    /// world, keeping this world's inverse masses (its pins): how new settings go on from
    /// where the GPU cloth is. Call it before [`Self::prepare`]; the carry runs first in
    /// [`Self::record`].
    ///
    /// With `settle` (the same upload in a world rebuilt around it), a settle of a settings
    /// change in progress goes on too: its steps left, last strain and the speeds it keeps.
    ///
    /// # Panics
    /// If the two cloths differ in size.
    pub fn record_carry(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        from: &GpuWorld,
        from_cloth: usize,
        cloth: usize,
        settle: bool,
    ) {
        let (old, new) = (from.cloth(from_cloth), self.cloth(cloth));
        assert_eq!(old.n, new.n, "a carried cloth keeps its vertices");
        if new.n == 0 {
            return;
        }
        let size = u64::from(new.n) * 16;
        let (old_at, new_at) = (u64::from(old.vbase) * 16, u64::from(new.vbase) * 16);
        encoder.copy_buffer_to_buffer(
            &from.state,
            old_at,
            &self.state,
            new_at + u64::from(self.regions.prev) * 16,
            size,
        );
        encoder.copy_buffer_to_buffer(
            &from.state,
            old_at + u64::from(from.regions.vel) * 16,
            &self.state,
            new_at + u64::from(self.regions.vel) * 16,
            size,
        );
        if settle && from.layout.settle_steps > 0 && self.layout.settle_steps > 0 {
            encoder.copy_buffer_to_buffer(
                &from.state,
                from.status_offset(from_cloth) + 8,
                &self.state,
                self.status_offset(cloth) + 8,
                8,
            );
            encoder.copy_buffer_to_buffer(
                &from.scratch,
                u64::from(from.scratch_regions.settle_speed + old.vbase) * 4,
                &self.scratch,
                u64::from(self.scratch_regions.settle_speed + new.vbase) * 4,
                u64::from(new.n) * 4,
            );
        }
        self.carries.push((new.vbase, new.n));
        self.tear_after_carry |= self.layout.any_tearing;
    }

    /// Records the frame [`Self::prepare`] wrote for into `encoder` (one compute pass).
    pub fn record(&mut self, encoder: &mut wgpu::CommandEncoder, kernels: &GpuKernels) {
        let cmds = self.commands(kernels);
        if let Some(bg) = self.bind_group.as_ref().filter(|_| !cmds.is_empty()) {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("cloth_world"),
                timestamp_writes: None,
            });
            replay(&mut pass, bg, &cmds, kernels.limits.groups_per_dimension);
        }
        self.recorded();
    }

    /// After a frame is recorded: its carries are done, and so is the tear check after them
    /// if it had a step to record it in.
    fn recorded(&mut self) {
        self.carries.clear();
        if self.steps > 0 {
            self.tear_after_carry = false;
            // The first frame with steps may have a cloth that joined for its last ones only.
            if self.settle_started {
                self.settle_left = self.settle_left.saturating_sub(self.steps);
            }
            self.settle_started = true;
        }
    }

    /// As [`Self::record`], one compute pass per stage run, each with timestamps into
    /// `queries` (pass `i` writes queries `2i` and `2i + 1`); returns the stage of each pass.
    /// For profiling (the `tradeoff` example): the extra passes cost a little.
    ///
    /// # Panics
    /// If `queries` is smaller than twice the number of passes.
    pub fn record_profiled(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        kernels: &GpuKernels,
        queries: &wgpu::QuerySet,
    ) -> Vec<GpuStage> {
        let cmds = self.commands(kernels);
        let mut stages = Vec::new();
        let Some(bg) = &self.bind_group else {
            return stages;
        };
        let starts: Vec<usize> = cmds
            .iter()
            .enumerate()
            .filter(|(_, c)| matches!(c, Cmd::Stage(_)))
            .map(|(i, _)| i)
            .collect();
        for (k, &start) in starts.iter().enumerate() {
            let Cmd::Stage(stage) = cmds[start] else {
                unreachable!("filtered to stages");
            };
            let end = starts.get(k + 1).copied().unwrap_or(cmds.len());
            let i = stages.len() as u32;
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(stage.name()),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: queries,
                    beginning_of_pass_write_index: Some(2 * i),
                    end_of_pass_write_index: Some(2 * i + 1),
                }),
            });
            replay(
                &mut pass,
                bg,
                &cmds[start..end],
                kernels.limits.groups_per_dimension,
            );
            stages.push(stage);
        }
        self.recorded();
        stages
    }

    /// How many dispatches the prepared frame records: in all, and in its busiest substep.
    #[must_use]
    pub fn dispatches(&self, kernels: &GpuKernels) -> DispatchCount {
        let mut out = DispatchCount::default();
        let mut in_substep: Option<u32> = None;
        for c in self.commands(kernels) {
            match c {
                Cmd::Substep => {
                    if let Some(n) = in_substep {
                        out.per_substep = out.per_substep.max(n);
                    }
                    in_substep = Some(0);
                }
                Cmd::Stage(GpuStage::Finish | GpuStage::Begin) => {
                    if let Some(n) = in_substep.take() {
                        out.per_substep = out.per_substep.max(n);
                    }
                }
                Cmd::Run(..) => {
                    out.per_frame += 1;
                    if let Some(n) = &mut in_substep {
                        *n += 1;
                    }
                }
                _ => {}
            }
        }
        if let Some(n) = in_substep {
            out.per_substep = out.per_substep.max(n);
        }
        out
    }

    /// The dispatches of the prepared frame, each run of one stage headed by its stage.
    fn commands<'k>(&self, kernels: &'k GpuKernels) -> Vec<Cmd<'k>> {
        let mut out = Vec::new();
        let l = &self.layout;
        if self.bind_group.is_none() || l.n == 0 {
            return out;
        }
        let groups = |count: u32| count.div_ceil(WORKGROUP);
        let vertex_groups = groups(l.n);
        let substeps = l.substeps;
        let sub_offset = |k: u32, s: u32| ((k * substeps + s) as u64 * TABLE_STRIDE) as u32;
        let level_offset = |i: usize| (i as u64 * TABLE_STRIDE) as u32;
        let mut stage = None;
        let mut enter = |out: &mut Vec<Cmd<'k>>, s: GpuStage, offsets: [u32; 2]| {
            if stage != Some(s) {
                out.push(Cmd::Stage(s));
                stage = Some(s);
            }
            out.push(Cmd::Bind(offsets));
        };
        for (i, &(_, count)) in self.carries.iter().enumerate() {
            enter(&mut out, GpuStage::Begin, [0, level_offset(8 + i)]);
            out.push(Cmd::Run(&kernels.carry, groups(count)));
        }
        if self.steps == 0 {
            return out;
        }
        if self.impulse_words > 0 {
            enter(&mut out, GpuStage::Begin, [0, 0]);
            out.push(Cmd::Run(&kernels.impulse_clear, groups(self.impulse_words)));
        }
        if self.tear_after_carry && l.edges > 0 {
            // A rebuilt world carrying a tearing cloth (the host's tear lags the GPU's by a
            // few steps): its edges past the threshold in the carried state hold nothing
            // before the first step, as they did in the old world.
            enter(&mut out, GpuStage::Finish, [sub_offset(0, 0), 0]);
            out.push(Cmd::Run(&kernels.tear_check, groups(l.edges)));
            out.push(Cmd::Run(&kernels.tear_release, groups(l.edges)));
        }
        for k in 0..self.steps {
            let first = sub_offset(k, 0);
            enter(&mut out, GpuStage::Begin, [first, 0]);
            if self
                .teleport_steps
                .get(k as usize)
                .copied()
                .unwrap_or(false)
            {
                out.push(Cmd::Run(&kernels.teleport, vertex_groups));
            }
            out.push(Cmd::Run(&kernels.step_begin, vertex_groups));
            let settle = k < self.settle_left || (!self.settle_started && self.settle_left > 0);
            if settle {
                out.push(Cmd::Run(&kernels.settle_begin, vertex_groups));
            }
            let settle_end = |out: &mut Vec<Cmd<'k>>| {
                if settle {
                    out.push(Cmd::Run(
                        &kernels.settle_end,
                        groups(l.n.max(l.settle_edges)),
                    ));
                    out.push(Cmd::Run(
                        &kernels.settle_update,
                        groups(l.cloths.len() as u32),
                    ));
                }
            };
            if l.lab {
                for s in 0..substeps {
                    let so = sub_offset(k, s);
                    out.push(Cmd::Substep);
                    enter(&mut out, GpuStage::Parts, [so, 0]);
                    out.push(Cmd::Run(&kernels.lab_begin, vertex_groups));
                    for _ in 0..l.iterations {
                        out.push(Cmd::Run(&kernels.lab_gather, vertex_groups));
                        out.push(Cmd::Run(&kernels.lab_apply, vertex_groups));
                    }
                    out.push(Cmd::Run(&kernels.lab_finish, vertex_groups));
                }
                let last = sub_offset(k, substeps - 1);
                enter(&mut out, GpuStage::Finish, [last, 0]);
                out.push(Cmd::Run(&kernels.lab_guard, vertex_groups));
                settle_end(&mut out);
                if l.any_tearing && l.edges > 0 {
                    out.push(Cmd::Run(&kernels.tear_check, groups(l.edges)));
                }
                continue;
            }
            if l.any_sc {
                enter(&mut out, GpuStage::SelfCollision, [first, 0]);
                out.push(Cmd::Run(&kernels.sc_query, vertex_groups));
            }
            let colliders = self.step_colliders.get(k as usize).copied().unwrap_or(0);
            for s in 0..substeps {
                let so = sub_offset(k, s);
                out.push(Cmd::Substep);
                for it in 0..l.iterations.min(2) as usize {
                    // Iterations after the first are all alike (level entries 4..8).
                    let repeat = if it == 0 { 1 } else { l.iterations - 1 };
                    for _ in 0..repeat {
                        for (level, lr) in l.levels.iter().enumerate() {
                            if lr.count == 0 {
                                continue;
                            }
                            let st = if level == 0 {
                                GpuStage::Parts
                            } else {
                                GpuStage::Seams
                            };
                            enter(&mut out, st, [so, level_offset(it * 4 + level)]);
                            out.push(Cmd::Run(&kernels.solve, lr.count));
                        }
                    }
                }
                if l.any_sc {
                    enter(&mut out, GpuStage::SelfCollision, [so, 0]);
                    out.push(Cmd::Run(&kernels.sc_collide, vertex_groups));
                }
                if l.any_tethers || l.any_sc || colliders > 0 || self.any_motion {
                    enter(&mut out, GpuStage::Contact, [so, 0]);
                    out.push(Cmd::Run(&kernels.finish_substep, vertex_groups));
                }
            }
            let last = sub_offset(k, substeps - 1);
            enter(&mut out, GpuStage::Finish, [last, 0]);
            out.push(Cmd::Run(&kernels.step_end, vertex_groups));
            settle_end(&mut out);
            if l.any_tearing && l.edges > 0 {
                out.push(Cmd::Run(&kernels.tear_check, groups(l.edges)));
                out.push(Cmd::Run(&kernels.tear_release, groups(l.edges)));
            }
        }
        out
    }

    /// Reads cloth `cloth`'s positions and velocities back (blocking: for tests and tools;
    /// the plugin reads back asynchronously).
    #[must_use]
    pub fn read_state(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        cloth: usize,
    ) -> (Vec<Vec4>, Vec<Vec4>) {
        let (p_at, size) = self.positions_range(cloth);
        if size == 0 {
            return (Vec::new(), Vec::new());
        }
        let (v_at, _) = self.velocities_range(cloth);
        (
            self.read(device, queue, p_at, size),
            self.read(device, queue, v_at, size),
        )
    }

    /// Whether a step since cloth `cloth`'s upload left a NaN or infinite position or
    /// velocity, and whether one ended with an edge past the tear threshold (blocking, as
    /// [`Self::read_state`]). The GPU lets go of a torn edge at once; the caller tears the
    /// cloth's topology on the CPU ([`Self::read_torn_edges`] says which edges) and uploads it.
    #[must_use]
    pub fn read_status(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        cloth: usize,
    ) -> (bool, bool) {
        let s = self.read(device, queue, self.status_offset(cloth), 16)[0];
        (s.x != 0.0, s.y != 0.0)
    }

    /// Cloth `cloth`'s settle of a settings change: the steps it has left and the largest
    /// strain after its last settling step, as
    /// [`Simulation::settle_state`](crate::solver::Simulation::settle_state) gives them on the
    /// CPU (blocking, as [`Self::read_state`]; the CPU's infinity is the largest finite
    /// `f32` here).
    #[must_use]
    pub fn read_settle(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        cloth: usize,
    ) -> (u32, f32) {
        let s = self.read(device, queue, self.status_offset(cloth), 16)[0];
        (s.z as u32, s.w)
    }

    /// Where cloth `cloth`'s torn-edge flags sit in [`Self::scratch_buffer`], and the edge of
    /// each: what the plugin reads back to tear on the CPU exactly what the GPU tore. `None`
    /// for a cloth that does not tear (or runs the lab solver, which has no torn flags).
    #[must_use]
    pub fn torn_flags(&self, cloth: usize) -> Option<TornFlags> {
        let c = self.cloth(cloth);
        let edge_of = self.torn_edge_of.get(cloth)?.clone()?;
        Some(TornFlags {
            at: u64::from(self.scratch_regions.torn + c.distances.start) * 4,
            bytes: u64::from(c.distances.end - c.distances.start) * 4,
            edge_of,
        })
    }

    /// Where cloth `cloth`'s dead-triangle flags sit in [`Self::scratch_buffer`]: the word
    /// of its first triangle's (one `u32` a triangle of its topology, in its order; non-zero
    /// once an edge of the triangle tore). `None` for a cloth that does not tear (or runs the
    /// lab solver). What the mesh kernel hides torn triangles by
    /// ([`MeshWriter::record_hide_torn`](super::mesh::MeshWriter::record_hide_torn)).
    #[must_use]
    pub fn dead_triangle_flags(&self, cloth: usize) -> Option<u32> {
        self.torn_edge_of.get(cloth)?.as_ref()?;
        Some(self.scratch_regions.dead + self.cloth(cloth).triangles.start)
    }

    /// What the GPU tore of cloth `cloth` since the world was built (blocking, as
    /// [`Self::read_state`]; [`TornFlags::edges`] read from its flags). Empty for a cloth that
    /// does not tear.
    #[must_use]
    pub fn read_torn_edges(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        cloth: usize,
    ) -> TornEdges {
        let Some(flags) = self.torn_flags(cloth) else {
            return TornEdges::default();
        };
        flags.edges(&self.read_bytes(device, queue, &self.scratch, flags.at, flags.bytes))
    }

    /// Whether the last prepared frame left its colliders' impulses out: the slots (six words
    /// per 64 vertices and collider) would not fit the device's buffers.
    #[must_use]
    pub fn impulses_dropped(&self) -> bool {
        self.impulses_dropped
    }

    /// Where the impulse slots of the last prepared frame sit in [`Self::scratch_buffer`]:
    /// byte offset and size (0 without colliders). Sum them with [`sum_impulses`].
    #[must_use]
    pub fn impulse_region(&self) -> (u64, u64) {
        (
            u64::from(self.scratch_regions.impulse) * 4,
            u64::from(self.impulse_words) * 4,
        )
    }

    /// Steps the last prepared frame records (0 when no cloth takes one).
    #[must_use]
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Where the cloths' largest squared speeds of the last prepared frame sit in
    /// [`Self::scratch_buffer`] (one `f32` per cloth, in the world's order, 0 for a cloth that
    /// cannot sleep or took no step): byte offset and size.
    #[must_use]
    pub fn frame_speed_region(&self) -> (u64, u64) {
        (
            u64::from(self.scratch_regions.frame_speed) * 4,
            self.layout.cloths.len() as u64 * 4,
        )
    }

    /// Reads back (blocking) every cloth's largest squared speed of a free vertex at the end
    /// of a step of the last frame (0 for a cloth that cannot sleep or took no step; the CPU
    /// twin's [`ClothState::max_free_speed_squared`](crate::solver::ClothState::max_free_speed_squared)).
    pub fn read_frame_speeds(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<f32> {
        let (offset, size) = self.frame_speed_region();
        if size == 0 {
            return Vec::new();
        }
        bytemuck::pod_collect_to_vec(&self.read_bytes(device, queue, &self.scratch, offset, size))
    }

    /// Collider slots of the last prepared frame (what [`sum_impulses`] sums into).
    #[must_use]
    pub fn collider_slots(&self) -> usize {
        self.collider_slots as usize
    }

    /// The scratch buffer (self-collision's hash and lists, then the impulse slots).
    #[must_use]
    pub fn scratch_buffer(&self) -> &wgpu::Buffer {
        &self.scratch
    }

    /// The impulse every cloth of the world gave each collider slot over the last recorded
    /// frame (the sum of the steps' [`StepScratch::impulses`](crate::solver::StepScratch::impulses)
    /// over the cloths), blocking, as [`Self::read_state`].
    #[must_use]
    pub fn read_impulses(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<ContactImpulse> {
        let (offset, size) = self.impulse_region();
        if size == 0 {
            return vec![ContactImpulse::default(); self.collider_slots as usize];
        }
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&self.read_bytes(
            device,
            queue,
            &self.scratch,
            offset,
            size,
        ));
        sum_impulses(&words, self.collider_slots as usize)
    }

    fn read(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        offset: u64,
        size: u64,
    ) -> Vec<Vec4> {
        bytemuck::pod_collect_to_vec(&self.read_bytes(device, queue, &self.state, offset, size))
    }

    fn read_bytes(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        buffer: &wgpu::Buffer,
        offset: u64,
        size: u64,
    ) -> Vec<u8> {
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cloth_readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
        queue.submit([encoder.finish()]);
        staging.map_async(wgpu::MapMode::Read, .., |r| {
            if let Err(e) = r {
                bevy::log::error!("cloth readback failed: {e}");
            }
        });
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let out = staging.get_mapped_range(..).to_vec();
        staging.unmap();
        out
    }
}

/// Adds up impulse slots read back from [`GpuWorld::impulse_region`] (6 words per finish
/// workgroup and collider slot, f32 bits) into one impulse per collider slot.
#[must_use]
pub fn sum_impulses(words: &[u32], slots: usize) -> Vec<ContactImpulse> {
    let mut out = vec![ContactImpulse::default(); slots];
    if slots == 0 {
        return out;
    }
    for (i, slot) in words.chunks_exact(6).enumerate() {
        let f = |j: usize| f32::from_bits(slot[j]);
        let imp = &mut out[i % slots];
        imp.linear += Vec3::new(f(0), f(1), f(2));
        imp.angular += Vec3::new(f(3), f(4), f(5));
    }
    out
}
