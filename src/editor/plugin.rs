//! [`ClothEditorPlugin`] and the systems it adds: the panel's pass, the toggle key, GPU
//! read-back while the panel is open, shape meshes kept in step, mesh files watched.

use bevy::asset::AssetApp;
use bevy::prelude::*;
use bevy_egui::egui;
use bevy_egui::{EguiContext, PrimaryEguiContext};

use super::actions::{make_mesh_cloth, say, shape_mesh};
use super::camera::ClothCameraBlock;
use super::obj::ObjMeshLoader;
use super::overlay::overlay_and_pointer;
use super::panel::panel_contents;
use super::state::{ClothEditor, EditorGrid, EditorShape, MeshLoad};
use super::stats;
use crate::collider::ClothCollider;
use crate::gpu::{ClothBackendInUse, ClothReadback};

/// The cloth editor: a panel beside the game with a card per cloth, collider and wind, pin
/// editing, add/delete buttons, axis arrows to move the selected object, live step time and
/// strain, and scene files. Add it after `DefaultPlugins` and [`ClothPlugins`]; it is never
/// part of the default plugin group.
///
/// ```no_run
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// App::new()
///     .add_plugins((DefaultPlugins, ClothPlugins::default()))
///     .add_plugins(ClothEditorPlugin::default()) // F2 shows and hides it
///     .run();
/// ```
///
/// The panel needs a renderer and a camera: bevy_egui draws it on the first camera spawned,
/// and the editor picks and draws arrows through that camera (to choose another, set
/// `EguiGlobalSettings::auto_create_primary_context` to `false` and put `PrimaryEguiContext`
/// on it).
/// In an app without a renderer (a headless test) the plugin still adds its state, the
/// OBJ loader and the live numbers, so [`actions`] and
/// [`scene`](super::scene) work the same way there.
///
/// [`ClothPlugins`]: crate::ClothPlugins
/// [`actions`]: super::actions
#[derive(Clone, Copy, Debug)]
pub struct ClothEditorPlugin {
    /// The key that shows and hides the panel (F2 by default).
    pub toggle: KeyCode,
    /// Whether the panel is shown at start.
    pub open: bool,
}

impl Default for ClothEditorPlugin {
    fn default() -> Self {
        Self {
            toggle: KeyCode::F2,
            open: true,
        }
    }
}

impl Plugin for ClothEditorPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(ClothEditor {
            open: self.open,
            toggle: self.toggle,
            ..default()
        })
        .init_resource::<ClothCameraBlock>()
        .init_resource::<stats::ClothStats>()
        .register_type::<EditorGrid>()
        .register_type::<EditorShape>()
        .add_systems(
            Update,
            (
                toggle_panel,
                read_back_gpu_cloths,
                sync_shape_meshes,
                watch_mesh_loads,
                stats::record,
            ),
        );
        if app.world().contains_resource::<AssetServer>() {
            app.register_asset_loader(ObjMeshLoader);
        }
        // The panel itself needs bevy_egui's renderer, which needs Bevy's.
        if app
            .world()
            .contains_resource::<Assets<bevy::shader::Shader>>()
        {
            if !app.is_plugin_added::<bevy_egui::EguiPlugin>() {
                app.add_plugins(bevy_egui::EguiPlugin::default());
            }
            app.add_systems(bevy_egui::EguiPrimaryContextPass, editor_ui);
        } else {
            info!(
                "ClothEditorPlugin: no renderer (none in this app, or the plugin was added \
                 before DefaultPlugins), so no panel; actions and scene files work"
            );
        }
    }
}

/// Marks a [`ClothReadback`] the editor added (and removes again when the panel closes).
#[derive(Component)]
struct EditorReadback;

/// While the panel is open, GPU cloths read their state back, so that picking, pins and the
/// live numbers see where they are.
fn read_back_gpu_cloths(
    mut commands: Commands,
    editor: Res<ClothEditor>,
    gpu: Query<(Entity, &ClothBackendInUse), Without<ClothReadback>>,
    added: Query<Entity, With<EditorReadback>>,
) {
    if editor.open {
        for (e, used) in &gpu {
            if used.gpu {
                commands.entity(e).insert((ClothReadback, EditorReadback));
            }
        }
    } else {
        for e in &added {
            commands
                .entity(e)
                .remove::<(ClothReadback, EditorReadback)>();
        }
    }
}

fn toggle_panel(
    keys: Option<Res<ButtonInput<KeyCode>>>,
    block: Res<ClothCameraBlock>,
    mut editor: ResMut<ClothEditor>,
) {
    // While a text field has the keyboard, the key is typed, not obeyed.
    if keys.is_some_and(|k| k.just_pressed(editor.toggle)) && !block.keyboard {
        editor.open = !editor.open;
    }
}

/// The panel and everything drawn over the scene, once per frame (bevy_egui's pass).
fn editor_ui(world: &mut World) {
    let Some(ctx) = world
        .query_filtered::<&mut EguiContext, With<PrimaryEguiContext>>()
        .iter_mut(world)
        .next()
        .map(|mut c| c.get_mut().clone())
    else {
        return;
    };
    if !world.resource::<ClothEditor>().open {
        *world.resource_mut::<ClothCameraBlock>() = ClothCameraBlock::default();
        return;
    }
    let mut root = egui::Ui::new(
        ctx.clone(),
        "bevy_cloth_editor_root".into(),
        egui::UiBuilder::new()
            .layer_id(egui::LayerId::background())
            .max_rect(ctx.viewport_rect()),
    );
    let panel = egui::Panel::left("bevy_cloth_editor")
        .resizable(true)
        .default_size(360.0)
        .show(&mut root, |ui| {
            egui::ScrollArea::vertical()
                .auto_shrink([false; 2])
                .show(ui, |ui| panel_contents(ui, world));
        });
    let panel_rect = panel.response.rect;
    overlay_and_pointer(world, &ctx, panel_rect);
}

/// Colliders whose shape changed and whose mesh the editor draws.
type ChangedShapes = (With<EditorShape>, Changed<ClothCollider>);

/// Keeps the visible mesh of [`EditorShape`] colliders in step with their shape.
fn sync_shape_meshes(
    changed: Query<(&ClothCollider, &Mesh3d), ChangedShapes>,
    meshes: Option<ResMut<Assets<Mesh>>>,
) {
    let Some(mut meshes) = meshes else {
        return;
    };
    for (collider, mesh3d) in &changed {
        if let Some(m) = shape_mesh(&collider.shape) {
            // A mesh handle the editor made: replace its contents in place.
            let _ = meshes.insert(mesh3d.id(), m);
        }
    }
}

/// Reports mesh files that failed to load (and removes their objects), and makes the objects
/// of loaded cloth files cloth.
fn watch_mesh_loads(world: &mut World) {
    let Some(loading) = world
        .get_resource::<ClothEditor>()
        .map(|e| e.loading.clone())
        .filter(|l| !l.is_empty())
    else {
        return;
    };
    let Some(server) = world.get_resource::<AssetServer>().cloned() else {
        return;
    };
    let mut still = Vec::new();
    for load in loading {
        let MeshLoad {
            entity,
            ref handle,
            ref path,
            cloth,
        } = load;
        match server.load_state(handle.id()) {
            bevy::asset::LoadState::Failed(e) => {
                if world.get_entity(entity).is_ok() {
                    world.entity_mut(entity).despawn();
                }
                say(world, format!("could not load {path}: {e}"));
            }
            bevy::asset::LoadState::Loaded => {
                let mesh = world.resource::<Assets<Mesh>>().get(handle).cloned();
                match mesh {
                    Some(mesh) if cloth => {
                        make_mesh_cloth(world, entity, &mesh);
                        say(
                            world,
                            format!("loaded {path}: a cloth hung by its top edge, tethered"),
                        );
                    }
                    _ => say(world, format!("loaded {path}")),
                }
            }
            _ => still.push(load),
        }
    }
    world.resource_mut::<ClothEditor>().loading = still;
}
