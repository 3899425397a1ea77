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

/// Height of the vertex in the middle of the far edge (the pins hold the near corners).
fn centre_y(app: &App, e: Entity) -> f32 {
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let sim = app.world().get::<ClothSim>(e).expect("simulated");
    sim.simulation()
        .state()
        .position(sim.particle(grid.index(6, 11)) as usize)
        .y
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
        on_the_cpu_because(&app, e, "no renderer", 5);
    }
}

/// Asserts that `e` runs on the CPU, says `why` in `ClothBackendInUse`, and has taken at least
/// `steps` steps there.
fn on_the_cpu_because(app: &App, e: Entity, why: &str, steps: u64) {
    let u = in_use(app, e);
    assert!(!u.gpu, "{u:?}");
    assert!(
        u.reason.as_deref().is_some_and(|r| r.contains(why)),
        "{u:?}"
    );
    assert!(app.world().get::<ClothSim>(e).unwrap().steps() >= steps);
}

/// A rendering app with no window, driven by hand (see BEVY019.md).
fn render_app() -> ExitingApp {
    render_app_with(ClothPlugins::default(), true)
}

/// A render app that exits (sends `AppExit` and runs the exit frame) when dropped, as a game
/// does when its window closes, so no pipeline is still compiling when the test binary ends.
struct ExitingApp(Option<App>);

impl ExitingApp {
    /// The app, to drop without exiting.
    fn into_inner(mut self) -> App {
        self.0.take().expect("taken once")
    }
}

impl std::ops::Deref for ExitingApp {
    type Target = App;
    fn deref(&self) -> &App {
        self.0.as_ref().expect("not taken")
    }
}

impl std::ops::DerefMut for ExitingApp {
    fn deref_mut(&mut self) -> &mut App {
        self.0.as_mut().expect("not taken")
    }
}

impl Drop for ExitingApp {
    fn drop(&mut self) {
        if let Some(app) = self.0.as_mut()
            && !std::thread::panicking()
        {
            app.world_mut().write_message(AppExit::Success);
            app.update();
        }
    }
}

/// `render_app` with `cloth`'s plugins; without pipelined rendering the render world stays a
/// sub-app of `app`, where a test can look at it.
fn render_app_with(cloth: ClothPlugins, pipelined: bool) -> ExitingApp {
    render_app_in_order(cloth, pipelined, false)
}

/// [`render_app_with`], the cloth plugins added before `DefaultPlugins` when `cloth_first`
/// (the order a game must not use).
fn render_app_in_order(cloth: ClothPlugins, pipelined: bool, cloth_first: bool) -> ExitingApp {
    render_app_limited(cloth, pipelined, cloth_first, None)
}

/// [`render_app_in_order`] on a device that allows no more than `limits` (WgpuSettings'
/// `constrained_limits`).
fn render_app_limited(
    cloth: ClothPlugins,
    pipelined: bool,
    cloth_first: bool,
    limits: Option<wgpu::Limits>,
) -> ExitingApp {
    let mut app = App::new();
    let mut plugins = DefaultPlugins
        .build()
        .disable::<bevy::winit::WinitPlugin>()
        .set(WindowPlugin {
            primary_window: None,
            exit_condition: bevy::window::ExitCondition::DontExit,
            ..default()
        });
    if let Some(limits) = limits {
        plugins = plugins.set(bevy::render::RenderPlugin {
            render_creation: bevy::render::settings::WgpuSettings {
                constrained_limits: Some(limits),
                ..default()
            }
            .into(),
            ..default()
        });
    }
    if !pipelined {
        plugins = plugins.disable::<bevy::render::pipelined_rendering::PipelinedRenderingPlugin>();
    }
    if cloth_first {
        app.add_plugins(cloth).add_plugins(plugins);
    } else {
        app.add_plugins(plugins).add_plugins(cloth);
    }
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        1.0 / 60.0,
    )))
    .insert_resource(Time::<Fixed>::from_hz(60.0));
    while app.plugins_state() == bevy::app::PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();
    ExitingApp(Some(app))
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
    // A software renderer (llvmpipe here, none on a real GPU) is named, and `Auto` keeps its
    // cloths on the CPU there.
    let adapter = app
        .world()
        .resource::<bevy::render::renderer::RenderAdapterInfo>();
    let software = adapter.device_type == wgpu::DeviceType::Cpu;
    assert_eq!(
        support.software_adapter.as_deref(),
        software.then_some(adapter.name.as_str()),
        "{} ({:?})",
        adapter.name,
        adapter.device_type
    );
    let cpu = spawn(&mut app, None, false);
    let gpu = spawn(&mut app, Some(ClothBackend::Gpu), false);
    let auto = spawn(&mut app, Some(ClothBackend::Auto), false);
    // Implicit bending, asked for by name, has no GPU twin.
    let torn = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(torn).insert(ClothConfig {
        solver: bevy_cloth::solver::Solver::Xpbd {
            stretch: 0.0,
            shear: 1e-6,
            bending: 1e-5,
        },
        bending_solve: bevy_cloth::solver::BendingSolve::Implicit,
        ..default()
    });
    common::run(&mut app, 12);
    assert!(in_use(&app, gpu).gpu);
    if software {
        on_the_cpu_because(&app, auto, "software renderer", 5);
    } else {
        assert!(in_use(&app, auto).gpu, "{:?}", in_use(&app, auto));
    }
    let u = in_use(&app, cpu);
    assert!(!u.gpu && u.reason.is_none(), "{u:?}");
    let u = in_use(&app, torn);
    assert!(
        !u.gpu && u.reason.as_deref().is_some_and(|r| r.contains("mplicit")),
        "{u:?}"
    );
    // The CPU stepped the CPU cloths only; the GPU cloth's steps were queued for the GPU and
    // its main-world state (no `ClothReadback`) is still the one it started from.
    let steps = |app: &App, e| app.world().get::<ClothSim>(e).unwrap().steps();
    assert!(steps(&app, cpu) >= 5 && steps(&app, torn) >= 5 && steps(&app, gpu) >= 5);
    assert_eq!(centre_y(&app, gpu), 1.0);
    assert!(centre_y(&app, cpu) < 0.99);
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

/// `ClothReadback` brings the GPU's state into `ClothSim` (a frame or two late); leaving the
/// GPU, with or without it, the CPU goes on from where the GPU cloth was, not from where it
/// started.
#[test]
fn readback_and_switching_to_the_cpu_carry_the_gpu_state() {
    if common::gpu_or_skip("readback_and_switching_to_the_cpu_carry_the_gpu_state").is_none() {
        return;
    }
    let mut app = render_app();
    let read = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(read).insert(ClothReadback);
    let blind = spawn(&mut app, Some(ClothBackend::Gpu), false);
    let cpu = spawn(&mut app, Some(ClothBackend::Cpu), false);
    common::run(&mut app, 40);
    assert!(in_use(&app, read).gpu && in_use(&app, blind).gpu);
    // The free edge swung down on the GPU, as on the CPU.
    let (r, c) = (centre_y(&app, read), centre_y(&app, cpu));
    eprintln!(
        "after 40 frames: read back {r}, CPU {c}, blind {}",
        centre_y(&app, blind)
    );
    assert!(r < 0.7 && c < 0.7, "read back {r}, CPU {c}");
    assert_eq!(centre_y(&app, blind), 1.0, "no readback, no change");
    let strain = app
        .world()
        .get::<ClothSim>(read)
        .unwrap()
        .simulation()
        .strain();
    assert!(strain.max < 0.3, "read-back strain {strain:?}");
    // Both leave the GPU: the CPU takes over from the GPU's state.
    for e in [read, blind] {
        app.world_mut().entity_mut(e).insert(ClothBackend::Cpu);
    }
    common::run(&mut app, 8);
    for e in [read, blind] {
        assert!(!in_use(&app, e).gpu);
        let y = centre_y(&app, e);
        assert!(y < 0.7, "the CPU restarted cloth {e} from its start: {y}");
        assert!(app.world().get::<ClothSim>(e).unwrap().recoveries() == 0);
    }
}

/// A GPU cloth read back is watched for overstretch as a CPU one is: a 64² grid hanging from
/// two corners says so after a second; the same cloth tethered does not.
#[test]
fn a_read_back_gpu_cloth_stretched_to_twice_its_length_says_so() {
    if common::gpu_or_skip("a_read_back_gpu_cloth_stretched_to_twice_its_length_says_so").is_none()
    {
        return;
    }
    let mut app = render_app();
    let gpu = (ClothBackend::Gpu, ClothReadback);
    let loose = common::hung_grid(&mut app, 64, false, gpu);
    let held = common::hung_grid(&mut app, 64, false, (gpu, ClothTethers::default()));
    let said = |app: &App, e| {
        app.world()
            .get::<ClothSim>(e)
            .is_some_and(ClothSim::overstretched)
    };
    let mut frames = 0;
    while !said(&app, loose) {
        common::run(&mut app, 1);
        frames += 1;
        assert!(frames < 400, "not said after {frames} frames");
    }
    assert!(in_use(&app, loose).gpu && in_use(&app, held).gpu);
    assert!(frames >= 60, "said after {frames} frames, under a second");
    common::run(&mut app, 60);
    let sim = app.world().get::<ClothSim>(held).unwrap();
    assert!(
        !sim.overstretched() && sim.max_strain() < 0.1,
        "tethered: {}",
        sim.max_strain()
    );
}

/// New settings on a GPU cloth go on from the GPU's state; an edit of the state through
/// `simulation_mut` restarts it from the edit; a state the GPU turns NaN is caught and reset
/// to the rest pose as on the CPU.
#[test]
fn settings_edits_and_bad_states_on_the_gpu() {
    if common::gpu_or_skip("settings_edits_and_bad_states_on_the_gpu").is_none() {
        return;
    }
    let mut app = render_app();
    // No readback: the main world's state stays the start until the cloth leaves the GPU.
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    common::run(&mut app, 40);
    // New damping: the GPU buffers are rebuilt and carry the hanging shape over (had they
    // restarted from the main world's state, the cloth would be near flat again).
    app.world_mut().get_mut::<ClothConfig>(e).unwrap().damping = 0.5;
    common::run(&mut app, 2);
    app.world_mut().entity_mut(e).insert(ClothBackend::Cpu);
    common::run(&mut app, 6);
    assert!(!in_use(&app, e).gpu);
    let y = centre_y(&app, e);
    assert!(
        y < 0.7,
        "new settings restarted the cloth from its start: {y}"
    );
    // Back on the GPU, with readback. An edit wins: the rest pose, flat, read back as such.
    app.world_mut()
        .entity_mut(e)
        .insert((ClothBackend::Gpu, ClothReadback));
    common::run(&mut app, 20);
    assert!(in_use(&app, e).gpu);
    assert!(centre_y(&app, e) < 0.7);
    app.world_mut()
        .get_mut::<ClothSim>(e)
        .unwrap()
        .simulation_mut()
        .reset_to_rest();
    common::run(&mut app, 4);
    let y = centre_y(&app, e);
    assert!(y > 0.9, "the edit did not reach the GPU: {y}");
    // A NaN velocity put in by hand reaches the GPU; the guard catches it.
    common::run(&mut app, 20);
    {
        let mut sim = app.world_mut().get_mut::<ClothSim>(e).unwrap();
        let s = sim.simulation_mut().state_mut();
        s.velocities[30].x = f32::NAN;
    }
    common::run(&mut app, 10);
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert_eq!(
        sim.recoveries(),
        1,
        "the NaN was not caught (or caught twice)"
    );
    assert!(sim.simulation().state().is_finite());
    assert!(in_use(&app, e).gpu, "it stays on the GPU");
}

/// Removing `Cloth` from a GPU cloth takes its GPU twin away too.
#[test]
fn removing_a_gpu_cloth_removes_its_gpu_state() {
    if common::gpu_or_skip("removing_a_gpu_cloth_removes_its_gpu_state").is_none() {
        return;
    }
    let mut app = render_app();
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    common::run(&mut app, 5);
    assert!(app.world().get::<bevy_cloth::gpu::ClothOnGpu>(e).is_some());
    app.world_mut().entity_mut(e).remove::<Cloth>();
    common::run(&mut app, 3);
    assert!(app.world().get::<bevy_cloth::gpu::ClothOnGpu>(e).is_none());
    assert!(app.world().get::<ClothSim>(e).is_none());
}

/// The teleport rule on the GPU: the cloth entity jumps 6 m (its pins' anchors with it) and
/// the whole cloth appears there, unstretched, instead of being dragged across.
#[test]
fn a_gpu_cloth_teleports_with_its_pins() {
    if common::gpu_or_skip("a_gpu_cloth_teleports_with_its_pins").is_none() {
        return;
    }
    let mut app = render_app();
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(e).insert(ClothReadback);
    common::run(&mut app, 30);
    assert!(in_use(&app, e).gpu);
    app.world_mut()
        .get_mut::<Transform>(e)
        .unwrap()
        .translation
        .x += 6.0;
    common::run(&mut app, 6);
    let sim = app.world().get::<ClothSim>(e).unwrap().simulation();
    let xs: Vec<f32> = sim.state().positions.iter().map(|p| p.x).collect();
    let lowest = xs.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(lowest > 5.0, "a vertex was left behind at x = {lowest}");
    let strain = sim.strain();
    assert!(strain.max < 0.3, "dragged across: {strain:?}");
}

/// Frames `app` runs (at most `limit`) until `e` sleeps; `None` if it never does.
fn frames_until_asleep(app: &mut App, e: Entity, limit: usize) -> Option<usize> {
    (1..=limit).find(|_| {
        common::run(app, 1);
        app.world()
            .get::<ClothSim>(e)
            .is_some_and(ClothSim::is_sleeping)
    })
}

/// Every particle's position `e`'s `ClothSim` holds.
fn positions(app: &App, e: Entity) -> Vec<Vec3> {
    let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
    (0..s.len()).map(|i| s.position(i)).collect()
}

/// A GPU cloth that comes to rest sleeps, as a CPU cloth does: read back or not, it stops
/// taking steps (its state read back stays the same bit for bit, and the GPU world takes no
/// step while every cloth in it sleeps), and a pin moved by a few centimetres wakes it. One
/// with sleeping switched off keeps stepping.
#[test]
fn a_gpu_cloth_at_rest_sleeps_and_a_moved_pin_wakes_it() {
    if common::gpu_or_skip("a_gpu_cloth_at_rest_sleeps_and_a_moved_pin_wakes_it").is_none() {
        return;
    }
    let mut app = render_app();
    let read = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(read).insert(ClothReadback);
    let blind = spawn(&mut app, Some(ClothBackend::Gpu), false);
    let never = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(never).insert((
        ClothReadback,
        ClothConfig {
            sleep: Sleep::NEVER,
            ..default()
        },
    ));
    let frames = frames_until_asleep(&mut app, read, 1800);
    eprintln!("the read-back GPU cloth fell asleep after {frames:?} frames");
    assert!(frames.is_some(), "a hanging GPU cloth never slept in 30 s");
    assert!(in_use(&app, read).gpu && in_use(&app, blind).gpu);
    // The one not read back sleeps too, in the state read back for it; a few frames for the
    // state each stopped in.
    assert!(frames_until_asleep(&mut app, blind, 300).is_some());
    common::run(&mut app, 10);
    let y = centre_y(&app, blind);
    assert!(y < 0.7, "the sleeping cloth kept its start: {y}");
    let asleep = positions(&app, read);
    let steps = app.world().get::<ClothSim>(read).unwrap().steps();
    common::run(&mut app, 30);
    let sim = app.world().get::<ClothSim>(read).unwrap();
    assert!(sim.is_sleeping());
    assert!(
        sim.steps() >= steps + 30,
        "the steps it sleeps through count"
    );
    assert_eq!(positions(&app, read), asleep, "a sleeping GPU cloth moved");
    assert!(!app.world().get::<ClothSim>(never).unwrap().is_sleeping());
    // Its entity (which carries its pins) moves 5 cm: it wakes and follows.
    app.world_mut()
        .get_mut::<Transform>(read)
        .unwrap()
        .translation
        .x += 0.05;
    common::run(&mut app, 10);
    assert!(!app.world().get::<ClothSim>(read).unwrap().is_sleeping());
    let moved = positions(&app, read);
    let shift = moved
        .iter()
        .zip(&asleep)
        .map(|(a, b)| a.x - b.x)
        .fold(0.0f32, f32::max);
    assert!(shift > 0.02, "woken, it moved by {shift} m");
    assert!(
        app.world().get::<ClothSim>(blind).unwrap().is_sleeping(),
        "the other cloth slept on"
    );
}

/// A GPU cloth sleeps with the velocities its `ClothSim` sleeps with (the free vertices'
/// zeroed, as the CPU's sleep leaves them), so that it wakes from rest as a CPU cloth does:
/// moved to the CPU while asleep, the state it brings back from the GPU has no velocity.
/// (Before, the GPU kept those of its last step: 142 of the 144 vertices here, at up to
/// 6 cm/s.)
#[test]
fn a_sleeping_gpu_cloth_keeps_no_velocity() {
    if common::gpu_or_skip("a_sleeping_gpu_cloth_keeps_no_velocity").is_none() {
        return;
    }
    let mut app = render_app();
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(e).insert(ClothReadback);
    let frames = frames_until_asleep(&mut app, e, 1800);
    assert!(frames.is_some(), "a hanging GPU cloth never slept in 30 s");
    common::run(&mut app, 5);
    app.world_mut().entity_mut(e).insert(ClothBackend::Cpu);
    common::run(&mut app, 8);
    assert!(!in_use(&app, e).gpu);
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert!(sim.is_sleeping(), "moved to the CPU, it sleeps on");
    let state = sim.simulation().state();
    let moving: Vec<f32> = state
        .positions
        .iter()
        .zip(&state.velocities)
        .filter(|(p, v)| p.w > 0.0 && v.truncate() != Vec3::ZERO)
        .map(|(_, v)| v.truncate().length())
        .collect();
    assert!(
        moving.is_empty(),
        "{} free vertices came back from the sleeping GPU cloth moving, at up to {} m/s",
        moving.len(),
        moving.iter().copied().fold(0.0f32, f32::max)
    );
}

/// A 1 m square of 30 × 30 vertices with self-collision at `x`, stood on its edge and spun
/// about the vertical at 5 rad/s (faster higher up), on `backend`: it twists as it collapses
/// and crumples onto the floor in overlapping folds (`tests/self_collision.rs`' crumpled pile;
/// on the CPU, 36 such piles all slept within 12.3 s: docs/experiments.md).
fn spawn_crumpling(app: &mut App, x: f32, backend: ClothBackend) -> Entity {
    let grid = Grid::new(30, 30, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    app.world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(x, 0.52, 0.0)
                .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2)),
            Cloth {
                mass: 0.3,
                ..default()
            },
            ClothConfig {
                substeps: 12,
                ..default()
            },
            ClothSelfCollision {
                thickness: Some(1.0 / 29.0),
                friction: 0.6,
            },
            backend,
        ))
        .id()
}

/// Spins `e` (standing at `x`) about the vertical through its centre.
fn spin(app: &mut App, e: Entity, x: f32) {
    let mut cloth = app.world_mut().get_mut::<ClothSim>(e).expect("built");
    let state = cloth.simulation_mut().state_mut();
    for (v, p) in state.velocities.iter_mut().zip(&state.positions) {
        let spin = Vec3::Y.cross(Vec3::new(p.x - x, p.y, p.z)) * 5.0 * (0.5 + p.y);
        *v = spin.extend(v.w);
    }
}

/// A pile of cloth with self-collision on the GPU comes to rest and sleeps, read back or not,
/// as it does on the CPU, although a few of its vertices keep trembling faster than the
/// 0.1 m/s under which the fastest vertex alone would let it be counted: its state is looked
/// at every few frames and counted by its mean (before, such a pile never slept on the GPU).
#[test]
fn a_gpu_pile_with_trembling_vertices_sleeps() {
    if common::gpu_or_skip("a_gpu_pile_with_trembling_vertices_sleeps").is_none() {
        return;
    }
    let mut app = render_app();
    let piles = [(-1.5, true), (1.5, false)].map(|(x, read)| {
        let e = spawn_crumpling(&mut app, x, ClothBackend::Gpu);
        if read {
            app.world_mut().entity_mut(e).insert(ClothReadback);
        }
        (e, x)
    });
    app.world_mut().spawn(
        ClothCollider::plane()
            .with_thickness(0.005)
            .with_friction(0.6),
    );
    while app.world().get::<ClothSim>(piles[0].0).is_none() {
        common::run(&mut app, 1);
    }
    for (e, x) in piles {
        spin(&mut app, e, x);
    }
    let read = piles[0].0;
    // Each pile's fastest vertex, frame by frame while it is awake, in the state its
    // `ClothSim` holds: read back every frame for the one, every frame it may be coming to
    // rest for the other (its last 30 frames awake among them).
    let mut fastest = [Vec::new(), Vec::new()];
    let mut seen: [Option<usize>; 2] = [None; 2];
    let mut frames = 0;
    while frames < 1800 && seen.iter().any(Option::is_none) {
        common::run(&mut app, 1);
        frames += 1;
        for (k, (e, _)) in piles.into_iter().enumerate() {
            let sim = app.world().get::<ClothSim>(e).unwrap();
            if seen[k].is_none() && sim.is_sleeping() {
                seen[k] = Some(frames);
            } else if seen[k].is_none() {
                fastest[k].push(sim.simulation().state().max_free_speed_squared().sqrt());
            }
        }
    }
    assert!(in_use(&app, read).gpu && in_use(&app, piles[1].0).gpu);
    eprintln!("asleep after frames (read back, not): {seen:?}");
    assert!(seen[0].is_some(), "the read-back pile never slept in 30 s");
    assert!(
        seen[1].is_some(),
        "the pile not read back never slept in 30 s"
    );
    // Their last 30 frames awake (the run of still steps that put them to sleep) had a vertex
    // faster than the fastest-vertex rule allows: the piles test the mean rule. (A pile's
    // trembling depends on its folds, which another GPU's rounding changes: of 12 such piles
    // on the CPU the fastest vertex over the last second was 0.06–0.6 m/s, so one of the two
    // may be slow and both rarely are.)
    let last = fastest.map(|f| {
        f[f.len().saturating_sub(30)..]
            .iter()
            .copied()
            .fold(0.0f32, f32::max)
    });
    eprintln!("their fastest vertex over their last 30 frames awake: {last:?} m/s");
    assert!(
        last.iter().any(|&v| v > 0.1),
        "both piles were slow by their fastest vertex ({last:?} m/s): they do not test the \
         mean rule"
    );
}

/// A GPU cloth falls asleep and sleeps on while a collider keeps moving far away (a game's
/// physics elsewhere), and wakes (and is pushed) when one comes to it.
#[test]
fn a_sleeping_gpu_cloth_wakes_for_a_collider_that_comes_near() {
    if common::gpu_or_skip("a_sleeping_gpu_cloth_wakes_for_a_collider_that_comes_near").is_none() {
        return;
    }
    let mut app = render_app();
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(e).insert(ClothReadback);
    let far = app
        .world_mut()
        .spawn((
            Transform::from_xyz(10.0, 1.0, 0.0),
            ClothCollider::sphere(0.2),
        ))
        .id();
    let roll = |app: &mut App, k: usize| {
        app.world_mut()
            .get_mut::<Transform>(far)
            .unwrap()
            .translation
            .z = 0.5 * (0.05 * k as f32).sin();
        common::run(app, 1);
    };
    let asleep_after = (0..1800).find(|&k| {
        roll(&mut app, k);
        app.world()
            .get::<ClothSim>(e)
            .is_some_and(ClothSim::is_sleeping)
    });
    assert!(
        asleep_after.is_some(),
        "never slept beside a moving collider"
    );
    // A few frames for the state it stopped in.
    for k in 0..10 {
        roll(&mut app, k);
    }
    let asleep = positions(&app, e);
    for k in 0..60 {
        roll(&mut app, k);
    }
    assert!(
        app.world().get::<ClothSim>(e).unwrap().is_sleeping(),
        "a collider moving 10 m away woke it"
    );
    assert_eq!(positions(&app, e), asleep);
    // The ball moves into the hanging cloth, from the side it hangs towards.
    let lowest = asleep.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    let centre = asleep.iter().copied().sum::<Vec3>() / asleep.len() as f32;
    app.world_mut()
        .get_mut::<Transform>(far)
        .unwrap()
        .translation = Vec3::new(centre.x, lowest - 0.5, centre.z);
    common::run(&mut app, 3);
    for _ in 0..40 {
        app.world_mut()
            .get_mut::<Transform>(far)
            .unwrap()
            .translation
            .y += 0.02;
        common::run(&mut app, 1);
    }
    assert!(!app.world().get::<ClothSim>(e).unwrap().is_sleeping());
    let pushed = positions(&app, e)
        .iter()
        .zip(&asleep)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    assert!(pushed > 0.05, "the ball moved the cloth by {pushed} m");
}

/// The plugin keeps its renderer's wgpu instance for the rest of the process, also after the
/// app is gone, so that the graphics driver is never unloaded under its own threads (NVIDIA's
/// Linux driver crashed processes so, and after about thirty loads no longer loaded).
#[test]
fn a_render_app_keeps_the_graphics_driver_loaded_after_it_ends() {
    if common::gpu_or_skip("a_render_app_keeps_the_graphics_driver_loaded_after_it_ends").is_none()
    {
        return;
    }
    let app = render_app();
    assert!(
        bevy_cloth::gpu::renderer_instance_kept(),
        "a render app with the cloth plugins keeps its instance"
    );
    drop(app);
    assert!(bevy_cloth::gpu::renderer_instance_kept());
}

/// `ClothPlugins` added before `DefaultPlugins` cannot set up its GPU backend (the renderer
/// is not there yet when it is built): a cloth asking for the GPU runs on the CPU and says
/// that the order is why, rather than blaming the device.
#[test]
fn cloth_plugins_added_before_the_renderer_say_so() {
    if common::gpu_or_skip("cloth_plugins_added_before_the_renderer_say_so").is_none() {
        return;
    }
    let mut app = render_app_in_order(ClothPlugins::default(), true, true);
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    common::run(&mut app, 5);
    on_the_cpu_because(&app, e, "add ClothPlugins after DefaultPlugins", 3);
}

/// A GPU cloth with no pins goes with its entity when that jumps past the teleport distance,
/// as on the CPU (`a_cloth_without_pins_moves_with_its_entity_only_when_that_jumps`).
#[test]
fn a_gpu_cloth_without_pins_jumps_with_its_entity() {
    if common::gpu_or_skip("a_gpu_cloth_without_pins_jumps_with_its_entity").is_none() {
        return;
    }
    let mut app = render_app();
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let e = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 1.0, 0.0),
            Cloth::default(),
            ClothBackend::Gpu,
            ClothReadback,
        ))
        .id();
    let xs = |app: &App| {
        let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
        (0..s.len())
            .map(|i| s.position(i).x)
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            })
    };
    common::run(&mut app, 30);
    assert!(in_use(&app, e).gpu);
    let before = xs(&app);
    // A step of 1 m leaves the free cloth where it is; a jump of 6 m takes it along.
    app.world_mut()
        .get_mut::<Transform>(e)
        .unwrap()
        .translation
        .x += 1.0;
    common::run(&mut app, 6);
    let stepped = xs(&app);
    assert!(
        (stepped.0 - before.0).abs() < 0.05 && (stepped.1 - before.1).abs() < 0.05,
        "{before:?} -> {stepped:?}"
    );
    app.world_mut()
        .get_mut::<Transform>(e)
        .unwrap()
        .translation
        .x += 6.0;
    common::run(&mut app, 6);
    let jumped = xs(&app);
    assert!(
        (jumped.0 - stepped.0 - 6.0).abs() < 0.05 && (jumped.1 - stepped.1 - 6.0).abs() < 0.05,
        "{stepped:?} -> {jumped:?}"
    );
}

/// A 12×12 cloth at `x` held along its left and right columns by two anchors; returns the
/// cloth and its anchors.
fn spawn_held(app: &mut App, x: f32, backend: ClothBackend) -> (Entity, [Entity; 2]) {
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let mut anchor = |side: f32| {
        app.world_mut()
            .spawn((
                Transform::from_xyz(x + side * 0.5, 1.0, -0.5),
                GlobalTransform::default(),
            ))
            .id()
    };
    let (left, right) = (anchor(-1.0), anchor(1.0));
    let pins = (0..12).fold(ClothPins::default(), |pins, r| {
        let z = r as f32 / 11.0;
        pins.with(
            grid.index(0, r),
            PinAnchor::Entity {
                entity: left,
                offset: Vec3::new(0.0, 0.0, z),
            },
        )
        .with(
            grid.index(11, r),
            PinAnchor::Entity {
                entity: right,
                offset: Vec3::new(0.0, 0.0, z),
            },
        )
    });
    let cloth = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(x, 1.0, 0.0),
            Cloth::default(),
            pins,
            ClothTearing { threshold: 1.4 },
            backend,
        ))
        .id();
    (cloth, [left, right])
}

/// Puts two anchors at `x ∓ d`.
fn spread(app: &mut App, [left, right]: [Entity; 2], x: f32, d: f32) {
    for (anchor, at) in [(left, x - d), (right, x + d)] {
        app.world_mut()
            .get_mut::<Transform>(anchor)
            .unwrap()
            .translation
            .x = at;
    }
}

/// Moves each cloth's anchors apart 2 cm a frame on either side for 60 frames, then 5 more
/// frames; returns the `ClothTorn` messages each cloth sent.
fn pull_apart(app: &mut App, held: &[(Entity, [Entity; 2], f32)]) -> Vec<usize> {
    let mut messages = vec![0; held.len()];
    for k in 0..60 {
        let d = 0.5 + 0.02 * k as f32;
        for &(_, anchors, x) in held {
            spread(app, anchors, x, d);
        }
        app.update();
        for (m, (cloth, _, _)) in messages.iter_mut().zip(held) {
            *m += app
                .world()
                .resource::<Messages<ClothTorn>>()
                .iter_current_update_messages()
                .filter(|t| t.cloth == *cloth)
                .count();
        }
    }
    common::run(app, 5);
    messages
}

/// Tearing on the GPU backend: the kernels let go of an edge past the threshold, the plugin
/// reads the torn edges back and tears them on the CPU; the cloth stays on the GPU with the
/// new topology, `ClothTorn` arrives, the mesh's index buffer loses the torn triangles.
#[test]
fn a_gpu_cloth_tears_when_pulled_apart() {
    if common::gpu_or_skip("a_gpu_cloth_tears_when_pulled_apart").is_none() {
        return;
    }
    let mut app = render_app();
    let (cloth, anchors) = spawn_held(&mut app, 0.0, ClothBackend::Gpu);
    common::run(&mut app, 5);
    assert!(in_use(&app, cloth).gpu, "{:?}", in_use(&app, cloth));
    let triangles_before = 3 * 11 * 11 * 2;
    let messages = pull_apart(&mut app, &[(cloth, anchors, 0.0)])[0];
    let sim = app.world().get::<ClothSim>(cloth).unwrap();
    assert!(sim.torn_edges() > 0, "nothing tore");
    assert!(messages > 0, "no ClothTorn message");
    assert!(in_use(&app, cloth).gpu, "it stays on the GPU");
    let mesh = app
        .world()
        .resource::<Assets<Mesh>>()
        .get(&app.world().get::<Mesh3d>(cloth).unwrap().0)
        .unwrap();
    let indices = mesh.indices().unwrap().len();
    assert!(indices < triangles_before, "{indices} indices");
    assert_eq!(indices, 3 * sim.simulation().topology().triangles().len());
    assert!(sim.simulation().state().is_finite());
}

/// The mesh's indices as the render world's index slab holds them now (a blocking copy; the
/// grid meshes here have 32-bit indices), once the mesh is there.
fn indices_on_the_gpu(app: &App, mesh: AssetId<Mesh>) -> Option<Vec<u32>> {
    use bevy::render::mesh::allocator::MeshAllocator;
    let render = render_world(app);
    let slice = render.resource::<MeshAllocator>().mesh_index_slice(&mesh)?;
    let range = u64::from(slice.range.start) * 4..u64::from(slice.range.end) * 4;
    Some(bytemuck::pod_collect_to_vec(&read_buffer(
        app,
        slice.buffer,
        range,
    )))
}

/// The render world of `app` (a sub-app: pipelined rendering off).
fn render_world(app: &App) -> &World {
    app.get_sub_app(bevy::render::RenderApp)
        .expect("the render world is a sub-app without pipelined rendering")
        .world()
}

/// Bytes `range` of `buffer`, copied out of the GPU of `app`'s render world.
fn read_buffer(app: &App, buffer: &wgpu::Buffer, range: core::ops::Range<u64>) -> Vec<u8> {
    use bevy::render::renderer::{RenderDevice, RenderQueue};
    let render = render_world(app);
    let device = render.resource::<RenderDevice>().wgpu_device();
    let size = range.end - range.start;
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, range.start, &staging, 0, size);
    render.resource::<RenderQueue>().submit([encoder.finish()]);
    staging.map_async(wgpu::MapMode::Read, .., |r| r.expect("map_async"));
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    staging.get_mapped_range(..).to_vec()
}

/// A GPU tear shows in the frame the GPU tears: its triangles become (0, 0, 0) in the mesh's
/// index slab before the host has read the tear back (the host tears a frame or more
/// later); once the host's tear has rewritten the mesh and the pull has stopped, the slab
/// holds exactly the main world's index list, with nothing hidden left over. A second
/// tearing cloth in the same world, spawned first (its triangles first in the world's) and
/// too strong to tear, never has a triangle hidden: each cloth reads its own flags.
#[test]
fn a_gpu_tear_shows_before_the_host_tears() {
    if common::gpu_or_skip("a_gpu_tear_shows_before_the_host_tears").is_none() {
        return;
    }
    let mut app = render_app_with(ClothPlugins::default(), false);
    let (strong, _) = spawn_held(&mut app, -3.0, ClothBackend::Gpu);
    app.world_mut()
        .entity_mut(strong)
        .insert(ClothTearing { threshold: 50.0 });
    let (cloth, anchors) = spawn_held(&mut app, 0.0, ClothBackend::Gpu);
    let mesh = |app: &App| app.world().get::<Mesh3d>(cloth).unwrap().0.id();
    let strong_mesh = |app: &App| app.world().get::<Mesh3d>(strong).unwrap().0.id();
    let (mut first_hidden, mut first_host_tear, mut most_hidden) = (None, None, 0);
    // Five frames held, then 60 pulling apart; every frame looked at.
    for k in 0..65u32 {
        spread(
            &mut app,
            anchors,
            0.0,
            0.5 + 0.02 * k.saturating_sub(5) as f32,
        );
        app.update();
        if let Some(indices) = indices_on_the_gpu(&app, strong_mesh(&app)) {
            assert!(
                !indices.chunks_exact(3).any(|t| t == [0, 0, 0]),
                "frame {k}: a triangle of the cloth that does not tear is hidden"
            );
        }
        let Some(indices) = indices_on_the_gpu(&app, mesh(&app)) else {
            continue;
        };
        let hidden = indices.chunks_exact(3).filter(|t| *t == [0, 0, 0]).count();
        most_hidden = most_hidden.max(hidden);
        if hidden > 0 && first_hidden.is_none() {
            first_hidden = Some(k);
        }
        let host = app
            .world()
            .get::<ClothSim>(cloth)
            .map_or(0, ClothSim::torn_edges);
        if host > 0 && first_host_tear.is_none() {
            first_host_tear = Some(k);
        }
    }
    eprintln!(
        "hidden on the GPU from frame {first_hidden:?}, torn by the host from {first_host_tear:?}; \
         at most {most_hidden} triangles hidden at once"
    );
    let (Some(hidden), Some(host)) = (first_hidden, first_host_tear) else {
        panic!("the cloth must tear: hidden {first_hidden:?}, host {first_host_tear:?}");
    };
    assert!(
        hidden < host,
        "the tear must show (frame {hidden}) before the host tears (frame {host})"
    );
    assert!(in_use(&app, cloth).gpu, "{:?}", in_use(&app, cloth));
    assert!(in_use(&app, strong).gpu, "{:?}", in_use(&app, strong));
    assert_eq!(
        app.world().get::<ClothSim>(strong).unwrap().torn_edges(),
        0,
        "the strong cloth holds"
    );
    common::run(&mut app, 10);
    let main: Vec<u32> = app
        .world()
        .resource::<Assets<Mesh>>()
        .get(mesh(&app))
        .and_then(|m| match m.indices() {
            Some(bevy::mesh::Indices::U32(i)) => Some(i.clone()),
            _ => None,
        })
        .expect("32-bit indices");
    assert!(
        main.len() < 3 * 11 * 11 * 2,
        "the main world's mesh lost triangles"
    );
    assert_eq!(
        indices_on_the_gpu(&app, mesh(&app)).expect("the mesh is on the GPU"),
        main,
        "the slab holds the host's list once it has caught up"
    );
}

/// Tearing switched on at runtime (as the editor's toggle does) on a GPU cloth already
/// stretched past the threshold: its world is rebuilt with the cloth's state carried over,
/// the edges past the threshold tear within a few frames, and the cloth stays on the GPU;
/// switched off again, nothing more tears.
#[test]
fn tearing_switched_on_at_runtime_tears_a_stretched_gpu_cloth() {
    if common::gpu_or_skip("tearing_switched_on_at_runtime_tears_a_stretched_gpu_cloth").is_none() {
        return;
    }
    let mut app = render_app();
    let (cloth, anchors) = spawn_held(&mut app, 0.0, ClothBackend::Gpu);
    app.world_mut().entity_mut(cloth).remove::<ClothTearing>();
    common::run(&mut app, 5);
    assert!(in_use(&app, cloth).gpu, "{:?}", in_use(&app, cloth));
    // Pulled to 2.6 times its width with nothing tearing.
    pull_apart(&mut app, &[(cloth, anchors, 0.0)]);
    let torn = |app: &App| app.world().get::<ClothSim>(cloth).unwrap().torn_edges();
    assert_eq!(torn(&app), 0);
    app.world_mut()
        .entity_mut(cloth)
        .insert(ClothTearing { threshold: 1.4 });
    common::run(&mut app, 10);
    let after = torn(&app);
    assert!(after > 0, "nothing tore");
    assert!(in_use(&app, cloth).gpu, "it stays on the GPU");
    app.world_mut().entity_mut(cloth).remove::<ClothTearing>();
    common::run(&mut app, 10);
    assert_eq!(torn(&app), after, "tearing is off again");
    let sim = app.world().get::<ClothSim>(cloth).unwrap();
    assert!(sim.simulation().state().is_finite());
}

/// The `tearing` example's curtain at `x`: 28×28 vertices, 1.4 m, hanging from two anchors
/// along its left and right columns, a slit at the top of its middle, tearing past 1.5×.
/// Returns the cloth and its anchors.
fn spawn_curtain(app: &mut App, x: f32, backend: ClothBackend) -> (Entity, [Entity; 2]) {
    const N: u32 = 28;
    let grid = Grid::new(N, N, 1.4, 1.4);
    let transform = Transform::from_xyz(x, 1.6, 0.0)
        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let anchors = [-0.7, 0.7].map(|side| {
        app.world_mut()
            .spawn((
                Transform::from_xyz(x + side, 1.6, 0.0),
                GlobalTransform::default(),
            ))
            .id()
    });
    let rest = grid.positions();
    let mut pins = Vec::new();
    for j in 0..N {
        for (i, k, side) in [(0, 0, -0.7), (N - 1, 1, 0.7)] {
            let v = grid.index(i, j);
            let world = transform.transform_point(rest[v as usize]);
            pins.push(ClothPin {
                vertex: v,
                anchor: PinAnchor::Entity {
                    entity: anchors[k],
                    offset: world - Vec3::new(x + side, 1.6, 0.0),
                },
            });
        }
    }
    let indices: Vec<u32> = grid
        .indices()
        .chunks(6)
        .enumerate()
        .filter(|(q, _)| {
            let (i, j) = (*q as u32 % (N - 1), *q as u32 / (N - 1));
            !(i == N / 2 - 1 && j < 4)
        })
        .flat_map(|(_, quad)| quad.to_vec())
        .collect();
    let mut mesh = grid_mesh(&grid);
    mesh.insert_indices(bevy::mesh::Indices::U32(indices));
    let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
    let cloth = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            transform,
            Cloth {
                mass: 0.3,
                ..default()
            },
            ClothConfig {
                substeps: 10,
                ..default()
            },
            ClothPins(pins),
            ClothTearing { threshold: 1.5 },
            backend,
        ))
        .id();
    (cloth, anchors)
}

/// The GPU tears what the CPU tears, although the host learns of a tear a few frames late:
/// the GPU lets go of a torn edge (and of the edges its tear leaves without a triangle) from
/// the next step, as the CPU does, and a world rebuilt for the host's tear lets go again of
/// what the GPU tore since. The `tearing` example's curtain on both backends in one app,
/// hanging for a second, then pulled apart at 0.4 m/s a side for 2.5 s: about as many edges
/// tear and as many triangles are left (before, the GPU tore about twice the CPU's edges,
/// the intact cloth pulling on until the host's tear came).
#[test]
fn the_gpu_tears_as_much_as_the_cpu() {
    if common::gpu_or_skip("the_gpu_tears_as_much_as_the_cpu").is_none() {
        return;
    }
    let mut app = render_app();
    let (gpu, gpu_anchors) = spawn_curtain(&mut app, -2.0, ClothBackend::Gpu);
    let (cpu, cpu_anchors) = spawn_curtain(&mut app, 2.0, ClothBackend::Cpu);
    common::run(&mut app, 60);
    assert!(in_use(&app, gpu).gpu && !in_use(&app, cpu).gpu);
    for k in 1..=150 {
        let d = 0.7 + 0.4 * k as f32 / 60.0;
        for (x, anchors) in [(-2.0, gpu_anchors), (2.0, cpu_anchors)] {
            spread(&mut app, anchors, x, d);
        }
        app.update();
    }
    common::run(&mut app, 30);
    let torn = |e: Entity| {
        let sim = app.world().get::<ClothSim>(e).unwrap();
        (
            sim.torn_edges(),
            sim.simulation().topology().triangles().len(),
        )
    };
    let (g, c) = (torn(gpu), torn(cpu));
    eprintln!("torn edges, triangles left: GPU {g:?}, CPU {c:?}");
    assert!(c.0 > 50, "the pull must tear the cloth: {c:?}");
    // Where the tear runs differs with rounding (and the GPU's state a step or two on from
    // the host's when it tears); how much tears may not.
    let ratio = g.0 as f32 / c.0 as f32;
    assert!((0.8..1.25).contains(&ratio), "GPU {g:?} against CPU {c:?}");
}

/// Contact impulses from a GPU cloth reach its collider (`ClothContactImpulse`, which the
/// rapier bridge pushes bodies with), a few frames late: a GPU cloth resting on one sphere
/// and the same cloth on the CPU resting on another, far apart, press on them alike.
#[test]
fn a_gpu_cloth_pushes_on_its_colliders() {
    if common::gpu_or_skip("a_gpu_cloth_pushes_on_its_colliders").is_none() {
        return;
    }
    let mut app = render_app();
    let pair = |app: &mut App, x: f32, backend: ClothBackend| {
        let grid = Grid::new(16, 16, 1.0, 1.0);
        let mesh = app
            .world_mut()
            .resource_mut::<Assets<Mesh>>()
            .add(grid_mesh(&grid));
        app.world_mut().spawn((
            Mesh3d(mesh),
            Transform::from_xyz(x, 0.6, 0.0),
            Cloth::default(),
            backend,
        ));
        app.world_mut()
            .spawn((ClothCollider::sphere(0.3), Transform::from_xyz(x, 0.0, 0.0)))
            .id()
    };
    let cpu_ball = pair(&mut app, -10.0, ClothBackend::Cpu);
    let gpu_ball = pair(&mut app, 10.0, ClothBackend::Gpu);
    let (mut cpu, mut gpu) = (Vec::new(), Vec::new());
    for _ in 0..120 {
        app.update();
        let push = |app: &App, e| {
            app.world()
                .get::<ClothContactImpulse>(e)
                .map_or(0.0, |i| i.linear.y)
        };
        cpu.push(push(&app, cpu_ball));
        gpu.push(push(&app, gpu_ball));
    }
    // Resting: the last second's mean downward push on each ball.
    let mean = |v: &[f32]| v[60..].iter().sum::<f32>() / 60.0;
    let (c, g) = (mean(&cpu), mean(&gpu));
    eprintln!("mean push per step: CPU cloth {c} N·s, GPU cloth {g} N·s");
    assert!(c < -1e-4, "the CPU cloth does not rest on its ball ({c})");
    assert!(
        (g - c).abs() < 0.15 * c.abs(),
        "GPU cloth {g} N·s against CPU cloth {c} N·s"
    );
}

/// `render_app` simulating in `schedule`.
fn render_app_in(schedule: impl bevy::ecs::schedule::ScheduleLabel) -> ExitingApp {
    render_app_with(ClothPlugins::new(schedule), true)
}

/// Whether any pipeline of `app`'s render world (a sub-app: no pipelined rendering) is still
/// being compiled.
fn compiling(app: &App) -> bool {
    use bevy::render::render_resource::{CachedPipelineState, PipelineCache};
    let render = app
        .get_sub_app(bevy::render::RenderApp)
        .expect("the render world is a sub-app without pipelined rendering");
    render
        .world()
        .resource::<PipelineCache>()
        .pipelines()
        .any(|p| matches!(p.state, CachedPipelineState::Creating(_)))
}

/// An app that exits a frame after its first GPU cloth started (pipelines still compiling):
/// the exit frame waits for them and for the GPU, so nothing is compiling when the app is
/// dropped; and dropping a render app mid-run, without exiting, leaves the next one working.
#[test]
fn an_app_exiting_right_after_a_gpu_cloth_starts_shuts_down_cleanly() {
    if common::gpu_or_skip("an_app_exiting_right_after_a_gpu_cloth_starts_shuts_down_cleanly")
        .is_none()
    {
        return;
    }
    let mut app = render_app_with(ClothPlugins::default(), false);
    // A camera and a lit material, so the renderer has pipelines of its own to compile.
    let target = app
        .world_mut()
        .resource_mut::<Assets<Image>>()
        .add(Image::new_target_texture(
            64,
            64,
            bevy::render::render_resource::TextureFormat::Rgba8UnormSrgb,
            None,
        ));
    app.world_mut().spawn((
        Camera3d::default(),
        bevy::camera::RenderTarget::Image(target.into()),
        Transform::from_xyz(0.0, 1.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    app.world_mut().spawn(DirectionalLight::default());
    let material = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial::default());
    let cloth = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut()
        .entity_mut(cloth)
        .insert((ClothReadback, MeshMaterial3d(material)));
    // Exit on the first frame that leaves a pipeline compiling (llvmpipe: the first).
    let mut seen_compiling = false;
    for _ in 0..3 {
        app.update();
        seen_compiling = compiling(&app);
        if seen_compiling {
            break;
        }
    }
    if !seen_compiling {
        eprintln!("every pipeline compiled within a frame: the exit frame had none to wait for");
    }
    app.world_mut().write_message(AppExit::Success);
    app.update();
    assert!(
        !compiling(&app),
        "a pipeline is still compiling after the exit frame"
    );
    assert!(in_use(&app, cloth).gpu);
    drop(app.into_inner());
    // Dropped without exiting, two frames in.
    let mut app = render_app();
    spawn(&mut app, Some(ClothBackend::Gpu), false);
    common::run(&mut app, 2);
    drop(app.into_inner());
    // And the next app runs its GPU cloth.
    let mut app = render_app();
    let cloth = spawn(&mut app, Some(ClothBackend::Gpu), false);
    app.world_mut().entity_mut(cloth).insert(ClothReadback);
    let start = centre_y(app_after(&mut app, 5), cloth);
    common::run(&mut app, 40);
    assert!(
        centre_y(&app, cloth) < start - 0.05,
        "the GPU cloth did not fall"
    );
}

fn app_after(app: &mut App, frames: usize) -> &App {
    common::run(app, frames);
    app
}

/// `ClothPlugins::new(schedule)` reaches the GPU backend: with cloth simulated in `FixedLast`
/// (after `FixedPostUpdate`), a GPU cloth resting on a ball still presses on it (its contact
/// impulses arrive in the schedule the colliders are gathered in) and follows its pins in the
/// same step.
#[test]
fn a_gpu_cloth_in_another_schedule_presses_on_its_colliders() {
    if common::gpu_or_skip("a_gpu_cloth_in_another_schedule_presses_on_its_colliders").is_none() {
        return;
    }
    let mut app = render_app_in(FixedLast);
    let grid = Grid::new(16, 16, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    app.world_mut().spawn((
        Mesh3d(mesh),
        Transform::from_xyz(0.0, 0.6, 0.0),
        Cloth::default(),
        ClothBackend::Gpu,
    ));
    let ball = app
        .world_mut()
        .spawn((ClothCollider::sphere(0.3), Transform::default()))
        .id();
    let mut pushes = Vec::new();
    for _ in 0..120 {
        app.update();
        pushes.push(
            app.world()
                .get::<ClothContactImpulse>(ball)
                .map_or(0.0, |i| i.linear.y),
        );
    }
    let mean = pushes[60..].iter().sum::<f32>() / 60.0;
    eprintln!("mean push per step in FixedLast: {mean} N·s");
    assert!(mean < -1e-4, "the ball feels nothing ({mean} N·s)");
}

/// A character moved in `FixedUpdate` with 15 fixed steps per rendered frame (a slow frame,
/// or llvmpipe): each step gives the GPU its own pin targets and collider poses, so the GPU
/// cape stretches as the CPU cape does instead of crumpling on a body swept across the whole
/// frame's path.
#[test]
fn many_fixed_steps_a_frame_give_the_gpu_the_cpus_cape() {
    if common::gpu_or_skip("many_fixed_steps_a_frame_give_the_gpu_the_cpus_cape").is_none() {
        return;
    }
    /// Walks a circle of 2 m around its centre.
    #[derive(Component)]
    struct Walker(Vec3);
    fn walk(time: Res<Time>, mut walkers: Query<(&mut Transform, &Walker)>) {
        for (mut t, w) in &mut walkers {
            let angle = 0.8 * time.elapsed_secs();
            t.translation = w.0 + Vec3::new(2.0 * angle.cos(), 1.0, 2.0 * angle.sin());
            t.rotation = Quat::from_rotation_y(-angle);
        }
    }
    let steps_per_frame = 15.0;
    let mut app = render_app();
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        steps_per_frame / 60.0,
    )))
    .add_systems(FixedUpdate, walk);
    let grid = Grid::new(10, 14, 0.6, 0.9);
    let capes: Vec<Entity> = [ClothBackend::Cpu, ClothBackend::Gpu]
        .into_iter()
        .enumerate()
        .map(|(k, backend)| {
            // Two walkers far apart, each with a body and a cape attached to it.
            let offset = Vec3::X * 20.0 * k as f32;
            let walker = app
                .world_mut()
                .spawn((
                    Walker(offset),
                    Transform::from_translation(offset + Vec3::new(2.0, 1.0, 0.0)),
                ))
                .id();
            let body = app
                .world_mut()
                .spawn((
                    ClothCollider::capsule(0.25, 0.9).with_thickness(0.02),
                    Transform::default(),
                    ChildOf(walker),
                ))
                .id();
            let mesh = app
                .world_mut()
                .resource_mut::<Assets<Mesh>>()
                .add(grid_mesh(&grid));
            let top: Vec<u32> = (0..10).map(|i| grid.index(i, 0)).collect();
            let cape = Transform::from_translation(Vec3::new(2.0, 1.2, 0.3) + offset)
                .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
            app.world_mut()
                .spawn((
                    Mesh3d(mesh),
                    cape,
                    Cloth::default(),
                    ClothPins::attached(top, body),
                    ClothTethers::default(),
                    backend,
                    ClothReadback,
                ))
                .id()
        })
        .collect();
    // The GPU state comes back a few frames late: compare at the end of a steady walk.
    common::run(&mut app, (360.0 / steps_per_frame) as usize);
    assert!(in_use(&app, capes[1]).gpu);
    let strain = |e| app.world().get::<ClothSim>(e).unwrap().max_strain();
    let (cpu, gpu) = (strain(capes[0]), strain(capes[1]));
    eprintln!("max strain with 15 steps a frame: CPU cape {cpu}, GPU cape {gpu}");
    assert!(cpu < 0.2, "the CPU cape itself stretched ({cpu})");
    assert!(
        gpu < 2.0 * cpu + 0.02,
        "GPU cape {gpu} against CPU cape {cpu}"
    );
}

/// A cape with `ClothInertia` 0 on a character that dashes off at 6 m/s and stops dead moves
/// rigidly with it on the GPU as on the CPU (the carried motion reaches the GPU step by
/// step); without inertia the same GPU cape trails and swings.
#[test]
fn a_gpu_cloth_with_inertia_moves_with_its_anchor_as_on_the_cpu() {
    if common::gpu_or_skip("a_gpu_cloth_with_inertia_moves_with_its_anchor_as_on_the_cpu").is_none()
    {
        return;
    }
    #[derive(Component)]
    struct Dasher;
    fn dash(time: Res<Time>, mut dashers: Query<&mut Transform, With<Dasher>>) {
        if (0.2..1.2).contains(&time.elapsed_secs()) {
            for mut t in &mut dashers {
                t.translation.x += 6.0 * time.delta_secs();
            }
        }
    }
    let mut app = render_app();
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        4.0 / 60.0,
    )))
    .add_systems(FixedUpdate, dash);
    let grid = Grid::new(8, 12, 0.5, 0.8);
    let cases = [
        (ClothBackend::Cpu, Some(0.0)),
        (ClothBackend::Gpu, Some(0.0)),
        (ClothBackend::Gpu, None),
    ];
    let mut capes = Vec::new();
    for (k, (backend, inertia)) in cases.into_iter().enumerate() {
        let offset = Vec3::Z * 10.0 * k as f32;
        let dasher = app
            .world_mut()
            .spawn((Dasher, Transform::from_translation(offset + Vec3::Y)))
            .id();
        let mesh = app
            .world_mut()
            .resource_mut::<Assets<Mesh>>()
            .add(grid_mesh(&grid));
        let top: Vec<u32> = (0..8).map(|i| grid.index(i, 0)).collect();
        let at = Transform::from_translation(offset + Vec3::new(0.0, 0.6, -0.2))
            .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
        let mut cape = app.world_mut().spawn((
            Mesh3d(mesh),
            at,
            Cloth::default(),
            ClothPins::attached(top, dasher),
            backend,
            ClothReadback,
        ));
        if let Some(i) = inertia {
            cape.insert(ClothInertia::new(i).relative_to(dasher));
        }
        capes.push((cape.id(), dasher));
    }
    // How far each cape's centre is along x from its character (0 where they were made).
    let offsets = |app: &App| -> Vec<f32> {
        capes
            .iter()
            .map(|&(cape, dasher)| {
                let s = app
                    .world()
                    .get::<ClothSim>(cape)
                    .unwrap()
                    .simulation()
                    .state();
                let centre = (0..s.len()).map(|i| s.position(i).x).sum::<f32>() / s.len() as f32;
                centre - app.world().get::<Transform>(dasher).unwrap().translation.x
            })
            .collect()
    };
    let mut drift = vec![0.0f32; capes.len()];
    // 0.2 s still, 1 s dashing, then 1 s standing: the read-back states of the last 0.6 s.
    // Measured on llvmpipe: 1.0 mm (CPU, inertia 0), 1.0 mm (GPU, inertia 0), 60 mm (GPU).
    for frame in 0..34 {
        app.update();
        if frame >= 25 {
            for (d, now) in drift.iter_mut().zip(offsets(&app)) {
                *d = d.max(now.abs());
            }
        }
    }
    assert!(in_use(&app, capes[1].0).gpu && in_use(&app, capes[2].0).gpu);
    eprintln!(
        "largest drift from the character after the dash (CPU + inertia 0, GPU + inertia 0, GPU): {drift:?}"
    );
    assert!(
        drift[0] < 0.02,
        "CPU cape with inertia 0 drifted {} m",
        drift[0]
    );
    assert!(
        drift[1] < 0.02,
        "GPU cape with inertia 0 drifted {} m",
        drift[1]
    );
    assert!(
        drift[2] > 0.03,
        "the GPU cape without inertia hardly swung ({} m)",
        drift[2]
    );
}

/// Skinned clothing on the GPU backend: a sheet skinned to one joint, its first row held to
/// the skin (max distance 0), the rest within 0.2 m; the joint moves 1 m and stops. The cloth
/// runs on the GPU, its first row ends on the skin and the rest within reach of it.
#[test]
fn a_skinned_gpu_cloth_follows_its_skin() {
    use bevy::mesh::VertexAttributeValues;
    use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
    if common::gpu_or_skip("a_skinned_gpu_cloth_follows_its_skin").is_none() {
        return;
    }
    let mut app = render_app();
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let mut mesh = grid_mesh(&grid);
    let n = grid.positions().len();
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_JOINT_INDEX,
        VertexAttributeValues::Uint16x4(vec![[0, 0, 0, 0]; n]),
    );
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_JOINT_WEIGHT,
        vec![[1.0f32, 0.0, 0.0, 0.0]; n],
    );
    let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
    let joint = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, 1.0, 0.0))
        .id();
    let bindposes = app
        .world_mut()
        .resource_mut::<Assets<SkinnedMeshInverseBindposes>>()
        .add(SkinnedMeshInverseBindposes::from(vec![Mat4::IDENTITY]));
    let max: Vec<f32> = (0..n as u32)
        .map(|v| if v < 12 { 0.0 } else { 0.2 })
        .collect();
    let e = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::IDENTITY,
            Cloth::default(),
            ClothBackend::Gpu,
            ClothReadback,
            SkinnedMesh {
                inverse_bindposes: bindposes,
                joints: vec![joint],
            },
            ClothSkinning {
                max_distance: MaxDistance::PerVertex(max),
                backstop: None,
            },
        ))
        .id();
    for frame in 0..60 {
        let x = (frame as f32 / 20.0).min(1.0);
        app.world_mut()
            .get_mut::<Transform>(joint)
            .unwrap()
            .translation
            .x = x;
        app.update();
    }
    assert!(in_use(&app, e).gpu, "{:?}", in_use(&app, e));
    let rest = grid.positions();
    let sim = app.world().get::<ClothSim>(e).unwrap();
    let (mut top, mut rest_worst) = (0.0f32, 0.0f32);
    for (v, r) in rest.iter().enumerate() {
        let skin = *r + Vec3::new(1.0, 1.0, 0.0);
        let p = sim
            .simulation()
            .state()
            .position(sim.particle(v as u32) as usize);
        let d = p.distance(skin);
        if v < 12 {
            top = top.max(d);
        } else {
            rest_worst = rest_worst.max(d);
        }
    }
    assert!(top < 1e-4, "the first row is {top} m off the skin");
    assert!(
        rest_worst <= 0.2 + 1e-4,
        "a vertex is {rest_worst} m off the skin"
    );
    assert!(rest_worst > 0.01, "the sheet followed the skin rigidly");
}

/// What a `FixedUpdate` system changes at the second of four fixed steps in a frame: `App`
/// with four steps a frame, whose `change` runs once, at fixed step `at` (the second of its
/// frame), and the render world in the main thread, so a panic there fails the test.
fn four_steps_a_frame(at: u32, change: fn(&mut Commands, Entity)) -> ExitingApp {
    #[derive(Resource)]
    struct Change(u32, fn(&mut Commands, Entity));
    fn run_change(
        mut commands: Commands,
        change: Res<Change>,
        mut step: Local<u32>,
        cloths: Query<Entity, With<Cloth>>,
    ) {
        *step += 1;
        if *step == change.0 {
            for e in &cloths {
                (change.1)(&mut commands, e);
            }
        }
    }
    let mut app = render_app_with(ClothPlugins::default(), false);
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        4.0 / 60.0,
    )))
    .insert_resource(Change(at, change))
    .add_systems(FixedUpdate, run_change);
    app
}

/// A tearing cloth whose mesh is replaced between two fixed steps of a frame starts from the
/// new mesh at that step on the GPU as on the CPU: the frame's earlier steps, queued for the
/// old cloth (its pins' targets where the old mesh had those vertices), are not run on the new
/// one. Before, they yanked the new cloth's pinned vertices to the old targets and it tore to
/// shreds (over 500 edges) where the CPU cloth tore none.
#[test]
fn a_mesh_replaced_between_fixed_steps_starts_the_gpu_cloth_afresh() {
    if common::gpu_or_skip("a_mesh_replaced_between_fixed_steps_starts_the_gpu_cloth_afresh")
        .is_none()
    {
        return;
    }
    // Step 62 is the second of the frame of steps 61–64.
    let mut app = four_steps_a_frame(62, |commands, e| {
        commands.queue(move |world: &mut World| {
            // 24 columns over the same width: vertices 0..12 (the pins) are now the left half
            // of the top edge, not all of it.
            let wider = grid_mesh(&Grid::new(24, 12, 1.0, 1.0));
            let mesh = world.resource_mut::<Assets<Mesh>>().add(wider);
            world.entity_mut(e).insert(Mesh3d(mesh));
        });
    });
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let cloths: Vec<Entity> = [ClothBackend::Cpu, ClothBackend::Gpu]
        .into_iter()
        .enumerate()
        .map(|(k, backend)| {
            let mesh = app
                .world_mut()
                .resource_mut::<Assets<Mesh>>()
                .add(grid_mesh(&grid));
            app.world_mut()
                .spawn((
                    Mesh3d(mesh),
                    Transform::from_xyz(3.0 * k as f32, 1.0, 0.0)
                        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2)),
                    Cloth::default(),
                    ClothPins::rest((0..12).map(|i| grid.index(i, 0))),
                    ClothTearing::default(),
                    ClothReadback,
                    backend,
                ))
                .id()
        })
        .collect();
    common::run(&mut app, 15);
    assert!(in_use(&app, cloths[1]).gpu, "the GPU cloth runs on the GPU");
    common::run(&mut app, 20);
    let sim = |e| app.world().get::<ClothSim>(e).expect("rebuilt");
    for &e in &cloths {
        assert_eq!(
            sim(e).simulation().state().len(),
            24 * 12,
            "rebuilt from the new mesh"
        );
    }
    let (cpu, gpu) = (sim(cloths[0]).torn_edges(), sim(cloths[1]).torn_edges());
    eprintln!("torn edges after the mesh change: CPU {cpu}, GPU {gpu}");
    assert_eq!(cpu, 0, "the CPU cloth itself tore");
    assert_eq!(gpu, 0, "the GPU cloth tore where the CPU cloth did not");
    // And it hangs from its new pins as the CPU cloth does.
    let strain = |e| sim(e).max_strain();
    assert!(
        strain(cloths[1]) < 2.0 * strain(cloths[0]) + 0.05,
        "GPU strain {} against CPU {}",
        strain(cloths[1]),
        strain(cloths[0])
    );
}

/// Pins changed between two fixed steps of a frame reach the GPU from that step: the frame's
/// earlier steps hold the new pins at their targets too (they were queued with one target per
/// old pin). Before, the render world panicked ("one target per pin") and the cloth froze.
#[test]
fn pins_changed_between_fixed_steps_hold_on_the_gpu() {
    if common::gpu_or_skip("pins_changed_between_fixed_steps_hold_on_the_gpu").is_none() {
        return;
    }
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let mut app = four_steps_a_frame(62, |commands, e| {
        let grid = Grid::new(12, 12, 1.0, 1.0);
        commands.entity(e).insert(ClothPins::rest([
            grid.index(0, 0),
            grid.index(6, 0),
            grid.index(11, 0),
        ]));
    });
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let place = Transform::from_xyz(0.0, 1.0, 0.0)
        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let cloth = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            place,
            Cloth::default(),
            ClothPins::rest([grid.index(0, 0), grid.index(11, 0)]),
            ClothReadback,
            ClothBackend::Gpu,
        ))
        .id();
    let middle = |app: &App| {
        let sim = app.world().get::<ClothSim>(cloth).unwrap();
        sim.simulation()
            .state()
            .position(sim.particle(grid.index(6, 0)) as usize)
    };
    common::run(&mut app, 15);
    assert!(in_use(&app, cloth).gpu, "the cloth runs on the GPU");
    // Its top edge sags between the two corners before the middle is pinned.
    let target = place.transform_point(grid.positions()[grid.index(6, 0) as usize]);
    let sag = middle(&app).distance(target);
    eprintln!("the top edge's middle, 2 pins: {sag} m from where the third pin holds it");
    assert!(sag > 1e-3, "the top edge does not sag ({sag} m)");
    common::run(&mut app, 20);
    let off = middle(&app).distance(target);
    let steps = app.world().get::<ClothSim>(cloth).unwrap().steps();
    eprintln!("3 pins: {off} m from its target after {steps} steps");
    assert!(off < 1e-4, "the third pin does not hold ({off} m off)");
}

/// A new welding (`Cloth::weld_tolerance`: other particles) builds the cloth again from its
/// rest shape on the GPU as on the CPU; before, the GPU carried the old state over whenever
/// the vertex count stayed the same, so the two backends parted. A new mass goes on from
/// where the cloth is, on both.
#[test]
fn a_rebuilt_gpu_cloth_starts_from_its_rest_shape_as_on_the_cpu() {
    if common::gpu_or_skip("a_rebuilt_gpu_cloth_starts_from_its_rest_shape_as_on_the_cpu").is_none()
    {
        return;
    }
    let mut app = render_app();
    let cloths = [ClothBackend::Cpu, ClothBackend::Gpu].map(|b| {
        let e = spawn(&mut app, Some(b), false);
        app.world_mut().entity_mut(e).insert(ClothReadback);
        e
    });
    common::run(&mut app, 40);
    assert!(in_use(&app, cloths[1]).gpu);
    for e in cloths {
        let y = centre_y(&app, e);
        assert!(y < 0.7, "cloth {e} did not swing down ({y})");
        app.world_mut().get_mut::<Cloth>(e).unwrap().mass *= 2.0;
    }
    common::run(&mut app, 5);
    for e in cloths {
        let y = centre_y(&app, e);
        assert!(y < 0.7, "cloth {e} started again with its new mass ({y})");
        let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
        let total: f32 = (0..s.len())
            .map(|i| 1.0 / s.positions[i].w)
            .filter(|m| m.is_finite())
            .sum();
        assert!(
            total > 0.39,
            "cloth {e}: {total} kg free, the new mass is 0.4 kg"
        );
        app.world_mut().get_mut::<Cloth>(e).unwrap().weld_tolerance *= 2.0;
    }
    // A few frames for the GPU's state to come back; the free edge falls about 2 cm meanwhile.
    common::run(&mut app, 5);
    for e in cloths {
        let y = centre_y(&app, e);
        eprintln!("cloth {e} 5 frames after the rebuild: free edge at {y} m");
        assert!(y > 0.9, "cloth {e} went on from its old state ({y})");
    }
}

/// The positions in `mesh`'s vertex slab on the GPU (the render world of `app`), read with
/// the stride of `layout`'s attributes.
fn positions_on_the_gpu(app: &App, mesh: AssetId<Mesh>, layout: &Mesh) -> Option<Vec<Vec3>> {
    let (words, stride) = vertices_on_the_gpu(app, mesh, layout)?;
    // The position is the first attribute (the lowest id).
    Some(
        words
            .chunks_exact(stride)
            .map(|v| Vec3::new(v[0], v[1], v[2]))
            .collect(),
    )
}

/// Every float of `mesh`'s vertex slab as the GPU holds it (attributes interleaved as in
/// `layout`, all of them 32-bit floats here), and the floats a vertex.
fn vertices_on_the_gpu(app: &App, mesh: AssetId<Mesh>, layout: &Mesh) -> Option<(Vec<f32>, usize)> {
    use bevy::render::mesh::allocator::MeshAllocator;
    let slice = render_world(app)
        .resource::<MeshAllocator>()
        .mesh_vertex_slice(&mesh)?;
    let stride: u64 = layout.attributes().map(|(a, _)| a.format.size()).sum();
    let range = u64::from(slice.range.start) * stride..u64::from(slice.range.end) * stride;
    let words = bytemuck::pod_collect_to_vec(&read_buffer(app, slice.buffer, range));
    Some((words, (stride / 4) as usize))
}

/// Cloth `e`'s drawn mesh and a copy of it from the main world (its vertex layout).
fn drawn_mesh(app: &App, e: Entity) -> (Handle<Mesh>, Mesh) {
    let handle = app.world().get::<Mesh3d>(e).unwrap().0.clone();
    let layout = app
        .world()
        .resource::<Assets<Mesh>>()
        .get(&handle)
        .unwrap()
        .clone();
    (handle, layout)
}

/// The local positions of GPU cloth `e`'s mesh as the GPU wrote them (the render world of a
/// render app without pipelined rendering).
fn drawn_on_the_gpu(app: &App, e: Entity) -> Vec<Vec3> {
    let handle = app.world().get::<Mesh3d>(e).unwrap().0.clone();
    let layout = app.world().resource::<Assets<Mesh>>().get(&handle).unwrap();
    positions_on_the_gpu(app, handle.id(), layout).expect("the cloth is on the GPU")
}

/// A mesh put on a GPU cloth's entity after the frame's fixed steps (in `Update`, as a game
/// swaps a level of detail) is the source of the next build, never a target: the GPU cloth
/// writes into its own copy only. Before, it wrote its vertices into the new mesh's slab for
/// the frame until the rebuild (here: a smaller mesh, so past its end into whatever the slab
/// holds next).
#[test]
fn a_mesh_put_in_from_update_is_not_written_by_the_gpu_cloth() {
    if common::gpu_or_skip("a_mesh_put_in_from_update_is_not_written_by_the_gpu_cloth").is_none() {
        return;
    }
    #[derive(Resource)]
    struct Swap(Option<(Entity, Handle<Mesh>)>);
    fn swap(mut commands: Commands, mut swap: ResMut<Swap>) {
        if let Some((e, mesh)) = swap.0.take() {
            commands.entity(e).insert(Mesh3d(mesh));
        }
    }
    let mut app = render_app_with(ClothPlugins::default(), false);
    app.insert_resource(Swap(None)).add_systems(Update, swap);
    let cloth = spawn(&mut app, Some(ClothBackend::Gpu), false);
    // A small sheet far above, drawn by an entity of its own.
    let small = grid_mesh(&Grid::new(4, 4, 0.3, 0.3)).translated_by(Vec3::Y * 5.0);
    let expected: Vec<Vec3> = match small.attribute(Mesh::ATTRIBUTE_POSITION) {
        Some(bevy::mesh::VertexAttributeValues::Float32x3(p)) => {
            p.iter().map(|&v| Vec3::from(v)).collect()
        }
        _ => panic!("positions"),
    };
    let layout = small.clone();
    let handle = app.world_mut().resource_mut::<Assets<Mesh>>().add(small);
    app.world_mut()
        .spawn((Mesh3d(handle.clone()), Transform::default()));
    common::run(&mut app, 15);
    assert!(in_use(&app, cloth).gpu);
    let before = positions_on_the_gpu(&app, handle.id(), &layout).expect("on the GPU");
    assert_eq!(before, expected, "the small sheet as uploaded");
    app.world_mut().resource_mut::<Swap>().0 = Some((cloth, handle.clone()));
    for frame in 0..3 {
        app.update();
        let now = positions_on_the_gpu(&app, handle.id(), &layout).expect("on the GPU");
        assert_eq!(
            now, expected,
            "frame {frame} after the swap: the GPU cloth wrote into the mesh put in"
        );
    }
    // And the cloth was built again from it, on the GPU.
    common::run(&mut app, 5);
    assert!(in_use(&app, cloth).gpu);
    let sim = app.world().get::<ClothSim>(cloth).unwrap();
    assert_eq!(
        sim.simulation().state().len(),
        16,
        "built from the small sheet"
    );
}

/// A game's runtime changes at random fixed steps of four-step frames (a fixed seed), the same
/// to a CPU cloth and a GPU cloth side by side: new meshes, pins, features, settings, `Cloth`
/// rebuilds, teleports, the GPU twin sent to the CPU and back. The render world runs in the
/// main thread (a panic there fails the test); nothing tears (the threshold, 3, is past what
/// the scene stretches unless a step is run on inputs it was not queued for); every state is
/// finite; and once left alone each GPU cloth hangs as its CPU twin does (lowest points within
/// a tenth of the cloth's size).
#[test]
fn random_runtime_changes_between_fixed_steps_keep_gpu_cloths_with_their_cpu_twins() {
    if common::gpu_or_skip(
        "random_runtime_changes_between_fixed_steps_keep_gpu_cloths_with_their_cpu_twins",
    )
    .is_none()
    {
        return;
    }
    /// The twins (CPU, GPU), and whether the changes go on.
    #[derive(Resource)]
    struct Twins(Vec<[Entity; 2]>, bool);
    #[expect(clippy::too_many_arguments, reason = "a system's inputs")]
    fn change(
        mut commands: Commands,
        twins: Res<Twins>,
        mut rng: Local<u64>,
        mut transforms: Query<&mut Transform>,
        mut configs: Query<&mut ClothConfig>,
        mut cloths: Query<&mut Cloth>,
        features: Query<(Has<ClothSelfCollision>, Has<ClothTethers>)>,
        backends: Query<&ClothBackend>,
        mut meshes: ResMut<Assets<Mesh>>,
    ) {
        if !twins.1 {
            return;
        }
        // xorshift64*, seeded.
        let mut next = |n: u64| {
            if *rng == 0 {
                *rng = 0x9E37_79B9_7F4A_7C15;
            }
            *rng ^= *rng >> 12;
            *rng ^= *rng << 25;
            *rng ^= *rng >> 27;
            (rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 33) % n
        };
        if next(3) != 0 {
            return;
        }
        let pair = twins.0[next(twins.0.len() as u64) as usize];
        let op = next(8);
        let a = next(1000);
        for (k, e) in pair.into_iter().enumerate() {
            match op {
                0 => {
                    let (c, r) = (6 + (a % 7) as u32, 6 + (a / 7 % 7) as u32);
                    let mesh = meshes.add(grid_mesh(&Grid::new(c, r, 0.8, 0.8)));
                    commands.entity(e).insert(Mesh3d(mesh));
                }
                1 => {
                    // Pins along the top edge (the first six vertices of any grid here).
                    let pins: Vec<u32> = (0..6u32).filter(|i| a >> i & 1 == 1 || *i == 0).collect();
                    commands.entity(e).insert(ClothPins::rest(pins));
                }
                2 => {
                    if features.get(e).unwrap().0 {
                        commands.entity(e).remove::<ClothSelfCollision>();
                    } else {
                        commands.entity(e).insert(ClothSelfCollision {
                            thickness: None,
                            friction: 0.1,
                        });
                    }
                }
                3 => {
                    if features.get(e).unwrap().1 {
                        commands.entity(e).remove::<ClothTethers>();
                    } else {
                        commands.entity(e).insert(ClothTethers::default());
                    }
                }
                4 => {
                    let mut c = configs.get_mut(e).unwrap();
                    c.substeps = 4 + (a % 9) as u32;
                    c.iterations = 1 + (a / 9 % 2) as u32;
                }
                // A teleport (past `Cloth::teleport_distance`): the whole cloth moves.
                5 => transforms.get_mut(e).unwrap().translation.y += (a % 2) as f32 * 6.0 - 3.0,
                6 => {
                    cloths.get_mut(e).unwrap().mass = 0.1 + a as f32 * 1e-3;
                }
                _ => {
                    if k == 1 {
                        let to = match backends.get(e) {
                            Ok(ClothBackend::Cpu) => ClothBackend::Gpu,
                            _ => ClothBackend::Cpu,
                        };
                        commands.entity(e).insert(to);
                    }
                }
            }
        }
    }
    let mut app = four_steps_a_frame(u32::MAX, |_, _| {});
    app.add_systems(FixedUpdate, change);
    let grid = Grid::new(10, 10, 0.8, 0.8);
    let twins: Vec<[Entity; 2]> = (0..3)
        .map(|p| {
            [ClothBackend::Cpu, ClothBackend::Gpu].map(|b| {
                let mesh = app
                    .world_mut()
                    .resource_mut::<Assets<Mesh>>()
                    .add(grid_mesh(&grid));
                let x = 3.0 * p as f32 + if b == ClothBackend::Gpu { 20.0 } else { 0.0 };
                app.world_mut()
                    .spawn((
                        Mesh3d(mesh),
                        Transform::from_xyz(x, 2.0, 0.0)
                            .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2)),
                        Cloth::default(),
                        ClothPins::rest(0..6),
                        ClothTearing { threshold: 3.0 },
                        ClothReadback,
                        b,
                    ))
                    .id()
            })
        })
        .collect();
    app.insert_resource(Twins(twins.clone(), true));
    for frame in 0..150 {
        app.update();
        for &e in twins.iter().flatten() {
            let Some(sim) = app.world().get::<ClothSim>(e) else {
                continue;
            };
            assert!(sim.simulation().state().is_finite(), "frame {frame}: {e}");
            assert_eq!(
                sim.torn_edges(),
                0,
                "frame {frame}: cloth {e} tore ({:?})",
                app.world().get::<ClothBackendInUse>(e)
            );
        }
    }
    // Left alone: every GPU twin back on the GPU, then settled.
    app.world_mut().resource_mut::<Twins>().1 = false;
    for [_, gpu] in &twins {
        app.world_mut().entity_mut(*gpu).insert(ClothBackend::Gpu);
    }
    common::run(&mut app, 120);
    for [cpu, gpu] in &twins {
        assert!(in_use(&app, *gpu).gpu, "{:?}", in_use(&app, *gpu));
        let sim = |e: Entity| app.world().get::<ClothSim>(e).expect("built");
        let (c, g) = (sim(*cpu), sim(*gpu));
        assert_eq!(c.simulation().state().len(), g.simulation().state().len());
        assert_eq!(c.torn_edges() + g.torn_edges(), 0);
        let low = |s: &ClothSim| {
            let st = s.simulation().state();
            (0..st.len())
                .map(|i| st.position(i).y)
                .fold(f32::INFINITY, f32::min)
        };
        // The twins stand 20 m apart along x; their lowest points hang alike. Not a rounding
        // bound: after a run of discrete changes (each GPU twin also spent frames on the
        // CPU) the two still swing a little apart, so the check is physical, a tenth of the
        // cloth's 0.8 m; the faults it catches put a cloth metres away (left behind at a
        // teleport, built where an old mesh was) or tear it.
        eprintln!(
            "twins {cpu}/{gpu}: lowest point {} / {} m, strain {} / {}",
            low(c),
            low(g),
            c.max_strain(),
            g.max_strain()
        );
        assert!(
            (low(c) - low(g)).abs() < 0.08,
            "lowest points {} and {}",
            low(c),
            low(g)
        );
        assert!(g.max_strain() < 2.0 * c.max_strain() + 0.05);
    }
}

/// A GPU cloth sent to the CPU in the step its entity teleports (10 m) goes on from its last
/// GPU state, which is some steps old, moved along with its pins (the teleport rule applied
/// to the gap); before, the CPU started from where the GPU had left it, 10 m from its pins,
/// and the cloth tore apart.
#[test]
fn a_gpu_cloth_sent_to_the_cpu_as_it_teleports_lands_with_its_pins() {
    if common::gpu_or_skip("a_gpu_cloth_sent_to_the_cpu_as_it_teleports_lands_with_its_pins")
        .is_none()
    {
        return;
    }
    let mut app = four_steps_a_frame(62, |commands, e| {
        commands.queue(move |world: &mut World| {
            world.get_mut::<Transform>(e).unwrap().translation.x += 10.0;
        });
        commands.entity(e).insert(ClothBackend::Cpu);
    });
    let grid = Grid::new(12, 12, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let cloth = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 1.0, 0.0)
                .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2)),
            Cloth::default(),
            ClothPins::rest((0..12).map(|i| grid.index(i, 0))),
            ClothTearing { threshold: 3.0 },
            ClothBackend::Gpu,
        ))
        .id();
    common::run(&mut app, 15);
    assert!(in_use(&app, cloth).gpu);
    common::run(&mut app, 20);
    assert!(!in_use(&app, cloth).gpu, "on the CPU");
    let sim = app.world().get::<ClothSim>(cloth).unwrap();
    let state = sim.simulation().state();
    let xs = (0..state.len()).map(|i| state.position(i).x);
    let (lo, hi) = xs.fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), x| {
        (l.min(x), h.max(x))
    });
    eprintln!(
        "after the teleport: x from {lo} to {hi}, {} edges torn",
        sim.torn_edges()
    );
    assert_eq!(sim.torn_edges(), 0, "the cloth tore");
    assert!(
        lo > 9.0 && hi < 11.0,
        "the cloth is not where its pins are: x from {lo} to {hi}"
    );
}

/// A GPU cloth scaled to nothing (hidden by a zero scale) leaves its mesh's slab at its last
/// finite shape, as the CPU leaves its mesh; before, the mesh kernel wrote the positions
/// through the singular transform's inverse (non-finite).
#[test]
fn a_gpu_cloth_at_zero_scale_keeps_a_finite_slab() {
    if common::gpu_or_skip("a_gpu_cloth_at_zero_scale_keeps_a_finite_slab").is_none() {
        return;
    }
    let mut app = render_app_with(ClothPlugins::default(), false);
    let cloth = spawn(&mut app, Some(ClothBackend::Gpu), false);
    common::run(&mut app, 15);
    assert!(in_use(&app, cloth).gpu);
    let (mesh, layout) = drawn_mesh(&app, cloth);
    let finite = |app: &App| {
        positions_on_the_gpu(app, mesh.id(), &layout)
            .expect("on the GPU")
            .iter()
            .all(|p| p.is_finite())
    };
    assert!(finite(&app));
    app.world_mut().get_mut::<Transform>(cloth).unwrap().scale = Vec3::ZERO;
    common::run(&mut app, 3);
    assert!(finite(&app), "the slab took non-finite positions");
    app.world_mut().get_mut::<Transform>(cloth).unwrap().scale = Vec3::ONE;
    common::run(&mut app, 3);
    assert!(finite(&app));
}

/// A mesh as a modelling tool can leave it — a zero-area triangle of three vertices in a row,
/// a triangle naming one vertex twice, a triangle to a vertex a hair off another (welded to
/// it: a zero-length edge), a vertex stored twice at one place and a vertex no triangle uses
/// — runs on the GPU with self-collision and tearing while its pinned entity is dragged
/// sideways at 3 m/s: every float the GPU writes into its vertex slab (positions, normals,
/// UVs, tangents) stays finite, every frame.
#[test]
fn a_broken_mesh_runs_on_the_gpu_and_draws_only_finite_vertices() {
    use bevy::mesh::{Indices, VertexAttributeValues};
    if common::gpu_or_skip("a_broken_mesh_runs_on_the_gpu_and_draws_only_finite_vertices").is_none()
    {
        return;
    }
    let mut app = render_app_with(ClothPlugins::default(), false);
    let grid = Grid::new(8, 8, 1.0, 1.0);
    let mut mesh = grid_mesh(&grid);
    let Some(VertexAttributeValues::Float32x3(positions)) =
        mesh.attribute(Mesh::ATTRIBUTE_POSITION).cloned()
    else {
        panic!("grid_mesh has positions");
    };
    let mut positions = positions;
    let Some(Indices::U32(mut indices)) = mesh.indices().cloned() else {
        panic!("grid_mesh has u32 indices");
    };
    let n = positions.len() as u32;
    let at = |i: u32, j: u32| grid.index(i, j);
    // Three vertices in a row (zero area), a vertex named twice, a triangle to a point a
    // hair off a vertex, a copy of a vertex, and a vertex of nobody's.
    indices.extend([at(0, 3), at(1, 3), at(2, 3)]);
    indices.extend([at(4, 4), at(4, 4), at(5, 4)]);
    let p = positions[at(6, 6) as usize];
    positions.push([p[0] + 1e-7, p[1], p[2]]);
    indices.extend([at(6, 6), at(7, 6), n]);
    let q = positions[at(3, 5) as usize];
    positions.push(q);
    indices.extend([n + 1, at(4, 5), at(3, 6)]);
    positions.push([5.0, 5.0, 5.0]);
    let count = positions.len();
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; count]);
    mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, vec![[0.5f32, 0.5]; count]);
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_TANGENT,
        vec![[1.0f32, 0.0, 0.0, 1.0]; count],
    );
    mesh.insert_indices(Indices::U32(indices));
    let handle = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
    let cloth = app
        .world_mut()
        .spawn((
            Mesh3d(handle),
            Transform::from_xyz(0.0, 1.0, 0.0),
            Cloth::default(),
            ClothBackend::Gpu,
            ClothSelfCollision::default(),
            ClothTearing::default(),
            ClothPins::rest([at(0, 0), at(7, 0)]),
        ))
        .id();
    common::run(&mut app, 10);
    assert!(in_use(&app, cloth).gpu, "{:?}", in_use(&app, cloth));
    let (drawn, layout) = drawn_mesh(&app, cloth);
    for frame in 0..40 {
        app.world_mut()
            .get_mut::<Transform>(cloth)
            .unwrap()
            .translation
            .x += 0.05;
        common::run(&mut app, 1);
        let (words, stride) = vertices_on_the_gpu(&app, drawn.id(), &layout).expect("on the GPU");
        assert_eq!(stride, 12, "position, normal, UV and tangent");
        let bad = words.iter().filter(|w| !w.is_finite()).count();
        assert_eq!(
            bad, 0,
            "frame {frame}: {bad} non-finite floats in the vertex slab"
        );
    }
    assert!(in_use(&app, cloth).gpu, "still on the GPU");
}

#[test]
fn a_gpu_character_cloned_with_its_children_wears_its_own_cape() {
    if common::gpu_or_skip("a_gpu_character_cloned_with_its_children_wears_its_own_cape").is_none()
    {
        return;
    }
    let mut app = render_app();
    let (root, _, cape, top) = common::caped_character(&mut app);
    app.world_mut()
        .entity_mut(cape)
        .insert((ClothBackend::Gpu, ClothReadback));
    common::run(&mut app, 20);
    assert!(in_use(&app, cape).gpu);
    let (twin, twin_cape) = common::clone_with_children(&mut app, root);
    common::walk_away(&mut app, twin);
    // Read back a few frames late: let the last positions arrive.
    common::run(&mut app, 10);
    assert!(in_use(&app, twin_cape).gpu, "{:?}", in_use(&app, twin_cape));
    common::assert_capes_apart(&app, cape, twin_cape, &top);
    // Both cloths hang below their edges: the twin runs its own GPU cloth.
    for e in [cape, twin_cape] {
        let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
        let low = (0..s.len())
            .map(|i| s.position(i).y)
            .fold(f32::MAX, f32::min);
        assert!(low < 1.2, "cloth {e} hangs no lower than {low}");
    }
}

/// A GPU cloth disabled with its character (Bevy's `Disabled`, as games pool entities) stops
/// and, enabled again, goes on from where it stopped: the same as a run that never paused.
/// Before, the render world dropped it while it was not extracted and, enabled again, it
/// started over from its first upload (its rest shape, flat).
#[test]
fn a_disabled_gpu_cloth_goes_on_where_it_stopped() {
    if common::gpu_or_skip("a_disabled_gpu_cloth_goes_on_where_it_stopped").is_none() {
        return;
    }
    use bevy::ecs::entity_disabling::Disabled;
    // Where the GPU draws the cloth this frame: the slab it wrote (the render world runs in
    // the app's update) placed by the entity's transform, as the renderer places it.
    let run = |pause: bool| -> Vec<Vec3> {
        let mut app = render_app_with(ClothPlugins::default(), false);
        let (root, bone, cape, _) = common::caped_character(&mut app);
        app.world_mut().entity_mut(cape).insert(ClothBackend::Gpu);
        common::run(&mut app, 30);
        assert!(in_use(&app, cape).gpu);
        if pause {
            for e in [root, bone, cape] {
                app.world_mut().entity_mut(e).insert(Disabled);
            }
            common::run(&mut app, 20);
        }
        // Moved 10 m (a teleport), disabled or not.
        app.world_mut()
            .get_mut::<Transform>(root)
            .unwrap()
            .translation
            .x = 10.0;
        if pause {
            common::run(&mut app, 20);
            for e in [root, bone, cape] {
                app.world_mut().entity_mut(e).remove::<Disabled>();
            }
        }
        common::run(&mut app, 40);
        let sim = app.world().get::<ClothSim>(cape).unwrap();
        assert_eq!(sim.steps(), 69);
        let mesh = sim.mesh().id();
        let layout = app
            .world()
            .resource::<Assets<Mesh>>()
            .get(mesh)
            .unwrap()
            .clone();
        let at = *app.world().get::<GlobalTransform>(cape).unwrap();
        positions_on_the_gpu(&app, mesh, &layout)
            .expect("the cloth's mesh is on the GPU")
            .into_iter()
            .map(|p| at.transform_point(p))
            .collect()
    };
    let (paused, straight) = (run(true), run(false));
    // The same kernels on the same inputs on one device (no float atomics): the same state.
    // The slabs themselves may differ: Bevy 0.19 does not propagate a transform changed
    // while its entity was disabled, so the paused run's cloth entity still has its old
    // `GlobalTransform` (x = 0) and its slab holds the cloth relative to that. Placed in the
    // world, the two agree up to the rounding of the mesh kernel's inverse transform and the
    // placing here: a few f32 steps at 10 m (9.5e-7 m each); 1e-5 m is ten.
    let apart = paused
        .iter()
        .zip(&straight)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f32::max);
    assert!(
        apart <= 1e-5,
        "after the pause a vertex is {apart} m from where the run without one has it"
    );
}

/// A GPU cloth cloned into a cloth that runs on the CPU steps there: the copy does not carry
/// the original's GPU markers (`ClothSteppedElsewhere` kept it from the CPU plugin).
#[test]
fn a_gpu_cloth_cloned_onto_the_cpu_steps_there() {
    if common::gpu_or_skip("a_gpu_cloth_cloned_onto_the_cpu_steps_there").is_none() {
        return;
    }
    let mut app = render_app();
    let e = spawn(&mut app, Some(ClothBackend::Gpu), false);
    common::run(&mut app, 10);
    assert!(in_use(&app, e).gpu);
    let twin = app.world_mut().entity_mut(e).clone_and_spawn();
    app.world_mut().entity_mut(twin).insert(ClothBackend::Cpu);
    common::run(&mut app, 30);
    let u = in_use(&app, twin);
    assert!(!u.gpu, "{u:?}");
    assert!(
        app.world().get::<ClothSim>(twin).unwrap().steps() >= 25,
        "the copy did not step on the CPU: {} steps",
        app.world().get::<ClothSim>(twin).unwrap().steps()
    );
}

/// Changing the solver or the substeps of a GPU cloth settles, as on the CPU (`game`'s
/// `switching_solver_and_substeps_does_not_fling_the_cloth`, the same cloths and bound): its
/// GPU state goes on at the new settings without the burst of speed that the stretch the old
/// settings tolerated would give. Before the GPU settled, its fastest vertex reached 16.7 m/s
/// after lab → XPBD and 17.8 m/s after 2 → 20 substeps (3.4 and 1.5 on the CPU).
#[test]
fn switching_solver_and_substeps_on_the_gpu_does_not_fling_the_cloth() {
    if common::gpu_or_skip("switching_solver_and_substeps_on_the_gpu_does_not_fling_the_cloth")
        .is_none()
    {
        return;
    }
    let mut app = render_app();
    for (from, to, what) in common::solver_switches() {
        let (natural, after) =
            common::fastest_before_and_after(&mut app, Some(ClothBackend::Gpu), from, |e| {
                e.insert(to);
            });
        assert!(
            after < natural.max(3.0),
            "{what}: {after} m/s after, {natural} m/s falling"
        );
    }
}

/// On the GPU too, a cloth's size follows its entity's scale (`game`'s
/// `a_cloth_grows_with_its_entitys_scale`, read back): each change of scale gives the GPU the
/// rest shape at the new scale, and the cloth's GPU state is stretched with it (the carry of
/// the `teleport` kernel) instead of starting again.
#[test]
fn a_gpu_cloth_grows_with_its_entitys_scale() {
    if common::gpu_or_skip("a_gpu_cloth_grows_with_its_entitys_scale").is_none() {
        return;
    }
    let mut app = render_app();
    let cloths = common::scaled_cloths(&mut app, Some(ClothBackend::Gpu));
    for e in cloths {
        assert!(in_use(&app, e).gpu, "it stays on the GPU");
    }
    common::check_scaled_cloths(&app, cloths);
}

/// On the GPU too, a cloth grown in from scale 0 is not whipped by its growth (`game`'s
/// `a_cloth_grown_in_is_not_whipped_by_its_growth`, the same bound, read back): the
/// `teleport` kernel keeps a stretched velocity's speed as `ClothState::carry` does (before:
/// 3.9 m/s against 1.1, and 43 edge–triangle pairs through itself).
#[test]
fn a_gpu_cloth_grown_in_is_not_whipped_by_its_growth() {
    if common::gpu_or_skip("a_gpu_cloth_grown_in_is_not_whipped_by_its_growth").is_none() {
        return;
    }
    let mut app = render_app();
    common::check_popped_in(common::popped_in(&mut app, Some(ClothBackend::Gpu)));
}

/// On the GPU too, banners popped in, out and in again by their own scale and their parent's
/// hang still after it (`game`'s `banners_popped_in_and_out_hang_still`, the same bound, read
/// back): the stretch's centre reaches the `teleport` kernel with the carry.
#[test]
fn gpu_banners_popped_in_and_out_hang_still() {
    gpu_banners_popped_in_and_out("gpu_banners_popped_in_and_out_hang_still", 1);
}

/// The same at 12 frames a second (five fixed steps a frame, each with a new rest shape): the
/// GPU solves a frame's steps with the last step's rest shape, so the frame's stretches all
/// apply at its first step. Before, the earlier steps ran the cloth at one size with the rest
/// shape of another.
#[test]
fn gpu_banners_popped_in_and_out_at_12_fps_hang_still() {
    gpu_banners_popped_in_and_out("gpu_banners_popped_in_and_out_at_12_fps_hang_still", 5);
}

/// [`common::banners_popped_in_and_out`] on the GPU, `steps` fixed steps a frame, checked.
fn gpu_banners_popped_in_and_out(test: &str, steps: usize) {
    if common::gpu_or_skip(test).is_none() {
        return;
    }
    let mut app = render_app();
    common::check_banners_popped_in_and_out(common::banners_popped_in_and_out(
        &mut app,
        Some(ClothBackend::Gpu),
        steps,
    ));
}

/// Tethers added to a running GPU cloth settle it as on the CPU (`game`'s
/// `tethers_added_to_a_running_cloth_do_not_fling_it`, the same bound): the new upload
/// carries the settle. Before, its fastest vertex reached 28.5 m/s (2.7 while it fell; 3.7
/// settled).
#[test]
fn tethers_added_to_a_running_gpu_cloth_do_not_fling_it() {
    if common::gpu_or_skip("tethers_added_to_a_running_gpu_cloth_do_not_fling_it").is_none() {
        return;
    }
    let mut app = render_app();
    let (before, after) = common::fastest_before_and_after(
        &mut app,
        Some(ClothBackend::Gpu),
        ClothConfig::default(),
        |e| {
            e.insert(ClothTethers::default());
        },
    );
    eprintln!("{after} m/s after, {before} m/s falling");
    assert!(
        after < 1.5 * before,
        "{after} m/s after, {before} m/s falling"
    );
}

/// A new fixed timestep settles a GPU cloth as on the CPU (`game`'s
/// `a_new_fixed_timestep_settles_running_cloths`, the same bound): the step is part of the
/// GPU cloth's settings, so the change makes an upload that carries the settle.
#[test]
fn a_new_fixed_timestep_settles_running_gpu_cloths() {
    if common::gpu_or_skip("a_new_fixed_timestep_settles_running_gpu_cloths").is_none() {
        return;
    }
    let mut app = render_app();
    let (before, after) = common::fastest_before_and_after(
        &mut app,
        Some(ClothBackend::Gpu),
        ClothConfig::default(),
        |e| {
            e.world_scope(|w| w.resource_mut::<Time<Fixed>>().set_timestep_hz(240.0));
        },
    );
    eprintln!("{after} m/s after, {before} m/s falling");
    assert!(after < before, "{after} m/s after, {before} m/s falling");
}

/// What a game changes at runtime, made to a CPU cloth and a GPU cloth side by side (24²,
/// hung for a second, read back): over the next second the two reach the same fastest speed
/// and the same largest strain, within a quarter and 0.3 m/s (strain: a quarter and 0.02).
/// Measured on llvmpipe: the fastest vertices within 0.02 m/s but after damping and a scale
/// change (0.2: the read-back lags the GPU by a step or two while the speeds decay), strain
/// within 0.015. Physical agreement, not rounding: the trajectories part once rounding
/// differs. A GPU that ignored a change would miss by far more (its unsettled solver switch
/// reached 17.8 m/s against 1.5).
#[test]
fn runtime_changes_move_a_gpu_cloth_as_they_move_its_cpu_twin() {
    if common::gpu_or_skip("runtime_changes_move_a_gpu_cloth_as_they_move_its_cpu_twin").is_none() {
        return;
    }
    type Change = fn(&mut EntityWorldMut);
    let changes: [(&str, Change); 10] = [
        ("gravity ×3", |e| {
            e.get_mut::<ClothConfig>().unwrap().gravity *= 3.0;
        }),
        ("damping 5", |e| {
            e.get_mut::<ClothConfig>().unwrap().damping = 5.0
        }),
        ("speed limit 0.5", |e| {
            e.get_mut::<ClothConfig>().unwrap().max_speed = 0.5;
        }),
        ("2 → 20 substeps", |e| {
            e.get_mut::<ClothConfig>().unwrap().substeps = 20
        }),
        ("mass ×4", |e| e.get_mut::<Cloth>().unwrap().mass *= 4.0),
        ("self-collision", |e| {
            e.insert(ClothSelfCollision::default());
        }),
        ("tethers", |e| {
            e.insert(ClothTethers::default());
        }),
        ("scale ×1.5", |e| {
            e.get_mut::<Transform>().unwrap().scale = Vec3::splat(1.5);
        }),
        ("inertia", |e| {
            e.insert(ClothInertia::new(0.5));
        }),
        ("dihedral bending", |e| {
            e.get_mut::<Cloth>().unwrap().bending_model =
                bevy_cloth::solver::BendingModel::Dihedral;
        }),
    ];
    let mut app = render_app();
    let grid = Grid::new(24, 24, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    for (what, change) in changes {
        let twins = [ClothBackend::Cpu, ClothBackend::Gpu].map(|b| {
            let x = if b == ClothBackend::Cpu { -2.0 } else { 2.0 };
            app.world_mut()
                .spawn((
                    Mesh3d(mesh.clone()),
                    Transform::from_xyz(x, 2.0, 0.0),
                    Cloth::default(),
                    ClothConfig {
                        substeps: if what.starts_with("2 →") { 2 } else { 10 },
                        ..default()
                    },
                    b,
                    ClothReadback,
                    ClothPins::rest([grid.index(0, 0), grid.index(23, 0)]),
                ))
                .id()
        });
        common::run(&mut app, 60);
        for e in twins {
            change(&mut app.world_mut().entity_mut(e));
        }
        // The read-back state of a changed GPU cloth shows the change three frames later (its
        // new upload, then the read-back's lag): from the fourth frame on.
        common::run(&mut app, 3);
        let mut fastest = [0.0f32; 2];
        for _ in 0..60 {
            common::run(&mut app, 1);
            for (k, &e) in twins.iter().enumerate() {
                let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
                let v = (0..s.len())
                    .filter(|&i| s.positions[i].w > 0.0)
                    .map(|i| s.velocity(i).length())
                    .fold(0.0, f32::max);
                fastest[k] = fastest[k].max(v);
            }
        }
        assert!(in_use(&app, twins[1]).gpu, "{what}: it left the GPU");
        let strain = twins.map(|e| app.world().get::<ClothSim>(e).unwrap().max_strain());
        eprintln!("{what}: fastest {fastest:?} m/s, strain {strain:?}");
        let [c, g] = fastest;
        assert!(
            (c - g).abs() <= 0.25 * c.max(g) + 0.3,
            "{what}: fastest {c} m/s on the CPU, {g} on the GPU"
        );
        let [c, g] = strain;
        assert!(
            (c - g).abs() <= 0.25 * c.max(g) + 0.02,
            "{what}: strain {c} on the CPU, {g} on the GPU"
        );
        for e in twins {
            app.world_mut().despawn(e);
        }
        common::run(&mut app, 2);
    }
}

/// `ClothSmoothing` on the GPU: the mesh kernel draws each vertex along its velocity as the
/// CPU's write-back does, so a cape on a character walking at 3 m/s in `FixedUpdate`, frames
/// of 1/144 s over a 60 Hz step, is drawn where the character is drawn interpolated (or
/// extrapolated), within f32 rounding (as `game`'s CPU test: the pin's velocity, 2 ε |x| / h,
/// times a shift of at most a step), glued to the character by `ClothInertia` too (drawn
/// along the carried motion's velocity); as of the last step, up to a step's walk off.
#[test]
fn a_smoothed_gpu_cape_is_drawn_where_its_character_is_drawn() {
    if common::gpu_or_skip("a_smoothed_gpu_cape_is_drawn_where_its_character_is_drawn").is_none() {
        return;
    }
    let rounding = common::smoothing_rounding();
    for (smoothing, want, glued) in [
        (None, None, false),
        (Some(ClothSmoothing::Interpolate), Some(0), false),
        (Some(ClothSmoothing::Extrapolate), Some(1), false),
        (Some(ClothSmoothing::Interpolate), Some(0), true),
    ] {
        let mut app = render_app_with(ClothPlugins::default(), false);
        let cape = common::smoothed_cape(&mut app, smoothing, Some(ClothBackend::Gpu), glued);
        let errors = common::smoothing_errors(&mut app, cape, drawn_on_the_gpu);
        assert!(in_use(&app, cape.0).gpu, "the cape runs on the GPU");
        eprintln!("{smoothing:?}, glued {glued}: {errors:?} m from the drawn character");
        match want {
            None => assert!(
                errors.0 > 0.03 && errors.1 > 0.02,
                "as stepped, the corner is a frame's walk off: {errors:?}"
            ),
            Some(k) => {
                let error = [errors.0, errors.1][k];
                assert!(
                    error < rounding,
                    "{smoothing:?}: the corner is drawn {error} m off"
                );
            }
        }
    }
}

/// The GPU twin of `game`'s test of a cape on a character the game moves in `Update`: with
/// cloth simulated once a frame in `PostUpdate` the GPU cape's pinned corner is drawn on the
/// character in every frame, to within the f32 rounding of positions up to 5 m from the origin
/// (1e-5 m, as there); on the fixed clock it trails by up to a frame's walk.
#[test]
fn a_gpu_cape_on_a_character_moved_in_update_is_drawn_on_it_when_simulated_in_post_update() {
    if common::gpu_or_skip(
        "a_gpu_cape_on_a_character_moved_in_update_is_drawn_on_it_when_simulated_in_post_update",
    )
    .is_none()
    {
        return;
    }
    let mut offs = Vec::new();
    for cloth in [ClothPlugins::new(PostUpdate), ClothPlugins::default()] {
        let mut app = render_app_with(cloth, false);
        let (cape, off) =
            common::cape_moved_in_update(&mut app, Some(ClothBackend::Gpu), drawn_on_the_gpu);
        assert!(in_use(&app, cape).gpu, "the cape runs on the GPU");
        offs.push(off);
    }
    eprintln!(
        "corner off the character: in PostUpdate {} m, fixed {} m",
        offs[0], offs[1]
    );
    assert!(
        offs[0] < 1e-5,
        "in PostUpdate the corner is drawn {} m off",
        offs[0]
    );
    assert!(
        offs[1] > 0.02,
        "on the fixed clock it trails by a frame's walk: {} m",
        offs[1]
    );
}

/// A GPU flag glued to a car by `ClothInertia` meets the car's airflow as on the CPU: its air
/// (uploaded per step) is the wind less the carried motion's velocity. At 20 m/s in still air
/// it streams behind its hoist as the CPU flag does; before, it hung limp.
#[test]
fn a_gpu_flag_glued_to_a_car_by_its_inertia_streams_in_the_cars_airflow() {
    if common::gpu_or_skip("a_gpu_flag_glued_to_a_car_by_its_inertia_streams_in_the_cars_airflow")
        .is_none()
    {
        return;
    }
    let mut app = render_app();
    let gpu = common::flag_on_a_car(&mut app, Some(0.0), Some(ClothBackend::Gpu));
    let mut app = common::app();
    let cpu = common::flag_on_a_car(&mut app, Some(0.0), None);
    eprintln!("fly edge from the hoist: GPU {gpu}, CPU {cpu}");
    assert!(
        gpu.x < -0.5 && gpu.y > -0.15,
        "the GPU flag does not stream: {gpu}"
    );
    assert!(
        gpu.distance(cpu) < 0.1,
        "the GPU flag streams unlike the CPU's: {gpu} against {cpu}"
    );
}

/// A triangle-strip mesh on the GPU: read as the list of its triangles, its own copy drawn as
/// that list (16-bit indices kept), it runs on the GPU and hangs exactly as the same
/// triangles given as a list beside it in the same world (their vertex slabs equal).
#[test]
fn a_triangle_strip_mesh_runs_on_the_gpu_as_its_list() {
    use bevy::asset::RenderAssetUsages;
    use bevy::mesh::{Indices, PrimitiveTopology};
    if common::gpu_or_skip("a_triangle_strip_mesh_runs_on_the_gpu_as_its_list").is_none() {
        return;
    }
    let (cols, rows) = (9u32, 7u32);
    let (grid, positions, strip, list) = common::strip_grid(cols, rows);
    let list: Vec<u16> = list.iter().map(|&v| v as u16).collect();
    let mut app = render_app_with(ClothPlugins::default(), false);
    let mut spawn = |topology, indices: Vec<u16>| {
        let mesh = Mesh::new(topology, RenderAssetUsages::default())
            .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions.clone())
            .with_inserted_indices(Indices::U16(indices));
        let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
        app.world_mut()
            .spawn((
                Mesh3d(mesh),
                Transform::from_xyz(0.0, 2.0, 0.0),
                Cloth::default(),
                ClothPins::rest([grid.index(0, 0), grid.index(cols - 1, 0)]),
                ClothBackend::Gpu,
            ))
            .id()
    };
    let strip_cloth = spawn(PrimitiveTopology::TriangleStrip, strip);
    let list_cloth = spawn(PrimitiveTopology::TriangleList, list);
    common::run(&mut app, 60);
    assert!(in_use(&app, strip_cloth).gpu, "the strip runs on the GPU");
    let drawn = |e: Entity| {
        let handle = app.world().get::<Mesh3d>(e).unwrap().0.clone();
        let layout = app.world().resource::<Assets<Mesh>>().get(&handle).unwrap();
        assert_eq!(layout.primitive_topology(), PrimitiveTopology::TriangleList);
        positions_on_the_gpu(&app, handle.id(), layout).expect("on the GPU")
    };
    let (a, b) = (drawn(strip_cloth), drawn(list_cloth));
    assert_eq!(a, b, "the strip hangs as the list does");
    assert!(
        a[grid.index(4, 6) as usize].y < -0.3,
        "and it hangs (local y)"
    );
}

/// A Bevy `Plane3d` painted at two corners and pinned there by a `ClothPinRule` runs on the
/// GPU (its own mesh without the paint) and hangs exactly as the same plane, unpainted, pinned
/// by a hand-written list beside it (their vertex slabs equal).
#[test]
fn a_painted_pin_rule_runs_on_the_gpu_as_the_same_pins_by_hand() {
    if common::gpu_or_skip("a_painted_pin_rule_runs_on_the_gpu_as_the_same_pins_by_hand").is_none()
    {
        return;
    }
    let plane = common::bevy_plane();
    let corners = common::vertices_where(&plane, |p| p.z == -0.5 && p.x.abs() == 0.5);
    assert_eq!(corners.len(), 2);
    let painted = common::painted(plane.clone(), &corners);
    let mut app = render_app_with(ClothPlugins::default(), false);
    let mut spawn = |mesh: Mesh, pins: Option<ClothPins>| {
        let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
        let mut e = app.world_mut().spawn((
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 2.0, 0.0),
            Cloth::default(),
            ClothBackend::Gpu,
        ));
        match pins {
            Some(pins) => e.insert(pins),
            None => e.insert(ClothPinRule::rest(VertexSelection::Painted {
                channel: ColorChannel::Red,
                at_least: 0.5,
            })),
        };
        e.id()
    };
    let by_rule = spawn(painted, None);
    let by_hand = spawn(plane, Some(ClothPins::rest(corners.clone())));
    common::run(&mut app, 60);
    assert!(in_use(&app, by_rule).gpu, "the ruled cloth runs on the GPU");
    assert_eq!(
        app.world().get::<ClothPins>(by_rule),
        Some(&ClothPins::rest(corners.clone()))
    );
    let drawn = |e: Entity| {
        let handle = app.world().get::<Mesh3d>(e).unwrap().0.clone();
        let layout = app.world().resource::<Assets<Mesh>>().get(&handle).unwrap();
        assert!(
            layout.attribute(Mesh::ATTRIBUTE_COLOR).is_none(),
            "no paint drawn"
        );
        positions_on_the_gpu(&app, handle.id(), layout).expect("on the GPU")
    };
    let (a, b) = (drawn(by_rule), drawn(by_hand));
    assert_eq!(a, b, "the rule pins what the list pins");
    // Held at its two corners (local y 0), the rest hangs.
    for &c in &corners {
        assert_eq!(a[c as usize].y, 0.0);
    }
    let lowest = a.iter().map(|v| v.y).fold(f32::MAX, f32::min);
    assert!(lowest < -0.3, "it hangs (lowest local y {lowest})");
}

/// A GPU that binds buffers of at most 1 MiB and dispatches at most eight workgroups a
/// dimension (a game sets such limits with `WgpuSettings::constrained_limits`; WebGPU's are
/// 128 MiB and 65 535, which cloths of a million vertices pass): a cloth too large for it
/// runs on the CPU and says why, two cloths that each fit but not together run in two
/// worlds, and a tearing cloth and the mesh writes run with every dispatch split (wgpu's
/// validation would fail an unsplit one, and the renderer would quit the app). Before, a
/// cloth too large for the adapter's buffers stayed "on the GPU", never moved, and quit the
/// app with a validation error.
#[test]
fn a_gpu_too_small_for_a_cloth_runs_it_on_the_cpu_and_the_rest_in_worlds_that_fit() {
    let test = "a_gpu_too_small_for_a_cloth_runs_it_on_the_cpu_and_the_rest_in_worlds_that_fit";
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 1 << 20,
        max_compute_workgroups_per_dimension: 8,
        ..wgpu::Limits::default()
    };
    let Some((_, device, queue, kernels)) =
        common::gpu_kernels_with_limits_or_skip(test, limits.clone())
    else {
        return;
    };
    let mut app = render_app_limited(ClothPlugins::default(), false, false, Some(limits));
    let extra = (ClothBackend::Gpu, ClothReadback);
    let a = common::hung_grid(&mut app, 64, false, extra);
    let b = common::hung_grid(&mut app, 64, false, extra);
    let big = common::hung_grid(&mut app, 110, false, extra);
    let torn = common::hung_grid(&mut app, 24, false, (extra, ClothTearing::default()));
    common::run(&mut app, 2);
    // What the device holds, by the public world API on a device with the same limits.
    let sim = |e: Entity| app.world().get::<ClothSim>(e).unwrap().simulation().clone();
    let (sa, sb, sbig) = (sim(a), sim(b), sim(big));
    let fits = |sims: &[&bevy_cloth::solver::Simulation]| {
        bevy_cloth::gpu::GpuWorld::new(&device, &queue, &kernels, sims).is_ok()
    };
    assert!(fits(&[&sa]) && fits(&[&sb]), "each 64² cloth fits alone");
    assert!(
        !fits(&[&sa, &sb]),
        "the two 64² cloths do not fit one world"
    );
    assert!(!fits(&[&sbig]), "the 110² cloth does not fit");
    let heights = |app: &App| -> Vec<f32> {
        [a, b, big, torn]
            .iter()
            .map(|&e| {
                let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
                (0..s.len()).map(|i| s.position(i).y).sum::<f32>() / s.len() as f32
            })
            .collect()
    };
    let before = heights(&app);
    common::run(&mut app, 40);
    assert!(app.should_exit().is_none(), "the renderer quit the app");
    for (e, what) in [
        (a, "the first 64² cloth"),
        (b, "the second"),
        (torn, "the tearing cloth"),
    ] {
        let u = in_use(&app, e);
        assert!(u.gpu, "{what}: {u:?}");
    }
    on_the_cpu_because(&app, big, "too large for this GPU", 10);
    let after = heights(&app);
    for (i, what) in ["first 64²", "second 64²", "110² (CPU)", "tearing"]
        .iter()
        .enumerate()
    {
        eprintln!("{what}: mean height {} -> {}", before[i], after[i]);
        assert!(
            after[i].is_finite() && after[i] < before[i] - 0.01,
            "the {what} cloth did not fall: {} -> {}",
            before[i],
            after[i]
        );
    }
}
