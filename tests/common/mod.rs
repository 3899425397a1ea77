//! Helpers shared by the integration tests (each test file uses some of them).
#![allow(dead_code)]

use std::time::Duration;

use bevy::mesh::MeshPlugin;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::gpu::{GpuFrame, GpuKernels, GpuWorld};
use bevy_cloth::prelude::*;
use bevy_cloth::solver::{Topology, TopologyOptions};

/// A headless app (no window, no GPU) with the cloth plugins, a 60 Hz fixed step and frames
/// of `frame` each.
pub fn app_with_frame(frame: Duration) -> App {
    app_in(ClothPlugins::default(), frame)
}

/// [`app_with_frame`] with `cloth` (e.g. `ClothPlugins::new(PostUpdate)`) for the plugins.
pub fn app_in(cloth: ClothPlugins, frame: Duration) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        AssetPlugin::default(),
        MeshPlugin,
        cloth,
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

/// Drops a 1.6 m, 24 × 24 cloth placed by `drop` onto ground whose height is `ground(x, z)`
/// in the frame of a terrain placed at `at`, and asserts that after four seconds it lies on
/// it: no vertex under the ground (the collider's thickness keeps them a little over it, and
/// the baked field blurs these slopes by far less than a centimetre), none left in the air.
pub fn assert_lies_on_the_ground(
    app: &mut App,
    at: Vec3,
    ground: impl Fn(f32, f32) -> f32,
    drop: Transform,
) {
    let grid = Grid::new(24, 24, 1.6, 1.6);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let cloth = app
        .world_mut()
        .spawn((Mesh3d(mesh), drop, Cloth::default()))
        .id();
    run(app, 240);
    let s = app
        .world()
        .get::<ClothSim>(cloth)
        .unwrap()
        .simulation()
        .state();
    let (mut lowest, mut highest) = (f32::MAX, f32::MIN);
    for i in 0..s.len() {
        let p = s.position(i) - at;
        let over = p.y - ground(p.x, p.z);
        lowest = lowest.min(over);
        highest = highest.max(over);
    }
    assert!(lowest > -0.005, "a vertex {lowest} m under the ground");
    assert!(
        highest < 0.1,
        "a vertex {highest} m over the ground after 4 s"
    );
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
///
/// Every call shares one wgpu instance, kept for the whole test process: an instance per call
/// made NVIDIA's Linux driver (580) load and unload its libraries each time, and after about
/// thirty times in one process it could not be loaded any more (the plugin keeps its
/// renderer's instance for the same reason: `gpu::plugin`'s `keep_graphics_driver_loaded`).
pub fn gpu_or_skip(test: &str) -> Option<(wgpu::Adapter, wgpu::Device, wgpu::Queue)> {
    gpu_with_limits_or_skip(test, wgpu::Limits::default())
}

/// [`gpu_or_skip`] with a device that allows no more than `limits` (each at most what the
/// adapter has).
pub fn gpu_with_limits_or_skip(
    test: &str,
    limits: wgpu::Limits,
) -> Option<(wgpu::Adapter, wgpu::Device, wgpu::Queue)> {
    static INSTANCE: std::sync::OnceLock<wgpu::Instance> = std::sync::OnceLock::new();
    let instance = INSTANCE.get_or_init(|| {
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
    });
    let found =
        bevy::tasks::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .map_err(|e| e.to_string())
            .and_then(|adapter| {
                let descriptor = wgpu::DeviceDescriptor {
                    required_limits: limits,
                    ..Default::default()
                };
                bevy::tasks::block_on(adapter.request_device(&descriptor))
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

/// [`gpu_or_skip`] with the GPU backend's kernels built for the device (checked against its
/// limits first).
pub fn gpu_kernels_or_skip(
    test: &str,
) -> Option<(wgpu::Adapter, wgpu::Device, wgpu::Queue, GpuKernels)> {
    gpu_kernels_with_limits_or_skip(test, wgpu::Limits::default())
}

/// [`gpu_kernels_or_skip`] on a device that allows no more than `limits`.
pub fn gpu_kernels_with_limits_or_skip(
    test: &str,
    limits: wgpu::Limits,
) -> Option<(wgpu::Adapter, wgpu::Device, wgpu::Queue, GpuKernels)> {
    let (adapter, device, queue) = gpu_with_limits_or_skip(test, limits)?;
    GpuKernels::check_limits(&device.limits()).expect("the adapter has the limits");
    let kernels = GpuKernels::new(&device);
    Some((adapter, device, queue, kernels))
}

/// Runs one frame of `world` on the GPU: prepares `frame`, records the world's passes and
/// submits them.
pub fn run_gpu_frame(
    world: &mut GpuWorld,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    kernels: &GpuKernels,
    frame: &GpuFrame,
) {
    world.prepare(device, queue, kernels, frame);
    let mut encoder = device.create_command_encoder(&Default::default());
    world.record(&mut encoder, kernels);
    queue.submit([encoder.finish()]);
}

/// A character (a root with a bone child) wearing a cape: a child of the root pinned along
/// its top edge to the bone (every other vertex `PinAnchor::Entity`, the rest `Attached`),
/// its inertia relative to the bone. Returns (root, bone, cape, top edge).
pub fn caped_character(app: &mut App) -> (Entity, Entity, Entity, Vec<u32>) {
    let grid = Grid::new(8, 8, 0.5, 0.5);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let root = app.world_mut().spawn(Transform::default()).id();
    let bone = app
        .world_mut()
        .spawn((Transform::from_xyz(0.0, 1.5, 0.0), ChildOf(root)))
        .id();
    let top: Vec<u32> = (0..8).map(|i| grid.index(i, 0)).collect();
    let rest = grid.positions();
    let pins = top
        .iter()
        .map(|&v| ClothPin {
            vertex: v,
            anchor: if v % 2 == 0 {
                PinAnchor::Entity {
                    entity: bone,
                    offset: rest[v as usize],
                }
            } else {
                PinAnchor::Attached(bone)
            },
        })
        .collect();
    let cape = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 1.5, 0.0),
            Cloth::default(),
            ClothPins(pins),
            ClothInertia::new(0.5).relative_to(bone),
            ChildOf(root),
        ))
        .id();
    (root, bone, cape, top)
}

/// Mean position of `vertices` of cloth `e`.
pub fn mean_of(app: &App, e: Entity, vertices: &[u32]) -> Vec3 {
    let sim = app
        .world()
        .get::<ClothSim>(e)
        .expect("cloth was not created");
    let s = sim.simulation().state();
    vertices
        .iter()
        .map(|&v| s.position(sim.particle(v) as usize))
        .sum::<Vec3>()
        / vertices.len() as f32
}

/// Moves `root` 2 cm along x a frame for 60 frames (1.18 m in all).
pub fn walk_away(app: &mut App, root: Entity) {
    let start = app.world().get::<Transform>(root).unwrap().translation.x;
    for f in 1..60 {
        app.world_mut()
            .get_mut::<Transform>(root)
            .unwrap()
            .translation
            .x = start + 0.02 * f as f32;
        app.update();
    }
}

/// Clones `root` with its children (Bevy's linked cloning, as a game copies a character with
/// its hierarchy) and runs a frame; returns the copy and its child that is a cloth.
pub fn clone_with_children(app: &mut App, root: Entity) -> (Entity, Entity) {
    let twin = app
        .world_mut()
        .entity_mut(root)
        .clone_and_spawn_with_opt_out(|b| {
            b.linked_cloning(true);
        });
    app.update();
    let cloth = app
        .world()
        .get::<Children>(twin)
        .expect("the children were cloned")
        .iter()
        .find(|&c| app.world().get::<Cloth>(c).is_some())
        .expect("the cloth was cloned with its parent");
    (twin, cloth)
}

/// Three 16² one-metre cloths hanging from two corners, side by side: one at scale 1, one
/// spawned at scale 0 that grows to 1 over 30 frames (a pop-in), one at scale 1 that grows to
/// 2 meanwhile; on `backend` (none: the default), read back. Returns them after 150 frames.
pub fn scaled_cloths(app: &mut App, backend: Option<ClothBackend>) -> [Entity; 3] {
    let tweens = [(1.0, 1.0), (0.0, 1.0), (1.0, 2.0)];
    let cloths = hanging_at_scales(app, 16, tweens.map(|(from, _)| from), backend);
    app.update();
    for f in 1..=30 {
        let t = f as f32 / 30.0;
        for (e, (from, to)) in cloths.iter().zip(tweens) {
            app.world_mut().get_mut::<Transform>(*e).unwrap().scale =
                Vec3::splat(from + (to - from) * t);
        }
        app.update();
    }
    run(app, 119);
    cloths
}

/// One-metre n² cloths hanging from two corners, 4 m apart, one at each of `scales`, on
/// `backend` (none: the default), read back.
fn hanging_at_scales<const N: usize>(
    app: &mut App,
    n: u32,
    scales: [f32; N],
    backend: Option<ClothBackend>,
) -> [Entity; N] {
    let grid = Grid::new(n, n, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    scales.map(|scale| {
        let x = 4.0 * app.world().entities().len() as f32;
        let mut e = app.world_mut().spawn((
            Mesh3d(mesh.clone()),
            Transform::from_xyz(x, 2.0, 0.0).with_scale(Vec3::splat(scale)),
            Cloth::default(),
            ClothPins::rest([grid.index(0, 0), grid.index(n - 1, 0)]),
            ClothReadback,
        ));
        if let Some(b) = backend {
            e.insert(b);
        }
        e.id()
    })
}

/// Checks [`popped_in`]: the popped-in cloth is no faster than twice the one spawned at
/// scale 1 and has not gone through itself.
pub fn check_popped_in([(plain, _), (popped, crossings)]: [(f32, usize); 2]) {
    println!(
        "fastest: spawned at scale 1 {plain} m/s, popped in {popped} m/s; {crossings} crossing pairs"
    );
    assert!(
        popped <= 2.0 * plain,
        "popped in {popped} m/s against {plain}"
    );
    assert_eq!(crossings, 0, "popped in through itself");
}

/// Checks [`scaled_cloths`]: each one's rest shape is the mesh at its entity's scale (mean
/// rest edge as the unscaled one's times the scale, to f32 rounding), it hangs as wide as its
/// pins are apart and no more stretched than a cloth falls (the unscaled one's strain, at
/// most 0.084, against a bound of 0.25; before the rest shape followed the scale, the pop-in
/// ended at 10 915 % strain and the grown one at 272 %).
pub fn check_scaled_cloths(app: &App, [plain, popped, grown]: [Entity; 3]) {
    let sim = |e: Entity| app.world().get::<ClothSim>(e).expect("built");
    let edge = sim(plain).simulation().topology().mean_rest_edge();
    assert_eq!(
        sim(plain).reshape_count(),
        0,
        "an unscaled cloth keeps its shape"
    );
    for (e, scale) in [(plain, 1.0), (popped, 1.0), (grown, 2.0)] {
        let s = sim(e);
        let rest = s.simulation().topology().mean_rest_edge();
        assert!(
            (rest - scale * edge).abs() <= 1e-5 * scale * edge,
            "scale {scale}: mean rest edge {rest} against {}",
            scale * edge
        );
        let state = s.simulation().state();
        let xs = (0..state.len()).map(|i| state.position(i).x);
        let (lo, hi) = xs.fold((f32::MAX, f32::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)));
        assert!(
            ((hi - lo) - scale).abs() < 0.03 * scale,
            "scale {scale}: {} m wide",
            hi - lo
        );
        assert!(
            s.max_strain() < 0.25,
            "scale {scale}: {} strain",
            s.max_strain()
        );
    }
}

/// The fastest vertex of a 24² cloth hanging from two corners (with `config`, on `backend`,
/// read back) while it falls for two seconds, and in the second after `change` was made to
/// its entity.
pub fn fastest_before_and_after(
    app: &mut App,
    backend: Option<ClothBackend>,
    config: ClothConfig,
    change: impl Fn(&mut EntityWorldMut),
) -> (f32, f32) {
    let fastest = |app: &App, e: Entity| -> f32 {
        let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
        (0..s.len())
            .map(|i| s.velocity(i).length())
            .fold(0.0, f32::max)
    };
    let grid = Grid::new(24, 24, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let mut e = app.world_mut().spawn((
        Mesh3d(mesh),
        Transform::from_xyz(0.0, 2.0, 0.0),
        Cloth::default(),
        config,
        ClothReadback,
        ClothPins::rest([grid.index(0, 0), grid.index(23, 0)]),
    ));
    if let Some(b) = backend {
        e.insert(b);
    }
    let e = e.id();
    run(app, 2);
    let mut before: f32 = 0.0;
    for _ in 0..118 {
        run(app, 1);
        before = before.max(fastest(app, e));
    }
    change(&mut app.world_mut().entity_mut(e));
    let mut after: f32 = 0.0;
    for _ in 0..60 {
        run(app, 1);
        after = after.max(fastest(app, e));
    }
    app.world_mut().despawn(e);
    run(app, 2);
    (before, after)
}

/// The four switches of solver and substeps the settle tests make — lab → XPBD and back,
/// 20 → 2 substeps and back: (from, to, in words).
pub fn solver_switches() -> [(ClothConfig, ClothConfig, String); 4] {
    use bevy_cloth::solver::Solver;
    let lab = ClothConfig {
        solver: Solver::LAB,
        substeps: 1,
        iterations: 32,
        ..default()
    };
    let fine = ClothConfig {
        substeps: 20,
        ..default()
    };
    let coarse = ClothConfig {
        substeps: 2,
        ..default()
    };
    let name = |c: &ClothConfig| format!("{} {}×{}", c.solver.name(), c.substeps, c.iterations);
    [
        (lab, ClothConfig::default()),
        (ClothConfig::default(), lab),
        (fine, coarse),
        (coarse, fine),
    ]
    .map(|(from, to)| (from, to, format!("{} → {}", name(&from), name(&to))))
}

/// Checks two caped characters after [`walk_away`] moved the second: the first cape's top
/// edge still at x = 0, the second's at its bone's 1.18 m. The top edges are pinned: on
/// their anchors up to the rounding of a pin target and of the mean of 8 positions near 1 m
/// (f32 steps of 1.2e-7 m; 1e-5 m is about eighty).
pub fn assert_capes_apart(app: &App, stayed: Entity, walked: Entity, top: &[u32]) {
    let (a, b) = (mean_of(app, stayed, top), mean_of(app, walked, top));
    assert!(
        a.x.abs() < 1e-5 && (b.x - 1.18).abs() < 1e-5,
        "the first cape's top edge at {a}, the second's at {b} (its bone at x = 1.18)"
    );
}

/// How fast the character of [`smoothed_cape`] walks along x, in m/s.
pub const WALK_SPEED: f32 = 3.0;

/// The walking character of [`smoothed_cape`] and where it stood at its last two fixed steps
/// (what an interpolation plugin keeps to draw it between them).
#[derive(Resource)]
pub struct Walker {
    pub entity: Entity,
    pub before: f32,
    pub now: f32,
}

/// Walks the [`Walker`] at [`WALK_SPEED`] in `FixedUpdate`, as a game moves a character.
fn walk(mut walker: ResMut<Walker>, mut transforms: Query<&mut Transform>, time: Res<Time>) {
    if let Ok(mut t) = transforms.get_mut(walker.entity) {
        t.translation.x += WALK_SPEED * time.delta_secs();
        walker.before = walker.now;
        walker.now = t.translation.x;
    }
}

/// Where the capes of [`cape_on`] and their characters start: 1.5 m up, the grid turned
/// upright (row 0 on top).
pub fn cape_pose() -> Transform {
    Transform::from_xyz(0.0, 1.5, 0.0)
        .with_rotation(Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2))
}

/// The f32 rounding bound of the smoothing tests: a pin's velocity is a difference of
/// positions (up to about 5 m from the origin) over a substep, 2 ε |x| / h, drawn along for
/// at most a step (`substeps` substeps), with a factor 4 of slack for the other roundings.
pub fn smoothing_rounding() -> f32 {
    8.0 * ClothConfig::default().substeps as f32 * f32::EPSILON * 5.0
}

/// A 0.5 m cape at [`cape_pose`], its top row pinned to `character` (standing there),
/// `glued` to it (`ClothInertia` 0: its motion carried, not felt) or not; frames of 1/144 s
/// over the 60 Hz fixed step. Returns the cape, its pinned vertex 0 and that vertex's offset
/// in the character's frame.
pub fn cape_on(
    app: &mut App,
    character: Entity,
    smoothing: Option<ClothSmoothing>,
    backend: Option<bevy_cloth::gpu::ClothBackend>,
    glued: bool,
) -> (Entity, u32, Vec3) {
    app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        1.0 / 144.0,
    )));
    let grid = Grid::new(8, 8, 0.5, 0.5);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let rest = grid.positions();
    let pins = (0..8)
        .map(|i| ClothPin {
            vertex: grid.index(i, 0),
            anchor: PinAnchor::Entity {
                entity: character,
                offset: rest[grid.index(i, 0) as usize],
            },
        })
        .collect();
    let mut cape =
        app.world_mut()
            .spawn((Mesh3d(mesh), cape_pose(), Cloth::default(), ClothPins(pins)));
    if let Some(s) = smoothing {
        cape.insert(s);
    }
    if let Some(b) = backend {
        cape.insert(b);
    }
    if glued {
        cape.insert(ClothInertia::new(0.0).relative_to(character));
    }
    (cape.id(), grid.index(0, 0), rest[grid.index(0, 0) as usize])
}

/// [`cape_on`] a character walking at [`WALK_SPEED`] along x (moved in `FixedUpdate`; the
/// [`Walker`]).
pub fn smoothed_cape(
    app: &mut App,
    smoothing: Option<ClothSmoothing>,
    backend: Option<bevy_cloth::gpu::ClothBackend>,
    glued: bool,
) -> (Entity, u32, Vec3) {
    let character = app.world_mut().spawn(cape_pose()).id();
    app.insert_resource(Walker {
        entity: character,
        before: 0.0,
        now: 0.0,
    })
    .add_systems(FixedUpdate, walk);
    cape_on(app, character, smoothing, backend, glued)
}

/// A [`cape_on`] a character that the game moves in `Update` (not on the fixed clock), at
/// [`WALK_SPEED`] along x, frames of 1/144 s, on `backend` if given. Runs 1.5 s and returns
/// how far the cape's pinned corner is drawn (`drawn`: the mesh's local positions) from where
/// its character is drawn, at worst over the last half second.
pub fn cape_moved_in_update(
    app: &mut App,
    backend: Option<bevy_cloth::gpu::ClothBackend>,
    drawn: impl Fn(&App, Entity) -> Vec<Vec3>,
) -> (Entity, f32) {
    let character = app.world_mut().spawn(cape_pose()).id();
    app.add_systems(
        Update,
        move |time: Res<Time>, mut transforms: Query<&mut Transform>| {
            if let Ok(mut t) = transforms.get_mut(character) {
                t.translation.x += WALK_SPEED * time.delta_secs();
            }
        },
    );
    let (cape, vertex, offset) = cape_on(app, character, None, backend, false);
    let mut worst = 0.0f32;
    for frame in 0..216 {
        app.update();
        if frame < 144 {
            continue;
        }
        let world = |e: Entity| *app.world().get::<GlobalTransform>(e).unwrap();
        let want = world(character).transform_point(offset);
        let got = world(cape).transform_point(drawn(app, cape)[vertex as usize]);
        worst = worst.max(got.distance(want));
    }
    (cape, worst)
}

/// The local positions of cloth `e`'s mesh as the CPU wrote them.
pub fn drawn_on_the_cpu(app: &App, e: Entity) -> Vec<Vec3> {
    let handle = &app.world().get::<Mesh3d>(e).unwrap().0;
    let mesh = app.world().resource::<Assets<Mesh>>().get(handle);
    positions_of(mesh.unwrap_or_else(|| panic!("cloth {e} has no mesh")))
}

/// A `cols × rows` grid (0.8 × 0.6 m) as triangle strips, one per row of quads, restarted
/// with `u16::MAX`, and the same triangles as a list written out by hand (Vulkan's strip
/// order: every other triangle turned): the grid, its positions, the strip, the list.
pub fn strip_grid(cols: u32, rows: u32) -> (Grid, Vec<[f32; 3]>, Vec<u16>, Vec<u32>) {
    let grid = Grid::new(cols, rows, 0.8, 0.6);
    let positions: Vec<[f32; 3]> = grid.positions().iter().map(|p| p.to_array()).collect();
    let (mut strip, mut list) = (Vec::new(), Vec::new());
    for j in 0..rows - 1 {
        let (t, b) = (|i: u32| j * cols + i, |i: u32| (j + 1) * cols + i);
        for i in 0..cols {
            strip.extend([t(i) as u16, b(i) as u16]);
        }
        strip.push(u16::MAX);
        for i in 0..cols - 1 {
            list.extend([t(i), b(i), t(i + 1)]);
            list.extend([t(i + 1), b(i), b(i + 1)]);
        }
    }
    (grid, positions, strip, list)
}

/// Runs the [`smoothed_cape`] app 1.5 s and returns how far its pinned `vertex` is drawn
/// (`drawn`: the mesh's local positions) over the last half second from where its character
/// is drawn interpolated between its last two fixed steps, and extrapolated past the last
/// one (the character's pose eased by the fixed clock's overstep, as interpolation plugins
/// draw it), at worst.
pub fn smoothing_errors(
    app: &mut App,
    (cape, vertex, offset): (Entity, u32, Vec3),
    drawn: impl Fn(&App, Entity) -> Vec<Vec3>,
) -> (f32, f32) {
    let (mut interpolated, mut extrapolated) = (0.0f32, 0.0f32);
    for frame in 0..216 {
        app.update();
        if frame < 144 {
            continue;
        }
        let fraction = app.world().resource::<Time<Fixed>>().overstep_fraction();
        let walker = app.world().resource::<Walker>();
        let (before, now) = (walker.before, walker.now);
        let pose = cape_pose();
        let at = |x: f32| Vec3::new(x, 0.0, 0.0) + pose.transform_point(offset);
        let gt = *app.world().get::<GlobalTransform>(cape).unwrap();
        let local = drawn(app, cape)[vertex as usize];
        let p = gt.transform_point(local);
        interpolated = interpolated.max(p.distance(at(before + (now - before) * fraction)));
        extrapolated = extrapolated.max(p.distance(at(now + (now - before) * fraction)));
    }
    (interpolated, extrapolated)
}

/// The car of [`flag_on_a_car`].
#[derive(Resource)]
struct Car(Entity);

/// Drives the [`Car`] at 20 m/s along x in `FixedUpdate`.
fn drive(car: Res<Car>, mut transforms: Query<&mut Transform>, time: Res<Time>) {
    if let Ok(mut t) = transforms.get_mut(car.0) {
        t.translation.x += 20.0 * time.delta_secs();
    }
}

/// A 0.6 × 0.4 m flag (default cloth, no wind) pinned along its hoist to a car driving at
/// 20 m/s along x, with `ClothInertia::new(inertia)` relative to the car if given, on
/// `backend` (read back) if given; after 3 s, where its fly edge is from its hoist (means).
/// Streaming in the airflow the fly edge is about 0.6 m behind (−x); hanging limp it is
/// about 0.4 m below.
pub fn flag_on_a_car(
    app: &mut App,
    inertia: Option<f32>,
    backend: Option<bevy_cloth::gpu::ClothBackend>,
) -> Vec3 {
    let grid = Grid::new(16, 11, 0.6, 0.4);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let at = Transform::from_xyz(0.0, 2.0, 0.0)
        .with_rotation(Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2));
    let car = app.world_mut().spawn(at).id();
    app.insert_resource(Car(car))
        .add_systems(FixedUpdate, drive);
    let rest = grid.positions();
    let hoist: Vec<u32> = (0..11).map(|j| grid.index(0, j)).collect();
    let fly: Vec<u32> = (0..11).map(|j| grid.index(15, j)).collect();
    let pins = hoist
        .iter()
        .map(|&v| ClothPin {
            vertex: v,
            anchor: PinAnchor::Entity {
                entity: car,
                offset: rest[v as usize],
            },
        })
        .collect();
    let mut flag = app
        .world_mut()
        .spawn((Mesh3d(mesh), at, Cloth::default(), ClothPins(pins)));
    if let Some(i) = inertia {
        flag.insert(ClothInertia::new(i).relative_to(car));
    }
    if let Some(b) = backend {
        flag.insert((b, bevy_cloth::gpu::ClothReadback));
    }
    let flag = flag.id();
    run(app, 180);
    mean_of(app, flag, &fly) - mean_of(app, flag, &hoist)
}

/// Adds glTF loading (and what it needs) to a headless app, with `more` plugins, and finishes
/// its plugins' set-up.
pub fn add_gltf<M>(app: &mut App, more: impl bevy::app::Plugins<M>) {
    app.add_plugins((
        bevy::image::ImagePlugin::default(),
        bevy::world_serialization::WorldSerializationPlugin,
        bevy::gltf::GltfPlugin::default(),
    ))
    .add_plugins(more);
    app.finish();
    app.cleanup();
}

/// Bevy's own plane mesh, 1 m square in the XZ plane, 9 × 9 vertices.
pub fn bevy_plane() -> Mesh {
    Plane3d::default()
        .mesh()
        .size(1.0, 1.0)
        .subdivisions(7)
        .build()
}

/// The vertices of `mesh` whose rest position passes `keep`.
pub fn vertices_where(mesh: &Mesh, keep: impl Fn(Vec3) -> bool) -> Vec<u32> {
    let p = positions_of(mesh);
    (0..p.len() as u32)
        .filter(|&i| keep(p[i as usize]))
        .collect()
}

/// `mesh` with `vertices` painted red in its vertex colours, the rest dark grey (a pin mask
/// as a modelling tool paints it).
pub fn painted(mesh: Mesh, vertices: &[u32]) -> Mesh {
    let paint: Vec<[f32; 4]> = (0..mesh.count_vertices() as u32)
        .map(|v| {
            if vertices.contains(&v) {
                [1.0, 0.0, 0.0, 1.0]
            } else {
                [0.2, 0.2, 0.2, 1.0]
            }
        })
        .collect();
    mesh.with_inserted_attribute(Mesh::ATTRIBUTE_COLOR, paint)
}

/// An `n` × `n`, 1 m grid cloth hung upright (row 0 on top) from its two top corners, or from
/// its whole top edge, with `extra` on its entity.
pub fn hung_grid(app: &mut App, n: u32, top_edge: bool, extra: impl Bundle) -> Entity {
    let grid = Grid::new(n, n, 1.0, 1.0);
    let pins: Vec<u32> = if top_edge {
        (0..n).map(|i| grid.index(i, 0)).collect()
    } else {
        vec![grid.index(0, 0), grid.index(n - 1, 0)]
    };
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    app.world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2)),
            Cloth::default(),
            ClothPins::rest(pins),
            extra,
        ))
        .id()
}

/// A closed cylinder of `sides` sides, `radius` and `height`, one segment high, its caps
/// fanned from their first rim vertex as Bevy's `Cylinder` mesh writes them (vertex 0, on the
/// top rim, joins every other top-rim vertex): positions and indices, outward-facing.
pub fn fanned_cylinder(sides: u32, radius: f32, height: f32) -> (Vec<Vec3>, Vec<u32>) {
    let ring = |y: f32| {
        (0..sides).map(move |i| {
            let a = i as f32 / sides as f32 * core::f32::consts::TAU;
            Vec3::new(radius * a.cos(), y, radius * a.sin())
        })
    };
    let positions: Vec<Vec3> = ring(height / 2.0).chain(ring(-height / 2.0)).collect();
    let n = sides;
    let mut indices: Vec<u32> = (0..n)
        .flat_map(|i| {
            let j = (i + 1) % n;
            [i, j, n + i, j, n + j, n + i]
        })
        .collect();
    indices.extend((1..n - 1).flat_map(|i| [0, i + 1, i]));
    indices.extend((1..n - 1).flat_map(|i| [n, n + i, n + i + 1]));
    (positions, indices)
}

/// A closed cube of `size` metres, `n` × `n` quads a face, centred at `centre`: positions and
/// indices, welded (each vertex once), outward-facing.
pub fn subdivided_cube(n: i32, size: f32, centre: Vec3) -> (Vec<Vec3>, Vec<u32>) {
    let mut ids = std::collections::HashMap::new();
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    let mut id = |p: [i32; 3], positions: &mut Vec<Vec3>| -> u32 {
        *ids.entry(p).or_insert_with(|| {
            let q = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32) * (size / n as f32);
            positions.push(q - Vec3::splat(size / 2.0) + centre);
            (positions.len() - 1) as u32
        })
    };
    for axis in 0..3 {
        for side in [0, n] {
            for a in 0..n {
                for b in 0..n {
                    let corner = |da: i32, db: i32| {
                        let mut p = [0; 3];
                        p[axis] = side;
                        p[(axis + 1) % 3] = a + da;
                        p[(axis + 2) % 3] = b + db;
                        p
                    };
                    let q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)]
                        .map(|p| id(p, &mut positions));
                    if side == 0 {
                        indices.extend([q[0], q[2], q[1], q[0], q[3], q[2]]);
                    } else {
                        indices.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
                    }
                }
            }
        }
    }
    (positions, indices)
}

/// A mesh's positions.
pub fn positions_of(mesh: &Mesh) -> Vec<Vec3> {
    match mesh.attribute(Mesh::ATTRIBUTE_POSITION) {
        Some(bevy::mesh::VertexAttributeValues::Float32x3(p)) => {
            p.iter().map(|a| Vec3::from_array(*a)).collect()
        }
        _ => panic!("positions as Float32x3"),
    }
}

/// `mesh`'s vertices welded where they coincide (as the plugin welds a mesh split along its
/// UV seams) and moved by `offset`, with its triangles on them: positions and indices.
pub fn welded(mesh: &Mesh, offset: Vec3) -> (Vec<Vec3>, Vec<u32>) {
    let positions: Vec<Vec3> = positions_of(mesh).into_iter().map(|p| p + offset).collect();
    let weld = bevy_cloth::solver::Weld::new(&positions, None, 1e-5);
    let welded = (0..weld.particle_count() as u32)
        .map(|q| positions[weld.representative(q) as usize])
        .collect();
    let indices = mesh
        .indices()
        .expect("indexed")
        .iter()
        .map(|i| weld.particle(i as u32))
        .collect();
    (welded, indices)
}

/// Switches self-collision on for `sim`, `thickness` thick with friction 0.3 (nothing else).
pub fn self_colliding(sim: &mut bevy_cloth::solver::Simulation, thickness: f32) {
    sim.set_features(bevy_cloth::solver::Features {
        self_collision: Some(bevy_cloth::solver::SelfCollision {
            thickness,
            friction: 0.3,
        }),
        ..bevy_cloth::solver::Features::default()
    })
    .unwrap();
}

/// The ground: a plane through the origin facing up, 5 mm thick, friction 0.6.
pub fn floor() -> bevy_cloth::solver::Collider {
    use bevy_cloth::solver::Pose;
    bevy_cloth::solver::Collider {
        shape: bevy_cloth::solver::Shape::Plane,
        start: Pose::at(Vec3::ZERO),
        end: Pose::at(Vec3::ZERO),
        thickness: 0.005,
        friction: 0.6,
    }
}

/// Three 0.9 m × 1.4 m banners (24 × 36) with tethers hanging from their top edges at 2.6 m,
/// on `backend` (none: the default), read back: one spawned at full size, and two that pop in
/// (scale 0 to 1 over 30 fixed steps), out (to 0 over 15, held near and at 0 for 5) and in
/// again: one by its own scale, one by its parent's, a mount on its top edge (a prefab's root
/// popped, the banner its child: the growth moves the banner's own origin). The scale is set
/// at each fixed step (`FixedUpdate`), each frame `steps` fixed steps long (a frame rate of
/// 60 / `steps`). The fastest vertex of each, about 30 steps after the second growth ended.
pub fn banners_popped_in_and_out(
    app: &mut App,
    backend: Option<ClothBackend>,
    steps: usize,
) -> [f32; 3] {
    app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
        Duration::from_secs_f64(steps as f64 / 60.0),
    ));
    let grid = Grid::new(24, 36, 0.9, 1.4);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    // Turned 90° about x, the grid stands in xy, its last row at the top, 0.7 m above its
    // centre.
    let turn = Quat::from_rotation_x(core::f32::consts::FRAC_PI_2);
    let below_top = Transform::from_xyz(0.0, -0.7, 0.0).with_rotation(turn);
    let top: Vec<u32> = (0..24).map(|i| grid.index(i, 35)).collect();
    // (x, scale of the mount, scale of the banner): the one scaled is 0 at first.
    let banners = [(0.0, 1.0, 1.0), (2.0, 1.0, 0.0), (4.0, 0.0, 1.0)].map(|(x, m, b)| {
        let mount = app
            .world_mut()
            .spawn(Transform::from_xyz(x, 2.6, 0.0).with_scale(Vec3::splat(m)))
            .id();
        let mut e = app.world_mut().spawn((
            Mesh3d(mesh.clone()),
            below_top.with_scale(Vec3::splat(b)),
            ChildOf(mount),
            Cloth::default(),
            ClothPins::rest(top.iter().copied()),
            ClothTethers::default(),
            ClothReadback,
        ));
        if let Some(b) = backend {
            e.insert(b);
        }
        e.id()
    });
    let scaled = [
        banners[1],
        app.world().get::<ChildOf>(banners[2]).unwrap().parent(),
    ];
    app.update();
    let grow = (1..=30).map(|f| f as f32 / 30.0);
    let shrink = (1..=15).map(|f| 1.0 - f as f32 / 15.0);
    // Held near 0 (a tween's end, a millionth: too small to place the cloth at) and at 0.
    let hidden = [1e-6, 1e-6, 0.0, 0.0, 1e-6];
    let schedule: Vec<f32> = grow
        .clone()
        .chain(shrink)
        .chain(hidden)
        .chain(grow)
        .collect();
    // Set at each fixed step, as a tween on the fixed clock does.
    app.insert_resource(PopSchedule {
        entities: scaled,
        scales: schedule.into_iter().rev().collect(),
    })
    .add_systems(FixedUpdate, pop_step);
    while !app.world().resource::<PopSchedule>().scales.is_empty() {
        app.update();
    }
    run(app, 30 / steps);
    banners.map(|e| {
        let state = app
            .world()
            .get::<ClothSim>(e)
            .expect("built")
            .simulation()
            .state();
        (0..state.len())
            .map(|i| state.velocity(i).length())
            .fold(0.0f32, f32::max)
    })
}

/// What [`banners_popped_in_and_out`] scales, and the scales left (the next last).
#[derive(Resource)]
struct PopSchedule {
    entities: [Entity; 2],
    scales: Vec<f32>,
}

/// Sets the next scale of a [`PopSchedule`].
fn pop_step(mut schedule: ResMut<PopSchedule>, mut transforms: Query<&mut Transform>) {
    let Some(s) = schedule.scales.pop() else {
        return;
    };
    for e in schedule.entities {
        if let Ok(mut t) = transforms.get_mut(e) {
            t.scale = Vec3::splat(s);
        }
    }
}

/// Checks [`banners_popped_in_and_out`]: all three hang still (no vertex faster than 5 cm/s;
/// a banner at rest moves by far less).
pub fn check_banners_popped_in_and_out(fastest: [f32; 3]) {
    let names = [
        "spawned at full size",
        "popped by its own scale",
        "popped by its parent's",
    ];
    for (v, name) in fastest.into_iter().zip(names) {
        println!("fastest: {name} {v} m/s");
    }
    for (v, name) in fastest.into_iter().zip(names) {
        assert!(v < 0.05, "{name}: {v} m/s");
    }
}

/// Two 32² one-metre cloths hanging from two corners, on `backend` (none: the default), read
/// back: one spawned at scale 1, one spawned at scale 0 that grows to 1 over 30 frames (a
/// pop-in); the fastest vertex of each, and each one's edge–triangle pairs crossing, half a
/// second after the growth ended.
pub fn popped_in(app: &mut App, backend: Option<ClothBackend>) -> [(f32, usize); 2] {
    let cloths = hanging_at_scales(app, 32, [1.0, 0.0], backend);
    app.update();
    for f in 1..=30 {
        let s = f as f32 / 30.0;
        app.world_mut()
            .get_mut::<Transform>(cloths[1])
            .unwrap()
            .scale = Vec3::splat(s);
        app.update();
    }
    run(app, 30);
    cloths.map(|e| {
        let sim = app.world().get::<ClothSim>(e).expect("built").simulation();
        let state = sim.state();
        let fastest = (0..state.len())
            .map(|i| state.velocity(i).length())
            .fold(0.0f32, f32::max);
        (fastest, sim.self_crossings())
    })
}
