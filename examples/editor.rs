//! The cloth editor on a small scene: a flag on a pole in a wind zone, a sheet falling onto a
//! ball and a box, a floor. Every part is editable in the panel (F2 hides it): sliders for
//! every setting, pins (click the cloth, or a preset, then "update pins"), add and delete
//! objects, drag the selected object's arrows (drag the pole and the flag follows), save and
//! load the scene.
//!
//! ```text
//! cargo run --release --features editor --example editor
//! cargo run --release --features editor --example editor -- --headless --frames 120
//! cargo run --release --features editor --example editor -- --mesh-cloth banner_statue.gltf#Mesh1/Primitive0
//! ```
//! Right mouse + WASD/QE flies the camera. `--mesh-cloth PATH` adds a cloth made from a mesh
//! file in the asset folder (as the panel's "add mesh cloth" does: hung by its top edge once
//! it has loaded).

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::editor::{ClothEditor, EditorShape, actions};
use bevy_cloth::prelude::*;
use support::Args;

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let grey = |materials: &mut Option<ResMut<Assets<StandardMaterial>>>, c: Color| {
        materials.as_deref_mut().map(|m| MeshMaterial3d(m.add(c)))
    };
    let mut materials = materials;
    // The pole: a thin capsule collider. The flag's hoist is pinned to it, so dragging the
    // pole's arrows carries the flag.
    let pole_at = Vec3::new(-1.6, 2.0, 0.0);
    let pole_shape = ClothCollider::capsule(0.04, 4.0);
    let mut pole = commands.spawn((
        Name::new("Pole"),
        pole_shape,
        EditorShape,
        Mesh3d(meshes.add(Capsule3d::new(0.04, 4.0))),
        Transform::from_translation(pole_at),
    ));
    if let Some(m) = grey(&mut materials, Color::srgb(0.6, 0.6, 0.62)) {
        pole.insert(m);
    }
    let pole = pole.id();
    // The flag: 2.4 m × 1.6 m, standing in XY (a grid lies in XZ; a quarter turn about X),
    // its hoist (column 0) on the pole.
    let grid = Grid::new(36, 24, 2.4, 1.6);
    let flag_at = Transform::from_xyz(pole_at.x + 0.05 + grid.width / 2.0, 3.2, 0.0)
        .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2));
    let positions = grid.positions();
    let hoist = (0..grid.rows).map(|j| {
        let v = grid.index(0, j);
        let world = flag_at.transform_point(positions[v as usize]);
        ClothPin {
            vertex: v,
            anchor: PinAnchor::Entity {
                entity: pole,
                offset: world - pole_at,
            },
        }
    });
    let mut flag = commands.spawn((
        Name::new("Flag"),
        Mesh3d(meshes.add(grid_mesh(&grid))),
        flag_at,
        Cloth {
            mass: 0.3,
            ..default()
        },
        ClothConfig {
            substeps: 12,
            ..default()
        },
        ClothPins(hoist.collect()),
    ));
    if materials.is_some() {
        flag.insert(support::ClothLook(Color::srgb(0.1, 0.25, 0.7)));
    }
    // A sheet dropped on a ball and a box.
    let sheet = Grid::new(28, 28, 1.6, 1.6);
    let mut cloth = commands.spawn((
        Name::new("Sheet"),
        Mesh3d(meshes.add(grid_mesh(&sheet))),
        Transform::from_xyz(2.05, 1.2, 0.65).with_rotation(Quat::from_rotation_y(0.4)),
        Cloth {
            mass: 0.3,
            ..default()
        },
    ));
    if materials.is_some() {
        cloth.insert(support::ClothLook(Color::srgb(0.75, 0.22, 0.2)));
    }
    for (name, collider, mesh, at) in [
        (
            "Ball",
            ClothCollider::sphere(0.45),
            Sphere::new(0.45).mesh().ico(4).expect("ico sphere"),
            Vec3::new(2.0, 0.45, 0.6),
        ),
        (
            "Box",
            ClothCollider::cuboid(Vec3::new(0.35, 0.3, 0.35)),
            Cuboid::new(0.7, 0.6, 0.7).mesh().build(),
            Vec3::new(2.9, 0.3, 1.1),
        ),
    ] {
        let mut e = commands.spawn((
            Name::new(name),
            collider.with_thickness(0.015),
            EditorShape,
            Mesh3d(meshes.add(mesh)),
            Transform::from_translation(at),
        ));
        if let Some(m) = grey(&mut materials, Color::srgb(0.75, 0.75, 0.72)) {
            e.insert(m);
        }
    }
    commands.spawn((
        Name::new("Floor"),
        ClothCollider::plane().with_thickness(0.01),
    ));
    // Wind only inside this box, around the flag.
    commands.spawn((
        Name::new("Breeze"),
        WindZone {
            wind: WindParams {
                velocity: Vec3::new(6.0, 0.0, 1.0),
                ..default()
            },
            half_extents: Vec3::new(1.7, 0.9, 1.0),
            falloff: 0.5,
        },
        Transform::from_xyz(-0.5, 2.7, 0.0),
    ));
    if let Some(mut materials) = materials {
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(-0.6, 2.6, 7.6),
            Vec3::new(-0.1, 1.5, 0.0),
        );
    }
}

/// Starts with the pole selected, so its arrows are there to drag.
fn select_pole(mut editor: ResMut<ClothEditor>, names: Query<(Entity, &Name)>) {
    editor.selected = names
        .iter()
        .find(|(_, n)| n.as_str() == "Pole")
        .map(|(e, _)| e);
}

/// The `--mesh-cloth` file, if one was given.
#[derive(Resource)]
struct MeshCloth(String);

fn add_mesh_cloth(world: &mut World) {
    let Some(path) = world.remove_resource::<MeshCloth>() else {
        return;
    };
    if let Err(why) = actions::add_mesh_cloth(world, &path.0) {
        eprintln!("--mesh-cloth: {why}");
        std::process::exit(2);
    }
}

fn report(world: &mut World) -> support::Json {
    let objects = world
        .query_filtered::<(), Or<(With<Cloth>, With<ClothCollider>, With<WindZone>)>>()
        .iter(world)
        .count();
    let open = world.resource::<ClothEditor>().open;
    support::cloth_report(world)
        .str("example", "editor")
        .num("objects", objects as f64)
        .num("panel_open", f64::from(u8::from(open)))
}

fn main() {
    let args = Args::parse(include_str!("editor.rs"));
    let mut app = support::app(&args, "bevy_cloth editor", 1.0 / 60.0);
    // The panel's mesh files (and `--mesh-cloth`) load with `--headless` too.
    support::add_gltf_support(&mut app);
    let mesh_cloth: String = args.get("mesh-cloth", String::new());
    if !mesh_cloth.is_empty() {
        app.insert_resource(MeshCloth(mesh_cloth));
    }
    app.add_plugins(ClothEditorPlugin::default())
        .add_systems(Startup, setup)
        .add_systems(PostStartup, (select_pole, add_mesh_cloth));
    support::run(app, &args, report);
}
