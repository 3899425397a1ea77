//! [`ClothPlugin`]: creates, steps and writes back every [`Cloth`] on the CPU.

use bevy::prelude::*;

use super::components::ClothPluginPresent;
use super::material::warn_one_sided_materials;
use super::pin_rule::resolve_pin_rules;
use super::skinning::{skin_cloths, unskin_free_cloths};
use super::systems::{
    init_cloths, on_cloth_removed, rebuild_changed_meshes, retry_cloths, step_cloths, sync_cloths,
};
use super::writeback::write_back;
use super::{
    Cloth, ClothConfig, ClothFailed, ClothInertia, ClothPin, ClothPinRule, ClothPins,
    ClothSelfCollision, ClothSkinning, ClothSmoothing, ClothSource, ClothTearing, ClothTethers,
    ClothTorn, ClothWorkers, PinAnchor,
};
use crate::foundation::{ClothSchedule, ClothSystems};

/// Simulates every [`Cloth`] entity on the CPU.
///
/// Runs in the group's fixed-timestep schedule ([`ClothSchedule`], `FixedPostUpdate` by
/// default), so a dropped frame changes how many steps run, never their length: the result
/// does not depend on the frame rate. Set the rate with `Time::<Fixed>::from_hz(..)`.
///
/// Its systems, in [`ClothSystems::Prepare`]: `retry_cloths` (cloths whose settings were
/// fixed, or whose mesh or [`Cloth`] changed to valid settings, are rebuilt),
/// `resolve_pin_rules` ([`ClothPinRule`]s written into [`ClothPins`]), `init_cloths`
/// (new cloths are built once their mesh has loaded) and `sync_cloths` (changed settings and
/// pins applied, pins moved to their anchors), `unskin_free_cloths` (a `Cloth` without [`ClothSkinning`] on a
/// skinned mesh takes its `SkinnedMesh` off), `skin_cloths` ([`ClothSkinning`]: the skin's
/// targets for this step); in [`ClothSystems::Simulate`], `step_cloths` (every cloth not
/// stepped elsewhere, in one `step_many`); in [`ClothSystems::Writeback`], `write_back`; in
/// `PreUpdate`, `rebuild_changed_meshes` (a cloth whose mesh asset changed, e.g. reloaded from
/// disk, is built again from it).
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothPlugin;

impl Plugin for ClothPlugin {
    fn build(&self, app: &mut App) {
        let schedule = ClothSchedule::of(app);
        app.register_type::<Cloth>()
            .register_type::<ClothConfig>()
            .register_type::<ClothPins>()
            .register_type::<ClothPin>()
            .register_type::<PinAnchor>()
            .register_type::<ClothPinRule>()
            .register_type::<ClothSelfCollision>()
            .register_type::<ClothTethers>()
            .register_type::<ClothTearing>()
            .register_type::<ClothInertia>()
            .register_type::<ClothSkinning>()
            .register_type::<ClothSource>()
            .register_type::<ClothSmoothing>()
            .init_resource::<ClothWorkers>()
            .init_resource::<ClothPluginPresent>()
            .add_message::<ClothTorn>()
            .add_message::<ClothFailed>()
            .add_observer(on_cloth_removed)
            .add_systems(Startup, say_if_unoptimized)
            .add_systems(
                schedule,
                (
                    (
                        retry_cloths,
                        resolve_pin_rules,
                        init_cloths,
                        sync_cloths,
                        unskin_free_cloths,
                        skin_cloths,
                    )
                        .chain()
                        .in_set(ClothSystems::Prepare),
                    step_cloths.in_set(ClothSystems::Simulate),
                ),
            )
            .add_systems(PostUpdate, write_back.in_set(ClothSystems::Writeback))
            .add_systems(
                Update,
                warn_one_sided_materials.run_if(resource_exists::<Assets<StandardMaterial>>),
            )
            .add_systems(
                PreUpdate,
                rebuild_changed_meshes.run_if(resource_exists::<Messages<AssetEvent<Mesh>>>),
            );
    }

    fn finish(&self, app: &mut App) {
        if !app.world().contains_resource::<Assets<Mesh>>() {
            warn!(
                "ClothPlugin: no Assets<Mesh> resource; add MeshPlugin (part of DefaultPlugins) \
                 and AssetPlugin, or no cloth will be simulated"
            );
        }
    }
}

/// What to tell a user whose build compiled this crate without optimizations, or `None`.
fn unoptimized_warning(unoptimized: bool) -> Option<&'static str> {
    unoptimized.then_some(
        "bevy_cloth was compiled without optimizations (a debug build), so its cloth runs 20 \
         to 60 times slower than in a release build (the flag example: 83 ms a frame against \
         1.4); optimize it in debug builds too, with `[profile.dev.package.bevy_cloth] \
         opt-level = 3` in your Cargo.toml (or Bevy's advice, `[profile.dev.package.\"*\"] \
         opt-level = 3`), or run with `--release`",
    )
}

/// Says once, at startup, that the crate was compiled without optimizations (see
/// [`unoptimized_warning`]).
fn say_if_unoptimized() {
    if let Some(why) = unoptimized_warning(cfg!(cloth_unoptimized)) {
        warn!("{why}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_unoptimized_build_is_told_how_to_optimize_the_crate() {
        assert_eq!(unoptimized_warning(false), None);
        let why = unoptimized_warning(true).expect("an unoptimized build is told");
        assert!(why.contains("[profile.dev.package.bevy_cloth]"), "{why}");
        assert!(why.contains("opt-level = 3"), "{why}");
        // CI runs the tests in release: there the crate must not call itself unoptimized.
        let release_told =
            !cfg!(debug_assertions) && unoptimized_warning(cfg!(cloth_unoptimized)).is_some();
        assert!(!release_told, "a release build took itself for unoptimized");
    }
}
