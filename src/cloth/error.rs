//! Why a cloth is not simulated: [`ClothError`], the [`ClothFailed`] message sent once, and the
//! [`ClothInvalid`] component left on the entity.

use bevy::prelude::*;

use crate::foundation::{EntityName, MeshError};
use crate::solver::{SolverError, limits};

/// Why a cloth is not simulated. Logged once (naming the entity) and stored in
/// [`ClothInvalid`]; every other cloth keeps running.
#[derive(Clone, Debug, PartialEq)]
pub enum ClothError {
    /// The mesh cannot be read (not a triangle list, no positions or indices, only in the
    /// render world).
    Mesh(MeshError),
    /// The entity's [`Mesh3d`] handle points at no mesh asset (it failed to load or was removed).
    MeshMissing,
    /// The cloth's total mass is outside [`limits::MASS`].
    BadMass(f32),
    /// [`Cloth::teleport_distance`](super::Cloth::teleport_distance) is outside [`limits::TELEPORT_DISTANCE`].
    BadTeleportDistance(f32),
    /// [`Cloth::weld_tolerance`](super::Cloth::weld_tolerance) is outside [`limits::WELD_TOLERANCE`].
    BadWeldTolerance(f32),
    /// A [`ClothInertia`](super::ClothInertia) share outside `0..=1`.
    BadInertia {
        /// Share of linear motion.
        linear: f32,
        /// Share of rotation.
        angular: f32,
    },
    /// The [`ClothInertia`](super::ClothInertia) anchor has no pose (it does not exist, or
    /// has no transform).
    InertiaAnchorMissing(Entity),
    /// A pin's anchor entity ([`PinAnchor::Entity`](super::PinAnchor::Entity) or
    /// [`PinAnchor::Attached`](super::PinAnchor::Attached)) has no pose: it does not exist (a
    /// bone name that matched nothing, a despawned entity) or has no transform. Its pins hold
    /// where they are meanwhile.
    PinAnchorMissing(Entity),
    /// [`ClothSkinning`](super::ClothSkinning) cannot hold the cloth to its skin (no
    /// `SkinnedMesh` or joint attributes, a weight map of the wrong length, a bad distance, a
    /// joint with no pose): the reason.
    Skinning(String),
    /// A [`ClothPinRule`](super::ClothPinRule) gives no pins: the reason.
    PinRule(super::PinRuleError),
    /// The solver rejected the mesh, masses, pins or parameters.
    Solver(SolverError),
}

impl core::fmt::Display for ClothError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ClothError::Mesh(e) => e.fmt(f),
            ClothError::MeshMissing => write!(f, "the Mesh3d handle points at no mesh asset"),
            ClothError::BadMass(m) => {
                let l = limits::MASS;
                write!(f, "cloth mass {m} is outside [{}, {}] kg", l.min, l.max)
            }
            ClothError::BadTeleportDistance(d) => {
                let l = limits::TELEPORT_DISTANCE;
                write!(
                    f,
                    "teleport distance {d} is outside [{}, {}] m (infinity turns it off)",
                    l.min, l.max
                )
            }
            ClothError::BadWeldTolerance(t) => {
                let l = limits::WELD_TOLERANCE;
                write!(f, "weld tolerance {t} is outside [{}, {}]", l.min, l.max)
            }
            ClothError::BadInertia { linear, angular } => write!(
                f,
                "inertia (linear {linear}, angular {angular}) is outside [0, 1] (1 feels all \
                 of the anchor's motion, 0 none)"
            ),
            ClothError::InertiaAnchorMissing(e) => {
                write!(
                    f,
                    "the inertia anchor {e} does not exist or has no transform"
                )
            }
            ClothError::PinAnchorMissing(e) => {
                write!(f, "the pin anchor {e} does not exist or has no transform")
            }
            ClothError::Skinning(why) => write!(f, "skinned clothing: {why}"),
            ClothError::PinRule(e) => e.fmt(f),
            ClothError::Solver(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for ClothError {}

impl From<SolverError> for ClothError {
    fn from(e: SolverError) -> Self {
        ClothError::Solver(e)
    }
}

impl From<MeshError> for ClothError {
    fn from(e: MeshError) -> Self {
        ClothError::Mesh(e)
    }
}

/// Sent once when a cloth is found invalid (the same moment the error is logged), so gameplay
/// or tools can react; the cloth then carries [`ClothInvalid`].
#[derive(Message, Clone, Debug, PartialEq)]
pub struct ClothFailed {
    /// The cloth entity.
    pub cloth: Entity,
    /// What is wrong with it.
    pub error: ClothError,
}

/// Present on a cloth entity that cannot be simulated, with the reason.
///
/// The plugin tries again when [`Cloth`](super::Cloth), [`ClothConfig`](super::ClothConfig),
/// [`ClothPins`](super::ClothPins), [`ClothPinRule`](super::ClothPinRule) or [`Mesh3d`]
/// change.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct ClothInvalid(pub ClothError);

/// Logs `error` once for the cloth, sends [`ClothFailed`] and marks the entity
/// [`ClothInvalid`] (dropping any running simulation: fixing it rebuilds from scratch).
pub(crate) fn report(commands: &mut Commands, who: EntityName<'_>, error: ClothError) {
    error!("cloth {who}: {error}; it is not simulated");
    commands.write_message(ClothFailed {
        cloth: who.entity,
        error: error.clone(),
    });
    commands
        .entity(who.entity)
        .try_remove::<super::ClothSim>()
        .try_insert(ClothInvalid(error));
}
