//! [`ClothPinRule`]: pins chosen by where a mesh's vertices rest or how they are painted, for
//! meshes whose vertex indices the game does not know (a glTF cape, a Bevy `Plane3d`).

use bevy::ecs::entity::{EntityMapper, MapEntities};
use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use super::error::report;
use super::systems::note_rejection;
use super::{
    Cloth, ClothError, ClothInvalid, ClothPin, ClothPins, ClothSim, ClothSource, PinAnchor,
};
use crate::foundation::{EntityName, finite_bounds};

/// Pins the vertices of a cloth's mesh that a [`VertexSelection`] chooses, all to the same
/// kind of anchor: the way to pin a mesh made elsewhere (a glTF cape from a modelling tool,
/// Bevy's `Plane3d` mesh), whose vertex indices the game does not know before it loads.
///
/// The rule is resolved against the mesh the user gave (its positions in the mesh's own
/// space, before the entity's transform; its vertex colours) whenever the cloth is built from
/// it (when the mesh has loaded, is replaced or changes) and whenever the rule changes, and
/// its result is written into the entity's [`ClothPins`]: while the rule is on the entity,
/// it owns `ClothPins` (remove the rule to pin by hand, or to edit its result). A rule that
/// is invalid or selects no vertex is reported ([`ClothError::PinRule`], naming the mesh's
/// bounds or the largest painted value): a cloth not yet running is not built
/// ([`ClothInvalid`]) until the rule or the mesh changes; a running one keeps its pins.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// fn spawn(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>) {
///     // A 2 m × 1 m flag from Bevy's own plane mesh (in the XZ plane), hung by its
///     // -X edge from where the entity is.
///     let plane = Plane3d::default().mesh().size(2.0, 1.0).subdivisions(15);
///     commands.spawn((
///         Mesh3d(meshes.add(plane)),
///         Transform::from_xyz(0.0, 2.0, 0.0),
///         Cloth::default(),
///         ClothPinRule::rest(VertexSelection::Farthest {
///             towards: Vec3::NEG_X,
///             within: 0.001,
///         }),
///     ));
/// }
/// # bevy::ecs::system::assert_is_system(spawn);
/// ```
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[component(map_entities)]
#[reflect(Component, Clone, PartialEq)]
pub struct ClothPinRule {
    /// Which vertices are pinned.
    pub select: VertexSelection,
    /// What each of them is pinned to: [`PinAnchor::Rest`] (where it rests, following the
    /// cloth entity) or [`PinAnchor::Attached`] (carried by another entity from where it is
    /// when pinned) give each vertex its own place; [`PinAnchor::World`] and
    /// [`PinAnchor::Entity`] gather them all at one point (a bag on a hook).
    pub anchor: PinAnchor,
}

impl MapEntities for ClothPinRule {
    fn map_entities<E: EntityMapper>(&mut self, mapper: &mut E) {
        match &mut self.anchor {
            PinAnchor::Entity { entity, .. } | PinAnchor::Attached(entity) => {
                *entity = mapper.get_mapped(*entity);
            }
            PinAnchor::Rest | PinAnchor::World(_) => {}
        }
    }
}

impl ClothPinRule {
    /// Pins the selected vertices at their rest positions (following the cloth entity).
    #[must_use]
    pub fn rest(select: VertexSelection) -> Self {
        Self {
            select,
            anchor: PinAnchor::Rest,
        }
    }

    /// Pins the selected vertices to `entity` where they are when the pins are applied
    /// ([`PinAnchor::Attached`]): a cape spawned on its character's back, attached to its
    /// shoulders.
    #[must_use]
    pub fn attached(select: VertexSelection, entity: Entity) -> Self {
        Self {
            select,
            anchor: PinAnchor::Attached(entity),
        }
    }

    /// The pins this rule gives `mesh`.
    ///
    /// # Errors
    /// The rule is invalid, the mesh lacks what it reads, or it selects no vertex.
    pub fn pins(&self, mesh: &Mesh) -> Result<ClothPins, PinRuleError> {
        let vertices = self.select.select(mesh)?;
        Ok(ClothPins(
            vertices
                .into_iter()
                .map(|vertex| ClothPin {
                    vertex,
                    anchor: self.anchor,
                })
                .collect(),
        ))
    }
}

/// Which vertices of a mesh a [`ClothPinRule`] pins. Positions are the mesh's own (as the
/// asset stores them, before the entity's transform); a vertex with a non-finite position is
/// never selected.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Clone, PartialEq)]
pub enum VertexSelection {
    /// The vertices resting inside a box (bounds included).
    Within {
        /// The box's lowest corner.
        min: Vec3,
        /// The box's highest corner (at least `min` on every axis).
        max: Vec3,
    },
    /// The vertices resting within `within` of the mesh's farthest extent along a direction:
    /// `Farthest { towards: Vec3::Y, within: 0.01 }` is the top edge of a hanging sheet, the
    /// top ring of a tube. `within` 0 selects the vertices exactly on the extent (a grid's
    /// edge row, whose coordinate is the same number).
    Farthest {
        /// The direction (any length but zero).
        towards: Vec3,
        /// How far below the extent a vertex may rest and still be selected, mesh units (≥ 0).
        within: f32,
    },
    /// The vertices painted in a modelling tool: those whose vertex colour
    /// (`Mesh::ATTRIBUTE_COLOR`, glTF `COLOR_0`) has at least `at_least` in `channel`. A
    /// cloth built with this rule drops the colours from its own mesh copy, so the paint
    /// does not tint its material.
    Painted {
        /// The colour channel read.
        channel: ColorChannel,
        /// The least value selected (a finite number; 0.5 selects what was painted more
        /// than half).
        at_least: f32,
    },
}

/// A channel of a vertex colour, for [`VertexSelection::Painted`].
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Clone, Default, PartialEq)]
pub enum ColorChannel {
    /// Red (the default: paint pinned vertices red).
    #[default]
    Red,
    /// Green.
    Green,
    /// Blue.
    Blue,
    /// Alpha.
    Alpha,
}

impl ColorChannel {
    fn index(self) -> usize {
        match self {
            ColorChannel::Red => 0,
            ColorChannel::Green => 1,
            ColorChannel::Blue => 2,
            ColorChannel::Alpha => 3,
        }
    }
}

/// Why a [`ClothPinRule`] gives no pins.
#[derive(Clone, Debug, PartialEq)]
pub enum PinRuleError {
    /// A value of the rule is out of range: what and why.
    Invalid(String),
    /// The mesh has no `Float32x3` positions.
    NoPositions,
    /// A [`VertexSelection::Painted`] rule on a mesh without vertex colours
    /// (`Mesh::ATTRIBUTE_COLOR`, `Float32x4`, one per vertex).
    NoColors,
    /// No vertex of the mesh is selected: where its vertices lie (mesh space), or the largest
    /// value painted in the channel read.
    NothingSelected(String),
}

impl core::fmt::Display for PinRuleError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PinRuleError::Invalid(why) => write!(f, "pin rule: {why}"),
            PinRuleError::NoPositions => write!(f, "pin rule: the mesh has no Float32x3 positions"),
            PinRuleError::NoColors => write!(
                f,
                "pin rule: the mesh has no Float32x4 vertex colours (ATTRIBUTE_COLOR, glTF \
                 COLOR_0) to read the paint from"
            ),
            PinRuleError::NothingSelected(where_) => {
                write!(f, "pin rule selects no vertex of the mesh: {where_}")
            }
        }
    }
}

impl std::error::Error for PinRuleError {}

impl VertexSelection {
    /// The indices of the vertices of `mesh` this selects, in increasing order.
    ///
    /// # Errors
    /// The selection's values are out of range, the mesh lacks what it reads, or no vertex is
    /// selected.
    pub fn select(&self, mesh: &Mesh) -> Result<Vec<u32>, PinRuleError> {
        let Some(VertexAttributeValues::Float32x3(positions)) =
            mesh.attribute(Mesh::ATTRIBUTE_POSITION)
        else {
            return Err(PinRuleError::NoPositions);
        };
        let positions: Vec<Vec3> = positions.iter().map(|p| Vec3::from(*p)).collect();
        self.select_from(&positions, || colors(mesh))
    }

    /// [`select`](Self::select) on positions (and colours, read only when painted).
    fn select_from(
        &self,
        positions: &[Vec3],
        colors: impl FnOnce() -> Option<Vec<[f32; 4]>>,
    ) -> Result<Vec<u32>, PinRuleError> {
        let invalid = |why: String| Err(PinRuleError::Invalid(why));
        let indexed = |keep: &dyn Fn(usize, Vec3) -> bool| -> Vec<u32> {
            positions
                .iter()
                .enumerate()
                .filter(|&(i, p)| p.is_finite() && keep(i, *p))
                .map(|(i, _)| i as u32)
                .collect()
        };
        let bounds = || match finite_bounds(positions.iter().copied()) {
            Some((lo, hi)) => format!("its vertices rest between {lo} and {hi} (mesh space)"),
            None => "it has no vertex with a finite position".to_owned(),
        };
        let selected = match *self {
            VertexSelection::Within { min, max } => {
                if !(min.is_finite() && max.is_finite() && min.cmple(max).all()) {
                    return invalid(format!(
                        "box from {min} to {max} (finite, min at most max on every axis)"
                    ));
                }
                let chosen = indexed(&|_, p| min.cmple(p).all() && p.cmple(max).all());
                if chosen.is_empty() {
                    return Err(PinRuleError::NothingSelected(format!(
                        "none lies in the box from {min} to {max}; {}",
                        bounds()
                    )));
                }
                chosen
            }
            VertexSelection::Farthest { towards, within } => {
                let length = towards.length();
                if !(length.is_finite() && length > 0.0 && within.is_finite() && within >= 0.0) {
                    return invalid(format!(
                        "farthest towards {towards} within {within} (a finite direction that is \
                         not zero, a finite distance ≥ 0)"
                    ));
                }
                let along = towards / length;
                let far = positions
                    .iter()
                    .filter(|p| p.is_finite())
                    .map(|p| along.dot(*p))
                    .fold(f32::NEG_INFINITY, f32::max);
                let chosen = indexed(&|_, p| along.dot(p) >= far - within);
                if chosen.is_empty() {
                    return Err(PinRuleError::NothingSelected(bounds()));
                }
                chosen
            }
            VertexSelection::Painted { channel, at_least } => {
                if !at_least.is_finite() {
                    return invalid(format!("painted at least {at_least} (a finite value)"));
                }
                let colors = colors()
                    .filter(|c| c.len() == positions.len())
                    .ok_or(PinRuleError::NoColors)?;
                let c = channel.index();
                let chosen = indexed(&|i, _| colors[i][c] >= at_least);
                if chosen.is_empty() {
                    let most = colors
                        .iter()
                        .map(|v| v[c])
                        .filter(|v| v.is_finite())
                        .fold(f32::NEG_INFINITY, f32::max);
                    return Err(PinRuleError::NothingSelected(format!(
                        "none is painted at least {at_least} in {channel:?}; the most is {most}"
                    )));
                }
                chosen
            }
        };
        Ok(selected)
    }
}

/// The mesh's vertex colours (RGBA).
fn colors(mesh: &Mesh) -> Option<Vec<[f32; 4]>> {
    match mesh.attribute(Mesh::ATTRIBUTE_COLOR)? {
        VertexAttributeValues::Float32x4(c) => Some(c.clone()),
        _ => None,
    }
}

/// Whether a cloth with this rule drops its mesh copy's vertex colours (they are a pin
/// mask, not a colour).
pub(super) fn drops_colors(rule: Option<&ClothPinRule>) -> bool {
    matches!(
        rule,
        Some(ClothPinRule {
            select: VertexSelection::Painted { .. },
            ..
        })
    )
}

/// Resolves each [`ClothPinRule`] into its entity's [`ClothPins`]: for a cloth about to be
/// built (no simulation yet, not refused) and whenever the rule changes. Runs before the
/// cloth is built, so the first step already has the rule's pins.
#[expect(clippy::type_complexity, reason = "a system's query")]
pub(super) fn resolve_pin_rules(
    mut commands: Commands,
    meshes: Option<Res<Assets<Mesh>>>,
    mut cloths: Query<
        (
            (Entity, Option<&Name>),
            Ref<ClothPinRule>,
            &Mesh3d,
            Option<&ClothSource>,
            &mut ClothPins,
            Option<&mut ClothSim>,
            Has<ClothInvalid>,
        ),
        With<Cloth>,
    >,
) {
    let Some(meshes) = meshes else {
        return;
    };
    for ((entity, name), rule, mesh3d, source, mut pins, sim, invalid) in &mut cloths {
        let building = sim.is_none() && !invalid;
        if !(rule.is_changed() || building) {
            continue;
        }
        // Not loaded yet: the cloth waits for it too (and says so).
        let Some(mesh) = meshes.get(ClothSource::user_mesh(source, mesh3d)) else {
            continue;
        };
        let who = EntityName::new(entity, name);
        let resolved = rule.pins(mesh);
        match sim {
            Some(mut sim) => {
                let checked = resolved.map(|p| {
                    pins.set_if_neq(p);
                });
                note_rejection(
                    &mut commands,
                    who,
                    &mut sim.rule_error,
                    checked.map_err(ClothError::PinRule),
                    ("pin rule", "its pins stay as they were"),
                );
            }
            None => match resolved {
                Ok(p) => {
                    pins.set_if_neq(p);
                }
                // Not built with pins the rule did not mean.
                Err(e) if !invalid => report(&mut commands, who, ClothError::PinRule(e)),
                Err(_) => {}
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Vec<Vec3> {
        (0..3)
            .flat_map(|z| (0..4).map(move |x| Vec3::new(x as f32 * 0.5, 0.0, z as f32 * 0.5)))
            .collect()
    }

    #[test]
    fn a_box_selects_what_rests_inside_it() {
        let sel = VertexSelection::Within {
            min: Vec3::new(-1.0, -1.0, -0.1),
            max: Vec3::new(0.5, 1.0, 0.5),
        };
        // Rows z = 0 and 0.5, columns x = 0 and 0.5.
        assert_eq!(sel.select_from(&grid(), || None), Ok(vec![0, 1, 4, 5]));
    }

    #[test]
    fn farthest_selects_the_extreme_row_and_what_lies_within_reach_of_it() {
        let edge = VertexSelection::Farthest {
            towards: Vec3::NEG_Z * 3.0,
            within: 0.0,
        };
        assert_eq!(edge.select_from(&grid(), || None), Ok(vec![0, 1, 2, 3]));
        let two_rows = VertexSelection::Farthest {
            towards: Vec3::X,
            within: 0.6,
        };
        assert_eq!(
            two_rows.select_from(&grid(), || None),
            Ok(vec![2, 3, 6, 7, 10, 11])
        );
    }

    #[test]
    fn a_vertex_with_a_non_finite_position_is_never_selected() {
        let mut p = grid();
        p[3] = Vec3::new(f32::NAN, 0.0, 0.0);
        p[7] = Vec3::new(f32::INFINITY, 0.0, 0.5);
        let sel = VertexSelection::Farthest {
            towards: Vec3::X,
            within: 0.0,
        };
        assert_eq!(sel.select_from(&p, || None), Ok(vec![11]));
    }

    #[test]
    fn painted_selects_by_the_channel_read() {
        let p = grid();
        let colors: Vec<[f32; 4]> = (0..p.len())
            .map(|i| match i {
                0 | 3 => [1.0, 0.0, 0.0, 1.0],
                5 => [0.4, 0.9, 0.0, 1.0],
                _ => [0.0, 0.0, 0.0, 1.0],
            })
            .collect();
        let red = VertexSelection::Painted {
            channel: ColorChannel::Red,
            at_least: 0.5,
        };
        assert_eq!(red.select_from(&p, || Some(colors.clone())), Ok(vec![0, 3]));
        let green = VertexSelection::Painted {
            channel: ColorChannel::Green,
            at_least: 0.5,
        };
        assert_eq!(green.select_from(&p, || Some(colors.clone())), Ok(vec![5]));
        assert_eq!(red.select_from(&p, || None), Err(PinRuleError::NoColors));
        // Colours for another number of vertices are no colours for these.
        assert_eq!(
            red.select_from(&p, || Some(colors[1..].to_vec())),
            Err(PinRuleError::NoColors)
        );
    }

    #[test]
    fn bad_values_and_empty_selections_are_refused_with_what_is_there() {
        let p = grid();
        let bad = [
            VertexSelection::Within {
                min: Vec3::ONE,
                max: Vec3::ZERO,
            },
            VertexSelection::Within {
                min: Vec3::NAN,
                max: Vec3::ONE,
            },
            VertexSelection::Farthest {
                towards: Vec3::ZERO,
                within: 0.0,
            },
            VertexSelection::Farthest {
                towards: Vec3::Y,
                within: -1.0,
            },
            VertexSelection::Painted {
                channel: ColorChannel::Alpha,
                at_least: f32::NAN,
            },
        ];
        for sel in bad {
            assert!(
                matches!(sel.select_from(&p, || None), Err(PinRuleError::Invalid(_))),
                "{sel:?}"
            );
        }
        let outside = VertexSelection::Within {
            min: Vec3::splat(5.0),
            max: Vec3::splat(6.0),
        };
        let Err(PinRuleError::NothingSelected(why)) = outside.select_from(&p, || None) else {
            panic!("an empty box must be refused");
        };
        assert!(
            why.contains("[0, 0, 0]") && why.contains("[1.5, 0, 1]"),
            "{why}"
        );
        let unpainted = VertexSelection::Painted {
            channel: ColorChannel::Red,
            at_least: 0.5,
        };
        let Err(PinRuleError::NothingSelected(why)) =
            unpainted.select_from(&p, || Some(vec![[0.25, 0.0, 0.0, 1.0]; p.len()]))
        else {
            panic!("an unpainted mesh must be refused");
        };
        assert!(why.contains("0.25"), "{why}");
    }

    #[test]
    fn the_anchors_entity_is_mapped_as_a_scene_maps_it() {
        use bevy::ecs::entity::EntityHashMap;
        let (a, b) = (
            Entity::from_raw_u32(1).unwrap(),
            Entity::from_raw_u32(2).unwrap(),
        );
        let mut map = EntityHashMap::default();
        map.insert(a, b);
        let select = VertexSelection::Farthest {
            towards: Vec3::Y,
            within: 0.0,
        };
        let mut attached = ClothPinRule::attached(select, a);
        attached.map_entities(&mut map);
        assert_eq!(attached.anchor, PinAnchor::Attached(b));
        let mut hooked = ClothPinRule {
            select,
            anchor: PinAnchor::Entity {
                entity: a,
                offset: Vec3::X,
            },
        };
        hooked.map_entities(&mut map);
        assert_eq!(
            hooked.anchor,
            PinAnchor::Entity {
                entity: b,
                offset: Vec3::X
            }
        );
    }

    #[test]
    fn the_rule_reads_a_meshs_positions_and_colours() {
        let plane = Plane3d::default()
            .mesh()
            .size(2.0, 1.0)
            .subdivisions(3)
            .build();
        let rule = ClothPinRule::rest(VertexSelection::Farthest {
            towards: Vec3::NEG_X,
            within: 0.0,
        });
        let pins = rule.pins(&plane).expect("the plane has positions");
        // 5 × 5 vertices: the -X column is one vertex of each row.
        assert_eq!(pins.0.len(), 5);
        let Some(VertexAttributeValues::Float32x3(p)) = plane.attribute(Mesh::ATTRIBUTE_POSITION)
        else {
            panic!("positions");
        };
        for pin in &pins.0 {
            assert_eq!(p[pin.vertex as usize][0], -1.0);
            assert_eq!(pin.anchor, PinAnchor::Rest);
        }
        let painted = ClothPinRule::rest(VertexSelection::Painted {
            channel: ColorChannel::Red,
            at_least: 0.5,
        });
        assert_eq!(painted.pins(&plane), Err(PinRuleError::NoColors));
        let mut coloured = plane.clone();
        let colours: Vec<[f32; 4]> = p
            .iter()
            .map(|v| {
                if v[2] > 0.4 {
                    [1.0, 0.0, 0.0, 1.0]
                } else {
                    [0.0, 0.0, 0.0, 1.0]
                }
            })
            .collect();
        coloured.insert_attribute(Mesh::ATTRIBUTE_COLOR, colours);
        let pins = painted.pins(&coloured).expect("painted");
        assert_eq!(pins.0.len(), 5);
        assert!(pins.0.iter().all(|pin| p[pin.vertex as usize][2] == 0.5));
    }
}
