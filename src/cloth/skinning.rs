//! Skinned clothing: [`ClothSkinning`] holds a cloth cut from a skinned mesh (a skirt, sleeves,
//! a tabard) near the animated skin.

use bevy::ecs::entity::{EntityMapper, MapEntities};
use bevy::mesh::VertexAttributeValues;
use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
use bevy::prelude::*;

use super::error::{ClothError, ClothInvalid};
use super::sim::{ClothSim, ClothSource};
use super::systems::note_rejection;
use crate::foundation::{EntityName, FixedPoses};

/// Skinned clothing: put it on a [`Cloth`](super::Cloth) whose entity has a [`SkinnedMesh`]
/// (a glTF character's skirt, cape or sleeves) and every vertex stays within its *max
/// distance* of where the animated skin puts it: 0 follows the skin (the waistband), larger
/// values let the hem swing (Unity Cloth's max distance, NvCloth's motion constraints).
/// Optionally a [`ClothBackstop`] keeps the cloth from passing through the body behind it.
///
/// The skin is evaluated on the cloth's fixed clock from the joints' poses of each step
/// ([`FixedPoses`]; with `ClothAnimationPlugin` the bones move on that clock too). The cloth takes over drawing: the entity's `SkinnedMesh`
/// is removed and the cloth's own mesh drops its joint attributes, so what is drawn is the
/// simulation. At the first step every vertex is placed where the skin puts it. Removing
/// `ClothSkinning` lets the cloth run free (the `SkinnedMesh` is not put back); removing the
/// `Cloth` puts the `SkinnedMesh` and the entity's own mesh back.
///
/// A `Cloth` on a skinned mesh *without* `ClothSkinning` runs free from the mesh's bind pose:
/// the `SkinnedMesh` is taken off the same way (with one warning), and adding `ClothSkinning`
/// later holds it to the skin.
///
/// A `PerVertex` list of the wrong length, a mesh without joint attributes or vertex colours
/// (where asked for), or a negative or non-finite distance is reported once as
/// [`ClothError::Skinning`] and the cloth runs free meanwhile; a joint with no pose is
/// reported the same way and the targets stay where they were. The same on the GPU backend
/// (the targets are uploaded every step).
#[derive(Component, Clone, Debug, PartialEq, Reflect)]
#[reflect(Component)]
pub struct ClothSkinning {
    /// How far each vertex may move from its skinned position, metres.
    pub max_distance: MaxDistance,
    /// A sphere behind the skin the cloth may not enter, if any.
    pub backstop: Option<ClothBackstop>,
}

impl Default for ClothSkinning {
    /// Max distances painted into the mesh's vertex colours (red, 1.0 = 10 cm), no backstop.
    fn default() -> Self {
        Self {
            max_distance: MaxDistance::VertexColor { scale: 0.1 },
            backstop: None,
        }
    }
}

/// Where [`ClothSkinning`]'s max distances come from.
#[derive(Clone, Debug, PartialEq, Reflect)]
pub enum MaxDistance {
    /// The same for every vertex, metres.
    Uniform(f32),
    /// One per vertex of the mesh (as the asset stores them, before welding), metres.
    PerVertex(Vec<f32>),
    /// A weight map painted into the mesh's vertex colours (`Mesh::ATTRIBUTE_COLOR`, glTF
    /// `COLOR_0`): the red channel times `scale` metres (black follows the skin). The cloth's
    /// own mesh drops the colours, so the map does not tint the material.
    VertexColor {
        /// Metres at red = 1.
        scale: f32,
    },
}

/// A sphere behind the skin that [`ClothSkinning`] keeps every vertex out of (Unity Cloth's
/// backstop, NvCloth's separation constraints): centred `radius + distance` behind the
/// skinned position along the skin's normal.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct ClothBackstop {
    /// Radius of the sphere, metres (larger: flatter, closer to the skin's tangent plane).
    pub radius: f32,
    /// How far behind the skin its surface lies, metres (0: the cloth may not go behind the
    /// skin at all).
    pub distance: f32,
}

/// What a [`ClothSkinning`] cloth keeps between steps: the skin per particle. Cloned with
/// the entity (its joints mapped as Bevy maps a `SkinnedMesh`'s), so that a clone of a
/// skinned cloth, whose `SkinnedMesh` this holds, is skinned too.
#[derive(Component, Clone, Debug)]
#[component(map_entities)]
pub(crate) struct ClothSkin {
    /// The entity's `SkinnedMesh`, taken over (`None` until it was).
    skinned: Option<SkinnedMesh>,
    joints: Vec<Entity>,
    inverse_bindposes: Vec<Mat4>,
    /// Per particle: bind-space position and normal, joints and weights, max distance.
    bind: Vec<(Vec3, Vec3)>,
    influence: Vec<([u16; 4], [f32; 4])>,
    max: Vec<f32>,
    /// Whether the next targets start the motion afresh.
    snap: bool,
    error: Option<ClothError>,
}

/// `joints` mapped one by one (a `SkinnedMesh` maps its own the same way).
fn map_joints<E: EntityMapper>(joints: &mut [Entity], mapper: &mut E) {
    for j in joints {
        *j = mapper.get_mapped(*j);
    }
}

impl MapEntities for ClothSkin {
    fn map_entities<E: EntityMapper>(&mut self, mapper: &mut E) {
        map_joints(&mut self.joints, mapper);
        if let Some(s) = &mut self.skinned {
            map_joints(&mut s.joints, mapper);
        }
    }
}

impl ClothSkin {
    /// The `SkinnedMesh` the cloth took off its entity, if it did.
    pub(super) fn taken(&self) -> Option<&SkinnedMesh> {
        self.skinned.as_ref()
    }
}

fn attribute_f32x3(mesh: &Mesh, id: bevy::mesh::MeshVertexAttribute) -> Option<&[[f32; 3]]> {
    match mesh.attribute(id)? {
        VertexAttributeValues::Float32x3(v) => Some(v),
        _ => None,
    }
}

/// The skin per particle (joints, inverse bind poses, bind pose, influences) from the mesh
/// and its `SkinnedMesh`.
type SkinData = (
    Vec<Entity>,
    Vec<Mat4>,
    Vec<(Vec3, Vec3)>,
    Vec<([u16; 4], [f32; 4])>,
);

fn skin_data(
    skinned: &SkinnedMesh,
    bindposes: &Assets<SkinnedMeshInverseBindposes>,
    mesh: &Mesh,
    cloth: &ClothSim,
) -> Result<SkinData, String> {
    let weld = cloth.weld();
    let n = weld.vertex_count();
    let positions = attribute_f32x3(mesh, Mesh::ATTRIBUTE_POSITION)
        .ok_or("the mesh has no Float32x3 positions")?;
    if positions.len() != n {
        return Err(format!(
            "the mesh has {} vertices, the cloth was built from {n}",
            positions.len()
        ));
    }
    let normals = attribute_f32x3(mesh, Mesh::ATTRIBUTE_NORMAL).filter(|v| v.len() == n);
    let joints: &[[u16; 4]] = match mesh.attribute(Mesh::ATTRIBUTE_JOINT_INDEX) {
        Some(VertexAttributeValues::Uint16x4(v)) if v.len() == n => v,
        _ => return Err("the mesh has no joint indices (Uint16x4 JOINTS_0)".to_owned()),
    };
    let weights: &[[f32; 4]] = match mesh.attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT) {
        Some(VertexAttributeValues::Float32x4(v)) if v.len() == n => v,
        _ => return Err("the mesh has no joint weights (Float32x4 WEIGHTS_0)".to_owned()),
    };
    let inverse_bindposes: Vec<Mat4> = bindposes
        .get(&skinned.inverse_bindposes)
        .ok_or("the SkinnedMesh's inverse bind poses are not loaded")?
        .iter()
        .copied()
        .collect();
    if inverse_bindposes.len() < skinned.joints.len() {
        return Err(format!(
            "{} joints but {} inverse bind poses",
            skinned.joints.len(),
            inverse_bindposes.len()
        ));
    }
    if let Some(bad) = joints
        .iter()
        .flatten()
        .find(|&&j| usize::from(j) >= skinned.joints.len())
    {
        return Err(format!(
            "a vertex names joint {bad}, the SkinnedMesh has {}",
            skinned.joints.len()
        ));
    }
    let particles = weld.particle_count();
    let mut bind = Vec::with_capacity(particles);
    let mut influence = Vec::with_capacity(particles);
    for p in 0..particles {
        let v = weld.representative(p as u32) as usize;
        let normal = normals.map_or(Vec3::Y, |ns| Vec3::from(ns[v]));
        bind.push((Vec3::from(positions[v]), normal));
        influence.push((joints[v], weights[v]));
    }
    Ok((skinned.joints.clone(), inverse_bindposes, bind, influence))
}

/// Each particle's max distance (the smallest of its mesh vertices'), checked.
fn max_distances(
    settings: &ClothSkinning,
    mesh: &Mesh,
    cloth: &ClothSim,
) -> Result<Vec<f32>, String> {
    let weld = cloth.weld();
    let n = weld.vertex_count();
    let per_vertex: Vec<f32> = match &settings.max_distance {
        MaxDistance::Uniform(d) => vec![*d; n],
        MaxDistance::PerVertex(list) => {
            if list.len() != n {
                return Err(format!(
                    "{} max distances for a mesh of {n} vertices",
                    list.len()
                ));
            }
            list.clone()
        }
        MaxDistance::VertexColor { scale } => match mesh.attribute(Mesh::ATTRIBUTE_COLOR) {
            Some(VertexAttributeValues::Float32x4(c)) if c.len() == n => {
                c.iter().map(|c| c[0] * scale).collect()
            }
            _ => {
                return Err(
                    "the mesh has no Float32x4 vertex colours (COLOR_0) to read max \
                            distances from"
                        .to_owned(),
                );
            }
        },
    };
    if let Some(d) = per_vertex.iter().find(|d| !(d.is_finite() && **d >= 0.0)) {
        return Err(format!("max distance {d} (must be finite and ≥ 0)"));
    }
    if let Some(b) = settings.backstop
        && !(b.radius.is_finite() && b.radius > 0.0 && b.distance.is_finite() && b.distance >= 0.0)
    {
        return Err(format!(
            "backstop radius {} and distance {} (must be finite, radius > 0, distance ≥ 0)",
            b.radius, b.distance
        ));
    }
    let mut max = vec![f32::INFINITY; weld.particle_count()];
    for (v, d) in per_vertex.iter().enumerate() {
        let p = weld.particle(v as u32) as usize;
        max[p] = max[p].min(*d);
    }
    Ok(max)
}

impl ClothSkin {
    /// The skin's targets (xyz, max distance in w) and backstop normals (with the backstop
    /// `behind` the skin, if any) at the joints' `matrices` (joint global × inverse bind pose).
    fn evaluate(
        &self,
        matrices: &[Mat4],
        behind: Option<f32>,
        targets: &mut Vec<Vec4>,
        backstop: &mut Vec<Vec4>,
    ) {
        targets.clear();
        backstop.clear();
        for (((p, n), (joints, weights)), max) in
            self.bind.iter().zip(&self.influence).zip(&self.max)
        {
            let mut m = Mat4::ZERO;
            let mut total = 0.0;
            for (j, w) in joints.iter().zip(weights) {
                if *w > 0.0 {
                    m += matrices[usize::from(*j)] * *w;
                    total += w;
                }
            }
            if total > 0.0 && (total - 1.0).abs() > 1e-6 {
                m *= 1.0 / total;
            }
            targets.push(m.transform_point3(*p).extend(*max));
            if let Some(distance) = behind {
                let normal = m.transform_vector3(*n).normalize_or(Vec3::Y);
                backstop.push(normal.extend(distance));
            }
        }
    }
}

/// A plain [`Cloth`](super::Cloth) (no [`ClothSkinning`]) put on a skinned mesh: the entity's
/// `SkinnedMesh`, taken off so that the renderer draws the simulation and not the simulation
/// skinned a second time; kept for a `ClothSkinning` added later.
/// Cloned with the entity, its joints mapped (as [`ClothSkin`]).
#[derive(Component, Clone, Debug)]
#[component(map_entities)]
pub(crate) struct ClothUnskinned(pub(super) SkinnedMesh);

impl MapEntities for ClothUnskinned {
    fn map_entities<E: EntityMapper>(&mut self, mapper: &mut E) {
        map_joints(&mut self.0.joints, mapper);
    }
}

/// A plain cloth on a skinned mesh runs free from the mesh's bind pose: takes the entity's
/// `SkinnedMesh` off and the joint attributes off the cloth's own mesh (as [`ClothSkinning`]
/// does), and says so once, naming what keeps a cloth on its skin.
#[expect(clippy::type_complexity, reason = "a system's query")]
pub(super) fn unskin_free_cloths(
    mut commands: Commands,
    cloths: Query<
        (Entity, Option<&Name>, Option<&SkinnedMesh>, Ref<ClothSim>),
        (
            Without<ClothSkinning>,
            Without<ClothSkin>,
            Or<(With<SkinnedMesh>, With<ClothUnskinned>)>,
        ),
    >,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    for (entity, name, skinned, cloth) in &cloths {
        // Taken over once; a cloth built again (a changed `Cloth`, mesh) has a new copy of
        // the mesh, with joints again.
        if skinned.is_none() && !cloth.is_added() {
            continue;
        }
        if let Some(skinned) = skinned {
            warn!(
                "cloth {}: the entity has a SkinnedMesh and no ClothSkinning: the cloth runs \
                 free from the mesh's bind pose and is no longer skinned; add ClothSkinning to \
                 keep it on the animated skin",
                EntityName::new(entity, name)
            );
            commands
                .entity(entity)
                .remove::<SkinnedMesh>()
                .insert(ClothUnskinned(skinned.clone()));
        }
        if let Some(mut mesh) = meshes.get_mut(cloth.mesh()) {
            mesh.remove_attribute(Mesh::ATTRIBUTE_JOINT_INDEX);
            mesh.remove_attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT);
        }
    }
}

/// Applies [`ClothSkinning`]: builds each cloth's skin once (and after a change), takes the
/// entity's `SkinnedMesh` over, and sets the cloth's motion targets for this step.
#[expect(clippy::type_complexity, reason = "a system's queries")]
pub(super) fn skin_cloths(
    mut commands: Commands,
    mut cloths: Query<
        (
            Entity,
            Option<&Name>,
            Ref<ClothSkinning>,
            Option<&SkinnedMesh>,
            Option<&ClothUnskinned>,
            Option<&ClothSource>,
            Option<&mut ClothSkin>,
            &mut ClothSim,
        ),
        Without<ClothInvalid>,
    >,
    mut released: Query<(Entity, &mut ClothSim), (With<ClothSkin>, Without<ClothSkinning>)>,
    mut meshes: ResMut<Assets<Mesh>>,
    bindposes: Option<Res<Assets<SkinnedMeshInverseBindposes>>>,
    poses: FixedPoses,
    mut scratch: Local<(Vec<Mat4>, Vec<Vec4>, Vec<Vec4>)>,
) {
    for (entity, mut cloth) in &mut released {
        cloth.clear_motion_targets();
        commands.entity(entity).remove::<ClothSkin>();
    }
    let no_bindposes = Assets::<SkinnedMeshInverseBindposes>::default();
    let bindposes = bindposes.as_deref().unwrap_or(&no_bindposes);
    for (entity, name, settings, skinned, unskinned, source, mut skin, mut cloth) in &mut cloths {
        let who = EntityName::new(entity, name);
        // Built once, and again when the settings change or the cloth was built again (its
        // new copy of the mesh has the joints again).
        let fresh = skin.is_none() || settings.is_changed() || cloth.is_added();
        if fresh {
            let mut slot = skin.as_deref_mut().and_then(|s| s.error.take());
            // The mesh as the user gave it (the cloth's copy holds simulated positions).
            let source = source.map_or_else(|| cloth.mesh().clone(), |s| s.source.clone());
            let skinned = skinned
                .or(unskinned.map(|u| &u.0))
                .cloned()
                .or_else(|| skin.as_deref().and_then(|s| s.skinned.clone()));
            let built = meshes
                .get(&source)
                .ok_or_else(|| "the cloth's mesh is not loaded".to_owned())
                .and_then(|mesh| {
                    let sk = skinned
                        .as_ref()
                        .ok_or_else(|| "the entity has no SkinnedMesh".to_owned())?;
                    Ok((
                        skin_data(sk, bindposes, mesh, &cloth)?,
                        max_distances(&settings, mesh, &cloth)?,
                    ))
                });
            match built {
                Ok(((joints, inverse_bindposes, bind, influence), max)) => {
                    note_rejection(&mut commands, who, &mut slot, Ok(()), ("skinning", ""));
                    if let Some(mut mesh) = meshes.get_mut(cloth.mesh()) {
                        // The cloth draws what it simulates: no skinning on its mesh.
                        mesh.remove_attribute(Mesh::ATTRIBUTE_JOINT_INDEX);
                        mesh.remove_attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT);
                        // A weight map, not a colour: not drawn.
                        if matches!(settings.max_distance, MaxDistance::VertexColor { .. }) {
                            mesh.remove_attribute(Mesh::ATTRIBUTE_COLOR);
                        }
                    }
                    commands
                        .entity(entity)
                        .remove::<(SkinnedMesh, ClothUnskinned)>()
                        .insert(ClothSkin {
                            skinned,
                            joints,
                            inverse_bindposes,
                            bind,
                            influence,
                            max,
                            snap: true,
                            error: None,
                        });
                }
                Err(reason) => {
                    note_rejection(
                        &mut commands,
                        who,
                        &mut slot,
                        Err(ClothError::Skinning(reason)),
                        ("skinning", "it runs free meanwhile"),
                    );
                    cloth.clear_motion_targets();
                    match skin.as_deref_mut() {
                        Some(s) => {
                            s.max.clear();
                            s.error = slot;
                        }
                        // Where the report is kept until the settings change.
                        None => {
                            commands.entity(entity).insert(ClothSkin {
                                skinned: None,
                                joints: Vec::new(),
                                inverse_bindposes: Vec::new(),
                                bind: Vec::new(),
                                influence: Vec::new(),
                                max: Vec::new(),
                                snap: true,
                                error: slot,
                            });
                        }
                    }
                }
            }
            // Applied from the next step on (the new skin lands with the commands).
            continue;
        }
        let Some(skin) = skin.as_deref_mut() else {
            continue;
        };
        if skin.bind.len() != cloth.simulation().state().len() || skin.max.len() != skin.bind.len()
        {
            continue;
        }
        let (matrices, targets, backstop) = &mut *scratch;
        matrices.clear();
        let mut missing = None;
        for (j, ibp) in skin.joints.iter().zip(&skin.inverse_bindposes) {
            match poses.get(*j) {
                Some(g) => matrices.push(g.to_matrix() * *ibp),
                None => {
                    missing = Some(*j);
                    break;
                }
            }
        }
        note_rejection(
            &mut commands,
            who,
            &mut skin.error,
            missing.map_or(Ok(()), |j| {
                Err(ClothError::Skinning(format!(
                    "joint {j} does not exist or has no transform"
                )))
            }),
            ("skinning", "its skin targets hold where they were"),
        );
        if missing.is_some() {
            continue;
        }
        skin.evaluate(
            matrices,
            settings.backstop.map(|b| b.distance),
            targets,
            backstop,
        );
        let radius = settings.backstop.map_or(0.0, |b| b.radius);
        let snap = core::mem::take(&mut skin.snap) || cloth.teleport.is_some();
        if !cloth.simulation().has_motion_targets() {
            // Start where the skin is (an edit: a GPU cloth restarts from it).
            let placed: Vec<Vec3> = targets.iter().map(|t| t.truncate()).collect();
            cloth.simulation_mut().reset_to(&placed);
        }
        if let Err(e) = cloth.set_motion_targets(targets, backstop, radius, snap) {
            note_rejection(
                &mut commands,
                who,
                &mut skin.error,
                Err(ClothError::Skinning(e.to_string())),
                ("skinning", "its skin targets hold where they were"),
            );
        }
    }
}
