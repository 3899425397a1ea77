//! Banners that pop in and out by their scale: banners hang from a rail by their top edge,
//! with tethers, each under a mount entity that a tween scales from 0 to 1 (a quarter second
//! after the banner before), holds, shrinks away and grows again every few seconds. The cloth
//! follows its entity's scale (rest shape, pins and tethers; a parent's scale too), and a
//! growth never whips it: each banner hangs as one spawned at full size would. Space pops them
//! all again at once.
//!
//! ```text
//! cargo run --release --example pop_in
//! cargo run --release --example pop_in -- --backend gpu
//! cargo run --release --example pop_in -- --headless --frames 300
//! ```
//! Options: `--banners N` (default 4), `--columns N --rows N` (each banner's grid, default
//! 24 × 36), `--period SECONDS` (from one pop to the next, default 4), `--self-collision`
//! (each banner with `ClothSelfCollision` at a 3 cm thickness: set for its full size, and
//! judged there, not at the sizes a growth passes).

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

/// Seconds a banner takes to grow in, and to shrink away.
const GROW: f32 = 0.5;
const SHRINK: f32 = 0.35;
/// Each banner pops this long after the one before it.
const STAGGER: f32 = 0.25;
/// A banner's size in metres (width, height) and the rail's height.
const SIZE: Vec2 = Vec2::new(0.9, 1.4);
const RAIL: f32 = 2.6;

#[derive(Resource, Clone, Copy)]
struct Setup {
    banners: u32,
    grid: Grid,
    period: f32,
    self_collision: bool,
}

/// A banner's mount on the rail: the entity the tween scales (the cloth is its child), and
/// its place in the row.
#[derive(Component)]
struct Mount(u32);

/// When the pops started (fixed-clock seconds): Space starts them again.
#[derive(Resource, Default)]
struct PopClock(f32);

/// The largest speed any banner's vertex had half a second to a second after a growth, and
/// how many such looks there were.
#[derive(Resource, Default)]
struct Watch {
    fastest: f32,
    looks: u32,
}

fn spawn_banners(
    mut commands: Commands,
    setup: Res<Setup>,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let grid = setup.grid;
    let mesh = meshes.add(grid_mesh(&grid));
    // The grid lies in XZ, front +Y; turned 90° about X it stands in XY facing the camera, its
    // last row at the top. Under the mount it hangs from the rail: scaled, it grows from there.
    let top = (0..grid.columns).map(|i| grid.index(i, grid.rows - 1));
    let pins: Vec<u32> = top.collect();
    let colours = [
        Color::srgb(0.75, 0.12, 0.1),
        Color::srgb(0.9, 0.65, 0.1),
        Color::srgb(0.1, 0.45, 0.25),
        Color::srgb(0.12, 0.25, 0.7),
    ];
    let spacing = SIZE.x + 0.25;
    let first = -spacing * (setup.banners as f32 - 1.0) / 2.0;
    for b in 0..setup.banners {
        commands
            .spawn((
                Mount(b),
                Transform::from_xyz(first + spacing * b as f32, RAIL, 0.0).with_scale(Vec3::ZERO),
                Visibility::default(),
            ))
            .with_children(|mount| {
                let mut banner = mount.spawn((
                    Mesh3d(mesh.clone()),
                    Transform::from_xyz(0.0, -SIZE.y / 2.0, 0.0)
                        .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2)),
                    Cloth {
                        mass: 0.3,
                        ..default()
                    },
                    ClothPins::rest(pins.iter().copied()),
                    ClothTethers::default(),
                ));
                if setup.self_collision {
                    banner.insert(ClothSelfCollision {
                        thickness: Some(0.03),
                        ..default()
                    });
                }
                if materials.is_some() {
                    banner.insert(support::ClothLook(colours[b as usize % colours.len()]));
                }
            });
    }
    if let Some(mut materials) = materials {
        let length = spacing * setup.banners as f32 + 0.4;
        commands.spawn((
            Mesh3d(meshes.add(Cylinder::new(0.03, length))),
            MeshMaterial3d(materials.add(Color::srgb(0.55, 0.45, 0.35))),
            Transform::from_xyz(0.0, RAIL + 0.03, 0.0)
                .with_rotation(Quat::from_rotation_z(core::f32::consts::FRAC_PI_2)),
        ));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(0.0, 1.9, 5.2),
            Vec3::new(0.0, 1.8, 0.0),
        );
    }
}

/// Scale `0..=1` of banner `b` at `t` seconds after the pops started: grows with an ease-out
/// over [`GROW`], holds, shrinks over [`SHRINK`] before the next pop, and waits at 0.
fn scale_at(t: f32, b: u32, period: f32) -> f32 {
    let local = t - STAGGER * b as f32;
    if local < 0.0 {
        return 0.0;
    }
    let phase = local % period;
    let shrink_at = period - SHRINK - 0.3;
    if phase < GROW {
        let x = phase / GROW;
        1.0 - (1.0 - x).powi(3)
    } else if phase < shrink_at {
        1.0
    } else {
        (1.0 - (phase - shrink_at) / SHRINK).max(0.0)
    }
}

/// Scales the mounts on the fixed clock, where the cloth steps.
fn pop(
    time: Res<Time<Fixed>>,
    clock: Res<PopClock>,
    setup: Res<Setup>,
    mut mounts: Query<(&Mount, &mut Transform)>,
) {
    let t = time.elapsed_secs() - clock.0;
    for (m, mut transform) in &mut mounts {
        transform.scale = Vec3::splat(scale_at(t, m.0, setup.period));
    }
}

/// Space: every banner pops again from now.
fn restart(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    time: Res<Time<Fixed>>,
    mut clock: ResMut<PopClock>,
) {
    if keys.is_some_and(|k| k.just_pressed(KeyCode::Space)) {
        clock.0 = time.elapsed_secs();
    }
}

/// Records the fastest vertex of each banner from half a second to a second after its growth
/// (what is left of the growth's motion: a banner spawned at full size hangs still).
fn watch(
    time: Res<Time<Fixed>>,
    clock: Res<PopClock>,
    setup: Res<Setup>,
    mounts: Query<(&Mount, &Children)>,
    cloths: Query<&ClothSim>,
    mut watch: ResMut<Watch>,
) {
    let t = time.elapsed_secs() - clock.0;
    for (m, children) in &mounts {
        let local = t - STAGGER * m.0 as f32;
        if local < 0.0 || !(GROW + 0.5..GROW + 1.0).contains(&(local % setup.period)) {
            continue;
        }
        for sim in cloths.iter_many(children) {
            let state = sim.simulation().state();
            let fastest = (0..state.len())
                .map(|i| state.velocity(i).length())
                .fold(0.0f32, f32::max);
            watch.fastest = watch.fastest.max(fastest);
            watch.looks += 1;
        }
    }
}

fn report(world: &mut World) -> support::Json {
    let unread = support::gpu_state_unread(world);
    let watch = world.resource::<Watch>();
    let (fastest, looks) = (watch.fastest, watch.looks);
    support::cloth_report(world)
        .str("example", "pop_in")
        .num("looks_after_growth", looks)
        .measured("fastest_after_growth", fastest, unread)
}

fn main() {
    let args = Args::parse(include_str!("pop_in.rs"));
    let grid = Grid::new(
        args.get("columns", 24),
        args.get("rows", 36),
        SIZE.x,
        SIZE.y,
    );
    let setup = Setup {
        banners: args.get("banners", 4u32).max(1),
        grid,
        period: args.get("period", 4.0f32).max(GROW + SHRINK + 0.5),
        self_collision: args.rest.contains_key("self-collision"),
    };
    let mut app = support::app(&args, "bevy_cloth: pop-in", 1.0 / 60.0);
    app.insert_resource(setup)
        .init_resource::<PopClock>()
        .init_resource::<Watch>()
        .add_systems(Startup, spawn_banners)
        .add_systems(FixedUpdate, pop)
        .add_systems(Update, (restart, watch));
    support::run(app, &args, report);
}
