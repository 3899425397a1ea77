//! A cape on a character walking a loop: the cape's top edge is pinned to the character's
//! shoulders (`PinAnchor::Entity`), tethers keep it from stretching like rubber, and the
//! character's body (a capsule collider) keeps it from falling through.
//!
//! ```text
//! cargo run --release --example cape
//! cargo run --release --example cape -- --headless --frames 600
//! cargo run --release --example cape -- --speed 8 --inertia 0.3
//! ```
//! `--speed M/S` sets the walking speed (default 1.6); `--inertia X` gives the cape a
//! `ClothInertia` of `X` relative to the character (1: it feels all of the motion, as without;
//! lower: less stretch and swing when the character runs). The JSON line adds `pin_error`
//! (largest distance between a pinned vertex and its anchor).

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

#[derive(Component)]
struct Walker {
    radius: f32,
    speed: f32,
}

/// `--speed` and `--inertia`.
#[derive(Resource)]
struct Options {
    speed: f32,
    inertia: Option<f32>,
}

const COLUMNS: u32 = 16;
const ROWS: u32 = 22;

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: Option<ResMut<Assets<StandardMaterial>>>,
    options: Res<Options>,
) {
    // The character: a capsule 1.7 m tall walking towards its local +z; its back is −z.
    let mut body = commands.spawn((
        Walker {
            radius: 3.0,
            speed: options.speed,
        },
        Transform::from_xyz(3.0, 0.85, 0.0),
        ClothCollider::capsule(0.28, 1.1).with_thickness(0.02),
        Mesh3d(meshes.add(Capsule3d::new(0.28, 1.1).mesh().build())),
    ));
    if let Some(m) = materials.as_deref_mut() {
        body.insert(MeshMaterial3d(m.add(Color::srgb(0.55, 0.5, 0.45))));
    }
    let character = body.id();

    // The cape: 0.8 m × 1.1 m hanging down the back, top row at the shoulders.
    let grid = Grid::new(COLUMNS, ROWS, 0.8, 1.1);
    let shoulders = Vec3::new(0.0, 0.6, -0.32);
    // Grid in XZ; −90° about X stands it up with row 0 on top, then it goes behind the back.
    let transform =
        Transform::from_translation(Vec3::new(3.0, 0.85, 0.0) + shoulders - Vec3::Y * 0.55)
            .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let rest = grid.positions();
    let pins = (0..COLUMNS).map(|i| {
        let v = grid.index(i, 0);
        // Offset in the character's frame: along its shoulders, just behind the back.
        let world_rest = transform.transform_point(rest[v as usize]);
        let offset = world_rest - Vec3::new(3.0, 0.85, 0.0);
        ClothPin {
            vertex: v,
            anchor: PinAnchor::Entity {
                entity: character,
                offset,
            },
        }
    });
    let mut cape = commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        transform,
        Cloth {
            mass: 0.5,
            ..default()
        },
        ClothConfig {
            substeps: 10,
            ..default()
        },
        ClothPins(pins.collect()),
        ClothTethers::default(),
    ));
    if let Some(inertia) = options.inertia {
        cape.insert(ClothInertia::new(inertia).relative_to(character));
    }
    if let Some(mut m) = materials {
        cape.insert(support::ClothLook(Color::srgb(0.6, 0.08, 0.12)));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut m,
            Vec3::new(0.0, 4.0, 8.0),
            Vec3::new(0.0, 0.8, 0.0),
        );
    }
}

/// Walk counter-clockwise around the origin, facing along the path (back towards −tangent).
fn walk(time: Res<Time>, mut walkers: Query<(&Walker, &mut Transform)>) {
    for (w, mut t) in &mut walkers {
        let angle = time.elapsed_secs() * w.speed / w.radius;
        let (s, c) = angle.sin_cos();
        t.translation = Vec3::new(
            w.radius * c,
            0.85 + 0.03 * (angle * 12.0).sin(),
            w.radius * s,
        );
        let forward = Vec3::new(-s, 0.0, c);
        t.look_to(-forward, Vec3::Y);
    }
}

fn report(world: &mut World) -> support::Json {
    let mut walkers = world.query_filtered::<&GlobalTransform, With<Walker>>();
    let body = *walkers.iter(world).next().expect("a walker");
    let mut q = world.query::<(
        &ClothSim,
        &ClothPins,
        Option<&ClothBackendInUse>,
        Has<ClothReadback>,
    )>();
    let mut pin_error = 0.0f32;
    for (sim, pins, backend, read_back) in q.iter(world) {
        if backend.is_some_and(|b| b.gpu) && !read_back {
            // Its state stays on the GPU (a windowed run reads none back).
            continue;
        }
        for pin in &pins.0 {
            if let PinAnchor::Entity { offset, .. } = pin.anchor {
                let at = body.transform_point(offset);
                pin_error = pin_error.max(
                    sim.simulation()
                        .state()
                        .position(pin.vertex as usize)
                        .distance(at),
                );
            }
        }
    }
    support::cloth_report(world)
        .str("example", "cape")
        .num("pin_error", pin_error)
}

fn main() {
    let args = Args::parse();
    let mut app = support::app(&args, "bevy_cloth: cape", 1.0 / 60.0);
    app.insert_resource(Options {
        speed: args.get("speed", 1.6),
        inertia: args.rest.get("inertia").map(|_| args.get("inertia", 1.0)),
    })
    .add_systems(Startup, setup)
    .add_systems(FixedUpdate, walk);
    support::run(app, &args, report);
}
