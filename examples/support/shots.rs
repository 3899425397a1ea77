//! Offscreen pictures: builds a scene in a windowless app with Bevy's renderer (llvmpipe works),
//! simulates it, then renders each camera into an image and returns (and optionally saves)
//! the pixels. Used by `examples/pictures.rs` (the README's pictures) and `tests/pictures.rs`.

#![allow(dead_code, reason = "the example and the test use different parts")]

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bevy::app::PluginsState;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::DebandDither;
use bevy::image::Image;
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::render::render_resource::TextureFormat;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured, save_to_disk};
use bevy::time::TimeUpdateStrategy;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use bevy_cloth::prelude::*;

/// One picture: a camera and the file name it is saved under.
#[derive(Clone, Debug)]
pub struct Shot {
    /// File stem (`<name>.png`).
    pub name: &'static str,
    /// Camera position.
    pub eye: Vec3,
    /// Point looked at.
    pub target: Vec3,
}

/// The pictures' background (a neutral grey, so colour tests can tell cloth from sky).
pub const CLEAR: Color = Color::srgb(0.62, 0.64, 0.66);

/// A captured picture, RGBA8 sRGB, row-major, `width × height`.
pub struct Picture {
    /// [`Shot::name`].
    pub name: &'static str,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height × 4` bytes.
    pub rgba: Vec<u8>,
}

impl Picture {
    /// Pixels as `[r, g, b]` in `0..=1` (sRGB-encoded values).
    pub fn pixels(&self) -> impl Iterator<Item = [f32; 3]> + '_ {
        self.rgba
            .chunks_exact(4)
            .map(|p| [p[0], p[1], p[2]].map(|c| f32::from(c) / 255.0))
    }
}

/// Builds the app with `scene` (which adds its Startup systems and resources), runs
/// `frames` frames of 1/60 s with the cameras off, then renders every shot at `size` and
/// returns the pictures, saving them as PNG into `out` when given. Panics if a picture does
/// not arrive (a renderer that never draws).
pub fn render(
    size: UVec2,
    frames: u32,
    scene: impl FnOnce(&mut App),
    shots: &[Shot],
    out: Option<&Path>,
) -> Vec<Picture> {
    let (mut app, cameras, targets) = build(size, scene, shots);
    warm_up(&mut app, &cameras, frames);
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).expect("create the output folder");
    }
    let captured: Arc<Mutex<Vec<Option<Image>>>> = Arc::new(Mutex::new(vec![None; shots.len()]));
    for (k, (image, shot)) in targets.iter().zip(shots).enumerate() {
        let slot = captured.clone();
        let mut screenshot = app.world_mut().spawn(Screenshot::image(image.clone()));
        screenshot.observe(move |shot: On<ScreenshotCaptured>| {
            slot.lock().expect("lock")[k] = Some(shot.image.clone());
        });
        if let Some(dir) = out {
            screenshot.observe(save_to_disk(dir.join(format!("{}.png", shot.name))));
        }
    }
    for _ in 0..120 {
        app.update();
        if captured.lock().expect("lock").iter().all(Option::is_some) {
            break;
        }
    }
    let images = std::mem::take(&mut *captured.lock().expect("lock"));
    shots
        .iter()
        .zip(images)
        .map(|(shot, image)| {
            let image = image.unwrap_or_else(|| panic!("picture {} never arrived", shot.name));
            if let Some(dir) = out {
                let path = dir.join(format!("{}.png", shot.name));
                assert!(path.exists(), "{} was not saved", path.display());
            }
            Picture::new(shot.name, image)
        })
        .collect()
}

impl Picture {
    fn new(name: &'static str, image: Image) -> Self {
        Picture {
            name,
            width: image.width(),
            height: image.height(),
            rgba: image.data.expect("picture without data"),
        }
    }
}

/// Runs `frames` frames with the cameras off, then turns them on and gives pipelines, shadow
/// maps and the mesh uploads a few frames to settle.
fn warm_up(app: &mut App, cameras: &[Entity], frames: u32) {
    for _ in 0..frames {
        app.update();
    }
    for &c in cameras {
        app.world_mut()
            .get_mut::<Camera>(c)
            .expect("camera")
            .is_active = true;
    }
    for _ in 0..4 {
        app.update();
    }
}

/// The windowless app with `scene` and one inactive camera per shot rendering into its own
/// image: `(app, cameras, images)`.
fn build(
    size: UVec2,
    scene: impl FnOnce(&mut App),
    shots: &[Shot],
) -> (App, Vec<Entity>, Vec<Handle<Image>>) {
    let mut app = App::new();
    app.add_plugins(
        DefaultPlugins
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: ExitCondition::DontExit,
                close_when_requested: false,
                ..default()
            })
            .set(RenderPlugin {
                synchronous_pipeline_compilation: true,
                ..default()
            })
            .disable::<WinitPlugin>(),
    )
    .add_plugins((ClothPlugins::default(), VelvetPlugin))
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
        1.0 / 60.0,
    )))
    .insert_resource(Time::<Fixed>::from_hz(60.0))
    .insert_resource(ClearColor(CLEAR));
    scene(&mut app);
    while app.plugins_state() == PluginsState::Adding {
        bevy::tasks::tick_global_task_pools_on_main_thread();
    }
    app.finish();
    app.cleanup();

    let mut cameras = Vec::new();
    let mut targets = Vec::new();
    for shot in shots {
        let image = app
            .world_mut()
            .resource_mut::<Assets<Image>>()
            .add(Image::new_target_texture(
                size.x,
                size.y,
                TextureFormat::Rgba8UnormSrgb,
                None,
            ));
        let camera = app
            .world_mut()
            .spawn((
                Camera3d::default(),
                Camera {
                    is_active: false,
                    ..default()
                },
                RenderTarget::from(image.clone()),
                DebandDither::Disabled,
                Transform::from_translation(shot.eye).looking_at(shot.target, Vec3::Y),
            ))
            .id();
        cameras.push(camera);
        targets.push(image);
    }
    (app, cameras, targets)
}

/// Renders `count` pictures of `shot`, one every `every` simulated frames of 1/60 s, after
/// `frames` frames: the frames of an animation. Panics if a picture does not arrive.
pub fn render_animation(
    size: UVec2,
    frames: u32,
    scene: impl FnOnce(&mut App),
    shot: &Shot,
    count: usize,
    every: u32,
) -> Vec<Picture> {
    let (mut app, cameras, targets) = build(size, scene, core::slice::from_ref(shot));
    warm_up(&mut app, &cameras, frames);
    let captured: Arc<Mutex<Vec<Option<Image>>>> = Arc::new(Mutex::new(vec![None; count]));
    for k in 0..count {
        let slot = captured.clone();
        app.world_mut()
            .spawn(Screenshot::image(targets[0].clone()))
            .observe(move |shot: On<ScreenshotCaptured>| {
                slot.lock().expect("lock")[k] = Some(shot.image.clone());
            });
        for _ in 0..every.max(1) {
            app.update();
        }
    }
    for _ in 0..120 {
        if captured.lock().expect("lock").iter().all(Option::is_some) {
            break;
        }
        app.update();
    }
    let images = std::mem::take(&mut *captured.lock().expect("lock"));
    images
        .into_iter()
        .enumerate()
        .map(|(k, image)| {
            let image = image.unwrap_or_else(|| panic!("frame {k} of {} never arrived", shot.name));
            Picture::new(shot.name, image)
        })
        .collect()
}

/// The flag's front (velvet) and back (lining) colours in the pictures.
pub const FLAG_FRONT: Color = Color::srgb(0.08, 0.16, 0.55);
/// See [`FLAG_FRONT`].
pub const FLAG_BACK: Color = Color::srgb(0.85, 0.62, 0.2);
/// The draped cloth's colour.
pub const DRAPE: Color = Color::srgb(0.45, 0.04, 0.1);
/// Where the drape stands (far enough from the flag to stay out of its pictures).
pub const DRAPE_AT: Vec3 = Vec3::new(30.0, 0.0, 0.0);
/// Where two velvet patches lie on the ground, the left one with a normal map.
pub const PATCHES_AT: Vec3 = Vec3::new(-30.0, 0.0, 0.0);
/// The patches' colour.
pub const PATCH: Color = Color::srgb(0.15, 0.45, 0.12);

/// Two 1 m velvet cloths lying on the ground side by side, seen from above: the left one
/// with a striped normal map (shaded through the tangents the solver writes), the right one
/// without. Rendered in [`velvet_scene`] but not one of the README pictures.
pub fn normal_map_shot() -> Shot {
    Shot {
        name: "velvet_normal_map",
        eye: PATCHES_AT + Vec3::new(0.0, 1.8, 1.6),
        target: PATCHES_AT,
    }
}

/// Where a 3 m velvet cloth lies under a spot light (left end) and a point light (right end).
pub const LAMPS_AT: Vec3 = Vec3::new(-60.0, 0.0, 0.0);

/// The lamp-lit cloth from above: its two ends lit by the spot and the point light, its
/// middle by the sun alone. Rendered in [`velvet_scene`] but not one of the README pictures.
pub fn lamps_shot() -> Shot {
    Shot {
        name: "velvet_lamps",
        eye: LAMPS_AT + Vec3::new(0.0, 2.4, 2.2),
        target: LAMPS_AT,
    }
}

/// A tangent-space normal map of 8 stripes whose normals lean alternately ±0.6 rad along the
/// texture's u axis (linear RGBA8, `n·0.5 + 0.5`).
fn striped_normal_map() -> Image {
    use bevy::asset::RenderAssetUsages;
    use bevy::render::render_resource::{Extent3d, TextureDimension};
    let size = 64u32;
    let mut data = Vec::with_capacity((size * size * 4) as usize);
    for _y in 0..size {
        for x in 0..size {
            let lean = if (x / 4) % 2 == 0 { 0.6f32 } else { -0.6 };
            let n = Vec3::new(lean.sin(), 0.0, lean.cos());
            let e = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
            data.extend_from_slice(&[e(n.x), e(n.y), e(n.z), 255]);
        }
    }
    Image::new(
        Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8Unorm,
        RenderAssetUsages::RENDER_WORLD,
    )
}

/// The flag in wind (front blue velvet, gold lining behind, sun in front) and a velvet cloth
/// dropped over a ball, on a ground plane.
pub fn velvet_scene(app: &mut App) {
    app.add_systems(Startup, spawn_velvet_scene);
}

/// The three README pictures of [`velvet_scene`].
pub fn velvet_shots() -> Vec<Shot> {
    vec![
        Shot {
            name: "velvet_front",
            eye: Vec3::new(-0.6, 2.2, 5.4),
            target: Vec3::new(1.4, 2.3, 0.0),
        },
        Shot {
            name: "velvet_back",
            eye: Vec3::new(-0.6, 2.2, -5.4),
            target: Vec3::new(1.4, 2.3, 0.0),
        },
        Shot {
            name: "velvet_drape",
            eye: DRAPE_AT + Vec3::new(2.0, 2.3, 3.0),
            target: DRAPE_AT + Vec3::new(0.0, 0.7, 0.0),
        },
    ]
}

fn spawn_velvet_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut standard: ResMut<Assets<StandardMaterial>>,
    mut velvet: ResMut<Assets<VelvetMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    commands.spawn((
        DirectionalLight {
            illuminance: 9_000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(3.0, 7.0, 6.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    commands.insert_resource(GlobalAmbientLight {
        brightness: 350.0,
        ..default()
    });
    let ground = standard.add(Color::srgb(0.36, 0.38, 0.35));
    for at in [Vec3::ZERO, DRAPE_AT, PATCHES_AT, LAMPS_AT] {
        commands.spawn((
            Mesh3d(meshes.add(Plane3d::default().mesh().size(14.0, 14.0))),
            MeshMaterial3d(ground.clone()),
            Transform::from_translation(at),
        ));
    }

    // The flag: 3 m × 2 m, hoist pinned to a pole, its front (the grid's +Y side) turned to
    // +Z, towards the sun; wind only around the flag, so the drape hangs still.
    commands.spawn((
        WindZone {
            wind: WindParams {
                velocity: Vec3::new(7.0, 0.0, -1.4),
                seed: 3,
                ..default()
            },
            half_extents: Vec3::new(6.0, 5.0, 6.0),
            falloff: 2.0,
        },
        Transform::from_xyz(1.5, 2.5, 0.0),
    ));
    let grid = Grid::new(48, 32, 3.0, 2.0);
    commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        MeshMaterial3d(velvet.add(velvet_material(
            FLAG_FRONT,
            VelvetExtension {
                back_color: Some(FLAG_BACK),
                alpha: 0.4,
                ..default()
            },
        ))),
        Transform::from_xyz(grid.width / 2.0, 3.4, 0.0)
            .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2)),
        Cloth {
            mass: 0.4,
            ..default()
        },
        // The default fabric, air and solver, as in the flag example.
        ClothConfig {
            substeps: 12,
            ..default()
        },
        ClothPins::rest((0..grid.rows).map(|j| grid.index(0, j))),
    ));
    commands.spawn((
        Mesh3d(meshes.add(Cylinder::new(0.04, 4.6))),
        MeshMaterial3d(standard.add(Color::srgb(0.7, 0.7, 0.72))),
        Transform::from_xyz(-0.04, 2.3, 0.0),
    ));

    // The drape: a 2.2 m square dropped over a ball held 1 m up (a tablecloth over a lamp).
    let ball = 0.55;
    let centre = DRAPE_AT + Vec3::Y * 1.0;
    commands.spawn((
        ClothCollider::sphere(ball).with_thickness(0.012),
        Mesh3d(meshes.add(Sphere::new(ball).mesh().uv(48, 24))),
        MeshMaterial3d(standard.add(Color::srgb(0.75, 0.74, 0.7))),
        Transform::from_translation(centre),
    ));
    commands.spawn((
        ClothCollider::plane().with_thickness(0.01),
        Transform::from_translation(DRAPE_AT),
    ));
    let cloth = Grid::new(56, 56, 2.2, 2.2);
    commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&cloth))),
        MeshMaterial3d(velvet.add(velvet_material(
            DRAPE,
            VelvetExtension {
                alpha: 0.35,
                ..default()
            },
        ))),
        // Upside down: the back side faces the sun, so its shadow on the ground comes from
        // back faces (the two-sided shadow pass; tests/pictures.rs checks the shadow is there).
        Transform::from_translation(centre + Vec3::new(0.02, ball + 0.1, -0.01)).with_rotation(
            Quat::from_rotation_y(0.4) * Quat::from_rotation_x(core::f32::consts::PI),
        ),
        Cloth {
            mass: 0.5,
            ..default()
        },
        ClothConfig {
            substeps: 12,
            // Softer in bending than the default, so it falls into folds around the ball.
            solver: Solver::Xpbd {
                stretch: 0.0,
                shear: 0.1,
                bending: 200.0,
            },
            ..default()
        },
    ));

    // Two patches on the ground (the plane collider above holds them), the left one
    // normal-mapped.
    let normal_map = images.add(striped_normal_map());
    let patch = Grid::new(24, 24, 1.0, 1.0);
    for (dx, map) in [(-0.6, Some(normal_map)), (0.6, None)] {
        commands.spawn((
            Mesh3d(meshes.add(grid_mesh(&patch))),
            MeshMaterial3d(velvet.add(velvet_material_from(
                StandardMaterial {
                    base_color: PATCH,
                    normal_map_texture: map,
                    ..default()
                },
                VelvetExtension::default(),
            ))),
            Transform::from_translation(PATCHES_AT + Vec3::new(dx, 0.05, 0.0)),
            Cloth::default(),
        ));
    }

    // A 3 m × 1 m cloth on the ground under a spot light (left end) and a point light
    // (right end), both casting shadows: the clustered-light path of the velvet shader.
    let strip = Grid::new(48, 16, 3.0, 1.0);
    commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&strip))),
        MeshMaterial3d(velvet.add(velvet_material(PATCH, VelvetExtension::default()))),
        Transform::from_translation(LAMPS_AT + Vec3::Y * 0.05),
        Cloth::default(),
    ));
    commands.spawn((
        SpotLight {
            intensity: 200_000.0,
            range: 6.0,
            outer_angle: 0.5,
            inner_angle: 0.3,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_translation(LAMPS_AT + Vec3::new(-1.2, 0.6, 0.0))
            .looking_at(LAMPS_AT + Vec3::new(-1.2, 0.0, 0.0), Vec3::Z),
    ));
    commands.spawn((
        PointLight {
            intensity: 50_000.0,
            range: 6.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_translation(LAMPS_AT + Vec3::new(1.2, 0.3, 0.0)),
    ));
}
