//! The panel (bevy_egui): cards, sliders, plots, buttons. Every button calls a function of
//! [`actions`] or [`scene`]; every slider is a [`Knob`] of [`knobs`].

use bevy::prelude::*;
use bevy_egui::egui::{self, Color32};

use super::actions;
use super::knobs::{self, Knob};
use super::scene;
use super::state::{ClothEditor, NewCloth, NewShape, PinPreset};
use super::stats::ClothStats;
use crate::cloth::{
    Cloth, ClothConfig, ClothSelfCollision, ClothSim, ClothSmoothing, ClothTearing, ClothTethers,
};
use crate::collider::{ClothCollider, ColliderMesh, ColliderShape};
use crate::gpu::{ClothBackend, ClothBackendInUse};
use crate::solver::limits::Spread;
use crate::solver::{BendRest, BendingModel, BendingSolve, MassDistribution, Solver, WindParams};
use crate::wind::{Wind, WindZone};

/// Smallest positive value logarithmic sliders that start at 0 show.
const SMALLEST_POSITIVE: f64 = 1e-9;

/// A card's header: open by default only for the selected object, and opened when the object
/// becomes selected.
fn card(world: &mut World, e: Entity, salt: &str, title: String) -> egui::CollapsingHeader {
    let selected = world.resource::<ClothEditor>().selected == Some(e);
    let just = selected && world.resource::<ClothEditor>().opened != Some(e);
    if just {
        world.resource_mut::<ClothEditor>().opened = Some(e);
    }
    let title = if selected {
        egui::RichText::new(format!("{title}  (selected)")).strong()
    } else {
        egui::RichText::new(title)
    };
    let h = egui::CollapsingHeader::new(title).id_salt((salt, e));
    if just {
        h.open(Some(true))
    } else {
        h.default_open(false)
    }
}

fn name(world: &World, e: Entity, kind: &str) -> String {
    world
        .get::<Name>(e)
        .map_or_else(|| format!("{kind} {e}"), |n| n.to_string())
}

/// One slider for a knob; writes `target` when the slider moved. `None` when the knob does
/// not apply to this value.
fn knob_slider<T>(ui: &mut egui::Ui, knob: &Knob<T>, target: &mut T) -> Option<egui::Response> {
    let before = (knob.get)(target)?;
    let mut v = before;
    let l = knob.limit;
    let mut slider = egui::Slider::new(&mut v, l.min..=l.max).text(knob.label);
    if l.spread == Spread::Logarithmic {
        // Ranges over many decades read best in scientific notation.
        let wide = l.max > 1e4 * l.min.abs().max(1e-3) && !l.integer;
        if wide {
            slider = slider.custom_formatter(|v, _| {
                if v == 0.0 || (1e-2..1e4).contains(&v.abs()) {
                    format!("{v:.3}")
                } else {
                    format!("{v:.2e}")
                }
            });
        }
        slider = slider.logarithmic(true).smallest_positive(if l.min > 0.0 {
            f64::from(l.min)
        } else {
            SMALLEST_POSITIVE
        });
    }
    if l.integer {
        slider = slider.integer();
    }
    if !l.unit.is_empty() {
        slider = slider.suffix(format!(" {}", l.unit));
    }
    let response = ui.add(slider);
    if v != before {
        knob.apply(target, v);
    }
    Some(response)
}

/// Sliders for every applicable knob of a component; writes the component back when a value
/// changed (only when the drag ends, for `on_release`).
fn knob_card<T: Component<Mutability = bevy::ecs::component::Mutable> + Clone + PartialEq>(
    ui: &mut egui::Ui,
    world: &mut World,
    e: Entity,
    knobs: &[Knob<T>],
    on_release: bool,
) {
    let Some(mut value) = world.get::<T>(e).cloned() else {
        return;
    };
    let before = value.clone();
    let mut dragging = false;
    for knob in knobs {
        if let Some(r) = knob_slider(ui, knob, &mut value) {
            dragging |= r.dragged();
        }
    }
    if value != before
        && !(on_release && dragging)
        && let Some(mut c) = world.get_mut::<T>(e)
    {
        *c = value;
    }
}

fn combo<V: PartialEq + Copy>(
    ui: &mut egui::Ui,
    id: impl std::hash::Hash + std::fmt::Debug,
    label: &str,
    value: &mut V,
    options: &[(V, &str)],
) {
    let current = options
        .iter()
        .find(|(v, _)| v == value)
        .map_or("?", |(_, n)| n);
    ui.horizontal(|ui| {
        egui::ComboBox::from_id_salt(id)
            .selected_text(current)
            .show_ui(ui, |ui| {
                for (v, n) in options {
                    ui.selectable_value(value, *v, *n);
                }
            });
        ui.label(label);
    });
}

fn position_row(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    let Some(mut t) = world.get::<Transform>(e).copied() else {
        return;
    };
    let before = t.translation;
    ui.horizontal(|ui| {
        ui.label("position");
        for k in 0..3 {
            ui.add(
                egui::DragValue::new(&mut t.translation[k])
                    .speed(0.01)
                    .prefix(["x ", "y ", "z "][k]),
            );
        }
    });
    if t.translation != before
        && t.translation.is_finite()
        && let Some(mut c) = world.get_mut::<Transform>(e)
    {
        c.translation = t.translation;
    }
}

fn object_buttons(ui: &mut egui::Ui, world: &mut World, e: Entity) -> bool {
    let mut deleted = false;
    ui.horizontal(|ui| {
        let selected = world.resource::<ClothEditor>().selected == Some(e);
        if ui.selectable_label(selected, "select (arrows)").clicked() {
            world.resource_mut::<ClothEditor>().selected = if selected { None } else { Some(e) };
        }
        if ui.button("delete").clicked() {
            deleted = actions::delete(world, e);
        }
    });
    deleted
}

fn panel(ui: &mut egui::Ui, world: &mut World) {
    let toggle = world.resource::<ClothEditor>().toggle;
    ui.heading("Cloth editor");
    ui.label(
        egui::RichText::new(format!(
            "{toggle:?} hides · right mouse + WASD/QE flies · click selects · drag an arrow moves"
        ))
        .small(),
    );
    let status = world.resource::<ClothEditor>().status.clone();
    if !status.is_empty() {
        ui.label(egui::RichText::new(status).color(Color32::from_rgb(250, 210, 120)));
    }
    ui.separator();
    add_section(ui, world);
    file_section(ui, world);
    ui.separator();

    let mut cloths: Vec<Entity> = world
        .query_filtered::<Entity, With<Cloth>>()
        .iter(world)
        .collect();
    by_name(world, &mut cloths);
    for e in cloths {
        cloth_card(ui, world, e);
    }
    let mut colliders: Vec<Entity> = world
        .query_filtered::<Entity, With<ClothCollider>>()
        .iter(world)
        .collect();
    by_name(world, &mut colliders);
    for e in colliders {
        collider_card(ui, world, e);
    }
    wind_card(ui, world);
    let mut zones: Vec<Entity> = world
        .query_filtered::<Entity, With<WindZone>>()
        .iter(world)
        .collect();
    by_name(world, &mut zones);
    for e in zones {
        zone_card(ui, world, e);
    }
}

/// Cards in name order (then entity order), stable from frame to frame.
fn by_name(world: &World, list: &mut [Entity]) {
    let name = |e: &Entity| world.get::<Name>(*e).map(Name::as_str);
    list.sort_by(|a, b| name(a).cmp(&name(b)).then(a.cmp(b)));
}

fn add_section(ui: &mut egui::Ui, world: &mut World) {
    egui::CollapsingHeader::new("Add")
        .default_open(true)
        .show(ui, |ui| {
            let mut spec = world.resource::<ClothEditor>().new_cloth;
            let (vlo, vhi) = NewCloth::VERTICES;
            let (slo, shi) = NewCloth::SIZE;
            let mass = crate::solver::limits::MASS;
            ui.add(
                egui::Slider::new(&mut spec.width, slo..=shi)
                    .logarithmic(true)
                    .text("width")
                    .suffix(" m"),
            );
            ui.add(
                egui::Slider::new(&mut spec.height, slo..=shi)
                    .logarithmic(true)
                    .text("height")
                    .suffix(" m"),
            );
            ui.add(
                egui::Slider::new(&mut spec.columns, vlo..=vhi)
                    .logarithmic(true)
                    .text("columns"),
            );
            ui.add(
                egui::Slider::new(&mut spec.rows, vlo..=vhi)
                    .logarithmic(true)
                    .text("rows"),
            );
            ui.add(
                egui::Slider::new(&mut spec.mass, mass.min..=mass.max)
                    .logarithmic(true)
                    .text("mass")
                    .suffix(" kg"),
            );
            if spec != world.resource::<ClothEditor>().new_cloth {
                world.resource_mut::<ClothEditor>().new_cloth = spec;
            }
            if ui.button("add cloth").clicked() {
                let e = actions::add_cloth(world, &spec);
                world.resource_mut::<ClothEditor>().selected = Some(e);
            }
            ui.horizontal_wrapped(|ui| {
                for (shape, label) in [
                    (NewShape::Sphere, "add sphere"),
                    (NewShape::Box, "add box"),
                    (NewShape::Capsule, "add capsule"),
                    (NewShape::Plane, "add floor"),
                ] {
                    if ui.button(label).clicked() {
                        let e = actions::add_collider(world, shape);
                        world.resource_mut::<ClothEditor>().selected = Some(e);
                    }
                }
                if ui.button("add wind zone").clicked() {
                    let e = actions::add_wind_zone(world);
                    world.resource_mut::<ClothEditor>().selected = Some(e);
                }
            });
            ui.horizontal(|ui| {
                let mut path = world.resource::<ClothEditor>().mesh_path.clone();
                ui.add(
                    egui::TextEdit::singleline(&mut path)
                        .hint_text("models/thing.glb or .obj")
                        .desired_width(180.0),
                );
                if path != world.resource::<ClothEditor>().mesh_path {
                    world.resource_mut::<ClothEditor>().mesh_path = path.clone();
                }
            });
            ui.horizontal(|ui| {
                let path = world.resource::<ClothEditor>().mesh_path.clone();
                if ui.button("add mesh collider").clicked() {
                    match actions::add_mesh_collider(world, &path) {
                        Ok(e) => world.resource_mut::<ClothEditor>().selected = Some(e),
                        Err(m) => actions::say(world, m),
                    }
                }
                if ui.button("add mesh cloth").clicked() {
                    match actions::add_mesh_cloth(world, &path) {
                        Ok(e) => world.resource_mut::<ClothEditor>().selected = Some(e),
                        Err(m) => actions::say(world, m),
                    }
                }
            });
        });
}

fn file_section(ui: &mut egui::Ui, world: &mut World) {
    egui::CollapsingHeader::new("Scene file")
        .default_open(false)
        .show(ui, |ui| {
            let mut path = world.resource::<ClothEditor>().scene_path.clone();
            ui.add(egui::TextEdit::singleline(&mut path).desired_width(240.0));
            if path != world.resource::<ClothEditor>().scene_path {
                world.resource_mut::<ClothEditor>().scene_path = path.clone();
            }
            ui.horizontal(|ui| {
                if ui.button("save").clicked()
                    && let Err(m) = scene::save_scene_file(world, &path)
                {
                    actions::say(world, m);
                }
                if ui.button("load (replaces the scene)").clicked()
                    && let Err(m) = scene::load_scene_file(world, &path)
                {
                    actions::say(world, m);
                }
            });
        });
}

fn live_numbers(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    let gpu = world.get::<ClothBackendInUse>(e).is_some_and(|b| b.gpu);
    let stats = world.resource::<ClothStats>();
    let Some(history) = stats.cloths.get(&e) else {
        ui.label("not simulated yet");
        return;
    };
    let Some(last) = history.back() else {
        return;
    };
    let step = if gpu {
        "on the GPU".to_string()
    } else {
        format!("{:.2} ms", last.step_ms)
    };
    ui.label(format!(
        "step {step} · strain max {:.1} % mean {:.2} % · torn {}{}",
        last.max_strain * 100.0,
        last.mean_strain * 100.0,
        last.torn,
        if last.asleep { " · asleep" } else { "" }
    ));
    let t0 = history.front().map_or(0.0, |s| s.time);
    let strain: Vec<[f64; 2]> = history
        .iter()
        .map(|s| [s.time - t0, f64::from(s.max_strain) * 100.0])
        .collect();
    let ms: Vec<[f64; 2]> = history
        .iter()
        .map(|s| [s.time - t0, f64::from(s.step_ms)])
        .collect();
    ui.horizontal(|ui| {
        let w = (ui.available_width() * 0.5 - 4.0).max(80.0);
        egui_plot::Plot::new(("strain", e))
            .height(70.0)
            .width(w)
            .allow_drag(false)
            .allow_zoom(false)
            .allow_scroll(false)
            .include_y(0.0)
            .show_axes([false, true])
            .show(ui, |p| {
                p.line(
                    egui_plot::Line::new("max strain %", strain)
                        .color(Color32::from_rgb(250, 150, 60)),
                );
            });
        egui_plot::Plot::new(("step", e))
            .height(70.0)
            .width(w)
            .allow_drag(false)
            .allow_zoom(false)
            .allow_scroll(false)
            .include_y(0.0)
            .show_axes([false, true])
            .show(ui, |p| {
                p.line(egui_plot::Line::new("step ms", ms).color(Color32::from_rgb(90, 180, 250)));
            });
    });
    ui.label(egui::RichText::new("max strain % (left), step ms (right), last 10 s").small());
    if world
        .get::<ClothSim>(e)
        .is_some_and(ClothSim::overstretched)
    {
        ui.colored_label(
            Color32::from_rgb(250, 150, 60),
            "stretched past twice its length: turn tethers on, or raise the substeps",
        );
    }
    if let Some(err) = world.get::<ClothSim>(e).and_then(|s| s.rejected()) {
        ui.colored_label(Color32::from_rgb(250, 110, 90), format!("refused: {err}"));
    }
    if let Some(invalid) = world.get::<crate::cloth::ClothInvalid>(e) {
        ui.colored_label(
            Color32::from_rgb(250, 110, 90),
            format!("not simulated: {}", invalid.0),
        );
    }
}

fn cloth_card(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    let title = name(world, e, "Cloth");
    card(world, e, "cloth", title).show(ui, |ui| {
        live_numbers(ui, world, e);
        if object_buttons(ui, world, e) {
            return;
        }
        position_row(ui, world, e);
        solver_section(ui, world, e);
        features_section(ui, world, e);
        pins_section(ui, world, e);
        rebuild_section(ui, world, e);
    });
}

fn solver_section(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    egui::CollapsingHeader::new("solver")
        .id_salt(("solver", e))
        .default_open(false)
        .show(ui, |ui| {
            let Some(mut config) = world.get::<ClothConfig>(e).copied() else {
                return;
            };
            let before = config;
            let mut kind = config.solver.name();
            combo(
                ui,
                ("kind", e),
                "solver",
                &mut kind,
                &[("lab", "lab (seed 000)"), ("pbd", "PBD"), ("xpbd", "XPBD")],
            );
            if kind != config.solver.name() {
                config.solver = match kind {
                    "lab" => Solver::LAB,
                    "pbd" => Solver::Pbd {
                        stretch: 1.0,
                        shear: 1.0,
                        bending: 0.1,
                    },
                    _ => Solver::default(),
                };
            }
            if let Solver::Xpbd { bending, .. } = &mut config.solver {
                let mut on = bending.is_finite();
                if ui.checkbox(&mut on, "bending").changed() {
                    *bending = if on {
                        crate::solver::DEFAULT_BENDING_COMPLIANCE
                    } else {
                        f32::INFINITY
                    };
                }
                combo(
                    ui,
                    ("bending solve", e),
                    "bending solve",
                    &mut config.bending_solve,
                    &[
                        (BendingSolve::Auto, "auto"),
                        (BendingSolve::Projected, "projected"),
                        (BendingSolve::Implicit, "implicit"),
                    ],
                );
            }
            for knob in knobs::CONFIG {
                knob_slider(ui, knob, &mut config);
            }
            if config != before
                && let Some(mut c) = world.get_mut::<ClothConfig>(e)
            {
                *c = config;
            }
            // The backend (applies at once; a GPU cloth carries its state over).
            let mut backend = world.get::<ClothBackend>(e).copied();
            let before = backend;
            let shown = backend.unwrap_or_default();
            let mut pick = shown;
            combo(
                ui,
                ("backend", e),
                "backend",
                &mut pick,
                &[
                    (ClothBackend::Cpu, "CPU"),
                    (ClothBackend::Gpu, "GPU"),
                    (ClothBackend::Auto, "auto"),
                ],
            );
            if pick != shown {
                backend = Some(pick);
            }
            if backend != before
                && let Some(b) = backend
            {
                world.entity_mut(e).insert(b);
            }
            // When between fixed steps it is drawn (applies at once).
            let shown = world.get::<ClothSmoothing>(e).copied().unwrap_or_default();
            let mut pick = shown;
            combo(
                ui,
                ("smoothing", e),
                "drawn",
                &mut pick,
                &[
                    (ClothSmoothing::LastStep, "as stepped"),
                    (ClothSmoothing::Interpolate, "interpolated"),
                    (ClothSmoothing::Extrapolate, "extrapolated"),
                ],
            );
            if pick != shown {
                world.entity_mut(e).insert(pick);
            }
            if let Some(used) = world.get::<ClothBackendInUse>(e) {
                let text = match (&used.reason, used.gpu) {
                    (_, true) => "running on the GPU".to_string(),
                    (Some(r), false) => format!("running on the CPU: {r}"),
                    (None, false) => "running on the CPU".to_string(),
                };
                ui.label(egui::RichText::new(text).small());
            }
        });
}

fn feature_toggle<T: Component + Default>(
    ui: &mut egui::Ui,
    world: &mut World,
    e: Entity,
    label: &str,
) -> bool {
    let mut on = world.get::<T>(e).is_some();
    if ui.checkbox(&mut on, label).changed() {
        if on {
            world.entity_mut(e).insert(T::default());
        } else {
            world.entity_mut(e).remove::<T>();
        }
    }
    on
}

fn features_section(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    egui::CollapsingHeader::new("features")
        .id_salt(("features", e))
        .show(ui, |ui| {
            if feature_toggle::<ClothSelfCollision>(ui, world, e, "self-collision") {
                ui.indent(("sc", e), |ui| {
                    if let Some(mut sc) = world.get::<ClothSelfCollision>(e).copied() {
                        let mut auto = sc.thickness.is_none();
                        if ui
                            .checkbox(&mut auto, "thickness: automatic (about an edge)")
                            .changed()
                        {
                            // Unticked: start from the thickness in use (the automatic one).
                            let in_use = world
                                .get::<ClothSim>(e)
                                .and_then(|s| s.simulation().features().self_collision)
                                .map_or(0.01, |s| s.thickness);
                            sc.thickness = if auto { None } else { Some(in_use) };
                            world.entity_mut(e).insert(sc);
                        }
                    }
                    knob_card(ui, world, e, knobs::SELF_COLLISION, false);
                });
            }
            if feature_toggle::<ClothTethers>(ui, world, e, "tethers") {
                ui.indent(("tethers", e), |ui| {
                    knob_card(ui, world, e, knobs::TETHERS, false)
                });
            }
            if feature_toggle::<ClothTearing>(ui, world, e, "tearing") {
                ui.indent(("tearing", e), |ui| {
                    knob_card(ui, world, e, knobs::TEARING, false)
                });
            }
        });
}

fn pins_section(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    egui::CollapsingHeader::new("pins")
        .id_salt(("pins", e))
        .show(ui, |ui| {
            if world.get::<ClothSim>(e).is_none() {
                ui.label("not simulated yet");
                return;
            }
            let pinned = world
                .get::<ClothSim>(e)
                .map_or(0, |s| s.simulation().state().pins().len());
            let editing = world.resource::<ClothEditor>().pin_edit == Some(e);
            let mut on = editing;
            ui.checkbox(&mut on, "click the cloth to pin or unpin a vertex");
            if on != editing {
                world.resource_mut::<ClothEditor>().pin_edit = on.then_some(e);
            }
            ui.horizontal(|ui| {
                for (preset, label) in [
                    (PinPreset::TopEdge, "top edge"),
                    (PinPreset::TwoCorners, "two corners"),
                    (PinPreset::None, "none"),
                ] {
                    if ui.button(label).clicked() {
                        actions::pin_preset(world, e, preset);
                        world.resource_mut::<ClothEditor>().pin_edit = Some(e);
                    }
                }
            });
            let draft = world
                .resource::<ClothEditor>()
                .drafts
                .get(&e)
                .map(|d| d.vertices.len());
            ui.label(match draft {
                Some(n) => format!("{pinned} pinned now; {n} in the draft"),
                None => format!("{pinned} pinned"),
            });
            ui.horizontal(|ui| {
                if ui
                    .add_enabled(draft.is_some(), egui::Button::new("update pins"))
                    .clicked()
                    && let Err(m) = actions::update_pins(world, e)
                {
                    actions::say(world, m);
                }
                if ui
                    .add_enabled(draft.is_some(), egui::Button::new("revert"))
                    .clicked()
                {
                    world.resource_mut::<ClothEditor>().drafts.remove(&e);
                }
            });
        });
}

fn rebuild_section(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    egui::CollapsingHeader::new("material")
        .id_salt(("rebuild", e))
        .show(ui, |ui| {
            ui.label(
                egui::RichText::new(
                    "changing these remakes the cloth where it is; the weld tolerance \
                     restarts it from its rest shape",
                )
                .small(),
            );
            knob_card(ui, world, e, knobs::CLOTH, true);
            let Some(mut cloth) = world.get::<Cloth>(e).copied() else {
                return;
            };
            let before = cloth;
            combo(
                ui,
                ("mass distribution", e),
                "mass distribution",
                &mut cloth.mass_distribution,
                &[
                    (MassDistribution::Area, "by area"),
                    (MassDistribution::Uniform, "uniform"),
                ],
            );
            combo(
                ui,
                ("bending model", e),
                "bending model",
                &mut cloth.bending_model,
                &[
                    (BendingModel::Isometric, "isometric"),
                    (BendingModel::Dihedral, "dihedral"),
                ],
            );
            combo(
                ui,
                ("bend rest", e),
                "bends toward",
                &mut cloth.bend_rest,
                &[
                    (BendRest::Flat, "flat"),
                    (BendRest::RestShape, "its rest shape"),
                ],
            );
            if cloth != before
                && let Some(mut c) = world.get_mut::<Cloth>(e)
            {
                *c = cloth;
            }
            if ui.button("restart from rest").clicked()
                && let Some(mut c) = world.get_mut::<Cloth>(e)
            {
                c.set_changed();
            }
        });
}

fn collider_card(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    let title = name(world, e, "Collider");
    card(world, e, "collider", title).show(ui, |ui| {
        let shape = world.get::<ClothCollider>(e).map(|c| match c.shape {
            ColliderShape::Sphere { .. } => "sphere",
            ColliderShape::Cuboid { .. } => "box",
            ColliderShape::Capsule { .. } => "capsule",
            ColliderShape::Plane => "floor (plane)",
            ColliderShape::Mesh(ColliderMesh::Asset { .. }) => "mesh (baked SDF)",
            ColliderShape::Mesh(ColliderMesh::Baked(_)) => "baked field",
        });
        ui.label(shape.unwrap_or("?"));
        if object_buttons(ui, world, e) {
            return;
        }
        position_row(ui, world, e);
        knob_card(ui, world, e, knobs::COLLIDER, false);
    });
}

fn wind_card(ui: &mut egui::Ui, world: &mut World) {
    egui::CollapsingHeader::new("Wind (everywhere)")
        .id_salt("global wind")
        .show(ui, |ui| {
            let mut on = world.contains_resource::<Wind>();
            if ui.checkbox(&mut on, "blowing").changed() {
                actions::set_wind(world, on.then(WindParams::default));
            }
            let Some(mut w) = world.get_resource::<Wind>().map(|w| w.0) else {
                return;
            };
            let before = w;
            for knob in knobs::WIND {
                knob_slider(ui, knob, &mut w);
            }
            seed_row(ui, &mut w);
            if w != before {
                world.resource_mut::<Wind>().0 = w;
            }
        });
}

/// The noise seed (any whole number).
fn seed_row(ui: &mut egui::Ui, wind: &mut WindParams) {
    ui.horizontal(|ui| {
        ui.add(egui::DragValue::new(&mut wind.seed).speed(1.0));
        ui.label("noise seed");
    });
}

fn zone_card(ui: &mut egui::Ui, world: &mut World, e: Entity) {
    let title = name(world, e, "Wind zone");
    card(world, e, "zone", title).show(ui, |ui| {
        if object_buttons(ui, world, e) {
            return;
        }
        position_row(ui, world, e);
        let Some(mut zone) = world.get::<WindZone>(e).copied() else {
            return;
        };
        let before = zone;
        for knob in knobs::WIND {
            knob_slider(ui, knob, &mut zone.wind);
        }
        for knob in knobs::ZONE {
            knob_slider(ui, knob, &mut zone);
        }
        if zone != before
            && let Some(mut z) = world.get_mut::<WindZone>(e)
        {
            *z = zone;
        }
    });
}

/// Draws the editor's panel contents (status, add buttons, scene file, a card per cloth,
/// collider and wind) into any egui `Ui`: for a game that wants the editor inside its own
/// egui window rather than [`ClothEditorPlugin`](super::ClothEditorPlugin)'s side panel.
pub fn panel_contents(ui: &mut egui::Ui, world: &mut World) {
    panel(ui, world);
}
