//! The bevy_rapier3d bridge (cargo feature `rapier`): rapier colliders act on cloth, and cloth
//! pushes dynamic rapier bodies back.
//!
//! Add [`ClothRapierPlugin`] to opt in. Every entity with a rapier [`Collider`] (unless it has
//! [`NoClothCollision`] or its own [`ClothCollider`]) gets a mirrored [`ClothCollider`]: balls,
//! cuboids and y-aligned capsules map to the analytic shapes, half-spaces with a +y normal to
//! planes, and triangle meshes, convex hulls, cylinders, cones and other capsules are
//! triangulated and baked into signed distance fields. After each cloth step, the impulse the
//! cloth gave each mirrored collider ([`ClothContactImpulse`]) is added, opposite to what the
//! cloth received, to the [`ExternalImpulse`] of its dynamic rigid body (the collider's entity
//! or its nearest ancestor with a [`RigidBody`]), which rapier applies on its next step.

use std::sync::Arc;

use bevy::prelude::*;
use bevy_rapier3d::geometry::ColliderView;
use bevy_rapier3d::prelude::{Collider, ExternalImpulse, RigidBody};

use super::{ClothCollider, ClothContactImpulse, ColliderMesh, ColliderShape};
use crate::foundation::{ClothSchedule, ClothSystems};
use crate::solver::SdfGrid;

/// Mirrors rapier colliders into cloth colliders and couples cloth to rapier bodies.
#[derive(Clone, Copy, Debug)]
pub struct ClothRapierPlugin {
    /// Thickness given to mirrored colliders (metres).
    pub thickness: f32,
    /// Friction given to mirrored colliders.
    pub friction: f32,
    /// SDF resolution (cells along the longest side) for baked shapes.
    pub resolution: u32,
    /// Whether cloth pushes dynamic bodies back (two-way coupling).
    pub two_way: bool,
}

impl Default for ClothRapierPlugin {
    fn default() -> Self {
        Self {
            thickness: 0.01,
            friction: 0.4,
            resolution: 40,
            two_way: true,
        }
    }
}

/// Settings of the bridge, from [`ClothRapierPlugin`].
#[derive(Resource, Clone, Copy, Debug)]
struct Settings(ClothRapierPlugin);

/// On a rapier collider: cloth ignores it.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct NoClothCollision;

/// Marks a [`ClothCollider`] the bridge made from a rapier collider (and keeps in sync).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct FromRapierCollider;

/// Present once the bridge's systems are in the cloth schedule.
#[derive(Resource)]
struct BridgeScheduled;

impl Plugin for ClothRapierPlugin {
    /// The bridge runs in the cloth plugins' schedule ([`ClothSchedule`]): added after
    /// `ClothPlugins`, its systems go in here; added before, in [`Plugin::finish`], once
    /// every plugin is built.
    fn build(&self, app: &mut App) {
        app.insert_resource(Settings(*self));
        if app.world().contains_resource::<ClothSchedule>() {
            schedule_bridge(app);
        }
    }

    fn finish(&self, app: &mut App) {
        if !app.world().contains_resource::<BridgeScheduled>() {
            schedule_bridge(app);
        }
    }
}

fn schedule_bridge(app: &mut App) {
    let schedule = ClothSchedule::of(app);
    app.insert_resource(BridgeScheduled).add_systems(
        schedule,
        (
            mirror_colliders.in_set(ClothSystems::Prepare),
            push_bodies.after(ClothSystems::Simulate),
        ),
    );
}

fn bake(vertices: &[Vec3], indices: &[[u32; 3]], resolution: u32) -> Option<ColliderShape> {
    let flat: Vec<u32> = indices.iter().flatten().copied().collect();
    match SdfGrid::from_mesh(vertices, &flat, resolution) {
        Ok(grid) => Some(ColliderShape::Mesh(ColliderMesh::Baked(Arc::new(grid)))),
        Err(e) => {
            warn!("rapier collider: cannot bake its triangles into an SDF: {e}");
            None
        }
    }
}

/// The cloth shape of a rapier collider (unscaled: the entity's transform scales both).
fn shape_of(collider: &Collider, resolution: u32) -> Option<ColliderShape> {
    Some(match collider.as_unscaled_typed_shape() {
        ColliderView::Ball(b) => ColliderShape::Sphere { radius: b.radius() },
        ColliderView::Cuboid(c) => ColliderShape::Cuboid {
            half_extents: c.half_extents(),
        },
        ColliderView::Capsule(c) => {
            let (a, b) = (c.segment().a(), c.segment().b());
            if a.x == 0.0 && a.z == 0.0 && b.x == 0.0 && b.z == 0.0 && (a.y + b.y).abs() < 1e-6 {
                ColliderShape::Capsule {
                    radius: c.radius(),
                    half_length: c.half_height(),
                }
            } else {
                let (v, i) = c.raw.to_trimesh(16, 8);
                return bake(&to_vec3(&v), &i, resolution);
            }
        }
        ColliderView::HalfSpace(h) if h.normal().abs_diff_eq(Vec3::Y, 1e-5) => ColliderShape::Plane,
        ColliderView::TriMesh(t) => {
            let v: Vec<Vec3> = t.vertices().collect();
            return bake(&v, t.indices(), resolution);
        }
        ColliderView::ConvexPolyhedron(c) => {
            let (v, i) = c.raw.to_trimesh();
            return bake(&to_vec3(&v), &i, resolution);
        }
        ColliderView::Cylinder(c) => {
            let (v, i) = c.raw.to_trimesh(24);
            return bake(&to_vec3(&v), &i, resolution);
        }
        ColliderView::Cone(c) => {
            let (v, i) = c.raw.to_trimesh(24);
            return bake(&to_vec3(&v), &i, resolution);
        }
        _ => return None,
    })
}

fn to_vec3<T: Copy + Into<Vec3>>(v: &[T]) -> Vec<Vec3> {
    v.iter().map(|&p| p.into()).collect()
}

#[expect(clippy::type_complexity, reason = "a query filter, read once")]
fn mirror_colliders(
    mut commands: Commands,
    settings: Res<Settings>,
    changed: Query<
        (
            Entity,
            &Collider,
            Option<&ClothCollider>,
            Has<FromRapierCollider>,
        ),
        (
            Without<NoClothCollision>,
            Or<(Added<Collider>, Changed<Collider>)>,
        ),
    >,
) {
    let s = settings.0;
    for (entity, collider, existing, mirrored) in &changed {
        if existing.is_some() && !mirrored {
            continue; // the user's own cloth collider wins
        }
        match shape_of(collider, s.resolution) {
            Some(shape) => {
                commands.entity(entity).insert((
                    ClothCollider {
                        shape,
                        thickness: s.thickness,
                        friction: s.friction,
                        ..ClothCollider::new(ColliderShape::Plane)
                    },
                    FromRapierCollider,
                ));
            }
            None => {
                debug!("rapier collider {entity}: shape not supported for cloth, ignored");
            }
        }
    }
}

/// Adds the reaction of every cloth contact to the dynamic body behind the collider.
fn push_bodies(
    settings: Res<Settings>,
    contacts: Query<(Entity, &ClothContactImpulse, &GlobalTransform), With<FromRapierCollider>>,
    parents: Query<&ChildOf>,
    bodies: Query<(&RigidBody, &GlobalTransform)>,
    mut impulses: Query<&mut ExternalImpulse>,
    mut commands: Commands,
) {
    if !settings.0.two_way {
        return;
    }
    for (entity, contact, collider_gt) in &contacts {
        if contact.linear == Vec3::ZERO && contact.angular == Vec3::ZERO {
            continue;
        }
        // The body: this entity or its nearest ancestor with a RigidBody.
        let mut body = entity;
        while bodies.get(body).is_err() {
            match parents.get(body) {
                Ok(p) => body = p.parent(),
                Err(_) => break,
            }
        }
        let Ok((kind, body_gt)) = bodies.get(body) else {
            continue;
        };
        if *kind != RigidBody::Dynamic {
            continue;
        }
        // The cloth's angular impulse is about the collider's origin: move it to the body's.
        let lever = collider_gt.translation() - body_gt.translation();
        let torque = contact.angular + lever.cross(contact.linear);
        match impulses.get_mut(body) {
            Ok(mut i) => {
                i.impulse += contact.linear;
                i.torque_impulse += torque;
            }
            Err(_) => {
                commands.entity(body).insert(ExternalImpulse {
                    impulse: contact.linear,
                    torque_impulse: torque,
                });
            }
        }
    }
}
