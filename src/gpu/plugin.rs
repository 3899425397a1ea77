//! [`ClothGpuPlugin`]: cloths stepped by the GPU kernels inside Bevy's render graph, writing
//! their mesh's vertex slab in place. The main world's systems are in `backend.rs`, the
//! render world's in `render.rs`.

use std::sync::mpsc::channel;
use std::sync::{Mutex, OnceLock};

use bevy::core_pipeline::schedule::camera_driver;
use bevy::prelude::*;
use bevy::render::mesh::allocator::MeshAllocatorSettings;
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice, RenderGraph, RenderInstance};
use bevy::render::{ExtractSchedule, Render, RenderApp, RenderSystems};

use super::backend::{
    ClothBackend, ClothGpuSupport, ClothReadback, DefaultBackend, GpuClothResults, GpuImpulses,
    GpuStepQueue, add_gpu_impulses, apply_gpu_results, choose_backends, clear_queued_steps,
    forget_gpu_cloth, queue_gpu_colliders, queue_gpu_steps,
};
use super::kernels::GpuKernels;
use super::mesh::MeshKernel;
use super::render::{
    ExitRequested, ExtractedGpuCloths, GpuClothPipelines, GpuWorlds, ReadbackChannel,
    drain_on_exit, extract_exit, extract_gpu_cloths, map_readbacks, prepare_gpu_worlds,
    run_gpu_worlds, send_gpu_results,
};
use crate::foundation::{ClothSchedule, ClothSystems};

/// Runs cloths on the GPU: their steps go to the render world, run as compute passes in the
/// `RenderGraph` schedule before the camera driver, and land in the mesh's vertex slab.
///
/// Part of [`ClothPlugins`](crate::ClothPlugins) with `default_backend: Cpu`: nothing
/// changes until a cloth asks for [`ClothBackend::Gpu`] or [`ClothBackend::Auto`], or the
/// default is set, e.g. `ClothPlugins::default().set(ClothGpuPlugin { default_backend:
/// ClothBackend::Auto })`. In an app without a renderer (`MinimalPlugins`) every cloth runs on
/// the CPU.
///
/// What the GPU backend runs: the lab solver, PBD and XPBD with substeps and iterations,
/// stretch, shear, isometric and dihedral bending, pins (moving with their anchors, with the
/// teleport rule), tethers, gravity, damping, the speed limit, air drag/lift/friction with the
/// wind, sphere/box/capsule/plane and mesh (baked SDF) colliders with friction, self-collision
/// (in its parallel form: each vertex moves by the mean of its contacts' corrections; the CPU
/// projects contacts one by one), tearing (a torn edge lets go on the GPU at once; the
/// topology tears on the CPU after a readback), normals and tangents. What keeps a cloth on the CPU: `BendingSolve::Implicit`.
/// Bending the CPU would solve implicitly under `BendingSolve::Auto` is projected.
///
/// The results stay on the GPU: [`ClothSim`](crate::cloth::ClothSim)'s state is the one the cloth started from unless
/// the cloth has [`ClothReadback`]. What comes back from the GPU comes a few frames late
/// (three or four with Bevy's pipelined rendering): read-back states, contact impulses on
/// colliders (added to their `ClothContactImpulse`), tears (`ClothTorn`), and the recovery of
/// a NaN or infinite state (as on the CPU: rest pose, [`crate::cloth::ClothSim::recoveries`], a warning).
/// A change of settings or pins carries the GPU state over; an edit through
/// [`ClothSim::simulation_mut`](crate::cloth::ClothSim::simulation_mut) restarts the GPU cloth from the edited state; switching to the
/// CPU reads the state back first (the cloth holds still until it arrives).
///
/// The plugin keeps the first renderer's wgpu instance until the process ends, so that the
/// graphics driver is never unloaded while its own threads run (NVIDIA's Linux driver crashed
/// processes that way, as they exited).
#[derive(Clone, Copy, Debug)]
pub struct ClothGpuPlugin {
    /// Backend of cloths without a [`ClothBackend`] component.
    pub default_backend: ClothBackend,
}

impl Default for ClothGpuPlugin {
    fn default() -> Self {
        Self {
            default_backend: ClothBackend::Cpu,
        }
    }
}

/// Whether the app had a renderer when [`ClothGpuPlugin`] was built.
#[derive(Resource)]
struct BuiltWithRenderer(bool);

/// Why a renderer added after the cloth plugins is of no use to them.
const PLUGIN_ORDER: &str = "ClothPlugins was added before the renderer (DefaultPlugins), so \
                            its GPU backend was not set up; add ClothPlugins after DefaultPlugins";

impl Plugin for ClothGpuPlugin {
    fn build(&self, app: &mut App) {
        let schedule = ClothSchedule::of(app);
        app.register_type::<ClothBackend>()
            .register_type::<ClothReadback>()
            .insert_resource(DefaultBackend(self.default_backend))
            .init_resource::<GpuClothResults>()
            .init_resource::<GpuImpulses>()
            .init_resource::<GpuStepQueue>()
            .add_observer(forget_gpu_cloth)
            .add_systems(First, clear_queued_steps)
            .add_systems(PreUpdate, apply_gpu_results)
            .add_systems(
                schedule,
                (
                    // Between the phases: once every cloth is built and its settings and pins
                    // are applied, before anything steps.
                    choose_backends
                        .after(ClothSystems::Prepare)
                        .before(ClothSystems::Simulate),
                    (
                        (queue_gpu_colliders, queue_gpu_steps).chain(),
                        add_gpu_impulses,
                    )
                        .in_set(ClothSystems::Simulate),
                ),
            );
        let has_renderer = app.get_sub_app(RenderApp).is_some();
        app.insert_resource(BuiltWithRenderer(has_renderer));
        // Refined in `finish`, once the renderer has its device.
        app.insert_resource(ClothGpuSupport {
            unavailable: Some(
                if has_renderer {
                    "the renderer is not set up yet"
                } else {
                    "the app has no renderer"
                }
                .to_owned(),
            ),
            software_adapter: None,
        });
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        let (sender, receiver) = channel();
        render_app
            .init_resource::<ExtractedGpuCloths>()
            .init_resource::<GpuWorlds>()
            .init_resource::<ExitRequested>()
            .insert_resource(ReadbackChannel {
                sender,
                receiver: Mutex::new(receiver),
            })
            .add_systems(
                ExtractSchedule,
                ((send_gpu_results, extract_gpu_cloths).chain(), extract_exit),
            )
            .add_systems(
                Render,
                (
                    prepare_gpu_worlds.in_set(RenderSystems::PrepareResources),
                    (map_readbacks, drain_on_exit)
                        .chain()
                        .in_set(RenderSystems::Cleanup),
                ),
            )
            .add_systems(RenderGraph, run_gpu_worlds.before(camera_driver));
    }

    fn finish(&self, app: &mut App) {
        let built_with_renderer = app
            .world()
            .get_resource::<BuiltWithRenderer>()
            .is_some_and(|b| b.0);
        let unavailable = match app.get_sub_app_mut(RenderApp) {
            None => Some("the app has no renderer".to_owned()),
            // The renderer came after this plugin was built: its render-world half is missing.
            Some(_) if !built_with_renderer => {
                warn!("{PLUGIN_ORDER}: a cloth that asks for the GPU runs on the CPU");
                Some(PLUGIN_ORDER.to_owned())
            }
            Some(render_app) => match render_app.world().get_resource::<RenderDevice>() {
                None => Some("the renderer has no device".to_owned()),
                Some(device) => match GpuKernels::check_limits(&device.limits()) {
                    Err(e) => Some(e.0),
                    Ok(()) => {
                        let wgpu_device = device.wgpu_device();
                        let pipelines = GpuClothPipelines {
                            kernels: GpuKernels::new(wgpu_device),
                            mesh: MeshKernel::new(wgpu_device),
                        };
                        let world = render_app.world_mut();
                        world.insert_resource(pipelines);
                        // Mesh slabs as storage buffers, so the kernels write vertices in
                        // place (read when the allocator is made, at render startup).
                        if let Some(mut settings) =
                            world.get_resource_mut::<MeshAllocatorSettings>()
                        {
                            settings.extra_buffer_usages |= wgpu::BufferUsages::STORAGE;
                            None
                        } else {
                            Some("the renderer has no mesh allocator".to_owned())
                        }
                    }
                },
            },
        };
        if let Some(why) = &unavailable {
            debug!("bevy_cloth: GPU backend unavailable: {why}");
        }
        let software_adapter = app
            .get_sub_app(RenderApp)
            .and_then(|r| r.world().get_resource::<RenderAdapterInfo>())
            .filter(|info| info.device_type == wgpu::DeviceType::Cpu)
            .map(|info| info.name.clone());
        app.insert_resource(ClothGpuSupport {
            unavailable,
            software_adapter,
        });
        keep_graphics_driver_loaded(app);
    }

    fn cleanup(&self, app: &mut App) {
        // For the plugin added before the renderer, whose `finish` came before the renderer
        // had its instance. (In the usual order only `finish` can: pipelined rendering's
        // `cleanup`, which runs before this one, moves the render world to its thread.)
        keep_graphics_driver_loaded(app);
    }
}

/// The first renderer's graphics API instance, kept for the rest of the process.
static KEPT_INSTANCE: OnceLock<RenderInstance> = OnceLock::new();

/// Whether this process keeps a renderer's wgpu instance alive (see [`ClothGpuPlugin`]): true
/// once an app with a renderer and the cloth plugins has been set up. For tests.
#[doc(hidden)]
#[must_use]
pub fn renderer_instance_kept() -> bool {
    KEPT_INSTANCE.get().is_some()
}

/// Keeps the renderer's wgpu instance alive until the process ends, so that the graphics
/// driver stays loaded.
///
/// When the last Vulkan instance is destroyed the Vulkan loader unloads the driver's
/// libraries. NVIDIA's Linux driver (580, on an H100 and an H200) runs threads of its own
/// that can outlive that: the process then crashed with SIGSEGV in code no library mapped any
/// more, as it exited or when a later app started (the `gpu_app` tests, many render apps in
/// one process; [wgpu #8365](https://github.com/gfx-rs/wgpu/issues/8365)). And after about
/// thirty loads in one process the driver could not be loaded again ("vulkan
/// drivers/libraries could not be loaded"), with nothing else left open. One instance kept
/// (never destroyed: the operating system reclaims it with the process) keeps the driver
/// loaded once; every other instance is destroyed as before.
fn keep_graphics_driver_loaded(app: &App) {
    let instance = app
        .get_sub_app(RenderApp)
        .and_then(|render| render.world().get_resource::<RenderInstance>());
    if let Some(instance) = instance {
        KEPT_INSTANCE.get_or_init(|| instance.clone());
    }
}
