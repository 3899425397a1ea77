//! The systems that create, configure and step cloths on the CPU.

use std::time::Duration;

use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::tasks::ComputeTaskPool;

use super::build::{
    THICKNESS_CHECK_STEPS, build, features, hidden, remake, reshape, typical_edge, warn_coarse,
    warn_loose, warn_self_collision,
};
use super::error::report;
use super::inertia::carry_unfelt_motion;
use super::pin_rule::drops_colors;
use super::pins::{attach, follow_anchors, pin_list, repin};
use super::skinning::{ClothSkin, ClothUnskinned};
use super::{
    Cloth, ClothConfig, ClothError, ClothFailed, ClothInertia, ClothInvalid, ClothPinRule,
    ClothPins, ClothSelfCollision, ClothSim, ClothSource, ClothSteppedElsewhere, ClothTearing,
    ClothTethers, ClothTorn, ClothWorkers, PinAnchor, TaskPoolParallel,
};
use crate::collider::{ClothColliders, ClothContactImpulse, add_impulses};
use crate::foundation::{
    EntityName, FixedPoses, SimulatedCloth, mesh_fingerprint, modified_meshes,
};
use crate::solver::{
    Carry, Environment, ManyItem, Serial, SolverError, StepReport, step_many, teleport_offset,
};
use crate::wind::ClothWindField;

/// How long a cloth may wait for its mesh to load before it says so (once).
const MESH_WAIT_WARNING: Duration = Duration::from_secs(5);

/// Creates the simulation of cloths that have none yet (waiting while their mesh loads).
#[expect(
    clippy::type_complexity,
    clippy::too_many_arguments,
    reason = "a system's inputs: the new cloths, the meshless ones, poses, time"
)]
pub(super) fn init_cloths(
    mut commands: Commands,
    mut meshes: Option<ResMut<Assets<Mesh>>>,
    asset_server: Option<Res<AssetServer>>,
    new: Query<
        (
            (Entity, Option<&Name>),
            &Cloth,
            &ClothConfig,
            &ClothPins,
            &Mesh3d,
            Option<&ClothSource>,
            FeatureQuery,
            Option<&ClothPinRule>,
        ),
        (Without<ClothSim>, Without<ClothInvalid>),
    >,
    meshless: Query<(Entity, Option<&Name>), (With<Cloth>, Without<Mesh3d>, Without<ClothSim>)>,
    // Where meshes are below a cloth that has none (a glTF node's children).
    descendants: Query<&Children>,
    with_mesh: Query<Option<&Name>, With<Mesh3d>>,
    poses: FixedPoses,
    time: Res<Time>,
    // Cloths waiting for their mesh: since when, and whether they said so.
    mut waiting: Local<HashMap<Entity, (Duration, bool)>>,
) {
    let Some(meshes) = meshes.as_deref_mut() else {
        return;
    };
    let now = time.elapsed();
    let mut still_waiting = HashMap::default();
    // A cloth that cannot be built yet waits; past MESH_WAIT_WARNING it says why, once.
    let wait = |still: &mut HashMap<Entity, (Duration, bool)>,
                entity: Entity,
                why: &dyn Fn() -> String| {
        let (since, said) = waiting.get(&entity).copied().unwrap_or((now, false));
        let late = now.saturating_sub(since) >= MESH_WAIT_WARNING;
        if late && !said {
            warn!("{}", why());
        }
        still.insert(entity, (since, said || late));
    };
    // No `Mesh3d` (a glTF node, whose meshes are on its child entities; a mesh forgotten):
    // nothing to simulate until one is put on it.
    for (entity, name) in &meshless {
        wait(&mut still_waiting, entity, &|| {
            let who = EntityName::new(entity, name);
            let meshes: Vec<String> = descendants
                .iter_descendants(entity)
                .filter_map(|e| {
                    with_mesh
                        .get(e)
                        .ok()
                        .map(|n| EntityName::new(e, n).to_string())
                })
                .take(4)
                .collect();
            let hint = if meshes.is_empty() {
                String::new()
            } else {
                format!(
                    " (a glTF node's meshes are on its child entities: put Cloth on {})",
                    meshes.join(" or ")
                )
            };
            format!(
                "cloth {who}: the entity has no Mesh3d after {} s; it is not simulated until \
                 it has one{hint}",
                MESH_WAIT_WARNING.as_secs()
            )
        });
    }
    for ((entity, name), cloth, config, pins, mesh3d, source, (sc, tethers, tearing), rule) in &new
    {
        let who = EntityName::new(entity, name);
        // Rebuilding (after a change to `Cloth` or a fix): start from the mesh the user gave.
        let source_handle = ClothSource::user_mesh(source, mesh3d).clone();
        let Some(mesh) = meshes.get(&source_handle) else {
            // Not loaded yet: wait. Failed to load: say so once.
            let failed = asset_server.as_ref().is_some_and(|s| {
                matches!(
                    s.get_load_state(&source_handle),
                    Some(bevy::asset::LoadState::Failed(_))
                )
            });
            if failed {
                report(&mut commands, who, ClothError::MeshMissing);
                continue;
            }
            // A handle that never loads (a typo in a path the server still tries, a handle
            // made by hand) would leave the cloth silent forever: say so once, and wait on.
            wait(&mut still_waiting, entity, &|| {
                format!(
                    "cloth {who}: its mesh {:?} has not loaded after {} s; it is not \
                     simulated until it does",
                    source_handle.id(),
                    MESH_WAIT_WARNING.as_secs()
                )
            });
            continue;
        };
        let fingerprint = mesh_fingerprint(mesh);
        // Where the entity is at this step, even if it was spawned in this fixed step and
        // has no propagated GlobalTransform yet.
        let own = poses.get(entity).unwrap_or_default();
        let local_edge = mesh
            .attribute(Mesh::ATTRIBUTE_POSITION)
            .and_then(|a| a.as_float3())
            .map_or(0.0, |p| typical_edge(p.iter().map(|&p| Vec3::from(p))));
        if hidden(&own, local_edge) {
            // A zero scale (an entity spawned hidden, to be shown later) flattens the mesh to
            // nothing, a tiny one to less than positions resolve: wait until the entity places
            // the cloth at a size it can be built at.
            wait(&mut still_waiting, entity, &|| {
                format!(
                    "cloth {who}: its transform has a zero scale (or one too small to place \
                     it at) after {} s; it is built once the scale places it larger",
                    MESH_WAIT_WARNING.as_secs()
                )
            });
            continue;
        }
        let built = build(cloth, config, pins, mesh, &own, &poses).and_then(|mut b| {
            // Features are checked before the cloth starts, so a bad one never runs a step.
            let wanted = features(&b.sim, sc, tethers, tearing);
            b.sim.set_features(wanted).map_err(SolverError::Params)?;
            // A painted pin mask is not a colour: not drawn.
            if drops_colors(rule) {
                b.mesh.remove_attribute(Mesh::ATTRIBUTE_COLOR);
            }
            Ok(b)
        });
        match built {
            Ok(b) => {
                let mut sim = b.into_sim(meshes);
                warn_coarse(&sim, who);
                warn_loose(&mut sim, who);
                let handle = sim.mesh().clone();
                commands.entity(entity).try_insert((
                    Mesh3d(handle.clone()),
                    ClothSource {
                        source: source_handle,
                        copy: handle,
                        fingerprint,
                    },
                    sim,
                ));
            }
            Err(e) => report(&mut commands, who, e),
        }
    }
    *waiting = still_waiting;
}

/// Clears [`ClothInvalid`] when the user changes what made the cloth invalid, so it is tried
/// again; drops the simulation (to rebuild it) when the entity's mesh is replaced by another
/// one or its [`Cloth`] changes to valid settings (invalid ones are refused while it runs on).
#[expect(clippy::type_complexity, reason = "a query filter, read once")]
pub(super) fn retry_cloths(
    mut commands: Commands,
    invalid: Query<
        Entity,
        (
            With<ClothInvalid>,
            Or<(
                Changed<Cloth>,
                Changed<ClothConfig>,
                Changed<ClothPins>,
                Changed<ClothPinRule>,
                Changed<Mesh3d>,
                Changed<ClothSelfCollision>,
                Changed<ClothTethers>,
                Changed<ClothTearing>,
            )>,
        ),
    >,
    mut changed: Query<
        (
            Entity,
            Option<&Name>,
            Ref<Cloth>,
            Option<Ref<Mesh3d>>,
            &mut ClothSim,
        ),
        Or<(Changed<Cloth>, Changed<Mesh3d>)>,
    >,
) {
    for entity in &invalid {
        commands.entity(entity).remove::<(ClothInvalid, ClothSim)>();
    }
    for (entity, name, cloth, mesh, mut sim) in &mut changed {
        // Another mesh put in: build the cloth from it.
        let swapped = mesh.is_some_and(|m| m.is_changed() && m.0 != sim.mesh);
        // Mass, mass distribution, bend rest and welding are baked into the simulation: made
        // again (in place where the welding stays, `remake`). A value out of its limits is
        // refused (once) and the cloth built from the last valid one runs on.
        let rebuild = cloth.is_changed() && {
            let checked = cloth.validate();
            let ok = checked.is_ok();
            note_rejection(
                &mut commands,
                EntityName::new(entity, name),
                &mut sim.cloth_error,
                checked,
                ("Cloth settings", "the last valid ones run meanwhile"),
            );
            ok
        };
        // A change that keeps the welding goes on from the cloth's state; one that does not
        // (or a remade topology that fails) builds the cloth again from its mesh.
        let remade = rebuild && !swapped && matches!(remake(&mut sim, &cloth), Ok(true));
        if swapped || (rebuild && !remade) {
            commands.entity(entity).remove::<ClothSim>();
        }
    }
}

/// A cloth whose mesh asset changed (reloaded from disk by Bevy's file watcher, or edited
/// through `Assets::get_mut`) is built again from it: a running cloth from its source mesh (not
/// its own copy, which the plugin rewrites every frame), a refused one tried again. Runs every
/// frame, so no change is missed between fixed steps.
#[expect(clippy::type_complexity, reason = "a system's query")]
pub(super) fn rebuild_changed_meshes(
    mut commands: Commands,
    mut events: MessageReader<AssetEvent<Mesh>>,
    cloths: Query<(Entity, &Mesh3d, Option<&ClothSource>, Has<ClothInvalid>), With<Cloth>>,
    meshes: Res<Assets<Mesh>>,
) {
    let changed = modified_meshes(&mut events);
    if changed.is_empty() {
        return;
    }
    for (entity, mesh, source, invalid) in &cloths {
        let (user_mesh, built_from) = match source {
            Some(s) if s.copy == mesh.0 => (s.source.id(), Some(s.fingerprint)),
            _ => (mesh.0.id(), None),
        };
        // Only a change of contents: the engine may touch an asset without changing it.
        let differs = || {
            meshes
                .get(user_mesh)
                .is_some_and(|m| built_from != Some(mesh_fingerprint(m)))
        };
        if changed.contains(&user_mesh) && differs() {
            if invalid {
                commands.entity(entity).remove::<ClothInvalid>();
            } else {
                commands.entity(entity).remove::<ClothSim>();
            }
        }
    }
}

/// Removing [`Cloth`] stops the simulation and gives the entity its own mesh back; adding it
/// again starts afresh.
#[expect(clippy::type_complexity, reason = "an observer's query")]
pub(super) fn on_cloth_removed(
    removed: On<Remove, Cloth>,
    mut commands: Commands,
    cloths: Query<(
        Option<&ClothSource>,
        Option<&Mesh3d>,
        Option<&ClothSkin>,
        Option<&ClothUnskinned>,
    )>,
) {
    let entity = removed.entity;
    let Ok((source, mesh, skin, unskinned)) = cloths.get(entity) else {
        return;
    };
    if let (Some(source), Some(mesh)) = (source, mesh)
        && mesh.0 == source.copy
    {
        commands
            .entity(entity)
            .try_insert(Mesh3d(source.source.clone()));
    }
    // The skin the cloth took over draws the entity's own mesh again.
    if let Some(skinned) = unskinned
        .map(|u| &u.0)
        .or_else(|| skin.and_then(ClothSkin::taken))
    {
        commands.entity(entity).try_insert(skinned.clone());
    }
    commands.entity(entity).try_remove::<(
        ClothSim,
        ClothSource,
        ClothInvalid,
        ClothSkin,
        ClothUnskinned,
        SimulatedCloth,
    )>();
}

/// The optional components of a cloth entity.
type FeatureQuery = (
    Option<&'static ClothSelfCollision>,
    Option<&'static ClothTethers>,
    Option<&'static ClothTearing>,
);

/// Logs and sends a refused change once, when a cloth goes from fine to refused; `what` names
/// it (plural), `meanwhile` says what the cloth does until it is fixed.
pub(super) fn note_rejection(
    commands: &mut Commands,
    who: EntityName<'_>,
    slot: &mut Option<ClothError>,
    result: Result<(), ClothError>,
    (what, meanwhile): (&str, &str),
) {
    match result {
        Ok(()) => {
            if slot.take().is_some() {
                info!("cloth {who}: its {what} are valid again and in use");
            }
        }
        Err(e) => {
            if slot.is_none() {
                error!("cloth {who}: {e}; {meanwhile}");
                commands.write_message(ClothFailed {
                    cloth: who.entity,
                    error: e.clone(),
                });
            }
            *slot = Some(e);
        }
    }
}

/// Applies changed configs, pins and features, and moves pin targets to their anchors
/// (moving the whole cloth along when an anchor teleports). A change of the fixed timestep
/// settles every running cloth, as a change of substeps does (its steps get stiffer or
/// softer at once).
#[expect(clippy::type_complexity, reason = "a query, read once")]
pub(super) fn sync_cloths(
    mut commands: Commands,
    mut cloths: Query<
        (
            (Entity, Option<&Name>),
            &Cloth,
            &mut ClothSim,
            Ref<ClothConfig>,
            Ref<ClothPins>,
            FeatureQuery,
            Option<&ClothInertia>,
        ),
        Without<ClothInvalid>,
    >,
    poses: FixedPoses,
    fixed: Option<Res<Time<Fixed>>>,
    mut timestep: Local<Option<Duration>>,
) {
    let now = fixed.map(|f| f.timestep());
    let retimed = timestep.is_some() && now != *timestep;
    *timestep = now;
    for ((entity, name), cloth, mut sim, config, pins, (sc, tethers, tearing), inertia) in
        &mut cloths
    {
        let who = EntityName::new(entity, name);
        let cs = &mut *sim;
        if retimed && cs.steps > 0 {
            cs.sim.settle();
        }
        let own = poses.get(entity).unwrap_or_default();
        carry_unfelt_motion(&mut commands, who, cs, cloth, inertia, &poses);
        // The pose the rest shape and rest pins are placed by: none while the cloth is hidden.
        let placed = (!hidden(&own, cs.local_edge)).then_some(&own);
        // The entity's scale changed: the rest shape and the state follow it.
        let reshaped = placed.map_or(Ok(None), |own| reshape(cs, own));
        if let Ok(Some(stretch)) = &reshaped {
            cs.carry = Some(cs.carry.unwrap_or(Carry::IDENTITY).then_stretch(*stretch));
            // The pins' last targets too, so that the size change is no jump of theirs.
            let s = *stretch;
            let targets: Vec<Vec3> = cs
                .sim
                .state()
                .pins()
                .iter()
                .map(|p| s.center + s.linear * (p.target - s.center))
                .collect();
            cs.sim.state_mut().set_pin_targets(targets);
        }
        // The thickness is judged at the size the cloth settles at, not at each size a
        // growth passes through (nor while it is hidden).
        let rescaled = matches!(reshaped, Ok(Some(_)));
        if rescaled {
            cs.thickness_check_in = THICKNESS_CHECK_STEPS;
        }
        note_rejection(
            &mut commands,
            who,
            &mut cs.reshape_error,
            reshaped.map(|_| ()),
            (
                "scaled rest lengths",
                "its rest shape stays at the last scale it could be built at",
            ),
        );
        if let Some(carry) = cs.carry {
            cs.sim.carry(&carry);
        }
        // A changed (or still refused) config is applied with the features; otherwise only
        // changed features are.
        let config_due = config.is_changed() || cs.settings_error.is_some();
        let wanted = features(&cs.sim, sc, tethers, tearing);
        let params = *config;
        let params_due = config_due && params != *cs.sim.params();
        let features_due = wanted != *cs.sim.features();
        if config_due || features_due {
            let result = if params_due {
                cs.sim.set_params(params)
            } else {
                Ok(())
            }
            .and_then(|()| {
                if features_due {
                    let tightened =
                        wanted.tethers.is_some() && wanted.tethers != cs.sim.features().tethers;
                    cs.sim.set_features(wanted)?;
                    if tightened {
                        // Tethers added (or changed) on a running cloth pull it back at once.
                        cs.sim.settle();
                    }
                    cs.thickness_check_in = THICKNESS_CHECK_STEPS;
                }
                Ok(())
            })
            .map_err(|e| ClothError::Solver(SolverError::Params(e)));
            note_rejection(
                &mut commands,
                who,
                &mut cs.settings_error,
                result,
                ("settings", "it keeps its last valid settings"),
            );
        }
        if cs.thickness_check_in > 0 && placed.is_some() && !rescaled {
            cs.thickness_check_in -= 1;
            if cs.thickness_check_in == 0 {
                warn_self_collision(cs, sc, who);
            }
        }
        let list = pin_list(&pins, cs.binding.weld()).map(|mut list| {
            attach(&mut list, &mut cs.attached, cs.sim.state(), &poses);
            list
        });
        if let Ok(list) = &list {
            let missing = list.iter().find_map(|&(_, anchor)| match anchor {
                PinAnchor::Entity { entity, .. } | PinAnchor::Attached(entity)
                    if poses.get(entity).is_none() =>
                {
                    Some(entity)
                }
                _ => None,
            });
            note_rejection(
                &mut commands,
                who,
                &mut cs.anchor_error,
                missing.map_or(Ok(()), |e| Err(ClothError::PinAnchorMissing(e))),
                ("pin anchors", "its pins on it hold where they are"),
            );
        }
        cs.teleport = None;
        // A cloth with no pins has no anchor but its entity: when that jumps past the
        // teleport distance in one step (a blanket put back on its bed, a cloth respawned),
        // the whole cloth moves with it; an entity that moves less leaves the free cloth be.
        let origin = poses
            .get(entity)
            .map(|p| p.translation())
            .filter(|o| o.is_finite());
        if cs.sim.state().pins().is_empty()
            && let (Some(from), Some(to)) = (cs.origin, origin)
            && let Some(offset) = teleport_offset([(from, to)], cloth.teleport_distance)
        {
            cs.sim.state_mut().teleport(offset, []);
            // Asleep where it lay, it falls from where it is put.
            cs.sim.wake();
            cs.teleport = Some(offset);
            cs.dirty = true;
        }
        cs.origin = origin;
        if pins.is_changed() || cs.pins_error.is_some() {
            let result = list.and_then(|list| {
                repin(
                    &mut cs.sim,
                    &list,
                    &cs.rest_local,
                    placed,
                    &poses,
                    cloth.teleport_distance,
                )
            });
            if let Ok(offset) = &result {
                cs.teleport = *offset;
                warn_loose(cs, who);
            }
            note_rejection(
                &mut commands,
                who,
                &mut cs.pins_error,
                result.map(|_| ()),
                ("pins", "it keeps its last valid pins"),
            );
            cs.dirty = true;
            continue;
        }
        if let Ok(list) = list
            && let Some(offset) = follow_anchors(
                &mut cs.sim,
                &list,
                &cs.rest_local,
                placed,
                &poses,
                cloth.teleport_distance,
            )
        {
            cs.teleport = Some(offset);
            cs.dirty = true;
        }
    }
}

/// Cloths the CPU steps: valid, and not stepped elsewhere.
type CpuCloths = (Without<ClothInvalid>, Without<ClothSteppedElsewhere>);

/// Advances every valid cloth by one fixed step among the colliders and the wind.
pub(super) fn step_cloths(
    (time, workers): (Res<Time>, Option<Res<ClothWorkers>>),
    colliders: Option<Res<ClothColliders>>,
    wind: Option<Res<ClothWindField>>,
    mut cloths: Query<(Entity, Option<&Name>, &mut ClothSim), CpuCloths>,
    mut impulses: Query<&mut ClothContactImpulse>,
    mut torn: MessageWriter<ClothTorn>,
    poses: FixedPoses,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    let no_colliders = ClothColliders::default();
    let colliders = colliders.as_deref().unwrap_or(&no_colliders);
    let env = Environment {
        colliders: &colliders.colliders,
        wind: wind.as_deref().map(|w| &w.field),
        time: wind.as_deref().map_or(0.0, |w| w.time),
    };
    // Big cloths one after another with their parts in parallel, then the small ones in
    // parallel with each other (`step_many`).
    let mut list: Vec<(Entity, Option<&Name>, Mut<ClothSim>)> = cloths.iter_mut().collect();
    let reports: Vec<(StepReport, f32)> = {
        let mut items: Vec<ManyItem<'_>> = list
            .iter_mut()
            .map(|(_, _, c)| ManyItem {
                sim: &mut c.sim,
                report: StepReport::default(),
                seconds: 0.0,
            })
            .collect();
        // The task pool only without `ClothWorkers` (then serial if there is none).
        match workers.as_deref() {
            Some(workers) => step_many(&mut items, dt, &env, &workers.0),
            None => match ComputeTaskPool::try_get() {
                Some(pool) => step_many(&mut items, dt, &env, &TaskPoolParallel(pool)),
                None => step_many(&mut items, dt, &env, &Serial),
            },
        }
        items.into_iter().map(|i| (i.report, i.seconds)).collect()
    };
    for ((entity, name, mut cloth), (report, seconds)) in list.into_iter().zip(reports) {
        let cloth = &mut *cloth;
        cloth.step_seconds = seconds;
        if report.recovered {
            // The solver already reset to its rest shape where the cloth was created; place
            // the rest shape where the entity is now.
            cloth.recover(EntityName::new(entity, name), poses.get(entity));
        }
        add_impulses(colliders, cloth.sim.impulses(), &mut impulses);
        cloth.note_torn(entity, &report.torn, &mut torn);
        cloth.steps += 1;
        cloth.watch_stretch(dt, EntityName::new(entity, name));
        // A sleeping cloth did not move: its mesh stays as it is.
        cloth.dirty |= !report.asleep;
    }
}
