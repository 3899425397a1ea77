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
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use serde::{Deserialize, Serialize};

use super::actions::{dress_cloth, say, spawn_collider};
use super::state::{ClothEditor, EditorGrid};
use crate::cloth::{
    Cloth, ClothConfig, ClothInertia, ClothParts, ClothPin, ClothPins, ClothSelfCollision,
    ClothSim, ClothSmoothing, ClothSource, ClothTearing, ClothTethers, PinAnchor, check_cloth,
};
use crate::collider::{ClothCollider, ColliderMesh, ColliderShape};
use crate::foundation::{EntityName, grid_mesh, read_mesh};
use crate::gpu::ClothBackend;
use crate::render::VelvetMaterial;
use crate::solver::{MAX_COORDINATE, Shape, WindParams, limits};
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
    /// Its [`ClothInertia`], if it has one (absent in files from before it existed).
    #[serde(default)]
    pub inertia: Option<SavedInertia>,
    /// Its [`ClothSmoothing`], if it has one (absent in files from before it existed).
    #[serde(default)]
    pub smoothing: Option<ClothSmoothing>,
}

/// A cloth's [`ClothInertia`] in a file.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub struct SavedInertia {
    /// Share of its anchor's linear motion the cloth feels.
    pub linear: f32,
    /// Share of its anchor's rotation the cloth feels.
    pub angular: f32,
    /// Whose motion.
    pub anchor: SavedInertiaAnchor,
}

/// The anchor of a saved [`ClothInertia`]. An anchor that is not in the file (a character's
/// bone) is saved as the cloth itself, with a warning.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
pub enum SavedInertiaAnchor {
    /// The cloth's own entity.
    Own,
    /// The saved collider of this index.
    Collider(usize),
    /// The saved cloth of this index.
    Cloth(usize),
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
    // What the cloth reads of it (a mesh without an index buffer gets its implied indices).
    let data = read_mesh(mesh).ok()?;
    Some(SavedMesh::Inline {
        positions: data.positions.iter().map(|p| p.to_array()).collect(),
        uvs: data
            .uvs
            .map(|uvs| uvs.iter().map(|uv| uv.to_array()).collect()),
        indices: data.indices,
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
            smoothing: world.get::<ClothSmoothing>(e).copied(),
            inertia: world.get::<ClothInertia>(e).map(|i| SavedInertia {
                linear: i.linear,
                angular: i.angular,
                anchor: match i.anchor {
                    None => SavedInertiaAnchor::Own,
                    Some(a) if a == e => SavedInertiaAnchor::Own,
                    Some(a) => {
                        if let Some(k) = saved_colliders.iter().position(|&c| c == a) {
                            SavedInertiaAnchor::Collider(k)
                        } else if let Some(k) = cloth_list.iter().position(|&c| c == a) {
                            SavedInertiaAnchor::Cloth(k)
                        } else {
                            let who = EntityName::in_world(world, e);
                            warn!(
                                "cloth editor: cloth {who}'s inertia anchor is not in the \
                                 file; it is saved relative to the cloth itself"
                            );
                            SavedInertiaAnchor::Own
                        }
                    }
                },
            }),
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

/// The mesh of an entry [`check_mesh`] accepted: made from the file, or an asset loaded while
/// checking (kept, so the scene is built from the mesh that was checked).
enum ReadyMesh {
    Made(Mesh),
    Loaded(Handle<Mesh>),
}

impl ReadyMesh {
    fn get<'a>(&'a self, world: &'a World) -> Option<&'a Mesh> {
        match self {
            ReadyMesh::Made(m) => Some(m),
            ReadyMesh::Loaded(h) => world.resource::<Assets<Mesh>>().get(h),
        }
    }

    fn into_handle(self, world: &mut World) -> Handle<Mesh> {
        match self {
            ReadyMesh::Made(m) => world.resource_mut::<Assets<Mesh>>().add(m),
            ReadyMesh::Loaded(h) => h,
        }
    }
}

/// Replaces the scene's cloths, colliders, wind zones and wind with `scene`'s. Everything is
/// checked first: nothing is changed when the scene cannot be built (a grid too large, a mesh
/// asset that does not exist or load, a pin on a vertex the cloth lacks or naming an object
/// the file lacks, a setting outside its limits), and the error says which object and why.
/// Mesh assets are loaded (waited for) while checking.
///
/// # Errors
/// Which object of the file is broken, and why.
pub fn load_scene(world: &mut World, scene: &ClothScene) -> Result<(), String> {
    let (cloth_meshes, collider_meshes) = check_scene(world, scene)?;
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
    for (c, mesh) in scene.colliders.iter().zip(collider_meshes) {
        let mesh = mesh.map(|m| m.into_handle(world));
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
    for (c, mesh) in scene.cloths.iter().zip(cloth_meshes) {
        let mesh = mesh.into_handle(world);
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
        if let Some(s) = c.smoothing {
            e.insert(s);
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
        if let Some(i) = c.inertia {
            let anchor = match i.anchor {
                SavedInertiaAnchor::Own => None,
                SavedInertiaAnchor::Collider(k) => Some(colliders[k]),
                SavedInertiaAnchor::Cloth(k) => Some(cloths[k]),
            };
            world.entity_mut(e).insert(ClothInertia {
                linear: i.linear,
                angular: i.angular,
                anchor,
            });
        }
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

/// Checks everything `scene` needs before the world is touched: every mesh (grids within
/// their size limit, inline triangles that index their vertices, assets that exist and load as
/// meshes), every cloth as the plugin would build it ([`check_cloth`]: mass, settings,
/// features, pinned vertices in range), pins naming objects of the file, colliders, wind zones
/// and the wind within their limits, and every transform finite. Returns the meshes to build
/// the cloths and the mesh colliders from.
fn check_scene(
    world: &mut World,
    scene: &ClothScene,
) -> Result<(Vec<ReadyMesh>, Vec<Option<ReadyMesh>>), String> {
    let named = |kind: &str, k: usize, name: &Option<String>| match name {
        Some(n) => format!("{kind} {k} ({n:?})"),
        None => format!("{kind} {k}"),
    };
    let mut cloth_meshes = Vec::with_capacity(scene.cloths.len());
    for (k, c) in scene.cloths.iter().enumerate() {
        let who = named("cloth", k, &c.name);
        check_transform(&c.transform).map_err(|e| format!("{who}: {e}"))?;
        for p in &c.pins {
            let (kind, i, len, offset) = match p.anchor {
                SavedAnchor::Rest => continue,
                SavedAnchor::World(at) => ("", 0, 1, at),
                SavedAnchor::Own(offset) => ("", 0, 1, offset),
                SavedAnchor::Collider(i, offset) => ("collider", i, scene.colliders.len(), offset),
                SavedAnchor::Cloth(i, offset) => ("cloth", i, scene.cloths.len(), offset),
            };
            if i >= len {
                return Err(format!(
                    "{who}: a pin names {kind} {i}, which is not in the file"
                ));
            }
            if !limits::within_range(offset) {
                return Err(format!(
                    "{who}: the pin of vertex {} is anchored at {offset}, not finite or over \
                     {MAX_COORDINATE} m",
                    p.vertex
                ));
            }
        }
        if let Some(i) = &c.inertia {
            let (kind, k, len) = match i.anchor {
                SavedInertiaAnchor::Own => ("", 0, 1),
                SavedInertiaAnchor::Collider(k) => ("collider", k, scene.colliders.len()),
                SavedInertiaAnchor::Cloth(k) => ("cloth", k, scene.cloths.len()),
            };
            if k >= len {
                return Err(format!(
                    "{who}: its inertia names {kind} {k}, which is not in the file"
                ));
            }
            ClothInertia {
                linear: i.linear,
                angular: i.angular,
                anchor: None,
            }
            .validate()
            .map_err(|e| format!("{who}: {e}"))?;
        }
        let mesh = check_mesh(world, &c.mesh).map_err(|e| format!("{who}: {e}"))?;
        // Pins are checked for their vertex here; their anchors above.
        let pins = ClothPins(
            c.pins
                .iter()
                .map(|p| ClothPin {
                    vertex: p.vertex,
                    anchor: PinAnchor::Rest,
                })
                .collect(),
        );
        let parts = ClothParts {
            cloth: &c.cloth,
            config: &c.config,
            pins: &pins,
            self_collision: c.self_collision.as_ref(),
            tethers: c.tethers.as_ref(),
            tearing: c.tearing.as_ref(),
        };
        let at = GlobalTransform::from(Transform::from(c.transform));
        let m = mesh
            .get(world)
            .ok_or_else(|| format!("{who}: its mesh did not load"))?;
        check_cloth(parts, m, &at).map_err(|e| format!("{who}: {e}"))?;
        cloth_meshes.push(mesh);
    }
    let mut collider_meshes = Vec::with_capacity(scene.colliders.len());
    for (k, c) in scene.colliders.iter().enumerate() {
        let who = named("collider", k, &c.name);
        check_transform(&c.transform).map_err(|e| format!("{who}: {e}"))?;
        let limits_ok = limits::COLLIDER_THICKNESS
            .check(c.thickness)
            .and_then(|()| limits::COLLIDER_FRICTION.check(c.friction))
            .and_then(|()| limits::TELEPORT_DISTANCE.check(c.teleport_distance))
            .map_err(|e| e.to_string());
        limits_ok.map_err(|e| format!("{who}: {e}"))?;
        if !c.shape.sizes_valid() {
            return Err(format!(
                "{who}: a size of {:?} is negative, not finite or over {MAX_COORDINATE} m",
                c.shape
            ));
        }
        collider_meshes.push(match (&c.shape, &c.mesh) {
            (Shape::Mesh(bake), Some(m)) => {
                // Resolutions are far below 2^24: the conversion is exact.
                limits::SDF_RESOLUTION
                    .check(bake.resolution as f32)
                    .map_err(|e| format!("{who}: {e}"))?;
                Some(check_mesh(world, m).map_err(|e| format!("{who}: {e}"))?)
            }
            (Shape::Mesh(_), None) => {
                return Err(format!("{who}: a mesh collider without its mesh"));
            }
            _ => None,
        });
    }
    for (k, z) in scene.zones.iter().enumerate() {
        let who = named("wind zone", k, &z.name);
        check_transform(&z.transform).map_err(|e| format!("{who}: {e}"))?;
        z.zone.validate().map_err(|e| format!("{who}: {e}"))?;
    }
    if let Some(w) = &scene.wind {
        w.validate().map_err(|e| format!("the wind: {e}"))?;
    }
    Ok((cloth_meshes, collider_meshes))
}

/// A placement Bevy can use: finite, within range, a unit rotation, no zero scale.
fn check_transform(t: &SavedTransform) -> Result<(), String> {
    if !limits::within_range(t.translation) {
        return Err(format!(
            "position {} is not finite or over {MAX_COORDINATE} m",
            t.translation
        ));
    }
    if !(t.rotation.is_finite() && (t.rotation.length() - 1.0).abs() < 1e-3) {
        return Err(format!("rotation {} is not a unit quaternion", t.rotation));
    }
    if !(limits::within_range(t.scale) && t.scale.abs().min_element() > 0.0) {
        return Err(format!(
            "scale {} is zero, not finite or too large",
            t.scale
        ));
    }
    Ok(())
}

/// Whether `m` can be built in this app: a grid within its limits, triangles that index
/// their vertices, an asset that exists and loads as a mesh (loaded now: the file is checked
/// against the mesh itself); and mesh assets to put it in. Returns the mesh.
fn check_mesh(world: &mut World, m: &SavedMesh) -> Result<ReadyMesh, String> {
    if !world.contains_resource::<Assets<Mesh>>() {
        return Err("this app has no mesh assets (MeshPlugin)".into());
    }
    match m {
        SavedMesh::Grid {
            columns,
            rows,
            width,
            height,
        } => {
            let grid = crate::solver::Grid::new(*columns, *rows, *width, *height);
            grid.validate().map_err(|e| e.to_string())?;
            Ok(ReadyMesh::Made(grid_mesh(&grid)))
        }
        SavedMesh::Asset(p) if p.trim().is_empty() => Err("an empty asset path".into()),
        SavedMesh::Asset(p) => load_mesh_now(world, p).map(ReadyMesh::Loaded),
        SavedMesh::Inline {
            positions,
            uvs,
            indices,
        } => {
            let n = positions.len();
            if n > limits::MAX_VERTICES || indices.len() / 3 > limits::MAX_TRIANGLES {
                return Err(format!(
                    "{n} vertices and {} triangles: a cloth may have at most {} and {}",
                    indices.len() / 3,
                    limits::MAX_VERTICES,
                    limits::MAX_TRIANGLES
                ));
            }
            if indices.iter().any(|&i| i as usize >= n) {
                return Err(format!("an index is beyond the {n} vertices"));
            }
            if uvs.as_ref().is_some_and(|u| u.len() != n) {
                return Err(format!("texture coordinates do not match the {n} vertices"));
            }
            let mut mesh = Mesh::new(
                PrimitiveTopology::TriangleList,
                RenderAssetUsages::default(),
            )
            .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions.clone())
            .with_inserted_indices(Indices::U32(indices.clone()));
            if let Some(uv) = uvs {
                mesh.insert_attribute(Mesh::ATTRIBUTE_UV_0, uv.clone());
            }
            Ok(ReadyMesh::Made(mesh))
        }
    }
}

/// Loads the mesh asset at `path` now, waiting for it, and puts it in `Assets<Mesh>` (rather
/// than at the next frame), so a file naming a missing file, a missing label or something
/// that is not a mesh is refused before the scene is replaced.
fn load_mesh_now(world: &mut World, path: &str) -> Result<Handle<Mesh>, String> {
    let Some(server) = world.get_resource::<AssetServer>().cloned() else {
        return Err(format!("this app has no asset server to load {path}"));
    };
    let owned = bevy::asset::AssetPath::from(path.to_owned());
    let handle = bevy::tasks::block_on(server.load_builder().load_untyped_async(owned))
        .map_err(|e| format!("cannot load {path}: {e}"))?;
    bevy::asset::handle_internal_asset_events(world);
    let handle = handle.try_typed::<Mesh>().map_err(|_| {
        format!(
            "{path} is not a mesh (a glTF file's mesh is named by a label, e.g. \
             model.glb#Mesh0/Primitive0)"
        )
    })?;
    if world.resource::<Assets<Mesh>>().get(&handle).is_none() {
        return Err(format!("{path} did not load as a mesh"));
    }
    Ok(handle)
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
