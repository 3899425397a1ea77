//! A hint for the first thing a cloth dressed in a plain `StandardMaterial` shows: where it
//! turns its back to the camera, it disappears.

use bevy::ecs::entity::EntityHashMap;
use bevy::prelude::*;
use bevy::render::render_resource::Face;

use super::ClothSim;
use crate::foundation::EntityName;

/// What to tell the user about a cloth drawn with `material`, when it culls a side: a cloth
/// shows both (a flag turning in the wind, a cape seen from the front).
pub(super) fn one_sided_warning(material: &StandardMaterial) -> Option<String> {
    let side = match material.cull_mode {
        Some(Face::Back) => "back",
        Some(Face::Front) => "front",
        None => return None,
    };
    Some(format!(
        "its StandardMaterial culls {side} faces, so wherever the cloth turns that side to the \
         camera it disappears; dress it in `lined_velvet(color)` or \
         `velvet_material_from(your_material, VelvetExtension::default())` (add `VelvetPlugin`), \
         which draw and light both sides, or set the material's `cull_mode: None` (Bevy then \
         lights the back as if it were the front: see the README's *Velvet*)"
    ))
}

/// A cloth entity drawn with a `StandardMaterial`.
type Dressed<'a> = (
    Entity,
    Option<&'a Name>,
    &'a MeshMaterial3d<StandardMaterial>,
);

/// Warns once per cloth entity and material whose `StandardMaterial` (once loaded) culls a
/// side: again when the entity is given another material that does. Runs only in apps with a
/// renderer's materials.
pub(super) fn warn_one_sided_materials(
    materials: Res<Assets<StandardMaterial>>,
    cloths: Query<Dressed, With<ClothSim>>,
    mut seen: Local<EntityHashMap<AssetId<StandardMaterial>>>,
) {
    // Forget despawned cloths (and ones dressed otherwise now) once they are most of the map.
    if seen.len() > 2 * cloths.iter().len() + 64 {
        seen.retain(|entity, _| cloths.contains(*entity));
    }
    for (entity, name, material) in &cloths {
        let id = material.id();
        if seen.get(&entity) == Some(&id) {
            continue;
        }
        // A material still loading is looked at once it is there.
        let Some(material) = materials.get(id) else {
            continue;
        };
        seen.insert(entity, id);
        if let Some(why) = one_sided_warning(material) {
            warn!("cloth {}: {why}", EntityName::new(entity, name));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_material_that_culls_a_side_is_named_and_a_two_sided_one_is_not() {
        let plain = StandardMaterial::default();
        let why = one_sided_warning(&plain).expect("Bevy's default culls back faces");
        assert!(why.contains("culls back faces"), "{why}");
        let front = StandardMaterial {
            cull_mode: Some(Face::Front),
            ..default()
        };
        assert!(one_sided_warning(&front).is_some_and(|w| w.contains("front faces")));
        let both = StandardMaterial {
            cull_mode: None,
            double_sided: true,
            ..default()
        };
        assert_eq!(one_sided_warning(&both), None);
    }
}
