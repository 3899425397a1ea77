//! A large cloth with self-collision falls onto a sphere, a box and a torus mesh (a baked SDF
//! collider) and settles on the floor, stepped on the GPU inside Bevy's render graph (or on
//! the CPU, to compare).
//!
//! ```text
//! cargo run --release --example gpu_cloth                      # 256², GPU
//! cargo run --release --example gpu_cloth -- --size 128 --backend cpu
//! cargo run --release --example gpu_cloth -- --headless --frames 120 --size 64
//! ```
//! `--backend gpu|cpu|auto` (default gpu); `--headless` runs with a renderer but no window
//! when the backend is not the CPU. The JSON line says which backend ran (`"backend"`).
//!
//! A window's frame runs at most four fixed steps (`Time<Virtual>::set_max_delta`): where a
//! step costs more than the 1/60 s it simulates (256² with self-collision on a CPU of a few
//! cores), the cloth falls behind the clock instead of every frame taking longer than the
//! last. On a software renderer (Mesa's llvmpipe, where there is no GPU) the kernels run on
//! the CPU's cores 30–70 times slower than the CPU solver: without `--size` the cloth is then
//! 64² (a 256² step takes over a second there) and a frame runs at most 1.5 steps. `auto`
//! runs it on the CPU there.
//!
//! `--no-self-collision` leaves self-collision out. Both backends run the same model: each
//! substep, every vertex moves by the mean of its contacts' corrections.

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::gpu::ClothGpuSupport;
use bevy_cloth::prelude::*;
use support::Args;

#[derive(Resource)]
struct Size(u32);

/// The size to use on a software renderer (no `--size` given and the GPU asked for).
#[derive(Resource)]
struct SoftwareSize(Option<u32>);

/// At most four fixed steps of virtual time a frame; on a software renderer, with no size
/// given, a 64² cloth and at most 1.5 steps (one step or two). Before `setup`, which builds
/// the cloth at `Size`.
fn fit_to_the_machine(
    support: Option<Res<ClothGpuSupport>>,
    software_size: Res<SoftwareSize>,
    mut size: ResMut<Size>,
    fixed: Res<Time<Fixed>>,
    mut time: ResMut<Time<Virtual>>,
) {
    let step = fixed.timestep().as_secs_f64();
    time.set_max_delta(core::time::Duration::from_secs_f64(4.0 * step));
    let name = support.and_then(|s| s.software_adapter.clone());
    if let (Some(name), Some(small)) = (name, software_size.0) {
        info!(
            "the GPU is a software renderer ({name}): a {small}² cloth instead of {}² \
             (--size N to choose, --backend cpu for the CPU solver)",
            size.0
        );
        size.0 = small;
        time.set_max_delta(core::time::Duration::from_secs_f64(1.5 * step));
    }
}

#[derive(Resource)]
struct SelfCollisionOn(bool);

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: Option<ResMut<Assets<StandardMaterial>>>,
    size: Res<Size>,
    self_collision: Res<SelfCollisionOn>,
) {
    let n = size.0;
    let grid = Grid::new(n, n, 2.4, 2.4);
    let cloth = commands
        .spawn((
            Mesh3d(meshes.add(grid_mesh(&grid))),
            Transform::from_xyz(0.1, 1.6, 0.05).with_rotation(Quat::from_rotation_y(0.25)),
            Cloth {
                mass: 0.6,
                ..default()
            },
            ClothConfig {
                substeps: 10,
                ..default()
            },
        ))
        .id();
    if self_collision.0 {
        commands.entity(cloth).insert(ClothSelfCollision {
            thickness: None,
            friction: 0.3,
        });
    }
    let obstacles = [
        (
            ClothCollider::sphere(0.45),
            Sphere::new(0.45).mesh().build(),
            Vec3::new(-0.4, 0.45, 0.0),
        ),
        (
            ClothCollider::cuboid(Vec3::new(0.3, 0.35, 0.3)),
            Cuboid::new(0.6, 0.7, 0.6).mesh().build(),
            Vec3::new(0.6, 0.35, 0.2),
        ),
        (
            // A mesh collider: the torus's own mesh, baked into a signed distance field.
            ClothCollider::mesh(32),
            Torus::new(0.12, 0.32).mesh().build(),
            Vec3::new(0.35, 0.1, 0.8),
        ),
    ];
    // Half the cloth's vertex spacing (at least 1 cm): a coarse cloth's flat triangles then
    // span a box's edges without cutting into the box drawn under them.
    let thickness = (0.5 * 2.4 / (n - 1) as f32).max(0.01);
    for (collider, mesh, at) in obstacles {
        let e = commands
            .spawn((
                collider.with_thickness(thickness),
                Mesh3d(meshes.add(mesh)),
                Transform::from_translation(at),
            ))
            .id();
        if let Some(materials) = materials.as_deref_mut() {
            commands
                .entity(e)
                .insert(MeshMaterial3d(materials.add(Color::srgb(0.75, 0.75, 0.72))));
        }
    }
    commands.spawn(ClothCollider::plane().with_thickness(0.01));
    if let Some(mut materials) = materials {
        commands
            .entity(cloth)
            .insert(MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.75, 0.2, 0.25),
                perceptual_roughness: 0.8,
                double_sided: true,
                cull_mode: None,
                ..default()
            })));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(0.3, 2.0, 2.9),
            Vec3::new(0.0, 0.35, 0.0),
        );
    }
}

fn report(world: &mut World) -> support::Json {
    let n = world.resource::<Size>().0;
    support::cloth_report(world)
        .str("example", "gpu_cloth")
        .num("size", n)
}

fn main() {
    let mut args = Args::parse(include_str!("gpu_cloth.rs"));
    args.rest
        .entry("backend".into())
        .or_insert_with(|| "gpu".into());
    let size: u32 = args.get("size", 256);
    let software_size =
        (!args.rest.contains_key("size") && args.backend() == ClothBackend::Gpu).then_some(64);
    if !(2..=1024).contains(&size) {
        eprintln!("--size must be in 2..=1024, got {size}");
        std::process::exit(2);
    }
    let mut app = support::app(&args, "bevy_cloth: GPU cloth", 1.0 / 60.0);
    app.insert_resource(Size(size))
        .insert_resource(SoftwareSize(software_size))
        .insert_resource(SelfCollisionOn(
            !args.rest.contains_key("no-self-collision"),
        ))
        .add_systems(Startup, (fit_to_the_machine, setup).chain());
    support::run(app, &args, report);
}
