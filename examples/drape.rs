//! Four cloths fall onto a sphere, a box, a capsule and a lumpy 20 480-triangle mesh baked
//! into a signed distance field, then settle on the floor around them.
//!
//! ```text
//! cargo run --release --example drape
//! cargo run --release --example drape -- --headless --frames 300
//! ```
//! The JSON line gives `max_penetration` (metres below any collider surface) and the mesh's
//! triangle count.

#[path = "support/mod.rs"]
mod support;

use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

/// An icosphere of 20 480 triangles with smooth bumps: a stand-in for a scanned model.
fn lumpy_mesh() -> Mesh {
    let mut mesh = Sphere::new(0.45).mesh().ico(5).expect("ico sphere");
    if let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
    {
        for v in p.iter_mut() {
            let q = Vec3::from(*v);
            let bump = 1.0 + 0.18 * (4.0 * q.x).sin() * (5.0 * q.y).sin() * (3.0 * q.z + 1.0).sin();
            *v = (q * bump).to_array();
        }
    }
    mesh.compute_smooth_normals();
    mesh
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let obstacles: [(ClothCollider, Mesh, Vec3); 4] = [
        (
            ClothCollider::sphere(0.45),
            Sphere::new(0.45).mesh().build(),
            Vec3::new(-3.0, 0.6, 0.0),
        ),
        (
            ClothCollider::cuboid(Vec3::new(0.4, 0.3, 0.4)),
            Cuboid::new(0.8, 0.6, 0.8).mesh().build(),
            Vec3::new(-1.0, 0.3, 0.0),
        ),
        (
            ClothCollider::capsule(0.25, 0.7),
            Capsule3d::new(0.25, 0.7).mesh().build(),
            Vec3::new(1.0, 0.5, 0.0),
        ),
        (
            ClothCollider::mesh(48),
            lumpy_mesh(),
            Vec3::new(3.0, 0.55, 0.0),
        ),
    ];
    let grid = Grid::new(32, 32, 1.6, 1.6);
    let cloth_mesh = meshes.add(grid_mesh(&grid));
    let colors = [
        Color::srgb(0.8, 0.25, 0.2),
        Color::srgb(0.2, 0.5, 0.8),
        Color::srgb(0.85, 0.7, 0.2),
        Color::srgb(0.3, 0.7, 0.4),
    ];
    for (k, (collider, mesh, at)) in obstacles.into_iter().enumerate() {
        let rotation = if k == 2 {
            Quat::from_rotation_z(core::f32::consts::FRAC_PI_2)
        } else {
            Quat::IDENTITY
        };
        let obstacle = commands
            .spawn((
                collider.with_thickness(0.015),
                Mesh3d(meshes.add(mesh)),
                Transform::from_translation(at).with_rotation(rotation),
            ))
            .id();
        let cloth = commands
            .spawn((
                Mesh3d(cloth_mesh.clone()),
                Transform::from_translation(at + Vec3::new(0.05, 1.2, -0.04))
                    .with_rotation(Quat::from_rotation_y(0.3)),
                Cloth {
                    mass: 0.4,
                    ..default()
                },
                ClothConfig {
                    substeps: 12,
                    ..default()
                },
            ))
            .id();
        if let Some(materials) = materials.as_deref_mut() {
            commands
                .entity(obstacle)
                .insert(MeshMaterial3d(materials.add(Color::srgb(0.75, 0.75, 0.72))));
            commands.entity(cloth).insert(support::ClothLook(colors[k]));
        }
    }
    commands.spawn(ClothCollider::plane().with_thickness(0.01));
    if let Some(mut materials) = materials {
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(0.0, 3.5, 6.5),
            Vec3::new(0.0, 0.4, 0.0),
        );
    }
}

fn report(world: &mut World) -> support::Json {
    let depth = support::max_penetration(world);
    let unread = support::gpu_state_unread(world);
    support::cloth_report(world)
        .str("example", "drape")
        .measured("max_penetration", depth, unread)
        .num("sdf_mesh_triangles", 20480.0)
}

fn main() {
    let args = Args::parse(include_str!("drape.rs"));
    let mut app = support::app(&args, "bevy_cloth: drape", 1.0 / 60.0);
    app.add_systems(Startup, setup);
    support::run(app, &args, report);
}
