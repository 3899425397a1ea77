//! Colliders, wind, tearing, teleports and (with `rapier`) two-way coupling, through the
//! plugin in a headless app.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

mod common;
use common::{app, run};

fn spawn_sheet(app: &mut App, n: u32, transform: Transform, extra: impl Bundle) -> Entity {
    let grid = Grid::new(n, n, 1.0, 1.0);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(grid_mesh(&grid));
    app.world_mut()
        .spawn((Mesh3d(mesh), transform, Cloth::default(), extra))
        .id()
}

fn sim(app: &App, e: Entity) -> &ClothSim {
    app.world().get::<ClothSim>(e).expect("cloth not created")
}

#[test]
fn a_cloth_drapes_over_a_sphere_and_the_sphere_feels_its_weight() {
    let mut app = app();
    let ball = app
        .world_mut()
        .spawn((
            ClothCollider::sphere(0.3).with_thickness(0.02),
            Transform::default(),
        ))
        .id();
    let cloth = spawn_sheet(&mut app, 20, Transform::from_xyz(0.0, 0.5, 0.0), ());
    run(&mut app, 240);
    let s = sim(&app, cloth).simulation().state();
    let lowest_inside = (0..s.len())
        .map(|i| s.position(i).length() - 0.3)
        .fold(f32::MAX, f32::min);
    assert!(
        lowest_inside > 0.0,
        "a vertex is inside the sphere: {lowest_inside}"
    );
    // The draped cloth rests on the sphere: per step, the sphere receives about the weight of
    // the part of the cloth it carries, pointing down.
    let impulse = app.world().get::<ClothContactImpulse>(ball).unwrap().linear;
    let weight_per_step = 0.2 * 9.81 / 60.0;
    assert!(impulse.y < -0.2 * weight_per_step, "{impulse}");
    assert!(impulse.y > -1.5 * weight_per_step, "{impulse}");
}

/// Where the middle of a 16 × 16 sheet dropped from `drop_y` onto a 1 × 0.4 × 1 m box mesh
/// ends up after two seconds; `collider` makes the box's collider from its mesh handle.
fn middle_on_a_box_mesh(
    collider: impl FnOnce(Handle<Mesh>) -> (ClothCollider, Option<Mesh3d>),
    at: Vec3,
    drop_y: f32,
) -> Vec3 {
    let mut app = app();
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(Cuboid::new(1.0, 0.4, 1.0).mesh().build());
    let (collider, mesh3d) = collider(mesh);
    let mut e = app.world_mut().spawn((
        collider.with_thickness(0.02),
        Transform::from_translation(at),
    ));
    if let Some(m) = mesh3d {
        e.insert(m);
    }
    let cloth = spawn_sheet(&mut app, 16, Transform::from_xyz(0.0, drop_y, 0.0), ());
    run(&mut app, 120);
    sim(&app, cloth).simulation().state().position(8 * 16 + 8)
}

#[test]
fn mesh_colliders_are_baked_from_the_entity_mesh() {
    let middle = middle_on_a_box_mesh(
        |m| (ClothCollider::mesh(24), Some(Mesh3d(m))),
        Vec3::ZERO,
        0.6,
    );
    // The middle of the sheet rests on the top face (y = 0.2 + thickness), not below it.
    assert!(middle.y > 0.2 && middle.y < 0.3, "{middle}");
}

/// A collider entity with no mesh of its own bakes the mesh it names (as a glTF primitive
/// loaded by its label would be), placed by its own transform.
#[test]
fn a_mesh_collider_bakes_the_mesh_asset_it_names() {
    let at = Vec3::new(0.0, 0.1, 0.0);
    let middle = middle_on_a_box_mesh(|m| (ClothCollider::mesh_asset(m, 24), None), at, 0.7);
    // On the top face (y = 0.1 + 0.2 + thickness).
    assert!(middle.y > 0.3 && middle.y < 0.4, "{middle}");
}

/// Bevy's solids, whose vertices are split along UV seams and hard edges, bake as closed
/// meshes (cloth is kept outside, by ray parity, as deep as they go); its sheets and open
/// shapes bake as open ones (cloth kept on the side they face).
#[test]
fn bevy_solids_bake_closed_and_bevy_sheets_open() {
    use bevy_cloth::foundation::read_mesh;
    use bevy_cloth::solver::SdfGrid;
    let open = |mesh: Mesh| {
        let data = read_mesh(&mesh).expect("a Bevy mesh reads");
        SdfGrid::from_mesh(&data.positions, &data.indices, 32)
            .expect("bakes")
            .is_open()
    };
    let solids: [(&str, Mesh); 7] = [
        ("uv sphere", Sphere::new(0.5).mesh().uv(32, 18)),
        ("ico sphere", Sphere::new(0.5).mesh().ico(4).unwrap()),
        ("cuboid", Cuboid::new(1.0, 0.4, 0.7).mesh().build()),
        ("capsule", Capsule3d::new(0.2, 0.8).mesh().build()),
        ("torus", Torus::new(0.3, 0.6).mesh().build()),
        ("cylinder", Cylinder::new(0.3, 1.0).mesh().build()),
        ("cone", Cone::new(0.4, 0.9).mesh().build()),
    ];
    for (name, mesh) in solids {
        assert!(!open(mesh), "{name} baked as open");
    }
    let sheets: [(&str, Mesh); 3] = [
        ("plane", Plane3d::default().mesh().subdivisions(8).build()),
        (
            "uncapped cylinder",
            Cylinder::new(0.3, 1.0).mesh().without_caps().build(),
        ),
        ("the cloth grid", grid_mesh(&Grid::new(8, 8, 1.0, 1.0))),
    ];
    for (name, mesh) in sheets {
        assert!(open(mesh), "{name} baked as closed");
    }
}

/// Bevy's closed solids with a hub (the capped `Cylinder` and the `ConicalFrustum`, their
/// caps fanned from one rim vertex; the `Cone`, its tip and base) as cloths, tilted and
/// dropped 1.5 m onto a ground plane: after five seconds each lies still on the ground in one
/// piece. Swept forward only (before `SYMMETRIC_SWEEP_DEGREE`), each shook itself apart in
/// the air at 35–100 m/s, its edges two to six times their length.
#[test]
fn bevy_solids_with_a_hub_fall_and_rest_in_one_piece() {
    let solids: [(&str, Mesh); 3] = [
        ("cylinder", Cylinder::new(0.3, 1.0).mesh().build()),
        ("cone", Cone::new(0.4, 0.9).mesh().build()),
        (
            "conical frustum",
            ConicalFrustum {
                radius_top: 0.2,
                radius_bottom: 0.5,
                height: 0.8,
            }
            .mesh()
            .build(),
        ),
    ];
    for (name, mesh) in solids {
        let mut app = app();
        let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
        let e = app
            .world_mut()
            .spawn((
                Mesh3d(mesh),
                Transform::from_xyz(0.0, 1.5, 0.0).with_rotation(Quat::from_rotation_z(0.3)),
                Cloth::default(),
            ))
            .id();
        app.world_mut()
            .spawn((ClothCollider::plane(), Transform::IDENTITY));
        // The cloth is built in the first frame.
        run(&mut app, 1);
        let mut fastest = 0.0f32;
        let mut stretch = 0.0f32;
        for _ in 0..300 {
            run(&mut app, 1);
            let c = sim(&app, e);
            let s = c.simulation().state();
            let mean = (0..s.len()).map(|i| s.velocity(i)).sum::<Vec3>() / s.len() as f32;
            fastest = fastest.max(
                (0..s.len())
                    .map(|i| (s.velocity(i) - mean).length())
                    .fold(0.0, f32::max),
            );
            stretch = stretch.max(c.max_strain());
        }
        let c = sim(&app, e);
        let s = c.simulation().state();
        let speed = (0..s.len())
            .map(|i| s.velocity(i).length())
            .fold(0.0, f32::max);
        let low = (0..s.len())
            .map(|i| s.position(i).y)
            .fold(f32::MAX, f32::min);
        assert!(
            fastest < 5.0 && stretch < 0.1,
            "{name}: vertices {fastest} m/s apart, edges {stretch} longer"
        );
        assert!(speed < 0.1, "{name}: still moving at {speed} m/s");
        assert!(
            (0.0..0.05).contains(&low),
            "{name}: lowest vertex at {low} m"
        );
    }
}

#[test]
fn wind_resource_pushes_the_cloth_and_zones_only_act_inside() {
    let mut calm = app();
    let mut windy = app();
    windy.insert_resource(Wind(WindParams {
        velocity: Vec3::new(0.0, 0.0, -10.0),
        ..default()
    }));
    let mut zoned = app();
    zoned.world_mut().spawn((
        WindZone {
            wind: WindParams {
                velocity: Vec3::new(0.0, 0.0, -10.0),
                ..default()
            },
            half_extents: Vec3::splat(0.5),
            falloff: 0.0,
        },
        Transform::from_xyz(50.0, 0.0, 0.0),
    ));
    let pins = ClothPins::rest(0..16);
    let upright = Transform::from_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let c = spawn_sheet(&mut calm, 16, upright, pins.clone());
    let w = spawn_sheet(&mut windy, 16, upright, pins.clone());
    let z = spawn_sheet(&mut zoned, 16, upright, pins);
    run(&mut calm, 90);
    run(&mut windy, 90);
    run(&mut zoned, 90);
    let mean_z = |app: &App, e| {
        let s = sim(app, e).simulation().state();
        (0..s.len()).map(|i| s.position(i).z).sum::<f32>() / s.len() as f32
    };
    assert!(mean_z(&windy, w) < mean_z(&calm, c) - 0.1);
    // The zone is 50 m away: the cloth there behaves as if calm.
    assert!((mean_z(&zoned, z) - mean_z(&calm, c)).abs() < 1e-4);
}

#[test]
fn tearing_sends_messages_and_shrinks_the_index_buffer() {
    let mut app = app();
    let grid = Grid::new(10, 10, 1.0, 1.0);
    let left = app.world_mut().spawn(Transform::default()).id();
    let right = app.world_mut().spawn(Transform::default()).id();
    let rest = grid.positions();
    let mut pins = ClothPins::default();
    for j in 0..10 {
        for (i, hand) in [(0, left), (9, right)] {
            let v = grid.index(i, j);
            pins = pins.with(
                v,
                PinAnchor::Entity {
                    entity: hand,
                    offset: rest[v as usize],
                },
            );
        }
    }
    let cloth = spawn_sheet(
        &mut app,
        10,
        Transform::default(),
        (pins, ClothTearing { threshold: 1.4 }),
    );
    run(&mut app, 5);
    let triangles_before = 2 * 9 * 9 * 3;
    for f in 0..90 {
        let x = 0.01 * f as f32;
        app.world_mut()
            .get_mut::<Transform>(left)
            .unwrap()
            .translation
            .x = -x;
        app.world_mut()
            .get_mut::<Transform>(right)
            .unwrap()
            .translation
            .x = x;
        app.update();
    }
    let torn: usize = app
        .world()
        .resource::<Messages<ClothTorn>>()
        .iter_current_update_messages()
        .count()
        + sim(&app, cloth).torn_edges();
    assert!(torn > 0, "nothing tore");
    let mesh_handle = &app.world().get::<Mesh3d>(cloth).unwrap().0;
    let mesh = app
        .world()
        .resource::<Assets<Mesh>>()
        .get(mesh_handle)
        .unwrap();
    let indices = mesh.indices().unwrap();
    assert!(indices.len() < triangles_before);
    assert!(indices.iter().all(|i| i < 100));
    assert_eq!(
        indices.len(),
        3 * sim(&app, cloth).simulation().topology().triangles().len()
    );
}

#[test]
fn teleporting_the_anchor_moves_the_cloth_instead_of_tearing_it_apart() {
    let mut app = app();
    let hand = app.world_mut().spawn(Transform::default()).id();
    let pins = ClothPins(vec![ClothPin {
        vertex: 0,
        anchor: PinAnchor::Entity {
            entity: hand,
            offset: Grid::new(12, 12, 1.0, 1.0).positions()[0],
        },
    }]);
    let cloth = spawn_sheet(&mut app, 12, Transform::default(), pins);
    run(&mut app, 60);
    app.world_mut()
        .get_mut::<Transform>(hand)
        .unwrap()
        .translation = Vec3::new(1000.0, 0.0, 0.0);
    run(&mut app, 3);
    let s = sim(&app, cloth).simulation();
    assert_eq!(s.state().non_finite_count(), 0);
    assert!(s.strain().max < 0.5, "strain {}", s.strain().max);
    let centre = (0..s.state().len())
        .map(|i| s.state().position(i))
        .sum::<Vec3>()
        / 144.0;
    assert!(centre.x > 990.0, "{centre}");
    // No explosion: vertices move at ordinary speeds after the jump.
    let fastest = (0..144)
        .map(|i| s.state().velocity(i).length())
        .fold(0.0, f32::max);
    assert!(fastest < 20.0, "{fastest} m/s");
}

/// A 20 × 20 curtain, 2 m wide, hanging in the XY plane from a rail at y = 2.
#[cfg(any(feature = "avian", feature = "rapier"))]
fn curtain(app: &mut App) -> Entity {
    let grid = Grid::new(20, 20, 2.0, 2.0);
    let upright = Transform::from_xyz(0.0, 1.0, 0.0)
        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    spawn_sheet(
        app,
        20,
        upright,
        ClothPins::rest((0..20).map(|i| grid.index(i, 0))),
    )
}

/// A 1.2 m hammock of 20 × 20 vertices at y = 1, held along its two x edges.
#[cfg(any(feature = "avian", feature = "rapier"))]
fn hammock(app: &mut App) -> Entity {
    let grid = Grid::new(20, 20, 1.2, 1.2);
    let edges: Vec<_> = (0..20)
        .flat_map(|j| [grid.index(0, j), grid.index(19, j)])
        .collect();
    spawn_sheet(
        app,
        20,
        Transform::from_xyz(0.0, 1.0, 0.0),
        ClothPins::rest(edges),
    )
}

/// How deep the deepest cloth vertex is inside the 0.3 × 0.1 × 0.3 box `body` (0 if none is).
#[cfg(any(feature = "avian", feature = "rapier"))]
fn deepest_in_box(app: &App, cloth: Entity, body: Entity) -> f32 {
    let to_local = app
        .world()
        .get::<Transform>(body)
        .unwrap()
        .to_matrix()
        .inverse();
    let s = sim(app, cloth).simulation().state();
    let half = Vec3::new(0.15, 0.05, 0.15);
    (0..s.len())
        .map(|i| half - to_local.transform_point3(s.position(i)).abs())
        .filter(|d| d.min_element() > 0.0)
        .map(|d| d.min_element())
        .fold(0.0, f32::max)
}

#[cfg(any(feature = "avian", feature = "rapier"))]
fn lowest(app: &App, cloth: Entity) -> f32 {
    let s = sim(app, cloth).simulation().state();
    (0..s.len())
        .map(|i| s.position(i).y)
        .fold(f32::MAX, f32::min)
}

/// The box `body`, dropped from 0.3 m above the `hammock`, lies in it: after two seconds to
/// land, over the next two (free fall would take it 20 m down) it stays above 0.6 m with no
/// cloth vertex inside it, does not sink, and is not thrown about (it may still sway).
#[cfg(any(feature = "avian", feature = "rapier"))]
fn assert_lies_in_the_hammock(app: &mut App, hammock: Entity, body: Entity) {
    let y_of = |app: &App| app.world().get::<Transform>(body).unwrap().translation;
    run(app, 120);
    let start = y_of(app);
    let (mut lowest_box, mut fastest, mut last) = (f32::MAX, 0.0f32, start);
    for _ in 0..120 {
        app.update();
        let p = y_of(app);
        lowest_box = lowest_box.min(p.y);
        fastest = fastest.max((p - last).length() * 60.0);
        last = p;
        let depth = deepest_in_box(app, hammock, body);
        assert!(depth < 0.02, "cloth {depth} m inside the box");
    }
    assert!(lowest_box > 0.6, "the box sank through: y = {lowest_box}");
    assert!(fastest < 0.5, "the box is thrown about: {fastest} m/s");
    assert!(
        (last.y - start.y).abs() < 0.03,
        "the box moved from {start} to {last}"
    );
    let low = lowest(app, hammock);
    assert!(low < 0.97, "the hammock does not sag: {low}");
}

/// Hills the same along x and along z (so that a height field's row order does not matter).
#[cfg(any(feature = "avian", feature = "rapier"))]
fn hills(x: f32, z: f32) -> f32 {
    0.2 * (2.0 * x).sin() * (2.0 * z).sin() + 0.05 * (x + z)
}

/// The [`hills`] over 4 × 4 m sampled 33 × 33 times (x and z from −2 to 2).
#[cfg(any(feature = "avian", feature = "rapier"))]
fn hill_heights() -> Vec<Vec<f32>> {
    let at = |i: usize| -2.0 + 4.0 * i as f32 / 32.0;
    (0..33)
        .map(|i| (0..33).map(|j| hills(at(i), at(j))).collect())
        .collect()
}

/// A 24 × 24 cloth dropped 1 m over the [`hills`] of a height field placed at `at` lies on
/// them after four seconds (the field's facets lie within 2 mm of the hills).
#[cfg(any(feature = "avian", feature = "rapier"))]
fn assert_lies_on_the_hills(app: &mut App, at: Vec3) {
    let drop = Transform::from_translation(at + Vec3::new(0.2, 1.0, -0.3));
    common::assert_lies_on_the_ground(app, at, hills, drop);
}

#[cfg(feature = "rapier")]
mod rapier {
    use super::*;
    use bevy_rapier3d::prelude::*;

    #[test]
    fn cloth_pushes_a_rapier_ball_back_with_the_opposite_impulse() {
        let mut app = app();
        app.add_plugins((
            RapierPhysicsPlugin::<NoUserData>::default(),
            ClothRapierPlugin::default(),
        ));
        // A curtain pinned along its top, a ball flying into it with gravity off.
        let curtain = curtain(&mut app);
        let speed = 5.0;
        let ball = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::ball(0.2),
                ColliderMassProperties::Mass(0.5),
                GravityScale(0.0),
                Velocity::linear(Vec3::new(0.0, 0.0, -speed)),
                Transform::from_xyz(0.0, 1.0, 1.0),
            ))
            .id();
        let mut total = Vec3::ZERO;
        let mut bulge = 0.0f32;
        for _ in 0..60 {
            app.update();
            if let Some(i) = app.world().get::<ClothContactImpulse>(ball) {
                total += i.linear;
            }
            if let Some(c) = app.world().get::<ClothSim>(curtain) {
                let s = c.simulation().state();
                bulge = (0..s.len()).map(|i| s.position(i).z).fold(bulge, f32::min);
            }
        }
        // The bridge mirrored the rapier ball as a cloth collider.
        assert!(app.world().get::<ClothCollider>(ball).is_some());
        // The curtain bulged, and the ball slowed down.
        assert!(bulge < -0.2, "curtain did not bulge: {bulge}");
        let v = app.world().get::<Velocity>(ball).unwrap().linear;
        assert!(v.z > -speed * 0.95, "ball not slowed: {v}");
        // Equal and opposite: what the cloth pushed on the ball (it points +z, against the
        // motion) matches the ball's momentum change within rapier's integration error.
        assert!(total.z > 0.0, "{total}");
        let dp = 0.5 * (v.z - (-speed));
        assert!(
            (dp - total.z).abs() < 0.25 * total.z.abs().max(0.05),
            "Δp {dp} vs impulse {total}"
        );
    }

    #[test]
    fn a_rapier_body_lying_on_cloth_is_held_up() {
        let mut app = app();
        // On the cloth's clock, as the README says: rapier steps in FixedUpdate, the cloth
        // after it, so both see the box where this step left it.
        app.insert_resource(TimestepMode::Fixed {
            dt: 1.0 / 60.0,
            substeps: 1,
        })
        .add_plugins((
            RapierPhysicsPlugin::<NoUserData>::default().in_fixed_schedule(),
            ClothRapierPlugin::default(),
        ));
        let hammock = hammock(&mut app);
        let body = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::cuboid(0.15, 0.05, 0.15),
                ColliderMassProperties::Mass(0.5),
                Velocity::zero(),
                Transform::from_xyz(0.0, 1.3, 0.0),
            ))
            .id();
        assert_lies_in_the_hammock(&mut app, hammock, body);
    }

    /// A rapier height field (a terrain) holds cloth up on the side it faces.
    #[test]
    fn a_cloth_dropped_on_a_rapier_height_field_lies_on_it() {
        let mut app = app();
        app.add_plugins((
            RapierPhysicsPlugin::<NoUserData>::default(),
            ClothRapierPlugin::default(),
        ));
        let rows = hill_heights();
        // Column-major: one column after another (the hills are the same either way).
        let heights: Vec<f32> = rows.iter().flatten().copied().collect();
        let at = Vec3::new(0.4, -1.0, 0.0);
        app.world_mut().spawn((
            RigidBody::Fixed,
            Collider::heightfield(heights, 33, 33, Vec3::new(4.0, 1.0, 4.0)),
            Transform::from_translation(at),
        ));
        assert_lies_on_the_hills(&mut app, at);
    }

    /// Removing a rapier collider (or despawning its entity) removes the cloth collider the
    /// bridge mirrored from it: nothing keeps pushing cloth where the body was.
    #[test]
    fn a_removed_rapier_collider_leaves_no_cloth_collider() {
        let mut app = app();
        app.add_plugins((
            RapierPhysicsPlugin::<NoUserData>::default(),
            ClothRapierPlugin::default(),
        ));
        let kept = app
            .world_mut()
            .spawn((RigidBody::Fixed, Collider::ball(0.2), Transform::default()))
            .id();
        let gone = app
            .world_mut()
            .spawn((RigidBody::Fixed, Collider::ball(0.2), Transform::default()))
            .id();
        run(&mut app, 2);
        assert!(app.world().get::<ClothCollider>(kept).is_some());
        let colliders = app
            .world()
            .resource::<bevy_cloth::collider::ClothColliders>();
        assert_eq!(colliders.entities.len(), 2);
        app.world_mut().entity_mut(kept).remove::<Collider>();
        app.world_mut().entity_mut(gone).despawn();
        run(&mut app, 2);
        assert!(app.world().get::<ClothCollider>(kept).is_none());
        let colliders = app
            .world()
            .resource::<bevy_cloth::collider::ClothColliders>();
        assert!(colliders.entities.is_empty(), "{:?}", colliders.entities);
    }

    /// `ClothPlugins::new(schedule)` reaches the rapier bridge whichever was added first: here
    /// the bridge comes first and cloth runs in `FixedLast`, finished as `App::run` does.
    #[test]
    fn the_bridge_runs_in_the_schedule_the_cloth_plugins_were_given() {
        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            TransformPlugin,
            AssetPlugin::default(),
            bevy::mesh::MeshPlugin,
            RapierPhysicsPlugin::<NoUserData>::default(),
            ClothRapierPlugin::default(),
            ClothPlugins::new(FixedLast),
        ))
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            std::time::Duration::from_secs_f64(1.0 / 60.0),
        ))
        .insert_resource(Time::<Fixed>::from_hz(60.0));
        app.finish();
        app.cleanup();
        curtain(&mut app);
        let ball = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::ball(0.2),
                ColliderMassProperties::Mass(0.5),
                GravityScale(0.0),
                Velocity::linear(Vec3::new(0.0, 0.0, -5.0)),
                Transform::from_xyz(0.0, 1.0, 1.0),
            ))
            .id();
        let mut total = Vec3::ZERO;
        for _ in 0..60 {
            app.update();
            if let Some(i) = app.world().get::<ClothContactImpulse>(ball) {
                total += i.linear;
            }
        }
        // Mirrored, touched, and pushed back.
        assert!(app.world().get::<ClothCollider>(ball).is_some());
        assert!(total.z > 0.0, "the cloth gave the ball no impulse: {total}");
        let v = app.world().get::<Velocity>(ball).unwrap().linear;
        assert!(v.z > -5.0 * 0.95, "ball not slowed: {v}");
    }
}

/// The avian bridge: the same scenes as the rapier bridge, plus a body lying on cloth and one
/// removed while it touches cloth.
#[cfg(feature = "avian")]
mod avian {
    use super::*;
    use avian3d::prelude::*;
    use bevy_cloth::collider::avian::FromAvianCollider;
    use bevy_cloth::collider::{ClothColliders, NoClothCollision};

    fn avian_app() -> App {
        let mut app = app();
        app.add_plugins((PhysicsPlugins::default(), ClothAvianPlugin::default()));
        // Avian sets up part of itself in `Plugin::finish` (as `App::run` calls it).
        app.finish();
        app.cleanup();
        app
    }

    /// The hammock scene with a 0.5 kg, 0.3 × 0.1 × 0.3 m avian box (avian's cuboid takes
    /// full lengths).
    fn box_on_hammock(app: &mut App) -> (Entity, Entity) {
        let hammock = hammock(app);
        let body = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::cuboid(0.3, 0.1, 0.3),
                Mass(0.5),
                Transform::from_xyz(0.0, 1.3, 0.0),
            ))
            .id();
        (hammock, body)
    }

    #[test]
    fn cloth_pushes_an_avian_ball_back_with_the_opposite_impulse() {
        let mut app = avian_app();
        let curtain = curtain(&mut app);
        let speed = 5.0;
        let ball = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::sphere(0.2),
                Mass(0.5),
                GravityScale(0.0),
                LinearVelocity(Vec3::new(0.0, 0.0, -speed)),
                Transform::from_xyz(0.0, 1.0, 1.0),
            ))
            .id();
        let mut total = Vec3::ZERO;
        let mut bulge = 0.0f32;
        for _ in 0..60 {
            app.update();
            if let Some(i) = app.world().get::<ClothContactImpulse>(ball) {
                total += i.linear;
            }
            if let Some(c) = app.world().get::<ClothSim>(curtain) {
                let s = c.simulation().state();
                bulge = (0..s.len()).map(|i| s.position(i).z).fold(bulge, f32::min);
            }
        }
        // Mirrored without a marker, as the bridge's own collider.
        assert!(app.world().get::<ClothCollider>(ball).is_some());
        assert!(app.world().get::<FromAvianCollider>(ball).is_some());
        // The curtain bulged, and the ball slowed down.
        assert!(bulge < -0.2, "curtain did not bulge: {bulge}");
        let v = app.world().get::<LinearVelocity>(ball).unwrap().0;
        assert!(v.z > -speed * 0.95, "ball not slowed: {v}");
        // Equal and opposite: the cloth's push on the ball (+z, against the motion) is the
        // ball's momentum change (avian applies impulses to the velocity at once; the last
        // step's impulse may not be applied yet when the loop ends).
        assert!(total.z > 0.0, "{total}");
        let dp = 0.5 * (v.z - (-speed));
        assert!(
            (dp - total.z).abs() < 0.25 * total.z.abs().max(0.05),
            "Δp {dp} vs impulse {total}"
        );
    }

    #[test]
    fn an_avian_body_lying_on_cloth_is_held_up() {
        let mut app = avian_app();
        let (hammock, body) = box_on_hammock(&mut app);
        assert_lies_in_the_hammock(&mut app, hammock, body);
    }

    /// An avian height field (a terrain) holds cloth up on the side it faces.
    #[test]
    fn a_cloth_dropped_on_an_avian_height_field_lies_on_it() {
        let mut app = avian_app();
        let at = Vec3::new(0.4, -1.0, 0.0);
        app.world_mut().spawn((
            RigidBody::Static,
            Collider::heightfield(hill_heights(), Vec3::new(4.0, 1.0, 4.0)),
            Transform::from_translation(at),
        ));
        assert_lies_on_the_hills(&mut app, at);
    }

    #[test]
    fn a_body_removed_mid_contact_leaves_nothing_behind() {
        let mut app = avian_app();
        let (hammock, body) = box_on_hammock(&mut app);
        run(&mut app, 120);
        let sagging = lowest(&app, hammock);
        assert!(
            sagging < 0.97,
            "the box does not weigh on the hammock: {sagging}"
        );
        app.world_mut().entity_mut(body).despawn();
        run(&mut app, 120);
        // No collider is left where the box was, and the hammock springs back.
        let colliders = app.world().resource::<ClothColliders>();
        assert!(colliders.entities.is_empty(), "{:?}", colliders.entities);
        let mut mirrors = app
            .world_mut()
            .query_filtered::<Entity, With<FromAvianCollider>>();
        assert_eq!(mirrors.iter(app.world()).count(), 0);
        let after = lowest(&app, hammock);
        assert!(
            after > sagging + 0.02,
            "still pressed down: {sagging} → {after}"
        );

        // Removing only the avian collider (the body stays) removes its mirror too.
        let (_, body) = box_on_hammock(&mut app);
        run(&mut app, 60);
        assert!(app.world().get::<ClothCollider>(body).is_some());
        app.world_mut().entity_mut(body).remove::<Collider>();
        run(&mut app, 2);
        assert!(app.world().get::<ClothCollider>(body).is_none());
        assert!(app.world().resource::<ClothColliders>().entities.is_empty());
    }

    #[test]
    fn no_cloth_collision_and_the_users_own_collider_are_left_alone() {
        let mut app = avian_app();
        let ignored = app
            .world_mut()
            .spawn((Collider::sphere(0.2), NoClothCollision))
            .id();
        let own = app
            .world_mut()
            .spawn((Collider::sphere(0.2), ClothCollider::sphere(0.5)))
            .id();
        run(&mut app, 3);
        assert!(app.world().get::<ClothCollider>(ignored).is_none());
        let c = app.world().get::<ClothCollider>(own).unwrap();
        assert_eq!(c.shape, ColliderShape::Sphere { radius: 0.5 });
        assert!(app.world().get::<FromAvianCollider>(own).is_none());
    }

    /// A cape pinned to a kinematic avian body walking at 3 m/s that avian draws
    /// interpolated (`TransformInterpolation`), frames of 1/144 s over the 60 Hz step: with
    /// `ClothSmoothing::Interpolate` the pinned corner is drawn where the body is drawn, within
    /// f32 rounding (as `game`'s test: the pin's velocity, 2 ε |x| / h, over a step); without
    /// it up to a step's walk (5 cm) off.
    #[test]
    fn a_smoothed_cape_on_an_interpolated_avian_body_is_drawn_with_it() {
        let mut worst = Vec::new();
        for smoothing in [None, Some(ClothSmoothing::Interpolate)] {
            let mut app = avian_app();
            let body = app
                .world_mut()
                .spawn((
                    RigidBody::Kinematic,
                    LinearVelocity(Vec3::new(3.0, 0.0, 0.0)),
                    TransformInterpolation,
                    common::cape_pose(),
                ))
                .id();
            let (cape, vertex, offset) = common::cape_on(&mut app, body, smoothing, None, false);
            let mut off = 0.0f32;
            for frame in 0..216 {
                app.update();
                if frame < 144 {
                    continue;
                }
                let w = app.world();
                let drawn_body = w
                    .get::<GlobalTransform>(body)
                    .unwrap()
                    .transform_point(offset);
                let drawn = w
                    .get::<GlobalTransform>(cape)
                    .unwrap()
                    .transform_point(common::drawn_on_the_cpu(&app, cape)[vertex as usize]);
                off = off.max(drawn.distance(drawn_body));
            }
            eprintln!("{smoothing:?}: the pinned corner {off} m from the drawn body");
            worst.push(off);
        }
        assert!(worst[0] > 0.03, "as stepped: {} m off", worst[0]);
        assert!(
            worst[1] < common::smoothing_rounding(),
            "interpolated: {} m off",
            worst[1]
        );
    }
}

/// Both bridges in one app: each mirrors and pushes only its own engine's bodies.
#[cfg(all(feature = "avian", feature = "rapier"))]
#[test]
fn rapier_and_avian_bridges_work_side_by_side() {
    use bevy_cloth::collider::avian::FromAvianCollider;
    use bevy_cloth::collider::rapier::FromRapierCollider;
    let mut app = app();
    app.add_plugins((
        avian3d::prelude::PhysicsPlugins::default(),
        ClothAvianPlugin::default(),
        bevy_rapier3d::prelude::RapierPhysicsPlugin::<bevy_rapier3d::prelude::NoUserData>::default(
        ),
        ClothRapierPlugin::default(),
    ));
    app.finish();
    app.cleanup();
    curtain(&mut app);
    let speed = 5.0;
    let avian_ball = {
        use avian3d::prelude::*;
        app.world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::sphere(0.2),
                Mass(0.5),
                GravityScale(0.0),
                LinearVelocity(Vec3::new(0.0, 0.0, -speed)),
                Transform::from_xyz(-0.5, 1.0, 1.0),
            ))
            .id()
    };
    let rapier_ball = {
        use bevy_rapier3d::prelude::*;
        app.world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::ball(0.2),
                ColliderMassProperties::Mass(0.5),
                GravityScale(0.0),
                Velocity::linear(Vec3::new(0.0, 0.0, -speed)),
                Transform::from_xyz(0.5, 1.0, 1.0),
            ))
            .id()
    };
    run(&mut app, 60);
    let w = app.world();
    assert!(w.get::<FromAvianCollider>(avian_ball).is_some());
    assert!(w.get::<FromRapierCollider>(avian_ball).is_none());
    assert!(w.get::<FromRapierCollider>(rapier_ball).is_some());
    assert!(w.get::<FromAvianCollider>(rapier_ball).is_none());
    let va = w
        .get::<avian3d::prelude::LinearVelocity>(avian_ball)
        .unwrap()
        .0;
    let vr = w
        .get::<bevy_rapier3d::prelude::Velocity>(rapier_ball)
        .unwrap()
        .linear;
    assert!(va.z > -speed * 0.95, "avian ball not slowed: {va}");
    assert!(vr.z > -speed * 0.95, "rapier ball not slowed: {vr}");
}
