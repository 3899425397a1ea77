//! How a world of cloths lies in the GPU's buffers: built on the CPU, once per world, from
//! each cloth's [`Simulation`] (no `wgpu` here, so it is tested without a device).
//!
//! Every cloth gets its own [`ConstraintBatches`] with the GPU's part count
//! ([`gpu_part_count`]): parts small enough for workgroup memory where the mesh allows it.
//! Their parts, seams and boundaries become *groups* (one workgroup each), laid out level by
//! level across all cloths: every cloth's parts, then every even seam, every odd seam, every
//! boundary. A level is one dispatch; its groups share no vertex (different cloths share
//! none at all).

use glam::{Vec3, Vec4};

use super::append_lists;
use super::kernels::TILE;
use crate::solver::collision::{first_corner_reach, limits_depenetration};
use crate::solver::constraints::{ConstraintBatches, Part};
use crate::solver::{Simulation, Solver, Tethers, Topology};

/// Words of a cloth's record in `topo` (`common.wgsl`'s `CLOTH_WORDS`).
pub(crate) const CLOTH_WORDS: usize = 20;
/// Words of a group's record in `topo` (`common.wgsl`'s `GROUP_WORDS`).
pub(crate) const GROUP_WORDS: usize = 16;
/// `common.wgsl`'s `NO_PIN`.
pub(crate) const NO_PIN: u32 = u32::MAX;

/// Cloth flags (`common.wgsl`'s `FLAG_*`).
pub(crate) const FLAG_AIR: u32 = 1;
pub(crate) const FLAG_XPBD: u32 = 2;
pub(crate) const FLAG_DIHEDRAL: u32 = 4;
pub(crate) const FLAG_ACCUMULATE: u32 = 8;
pub(crate) const FLAG_SC: u32 = 16;
pub(crate) const FLAG_TETHERS: u32 = 32;
pub(crate) const FLAG_TEARING: u32 = 64;
/// The distances are swept forward and back ([`ConstraintBatches::symmetric_sweeps`]).
///
/// [`ConstraintBatches::symmetric_sweeps`]: crate::solver::ConstraintBatches::symmetric_sweeps
pub(crate) const FLAG_SYMMETRIC: u32 = 128;
/// The cloth is closed: self-collision caps the thickness near a vertex
/// ([`Topology::is_closed`], [`NEAR_CORNER_THICKNESS`]).
///
/// [`NEAR_CORNER_THICKNESS`]: crate::solver::NEAR_CORNER_THICKNESS
pub(crate) const FLAG_CLOSED: u32 = 256;
/// The cloth's edges are even: an open one's self-collision undoes an old overlap with a
/// triangle only up to a distance a corner resting near the vertex allows
/// ([`limits_depenetration`]; set whether the cloth is closed or not, since a tear opens it).
pub(crate) const FLAG_EVEN: u32 = 512;
/// The cloth may sleep ([`Sleep::enabled`]): each step's end takes its free vertices'
/// largest squared speed into the frame's (`frame_speed_at`), which the host reads back to
/// tell when it has come to rest.
///
/// [`Sleep::enabled`]: crate::solver::Sleep::enabled
pub(crate) const FLAG_SLEEP: u32 = 1024;

/// The part count the GPU projects `sim` with: parts of at most [`TILE`] vertices (one
/// workgroup each, in workgroup memory), fewer when the mesh's vertex order would leave
/// constraints joining parts further apart than neighbours (those run in one workgroup, in
/// order). `sim.set_part_count(gpu_part_count(sim))` gives the CPU twin of a GPU cloth.
#[must_use]
pub fn gpu_part_count(sim: &Simulation) -> usize {
    choose_batches(sim).part_count()
}

/// A cloth's GPU batches ([`choose_batches`]) for one upload of it, made the first time a
/// world is laid out with it and kept for the world's later layouts (another cloth's change
/// lays out the whole world again). Where the upload before it had them and only the rest
/// shape changed (the same edges and hinges: an entity being scaled), they are that
/// upload's measured again ([`ConstraintBatches::remeasure`]) instead of partitioned and
/// coloured again.
#[derive(Debug, Default)]
pub(crate) struct BatchesCell {
    made: std::sync::OnceLock<ConstraintBatches>,
    /// The last upload's cell (not kept alive by this one), looked at when these are made.
    seed: Option<std::sync::Weak<BatchesCell>>,
}

impl BatchesCell {
    /// A cell whose batches may be measured again from `last`'s (the cloth's last upload's).
    pub(crate) fn after(last: Option<&std::sync::Arc<BatchesCell>>) -> Self {
        Self {
            made: std::sync::OnceLock::new(),
            seed: last.map(std::sync::Arc::downgrade),
        }
    }

    /// The GPU's batches for `sim` (the simulation of this cell's upload).
    pub(crate) fn get(&self, sim: &Simulation) -> &ConstraintBatches {
        self.made.get_or_init(|| {
            let seed = self.seed.as_ref().and_then(std::sync::Weak::upgrade);
            seed.and_then(|cell| {
                let mut b = cell.made.get()?.clone();
                let same = b.built_from(sim.topology())
                    && b.symmetric_sweeps() == sim.batches().symmetric_sweeps();
                same.then(|| {
                    b.remeasure(sim.topology(), sim.params().solver);
                    b
                })
            })
            .unwrap_or_else(|| choose_batches(sim))
        })
    }
}

/// The GPU's batches for `sim` (see [`gpu_part_count`]).
fn choose_batches(sim: &Simulation) -> ConstraintBatches {
    let n = sim.state().len();
    let solver = sim.params().solver;
    let mut k = n.div_ceil(TILE).max(1);
    loop {
        let mut b = ConstraintBatches::new(sim.topology(), solver, k);
        // The CPU's sweep order (kept through a tear: `ConstraintBatches::sweep_symmetrically`).
        if sim.batches().symmetric_sweeps() {
            b.sweep_symmetrically();
        }
        let straddling = b.boundary.distance.a().len() + b.boundary.bending.v()[0].len();
        if k == 1 || straddling == 0 {
            return b;
        }
        k = (k / 2).max(1);
    }
}

/// One cloth's place in a world.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ClothLayout {
    /// Its first vertex in every per-vertex region.
    pub vbase: u32,
    /// Its vertices.
    pub n: u32,
    /// Its first pin among the world's pins, and how many it has.
    pub pin_base: u32,
    pub pins: u32,
    /// Its parts (the GPU's part count).
    pub parts: usize,
    /// Its record's flags.
    pub flags: u32,
    /// Whether its edges are checked against a tear threshold.
    pub tearing: bool,
    /// Its distance constraints in `cons` (a cloth's are contiguous): the range of the
    /// world's torn flags that are its own.
    pub distances: core::ops::Range<u32>,
    /// Its triangles among the world's (the tear's dead-triangle flags: one a triangle).
    pub triangles: core::ops::Range<u32>,
    /// Gravity, damping (1/s) and, for the lab solver, the velocity kept per step: what the
    /// record's per-frame words (gravity·h, damping factor) are made from.
    pub gravity: Vec3,
    pub damping: f32,
    pub keep: Option<f32>,
}

/// Where a level's groups sit in the group table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct LevelRange {
    pub first: u32,
    pub count: u32,
}

/// A world's buffers' contents (apart from the per-frame inputs) and where everything is.
#[derive(Clone, Debug, Default)]
pub(crate) struct WorldLayout {
    pub cloths: Vec<ClothLayout>,
    /// Vertices and pins of every cloth.
    pub n: u32,
    pub pins: u32,
    /// `cons`: distances, then hinges (three vec4 each, from `bend_at`).
    pub cons: Vec<[u32; 4]>,
    pub distances: u32,
    pub hinges: u32,
    pub bend_at: u32,
    /// `topo` and where its tables start.
    pub topo: Vec<u32>,
    pub cloth_at: u32,
    pub vertex_cloth_at: u32,
    pub vertex_pin_at: u32,
    pub group_at: u32,
    pub tri_offsets_at: u32,
    pub tri_at: u32,
    /// Per vertex, the triangles whose first corner it is, in triangle order (self-collision
    /// finds triangles through their first corner; only in a world with self-collision).
    pub first_tri_at: u32,
    /// Per vertex, the thickness it keeps from triangles over its cloth's (f32 bits:
    /// `Topology::self_collision_triangle_scales`, else its own scale; only in a world with
    /// self-collision).
    pub sc_triangle_scale_at: u32,
    pub tether_at: u32,
    pub lab_at: u32,
    pub edges_at: u32,
    pub edges: u32,
    /// Per tearing edge the triangles it belongs to (offsets, list; global triangles).
    pub edge_tris_at: u32,
    /// The edges of the cloths that settle a settings change (a, b: global vertices; rest
    /// length bits), whose largest strain decides how long the settle goes on.
    pub settle_edges_at: u32,
    pub settle_edges: u32,
    /// Most steps a cloth of the world settles (0: none settles).
    pub settle_steps: u32,
    /// Triangles of every cloth (the tear's dead-triangle flags have one each).
    pub triangles: u32,
    /// The levels: parts, seams (all of a cloth's, or its even ones), odd seams (where a
    /// cloth's seams overlap), boundaries.
    pub levels: [LevelRange; 4],
    /// Words of self-collision hash heads (2 per vertex of each self-colliding cloth).
    pub head_words: u32,
    /// Rest positions of every vertex (self-collision's topological skip), if any cloth
    /// collides with itself.
    pub rest: Vec<Vec4>,
    /// What any cloth needs.
    pub any_sc: bool,
    pub any_tethers: bool,
    pub any_accumulate: bool,
    pub any_tearing: bool,
    /// The lab solver (a world is all lab or all not).
    pub lab: bool,
    /// The world's substeps and iterations (every cloth's).
    pub substeps: u32,
    pub iterations: u32,
}

/// A group's constraints appended to `cons` and its record: `(record, colour bounds)`.
struct GroupSpec {
    record: [u32; GROUP_WORDS],
    dist_bounds: Vec<u32>,
    bend_bounds: Vec<u32>,
}

/// The distance constraints of `cons` as they are laid out, with the topology edge (of its
/// cloth) each one holds.
#[derive(Default)]
struct Distances {
    cons: Vec<[u32; 4]>,
    edge: Vec<u32>,
}

impl Distances {
    fn len(&self) -> usize {
        self.cons.len()
    }
}

/// Appends `part`'s distance constraints of `range` (local indices).
fn push_distances(part: &Part, range: core::ops::Range<usize>, out: &mut Distances) {
    let d = &part.distance;
    for i in range {
        out.cons.push([
            d.a()[i],
            d.b()[i],
            d.rest[i].to_bits(),
            d.param[i].to_bits(),
        ]);
        out.edge.push(d.edge[i]);
    }
}

/// The hinges of `cons` as they are laid out (three vec4 each), with the topology bend (of
/// its cloth) each one holds.
#[derive(Default)]
struct Hinges {
    cons: Vec<[[u32; 4]; 3]>,
    bend: Vec<u32>,
}

impl Hinges {
    fn len(&self) -> usize {
        self.cons.len()
    }
}

/// Appends hinges: four local vertices, then four weights (isometric) or the rest angle
/// (dihedral), then the material parameter and, for a tearing cloth, the hinge's two
/// triangles (written once its cloth's groups are laid out; `NO_PIN` otherwise).
fn push_hinges(part: &Part, range: core::ops::Range<usize>, out: &mut Hinges) {
    let b = &part.bending;
    for i in range {
        let a = if b.iso {
            [0, 1, 2, 3].map(|k| b.a[k][i].to_bits())
        } else {
            [b.rest[i].to_bits(), 0, 0, 0]
        };
        out.cons.push([
            [0, 1, 2, 3].map(|k| b.v()[k][i]),
            a,
            [b.param[i].to_bits(), NO_PIN, NO_PIN, 0],
        ]);
        out.bend.push(b.bend[i]);
    }
}

/// The group of `part` of cloth `cloth` (its range starting at global vertex `vbase +
/// range.start`): its constraints appended colour by colour, leftovers last.
fn group(
    cloth: u32,
    vbase: u32,
    part: &Part,
    bending: bool,
    shared: bool,
    dist: &mut Distances,
    hinges: &mut Hinges,
) -> GroupSpec {
    let mut record = [0u32; GROUP_WORDS];
    record[0] = cloth;
    record[1] = vbase + part.range.start as u32;
    record[2] = part.range.len() as u32;
    record[3] = u32::from(shared);
    let mut dist_bounds = vec![dist.len() as u32];
    for r in &part.distance.colours.independent {
        push_distances(part, r.clone(), dist);
        dist_bounds.push(dist.len() as u32);
    }
    record[5] = part.distance.colours.independent.len() as u32;
    record[7] = dist.len() as u32;
    push_distances(part, part.distance.colours.sequential.clone(), dist);
    record[8] = dist.len() as u32 - record[7];
    let mut bend_bounds = vec![hinges.len() as u32];
    if bending {
        for r in &part.bending.colours.independent {
            push_hinges(part, r.clone(), hinges);
            bend_bounds.push(hinges.len() as u32);
        }
        record[10] = part.bending.colours.independent.len() as u32;
    }
    record[12] = hinges.len() as u32;
    if bending {
        push_hinges(part, part.bending.colours.sequential.clone(), hinges);
    }
    record[13] = hinges.len() as u32 - record[12];
    GroupSpec {
        record,
        dist_bounds,
        bend_bounds,
    }
}

/// Per edge of `t`, the triangles it belongs to.
fn edge_triangles(t: &Topology) -> Vec<Vec<u32>> {
    let mut index: Vec<([u32; 2], usize)> = t
        .edges()
        .iter()
        .enumerate()
        .map(|(i, e)| (e.v, i))
        .collect();
    index.sort_unstable();
    let mut out = vec![Vec::new(); t.edges().len()];
    for (k, tri) in t.triangles().iter().enumerate() {
        for j in 0..3 {
            let (a, b) = (tri[j], tri[(j + 1) % 3]);
            if let Ok(i) = index.binary_search_by_key(&[a.min(b), a.max(b)], |x| x.0) {
                out[index[i].1].push(k as u32);
            }
        }
    }
    out
}

impl WorldLayout {
    /// [`Self::build_with`] the GPU batches of each of `sims` made afresh.
    #[must_use]
    #[cfg(test)]
    pub(crate) fn build(sims: &[&Simulation]) -> Self {
        let batches: Vec<ConstraintBatches> = sims.iter().map(|s| choose_batches(s)).collect();
        let batches: Vec<&ConstraintBatches> = batches.iter().collect();
        Self::build_with(sims, &batches)
    }

    /// The layout of `sims`, each with its GPU batches (`chosen`: its upload's
    /// [`BatchesCell`]'s). They must share their substep and iteration counts and be all
    /// lab-solver cloths or none (the caller groups cloths by [`WorldKey`]).
    ///
    /// # Panics
    /// If `sims` do not share a key, or `chosen` is not one set of batches for each.
    #[must_use]
    pub(crate) fn build_with(sims: &[&Simulation], chosen: &[&ConstraintBatches]) -> Self {
        assert_eq!(sims.len(), chosen.len(), "one set of batches a cloth");
        let key = sims.first().map(|s| WorldKey::of(s));
        assert!(
            sims.iter().all(|s| Some(WorldKey::of(s)) == key),
            "a world's cloths share substeps, iterations and solver kind"
        );
        let key = key.unwrap_or(WorldKey {
            substeps: 1,
            iterations: 1,
            lab: false,
        });
        let mut out = WorldLayout {
            substeps: key.substeps,
            iterations: key.iterations,
            lab: key.lab,
            ..Default::default()
        };
        // The big tables at their final sizes from the start: grown as they fill, their copies
        // and fresh pages were a third of a layout's time.
        let total = |f: fn(&Topology) -> usize| sims.iter().map(|s| f(s.topology())).sum();
        // (The lab solver's cloths have no constraint groups.)
        let (all_edges, all_bends) = if key.lab {
            (0, 0)
        } else {
            let bent = sims.iter().zip(chosen).filter(|(_, b)| b.bending);
            let bends = bent.map(|(s, _)| s.topology().bends().len()).sum();
            (total(|t| t.edges().len()), bends)
        };
        let all_vertices = total(Topology::vertex_count);
        let mut dist = Distances {
            // `cons` takes the hinges' three words each after the distances.
            cons: Vec::with_capacity(all_edges + 3 * all_bends),
            edge: Vec::with_capacity(all_edges),
        };
        let mut hinges = Hinges {
            cons: Vec::with_capacity(all_bends),
            bend: Vec::with_capacity(all_bends),
        };
        let mut levels: [Vec<GroupSpec>; 4] = Default::default();
        let mut vertex_cloth = Vec::with_capacity(all_vertices);
        let mut vertex_pin = Vec::with_capacity(all_vertices);
        let mut records = Vec::new();
        let mut triangles: Vec<[u32; 3]> = Vec::with_capacity(total(|t| t.triangles().len()));
        let mut tethers: Vec<(u32, [u32; 2])> = Vec::new();
        let mut lab_edges: Vec<(u32, [u32; 2])> = Vec::new();
        let mut tear_edges: Vec<[u32; 4]> = Vec::new();
        let mut edge_tris: Vec<(u32, [u32; 1])> = Vec::new();
        let mut triangle_scales: Vec<u32> = Vec::new();
        let mut settle_edges: Vec<[u32; 3]> = Vec::new();
        let any_sc = sims.iter().any(|s| s.features().self_collision.is_some());
        for (c, sim) in sims.iter().enumerate() {
            let c = c as u32;
            let n = sim.state().len() as u32;
            let vbase = out.n;
            let pin_base = out.pins;
            let pins = sim.state().pins();
            vertex_cloth.extend(core::iter::repeat_n(c, n as usize));
            let first_pin = vertex_pin.len();
            vertex_pin.extend(core::iter::repeat_n(NO_PIN, n as usize));
            for (k, p) in pins.iter().enumerate() {
                vertex_pin[first_pin + p.vertex as usize] = pin_base + k as u32;
            }
            let params = sim.params();
            let features = sim.features();
            let xpbd = matches!(params.solver, Solver::Xpbd { .. });
            let mut flags = 0;
            if params.sleep.enabled() {
                flags |= FLAG_SLEEP;
            }
            if !params.air.is_none() && !key.lab {
                flags |= FLAG_AIR;
            }
            if xpbd {
                flags |= FLAG_XPBD;
            }
            if xpbd && params.iterations > 1 {
                flags |= FLAG_ACCUMULATE;
            }
            let sc = features.self_collision.filter(|_| !key.lab);
            if sc.is_some() {
                flags |= FLAG_SC;
                if sim.topology().is_closed() {
                    flags |= FLAG_CLOSED;
                }
                if limits_depenetration(sim.topology()) {
                    flags |= FLAG_EVEN;
                }
            }
            let batches = chosen[c as usize];
            if batches.bending && !batches.boundary.bending.iso {
                flags |= FLAG_DIHEDRAL;
            }
            if batches.symmetric_sweeps() && !key.lab {
                flags |= FLAG_SYMMETRIC;
            }
            if let Some(tp) = features.tethers.filter(|_| !key.lab) {
                // The simulation's own where the backend made them before the upload.
                let built;
                let t = if let Some(t) = sim.current_tethers() {
                    t
                } else {
                    let pinned: Vec<u32> = pins.iter().map(|p| p.vertex).collect();
                    built = Tethers::build(sim.topology(), &pinned, tp);
                    &built
                };
                if !t.is_empty() {
                    flags |= FLAG_TETHERS;
                    tethers.extend(
                        t.entries()
                            .map(|(v, pin, max)| (vbase + v, [vbase + pin, max.to_bits()])),
                    );
                }
            }
            let tri_base = triangles.len() as u32;
            triangles.extend(
                sim.topology()
                    .triangles()
                    .iter()
                    .map(|t| t.map(|v| v + vbase)),
            );
            if key.lab {
                lab_edges.extend(sim.topology().edges().iter().flat_map(|e| {
                    let rest = e.rest.to_bits();
                    [
                        (vbase + e.v[0], [vbase + e.v[1], rest]),
                        (vbase + e.v[1], [vbase + e.v[0], rest]),
                    ]
                }));
            }
            let (settling, _) = sim.settle_state();
            if settling > 0 {
                out.settle_steps = out.settle_steps.max(settling);
                settle_edges.extend(
                    sim.topology()
                        .edges()
                        .iter()
                        .map(|e| [vbase + e.v[0], vbase + e.v[1], e.rest.to_bits()]),
                );
            }
            let tearing = features.tear_threshold.is_some_and(|t| t > 1.0);
            if tearing && !key.lab {
                flags |= FLAG_TEARING;
            }
            // The record (`common.wgsl`'s `cloth_of`); gravity·h and the damping factor
            // (words 5–8) depend on the step length and are written per frame.
            let mut rec = [0u32; CLOTH_WORDS];
            rec[0] = vbase;
            rec[1] = n;
            rec[2] = pin_base;
            rec[3] = pins.len() as u32;
            rec[4] = flags;
            rec[9] = params.max_speed.to_bits();
            rec[10] = params.air.drag.to_bits();
            rec[11] = params.air.lift.to_bits();
            rec[12] = params.air.friction.to_bits();
            rec[13] = sc.map_or(0.0, |s| s.thickness).to_bits();
            rec[14] = sc.map_or(0.0, |s| s.friction).to_bits();
            rec[15] = features.tear_threshold.unwrap_or(0.0).to_bits();
            rec[16] = c;
            rec[17] = if sc.is_some() { out.head_words } else { 0 };
            // Each vertex's thickness over the cloth's rides in its rest position's w (1 where
            // the mesh is even and has no scales).
            let (rest, tris) = (sim.topology().rest_positions(), sim.topology().triangles());
            let scales = sim.topology().self_collision_scales();
            if let Some(sc) = sc {
                rec[18] = first_corner_reach(rest, tris).to_bits();
                let most = scales.iter().copied().fold(1.0, f32::max);
                rec[19] = (sc.thickness * most).to_bits();
            }
            if sc.is_some() {
                out.head_words += 2 * n;
            }
            records.push(rec);
            // Groups: parts (in workgroup memory when they fit), seams, the boundary.
            let first_distance = dist.len();
            let first_hinge = hinges.len();
            if !key.lab {
                let bending = batches.bending;
                for part in &batches.parts {
                    let shared = part.range.len() <= TILE;
                    let g = group(c, vbase, part, bending, shared, &mut dist, &mut hinges);
                    levels[0].push(g);
                }
                for (parity, seams) in batches.seams.iter().enumerate() {
                    for seam in seams {
                        let g = group(c, vbase, seam, bending, false, &mut dist, &mut hinges);
                        levels[1 + parity].push(g);
                    }
                }
                let b = &batches.boundary;
                if !b.distance.a().is_empty() || !b.bending.v()[0].is_empty() {
                    let g = group(c, vbase, b, bending, false, &mut dist, &mut hinges);
                    levels[3].push(g);
                }
            }
            if tearing {
                // Each edge with the slot of its distance constraint in `cons`, where
                // `tear_check` flags it torn (`NO_PIN`: the lab solver, which has none).
                let mut slot = vec![NO_PIN; sim.topology().edges().len()];
                for (k, &e) in dist.edge[first_distance..].iter().enumerate() {
                    slot[e as usize] = (first_distance + k) as u32;
                }
                // And each edge's triangles, which its tear takes with it.
                let t = sim.topology();
                let tris_of = edge_triangles(t);
                let edge_base = tear_edges.len() as u32;
                for (e, tris) in tris_of.iter().enumerate() {
                    edge_tris.extend(tris.iter().map(|&k| (edge_base + e as u32, [tri_base + k])));
                }
                tear_edges.extend(
                    t.edges()
                        .iter()
                        .zip(slot)
                        .map(|(e, slot)| [vbase + e.v[0], vbase + e.v[1], e.rest.to_bits(), slot]),
                );
                // Each hinge's two triangles (those of its edge with either opposite corner),
                // which hold it only while neither tore.
                for k in first_hinge..hinges.len() {
                    let bend = t.bends()[hinges.bend[k] as usize];
                    let with = |corner: u32| {
                        tris_of[bend.edge as usize]
                            .iter()
                            .find(|&&tri| t.triangles()[tri as usize].contains(&corner))
                            .map_or(NO_PIN, |&tri| tri_base + tri)
                    };
                    hinges.cons[k][2][1] = with(bend.v[2]);
                    hinges.cons[k][2][2] = with(bend.v[3]);
                }
            }
            out.any_tethers |= flags & FLAG_TETHERS != 0;
            out.any_accumulate |= flags & FLAG_ACCUMULATE != 0;
            out.any_tearing |= tearing;
            out.cloths.push(ClothLayout {
                vbase,
                n,
                pin_base,
                pins: pins.len() as u32,
                parts: batches.part_count(),
                flags,
                tearing,
                distances: first_distance as u32..dist.len() as u32,
                triangles: tri_base..triangles.len() as u32,
                gravity: params.gravity,
                damping: params.damping,
                keep: match params.solver {
                    Solver::Lab { velocity_keep } => Some(velocity_keep),
                    _ => None,
                },
            });
            out.n += n;
            out.pins += pins.len() as u32;
            if any_sc {
                let scale = |i: usize| scales.get(i).copied().unwrap_or(1.0);
                out.rest.reserve_exact(all_vertices - out.rest.len());
                out.rest
                    .extend(rest.iter().enumerate().map(|(i, p)| p.extend(scale(i))));
                let from_triangles = sim.topology().self_collision_triangle_scales();
                triangle_scales.extend((0..rest.len()).map(|i| {
                    from_triangles
                        .get(i)
                        .copied()
                        .unwrap_or_else(|| scale(i))
                        .to_bits()
                }));
            }
        }
        out.any_sc = any_sc && out.head_words > 0;
        if !out.any_sc {
            out.rest.clear();
        }
        // `cons`: distances, then hinges.
        out.distances = dist.len() as u32;
        out.hinges = hinges.len() as u32;
        out.bend_at = dist.len() as u32;
        out.cons = dist.cons;
        out.cons.extend(hinges.cons.iter().flatten());
        // `topo`.
        let n = out.n as usize;
        // Its size, so that it is allocated once: the tables appended below, in order.
        let lists = |owners: usize, items: usize, words: usize| owners + 1 + words * items;
        let group_words: usize = levels
            .iter()
            .flatten()
            .map(|g| GROUP_WORDS + g.dist_bounds.len() + g.bend_bounds.len())
            .sum();
        let t = triangles.len();
        let sc_words = if out.any_sc { n + lists(n, t, 1) } else { 0 };
        let size = records.len() * CLOTH_WORDS
            + 2 * n
            + group_words
            + lists(n, 3 * t, 1)
            + 3 * t
            + sc_words
            + lists(n, tethers.len(), 2)
            + lists(n, lab_edges.len(), 2)
            + 4 * tear_edges.len()
            + lists(tear_edges.len(), edge_tris.len(), 1)
            + 3 * settle_edges.len();
        let mut topo: Vec<u32> = Vec::with_capacity(size);
        out.cloth_at = topo.len() as u32;
        topo.extend(records.iter().flatten());
        out.vertex_cloth_at = topo.len() as u32;
        topo.extend(&vertex_cloth);
        out.vertex_pin_at = topo.len() as u32;
        topo.extend(&vertex_pin);
        // Group records, then each group's colour bounds (absolute constraint indices).
        out.group_at = topo.len() as u32;
        let groups: Vec<GroupSpec> = levels
            .iter_mut()
            .enumerate()
            .flat_map(|(l, g)| {
                let first = out.levels[..l].iter().map(|r| r.count).sum::<u32>();
                out.levels[l] = LevelRange {
                    first,
                    count: g.len() as u32,
                };
                core::mem::take(g)
            })
            .collect();
        let bounds_at = topo.len() + groups.len() * GROUP_WORDS;
        topo.resize(bounds_at, 0);
        for (i, g) in groups.iter().enumerate() {
            let mut rec = g.record;
            rec[6] = topo.len() as u32;
            topo.extend(&g.dist_bounds);
            rec[11] = topo.len() as u32;
            // Hinge bounds count hinges; the kernel indexes hinges from `bend_at`.
            topo.extend(&g.bend_bounds);
            let at = out.group_at as usize + i * GROUP_WORDS;
            topo[at..at + GROUP_WORDS].copy_from_slice(&rec);
        }
        // Triangles per vertex in triangle order, then the triangles.
        out.tri_offsets_at = append_lists(
            &mut topo,
            n,
            triangles
                .iter()
                .enumerate()
                .flat_map(|(i, t)| t.map(|v| (v, [i as u32]))),
        );
        out.tri_at = topo.len() as u32;
        topo.extend(triangles.iter().flatten());
        if out.any_sc {
            out.sc_triangle_scale_at = topo.len() as u32;
            topo.extend(&triangle_scales);
            out.first_tri_at = append_lists(
                &mut topo,
                n,
                triangles
                    .iter()
                    .enumerate()
                    .map(|(i, t)| (t[0], [i as u32])),
            );
        }
        out.tether_at = append_lists(&mut topo, n, tethers.iter().copied());
        out.lab_at = append_lists(&mut topo, n, lab_edges.iter().copied());
        out.edges_at = topo.len() as u32;
        out.edges = tear_edges.len() as u32;
        topo.extend(tear_edges.iter().flatten());
        out.edge_tris_at = append_lists(&mut topo, tear_edges.len(), edge_tris);
        out.settle_edges_at = topo.len() as u32;
        out.settle_edges = settle_edges.len() as u32;
        topo.extend(settle_edges.iter().flatten());
        out.triangles = triangles.len() as u32;
        out.topo = topo;
        out
    }
}

/// What cloths must share to step in one world: the dispatches of a substep, and how many.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct WorldKey {
    /// Substeps per step.
    pub substeps: u32,
    /// Iterations per substep.
    pub iterations: u32,
    /// Whether the cloths use the lab solver (its own kernels).
    pub lab: bool,
}

impl WorldKey {
    /// The key of `sim`'s settings.
    #[must_use]
    pub fn of(sim: &Simulation) -> Self {
        let p = sim.params();
        Self {
            substeps: p.substeps.max(1),
            iterations: p.iterations.max(1),
            lab: matches!(p.solver, Solver::Lab { .. }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::{Features, Grid, HangingCloth, SelfCollision, SolverParams, TetherParams};

    fn standard(n: u32) -> Simulation {
        HangingCloth::new(n).build().unwrap()
    }

    /// An upload's GPU batches measured again from the last upload's are the batches made
    /// afresh for it where only the rest shape changed; made afresh after a tear, another
    /// bending model, or where the last upload's were never made or are gone; kept for the
    /// upload's later layouts.
    #[test]
    fn batches_measured_again_from_the_last_upload_are_the_ones_made_afresh() {
        use std::sync::Arc;
        let mut scene = HangingCloth::new(64);
        scene.params.solver = Solver::Xpbd {
            stretch: 0.0,
            shear: 1e-6,
            bending: 1e-4,
        };
        let was = scene.build().unwrap();
        let first = Arc::new(BatchesCell::after(None));
        assert_eq!(first.get(&was), &choose_batches(&was));
        // Its rest shape scaled unevenly and rolled: measured again.
        let shaped: Vec<glam::Vec3> = was
            .topology()
            .rest_positions()
            .iter()
            .map(|p| glam::Vec3::new(2.0 * p.x, p.y + 0.3 * (3.0 * p.x).sin(), 0.5 * p.z))
            .collect();
        let mut grown = was.clone();
        grown
            .set_rest_shape(was.topology().reshaped(&shaped).unwrap())
            .unwrap();
        let made = choose_batches(&grown);
        assert_ne!(&made, first.get(&was));
        let next = Arc::new(BatchesCell::after(Some(&first)));
        assert_eq!(next.get(&grown), &made);
        assert!(first.made.get().unwrap().built_from(grown.topology()));
        // Kept: asked again (another cloth's change), the same batches.
        assert!(core::ptr::eq(next.get(&grown), next.get(&grown)));
        // Torn: other edges, made afresh.
        let mut torn = grown.clone();
        torn.tear_edges(&[[0, 1], [64, 65]]);
        assert!(!next.made.get().unwrap().built_from(torn.topology()));
        assert_eq!(
            BatchesCell::after(Some(&next)).get(&torn),
            &choose_batches(&torn)
        );
        // The last upload's never made, or gone: made afresh.
        let unmade = Arc::new(BatchesCell::after(None));
        assert_eq!(BatchesCell::after(Some(&unmade)).get(&grown), &made);
        let gone = BatchesCell::after(Some(&Arc::new(BatchesCell::after(None))));
        assert_eq!(gone.get(&grown), &made);
        // Another bending model (the same edges and hinges): made afresh.
        let mut dihedral = HangingCloth::new(64);
        dihedral.params = *was.params();
        dihedral.options.bending = crate::solver::BendingModel::Dihedral;
        let dihedral = dihedral.build().unwrap();
        assert!(!first.made.get().unwrap().built_from(dihedral.topology()));
        let other = BatchesCell::after(Some(&first));
        assert_eq!(other.get(&dihedral), &choose_batches(&dihedral));
    }

    /// A layout's big tables are allocated at their final sizes (not grown as they fill):
    /// cloths with and without self-collision, tethers, tearing and a settle, and the lab
    /// solver's.
    #[test]
    fn the_tables_are_allocated_once_at_their_size() {
        let mut full = HangingCloth::new(24);
        full.features = Features {
            self_collision: Some(SelfCollision {
                thickness: 0.02,
                friction: 0.2,
            }),
            tethers: Some(TetherParams::default()),
            tear_threshold: Some(2.0),
        };
        let full = full.build().unwrap();
        let mut settling = standard(16);
        settling.settle();
        let mut lab = HangingCloth::new(12);
        lab.params.solver = Solver::Lab {
            velocity_keep: 0.99,
        };
        let lab = lab.build().unwrap();
        let mut stiff = HangingCloth::new(12);
        stiff.params.solver = Solver::Pbd {
            stretch: 1.0,
            shear: 1.0,
            bending: 0.0,
        };
        let unbent = stiff.build().unwrap();
        for sims in [
            vec![&full],
            vec![&full, &settling],
            vec![&settling],
            vec![&lab],
            vec![&unbent],
        ] {
            let w = WorldLayout::build(&sims);
            assert_eq!(w.topo.capacity(), w.topo.len(), "topo");
            assert_eq!(w.cons.capacity(), w.cons.len(), "cons");
            if w.any_sc {
                assert_eq!(w.rest.capacity(), w.rest.len(), "rest");
            }
        }
    }

    #[test]
    fn parts_fit_workgroup_memory_without_constraints_far_apart() {
        for (n, parts) in [(8, 1), (32, 1), (64, 4), (256, 64), (512, 256)] {
            let sim = standard(n);
            let b = choose_batches(&sim);
            assert_eq!(b.part_count(), parts, "{n}²");
            assert!(b.boundary.distance.a().is_empty(), "{n}²: boundary");
        }
    }

    #[test]
    fn every_constraint_is_in_exactly_one_group_of_a_level_whose_groups_share_no_vertex() {
        let mut a = HangingCloth::new(48);
        a.features = Features {
            self_collision: Some(SelfCollision {
                thickness: 0.02,
                friction: 0.2,
            }),
            tethers: Some(TetherParams::default()),
            tear_threshold: Some(2.0),
        };
        let a = a.build().unwrap();
        let b = standard(64);
        let world = WorldLayout::build(&[&a, &b]);
        let total_edges: usize = [&a, &b].iter().map(|s| s.topology().edges().len()).sum();
        let total_bends: usize = [&a, &b].iter().map(|s| s.topology().bends().len()).sum();
        assert_eq!(world.distances as usize, total_edges);
        assert_eq!(world.hinges as usize, total_bends);
        assert_eq!(world.cloths[1].vbase, 48 * 48);
        assert!(world.any_sc && world.any_tethers && world.any_tearing);
        // Each cloth's distance constraints are one range, the ranges in order.
        assert_eq!(world.cloths[0].distances.start, 0);
        assert_eq!(
            world.cloths[0].distances.end,
            world.cloths[1].distances.start
        );
        assert_eq!(world.cloths[1].distances.end, world.distances);
        // The group base of every distance constraint, to check the tear edges' slots.
        let mut base_of = vec![u32::MAX; world.distances as usize];
        for g in 0..world.levels.iter().map(|l| l.count).sum::<u32>() {
            let at = (world.group_at as usize) + g as usize * GROUP_WORDS;
            let rec = &world.topo[at..at + GROUP_WORDS];
            for i in world.topo[rec[6] as usize]..rec[7] + rec[8] {
                base_of[i as usize] = rec[1];
            }
        }
        // The tearing cloth's edges, each with the slot of its own distance constraint.
        assert_eq!(world.edges as usize, a.topology().edges().len());
        let edges = &world.topo[world.edges_at as usize..][..4 * world.edges as usize];
        for (e, w) in a.topology().edges().iter().zip(edges.chunks(4)) {
            assert_eq!([w[0], w[1], w[2]], [e.v[0], e.v[1], e.rest.to_bits()]);
            let slot = w[3] as usize;
            assert!(world.cloths[0].distances.contains(&w[3]));
            let c = world.cons[slot];
            assert_eq!([base_of[slot] + c[0], base_of[slot] + c[1]], e.v);
            assert_eq!(c[2], e.rest.to_bits());
        }
        assert_ne!(world.cloths[0].flags & FLAG_TEARING, 0);
        assert_eq!(world.cloths[1].flags & FLAG_TEARING, 0);
        // Within each level, no two groups touch the same vertex.
        for level in &world.levels {
            let mut owner = vec![u32::MAX; world.n as usize];
            for g in level.first..level.first + level.count {
                let at = (world.group_at as usize) + g as usize * GROUP_WORDS;
                let rec = &world.topo[at..at + GROUP_WORDS];
                let base = rec[1];
                let (d_from, d_to) = (world.topo[rec[6] as usize], rec[7] + rec[8]);
                for i in d_from..d_to {
                    let c = world.cons[i as usize];
                    for v in [c[0], c[1]] {
                        let v = (base + v) as usize;
                        assert!(
                            owner[v] == u32::MAX || owner[v] == g,
                            "vertex {v} in two groups"
                        );
                        owner[v] = g;
                    }
                }
            }
        }
    }

    #[test]
    fn each_tearing_cloths_flags_name_its_own_edges() {
        // Three cloths, the first and last tearing: every flag of a tearing cloth is one of
        // its edges, each edge has one flag, and its triangles are those that have the edge.
        let tearing = |n: u32| {
            let mut c = HangingCloth::new(n);
            c.features.tear_threshold = Some(1.5);
            c.build().unwrap()
        };
        let (a, b, c) = (tearing(20), standard(12), tearing(40));
        let world = WorldLayout::build(&[&a, &b, &c]);
        let tables = crate::gpu::world::torn_edge_tables(&world);
        assert!(tables[1].is_none());
        let lists = &world.topo[world.edge_tris_at as usize..];
        let mut tear_edge = 0;
        for (k, sim) in [(0, &a), (2, &c)] {
            let layout = &world.cloths[k];
            let table = tables[k].as_ref().unwrap();
            assert_eq!(table.len(), layout.distances.len());
            let mut flags: Vec<[u32; 2]> = table.to_vec();
            flags.sort_unstable();
            let mut edges: Vec<[u32; 2]> = sim.topology().edges().iter().map(|e| e.v).collect();
            edges.sort_unstable();
            assert_eq!(flags, edges);
            for e in sim.topology().edges() {
                let (from, to) = (lists[tear_edge] as usize, lists[tear_edge + 1] as usize);
                let mut tris: Vec<u32> = world.topo[from..to].to_vec();
                tris.sort_unstable();
                let base = if k == 0 {
                    0
                } else {
                    (a.topology().triangles().len() + b.topology().triangles().len()) as u32
                };
                let expected: Vec<u32> = sim
                    .topology()
                    .triangles()
                    .iter()
                    .enumerate()
                    .filter(|(_, t)| t.contains(&e.v[0]) && t.contains(&e.v[1]))
                    .map(|(i, _)| base + i as u32)
                    .collect();
                assert_eq!(tris, expected);
                tear_edge += 1;
            }
        }
        assert_eq!(tear_edge, world.edges as usize);
    }

    #[test]
    fn worlds_hold_one_key() {
        let a = standard(8);
        let mut b = HangingCloth::new(8);
        b.params = SolverParams {
            substeps: 3,
            ..Default::default()
        };
        let b = b.build().unwrap();
        assert_ne!(WorldKey::of(&a), WorldKey::of(&b));
        let _ = Grid::new(2, 2, 1.0, 1.0);
    }
}
