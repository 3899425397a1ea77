//! A banner from a glTF file drapes over a statue from the same file.
//!
//! Loads `assets/banner_statue.gltf` through Bevy's `AssetServer` (written by the `make_gltf`
//! example, as a modelling tool would export it: the banner's two panels split along a UV seam,
//! `u16` indices; the statue with a hard edge around its pedestal), turns the mesh named
//! `Banner` into cloth and the one named `Statue` into a mesh collider, and lets the banner
//! fall over the statue's head and shoulders.
//!
//! ```text
//! cargo run --release --example gltf_drape
//! cargo run --release --example gltf_drape -- --headless --frames 300
//! ```
//! The JSON line adds how far the banner's seam copies are apart (0: welded), how many
//! particles the mesh's vertices became, the deepest penetration into the statue, the banner's
//! edge–triangle pairs crossing (its self-collision holds: 0) and whether it is asleep (after
//! about half a minute, `--frames 1800`).

#[path = "support/mod.rs"]
mod support;

use bevy::gltf::{Gltf, GltfMesh, GltfNode};
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use support::Args;

const SCENE: &str = "banner_statue.gltf";

/// The loading glTF, until its meshes have been spawned.
#[derive(Resource)]
struct Loading(Handle<Gltf>);

/// Inserted once the glTF has been turned into entities (or failed to load).
#[derive(Resource)]
struct Done;

fn load(mut commands: Commands, assets: Res<AssetServer>) {
    commands.insert_resource(Loading(assets.load(SCENE)));
}

/// The named node's first mesh primitive and its transform.
fn named(
    gltf: &Gltf,
    name: &str,
    nodes: &Assets<GltfNode>,
    meshes: &Assets<GltfMesh>,
) -> Option<(Handle<Mesh>, Transform)> {
    let node = nodes.get(gltf.named_nodes.get(name)?)?;
    let mesh = meshes.get(node.mesh.as_ref()?)?;
    Some((mesh.primitives.first()?.mesh.clone(), node.transform))
}

#[expect(clippy::too_many_arguments, reason = "a startup-like system")]
fn spawn_when_loaded(
    mut commands: Commands,
    loading: Option<Res<Loading>>,
    gltfs: Res<Assets<Gltf>>,
    nodes: Res<Assets<GltfNode>>,
    gltf_meshes: Res<Assets<GltfMesh>>,
    assets: Res<AssetServer>,
    mut meshes: ResMut<Assets<Mesh>>,
    materials: Option<ResMut<Assets<StandardMaterial>>>,
) {
    let Some(loading) = loading else {
        return;
    };
    if let Some(bevy::asset::LoadState::Failed(e)) = assets.get_load_state(&loading.0) {
        error!("cannot load {SCENE}: {e}; run `cargo run --example make_gltf` to write it");
        eprintln!("cannot load {SCENE}: {e}; run `cargo run --example make_gltf` to write it");
        commands.remove_resource::<Loading>();
        commands.insert_resource(Done);
        return;
    }
    let Some(gltf) = gltfs.get(&loading.0) else {
        return;
    };
    let (Some((statue, statue_at)), Some((banner, banner_at))) = (
        named(gltf, "Statue", &nodes, &gltf_meshes),
        named(gltf, "Banner", &nodes, &gltf_meshes),
    ) else {
        error!("{SCENE} has no meshes named Statue and Banner");
        commands.remove_resource::<Loading>();
        commands.insert_resource(Done);
        return;
    };
    commands.remove_resource::<Loading>();
    commands.insert_resource(Done);
    let statue_entity = commands
        .spawn((
            Name::new("Statue"),
            Mesh3d(statue),
            statue_at,
            // Baked once into a signed distance field, 64 cells along its height.
            ClothCollider::mesh(64)
                .with_thickness(0.012)
                .with_friction(0.6),
        ))
        .id();
    let banner_entity = commands
        .spawn((
            Name::new("Banner"),
            Mesh3d(banner),
            banner_at,
            Cloth {
                mass: 0.35,
                ..default()
            },
            ClothConfig {
                substeps: 12,
                ..default()
            },
            // Under the banner's short edge (0.041 m): wrapped over the head, its layers fold
            // tighter than the default thickness (1.1 short edges) allows, and there the
            // contacts fight the edges; of six drops at the default three kept creeping.
            ClothSelfCollision {
                thickness: Some(0.035),
                ..default()
            },
        ))
        .id();
    if let Some(mut materials) = materials {
        commands
            .entity(statue_entity)
            .insert(MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.62, 0.6, 0.56),
                perceptual_roughness: 0.85,
                ..default()
            })));
        commands
            .entity(banner_entity)
            .insert(support::ClothLook(Color::srgb(0.5, 0.07, 0.1)));
        support::stage(
            &mut commands,
            &mut meshes,
            &mut materials,
            Vec3::new(1.6, 2.0, 2.6),
            Vec3::new(0.0, 1.1, 0.0),
        );
    }
}

fn report(world: &mut World) -> support::Json {
    let penetration = support::max_penetration(world);
    let mut q = world.query::<(&Name, &ClothSim, &Mesh3d)>();
    let mut seam_gap = f32::NAN;
    let mut counts = (0usize, 0usize);
    let (mut asleep, mut crossings) = (false, 0usize);
    let meshes = world.resource::<Assets<Mesh>>();
    for (name, sim, mesh3d) in q.iter(world) {
        if name.as_str() != "Banner" {
            continue;
        }
        counts = (sim.weld().vertex_count(), sim.weld().particle_count());
        (asleep, crossings) = (sim.is_sleeping(), sim.simulation().self_crossings());
        // Largest distance between written copies of one particle (0 when welded).
        let Some(mesh) = meshes.get(&mesh3d.0) else {
            continue;
        };
        let Some(bevy::mesh::VertexAttributeValues::Float32x3(p)) =
            mesh.attribute(Mesh::ATTRIBUTE_POSITION)
        else {
            continue;
        };
        seam_gap = 0.0;
        for (v, &particle) in sim.weld().particles().iter().enumerate() {
            let first = sim.weld().representative(particle) as usize;
            seam_gap = seam_gap.max(Vec3::from(p[v]).distance(Vec3::from(p[first])));
        }
    }
    let unread = support::gpu_state_unread(world);
    support::cloth_report(world)
        .str("example", "gltf_drape")
        .num("mesh_vertices", counts.0 as f64)
        .num("particles", counts.1 as f64)
        .measured("seam_gap", seam_gap, unread)
        .measured("max_penetration", penetration, unread)
        .measured("crossings", crossings as f64, unread)
        .measured("asleep", u8::from(asleep), unread)
}

fn main() {
    let args = Args::parse(include_str!("gltf_drape.rs"));
    let mut app = support::app(&args, "bevy_cloth: glTF banner on a statue", 1.0 / 60.0);
    // Loading glTF also without a renderer: its asset types and loader.
    support::add_gltf_support(&mut app);
    app.add_systems(Startup, load)
        .add_systems(Update, spawn_when_loaded)
        .insert_resource(support::WaitUntil(|world| {
            world.contains_resource::<Done>()
        }));
    support::run(app, &args, report);
}
