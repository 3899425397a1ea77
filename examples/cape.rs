//! A cape and a skirt on an animated, skinned character walking (or running) a loop.
//!
//! The character is `assets/character.gltf` (written by the `make_character` example): a
//! skinned humanoid with 13 bones and a `Walk` and a `Run` animation, loaded through the
//! `AssetServer` as a scene and played by Bevy's animation system. The cape's top edge is
//! pinned to the `Chest` bone (`PinAnchor::Entity` with an offset in the bone's frame), the
//! torso carries box colliders and the limbs capsules, each a child entity of its bone, and
//! tethers keep the cape from stretching like rubber. The skirt is part of the glTF, skinned
//! to the hips and thighs: `ClothSkinning` keeps each of its vertices within the max distance
//! painted in its vertex colours (0 at the waist, 15 cm at the hem) of where the animated
//! skin puts it, and the thigh capsules keep it off the legs. `ClothAnimationPlugin` advances the
//! animation on the cloth's fixed clock, so every fixed step's pins and colliders are that
//! step's bone poses, at any frame rate.
//!
//! ```text
//! cargo run --release --features animation --example cape
//! cargo run --release --features animation --example cape -- --speed 4.5         # runs
//! cargo run --release --features animation --example cape -- --headless --frames 600 --fps 30
//! ```
//! `--speed M/S` sets the speed along the loop (default 1.4; above 2.5 the character runs);
//! `--inertia X` gives the cape a `ClothInertia` of `X` relative to the character;
//! `--self-collision` gives the cape and the skirt `ClothSelfCollision::default()`; `--fps N`
//! (headless) sets the frame rate the app runs at (the cloth and the animation step at 60 Hz
//! whatever it is); `--per-frame-animation` leaves Bevy's animation once a frame, to compare.
//! `--walk-in-update` moves the character in `Update`, as many games do, instead of on the
//! fixed clock: the cape's pins then read it a frame late (see `pin_error`), unless
//! `--cloth-in-post-update` also simulates the cloth once a frame after `Update`
//! (`ClothPlugins::new(PostUpdate)`).
//! The JSON line adds `pin_error` (largest distance, over every frame after the first
//! second, between a pinned vertex and where its bone is drawn), `penetration` (deepest cape
//! vertex inside a body collider over every step after the first second), `colliders`,
//! `touching_steps` (steps in which a cloth touched the body), `cape_crossings` and
//! `skirt_crossings` (most edge–triangle pairs of each cloth crossing each other after any
//! step after the first second: the cloth passing through itself; 0 with self-collision
//! that holds), `cape_strain` and `skirt_strain` (largest edge strain after the first
//! second), `gait`, and for the skirt
//! `skirt_over_max_distance` (farthest any skirt vertex got past its max distance from the
//! skin, after the first second; a collider pushing it counts) and `skirt_penetration`
//! (deepest skirt vertex inside a body collider after the first second). With `--backend
//! gpu` the cloths' state is read back a few frames late, so these figures then measure that
//! lag, not the simulation; in a window nothing is read back and they are `null`.

#[path = "support/mod.rs"]
mod support;

use std::time::Duration;

use bevy::animation::{AnimationPlayer, graph::AnimationGraph, graph::AnimationGraphHandle};
use bevy::ecs::schedule::ScheduleLabel;
use bevy::gltf::GltfAssetLabel;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy::world_serialization::{WorldAssetRoot, WorldInstanceReady};
use bevy_cloth::prelude::*;
use support::Args;

const CHARACTER: &str = "character.gltf";
/// Radius of the loop the character walks (metres).
const LOOP: f32 = 3.0;
const COLUMNS: u32 = 16;
const ROWS: u32 = 20;

/// The character's root: it walks the loop; the glTF scene hangs below it.
#[derive(Component)]
struct Walker {
    speed: f32,
}

/// `--speed`, `--inertia`, `--self-collision`.
#[derive(Resource)]
struct Options {
    speed: f32,
    inertia: Option<f32>,
    self_collision: bool,
}

impl Options {
    /// Runs above 2.5 m/s. A walk cycle covers 1.4 m in 1 s, a run cycle 2.4 m in 0.6 s: the
    /// animation plays faster or slower so the feet keep pace with the ground.
    fn gait(&self) -> (&'static str, usize, f32) {
        if self.speed > 2.5 {
            ("run", 1, self.speed / 4.0)
        } else {
            ("walk", 0, self.speed / 1.4)
        }
    }
}

/// What the run measured, every fixed step.
#[derive(Resource, Default, Clone)]
struct Measured {
    pin_error: f32,
    penetration: f32,
    steps: u32,
    colliders: usize,
    touching_steps: u32,
    cape_crossings: usize,
    cape_strain: f32,
    skirt_crossings: usize,
    skirt_strain: f32,
    skirt_over: f32,
    skirt_penetration: f32,
    skirt_steps: u32,
}

/// Marks the cape.
#[derive(Component)]
struct Cape;

/// Marks the skirt.
#[derive(Component)]
struct Skirt;

/// Where the character starts: on the loop, facing along it.
fn start_pose(speed: f32, t: f32) -> Transform {
    let angle = t * speed / LOOP;
    let (s, c) = angle.sin_cos();
    let forward = Vec3::new(-s, 0.0, c);
    // The model faces its +z: `looking_to(-forward)` turns its +z along the path.
    Transform::from_xyz(LOOP * c, 0.0, LOOP * s).looking_to(-forward, Vec3::Y)
}

fn setup(
    mut commands: Commands,
    assets: Res<AssetServer>,
    options: Res<Options>,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    if let Some(mut m) = materials {
        support::stage(
            &mut commands,
            &mut meshes,
            &mut m,
            Vec3::new(0.0, 1.9, 7.0),
            Vec3::new(0.0, 0.9, 1.5),
        );
    }
    commands
        .spawn((
            Walker {
                speed: options.speed,
            },
            start_pose(options.speed, 0.0),
            WorldAssetRoot(assets.load(GltfAssetLabel::Scene(0).from_asset(CHARACTER))),
            Name::new("Walker"),
        ))
        .observe(dress);
}

/// Walks the loop on the fixed clock (the cloth's), facing along it.
fn walk(time: Res<Time>, mut walkers: Query<(&Walker, &mut Transform)>) {
    for (w, mut t) in &mut walkers {
        *t = start_pose(w.speed, time.elapsed_secs());
    }
}

/// The body's colliders: bone, centre and shape in the character's rest frame (the bones'
/// rest rotations are the identity, so a bone's frame is the character's moved to the bone).
fn body_colliders() -> [(&'static str, Vec3, ClothCollider); 13] {
    let limb = |r: f32, len: f32| ClothCollider::capsule(r, len).with_thickness(0.015);
    let block = |h: Vec3| ClothCollider::cuboid(h).with_thickness(0.015);
    [
        (
            "Hips",
            Vec3::new(0.0, 0.95, 0.0),
            block(Vec3::new(0.17, 0.09, 0.1)),
        ),
        (
            "Spine",
            Vec3::new(0.0, 1.15, 0.0),
            block(Vec3::new(0.15, 0.1, 0.09)),
        ),
        (
            "Chest",
            Vec3::new(0.0, 1.37, 0.0),
            block(Vec3::new(0.19, 0.13, 0.11)),
        ),
        (
            "Head",
            Vec3::new(0.0, 1.7, 0.01),
            ClothCollider::sphere(0.13).with_thickness(0.015),
        ),
        ("Neck", Vec3::new(0.0, 1.54, 0.0), limb(0.05, 0.04)),
        ("UpperArm.L", Vec3::new(0.26, 1.33, 0.0), limb(0.05, 0.2)),
        ("Forearm.L", Vec3::new(0.26, 1.05, 0.0), limb(0.045, 0.19)),
        ("UpperArm.R", Vec3::new(-0.26, 1.33, 0.0), limb(0.05, 0.2)),
        ("Forearm.R", Vec3::new(-0.26, 1.05, 0.0), limb(0.045, 0.19)),
        ("Thigh.L", Vec3::new(0.1, 0.71, 0.0), limb(0.07, 0.28)),
        ("Shin.L", Vec3::new(0.1, 0.27, 0.0), limb(0.06, 0.34)),
        ("Thigh.R", Vec3::new(-0.1, 0.71, 0.0), limb(0.07, 0.28)),
        ("Shin.R", Vec3::new(-0.1, 0.27, 0.0), limb(0.06, 0.34)),
    ]
}

/// Rest positions of the bones the example uses (as `make_character` writes them).
fn bone_rest(name: &str) -> Option<Vec3> {
    Some(match name {
        "Hips" => Vec3::new(0.0, 0.95, 0.0),
        "Spine" => Vec3::new(0.0, 1.08, 0.0),
        "Chest" => Vec3::new(0.0, 1.26, 0.0),
        "Neck" => Vec3::new(0.0, 1.52, 0.0),
        "Head" => Vec3::new(0.0, 1.6, 0.0),
        "UpperArm.L" => Vec3::new(0.24, 1.47, 0.0),
        "Forearm.L" => Vec3::new(0.24, 1.18, 0.0),
        "UpperArm.R" => Vec3::new(-0.24, 1.47, 0.0),
        "Forearm.R" => Vec3::new(-0.24, 1.18, 0.0),
        "Thigh.L" => Vec3::new(0.1, 0.92, 0.0),
        "Shin.L" => Vec3::new(0.1, 0.5, 0.0),
        "Thigh.R" => Vec3::new(-0.1, 0.92, 0.0),
        "Shin.R" => Vec3::new(-0.1, 0.5, 0.0),
        _ => return None,
    })
}

/// Once the character's scene is in the world: play its animation, put colliders on its
/// bones and hang the cape from its chest.
#[expect(clippy::too_many_arguments, reason = "a one-off setup observer")]
fn dress(
    ready: On<WorldInstanceReady>,
    mut commands: Commands,
    children: Query<&Children>,
    names: Query<&Name>,
    mut players: Query<&mut AnimationPlayer>,
    skinned: Query<(), With<bevy::mesh::skinning::SkinnedMesh>>,
    walkers: Query<&Transform, With<Walker>>,
    assets: Res<AssetServer>,
    mut graphs: ResMut<Assets<AnimationGraph>>,
    mut meshes: ResMut<Assets<Mesh>>,
    options: Res<Options>,
) {
    let root = ready.entity;
    let bone = |name: &str| {
        children
            .iter_descendants(root)
            .find(|&e| names.get(e).is_ok_and(|n| n.as_str() == name))
    };
    // The animation: the gait for the speed, looping.
    let (_, clip, rate) = options.gait();
    let (graph, node) = AnimationGraph::from_clip(
        assets.load(GltfAssetLabel::Animation(clip).from_asset(CHARACTER)),
    );
    let graph = graphs.add(graph);
    for e in children.iter_descendants(root) {
        if let Ok(mut player) = players.get_mut(e) {
            player.play(node).repeat().set_speed(rate);
            commands
                .entity(e)
                .insert(AnimationGraphHandle(graph.clone()));
        }
    }
    // Colliders on the bones.
    for (name, centre, collider) in body_colliders() {
        let (Some(b), Some(rest)) = (bone(name), bone_rest(name)) else {
            error!("{CHARACTER} has no bone {name}: run `cargo run --example make_character`");
            continue;
        };
        let child = commands
            .spawn((collider, Transform::from_translation(centre - rest)))
            .id();
        commands.entity(b).add_child(child);
    }
    // The skirt: the glTF's skinned "Skirt" mesh becomes cloth held near its skin.
    let skirt = bone("Skirt").and_then(|node| {
        std::iter::once(node)
            .chain(children.iter_descendants(node))
            .find(|&e| skinned.contains(e))
    });
    match skirt {
        Some(e) => {
            commands.entity(e).insert((
                Cloth {
                    mass: 0.3,
                    ..default()
                },
                ClothConfig {
                    substeps: 10,
                    ..default()
                },
                ClothSkinning {
                    max_distance: MaxDistance::VertexColor { scale: 0.15 },
                    backstop: None,
                },
                Skirt,
            ));
            if options.self_collision {
                commands.entity(e).insert(ClothSelfCollision::default());
            }
        }
        None => {
            error!("{CHARACTER} has no skinned Skirt: run `cargo run --example make_character`")
        }
    }
    // The cape: 0.7 m × 1.0 m down the back from the shoulders, pinned along its top edge to
    // the chest bone.
    let Some(chest) = bone("Chest") else {
        error!("{CHARACTER} has no Chest bone");
        return;
    };
    let Ok(&walker) = walkers.get(root) else {
        return;
    };
    let grid = Grid::new(COLUMNS, ROWS, 0.7, 1.0);
    // In the character's frame: top row along the shoulders, just behind the back (the chest
    // box's back is at z = −0.11), hanging down; grid in XZ, −90° about X stands it up.
    let top = Vec3::new(0.0, 1.48, -0.14);
    let local = Transform::from_translation(top - Vec3::Y * 0.5)
        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let rest = grid.positions();
    let pins = (0..COLUMNS).map(|i| {
        let v = grid.index(i, 0);
        ClothPin {
            vertex: v,
            anchor: PinAnchor::Entity {
                entity: chest,
                offset: local.transform_point(rest[v as usize]) - bone_rest("Chest").unwrap(),
            },
        }
    });
    let mut cape = commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        walker * local,
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
        Cape,
        support::ClothLook(Color::srgb(0.6, 0.08, 0.12)),
    ));
    if let Some(inertia) = options.inertia {
        cape.insert(ClothInertia::new(inertia).relative_to(root));
    }
    if options.self_collision {
        cape.insert(ClothSelfCollision::default());
    }
}

/// How deep the deepest vertex of `s` is inside any of `colliders` (0 if none is).
fn deepest(s: &bevy_cloth::solver::ClothState, colliders: &[bevy_cloth::solver::Collider]) -> f32 {
    colliders
        .iter()
        .flat_map(|c| {
            (0..s.len())
                .map(move |i| -c.shape.distance(c.end.inverse_apply(s.position(i))).0 * c.end.scale)
        })
        .fold(0.0, f32::max)
}

/// Every fixed step, after the cloth stepped: how deep the cape is inside the body, how far
/// the skirt is past its max distances and how deep in the body.
fn measure_step(
    capes: Query<&ClothSim, With<Cape>>,
    skirts: Query<&ClothSim, With<Skirt>>,
    colliders: Res<bevy_cloth::collider::ClothColliders>,
    impulses: Query<&ClothContactImpulse>,
    time: Res<Time>,
    mut measured: ResMut<Measured>,
) {
    if impulses.iter().any(|i| i.linear != Vec3::ZERO) {
        measured.touching_steps += 1;
    }
    for sim in &capes {
        let s = sim.simulation().state();
        if time.elapsed_secs() > 1.0 {
            measured.penetration = measured.penetration.max(deepest(s, &colliders.colliders));
            measured.cape_crossings = measured
                .cape_crossings
                .max(sim.simulation().self_crossings());
            measured.cape_strain = measured.cape_strain.max(sim.max_strain());
        }
        measured.steps += 1;
        measured.colliders = colliders.colliders.len();
    }
    for sim in &skirts {
        let s = sim.simulation().state();
        if time.elapsed_secs() > 1.0
            && let Some(m) = sim.simulation().motion_targets()
        {
            // The targets of the step just taken (its end is the next step's start).
            for (i, t) in m.end.iter().enumerate() {
                let over = s.position(i).distance(t.truncate()) - t.w;
                measured.skirt_over = measured.skirt_over.max(over);
            }
            measured.skirt_penetration = measured
                .skirt_penetration
                .max(deepest(s, &colliders.colliders));
            measured.skirt_crossings = measured
                .skirt_crossings
                .max(sim.simulation().self_crossings());
            measured.skirt_strain = measured.skirt_strain.max(sim.max_strain());
            measured.skirt_steps += 1;
        }
    }
}

/// Every frame, as drawn (after transforms are propagated): how far each pinned vertex is
/// from where its bone is drawn, after the first second.
fn measure_frame(
    capes: Query<(&ClothSim, &ClothPins), With<Cape>>,
    bones: Query<&GlobalTransform>,
    time: Res<Time>,
    mut measured: ResMut<Measured>,
) {
    if time.elapsed_secs() < 1.0 {
        return; // the character's scene loading, the cape hanging itself on
    }
    for (sim, pins) in &capes {
        let s = sim.simulation().state();
        for pin in &pins.0 {
            if let PinAnchor::Entity { entity, offset } = pin.anchor
                && let Ok(at) = bones.get(entity)
            {
                let error = s
                    .position(pin.vertex as usize)
                    .distance(at.transform_point(offset));
                measured.pin_error = measured.pin_error.max(error);
            }
        }
    }
}

fn report(world: &mut World) -> support::Json {
    let gait = world.resource::<Options>().gait().0;
    let m = world.resource::<Measured>().clone();
    // A GPU cloth in a window reads nothing back: its measured figures become `null`.
    let unread = support::gpu_state_unread(world);
    support::cloth_report(world)
        .str("example", "cape")
        .str("gait", gait)
        .num("measured_steps", m.steps)
        .num("colliders", m.colliders as f64)
        .num("touching_steps", m.touching_steps)
        .measured("pin_error", m.pin_error, unread)
        .measured("penetration", m.penetration, unread)
        .measured("cape_crossings", m.cape_crossings as f64, unread)
        .measured("cape_strain", m.cape_strain, unread)
        .measured("skirt_crossings", m.skirt_crossings as f64, unread)
        .measured("skirt_strain", m.skirt_strain, unread)
        .num("skirt_steps", m.skirt_steps)
        .measured("skirt_over_max_distance", m.skirt_over, unread)
        .measured("skirt_penetration", m.skirt_penetration, unread)
}

fn main() {
    let args = Args::parse(include_str!("cape.rs"));
    let schedule = if args.rest.contains_key("cloth-in-post-update") {
        PostUpdate.intern()
    } else {
        FixedPostUpdate.intern()
    };
    let mut app = support::app_simulating_in(&args, "bevy_cloth: cape", 1.0 / 60.0, schedule);
    // A skinned glTF scene and its animations, also without a renderer.
    support::add_gltf_support(&mut app);
    if args.headless
        && let Some(fps) = args.rest.get("fps").map(|_| args.get("fps", 60.0f64))
    {
        app.insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
            1.0 / fps,
        )));
    }
    app.insert_resource(Options {
        speed: args.get("speed", 1.4),
        inertia: args.rest.get("inertia").map(|_| args.get("inertia", 1.0)),
        self_collision: args.rest.contains_key("self-collision"),
    })
    .init_resource::<Measured>()
    .add_systems(Startup, setup)
    .add_systems(schedule, measure_step.after(ClothSystems::Simulate))
    .add_systems(Last, measure_frame);
    // `--per-frame-animation` (to compare) leaves Bevy's animation once a frame, in
    // PostUpdate, after the frame's fixed steps.
    if args.rest.contains_key("walk-in-update") {
        app.add_systems(Update, walk);
    } else {
        app.add_systems(FixedUpdate, walk);
    }
    if !args.rest.contains_key("per-frame-animation") {
        app.add_plugins(ClothAnimationPlugin);
    }
    support::run(app, &args, report);
}
