//! The render world's side of the GPU backend: extraction, the worlds (every GPU cloth with
//! the same substeps and iterations in one [`GpuWorld`]), the `RenderGraph` system that steps
//! them and writes their meshes, and the readback.
//!
//! Frame flow:
//! 1. Extract: the frame's queued steps (colliders per step), each GPU cloth's pin targets,
//!    teleports and air, transform, and (new cloth, changed settings, an edit) its upload; the
//!    cloths leaving the GPU, which wait for a last readback; disabled cloths (Bevy's
//!    `Disabled`), which keep their place and state in their world without being stepped.
//! 2. `PrepareResources`: the cloths grouped by [`WorldKey`]; a world whose members changed
//!    is rebuilt, carrying the GPU state of the cloths that go on; every world is prepared
//!    for the frame.
//! 3. `RenderGraph`, before the camera driver: every world's steps, then every cloth's mesh
//!    kernel into its vertex slab, so this frame's main, shadow and prepass passes draw it;
//!    then a copy of the statuses, the read-back states and the impulse slots to staging.
//! 4. `Cleanup`: the copies mapped; extraction hands what arrived to the main world.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::mpsc::{Receiver, Sender};

use bevy::ecs::entity_disabling::Disabled;
use bevy::prelude::*;
use bevy::render::mesh::allocator::MeshAllocator;
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue};
use bevy::render::{Extract, MainWorld};

use super::backend::{
    ClothLeavingGpu, ClothOnGpu, ClothReadback, GpuClothResults, GpuResult, GpuStepQueue,
    GpuUpload, QueuedStep,
};
use super::kernels::GpuKernels;
use super::layout::{BatchesCell, WorldKey};
use super::mesh::{DrawShift, MeshKernel, MeshWriter};
use super::world::{
    ClothFrame, GpuFrame, GpuWorld, MotionTargets, StepColliders, TornFlags, sum_impulses,
};
use crate::cloth::ClothSim;
use crate::cloth::ClothSmoothing;
use crate::foundation::ClothSchedule;
use crate::solver::{CarriedVelocity, Carry};

/// The compiled kernels (render world).
#[derive(Resource)]
pub(crate) struct GpuClothPipelines {
    pub kernels: GpuKernels,
    pub mesh: MeshKernel,
}

/// One GPU cloth's frame, in the render world.
struct ExtractedGpuCloth {
    entity: Entity,
    generation: u64,
    /// `None` for a cloth held in its world but not stepped (leaving the GPU, or disabled).
    upload: Option<Arc<GpuUpload>>,
    pin_targets: Vec<Vec<Vec3>>,
    first_step: u32,
    teleports: Vec<Vec3>,
    carries: Vec<Carry>,
    air: Vec<Vec4>,
    motion: Vec<MotionTargets>,
    transform: bevy::math::Affine3A,
    /// Seconds along their velocities the vertices are drawn ([`ClothSmoothing`]).
    shift: f32,
    /// The velocity of the motion carried into its last step.
    carried: Option<CarriedVelocity>,
    /// Read positions and velocities back this frame.
    readback: bool,
    /// At rest (asleep, or falling asleep): it keeps its place and state in its world and its
    /// mesh is written, but it takes no step.
    frozen: bool,
    /// Velocities its GPU state takes this frame: those it fell asleep with (free vertices'
    /// zeroed, as the CPU's sleep leaves them).
    velocities: Option<Arc<Vec<Vec4>>>,
}

impl ExtractedGpuCloth {
    /// A cloth that keeps its place (and upload) in the world holding it, not stepped.
    fn held(entity: Entity, generation: u64, transform: &GlobalTransform, readback: bool) -> Self {
        Self {
            entity,
            generation,
            upload: None,
            pin_targets: Vec::new(),
            first_step: 0,
            teleports: Vec::new(),
            carries: Vec::new(),
            air: Vec::new(),
            motion: Vec::new(),
            transform: transform.affine(),
            shift: 0.0,
            carried: None,
            readback,
            frozen: false,
            velocities: None,
        }
    }
}

#[derive(Resource, Default)]
pub(crate) struct ExtractedGpuCloths {
    cloths: Vec<ExtractedGpuCloth>,
    queue: GpuStepQueue,
}

#[expect(
    clippy::type_complexity,
    reason = "the GPU cloths and those leaving the GPU"
)]
pub(crate) fn extract_gpu_cloths(
    mut out: ResMut<ExtractedGpuCloths>,
    queue: Extract<Res<GpuStepQueue>>,
    cloths: Extract<
        Query<(
            Entity,
            &ClothOnGpu,
            &GlobalTransform,
            Has<ClothReadback>,
            Has<Disabled>,
            Option<&ClothSmoothing>,
            &ClothSim,
        )>,
    >,
    leaving: Extract<Query<(Entity, &ClothLeavingGpu, &GlobalTransform), Allow<Disabled>>>,
    (schedule, fixed): (
        Extract<Option<Res<ClothSchedule>>>,
        Extract<Option<Res<Time<Fixed>>>>,
    ),
) {
    out.cloths.clear();
    out.queue = queue.clone();
    let overstep = ClothSchedule::overstep(schedule.as_deref(), fixed.as_deref());
    for (entity, g, transform, readback, disabled, smoothing, sim) in &cloths {
        if disabled {
            // Disabled (a pooled character): it keeps its place and its state in its world,
            // not stepped, not read back, until it is enabled again. Left out, its world
            // would be rebuilt without it and it would start again from its upload.
            out.cloths.push(ExtractedGpuCloth::held(
                entity,
                g.generation,
                transform,
                false,
            ));
            continue;
        }
        // A tearing cloth is always read back: the CPU tears it; one coming to rest, to count
        // its steps and for the state it sleeps in; not one asleep.
        let readback = g.reads_back(readback);
        out.cloths.push(ExtractedGpuCloth {
            entity,
            generation: g.generation,
            upload: Some(g.upload.clone()),
            pin_targets: g.pending.clone(),
            first_step: g.first_step,
            teleports: g.teleports.clone(),
            carries: g.carries.clone(),
            air: g.air.clone(),
            motion: g.motion.clone(),
            transform: transform.affine(),
            shift: match (smoothing, overstep) {
                (Some(s), Some((step, fraction))) => s.shift(step, fraction),
                _ => 0.0,
            },
            carried: sim.simulation().carried_velocity(),
            readback,
            frozen: g.is_frozen(),
            velocities: g.sleep_velocities.clone(),
        });
    }
    for (entity, l, transform) in &leaving {
        // Leaving: read back once more.
        out.cloths.push(ExtractedGpuCloth::held(
            entity,
            l.generation,
            transform,
            true,
        ));
    }
}

/// A cloth of a world.
struct Member {
    entity: Entity,
    generation: u64,
    upload: Arc<GpuUpload>,
    /// On the GPU (not leaving it).
    on_gpu: bool,
    /// Steps it takes this frame (none while at rest, leaving or disabled).
    steps: u32,
    /// Read its positions and velocities back this frame.
    readback: bool,
    /// Started this frame from its upload's state (not carried over from a GPU state): the
    /// carries of its first [`GpuUpload::carried`] steps are in that state already.
    fresh: bool,
}

/// A world and its cloths, in the world's order.
struct WorldEntry {
    key: WorldKey,
    /// Which world it is (a key's cloths fill several worlds where one would not fit the
    /// device), for its staging buffers.
    id: u64,
    world: GpuWorld,
    members: Vec<Member>,
    /// The frame's collider entities (slot → entity), for the impulses.
    slots: Vec<Entity>,
    /// Whether the frame stepped (impulses to read).
    stepped: bool,
    /// Staging buffers not being mapped (a few, of the sizes recently used).
    staging: Vec<wgpu::Buffer>,
}

/// A cloth's mesh writer.
struct WriterEntry {
    generation: u64,
    writer: MeshWriter,
    mesh: AssetId<Mesh>,
    transform: bevy::math::Affine3A,
    /// Seconds along their velocities the vertices are drawn.
    shift: f32,
    /// The velocity of the motion carried into the last step.
    carried: Option<CarriedVelocity>,
    /// Whether the mesh's indices are 16-bit.
    u16_indices: bool,
}

/// A copy of a world's statuses, read-back states and impulses on its way to the main world.
pub(crate) struct Readback {
    /// Per member: entity, generation, vertices, where its state is in the copy (if read),
    /// steps it took in the frame.
    cloths: Vec<(Entity, u64, usize, Option<u64>, u32)>,
    /// Where the members' largest squared speeds are in the copy (when the frame stepped).
    speeds_at: Option<u64>,
    /// Per member that tears: where its torn-edge flags are in the copy, and their edges.
    torn: Vec<Option<TornFlags>>,
    /// The collider entities of the impulse slots after the states (empty: none copied).
    colliders: Vec<Entity>,
    impulses_at: u64,
    buffer: wgpu::Buffer,
    /// The mapped bytes (`None` if mapping failed).
    data: Option<Vec<u8>>,
    /// The world the staging buffer goes back to.
    world: u64,
}

#[derive(Resource, Default)]
pub(crate) struct GpuWorlds {
    worlds: Vec<WorldEntry>,
    writers: HashMap<Entity, WriterEntry>,
    /// Copies recorded this frame, to map once submitted.
    requested: Vec<Readback>,
    /// The last world id given.
    last_id: u64,
    /// Cloths (by generation) the device cannot run, not tried again.
    refusing: HashMap<Entity, u64>,
    /// Refusals for the main world (sent at the next extraction): entity, generation, why.
    refused: Vec<(Entity, u64, String)>,
}

impl GpuWorlds {
    /// Keeps generation `generation` of `entity` off the GPU (the main world moves it to the
    /// CPU with `why`).
    fn refuse(&mut self, entity: Entity, generation: u64, why: String) {
        if self.refusing.insert(entity, generation) != Some(generation) {
            self.refused.push((entity, generation, why));
        }
    }

    fn refuses(&self, entity: Entity, generation: u64) -> bool {
        self.refusing.get(&entity) == Some(&generation)
    }
}

#[derive(Resource)]
pub(crate) struct ReadbackChannel {
    pub sender: Sender<Readback>,
    pub receiver: Mutex<Receiver<Readback>>,
}

/// Groups the frame's GPU cloths into worlds (rebuilding those whose cloths changed, with the
/// state of the cloths that go on), prepares every world for the frame, keeps mesh writers.
pub(crate) fn prepare_gpu_worlds(
    extracted: Res<ExtractedGpuCloths>,
    pipelines: Option<Res<GpuClothPipelines>>,
    mut worlds: ResMut<GpuWorlds>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let Some(pipelines) = pipelines else {
        return;
    };
    let device = device.wgpu_device();
    let worlds = &mut *worlds;
    // Cloths refused in an earlier generation may try again.
    worlds.refusing.retain(|e, generation| {
        extracted
            .cloths
            .iter()
            .any(|x| x.entity == *e && x.generation == *generation)
    });
    // Mesh writers for the cloths on the GPU (first: a mesh the device cannot write keeps
    // its cloth out of the worlds).
    worlds.writers.retain(|e, _| {
        extracted
            .cloths
            .iter()
            .any(|x| x.entity == *e && x.upload.is_some())
    });
    for x in &extracted.cloths {
        let Some(upload) = &x.upload else {
            continue;
        };
        if worlds.refuses(x.entity, x.generation) {
            continue;
        }
        let fresh = worlds
            .writers
            .get(&x.entity)
            .is_none_or(|w| w.generation != x.generation);
        if fresh {
            match MeshWriter::new(
                device,
                &upload.weld,
                &upload.drawn,
                upload.layout,
                upload.tangents.as_ref(),
                upload.drawn_cloth_triangles.as_deref(),
            ) {
                Ok(writer) => {
                    worlds.writers.insert(
                        x.entity,
                        WriterEntry {
                            generation: x.generation,
                            writer,
                            mesh: upload.mesh,
                            transform: x.transform,
                            shift: x.shift,
                            carried: x.carried,
                            u16_indices: upload.u16_indices,
                        },
                    );
                }
                Err(why) => {
                    worlds.writers.remove(&x.entity);
                    worlds.refuse(x.entity, x.generation, why.0);
                    continue;
                }
            }
        }
        if let Some(w) = worlds.writers.get_mut(&x.entity) {
            w.transform = x.transform;
            w.shift = x.shift;
            w.carried = x.carried;
        }
    }
    // The wanted members per key: cloths on the GPU with their upload; cloths leaving it keep
    // their place (and upload) in the world that holds them until their last readback.
    let mut wanted: BTreeMap<WorldKey, Vec<Member>> = BTreeMap::new();
    for x in &extracted.cloths {
        if worlds.refuses(x.entity, x.generation) {
            continue;
        }
        let upload = match &x.upload {
            Some(u) => u.clone(),
            None => {
                let held = worlds
                    .worlds
                    .iter()
                    .flat_map(|w| &w.members)
                    .find(|m| m.entity == x.entity && m.generation == x.generation);
                match held {
                    Some(m) => m.upload.clone(),
                    None => continue,
                }
            }
        };
        wanted
            .entry(WorldKey::of(&upload.sim))
            .or_default()
            .push(Member {
                entity: x.entity,
                generation: x.generation,
                upload,
                on_gpu: x.upload.is_some(),
                steps: if x.upload.is_some() && !x.frozen {
                    x.pin_targets.len() as u32
                } else {
                    0
                },
                readback: x.readback,
                fresh: false,
            });
    }
    let mut old: Vec<WorldEntry> = core::mem::take(&mut worlds.worlds);
    for (key, mut members) in wanted {
        members.sort_by_key(|m| m.entity);
        // The worlds that held exactly these cloths go on (one, or several where one would
        // not fit the device).
        let held: Vec<usize> = (0..old.len()).filter(|&i| old[i].key == key).collect();
        let held_members: HashMap<Entity, u64> = held
            .iter()
            .flat_map(|&i| old[i].members.iter().map(|o| (o.entity, o.generation)))
            .collect();
        let same = held_members.len() == members.len()
            && members
                .iter()
                .all(|m| held_members.get(&m.entity) == Some(&m.generation));
        if same {
            let mut by_entity: HashMap<Entity, Member> =
                members.into_iter().map(|m| (m.entity, m)).collect();
            for i in held.into_iter().rev() {
                let mut e = old.swap_remove(i);
                for o in &mut e.members {
                    *o = by_entity.remove(&o.entity).expect("the same members");
                }
                worlds.worlds.push(e);
            }
            continue;
        }
        // Built again: as many worlds as the device needs, halving a group of cloths that
        // does not fit; a cloth that does not fit alone is refused.
        let mut groups = vec![members];
        while let Some(mut members) = groups.pop() {
            let sims: Vec<&crate::solver::Simulation> =
                members.iter().map(|m| &m.upload.sim).collect();
            let cells: Vec<&BatchesCell> = members.iter().map(|m| &*m.upload.batches).collect();
            let made = GpuWorld::with_batches(device, &queue, &pipelines.kernels, &sims, &cells);
            let mut world = match made {
                Ok(world) => world,
                Err(why) => {
                    if members.len() > 1 {
                        let mut first = members;
                        let second = first.split_off(first.len() / 2);
                        groups.push(second);
                        groups.push(first);
                    } else if let Some(m) = members.first() {
                        worlds.writers.remove(&m.entity);
                        worlds.refuse(m.entity, m.generation, why.0);
                    }
                    continue;
                }
            };
            // Cloths that go on carry their GPU state over: the same upload, or new
            // settings made to go on from where the GPU cloth is.
            let mut encoder =
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
            for (i, m) in members.iter_mut().enumerate() {
                let from = old.iter().find_map(|w| {
                    w.members
                        .iter()
                        .position(|o| {
                            o.entity == m.entity && (o.generation == m.generation || m.upload.carry)
                        })
                        .filter(|&k| w.world.cloth_len(k) == world.cloth_len(i))
                        .map(|k| (w, k))
                });
                if let Some((w, k)) = from {
                    // The same upload goes on with its settle; new settings start theirs.
                    let same = w.members[k].generation == m.generation;
                    world.record_carry(&mut encoder, &w.world, k, i, same);
                } else {
                    m.fresh = true;
                }
            }
            queue.submit([encoder.finish()]);
            worlds.last_id += 1;
            worlds.worlds.push(WorldEntry {
                key,
                id: worlds.last_id,
                world,
                members,
                slots: Vec::new(),
                stepped: false,
                staging: Vec::new(),
            });
        }
    }
    // Prepare every world for the frame.
    let steps: Vec<StepColliders<'_>> = extracted
        .queue
        .steps
        .iter()
        .map(|s: &QueuedStep| StepColliders {
            colliders: &s.colliders,
            slots: &s.slots,
        })
        .collect();
    let dt = extracted.queue.steps.first().map_or(0.0, |s| s.dt);
    // A cloth started from its upload's state skips the carries that state has had already.
    let skipped: HashMap<Entity, Vec<Carry>> = worlds
        .worlds
        .iter()
        .flat_map(|w| &w.members)
        .filter(|m| m.fresh && m.upload.carried > 0)
        .filter_map(|m| {
            let x = extracted.cloths.iter().find(|x| x.entity == m.entity)?;
            let mut carries = x.carries.clone();
            let had = m.upload.carried.min(carries.len());
            carries[..had].fill(Carry::IDENTITY);
            Some((m.entity, carries))
        })
        .collect();
    for w in &mut worlds.worlds {
        let cloths: Vec<ClothFrame<'_>> = w
            .members
            .iter()
            .map(|m| {
                let x = extracted.cloths.iter().find(|x| x.entity == m.entity);
                match x.filter(|_| m.steps > 0) {
                    Some(x) => ClothFrame {
                        first_step: x.first_step,
                        pin_targets: &x.pin_targets,
                        teleports: &x.teleports,
                        carries: skipped.get(&m.entity).unwrap_or(&x.carries),
                        air_velocities: &x.air,
                        motion: &x.motion,
                    },
                    // Leaving, disabled or at rest: not stepped.
                    None => ClothFrame {
                        first_step: u32::MAX,
                        ..Default::default()
                    },
                }
            })
            .collect();
        // A frame in which none of its cloths steps records no step (`GpuWorld::prepare`).
        let frame = GpuFrame {
            dt,
            steps: steps.clone(),
            cloths,
        };
        // A cloth that fell asleep sleeps with the velocities its `ClothSim` sleeps with (the
        // free vertices' zeroed), so that it wakes from them as on the CPU; written after any
        // carry into a rebuilt world (submitted above), before the frame's steps.
        for x in &extracted.cloths {
            let Some(v) = &x.velocities else {
                continue;
            };
            let member = w
                .members
                .iter()
                .position(|m| m.entity == x.entity && m.generation == x.generation);
            if let Some(i) = member {
                let (at, bytes) = w.world.velocities_range(i);
                if v.len() as u64 * 16 == bytes {
                    queue.write_buffer(w.world.state_buffer(), at, bytemuck::cast_slice(v));
                }
            }
        }
        w.world.prepare(device, &queue, &pipelines.kernels, &frame);
        if let Some(why) = w.world.inputs_too_large() {
            warn_once!("bevy_cloth: GPU cloths hold still: {why}");
        }
        if w.world.impulses_dropped() {
            warn_once!(
                "bevy_cloth: {} GPU cloth vertices against {} colliders need more impulse \
                 slots than the GPU's buffers hold; GPU cloths push no collider while that lasts",
                w.world.len(),
                extracted.queue.entities.len()
            );
        }
        w.stepped = w.world.steps() > 0;
        w.slots.clone_from(&extracted.queue.entities);
    }
}

/// `RenderGraph`, before the camera driver: every world's steps, every GPU cloth's mesh, and
/// the copies to read back.
pub(crate) fn run_gpu_worlds(
    mut ctx: RenderContext,
    pipelines: Option<Res<GpuClothPipelines>>,
    mut worlds: ResMut<GpuWorlds>,
    allocator: Res<MeshAllocator>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let Some(pipelines) = pipelines else {
        return;
    };
    let worlds = &mut *worlds;
    let encoder = ctx.command_encoder();
    for w in &mut worlds.worlds {
        w.world.record(encoder, &pipelines.kernels);
        for (i, m) in w.members.iter().enumerate() {
            if !m.on_gpu {
                continue;
            }
            // The mesh every frame while on the GPU: a change of the mesh asset (torn
            // triangles leaving the index buffer) uploads its main-world vertices again.
            if let Some(writer) = worlds.writers.get(&m.entity)
                && writer.generation == m.generation
                && let Some(slice) = allocator.mesh_vertex_slice(&writer.mesh)
            {
                let dead_at = w.world.dead_triangle_flags(i);
                writer.writer.record(
                    device.wgpu_device(),
                    &queue,
                    &pipelines.mesh,
                    encoder,
                    w.world.state_buffer(),
                    w.world.vertex_base(i),
                    slice.buffer,
                    slice.range.start,
                    writer.transform,
                    (writer.shift != 0.0).then(|| DrawShift {
                        velocity_base: (w.world.velocities_range(i).0 / 16) as u32,
                        seconds: writer.shift,
                        carried: writer.carried,
                    }),
                    dead_at.map(|at| (w.world.scratch_buffer(), at)),
                );
                // A tearing cloth's torn triangles, hidden until the host's tear removes
                // them from the index buffer.
                if let Some(dead_at) = dead_at
                    && let Some(indices) = allocator.mesh_index_slice(&writer.mesh)
                {
                    writer.writer.record_hide_torn(
                        device.wgpu_device(),
                        &queue,
                        &pipelines.mesh,
                        encoder,
                        w.world.scratch_buffer(),
                        dead_at,
                        indices.buffer,
                        indices.range.start,
                        writer.u16_indices,
                    );
                }
            }
        }
        let any_state = w.members.iter().any(|m| m.readback);
        if !w.stepped && !any_state {
            continue;
        }
        // [statuses | per read-back cloth: positions, velocities | per read-back tearing
        // cloth: its torn-edge flags | largest speeds | impulse slots].
        let members = w.members.len() as u64;
        let mut cloths = Vec::with_capacity(w.members.len());
        let mut at = 16 * members;
        for (i, m) in w.members.iter().enumerate() {
            let n = w.world.cloth_len(i);
            let state_at = m.readback.then(|| {
                let here = at;
                at += 32 * n as u64;
                here
            });
            cloths.push((m.entity, m.generation, n, state_at, m.steps));
        }
        let mut torn = Vec::with_capacity(w.members.len());
        let mut torn_copies = Vec::new();
        for (i, m) in w.members.iter().enumerate() {
            let flags = w.world.torn_flags(i).filter(|_| m.readback);
            torn.push(flags.map(|f| {
                torn_copies.push((f.at, at, f.bytes));
                let here = at;
                at += f.bytes;
                TornFlags { at: here, ..f }
            }));
        }
        let (speeds_from, speed_bytes) = w.world.frame_speed_region();
        let speeds_at = (w.stepped && speed_bytes > 0).then(|| {
            let here = at;
            at += speed_bytes;
            here
        });
        let impulses_at = at;
        let (impulse_from, impulse_bytes) = if w.stepped {
            w.world.impulse_region()
        } else {
            (0, 0)
        };
        let size = impulses_at + impulse_bytes;
        let buffer = match w.staging.iter().position(|b| b.size() == size) {
            Some(k) => w.staging.swap_remove(k),
            None => device.wgpu_device().create_buffer(&wgpu::BufferDescriptor {
                label: Some("cloth_readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        };
        let state = w.world.state_buffer();
        encoder.copy_buffer_to_buffer(state, w.world.status_offset(0), &buffer, 0, 16 * members);
        for (i, c) in cloths.iter().enumerate() {
            if let Some(to) = c.3 {
                let (p, bytes) = w.world.positions_range(i);
                let (v, _) = w.world.velocities_range(i);
                if bytes > 0 {
                    encoder.copy_buffer_to_buffer(state, p, &buffer, to, bytes);
                    encoder.copy_buffer_to_buffer(state, v, &buffer, to + bytes, bytes);
                }
            }
        }
        for (from, to, bytes) in torn_copies {
            encoder.copy_buffer_to_buffer(w.world.scratch_buffer(), from, &buffer, to, bytes);
        }
        if let Some(to) = speeds_at {
            let scratch = w.world.scratch_buffer();
            encoder.copy_buffer_to_buffer(scratch, speeds_from, &buffer, to, speed_bytes);
        }
        if impulse_bytes > 0 {
            encoder.copy_buffer_to_buffer(
                w.world.scratch_buffer(),
                impulse_from,
                &buffer,
                impulses_at,
                impulse_bytes,
            );
        }
        let colliders = if impulse_bytes > 0 {
            w.slots[..w.world.collider_slots().min(w.slots.len())].to_vec()
        } else {
            Vec::new()
        };
        worlds.requested.push(Readback {
            cloths,
            speeds_at,
            torn,
            colliders,
            impulses_at,
            buffer,
            data: None,
            world: w.id,
        });
    }
}

/// `Cleanup`, after the frame's commands were submitted: maps this frame's copies; the
/// results come back through the channel when the GPU is done.
pub(crate) fn map_readbacks(mut worlds: ResMut<GpuWorlds>, channel: Res<ReadbackChannel>) {
    for mut r in worlds.requested.drain(..) {
        let sender = channel.sender.clone();
        let buffer = r.buffer.clone();
        buffer
            .clone()
            .map_async(wgpu::MapMode::Read, .., move |result| {
                if result.is_ok() {
                    r.data = Some(buffer.get_mapped_range(..).to_vec());
                    buffer.unmap();
                }
                // The receiver lives as long as the render world.
                let _ = sender.send(r);
            });
    }
}

/// Extraction: what the GPU finished, and the cloths it cannot run, go to the main world;
/// staging buffers return to their worlds.
pub(crate) fn send_gpu_results(
    channel: Res<ReadbackChannel>,
    mut worlds: ResMut<GpuWorlds>,
    mut main_world: ResMut<MainWorld>,
) {
    let Ok(receiver) = channel.receiver.lock() else {
        return;
    };
    let mut cloths = Vec::new();
    let mut impulses = Vec::new();
    for r in receiver.try_iter() {
        if let Some(w) = worlds.worlds.iter_mut().find(|w| w.id == r.world)
            && w.staging.len() < 4
        {
            w.staging.push(r.buffer.clone());
        }
        let Some(data) = &r.data else {
            continue;
        };
        for (i, &(entity, generation, n, state_at, steps)) in r.cloths.iter().enumerate() {
            let status: Vec4 = bytemuck::pod_read_unaligned(&data[16 * i..16 * i + 16]);
            // The largest squared speed of the steps it took (none: not measured).
            let max_speed_squared = r.speeds_at.filter(|_| steps > 0).map(|at| {
                let at = at as usize + 4 * i;
                f32::from_bits(bytemuck::pod_read_unaligned(&data[at..at + 4]))
            });
            let state = state_at.map(|at| {
                let at = at as usize;
                let values: Vec<Vec4> = bytemuck::pod_collect_to_vec(&data[at..at + 32 * n]);
                (values[..n].to_vec(), values[n..].to_vec())
            });
            // The edges the GPU tore past the threshold (flag 1; those it let go of for want
            // of a triangle go with them on the CPU).
            let torn = r.torn.get(i).and_then(Option::as_ref);
            let torn = torn.map(|f| f.edges(&data[f.at as usize..]).torn);
            cloths.push(GpuResult {
                entity,
                generation,
                failed: status.x != 0.0,
                tear: status.y != 0.0,
                torn,
                state,
                steps,
                max_speed_squared,
            });
        }
        if !r.colliders.is_empty() {
            let words: Vec<u32> = bytemuck::pod_collect_to_vec(&data[r.impulses_at as usize..]);
            let sums = sum_impulses(&words, r.colliders.len());
            impulses.extend(r.colliders.iter().copied().zip(sums));
        }
    }
    let refused = core::mem::take(&mut worlds.refused);
    if (!cloths.is_empty() || !impulses.is_empty() || !refused.is_empty())
        && let Some(mut results) = main_world.get_resource_mut::<GpuClothResults>()
    {
        results.cloths.extend(cloths);
        results.impulses.extend(impulses);
        results.refused.extend(refused);
    }
}

/// Whether the main world asked the app to exit (set during extraction).
#[derive(Resource, Default)]
pub(crate) struct ExitRequested(pub bool);

pub(crate) fn extract_exit(
    mut flag: ResMut<ExitRequested>,
    exits: Extract<Option<Res<Messages<AppExit>>>>,
) {
    flag.0 |= exits.as_ref().is_some_and(|m| !m.is_empty());
}

/// Longest an exiting app waits for pipelines still compiling.
const EXIT_DRAIN: std::time::Duration = std::time::Duration::from_secs(20);

/// `Cleanup` of the frame in which the app exits: waits until no pipeline is still being
/// compiled on the async compute pool and the GPU is idle, so the app (and the process) is not
/// torn down while a driver thread is inside `create_*_pipeline` or a readback is in flight —
/// which is how GPU-cloth apps died at exit on an NVIDIA driver (a debugger showed an async
/// compute thread inside `create_compute_pipeline` while the app was dropped). The cloth
/// kernels themselves are compiled synchronously when the plugin starts; what is still compiling
/// are Bevy's own pipelines, which it compiles on that pool as the scene appears (on llvmpipe,
/// the first frame with a camera leaves mesh preprocessing, clustering, irradiance and depth
/// downsampling pipelines compiling), and a start slowed by the cloth kernels' compilation makes
/// a short run end before they are done.
pub(crate) fn drain_on_exit(
    flag: Res<ExitRequested>,
    mut cache: ResMut<bevy::render::render_resource::PipelineCache>,
    device: Res<RenderDevice>,
) {
    if !flag.0 {
        return;
    }
    let start = std::time::Instant::now();
    let compiling = |cache: &bevy::render::render_resource::PipelineCache| {
        cache.pipelines().any(|p| {
            matches!(
                p.state,
                bevy::render::render_resource::CachedPipelineState::Creating(_)
            )
        })
    };
    while compiling(&cache) && start.elapsed() < EXIT_DRAIN {
        cache.process_queue();
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let _ = device
        .wgpu_device()
        .poll(wgpu::PollType::wait_indefinitely());
}
