//! Choosing the backend in an app: `ClothBackend` per cloth, `ClothBackendInUse` saying what
//! runs and why. A headless app without a renderer keeps every cloth on the CPU; an app with
//! a renderer (llvmpipe in CI) runs the cloths the GPU kernels can run on the GPU and keeps
//! the rest on the CPU with a reason.

mod common;

use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;

fn spawn(app: &mut App, backend: Option<ClothBackend>, tearing: bool) -> Entity {
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let mut e = app.world_mut().spawn((
        Mesh3d(mesh),
        Transform::from_xyz(0.0, 1.0, 0.0),
        Cloth::default(),
        ClothPins::rest([grid.index(0, 0), grid.index(11, 0)]),
    ));
    if let Some(b) = backend {
        e.insert(b);
    }
    if tearing {
        e.insert(ClothTearing::default());
    }
    e.id()
}

fn in_use(app: &App, e: Entity) -> ClothBackendInUse {
    app.world()
        .get::<ClothBackendInUse>(e)
        .cloned()
        .expect("the plugin says which backend runs")
}

#[test]
fn without_a_renderer_every_cloth_runs_on_the_cpu_and_says_why() {
    let mut app = common::app();
    let cpu = spawn(&mut app, None, false);
    let auto = spawn(&mut app, Some(ClothBackend::Auto), false);
    let gpu = spawn(&mut app, Some(ClothBackend::Gpu), false);
    let start = app.world().get::<ClothSim>(auto).map(|c| c.steps());
    common::run(&mut app, 10);
    assert!(start.is_none() || start == Some(0));
    let u = in_use(&app, cpu);
    assert!(!u.gpu && u.reason.is_none(), "{u:?}");
    for e in [auto, gpu] {
        let u = in_use(&app, e);
        assert!(!u.gpu, "{u:?}");
        assert!(
            u.reason
                .as_deref()
                .is_some_and(|r| r.contains("no renderer")),
            "{u:?}"
        );
        // And it is simulated, on the CPU.
        assert!(app.world().get::<ClothSim>(e).unwrap().steps() >= 5);
    }
}

/// A rendering app with no window, driven by hand (see BEVY019.md).
fn render_app() -> App {
    let mut app = App::new();
    app.add_plugins(
        DefaultPlugins
            .build()
            .disable::<bevy::winit::WinitPlugin>()
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: bevy::window::ExitCondition::DontExit,
                ..default()
            }),
    )
    .add_plugins(ClothPlugins::default())
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        1.0 / 60.0,
    )))
    .insert_resource(Time::<Fixed>::from_hz(60.0));
    while app.plugins_state() == bevy::app::PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    app
}

#[test]
fn with_a_renderer_gpu_cloths_leave_the_cpu_and_the_rest_say_why() {
    if common::gpu_or_skip("with_a_renderer_gpu_cloths_leave_the_cpu_and_the_rest_say_why")
        .is_none()
    {
        return;
    }
    let mut app = render_app();
    let support = app
        .world()
        .resource::<bevy_cloth::gpu::ClothGpuSupport>()
        .clone();
    assert_eq!(support.unavailable, None, "llvmpipe runs the kernels");
    let cpu = spawn(&mut app, None, false);
    let gpu = spawn(&mut app, Some(ClothBackend::Gpu), false);
    let torn = spawn(&mut app, Some(ClothBackend::Auto), true);
    common::run(&mut app, 12);
    assert!(in_use(&app, gpu).gpu);
    let u = in_use(&app, cpu);
    assert!(!u.gpu && u.reason.is_none(), "{u:?}");
    let u = in_use(&app, torn);
    assert!(
        !u.gpu && u.reason.as_deref().is_some_and(|r| r.contains("tearing")),
        "{u:?}"
    );
    // The CPU stepped the CPU cloths only; the GPU cloth's steps were queued for the GPU.
    let steps = |app: &App, e| app.world().get::<ClothSim>(e).unwrap().steps();
    assert!(steps(&app, cpu) >= 5 && steps(&app, torn) >= 5);
    assert_eq!(steps(&app, gpu), 0);
    assert!(
        app.world()
            .get::<bevy_cloth::gpu::ClothOnGpu>(gpu)
            .is_some()
    );
    // Back to the CPU at runtime: the CPU steps it again.
    app.world_mut().entity_mut(gpu).insert(ClothBackend::Cpu);
    common::run(&mut app, 6);
    assert!(!in_use(&app, gpu).gpu);
    assert!(steps(&app, gpu) >= 3);
}
