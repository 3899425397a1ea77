//! Seed 000 reproduced: the lab's 21×21 cloth, pinned at two corners, solved by Jacobi
//! averaging with weight 0.2 and 32 iterations a step of 0.0333 s.
//!
//! ```text
//! cargo run --release --example lab                      # window
//! cargo run --release --example lab -- --headless --frames 300 --out lab.csv
//! ```
//! `--out FILE` writes the final positions as `x,y,z` lines in vertex order.

#[path = "support/mod.rs"]
mod support;

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

const N: u32 = 21;
const DT: f64 = 0.0333;

/// The lab's mesh, exactly: vertex `j·21+i` at `(5 − 10i/20, 0, 5 − 10j/20)`, quad `a = j·21+i`
/// split into `(a, a+1, a+22)` and `(a, a+22, a+21)`.
fn lab_mesh() -> Mesh {
    let mut pos = Vec::new();
    let mut uv = Vec::new();
    for j in 0..N {
        for i in 0..N {
            pos.push([
                5.0 - 10.0 * i as f32 / 20.0,
                0.0,
                5.0 - 10.0 * j as f32 / 20.0,
            ]);
            uv.push([i as f32 / 20.0, j as f32 / 20.0]);
        }
    }
    let mut idx = Vec::new();
    for j in 0..N - 1 {
        for i in 0..N - 1 {
            let a = j * N + i;
            idx.extend_from_slice(&[a, a + 1, a + 22, a, a + 22, a + 21]);
        }
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, pos)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uv)
    .with_inserted_indices(Indices::U32(idx))
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let mut cloth = commands.spawn((
        Mesh3d(meshes.add(lab_mesh())),
        Transform::from_xyz(0.0, 6.0, 0.0),
        Cloth {
            mass: (N * N) as f32,
            mass_distribution: MassDistribution::Uniform,
            ..default()
        },
        ClothConfig {
            solver: Solver::LAB,
            substeps: 1,
            iterations: 32,
            gravity: Vec3::new(0.0, -9.8, 0.0),
            damping: 0.0,
            ..default()
        },
        ClothPins::rest([0, 20]),
    ));
    if let Some(mut materials) = materials {
        cloth.insert(support::ClothLook(Color::srgb(0.75, 0.2, 0.25)));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(0.0, 4.0, 18.0),
            Vec3::new(0.0, 2.0, 0.0),
        );
    }
}

fn report(world: &mut World) -> support::Json {
    let json = support::cloth_report(world);
    let mut q = world.query::<&ClothSim>();
    let positions: Vec<Vec3> = q
        .iter(world)
        .flat_map(|c| {
            let s = c.simulation().state();
            (0..s.len()).map(|i| s.position(i)).collect::<Vec<_>>()
        })
        .collect();
    if let Some(path) = world.resource::<OutFile>().0.clone() {
        // World positions with the entity's lift removed: the lab's own coordinates.
        let text: String = positions
            .iter()
            .map(|p| format!("{},{},{}\n", p.x, p.y - 6.0, p.z))
            .collect();
        if let Err(e) = std::fs::write(&path, text) {
            eprintln!("cannot write {path}: {e}");
            std::process::exit(1);
        }
    }
    let lowest = positions.iter().map(|p| p.y - 6.0).fold(f32::MAX, f32::min);
    json.str("example", "lab").num("lowest_y", lowest)
}

#[derive(Resource)]
struct OutFile(Option<String>);

fn main() {
    let args = Args::parse(include_str!("lab.rs"));
    let mut app = support::app(&args, "bevy_cloth: seed 000 lab", DT);
    app.insert_resource(OutFile(args.rest.get("out").cloned()))
        .add_systems(Startup, setup);
    support::run(app, &args, report);
}
