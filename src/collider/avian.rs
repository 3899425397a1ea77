//! The avian3d bridge (cargo feature `avian`): avian colliders act on cloth, and cloth pushes
//! dynamic avian bodies back.
//!
//! Add [`ClothAvianPlugin`] to opt in. Every entity with an avian [`Collider`] (unless it has
//! [`NoClothCollision`] or its own [`ClothCollider`](super::ClothCollider)) gets a mirrored
//! [`ClothCollider`](super::ClothCollider): balls, cuboids and y-aligned capsules map to the
//! analytic shapes, half-spaces with a +y normal to planes, and triangle meshes, height fields,
//! convex hulls, cylinders, cones and other capsules are triangulated and baked into signed
//! distance fields (compound shapes and other shapes are ignored, with a warning). A height
//! field or an open triangle mesh (a terrain) keeps cloth on the side its triangles face. Removing the
//! avian collider, or despawning its entity, removes the mirror.
//!
//! After each cloth step, the impulse the cloth gave each mirrored collider
//! ([`ClothContactImpulse`]) is applied, opposite to what the cloth received, to its dynamic
//! rigid body (avian's [`ColliderOf`]) through avian's [`Forces`]: an impulse changes the
//! body's velocity at once, and avian integrates it on its next step.
//!
//! The cloth solves its contacts as if the body could not yield, and the body feels them a
//! step later, so a body landing on taut cloth would be thrown back by the whole stretch it
//! made in that step (a trampoline gaining energy each bounce). The reaction is therefore
//! capped where it would send the body away from the cloth faster than
//! [`max_push_speed`](ClothAvianPlugin::max_push_speed): the cloth still stops what moves
//! into it and holds up what lies on it.
//!
//! # Order
//! Avian steps in `FixedPostUpdate` by default, the cloth schedule's default too. In the
//! cloth schedule the bridge runs cloth after avian's [`PhysicsSystems::Last`]: the cloth sees
//! every body where avian's step of this fixed step left it, and the bodies feel the cloth on
//! avian's next step (one fixed step later, as with rapier). With avian in another schedule,
//! that schedule's order decides.
//!
//! Both bridges can be on at once: each mirrors and pushes only its own engine's colliders.

use avian3d::parry::shape::TypedShape;
use avian3d::prelude::{
    Collider, ColliderOf, ComputedMass, Forces, PhysicsSystems, ReadRigidBodyForces, RigidBody,
    WriteRigidBodyForces,
};
use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;

pub use super::NoClothCollision;
use super::bridge::{self, EngineCollider, Mirroring, Settings};
use super::{ClothContactImpulse, ColliderShape};
use crate::foundation::ClothSystems;
use crate::solver::Workers;

/// Mirrors avian colliders into cloth colliders and couples cloth to avian bodies.
///
/// # Example
/// ```no_run
/// use avian3d::prelude::*;
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// App::new()
///     .add_plugins((DefaultPlugins, PhysicsPlugins::default(), ClothPlugins::default()))
///     .add_plugins(ClothAvianPlugin::default())
///     .add_systems(Startup, |mut commands: Commands| {
///         // Collides with every cloth, and cloth pushes it back.
///         commands.spawn((RigidBody::Dynamic, Collider::sphere(0.2), Transform::from_xyz(0.0, 2.0, 0.0)));
///     })
///     .run();
/// ```
#[derive(Clone, Copy, Debug)]
pub struct ClothAvianPlugin {
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

impl Default for ClothAvianPlugin {
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

/// Marks a [`ClothCollider`](super::ClothCollider) the bridge made from an avian
/// collider (and keeps in sync).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct FromAvianCollider;

impl Plugin for ClothAvianPlugin {
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
        bridge::install::<Collider, FromAvianCollider>(app, m);
        crate::foundation::schedule_once::<Self>(app, false, schedule_bridge);
    }

    fn finish(&self, app: &mut App) {
        crate::foundation::schedule_once::<Self>(app, true, schedule_bridge);
    }
}

fn schedule_bridge(app: &mut App, schedule: Interned<dyn ScheduleLabel>) {
    app.configure_sets(schedule, ClothSystems::Prepare.after(PhysicsSystems::Last))
        .add_systems(
            schedule,
            (
                bridge::mirror_colliders::<Collider, FromAvianCollider>
                    .in_set(ClothSystems::Prepare),
                push_bodies.after(ClothSystems::Simulate),
            ),
        );
}

impl EngineCollider for Collider {
    const ENGINE: &'static str = "avian";

    fn cloth_shape(&self, resolution: u32, par: &Workers) -> Option<ColliderShape> {
        shape_of(self, resolution, par)
    }
}

/// The cloth shape of an avian collider (unscaled: the entity's transform scales both).
fn shape_of(collider: &Collider, resolution: u32, par: &Workers) -> Option<ColliderShape> {
    Some(match collider.shape().as_typed_shape() {
        TypedShape::Ball(b) => ColliderShape::Sphere { radius: b.radius },
        TypedShape::Cuboid(c) => ColliderShape::Cuboid {
            half_extents: c.half_extents,
        },
        TypedShape::Capsule(c) => {
            let (a, b) = (c.segment.a, c.segment.b);
            if a.x == 0.0 && a.z == 0.0 && b.x == 0.0 && b.z == 0.0 && (a.y + b.y).abs() < 1e-6 {
                ColliderShape::Capsule {
                    radius: c.radius,
                    half_length: c.half_height(),
                }
            } else {
                let (v, i) = c.to_trimesh(16, 8);
                return bridge::bake::<Collider>(&v, &i, resolution, par);
            }
        }
        TypedShape::HalfSpace(h) if h.normal.abs_diff_eq(Vec3::Y, 1e-5) => ColliderShape::Plane,
        TypedShape::TriMesh(t) => {
            return bridge::bake::<Collider>(t.vertices(), t.indices(), resolution, par);
        }
        TypedShape::ConvexPolyhedron(c) => {
            let (v, i) = c.to_trimesh();
            return bridge::bake::<Collider>(&v, &i, resolution, par);
        }
        TypedShape::Cylinder(c) => {
            let (v, i) = c.to_trimesh(24);
            return bridge::bake::<Collider>(&v, &i, resolution, par);
        }
        TypedShape::Cone(c) => {
            let (v, i) = c.to_trimesh(24);
            return bridge::bake::<Collider>(&v, &i, resolution, par);
        }
        // An open surface: cloth is kept on the side it faces (up).
        TypedShape::HeightField(h) => {
            let (v, i) = h.to_trimesh();
            return bridge::bake::<Collider>(&v, &i, resolution, par);
        }
        _ => return None,
    })
}

/// Applies the reaction of every cloth contact to the dynamic body behind the collider.
fn push_bodies(
    settings: Res<Settings<FromAvianCollider>>,
    contacts: Query<
        (
            Entity,
            &ClothContactImpulse,
            &GlobalTransform,
            Option<&ColliderOf>,
        ),
        With<FromAvianCollider>,
    >,
    mut bodies: Query<(&RigidBody, &ComputedMass, Forces)>,
) {
    if !settings.0.two_way {
        return;
    }
    for (entity, contact, collider_gt, collider_of) in &contacts {
        if contact.linear == Vec3::ZERO && contact.angular == Vec3::ZERO {
            continue;
        }
        // Avian links every collider to its body (the collider's own entity for a body with
        // its collider on it).
        let body = collider_of.map_or(entity, |c| c.body);
        let Ok((kind, mass, mut forces)) = bodies.get_mut(body) else {
            continue;
        };
        if !kind.is_dynamic() {
            continue;
        }
        let at = collider_gt.translation();
        let share = bridge::reaction_share(
            contact.linear,
            mass.value(),
            forces.velocity_at_point(at),
            settings.0.max_push_speed,
        );
        // The cloth's angular impulse is about the collider's origin: the linear impulse at
        // that point adds the lever arm about the body's centre of mass.
        forces.apply_linear_impulse_at_point(share * contact.linear, at);
        forces.apply_angular_impulse(share * contact.angular);
    }
}
