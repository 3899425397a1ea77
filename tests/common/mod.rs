//! Helpers shared by the integration tests (each test file uses some of them).
#![allow(dead_code)]

use std::time::Duration;

use bevy::mesh::MeshPlugin;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;
use bevy_cloth::solver::{Topology, TopologyOptions};

/// A headless app (no window, no GPU) with the cloth plugins, a 60 Hz fixed step and frames
/// of `frame` each.
pub fn app_with_frame(frame: Duration) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        AssetPlugin::default(),
        MeshPlugin,
        ClothPlugins::default(),
    ))
    .insert_resource(TimeUpdateStrategy::ManualDuration(frame))
    .insert_resource(Time::<Fixed>::from_hz(60.0));
    app
}

/// [`app_with_frame`] at 60 frames a second.
pub fn app() -> App {
    app_with_frame(Duration::from_secs_f64(1.0 / 60.0))
}

/// Every `ClothFailed` message so far (add [`collect_failures`] to a schedule).
#[derive(Resource, Default)]
pub struct Failures(pub Vec<ClothFailed>);

/// Appends the frame's `ClothFailed` messages to [`Failures`].
pub fn collect_failures(mut reader: MessageReader<ClothFailed>, mut out: ResMut<Failures>) {
    out.0.extend(reader.read().cloned());
}

/// Runs `frames` app updates.
pub fn run(app: &mut App, frames: usize) {
    for _ in 0..frames {
        app.update();
    }
}

/// The topology of `grid` with every vertex moved by `place`.
pub fn placed_grid(grid: &Grid, place: impl Fn(Vec3) -> Vec3) -> Topology {
    let positions: Vec<Vec3> = grid.positions().into_iter().map(place).collect();
    Topology::from_triangles(
        &positions,
        Some(&grid.uvs()),
        &grid.indices(),
        TopologyOptions::default(),
    )
    .unwrap()
}

/// A wgpu adapter and device for GPU tests, or `None` after printing why the test is skipped.
/// With `CLOTH_REQUIRE_GPU=1` (set by CI) a missing adapter fails the test instead.
pub fn gpu_or_skip(test: &str) -> Option<(wgpu::Adapter, wgpu::Device, wgpu::Queue)> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let found =
        bevy::tasks::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .map_err(|e| e.to_string())
            .and_then(|adapter| {
                bevy::tasks::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
                    .map(|(device, queue)| (adapter, device, queue))
                    .map_err(|e| e.to_string())
            });
    match found {
        Ok(gpu) => Some(gpu),
        Err(e) if std::env::var("CLOTH_REQUIRE_GPU").as_deref() == Ok("1") => {
            panic!(
                "{test}: no GPU adapter ({e}) and CLOTH_REQUIRE_GPU=1; install mesa-vulkan-drivers for llvmpipe"
            )
        }
        Err(e) => {
            eprintln!(
                "{test}: SKIPPED, no GPU adapter ({e}); install mesa-vulkan-drivers for llvmpipe"
            );
            None
        }
    }
}
