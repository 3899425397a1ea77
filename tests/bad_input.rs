//! Bad input: every kind of broken mesh, pin, size or parameter gets a typed error naming the
//! problem on its entity, is reported once (log + [`ClothFailed`]), is left unsimulated, and
//! leaves every other cloth and the app exactly as they would have been without it.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;
use bevy_cloth::foundation::MeshError;
use bevy_cloth::prelude::*;
use bevy_cloth::solver::{SolverError, StateError, TopologyError};

mod common;
use common::{Failures, collect_failures, run};

fn app() -> App {
    let mut app = common::app();
    app.init_resource::<Failures>()
        .add_systems(Update, collect_failures);
    app
}

const GRID: Grid = Grid {
    columns: 8,
    rows: 8,
    width: 1.0,
    height: 1.0,
};

fn add_mesh(app: &mut App, mesh: Mesh) -> Handle<Mesh> {
    app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh)
}

/// The well-behaved cloth every test runs beside the broken ones.
fn spawn_good(app: &mut App) -> (Entity, Handle<Mesh>) {
    let mesh = add_mesh(app, grid_mesh(&GRID));
    let e = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 2.0, 0.0),
            Cloth::default(),
            ClothPins::rest([GRID.index(0, 0), GRID.index(7, 0)]),
        ))
        .id();
    (e, Handle::default())
}

fn good_positions(app: &App, e: Entity) -> Vec<Vec3> {
    let sim = app.world().get::<ClothSim>(e).expect("the good cloth runs");
    (0..sim.simulation().state().len())
        .map(|i| sim.simulation().state().position(i))
        .collect()
}

fn mesh_with(positions: Vec<[f32; 3]>, indices: Option<Vec<u32>>) -> Mesh {
    let mut m = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    if let Some(i) = indices {
        m.insert_indices(Indices::U32(i));
    }
    m
}

fn grid_positions() -> Vec<[f32; 3]> {
    GRID.positions().iter().map(|p| p.to_array()).collect()
}

/// One broken cloth: what to spawn and what must be said about it.
struct Case {
    name: &'static str,
    bundle: Box<dyn FnOnce(&mut App) -> Entity>,
    expect: Expect,
    /// A word the error's message must contain, so the user sees what is wrong.
    says: &'static str,
}

/// The error a case must get.
enum Expect {
    /// One that satisfies this test.
    Error(fn(&ClothError) -> bool),
    /// An out-of-range parameter of this name.
    Param(&'static str),
}

impl Expect {
    fn matches(&self, e: &ClothError) -> bool {
        match self {
            Expect::Error(f) => f(e),
            Expect::Param(name) => {
                matches!(e, ClothError::Solver(SolverError::Params(p)) if p.name == *name)
            }
        }
    }
}

fn spawn_with(mesh: Mesh, extra: impl Bundle) -> Box<dyn FnOnce(&mut App) -> Entity> {
    Box::new(move |app: &mut App| {
        let h = add_mesh(app, mesh);
        app.world_mut().spawn((Mesh3d(h), extra)).id()
    })
}

fn cases() -> Vec<Case> {
    let mut nan = grid_positions();
    nan[5][1] = f32::NAN;
    let mut inf = grid_positions();
    inf[9][0] = f32::INFINITY;
    let mut out_of_range = GRID.indices();
    out_of_range[4] = 999;
    let mut not_multiple = GRID.indices();
    not_multiple.pop();
    let xpbd = |stretch: f32| ClothConfig {
        solver: Solver::Xpbd {
            stretch,
            shear: 0.0,
            bending: 1e-3,
        },
        ..default()
    };
    vec![
        Case {
            name: "mesh without positions",
            bundle: spawn_with(
                Mesh::new(
                    PrimitiveTopology::TriangleList,
                    RenderAssetUsages::default(),
                )
                .with_inserted_indices(Indices::U32(vec![0, 1, 2])),
                Cloth::default(),
            ),
            expect: Expect::Error(|e| matches!(e, ClothError::Mesh(MeshError::NoPositions))),
            says: "POSITION",
        },
        Case {
            name: "mesh without indices, not whole triangles",
            bundle: spawn_with(
                mesh_with(grid_positions()[..7].to_vec(), None),
                Cloth::default(),
            ),
            expect: Expect::Error(|e| matches!(e, ClothError::Mesh(MeshError::PartialTriangle(7)))),
            says: "multiple of 3",
        },
        Case {
            name: "line list",
            bundle: spawn_with(
                Mesh::new(PrimitiveTopology::LineList, RenderAssetUsages::default())
                    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 2]),
                Cloth::default(),
            ),
            expect: Expect::Error(|e| matches!(e, ClothError::Mesh(MeshError::NotTriangleList(_)))),
            says: "triangle list",
        },
        Case {
            name: "index count not a multiple of three",
            bundle: spawn_with(
                mesh_with(grid_positions(), Some(not_multiple)),
                Cloth::default(),
            ),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::Topology(TopologyError::NotTriangles { .. }))
                )
            }),
            says: "multiple of 3",
        },
        Case {
            name: "NaN vertex position",
            bundle: spawn_with(mesh_with(nan, Some(GRID.indices())), Cloth::default()),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::Topology(TopologyError::NonFinitePosition {
                        vertex: 5
                    }))
                )
            }),
            says: "5",
        },
        Case {
            name: "infinite vertex position",
            bundle: spawn_with(mesh_with(inf, Some(GRID.indices())), Cloth::default()),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::Topology(TopologyError::NonFinitePosition {
                        vertex: 9
                    }))
                )
            }),
            says: "9",
        },
        Case {
            name: "index out of range",
            bundle: spawn_with(
                mesh_with(grid_positions(), Some(out_of_range)),
                Cloth::default(),
            ),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::Topology(TopologyError::IndexOutOfRange {
                        index: 999,
                        ..
                    }))
                )
            }),
            says: "999",
        },
        Case {
            name: "pin index out of range",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (Cloth::default(), ClothPins::rest([0, 64])),
            ),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::State(StateError::PinOutOfRange {
                        vertex: 64,
                        ..
                    }))
                )
            }),
            says: "64",
        },
        Case {
            name: "zero-sized grid (no vertices)",
            bundle: spawn_with(grid_mesh(&Grid::new(0, 0, 1.0, 1.0)), Cloth::default()),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::Topology(TopologyError::NoVertices))
                )
            }),
            says: "vertices",
        },
        Case {
            name: "every vertex at one point (every triangle degenerate)",
            bundle: spawn_with(
                grid_mesh(&Grid::new(8, 8, 1.0, 1.0))
                    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 8 * 8]),
                Cloth::default(),
            ),
            expect: Expect::Error(|e| {
                matches!(
                    e,
                    ClothError::Solver(SolverError::Topology(TopologyError::ZeroArea))
                )
            }),
            says: "zero area",
        },
        Case {
            name: "negative mass",
            bundle: spawn_with(
                grid_mesh(&GRID),
                Cloth {
                    mass: -1.0,
                    ..default()
                },
            ),
            expect: Expect::Error(|e| matches!(e, ClothError::BadMass(m) if *m == -1.0)),
            says: "mass",
        },
        Case {
            name: "infinite mass",
            bundle: spawn_with(
                grid_mesh(&GRID),
                Cloth {
                    mass: f32::INFINITY,
                    ..default()
                },
            ),
            expect: Expect::Error(|e| matches!(e, ClothError::BadMass(m) if m.is_infinite())),
            says: "mass",
        },
        Case {
            name: "NaN teleport distance",
            bundle: spawn_with(
                grid_mesh(&GRID),
                Cloth {
                    teleport_distance: f32::NAN,
                    ..default()
                },
            ),
            expect: Expect::Error(
                |e| matches!(e, ClothError::BadTeleportDistance(d) if d.is_nan()),
            ),
            says: "teleport",
        },
        Case {
            name: "zero iterations",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothConfig {
                        iterations: 0,
                        ..default()
                    },
                ),
            ),
            expect: Expect::Param("iterations"),
            says: "iterations",
        },
        Case {
            name: "negative damping",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothConfig {
                        damping: -1.0,
                        ..default()
                    },
                ),
            ),
            expect: Expect::Param("damping"),
            says: "damping",
        },
        Case {
            name: "negative air drag",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothConfig {
                        air: Aerodynamics {
                            drag: -0.5,
                            ..default()
                        },
                        ..default()
                    },
                ),
            ),
            expect: Expect::Param("air.drag"),
            says: "air.drag",
        },
        Case {
            name: "infinite gravity",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothConfig {
                        gravity: Vec3::new(0.0, f32::NEG_INFINITY, 0.0),
                        ..default()
                    },
                ),
            ),
            expect: Expect::Param("gravity"),
            says: "gravity",
        },
        Case {
            name: "NaN compliance",
            bundle: spawn_with(grid_mesh(&GRID), (Cloth::default(), xpbd(f32::NAN))),
            expect: Expect::Param("stretch"),
            says: "stretch",
        },
        Case {
            name: "negative compliance",
            bundle: spawn_with(grid_mesh(&GRID), (Cloth::default(), xpbd(-1.0))),
            expect: Expect::Param("stretch"),
            says: "stretch",
        },
        Case {
            name: "PBD stiffness above one",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothConfig {
                        solver: Solver::Pbd {
                            stretch: 2.0,
                            shear: 1.0,
                            bending: 0.1,
                        },
                        ..default()
                    },
                ),
            ),
            expect: Expect::Param("stretch"),
            says: "stretch",
        },
        Case {
            name: "zero speed limit",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothConfig {
                        max_speed: 0.0,
                        ..default()
                    },
                ),
            ),
            expect: Expect::Param("max_speed"),
            says: "max_speed",
        },
        Case {
            name: "negative self-collision thickness",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothSelfCollision {
                        thickness: Some(-0.1),
                        friction: 0.2,
                    },
                ),
            ),
            expect: Expect::Param("self_collision.thickness"),
            says: "thickness",
        },
        Case {
            name: "tear threshold below one",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (Cloth::default(), ClothTearing { threshold: 0.5 }),
            ),
            expect: Expect::Param("tear_threshold"),
            says: "tear",
        },
        Case {
            name: "NaN tether slack",
            bundle: spawn_with(
                grid_mesh(&GRID),
                (
                    Cloth::default(),
                    ClothPins::rest([0]),
                    ClothTethers {
                        slack: f32::NAN,
                        pins_per_vertex: 1,
                    },
                ),
            ),
            expect: Expect::Param("tethers.slack"),
            says: "slack",
        },
    ]
}

#[test]
fn every_bad_input_gets_a_typed_error_once_and_nothing_else_changes() {
    const FRAMES: usize = 30;
    // The reference: the good cloth alone.
    let mut alone = app();
    let (good_alone, _) = spawn_good(&mut alone);
    run(&mut alone, FRAMES);
    let reference = good_positions(&alone, good_alone);

    let mut app = app();
    let (good, _) = spawn_good(&mut app);
    let mut spawned = Vec::new();
    for case in cases() {
        let e = (case.bundle)(&mut app);
        spawned.push((e, case.name, case.expect, case.says));
    }
    run(&mut app, FRAMES);

    let failures = &app.world().resource::<Failures>().0;
    for (e, name, expect, says) in &spawned {
        let invalid = app
            .world()
            .get::<ClothInvalid>(*e)
            .unwrap_or_else(|| panic!("{name}: no ClothInvalid"));
        assert!(
            expect.matches(&invalid.0),
            "{name}: unexpected error {:?}",
            invalid.0
        );
        let text = invalid.0.to_string();
        assert!(
            text.contains(says),
            "{name}: message {text:?} does not say {says:?}"
        );
        assert!(
            app.world().get::<ClothSim>(*e).is_none(),
            "{name}: was simulated"
        );
        let reports: Vec<_> = failures.iter().filter(|f| f.cloth == *e).collect();
        assert_eq!(reports.len(), 1, "{name}: reported {} times", reports.len());
        // (Compared as text: an error holding a NaN is not equal to itself.)
        assert_eq!(reports[0].error.to_string(), text, "{name}");
    }
    assert_eq!(
        failures.len(),
        spawned.len(),
        "only the broken cloths are reported"
    );
    assert!(app.world().get::<ClothInvalid>(good).is_none());
    // The good cloth did exactly what it does alone, bit for bit.
    assert_eq!(good_positions(&app, good), reference);
}

/// A self-collision thickness of more than `MAX_SELF_COLLISION_EDGES` mean rest edges (where
/// layers would pass through each other) is brought down to that when the cloth is built
/// and when it is changed at runtime; the cloth runs and nothing is reported as failed. A
/// thinner one is used as it is.
#[test]
fn a_self_collision_thicker_than_an_edge_is_brought_down() {
    let mut app = app();
    let spawn = spawn_with(
        grid_mesh(&GRID),
        (
            Cloth::default(),
            ClothSelfCollision {
                thickness: Some(1.0),
                friction: 0.2,
            },
        ),
    );
    let e = spawn(&mut app);
    run(&mut app, 5);
    let used = |app: &App| {
        let sim = app.world().get::<ClothSim>(e).expect("simulated");
        let mean = sim.simulation().topology().mean_rest_edge();
        let thickness = sim
            .simulation()
            .features()
            .self_collision
            .unwrap()
            .thickness;
        (thickness, mean, sim.steps())
    };
    let (thickness, mean, steps) = used(&app);
    assert!(
        mean > 0.1,
        "the 8 × 8 grid of 1 m has edges of 1/7 m and more: {mean}"
    );
    assert_eq!(
        thickness,
        bevy_cloth::solver::MAX_SELF_COLLISION_EDGES * mean
    );
    assert!(steps > 0);
    // Thicker still at runtime: the same; then thinner: as asked.
    app.world_mut()
        .get_mut::<ClothSelfCollision>(e)
        .unwrap()
        .thickness = Some(100.0);
    run(&mut app, 2);
    assert_eq!(used(&app).0, thickness);
    app.world_mut()
        .get_mut::<ClothSelfCollision>(e)
        .unwrap()
        .thickness = Some(0.05);
    run(&mut app, 2);
    assert_eq!(used(&app).0, 0.05);
    assert!(app.world().get::<ClothInvalid>(e).is_none());
    assert!(app.world().resource::<Failures>().0.is_empty());
}

#[test]
fn broken_colliders_and_wind_are_ignored_and_the_cloth_runs_as_without_them() {
    const FRAMES: usize = 30;
    let mut alone = app();
    let (good_alone, _) = spawn_good(&mut alone);
    run(&mut alone, FRAMES);
    let reference = good_positions(&alone, good_alone);

    let mut app = app();
    let (good, _) = spawn_good(&mut app);
    for collider in [
        ClothCollider::sphere(f32::NAN),
        ClothCollider::sphere(-1.0),
        ClothCollider::cuboid(Vec3::new(1.0, f32::INFINITY, 1.0)),
        ClothCollider::capsule(0.2, -1.0),
        ClothCollider::sphere(0.3).with_thickness(f32::NAN),
        ClothCollider::sphere(0.3).with_friction(-1.0),
    ] {
        app.world_mut()
            .spawn((Transform::from_xyz(0.0, 1.8, 0.0), collider));
    }
    // A valid shape on a transform that is not finite.
    app.world_mut().spawn((
        Transform::from_xyz(f32::NAN, 1.8, 0.0),
        ClothCollider::sphere(0.3),
    ));
    app.insert_resource(Wind(WindParams {
        velocity: Vec3::new(f32::NAN, 0.0, 0.0),
        ..default()
    }));
    app.world_mut().spawn((
        Transform::default(),
        WindZone {
            wind: WindParams {
                turbulence_scale: -1.0,
                ..default()
            },
            half_extents: Vec3::splat(10.0),
            falloff: 1.0,
        },
    ));
    run(&mut app, FRAMES);
    let sim = app.world().get::<ClothSim>(good).unwrap();
    assert_eq!(sim.recoveries(), 0);
    assert_eq!(good_positions(&app, good), reference);
}

#[test]
fn a_fixed_cloth_runs_and_a_changed_cloth_is_rebuilt() {
    let mut app = app();
    let mesh = add_mesh(&mut app, grid_mesh(&GRID));
    let e = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Cloth {
                mass: f32::NAN,
                ..default()
            },
        ))
        .id();
    run(&mut app, 5);
    assert!(app.world().get::<ClothInvalid>(e).is_some());
    app.world_mut().get_mut::<Cloth>(e).unwrap().mass = 0.5;
    run(&mut app, 30);
    assert!(app.world().get::<ClothInvalid>(e).is_none());
    let steps = app.world().get::<ClothSim>(e).unwrap().steps();
    assert!(steps > 0);
    // Changing the mass of a running cloth applies to it where it is.
    app.world_mut().get_mut::<Cloth>(e).unwrap().mass = 1.0;
    run(&mut app, 2);
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert!(
        sim.steps() > steps,
        "built again: {} ≤ {steps}",
        sim.steps()
    );
    let total: f32 = (0..sim.simulation().state().len())
        .map(|i| 1.0 / sim.simulation().state().positions[i].w)
        .sum();
    assert!((total - 1.0).abs() < 1e-3, "new mass not applied: {total}");
    // Changing its welding builds it again from its rest shape.
    app.world_mut().get_mut::<Cloth>(e).unwrap().weld_tolerance = 2e-5;
    run(&mut app, 2);
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert!(
        sim.steps() < steps,
        "not rebuilt: {} ≥ {steps}",
        sim.steps()
    );
    // From the mesh the user gave (flat at y = 0), not from the fallen copy (over 1 m lower).
    let lowest = (0..sim.simulation().state().len())
        .map(|i| sim.simulation().state().position(i).y)
        .fold(f32::INFINITY, f32::min);
    assert!(
        lowest > -0.05,
        "rebuilt from the deformed mesh: lowest y {lowest}"
    );
}

#[test]
fn a_cloth_whose_state_goes_bad_is_reset_to_its_rest_pose() {
    let mut app = app();
    let (e, _) = spawn_good(&mut app);
    run(&mut app, 20);
    let mesh = app.world().get::<ClothSim>(e).unwrap().mesh().clone();
    // Something outside the solver poisons the state.
    {
        let mut sim = app.world_mut().get_mut::<ClothSim>(e).unwrap();
        sim.simulation_mut().state_mut().positions[10].x = f32::NAN;
        sim.simulation_mut().state_mut().velocities[20].y = f32::INFINITY;
    }
    run(&mut app, 1);
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert_eq!(sim.recoveries(), 1);
    assert_eq!(sim.simulation().state().non_finite_count(), 0);
    // Back at the rest shape placed by the entity (y = 2), at most one step of sag away.
    let y: Vec<f32> = (0..64)
        .map(|i| sim.simulation().state().position(i).y)
        .collect();
    assert!(y.iter().all(|y| (y - 2.0).abs() < 0.01), "{y:?}");
    // Nothing bad reached the mesh.
    let meshes = app.world().resource::<Assets<Mesh>>();
    let m = meshes.get(&mesh).unwrap();
    let Some(VertexAttributeValues::Float32x3(p)) = m.attribute(Mesh::ATTRIBUTE_POSITION) else {
        panic!("no positions");
    };
    assert!(p.iter().flatten().all(|c| c.is_finite()));
    let Some(VertexAttributeValues::Float32x3(n)) = m.attribute(Mesh::ATTRIBUTE_NORMAL) else {
        panic!("no normals");
    };
    assert!(n.iter().flatten().all(|c| c.is_finite()));
    // And it keeps running normally.
    run(&mut app, 10);
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert_eq!(sim.recoveries(), 1);
}

/// A pin on an entity that does not exist (a bone name that matched nothing, a despawned
/// anchor) is reported once, naming the entity; the cloth runs on with those pins holding
/// where they are, the other pins following their anchors, and the report clears when the
/// anchor is there again.
#[test]
fn a_pin_on_a_missing_entity_is_reported_once_and_the_cloth_runs_on() {
    let mut app = app();
    let anchor = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, 2.0, 0.0))
        .id();
    let gone = app.world_mut().spawn(Transform::default()).id();
    app.world_mut().entity_mut(gone).despawn();
    let mesh = add_mesh(&mut app, grid_mesh(&GRID));
    let (left, right) = (GRID.index(0, 0), GRID.index(7, 0));
    let e = app
        .world_mut()
        .spawn((
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 2.0, 0.0),
            Cloth::default(),
            ClothPins(vec![
                ClothPin {
                    vertex: left,
                    anchor: PinAnchor::Entity {
                        entity: anchor,
                        offset: Vec3::new(-0.5, 0.0, -0.5),
                    },
                },
                ClothPin {
                    vertex: right,
                    anchor: PinAnchor::Entity {
                        entity: gone,
                        offset: Vec3::ZERO,
                    },
                },
            ]),
        ))
        .id();
    run(&mut app, 10);
    let held = app
        .world()
        .get::<ClothSim>(e)
        .unwrap()
        .simulation()
        .state()
        .position(right as usize);
    // Moving the anchor that exists moves its pin; the other pin stays where it was.
    app.world_mut()
        .get_mut::<Transform>(anchor)
        .unwrap()
        .translation
        .x += 0.3;
    run(&mut app, 20);
    let failures = &app.world().resource::<Failures>().0;
    assert_eq!(failures.len(), 1, "{failures:?}");
    assert_eq!(failures[0].cloth, e);
    assert_eq!(failures[0].error, ClothError::PinAnchorMissing(gone));
    assert!(app.world().get::<ClothInvalid>(e).is_none());
    let sim = app.world().get::<ClothSim>(e).unwrap();
    assert!(
        sim.steps() >= 29,
        "the cloth stopped: {} steps",
        sim.steps()
    );
    let s = sim.simulation().state();
    let (l, r) = (s.position(left as usize), s.position(right as usize));
    assert!(l.distance(Vec3::new(-0.2, 2.0, -0.5)) < 1e-5, "{l}");
    assert_eq!(r, held);
    assert!((0..s.len()).all(|i| s.position(i).is_finite()));
    // Pinned to the existing anchor instead: no new report, and the pins follow it.
    app.world_mut().get_mut::<ClothPins>(e).unwrap().0[1].anchor = PinAnchor::Entity {
        entity: anchor,
        offset: Vec3::new(0.5, 0.0, -0.5),
    };
    run(&mut app, 3);
    assert_eq!(app.world().resource::<Failures>().0.len(), 1);
    let s = app.world().get::<ClothSim>(e).unwrap().simulation().state();
    assert!(
        s.position(right as usize)
            .distance(Vec3::new(0.8, 2.0, -0.5))
            < 1e-5
    );
}
