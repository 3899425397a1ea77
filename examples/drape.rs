//! Four cloths fall onto a sphere, a box, a capsule and a lumpy 20 480-triangle mesh baked
//! into a signed distance field, then settle on the floor around them.
//!
//! `--terrain` drops three cloths on hills instead: Bevy's `Plane3d`, subdivided and raised
//! into a terrain, an open mesh with no underside, as a mesh collider (cloth is kept on the
//! side its triangles face).
//!
//! ```text
//! cargo run --release --example drape
//! cargo run --release --example drape -- --headless --frames 300
//! cargo run --release --example drape -- --terrain
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

/// The cloth settings of every dropped cloth: 0.4 kg, 12 substeps.
fn falling_cloth() -> (Cloth, ClothConfig) {
    (
        Cloth {
            mass: 0.4,
            ..default()
        },
        ClothConfig {
            substeps: 12,
            ..default()
        },
    )
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
                falling_cloth(),
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

/// Height of the `--terrain` hills at `(x, z)`: rolling hills and a narrow ridge along z.
fn hills(x: f32, z: f32) -> f32 {
    let ridge = 0.5 * (-(x - 0.2) * (x - 0.2) / 0.06).exp();
    0.5 + 0.35 * (0.9 * x).sin() * (0.7 * z).cos() + 0.15 * (1.7 * x + 0.4 * z).cos() + ridge
}

/// Subdivisions of the terrain's plane along each side.
const TERRAIN_SUBDIVISIONS: u32 = 80;

/// The `--terrain` scene: an 8 × 8 m hilly `Plane3d` as a mesh collider, three cloths over it.
fn terrain_setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let mut ground = Plane3d::default()
        .mesh()
        .size(8.0, 8.0)
        .subdivisions(TERRAIN_SUBDIVISIONS)
        .build();
    if let Some(VertexAttributeValues::Float32x3(p)) =
        ground.attribute_mut(Mesh::ATTRIBUTE_POSITION)
    {
        for v in p.iter_mut() {
            v[1] = hills(v[0], v[2]);
        }
    }
    ground.compute_smooth_normals();
    let terrain = commands
        .spawn((
            Mesh3d(meshes.add(ground)),
            Transform::default(),
            // An open mesh: baked with its triangles' side as the outside.
            ClothCollider::mesh(128).with_thickness(0.015),
        ))
        .id();
    let grid = Grid::new(32, 32, 1.6, 1.6);
    let cloth_mesh = meshes.add(grid_mesh(&grid));
    let drops = [
        (Vec3::new(-2.0, 2.0, -1.0), Color::srgb(0.8, 0.25, 0.2)),
        (Vec3::new(0.2, 2.0, 1.0), Color::srgb(0.2, 0.5, 0.8)),
        (Vec3::new(2.1, 2.0, -0.6), Color::srgb(0.85, 0.7, 0.2)),
    ];
    for (k, (at, color)) in drops.into_iter().enumerate() {
        let cloth = commands
            .spawn((
                Mesh3d(cloth_mesh.clone()),
                Transform::from_translation(at)
                    .with_rotation(Quat::from_rotation_y(0.3 + k as f32)),
                falling_cloth(),
            ))
            .id();
        if materials.is_some() {
            commands.entity(cloth).insert(support::ClothLook(color));
        }
    }
    if let Some(mut materials) = materials {
        commands
            .entity(terrain)
            .insert(MeshMaterial3d(materials.add(Color::srgb(0.45, 0.55, 0.3))));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(0.0, 4.0, 6.5),
            Vec3::new(0.0, 0.6, 0.0),
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

/// The `--terrain` report: the deepest penetration, and how far the lowest and highest cloth
/// vertex lie over the hills under them.
fn terrain_report(world: &mut World) -> support::Json {
    let depth = support::max_penetration(world);
    let unread = support::gpu_state_unread(world);
    let (mut lowest, mut highest) = (f32::MAX, f32::MIN);
    let mut q = world.query::<&ClothSim>();
    for c in q.iter(world) {
        let s = c.simulation().state();
        for i in 0..s.len() {
            let p = s.position(i);
            let over = p.y - hills(p.x, p.z);
            lowest = lowest.min(over);
            highest = highest.max(over);
        }
    }
    support::cloth_report(world)
        .str("example", "drape --terrain")
        .measured("max_penetration", depth, unread)
        .measured("lowest_over_hills", lowest, unread)
        .measured("highest_over_hills", highest, unread)
        .num("terrain_triangles", 2 * (TERRAIN_SUBDIVISIONS + 1).pow(2))
}

fn main() {
    let args = Args::parse(include_str!("drape.rs"));
    let mut app = support::app(&args, "bevy_cloth: drape", 1.0 / 60.0);
    if args.rest.contains_key("terrain") {
        app.add_systems(Startup, terrain_setup);
        support::run(app, &args, terrain_report);
    } else {
        app.add_systems(Startup, setup);
        support::run(app, &args, report);
    }
}
