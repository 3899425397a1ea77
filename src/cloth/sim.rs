//! [`ClothSim`]: the running simulation of a cloth entity, what it reads back to gameplay,
//! and what a backend that steps the cloth elsewhere hands back to it.

use bevy::math::Affine3A;
use bevy::mesh::Indices;
use bevy::prelude::*;

use super::ClothError;
use super::ClothTorn;
use crate::foundation::EntityName;
use crate::solver::{
    Carry, MeshBinding, Simulation, Weld, WindField, max_stretch, max_stretch_beyond, ray_hit,
    teleport_offset,
};

/// The running simulation of a cloth entity, inserted by the plugin on its first step.
///
/// Read it for the simulated positions (world space), normals and strain
/// ([`ClothSim::max_strain`]); mutate it through [`ClothSim::simulation_mut`] to teleport or
/// reset the cloth.
///
/// A cloth stepped on the GPU keeps its state there: its `ClothSim` shows the state the cloth
/// started from unless the entity also has
/// [`ClothReadback`](crate::gpu::ClothReadback), which copies the GPU's state back every frame
/// (a few frames late). Such a cloth carries [`ClothSteppedElsewhere`](super::ClothSteppedElsewhere)
/// and [`ClothBackendInUse`](crate::gpu::ClothBackendInUse) says where it runs.
///
/// The solver simulates *particles*: the mesh's vertices after welding (see
/// [`Cloth::weld_tolerance`](super::Cloth::weld_tolerance)). For a mesh without duplicated vertices particle `i` is mesh
/// vertex `i`; in general [`ClothSim::particle`] maps a mesh vertex to its particle, and
/// [`ClothSim::position`] reads a mesh vertex directly.
#[derive(Component)]
pub struct ClothSim {
    pub(super) sim: Simulation,
    pub(super) mesh: Handle<Mesh>,
    pub(super) binding: MeshBinding,
    /// Mesh-space rest position of every particle (for pins that follow the cloth entity).
    pub(super) rest_local: Vec<Vec3>,
    /// How long its mesh's edges are, about ([`typical_edge`](super::build::typical_edge)):
    /// below some scale the cloth is hidden.
    pub(super) local_edge: f32,
    pub(super) u16_indices: bool,
    pub(super) steps: u64,
    /// Moved since the last write-back.
    pub(super) dirty: bool,
    /// How far along their velocities the mesh shows the vertices, in seconds
    /// ([`ClothSmoothing`](super::ClothSmoothing)), as of the last write-back.
    pub(super) drawn_shift: f32,
    /// The shifted positions drawn (working space of the write-back).
    pub(super) drawn: Vec<bevy::math::Vec4>,
    /// The vertices in the entity's local space (working space of the write-back).
    pub(super) local: super::writeback::LocalVertices,
    /// The triangles changed (tearing): the index buffer must be rewritten.
    pub(super) indices_dirty: bool,
    pub(super) torn_edges: usize,
    pub(super) recoveries: u32,
    /// Wall-clock seconds of the last CPU step.
    pub(super) step_seconds: f32,
    /// Calls of [`ClothSim::simulation_mut`] so far (a GPU cloth restarts from an edited state).
    pub(super) edits: u64,
    /// How far the whole cloth jumped with its pins' anchors at the start of this fixed step
    /// (the teleport rule; a backend stepping elsewhere applies it to its own state).
    pub(super) teleport: Option<Vec3>,
    /// Where [`PinAnchor::Attached`](super::PinAnchor::Attached) pins sit on their entities:
    /// particle, entity, offset in the entity's space, fixed when the pin was applied.
    pub(super) attached: Vec<(u32, Entity, Vec3)>,
    /// A config or feature change that was refused (the last valid settings run meanwhile).
    pub(super) settings_error: Option<ClothError>,
    /// The self-collision thickness last warned about as too thick (brought down to
    /// [`MAX_SELF_COLLISION_EDGES`](crate::solver::MAX_SELF_COLLISION_EDGES) mean edges): a
    /// tear, which changes the mean edge, does not warn again.
    pub(super) thickness_warned: Option<f32>,
    /// The self-collision thickness set (as used) when the warning that it is wider than half
    /// the gaps across the rest shape was last considered: warned once per thickness set.
    pub(super) gap_warned: Option<f32>,
    /// Whether the warning that the mesh's edges are uneven for self-collision was given
    /// (once per cloth built).
    pub(super) uneven_warned: bool,
    /// Steps its scale is still to hold before the self-collision thickness is checked
    /// against the cloth's edges and gaps (0: no check due). Set to
    /// [`THICKNESS_CHECK_STEPS`](super::build::THICKNESS_CHECK_STEPS) when it is built, scaled
    /// or its features change: a cloth growing in from a small scale is not warned about at
    /// the sizes it passes.
    pub(super) thickness_check_in: u32,
    /// A pin list that was refused (the last valid pins hold meanwhile).
    pub(super) pins_error: Option<ClothError>,
    /// A [`ClothPinRule`](super::ClothPinRule) change that gave no pins (the last pins hold
    /// meanwhile).
    pub(super) rule_error: Option<ClothError>,
    /// A [`Cloth`](super::Cloth) change that was refused (the cloth built from the last valid
    /// one runs meanwhile).
    pub(super) cloth_error: Option<ClothError>,
    /// The motion carried at the start of this fixed step
    /// ([`ClothInertia`](super::ClothInertia); a backend stepping elsewhere applies it to its
    /// own state).
    pub(super) carry: Option<Carry>,
    /// The [`ClothInertia`](super::ClothInertia) anchor and its pose at the last step.
    pub(super) inertia_from: Option<(Entity, Vec3, Quat)>,
    /// A refused [`ClothInertia`](super::ClothInertia) (the cloth feels all its motion
    /// meanwhile).
    pub(super) inertia_error: Option<ClothError>,
    /// A pin anchor with no pose (its pins hold still meanwhile).
    pub(super) anchor_error: Option<ClothError>,
    /// The entity's pose the rest shape is placed by: the cloth's size follows the entity's
    /// scale from it (see `build::reshape`).
    pub(super) shaped: Affine3A,
    /// The entity's origin at the last step its scale was not zero: a change of scale
    /// stretches the cloth about the point the change holds still (see `build::reshape`).
    pub(super) placed_at: Option<Vec3>,
    /// How many times the rest shape followed the entity's scale (a backend stepping
    /// elsewhere takes the new shape when this changes).
    pub(super) reshapes: u64,
    /// A rest shape at the entity's new scale that could not be built (the last one runs on).
    pub(super) reshape_error: Option<ClothError>,
    /// The [`Cloth`](super::Cloth) the simulation was made from (a change that keeps its
    /// welding is applied in place, see `build::remake`).
    pub(super) made_from: super::Cloth,
    /// Game-time seconds the cloth has been overstretched, less those it has not since (see
    /// [`ClothSim::overstretched`]).
    pub(super) stretched_for: f32,
    /// Game-time seconds since the cloth's stretch was last looked at.
    pub(super) since_look: f32,
    /// Where the entity was at the last fixed step: a cloth with no pins moves with its
    /// entity when that jumps past the teleport distance.
    pub(super) origin: Option<Vec3>,
    /// Whether the warning that pieces of the mesh hold no pin was given (once per cloth
    /// built).
    pub(super) loose_warned: bool,
    /// Whether the overstretch warning was given (once per cloth built).
    pub(super) overstretched: bool,
}

/// Game-time seconds between two looks at a cloth's stretch (a pass over its edges).
const STRETCH_LOOK_SECONDS: f32 = 0.25;

/// Stretch (`length / rest − 1`) past which a visible edge counts as overstretched: twice its
/// rest length.
pub const OVERSTRETCH: f32 = 1.0;

/// Game-time seconds a cloth stays overstretched before [`ClothSim::overstretched`] (and the
/// warning).
pub const OVERSTRETCH_SECONDS: f32 = 1.0;

impl ClothSim {
    /// The solver-side simulation (topology, state in world space, parameters), in particle
    /// indices.
    #[must_use]
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// Makes its simulation's tethers current (see `Simulation::prepare_tethers`) without
    /// counting as an edit: the GPU backend uploads them.
    pub(crate) fn prepare_tethers(&mut self) {
        self.sim.prepare_tethers();
    }

    /// Mutable access, e.g. to [`ClothState::reset`](crate::solver::ClothState::reset) the
    /// cloth. Changes are written to the mesh at the next write-back; a cloth on the GPU
    /// restarts from the state as edited here.
    pub fn simulation_mut(&mut self) -> &mut Simulation {
        self.dirty = true;
        self.edits += 1;
        &mut self.sim
    }

    /// The GPU backend took over the settle of a settings change with its upload: this
    /// copy, which the CPU does not step meanwhile, does not start it again with the next
    /// upload (not an edit of the state).
    pub(crate) fn settle_handed_over(&mut self) {
        self.sim.stop_settling();
    }

    /// Each particle's rest position placed by `pose` (the rest shape the entity's transform
    /// gives the cloth).
    pub(super) fn rest_at(&self, pose: &GlobalTransform) -> Vec<Vec3> {
        self.rest_local
            .iter()
            .map(|&p| pose.transform_point(p))
            .collect()
    }

    /// After a NaN or infinite state (found by the step, or by a backend stepping the cloth
    /// elsewhere): the rest pose, placed where the entity is now (`placement`, when known),
    /// counted and logged as a warning.
    pub fn recover(&mut self, who: EntityName<'_>, placement: Option<GlobalTransform>) {
        self.sim.reset_to_rest();
        if let Some(t) = placement {
            let placed = self.rest_at(&t);
            self.sim.reset_to(&placed);
        }
        self.recoveries += 1;
        self.binding.retain(self.sim.topology());
        self.indices_dirty = true;
        self.dirty = true;
        warn!(
            "cloth {who}: its state became NaN or infinite at step {}; reset to the rest \
             pose (recovery {})",
            self.steps, self.recoveries
        );
    }

    /// Counts `elapsed` seconds of game time (a fixed step on the CPU, a frame's time for a
    /// GPU state read back) and, every [`STRETCH_LOOK_SECONDS`], looks at the cloth's stretch;
    /// warns once when its visible edges (the 90 % longest at rest: a modelling tool's tiny
    /// detail edges left out) have stayed past [`OVERSTRETCH`] for [`OVERSTRETCH_SECONDS`]. A
    /// cloth that tears is left alone: its edges tear first, or are allowed to stretch that
    /// far.
    pub(crate) fn watch_stretch(&mut self, elapsed: f32, who: EntityName<'_>) {
        if self.overstretched || self.sim.features().tear_threshold.is_some() {
            return;
        }
        self.since_look += elapsed.max(0.0);
        if self.since_look < STRETCH_LOOK_SECONDS {
            return;
        }
        let span = core::mem::take(&mut self.since_look);
        let topology = self.sim.topology();
        let positions = &self.sim.state().positions;
        // A skinned cloth is measured against its skin: an animation (or a skin's weights
        // blending between bones) may stretch its edges itself, which no setting fixes.
        let stretch = match self.sim.motion_targets() {
            Some(skin) => max_stretch_beyond(
                positions,
                skin.end,
                topology.edges(),
                topology.short_rest_edge(),
            ),
            None => max_stretch(positions, topology.edges(), topology.short_rest_edge()),
        };
        self.stretched_for = if stretch > OVERSTRETCH {
            self.stretched_for + span
        } else {
            (self.stretched_for - span).max(0.0)
        };
        if self.stretched_for < OVERSTRETCH_SECONDS {
            return;
        }
        self.overstretched = true;
        let params = self.sim.params();
        let fix = if self.sim.features().tethers.is_some() {
            "raise `ClothConfig::substeps` (stretch falls with the substep's length), or pin it \
             at more vertices"
        } else {
            "add `ClothTethers` (long-range attachments that keep each vertex within its rest \
             distance of the pins: 10–25 % more time), raise `ClothConfig::substeps` (stretch \
             falls with the substep's length), or pin it at more vertices"
        };
        warn!(
            "cloth {who}: its edges have been stretched to more than {} times their rest \
             length for {OVERSTRETCH_SECONDS} s ({:.1} times now; {} particles, {} substeps × {} \
             iteration(s) a step): at these settings it cannot hold its own weight from its \
             pins. For a cloth that hangs at its size, {fix}. If it is meant to stretch this \
             far, this is said only once",
            1.0 + OVERSTRETCH,
            1.0 + stretch,
            topology.vertex_count(),
            params.substeps,
            params.iterations,
        );
    }

    /// Whether the cloth has been overstretched: its visible edges (a modelling tool's tiny
    /// detail edges left out) pulled past twice their rest length ([`OVERSTRETCH`]; a
    /// skinned cloth's, [`ClothSkinning`](super::ClothSkinning), past twice the longer of
    /// that and their length on the skin) for
    /// [`OVERSTRETCH_SECONDS`] of game time, which a fine cloth hanging from a few pins does
    /// at the default 10 substeps (a 64² grid from two corners: its corners stretch 3–5 fold).
    /// It was logged once as a warning naming the remedies (`ClothTethers`, more substeps, more
    /// pins). Looked at on the CPU, and for a GPU cloth only when its state is read back
    /// ([`ClothReadback`](crate::gpu::ClothReadback)); never for a cloth that tears.
    #[must_use]
    pub fn overstretched(&self) -> bool {
        self.overstretched
    }

    /// After edges tore (particle pairs): counts them, drops their triangles from the drawn
    /// mesh and sends [`ClothTorn`] (in mesh vertices).
    pub(super) fn note_torn(
        &mut self,
        entity: Entity,
        torn: &[[u32; 2]],
        messages: &mut MessageWriter<ClothTorn>,
    ) {
        if torn.is_empty() {
            return;
        }
        self.torn_edges += torn.len();
        self.binding.retain(self.sim.topology());
        self.indices_dirty = true;
        let weld = self.binding.weld();
        messages.write(ClothTorn {
            cloth: entity,
            edges: torn
                .iter()
                .map(|e| e.map(|p| weld.representative(p)))
                .collect(),
        });
    }

    /// Counts `steps` steps taken elsewhere (see [`ClothSteppedElsewhere`](super::ClothSteppedElsewhere)).
    pub fn count_external_steps(&mut self, steps: u64) {
        self.steps += steps;
    }

    /// Sets where the skin holds each particle for the next step
    /// ([`Simulation::set_motion_targets`]); an input like pin targets, not an edit of the
    /// state (a GPU cloth is not restarted).
    ///
    /// # Errors
    /// As [`Simulation::set_motion_targets`].
    pub fn set_motion_targets(
        &mut self,
        targets: &[Vec4],
        backstop: &[Vec4],
        backstop_radius: f32,
        snap: bool,
    ) -> Result<(), crate::solver::StateError> {
        self.sim
            .set_motion_targets(targets, backstop, backstop_radius, snap)
    }

    /// Lets every particle go ([`Simulation::clear_motion_targets`]); not an edit either.
    pub fn clear_motion_targets(&mut self) {
        self.sim.clear_motion_targets();
    }

    /// After a step taken elsewhere: see [`Simulation::motion_step_taken`].
    pub fn motion_step_taken(&mut self) {
        self.sim.motion_step_taken();
    }

    /// The simulation, for a backend that steps the cloth elsewhere to count its rest, put it
    /// to sleep and wake it ([`Simulation::count_rest`], [`Simulation::sleep_in`],
    /// [`Simulation::stays_asleep_in`]): inputs and results of steps taken there, not an edit
    /// (unlike [`Self::simulation_mut`], the GPU cloth is not restarted).
    pub(crate) fn stepped_elsewhere(&mut self) -> &mut Simulation {
        &mut self.sim
    }

    /// Takes a state computed elsewhere: positions (`xyz`; the inverse masses stay as they are)
    /// and velocities of every particle. Ignored unless both have one entry per particle.
    pub fn receive_state(&mut self, positions: &[Vec4], velocities: &[Vec4]) {
        let state = self.sim.state_mut();
        if positions.len() != state.len() || velocities.len() != state.len() {
            return;
        }
        for (x, g) in state.positions.iter_mut().zip(positions) {
            *x = g.truncate().extend(x.w);
        }
        state.velocities.copy_from_slice(velocities);
    }

    /// After [`Self::receive_state`] took over a state some steps old (a cloth back from the
    /// GPU: its last read-back), the teleport rule applied to the gap: the pins whose vertex
    /// lies farther than `limit` from its target count as a jump, and the whole cloth moves by
    /// their mean (the pinned vertices landing on their targets), as a teleport of its anchor
    /// in the gap moved the cloth where it was stepped. Returns the offset, if any.
    pub fn catch_up_with_pins(&mut self, limit: f32) -> Option<Vec3> {
        let state = self.sim.state();
        let offset = teleport_offset(
            state
                .pins()
                .iter()
                .map(|p| (state.position(p.vertex as usize), p.target)),
            limit,
        )?;
        let targets: Vec<Vec3> = state.pins().iter().map(|p| p.target).collect();
        self.sim.state_mut().teleport(offset, targets);
        self.dirty = true;
        Some(offset)
    }

    /// Tears the edges stretched past the tear threshold in the current state (a backend
    /// stepping elsewhere calls it on a state it handed back): the topology loses them, their
    /// triangles leave the drawn mesh and [`ClothTorn`] says which. Returns whether any tore.
    pub fn tear_now(&mut self, entity: Entity, messages: &mut MessageWriter<ClothTorn>) -> bool {
        let torn = self.sim.tear();
        self.note_torn(entity, &torn, messages);
        !torn.is_empty()
    }

    /// Tears `edges` (particle pairs, as [`Simulation::tear_edges`](crate::solver::Simulation::tear_edges)):
    /// the edges a backend stepping elsewhere found past the tear threshold, torn as
    /// [`Self::tear_now`] tears. Returns whether any tore.
    pub fn tear_edges_now(
        &mut self,
        entity: Entity,
        edges: &[[u32; 2]],
        messages: &mut MessageWriter<ClothTorn>,
    ) -> bool {
        let torn = self.sim.tear_edges(edges);
        self.note_torn(entity, &torn, messages);
        !torn.is_empty()
    }

    /// Writes the index buffer without the torn triangles into `mesh` (the cloth's own mesh),
    /// if any tore since the last write, in the mesh's own index format.
    pub fn write_indices(&mut self, mesh: &mut Mesh) {
        if core::mem::take(&mut self.indices_dirty) {
            let indices = self.binding.drawn_indices();
            mesh.insert_indices(if self.u16_indices {
                Indices::U16(indices.map(|i| i as u16).collect())
            } else {
                Indices::U32(indices.collect())
            });
        }
    }

    /// Whether the cloth's own mesh keeps 16-bit indices (as the mesh it came from did).
    #[must_use]
    pub fn u16_indices(&self) -> bool {
        self.u16_indices
    }

    /// Asks for the mesh to be written at the next write-back (a cloth coming back from
    /// elsewhere with a new state).
    pub fn mark_changed(&mut self) {
        self.dirty = true;
    }

    /// How far the whole cloth jumped with its pins at the start of this fixed step (the
    /// teleport rule), taken: a backend stepping elsewhere applies it to its own state.
    pub fn take_teleport(&mut self) -> Option<Vec3> {
        self.teleport.take()
    }

    /// The motion carried at the start of this fixed step (the part of its
    /// [`ClothInertia`](super::ClothInertia) anchor's motion the cloth does not feel, and a
    /// change of size with its entity's scale, applied before the pins and the teleport rule),
    /// taken: a backend stepping elsewhere applies it to its own state.
    pub fn take_carry(&mut self) -> Option<Carry> {
        self.carry.take()
    }

    /// How many times the rest shape followed a change of the entity's scale or the masses
    /// and bending a change of [`Cloth`](super::Cloth): a backend stepping elsewhere takes
    /// the new ones (and goes on from its own state) when this changes.
    #[must_use]
    pub fn reshape_count(&self) -> u64 {
        self.reshapes
    }

    /// How many times [`Self::simulation_mut`] was called: a backend stepping elsewhere
    /// restarts from the state when this changes.
    #[must_use]
    pub fn edit_count(&self) -> u64 {
        self.edits
    }

    /// The air each particle meets over the coming step of `dt` seconds (empty: none), as a
    /// CPU step computes it: the wind of `field` at time `t` (seconds) around the cloth's
    /// current positions, less the velocity of the motion carried into the step (see
    /// `Simulation::carried_velocity`).
    pub fn step_air(&mut self, field: Option<&WindField>, t: f64, dt: f32, out: &mut Vec<Vec4>) {
        self.sim.step_air(field, t, dt, out);
    }

    /// How the mesh's vertices map onto particles, the drawn triangles and the shading.
    #[must_use]
    pub fn binding(&self) -> &MeshBinding {
        &self.binding
    }

    /// The cloth's own mesh asset (a copy of the source mesh).
    #[must_use]
    pub fn mesh(&self) -> &Handle<Mesh> {
        &self.mesh
    }

    /// How the mesh's vertices map onto particles.
    #[must_use]
    pub fn weld(&self) -> &Weld {
        self.binding.weld()
    }

    /// The rest position of every particle in the mesh's own space (before the entity's
    /// transform): where [`PinAnchor::Rest`](super::PinAnchor::Rest) pins hold them.
    #[must_use]
    pub fn rest_shape(&self) -> &[Vec3] {
        &self.rest_local
    }

    /// The offset from `entity` at which mesh vertex `vertex` is held by a
    /// [`PinAnchor::Attached`](super::PinAnchor::Attached) pin: where the vertex was, in the
    /// entity's space, when the pin was applied. `None` before that (the entity had no pose
    /// yet) or for another kind of pin.
    #[must_use]
    pub fn attached_offset(&self, vertex: u32, entity: Entity) -> Option<Vec3> {
        let weld = self.binding.weld();
        if vertex as usize >= weld.vertex_count() {
            return None;
        }
        let particle = weld.particle(vertex);
        self.attached
            .iter()
            .find(|&&(p, e, _)| p == particle && e == entity)
            .map(|&(_, _, offset)| offset)
    }

    /// The particle that simulates mesh vertex `vertex`.
    ///
    /// # Panics
    /// If `vertex` is not a vertex of the mesh.
    #[must_use]
    pub fn particle(&self, vertex: u32) -> u32 {
        self.binding.weld().particle(vertex)
    }

    /// Where a world-space ray (e.g. from `Camera::viewport_to_world` under the cursor)
    /// meets the cloth first, from either side, and the mesh vertex nearest that point: for
    /// grabbing the cloth or choosing vertices to pin. A cloth stepped elsewhere is picked
    /// where [`ClothSim`] knows it to be (see the type's docs).
    #[must_use]
    pub fn pick(&self, ray: Ray3d) -> Option<ClothPick> {
        let hit = ray_hit(
            &self.sim.state().positions,
            self.sim.topology().triangles(),
            ray.origin,
            *ray.direction,
        )?;
        Some(ClothPick {
            vertex: self.binding.weld().representative(hit.nearest),
            particle: hit.nearest,
            point: hit.point,
            distance: hit.t,
        })
    }

    /// World position of mesh vertex `vertex` now.
    ///
    /// # Panics
    /// If `vertex` is not a vertex of the mesh.
    #[must_use]
    pub fn position(&self, vertex: u32) -> Vec3 {
        self.sim.state().position(self.particle(vertex) as usize)
    }

    /// World-space unit normal of every mesh vertex, as of the last write-back (as drawn: with
    /// [`ClothSmoothing`](super::ClothSmoothing), of the shifted shape).
    #[must_use]
    pub fn normals(&self) -> &[Vec3] {
        self.binding.shading().normals()
    }

    /// World-space tangents of every mesh vertex as of the last write-back, as drawn (empty
    /// when the mesh has neither UVs nor tangents).
    #[must_use]
    pub fn tangents(&self) -> &[Vec4] {
        self.binding.shading().tangents()
    }

    /// The largest edge strain now: how much longer than at rest the most stretched edge is
    /// (0.05 = 5 % longer). [`Simulation::strain`] has the mean as well.
    #[must_use]
    pub fn max_strain(&self) -> f32 {
        self.sim.strain().max
    }

    /// Steps simulated so far.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Edges torn so far (every edge that left the cloth, as in [`ClothTorn`]).
    #[must_use]
    pub fn torn_edges(&self) -> usize {
        self.torn_edges
    }

    /// Times the state went NaN or infinite and was reset to the rest pose (each one is
    /// logged as a warning).
    #[must_use]
    pub fn recoveries(&self) -> u32 {
        self.recoveries
    }

    /// Why the latest [`Cloth`](super::Cloth), [`ClothConfig`](super::ClothConfig), opt-in
    /// feature, [`ClothPins`](super::ClothPins) or [`ClothPinRule`](super::ClothPinRule) change
    /// was refused, while the cloth runs on
    /// its last valid ones; `None` when everything asked for is in use.
    #[must_use]
    pub fn rejected(&self) -> Option<&ClothError> {
        self.cloth_error
            .as_ref()
            .or(self.settings_error.as_ref())
            .or(self.pins_error.as_ref())
            .or(self.rule_error.as_ref())
    }

    /// Wall-clock seconds the last CPU step of this cloth took (0 before the first step and
    /// for a cloth stepped on the GPU). Cloths are stepped in parallel with each other, so
    /// this is the time of this cloth's own step, not its share of the frame.
    #[must_use]
    pub fn step_seconds(&self) -> f32 {
        self.step_seconds
    }

    /// Whether the cloth is asleep: it came to rest, its steps are skipped and its mesh is not
    /// rewritten until a pin, a collider near it, the wind at it or its settings change
    /// ([`ClothConfig::sleep`](super::ClothConfig) sets when). A GPU cloth sleeps by the same
    /// rules a few frames late, counted from states read back while it may be coming to rest
    /// ([`Simulation::may_be_at_rest`], [`Simulation::may_be_at_rest_in`]; its mesh is still
    /// written every frame, from the same state).
    #[must_use]
    pub fn is_sleeping(&self) -> bool {
        self.sim.is_sleeping()
    }
}

/// What [`ClothSim::pick`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClothPick {
    /// The mesh vertex nearest the point hit (the first copy of its particle, for a welded
    /// mesh): what [`ClothPins`](super::ClothPins) and [`ClothSim::position`] take.
    pub vertex: u32,
    /// Its particle.
    pub particle: u32,
    /// The point hit, in world space.
    pub point: Vec3,
    /// Distance from the ray's origin to the point, in metres.
    pub distance: f32,
}

/// The mesh a cloth was built from and the cloth's own copy of it (which its [`Mesh3d`] shows
/// and the simulation rewrites). Inserted by the plugin; rebuilding the cloth starts again from
/// `source` as long as the entity still shows `copy`, and removing [`Cloth`](super::Cloth) puts `source`
/// back on the entity.
///
/// Reflected, so that a scene (`DynamicWorld`) made from a running cloth carries it beside
/// the `Mesh3d` it saves (the copy, deformed): the cloth the scene spawns is built from
/// `source`, its rest shape the user's mesh, not the shape the cloth had when saved.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Clone, PartialEq)]
pub struct ClothSource {
    /// The mesh the user gave.
    pub source: Handle<Mesh>,
    /// The cloth's own copy.
    pub copy: Handle<Mesh>,
    /// `source`'s contents when the cloth was built from it (a changed asset rebuilds it).
    pub(crate) fingerprint: u64,
}

impl ClothSource {
    /// The mesh a cloth showing `shown` is built from: the user's mesh, not the cloth's own,
    /// deformed copy — unless the user has put another mesh in (`shown` is not the copy).
    pub(super) fn user_mesh<'a>(
        source: Option<&'a ClothSource>,
        shown: &'a Mesh3d,
    ) -> &'a Handle<Mesh> {
        match source {
            Some(s) if s.copy == shown.0 => &s.source,
            _ => &shown.0,
        }
    }
}
