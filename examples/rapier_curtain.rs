//! Two-way coupling with bevy_rapier3d: balls are thrown into a curtain hanging from a rail.
//! The rapier balls collide with the cloth without any extra marker (`ClothRapierPlugin`
//! mirrors them), the curtain bulges, and the cloth pushes back: the balls slow down.
//! `avian_curtain` is the same scene with avian3d.
//!
//! ```text
//! cargo run --release --features rapier --example rapier_curtain
//! cargo run --release --features rapier --example rapier_curtain -- --headless --frames 300
//! ```
//! The JSON line adds `speed_loss` (mean fraction of speed the balls lost passing the curtain,
//! gravity off for the balls so only the cloth slows them) and `bulge` (largest distance a
//! curtain vertex was pushed from its rest plane).

#[path = "support/curtain.rs"]
mod curtain;
#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use bevy_rapier3d::prelude::*;
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
            Collider::ball(BALL_RADIUS),
            ColliderMassProperties::Mass(BALL_MASS),
            GravityScale(0.0),
            Velocity::linear(Vec3::new(0.0, 0.0, -SPEED)),
        ));
    }
}

fn measure(
    mut commands: Commands,
    time: Res<Time>,
    balls: Query<(Entity, &Ball, &Velocity)>,
    cloths: Query<&ClothSim>,
    mut stats: ResMut<Stats>,
) {
    let balls = balls.iter().map(|(e, b, v)| (e, b, v.linear.length()));
    curtain::measure(&mut commands, &time, balls, &cloths, &mut stats);
}

fn main() {
    let args = Args::parse(include_str!("rapier_curtain.rs"));
    let mut app = curtain::app(&args, "bevy_cloth: rapier curtain");
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
    .add_systems(FixedUpdate, (throw, measure));
    support::run(app, &args, |world| curtain::report(world, "rapier_curtain"));
}
