//! Self-collision: a long strip dropped end-first onto the floor folds and piles up on itself
//! without passing through itself (`ClothSelfCollision`).
//!
//! ```text
//! cargo run --release --example self_collision
//! cargo run --release --example self_collision -- --headless --frames 240
//! cargo run --release --example self_collision -- --headless --frames 240 --off   # for comparison
//! ```
//! The JSON line adds `crossings` (edge–triangle pairs of the strip that cross at the end),
//! `max_crossings` over the run and `asleep_after_steps`, the fixed step at which the pile
//! came to rest and fell asleep (−1: still awake).

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

#[derive(Resource, Default)]
struct Crossings {
    now: usize,
    max: usize,
    /// The cloth's step count when it was first seen asleep.
    asleep_after: Option<u64>,
}

#[derive(Resource)]
struct Off(bool);

fn setup(
    mut commands: Commands,
    off: Res<Off>,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let grid = Grid::new(12, 60, 0.5, 3.0);
    let mut strip = commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        // Stood almost upright, its lower end just above the floor.
        Transform::from_xyz(0.0, 1.56, 0.0)
            .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2 * 0.96)),
        Cloth {
            mass: 0.3,
            ..default()
        },
        ClothConfig {
            substeps: 12,
            ..default()
        },
    ));
    if !off.0 {
        // Without friction between its layers (the default) this strip settles within a
        // few seconds; with it (0.2 here before) parts of it kept moving for about ten.
        strip.insert(ClothSelfCollision::default());
    }
    if let Some(mut m) = materials {
        strip.insert(support::ClothLook(Color::srgb(0.3, 0.3, 0.75)));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut m,
            Vec3::new(2.5, 1.5, 2.5),
            Vec3::new(0.0, 0.2, 0.0),
        );
    }
    commands.spawn(
        ClothCollider::plane()
            .with_thickness(0.005)
            .with_friction(0.6),
    );
}

fn measure(cloths: Query<&ClothSim>, mut c: ResMut<Crossings>) {
    for sim in &cloths {
        c.now = sim.simulation().self_crossings();
        c.max = c.max.max(c.now);
        if sim.is_sleeping() && c.asleep_after.is_none() {
            c.asleep_after = Some(sim.steps());
        }
    }
}

fn report(world: &mut World) -> support::Json {
    let (now, max, asleep_after) = {
        let c = world.resource::<Crossings>();
        (c.now, c.max, c.asleep_after)
    };
    let on = !world.resource::<Off>().0;
    let unread = support::gpu_state_unread(world);
    support::cloth_report(world)
        .str("example", "self_collision")
        .num("self_collision", if on { 1.0 } else { 0.0 })
        .measured("crossings", now as f64, unread)
        .measured("max_crossings", max as f64, unread)
        .num(
            "asleep_after_steps",
            asleep_after.map_or(-1.0, |steps| steps as f64),
        )
}

fn main() {
    let args = Args::parse(include_str!("self_collision.rs"));
    let mut app = support::app(&args, "bevy_cloth: self-collision", 1.0 / 60.0);
    app.insert_resource(Off(args.rest.contains_key("off")))
        .init_resource::<Crossings>()
        .add_systems(Startup, setup)
        .add_systems(FixedPostUpdate, measure.after(ClothSystems::Simulate));
    support::run(app, &args, report);
}
