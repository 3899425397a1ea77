//! Wind for cloth: a global [`Wind`] resource and local [`WindZone`]s.
//!
//! Each fixed step, [`ClothWindPlugin`] turns them, with each zone where it is at that step
//! ([`FixedPoses`]: a zone moved in `FixedUpdate` blows from there in the same step), into a
//! [`WindField`] (noise generators included) stored in
//! [`ClothWindField`]; every cloth samples it on a coarse [`AirGrid`](crate::solver::AirGrid)
//! around itself once per step and feels it, every substep, through its own
//! [`Aerodynamics`](crate::solver::Aerodynamics) (drag, lift, skin friction). No wind resource
//! and no zones: the cloth still meets still air, and there is no wind sampling at all.

use bevy::prelude::*;
use bevy::reflect::impl_reflect_opaque;

use crate::foundation::{ClothSchedule, ClothSystems, EntityName, FixedPoses};
use crate::solver::{ParamError, Pose, WindField, WindParams, WindRegion, limits};

impl_reflect_opaque!((in bevy_cloth::solver) WindParams(Debug, Clone, PartialEq, Default));

/// Wind blowing everywhere.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// App::new().insert_resource(Wind(WindParams {
///     velocity: Vec3::new(8.0, 0.0, 2.0),
///     gust_amplitude: 0.4,
///     ..default()
/// }));
/// ```
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Resource, Reflect, Clone, Copy, Debug, Default, PartialEq, Deref, DerefMut)]
#[reflect(Resource, Default, Clone, PartialEq)]
pub struct Wind(pub WindParams);

/// Wind blowing inside a box around the entity (its transform places and turns the box),
/// fading out over `falloff` metres outside it: a fan, a doorway draught, a vent.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Clone, PartialEq)]
#[require(Transform)]
pub struct WindZone {
    /// The wind inside the zone (velocity in world space).
    pub wind: WindParams,
    /// Half size of the box.
    pub half_extents: Vec3,
    /// Fade-out distance outside the box.
    pub falloff: f32,
}

impl WindZone {
    /// Checks the wind and the box: [`WindParams::validate`], and each half extent and the
    /// falloff within [`limits::ZONE_HALF_EXTENT`] and [`limits::ZONE_FALLOFF`].
    ///
    /// # Errors
    /// A [`ParamError`] naming the first value out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.wind.validate()?;
        for v in self.half_extents.to_array() {
            limits::ZONE_HALF_EXTENT.check(v)?;
        }
        limits::ZONE_FALLOFF.check(self.falloff)
    }

    /// The box the wind blows in, placed by the entity's global transform (its scale
    /// stretches the box).
    #[must_use]
    pub fn region(&self, at: &GlobalTransform) -> WindRegion {
        let (scale, rotation, translation) = at.to_scale_rotation_translation();
        WindRegion {
            pose: Pose {
                translation,
                rotation,
                scale: 1.0,
            },
            half_extents: self.half_extents * scale.abs(),
            falloff: self.falloff,
        }
    }
}

impl Default for WindZone {
    /// The default wind in a 2 m box, fading out over 1 m.
    fn default() -> Self {
        Self {
            wind: WindParams::default(),
            half_extents: Vec3::ONE,
            falloff: 1.0,
        }
    }
}

/// The wind field of this step, with the time that drives its gusts.
#[derive(Resource, Clone, Debug, Default)]
pub struct ClothWindField {
    /// The field; empty when there is no wind.
    pub field: WindField,
    /// Seconds of fixed time elapsed at the start of this step (`f64`: no precision lost
    /// and no jump however long the game runs).
    pub time: f64,
}

/// Adds [`Wind`] and [`WindZone`] support.
///
/// Part of `ClothPlugins`; gathers the wind in the group's [`ClothSchedule`], in
/// [`ClothSystems::Prepare`].
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothWindPlugin;

impl Plugin for ClothWindPlugin {
    fn build(&self, app: &mut App) {
        let schedule = ClothSchedule::of(app);
        app.register_type::<Wind>()
            .register_type::<WindZone>()
            .init_resource::<ClothWindField>()
            .add_systems(schedule, gather_wind.in_set(ClothSystems::Prepare));
    }
}

fn gather_wind(
    time: Res<Time>,
    global: Option<Res<Wind>>,
    zones: Query<(Entity, &WindZone)>,
    poses: FixedPoses,
    names: Query<&Name>,
    mut out: ResMut<ClothWindField>,
    mut reported: Local<bevy::platform::collections::HashSet<Option<Entity>>>,
) {
    out.time = time.elapsed_secs_f64() - time.delta_secs_f64();
    // An invalid wind (NaN velocity, negative drag, ...) is left out, and said once.
    let mut valid = |source: Option<Entity>, check: Result<(), ParamError>| match check {
        Ok(()) => {
            reported.remove(&source);
            true
        }
        Err(e) => {
            if reported.insert(source) {
                match source {
                    Some(entity) => {
                        let who = EntityName::new(entity, names.get(entity).ok());
                        error!("wind zone {who}: {e}; it is ignored");
                    }
                    None => error!("Wind resource: {e}; it is ignored"),
                }
            }
            false
        }
    };
    let global = global.filter(|w| valid(None, w.0.validate()));
    let sources = global.map(|w| (w.0, None)).into_iter().chain(
        zones
            .iter()
            .filter(|(e, z)| valid(Some(*e), z.validate()))
            // Where the zone is at this fixed step (moved in `FixedUpdate`, spawned this
            // step), not last frame's `GlobalTransform`.
            .filter_map(|(e, z)| poses.get(e).map(|at| (z, at)))
            .filter(|(_, at)| at.translation().is_finite())
            .map(|(z, at)| (z.wind, Some(z.region(&at)))),
    );
    out.field = WindField::new(sources);
}
