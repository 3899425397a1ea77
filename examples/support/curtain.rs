//! The curtain scene the physics-engine examples share (`rapier_curtain`, `avian_curtain`): a
//! curtain pinned along a rail, a ball thrown at it every 0.8 s at one of five heights, the
//! balls' speed measured a second after each throw. Each example adds only its engine's ball
//! and how it reads the ball's velocity.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::support::{self, Args, Json};

/// Speed the balls are thrown at (m/s), along −z.
pub const SPEED: f32 = 6.0;
/// Ball radius (metres) and mass (kg).
pub const BALL_RADIUS: f32 = 0.15;
/// Ball mass (kg).
pub const BALL_MASS: f32 = 0.4;

/// A thrown ball and when (seconds of the fixed clock).
#[derive(Component)]
pub struct Ball {
    launched: f32,
}

/// What the run measured.
#[derive(Resource, Default)]
pub struct Stats {
    thrown: usize,
    speed_after: Vec<f32>,
    bulge: f32,
}

/// Spawns the curtain (and, windowed, the stage).
pub fn setup(
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

/// When a ball is due (every 0.8 s of the fixed clock, from 0.5 s), spawns its [`Ball`], its
/// start transform and, windowed, its look, and returns the entity for the engine's
/// components (moving at [`SPEED`] along −z); `None` otherwise.
pub fn throw(
    commands: &mut Commands,
    time: &Time,
    stats: &mut Stats,
    meshes: Option<&mut Assets<Mesh>>,
    materials: Option<&mut Assets<StandardMaterial>>,
) -> Option<Entity> {
    let t = time.elapsed_secs();
    if t < 0.5 + stats.thrown as f32 * 0.8 {
        return None;
    }
    let k = (stats.thrown % 5) as f32;
    let mut ball = commands.spawn((
        Ball { launched: t },
        Transform::from_xyz(-0.6 + 0.3 * k, 1.0 + 0.15 * k, 2.0),
    ));
    if let (Some(meshes), Some(materials)) = (meshes, materials) {
        ball.insert((
            Mesh3d(meshes.add(Sphere::new(BALL_RADIUS))),
            MeshMaterial3d(materials.add(Color::srgb(0.9, 0.9, 0.3))),
        ));
    }
    stats.thrown += 1;
    Some(ball.id())
}

/// Records the speed of each ball (as the engine reads it) once it has had a second to pass
/// through the curtain, then removes it; and the curtain's largest bulge.
pub fn measure<'a>(
    commands: &mut Commands,
    time: &Time,
    balls: impl IntoIterator<Item = (Entity, &'a Ball, f32)>,
    cloths: &Query<&ClothSim>,
    stats: &mut Stats,
) {
    for (e, ball, speed) in balls {
        if time.elapsed_secs() - ball.launched > 1.0 {
            stats.speed_after.push(speed);
            commands.entity(e).despawn();
        }
    }
    for c in cloths {
        let s = c.simulation().state();
        let bulge = (0..s.len())
            .map(|i| s.position(i).z.abs())
            .fold(0.0, f32::max);
        stats.bulge = stats.bulge.max(bulge);
    }
}

/// The final JSON line: the cloth report plus `balls`, `speed_loss` and `bulge`.
pub fn report(world: &mut World, example: &str) -> Json {
    let stats = world.resource::<Stats>();
    let n = stats.speed_after.len().max(1) as f32;
    let loss = stats
        .speed_after
        .iter()
        .map(|s| 1.0 - s / SPEED)
        .sum::<f32>()
        / n;
    let (balls, bulge) = (stats.speed_after.len(), stats.bulge);
    let unread = support::gpu_state_unread(world);
    support::cloth_report(world)
        .str("example", example)
        .num("balls", balls as f64)
        .num("speed_loss", loss)
        .measured("bulge", bulge, unread)
}

/// The app both examples start from: the curtain scene on a 1/60 s fixed clock.
pub fn app(args: &Args, title: &str) -> App {
    let mut app = support::app(args, title, 1.0 / 60.0);
    app.init_resource::<Stats>().add_systems(Startup, setup);
    app
}
