//! The plugin in a headless `MinimalPlugins` app: no window, no GPU.

use std::time::Duration;

use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;
use bevy_cloth::foundation::MeshError;
use bevy_cloth::prelude::*;

mod common;
use common::{app_with_frame, run};

const GRID: Grid = Grid {
    columns: 16,
    rows: 16,
    width: 1.0,
    height: 1.0,
};

fn spawn_cloth(app: &mut App, transform: Transform) -> (Entity, Handle<Mesh>) {
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&GRID));
    let e = app
        .world_mut()
        .spawn((
            Mesh3d(mesh.clone()),
            transform,
            Cloth::default(),
            ClothPins::rest([GRID.index(0, 0), GRID.index(15, 0)]),
        ))
        .id();
    (e, mesh)
}

fn sim(app: &App, e: Entity) -> &ClothSim {
    app.world()
        .get::<ClothSim>(e)
        .expect("cloth was not created")
}

fn positions(app: &App, handle: &Handle<Mesh>) -> Vec<[f32; 3]> {
    let mesh = app.world().resource::<Assets<Mesh>>().get(handle).unwrap();
    match mesh.attribute(Mesh::ATTRIBUTE_POSITION) {
        Some(VertexAttributeValues::Float32x3(p)) => p.clone(),
        _ => panic!("no positions"),
    }
}

#[test]
fn a_pinned_cloth_sags_and_its_mesh_is_rewritten() {
    let mut app = app_with_frame(Duration::from_secs_f64(1.0 / 60.0));
    let lift = Transform::from_xyz(0.0, 2.0, 0.0);
    let (e, source) = spawn_cloth(&mut app, lift);
    run(&mut app, 90);

    let s = sim(&app, e);
    assert!(s.steps() > 80, "{} steps", s.steps());
    let state = s.simulation().state();
    assert_eq!(state.non_finite_count(), 0);
    // Pins stay at their rest positions, carried by the entity's transform.
    for v in [GRID.index(0, 0), GRID.index(15, 0)] {
        let rest = lift.transform_point(GRID.positions()[v as usize]);
        assert!((state.position(v as usize) - rest).length() < 1e-5);
    }
    // The free edge fell well below the pins.
    let far = state.position(GRID.index(8, 15) as usize);
    assert!(far.y < 2.0 - 0.4, "far edge at {far}");
    assert!(s.simulation().strain().max < 0.5);

    // The entity now draws its own copy of the mesh, rewritten in local space.
    let own = app.world().get::<Mesh3d>(e).unwrap().0.clone();
    assert_ne!(own, source);
    let written = positions(&app, &own);
    let local_far = written[GRID.index(8, 15) as usize];
    assert!((local_far[1] - (far.y - 2.0)).abs() < 1e-5);
    // The source mesh is untouched.
    let original = positions(&app, &source);
    assert_eq!(original[GRID.index(8, 15) as usize][1], 0.0);
    // Normals and tangents were recomputed: the hanging cloth no longer faces +Y everywhere.
    let mesh = app.world().resource::<Assets<Mesh>>().get(&own).unwrap();
    let Some(VertexAttributeValues::Float32x3(normals)) = mesh.attribute(Mesh::ATTRIBUTE_NORMAL)
    else {
        panic!("no normals")
    };
    assert!(normals.iter().any(|n| n[1] < 0.9));
    assert!(
        normals
            .iter()
            .all(|n| (Vec3::from(*n).length() - 1.0).abs() < 1e-4)
    );
    let Some(VertexAttributeValues::Float32x4(tangents)) = mesh.attribute(Mesh::ATTRIBUTE_TANGENT)
    else {
        panic!("no tangents")
    };
    assert!(tangents.iter().any(|t| t[0] < 0.99));
}

#[test]
fn many_cloths_written_back_together_each_draw_their_own_state() {
    // Cloths of different sizes, turned, scaled and mirrored, written back in the same frame
    // (their normals and local vertices computed in parallel on the plugin's workers): each
    // mesh shows its own cloth, in its own entity's space, with unit normals.
    let mut app = app_with_frame(Duration::from_secs_f64(1.0 / 60.0));
    let mut cloths = Vec::new();
    for k in 0..7u32 {
        let g = Grid {
            columns: 6 + 3 * k,
            rows: 5 + 2 * k,
            width: 0.5 + 0.2 * k as f32,
            height: 0.8,
        };
        let mesh = app
            .world_mut()
            .resource_mut::<Assets<Mesh>>()
            .add(grid_mesh(&g));
        let mut transform = Transform::from_xyz(3.0 * k as f32, 2.0, -(k as f32))
            .with_rotation(Quat::from_rotation_y(0.4 * k as f32))
            .with_scale(Vec3::splat(0.8 + 0.1 * k as f32));
        if k % 3 == 2 {
            transform.scale.x = -transform.scale.x;
        }
        let e = app
            .world_mut()
            .spawn((
                Mesh3d(mesh),
                transform,
                Cloth::default(),
                ClothPins::rest([g.index(0, 0), g.index(g.columns - 1, 0)]),
            ))
            .id();
        cloths.push((e, transform));
    }
    run(&mut app, 40);
    for (e, transform) in cloths {
        let s = sim(&app, e);
        let own = app.world().get::<Mesh3d>(e).unwrap().0.clone();
        assert_eq!(&own, s.mesh());
        let written = positions(&app, &own);
        let state = s.simulation().state();
        let weld = s.weld();
        assert_eq!(written.len(), weld.particles().len());
        let to_local = transform.compute_affine().inverse();
        let mut moved = 0.0f32;
        for (v, (w, &p)) in written.iter().zip(weld.particles()).enumerate() {
            let expect = to_local.transform_point3(state.position(p as usize));
            let error = (Vec3::from(*w) - expect).length();
            assert!(
                error < 1e-4,
                "{e}: vertex {v} drawn {w:?}, simulated {expect}"
            );
            moved = moved.max((Vec3::from(*w) - s.rest_shape()[p as usize]).length());
        }
        assert!(moved > 0.05, "{e}: the cloth hung down ({moved} m at most)");
        let mesh = app.world().resource::<Assets<Mesh>>().get(&own).unwrap();
        let Some(VertexAttributeValues::Float32x3(normals)) =
            mesh.attribute(Mesh::ATTRIBUTE_NORMAL)
        else {
            panic!("no normals")
        };
        assert_eq!(normals.len(), written.len());
        assert!(
            normals
                .iter()
                .all(|n| (Vec3::from(*n).length() - 1.0).abs() < 1e-4)
        );
    }
}

#[test]
fn frame_rate_does_not_change_the_result() {
    // Same fixed rate, frames of 1/144 s against 1/25 s: after the same number of fixed steps
    // the cloths must be bit-identical.
    let mut fast = app_with_frame(Duration::from_secs_f64(1.0 / 144.0));
    let mut slow = app_with_frame(Duration::from_secs_f64(1.0 / 25.0));
    let (ef, _) = spawn_cloth(&mut fast, Transform::IDENTITY);
    let (es, _) = spawn_cloth(&mut slow, Transform::IDENTITY);
    run(&mut slow, 30);
    let n = sim(&slow, es).steps();
    assert!(n > 60, "{n}");
    let steps = |app: &App| app.world().get::<ClothSim>(ef).map_or(0, |s| s.steps());
    while steps(&fast) < n {
        fast.update();
    }
    assert_eq!(sim(&fast, ef).steps(), n);
    let a = &sim(&fast, ef).simulation().state().positions;
    let b = &sim(&slow, es).simulation().state().positions;
    assert!(a.iter().zip(b).all(|(p, q)| p.to_array() == q.to_array()));
}

#[test]
fn bad_cloths_are_reported_and_others_keep_running() {
    let mut app = app_with_frame(Duration::from_secs_f64(1.0 / 60.0));
    let (good, _) = spawn_cloth(&mut app, Transform::IDENTITY);
    let lines = Mesh::new(
        bevy::mesh::PrimitiveTopology::LineList,
        bevy::asset::RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 2]);
    let lines = app.world_mut().resource_mut::<Assets<Mesh>>().add(lines);
    let grid = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&GRID));
    let not_triangles = app
        .world_mut()
        .spawn((Mesh3d(lines), Cloth::default()))
        .id();
    let bad_mass = app
        .world_mut()
        .spawn((
            Mesh3d(grid.clone()),
            Cloth {
                mass: f32::NAN,
                ..default()
            },
        ))
        .id();
    let bad_pin = app
        .world_mut()
        .spawn((
            Mesh3d(grid.clone()),
            Cloth::default(),
            ClothPins::rest([9999]),
        ))
        .id();
    let bad_config = app
        .world_mut()
        .spawn((
            Mesh3d(grid),
            Cloth::default(),
            ClothConfig {
                substeps: 0,
                ..default()
            },
        ))
        .id();
    run(&mut app, 10);
    let err = |e| app.world().get::<ClothInvalid>(e).map(|i| i.0.clone());
    assert!(matches!(
        err(not_triangles),
        Some(ClothError::Mesh(MeshError::NotTriangleList(_)))
    ));
    assert!(matches!(err(bad_mass), Some(ClothError::BadMass(m)) if m.is_nan()));
    assert!(
        matches!(err(bad_pin), Some(ClothError::Solver(_))),
        "{:?}",
        err(bad_pin)
    );
    assert!(err(bad_pin).unwrap().to_string().contains("9999"));
    assert!(err(bad_config).unwrap().to_string().contains("substeps"));
    for e in [not_triangles, bad_mass, bad_pin, bad_config] {
        assert!(app.world().get::<ClothSim>(e).is_none());
    }
    assert!(sim(&app, good).steps() > 5);
    assert!(app.world().get::<ClothInvalid>(good).is_none());

    // Fixing the config makes the cloth run.
    app.world_mut()
        .get_mut::<ClothConfig>(bad_config)
        .unwrap()
        .substeps = 4;
    run(&mut app, 5);
    assert!(app.world().get::<ClothInvalid>(bad_config).is_none());
    assert!(sim(&app, bad_config).steps() > 0);
}

#[test]
fn pins_change_at_runtime_and_follow_entities() {
    let mut app = app_with_frame(Duration::from_secs_f64(1.0 / 60.0));
    let (e, _) = spawn_cloth(&mut app, Transform::IDENTITY);
    let corner = GRID.positions()[0];
    let hand = app
        .world_mut()
        .spawn(Transform::from_translation(corner))
        .id();
    run(&mut app, 5);

    // Re-pin: one corner to a moving entity, everything else free.
    app.world_mut()
        .entity_mut(e)
        .insert(ClothPins(vec![ClothPin {
            vertex: 0,
            anchor: PinAnchor::Entity {
                entity: hand,
                offset: Vec3::ZERO,
            },
        }]));
    for k in 0..60 {
        app.world_mut()
            .get_mut::<Transform>(hand)
            .unwrap()
            .translation = corner + Vec3::new(0.02 * k as f32, 0.0, 0.0);
        app.update();
    }
    let hand_at = app
        .world()
        .get::<GlobalTransform>(hand)
        .unwrap()
        .translation();
    let s = sim(&app, e);
    assert_eq!(s.simulation().state().pins().len(), 1);
    // The pin lags its anchor by at most one frame of motion.
    assert!((s.simulation().state().position(0) - hand_at).length() < 0.05);
    // The formerly pinned corner fell.
    assert!(
        s.simulation()
            .state()
            .position(GRID.index(15, 0) as usize)
            .y
            < -0.3
    );

    // Moving the cloth entity carries `Rest` pins.
    app.world_mut()
        .entity_mut(e)
        .insert(ClothPins::rest([GRID.index(0, 0)]));
    app.world_mut().get_mut::<Transform>(e).unwrap().translation = Vec3::new(0.0, 3.0, 0.0);
    run(&mut app, 10);
    let p = sim(&app, e).simulation().state().position(0);
    let expect = GRID.positions()[0] + Vec3::new(0.0, 3.0, 0.0);
    assert!((p - expect).length() < 1e-4, "{p} vs {expect}");
}

#[test]
fn config_changes_apply_without_rebuild() {
    let mut app = app_with_frame(Duration::from_secs_f64(1.0 / 60.0));
    let (e, _) = spawn_cloth(&mut app, Transform::IDENTITY);
    run(&mut app, 3);
    app.world_mut().get_mut::<ClothConfig>(e).unwrap().gravity = Vec3::ZERO;
    app.world_mut().get_mut::<ClothConfig>(e).unwrap().substeps = 3;
    run(&mut app, 2);
    let params = *sim(&app, e).simulation().params();
    assert_eq!(params.gravity, Vec3::ZERO);
    assert_eq!(params.substeps, 3);
}

#[test]
fn velvet_plugin_in_a_headless_app_adds_nothing_and_cloth_still_runs() {
    // No renderer: the plugin logs and steps aside instead of panicking, so one plugin list
    // serves windowed and headless builds.
    let mut app = common::app();
    app.add_plugins(VelvetPlugin);
    let (e, _) = spawn_cloth(&mut app, Transform::default());
    common::run(&mut app, 10);
    assert!(
        app.world()
            .get_resource::<Assets<VelvetMaterial>>()
            .is_none()
    );
    assert!(sim(&app, e).steps() > 0);
}
