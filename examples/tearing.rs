//! A cloth pulled apart: two hands hold its left and right edges and move apart until the
//! cloth tears, starting from a small slit at the top of its middle. `ClothTearing` breaks
//! edges stretched past 1.5× their rest length; the torn triangles vanish from the mesh and
//! `ClothTorn` messages report them.
//!
//! ```text
//! cargo run --release --example tearing
//! cargo run --release --example tearing -- --headless --frames 240
//! ```
//! The JSON line adds `torn_edges` (edges torn in all) and `torn_messages`.

#[path = "support/mod.rs"]
mod support;

use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

#[derive(Component)]
struct Hand(f32);

#[derive(Resource, Default)]
struct Torn {
    messages: usize,
    edges: usize,
}

const N: u32 = 28;

/// How long the hands pull, in seconds.
const PULL_SECONDS: f32 = 2.5;

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let grid = Grid::new(N, N, 1.4, 1.4);
    let left = commands
        .spawn((Hand(-1.0), Transform::from_xyz(-0.7, 1.6, 0.0)))
        .id();
    let right = commands
        .spawn((Hand(1.0), Transform::from_xyz(0.7, 1.6, 0.0)))
        .id();
    let transform = Transform::from_xyz(0.0, 1.6, 0.0)
        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let rest = grid.positions();
    let mut pins = Vec::new();
    for j in 0..N {
        for (i, hand, x) in [(0, left, -0.7), (N - 1, right, 0.7)] {
            let v = grid.index(i, j);
            let world = transform.transform_point(rest[v as usize]);
            pins.push(ClothPin {
                vertex: v,
                anchor: PinAnchor::Entity {
                    entity: hand,
                    offset: world - Vec3::new(x, 1.6, 0.0),
                },
            });
        }
    }
    // A slit: the quads of the middle column in the top four rows are cut out, so the tear
    // starts there instead of everywhere at once.
    let mut mesh = grid_mesh(&grid);
    let indices: Vec<u32> = grid
        .indices()
        .chunks(6)
        .enumerate()
        .filter(|(q, _)| {
            let (i, j) = (*q as u32 % (N - 1), *q as u32 / (N - 1));
            !(i == N / 2 - 1 && j < 4)
        })
        .flat_map(|(_, quad)| quad.to_vec())
        .collect();
    mesh.insert_indices(bevy::mesh::Indices::U32(indices));
    let mut cloth = commands.spawn((
        Mesh3d(meshes.add(mesh)),
        transform,
        Cloth {
            mass: 0.3,
            ..default()
        },
        ClothConfig {
            substeps: 10,
            ..default()
        },
        ClothPins(pins),
        ClothTearing { threshold: 1.5 },
    ));
    if let Some(mut m) = materials {
        cloth.insert(support::ClothLook(Color::srgb(0.85, 0.8, 0.65)));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut m,
            Vec3::new(0.0, 1.8, 4.0),
            Vec3::new(0.0, 1.1, 0.0),
        );
    }
}

/// After a second of hanging, the hands move apart at 0.4 m/s each for 2.5 s (by then the
/// cloth is in two pieces), then hold still. Runs in `FixedUpdate`, on the fixed clock: the
/// pull is the same however slow the frames are, and the hands stay in view.
fn pull(time: Res<Time>, mut hands: Query<(&Hand, &mut Transform)>) {
    let t = (time.elapsed_secs() - 1.0).clamp(0.0, PULL_SECONDS);
    for (hand, mut tr) in &mut hands {
        tr.translation.x = hand.0 * (0.7 + 0.4 * t);
    }
}

fn count(mut torn: MessageReader<ClothTorn>, mut total: ResMut<Torn>) {
    for m in torn.read() {
        total.messages += 1;
        total.edges += m.edges.len();
    }
}

fn report(world: &mut World) -> support::Json {
    let torn = world.resource::<Torn>();
    let (messages, edges) = (torn.messages, torn.edges);
    let mut q = world.query::<&ClothSim>();
    let triangles = q
        .iter(world)
        .map(|c| c.simulation().topology().triangles().len())
        .sum::<usize>();
    support::cloth_report(world)
        .str("example", "tearing")
        .num("torn_edges", edges as f64)
        .num("torn_messages", messages as f64)
        .num("triangles_left", triangles as f64)
}

fn main() {
    let args = Args::parse(include_str!("tearing.rs"));
    let mut app = support::app(&args, "bevy_cloth: tearing", 1.0 / 60.0);
    app.init_resource::<Torn>()
        .add_systems(Startup, setup)
        .add_systems(FixedUpdate, pull)
        .add_systems(Update, count);
    support::run(app, &args, report);
}
