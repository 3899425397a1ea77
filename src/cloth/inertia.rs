//! [`ClothInertia`]: the part of its anchor's motion a cloth does not feel, carried rigidly at
//! the start of each step (`solver::Carry`).

use bevy::prelude::*;

use super::systems::note_rejection;
use super::{Cloth, ClothError, ClothInertia, ClothSim};
use crate::foundation::{EntityName, FixedPoses};
use crate::solver::{Carry, is_teleport};

/// Carries the cloth of `cs` by the part of its inertia anchor's motion since the last step
/// that it does not feel, and remembers where the anchor is now. Nothing happens without a
/// [`ClothInertia`] or with one that feels everything (the cloth steps exactly as without);
/// a refused one is reported once and the cloth feels all of its motion meanwhile. An anchor
/// that jumped past the cloth's teleport distance is not carried (a teleport, not a motion).
pub(super) fn carry_unfelt_motion(
    commands: &mut Commands,
    who: EntityName<'_>,
    cs: &mut ClothSim,
    cloth: &Cloth,
    inertia: Option<&ClothInertia>,
    poses: &FixedPoses,
) {
    let meanwhile = (
        "inertia",
        "it feels all of its anchor's motion until this is fixed",
    );
    cs.carry = None;
    let inertia = match inertia.map(|i| i.validate().map(|()| i)) {
        Some(Ok(i)) if !i.is_world_space() => i,
        other => {
            // None, world space, or refused: the cloth feels all of its motion.
            cs.inertia_from = None;
            let result = other.map_or(Ok(()), |r| r.map(|_| ()));
            note_rejection(commands, who, &mut cs.inertia_error, result, meanwhile);
            return;
        }
    };
    let anchor = inertia.anchor.unwrap_or(who.entity);
    let pose = poses
        .get(anchor)
        .map(|at| {
            let (_, rotation, translation) = at.to_scale_rotation_translation();
            (translation, rotation)
        })
        .filter(|(t, r)| t.is_finite() && r.is_finite())
        .ok_or(ClothError::InertiaAnchorMissing(anchor));
    let now = match pose {
        Ok(now) => now,
        Err(e) => {
            cs.inertia_from = None;
            note_rejection(commands, who, &mut cs.inertia_error, Err(e), meanwhile);
            return;
        }
    };
    note_rejection(commands, who, &mut cs.inertia_error, Ok(()), meanwhile);
    if let Some((from_anchor, from, from_rotation)) = cs.inertia_from
        && from_anchor == anchor
        && !is_teleport(from, now.0, cloth.teleport_distance)
        && let Some(carry) =
            Carry::unfelt((from, from_rotation), now, inertia.linear, inertia.angular)
    {
        // Applied (with a change of size, if any) by `sync_cloths`.
        cs.carry = Some(carry);
        cs.dirty = true;
    }
    cs.inertia_from = Some((anchor, now.0, now.1));
}
