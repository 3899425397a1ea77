//! A free-flying camera for looking at cloth from anywhere: hold the right mouse button to
//! look around (pitch clamped short of straight up and down), WASD to move along the view,
//! Q/E down/up, shift for faster. Add [`ClothCameraPlugin`] and put [`ClothFlyCamera`] on a
//! camera; leave both out if the game has its own camera.

use bevy::input::mouse::AccumulatedMouseMotion;
use bevy::prelude::*;

/// Moves every camera that has [`ClothFlyCamera`] from the keyboard and mouse (in `Update`).
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothCameraPlugin;

impl Plugin for ClothCameraPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<ClothFlyCamera>()
            .init_resource::<ClothCameraBlock>()
            .add_systems(Update, fly_cameras);
    }
}

/// Makes an entity (a camera) fly: right mouse held looks around, WASD moves along the view,
/// Q/E move down/up, shift multiplies the speed. The view's yaw and pitch are taken from the
/// entity's rotation when the component is added.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default)]
pub struct ClothFlyCamera {
    /// Speed in metres per second.
    pub speed: f32,
    /// Speed factor while shift is held.
    pub fast: f32,
    /// Radians of turn per pixel of mouse motion.
    pub sensitivity: f32,
    /// Turn about the world's vertical axis (radians).
    pub yaw: f32,
    /// Tilt up (positive) or down (radians), kept within ±[`Self::MAX_PITCH`].
    pub pitch: f32,
    /// Whether yaw and pitch were read from the transform yet.
    pub initialized: bool,
}

impl ClothFlyCamera {
    /// Largest tilt up or down: just short of vertical, so the view never flips over.
    pub const MAX_PITCH: f32 = 1.54;
}

impl Default for ClothFlyCamera {
    fn default() -> Self {
        Self {
            speed: 3.0,
            fast: 4.0,
            sensitivity: 0.003,
            yaw: 0.0,
            pitch: 0.0,
            initialized: false,
        }
    }
}

/// Tells the fly camera to ignore input that belongs to someone else: a UI under the pointer
/// or a text field with the keyboard. [`ClothEditorPlugin`](crate::editor::ClothEditorPlugin)
/// sets it every frame; other UIs can too.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClothCameraBlock {
    /// The pointer is over a UI: a right-button press there does not start looking around.
    pub pointer: bool,
    /// A UI takes the keyboard: WASD/QE do not move the camera.
    pub keyboard: bool,
}

fn fly_cameras(
    time: Res<Time>,
    block: Option<Res<ClothCameraBlock>>,
    mut looking: Local<(bool, bool)>,
    keys: Option<Res<ButtonInput<KeyCode>>>,
    buttons: Option<Res<ButtonInput<MouseButton>>>,
    motion: Option<Res<AccumulatedMouseMotion>>,
    mut cameras: Query<(&mut Transform, &mut ClothFlyCamera)>,
) {
    let dt = time.delta_secs();
    let block = block.as_deref().copied().unwrap_or_default();
    // A look starts with a right press outside any UI and lasts while the button is held.
    let held = buttons
        .as_deref()
        .is_some_and(|b| b.pressed(MouseButton::Right));
    let (was_looking, was_held) = *looking;
    let looking_now = held
        && if was_held {
            was_looking
        } else {
            !block.pointer
        };
    *looking = (looking_now, held);
    let keys = keys.filter(|_| !block.keyboard);
    for (mut transform, mut fly) in &mut cameras {
        if !fly.initialized {
            let (yaw, pitch, _) = transform.rotation.to_euler(EulerRot::YXZ);
            fly.yaw = yaw;
            fly.pitch = pitch.clamp(-ClothFlyCamera::MAX_PITCH, ClothFlyCamera::MAX_PITCH);
            fly.initialized = true;
        }
        if looking_now && let Some(m) = motion.as_deref() {
            let d = m.delta * fly.sensitivity;
            if d.is_finite() {
                fly.yaw -= d.x;
                fly.pitch =
                    (fly.pitch - d.y).clamp(-ClothFlyCamera::MAX_PITCH, ClothFlyCamera::MAX_PITCH);
            }
        }
        transform.rotation = Quat::from_euler(EulerRot::YXZ, fly.yaw, fly.pitch, 0.0);
        let Some(keys) = keys.as_deref() else {
            continue;
        };
        let forward = transform.rotation * Vec3::NEG_Z;
        let right = transform.rotation * Vec3::X;
        let mut dir = Vec3::ZERO;
        for (key, step) in [
            (KeyCode::KeyW, forward),
            (KeyCode::KeyS, -forward),
            (KeyCode::KeyD, right),
            (KeyCode::KeyA, -right),
            (KeyCode::KeyE, Vec3::Y),
            (KeyCode::KeyQ, Vec3::NEG_Y),
        ] {
            if keys.pressed(key) {
                dir += step;
            }
        }
        let fast = if keys.any_pressed([KeyCode::ShiftLeft, KeyCode::ShiftRight]) {
            fly.fast
        } else {
            1.0
        };
        let step = dir.normalize_or_zero() * fly.speed * fast * dt;
        if step.is_finite() {
            transform.translation += step;
        }
    }
}
