//! [`ClothEditorPlugin`], the editor's state and the components it puts on what it spawns.

use std::collections::BTreeSet;

use bevy::asset::AssetApp;
use bevy::platform::collections::HashMap;
use bevy::prelude::*;

use super::camera::ClothCameraBlock;
use super::gizmo::AxisDrag;
use super::obj::ObjMeshLoader;
use super::{actions, stats};
use crate::gpu::{ClothBackendInUse, ClothReadback};
use crate::solver::Grid;

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
/// [`ClothPlugins`]: crate::cloth::ClothPlugins
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
                actions::sync_shape_meshes,
                actions::watch_mesh_loads,
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
            app.add_systems(bevy_egui::EguiPrimaryContextPass, super::ui::editor_ui);
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

/// The editor's state: what is selected, the pin drafts, the add dialog's values, the file
/// paths and the last message. Read and change it from game code or tests; the panel shows it.
#[derive(Resource, Debug)]
pub struct ClothEditor {
    /// Whether the panel is shown.
    pub open: bool,
    /// The key that shows and hides the panel.
    pub toggle: KeyCode,
    /// The object whose axis arrows are shown (click it, or its card's "select").
    pub selected: Option<Entity>,
    /// The cloth whose pins a click toggles (its card's "edit pins"), if any.
    pub pin_edit: Option<Entity>,
    /// Pins being edited, per cloth: nothing changes on the cloth until
    /// [`actions::update_pins`].
    pub drafts: HashMap<Entity, PinDraft>,
    /// Values of the "add cloth" dialog.
    pub new_cloth: NewCloth,
    /// Path typed for "add mesh collider" (relative to the asset folder).
    pub mesh_path: String,
    /// Path typed for "save" and "load" (a file path).
    pub scene_path: String,
    /// The last result of an action, for the status line (errors say what went wrong).
    pub status: String,
    /// An axis drag in progress.
    pub(crate) drag: Option<AxisDrag>,
    /// Mesh colliders whose file is still loading, with the path asked for.
    pub(crate) loading: Vec<(Entity, Handle<Mesh>, String)>,
    /// Names given so far, for "Cloth 3", "Sphere 2", ...
    pub(crate) counter: u32,
    /// The selected object whose card was last opened for it.
    pub(crate) opened: Option<Entity>,
}

impl Default for ClothEditor {
    fn default() -> Self {
        Self {
            open: true,
            toggle: KeyCode::F2,
            selected: None,
            pin_edit: None,
            drafts: HashMap::default(),
            new_cloth: NewCloth::default(),
            mesh_path: String::new(),
            scene_path: "cloth_scene.ron".into(),
            status: String::new(),
            drag: None,
            loading: Vec::new(),
            counter: 0,
            opened: None,
        }
    }
}

/// A pin set being edited: mesh vertex indices (the first copy of each welded vertex).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PinDraft {
    /// The vertices that will be pinned when the draft is applied.
    pub vertices: BTreeSet<u32>,
}

/// Ready-made pin sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PinPreset {
    /// The boundary vertices highest in the cloth's rest shape as placed now (for a flat,
    /// level cloth: its local +z edge, the first row of a [`Grid`]).
    TopEdge,
    /// The two ends of the top edge.
    TwoCorners,
    /// No pins: the cloth falls.
    None,
}

/// What "add cloth" makes: a `columns × rows` grid of `width × height` metres, hanging from
/// its two top corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewCloth {
    /// Width in metres.
    pub width: f32,
    /// Height in metres.
    pub height: f32,
    /// Vertices along the width.
    pub columns: u32,
    /// Vertices along the height.
    pub rows: u32,
    /// Total mass in kilograms.
    pub mass: f32,
}

impl NewCloth {
    /// Smallest and largest vertex count along a side the dialog offers.
    pub const VERTICES: (u32, u32) = (2, 256);
    /// Smallest and largest side the dialog offers, metres.
    pub const SIZE: (f32, f32) = (0.05, 20.0);
}

impl Default for NewCloth {
    fn default() -> Self {
        Self {
            width: 1.0,
            height: 1.0,
            columns: 24,
            rows: 24,
            mass: 0.2,
        }
    }
}

/// On a cloth the editor made: the grid its mesh was built from (saved as a grid, not as
/// vertices).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component)]
pub struct EditorGrid {
    /// Vertices along the width.
    pub columns: u32,
    /// Vertices along the height.
    pub rows: u32,
    /// Width in metres.
    pub width: f32,
    /// Height in metres.
    pub height: f32,
}

impl EditorGrid {
    /// The solver grid.
    #[must_use]
    pub fn grid(&self) -> Grid {
        Grid::new(self.columns, self.rows, self.width, self.height)
    }
}

/// On a collider whose visible mesh the editor draws from its shape: a slider that changes
/// the radius changes the mesh too. Add it to your own colliders to get the same.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Component)]
pub struct EditorShape;

/// The shapes "add collider" offers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NewShape {
    /// A ball.
    Sphere,
    /// A box.
    Box,
    /// A capsule.
    Capsule,
    /// A floor.
    Plane,
}
