//! The editor's state: the [`ClothEditor`] resource (selection, pin drafts, the add dialog,
//! files, messages) and the components and values the editor's actions take.

use std::collections::BTreeSet;

use bevy::platform::collections::HashMap;
use bevy::prelude::*;

use super::gizmo::AxisDrag;
use crate::solver::Grid;

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
    /// [`actions::update_pins`](super::actions::update_pins).
    pub drafts: HashMap<Entity, PinDraft>,
    /// Values of the "add cloth" dialog.
    pub new_cloth: NewCloth,
    /// Path typed for "add mesh collider" and "add mesh cloth" (relative to the asset folder).
    pub mesh_path: String,
    /// Path typed for "save" and "load" (a file path).
    pub scene_path: String,
    /// The last result of an action, for the status line (errors say what went wrong).
    pub status: String,
    /// An axis drag in progress.
    pub(crate) drag: Option<AxisDrag>,
    /// Mesh colliders and cloths whose file is still loading.
    pub(crate) loading: Vec<MeshLoad>,
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

/// A mesh file the editor is loading for an object it added.
#[derive(Clone, Debug)]
pub(crate) struct MeshLoad {
    /// The object.
    pub entity: Entity,
    /// The mesh.
    pub handle: Handle<Mesh>,
    /// The path asked for (with its label).
    pub path: String,
    /// Whether the object becomes a cloth once the mesh is in (else it is a mesh collider).
    pub cloth: bool,
}
