//! Writes `assets/banner_statue.gltf` (+ `.bin`): the scene the `gltf_drape` example loads.
//!
//! Two named meshes, as a modelling tool would export them:
//! - `Statue`: a bust on a pedestal, one closed surface of revolution (a good mesh collider),
//!   with a hard edge around the pedestal's rim (its vertices split there with two normals).
//! - `Banner`: a 1.3 m square of cloth laid flat above the statue, in two panels that meet
//!   along a UV seam down the middle: the seam's vertices are split (same position, different
//!   UVs), as every exporter does, and its indices are `u16`.
//!
//! ```text
//! cargo run --release --example make_gltf            # writes assets/banner_statue.gltf + .bin
//! cargo run --release --example make_gltf -- --out DIR
//! ```
//!
//! The files are committed; run this to regenerate them after changing the shapes.

use std::fmt::Write as _;

/// Vertex data of one mesh, glTF-ready.
struct MeshOut {
    name: &'static str,
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    uvs: Option<Vec<[f32; 2]>>,
    indices: Vec<u16>,
    color: [f32; 4],
    translation: [f32; 3],
}

/// The bust's profile: (radius, height) from the bottom centre to the top of the head.
const PROFILE: &[(f32, f32)] = &[
    (0.0, 0.0),
    (0.34, 0.0),
    (0.34, 0.55), // pedestal rim: a hard edge
    (0.34, 0.55),
    (0.24, 0.55),
    (0.21, 0.62),
    (0.24, 0.85),
    (0.29, 1.05),
    (0.30, 1.12),
    (0.24, 1.24),
    (0.10, 1.30),
    (0.08, 1.38),
    (0.10, 1.44),
    (0.12, 1.52),
    (0.115, 1.60),
    (0.09, 1.67),
    (0.05, 1.71),
    (0.0, 1.72),
];

fn statue() -> MeshOut {
    let segments = 40u16;
    let mut positions = Vec::new();
    let mut rings: Vec<Vec<u16>> = Vec::new();
    for &(r, y) in PROFILE {
        let mut ring = Vec::new();
        let count = if r == 0.0 { 1 } else { segments };
        for k in 0..count {
            let a = k as f32 / segments as f32 * core::f32::consts::TAU;
            ring.push(positions.len() as u16);
            positions.push([r * a.cos(), y, r * a.sin()]);
        }
        rings.push(ring);
    }
    let mut indices = Vec::new();
    for (k, w) in rings.windows(2).enumerate() {
        // The rim's two rings sit on one circle: no band between them (a hard edge).
        if PROFILE[k] == PROFILE[k + 1] {
            continue;
        }
        let (a, b) = (&w[0], &w[1]);
        for k in 0..segments as usize {
            let at = |ring: &Vec<u16>, k: usize| ring[k % ring.len()];
            let (a0, a1, b0, b1) = (at(a, k), at(a, k + 1), at(b, k), at(b, k + 1));
            // Outward facing (counter-clockwise seen from outside).
            if a.len() > 1 {
                indices.extend([a0, b0, a1]);
            }
            if b.len() > 1 {
                indices.extend([a1, b0, b1]);
            }
        }
    }
    // Smooth normals per ring, except across the duplicated rim ring (a hard edge): each
    // ring's normal comes only from the faces that use its own vertices.
    let mut normals = vec![[0.0f32; 3]; positions.len()];
    for t in indices.chunks(3) {
        let p = |i: u16| positions[i as usize];
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        let n = cross(sub(b, a), sub(c, a));
        for &i in t {
            let o = &mut normals[i as usize];
            for k in 0..3 {
                o[k] += n[k];
            }
        }
    }
    for n in &mut normals {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt().max(1e-12);
        *n = [n[0] / l, n[1] / l, n[2] / l];
    }
    MeshOut {
        name: "Statue",
        positions,
        normals,
        uvs: None,
        indices,
        color: [0.62, 0.6, 0.56, 1.0],
        translation: [0.0, 0.0, 0.0],
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// A `n × n` square of `size` metres in the XZ plane facing +Y, split down the middle column
/// into two UV islands (left panel u ∈ [0, 0.48], right panel u ∈ [0.52, 1]).
fn banner() -> MeshOut {
    let n = 33u16;
    let size = 1.3f32;
    let seam = n / 2;
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let at = |i: u16, j: u16| {
        [
            size * (i as f32 / (n - 1) as f32 - 0.5),
            0.0,
            size * (j as f32 / (n - 1) as f32 - 0.5),
        ]
    };
    let v = |j: u16| j as f32 / (n - 1) as f32;
    // Left panel: columns 0..=seam; right panel: columns seam..n (the seam column twice).
    let mut left = vec![vec![0u16; n as usize]; seam as usize + 1];
    for (i, col) in left.iter_mut().enumerate() {
        for (j, slot) in col.iter_mut().enumerate() {
            *slot = positions.len() as u16;
            positions.push(at(i as u16, j as u16));
            uvs.push([0.48 * i as f32 / seam as f32, v(j as u16)]);
        }
    }
    let mut right = vec![vec![0u16; n as usize]; (n - seam) as usize];
    for (k, col) in right.iter_mut().enumerate() {
        let i = seam + k as u16;
        for (j, slot) in col.iter_mut().enumerate() {
            *slot = positions.len() as u16;
            positions.push(at(i, j as u16));
            uvs.push([0.52 + 0.48 * k as f32 / (n - 1 - seam) as f32, v(j as u16)]);
        }
    }
    let index = |i: u16, j: u16, right_side: bool| -> u16 {
        if right_side {
            right[(i - seam) as usize][j as usize]
        } else {
            left[i as usize][j as usize]
        }
    };
    let mut indices = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let r = i >= seam;
            let (a, b, c, d) = (
                index(i, j, r),
                index(i + 1, j, r),
                index(i + 1, j + 1, r),
                index(i, j + 1, r),
            );
            // Facing +Y: z grows with j, so wind (a, d, c), (a, c, b).
            indices.extend([a, d, c, a, c, b]);
        }
    }
    let normals = vec![[0.0, 1.0, 0.0]; positions.len()];
    MeshOut {
        name: "Banner",
        positions,
        normals,
        uvs: Some(uvs),
        indices,
        color: [0.5, 0.07, 0.1, 1.0],
        translation: [0.0, 2.1, 0.0],
    }
}

fn main() {
    let mut out_dir = "assets".to_string();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--out" {
            out_dir = args.next().expect("--out needs a folder");
        }
    }
    let meshes = [statue(), banner()];
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut mesh_json = Vec::new();
    let mut push_view = |bin: &mut Vec<u8>, bytes: &[u8], target: u32| -> usize {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        views.push(format!(
            r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{},"target":{target}}}"#,
            bytes.len()
        ));
        views.len() - 1
    };
    for m in &meshes {
        let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let flat3: Vec<f32> = m.positions.iter().flatten().copied().collect();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in &m.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let view = push_view(&mut bin, &f32s(&flat3), 34962);
        accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}}"#,
            m.positions.len(),
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        ));
        let pos = accessors.len() - 1;
        let flat_n: Vec<f32> = m.normals.iter().flatten().copied().collect();
        let view = push_view(&mut bin, &f32s(&flat_n), 34962);
        accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":5126,"count":{},"type":"VEC3"}}"#,
            m.normals.len()
        ));
        let nrm = accessors.len() - 1;
        let mut attributes = format!(r#""POSITION":{pos},"NORMAL":{nrm}"#);
        if let Some(uvs) = &m.uvs {
            let flat: Vec<f32> = uvs.iter().flatten().copied().collect();
            let view = push_view(&mut bin, &f32s(&flat), 34962);
            accessors.push(format!(
                r#"{{"bufferView":{view},"componentType":5126,"count":{},"type":"VEC2"}}"#,
                uvs.len()
            ));
            write!(attributes, r#","TEXCOORD_0":{}"#, accessors.len() - 1).unwrap();
        }
        let idx: Vec<u8> = m.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = push_view(&mut bin, &idx, 34963);
        accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":5123,"count":{},"type":"SCALAR"}}"#,
            m.indices.len()
        ));
        let material = mesh_json.len();
        mesh_json.push(format!(
            r#"{{"name":"{}","primitives":[{{"attributes":{{{attributes}}},"indices":{},"material":{material}}}]}}"#,
            m.name,
            accessors.len() - 1
        ));
    }
    let nodes: Vec<String> = meshes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let t = m.translation;
            format!(
                r#"{{"name":"{}","mesh":{i},"translation":[{},{},{}]}}"#,
                m.name, t[0], t[1], t[2]
            )
        })
        .collect();
    let materials: Vec<String> = meshes
        .iter()
        .map(|m| {
            let c = m.color;
            format!(
                r#"{{"name":"{}","doubleSided":true,"pbrMetallicRoughness":{{"baseColorFactor":[{},{},{},{}],"metallicFactor":0.0,"roughnessFactor":0.85}}}}"#,
                m.name, c[0], c[1], c[2], c[3]
            )
        })
        .collect();
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0", "generator": "bevy_cloth examples/make_gltf.rs"}},
  "scene": 0,
  "scenes": [{{"name": "Scene", "nodes": [0, 1]}}],
  "nodes": [{}],
  "meshes": [{}],
  "materials": [{}],
  "buffers": [{{"byteLength": {}, "uri": "banner_statue.bin"}}],
  "bufferViews": [{}],
  "accessors": [{}]
}}
"#,
        nodes.join(","),
        mesh_json.join(","),
        materials.join(","),
        bin.len(),
        views.join(","),
        accessors.join(",\n    ")
    );
    std::fs::create_dir_all(&out_dir).expect("create the output folder");
    std::fs::write(format!("{out_dir}/banner_statue.gltf"), json).expect("write the glTF");
    std::fs::write(format!("{out_dir}/banner_statue.bin"), &bin).expect("write the buffer");
    println!(
        "wrote {out_dir}/banner_statue.gltf and .bin ({} bytes): Statue {} vertices, Banner {} \
         vertices",
        bin.len(),
        meshes[0].positions.len(),
        meshes[1].positions.len()
    );
}
