//! The bevy_rapier3d bridge (cargo feature `rapier`): rapier colliders act on cloth, and cloth
//! pushes dynamic rapier bodies back.
//!
//! Add [`ClothRapierPlugin`] to opt in. Every entity with a rapier [`Collider`] (unless it has
//! [`NoClothCollision`] or its own [`ClothCollider`](super::ClothCollider)) gets a mirrored
//! [`ClothCollider`](super::ClothCollider): balls, cuboids and y-aligned capsules map to the
//! analytic shapes, half-spaces with a +y normal to planes, and triangle meshes, height fields,
//! convex hulls, cylinders, cones and other capsules are triangulated and baked into signed
//! distance fields (other shapes are ignored, with a warning; a height field or an open
//! triangle mesh, such as a terrain, keeps cloth on the side its triangles face). After each
//! cloth step, the impulse the cloth
//! gave each mirrored collider ([`ClothContactImpulse`]) is added, opposite to what the cloth
//! received, to the [`ExternalImpulse`] of its dynamic rigid body (the collider's entity or its
//! nearest ancestor with a [`RigidBody`]), which rapier applies on its next step.
//!
//! The cloth solves its contacts as if the body could not yield, and the body feels them a
//! step later, so a body landing on taut cloth would be thrown back by the whole stretch it
//! made in that step (a trampoline gaining energy each bounce). The reaction is therefore
//! capped where it would send the body away from the cloth faster than
//! [`max_push_speed`](ClothRapierPlugin::max_push_speed) (the body's mass and velocity are
//! read from rapier's own body): the cloth still stops what moves into it and holds up what
//! lies on it.

use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;
use bevy_rapier3d::geometry::ColliderView;
use bevy_rapier3d::prelude::{
    Collider, ExternalImpulse, RapierRigidBodyHandle, ReadRapierContext, RigidBody,
};

pub use super::NoClothCollision;
use super::bridge::{self, EngineCollider, Mirroring, Settings};
use super::{ClothContactImpulse, ColliderShape};
use crate::foundation::ClothSystems;
use crate::solver::Workers;

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
    /// The fastest the cloth's reaction may send a body away from it (m/s along the
    /// reaction). The cloth stops whatever moves into it and holds up what lies on it; this
    /// caps only how hard taut cloth throws a body back (see the module docs).
    pub max_push_speed: f32,
}

impl Default for ClothRapierPlugin {
    fn default() -> Self {
        Self {
            thickness: 0.01,
            friction: 0.4,
            resolution: 40,
            two_way: true,
            max_push_speed: 0.25,
        }
    }
}

/// Marks a [`ClothCollider`](super::ClothCollider) the bridge made from a rapier
/// collider (and keeps in sync).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct FromRapierCollider;

impl Plugin for ClothRapierPlugin {
    /// The bridge runs in the cloth plugins' schedule ([`ClothSchedule`](crate::foundation::ClothSchedule)):
    /// added after `ClothPlugins`, its systems go in here; added before, in [`Plugin::finish`],
    /// once every plugin is built.
    fn build(&self, app: &mut App) {
        let m = Mirroring {
            thickness: self.thickness,
            friction: self.friction,
            resolution: self.resolution,
            two_way: self.two_way,
            max_push_speed: self.max_push_speed,
        };
        bridge::install::<Collider, FromRapierCollider>(app, m);
        crate::foundation::schedule_once::<Self>(app, false, schedule_bridge);
    }

    fn finish(&self, app: &mut App) {
        crate::foundation::schedule_once::<Self>(app, true, schedule_bridge);
    }
}

fn schedule_bridge(app: &mut App, schedule: Interned<dyn ScheduleLabel>) {
    app.add_systems(
        schedule,
        (
            bridge::mirror_colliders::<Collider, FromRapierCollider>.in_set(ClothSystems::Prepare),
            push_bodies.after(ClothSystems::Simulate),
        ),
    );
}

impl EngineCollider for Collider {
    const ENGINE: &'static str = "rapier";

    fn cloth_shape(&self, resolution: u32, par: &Workers) -> Option<ColliderShape> {
        shape_of(self, resolution, par)
    }
}

/// The cloth shape of a rapier collider (unscaled: the entity's transform scales both).
fn shape_of(collider: &Collider, resolution: u32, par: &Workers) -> Option<ColliderShape> {
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
                return bridge::bake::<Collider>(&to_vec3(&v), &i, resolution, par);
            }
        }
        ColliderView::HalfSpace(h) if h.normal().abs_diff_eq(Vec3::Y, 1e-5) => ColliderShape::Plane,
        ColliderView::TriMesh(t) => {
            let v: Vec<Vec3> = t.vertices().collect();
            return bridge::bake::<Collider>(&v, t.indices(), resolution, par);
        }
        ColliderView::ConvexPolyhedron(c) => {
            let (v, i) = c.raw.to_trimesh();
            return bridge::bake::<Collider>(&to_vec3(&v), &i, resolution, par);
        }
        ColliderView::Cylinder(c) => {
            let (v, i) = c.raw.to_trimesh(24);
            return bridge::bake::<Collider>(&to_vec3(&v), &i, resolution, par);
        }
        ColliderView::Cone(c) => {
            let (v, i) = c.raw.to_trimesh(24);
            return bridge::bake::<Collider>(&to_vec3(&v), &i, resolution, par);
        }
        // An open surface: cloth is kept on the side it faces (up).
        ColliderView::HeightField(h) => {
            let (v, i) = h.raw.to_trimesh();
            return bridge::bake::<Collider>(&to_vec3(&v), &i, resolution, par);
        }
        _ => return None,
    })
}

fn to_vec3<T: Copy + Into<Vec3>>(v: &[T]) -> Vec<Vec3> {
    v.iter().map(|&p| p.into()).collect()
}

/// Adds the reaction of every cloth contact to the dynamic body behind the collider.
fn push_bodies(
    settings: Res<Settings<FromRapierCollider>>,
    contacts: Query<(Entity, &ClothContactImpulse, &GlobalTransform), With<FromRapierCollider>>,
    parents: Query<&ChildOf>,
    bodies: Query<(&RigidBody, &GlobalTransform, Option<&RapierRigidBodyHandle>)>,
    rapier: ReadRapierContext,
    mut impulses: Query<&mut ExternalImpulse>,
    mut commands: Commands,
) {
    if !settings.0.two_way {
        return;
    }
    let context = rapier.single().ok();
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
        let Ok((kind, body_gt, handle)) = bodies.get(body) else {
            continue;
        };
        if *kind != RigidBody::Dynamic {
            continue;
        }
        let at = collider_gt.translation();
        // The body's mass and the velocity of the contact point, from rapier's own body (a
        // body rapier has not created yet gets all of the reaction).
        let rapier_body = context.as_ref().and_then(|context| {
            let rb = context.rigidbody_set.bodies.get(handle?.0)?;
            Some((rb.mass(), rb.velocity_at_point(at)))
        });
        let share = rapier_body.map_or(1.0, |(mass, v_at)| {
            bridge::reaction_share(contact.linear, mass, v_at, settings.0.max_push_speed)
        });
        let (linear, angular) = (share * contact.linear, share * contact.angular);
        // The cloth's angular impulse is about the collider's origin: move it to the body's.
        let lever = at - body_gt.translation();
        let torque = angular + lever.cross(linear);
        match impulses.get_mut(body) {
            Ok(mut i) => {
                i.impulse += linear;
                i.torque_impulse += torque;
            }
            Err(_) => {
                commands.entity(body).insert(ExternalImpulse {
                    impulse: linear,
                    torque_impulse: torque,
                });
            }
        }
    }
}
