//! What the editor's buttons do, as functions on `&mut World`: the panel calls exactly these,
//! and so can game code and tests.
//!
//! - Add: [`add_cloth`], [`add_mesh_cloth`], [`add_collider`], [`add_mesh_collider`],
//!   [`add_wind_zone`],
//!   [`set_wind`].
//! - Delete: [`delete`] (despawns with children; the meshes and materials go with their last
//!   handle; pins anchored to the deleted entity are removed from every cloth).
//! - Pins: [`pin_draft`], [`toggle_pin`], [`pin_preset`], [`update_pins`]: a draft changes
//!   nothing on the cloth until it is applied.
//! - Pointer: [`pick`], [`click`], and the axis drag in [`super::gizmo`].

use std::collections::BTreeSet;

use bevy::math::Ray3d;
use bevy::prelude::*;

use super::state::{
    ClothEditor, EditorGrid, EditorShape, MeshLoad, NewCloth, NewShape, PinDraft, PinPreset,
};
use crate::cloth::{
    Cloth, ClothPin, ClothPinRule, ClothPins, ClothSim, ClothTethers, PinAnchor, VertexSelection,
};
use crate::collider::{ClothCollider, ClothColliders, ColliderShape};
use crate::foundation::{finite_bounds, grid_mesh};
use crate::render::{VelvetMaterial, lined_velvet};
use crate::solver::{Shape, Topology, WindParams, ray_shape};
use crate::wind::{Wind, WindZone};

/// Colours given to new cloths in turn.
const CLOTH_COLOURS: [Color; 5] = [
    Color::srgb(0.75, 0.2, 0.2),
    Color::srgb(0.2, 0.45, 0.8),
    Color::srgb(0.85, 0.65, 0.15),
    Color::srgb(0.25, 0.6, 0.35),
    Color::srgb(0.55, 0.3, 0.7),
];

/// Colour of the colliders the editor adds.
const COLLIDER_COLOUR: Color = Color::srgb(0.72, 0.72, 0.7);

fn next_number(world: &mut World) -> u32 {
    let mut editor = world.get_resource_or_init::<ClothEditor>();
    editor.counter += 1;
    editor.counter
}

/// Sets the status line (and logs it).
pub fn say(world: &mut World, message: impl Into<String>) {
    let message = message.into();
    info!("cloth editor: {message}");
    world.get_resource_or_init::<ClothEditor>().status = message;
}

fn material(
    world: &mut World,
    color: Color,
    double_sided: bool,
) -> Option<MeshMaterial3d<StandardMaterial>> {
    let mut materials = world.get_resource_mut::<Assets<StandardMaterial>>()?;
    Some(MeshMaterial3d(materials.add(StandardMaterial {
        base_color: color,
        perceptual_roughness: 0.85,
        double_sided,
        cull_mode: if double_sided {
            None
        } else {
            Some(bevy::render::render_resource::Face::Back)
        },
        ..default()
    })))
}

/// Gives a cloth a two-sided material of `color`: the crate's velvet if the app has
/// [`VelvetPlugin`](crate::render::VelvetPlugin), else a standard one. Nothing without a
/// renderer.
pub fn dress_cloth(world: &mut World, cloth: Entity, color: Color) {
    if let Some(mut velvet) = world.get_resource_mut::<Assets<VelvetMaterial>>() {
        let m = velvet.add(lined_velvet(color));
        world.entity_mut(cloth).insert(MeshMaterial3d(m));
    } else if let Some(m) = material(world, color, true) {
        world.entity_mut(cloth).insert(m);
    }
}

/// Adds a cloth: a `spec.columns × spec.rows` grid hanging from its two top corners, 1 m
/// above the ground in front of the origin, named "Cloth N". The dialog's values are clamped
/// to [`NewCloth::VERTICES`] and [`NewCloth::SIZE`] and the mass to its limit.
pub fn add_cloth(world: &mut World, spec: &NewCloth) -> Entity {
    let (lo, hi) = NewCloth::VERTICES;
    let (small, big) = NewCloth::SIZE;
    let clamp = |v: f32| {
        if v.is_nan() {
            small
        } else {
            v.clamp(small, big)
        }
    };
    let grid = EditorGrid {
        columns: spec.columns.clamp(lo, hi),
        rows: spec.rows.clamp(lo, hi),
        width: clamp(spec.width),
        height: clamp(spec.height),
    };
    let g = grid.grid();
    let mesh = world.resource_mut::<Assets<Mesh>>().add(grid_mesh(&g));
    let n = next_number(world);
    // The grid lies in its xz plane with row 0 at +z; turned a quarter about x, row 0 is on
    // top and the cloth hangs in the xy plane.
    let transform = Transform::from_xyz(0.0, 1.0 + grid.height, 0.0)
        .with_rotation(Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2));
    let corners = [g.index(0, 0), g.index(grid.columns - 1, 0)];
    let color = CLOTH_COLOURS[(n as usize - 1) % CLOTH_COLOURS.len()];
    let id = world
        .spawn((
            Name::new(format!("Cloth {n}")),
            Mesh3d(mesh),
            transform,
            Cloth {
                mass: crate::solver::limits::MASS.clamp(spec.mass),
                ..default()
            },
            ClothPins::rest(corners),
            grid,
        ))
        .id();
    dress_cloth(world, id, color);
    say(world, format!("added Cloth {n}"));
    id
}

/// The mesh the editor shows for a collider shape (`None` for mesh and baked shapes, which
/// bring their own).
#[must_use]
pub fn shape_mesh(shape: &ColliderShape) -> Option<Mesh> {
    // Sizes of zero make degenerate meshes; keep them visible as a dot.
    let at_least = |v: f32| v.max(1e-4);
    Some(match shape {
        ColliderShape::Sphere { radius } => Sphere::new(at_least(*radius)).mesh().ico(4).ok()?,
        ColliderShape::Cuboid { half_extents } => {
            let s = half_extents.max(Vec3::splat(1e-4)) * 2.0;
            Cuboid::new(s.x, s.y, s.z).mesh().build()
        }
        ColliderShape::Capsule {
            radius,
            half_length,
        } => Capsule3d::new(at_least(*radius), 2.0 * half_length.max(0.0))
            .mesh()
            .build(),
        ColliderShape::Plane => Plane3d::default().mesh().size(30.0, 30.0).build(),
        ColliderShape::Mesh(_) => return None,
    })
}

/// Adds a collider of the given shape (ball of radius 0.3, box of 0.6 m, capsule, floor)
/// beside the origin, named after its shape, with a visible mesh that follows its size
/// ([`EditorShape`]).
pub fn add_collider(world: &mut World, shape: NewShape) -> Entity {
    let n = next_number(world);
    let (collider, name, at) = match shape {
        NewShape::Sphere => (
            ClothCollider::sphere(0.3),
            "Sphere",
            Vec3::new(0.0, 0.6, 0.6),
        ),
        NewShape::Box => (
            ClothCollider::cuboid(Vec3::splat(0.3)),
            "Box",
            Vec3::new(0.8, 0.3, 0.6),
        ),
        NewShape::Capsule => (
            ClothCollider::capsule(0.15, 0.6),
            "Capsule",
            Vec3::new(-0.8, 0.5, 0.6),
        ),
        NewShape::Plane => (ClothCollider::plane(), "Floor", Vec3::ZERO),
    };
    let id = spawn_collider(
        world,
        format!("{name} {n}"),
        collider,
        Transform::from_translation(at),
        None,
    );
    say(world, format!("added {name} {n}"));
    id
}

/// Spawns a collider with a visible mesh: its own `mesh` if given (a mesh collider), else one
/// drawn from the shape and kept in step with it ([`EditorShape`]).
pub(crate) fn spawn_collider(
    world: &mut World,
    name: String,
    collider: ClothCollider,
    transform: Transform,
    mesh: Option<Handle<Mesh>>,
) -> Entity {
    let shown = match mesh {
        Some(h) => Some(h),
        None => shape_mesh(&collider.shape)
            .and_then(|m| Some(world.get_resource_mut::<Assets<Mesh>>()?.add(m))),
    };
    let drawn_from_shape = !matches!(collider.shape, ColliderShape::Mesh(_));
    let look = material(world, COLLIDER_COLOUR, false);
    let mut e = world.spawn((Name::new(name), collider, transform));
    if let Some(h) = shown {
        e.insert(Mesh3d(h));
    }
    if drawn_from_shape {
        e.insert(EditorShape);
    }
    if let Some(m) = look {
        e.insert(m);
    }
    e.id()
}

/// Adds a mesh collider from a file in the asset folder: glTF (`.gltf`, `.glb`; the first
/// primitive of the first mesh unless the path has a `#Mesh…/Primitive…` label) or Wavefront
/// OBJ (`.obj`). The file loads in the background; if it fails, the collider is removed
/// again and the status line says why.
///
/// # Errors
/// A message when the path is empty, has another extension, or the app has no asset server.
pub fn add_mesh_collider(world: &mut World, path: &str) -> Result<Entity, String> {
    let (handle, full, stem) = load_mesh_file(world, path, "a mesh collider")?;
    let n = next_number(world);
    let id = spawn_collider(
        world,
        format!("{stem} {n}"),
        ClothCollider::mesh(48),
        Transform::from_xyz(0.0, 0.6, 1.2),
        Some(handle.clone()),
    );
    watch_load(world, id, handle, full, false);
    Ok(id)
}

/// Has the editor watch the load of `entity`'s mesh file (see `MeshLoad`), and says so.
fn watch_load(world: &mut World, entity: Entity, handle: Handle<Mesh>, path: String, cloth: bool) {
    say(world, format!("loading {path}"));
    world
        .get_resource_or_init::<ClothEditor>()
        .loading
        .push(MeshLoad {
            entity,
            handle,
            path,
            cloth,
        });
}

/// Starts loading the mesh at `path` in the asset folder (`.gltf`/`.glb`, its first
/// primitive unless a `#Mesh…/Primitive…` label says which, or `.obj`): its handle, the full
/// path and the file's stem. `what` names the object for the error.
fn load_mesh_file(
    world: &World,
    path: &str,
    what: &str,
) -> Result<(Handle<Mesh>, String, String), String> {
    let path = path.trim();
    let (file, label) = match path.split_once('#') {
        Some((f, l)) => (f, Some(l)),
        None => (path, None),
    };
    if file.is_empty() {
        return Err("give the mesh's path in the asset folder, e.g. models/statue.glb".into());
    }
    let ext = std::path::Path::new(file)
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let full = match (ext.as_deref(), label) {
        (Some("gltf" | "glb"), None) => format!("{file}#Mesh0/Primitive0"),
        (Some("gltf" | "glb" | "obj"), _) => path.to_string(),
        _ => {
            return Err(format!(
                "{file}: {what} is read from a .gltf, .glb or .obj file"
            ));
        }
    };
    let Some(server) = world.get_resource::<AssetServer>() else {
        return Err("this app has no asset server (AssetPlugin)".into());
    };
    let handle: Handle<Mesh> = server.load(full.clone());
    let stem = std::path::Path::new(file)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("Mesh")
        .to_string();
    Ok((handle, full, stem))
}

/// Adds a cloth made from a mesh file in the asset folder (as [`add_mesh_collider`] reads
/// it), 1.5 m above the ground in front of the origin (over where a mesh collider is added),
/// named after the file. It becomes
/// cloth once the mesh has loaded ([`make_mesh_cloth`]), hung by its top edge; if the file
/// fails to load the object is removed again and the status line says why.
///
/// # Errors
/// A message when the path is empty, has another extension, or the app has no asset server.
pub fn add_mesh_cloth(world: &mut World, path: &str) -> Result<Entity, String> {
    let (handle, full, stem) = load_mesh_file(world, path, "a cloth")?;
    let n = next_number(world);
    let id = world
        .spawn((
            Name::new(format!("{stem} {n}")),
            Mesh3d(handle.clone()),
            // Above where "add mesh collider" puts a collider, to drape over it.
            Transform::from_xyz(0.0, 1.5, 1.2),
        ))
        .id();
    dress_cloth(
        world,
        id,
        CLOTH_COLOURS[(n as usize - 1) % CLOTH_COLOURS.len()],
    );
    watch_load(world, id, handle, full, true);
    Ok(id)
}

/// Makes the object of a loaded mesh file a cloth hung by its top edge: a mesh lying flat
/// (its height under 1 % of its size, as a modelling tool's plane is exported) is stood up a
/// quarter turn about x, its -z edge on top; any other hangs from the vertices within 0.1 % of
/// its size of its highest point. Pinned by a [`ClothPinRule`] (re-pin in its card), with
/// [`ClothTethers`] (turn them off in its card).
pub fn make_mesh_cloth(world: &mut World, entity: Entity, mesh: &Mesh) {
    let Some(bevy::mesh::VertexAttributeValues::Float32x3(p)) =
        mesh.attribute(Mesh::ATTRIBUTE_POSITION)
    else {
        say(world, "the mesh has no positions: it stays as it is");
        return;
    };
    let bounds = finite_bounds(p.iter().map(|v| Vec3::from(*v)));
    let Some((lo, hi)) = bounds.filter(|(lo, hi)| lo != hi) else {
        say(world, "the mesh has no size: it stays as it is");
        return;
    };
    let size = (hi - lo).length();
    let flat = hi.y - lo.y < 0.01 * size;
    let towards = if flat { Vec3::NEG_Z } else { Vec3::Y };
    let Ok(mut e) = world.get_entity_mut(entity) else {
        return;
    };
    if flat && let Some(mut t) = e.get_mut::<Transform>() {
        t.rotation = Quat::from_rotation_x(core::f32::consts::FRAC_PI_2) * t.rotation;
    }
    // Tethered: a mesh made elsewhere is often far finer than the editor's grids, and at the
    // default substeps a fine mesh hung from one edge stretches to a string.
    e.insert((
        Cloth::default(),
        ClothPinRule::rest(VertexSelection::Farthest {
            towards,
            within: 1e-3 * size,
        }),
        ClothTethers::default(),
    ));
}

/// Adds a wind zone: a 2 m box of 6 m/s wind beside the origin, fading over 1 m.
pub fn add_wind_zone(world: &mut World) -> Entity {
    let n = next_number(world);
    let id = world
        .spawn((
            Name::new(format!("Wind zone {n}")),
            WindZone {
                wind: WindParams::default(),
                half_extents: Vec3::splat(1.0),
                falloff: 1.0,
            },
            Transform::from_xyz(-1.5, 1.5, 0.0),
        ))
        .id();
    say(world, format!("added Wind zone {n}"));
    id
}

/// Sets (`Some`) or removes (`None`) the global [`Wind`].
pub fn set_wind(world: &mut World, wind: Option<WindParams>) {
    match wind {
        Some(w) => world.insert_resource(Wind(w)),
        None => {
            world.remove_resource::<Wind>();
        }
    }
}

/// Deletes an object and everything under it: its children, its meshes and materials (their
/// assets go with the last handle), the pins of other cloths anchored to it, its pin draft
/// and the selection. Returns whether there was such an entity.
pub fn delete(world: &mut World, entity: Entity) -> bool {
    if world.get_entity(entity).is_err() {
        return false;
    }
    // The entity and its descendants: pins anchored to any of them go.
    let mut gone = vec![entity];
    let mut k = 0;
    while k < gone.len() {
        if let Some(children) = world.get::<Children>(gone[k]) {
            gone.extend(children.iter());
        }
        k += 1;
    }
    let mut cloths = world.query::<(Entity, &mut ClothPins)>();
    let mut stale = 0;
    for (e, mut pins) in cloths.iter_mut(world) {
        if gone.contains(&e) {
            continue;
        }
        let before = pins.0.len();
        let keep: Vec<ClothPin> = pins
            .0
            .iter()
            .copied()
            .filter(
                |p| !matches!(p.anchor, PinAnchor::Entity { entity, .. } | PinAnchor::Attached(entity) if gone.contains(&entity)),
            )
            .collect();
        if keep.len() != before {
            stale += before - keep.len();
            pins.0 = keep;
        }
    }
    let name = world
        .get::<Name>(entity)
        .map_or_else(|| entity.to_string(), |n| n.to_string());
    if let Some(mut editor) = world.get_resource_mut::<ClothEditor>() {
        for e in &gone {
            editor.drafts.remove(e);
        }
        if editor.selected.is_some_and(|s| gone.contains(&s)) {
            editor.selected = None;
        }
        if editor.pin_edit.is_some_and(|s| gone.contains(&s)) {
            editor.pin_edit = None;
        }
        if editor.drag.is_some_and(|d| gone.contains(&d.entity)) {
            editor.drag = None;
        }
        editor.loading.retain(|l| !gone.contains(&l.entity));
    }
    world.entity_mut(entity).despawn();
    if stale > 0 {
        say(
            world,
            format!("deleted {name} and {stale} pins anchored to it"),
        );
    } else {
        say(world, format!("deleted {name}"));
    }
    true
}

/// The mesh vertex that stands for `particle` (its first copy).
fn vertex_of(sim: &ClothSim, particle: u32) -> u32 {
    sim.weld().representative(particle)
}

/// The pin draft of `cloth`, or its current pins as a draft if none is being edited (nothing
/// is stored). `None` if the entity is not a simulated cloth.
pub fn pin_draft(world: &World, cloth: Entity) -> Option<PinDraft> {
    if let Some(d) = world
        .get_resource::<ClothEditor>()
        .and_then(|e| e.drafts.get(&cloth))
    {
        return Some(d.clone());
    }
    let sim = world.get::<ClothSim>(cloth)?;
    let pins = world.get::<ClothPins>(cloth)?;
    let vertices: BTreeSet<u32> = pins
        .0
        .iter()
        .filter(|p| (p.vertex as usize) < sim.weld().vertex_count())
        .map(|p| vertex_of(sim, sim.particle(p.vertex)))
        .collect();
    Some(PinDraft { vertices })
}

fn set_draft(world: &mut World, cloth: Entity, draft: PinDraft) {
    world
        .get_resource_or_init::<ClothEditor>()
        .drafts
        .insert(cloth, draft);
}

/// Toggles `vertex` (any copy of a welded vertex) in `cloth`'s pin draft. Returns whether it
/// is in the draft now, or `None` if `cloth` is not a simulated cloth or the vertex is not
/// one of its mesh's.
pub fn toggle_pin(world: &mut World, cloth: Entity, vertex: u32) -> Option<bool> {
    let mut draft = pin_draft(world, cloth)?;
    let sim = world.get::<ClothSim>(cloth)?;
    if vertex as usize >= sim.weld().vertex_count() {
        return None;
    }
    let v = vertex_of(sim, sim.particle(vertex));
    let now = if draft.vertices.remove(&v) {
        false
    } else {
        draft.vertices.insert(v);
        true
    };
    set_draft(world, cloth, draft);
    Some(now)
}

/// Particles on the cloth's boundary (on an edge of only one triangle).
fn boundary_particles(topology: &Topology) -> Vec<u32> {
    let mut count: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for t in topology.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut out: BTreeSet<u32> = BTreeSet::new();
    for ((a, b), n) in count {
        if n == 1 {
            out.insert(a);
            out.insert(b);
        }
    }
    out.into_iter().collect()
}

/// The particles of the top edge: boundary particles highest in the rest shape as placed by
/// `own` (or, for a level cloth, farthest along its local +z).
fn top_edge(sim: &ClothSim, own: &GlobalTransform) -> Vec<u32> {
    let rest = sim.rest_shape();
    let boundary = boundary_particles(sim.simulation().topology());
    if boundary.is_empty() {
        return Vec::new();
    }
    let world_rest: Vec<Vec3> = boundary
        .iter()
        .map(|&p| own.transform_point(rest[p as usize]))
        .collect();
    let (lo, hi) = world_rest
        .iter()
        .fold((Vec3::MAX, Vec3::MIN), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    let diagonal = (hi - lo).length().max(1e-6);
    // Height of each boundary particle: world up, or the mesh's +z when the cloth is level.
    let level = hi.y - lo.y < 1e-3 * diagonal;
    let height: Vec<f32> = boundary
        .iter()
        .zip(&world_rest)
        .map(|(&p, w)| if level { rest[p as usize].z } else { w.y })
        .collect();
    let top = height.iter().copied().fold(f32::MIN, f32::max);
    // Within a quarter of a mean edge of the top: one row of a grid, not the next.
    let topology = sim.simulation().topology();
    let mean_edge = if topology.edges().is_empty() {
        diagonal
    } else {
        topology.mean_rest_edge()
    };
    let scale = if level {
        // Heights are in mesh units then.
        let s = own.compute_transform().scale.max_element();
        if s > 0.0 { mean_edge / s } else { mean_edge }
    } else {
        mean_edge
    };
    boundary
        .iter()
        .zip(height)
        .filter(|(_, h)| top - h <= 0.25 * scale)
        .map(|(&p, _)| p)
        .collect()
}

/// Replaces `cloth`'s pin draft with a preset. Returns the number of vertices in the draft,
/// or `None` if `cloth` is not a simulated cloth.
pub fn pin_preset(world: &mut World, cloth: Entity, preset: PinPreset) -> Option<usize> {
    let sim = world.get::<ClothSim>(cloth)?;
    let own = world
        .get::<GlobalTransform>(cloth)
        .copied()
        .unwrap_or_default();
    let particles: Vec<u32> = match preset {
        PinPreset::None => Vec::new(),
        PinPreset::TopEdge => top_edge(sim, &own),
        PinPreset::TwoCorners => {
            let top = top_edge(sim, &own);
            let rest = sim.rest_shape();
            let at = |p: u32| rest[p as usize];
            // The two top particles farthest apart: from the centre, the farthest one; from
            // it, the farthest one again.
            let centre = top.iter().map(|&p| at(p)).sum::<Vec3>() / top.len().max(1) as f32;
            let far = |from: Vec3| {
                top.iter()
                    .copied()
                    .max_by(|a, b| at(*a).distance(from).total_cmp(&at(*b).distance(from)))
            };
            match far(centre) {
                Some(a) => {
                    let b = far(at(a)).unwrap_or(a);
                    if a == b { vec![a] } else { vec![a, b] }
                }
                None => Vec::new(),
            }
        }
    };
    let vertices: BTreeSet<u32> = particles.iter().map(|&p| vertex_of(sim, p)).collect();
    let n = vertices.len();
    set_draft(world, cloth, PinDraft { vertices });
    Some(n)
}

/// Applies `cloth`'s pin draft (the report's "update anchors"): vertices that stay pinned
/// keep their anchors; newly pinned ones are held where they are now, carried by the cloth
/// entity's transform (drag the cloth and they follow). A [`ClothPinRule`] on the cloth is
/// removed: the pins are the user's from then on (a rule would choose them again when the
/// cloth is next built). Returns the number of pins.
///
/// # Errors
/// A message when `cloth` is not a simulated cloth.
pub fn update_pins(world: &mut World, cloth: Entity) -> Result<usize, String> {
    let Some(draft) = pin_draft(world, cloth) else {
        return Err(format!("{cloth} is not a simulated cloth"));
    };
    let (Some(sim), Some(pins), Some(own)) = (
        world.get::<ClothSim>(cloth),
        world.get::<ClothPins>(cloth),
        world.get::<GlobalTransform>(cloth),
    ) else {
        return Err(format!("{cloth} is not a simulated cloth"));
    };
    let inverse = own.affine().inverse();
    let mut list = Vec::with_capacity(draft.vertices.len());
    for &v in &draft.vertices {
        let particle = sim.particle(v);
        let kept = pins.0.iter().find(|p| {
            (p.vertex as usize) < sim.weld().vertex_count() && sim.particle(p.vertex) == particle
        });
        list.push(match kept {
            Some(p) => *p,
            None => ClothPin {
                vertex: v,
                anchor: PinAnchor::Entity {
                    entity: cloth,
                    offset: inverse.transform_point3(sim.position(v)),
                },
            },
        });
    }
    let n = list.len();
    let name = world
        .get::<Name>(cloth)
        .map_or_else(|| cloth.to_string(), |n| n.to_string());
    if let Some(mut pins) = world.get_mut::<ClothPins>(cloth) {
        pins.0 = list;
    }
    let ruled = world.entity_mut(cloth).take::<ClothPinRule>().is_some();
    if let Some(mut editor) = world.get_resource_mut::<ClothEditor>() {
        editor.drafts.remove(&cloth);
    }
    let rule = if ruled {
        " (its pin rule removed: pinned by hand now)"
    } else {
        ""
    };
    say(world, format!("{name}: {n} pins{rule}"));
    Ok(n)
}

/// The object a world-space ray meets first: a cloth (its simulated triangles), a collider
/// (its shape as the solver sees it) or a wind zone (its box), with the distance along the ray.
pub fn pick(world: &mut World, ray: Ray3d) -> Option<(Entity, f32)> {
    let mut best: Option<(Entity, f32)> = None;
    let mut consider = |e: Entity, t: f32| {
        if t.is_finite() && best.is_none_or(|(_, b)| t < b) {
            best = Some((e, t));
        }
    };
    let mut cloths = world.query::<(Entity, &ClothSim)>();
    for (e, sim) in cloths.iter(world) {
        if let Some(hit) = sim.pick(ray) {
            consider(e, hit.distance);
        }
    }
    if let Some(colliders) = world.get_resource::<ClothColliders>() {
        for (c, &e) in colliders.colliders.iter().zip(&colliders.entities) {
            if let Some(t) = ray_shape(&c.shape, &c.end, ray.origin, *ray.direction) {
                consider(e, t);
            }
        }
    }
    let mut zones = world.query::<(Entity, &WindZone, &GlobalTransform)>();
    for (e, zone, gt) in zones.iter(world) {
        let region = zone.region(gt);
        let shape = Shape::Cuboid {
            half_extents: region.half_extents,
        };
        if let Some(t) = ray_shape(&shape, &region.pose, ray.origin, *ray.direction) {
            consider(e, t);
        }
    }
    best
}

/// A click along `ray`: while a cloth's pins are being edited, toggles the vertex of that
/// cloth under the ray; otherwise selects the object under it (or nothing). Returns the
/// entity clicked.
pub fn click(world: &mut World, ray: Ray3d) -> Option<Entity> {
    let editing = world.get_resource::<ClothEditor>().and_then(|e| e.pin_edit);
    if let Some(cloth) = editing {
        let hit = world.get::<ClothSim>(cloth).and_then(|s| s.pick(ray))?;
        let pinned = toggle_pin(world, cloth, hit.vertex)?;
        say(
            world,
            format!(
                "vertex {} {} (press \"update pins\" to apply)",
                hit.vertex,
                if pinned { "pinned" } else { "unpinned" }
            ),
        );
        return Some(cloth);
    }
    let hit = pick(world, ray).map(|(e, _)| e);
    world.get_resource_or_init::<ClothEditor>().selected = hit;
    hit
}
