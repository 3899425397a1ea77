//! Collision: the shapes cloth meets ([`Shape`] in a [`Pose`]), colliders moving through a
//! step and the impulses they receive ([`Collider`], [`ContactImpulse`]), signed distance
//! fields baked from meshes ([`SdfGrid`]), self-collision, and ray queries for picking.

mod collider;
mod pick;
mod sdf;
mod self_collision;
mod shape;

pub use collider::{Collider, ContactImpulse};
pub(crate) use collider::{SubstepPose, collide_vertices, substep_poses};
pub use pick::{RayHit, ray_hit, ray_shape};
pub use sdf::{SdfError, SdfGrid, point_triangle_distance};
pub use self_collision::{
    MAX_SELF_NEIGHBOURS, MAX_SELF_TRIANGLES, NEAR_CORNER_THICKNESS, SelfCollision,
    SelfCollisionScratch, count_self_crossings, triangle_reach,
};
pub(crate) use self_collision::{
    Scales, find_self_collision_candidates, first_corner_reach, limits_depenetration,
    near_corner_rule, self_collide,
};
pub use shape::{Pose, Shape};
