//! Colliders: shapes placed by an entity's transform that every cloth collides with.
//!
//! Data flow: each fixed step, [`ClothColliderPlugin`]'s systems (in
//! [`ClothSystems::Prepare`]) bake mesh colliders into signed
//! distance fields once, then gather every [`ClothCollider`] with its pose at the start and end
//! of the step into [`ClothColliders`]. The cloth step collides against them and leaves the
//! impulse each collider received in its [`ClothContactImpulse`], which gameplay (or the
//! `rapier` bridge) can apply to rigid bodies.
//!
//! Moving colliders are interpolated over the substeps, so they do not tunnel through cloth
//! while `speed × substep length < radius + thickness` (about 120 m/s for a 0.2 m ball at 60 Hz
//! with 10 substeps). A collider that jumps farther than its
//! [`teleport_distance`](ClothCollider::teleport_distance) in one step (2 m by default, the
//! same rule and default as cloth pins) is treated as teleported: it appears at its new place
//! without sweeping through the cloth. Poses are read as of the fixed step
//! ([`FixedPoses`]), so a collider moved in `FixedUpdate` acts where it is in that step.
//! Removing [`ClothCollider`] forgets its last pose and impulse: put back elsewhere, it
//! appears there.

#[cfg(feature = "avian")]
pub mod avian;
#[cfg(any(feature = "rapier", feature = "avian"))]
mod bridge;
#[cfg(feature = "rapier")]
pub mod rapier;

#[cfg(any(feature = "rapier", feature = "avian"))]
pub use bridge::NoClothCollision;

use std::sync::Arc;

use bevy::prelude::*;
use bevy::reflect::{TypePath, impl_reflect_opaque};

use crate::foundation::{
    ClothSchedule, ClothSystems, ClothWorkers, EntityName, FixedPoses, SimulatedCloth,
    mesh_fingerprint, modified_meshes, read_mesh,
};
use crate::solver::{
    Collider, ContactImpulse, DEFAULT_TELEPORT_DISTANCE, Pose, SdfGrid, Shape, is_teleport, limits,
};

/// What a mesh collider is made from.
#[derive(TypePath, Clone, Debug, PartialEq)]
pub enum ColliderMesh {
    /// A triangle mesh asset, baked into a signed distance field when it has loaded (and again
    /// when the asset changes, e.g. reloaded from disk): the entity's own [`Mesh3d`] when
    /// `mesh` is `None`. `resolution` is the number of cells along the mesh's longest side (48
    /// is a good start). Cloth stays outside a closed mesh and on the side an open one's
    /// triangles face (a terrain, a floor; see [`SdfGrid`]); an index buffer is optional. A
    /// skinned mesh is baked in its bind pose and does not follow its bones.
    Asset {
        /// The mesh to bake, or `None` for the entity's `Mesh3d`.
        mesh: Option<Handle<Mesh>>,
        /// Cells along the longest side.
        resolution: u32,
    },
    /// An already baked field (from the rapier bridge, or one bake shared by many colliders).
    Baked(Arc<SdfGrid>),
}

/// The shape of a [`ClothCollider`], in the entity's local frame (scaled by its transform):
/// the solver's [`Shape`], with a mesh named by [`ColliderMesh`].
///
/// Spheres scale by the largest scale axis, boxes by each axis, capsules' lengths by y and
/// their radius by the larger of x and z; a mesh scales uniformly by the largest axis.
pub type ColliderShape = Shape<ColliderMesh>;

impl_reflect_opaque!((in bevy_cloth::solver) Shape<M: Clone + core::fmt::Debug + PartialEq + Send + Sync + TypePath>(Clone, Debug, PartialEq));

/// Makes an entity an obstacle for every cloth.
///
/// # Example
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// fn spawn(mut commands: Commands) {
///     commands.spawn((ClothCollider::sphere(0.5), Transform::from_xyz(0.0, 1.0, 0.0)));
///     commands.spawn((ClothCollider::plane(), Transform::default()));
/// }
/// # bevy::ecs::system::assert_is_system(spawn);
/// ```
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Clone, PartialEq)]
#[require(Transform)]
pub struct ClothCollider {
    /// The shape.
    pub shape: ColliderShape,
    /// Gap kept between cloth vertices and the surface, in metres. A little more than the
    /// cloth's half thickness keeps rendered triangles from dipping into the surface.
    pub thickness: f32,
    /// Coulomb friction: 0 slides, around 0.5 for fabric on wood, 1 or more grips.
    pub friction: f32,
    /// A jump farther than this in one fixed step (metres) is a teleport: the collider appears
    /// at its new place instead of sweeping through the cloth on its way. The same rule as
    /// a cloth's pins ([`DEFAULT_TELEPORT_DISTANCE`] by default).
    pub teleport_distance: f32,
}

impl ClothCollider {
    /// A collider with default thickness (1 cm), friction (0.4) and teleport distance (2 m).
    #[must_use]
    pub fn new(shape: ColliderShape) -> Self {
        Self {
            shape,
            thickness: 0.01,
            friction: 0.4,
            teleport_distance: DEFAULT_TELEPORT_DISTANCE,
        }
    }

    /// A ball of `radius`.
    #[must_use]
    pub fn sphere(radius: f32) -> Self {
        Self::new(ColliderShape::Sphere { radius })
    }

    /// A box of `half_extents`.
    #[must_use]
    pub fn cuboid(half_extents: Vec3) -> Self {
        Self::new(ColliderShape::Cuboid { half_extents })
    }

    /// A capsule along local y, as Bevy's `Capsule3d::new(radius, length)`: `length` is the
    /// straight part between the two hemispheres' centres (the capsule is
    /// `length + 2·radius` tall).
    #[must_use]
    pub fn capsule(radius: f32, length: f32) -> Self {
        Self::new(ColliderShape::Capsule {
            radius,
            half_length: 0.5 * length,
        })
    }

    /// A floor through the entity, normal along its local +y.
    #[must_use]
    pub fn plane() -> Self {
        Self::new(ColliderShape::Plane)
    }

    /// The entity's own `Mesh3d`, baked into a signed distance field of `resolution` cells.
    #[must_use]
    pub fn mesh(resolution: u32) -> Self {
        Self::new(ColliderShape::Mesh(ColliderMesh::Asset {
            mesh: None,
            resolution,
        }))
    }

    /// The mesh asset `mesh` (any entity's, or a glTF primitive loaded by its label, such as
    /// `assets.load("statue.gltf#Mesh0/Primitive0")`), baked into a signed distance field of
    /// `resolution` cells when it has loaded; the collider is placed by its own entity.
    #[must_use]
    pub fn mesh_asset(mesh: Handle<Mesh>, resolution: u32) -> Self {
        Self::new(ColliderShape::Mesh(ColliderMesh::Asset {
            mesh: Some(mesh),
            resolution,
        }))
    }

    /// A mesh already baked into a signed distance field (shared, not copied).
    #[must_use]
    pub fn baked(field: Arc<SdfGrid>) -> Self {
        Self::new(ColliderShape::Mesh(ColliderMesh::Baked(field)))
    }

    /// Sets the thickness.
    #[must_use]
    pub fn with_thickness(mut self, thickness: f32) -> Self {
        self.thickness = thickness;
        self
    }

    /// Sets the friction.
    #[must_use]
    pub fn with_friction(mut self, friction: f32) -> Self {
        self.friction = friction;
        self
    }
}

/// The impulse every cloth applied to this collider during the last fixed step (N·s, and
/// N·m·s about the collider's origin). Zero when nothing touched it.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Clone, PartialEq)]
pub struct ClothContactImpulse {
    /// Linear impulse.
    pub linear: Vec3,
    /// Angular impulse about the collider's origin.
    pub angular: Vec3,
}

/// Where a collider was at the end of the last step (to sweep it through this one), and its
/// baked field for mesh shapes.
///
/// Not copied when the entity is cloned: a copy starts where it is put, instead of sweeping
/// from where its original was through whatever cloth lies between.
#[derive(Component, Clone, Debug, Default)]
#[component(clone_behavior = Ignore)]
pub struct ColliderRuntime {
    last: Option<Pose>,
    /// The step `last` is from ([`gather_colliders`]' count): a collider left out of a step
    /// (disabled, scaled to nothing, without a pose) starts the next one where it is.
    last_step: u64,
    baked: Option<Arc<SdfGrid>>,
    failed: bool,
    /// The mesh and resolution the field was baked (or refused) for: a change bakes again.
    baked_for: Option<(AssetId<Mesh>, u32)>,
    /// The mesh's contents when baked (a changed asset bakes again).
    fingerprint: u64,
}

/// Every collider of this step, ready for the solver, with its entity.
#[derive(Resource, Clone, Debug, Default)]
pub struct ClothColliders {
    /// Colliders in solver form.
    pub colliders: Vec<Collider>,
    /// The entity of each collider.
    pub entities: Vec<Entity>,
}

/// Adds colliders: mesh baking, per-step gathering, contact impulses.
///
/// Part of `ClothPlugins`; its systems run in the group's [`ClothSchedule`], in
/// [`ClothSystems::Prepare`].
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothColliderPlugin;

impl Plugin for ClothColliderPlugin {
    fn build(&self, app: &mut App) {
        let schedule = ClothSchedule::of(app);
        app.register_type::<ClothCollider>()
            .register_type::<ClothContactImpulse>()
            .init_resource::<ClothColliders>()
            .add_systems(
                schedule,
                (bake_mesh_colliders, gather_colliders)
                    .chain()
                    .in_set(ClothSystems::Prepare),
            )
            .add_observer(on_collider_removed)
            .add_systems(
                PreUpdate,
                rebake_changed_meshes.run_if(resource_exists::<Messages<AssetEvent<Mesh>>>),
            );
    }
}

/// A mesh collider whose mesh asset changed (reloaded from disk, or edited through
/// `Assets::get_mut`) is baked again at the next step; the old field acts until then.
fn rebake_changed_meshes(
    mut events: MessageReader<AssetEvent<Mesh>>,
    mut colliders: Query<&mut ColliderRuntime>,
    meshes: Res<Assets<Mesh>>,
) {
    let changed = modified_meshes(&mut events);
    if changed.is_empty() {
        return;
    }
    for mut rt in &mut colliders {
        // Only a change of contents: the engine may touch an asset without changing it.
        if let Some((id, _)) = rt.baked_for
            && changed.contains(&id)
            && meshes
                .get(id)
                .is_some_and(|m| mesh_fingerprint(m) != rt.fingerprint)
        {
            rt.baked_for = None;
        }
    }
}

/// A removed collider forgets where it was and what it received: put back elsewhere, it
/// appears there instead of sweeping from its old place.
fn on_collider_removed(removed: On<Remove, ClothCollider>, mut commands: Commands) {
    commands
        .entity(removed.entity)
        .try_remove::<(ColliderRuntime, ClothContactImpulse)>();
}

/// Pose of a transform for the solver: translation, rotation and the largest scale axis; the
/// shape absorbs non-uniform scale where it can (boxes, capsules). `None` for a mesh not baked
/// yet.
fn pose_and_shape(
    gt: &GlobalTransform,
    shape: &ColliderShape,
    baked: Option<&Arc<SdfGrid>>,
) -> Option<(Pose, Shape)> {
    let (scale, rotation, translation) = gt.to_scale_rotation_translation();
    let s = scale.abs();
    let max = s.max_element();
    let unit = Pose {
        translation,
        rotation,
        scale: 1.0,
    };
    let shape = shape.clone().try_map_mesh(|m| match m {
        ColliderMesh::Asset { .. } => baked.cloned(),
        ColliderMesh::Baked(field) => Some(field),
    })?;
    Some(match shape {
        Shape::Sphere { radius } => (
            unit,
            Shape::Sphere {
                radius: radius * max,
            },
        ),
        Shape::Cuboid { half_extents } => (
            unit,
            Shape::Cuboid {
                half_extents: half_extents * s,
            },
        ),
        Shape::Capsule {
            radius,
            half_length,
        } => (
            unit,
            Shape::Capsule {
                radius: radius * s.x.max(s.z),
                half_length: half_length * s.y,
            },
        ),
        Shape::Plane => (unit, Shape::Plane),
        Shape::Mesh(field) => (Pose { scale: max, ..unit }, Shape::Mesh(field)),
    })
}

/// What [`bake_mesh_colliders`] reads of each collider entity.
type BakeQueryData = (
    (Entity, Option<&'static Name>),
    &'static ClothCollider,
    Option<&'static Mesh3d>,
    Option<&'static mut ColliderRuntime>,
    Has<bevy::mesh::skinning::SkinnedMesh>,
    Has<SimulatedCloth>,
);

/// Bakes mesh colliders once their mesh is loaded.
fn bake_mesh_colliders(
    mut commands: Commands,
    meshes: Option<Res<Assets<Mesh>>>,
    workers: Option<Res<ClothWorkers>>,
    mut colliders: Query<BakeQueryData>,
) {
    // Baked on the cloth plugins' threads: the field is the same on any number of them.
    let par = ClothWorkers::or_serial(workers.as_deref());
    for ((entity, name), collider, mesh3d, runtime, skinned, cloth) in &mut colliders {
        let who = EntityName::new(entity, name);
        let ColliderShape::Mesh(ColliderMesh::Asset { mesh, resolution }) = &collider.shape else {
            continue;
        };
        // The mesh to bake: its own handle, or the entity's `Mesh3d` — not on a cloth's
        // entity, whose mesh is the cloth (baked again every frame as it moves, it would push
        // the cloth against itself).
        let handle = match (mesh, mesh3d) {
            (Some(h), _) => Ok(h),
            (None, Some(_)) if cloth => Err(
                "a Mesh shape on a cloth's own entity would be the cloth itself; it is ignored \
                 (ClothSelfCollision keeps a cloth from passing through itself; to collide other \
                 cloths with this mesh, give the collider a mesh handle of its own)",
            ),
            (None, Some(m)) => Ok(&m.0),
            (None, None) => Err(
                "ClothCollider::mesh bakes the entity's own Mesh3d, and it has none (a glTF \
                 scene keeps its meshes on child entities: put the collider on the child with \
                 the Mesh3d, or name the mesh with ClothCollider::mesh_asset)",
            ),
        };
        let handle = match handle {
            Ok(h) => h,
            Err(why) => {
                // Said once (`failed` stays until the collider bakes).
                if !runtime.as_ref().is_some_and(|r| r.failed) {
                    error!("cloth collider {who}: {why}");
                    commands.entity(entity).insert(ColliderRuntime {
                        failed: true,
                        ..default()
                    });
                }
                continue;
            }
        };
        let key = (handle.id(), *resolution);
        // Baked (or refused) for this mesh and resolution already: nothing to do. A new mesh
        // or resolution (the editor's slider) bakes again.
        if runtime
            .as_ref()
            .is_some_and(|r| r.baked_for == Some(key) && (r.baked.is_some() || r.failed))
        {
            continue;
        }
        let Some(source) = meshes.as_ref().and_then(|m| m.get(handle)) else {
            continue; // not loaded yet
        };
        let fingerprint = mesh_fingerprint(source);
        let baked = limits::SDF_RESOLUTION
            .check_count(*resolution)
            .map_err(|e| e.to_string())
            .and_then(|()| read_mesh(source).map_err(|e| e.to_string()))
            .and_then(|data| {
                SdfGrid::from_mesh_on(&data.positions, &data.indices, *resolution, par)
                    .map_err(|e| e.to_string())
            });
        let mut rt = ColliderRuntime {
            baked_for: Some(key),
            fingerprint,
            ..default()
        };
        match baked {
            Ok(grid) => {
                debug!("cloth collider {who}: baked a {} SDF", grid.dims());
                if skinned {
                    warn!(
                        "cloth collider {who}: its mesh is skinned; the field is baked from the \
                         bind pose and moves with the entity, not with the bones (put sphere or \
                         capsule colliders on the bones of an animated body)"
                    );
                }
                rt.baked = Some(Arc::new(grid));
            }
            Err(e) => {
                error!("cloth collider {who}: cannot bake its mesh: {e}");
                rt.failed = true;
            }
        }
        match runtime {
            Some(mut r) => {
                r.baked = rt.baked;
                r.failed = rt.failed;
                r.baked_for = rt.baked_for;
                r.fingerprint = rt.fingerprint;
            }
            None => {
                commands.entity(entity).insert(rt);
            }
        }
    }
}

/// What [`gather_colliders`] reads of each collider entity.
type ColliderQueryData = (
    Entity,
    &'static ClothCollider,
    Option<&'static mut ColliderRuntime>,
    Option<&'static mut ClothContactImpulse>,
    Option<&'static Name>,
);

/// Collects every collider's shape and its poses at the start and end of this step.
fn gather_colliders(
    mut commands: Commands,
    mut out: ResMut<ClothColliders>,
    mut colliders: Query<ColliderQueryData>,
    poses: FixedPoses,
    mut reported: Local<bevy::platform::collections::HashSet<Entity>>,
    mut step: Local<u64>,
) {
    out.colliders.clear();
    out.entities.clear();
    *step += 1;
    let step = *step;
    for (entity, collider, runtime, impulse, name) in &mut colliders {
        let Some(gt) = poses.get(entity) else {
            continue;
        };
        let gt = &gt;
        if let Some(mut i) = impulse {
            *i = ClothContactImpulse::default();
        } else {
            commands
                .entity(entity)
                .insert(ClothContactImpulse::default());
        }
        // Scaled to nothing (an entity hidden by a zero scale): no extent to collide with,
        // left out without a word until it has one again.
        if gt.affine().matrix3.determinant() == 0.0 {
            continue;
        }
        let baked = runtime.as_ref().and_then(|r| r.baked.as_ref());
        let Some((pose, shape)) = pose_and_shape(gt, &collider.shape, baked) else {
            continue;
        };
        // Swept from where it was at the end of the last step, if it took part in it.
        let last = runtime
            .as_ref()
            .filter(|r| r.last_step + 1 == step)
            .and_then(|r| r.last);
        let start = match last {
            Some(l)
                if !is_teleport(l.translation, pose.translation, collider.teleport_distance) =>
            {
                l
            }
            _ => pose,
        };
        let c = Collider {
            shape,
            start,
            end: pose,
            thickness: collider.thickness,
            friction: collider.friction,
        };
        // An invalid collider is left out, and said once (again after it was fixed).
        let valid = limits::TELEPORT_DISTANCE
            .check(collider.teleport_distance)
            .map_err(|e| e.to_string())
            .and_then(|()| c.validate());
        if let Err(problem) = valid {
            if reported.insert(entity) {
                let who = EntityName::new(entity, name);
                error!("cloth collider {who}: {problem}; it is ignored");
            }
            continue;
        }
        reported.remove(&entity);
        match runtime {
            Some(mut r) => {
                r.last = Some(pose);
                r.last_step = step;
            }
            None => {
                commands.entity(entity).insert(ColliderRuntime {
                    last: Some(pose),
                    last_step: step,
                    ..default()
                });
            }
        }
        out.colliders.push(c);
        out.entities.push(entity);
    }
}

/// Adds a cloth's impulses on the colliders to their [`ClothContactImpulse`]s.
pub(crate) fn add_impulses(
    colliders: &ClothColliders,
    impulses: &[ContactImpulse],
    targets: &mut Query<&mut ClothContactImpulse>,
) {
    for (entity, imp) in colliders.entities.iter().zip(impulses) {
        if (imp.linear.length_squared() + imp.angular.length_squared()) > 0.0
            && let Ok(mut t) = targets.get_mut(*entity)
        {
            t.linear += imp.linear;
            t.angular += imp.angular;
        }
    }
}
