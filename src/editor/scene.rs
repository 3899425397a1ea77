//! Scene files: every cloth, collider and wind zone and the global wind, saved to RON and
//! loaded back exactly (a save, a load and a second save give the same text).
//!
//! A cloth's mesh is saved as the grid the editor made it from ([`EditorGrid`]), as the asset
//! path it was loaded from, or else vertex by vertex. Pins anchored to the cloth itself, to a
//! saved collider or to another saved cloth keep their anchor; pins anchored to anything
//! else are saved where that anchor is now. Transforms are saved in world space, so a child
//! entity comes back as a root at the same place.
//!
//! Objects are listed by name, so save the names you want to keep the order of; unnamed
//! objects of the same kind may come back in another order (the scene is the same).
//!
//! Loading **replaces** the scene's cloths, colliders and wind zones (despawned with their
//! children) and the [`Wind`] resource.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;
use serde::{Deserialize, Serialize};

use super::actions::{dress_cloth, say, spawn_collider};
use super::state::{ClothEditor, EditorGrid};
use crate::cloth::{
    Cloth, ClothConfig, ClothPin, ClothPins, ClothSelfCollision, ClothSim, ClothSource,
    ClothTearing, ClothTethers, PinAnchor,
};
use crate::collider::{ClothCollider, ColliderMesh, ColliderShape};
use crate::foundation::{EntityName, grid_mesh};
use crate::gpu::ClothBackend;
use crate::render::VelvetMaterial;
use crate::solver::{Shape, WindParams};
use crate::wind::{Wind, WindZone};

/// A whole scene's cloth setup, as saved.
#[derive(Serialize, Deserialize, Clone, Debug, Default, PartialEq)]
pub struct ClothScene {
    /// Every cloth.
    pub cloths: Vec<SavedCloth>,
    /// Every collider.
    pub colliders: Vec<SavedCollider>,
    /// The global wind, if any.
    pub wind: Option<WindParams>,
    /// Every wind zone.
    pub zones: Vec<SavedZone>,
}

/// A world-space placement.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SavedTransform {
    /// Position.
    pub translation: Vec3,
    /// Orientation.
    pub rotation: Quat,
    /// Scale.
    pub scale: Vec3,
}

impl From<Transform> for SavedTransform {
    fn from(t: Transform) -> Self {
        Self {
            translation: t.translation,
            rotation: t.rotation,
            scale: t.scale,
        }
    }
}

impl From<SavedTransform> for Transform {
    fn from(t: SavedTransform) -> Self {
        Self {
            translation: t.translation,
            rotation: t.rotation,
            scale: t.scale,
        }
    }
}

/// Where a mesh comes from.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub enum SavedMesh {
    /// A grid made by the editor (see [`EditorGrid`]).
    Grid {
        /// Vertices along the width.
        columns: u32,
        /// Vertices along the height.
        rows: u32,
        /// Width in metres.
        width: f32,
        /// Height in metres.
        height: f32,
    },
    /// An asset path (with its label), loaded through the asset server.
    Asset(String),
    /// The triangles themselves.
    Inline {
        /// Vertex positions.
        positions: Vec<[f32; 3]>,
        /// Texture coordinates, if the mesh has them.
        uvs: Option<Vec<[f32; 2]>>,
        /// Triangle list.
        indices: Vec<u32>,
    },
}

/// A pin's anchor in a file.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub enum SavedAnchor {
    /// [`PinAnchor::Rest`].
    Rest,
    /// [`PinAnchor::World`].
    World(Vec3),
    /// Anchored to the cloth's own entity at this offset.
    Own(Vec3),
    /// Anchored to the saved collider of this index at this offset.
    Collider(usize, Vec3),
    /// Anchored to the saved cloth of this index at this offset.
    Cloth(usize, Vec3),
}

/// A pinned vertex in a file.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SavedPin {
    /// Mesh vertex index.
    pub vertex: u32,
    /// Its anchor.
    pub anchor: SavedAnchor,
}

/// A cloth in a file.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SavedCloth {
    /// Its [`Name`], if it has one.
    pub name: Option<String>,
    /// Where it is.
    pub transform: SavedTransform,
    /// Its source mesh.
    pub mesh: SavedMesh,
    /// Its material's base colour (sRGBA), if it has a standard or velvet material.
    pub color: Option<[f32; 4]>,
    /// Mass, mass distribution, bending model, ...
    pub cloth: Cloth,
    /// Solver settings.
    pub config: ClothConfig,
    /// Pins.
    pub pins: Vec<SavedPin>,
    /// Self-collision, if on.
    pub self_collision: Option<ClothSelfCollision>,
    /// Tethers, if on.
    pub tethers: Option<ClothTethers>,
    /// Tearing, if on.
    pub tearing: Option<ClothTearing>,
    /// The backend asked for, if set on the entity.
    pub backend: Option<ClothBackend>,
}

/// How finely a mesh collider in a file is baked (its mesh is [`SavedCollider::mesh`]).
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SavedBake {
    /// Cells along the mesh's longest side.
    pub resolution: u32,
}

/// A collider shape in a file: the crate's one [`Shape`], whose mesh shape says how finely
/// it is baked.
pub type SavedShape = Shape<SavedBake>;

/// A collider in a file.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SavedCollider {
    /// Its [`Name`], if it has one.
    pub name: Option<String>,
    /// Where it is.
    pub transform: SavedTransform,
    /// Its shape.
    pub shape: SavedShape,
    /// The mesh of a mesh shape.
    pub mesh: Option<SavedMesh>,
    /// Gap kept from the surface.
    pub thickness: f32,
    /// Friction.
    pub friction: f32,
    /// Teleport distance.
    pub teleport_distance: f32,
}

/// A wind zone in a file.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SavedZone {
    /// Its [`Name`], if it has one.
    pub name: Option<String>,
    /// Where it is.
    pub transform: SavedTransform,
    /// The zone.
    pub zone: WindZone,
}

/// An attached pin as the entity pin it became when it was applied (the offset it has kept
/// since); other pins as they are.
fn attached_as_entity(world: &World, cloth: Entity, pin: ClothPin) -> PinAnchor {
    match pin.anchor {
        PinAnchor::Attached(entity) => world
            .get::<ClothSim>(cloth)
            .and_then(|s| s.attached_offset(pin.vertex, entity))
            .map_or(pin.anchor, |offset| PinAnchor::Entity { entity, offset }),
        other => other,
    }
}

fn world_transform(world: &World, e: Entity) -> SavedTransform {
    // A root entity's own transform (exact); a child's composed world transform.
    if world.get::<ChildOf>(e).is_none()
        && let Some(t) = world.get::<Transform>(e)
    {
        return (*t).into();
    }
    world
        .get::<GlobalTransform>(e)
        .map(|g| g.compute_transform().into())
        .unwrap_or_else(|| Transform::default().into())
}

fn name_of(world: &World, e: Entity) -> Option<String> {
    world.get::<Name>(e).map(|n| n.as_str().to_string())
}

fn color_of(world: &World, e: Entity) -> Option<[f32; 4]> {
    let base = if let Some(m) = world.get::<MeshMaterial3d<StandardMaterial>>(e) {
        world
            .get_resource::<Assets<StandardMaterial>>()?
            .get(&m.0)?
            .base_color
    } else {
        let m = world.get::<MeshMaterial3d<VelvetMaterial>>(e)?;
        world
            .get_resource::<Assets<VelvetMaterial>>()?
            .get(&m.0)?
            .base
            .base_color
    };
    Some(base.to_srgba().to_f32_array())
}

fn mesh_of(world: &World, handle: &Handle<Mesh>) -> Option<SavedMesh> {
    if let Some(path) = handle.path() {
        return Some(SavedMesh::Asset(path.to_string()));
    }
    let mesh = world.get_resource::<Assets<Mesh>>()?.get(handle)?;
    let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute(Mesh::ATTRIBUTE_POSITION) else {
        return None;
    };
    let uvs = match mesh.attribute(Mesh::ATTRIBUTE_UV_0) {
        Some(VertexAttributeValues::Float32x2(uv)) => Some(uv.clone()),
        _ => None,
    };
    let indices = mesh.indices()?.iter().map(|i| i as u32).collect();
    Some(SavedMesh::Inline {
        positions: p.clone(),
        uvs,
        indices,
    })
}

/// The scene's cloth setup as it is now.
pub fn save_scene(world: &mut World) -> ClothScene {
    let mut collider_list: Vec<Entity> = world
        .query_filtered::<Entity, With<ClothCollider>>()
        .iter(world)
        .collect();
    let mut cloth_list: Vec<Entity> = world
        .query_filtered::<Entity, With<Cloth>>()
        .iter(world)
        .collect();
    let mut zone_list: Vec<Entity> = world
        .query_filtered::<Entity, With<WindZone>>()
        .iter(world)
        .collect();
    // By name (then entity): a loaded scene saves in the same order it was read.
    let key = |world: &World, e: &Entity| (name_of(world, *e), *e);
    collider_list.sort_by_cached_key(|e| key(world, e));
    cloth_list.sort_by_cached_key(|e| key(world, e));
    zone_list.sort_by_cached_key(|e| key(world, e));
    let world = &*world;
    let mut scene = ClothScene {
        wind: world.get_resource::<Wind>().map(|w| w.0),
        ..default()
    };
    for &e in &collider_list {
        let c = world.get::<ClothCollider>(e).expect("queried");
        let (shape, mesh) = match &c.shape {
            ColliderShape::Mesh(ColliderMesh::Asset { mesh, resolution }) => {
                let handle = mesh
                    .clone()
                    .or_else(|| world.get::<Mesh3d>(e).map(|m| m.0.clone()));
                let saved = handle.as_ref().and_then(|h| mesh_of(world, h));
                if saved.is_none() {
                    let who = EntityName::in_world(world, e);
                    warn!("cloth editor: collider {who}'s mesh is not loaded; it is not saved");
                    continue;
                }
                (
                    Shape::Mesh(SavedBake {
                        resolution: *resolution,
                    }),
                    saved,
                )
            }
            ColliderShape::Mesh(ColliderMesh::Baked(_)) => {
                let who = EntityName::in_world(world, e);
                warn!("cloth editor: collider {who} is an already baked field; it is not saved");
                continue;
            }
            analytic => (
                analytic
                    .clone()
                    .try_map_mesh(|_| None)
                    .expect("mesh shapes are matched above"),
                None,
            ),
        };
        scene.colliders.push(SavedCollider {
            name: name_of(world, e),
            transform: world_transform(world, e),
            shape,
            mesh,
            thickness: c.thickness,
            friction: c.friction,
            teleport_distance: c.teleport_distance,
        });
    }
    // Colliders that were skipped are not anchors.
    let saved_colliders: Vec<Entity> = collider_list
        .iter()
        .copied()
        .filter(|&e| {
            !matches!(
                world.get::<ClothCollider>(e).map(|c| &c.shape),
                Some(ColliderShape::Mesh(ColliderMesh::Baked(_)))
            )
        })
        .collect();
    for &e in &cloth_list {
        let mesh = if let Some(g) = world.get::<EditorGrid>(e) {
            Some(SavedMesh::Grid {
                columns: g.columns,
                rows: g.rows,
                width: g.width,
                height: g.height,
            })
        } else {
            let handle = world
                .get::<ClothSource>(e)
                .map(|s| s.source.clone())
                .or_else(|| world.get::<Mesh3d>(e).map(|m| m.0.clone()));
            handle.and_then(|h| mesh_of(world, &h))
        };
        let Some(mesh) = mesh else {
            let who = EntityName::in_world(world, e);
            warn!("cloth editor: cloth {who}'s mesh is not loaded; it is not saved");
            continue;
        };
        let pins = world
            .get::<ClothPins>(e)
            .map(|p| p.0.clone())
            .unwrap_or_default()
            .into_iter()
            .map(|p| SavedPin {
                vertex: p.vertex,
                anchor: match attached_as_entity(world, e, p) {
                    PinAnchor::Rest => SavedAnchor::Rest,
                    PinAnchor::World(w) => SavedAnchor::World(w),
                    PinAnchor::Entity { entity, offset } => {
                        if entity == e {
                            SavedAnchor::Own(offset)
                        } else if let Some(i) = saved_colliders.iter().position(|&c| c == entity) {
                            SavedAnchor::Collider(i, offset)
                        } else if let Some(i) = cloth_list.iter().position(|&c| c == entity) {
                            SavedAnchor::Cloth(i, offset)
                        } else {
                            // Not in the file: held where its anchor is now.
                            let at = world
                                .get::<GlobalTransform>(entity)
                                .map_or(offset, |g| g.transform_point(offset));
                            SavedAnchor::World(at)
                        }
                    }
                    // Its entity has no pose yet: held where it is.
                    PinAnchor::Attached(_) => SavedAnchor::World(
                        world
                            .get::<ClothSim>(e)
                            .map_or(Vec3::ZERO, |s| s.position(p.vertex)),
                    ),
                },
            })
            .collect();
        scene.cloths.push(SavedCloth {
            name: name_of(world, e),
            transform: world_transform(world, e),
            mesh,
            color: color_of(world, e),
            cloth: *world.get::<Cloth>(e).expect("queried"),
            config: world.get::<ClothConfig>(e).copied().unwrap_or_default(),
            pins,
            self_collision: world.get::<ClothSelfCollision>(e).copied(),
            tethers: world.get::<ClothTethers>(e).copied(),
            tearing: world.get::<ClothTearing>(e).copied(),
            backend: world.get::<ClothBackend>(e).copied(),
        });
    }
    for &e in &zone_list {
        scene.zones.push(SavedZone {
            name: name_of(world, e),
            transform: world_transform(world, e),
            zone: *world.get::<WindZone>(e).expect("queried"),
        });
    }
    scene
}

/// The scene as RON text.
///
/// # Errors
/// The serializer's message (it has none to give for these types in practice).
pub fn scene_to_ron(scene: &ClothScene) -> Result<String, String> {
    ron::ser::to_string_pretty(scene, ron::ser::PrettyConfig::new().struct_names(true))
        .map_err(|e| e.to_string())
}

/// A scene from RON text.
///
/// # Errors
/// Where and why the text is not a scene.
pub fn scene_from_ron(text: &str) -> Result<ClothScene, String> {
    ron::from_str(text).map_err(|e| e.to_string())
}

/// The mesh of an entry [`check_mesh`] accepted.
fn build_mesh(world: &mut World, saved: &SavedMesh) -> Handle<Mesh> {
    let mesh = match saved {
        SavedMesh::Grid {
            columns,
            rows,
            width,
            height,
        } => grid_mesh(&crate::solver::Grid::new(*columns, *rows, *width, *height)),
        SavedMesh::Asset(path) => return world.resource::<AssetServer>().load(path.clone()),
        SavedMesh::Inline {
            positions,
            uvs,
            indices,
        } => {
            let mut m = Mesh::new(
                PrimitiveTopology::TriangleList,
                RenderAssetUsages::default(),
            )
            .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions.clone())
            .with_inserted_indices(Indices::U32(indices.clone()));
            if let Some(uv) = uvs {
                m.insert_attribute(Mesh::ATTRIBUTE_UV_0, uv.clone());
            }
            m
        }
    };
    world.resource_mut::<Assets<Mesh>>().add(mesh)
}

/// Replaces the scene's cloths, colliders, wind zones and wind with `scene`'s. Everything is
/// checked first: nothing is changed when the scene cannot be built (a bad grid or mesh in
/// it, a pin naming an object it lacks), and the error says which.
///
/// # Errors
/// Which object of the file is broken, and why.
pub fn load_scene(world: &mut World, scene: &ClothScene) -> Result<(), String> {
    // Check the meshes first, so a broken file changes nothing.
    for (k, c) in scene.cloths.iter().enumerate() {
        check_mesh(world, &c.mesh).map_err(|e| format!("cloth {k}: {e}"))?;
        for p in &c.pins {
            match p.anchor {
                SavedAnchor::Collider(i, _) if i >= scene.colliders.len() => {
                    return Err(format!(
                        "cloth {k}: a pin names collider {i}, which is not in the file"
                    ));
                }
                SavedAnchor::Cloth(i, _) if i >= scene.cloths.len() => {
                    return Err(format!(
                        "cloth {k}: a pin names cloth {i}, which is not in the file"
                    ));
                }
                _ => {}
            }
        }
    }
    for (k, c) in scene.colliders.iter().enumerate() {
        match (&c.shape, &c.mesh) {
            (Shape::Mesh(_), Some(m)) => {
                check_mesh(world, m).map_err(|e| format!("collider {k}: {e}"))?;
            }
            (Shape::Mesh(_), None) => {
                return Err(format!("collider {k}: a mesh collider without its mesh"));
            }
            _ => {}
        }
    }
    // Out with the old.
    let old: Vec<Entity> = world
        .query_filtered::<Entity, Or<(With<Cloth>, With<ClothCollider>, With<WindZone>)>>()
        .iter(world)
        .collect();
    for e in old {
        if world.get_entity(e).is_ok() {
            world.entity_mut(e).despawn();
        }
    }
    if let Some(mut editor) = world.get_resource_mut::<ClothEditor>() {
        editor.drafts.clear();
        editor.selected = None;
        editor.pin_edit = None;
        editor.drag = None;
        editor.loading.clear();
    }
    match scene.wind {
        Some(w) => world.insert_resource(Wind(w)),
        None => {
            world.remove_resource::<Wind>();
        }
    }
    // Colliders first: pins may name them.
    let mut colliders = Vec::with_capacity(scene.colliders.len());
    for c in &scene.colliders {
        let mesh = match c.shape {
            Shape::Mesh(_) => Some(build_mesh(world, c.mesh.as_ref().expect("checked above"))),
            _ => None,
        };
        let shape = c.shape.map_mesh(|bake| ColliderMesh::Asset {
            mesh: None,
            resolution: bake.resolution,
        });
        let collider = ClothCollider {
            shape,
            thickness: c.thickness,
            friction: c.friction,
            teleport_distance: c.teleport_distance,
        };
        let e = spawn_collider(world, String::new(), collider, c.transform.into(), mesh);
        set_name(world, e, &c.name);
        colliders.push(e);
    }
    // Cloths: spawned first, pinned after (pins may name other cloths).
    let mut cloths = Vec::with_capacity(scene.cloths.len());
    for c in &scene.cloths {
        let mesh = build_mesh(world, &c.mesh);
        let mut e = world.spawn((
            Mesh3d(mesh),
            Transform::from(c.transform),
            c.cloth,
            c.config,
        ));
        if let Some(n) = &c.name {
            e.insert(Name::new(n.clone()));
        }
        if let SavedMesh::Grid {
            columns,
            rows,
            width,
            height,
        } = c.mesh
        {
            e.insert(EditorGrid {
                columns,
                rows,
                width,
                height,
            });
        }
        if let Some(f) = c.self_collision {
            e.insert(f);
        }
        if let Some(f) = c.tethers {
            e.insert(f);
        }
        if let Some(f) = c.tearing {
            e.insert(f);
        }
        if let Some(b) = c.backend {
            e.insert(b);
        }
        let id = e.id();
        if let Some([r, g, b, a]) = c.color {
            dress_cloth(world, id, Color::srgba(r, g, b, a));
        }
        cloths.push(id);
    }
    for (c, &e) in scene.cloths.iter().zip(&cloths) {
        let pins = c
            .pins
            .iter()
            .map(|p| ClothPin {
                vertex: p.vertex,
                anchor: match p.anchor {
                    SavedAnchor::Rest => PinAnchor::Rest,
                    SavedAnchor::World(w) => PinAnchor::World(w),
                    SavedAnchor::Own(offset) => PinAnchor::Entity { entity: e, offset },
                    SavedAnchor::Collider(i, offset) => PinAnchor::Entity {
                        entity: colliders[i],
                        offset,
                    },
                    SavedAnchor::Cloth(i, offset) => PinAnchor::Entity {
                        entity: cloths[i],
                        offset,
                    },
                },
            })
            .collect();
        world.entity_mut(e).insert(ClothPins(pins));
    }
    for z in &scene.zones {
        let e = world.spawn((z.zone, Transform::from(z.transform))).id();
        set_name(world, e, &z.name);
    }
    Ok(())
}

fn set_name(world: &mut World, e: Entity, name: &Option<String>) {
    match name {
        Some(n) => {
            world.entity_mut(e).insert(Name::new(n.clone()));
        }
        None => {
            world.entity_mut(e).remove::<Name>();
        }
    }
}

/// Whether `m` can be built in this app: a valid grid, an asset path with an asset server,
/// triangles that index their vertices; and mesh assets to put it in.
fn check_mesh(world: &World, m: &SavedMesh) -> Result<(), String> {
    if !world.contains_resource::<Assets<Mesh>>() {
        return Err("this app has no mesh assets (MeshPlugin)".into());
    }
    match m {
        SavedMesh::Grid {
            columns,
            rows,
            width,
            height,
        } => crate::solver::Grid::new(*columns, *rows, *width, *height)
            .validate()
            .map_err(|e| e.to_string()),
        SavedMesh::Asset(p) if p.trim().is_empty() => Err("an empty asset path".into()),
        SavedMesh::Asset(p) if !world.contains_resource::<AssetServer>() => {
            Err(format!("this app has no asset server to load {p}"))
        }
        SavedMesh::Asset(_) => Ok(()),
        SavedMesh::Inline {
            positions,
            uvs,
            indices,
        } => {
            let n = positions.len();
            if indices.iter().any(|&i| i as usize >= n) {
                return Err(format!("an index is beyond the {n} vertices"));
            }
            if uvs.as_ref().is_some_and(|u| u.len() != n) {
                return Err(format!("texture coordinates do not match the {n} vertices"));
            }
            Ok(())
        }
    }
}

/// Saves the scene to a RON file.
///
/// # Errors
/// The file could not be written.
pub fn save_scene_file(world: &mut World, path: &str) -> Result<(), String> {
    let text = scene_to_ron(&save_scene(world))?;
    std::fs::write(path, text).map_err(|e| format!("cannot write {path}: {e}"))?;
    say(world, format!("saved {path}"));
    Ok(())
}

/// Loads a RON scene file, replacing the scene's cloths, colliders and wind.
///
/// # Errors
/// The file could not be read, is not a scene, or names broken objects; nothing changed.
pub fn load_scene_file(world: &mut World, path: &str) -> Result<(), String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read {path}: {e}"))?;
    let scene = scene_from_ron(&text).map_err(|e| format!("{path}: {e}"))?;
    load_scene(world, &scene).map_err(|e| format!("{path}: {e}"))?;
    say(world, format!("loaded {path}"));
    Ok(())
}
