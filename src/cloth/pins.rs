//! Pins in particle terms: the user's [`ClothPins`] (mesh vertices) resolved to particles, the
//! offsets of [`PinAnchor::Attached`] pins, where each pin should be at this step, and
//! re-pinning under the teleport rule.

use std::collections::{HashMap, HashSet};

use bevy::prelude::*;

use super::{ClothError, ClothPins, PinAnchor};
use crate::foundation::FixedPoses;
use crate::solver::{ClothState, Pin, Simulation, SolverError, StateError, Weld, teleport_offset};

/// Pins in particle terms: `(particle, anchor)`.
pub(super) type PinList = Vec<(u32, PinAnchor)>;

/// The pins of `pins` in particle terms, first pin of a particle winning.
pub(super) fn pin_list(pins: &ClothPins, weld: &Weld) -> Result<PinList, ClothError> {
    let n = weld.vertex_count();
    let mut seen = HashSet::new();
    let mut out = Vec::with_capacity(pins.0.len());
    for p in &pins.0 {
        if p.vertex as usize >= n {
            return Err(SolverError::State(StateError::PinOutOfRange {
                vertex: p.vertex,
                vertex_count: n,
            })
            .into());
        }
        let particle = weld.particle(p.vertex);
        if seen.insert(particle) {
            out.push((particle, p.anchor));
        }
    }
    Ok(out)
}

/// Turns the [`PinAnchor::Attached`] pins of `list` into [`PinAnchor::Entity`] pins with the
/// offset they have from their entity: the one fixed when the pin was first applied (kept in
/// `attached`), or, for a new pin, where its vertex is now (its pin target if it was pinned
/// already) in the entity's space. A pin whose entity has no pose yet stays `Attached` and
/// holds still until the entity has one. Attachments no longer in the list are forgotten.
pub(super) fn attach(
    list: &mut PinList,
    attached: &mut Vec<(u32, Entity, Vec3)>,
    state: &ClothState,
    poses: &FixedPoses,
) {
    attached.retain(|&(p, e, _)| list.contains(&(p, PinAnchor::Attached(e))));
    if attached.is_empty()
        && !list
            .iter()
            .any(|(_, a)| matches!(a, PinAnchor::Attached(_)))
    {
        return;
    }
    let targets: HashMap<u32, Vec3> = state.pins().iter().map(|p| (p.vertex, p.target)).collect();
    for (particle, anchor) in list.iter_mut() {
        let PinAnchor::Attached(entity) = *anchor else {
            continue;
        };
        let known = attached
            .iter()
            .find(|&&(p, e, _)| p == *particle && e == entity)
            .map(|&(_, _, offset)| offset);
        let offset = known.or_else(|| {
            let pose = poses.get(entity)?;
            let now = targets
                .get(particle)
                .copied()
                .unwrap_or_else(|| state.position(*particle as usize));
            let offset = pose.affine().inverse().transform_point3(now);
            offset.is_finite().then(|| {
                attached.push((*particle, entity, offset));
                offset
            })
        });
        if let Some(offset) = offset {
            *anchor = PinAnchor::Entity { entity, offset };
        }
    }
}

/// Where a pin should be now (`None`: its anchor entity has no pose; the pin stays).
fn pin_target(
    particle: u32,
    anchor: PinAnchor,
    rest_local: &[Vec3],
    own: Option<&GlobalTransform>,
    poses: &FixedPoses,
) -> Option<Vec3> {
    match anchor {
        // Hidden by a scale too small to place the cloth at (`own` is `None`), the rest pins
        // hold where they are, as its rest shape does: drawn to one point, they would crumple
        // the cloth it grows back from.
        PinAnchor::Rest => own.and_then(|own| {
            rest_local
                .get(particle as usize)
                .map(|r| own.transform_point(*r))
        }),
        PinAnchor::World(w) => Some(w),
        PinAnchor::Entity { entity, offset } => {
            poses.get(entity).map(|t| t.transform_point(offset))
        }
        // Not attached yet (see `attach`): holds still.
        PinAnchor::Attached(_) => None,
    }
}

/// Replaces the pins of `sim` with `list`. Vertices pinned before and after keep the teleport
/// rule: if their anchors jumped farther than `teleport` since the last step, the whole cloth
/// moves with them (the offset is returned). Atomic: on error nothing changes.
pub(super) fn repin(
    sim: &mut Simulation,
    list: &[(u32, PinAnchor)],
    rest_local: &[Vec3],
    own: Option<&GlobalTransform>,
    poses: &FixedPoses,
    teleport: f32,
) -> Result<Option<Vec3>, ClothError> {
    let old: HashMap<u32, Vec3> = sim
        .state()
        .pins()
        .iter()
        .map(|p| (p.vertex, p.target))
        .collect();
    let new: Vec<Pin> = list
        .iter()
        .map(|&(particle, anchor)| Pin {
            vertex: particle,
            target: pin_target(particle, anchor, rest_local, own, poses)
                .unwrap_or_else(|| sim.state().position(particle as usize)),
        })
        .collect();
    let offset = teleport_offset(
        new.iter()
            .filter_map(|p| old.get(&p.vertex).map(|&o| (o, p.target))),
        teleport,
    );
    let state = sim.state_mut();
    state
        .set_pins(new.iter().copied())
        .map_err(SolverError::from)?;
    if let Some(offset) = offset {
        state.teleport(offset, new.iter().map(|p| p.target));
    }
    Ok(offset)
}

/// Moves the pins of an unchanged pin list to their anchors; a jump past `teleport` moves the
/// whole cloth by the pins' mean jump (returned).
pub(super) fn follow_anchors(
    sim: &mut Simulation,
    list: &[(u32, PinAnchor)],
    rest_local: &[Vec3],
    own: Option<&GlobalTransform>,
    poses: &FixedPoses,
    teleport: f32,
) -> Option<Vec3> {
    let current: Vec<Vec3> = sim.state().pins().iter().map(|p| p.target).collect();
    let targets: Vec<Option<Vec3>> = list
        .iter()
        .map(|&(p, a)| pin_target(p, a, rest_local, own, poses))
        .collect();
    let offset = teleport_offset(
        targets
            .iter()
            .zip(&current)
            .filter_map(|(t, &c)| t.map(|t| (c, t))),
        teleport,
    );
    let resolved = targets.iter().zip(&current).map(|(t, &c)| t.unwrap_or(c));
    let state = sim.state_mut();
    match offset {
        Some(offset) => state.teleport(offset, resolved),
        None => state.set_pin_targets(resolved),
    }
    offset
}
