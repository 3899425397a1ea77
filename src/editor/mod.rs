//! The in-app editor's pieces.
//!
//! [`ClothCameraPlugin`] (a free-flying camera: right mouse to look, WASD/QE to move) needs
//! nothing beyond Bevy's input and works in any app.
//!
//! With the cargo feature `editor`, `ClothEditorPlugin` adds a panel (bevy_egui) to the
//! running game that finds every [`Cloth`](crate::cloth::Cloth),
//! [`ClothCollider`](crate::collider::ClothCollider), [`WindZone`](crate::wind::WindZone) and the
//! [`Wind`](crate::wind::Wind) resource, whoever spawned them: a card per object with a slider
//! per setting (ranges from [`crate::solver::limits`]), pin editing with an explicit "update
//! pins", buttons that add and delete objects, axis arrows to drag the selected object, live
//! step time and strain with plots, and scene files (RON). Everything the buttons do is a
//! public function on `&mut World` in [`actions`] and [`scene`], so games and tests can drive
//! the editor without a mouse.

mod camera;

#[cfg(feature = "editor")]
pub mod actions;
#[cfg(feature = "editor")]
pub mod gizmo;
#[cfg(feature = "editor")]
pub mod knobs;
#[cfg(feature = "editor")]
mod obj;
#[cfg(feature = "editor")]
mod overlay;
#[cfg(feature = "editor")]
mod panel;
#[cfg(feature = "editor")]
mod plugin;
#[cfg(feature = "editor")]
pub mod scene;
#[cfg(feature = "editor")]
mod state;
#[cfg(feature = "editor")]
pub mod stats;

pub use camera::{ClothCameraBlock, ClothCameraPlugin, ClothFlyCamera};
#[cfg(feature = "editor")]
pub use obj::{ObjError, ObjMeshLoader};
#[cfg(feature = "editor")]
pub use panel::panel_contents;
#[cfg(feature = "editor")]
pub use plugin::ClothEditorPlugin;
#[cfg(feature = "editor")]
pub use state::{ClothEditor, EditorGrid, EditorShape, NewCloth, NewShape, PinDraft, PinPreset};
