//! The velvet material gallery: five presets on balls, and a banner in a breeze wearing the
//! material the sliders edit (α, k_amp, F0, sheen strength, back colour on/off). Drag a slider
//! with the left mouse button.
//!
//! ```text
//! cargo run --release --example velvet
//! ```
//! Also `--frames N --screenshot FILE.png`, and `--headless` (simulates the banner only).

#[path = "support/mod.rs"]
mod support;

use core::ops::RangeInclusive;

use bevy::prelude::*;
use bevy::ui::RelativeCursorPosition;
use bevy_cloth::prelude::*;
use bevy_cloth::render::brdf::{ALPHA_RANGE, F0_RANGE, K_AMP_RANGE};
use support::Args;

/// The material the sliders edit.
#[derive(Resource)]
struct Live(Handle<VelvetMaterial>);

#[derive(Clone, Copy, Debug, PartialEq)]
enum Param {
    Alpha,
    KAmp,
    F0,
    Sheen,
    Back,
}

impl Param {
    const ALL: [Param; 5] = [
        Param::Alpha,
        Param::KAmp,
        Param::F0,
        Param::Sheen,
        Param::Back,
    ];

    fn range(self) -> RangeInclusive<f32> {
        match self {
            Param::Alpha => ALPHA_RANGE,
            Param::KAmp => K_AMP_RANGE,
            Param::F0 => F0_RANGE,
            Param::Sheen | Param::Back => 0.0..=1.0,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Param::Alpha => "alpha",
            Param::KAmp => "k_amp",
            Param::F0 => "F0",
            Param::Sheen => "sheen",
            Param::Back => "back colour",
        }
    }

    fn get(self, v: &VelvetExtension) -> f32 {
        match self {
            Param::Alpha => v.alpha,
            Param::KAmp => v.k_amp,
            Param::F0 => v.f0,
            Param::Sheen => v.sheen_color.to_linear().red,
            Param::Back => f32::from(u8::from(v.back_color.is_some())),
        }
    }

    fn set(self, v: &mut VelvetExtension, x: f32) {
        match self {
            Param::Alpha => v.alpha = x,
            Param::KAmp => v.k_amp = x,
            Param::F0 => v.f0 = x,
            Param::Sheen => v.sheen_color = Color::linear_rgb(x, x, x),
            Param::Back => v.back_color = (x >= 0.5).then_some(Color::srgb(0.85, 0.7, 0.3)),
        }
    }
}

#[derive(Component)]
struct Slider(Param);

#[derive(Component)]
struct SliderFill(Param);

#[derive(Component)]
struct SliderText(Param);

fn presets() -> [(&'static str, Color, VelvetExtension); 5] {
    [
        (
            "crushed red",
            Color::srgb(0.4, 0.02, 0.06),
            VelvetExtension::default(),
        ),
        (
            "midnight, thin rim",
            Color::srgb(0.03, 0.05, 0.2),
            VelvetExtension {
                alpha: 0.15,
                k_amp: 8.0,
                ..default()
            },
        ),
        (
            "moss, broad sheen",
            Color::srgb(0.08, 0.22, 0.05),
            VelvetExtension {
                alpha: 0.9,
                k_amp: 3.0,
                ..default()
            },
        ),
        (
            "gold silk-ish",
            Color::srgb(0.5, 0.32, 0.06),
            VelvetExtension {
                alpha: 0.3,
                f0: 0.3,
                sheen_color: Color::srgb(1.0, 0.85, 0.5),
                ..default()
            },
        ),
        (
            "no peak (k_amp 0)",
            Color::srgb(0.35, 0.35, 0.38),
            VelvetExtension {
                k_amp: 0.0,
                ..default()
            },
        ),
    ]
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    standard: Option<ResMut<Assets<StandardMaterial>>>,
    velvet: Option<ResMut<Assets<VelvetMaterial>>>,
) {
    // The banner: 2 m × 3 m hanging from its top edge. Turned 90° about X, the grid's front
    // (+Y) faces the camera and its last row is on top.
    let grid = Grid::new(32, 48, 2.0, 3.0);
    let mut banner = commands.spawn((
        Mesh3d(meshes.add(grid_mesh(&grid))),
        Transform::from_xyz(0.0, 3.0, 0.0)
            .with_rotation(Quat::from_rotation_x(core::f32::consts::FRAC_PI_2)),
        Cloth {
            mass: 0.6,
            ..default()
        },
        ClothConfig {
            solver: Solver::Xpbd {
                stretch: 0.0,
                shear: 1e-4,
                bending: 0.5,
            },
            ..default()
        },
        ClothPins::rest((0..grid.columns).map(|i| grid.index(i, grid.rows - 1))),
    ));
    let (Some(mut standard), Some(mut velvet)) = (standard, velvet) else {
        return;
    };
    let live = velvet.add(velvet_material(
        Color::srgb(0.3, 0.03, 0.12),
        VelvetExtension {
            back_color: Some(Color::srgb(0.85, 0.7, 0.3)),
            ..default()
        },
    ));
    banner.insert(MeshMaterial3d(live.clone()));
    commands.insert_resource(Live(live));

    let ball = meshes.add(Sphere::new(0.45).mesh().uv(64, 32));
    for (k, (name, color, ext)) in presets().into_iter().enumerate() {
        let x = (k as f32 - 2.0) * 1.2;
        commands.spawn((
            Mesh3d(ball.clone()),
            MeshMaterial3d(velvet.add(velvet_material(color, ext))),
            Transform::from_xyz(x, 0.45, 2.2),
            Name::new(name),
        ));
    }
    support::stage(
        &mut commands,
        &mut meshes,
        &mut standard,
        Vec3::new(0.0, 2.4, 8.0),
        Vec3::new(0.0, 2.0, 0.0),
    );
    commands.insert_resource(Wind(WindParams {
        velocity: Vec3::new(1.0, 0.0, 0.4),
        gust_amplitude: 0.5,
        gust_frequency: 0.7,
        turbulence: 0.4,
        ..default()
    }));

    // The sliders, top left.
    commands
        .spawn((
            Node {
                position_type: PositionType::Absolute,
                left: px(12),
                top: px(12),
                flex_direction: FlexDirection::Column,
                row_gap: px(6),
                padding: UiRect::all(px(8)),
                ..default()
            },
            BackgroundColor(Color::srgba(0.0, 0.0, 0.0, 0.45)),
        ))
        .with_children(|panel| {
            for p in Param::ALL {
                panel.spawn((
                    Text::new(p.name()),
                    TextFont::from_font_size(14.0),
                    SliderText(p),
                ));
                panel
                    .spawn((
                        Node {
                            width: px(220),
                            height: px(14),
                            ..default()
                        },
                        BackgroundColor(Color::srgb(0.2, 0.2, 0.22)),
                        Interaction::default(),
                        RelativeCursorPosition::default(),
                        Slider(p),
                    ))
                    .with_child((
                        Node {
                            width: percent(0),
                            height: percent(100),
                            ..default()
                        },
                        BackgroundColor(Color::srgb(0.85, 0.75, 0.45)),
                        SliderFill(p),
                    ));
            }
        });
}

/// Dragging a slider sets its parameter on the live material.
fn drag_sliders(
    sliders: Query<(&Interaction, &RelativeCursorPosition, &Slider)>,
    live: Option<Res<Live>>,
    mut materials: Option<ResMut<Assets<VelvetMaterial>>>,
) {
    let (Some(live), Some(materials)) = (live, materials.as_deref_mut()) else {
        return;
    };
    for (interaction, cursor, slider) in &sliders {
        if *interaction != Interaction::Pressed {
            continue;
        }
        let Some(at) = cursor.normalized else {
            continue;
        };
        let t = (at.x + 0.5).clamp(0.0, 1.0);
        let r = slider.0.range();
        let value = r.start() + t * (r.end() - r.start());
        // Only touch the asset when the setting moves: each mutable access re-uploads it.
        let Some(current) = materials.get(&live.0).map(|m| m.extension.clone()) else {
            continue;
        };
        let mut next = current.clone();
        slider.0.set(&mut next, value);
        if slider.0.get(&next) != slider.0.get(&current)
            && let Some(mut m) = materials.get_mut(&live.0)
        {
            m.extension = next;
        }
    }
}

/// Slider fills and labels follow the live material, when it changes.
fn show_values(
    live: Option<Res<Live>>,
    materials: Option<Res<Assets<VelvetMaterial>>>,
    mut shown: Local<Option<[f32; 5]>>,
    mut fills: Query<(&mut Node, &SliderFill)>,
    mut texts: Query<(&mut Text, &SliderText)>,
) {
    let (Some(live), Some(materials)) = (live, materials) else {
        return;
    };
    let Some(m) = materials.get(&live.0) else {
        return;
    };
    let values = Param::ALL.map(|p| p.get(&m.extension));
    if *shown == Some(values) {
        return;
    }
    *shown = Some(values);
    for (mut node, fill) in &mut fills {
        let r = fill.0.range();
        let t = (fill.0.get(&m.extension) - r.start()) / (r.end() - r.start());
        node.width = percent(100.0 * t.clamp(0.0, 1.0));
    }
    for (mut text, label) in &mut texts {
        text.0 = format!("{}: {:.2}", label.0.name(), label.0.get(&m.extension));
    }
}

fn report(world: &mut World) -> support::Json {
    support::cloth_report(world).str("example", "velvet")
}

fn main() {
    let args = Args::parse(include_str!("velvet.rs"));
    let mut app = support::app(&args, "bevy_cloth: velvet gallery", 1.0 / 60.0);
    app.add_systems(Startup, setup)
        .add_systems(Update, (drag_sliders, show_values).chain());
    support::run(app, &args, report);
}
