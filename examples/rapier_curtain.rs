//! Two-way coupling with bevy_rapier3d: balls are thrown into a curtain hanging from a rail.
//! The rapier balls collide with the cloth without any extra marker (`ClothRapierPlugin`
//! mirrors them), the curtain bulges, and the cloth pushes back: the balls slow down.
//!
//! ```text
//! cargo run --release --features rapier --example rapier_curtain
//! cargo run --release --features rapier --example rapier_curtain -- --headless --frames 300
//! ```
//! The JSON line adds `speed_loss` (mean fraction of speed the balls lost passing the curtain,
//! gravity off for the balls so only the cloth slows them) and `bulge` (largest distance a
//! curtain vertex was pushed from its rest plane).

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use bevy_rapier3d::prelude::*;
use support::Args;

const SPEED: f32 = 6.0;

#[derive(Component)]
struct Ball {
    launched: f32,
}

#[derive(Resource, Default)]
struct Stats {
    thrown: usize,
    speed_after: Vec<f32>,
    bulge: f32,
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let grid = Grid::new(30, 30, 2.0, 2.0);
    let mut curtain = commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        // Hanging in the XY plane at z = 0, top edge at y = 2.5.
        Transform::from_xyz(0.0, 1.5, 0.0)
            .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2)),
        Cloth {
            mass: 0.6,
            ..default()
        },
        ClothConfig {
            substeps: 12,
            ..default()
        },
        ClothPins::rest((0..30).map(|i| grid.index(i, 0))),
        ClothTethers::default(),
    ));
    if let Some(mut m) = materials {
        curtain.insert(support::ClothLook(Color::srgb(0.55, 0.15, 0.35)));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut m,
            Vec3::new(4.0, 2.0, 4.5),
            Vec3::new(0.0, 1.3, 0.0),
        );
    }
}

/// Throws a ball at the curtain every 0.8 s of the fixed clock, at one of five heights in
/// turn (each ball is gone a second after it was thrown, so a few are in the air at most).
fn throw(
    mut commands: Commands,
    time: Res<Time>,
    mut stats: ResMut<Stats>,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let t = time.elapsed_secs();
    if t < 0.5 + stats.thrown as f32 * 0.8 {
        return;
    }
    let k = (stats.thrown % 5) as f32;
    let mut ball = commands.spawn((
        Ball { launched: t },
        RigidBody::Dynamic,
        Collider::ball(0.15),
        ColliderMassProperties::Mass(0.4),
        GravityScale(0.0),
        Velocity::linear(Vec3::new(0.0, 0.0, -SPEED)),
        Transform::from_xyz(-0.6 + 0.3 * k, 1.0 + 0.15 * k, 2.0),
    ));
    if let (Some(meshes), Some(materials)) = (meshes.as_deref_mut(), materials.as_deref_mut()) {
        ball.insert((
            Mesh3d(meshes.add(Sphere::new(0.15))),
            MeshMaterial3d(materials.add(Color::srgb(0.9, 0.9, 0.3))),
        ));
    }
    stats.thrown += 1;
}

/// Records each ball's speed once it has had time to pass through the curtain.
fn measure(
    mut commands: Commands,
    time: Res<Time>,
    balls: Query<(Entity, &Ball, &Velocity)>,
    cloths: Query<&ClothSim>,
    mut stats: ResMut<Stats>,
) {
    for (e, ball, v) in &balls {
        if time.elapsed_secs() - ball.launched > 1.0 {
            stats.speed_after.push(v.linear.length());
            commands.entity(e).despawn();
        }
    }
    for c in &cloths {
        let s = c.simulation().state();
        let bulge = (0..s.len())
            .map(|i| s.position(i).z.abs())
            .fold(0.0, f32::max);
        stats.bulge = stats.bulge.max(bulge);
    }
}

fn report(world: &mut World) -> support::Json {
    let stats = world.resource::<Stats>();
    let n = stats.speed_after.len().max(1) as f32;
    let loss = stats
        .speed_after
        .iter()
        .map(|s| 1.0 - s / SPEED)
        .sum::<f32>()
        / n;
    let (balls, bulge) = (stats.speed_after.len(), stats.bulge);
    support::cloth_report(world)
        .str("example", "rapier_curtain")
        .num("balls", balls as f64)
        .num("speed_loss", loss)
        .num("bulge", bulge)
}

fn main() {
    let args = Args::parse();
    let mut app = support::app(&args, "bevy_cloth: rapier curtain", 1.0 / 60.0);
    // Rapier steps in FixedUpdate, one 1/60 s step per fixed step, like the cloth: when frames
    // are slow both catch up together (rapier's default, a variable step of at most 1/60 s
    // per frame, would fall behind the cloth and the throwing clock).
    app.insert_resource(TimestepMode::Fixed {
        dt: 1.0 / 60.0,
        substeps: 1,
    })
    .add_plugins((
        RapierPhysicsPlugin::<NoUserData>::default().in_fixed_schedule(),
        ClothRapierPlugin::default(),
    ))
    .init_resource::<Stats>()
    .add_systems(Startup, setup)
    .add_systems(FixedUpdate, (throw, measure));
    support::run(app, &args, report);
}
