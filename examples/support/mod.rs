//! Shared by the examples: command-line flags, headless or windowed apps, the final JSON line.
//!
//! Every example accepts `--headless` (no window, no GPU: `MinimalPlugins`, frames of the fixed
//! time step), `--frames N` (stop after N frames; windowed runs otherwise go on until closed)
//! and, windowed, `--screenshot FILE.png` (save the window after `--frames` frames, default 240,
//! or once the fixed clock passes `--at SECONDS`, then exit); it ends by printing one JSON line
//! of measurements.

#![allow(dead_code, reason = "each example uses a different part")]

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use bevy::app::AppExit;
use bevy::mesh::MeshPlugin;
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured, save_to_disk};
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;

/// This module's source: the flags every example reads (`--headless`, `--frames`,
/// `--backend`, `--screenshot`, `--at`) are among its quoted words.
const SUPPORT: &str = include_str!("mod.rs");

/// Prints the leading `//!` lines of an example's source, and the flags every example takes.
fn print_help(source: &str) {
    for line in source.lines() {
        let Some(doc) = line.strip_prefix("//!") else {
            break;
        };
        println!("{}", doc.strip_prefix(' ').unwrap_or(doc));
    }
    println!();
    for line in SUPPORT.lines() {
        let Some(doc) = line.strip_prefix("//!") else {
            break;
        };
        println!("{}", doc.strip_prefix(' ').unwrap_or(doc));
    }
}

/// Parsed command line.
#[derive(Clone, Debug, Default)]
pub struct Args {
    /// `--headless`.
    pub headless: bool,
    /// `--frames N`.
    pub frames: Option<u32>,
    /// Every other `--key value` (or `--flag` → `"true"`).
    pub rest: BTreeMap<String, String>,
}

impl Args {
    /// Reads `std::env::args` for the example whose source is `source` (`include_str!` of its
    /// file): `--help` prints the example's `//!` documentation and exits; a flag that neither
    /// the example nor this module reads is refused (exit code 2), so a mistyped one is not
    /// silently ignored.
    pub fn parse(source: &str) -> Self {
        let mut out = Args::default();
        let mut it = std::env::args().skip(1).peekable();
        while let Some(a) = it.next() {
            if a == "--help" || a == "-h" {
                print_help(source);
                std::process::exit(0);
            }
            let Some(key) = a.strip_prefix("--") else {
                eprintln!("ignoring argument {a:?} (flags start with --; --help lists them)");
                continue;
            };
            let quoted = format!("\"{key}\"");
            if !source.contains(&quoted) && !SUPPORT.contains(&quoted) {
                eprintln!("--{key}: not a flag of this example (--help lists them)");
                std::process::exit(2);
            }
            let value = match it.peek() {
                Some(v) if !v.starts_with("--") => it.next().unwrap(),
                _ => "true".to_string(),
            };
            match key {
                "headless" => out.headless = value == "true",
                "frames" => {
                    out.frames = Some(value.parse().unwrap_or_else(|_| {
                        eprintln!("--frames needs a number, got {value:?}");
                        std::process::exit(2)
                    }))
                }
                _ => {
                    out.rest.insert(key.to_string(), value);
                }
            }
        }
        out
    }

    /// `--backend cpu|gpu|auto` (default cpu).
    pub fn backend(&self) -> ClothBackend {
        match self.rest.get("backend").map(String::as_str) {
            None | Some("cpu") => ClothBackend::Cpu,
            Some("gpu") => ClothBackend::Gpu,
            Some("auto") => ClothBackend::Auto,
            Some(other) => {
                eprintln!("--backend: expected cpu, gpu or auto, got {other:?}");
                std::process::exit(2)
            }
        }
    }

    /// A `--key value` parsed as `T`, or `default`.
    pub fn get<T: std::str::FromStr>(&self, key: &str, default: T) -> T {
        match self.rest.get(key) {
            None => default,
            Some(v) => v.parse().unwrap_or_else(|_| {
                eprintln!("--{key}: cannot parse {v:?}");
                std::process::exit(2)
            }),
        }
    }
}

/// One JSON object, written by hand (flat, numbers and strings only).
#[derive(Default)]
pub struct Json(Vec<(String, String)>);

impl Json {
    /// Adds a number (NaN and infinities become `null`).
    pub fn num(mut self, k: &str, v: impl Into<f64>) -> Self {
        let v: f64 = v.into();
        let s = if v.is_finite() {
            format!("{v}")
        } else {
            "null".to_string()
        };
        self.0.push((k.to_string(), s));
        self
    }

    /// Adds a number measured from the cloths' state, or `null` when some GPU cloth's state
    /// is not read back (`unread`, see [`gpu_state_unread`]): the figure would describe the
    /// state the cloth started from.
    pub fn measured(self, k: &str, v: impl Into<f64>, unread: bool) -> Self {
        self.num(k, if unread { f64::NAN } else { v.into() })
    }

    /// Adds a string.
    pub fn str(mut self, k: &str, v: &str) -> Self {
        self.0.push((k.to_string(), format!("{v:?}")));
        self
    }
}

impl core::fmt::Display for Json {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{{")?;
        for (i, (k, v)) in self.0.iter().enumerate() {
            if i > 0 {
                write!(f, ",")?;
            }
            write!(f, "{k:?}:{v}")?;
        }
        write!(f, "}}")
    }
}

/// Wall time spent in the cloth systems, frame by frame.
#[derive(Resource, Default)]
pub struct ClothTiming {
    start: Option<Instant>,
    /// Simulation time per rendered frame (sum over that frame's fixed steps).
    pub per_frame: Vec<Duration>,
    current: Duration,
}

fn timing_start(mut t: ResMut<ClothTiming>) {
    t.start = Some(Instant::now());
}

fn timing_stop(mut t: ResMut<ClothTiming>) {
    if let Some(s) = t.start.take() {
        t.current += s.elapsed();
    }
}

fn timing_frame(mut t: ResMut<ClothTiming>) {
    let c = core::mem::take(&mut t.current);
    t.per_frame.push(c);
}

/// Assets from this crate's `assets/` folder, however the example binary is started.
fn assets() -> AssetPlugin {
    AssetPlugin {
        file_path: concat!(env!("CARGO_MANIFEST_DIR"), "/assets").into(),
        ..default()
    }
}

/// The app every example starts from: a window with `DefaultPlugins`, or with `--headless`
/// `MinimalPlugins` plus transforms, assets and meshes, stepping one fixed step per frame.
pub fn app(args: &Args, title: &str, fixed_step: f64) -> App {
    app_simulating_in(args, title, fixed_step, FixedPostUpdate)
}

/// [`app`] with cloth simulated in `schedule` (`ClothPlugins::new(schedule)`).
pub fn app_simulating_in(
    args: &Args,
    title: &str,
    fixed_step: f64,
    schedule: impl bevy::ecs::schedule::ScheduleLabel + Clone,
) -> App {
    let mut app = App::new();
    let backend = args.backend();
    if args.headless && backend != ClothBackend::Cpu {
        // The GPU backend needs a renderer: every default plugin but the window.
        app.add_plugins(
            DefaultPlugins
                .build()
                .disable::<bevy::winit::WinitPlugin>()
                .set(WindowPlugin {
                    primary_window: None,
                    exit_condition: bevy::window::ExitCondition::DontExit,
                    ..default()
                })
                .set(assets()),
        )
        .add_plugins(bevy::app::ScheduleRunnerPlugin::run_loop(Duration::ZERO))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
            fixed_step,
        )))
        // The report reads GPU cloths' state back.
        .add_systems(Update, read_back_cloths);
    } else if args.headless {
        // Logs too, so that what the plugin reports (an invalid cloth) shows.
        app.add_plugins((
            MinimalPlugins,
            bevy::log::LogPlugin::default(),
            TransformPlugin,
            assets(),
            MeshPlugin,
        ))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
            fixed_step,
        )));
    } else {
        app.add_plugins(
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: Some(Window {
                        title: title.into(),
                        ..default()
                    }),
                    ..default()
                })
                .set(assets()),
        )
        .add_plugins((VelvetPlugin, ClothCameraPlugin))
        .add_systems(Update, dress_cloths);
    }
    app.add_plugins(ClothPlugins::new(schedule.clone()).set(ClothGpuPlugin {
        default_backend: backend,
    }))
    .insert_resource(Time::<Fixed>::from_seconds(fixed_step))
    .init_resource::<ClothTiming>()
    .add_systems(
        schedule,
        (
            timing_start.before(ClothSystems::Prepare),
            timing_stop.after(ClothSystems::Simulate),
        ),
    )
    .add_systems(Last, timing_frame);
    app
}

/// Headless runs on a renderer: every cloth's GPU state comes back for the report.
fn read_back_cloths(
    mut commands: Commands,
    cloths: Query<Entity, (With<Cloth>, Without<ClothReadback>)>,
) {
    for e in &cloths {
        commands.entity(e).insert(ClothReadback);
    }
}

/// Whether some cloth runs on the GPU without reading its state back (a window): its
/// `ClothSim` then holds the starting state, and figures measured from it mean nothing.
pub fn gpu_state_unread(world: &mut World) -> bool {
    let mut q = world.query::<(Option<&ClothBackendInUse>, Has<ClothReadback>)>();
    q.iter(world)
        .any(|(backend, read_back)| backend.is_some_and(|b| b.gpu) && !read_back)
}

/// What every example reports about its cloths.
pub fn cloth_report(world: &mut World) -> Json {
    let mut q = world.query::<(&ClothSim, Option<&ClothBackendInUse>, Has<ClothReadback>)>();
    let (mut vertices, mut max_strain, mut nan, mut steps) = (0usize, 0.0f32, 0usize, 0u64);
    let mut gpu = 0;
    for (c, backend, read_back) in q.iter(world) {
        if backend.is_some_and(|b| b.gpu) {
            gpu += 1;
            if !read_back {
                // Its results stay on the GPU: the main world has its starting state only.
                continue;
            }
        }
        let s = c.simulation();
        vertices += s.state().len();
        max_strain = max_strain.max(s.strain().max);
        nan += s.state().non_finite_count();
        steps = steps.max(c.steps());
    }
    let t = world.resource::<ClothTiming>();
    let frames = t.per_frame.len();
    let mut ms: Vec<f64> = t
        .per_frame
        .iter()
        .skip(frames.min(5))
        .map(|d| d.as_secs_f64() * 1e3)
        .collect();
    ms.sort_by(f64::total_cmp);
    let median = ms.get(ms.len() / 2).copied().unwrap_or(0.0);
    Json::default()
        .num("frames", frames as f64)
        .num("steps", steps as f64)
        .num("vertices", vertices as f64)
        .num("max_strain", max_strain)
        .num("nan_count", nan as f64)
        .num("ms_per_frame", median)
        .num("gpu_cloths", gpu as f64)
        .str("backend", if gpu > 0 { "gpu" } else { "cpu" })
}

/// Headless runs first update the app until this returns true (assets loaded), then run
/// their `--frames`.
#[derive(Resource)]
pub struct WaitUntil(pub fn(&World) -> bool);

/// Runs the app: `--frames N` frames (headless: driven here; windowed: then exits), then prints
/// `report(world)` as one JSON line.
pub fn run(mut app: App, args: &Args, report: fn(&mut World) -> Json) {
    if args.headless {
        let frames = args.frames.unwrap_or(300);
        // A renderer (the GPU backend) finishes setting up on other threads.
        while app.plugins_state() == bevy::app::PluginsState::Adding {
            bevy::tasks::tick_global_task_pools_on_main_thread();
        }
        app.finish();
        app.cleanup();
        // Assets load on other threads: wait (at most 30 s) until the example says it is ready.
        if let Some(ready) = app.world().get_resource::<WaitUntil>().map(|w| w.0) {
            let start = Instant::now();
            while !ready(app.world()) && start.elapsed() < Duration::from_secs(30) {
                app.update();
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        // With a renderer and no window nothing paces the frames: wait for the GPU after
        // each one, so the GPU cloths' steps keep up and the report reads recent states.
        let device = app
            .get_sub_app(bevy::render::RenderApp)
            .and_then(|r| {
                r.world()
                    .get_resource::<bevy::render::renderer::RenderDevice>()
            })
            .cloned();
        for _ in 0..frames {
            app.update();
            if let Some(device) = &device {
                let _ = device
                    .wgpu_device()
                    .poll(wgpu::PollType::wait_indefinitely());
            }
        }
        println!("{}", report(app.world_mut()));
        return;
    }
    #[derive(Resource)]
    struct Limit {
        frames: Option<u32>,
        /// Fixed-clock seconds after which to stop (the same moment however slow the frames).
        at: Option<f64>,
        report: fn(&mut World) -> Json,
        screenshot: Option<String>,
        requested: bool,
    }
    #[derive(Resource, Default)]
    struct ShotSaved(bool);
    fn stop(world: &mut World) {
        let frames = world.resource::<ClothTiming>().per_frame.len() as u32;
        let limit = world.resource::<Limit>();
        let clock = world.resource::<Time<Fixed>>().elapsed_secs_f64();
        let due = limit.frames.is_some_and(|m| frames >= m) || limit.at.is_some_and(|t| clock >= t);
        let (report, shot, requested) = (limit.report, limit.screenshot.clone(), limit.requested);
        if !due {
            return;
        }
        if let Some(path) = shot {
            // Shoot once, then wait for the file before leaving.
            if !requested {
                world.resource_mut::<Limit>().requested = true;
                world
                    .spawn(Screenshot::primary_window())
                    .observe(save_to_disk(path))
                    .observe(|_: On<ScreenshotCaptured>, mut saved: ResMut<ShotSaved>| {
                        saved.0 = true;
                    });
                return;
            }
            if !world.resource::<ShotSaved>().0 {
                return;
            }
        }
        println!("{}", report(world));
        world.write_message(AppExit::Success);
    }
    let screenshot = args.rest.get("screenshot").cloned();
    let at = args.rest.contains_key("at").then(|| args.get("at", 0.0f64));
    let frames = args
        .frames
        .or(screenshot.as_ref().filter(|_| at.is_none()).map(|_| 240));
    app.insert_resource(Limit {
        frames,
        at,
        report,
        screenshot,
        requested: false,
    })
    .init_resource::<ShotSaved>()
    .add_systems(Last, stop.after(timing_frame));
    app.run();
}

/// A camera (right mouse to look, WASD/QE to fly: `ClothFlyCamera`), a sun with shadows,
/// and a ground plane.
pub fn stage(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    eye: Vec3,
    target: Vec3,
) {
    commands.spawn((
        Camera3d::default(),
        Transform::from_translation(eye).looking_at(target, Vec3::Y),
        ClothFlyCamera::default(),
    ));
    commands.spawn((
        DirectionalLight {
            illuminance: 8_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(3.0, 8.0, 5.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    commands.insert_resource(GlobalAmbientLight {
        brightness: 300.0,
        ..default()
    });
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(30.0, 30.0))),
        MeshMaterial3d(materials.add(Color::srgb(0.35, 0.37, 0.33))),
    ));
}

/// Deepest penetration (metres) of any cloth vertex below any collider's surface this step.
pub fn max_penetration(world: &mut World) -> f32 {
    let colliders = world
        .resource::<bevy_cloth::collider::ClothColliders>()
        .clone();
    let mut q = world.query::<&ClothSim>();
    let mut worst = 0.0f32;
    for c in q.iter(world) {
        let s = c.simulation().state();
        for collider in &colliders.colliders {
            for i in 0..s.len() {
                let local = collider.end.inverse_apply(s.position(i));
                let d = collider.shape.distance(local).0 * collider.end.scale;
                worst = worst.max(-d);
            }
        }
    }
    worst
}

/// How the examples dress a cloth: velvet in this colour on the front, a paler lining on the
/// back (windowed runs; headless runs ignore it).
#[derive(Component, Clone, Copy, Debug)]
pub struct ClothLook(pub Color);

fn dress_cloths(
    mut commands: Commands,
    looks: Query<(Entity, &ClothLook), Without<MeshMaterial3d<VelvetMaterial>>>,
    materials: Option<ResMut<Assets<VelvetMaterial>>>,
) {
    let Some(mut materials) = materials else {
        return;
    };
    for (entity, look) in &looks {
        commands
            .entity(entity)
            .insert(MeshMaterial3d(materials.add(lined_velvet(look.0))));
    }
}

/// What loading glTF scenes (and their animations) needs that a headless CPU app, built on
/// `MinimalPlugins`, lacks; a windowed or GPU app has it from `DefaultPlugins` already.
pub fn add_gltf_support(app: &mut App) {
    if !app.is_plugin_added::<bevy::image::ImagePlugin>() {
        app.add_plugins(bevy::image::ImagePlugin::default());
    }
    if !app.is_plugin_added::<bevy::world_serialization::WorldSerializationPlugin>() {
        app.add_plugins(bevy::world_serialization::WorldSerializationPlugin);
    }
    if !app.is_plugin_added::<bevy::gltf::GltfPlugin>() {
        // No renderer, so no GPU to ask which compressed textures it reads: none.
        use bevy::image::{CompressedImageFormatSupport, CompressedImageFormats};
        app.insert_resource(CompressedImageFormatSupport(CompressedImageFormats::NONE))
            .add_plugins(bevy::gltf::GltfPlugin::default());
    }
    if !app.is_plugin_added::<bevy::animation::AnimationPlugin>() {
        app.add_plugins(bevy::animation::AnimationPlugin);
    }
}
