//! The velvet material rendered for real (offscreen, llvmpipe in CI): the pictures are not
//! empty, the flag's front shows the velvet colour and its back the lining colour, the sunlit
//! front is brighter than the back, the drape shows its velvet and (lying upside down) casts a
//! shadow from its back faces, and a normal map shades a cloth through the solver's tangents;
//! skinned cloths built again still draw.

mod common;
#[path = "../examples/support/shots.rs"]
mod shots;

use bevy::prelude::*;
use shots::Picture;

/// Fraction of pixels that are not the clear colour (more than 8/255 away in some channel).
fn coverage(p: &Picture) -> f32 {
    let clear = shots::CLEAR.to_srgba();
    let clear = [clear.red, clear.green, clear.blue];
    let n = p
        .pixels()
        .filter(|c| (0..3).any(|i| (c[i] - clear[i]).abs() > 8.0 / 255.0))
        .count();
    n as f32 / (p.width * p.height) as f32
}

/// Pixels of a clearly blue, gold, wine-red or green hue: the flag's front, its lining, the drape
/// and the patches
/// (lighting and tonemapping shift the exact colour; the hue family survives). Background,
/// ground, ball and pole are all near grey and match none.
fn blue(v: &[f32; 3]) -> bool {
    v[2] > v[0] + 0.15 && v[2] > v[1] + 0.1
}

fn gold(v: &[f32; 3]) -> bool {
    v[0] > v[2] + 0.15 && v[1] > v[2] + 0.05
}

fn wine(v: &[f32; 3]) -> bool {
    v[0] > v[1] + 0.12 && v[0] > v[2] + 0.08 && v[1] < v[2] + 0.05
}

fn green(v: &[f32; 3]) -> bool {
    v[1] > v[0] + 0.05 && v[1] > v[2] + 0.05
}

/// Pixels of `family` in the columns `x` for which `columns(x)` holds.
fn in_columns(
    p: &Picture,
    columns: impl Fn(u32) -> bool,
    family: fn(&[f32; 3]) -> bool,
) -> Vec<[f32; 3]> {
    p.pixels()
        .enumerate()
        .filter(|(i, _)| columns(*i as u32 % p.width))
        .map(|(_, v)| v)
        .filter(family)
        .collect()
}

fn matching(p: &Picture, family: fn(&[f32; 3]) -> bool) -> Vec<[f32; 3]> {
    p.pixels().filter(family).collect()
}

fn luminance(px: &[[f32; 3]]) -> f32 {
    px.iter()
        .map(|v| 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2])
        .sum::<f32>()
        / px.len().max(1) as f32
}

#[test]
fn velvet_pictures_show_both_sides() {
    if common::gpu_or_skip("velvet_pictures_show_both_sides").is_none() {
        return;
    }
    let out = std::env::temp_dir().join("bevy_cloth_pictures");
    let mut list = shots::velvet_shots();
    list.push(shots::normal_map_shot());
    list.push(shots::lamps_shot());
    let pictures = shots::render(
        UVec2::new(320, 200),
        120,
        shots::velvet_scene,
        &list,
        Some(&out),
    );
    let [front, back, drape, patches, lamps] = &pictures[..] else {
        panic!("five pictures expected");
    };
    for p in &pictures {
        let c = coverage(p);
        eprintln!("{}: {:.0} % not background", p.name, c * 100.0);
        // The ground fills the lower part and the subject the middle: far from empty.
        assert!(c > 0.3, "{} is nearly empty ({c})", p.name);
        let lum: Vec<[f32; 3]> = p.pixels().collect();
        let mean = luminance(&lum);
        assert!(
            mean > 0.05 && mean < 0.95,
            "{}: mean luminance {mean}",
            p.name
        );
    }
    let (front_blue, front_gold) = (matching(front, blue), matching(front, gold));
    let (back_blue, back_gold) = (matching(back, blue), matching(back, gold));
    eprintln!(
        "front: {} blue, {} gold px; back: {} blue, {} gold px",
        front_blue.len(),
        front_gold.len(),
        back_blue.len(),
        back_gold.len()
    );
    let area = (front.width * front.height) as usize;
    // Each view mostly shows its own side (folds may show a little of the other).
    assert!(front_blue.len() > area / 20, "front shows little velvet");
    assert!(back_gold.len() > area / 20, "back shows little lining");
    assert!(front_blue.len() > 3 * front_gold.len());
    assert!(back_gold.len() > 3 * back_blue.len());
    // The sun is on the front side: the front's own colour is lit, the back only by ambient
    // light and what the flipped normal catches. Compare each side relative to its albedo.
    let rel = |px: &[[f32; 3]], c: Color| {
        let s = c.to_srgba();
        luminance(px) / (0.2126 * s.red + 0.7152 * s.green + 0.0722 * s.blue)
    };
    let (lit_front, lit_back) = (
        rel(&front_blue, shots::FLAG_FRONT),
        rel(&back_gold, shots::FLAG_BACK),
    );
    eprintln!("relative brightness: front {lit_front:.2}, back {lit_back:.2}");
    assert!(
        lit_front > 1.2 * lit_back,
        "front {lit_front} back {lit_back}"
    );
    let wine = matching(drape, wine);
    eprintln!("drape: {} velvet px", wine.len());
    assert!(wine.len() > area / 20, "the drape shows little velvet");
    // The drape lies upside down (its back side towards the sun): its shadow on the ground
    // exists only if back faces are drawn into the shadow map. The lit ground is about 0.5
    // bright and grey; shadowed ground is grey and under 0.3. Measured at 320×200: 875 px
    // with the two-sided shadow pass, 267 (the ball's shadow alone) with back faces culled
    // from it.
    let shadow = drape
        .pixels()
        .filter(|v| {
            let l = luminance(&[*v]);
            l < 0.3 && (v[0] - v[2]).abs() < 0.05 && (v[0] - v[1]).abs() < 0.05
        })
        .count();
    eprintln!("drape: {shadow} shadow px");
    assert!(
        shadow > area / 100,
        "no shadow under the upside-down drape: {shadow} px"
    );

    // Normal map: the left patch (striped normal map, shaded through the solver's tangents)
    // varies in brightness stripe by stripe; the right one (none) is nearly uniform.
    let half = patches.width / 2;
    let spread = |left: bool| {
        let px: Vec<f32> = in_columns(patches, |x| (x < half) == left, green)
            .iter()
            .map(|v| luminance(&[*v]))
            .collect();
        let mean = px.iter().sum::<f32>() / px.len().max(1) as f32;
        let var = px.iter().map(|l| (l - mean) * (l - mean)).sum::<f32>() / px.len().max(1) as f32;
        (px.len(), var.sqrt())
    };
    let ((n_left, sd_left), (n_right, sd_right)) = (spread(true), spread(false));
    eprintln!(
        "patches: normal-mapped {n_left} px, sd {sd_left:.4}; plain {n_right} px, sd {sd_right:.4}"
    );
    assert!(
        n_left > area / 20 && n_right > area / 20,
        "patches not in view"
    );
    assert!(
        sd_left > 3.0 * sd_right,
        "the normal map changes nothing: {sd_left} vs {sd_right}"
    );

    // Clustered lights: the cloth's ends under the spot and the point light are brighter
    // than its middle, which only the sun and the ambient light reach.
    // The brightest tenth of each third's cloth pixels (a lamp lights a disc, not the whole end).
    let third = |k: u32| {
        let px = in_columns(lamps, |x| x * 3 / lamps.width == k, green);
        let mut l: Vec<f32> = px.iter().map(|v| luminance(&[*v])).collect();
        l.sort_by(f32::total_cmp);
        (px.len(), l.get(l.len() * 9 / 10).copied().unwrap_or(0.0))
    };
    let (spot, middle, point) = (third(0), third(1), third(2));
    eprintln!(
        "lamps: spot end {spot:?}, middle {middle:?}, point end {point:?} (px, 90th-percentile luminance)"
    );
    assert!(
        spot.0 > area / 50 && middle.0 > area / 50 && point.0 > area / 50,
        "cloth not in view"
    );
    assert!(
        spot.1 > 1.2 * middle.1,
        "the spot light does not light the velvet"
    );
    assert!(
        point.1 > 1.2 * middle.1,
        "the point light does not light the velvet"
    );
}

/// Two skinned sheets, one held by `ClothSkinning` and one a plain `Cloth`, built again after
/// a few steps (a new mass), then drawn: a cloth's new copy of a skinned mesh must not keep
/// its joints once the entity has no `SkinnedMesh` (the renderer refuses such a draw — a wgpu
/// validation error that quits the app — as the `cape` example did in a window).
#[test]
fn skinned_cloths_built_again_still_draw() {
    use bevy::asset::RenderAssetUsages;
    use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
    use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
    use bevy_cloth::prelude::{Cloth, ClothSkinning, MaxDistance};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    if common::gpu_or_skip("skinned_cloths_built_again_still_draw").is_none() {
        return;
    }
    const N: u32 = 8;
    fn sheet(x: f32) -> Mesh {
        let mut positions = Vec::new();
        let mut weights = Vec::new();
        for j in 0..N {
            for i in 0..N {
                let y = 2.0 - j as f32 / (N - 1) as f32;
                positions.push([x + i as f32 / (N - 1) as f32 - 0.5, y, 0.0]);
                weights.push([y - 1.0, 2.0 - y, 0.0, 0.0]);
            }
        }
        let mut indices = Vec::new();
        for j in 0..N - 1 {
            for i in 0..N - 1 {
                let a = j * N + i;
                indices.extend([a, a + N, a + 1, a + 1, a + N, a + N + 1]);
            }
        }
        Mesh::new(
            PrimitiveTopology::TriangleList,
            RenderAssetUsages::default(),
        )
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        .with_inserted_attribute(
            Mesh::ATTRIBUTE_JOINT_INDEX,
            VertexAttributeValues::Uint16x4(vec![[0, 1, 0, 0]; (N * N) as usize]),
        )
        .with_inserted_attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT, weights)
        .with_computed_normals()
        .with_inserted_indices(Indices::U32(indices))
    }
    fn setup(
        mut commands: Commands,
        mut meshes: ResMut<Assets<Mesh>>,
        mut materials: ResMut<Assets<StandardMaterial>>,
        mut bindposes: ResMut<Assets<SkinnedMeshInverseBindposes>>,
    ) {
        let bones = [Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        let joints = bones.map(|b| commands.spawn(Transform::from_translation(b)).id());
        let inverse = bindposes.add(SkinnedMeshInverseBindposes::from(
            bones.map(|b| Mat4::from_translation(-b)).to_vec(),
        ));
        let material = materials.add(Color::srgb(0.8, 0.1, 0.1));
        commands.spawn(DirectionalLight::default());
        for (x, skinning) in [(-0.6, true), (0.6, false)] {
            let mut e = commands.spawn((
                Mesh3d(meshes.add(sheet(x))),
                MeshMaterial3d(material.clone()),
                Cloth::default(),
                SkinnedMesh {
                    inverse_bindposes: inverse.clone(),
                    joints: joints.to_vec(),
                },
            ));
            if skinning {
                e.insert(ClothSkinning {
                    max_distance: MaxDistance::Uniform(0.05),
                    backstop: None,
                });
            }
        }
    }
    fn rebuild(mut steps: Local<u32>, mut cloths: Query<&mut Cloth>) {
        *steps += 1;
        if *steps == 10 {
            for mut c in &mut cloths {
                c.mass = 0.5;
            }
        }
    }
    let quit = Arc::new(AtomicBool::new(false));
    let flag = quit.clone();
    let pictures = shots::render(
        UVec2::new(160, 100),
        30,
        move |app: &mut App| {
            app.add_systems(Startup, setup)
                .add_systems(FixedUpdate, rebuild)
                .add_systems(Last, move |mut exits: MessageReader<AppExit>| {
                    if exits.read().next().is_some() {
                        flag.store(true, Ordering::SeqCst);
                    }
                });
        },
        &[shots::Shot {
            name: "skinned_rebuilt",
            eye: Vec3::new(0.0, 1.5, 4.0),
            target: Vec3::new(0.0, 1.5, 0.0),
        }],
        None,
    );
    assert!(
        !quit.load(Ordering::SeqCst),
        "the app quit (a render error, see the log)"
    );
    let red = matching(&pictures[0], |v| v[0] > v[1] + 0.2 && v[0] > v[2] + 0.2).len();
    assert!(red > 200, "the sheets were not drawn ({red} red pixels)");
}
