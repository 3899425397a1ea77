//! What the physics-engine bridges (`rapier`, `avian`) share: the opt-out marker, the settings
//! every bridge takes, baking an engine's triangles, mirroring a collider, forgetting a removed
//! one (scheduling in the cloth schedule, whichever plugin came first, is
//! [`schedule_once`](crate::foundation::schedule_once)).
//!
//! Each bridge keeps only what differs between engines: how its shapes map to
//! [`ColliderShape`] ([`EngineCollider`]), where it runs, and how an impulse reaches its
//! bodies.

use std::marker::PhantomData;
use std::sync::Arc;

use bevy::prelude::*;

use super::{ClothCollider, ColliderMesh, ColliderShape};
use crate::foundation::ClothWorkers;
use crate::solver::{SdfGrid, Workers};

/// On a physics-engine collider (rapier or avian): cloth ignores it.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct NoClothCollision;

/// How a bridge mirrors colliders and whether it pushes bodies back (each bridge plugin's
/// fields).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Mirroring {
    pub thickness: f32,
    pub friction: f32,
    pub resolution: u32,
    pub two_way: bool,
    pub max_push_speed: f32,
}

/// The share (`0..=1`) of the cloth's reaction impulse `j` a body of `mass` gets when its
/// contact point moves at `velocity`: all of it, unless that would send the body away from
/// the cloth (along `j`) faster than `max_push_speed`.
///
/// The cloth solves its contacts as if the body could not yield, and the body feels them one
/// step later: a heavy body landing on taut cloth stretches it for a whole step, and the
/// whole of that stretch, given back, throws it off again higher than it fell, a trampoline
/// that gains energy. Capped, the reaction still stops what moves into the cloth (a ball in
/// a net, a box landing in a hammock, the weight of a body lying on cloth) and lets the cloth
/// push a body it moves into, only not faster than `max_push_speed`.
pub(crate) fn reaction_share(j: Vec3, mass: f32, velocity: Vec3, max_push_speed: f32) -> f32 {
    let len = j.length();
    if !(len.is_finite() && len > 0.0 && mass.is_finite() && mass > 0.0) {
        return 0.0;
    }
    let along = velocity.dot(j / len);
    let allowed = mass * (max_push_speed - along).max(0.0);
    (allowed / len).clamp(0.0, 1.0)
}

/// Bakes an engine `C`'s shape's triangles into an SDF collider shape on `par`; `None` (with a
/// warning naming the engine) when they cannot be baked.
pub(crate) fn bake<C: EngineCollider>(
    vertices: &[Vec3],
    indices: &[[u32; 3]],
    resolution: u32,
    par: &Workers,
) -> Option<ColliderShape> {
    let flat: Vec<u32> = indices.iter().flatten().copied().collect();
    match SdfGrid::from_mesh_on(vertices, &flat, resolution, par) {
        Ok(grid) => Some(ColliderShape::Mesh(ColliderMesh::Baked(Arc::new(grid)))),
        Err(e) => {
            warn!(
                "{} collider: cannot bake its triangles into an SDF: {e}",
                C::ENGINE
            );
            None
        }
    }
}

/// An engine's collider component, as the bridge reads it.
pub(crate) trait EngineCollider: Component {
    /// The engine's name in messages.
    const ENGINE: &'static str;
    /// Its cloth shape, unscaled (the entity's transform scales both); `None` for a shape
    /// cloth does not collide with.
    fn cloth_shape(&self, resolution: u32, par: &Workers) -> Option<ColliderShape>;
}

/// The settings of the bridge whose mirrors are marked `M`.
#[derive(Resource)]
pub(crate) struct Settings<M>(pub Mirroring, PhantomData<fn() -> M>);

/// What every bridge adds when built: its settings, and the observer that forgets a mirror
/// when its engine collider `C` goes.
pub(crate) fn install<C: EngineCollider, M: Component>(app: &mut App, m: Mirroring) {
    app.insert_resource(Settings::<M>(m, PhantomData))
        .add_observer(forget_removed::<C, M>);
}

/// Gives every new or changed engine collider `C` the cloth collider mirroring it, with the
/// marker `M` that says the bridge made it. A cloth collider the user put there is left alone;
/// a shape cloth cannot use is ignored with a warning (and a mirror made earlier from another
/// shape removed).
#[expect(clippy::type_complexity, reason = "a query filter, read once")]
pub(crate) fn mirror_colliders<C: EngineCollider, M: Component + Default>(
    mut commands: Commands,
    settings: Res<Settings<M>>,
    workers: Option<Res<ClothWorkers>>,
    changed: Query<
        (Entity, &C, Has<ClothCollider>, Has<M>),
        (Without<NoClothCollision>, Changed<C>),
    >,
) {
    let m = settings.0;
    // Baked on the cloth plugins' threads: the field is the same on any number of them.
    let par = ClothWorkers::or_serial(workers.as_deref());
    for (entity, collider, has_cloth_collider, mirrored) in &changed {
        if has_cloth_collider && !mirrored {
            continue; // the user's own cloth collider wins
        }
        match collider.cloth_shape(m.resolution, par) {
            Some(shape) => {
                commands.entity(entity).insert((
                    ClothCollider {
                        shape,
                        thickness: m.thickness,
                        friction: m.friction,
                        ..ClothCollider::new(ColliderShape::Plane)
                    },
                    M::default(),
                ));
            }
            None => {
                warn!(
                    "{} collider {entity}: its shape (a compound, height field, half-space \
                     not facing +y, segment, polyline or voxels) is not one cloth collides \
                     with; cloth ignores it (give the entity a ClothCollider of its own instead)",
                    C::ENGINE
                );
                commands.entity(entity).try_remove::<(ClothCollider, M)>();
            }
        }
    }
}

/// When an engine collider `C` goes (removed, or its entity despawned), the cloth collider the
/// bridge mirrored from it (marked `M`) goes too: nothing keeps pushing cloth where the body was.
fn forget_removed<C: Component, M: Component>(
    removed: On<Remove, C>,
    mirrored: Query<(), With<M>>,
    mut commands: Commands,
) {
    if mirrored.contains(removed.entity) {
        commands
            .entity(removed.entity)
            .try_remove::<(ClothCollider, M)>();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reaction_stops_a_body_and_throws_it_back_no_faster_than_the_cap() {
        let up = Vec3::new(0.0, 0.3, 0.0);
        // Falling at 1 m/s into the cloth, 0.5 kg: 0.3 N·s would send it up at 0.6 m/s;
        // capped at 0.25 m/s it gets 0.5 × 1.25 = 0.625 N·s worth, so all of it.
        assert_eq!(
            reaction_share(up, 0.5, Vec3::new(0.0, -1.0, 0.0), 0.25),
            1.0
        );
        // Resting: all of 0.3 would send it up at 0.6 m/s; it gets 0.5 × 0.25 / 0.3.
        let s = reaction_share(up, 0.5, Vec3::ZERO, 0.25);
        assert!((s - 0.125 / 0.3).abs() < 1e-6, "{s}");
        // Already leaving faster than the cap, or sideways motion only: nothing, and all.
        assert_eq!(reaction_share(up, 0.5, Vec3::new(0.0, 0.4, 0.0), 0.25), 0.0);
        assert_eq!(
            reaction_share(up, 0.5, Vec3::new(3.0, -1.0, 0.0), 0.25),
            1.0
        );
        // Bad input gives nothing, never NaN.
        for (j, m, v) in [
            (Vec3::ZERO, 0.5, Vec3::ZERO),
            (Vec3::NAN, 0.5, Vec3::ZERO),
            (up, 0.0, Vec3::ZERO),
            (up, f32::INFINITY, Vec3::ZERO),
            (up, 0.5, Vec3::NAN),
        ] {
            assert_eq!(reaction_share(j, m, v, 0.25), 0.0, "{j} {m} {v}");
        }
    }
}
