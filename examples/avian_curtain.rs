//! Two-way coupling with avian3d: balls are thrown into a curtain hanging from a rail.
//! The avian balls collide with the cloth without any extra marker (`ClothAvianPlugin`
//! mirrors them), the curtain bulges, and the cloth pushes back: the balls slow down.
//! `rapier_curtain` is the same scene with bevy_rapier3d.
//!
//! ```text
//! cargo run --release --features avian --example avian_curtain
//! cargo run --release --features avian --example avian_curtain -- --headless --frames 300
//! ```
//! Avian draws the balls interpolated between its fixed steps
//! (`PhysicsInterpolationPlugin::interpolate_all`) and the curtain is drawn the same way
//! (`ClothSmoothing::Interpolate`), so at a frame rate above the 60 Hz step a ball and the
//! bulge it makes are drawn at the same moment.
//!
//! The JSON line adds `speed_loss` (mean fraction of speed the balls lost passing the curtain,
//! gravity off for the balls so only the cloth slows them) and `bulge` (largest distance a
//! curtain vertex was pushed from its rest plane).

#[path = "support/curtain.rs"]
mod curtain;
#[path = "support/mod.rs"]
mod support;

use avian3d::prelude::*;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use curtain::{BALL_MASS, BALL_RADIUS, Ball, SPEED, Stats};
use support::Args;

fn throw(
    mut commands: Commands,
    time: Res<Time>,
    mut stats: ResMut<Stats>,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    mut materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let (meshes, materials) = (meshes.as_deref_mut(), materials.as_deref_mut());
    if let Some(ball) = curtain::throw(&mut commands, &time, &mut stats, meshes, materials) {
        commands.entity(ball).insert((
            RigidBody::Dynamic,
            Collider::sphere(BALL_RADIUS),
            Mass(BALL_MASS),
            GravityScale(0.0),
            LinearVelocity(Vec3::new(0.0, 0.0, -SPEED)),
        ));
    }
}

/// Draws every cloth between fixed steps as avian draws the balls.
fn smooth_cloths(mut commands: Commands, cloths: Query<Entity, With<Cloth>>) {
    for e in &cloths {
        commands.entity(e).insert(ClothSmoothing::Interpolate);
    }
}

fn measure(
    mut commands: Commands,
    time: Res<Time>,
    balls: Query<(Entity, &Ball, &LinearVelocity)>,
    cloths: Query<&ClothSim>,
    mut stats: ResMut<Stats>,
) {
    let balls = balls.iter().map(|(e, b, v)| (e, b, v.length()));
    curtain::measure(&mut commands, &time, balls, &cloths, &mut stats);
}

fn main() {
    let args = Args::parse(include_str!("avian_curtain.rs"));
    let mut app = curtain::app(&args, "bevy_cloth: avian curtain");
    // Avian steps in FixedPostUpdate (its default), one step per fixed step, like the cloth,
    // which the bridge runs right after it.
    app.add_plugins((
        PhysicsPlugins::default().set(PhysicsInterpolationPlugin::interpolate_all()),
        ClothAvianPlugin::default(),
    ))
    .add_systems(PostStartup, smooth_cloths)
    .add_systems(FixedUpdate, (throw, measure));
    support::run(app, &args, |world| curtain::report(world, "avian_curtain"));
}
