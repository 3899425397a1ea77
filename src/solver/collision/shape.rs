//! The shapes cloth collides with ([`Shape`]) and where they are ([`Pose`]).

use std::sync::Arc;

use glam::{Quat, Vec3};

use super::sdf::SdfGrid;
use crate::solver::limits;

/// A rigid shape in its local frame: the one shape type of the crate.
///
/// The analytic shapes are the same everywhere; what a mesh shape carries depends on who holds
/// it, so it is a type parameter `M`: the solver steps against a baked signed distance field
/// (`Shape` = `Shape<Arc<SdfGrid>>`), the Bevy component names the mesh to bake
/// (`ColliderShape`), and a scene file stores how finely to bake it.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape<M = Arc<SdfGrid>> {
    /// A ball of this radius, centred on the origin.
    Sphere {
        /// Radius in metres.
        radius: f32,
    },
    /// A box centred on the origin, along the local axes.
    Cuboid {
        /// Half size along x, y, z in metres.
        half_extents: Vec3,
    },
    /// A capsule along the local y axis, as Bevy's `Capsule3d`: a segment from
    /// `−half_length` to `+half_length` swept by a ball of `radius` (total height
    /// `2·(half_length + radius)`).
    Capsule {
        /// Radius in metres.
        radius: f32,
        /// Half the length of the straight part (the segment between the two hemispheres'
        /// centres).
        #[cfg_attr(feature = "serde", serde(alias = "half_height"))]
        half_length: f32,
    },
    /// The half-space below the local xz plane (surface normal +y): a floor.
    Plane,
    /// A triangle mesh: a baked signed distance field in the solver.
    Mesh(M),
}

impl<M> Shape<M> {
    /// Whether every size of the shape (radius, half extents, half length) is within
    /// [`limits::COLLIDER_SIZE`]: finite, not negative, at most `MAX_COORDINATE`.
    #[must_use]
    pub fn sizes_valid(&self) -> bool {
        let ok = |v: f32| limits::COLLIDER_SIZE.contains(v);
        match self {
            Shape::Sphere { radius } => ok(*radius),
            Shape::Cuboid { half_extents } => half_extents.to_array().into_iter().all(ok),
            Shape::Capsule {
                half_length,
                radius,
            } => ok(*half_length) && ok(*radius),
            Shape::Plane | Shape::Mesh(_) => true,
        }
    }

    /// The same shape with its mesh (if it is one) turned into `f(mesh)`.
    pub fn map_mesh<N>(self, f: impl FnOnce(M) -> N) -> Shape<N> {
        self.try_map_mesh(|m| Some(f(m)))
            .unwrap_or_else(|| unreachable!("the closure always gives Some"))
    }

    /// The same shape with its mesh turned into `f(mesh)`; `None` when `f` gives `None` (a
    /// mesh not baked yet).
    pub fn try_map_mesh<N>(self, f: impl FnOnce(M) -> Option<N>) -> Option<Shape<N>> {
        Some(match self {
            Shape::Sphere { radius } => Shape::Sphere { radius },
            Shape::Cuboid { half_extents } => Shape::Cuboid { half_extents },
            Shape::Capsule {
                radius,
                half_length,
            } => Shape::Capsule {
                radius,
                half_length,
            },
            Shape::Plane => Shape::Plane,
            Shape::Mesh(m) => Shape::Mesh(f(m)?),
        })
    }

    /// The mesh, for a mesh shape.
    #[must_use]
    pub fn mesh(&self) -> Option<&M> {
        match self {
            Shape::Mesh(m) => Some(m),
            _ => None,
        }
    }
}

impl Shape {
    /// Signed distance from `p` (local frame) to the surface, negative inside, with the unit
    /// outward normal of the closest surface point.
    #[must_use]
    pub fn distance(&self, p: Vec3) -> (f32, Vec3) {
        match self {
            Shape::Sphere { radius } => {
                let len = p.length();
                (len - radius, p.try_normalize().unwrap_or(Vec3::Y))
            }
            Shape::Cuboid { half_extents } => cuboid_distance(p, *half_extents),
            Shape::Capsule {
                radius,
                half_length,
            } => {
                let c = Vec3::new(0.0, p.y.clamp(-half_length, *half_length), 0.0);
                let d = p - c;
                (d.length() - radius, d.try_normalize().unwrap_or(Vec3::X))
            }
            Shape::Plane => (p.y, Vec3::Y),
            Shape::Mesh(grid) => grid.sample(p),
        }
    }

    /// How far the surface lies beyond the shape's *core* — a sphere's centre, a capsule's
    /// segment, a cuboid's box — so that a point farther than that from the core cannot
    /// touch the shape: the radius of a sphere or capsule, 0 for a cuboid; infinite for a
    /// plane or a mesh, which have no core.
    #[must_use]
    pub(crate) fn core_radius(&self) -> f32 {
        match self {
            Shape::Sphere { radius } | Shape::Capsule { radius, .. } => *radius,
            Shape::Cuboid { .. } => 0.0,
            Shape::Plane | Shape::Mesh(_) => f32::INFINITY,
        }
    }

    /// Radius of a ball around the local origin that contains the shape (infinite for a plane).
    #[must_use]
    pub fn bounding_radius(&self) -> f32 {
        match self {
            Shape::Sphere { radius } => *radius,
            Shape::Cuboid { half_extents } => half_extents.length(),
            Shape::Capsule {
                radius,
                half_length,
            } => half_length + radius,
            Shape::Plane => f32::INFINITY,
            Shape::Mesh(grid) => grid.bounding_radius(),
        }
    }
}

fn cuboid_distance(p: Vec3, e: Vec3) -> (f32, Vec3) {
    let q = p.abs() - e;
    let outside = q.max(Vec3::ZERO);
    if outside.length_squared() > 0.0 {
        let n = (outside * p.signum()).normalize();
        (outside.length(), n)
    } else {
        // Inside: leave through the nearest face.
        let axis = if q.x >= q.y && q.x >= q.z {
            Vec3::X
        } else if q.y >= q.z {
            Vec3::Y
        } else {
            Vec3::Z
        };
        (q.max_element(), axis * p.signum())
    }
}

/// Position, orientation and uniform scale of a collider.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// World position of the local origin.
    pub translation: Vec3,
    /// World orientation.
    pub rotation: Quat,
    /// Uniform scale (the shape's sizes are multiplied by it).
    pub scale: f32,
}

impl Default for Pose {
    fn default() -> Self {
        Self {
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: 1.0,
        }
    }
}

impl Pose {
    /// A pose at `translation` with no rotation.
    #[must_use]
    pub fn at(translation: Vec3) -> Self {
        Self {
            translation,
            ..Default::default()
        }
    }

    /// World point of a local point.
    #[inline]
    #[must_use]
    pub fn apply(&self, p: Vec3) -> Vec3 {
        self.translation + self.rotation * (p * self.scale)
    }

    /// Local point of a world point.
    #[inline]
    #[must_use]
    pub fn inverse_apply(&self, p: Vec3) -> Vec3 {
        (self.rotation.inverse() * (p - self.translation)) / self.scale
    }

    /// The pose a fraction `t` of the way to `other`.
    #[must_use]
    pub fn lerp(&self, other: &Pose, t: f32) -> Pose {
        Pose {
            translation: self.translation.lerp(other.translation, t),
            rotation: self.rotation.slerp(other.rotation, t),
            scale: self.scale + (other.scale - self.scale) * t,
        }
    }
}
