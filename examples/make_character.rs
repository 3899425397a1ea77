//! Writes `assets/character.gltf` (+ `.bin`): the skinned, animated humanoid the `cape`
//! example dresses.
//!
//! A 1.8 m figure facing +z (its left is +x), built of boxes, each bound rigidly to one of 13
//! bones: `Hips` → `Spine` → `Chest` → `Neck` → `Head`; `Chest` → `UpperArm.L` → `Forearm.L`
//! (and `.R`); `Hips` → `Thigh.L` → `Shin.L` (and `.R`). Every bone's rest rotation is the
//! identity, so a bone's local frame is the character's. Two looping, in-place animations:
//! `Walk` (1 s a cycle) and `Run` (0.6 s), rotations of the limbs and spine and a bob of the
//! hips, sampled at 17 keys a cycle (linear). A skirt, a second skinned mesh, is skinned to
//! the hips and thighs, its max distances painted in its vertex colours (see [`skirt`]).
//!
//! ```text
//! cargo run --release --example make_character            # writes assets/character.gltf + .bin
//! cargo run --release --example make_character -- --out DIR
//! ```
//!
//! The files are committed; run this to regenerate them after changing the figure.

use std::f32::consts::TAU;

/// A bone: name, parent (index into `BONES`), rest position in the character's frame.
struct Bone {
    name: &'static str,
    parent: Option<usize>,
    at: [f32; 3],
}

const fn bone(name: &'static str, parent: Option<usize>, at: [f32; 3]) -> Bone {
    Bone { name, parent, at }
}

const HIPS: usize = 0;
const SPINE: usize = 1;
const CHEST: usize = 2;
const NECK: usize = 3;
const HEAD: usize = 4;
const UPPER_ARM_L: usize = 5;
const FOREARM_L: usize = 6;
const UPPER_ARM_R: usize = 7;
const FOREARM_R: usize = 8;
const THIGH_L: usize = 9;
const SHIN_L: usize = 10;
const THIGH_R: usize = 11;
const SHIN_R: usize = 12;

const BONES: [Bone; 13] = [
    bone("Hips", None, [0.0, 0.95, 0.0]),
    bone("Spine", Some(HIPS), [0.0, 1.08, 0.0]),
    bone("Chest", Some(SPINE), [0.0, 1.26, 0.0]),
    bone("Neck", Some(CHEST), [0.0, 1.52, 0.0]),
    bone("Head", Some(NECK), [0.0, 1.60, 0.0]),
    bone("UpperArm.L", Some(CHEST), [0.24, 1.47, 0.0]),
    bone("Forearm.L", Some(UPPER_ARM_L), [0.24, 1.18, 0.0]),
    bone("UpperArm.R", Some(CHEST), [-0.24, 1.47, 0.0]),
    bone("Forearm.R", Some(UPPER_ARM_R), [-0.24, 1.18, 0.0]),
    bone("Thigh.L", Some(HIPS), [0.1, 0.92, 0.0]),
    bone("Shin.L", Some(THIGH_L), [0.1, 0.5, 0.0]),
    bone("Thigh.R", Some(HIPS), [-0.1, 0.92, 0.0]),
    bone("Shin.R", Some(THIGH_R), [-0.1, 0.5, 0.0]),
];

/// The boxes of the body: bone, centre, size (all in the character's frame).
const BOXES: &[(usize, [f32; 3], [f32; 3])] = &[
    (HIPS, [0.0, 0.95, 0.0], [0.34, 0.18, 0.2]),
    (SPINE, [0.0, 1.15, 0.0], [0.3, 0.2, 0.18]),
    (CHEST, [0.0, 1.37, 0.0], [0.38, 0.26, 0.22]),
    (NECK, [0.0, 1.54, 0.0], [0.09, 0.1, 0.09]),
    (HEAD, [0.0, 1.7, 0.01], [0.2, 0.24, 0.22]),
    (UPPER_ARM_L, [0.26, 1.33, 0.0], [0.09, 0.3, 0.09]),
    (FOREARM_L, [0.26, 1.05, 0.0], [0.08, 0.28, 0.08]),
    (UPPER_ARM_R, [-0.26, 1.33, 0.0], [0.09, 0.3, 0.09]),
    (FOREARM_R, [-0.26, 1.05, 0.0], [0.08, 0.28, 0.08]),
    (THIGH_L, [0.1, 0.71, 0.0], [0.13, 0.42, 0.13]),
    (SHIN_L, [0.1, 0.27, 0.0], [0.11, 0.46, 0.11]),
    (SHIN_L, [0.1, 0.03, 0.05], [0.11, 0.06, 0.22]),
    (THIGH_R, [-0.1, 0.71, 0.0], [0.13, 0.42, 0.13]),
    (SHIN_R, [-0.1, 0.27, 0.0], [0.11, 0.46, 0.11]),
    (SHIN_R, [-0.1, 0.03, 0.05], [0.11, 0.06, 0.22]),
];

/// Vertices of the skinned body: position, normal, joint.
#[derive(Default)]
struct Body {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    joints: Vec<u8>,
    indices: Vec<u16>,
}

fn body() -> Body {
    let mut b = Body::default();
    for &(joint, c, s) in BOXES {
        // Six faces, four vertices each (hard edges): normal axis, the two others.
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let base = b.positions.len() as u16;
                for (du, dv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    let mut p = c;
                    p[axis] += sign * 0.5 * s[axis];
                    p[u] += du * 0.5 * s[u];
                    p[v] += dv * 0.5 * s[v];
                    let mut n = [0.0; 3];
                    n[axis] = sign;
                    b.positions.push(p);
                    b.normals.push(n);
                    b.joints.push(joint as u8);
                }
                // Counter-clockwise seen from outside.
                if sign > 0.0 {
                    b.indices
                        .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
                } else {
                    b.indices
                        .extend([base, base + 2, base + 1, base, base + 3, base + 2]);
                }
            }
        }
    }
    b
}

/// A skirt skinned to the hips and thighs: a closed tube of `SKIRT_ROWS` rings of
/// `SKIRT_COLUMNS` vertices from the waist (y = 1.0, half widths 0.195 × 0.145 m, a
/// superellipse: clear of the hips' box collider in the `cape` example and of the hanging
/// hands) to the hem (y = 0.56, 0.33 × 0.28 m). The waist follows `Hips`; lower down each vertex leans on
/// the thigh on its side (up to 60 % at the hem), so the skin swings with the legs. Vertex
/// colour red is the painted max distance (0 at the waist, 1 at the hem, growing as the
/// square of the height fraction): what `ClothSkinning`'s `MaxDistance::VertexColor` reads.
struct Skirt {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    joints: Vec<[u8; 4]>,
    weights: Vec<[f32; 4]>,
    colours: Vec<[f32; 4]>,
    indices: Vec<u16>,
}

const SKIRT_ROWS: usize = 12;
const SKIRT_COLUMNS: usize = 32;

fn skirt() -> Skirt {
    let mut k = Skirt {
        positions: Vec::new(),
        normals: Vec::new(),
        joints: Vec::new(),
        weights: Vec::new(),
        colours: Vec::new(),
        indices: Vec::new(),
    };
    for r in 0..SKIRT_ROWS {
        let t = r as f32 / (SKIRT_ROWS - 1) as f32;
        let y = 1.0 - 0.44 * t;
        // Flaring slowly at first, past the hanging hands.
        let (rx, rz) = (0.195 + 0.135 * t * t, 0.145 + 0.135 * t);
        for c in 0..SKIRT_COLUMNS {
            let a = TAU * c as f32 / SKIRT_COLUMNS as f32;
            // A superellipse |x/rx|⁶ + |z/rz|⁶ = 1: round, but square enough at the waist to
            // clear the corners of the hips.
            let (ca, sa) = (a.cos(), a.sin());
            let e = |v: f32| v.signum() * v.abs().powf(1.0 / 3.0);
            let (x, z) = (rx * e(ca), rz * e(sa));
            // Outward: the gradient of the superellipse, tilted by the flare.
            let g = |v: f32, r: f32| v.signum() * (v.abs() / r).powi(5) / r;
            let n = [g(x, rx), 0.3 * t + 0.05, g(z, rz)];
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            k.positions.push([x, y, z]);
            k.normals.push([n[0] / l, n[1] / l, n[2] / l]);
            // Shared between the thighs by the side it is on (half each at the front and
            // back middle, so the skin never tears apart between the legs).
            let w = 0.6 * t;
            let left = 0.5 + 0.5 * ca;
            k.joints.push([HIPS as u8, THIGH_L as u8, THIGH_R as u8, 0]);
            k.weights.push([1.0 - w, w * left, w * (1.0 - left), 0.0]);
            k.colours.push([t * t, 0.0, 0.0, 1.0]);
        }
    }
    let at = |r: usize, c: usize| (r * SKIRT_COLUMNS + c % SKIRT_COLUMNS) as u16;
    for r in 0..SKIRT_ROWS - 1 {
        for c in 0..SKIRT_COLUMNS {
            // Counter-clockwise seen from outside.
            k.indices.extend([
                at(r, c),
                at(r, c + 1),
                at(r + 1, c),
                at(r + 1, c),
                at(r, c + 1),
                at(r + 1, c + 1),
            ]);
        }
    }
    k
}

/// One animation: its name, cycle length, and the pose at phase `φ ∈ [0, 1)`: rotation
/// angles about x (radians) per bone, and the hips' height offset.
struct Gait {
    name: &'static str,
    period: f32,
    /// Thigh swing, knee bend, arm swing, elbow bend, forward lean, hips bob.
    amp: [f32; 6],
}

const GAITS: [Gait; 2] = [
    Gait {
        name: "Walk",
        period: 1.0,
        amp: [0.45, 0.6, 0.35, 0.25, 0.05, 0.03],
    },
    Gait {
        name: "Run",
        period: 0.6,
        amp: [0.8, 1.3, 0.7, 1.2, 0.25, 0.06],
    },
];

/// Angles about x for every bone, and the hips' bob, at phase `phase` (0..1).
fn pose(g: &Gait, phase: f32) -> ([f32; 13], f32) {
    let [thigh, knee, arm, elbow, lean, bob] = g.amp;
    let a = phase * TAU;
    let mut r = [0.0f32; 13];
    // A hanging limb points −y; a rotation about +x by +θ turns it backwards (towards −z),
    // a standing one (the spine) forwards.
    r[THIGH_L] = -thigh * a.sin();
    r[THIGH_R] = thigh * a.sin();
    // Knees bend backwards while the leg swings forward (the shin's lower end goes −z).
    r[SHIN_L] = knee * (0.5 + 0.5 * (a + 1.2).sin()).powi(2);
    r[SHIN_R] = knee * (0.5 + 0.5 * (a + 1.2 + TAU / 2.0).sin()).powi(2);
    r[UPPER_ARM_L] = arm * a.sin();
    r[UPPER_ARM_R] = -arm * a.sin();
    // Elbows bend forward.
    r[FOREARM_L] = -elbow * (0.6 + 0.4 * a.sin());
    r[FOREARM_R] = -elbow * (0.6 - 0.4 * a.sin());
    r[SPINE] = lean;
    r[NECK] = -0.5 * lean;
    (r, bob * (2.0 * a).cos())
}

fn quat_x(angle: f32) -> [f32; 4] {
    let (s, c) = (0.5 * angle).sin_cos();
    [s, 0.0, 0.0, c]
}

struct Writer {
    bin: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl Writer {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let target = target.map_or(String::new(), |t| format!(r#","target":{t}"#));
        self.views.push(format!(
            r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{}{target}}}"#,
            bytes.len()
        ));
        self.views.len() - 1
    }

    /// An accessor of f32s of `ty` (`"SCALAR"`, `"VEC3"`, …, `"MAT4"`), with min and max
    /// when `bounds`.
    fn floats(
        &mut self,
        data: &[f32],
        width: usize,
        ty: &str,
        bounds: bool,
        target: Option<u32>,
    ) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let count = data.len() / width;
        let mut extra = String::new();
        if bounds {
            let (mut lo, mut hi) = (vec![f32::MAX; width], vec![f32::MIN; width]);
            for chunk in data.chunks(width) {
                for k in 0..width {
                    lo[k] = lo[k].min(chunk[k]);
                    hi[k] = hi[k].max(chunk[k]);
                }
            }
            let list = |v: &[f32]| {
                v.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join(",")
            };
            extra = format!(r#","min":[{}],"max":[{}]"#, list(&lo), list(&hi));
        }
        self.accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":5126,"count":{count},"type":"{ty}"{extra}}}"#
        ));
        self.accessors.len() - 1
    }

    fn raw(&mut self, bytes: &[u8], component: u32, count: usize, ty: &str, target: u32) -> usize {
        let view = self.view(bytes, Some(target));
        self.accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":{component},"count":{count},"type":"{ty}"}}"#
        ));
        self.accessors.len() - 1
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
    let b = body();
    let mut w = Writer {
        bin: Vec::new(),
        views: Vec::new(),
        accessors: Vec::new(),
    };
    let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    let pos = w.floats(&flat(&b.positions), 3, "VEC3", true, Some(34962));
    let nrm = w.floats(&flat(&b.normals), 3, "VEC3", false, Some(34962));
    let joints: Vec<u8> = b.joints.iter().flat_map(|&j| [j, 0, 0, 0]).collect();
    let jnt = w.raw(&joints, 5121, b.joints.len(), "VEC4", 34962);
    let weights: Vec<f32> = b.joints.iter().flat_map(|_| [1.0, 0.0, 0.0, 0.0]).collect();
    let wgt = w.floats(&weights, 4, "VEC4", false, Some(34962));
    let idx: Vec<u8> = b.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let ind = w.raw(&idx, 5123, b.indices.len(), "SCALAR", 34963);
    let k = skirt();
    let flat4 = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    let skirt_pos = w.floats(&flat(&k.positions), 3, "VEC3", true, Some(34962));
    let skirt_nrm = w.floats(&flat(&k.normals), 3, "VEC3", false, Some(34962));
    let skirt_joints: Vec<u8> = k.joints.iter().flatten().copied().collect();
    let skirt_jnt = w.raw(&skirt_joints, 5121, k.joints.len(), "VEC4", 34962);
    let skirt_wgt = w.floats(&flat4(&k.weights), 4, "VEC4", false, Some(34962));
    let skirt_col = w.floats(&flat4(&k.colours), 4, "VEC4", false, Some(34962));
    let skirt_idx: Vec<u8> = k.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let skirt_ind = w.raw(&skirt_idx, 5123, k.indices.len(), "SCALAR", 34963);
    // Inverse bind matrices: the bones' rest frames are translations only.
    let ibm: Vec<f32> = BONES
        .iter()
        .flat_map(|bn| {
            let [x, y, z] = bn.at;
            [
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -x, -y, -z, 1.0,
            ]
        })
        .collect();
    let ibm = w.floats(&ibm, 16, "MAT4", false, None);

    // Nodes: 0 "Character" (the scene root), 1 "Body" and 2 "Skirt" (the skinned meshes),
    // 3.. the bones.
    let bone_node = |i: usize| i + 3;
    let mut nodes = vec![
        format!(
            r#"{{"name":"Character","children":[1,2,{}]}}"#,
            bone_node(HIPS)
        ),
        r#"{"name":"Body","mesh":0,"skin":0}"#.to_string(),
        r#"{"name":"Skirt","mesh":1,"skin":0}"#.to_string(),
    ];
    for (i, bn) in BONES.iter().enumerate() {
        let local = match bn.parent {
            Some(p) => [0, 1, 2].map(|k| bn.at[k] - BONES[p].at[k]),
            None => bn.at,
        };
        let children: Vec<String> = BONES
            .iter()
            .enumerate()
            .filter(|(_, c)| c.parent == Some(i))
            .map(|(j, _)| bone_node(j).to_string())
            .collect();
        let children = if children.is_empty() {
            String::new()
        } else {
            format!(r#","children":[{}]"#, children.join(","))
        };
        nodes.push(format!(
            r#"{{"name":"{}","translation":[{},{},{}]{children}}}"#,
            bn.name, local[0], local[1], local[2]
        ));
    }

    // Animations: 17 keys over one cycle (the last equals the first, so it loops).
    let keys = 17;
    let mut animations = Vec::new();
    for g in &GAITS {
        let times: Vec<f32> = (0..keys)
            .map(|k| g.period * k as f32 / (keys - 1) as f32)
            .collect();
        let input = w.floats(&times, 1, "SCALAR", true, None);
        let mut samplers = Vec::new();
        let mut channels = Vec::new();
        // One linear sampler over the cycle's keys and the channel driving `path` of `node`.
        let mut channel = |output: usize, node: usize, path: &str| {
            samplers.push(format!(
                r#"{{"input":{input},"output":{output},"interpolation":"LINEAR"}}"#
            ));
            channels.push(format!(
                r#"{{"sampler":{},"target":{{"node":{node},"path":"{path}"}}}}"#,
                samplers.len() - 1
            ));
        };
        for (i, _) in BONES.iter().enumerate() {
            let rotations: Vec<f32> = (0..keys)
                .flat_map(|k| quat_x(pose(g, k as f32 / (keys - 1) as f32).0[i]))
                .collect();
            if rotations.chunks(4).all(|q| q[0] == 0.0) {
                continue; // this bone does not turn in this gait
            }
            let output = w.floats(&rotations, 4, "VEC4", false, None);
            channel(output, bone_node(i), "rotation");
        }
        let hips: Vec<f32> = (0..keys)
            .flat_map(|k| {
                let bob = pose(g, k as f32 / (keys - 1) as f32).1;
                let [x, y, z] = BONES[HIPS].at;
                [x, y + bob, z]
            })
            .collect();
        let output = w.floats(&hips, 3, "VEC3", false, None);
        channel(output, bone_node(HIPS), "translation");
        animations.push(format!(
            r#"{{"name":"{}","samplers":[{}],"channels":[{}]}}"#,
            g.name,
            samplers.join(","),
            channels.join(",")
        ));
    }

    let joint_nodes: Vec<String> = (0..BONES.len()).map(|i| bone_node(i).to_string()).collect();
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0", "generator": "bevy_cloth examples/make_character.rs"}},
  "scene": 0,
  "scenes": [{{"name": "Scene", "nodes": [0]}}],
  "nodes": [
    {}
  ],
  "meshes": [
    {{"name": "Body", "primitives": [{{"attributes": {{"POSITION": {pos}, "NORMAL": {nrm}, "JOINTS_0": {jnt}, "WEIGHTS_0": {wgt}}}, "indices": {ind}, "material": 0}}]}},
    {{"name": "Skirt", "primitives": [{{"attributes": {{"POSITION": {skirt_pos}, "NORMAL": {skirt_nrm}, "JOINTS_0": {skirt_jnt}, "WEIGHTS_0": {skirt_wgt}, "COLOR_0": {skirt_col}}}, "indices": {skirt_ind}, "material": 1}}]}}
  ],
  "materials": [
    {{"name": "Body", "pbrMetallicRoughness": {{"baseColorFactor": [0.22, 0.2, 0.18, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}}}},
    {{"name": "Skirt", "doubleSided": true, "pbrMetallicRoughness": {{"baseColorFactor": [0.12, 0.3, 0.55, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.9}}}}
  ],
  "skins": [{{"name": "Armature", "inverseBindMatrices": {ibm}, "joints": [{}], "skeleton": {}}}],
  "animations": [
    {}
  ],
  "buffers": [{{"byteLength": {}, "uri": "character.bin"}}],
  "bufferViews": [
    {}
  ],
  "accessors": [
    {}
  ]
}}
"#,
        nodes.join(",\n    "),
        joint_nodes.join(","),
        bone_node(HIPS),
        animations.join(",\n    "),
        w.bin.len(),
        w.views.join(",\n    "),
        w.accessors.join(",\n    ")
    );
    std::fs::create_dir_all(&out_dir).expect("create the output folder");
    std::fs::write(format!("{out_dir}/character.gltf"), json).expect("write the glTF");
    std::fs::write(format!("{out_dir}/character.bin"), &w.bin).expect("write the buffer");
    println!(
        "wrote {out_dir}/character.gltf and .bin ({} bytes): {} + {} (skirt) vertices, {} bones, animations {}",
        w.bin.len(),
        b.positions.len(),
        k.positions.len(),
        BONES.len(),
        GAITS.map(|g| g.name).join(", ")
    );
}
