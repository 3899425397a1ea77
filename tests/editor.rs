//! The editor driven headlessly through the same functions its buttons and sliders call:
//! add, edit every slider at both ends of its range, pins (draft, presets, click, update),
//! delete, mesh colliders from files, scene files round trip, the axis drag, and the panel
//! drawn by a bare egui context.

mod common;

use std::time::{Duration, Instant};

use bevy::math::Ray3d;
use bevy::prelude::*;
use bevy_cloth::cloth::ClothInvalid;
use bevy_cloth::collider::ClothColliders;
use bevy_cloth::editor::gizmo::{AxisDrag, move_to};
use bevy_cloth::editor::knobs::{self, Knob};
use bevy_cloth::editor::{
    ClothEditor, NewCloth, NewShape, PinPreset, actions, panel_contents, scene,
};
use bevy_cloth::prelude::*;
use bevy_cloth::solver::Shape;
use bevy_cloth::wind::ClothWindField;
use common::run;

fn editor_app() -> App {
    let mut app = common::app();
    app.add_plugins(ClothEditorPlugin::default());
    app.update();
    app
}

fn ray(from: Vec3, to: Vec3) -> Ray3d {
    Ray3d::new(from, Dir3::new(to - from).unwrap())
}

fn sim(app: &App, e: Entity) -> &ClothSim {
    app.world().get::<ClothSim>(e).expect("simulated")
}

fn small() -> NewCloth {
    NewCloth {
        columns: 12,
        rows: 10,
        ..default()
    }
}

#[test]
fn pins_change_only_when_updated_and_follow_presets_and_clicks() {
    let mut app = editor_app();
    let e = actions::add_cloth(app.world_mut(), &small());
    run(&mut app, 20);
    let grid = Grid::new(12, 10, 1.0, 1.0);
    assert_eq!(sim(&app, e).simulation().state().pins().len(), 2);
    // The top edge: the 12 vertices of row 0, in the draft only.
    let n = actions::pin_preset(app.world_mut(), e, PinPreset::TopEdge).unwrap();
    assert_eq!(n, 12);
    let draft = actions::pin_draft(app.world(), e).unwrap();
    assert_eq!(
        draft.vertices,
        (0..12).map(|i| grid.index(i, 0)).collect(),
        "top edge"
    );
    run(&mut app, 10);
    assert_eq!(
        sim(&app, e).simulation().state().pins().len(),
        2,
        "a draft changes nothing"
    );
    // Applied: 12 pins, held where they are.
    let before: Vec<Vec3> = (0..12)
        .map(|i| sim(&app, e).position(grid.index(i, 0)))
        .collect();
    assert_eq!(actions::update_pins(app.world_mut(), e), Ok(12));
    run(&mut app, 30);
    assert_eq!(sim(&app, e).simulation().state().pins().len(), 12);
    for (i, b) in before.iter().enumerate() {
        let now = sim(&app, e).position(grid.index(i as u32, 0));
        assert!(now.distance(*b) < 1e-4, "pin {i} moved from {b} to {now}");
    }
    // Two corners: the ends of row 0.
    actions::pin_preset(app.world_mut(), e, PinPreset::TwoCorners).unwrap();
    let draft = actions::pin_draft(app.world(), e).unwrap();
    assert_eq!(
        draft.vertices,
        [grid.index(0, 0), grid.index(11, 0)].into_iter().collect()
    );
    // A click on a free vertex (the cloth hangs in the xy plane, facing +z) adds it.
    let v = grid.index(6, 5);
    let at = sim(&app, e).position(v);
    app.world_mut().resource_mut::<ClothEditor>().pin_edit = Some(e);
    let clicked = actions::click(app.world_mut(), ray(at + Vec3::new(0.0, 0.0, 3.0), at));
    assert_eq!(clicked, Some(e));
    let draft = actions::pin_draft(app.world(), e).unwrap();
    assert!(draft.vertices.contains(&v), "{:?}", draft.vertices);
    assert_eq!(draft.vertices.len(), 3);
    // Clicking it again takes it out.
    actions::click(app.world_mut(), ray(at + Vec3::new(0.0, 0.0, 3.0), at));
    assert_eq!(
        actions::pin_draft(app.world(), e).unwrap().vertices.len(),
        2
    );
    // No pins: the cloth falls.
    actions::pin_preset(app.world_mut(), e, PinPreset::None).unwrap();
    let top = sim(&app, e).position(grid.index(0, 0)).y;
    actions::update_pins(app.world_mut(), e).unwrap();
    run(&mut app, 30);
    assert!(sim(&app, e).simulation().state().pins().is_empty());
    assert!(sim(&app, e).position(grid.index(0, 0)).y < top - 0.3);
}

#[test]
fn clicks_select_what_is_under_the_pointer() {
    let mut app = editor_app();
    let ball = actions::add_collider(app.world_mut(), NewShape::Sphere);
    let zone = actions::add_wind_zone(app.world_mut());
    let cloth = actions::add_cloth(app.world_mut(), &small());
    run(&mut app, 3);
    let world = app.world_mut();
    let ball_at = world.get::<GlobalTransform>(ball).unwrap().translation();
    let zone_at = world.get::<GlobalTransform>(zone).unwrap().translation();
    let cloth_at = world.get::<ClothSim>(cloth).unwrap().position(30);
    let eye = Vec3::new(0.0, 1.0, 8.0);
    assert_eq!(actions::click(world, ray(eye, ball_at)), Some(ball));
    assert_eq!(world.resource::<ClothEditor>().selected, Some(ball));
    assert_eq!(actions::click(world, ray(eye, zone_at)), Some(zone));
    assert_eq!(actions::click(world, ray(eye, cloth_at)), Some(cloth));
    // Into the sky: nothing, and the selection is cleared.
    assert_eq!(
        actions::click(world, ray(eye, Vec3::new(0.0, 30.0, 0.0))),
        None
    );
    assert_eq!(world.resource::<ClothEditor>().selected, None);
}

#[test]
fn deleting_leaves_no_meshes_and_no_stale_pins() {
    let mut app = editor_app();
    run(&mut app, 2);
    let meshes_before = app.world().resource::<Assets<Mesh>>().len();
    let cloth = actions::add_cloth(app.world_mut(), &small());
    let ball = actions::add_collider(app.world_mut(), NewShape::Sphere);
    let others = [
        actions::add_collider(app.world_mut(), NewShape::Box),
        actions::add_collider(app.world_mut(), NewShape::Capsule),
        actions::add_collider(app.world_mut(), NewShape::Plane),
        actions::add_wind_zone(app.world_mut()),
    ];
    run(&mut app, 3);
    assert_eq!(app.world().resource::<ClothColliders>().entities.len(), 4);
    // Hang a corner of the cloth on the ball.
    app.world_mut()
        .get_mut::<ClothPins>(cloth)
        .unwrap()
        .0
        .push(ClothPin {
            vertex: 5,
            anchor: PinAnchor::Entity {
                entity: ball,
                offset: Vec3::Y,
            },
        });
    app.world_mut().resource_mut::<ClothEditor>().selected = Some(ball);
    run(&mut app, 2);
    assert_eq!(sim(&app, cloth).simulation().state().pins().len(), 3);
    assert!(actions::delete(app.world_mut(), ball));
    assert!(!actions::delete(app.world_mut(), ball), "already gone");
    assert_eq!(app.world().resource::<ClothEditor>().selected, None);
    let pins = &app.world().get::<ClothPins>(cloth).unwrap().0;
    assert_eq!(pins.len(), 2, "the pin on the ball went with it: {pins:?}");
    run(&mut app, 2);
    assert_eq!(sim(&app, cloth).simulation().state().pins().len(), 2);
    assert_eq!(app.world().resource::<ClothColliders>().entities.len(), 3);
    for e in others.into_iter().chain([cloth]) {
        assert!(actions::delete(app.world_mut(), e));
    }
    run(&mut app, 3);
    assert_eq!(
        app.world().resource::<Assets<Mesh>>().len(),
        meshes_before,
        "every mesh the editor made is gone"
    );
    assert!(app.world().resource::<ClothColliders>().entities.is_empty());
}

/// Every slider at both ends of its range: the plugin takes the value (no refusal, no
/// invalid cloth, nothing non-finite, every collider and wind in use).
#[test]
fn every_slider_end_is_taken_by_the_plugin() {
    let mut app = editor_app();
    let grid = Grid::new(5, 5, 0.5, 0.5);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let spawn_cloth = |app: &mut App, bundle: (Cloth, ClothConfig)| {
        app.world_mut()
            .spawn((
                Mesh3d(mesh.clone()),
                Transform::from_xyz(0.0, 1.0, 0.0),
                bundle.0,
                bundle.1,
                ClothPins::rest([0, 4]),
            ))
            .id()
    };
    let mut cloths: Vec<(Entity, String)> = Vec::new();
    let ends = |knob_label: &str, limit: bevy_cloth::solver::limits::Limit| {
        [limit.min, limit.max].map(|v| (format!("{knob_label} = {v}"), v))
    };
    let solvers = [
        Solver::LAB,
        Solver::Pbd {
            stretch: 1.0,
            shear: 1.0,
            bending: 0.1,
        },
        Solver::default(),
    ];
    let mut tried = 0;
    for solver in solvers {
        for knob in knobs::CONFIG {
            let base = ClothConfig {
                solver,
                ..default()
            };
            if (knob.get)(&base).is_none() {
                continue;
            }
            for (what, v) in ends(knob.label, knob.limit) {
                let mut config = base;
                knob.apply(&mut config, v);
                cloths.push((spawn_cloth(&mut app, (Cloth::default(), config)), what));
                tried += 1;
            }
        }
    }
    for knob in knobs::CLOTH {
        for (what, v) in ends(knob.label, knob.limit) {
            let mut cloth = Cloth::default();
            knob.apply(&mut cloth, v);
            cloths.push((spawn_cloth(&mut app, (cloth, ClothConfig::default())), what));
            tried += 1;
        }
    }
    fn with_feature<T: Component + Default>(
        app: &mut App,
        cloths: &mut Vec<(Entity, String)>,
        base: Entity,
        knobs: &[Knob<T>],
        tried: &mut usize,
    ) {
        for knob in knobs {
            for v in [knob.limit.min, knob.limit.max] {
                let mut f = T::default();
                if (knob.get)(&f).is_none() {
                    knob.apply(&mut f, knob.limit.min);
                }
                knob.apply(&mut f, v);
                let mesh = app.world().get::<Mesh3d>(base).unwrap().clone();
                let e = app
                    .world_mut()
                    .spawn((
                        mesh,
                        Transform::from_xyz(0.0, 1.0, 0.0),
                        Cloth::default(),
                        ClothPins::rest([0, 4]),
                        f,
                    ))
                    .id();
                cloths.push((e, format!("{} = {v}", knob.label)));
                *tried += 1;
            }
        }
    }
    let base = cloths[0].0;
    with_feature(
        &mut app,
        &mut cloths,
        base,
        knobs::SELF_COLLISION,
        &mut tried,
    );
    with_feature(&mut app, &mut cloths, base, knobs::TETHERS, &mut tried);
    with_feature(&mut app, &mut cloths, base, knobs::TEARING, &mut tried);

    // Colliders of every shape, each knob that applies at both ends.
    let box_mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(Cuboid::new(0.4, 0.4, 0.4).mesh().build());
    let shapes = [
        ClothCollider::sphere(0.2),
        ClothCollider::cuboid(Vec3::splat(0.2)),
        ClothCollider::capsule(0.1, 0.4),
        ClothCollider::plane(),
        ClothCollider::mesh(16),
    ];
    let mut colliders: Vec<(Entity, String)> = Vec::new();
    for shape in shapes {
        for knob in knobs::COLLIDER {
            if (knob.get)(&shape).is_none() {
                continue;
            }
            for (what, v) in ends(knob.label, knob.limit) {
                let mut c = shape.clone();
                knob.apply(&mut c, v);
                let e = app
                    .world_mut()
                    .spawn((
                        c,
                        Transform::from_xyz(5.0, 0.0, 0.0),
                        Mesh3d(box_mesh.clone()),
                    ))
                    .id();
                colliders.push((e, what));
                tried += 1;
            }
        }
    }
    // Winds: the global one and zones, every knob at both ends.
    let mut zones = 0;
    for knob in knobs::WIND {
        for v in [knob.limit.min, knob.limit.max] {
            let mut zone = WindZone::default();
            knob.apply(&mut zone.wind, v);
            app.world_mut().spawn((zone, Transform::default()));
            zones += 1;
            tried += 1;
        }
    }
    for knob in knobs::ZONE {
        for v in [knob.limit.min, knob.limit.max] {
            let mut zone = WindZone::default();
            knob.apply(&mut zone, v);
            app.world_mut().spawn((zone, Transform::default()));
            zones += 1;
            tried += 1;
        }
    }
    let mut global = WindParams::default();
    knobs::WIND[0].apply(&mut global, knobs::WIND[0].limit.max);
    app.world_mut().insert_resource(Wind(global));
    run(&mut app, 3);

    for (e, what) in &cloths {
        let world = app.world();
        assert!(
            world.get::<ClothInvalid>(*e).is_none(),
            "{what}: {:?}",
            world.get::<ClothInvalid>(*e)
        );
        let s = world
            .get::<ClothSim>(*e)
            .unwrap_or_else(|| panic!("{what}: not simulated"));
        assert!(s.rejected().is_none(), "{what}: {:?}", s.rejected());
        assert_eq!(s.simulation().state().non_finite_count(), 0, "{what}");
        assert!(s.steps() > 0, "{what}");
    }
    let used = &app.world().resource::<ClothColliders>().entities;
    for (e, what) in &colliders {
        assert!(used.contains(e), "collider with {what} is not in use");
    }
    assert_eq!(
        app.world().resource::<ClothWindField>().field.len(),
        zones + 1,
        "every zone and the global wind blow"
    );
    assert!(tried > 100, "{tried}");
}

fn wait_for(app: &mut App, what: &str, done: impl Fn(&World) -> bool) {
    let start = Instant::now();
    while !done(app.world()) {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "timed out waiting for {what}"
        );
        app.update();
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn mesh_colliders_load_from_files_and_bad_paths_say_why() {
    let mut app = editor_app();
    let rock = actions::add_mesh_collider(app.world_mut(), "rock.obj").unwrap();
    wait_for(&mut app, "the rock to be baked", |w| {
        w.resource::<ClothColliders>().entities.contains(&rock)
    });
    assert!(
        app.world()
            .resource::<ClothEditor>()
            .status
            .contains("loaded rock.obj")
    );
    // A cloth dropped on it stays above it.
    let cloth = actions::add_cloth(app.world_mut(), &small());
    app.world_mut()
        .get_mut::<Transform>(rock)
        .unwrap()
        .translation = Vec3::new(0.0, 1.0, 0.0);
    *app.world_mut().get_mut::<Transform>(cloth).unwrap() = Transform::from_xyz(0.0, 1.6, 0.0);
    actions::pin_preset(app.world_mut(), cloth, PinPreset::None);
    run(&mut app, 2);
    actions::update_pins(app.world_mut(), cloth).unwrap();
    run(&mut app, 60);
    let s = sim(&app, cloth);
    let centre = (0..s.simulation().state().len())
        .map(|i| s.simulation().state().position(i))
        .min_by(|a, b| a.xz().length().total_cmp(&b.xz().length()))
        .unwrap();
    assert!(centre.y > 1.2, "the cloth fell through the rock: {centre}");

    let missing = actions::add_mesh_collider(app.world_mut(), "no_such_rock.obj").unwrap();
    wait_for(&mut app, "the missing file to fail", |w| {
        w.get_entity(missing).is_err()
    });
    let status = app.world().resource::<ClothEditor>().status.clone();
    assert!(
        status.contains("could not load no_such_rock.obj"),
        "{status}"
    );
    let e = actions::add_mesh_collider(app.world_mut(), "statue.fbx").unwrap_err();
    assert!(e.contains(".gltf, .glb or .obj"), "{e}");
    assert!(actions::add_mesh_collider(app.world_mut(), "  ").is_err());
}

#[test]
fn scene_files_round_trip_exactly() {
    let mut app = editor_app();
    // An editor cloth re-pinned along its top edge (pins anchored to itself).
    let a = actions::add_cloth(app.world_mut(), &small());
    // A user's cloth from its own mesh, with features, pinned to a collider and in the world.
    let ball = actions::add_collider(app.world_mut(), NewShape::Sphere);
    actions::add_collider(app.world_mut(), NewShape::Box);
    actions::add_collider(app.world_mut(), NewShape::Capsule);
    actions::add_collider(app.world_mut(), NewShape::Plane);
    let rock = actions::add_mesh_collider(app.world_mut(), "rock.obj").unwrap();
    let grid = Grid::new(7, 6, 0.8, 0.6);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    let b = app
        .world_mut()
        .spawn((
            Name::new("User cloth"),
            Mesh3d(mesh),
            Transform::from_xyz(0.3, 2.0, -0.5).with_rotation(Quat::from_rotation_z(0.2)),
            Cloth {
                mass: 0.35,
                bending_model: BendingModel::Dihedral,
                ..default()
            },
            ClothConfig {
                solver: Solver::Pbd {
                    stretch: 0.9,
                    shear: 0.8,
                    bending: 0.05,
                },
                substeps: 7,
                ..default()
            },
            ClothPins(vec![
                ClothPin {
                    vertex: 0,
                    anchor: PinAnchor::Entity {
                        entity: ball,
                        offset: Vec3::new(0.0, 0.31, 0.0),
                    },
                },
                ClothPin {
                    vertex: 6,
                    anchor: PinAnchor::World(Vec3::new(1.0, 2.5, -0.5)),
                },
            ]),
            ClothTethers::default(),
            ClothTearing { threshold: 2.5 },
            ClothSelfCollision {
                thickness: Some(0.02),
                friction: 0.3,
            },
            ClothBackend::Cpu,
            ClothInertia::new(0.4).relative_to(ball),
            ClothSmoothing::Extrapolate,
        ))
        .id();
    actions::add_wind_zone(app.world_mut());
    actions::set_wind(
        app.world_mut(),
        Some(WindParams {
            velocity: Vec3::new(3.0, 0.1, -1.0),
            seed: 7,
            ..default()
        }),
    );
    wait_for(&mut app, "the rock", |w| {
        w.resource::<ClothColliders>().entities.contains(&rock)
    });
    run(&mut app, 5);
    actions::pin_preset(app.world_mut(), a, PinPreset::TopEdge).unwrap();
    actions::update_pins(app.world_mut(), a).unwrap();
    run(&mut app, 5);

    let first = scene::save_scene(app.world_mut());
    assert_eq!(
        (first.cloths.len(), first.colliders.len(), first.zones.len()),
        (2, 5, 1)
    );
    let text = scene::scene_to_ron(&first).unwrap();
    assert!(text.contains("Own("), "self-anchored pins: {text}");
    assert!(
        text.contains("anchor: Collider("),
        "a pin on the ball: {text}"
    );
    assert!(text.contains("Asset(\"rock.obj\")"), "the rock by its path");
    assert!(
        text.split("SavedInertia(").nth(1).is_some_and(|rest| rest
            .split("anchor: ")
            .nth(1)
            .is_some_and(|a| a.starts_with("Collider("))),
        "the inertia relative to the ball: {text}"
    );
    assert!(
        text.contains("Inline("),
        "the user's mesh, vertex by vertex"
    );
    assert!(
        text.contains("smoothing: Some(Extrapolate)"),
        "the smoothing: {text}"
    );

    // Through a file, and back.
    let path = std::env::temp_dir().join(format!("bevy_cloth_scene_{}.ron", std::process::id()));
    let path = path.to_str().unwrap().to_string();
    scene::save_scene_file(app.world_mut(), &path).unwrap();
    scene::load_scene_file(app.world_mut(), &path).unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(
        app.world().get_entity(b).is_err(),
        "the old objects are replaced"
    );
    run(&mut app, 5);
    let second = scene::save_scene(app.world_mut());
    assert_eq!(second, first);
    assert_eq!(scene::scene_to_ron(&second).unwrap(), text, "the same text");

    // The loaded scene runs: both cloths simulated, the user's cloth hanging from the new
    // ball (by its name).
    let world = app.world_mut();
    let mut q = world.query::<(&Name, &ClothSim, &ClothPins)>();
    let loaded: Vec<(String, usize, ClothPins)> = q
        .iter(world)
        .map(|(n, s, p)| {
            (
                n.to_string(),
                s.simulation().state().pins().len(),
                p.clone(),
            )
        })
        .collect();
    assert_eq!(loaded.len(), 2);
    let user = loaded.iter().find(|(n, ..)| n == "User cloth").unwrap();
    assert_eq!(user.1, 2);
    let PinAnchor::Entity { entity, .. } = user.2.0[0].anchor else {
        panic!("{:?}", user.2);
    };
    assert_eq!(
        world.get::<Name>(entity).map(|n| n.to_string()),
        Some("Sphere 2".to_string())
    );

    // A broken file changes nothing.
    let objects = |world: &mut World| {
        world
            .query_filtered::<(), Or<(With<Cloth>, With<ClothCollider>, With<WindZone>)>>()
            .iter(world)
            .count()
    };
    let before = objects(world);
    assert!(scene::scene_from_ron("ClothScene(cloths: 3)").is_err());
    let mut bad = first.clone();
    bad.cloths[0].mesh = scene::SavedMesh::Grid {
        columns: 1,
        rows: 4,
        width: 1.0,
        height: 1.0,
    };
    let err = scene::load_scene(world, &bad).unwrap_err();
    assert!(err.contains("cloth 0"), "{err}");
    assert_eq!(objects(world), before);
}

/// A scene file that cannot be built is refused whole, before anything is despawned: a mesh
/// asset that does not exist, a pin on a vertex the cloth lacks, a grid too large to allocate
/// (60 000², as a file from a mod folder might ask), values outside their limits. Each leaves
/// the running scene as it was, with no `ClothInvalid` cloth.
#[test]
fn a_scene_file_that_cannot_be_built_changes_nothing() {
    let mut app = editor_app();
    actions::add_cloth(app.world_mut(), &small());
    actions::add_collider(app.world_mut(), NewShape::Sphere);
    actions::add_wind_zone(app.world_mut());
    run(&mut app, 3);
    let good = scene::save_scene(app.world_mut());
    assert_eq!((good.cloths.len(), good.colliders.len()), (1, 1));
    let state = |world: &mut World| {
        let mut q = world
            .query_filtered::<Entity, Or<(With<Cloth>, With<ClothCollider>, With<WindZone>)>>();
        let mut objects: Vec<Entity> = q.iter(world).collect();
        objects.sort();
        let invalid = world
            .query_filtered::<(), With<ClothInvalid>>()
            .iter(world)
            .count();
        (objects, invalid)
    };
    let before = state(app.world_mut());
    assert_eq!((before.0.len(), before.1), (3, 0));

    type Break = fn(&mut scene::ClothScene);
    let cases: [(&str, Break, &str); 10] = [
        (
            "an inertia over 1",
            |s| {
                s.cloths[0].inertia = Some(scene::SavedInertia {
                    linear: 2.0,
                    angular: 1.0,
                    anchor: scene::SavedInertiaAnchor::Own,
                })
            },
            "inertia",
        ),
        (
            "a mesh asset that does not exist",
            |s| s.cloths[0].mesh = scene::SavedMesh::Asset("no_such_cloth.obj".into()),
            "cannot load no_such_cloth.obj",
        ),
        (
            "a pin on a vertex the cloth lacks",
            |s| s.cloths[0].pins[0].vertex = 10_000,
            "10000",
        ),
        (
            "a 60 000 × 60 000 grid",
            |s| {
                s.cloths[0].mesh = scene::SavedMesh::Grid {
                    columns: 60_000,
                    rows: 60_000,
                    width: 1.0,
                    height: 1.0,
                }
            },
            "at most 4194304 vertices",
        ),
        ("a negative mass", |s| s.cloths[0].cloth.mass = -1.0, "mass"),
        (
            "no substeps",
            |s| s.cloths[0].config.substeps = 0,
            "substeps",
        ),
        (
            "a NaN position",
            |s| s.cloths[0].transform.translation.x = f32::NAN,
            "position",
        ),
        (
            "a ball of negative radius",
            |s| s.colliders[0].shape = Shape::Sphere { radius: -1.0 },
            "collider 0",
        ),
        (
            "a wind zone of NaN falloff",
            |s| s.zones[0].zone.falloff = f32::NAN,
            "wind zone 0",
        ),
        (
            "a pin anchored at infinity",
            |s| s.cloths[0].pins[0].anchor = scene::SavedAnchor::World(Vec3::INFINITY),
            "anchored",
        ),
    ];
    for (what, break_it, says) in cases {
        let mut bad = good.clone();
        break_it(&mut bad);
        let err = scene::load_scene(app.world_mut(), &bad).expect_err(what);
        assert!(err.contains(says), "{what}: {err}");
        run(&mut app, 2);
        assert_eq!(state(app.world_mut()), before, "{what} changed the scene");
    }
    // The good file still loads.
    scene::load_scene(app.world_mut(), &good).unwrap();
    run(&mut app, 2);
    let after = state(app.world_mut());
    assert_eq!((after.0.len(), after.1), (3, 0));
}

/// A scene file whose cloth is a mesh inside a glTF file (as the editor saves a cloth loaded
/// from one): the file is loaded and checked before the scene is replaced, and a label the
/// file lacks is refused by name.
#[test]
fn a_scene_file_naming_a_gltf_mesh_loads_it_before_replacing_the_scene() {
    let mut app = common::app();
    common::add_gltf(&mut app, ClothEditorPlugin::default());
    app.update();
    let cloth = scene::SavedCloth {
        name: Some("Banner".into()),
        transform: Transform::from_xyz(0.0, 1.0, 0.0).into(),
        mesh: scene::SavedMesh::Asset("banner_statue.gltf#Mesh1/Primitive0".into()),
        color: None,
        cloth: Cloth::default(),
        config: ClothConfig::default(),
        pins: vec![scene::SavedPin {
            vertex: 0,
            anchor: scene::SavedAnchor::Rest,
        }],
        self_collision: None,
        tethers: None,
        tearing: None,
        backend: None,
        inertia: None,
        smoothing: None,
    };
    let file = scene::ClothScene {
        cloths: vec![cloth],
        ..default()
    };
    let mut wrong = file.clone();
    wrong.cloths[0].mesh = scene::SavedMesh::Asset("banner_statue.gltf#Mesh7/Primitive0".into());
    let err = scene::load_scene(app.world_mut(), &wrong).unwrap_err();
    assert!(err.contains("Mesh7/Primitive0"), "{err}");
    assert_eq!(
        app.world_mut()
            .query_filtered::<(), With<Cloth>>()
            .iter(app.world())
            .count(),
        0
    );
    // The banner has 33 × 33 vertices and 33 seam copies: 1122, so vertex 1122 is past the end.
    let mut past_the_end = file.clone();
    past_the_end.cloths[0].pins[0].vertex = 33 * 33 + 33;
    let err = scene::load_scene(app.world_mut(), &past_the_end).unwrap_err();
    assert!(err.contains("pin on vertex 1122"), "{err}");

    scene::load_scene(app.world_mut(), &file).unwrap();
    run(&mut app, 3);
    let world = app.world_mut();
    let sims: Vec<usize> = world
        .query::<&ClothSim>()
        .iter(world)
        .map(|s| s.simulation().state().len())
        .collect();
    assert_eq!(sims, vec![33 * 33], "the banner, welded, simulated");
}

#[test]
fn an_arrow_drag_moves_a_child_along_one_world_axis() {
    let mut app = editor_app();
    let parent = app
        .world_mut()
        .spawn(Transform::from_xyz(1.0, 0.0, 0.0).with_rotation(Quat::from_rotation_y(0.8)))
        .id();
    let ball = actions::add_collider(app.world_mut(), NewShape::Sphere);
    app.world_mut().entity_mut(ball).insert(ChildOf(parent));
    run(&mut app, 2);
    let start = app
        .world()
        .get::<GlobalTransform>(ball)
        .unwrap()
        .translation();
    let eye = Vec3::new(0.0, 1.5, 6.0);
    let drag = AxisDrag::begin(ball, 1, start, ray(eye, start)).unwrap();
    let target = drag.target(ray(eye, start + Vec3::Y * 0.7)).unwrap();
    assert!(move_to(app.world_mut(), ball, target));
    run(&mut app, 2);
    let now = app
        .world()
        .get::<GlobalTransform>(ball)
        .unwrap()
        .translation();
    assert!(
        (now - (start + Vec3::Y * 0.7)).length() < 1e-4,
        "{start} → {now}"
    );
}

#[test]
fn the_panel_draws_every_card() {
    let mut app = editor_app();
    let cloth = actions::add_cloth(app.world_mut(), &small());
    for s in [
        NewShape::Sphere,
        NewShape::Box,
        NewShape::Capsule,
        NewShape::Plane,
    ] {
        actions::add_collider(app.world_mut(), s);
    }
    actions::add_wind_zone(app.world_mut());
    actions::set_wind(app.world_mut(), Some(WindParams::default()));
    app.world_mut().entity_mut(cloth).insert((
        ClothSelfCollision::default(),
        ClothTethers::default(),
        ClothTearing::default(),
    ));
    run(&mut app, 5);
    app.world_mut().resource_mut::<ClothEditor>().selected = Some(cloth);
    app.world_mut().resource_mut::<ClothEditor>().pin_edit = Some(cloth);
    let config = *app.world().get::<ClothConfig>(cloth).unwrap();
    let ctx = bevy_egui::egui::Context::default();
    let mut shapes = 0;
    for _ in 0..3 {
        let out = ctx.run_ui(bevy_egui::egui::RawInput::default(), |ui| {
            panel_contents(ui, app.world_mut());
        });
        shapes = out.shapes.len();
        out.drop_without_applying_deltas();
    }
    assert!(shapes > 100, "{shapes} shapes");
    // Drawing changes nothing by itself (no slider writes when nothing moved).
    assert_eq!(*app.world().get::<ClothConfig>(cloth).unwrap(), config);
    run(&mut app, 2);
    assert!(sim(&app, cloth).rejected().is_none());
}

#[test]
fn the_toggle_key_shows_and_hides_the_panel() {
    let mut app = common::app();
    app.add_plugins(ClothEditorPlugin {
        toggle: KeyCode::F9,
        open: false,
    })
    .init_resource::<ButtonInput<KeyCode>>();
    app.update();
    assert!(!app.world().resource::<ClothEditor>().open);
    let tap = |app: &mut App, key: KeyCode| {
        app.world_mut()
            .resource_mut::<ButtonInput<KeyCode>>()
            .press(key);
        app.update();
        let mut keys = app.world_mut().resource_mut::<ButtonInput<KeyCode>>();
        keys.release(key);
        keys.clear();
    };
    tap(&mut app, KeyCode::F2);
    assert!(
        !app.world().resource::<ClothEditor>().open,
        "F2 is not the key here"
    );
    tap(&mut app, KeyCode::F9);
    assert!(app.world().resource::<ClothEditor>().open);
    tap(&mut app, KeyCode::F9);
    assert!(!app.world().resource::<ClothEditor>().open);
}

/// Pins updated in the editor on a cloth pinned by a `ClothPinRule` take its place: the rule
/// is removed, so rebuilding the cloth (a new weld tolerance) keeps the hand-made pins.
#[test]
fn pins_updated_by_hand_replace_a_pin_rule() {
    let mut app = editor_app();
    let e = actions::add_cloth(app.world_mut(), &small());
    app.world_mut()
        .entity_mut(e)
        .insert(ClothPinRule::rest(VertexSelection::Farthest {
            towards: Vec3::NEG_X,
            within: 0.0,
        }));
    run(&mut app, 20);
    // The rule's column: one vertex of each of the 10 rows.
    assert_eq!(sim(&app, e).simulation().state().pins().len(), 10);
    actions::pin_preset(app.world_mut(), e, PinPreset::TwoCorners).unwrap();
    assert_eq!(actions::update_pins(app.world_mut(), e), Ok(2));
    assert!(app.world().get::<ClothPinRule>(e).is_none());
    // Built again from its mesh: still the two corners.
    app.world_mut().get_mut::<Cloth>(e).unwrap().weld_tolerance = 1e-5;
    run(&mut app, 20);
    assert_eq!(sim(&app, e).simulation().state().pins().len(), 2);
    assert_eq!(app.world().get::<ClothPins>(e).unwrap().0.len(), 2);
}

/// "add mesh cloth": a flat glTF mesh (the banner of `assets/banner_statue.gltf`, modelled
/// lying in its xz plane) becomes cloth once it has loaded, stood up and hung by its top edge
/// through a `ClothPinRule`; a scene file keeps its asset path.
#[test]
fn a_cloth_from_a_mesh_file_hangs_by_its_top_edge() {
    let mut app = common::app();
    common::add_gltf(&mut app, ClothEditorPlugin::default());
    let path = "banner_statue.gltf#Mesh1/Primitive0";
    let e = actions::add_mesh_cloth(app.world_mut(), path).unwrap();
    wait_for(&mut app, "the banner to become cloth", |w| {
        w.get::<ClothSim>(e).is_some()
    });
    let status = app.world().resource::<ClothEditor>().status.clone();
    assert!(status.contains("hung by its top edge"), "{status}");
    assert!(app.world().get::<ClothPinRule>(e).is_some());
    // Tethered, as a mesh made elsewhere (often far finer than a grid) needs to hang at its
    // size at the default substeps.
    assert!(app.world().get::<ClothTethers>(e).is_some());
    run(&mut app, 90);
    let s = sim(&app, e);
    let pins = &app.world().get::<ClothPins>(e).unwrap().0;
    // One row of the 33 × 33 banner (and the seam's copy on it).
    assert!((33..=34).contains(&pins.len()), "{} pins", pins.len());
    // Its -z edge is on top, 0.65 m (half the banner) above where it was put (1.5 m), and
    // the rest hangs below it.
    for pin in pins {
        let y = s.position(pin.vertex).y;
        assert!(
            (y - 2.15).abs() < 1e-4,
            "pinned vertex {} at {y}",
            pin.vertex
        );
    }
    let n = s.weld().vertex_count() as u32;
    let lowest = (0..n).map(|v| s.position(v).y).fold(f32::MAX, f32::min);
    assert!(lowest < 1.0, "lowest point {lowest}: not hanging");
    let saved = scene::save_scene(app.world_mut());
    assert_eq!(saved.cloths.len(), 1);
    assert_eq!(
        saved.cloths[0].mesh,
        scene::SavedMesh::Asset(path.to_string())
    );
    let e = actions::add_mesh_cloth(app.world_mut(), "cape.fbx").unwrap_err();
    assert!(
        e.contains("a cloth is read from a .gltf, .glb or .obj"),
        "{e}"
    );
}
