//! Every numeric setting the editor shows, as data: a label, the solver's own [`Limit`] and a
//! getter and setter. The cards draw one slider per [`Knob`]; the tests set each knob to both
//! ends of its limit through the same setter and check the plugin takes the value.

use bevy::prelude::*;

use crate::cloth::{Cloth, ClothConfig, ClothSelfCollision, ClothTearing, ClothTethers};
use crate::collider::{ClothCollider, ColliderMesh, ColliderShape};
use crate::solver::limits::{self, Limit};
use crate::solver::{Solver, WindParams};
use crate::wind::WindZone;

/// One numeric setting of a `T`: what the editor draws as a slider.
pub struct Knob<T> {
    /// Label beside the slider.
    pub label: &'static str,
    /// The accepted range (from [`crate::solver::limits`]): the slider spans exactly it.
    pub limit: Limit,
    /// The current value, or `None` where the setting does not apply (another solver, another
    /// shape, an automatic value).
    pub get: fn(&T) -> Option<f32>,
    /// Writes a value (already within `limit`).
    pub set: fn(&mut T, f32),
}

impl<T> Knob<T> {
    /// Writes `v`, brought into the limit first (a count rounded to a whole number).
    pub fn apply(&self, target: &mut T, v: f32) {
        let mut v = self.limit.clamp(v);
        if self.limit.integer {
            v = v.round();
        }
        (self.set)(target, v);
    }
}

impl<T> Clone for Knob<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Knob<T> {}

impl<T> core::fmt::Debug for Knob<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Knob")
            .field("label", &self.label)
            .field("limit", &self.limit)
            .finish_non_exhaustive()
    }
}

// Solver parameters of each solver kind, read and written through the enum.

fn pbd(c: &ClothConfig) -> Option<[f32; 3]> {
    match c.solver {
        Solver::Pbd {
            stretch,
            shear,
            bending,
        } => Some([stretch, shear, bending]),
        _ => None,
    }
}

fn set_pbd(c: &mut ClothConfig, k: usize, v: f32) {
    if let Solver::Pbd {
        stretch,
        shear,
        bending,
    } = &mut c.solver
    {
        *[stretch, shear, bending][k] = v;
    }
}

fn xpbd(c: &ClothConfig) -> Option<[f32; 3]> {
    match c.solver {
        Solver::Xpbd {
            stretch,
            shear,
            bending,
        } => Some([stretch, shear, bending]),
        _ => None,
    }
}

fn set_xpbd(c: &mut ClothConfig, k: usize, v: f32) {
    if let Solver::Xpbd {
        stretch,
        shear,
        bending,
    } = &mut c.solver
    {
        *[stretch, shear, bending][k] = v;
    }
}

fn not_lab(c: &ClothConfig) -> bool {
    !matches!(c.solver, Solver::Lab { .. })
}

/// The knobs of [`ClothConfig`]: counts, gravity, damping, speed limit, each solver's
/// material, air and sleep. Applied live (no rebuild).
pub const CONFIG: &[Knob<ClothConfig>] = &[
    Knob {
        label: "substeps",
        limit: limits::SUBSTEPS,
        get: |c| Some(c.substeps as f32),
        set: |c, v| c.substeps = v as u32,
    },
    Knob {
        label: "iterations",
        limit: limits::ITERATIONS,
        get: |c| Some(c.iterations as f32),
        set: |c, v| c.iterations = v as u32,
    },
    Knob {
        label: "velocity kept",
        limit: limits::LAB_VELOCITY_KEEP,
        get: |c| match c.solver {
            Solver::Lab { velocity_keep } => Some(velocity_keep),
            _ => None,
        },
        set: |c, v| {
            if let Solver::Lab { velocity_keep } = &mut c.solver {
                *velocity_keep = v;
            }
        },
    },
    Knob {
        label: "stretch stiffness",
        limit: limits::PBD_STIFFNESS.named("stretch"),
        get: |c| pbd(c).map(|p| p[0]),
        set: |c, v| set_pbd(c, 0, v),
    },
    Knob {
        label: "shear stiffness",
        limit: limits::PBD_STIFFNESS.named("shear"),
        get: |c| pbd(c).map(|p| p[1]),
        set: |c, v| set_pbd(c, 1, v),
    },
    Knob {
        label: "bending stiffness",
        limit: limits::PBD_STIFFNESS.named("bending"),
        get: |c| pbd(c).map(|p| p[2]),
        set: |c, v| set_pbd(c, 2, v),
    },
    Knob {
        label: "stretch compliance",
        limit: limits::XPBD_COMPLIANCE.named("stretch"),
        get: |c| xpbd(c).map(|p| p[0]),
        set: |c, v| set_xpbd(c, 0, v),
    },
    Knob {
        label: "shear compliance",
        limit: limits::XPBD_COMPLIANCE.named("shear"),
        get: |c| xpbd(c).map(|p| p[1]),
        set: |c, v| set_xpbd(c, 1, v),
    },
    Knob {
        label: "bending compliance",
        limit: limits::XPBD_BENDING_COMPLIANCE,
        // Infinite compliance (no bending) is the "bending" checkbox, not a slider value.
        get: |c| xpbd(c).map(|p| p[2]).filter(|b| b.is_finite()),
        set: |c, v| set_xpbd(c, 2, v),
    },
    Knob {
        label: "gravity x",
        limit: limits::GRAVITY.component(),
        get: |c| Some(c.gravity.x),
        set: |c, v| c.gravity.x = v,
    },
    Knob {
        label: "gravity y",
        limit: limits::GRAVITY.component(),
        get: |c| Some(c.gravity.y),
        set: |c, v| c.gravity.y = v,
    },
    Knob {
        label: "gravity z",
        limit: limits::GRAVITY.component(),
        get: |c| Some(c.gravity.z),
        set: |c, v| c.gravity.z = v,
    },
    Knob {
        label: "damping",
        limit: limits::DAMPING,
        get: |c| not_lab(c).then_some(c.damping),
        set: |c, v| c.damping = v,
    },
    Knob {
        label: "speed limit",
        limit: limits::MAX_SPEED,
        get: |c| Some(c.max_speed),
        set: |c, v| c.max_speed = v,
    },
    Knob {
        label: "air drag",
        limit: limits::AIR_DRAG,
        get: |c| not_lab(c).then_some(c.air.drag),
        set: |c, v| c.air.drag = v,
    },
    Knob {
        label: "air lift",
        limit: limits::AIR_LIFT,
        get: |c| not_lab(c).then_some(c.air.lift),
        set: |c, v| c.air.lift = v,
    },
    Knob {
        label: "air friction",
        limit: limits::AIR_FRICTION,
        get: |c| not_lab(c).then_some(c.air.friction),
        set: |c, v| c.air.friction = v,
    },
    Knob {
        label: "sleep below",
        limit: limits::SLEEP_ENERGY,
        get: |c| Some(c.sleep.energy),
        set: |c, v| c.sleep.energy = v,
    },
    Knob {
        label: "sleep after steps",
        limit: limits::SLEEP_STEPS,
        get: |c| Some(c.sleep.steps as f32),
        set: |c, v| c.sleep.steps = v as u32,
    },
];

/// The knobs of [`Cloth`]: changing them remakes the cloth where it is (the weld tolerance
/// builds it again from its rest shape).
pub const CLOTH: &[Knob<Cloth>] = &[
    Knob {
        label: "mass",
        limit: limits::MASS,
        get: |c| Some(c.mass),
        set: |c, v| c.mass = v,
    },
    Knob {
        label: "teleport distance",
        limit: limits::TELEPORT_DISTANCE,
        get: |c| Some(c.teleport_distance),
        set: |c, v| c.teleport_distance = v,
    },
    Knob {
        label: "weld tolerance",
        limit: limits::WELD_TOLERANCE,
        get: |c| Some(c.weld_tolerance),
        set: |c, v| c.weld_tolerance = v,
    },
];

/// The knobs of [`ClothSelfCollision`] (the thickness only when it is set, not automatic).
pub const SELF_COLLISION: &[Knob<ClothSelfCollision>] = &[
    Knob {
        label: "thickness",
        limit: limits::SELF_COLLISION_THICKNESS,
        get: |c| c.thickness,
        set: |c, v| c.thickness = Some(v),
    },
    Knob {
        label: "friction",
        limit: limits::SELF_COLLISION_FRICTION,
        get: |c| Some(c.friction),
        set: |c, v| c.friction = v,
    },
];

/// The knobs of [`ClothTethers`].
pub const TETHERS: &[Knob<ClothTethers>] = &[
    Knob {
        label: "slack",
        limit: limits::TETHER_SLACK,
        get: |t| Some(t.slack),
        set: |t, v| t.slack = v,
    },
    Knob {
        label: "pins per vertex",
        limit: limits::TETHER_PINS,
        get: |t| Some(t.pins_per_vertex as f32),
        set: |t, v| t.pins_per_vertex = v as usize,
    },
];

/// The knobs of [`ClothTearing`].
pub const TEARING: &[Knob<ClothTearing>] = &[Knob {
    label: "tears at stretch",
    limit: limits::TEAR_THRESHOLD,
    get: |t| Some(t.threshold),
    set: |t, v| t.threshold = v,
}];

fn half_extents(c: &ClothCollider) -> Option<Vec3> {
    match c.shape {
        ColliderShape::Cuboid { half_extents } => Some(half_extents),
        _ => None,
    }
}

fn set_half_extent(c: &mut ClothCollider, k: usize, v: f32) {
    if let ColliderShape::Cuboid { half_extents } = &mut c.shape {
        half_extents[k] = v;
    }
}

/// The knobs of [`ClothCollider`]: the shape's sizes, thickness, friction, teleport distance.
pub const COLLIDER: &[Knob<ClothCollider>] = &[
    Knob {
        label: "radius",
        limit: limits::COLLIDER_SIZE.named("radius"),
        get: |c| match c.shape {
            ColliderShape::Sphere { radius } | ColliderShape::Capsule { radius, .. } => {
                Some(radius)
            }
            _ => None,
        },
        set: |c, v| match &mut c.shape {
            ColliderShape::Sphere { radius } | ColliderShape::Capsule { radius, .. } => {
                *radius = v;
            }
            _ => {}
        },
    },
    Knob {
        label: "half height",
        limit: limits::COLLIDER_SIZE.named("half_length"),
        get: |c| match c.shape {
            ColliderShape::Capsule { half_length, .. } => Some(half_length),
            _ => None,
        },
        set: |c, v| {
            if let ColliderShape::Capsule { half_length, .. } = &mut c.shape {
                *half_length = v;
            }
        },
    },
    Knob {
        label: "half size x",
        limit: limits::COLLIDER_SIZE.named("half_extents"),
        get: |c| half_extents(c).map(|h| h.x),
        set: |c, v| set_half_extent(c, 0, v),
    },
    Knob {
        label: "half size y",
        limit: limits::COLLIDER_SIZE.named("half_extents"),
        get: |c| half_extents(c).map(|h| h.y),
        set: |c, v| set_half_extent(c, 1, v),
    },
    Knob {
        label: "half size z",
        limit: limits::COLLIDER_SIZE.named("half_extents"),
        get: |c| half_extents(c).map(|h| h.z),
        set: |c, v| set_half_extent(c, 2, v),
    },
    Knob {
        label: "resolution",
        limit: limits::SDF_RESOLUTION,
        get: |c| match c.shape {
            ColliderShape::Mesh(ColliderMesh::Asset { resolution, .. }) => Some(resolution as f32),
            _ => None,
        },
        set: |c, v| {
            if let ColliderShape::Mesh(ColliderMesh::Asset { resolution, .. }) = &mut c.shape {
                *resolution = v as u32;
            }
        },
    },
    Knob {
        label: "thickness",
        limit: limits::COLLIDER_THICKNESS,
        get: |c| Some(c.thickness),
        set: |c, v| c.thickness = v,
    },
    Knob {
        label: "friction",
        limit: limits::COLLIDER_FRICTION,
        get: |c| Some(c.friction),
        set: |c, v| c.friction = v,
    },
    Knob {
        label: "teleport distance",
        limit: limits::TELEPORT_DISTANCE,
        get: |c| Some(c.teleport_distance),
        set: |c, v| c.teleport_distance = v,
    },
];

/// The knobs of [`WindParams`] (the [`Wind`](crate::wind::Wind) resource and each zone's wind).
pub const WIND: &[Knob<WindParams>] = &[
    Knob {
        label: "velocity x",
        limit: limits::WIND_SPEED.component(),
        get: |w| Some(w.velocity.x),
        set: |w, v| w.velocity.x = v,
    },
    Knob {
        label: "velocity y",
        limit: limits::WIND_SPEED.component(),
        get: |w| Some(w.velocity.y),
        set: |w, v| w.velocity.y = v,
    },
    Knob {
        label: "velocity z",
        limit: limits::WIND_SPEED.component(),
        get: |w| Some(w.velocity.z),
        set: |w, v| w.velocity.z = v,
    },
    Knob {
        label: "gust amplitude",
        limit: limits::GUST_AMPLITUDE,
        get: |w| Some(w.gust_amplitude),
        set: |w, v| w.gust_amplitude = v,
    },
    Knob {
        label: "gust frequency",
        limit: limits::GUST_FREQUENCY,
        get: |w| Some(w.gust_frequency),
        set: |w, v| w.gust_frequency = v,
    },
    Knob {
        label: "turbulence",
        limit: limits::TURBULENCE,
        get: |w| Some(w.turbulence),
        set: |w, v| w.turbulence = v,
    },
    Knob {
        label: "eddy size",
        limit: limits::TURBULENCE_SCALE,
        get: |w| Some(w.turbulence_scale),
        set: |w, v| w.turbulence_scale = v,
    },
];

/// The knobs of a [`WindZone`]'s box (its wind takes [`WIND`]).
pub const ZONE: &[Knob<WindZone>] = &[
    Knob {
        label: "half size x",
        limit: limits::ZONE_HALF_EXTENT,
        get: |z| Some(z.half_extents.x),
        set: |z, v| z.half_extents.x = v,
    },
    Knob {
        label: "half size y",
        limit: limits::ZONE_HALF_EXTENT,
        get: |z| Some(z.half_extents.y),
        set: |z, v| z.half_extents.y = v,
    },
    Knob {
        label: "half size z",
        limit: limits::ZONE_HALF_EXTENT,
        get: |z| Some(z.half_extents.z),
        set: |z, v| z.half_extents.z = v,
    },
    Knob {
        label: "falloff",
        limit: limits::ZONE_FALLOFF,
        get: |z| Some(z.falloff),
        set: |z, v| z.falloff = v,
    },
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::SolverParams;

    /// Every knob at both ends of its limit passes the solver's own validation.
    #[test]
    fn config_knob_ends_pass_validation() {
        for solver in [
            Solver::LAB,
            Solver::Pbd {
                stretch: 1.0,
                shear: 1.0,
                bending: 0.5,
            },
            Solver::default(),
        ] {
            for knob in CONFIG {
                let mut c = ClothConfig {
                    solver,
                    ..default()
                };
                if (knob.get)(&c).is_none() {
                    continue;
                }
                for end in [knob.limit.min, knob.limit.max] {
                    knob.apply(&mut c, end);
                    assert_eq!((knob.get)(&c), Some(end), "{}", knob.label);
                    let p: SolverParams = c;
                    assert!(
                        p.validate().is_ok(),
                        "{} = {end}: {:?}",
                        knob.label,
                        p.validate()
                    );
                }
            }
        }
    }

    #[test]
    fn wind_knob_ends_pass_validation() {
        for knob in WIND {
            for end in [knob.limit.min, knob.limit.max] {
                let mut w = WindParams::default();
                knob.apply(&mut w, end);
                assert!(w.validate().is_ok(), "{} = {end}", knob.label);
            }
        }
        for knob in ZONE {
            for end in [knob.limit.min, knob.limit.max] {
                let mut z = WindZone::default();
                knob.apply(&mut z, end);
                assert!(z.validate().is_ok(), "{} = {end}", knob.label);
            }
        }
    }

    #[test]
    fn counts_are_rounded_and_values_clamped() {
        let mut c = ClothConfig::default();
        CONFIG[0].apply(&mut c, 12.6);
        assert_eq!(c.substeps, 13);
        CONFIG[0].apply(&mut c, -5.0);
        assert_eq!(c.substeps, 1);
        CONFIG[0].apply(&mut c, f32::NAN);
        assert_eq!(c.substeps, 1);
    }
}
