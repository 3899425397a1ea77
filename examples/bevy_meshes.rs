//! Cloth from Bevy's own meshes, pinned by rule: no vertex index is written anywhere.
//!
//! A `Plane3d` stood up as a flag, pinned along its -X edge (`VertexSelection::Farthest`); an
//! uncapped `Cylinder` (a lamp shade, a skirt) hung by its top ring; and a `Plane3d` banner
//! whose top corners are painted red in its vertex colours, as a modelling tool would paint
//! them into glTF `COLOR_0`, pinned where it is painted (`VertexSelection::Painted`). Press
//! Space to pin the flag by its top edge instead (the rule changed at runtime).
//!
//! ```text
//! cargo run --release --example bevy_meshes
//! cargo run --release --example bevy_meshes -- --headless --frames 300
//! ```
//! The JSON line adds how many vertices each rule pinned, each cloth's lowest point and its
//! largest strain.

#[path = "support/mod.rs"]
mod support;

use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

/// Which cloth an entity is, for the report.
#[derive(Component, Clone, Copy)]
enum Piece {
    Flag,
    Tube,
    Painted,
}

/// A plane with its two -Z corners painted red, the rest grey.
fn painted_plane() -> Mesh {
    let mut mesh = Plane3d::default()
        .mesh()
        .size(1.0, 1.4)
        .subdivisions(22)
        .build();
    let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute(Mesh::ATTRIBUTE_POSITION) else {
        unreachable!("Bevy's plane has positions");
    };
    let paint: Vec<[f32; 4]> = p
        .iter()
        .map(|&[x, _, z]| {
            // The corner vertex only (the grid's spacing is over 4 cm).
            let near = |a: f32, b: f32| (a - b).abs() < 0.01;
            if near(z, -0.7) && (near(x, -0.5) || near(x, 0.5)) {
                [1.0, 0.0, 0.0, 1.0]
            } else {
                [0.3, 0.3, 0.3, 1.0]
            }
        })
        .collect();
    mesh.insert_attribute(Mesh::ATTRIBUTE_COLOR, paint);
    mesh
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let config = ClothConfig {
        substeps: 12,
        ..default()
    };
    // Bevy's plane lies in XZ, its front up: turned 90° about X it stands in XY, its -Z edge
    // on top.
    let stand_up = Quat::from_rotation_x(core::f32::consts::FRAC_PI_2);
    let edge = |towards| VertexSelection::Farthest {
        towards,
        within: 0.0,
    };
    let painted = VertexSelection::Painted {
        channel: ColorChannel::Red,
        at_least: 0.5,
    };
    let pieces = [
        (
            Piece::Flag,
            meshes.add(Plane3d::default().mesh().size(1.6, 1.0).subdivisions(30)),
            Transform::from_xyz(-1.4, 2.6, 0.0).with_rotation(stand_up),
            0.3,
            edge(Vec3::NEG_X),
            Color::srgb(0.75, 0.2, 0.15),
        ),
        (
            Piece::Tube,
            meshes.add(
                Cylinder::new(0.35, 0.9)
                    .mesh()
                    .resolution(32)
                    .segments(12)
                    .without_caps(),
            ),
            Transform::from_xyz(0.6, 2.0, 0.0),
            0.8,
            edge(Vec3::Y),
            Color::srgb(0.85, 0.7, 0.25),
        ),
        (
            Piece::Painted,
            meshes.add(painted_plane()),
            Transform::from_xyz(2.3, 1.9, 0.0).with_rotation(stand_up),
            0.3,
            painted,
            Color::srgb(0.2, 0.45, 0.8),
        ),
    ];
    for (piece, mesh, at, mass, select, color) in pieces {
        let mut cloth = commands.spawn((
            piece,
            Mesh3d(mesh),
            at,
            Cloth { mass, ..default() },
            config,
            ClothPinRule::rest(select),
        ));
        if materials.is_some() {
            cloth.insert(support::ClothLook(color));
        }
    }
    commands.spawn(ClothCollider::plane().with_thickness(0.01));
    if let Some(mut materials) = materials {
        let metal = materials.add(Color::srgb(0.6, 0.6, 0.62));
        commands.spawn((
            Mesh3d(meshes.add(Cylinder::new(0.03, 3.0))),
            MeshMaterial3d(metal.clone()),
            Transform::from_xyz(-2.23, 1.5, 0.0),
        ));
        // The bar the banner's corners hang from.
        commands.spawn((
            Mesh3d(meshes.add(Cylinder::new(0.02, 1.2))),
            MeshMaterial3d(metal),
            Transform::from_xyz(2.3, 2.62, 0.0)
                .with_rotation(Quat::from_rotation_z(core::f32::consts::FRAC_PI_2)),
        ));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(0.4, 2.2, 5.5),
            Vec3::new(0.4, 1.5, 0.0),
        );
    }
}

/// Space: the flag's rule changes to its top edge (and back).
fn toggle_flag(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut flags: Query<(&Piece, &mut ClothPinRule)>,
) {
    if !keys.is_some_and(|k| k.just_pressed(KeyCode::Space)) {
        return;
    }
    for (piece, mut rule) in &mut flags {
        if let (Piece::Flag, VertexSelection::Farthest { towards, .. }) = (piece, rule.select) {
            // The mesh's -Z side is the top once it is stood up.
            let next = if towards == Vec3::NEG_X {
                Vec3::NEG_Z
            } else {
                Vec3::NEG_X
            };
            *rule = ClothPinRule::rest(VertexSelection::Farthest {
                towards: next,
                within: 0.0,
            });
        }
    }
}

fn report(world: &mut World) -> support::Json {
    let mut q = world.query::<(&Piece, &ClothPins, Option<&ClothSim>)>();
    let mut json = support::cloth_report(world).str("example", "bevy_meshes");
    let rows: Vec<(Piece, usize, f32, f32)> = q
        .iter(world)
        .map(|(piece, pins, sim)| {
            let lowest = sim.map_or(f32::NAN, |sim| {
                let n = sim.weld().vertex_count() as u32;
                (0..n).map(|v| sim.position(v).y).fold(f32::MAX, f32::min)
            });
            let strain = sim.map_or(f32::NAN, ClothSim::max_strain);
            (*piece, pins.0.len(), lowest, strain)
        })
        .collect();
    let unread = support::gpu_state_unread(world);
    for (piece, pinned, lowest, strain) in rows {
        let name = match piece {
            Piece::Flag => "flag",
            Piece::Tube => "tube",
            Piece::Painted => "painted",
        };
        json = json
            .num(&format!("{name}_pinned"), pinned as f64)
            .measured(&format!("{name}_lowest"), lowest, unread)
            .measured(&format!("{name}_strain"), strain, unread);
    }
    json
}

fn main() {
    let args = Args::parse(include_str!("bevy_meshes.rs"));
    let mut app = support::app(
        &args,
        "bevy_cloth: Bevy's meshes, pinned by rule",
        1.0 / 60.0,
    );
    app.insert_resource(Wind(WindParams {
        velocity: Vec3::new(3.5, 0.0, -1.0),
        ..default()
    }))
    .add_systems(Startup, setup)
    .add_systems(Update, toggle_flag);
    support::run(app, &args, report);
}
