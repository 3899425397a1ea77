//! The in-app editor's pieces. [`ClothCameraPlugin`] (a free-flying camera: right mouse to
//! look, WASD/QE to move) needs nothing beyond Bevy's input and works in any app.

mod camera;

pub use camera::{ClothCameraPlugin, ClothFlyCamera};
