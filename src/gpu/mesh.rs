//! Writing a GPU cloth into its mesh's vertex slab (`mesh.wgsl`): positions, normals and
//! (when the mesh has them) tangents in the entity's local space, straight from the state
//! buffer, with no copy through the CPU.

use bytemuck::{Pod, Zeroable};
use glam::{Affine3A, Mat3, Mat4, Vec2, Vec3};
use wgpu::util::DeviceExt;

use super::append_lists;
use super::kernels::{
    DeviceSizeLimits, GpuUnsupported, dispatch_flat, storage_entry, uniform_entry,
};
use crate::solver::{CarriedVelocity, Weld};

/// The WGSL of the mesh-writing kernel.
pub const MESH_WGSL: &str = include_str!("mesh.wgsl");

/// The WGSL of the kernel that hides a tearing cloth's torn triangles from its index slab.
pub const HIDE_WGSL: &str = include_str!("hide.wgsl");

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct HideParams {
    index_base: u32,
    triangles: u32,
    u16_indices: u32,
    drawn_at: u32,
    cloth_tri_at: u32,
    dead_at: u32,
    _pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct MeshParams {
    to_local: [f32; 16],
    normal_x: [f32; 4],
    normal_y: [f32; 4],
    normal_z: [f32; 4],
    carry_x: [f32; 4],
    carry_y: [f32; 4],
    carry_z: [f32; 4],
    carry_pivot: [f32; 4],
    carry_along: [f32; 4],
    base: u32,
    stride: u32,
    normal_offset: u32,
    vertices: u32,
    groups_at: u32,
    offsets_at: u32,
    triangles_at: u32,
    flip: f32,
    tangent_offset: u32,
    vertex_offsets_at: u32,
    uvs_at: u32,
    handedness_at: u32,
    particle_base: u32,
    cloth_tri_at: u32,
    dead_at: u32,
    velocity_base: u32,
    shift: f32,
    _pad: [u32; 3],
}

/// A cloth drawn along its velocities ([`ClothSmoothing`](crate::cloth::ClothSmoothing)):
/// each vertex at `x + seconds·v`, `v` read from the state buffer plus the velocity of the
/// motion carried into the step at `x`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrawShift {
    /// The cloth's first velocity in the state buffer, in `vec4`s from its start.
    pub velocity_base: u32,
    /// How far along its velocity each vertex is drawn, in seconds.
    pub seconds: f32,
    /// The motion carried into the last step (`Simulation::carried_velocity`), if any.
    pub carried: Option<CarriedVelocity>,
}

/// Where a mesh keeps positions and normals in its interleaved vertex buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VertexLayout {
    /// Bytes per vertex.
    pub stride: u32,
    /// Byte offset of the position (`Float32x3`).
    pub position: u32,
    /// Byte offset of the normal (`Float32x3`).
    pub normal: u32,
    /// Byte offset of the tangent (`Float32x4`), if the mesh has tangents.
    pub tangent: Option<u32>,
}

/// What tangents are made from (see `MeshShading`): per drawn triangle, in the order of the
/// drawn index list, its corners' UVs; per mesh vertex the handedness to keep, when the UVs
/// were made from source tangents.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TangentSource {
    /// UVs of each drawn triangle's corners.
    pub corner_uvs: Vec<[Vec2; 3]>,
    /// Handedness per mesh vertex, or `None` to take it from the UVs.
    pub handedness: Option<Vec<f32>>,
}

/// The compiled mesh-writing kernel, and the one that hides torn triangles.
#[derive(Debug)]
pub struct MeshKernel {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    hide_layout: wgpu::BindGroupLayout,
    hide_pipeline: wgpu::ComputePipeline,
    /// The device's limits (dispatches split past its workgroups per dimension).
    limits: DeviceSizeLimits,
}

impl MeshKernel {
    /// Compiles the kernel on `device`.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let (layout, pipeline) = compile(
            device,
            "cloth_mesh",
            MESH_WGSL,
            "write_mesh",
            &[
                uniform_entry(0, false, size_of::<MeshParams>() as u64),
                storage_entry(1, true),
                storage_entry(2, true),
                storage_entry(3, false),
                storage_entry(4, true),
            ],
        );
        let (hide_layout, hide_pipeline) = compile(
            device,
            "cloth_hide_torn",
            HIDE_WGSL,
            "hide_torn",
            &[
                uniform_entry(0, false, size_of::<HideParams>() as u64),
                storage_entry(1, true),
                storage_entry(2, true),
                storage_entry(3, false),
            ],
        );
        Self {
            layout,
            pipeline,
            hide_layout,
            hide_pipeline,
            limits: DeviceSizeLimits::of(device),
        }
    }
}

/// A one-entry-point compute kernel from `source` with one bind group of `entries`.
fn compile(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry_point: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> (wgpu::BindGroupLayout, wgpu::ComputePipeline) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(entry_point),
        compilation_options: Default::default(),
        cache: None,
    });
    (layout, pipeline)
}

/// Per drawn triangle (three mesh vertices each in `drawn`, as the index buffer holds them),
/// the triangle of `triangles` (a cloth's topology, particle indices) it draws, through the
/// weld's particle of each mesh vertex; `u32::MAX` for one the topology does not have.
#[must_use]
pub fn drawn_cloth_triangles(weld: &Weld, drawn: &[u32], triangles: &[[u32; 3]]) -> Vec<u32> {
    let key = |mut t: [u32; 3]| {
        t.sort_unstable();
        t
    };
    let of: std::collections::HashMap<[u32; 3], u32> = triangles
        .iter()
        .enumerate()
        .map(|(i, &t)| (key(t), i as u32))
        .collect();
    let particles = weld.particles();
    drawn
        .chunks_exact(3)
        .map(|t| {
            let p =
                [t[0], t[1], t[2]].map(|v| particles.get(v as usize).copied().unwrap_or(u32::MAX));
            of.get(&key(p)).copied().unwrap_or(u32::MAX)
        })
        .collect()
}

/// The CPU twin of `hide.wgsl`: each triangle of `indices` (three a triangle, the mesh's index
/// list) that draws a dead cloth triangle (`dead[cloth_triangles[t]] != 0`) becomes (0, 0, 0),
/// where `indices` still holds `drawn`'s vertices for it.
pub fn hide_torn_triangles(
    indices: &mut [u32],
    drawn: &[u32],
    cloth_triangles: &[u32],
    dead: &[u32],
) {
    for ((slot, expected), &c) in indices
        .chunks_exact_mut(3)
        .zip(drawn.chunks_exact(3))
        .zip(cloth_triangles)
    {
        if dead.get(c as usize).is_some_and(|&d| d != 0) && slot == expected {
            slot.fill(0);
        }
    }
}

/// What `hide.wgsl` needs of a tearing cloth besides the writer's table (which holds its
/// drawn triangles and, from `cloth_tri_at`, the cloth triangle of each).
#[derive(Debug)]
struct HideTorn {
    params: wgpu::Buffer,
    cloth_tri_at: u32,
    triangles: u32,
}

/// One cloth mesh's kernel inputs.
#[derive(Debug)]
pub struct MeshWriter {
    params: wgpu::Buffer,
    topo: wgpu::Buffer,
    layout: VertexLayout,
    vertices: u32,
    header: [u32; 3],
    /// Where the tangent data starts in `topo`: vertex offsets, UVs, handedness (0: none).
    tangent_header: Option<[u32; 3]>,
    /// For a tearing cloth: what hides its torn triangles.
    hide: Option<HideTorn>,
}

impl MeshWriter {
    /// The mesh's weld (mesh vertex → particle, normal groups), its drawn triangles (mesh
    /// vertex indices, three per triangle), where its attributes sit, for a layout with
    /// tangents what they are made from (without it, the tangents are left as they are), and
    /// for a tearing cloth the cloth triangle of each drawn triangle
    /// ([`drawn_cloth_triangles`]): its torn triangles then leave the normals and tangents
    /// ([`Self::record`] with the dead-triangle flags) and the index slab
    /// ([`Self::record_hide_torn`]) before the host's tear.
    ///
    /// # Errors
    /// The mesh needs a table larger than the device can bind, or more workgroups than a
    /// dispatch reaches.
    pub fn new(
        device: &wgpu::Device,
        weld: &Weld,
        drawn: &[u32],
        layout: VertexLayout,
        tangents: Option<&TangentSource>,
        cloth_triangles: Option<&[u32]>,
    ) -> Result<Self, GpuUnsupported> {
        let m = weld.vertex_count();
        let (group, groups) = weld.normal_groups();
        let mut topo: Vec<u32> = weld.particles().to_vec();
        let groups_at = topo.len() as u32;
        topo.extend_from_slice(group);
        // Per group, the drawn triangles touching it (once per corner in the group, as the
        // CPU sums them).
        let triangles = || {
            drawn
                .chunks_exact(3)
                .enumerate()
                .flat_map(|(i, t)| [t[0], t[1], t[2]].map(|v| (v, [i as u32])))
        };
        let offsets_at = append_lists(
            &mut topo,
            groups,
            triangles().map(|(v, t)| (group[v as usize], t)),
        );
        let triangles_at = topo.len() as u32;
        topo.extend_from_slice(drawn);
        let tangent_header = match (layout.tangent, tangents) {
            (Some(_), Some(src)) if src.corner_uvs.len() * 3 == drawn.len() => {
                // Per mesh vertex, its drawn triangles.
                let vertex_offsets_at = append_lists(&mut topo, m, triangles());
                let uvs_at = topo.len() as u32;
                for corners in &src.corner_uvs {
                    for uv in corners {
                        topo.extend([uv.x.to_bits(), uv.y.to_bits()]);
                    }
                }
                let handedness_at = match &src.handedness {
                    Some(h) if h.len() == m => {
                        let at = topo.len() as u32;
                        topo.extend(h.iter().map(|x| x.to_bits()));
                        at
                    }
                    _ => 0,
                };
                Some([vertex_offsets_at, uvs_at, handedness_at])
            }
            _ => None,
        };
        let hide = cloth_triangles
            .filter(|c| c.len() * 3 == drawn.len())
            .map(|c| {
                let cloth_tri_at = topo.len() as u32;
                topo.extend_from_slice(c);
                HideTorn {
                    params: device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("cloth_hide_params"),
                        size: size_of::<HideParams>() as u64,
                        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    }),
                    cloth_tri_at,
                    triangles: c.len() as u32,
                }
            });
        let limits = DeviceSizeLimits::of(device);
        let bytes = topo.len() as u64 * 4;
        let groups = (m as u64).max(drawn.len() as u64 / 3).div_ceil(64);
        if !limits.binds(bytes) || !limits.dispatches(groups) {
            return Err(GpuUnsupported(format!(
                "its mesh of {m} vertices and {} triangles is too large to be written on the \
                 GPU (a {} MB table; the adapter binds {} MB and dispatches {} workgroups a \
                 dimension)",
                drawn.len() / 3,
                bytes.div_ceil(1 << 20),
                limits.storage_binding.min(limits.buffer) >> 20,
                limits.groups_per_dimension
            )));
        }
        let topo = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("cloth_mesh_topology"),
            contents: bytemuck::cast_slice(&topo),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cloth_mesh_params"),
            size: size_of::<MeshParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            params,
            topo,
            layout,
            vertices: m as u32,
            header: [groups_at, offsets_at, triangles_at],
            tangent_header,
            hide,
        })
    }

    /// Records the pass that turns each drawn triangle whose cloth triangle is dead (the flags
    /// of the cloth from word `dead_at` of `scratch`, a [`GpuWorld`](super::GpuWorld)'s
    /// scratch buffer: [`GpuWorld::dead_triangle_flags`](super::GpuWorld::dead_triangle_flags))
    /// into (0, 0, 0) in `slab`, the index slab holding the mesh's indices from index
    /// `first` on, 16-bit ones if `u16_indices`. Nothing for a writer made without cloth
    /// triangles. The pass's parameters go through `queue`: record it once per
    /// submission (a second record before the submission would give both passes its own).
    #[expect(
        clippy::too_many_arguments,
        reason = "a record call takes all it needs explicitly"
    )]
    pub fn record_hide_torn(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        kernel: &MeshKernel,
        encoder: &mut wgpu::CommandEncoder,
        scratch: &wgpu::Buffer,
        dead_at: u32,
        slab: &wgpu::Buffer,
        first: u32,
        u16_indices: bool,
    ) {
        let Some(hide) = &self.hide else {
            return;
        };
        if hide.triangles == 0 {
            return;
        }
        // Bind only the mesh's indices (from an aligned offset): a slab may be larger than a
        // storage binding may be.
        let size = if u16_indices { 2u64 } else { 4 };
        let start = u64::from(first) * size;
        let end = start + u64::from(hide.triangles) * 3 * size;
        let align = kernel.limits.offset_alignment;
        let offset = start / align * align;
        let bytes = (end - offset).div_ceil(4) * 4;
        if offset + bytes > slab.size() {
            return;
        }
        let p = HideParams {
            index_base: ((start - offset) / size) as u32,
            triangles: hide.triangles,
            u16_indices: u32::from(u16_indices),
            drawn_at: self.header[2],
            cloth_tri_at: hide.cloth_tri_at,
            dead_at,
            _pad: [0; 2],
        };
        queue.write_buffer(&hide.params, 0, bytemuck::bytes_of(&p));
        let indices = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: slab,
            offset,
            size: std::num::NonZeroU64::new(bytes),
        });
        dispatch(
            device,
            encoder,
            "cloth_hide_torn",
            (&kernel.hide_layout, &kernel.hide_pipeline),
            [
                hide.params.as_entire_binding(),
                self.topo.as_entire_binding(),
                scratch.as_entire_binding(),
                indices,
            ],
            hide.triangles.div_ceil(64),
            kernel.limits.groups_per_dimension,
        );
    }

    /// Records the write of the cloth whose particles start at `particle_base` in `state`
    /// (a [`GpuWorld`](super::GpuWorld)'s state buffer) into `slab` from vertex `first` on,
    /// placed by `transform` (the entity's world transform), each vertex `shift` along its
    /// velocity (`None`: as stepped). For a writer made with cloth
    /// triangles, `dead` (the world's scratch buffer and the cloth's first dead-triangle flag
    /// in it, as for [`Self::record_hide_torn`]) leaves the torn triangles out of the normals
    /// and tangents, as the CPU's shading leaves out the triangles its tear removed.
    #[expect(
        clippy::too_many_arguments,
        reason = "a record call takes all it needs explicitly"
    )]
    pub fn record(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        kernel: &MeshKernel,
        encoder: &mut wgpu::CommandEncoder,
        state: &wgpu::Buffer,
        particle_base: u32,
        slab: &wgpu::Buffer,
        first: u32,
        transform: Affine3A,
        shift: Option<DrawShift>,
        dead: Option<(&wgpu::Buffer, u32)>,
    ) {
        if self.vertices == 0 {
            return;
        }
        let to_local = Mat4::from(transform.inverse());
        if !to_local.is_finite() {
            // A zero scale: nothing is drawn; the slab keeps its last shape (as on the CPU).
            return;
        }
        let linear = transform.matrix3;
        let flip = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let normal = linear.transpose();
        let floats = self.layout.stride / 4;
        // Bind only the mesh's vertices (from an aligned offset), as its indices above: a slab
        // may be larger than a storage binding may be.
        let start = u64::from(first) * u64::from(self.layout.stride);
        let end = start + u64::from(self.vertices) * u64::from(self.layout.stride);
        let align = kernel.limits.offset_alignment;
        let offset = start / align * align;
        let bytes = (end - offset).div_ceil(4) * 4;
        if offset + bytes > slab.size() {
            return;
        }
        let vertices = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: slab,
            offset,
            size: std::num::NonZeroU64::new(bytes),
        });
        let carried = shift.and_then(|s| s.carried).unwrap_or(CarriedVelocity {
            turn: Mat3::ZERO,
            pivot: Vec3::ZERO,
            along: Vec3::ZERO,
        });
        let p = MeshParams {
            to_local: to_local.to_cols_array(),
            normal_x: normal.x_axis.extend(0.0).to_array(),
            normal_y: normal.y_axis.extend(0.0).to_array(),
            normal_z: normal.z_axis.extend(0.0).to_array(),
            carry_x: carried.turn.x_axis.extend(0.0).to_array(),
            carry_y: carried.turn.y_axis.extend(0.0).to_array(),
            carry_z: carried.turn.z_axis.extend(0.0).to_array(),
            carry_pivot: carried.pivot.extend(0.0).to_array(),
            carry_along: carried.along.extend(0.0).to_array(),
            base: ((start - offset) / 4) as u32 + self.layout.position / 4,
            stride: floats,
            normal_offset: (self.layout.normal as i64 - self.layout.position as i64) as u32 / 4,
            vertices: self.vertices,
            groups_at: self.header[0],
            offsets_at: self.header[1],
            triangles_at: self.header[2],
            flip,
            tangent_offset: match (self.layout.tangent, self.tangent_header) {
                (Some(t), Some(_)) => (t as i64 - self.layout.position as i64) as u32 / 4,
                _ => u32::MAX,
            },
            vertex_offsets_at: self.tangent_header.map_or(0, |h| h[0]),
            uvs_at: self.tangent_header.map_or(0, |h| h[1]),
            handedness_at: self.tangent_header.map_or(0, |h| h[2]),
            particle_base,
            cloth_tri_at: self.hide.as_ref().map_or(0, |h| h.cloth_tri_at),
            dead_at: match (&self.hide, dead) {
                (Some(_), Some((_, at))) => at,
                _ => u32::MAX,
            },
            velocity_base: shift.map_or(0, |s| s.velocity_base),
            shift: shift.map_or(0.0, |s| s.seconds),
            _pad: [0; 3],
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&p));
        dispatch(
            device,
            encoder,
            "cloth_mesh",
            (&kernel.layout, &kernel.pipeline),
            [
                self.params.as_entire_binding(),
                state.as_entire_binding(),
                self.topo.as_entire_binding(),
                vertices,
                dead.map_or(&self.topo, |(b, _)| b).as_entire_binding(),
            ],
            self.vertices.div_ceil(64),
            kernel.limits.groups_per_dimension,
        );
    }
}

/// One compute pass: `resources` bound in order from binding 0 to the kernel's layout, then
/// `groups` workgroups of its pipeline (split by
/// [`flat_groups`](super::kernels::flat_groups) within `max_groups` a dimension).
fn dispatch<const N: usize>(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    (layout, pipeline): (&wgpu::BindGroupLayout, &wgpu::ComputePipeline),
    resources: [wgpu::BindingResource<'_>; N],
    groups: u32,
    max_groups: u32,
) {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
        .into_iter()
        .enumerate()
        .map(|(binding, resource)| wgpu::BindGroupEntry {
            binding: binding as u32,
            resource,
        })
        .collect();
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    });
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, &bind_group, &[]);
    dispatch_flat(&mut pass, groups, max_groups);
}
