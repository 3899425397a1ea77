//! What the editor draws over the scene (pin markers, axis arrows, wind zones) and what the
//! pointer does there: pick, toggle a pin, drag an arrow. Clicks call [`actions`].

use bevy::prelude::*;
use bevy_egui::PrimaryEguiContext;
use bevy_egui::egui::{self, Color32, Pos2, Stroke};

use super::actions;
use super::camera::ClothCameraBlock;
use super::gizmo::{ARROW_SCALE, AXES, AxisDrag, move_to};
use super::state::ClothEditor;
use crate::cloth::ClothSim;
use crate::wind::WindZone;

/// Pointer distance (points) within which an arrow is grabbed.
const GRAB_RADIUS: f32 = 8.0;

const AXIS_COLOURS: [Color32; 3] = [
    Color32::from_rgb(230, 70, 60),
    Color32::from_rgb(90, 200, 80),
    Color32::from_rgb(70, 120, 240),
];

/// Whether the pointer belongs to the UI, and the camera's view of the world.
pub(super) fn overlay_and_pointer(world: &mut World, ctx: &egui::Context, panel_rect: egui::Rect) {
    let (hover, pressed, down) = ctx.input(|i| {
        (
            i.pointer.hover_pos(),
            i.pointer.primary_pressed(),
            i.pointer.primary_down(),
        )
    });
    let over_ui = hover.is_some_and(|p| panel_rect.contains(p))
        || ctx.is_pointer_over_egui()
        || ctx.egui_is_using_pointer();
    *world.resource_mut::<ClothCameraBlock>() = ClothCameraBlock {
        pointer: over_ui,
        keyboard: ctx.egui_wants_keyboard_input(),
    };
    let Some((camera, eye)) = world
        .query_filtered::<(&Camera, &GlobalTransform), With<PrimaryEguiContext>>()
        .iter(world)
        .next()
        .map(|(c, g)| (c.clone(), *g))
    else {
        return;
    };
    let to_screen = |p: Vec3| {
        camera
            .world_to_viewport(&eye, p)
            .ok()
            .map(|v| Pos2::new(v.x, v.y))
    };
    let ray = hover.and_then(|p| camera.viewport_to_world(&eye, Vec2::new(p.x, p.y)).ok());
    let painter = ctx.layer_painter(egui::LayerId::new(
        egui::Order::Background,
        egui::Id::new("bevy_cloth_editor_overlay"),
    ));
    draw_zones(world, &painter, &to_screen);
    draw_pins(world, &painter, &to_screen);

    // Axis arrows of the selected object, and which one is under the pointer.
    let editor = world.resource::<ClothEditor>();
    let (selected, drag) = (editor.selected, editor.drag);
    let mut hovered_axis = None;
    let mut origin = None;
    if let Some(e) = selected
        && let Some(gt) = world.get::<GlobalTransform>(e)
    {
        let o = gt.translation();
        origin = Some(o);
        let len = ARROW_SCALE * o.distance(eye.translation()).max(0.1);
        for (k, axis) in AXES.iter().enumerate() {
            let (Some(a), Some(b)) = (to_screen(o), to_screen(o + *axis * len)) else {
                continue;
            };
            let near = hover.is_some_and(|p| segment_distance(p, a, b) < GRAB_RADIUS);
            if near && hovered_axis.is_none() && !over_ui {
                hovered_axis = Some(k);
            }
            let active = drag.is_some_and(|d| d.axis == k) || (drag.is_none() && near);
            let width = if active { 4.0 } else { 2.5 };
            painter.arrow(a, b - a, Stroke::new(width, AXIS_COLOURS[k]));
        }
        if let Some(a) = to_screen(o) {
            let name = world
                .get::<Name>(e)
                .map_or_else(|| e.to_string(), |n| n.to_string());
            painter.text(
                a + egui::vec2(8.0, 8.0),
                egui::Align2::LEFT_TOP,
                name,
                egui::FontId::proportional(13.0),
                Color32::WHITE,
            );
        }
    }

    // The pointer: drag an arrow, or click to select / toggle a pin.
    match (drag, ray) {
        (Some(d), Some(ray)) if down => {
            if let Some(target) = d.target(ray) {
                move_to(world, d.entity, target);
            }
        }
        (Some(_), _) if !down => world.resource_mut::<ClothEditor>().drag = None,
        (None, Some(ray)) if pressed && !over_ui => {
            if let (Some(k), Some(e), Some(o)) = (hovered_axis, selected, origin) {
                world.resource_mut::<ClothEditor>().drag = AxisDrag::begin(e, k, o, ray);
            } else {
                actions::click(world, ray);
            }
        }
        _ => {}
    }
}

/// Distance from `p` to the segment `a–b`, in points.
fn segment_distance(p: Pos2, a: Pos2, b: Pos2) -> f32 {
    let ab = b - a;
    let t = if ab.length_sq() > 0.0 {
        ((p - a).dot(ab) / ab.length_sq()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).length()
}

fn draw_zones(
    world: &mut World,
    painter: &egui::Painter,
    to_screen: &dyn Fn(Vec3) -> Option<Pos2>,
) {
    let selected = world.resource::<ClothEditor>().selected;
    let mut q = world.query::<(Entity, &WindZone, &GlobalTransform)>();
    for (e, zone, gt) in q.iter(world) {
        let colour = if Some(e) == selected {
            Color32::from_rgb(140, 220, 255)
        } else {
            Color32::from_rgba_unmultiplied(140, 200, 255, 120)
        };
        let h = zone.half_extents;
        let corner = |i: u32| {
            let s = Vec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            );
            gt.transform_point(s * h)
        };
        for i in 0..8u32 {
            for bit in [1, 2, 4] {
                let j = i | bit;
                if j != i
                    && let (Some(a), Some(b)) = (to_screen(corner(i)), to_screen(corner(j)))
                {
                    painter.line_segment([a, b], Stroke::new(1.0, colour));
                }
            }
        }
        let c = gt.translation();
        let v = zone.wind.velocity;
        if v.length() > 0.0
            && let (Some(a), Some(b)) = (
                to_screen(c),
                to_screen(c + v.normalize() * h.max_element().max(0.2)),
            )
        {
            painter.arrow(a, b - a, Stroke::new(2.0, colour));
        }
    }
}

fn draw_pins(world: &mut World, painter: &egui::Painter, to_screen: &dyn Fn(Vec3) -> Option<Pos2>) {
    let Some(cloth) = world.resource::<ClothEditor>().pin_edit else {
        return;
    };
    let Some(draft) = actions::pin_draft(world, cloth) else {
        return;
    };
    let Some(sim) = world.get::<ClothSim>(cloth) else {
        return;
    };
    let pinned: Vec<u32> = sim
        .simulation()
        .state()
        .pins()
        .iter()
        .map(|p| p.vertex)
        .collect();
    let draft_particles: Vec<u32> = draft.vertices.iter().map(|&v| sim.particle(v)).collect();
    // Pinned now but not in the draft: hollow (they fall when the draft is applied).
    for &p in &pinned {
        if !draft_particles.contains(&p)
            && let Some(s) = to_screen(sim.simulation().state().position(p as usize))
        {
            painter.circle_stroke(s, 5.0, Stroke::new(1.5, Color32::GRAY));
        }
    }
    for &p in &draft_particles {
        if let Some(s) = to_screen(sim.simulation().state().position(p as usize)) {
            let colour = if pinned.contains(&p) {
                Color32::from_rgb(255, 170, 40)
            } else {
                Color32::from_rgb(255, 240, 80)
            };
            painter.circle_filled(s, 4.5, colour);
        }
    }
}
