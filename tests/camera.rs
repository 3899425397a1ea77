//! `ClothCameraPlugin`: the free-flying camera, driven by hand-set input resources in a
//! headless app (what a window's input plugin would fill in).

use std::time::Duration;

use bevy::input::mouse::AccumulatedMouseMotion;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::editor::ClothCameraBlock;
use bevy_cloth::prelude::*;

const DT: f32 = 0.1;

fn app(camera: Transform) -> (App, Entity) {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, ClothCameraPlugin))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f32(
            DT,
        )))
        .init_resource::<ButtonInput<KeyCode>>()
        .init_resource::<ButtonInput<MouseButton>>()
        .init_resource::<AccumulatedMouseMotion>();
    let e = app
        .world_mut()
        .spawn((camera, ClothFlyCamera::default()))
        .id();
    // The first frame has no elapsed time; it reads the view from the transform.
    app.update();
    (app, e)
}

fn transform(app: &App, e: Entity) -> Transform {
    *app.world().get::<Transform>(e).unwrap()
}

fn hold(app: &mut App, keys: &[KeyCode], frames: usize) {
    {
        let mut input = app.world_mut().resource_mut::<ButtonInput<KeyCode>>();
        for k in keys {
            input.press(*k);
        }
    }
    for _ in 0..frames {
        app.update();
    }
    app.world_mut()
        .resource_mut::<ButtonInput<KeyCode>>()
        .release_all();
}

#[test]
fn the_view_it_starts_with_is_kept() {
    let start = Transform::from_xyz(2.0, 1.5, 4.0).looking_at(Vec3::new(0.0, 0.5, 0.0), Vec3::Y);
    let (app, e) = app(start);
    let t = transform(&app, e);
    assert!((t.forward().as_vec3() - start.forward().as_vec3()).length() < 1e-4);
    assert_eq!(t.translation, start.translation);
}

#[test]
fn wasd_moves_along_the_view_and_shift_is_faster() {
    let (mut app, e) = app(Transform::from_xyz(0.0, 1.0, 5.0));
    hold(&mut app, &[KeyCode::KeyW], 10);
    let t = transform(&app, e);
    // 10 frames of 0.1 s at 3 m/s along −z.
    assert!(
        (t.translation - Vec3::new(0.0, 1.0, 2.0)).length() < 1e-3,
        "{t:?}"
    );
    hold(&mut app, &[KeyCode::KeyD, KeyCode::ShiftLeft], 5);
    let t = transform(&app, e);
    // 5 frames at 4 × 3 m/s along +x.
    assert!(
        (t.translation - Vec3::new(6.0, 1.0, 2.0)).length() < 1e-3,
        "{t:?}"
    );
    hold(&mut app, &[KeyCode::KeyS, KeyCode::KeyA], 10);
    let t = transform(&app, e);
    // Diagonal: 3 m along (−x + z)/√2.
    let d = 3.0 / 2f32.sqrt();
    assert!(
        (t.translation - Vec3::new(6.0 - d, 1.0, 2.0 + d)).length() < 1e-3,
        "{t:?}"
    );
}

#[test]
fn q_and_e_move_down_and_up_whatever_the_view() {
    let (mut app, e) =
        app(Transform::from_xyz(0.0, 1.0, 0.0).looking_at(Vec3::new(1.0, -3.0, 0.0), Vec3::Y));
    hold(&mut app, &[KeyCode::KeyE], 10);
    assert!((transform(&app, e).translation - Vec3::new(0.0, 4.0, 0.0)).length() < 1e-3);
    hold(&mut app, &[KeyCode::KeyQ], 5);
    assert!((transform(&app, e).translation - Vec3::new(0.0, 2.5, 0.0)).length() < 1e-3);
}

#[test]
fn the_mouse_looks_only_with_the_right_button_and_never_flips_over() {
    let (mut app, e) = app(Transform::from_xyz(0.0, 1.0, 5.0));
    let forward = |app: &App| transform(app, e).forward().as_vec3();
    // Motion without the button: nothing turns.
    app.world_mut()
        .resource_mut::<AccumulatedMouseMotion>()
        .delta = Vec2::new(100.0, 0.0);
    app.update();
    assert!((forward(&app) - Vec3::NEG_Z).length() < 1e-5);
    // With it: 100 px right at 0.003 rad/px turns the view 0.3 rad to the right.
    app.world_mut()
        .resource_mut::<ButtonInput<MouseButton>>()
        .press(MouseButton::Right);
    app.update();
    let f = forward(&app);
    assert!(
        (f.x - 0.3f32.sin()).abs() < 1e-4 && (f.z + 0.3f32.cos()).abs() < 1e-4,
        "{f}"
    );
    // A huge upward motion: the pitch stops short of straight up, the view stays upright.
    app.world_mut()
        .resource_mut::<AccumulatedMouseMotion>()
        .delta = Vec2::new(0.0, -1.0e5);
    app.update();
    let fly = *app.world().get::<ClothFlyCamera>(e).unwrap();
    assert_eq!(fly.pitch, ClothFlyCamera::MAX_PITCH);
    let t = transform(&app, e);
    assert!(t.up().y > 0.0, "flipped over: {t:?}");
    // And a NaN motion changes nothing.
    app.world_mut()
        .resource_mut::<AccumulatedMouseMotion>()
        .delta = Vec2::NAN;
    app.update();
    assert_eq!(*app.world().get::<ClothFlyCamera>(e).unwrap(), fly);
    assert!(transform(&app, e).rotation.is_finite());
}

#[test]
fn a_ui_that_holds_the_pointer_or_keyboard_keeps_the_camera_still() {
    let (mut app, e) = app(Transform::from_xyz(0.0, 1.0, 5.0));
    let start = transform(&app, e);
    // Typing into a text field: WASD is text, not motion.
    app.world_mut().resource_mut::<ClothCameraBlock>().keyboard = true;
    hold(&mut app, &[KeyCode::KeyW, KeyCode::KeyQ], 5);
    assert_eq!(transform(&app, e).translation, start.translation);
    app.world_mut().resource_mut::<ClothCameraBlock>().keyboard = false;
    // A right press over the panel does not start a look, however long it is held, even
    // after the pointer leaves the panel.
    app.world_mut().resource_mut::<ClothCameraBlock>().pointer = true;
    app.world_mut()
        .resource_mut::<ButtonInput<MouseButton>>()
        .press(MouseButton::Right);
    app.world_mut()
        .resource_mut::<AccumulatedMouseMotion>()
        .delta = Vec2::new(100.0, 0.0);
    app.update();
    app.world_mut().resource_mut::<ClothCameraBlock>().pointer = false;
    app.update();
    assert!((transform(&app, e).forward().as_vec3() - Vec3::NEG_Z).length() < 1e-5);
    // Released and pressed again outside the panel: it looks.
    app.world_mut()
        .resource_mut::<ButtonInput<MouseButton>>()
        .release(MouseButton::Right);
    app.update();
    app.world_mut()
        .resource_mut::<ButtonInput<MouseButton>>()
        .press(MouseButton::Right);
    app.update();
    assert!((transform(&app, e).forward().as_vec3() - Vec3::NEG_Z).length() > 0.1);
}
