//! A flag on a pole in gusty wind: a 3 m × 2 m cloth pinned along its hoist edge, XPBD with
//! the default (fabric) bending, drag, lift and skin friction against a wind whose gusts and
//! turbulence change its speed and direction; lit, with shadows.
//!
//! ```text
//! cargo run --release --example flag
//! cargo run --release --example flag -- --headless --frames 300
//! ```
//! Options: `--wind M_PER_S` (default 7; 0 for none), `--columns N --rows N` (grid, default
//! 48 × 32), `--substeps N`, `--iterations N`.

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

#[derive(Resource, Clone, Copy)]
struct Setup {
    grid: Grid,
    config: ClothConfig,
}

fn setup(
    mut commands: Commands,
    setup: Res<Setup>,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let grid = setup.grid;
    // Grid vertices lie in XZ with the front on +Y; rotating 90° about X stands the flag up in
    // XY with its front towards the camera (+Z). Shift so column 0 (the hoist) sits on the
    // pole at x = 0.
    let transform = Transform::from_xyz(grid.width / 2.0, 3.2, 0.0)
        .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2));
    let hoist = (0..grid.rows).map(|j| grid.index(0, j));
    let mut flag = commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        transform,
        Cloth {
            mass: 0.4,
            ..default()
        },
        setup.config,
        ClothPins::rest(hoist),
    ));
    if let Some(mut materials) = materials {
        flag.insert(support::ClothLook(Color::srgb(0.1, 0.25, 0.7)));
        commands.spawn((
            Mesh3d(meshes.add(Cylinder::new(0.04, 4.4))),
            MeshMaterial3d(materials.add(Color::srgb(0.6, 0.6, 0.62))),
            Transform::from_xyz(-0.04, 2.2, 0.0),
        ));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(1.5, 2.0, 6.5),
            Vec3::new(1.2, 2.0, 0.0),
        );
    }
}

fn report(world: &mut World) -> support::Json {
    let wind = world
        .get_resource::<Wind>()
        .map_or(0.0, |w| w.velocity.length());
    // How far the flag flies out from the pole, on average.
    let mut q = world.query::<&ClothSim>();
    let reach = q.iter(world).next().map_or(0.0, |c| {
        let s = c.simulation().state();
        (0..s.len()).map(|i| s.position(i).x).sum::<f32>() / s.len() as f32
    });
    let unread = support::gpu_state_unread(world);
    support::cloth_report(world)
        .str("example", "flag")
        .num("wind", wind)
        .measured("mean_x", reach, unread)
}

fn main() {
    let args = Args::parse(include_str!("flag.rs"));
    let grid = Grid::new(args.get("columns", 48), args.get("rows", 32), 3.0, 2.0);
    let config = ClothConfig {
        substeps: args.get("substeps", 12),
        iterations: args.get("iterations", 1),
        ..default()
    };
    let mut app = support::app(&args, "bevy_cloth: flag", 1.0 / 60.0);
    let speed: f32 = args.get("wind", 7.0);
    if speed > 0.0 {
        app.insert_resource(Wind(WindParams {
            velocity: Vec3::new(speed, 0.0, -speed * 0.2),
            ..default()
        }));
    }
    app.insert_resource(Setup { grid, config })
        .add_systems(Startup, setup);
    support::run(app, &args, report);
}
