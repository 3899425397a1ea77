//! Building a cloth's simulation from its components and mesh, and the solver features its
//! opt-in components ask for.

use bevy::math::Affine3A;
use bevy::prelude::*;

use super::mesh::cloth_mesh;
use super::pins::{attach, pin_list, repin};
use super::{
    Cloth, ClothConfig, ClothError, ClothPins, ClothSelfCollision, ClothSim, ClothTearing,
    ClothTethers,
};
use crate::foundation::{EntityName, FixedPoses, finite_bounds, read_mesh};
use crate::solver::{
    EVEN_EDGE_SPREAD, Features, MAX_SELF_COLLISION_EDGES, MeshBinding, Pin, REST_GAP_THICKNESS,
    SelfCollision, Simulation, SolverError, Stretch, TetherParams, Topology, TopologyError,
    TopologyOptions, limits,
};

/// A cloth built from its mesh, before its own mesh asset exists.
pub(super) struct Built {
    pub(super) sim: Simulation,
    binding: MeshBinding,
    rest_local: Vec<Vec3>,
    attached: Vec<(u32, Entity, Vec3)>,
    /// The cloth's own copy of the mesh.
    pub(super) mesh: Mesh,
    u16_indices: bool,
    /// The entity's pose the rest shape was placed by.
    shaped: Affine3A,
    made_from: Cloth,
}

impl Built {
    /// The cloth's [`ClothSim`], its own mesh added to `meshes`.
    pub(super) fn into_sim(self, meshes: &mut Assets<Mesh>) -> ClothSim {
        ClothSim {
            sim: self.sim,
            mesh: meshes.add(self.mesh),
            binding: self.binding,
            local_edge: typical_edge(self.rest_local.iter().copied()),
            rest_local: self.rest_local,
            u16_indices: self.u16_indices,
            steps: 0,
            dirty: true,
            drawn_shift: 0.0,
            drawn: Vec::new(),
            local: Default::default(),
            indices_dirty: false,
            torn_edges: 0,
            recoveries: 0,
            step_seconds: 0.0,
            edits: 0,
            teleport: None,
            attached: self.attached,
            settings_error: None,
            thickness_warned: None,
            gap_warned: None,
            uneven_warned: false,
            thickness_check_in: THICKNESS_CHECK_STEPS,
            cloth_error: None,
            pins_error: None,
            rule_error: None,
            carry: None,
            inertia_from: None,
            inertia_error: None,
            anchor_error: None,
            shaped: self.shaped,
            placed_at: None,
            reshapes: 0,
            reshape_error: None,
            made_from: self.made_from,
            stretched_for: 0.0,
            since_look: 0.0,
            origin: None,
            loose_warned: false,
            overstretched: false,
        }
    }
}

/// A cloth's simulation before its pins: the mesh read, welded and placed.
struct Unpinned {
    sim: Simulation,
    binding: MeshBinding,
    data: crate::foundation::MeshData,
}

/// Reads, welds and places `mesh` (by `own`) into an unpinned simulation of `cloth`.
fn build_unpinned(
    cloth: &Cloth,
    config: &ClothConfig,
    mesh: &Mesh,
    own: &GlobalTransform,
) -> Result<Unpinned, ClothError> {
    cloth.validate()?;
    let data = read_mesh(mesh)?;
    // Refused before welding allocates anything for it.
    if data.positions.len() > limits::MAX_VERTICES || data.indices.len() / 3 > limits::MAX_TRIANGLES
    {
        return Err(SolverError::from(TopologyError::TooLarge {
            vertices: data.positions.len() as u64,
            triangles: (data.indices.len() / 3) as u64,
        })
        .into());
    }
    let size =
        finite_bounds(data.positions.iter().copied()).map_or(0.0, |(lo, hi)| (hi - lo).length());
    let binding = MeshBinding::new(
        &data.positions,
        data.attributes(),
        &data.indices,
        cloth.weld_tolerance * size,
    )
    .map_err(SolverError::from)?;
    // The rest shape is the mesh placed by the entity's transform, so a scaled entity gets a
    // scaled cloth (rest lengths in world units).
    let world: Vec<Vec3> = data
        .positions
        .iter()
        .map(|p| own.transform_point(*p))
        .collect();
    let topology = binding
        .topology(
            &world,
            TopologyOptions {
                bend_rest: cloth.bend_rest,
                bending: cloth.bending_model,
            },
        )
        .map_err(SolverError::from)?;
    let masses = topology.masses(cloth.mass, cloth.mass_distribution);
    let sim = Simulation::new(topology, &masses, *config)?;
    Ok(Unpinned { sim, binding, data })
}

/// A cloth's components, to check before spawning them ([`check_cloth`]).
#[derive(Clone, Copy, Debug)]
pub struct ClothParts<'a> {
    /// The cloth.
    pub cloth: &'a Cloth,
    /// Its solver settings.
    pub config: &'a ClothConfig,
    /// Its pins.
    pub pins: &'a ClothPins,
    /// Self-collision, if on.
    pub self_collision: Option<&'a ClothSelfCollision>,
    /// Tethers, if on.
    pub tethers: Option<&'a ClothTethers>,
    /// Tearing, if on.
    pub tearing: Option<&'a ClothTearing>,
}

/// Checks that a cloth with these components would start from `mesh` placed by `at`: what
/// the plugin checks when it builds the cloth (mass, teleport distance, weld tolerance, the
/// mesh and its size, settings, pinned vertices in range, features), without an app and
/// without keeping anything. Where a pin's anchor is is not checked (its entity may not exist
/// yet). Scene files are checked with it before the world is touched.
///
/// # Errors
/// The [`ClothError`] the plugin would report for the cloth.
pub fn check_cloth(parts: ClothParts, mesh: &Mesh, at: &GlobalTransform) -> Result<(), ClothError> {
    let mut u = build_unpinned(parts.cloth, parts.config, mesh, at)?;
    pin_list(parts.pins, u.binding.weld())?;
    let wanted = features(&u.sim, parts.self_collision, parts.tethers, parts.tearing);
    u.sim.set_features(wanted).map_err(SolverError::Params)?;
    Ok(())
}

/// Builds the simulation of `cloth` from `mesh`, placed by `own` (its entity's pose now), its
/// pins on their anchors.
pub(super) fn build(
    cloth: &Cloth,
    config: &ClothConfig,
    pins: &ClothPins,
    mesh: &Mesh,
    own: &GlobalTransform,
    poses: &FixedPoses,
) -> Result<Built, ClothError> {
    let Unpinned {
        mut sim,
        binding,
        data,
    } = build_unpinned(cloth, config, mesh, own)?;
    let rest_local = binding.weld().gather(&data.positions);
    let mut list = pin_list(pins, binding.weld())?;
    let mut attached = Vec::new();
    attach(&mut list, &mut attached, sim.state(), poses);
    repin(
        &mut sim,
        &list,
        &rest_local,
        Some(own),
        poses,
        cloth.teleport_distance,
    )?;
    sim.state_mut().snap_pins();
    let mut binding = binding;
    binding.update_shading(&sim.state().positions);
    Ok(Built {
        sim,
        binding,
        rest_local,
        attached,
        mesh: cloth_mesh(mesh, &data),
        u16_indices: data.u16_indices,
        shaped: own.affine(),
        made_from: *cloth,
    })
}

/// The rest position of each of the cloth's mesh vertices placed by `at` (as `build` places
/// them).
fn rest_placed(cs: &ClothSim, at: &GlobalTransform) -> Vec<Vec3> {
    cs.binding
        .weld()
        .particles()
        .iter()
        .map(|&p| at.transform_point(cs.rest_local[p as usize]))
        .collect()
}

/// The shortest a cloth's typical edge ([`typical_edge`]) may be placed at, in multiples of
/// the f32 spacing at its distance from the origin (64 ulps: rest lengths within 2 %), and in
/// metres wherever it is: smaller, it is [`hidden`].
const SMALLEST_EDGE_ULPS: f32 = 64.0;
const SMALLEST_EDGE: f32 = 1e-5;

/// Whether `pose` places a cloth whose mesh has edges about `local_edge` long
/// ([`typical_edge`]) too small to simulate: a zero (or not finite) scale along some axis, or
/// one that makes its edges shorter than [`SMALLEST_EDGE`] or than [`SMALLEST_EDGE_ULPS`] f32
/// steps at its distance from the origin (where positions no longer resolve its shape: a
/// pop-in's tween near 0). Such a cloth waits to be built, or keeps the shape, size and pins it
/// had (hidden), until its scale places it larger.
pub(super) fn hidden(pose: &GlobalTransform, local_edge: f32) -> bool {
    let affine = pose.affine();
    let det = affine.matrix3.determinant();
    if !(det.is_finite() && det.abs() > f32::MIN_POSITIVE) {
        return true;
    }
    // A mesh with no extent (no positions yet, all at one point) is left to the build to
    // report.
    let edge = local_edge * det.abs().cbrt();
    let far = Vec3::from(affine.translation).abs().max_element();
    local_edge > 0.0 && !(edge >= SMALLEST_EDGE && edge >= SMALLEST_EDGE_ULPS * f32::EPSILON * far)
}

/// A length typical of the edges of a mesh with vertices at `positions`: the diagonal of their
/// bounds over the square root of their count (a square grid's diagonal edge, near enough).
pub(super) fn typical_edge(positions: impl ExactSizeIterator<Item = Vec3>) -> f32 {
    let count = positions.len().max(1) as f32;
    finite_bounds(positions).map_or(0.0, |(lo, hi)| (hi - lo).length() / count.sqrt())
}

/// Relative change of an entity's scale (along any of its axes) from the one its cloth's rest
/// shape was placed at past which the rest shape follows it.
const RESHAPE_TOLERANCE: f32 = 1e-4;

/// When the entity's scale (`own`, its pose at this step) is no longer the one the rest shape
/// was placed at: the rest shape placed at the new scale (the same vertices and triangles, a
/// tear kept), and the stretch that takes the cloth's state along with it (in the entity's
/// current orientation, so that its turning stays the pins' business) about the point the
/// change holds still, within the new rest shape's bounds ([`Stretch::holding`]: the
/// entity's origin when it is scaled itself, a scaled parent's when that moved the origin;
/// the entity's motion stays the pins' business). A scale too small to place the cloth at
/// ([`hidden`]: zero, or a tween's first frames) keeps the last shape (the cloth hidden, not
/// squashed): the caller passes `own` only when it places the cloth.
///
/// # Errors
/// The rest shape at the new scale cannot be built (triangles collapsed); nothing changes.
pub(super) fn reshape(
    cs: &mut ClothSim,
    own: &GlobalTransform,
) -> Result<Option<Stretch>, ClothError> {
    let now = own.affine();
    let shaped = GlobalTransform::from(cs.shaped);
    let (scale, rotation, origin) = own.to_scale_rotation_translation();
    let (scale_was, rotation_was, _) = shaped.to_scale_rotation_translation();
    // Where the entity's origin was at the last step it had a shape at (a zero scale holds
    // the cloth as it was): the stretch holds still the point the change of pose holds still.
    let origin_was = cs
        .placed_at
        .replace(origin)
        .unwrap_or(Vec3::from(cs.shaped.translation));
    let changed = (scale - scale_was)
        .abs()
        .cmpgt(RESHAPE_TOLERANCE * scale_was.abs())
        .any();
    if !changed {
        return Ok(None);
    }
    // The old shape's linear map turned into the entity's orientation now, and the map from
    // it to the new one.
    let was = Mat3::from_quat(rotation * rotation_was.inverse()) * Mat3::from(cs.shaped.matrix3);
    let linear = Mat3::from(now.matrix3) * was.inverse();
    if !linear.is_finite() {
        return Ok(None);
    }
    // The rest shape at the new pose, the topology's edges and hinges kept (and, scaled
    // evenly, the gaps across it).
    let rest = cs.rest_at(own);
    let was_topology = cs.sim.topology();
    let topology = match even_scale(linear) {
        Some(by) => was_topology.reshaped_evenly(&rest, by),
        None => was_topology.reshaped(&rest),
    }
    .map_err(SolverError::from)?;
    let stretch = Stretch::holding(
        linear,
        origin_was,
        origin,
        finite_bounds(rest.iter().copied()),
    );
    cs.sim.set_rest_shape(topology)?;
    cs.shaped = now;
    cs.reshapes += 1;
    cs.dirty = true;
    Ok(Some(stretch))
}

/// Relative difference within which the lengths of `linear`'s columns count as one, and
/// their dot products as nothing ([`even_scale`]).
const EVEN_SCALE_TOLERANCE: f32 = 1e-5;

/// The factor by which `linear` scales every length, when it is a rotation (or a reflection)
/// times one even scale within [`EVEN_SCALE_TOLERANCE`]; `None` otherwise.
fn even_scale(linear: Mat3) -> Option<f32> {
    let [x, y, z] = [linear.x_axis, linear.y_axis, linear.z_axis];
    let lengths2 = [x, y, z].map(Vec3::length_squared);
    let mean2 = lengths2.iter().sum::<f32>() / 3.0;
    let tolerance = EVEN_SCALE_TOLERANCE * mean2;
    let square = lengths2
        .iter()
        .all(|l| (l - mean2).abs() <= 2.0 * tolerance)
        && [x.dot(y), y.dot(z), z.dot(x)]
            .iter()
            .all(|d| d.abs() <= tolerance);
    (mean2.is_finite() && mean2 > 0.0 && square).then(|| mean2.sqrt())
}

/// Applies a change of [`Cloth`] that keeps the welding (the same particles) to the running
/// cloth: its topology (bending model, bend rest) and masses (mass, distribution) made again
/// from its mesh, its state (positions, velocities, pins) kept. Returns `false` for a change of
/// welding, which needs the cloth built again from its mesh.
///
/// # Errors
/// The topology or masses cannot be made; nothing changes.
pub(super) fn remake(cs: &mut ClothSim, cloth: &Cloth) -> Result<bool, ClothError> {
    let was = cs.made_from;
    if cloth.weld_tolerance != was.weld_tolerance {
        return Ok(false);
    }
    let same_model = (
        cloth.mass,
        cloth.mass_distribution,
        cloth.bend_rest,
        cloth.bending_model,
    ) == (
        was.mass,
        was.mass_distribution,
        was.bend_rest,
        was.bending_model,
    );
    if !same_model {
        let rest = rest_placed(cs, &GlobalTransform::from(cs.shaped));
        let options = TopologyOptions {
            bend_rest: cloth.bend_rest,
            bending: cloth.bending_model,
        };
        let topology = cs
            .binding
            .topology(&rest, options)
            .map_err(SolverError::from)?;
        let masses = topology.masses(cloth.mass, cloth.mass_distribution);
        cs.sim.set_topology_and_masses(topology, &masses)?;
        cs.reshapes += 1;
        cs.dirty = true;
    }
    cs.made_from = *cloth;
    Ok(true)
}

/// The self-collision thickness a cloth uses: its own, or
/// [`Topology::default_self_collision_thickness`](crate::solver::Topology::default_self_collision_thickness); at most
/// [`Topology::thickest_self_collision`](crate::solver::Topology::thickest_self_collision) (the
/// solver refuses more). Also the thickness asked for when it was more than that.
fn self_collision_thickness(sim: &Simulation, sc: &ClothSelfCollision) -> (f32, Option<f32>) {
    let topology = sim.topology();
    let asked = sc
        .thickness
        .unwrap_or_else(|| topology.default_self_collision_thickness());
    let most = topology.thickest_self_collision();
    // Not `min`: a NaN stays, to be refused with the other values out of range.
    if asked > most {
        (most, Some(asked))
    } else {
        (asked, None)
    }
}

/// How many steps a cloth's scale holds before its self-collision thickness is checked
/// ([`warn_self_collision`]): a quarter of a second at 60 steps a second, longer than a
/// pop-in's tween takes to start after the cloth is built at its first size.
pub(super) const THICKNESS_CHECK_STEPS: u32 = 15;

/// Warns when a cloth's self-collision thickness was brought down to
/// [`MAX_SELF_COLLISION_EDGES`] mean edges, once per thickness asked (a tear changes the mean
/// edge, and with it the thickness used, without warning again); and, once per cloth built,
/// when its edges are more uneven than [`EVEN_EDGE_SPREAD`] (self-collision then keeps a
/// thickness per vertex, which holds less well than one thickness on an even mesh).
pub(super) fn warn_self_collision(
    cs: &mut ClothSim,
    sc: Option<&ClothSelfCollision>,
    who: EntityName,
) {
    let asked = sc.and_then(|sc| self_collision_thickness(&cs.sim, sc).1);
    if let Some(asked) = asked
        && cs.thickness_warned != Some(asked)
    {
        let used = cs.sim.topology().thickest_self_collision();
        warn!(
            "cloth {who}: its self-collision thickness {asked} m is more than \
             {MAX_SELF_COLLISION_EDGES} mean rest edge: {used} m is used (layers thicker than an \
             edge pass through each other where the cloth crumples); use a coarser mesh for a \
             thicker layer"
        );
    }
    cs.thickness_warned = asked;
    // A thickness set, as used: wider than half the rest shape's gaps, the mesh fights itself.
    let set = sc
        .filter(|sc| sc.thickness.is_some())
        .map(|sc| self_collision_thickness(&cs.sim, sc).0);
    if let Some(set) = set
        && cs.gap_warned != Some(set)
        && let Some(why) = gap_warning(cs.sim.topology(), set)
    {
        warn!("cloth {who}: {why}");
    }
    cs.gap_warned = set;
    let topology = cs.sim.topology();
    let spread = topology.rest_edge_spread();
    if sc.is_some() && !cs.uneven_warned && spread > EVEN_EDGE_SPREAD {
        cs.uneven_warned = true;
        warn!(
            "cloth {who}: its edges are uneven for self-collision (the 90th percentile of their \
             lengths is {spread:.2} times the 10th, more than {EVEN_EDGE_SPREAD}): each vertex \
             keeps a thickness from its own edges, and layers can still pass through each other \
             in a few places where the cloth crumples; a mesh remeshed to even edges holds"
        );
    }
}

/// What to tell the user about a self-collision `thickness` they set that is more than
/// [`REST_GAP_THICKNESS`] of the narrowest gap across the cloth's rest shape
/// ([`Topology::rest_clearance`]), the most the default takes: the walls of a sleeve, the
/// sides of a low-poly model's creases then push each other apart every step. (Of Bevy's
/// glTF model parts dropped at three tilts with thicknesses set, 22 of the 36 set at more
/// than half their gap still moved after seven seconds, 4 of the 18 at up to half.)
fn gap_warning(topology: &Topology, thickness: f32) -> Option<String> {
    let clear = topology.rest_clearance();
    let most = REST_GAP_THICKNESS * clear;
    // Not for what the message's rounded figure lets through (3 digits: within 0.5 %).
    (thickness > 1.01 * most).then(|| {
        format!(
            "its self-collision thickness {thickness} m is more than half the narrowest gap \
             across its rest shape ({} m: walls or creases of the mesh that rest that close to \
             another of its layers), so they push each other apart every step and it may never \
             come to rest; at most {} m (what the default takes) holds, or leave the thickness \
             unset",
            three_digits(clear),
            three_digits(most)
        )
    })
}

/// `x` (positive, finite) to three significant digits: 0.2 for 0.199_999_99, 0.00123 for
/// 0.001_234_5.
fn three_digits(x: f32) -> String {
    let decimals = (2.0 - x.log10().floor()).clamp(0.0, 12.0) as usize;
    let text = format!("{x:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    }
}

/// Fewer triangles than this and a cloth cannot fold: it bends only along its edges, so it
/// moves as a few flat plates (a 3 × 3 grid has 8 triangles).
const COARSE_TRIANGLES: usize = 8;

/// What to tell the user about a cloth of `triangles` triangles, when it is too coarse to fold
/// (a modelling tool's default plane, exported as it is, has 2).
fn coarse_warning(triangles: usize) -> Option<String> {
    (triangles < COARSE_TRIANGLES).then(|| {
        format!(
            "its mesh has only {triangles} triangle(s), and cloth bends only along the edges \
             between them, so it moves as {triangles} flat plate(s); subdivide it (in the \
             modelling tool, or `Plane3d::default().mesh().subdivisions(n)`, or `grid_mesh`) \
             for a cloth that folds"
        )
    })
}

/// Warns once, when a cloth is built, that its mesh is too coarse to fold.
pub(super) fn warn_coarse(cs: &ClothSim, who: EntityName) {
    if let Some(why) = coarse_warning(cs.sim.topology().triangles().len()) {
        warn!("cloth {who}: {why}");
    }
}

/// What to tell the user about pieces of a cloth's mesh (`topology`) that no pin holds while
/// others are pinned (`pins`, particles): they fall on their own, away from the rest.
fn loose_warning(topology: &Topology, pins: &[Pin]) -> Option<String> {
    let (pieces, vertices) = topology.loose_pieces(pins.iter().map(|p| p.vertex));
    (pieces > 0).then(|| {
        format!(
            "{vertices} of its {} particles, in {pieces} piece(s) of its mesh that no edge joins \
             to a pinned vertex, fall on their own (parts kept separate in the modelling tool: \
             hooks, trims, a second layer); pin them too, join them to the rest (vertices that \
             only lie close are welded by a larger `Cloth::weld_tolerance`), or make them an \
             entity of their own",
            topology.vertex_count()
        )
    })
}

/// Warns once per cloth built, when it starts or is re-pinned, that pieces of its mesh hold
/// no pin while others are pinned; not once it has torn (pieces torn off fall as they should).
pub(super) fn warn_loose(cs: &mut ClothSim, who: EntityName) {
    if cs.loose_warned || cs.torn_edges > 0 {
        return;
    }
    if let Some(why) = loose_warning(cs.sim.topology(), cs.sim.state().pins()) {
        cs.loose_warned = true;
        warn!("cloth {who}: {why}");
    }
}

/// The solver features a cloth's opt-in components ask for.
pub(super) fn features(
    sim: &Simulation,
    self_collision: Option<&ClothSelfCollision>,
    tethers: Option<&ClothTethers>,
    tearing: Option<&ClothTearing>,
) -> Features {
    Features {
        self_collision: self_collision.map(|sc| SelfCollision {
            thickness: self_collision_thickness(sim, sc).0,
            friction: sc.friction,
        }),
        tethers: tethers.map(|t| TetherParams {
            slack: t.slack,
            pins_per_vertex: t.pins_per_vertex,
        }),
        tear_threshold: tearing.map(|t| t.threshold),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A map scales evenly when it is a rotation or reflection times one scale (the factor),
    /// not when it scales one axis more, shears, collapses or is not finite.
    #[test]
    fn an_even_scale_is_a_rotation_times_one_factor() {
        let turn = Mat3::from_quat(Quat::from_euler(EulerRot::YXZ, 0.7, -1.2, 2.9));
        for by in [1e-4, 0.05, 1.0, 3.0, 2e3] {
            let even = even_scale(turn * Mat3::from_diagonal(Vec3::splat(by)));
            assert!(
                even.is_some_and(|s| (s - by).abs() <= 1e-6 * by),
                "{by}: {even:?}"
            );
        }
        let mirrored = turn * Mat3::from_diagonal(Vec3::new(-2.0, 2.0, 2.0));
        assert!(even_scale(mirrored).is_some_and(|s| (s - 2.0).abs() <= 1e-6));
        for uneven in [
            Mat3::from_diagonal(Vec3::new(1.0, 1.0, 1.001)),
            turn * Mat3::from_diagonal(Vec3::new(2.0, 1.0, 2.0)),
            Mat3::from_cols(Vec3::X, Vec3::new(0.01, 1.0, 0.0), Vec3::Z),
            Mat3::ZERO,
            Mat3::from_diagonal(Vec3::new(f32::NAN, 1.0, 1.0)),
            Mat3::from_diagonal(Vec3::splat(f32::INFINITY)),
        ] {
            assert_eq!(even_scale(uneven), None, "{uneven}");
        }
    }

    /// A cloth is hidden at a zero scale along any axis and below the smallest edge its
    /// position resolves, and placed at any scale above it, near the origin or far from it.
    #[test]
    fn a_cloth_too_small_to_place_is_hidden() {
        // A 1.4 m banner of 36 rows: edges of about 4 cm.
        let edge = 0.04;
        let at = |x: f32, scale: Vec3| {
            GlobalTransform::from(Transform::from_xyz(x, 2.6, 0.0).with_scale(scale))
        };
        assert!(!hidden(&at(0.0, Vec3::ONE), edge));
        assert!(hidden(&at(0.0, Vec3::ZERO), edge));
        assert!(hidden(&at(0.0, Vec3::new(1.0, 0.0, 1.0)), edge));
        assert!(hidden(&at(0.0, Vec3::splat(f32::NAN)), edge));
        // 2.6 m from the origin f32 steps are at most 3.1e-7 m: edges of 64 steps, 2e-5 m,
        // need a scale of 5e-4.
        assert!(hidden(&at(0.0, Vec3::splat(3e-4)), edge));
        assert!(!hidden(&at(0.0, Vec3::splat(1e-3)), edge));
        // 2 km out they are 2.4e-4 m: a scale of 0.38 at least.
        assert!(!hidden(&at(2000.0, Vec3::splat(0.5)), edge));
        assert!(hidden(&at(2000.0, Vec3::splat(0.3)), edge));
        // At the origin, edges of a hundredth of a millimetre at least.
        let origin = |s: f32| GlobalTransform::from(Transform::from_scale(Vec3::splat(s)));
        assert!(hidden(&origin(1e-4), edge));
        assert!(!hidden(&origin(1e-3), edge));
        // A mesh with no extent is not hidden by its size (its build says what is wrong).
        assert!(!hidden(&origin(1e-4), 0.0));
        assert!(hidden(&origin(0.0), 0.0));
        assert!(
            (typical_edge([Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::new(1.0, 0.0, 1.0)].into_iter())
                - 0.5f32.sqrt())
            .abs()
                < 1e-6
        );
    }

    /// Two sheets, one of them pinned: the other is named, with its vertex count; both pinned,
    /// or none (a cloth dropped on something), nothing is said.
    #[test]
    fn a_mesh_piece_no_pin_holds_is_named() {
        let grid = crate::solver::Grid::new(3, 3, 1.0, 1.0);
        let mut positions = grid.positions();
        positions.extend(grid.positions().iter().map(|p| *p + Vec3::X * 5.0));
        let mut indices = grid.indices();
        indices.extend(grid.indices().iter().map(|i| i + 9));
        let topology = Topology::from_triangles(
            &positions,
            None,
            &indices,
            crate::solver::TopologyOptions::default(),
        )
        .unwrap();
        let pin = |vertex| Pin {
            vertex,
            target: Vec3::ZERO,
        };
        let why = loose_warning(&topology, &[pin(0), pin(2)]).expect("the second sheet is loose");
        assert!(
            why.starts_with("9 of its 18 particles, in 1 piece(s)"),
            "{why}"
        );
        assert_eq!(loose_warning(&topology, &[pin(0), pin(9)]), None);
        assert_eq!(loose_warning(&topology, &[]), None);
    }

    /// A thickness set wider than half the gap across a sheet creased at a right angle (the
    /// vertices a row, 0.2 m, from the crease rest over the other side) is named with the
    /// gap; a thinner one, the same on the flat sheet, and any on a closed tetrahedron (capped
    /// pair by pair) are not.
    #[test]
    fn a_thickness_set_wider_than_half_the_rest_gap_is_named() {
        let options = crate::solver::TopologyOptions::default();
        let grid = crate::solver::Grid::new(11, 11, 2.0, 2.0);
        let creased: Vec<Vec3> = grid
            .positions()
            .iter()
            .map(|p| {
                if p.x > 0.0 {
                    Vec3::new(0.0, p.x, p.z)
                } else {
                    *p
                }
            })
            .collect();
        let creased = Topology::from_triangles(&creased, None, &grid.indices(), options).unwrap();
        let flat = grid.topology(options).unwrap();
        let wide = 0.11;
        let why = gap_warning(&creased, wide).expect("0.11 m is over half the 0.2 m gap");
        assert!(
            why.starts_with("its self-collision thickness 0.11 m is more than half"),
            "{why}"
        );
        let clear = creased.rest_clearance();
        assert!((clear - 0.2).abs() < 1e-5, "{clear}");
        assert!(
            why.contains("(0.2 m: walls") && why.contains("at most 0.1 m"),
            "{why}"
        );
        assert_eq!(gap_warning(&creased, 0.09), None);
        // The figure it gives, as printed, passes.
        assert_eq!(gap_warning(&creased, 0.1), None);
        assert_eq!(gap_warning(&flat, wide), None);
        let tetrahedron = Topology::from_triangles(
            &[Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::Y],
            None,
            &[0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2],
            options,
        )
        .unwrap();
        assert!(tetrahedron.is_closed());
        assert_eq!(
            gap_warning(&tetrahedron, tetrahedron.thickest_self_collision()),
            None
        );
    }

    #[test]
    fn a_mesh_too_coarse_to_fold_is_named_and_a_three_by_three_grid_is_not() {
        // Blender's default plane: two triangles.
        let plate = coarse_warning(2).expect("two triangles cannot fold");
        assert!(plate.contains("only 2 triangle"), "{plate}");
        assert!(coarse_warning(7).is_some());
        let grid = crate::solver::Grid::new(3, 3, 1.0, 1.0);
        assert_eq!(grid.indices().len() / 3, 8);
        assert_eq!(coarse_warning(grid.indices().len() / 3), None);
    }

    /// A cloth's self-collision thickness is judged at the size it settles at: a banner
    /// popped in from a twentieth of its size with a thickness set for its full size is not
    /// warned about at the sizes it grows through, and one shrunk for good to less than that
    /// thickness is, once it stops shrinking.
    #[test]
    fn the_thickness_is_judged_at_the_size_a_cloth_settles_at() {
        let mut app = App::new();
        app.add_plugins((
            MinimalPlugins,
            TransformPlugin,
            AssetPlugin::default(),
            bevy::mesh::MeshPlugin,
            crate::foundation::ClothFoundationPlugin::default(),
            crate::collider::ClothColliderPlugin,
            crate::wind::ClothWindPlugin,
            super::super::ClothPlugin,
        ))
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            std::time::Duration::from_secs_f64(1.0 / 60.0),
        ))
        .insert_resource(Time::<Fixed>::from_hz(60.0));
        // Edges of about 4 cm at full size; a 3 cm thickness.
        let grid = crate::solver::Grid::new(24, 36, 0.9, 1.4);
        let mesh = app
            .world_mut()
            .resource_mut::<Assets<Mesh>>()
            .add(crate::foundation::grid_mesh(&grid));
        let sized = |s: f32| Transform::from_xyz(0.0, 2.0, 0.0).with_scale(Vec3::splat(s));
        let e = app
            .world_mut()
            .spawn((
                Mesh3d(mesh),
                sized(0.05),
                Cloth::default(),
                ClothPins::rest([grid.index(0, 0), grid.index(23, 0)]),
                ClothSelfCollision {
                    thickness: Some(0.03),
                    ..default()
                },
            ))
            .id();
        let warned = |app: &App| {
            let cs = app.world().get::<ClothSim>(e).expect("built");
            (cs.thickness_warned, cs.thickness_check_in)
        };
        let resize = |app: &mut App, s: f32| {
            *app.world_mut().get_mut::<Transform>(e).unwrap() = sized(s);
            app.update();
        };
        let hold = THICKNESS_CHECK_STEPS;
        // Built at the first fixed step, at a twentieth of its size.
        for _ in 0..3 {
            resize(&mut app, 0.05);
        }
        let (at_first, due) = warned(&app);
        assert!(
            at_first.is_none() && (1..hold).contains(&due),
            "built: {due}"
        );
        for f in 1..=30 {
            resize(&mut app, 0.05 + 0.95 * f as f32 / 30.0);
            assert_eq!(warned(&app), (None, hold), "frame {f} of the growth");
        }
        for _ in 0..hold {
            resize(&mut app, 1.0);
        }
        assert_eq!(warned(&app), (None, 0), "grown");
        // Shrunk to a third for good: its 1.3 cm edges are thinner than the thickness.
        resize(&mut app, 0.33);
        assert_eq!(warned(&app), (None, hold), "shrinking");
        for _ in 0..hold {
            resize(&mut app, 0.33);
        }
        assert_eq!(warned(&app), (Some(0.03), 0), "shrunk");
    }
}
