//! Welding: the user's mesh vertices onto simulated particles, and shading back onto them.
//!
//! A mesh exported from a modelling tool splits a vertex wherever its attributes differ on two
//! sides: along UV seams (same position, different UV) and along hard edges (same position,
//! different normal). Simulating each copy as its own particle would tear the cloth along
//! every seam, so copies closer than a tolerance become one particle ([`Weld::new`]).
//!
//! Data flow: mesh positions (+ source normals) → [`Weld`] (particle of each mesh vertex,
//! normal group of each mesh vertex) → particle positions and particle triangles
//! ([`Weld::gather`], [`Weld::particle_triangles`]) for the
//! [`Topology`]. After each step, [`MeshShading`] turns particle positions
//! back into per-mesh-vertex normals and tangents; positions are read through
//! [`Weld::particle`].
//!
//! The normal rule: copies of one particle whose *source* normals agree (within
//! [`HARD_EDGE_COS`], about 8°) form one normal group and share one normal, averaged over all
//! their triangles — smooth across UV seams. Copies whose source normals differ more keep a
//! normal of their own, averaged over their own triangles only — hard edges stay hard. A mesh
//! without normals is smooth everywhere. Tangents follow each copy's own UVs (a seam is where
//! the texture's direction may jump).

use std::collections::HashMap;

use glam::{IVec3, Vec2, Vec3, Vec4};

use super::shading::{GatherLayout, MeshShading};
use super::topology::{Topology, TopologyError, TopologyOptions};
use crate::solver::parallel::Parallel;

/// Copies whose source normals have a cosine at least this large share a normal (about 8°).
pub const HARD_EDGE_COS: f32 = 0.99;

/// Which particle each mesh vertex is, and which copies share a normal.
#[derive(Clone, Debug, PartialEq)]
pub struct Weld {
    particle: Vec<u32>,
    representative: Vec<u32>,
    group: Vec<u32>,
    groups: usize,
}

impl Weld {
    /// Every mesh vertex its own particle.
    #[must_use]
    pub fn identity(vertex_count: usize) -> Self {
        let ids: Vec<u32> = (0..vertex_count as u32).collect();
        Self {
            particle: ids.clone(),
            representative: ids.clone(),
            group: ids,
            groups: vertex_count,
        }
    }

    /// Welds vertices closer than `tolerance` (metres, ≥ 0; 0 welds exact duplicates only).
    ///
    /// Particles are numbered in order of their first copy, so a mesh without duplicates
    /// gets particle `i` = vertex `i`. Non-finite positions are never welded (the topology
    /// refuses them later with the vertex's index). `normals`, when given, decide the normal
    /// groups (see the module docs); a NaN or negative tolerance welds exact duplicates only.
    #[must_use]
    pub fn new(positions: &[Vec3], normals: Option<&[Vec3]>, tolerance: f32) -> Self {
        let n = positions.len();
        let tol = if tolerance.is_finite() && tolerance > 0.0 {
            tolerance
        } else {
            0.0
        };
        let mut particle = Vec::with_capacity(n);
        let mut representative: Vec<u32> = Vec::new();
        if tol == 0.0 {
            let mut exact: HashMap<[u32; 3], u32> = HashMap::with_capacity(n);
            for (i, p) in positions.iter().enumerate() {
                let id = if p.is_finite() {
                    // +0 and −0 are the same place.
                    let key = (*p + Vec3::ZERO).to_array().map(f32::to_bits);
                    *exact.entry(key).or_insert_with(|| {
                        representative.push(i as u32);
                        representative.len() as u32 - 1
                    })
                } else {
                    representative.push(i as u32);
                    representative.len() as u32 - 1
                };
                particle.push(id);
            }
        } else {
            // Cells of the tolerance: a match lies in one of the 27 cells around a vertex.
            let inv = 1.0 / tol;
            let mut cells: HashMap<IVec3, Vec<u32>> = HashMap::with_capacity(n);
            let tol2 = tol * tol;
            for (i, p) in positions.iter().enumerate() {
                let found = if p.is_finite() && (*p * inv).abs().max_element() < 1e9 {
                    let c = (*p * inv).floor().as_ivec3();
                    let mut hit = None;
                    'search: for dz in -1..=1 {
                        for dy in -1..=1 {
                            for dx in -1..=1 {
                                if let Some(list) = cells.get(&(c + IVec3::new(dx, dy, dz))) {
                                    for &q in list {
                                        let r = representative[q as usize] as usize;
                                        if positions[r].distance_squared(*p) <= tol2 {
                                            hit = Some(q);
                                            break 'search;
                                        }
                                    }
                                }
                            }
                        }
                    }
                    match hit {
                        Some(q) => Some(q),
                        None => {
                            let id = representative.len() as u32;
                            representative.push(i as u32);
                            cells.entry(c).or_default().push(id);
                            Some(id)
                        }
                    }
                } else {
                    None
                };
                particle.push(found.unwrap_or_else(|| {
                    representative.push(i as u32);
                    representative.len() as u32 - 1
                }));
            }
        }
        let (group, groups) = normal_groups(&particle, representative.len(), normals);
        Self {
            particle,
            representative,
            group,
            groups,
        }
    }

    /// Whether every mesh vertex is its own particle with its own normal.
    #[must_use]
    pub fn is_identity(&self) -> bool {
        self.representative.len() == self.particle.len() && self.groups == self.particle.len()
    }

    /// Number of mesh vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.particle.len()
    }

    /// Number of particles.
    #[must_use]
    pub fn particle_count(&self) -> usize {
        self.representative.len()
    }

    /// The particle of mesh vertex `v`.
    #[inline]
    #[must_use]
    pub fn particle(&self, v: u32) -> u32 {
        self.particle[v as usize]
    }

    /// The particle of every mesh vertex.
    #[must_use]
    pub fn particles(&self) -> &[u32] {
        &self.particle
    }

    /// The first mesh vertex of particle `p` (how a particle is named to the user).
    #[inline]
    #[must_use]
    pub fn representative(&self, p: u32) -> u32 {
        self.representative[p as usize]
    }

    /// Normal group of every mesh vertex, and the number of groups.
    #[must_use]
    pub fn normal_groups(&self) -> (&[u32], usize) {
        (&self.group, self.groups)
    }

    /// Per-particle values taken from each particle's first copy.
    #[must_use]
    pub fn gather<T: Copy>(&self, per_vertex: &[T]) -> Vec<T> {
        self.representative
            .iter()
            .map(|&r| per_vertex[r as usize])
            .collect()
    }

    /// The mesh's triangle list in particle indices, each particle triangle once (a
    /// double-sided mesh's back faces land on its front faces), with the index of the first
    /// mesh triangle behind each. Out-of-range indices are kept as they are for the topology
    /// to report.
    #[must_use]
    pub fn particle_triangles(&self, indices: &[u32]) -> (Vec<u32>, Vec<u32>) {
        let mut seen: HashMap<[u32; 3], ()> = HashMap::with_capacity(indices.len() / 3);
        let mut out = Vec::with_capacity(indices.len());
        let mut source = Vec::with_capacity(indices.len() / 3);
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            let p = [tri[0], tri[1], tri[2]].map(|v| {
                self.particle
                    .get(v as usize)
                    .copied()
                    .unwrap_or(v.max(self.particle_count() as u32))
            });
            let mut key = p;
            key.sort_unstable();
            if seen.insert(key, ()).is_none() {
                out.extend_from_slice(&p);
                source.push(t as u32);
            }
        }
        (out, source)
    }
}

fn normal_groups(
    particle: &[u32],
    particles: usize,
    normals: Option<&[Vec3]>,
) -> (Vec<u32>, usize) {
    let Some(normals) = normals.filter(|n| n.len() == particle.len()) else {
        return (particle.to_vec(), particles);
    };
    // For each particle, the groups made so far: (group id, its first copy's normal).
    let mut made: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); particles];
    let mut group = Vec::with_capacity(particle.len());
    let mut count = 0u32;
    for (v, &p) in particle.iter().enumerate() {
        let n = normals[v].normalize_or_zero();
        let list = &mut made[p as usize];
        let g = match list.iter().find(|(_, m)| m.dot(n) >= HARD_EDGE_COS) {
            Some((g, _)) => *g,
            None if list.is_empty() || n == Vec3::ZERO => {
                // The first copy, or one with no usable normal: join the first group.
                if let Some((g, _)) = list.first() {
                    *g
                } else {
                    list.push((count, n));
                    count += 1;
                    count - 1
                }
            }
            None => {
                list.push((count, n));
                count += 1;
                count - 1
            }
        };
        group.push(g);
    }
    (group, count as usize)
}

/// How a user's mesh is simulated: its [`Weld`], its triangles (mesh indices), which of them
/// are still drawn after tearing, and its [`MeshShading`].
///
/// Built once per cloth; [`Self::topology`] gives the particles' [`Topology`] (rest shape in
/// any space the caller places the mesh in); after a tear, [`Self::retain`] keeps the mesh
/// triangles whose particle triangle survived.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshBinding {
    weld: Weld,
    triangles: Vec<[u32; 3]>,
    /// Particle triangle (sorted particle triple) behind each mesh triangle.
    keys: Vec<[u32; 3]>,
    /// Mesh triangles drawn now.
    drawn: Vec<u32>,
    uvs: Option<Vec<Vec2>>,
    shading: MeshShading,
    /// The layout of the shading's sums over `drawn`, once [`Self::update_shading_in`] has
    /// needed it (dropped when `drawn` changes).
    gather: Option<GatherLayout>,
}

/// What a mesh carries besides positions and indices, all optional, one entry per vertex.
#[derive(Clone, Copy, Debug, Default)]
pub struct MeshAttributes<'a> {
    /// Source normals (decide hard edges).
    pub normals: Option<&'a [Vec3]>,
    /// Texture coordinates (tell stretch from shear, give tangents).
    pub uvs: Option<&'a [Vec2]>,
    /// Source tangents with handedness (give tangents when there are no UVs).
    pub tangents: Option<&'a [Vec4]>,
}

impl MeshBinding {
    /// Welds `positions` (mesh space) within `tolerance` metres and checks the index list.
    ///
    /// # Errors
    /// [`TopologyError::NoVertices`], [`TopologyError::NotTriangles`] or
    /// [`TopologyError::IndexOutOfRange`] (naming the mesh index), or
    /// [`TopologyError::UvCount`] for a UV array of the wrong length.
    pub fn new(
        positions: &[Vec3],
        attributes: MeshAttributes<'_>,
        indices: &[u32],
        tolerance: f32,
    ) -> Result<Self, TopologyError> {
        let n = positions.len();
        if n == 0 {
            return Err(TopologyError::NoVertices);
        }
        if !indices.len().is_multiple_of(3) {
            return Err(TopologyError::NotTriangles {
                index_count: indices.len(),
            });
        }
        if let Some((position, &index)) =
            indices.iter().enumerate().find(|(_, i)| **i as usize >= n)
        {
            return Err(TopologyError::IndexOutOfRange {
                position,
                index,
                vertex_count: n,
            });
        }
        if let Some(uv) = attributes.uvs
            && uv.len() != n
        {
            return Err(TopologyError::UvCount {
                uvs: uv.len(),
                positions: n,
            });
        }
        let weld = Weld::new(positions, attributes.normals, tolerance);
        let triangles: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        let keys: Vec<[u32; 3]> = triangles
            .iter()
            .map(|t| {
                let mut k = t.map(|v| weld.particle(v));
                k.sort_unstable();
                k
            })
            .collect();
        let drawn = (0..triangles.len() as u32).collect();
        let tangents = attributes.tangents.filter(|t| t.len() == n);
        let shading = MeshShading::new(&triangles, attributes.uvs, positions, tangents);
        Ok(Self {
            weld,
            triangles,
            keys,
            drawn,
            uvs: attributes.uvs.map(<[Vec2]>::to_vec),
            shading,
            gather: None,
        })
    }

    /// The particles' topology, with the rest shape given per *mesh vertex* (e.g. the mesh
    /// placed in the world): each particle takes its first copy's position. Made of the
    /// triangles drawn now: after a tear ([`Self::retain`]), the torn topology at this rest
    /// shape.
    ///
    /// # Errors
    /// [`TopologyError`] as [`Topology::from_triangles`].
    ///
    /// # Panics
    /// If `rest` does not have one position per mesh vertex.
    pub fn topology(
        &self,
        rest: &[Vec3],
        options: TopologyOptions,
    ) -> Result<Topology, TopologyError> {
        assert_eq!(
            rest.len(),
            self.weld.vertex_count(),
            "one rest position per mesh vertex"
        );
        let triangle = |k: u32| self.triangles[self.drawn[k as usize] as usize];
        let flat: Vec<u32> = (0..self.drawn.len() as u32).flat_map(triangle).collect();
        let (indices, source) = self.weld.particle_triangles(&flat);
        let particle_uvs = self.uvs.as_ref().map(|uv| self.weld.gather(uv));
        let corner_uvs: Option<Vec<[Vec2; 3]>> = self.uvs.as_ref().map(|uv| {
            source
                .iter()
                .map(|&t| triangle(t).map(|v| uv[v as usize]))
                .collect()
        });
        Topology::from_triangles_with_corner_uvs(
            &self.weld.gather(rest),
            particle_uvs.as_deref(),
            corner_uvs.as_deref(),
            &indices,
            options,
        )
        .map_err(|e| {
            // Triangles that only collapsed because their corners welded together had no size.
            let distinct = self
                .triangles
                .iter()
                .any(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
            if e == TopologyError::NoTriangles && distinct {
                TopologyError::ZeroArea
            } else {
                e
            }
        })
    }

    /// Keeps drawing only the mesh triangles whose particle triangle is still in `topology`
    /// (after a tear).
    pub fn retain(&mut self, topology: &Topology) {
        let alive: std::collections::HashSet<[u32; 3]> = topology
            .triangles()
            .iter()
            .map(|t| {
                let mut k = *t;
                k.sort_unstable();
                k
            })
            .collect();
        self.drawn = (0..self.triangles.len() as u32)
            .filter(|&t| alive.contains(&self.keys[t as usize]))
            .collect();
        self.gather = None;
    }

    /// Recomputes the mesh's normals and tangents from the particle positions.
    pub fn update_shading(&mut self, particles: &[Vec4]) {
        self.shading
            .update(&self.weld, particles, &self.triangles, &self.drawn);
    }

    /// [`Self::update_shading`] with the triangles and vertices in chunks on `par`: the same
    /// values bit for bit, whatever the threads. Each vertex gathers its sums, which costs
    /// more work than [`Self::update_shading`]'s scatter over the triangles: worth it where
    /// `par` has threads to spare (one big cloth), not inside another parallel region.
    pub fn update_shading_in(&mut self, particles: &[Vec4], par: &impl Parallel) {
        let (weld, triangles, drawn) = (&self.weld, &self.triangles, &self.drawn);
        let layout = self
            .gather
            .get_or_insert_with(|| GatherLayout::new(weld, triangles, drawn));
        self.shading
            .update_gathered(weld, particles, triangles, drawn, layout, par);
    }

    /// The weld.
    #[must_use]
    pub fn weld(&self) -> &Weld {
        &self.weld
    }

    /// The shading as of the last [`Self::update_shading`].
    #[must_use]
    pub fn shading(&self) -> &MeshShading {
        &self.shading
    }

    /// The mesh triangles drawn now (indices into the mesh's triangle list).
    #[must_use]
    pub fn drawn_triangles(&self) -> &[u32] {
        &self.drawn
    }

    /// The mesh triangles drawn now, as a mesh index list.
    pub fn drawn_indices(&self) -> impl Iterator<Item = u32> + '_ {
        self.drawn.iter().flat_map(|&t| self.triangles[t as usize])
    }

    /// Number of mesh triangles drawn now.
    #[must_use]
    pub fn drawn_count(&self) -> usize {
        self.drawn.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4Swizzles;

    /// Two quads side by side sharing the middle column, split there as an exporter would
    /// (UV seam: vertices 2 and 3 repeat 4 and 5 in position).
    fn seamed() -> (Vec<Vec3>, Vec<u32>) {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 0.0), // seam copy A
            Vec3::new(1.0, 0.0, 1.0), // seam copy A
            Vec3::new(1.0, 0.0, 0.0), // seam copy B
            Vec3::new(1.0, 0.0, 1.0), // seam copy B
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 1.0),
        ];
        let i = vec![0, 1, 2, 2, 1, 3, 4, 5, 6, 6, 5, 7];
        (p, i)
    }

    #[test]
    fn seam_copies_become_one_particle_in_first_appearance_order() {
        let (p, i) = seamed();
        let w = Weld::new(&p, None, 0.0);
        assert_eq!(w.particle_count(), 6);
        assert_eq!(w.particles(), &[0, 1, 2, 3, 2, 3, 4, 5]);
        assert_eq!(w.representative(4), 6);
        let (tris, source) = w.particle_triangles(&i);
        assert_eq!(tris, vec![0, 1, 2, 2, 1, 3, 2, 3, 4, 4, 3, 5]);
        assert_eq!(source, vec![0, 1, 2, 3]);
        // No duplicates: the identity, vertex i is particle i.
        let plain = Weld::new(&p[..4], None, 1e-3);
        assert!(plain.is_identity());
    }

    #[test]
    fn tolerance_welds_near_copies_only() {
        let p = [
            Vec3::ZERO,
            Vec3::new(1e-4, 0.0, 0.0),
            Vec3::new(0.1, 0.0, 0.0),
        ];
        assert_eq!(Weld::new(&p, None, 1e-3).particles(), &[0, 0, 1]);
        assert_eq!(Weld::new(&p, None, 0.0).particles(), &[0, 1, 2]);
        // Non-finite positions stay apart; NaN tolerance means exact.
        let bad = [Vec3::NAN, Vec3::NAN, Vec3::ZERO, Vec3::ZERO];
        assert_eq!(Weld::new(&bad, None, f32::NAN).particles(), &[0, 1, 2, 2]);
        assert_eq!(Weld::new(&bad, None, 1.0).particles(), &[0, 1, 2, 2]);
    }

    #[test]
    fn double_sided_faces_collapse_to_one_particle_triangle() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::ZERO, Vec3::X, Vec3::Z];
        let w = Weld::new(
            &p,
            Some(&[Vec3::Y, Vec3::Y, Vec3::Y, -Vec3::Y, -Vec3::Y, -Vec3::Y]),
            0.0,
        );
        let (tris, source) = w.particle_triangles(&[0, 2, 1, 3, 4, 5]);
        assert_eq!(tris, vec![0, 2, 1]);
        assert_eq!(source, vec![0]);
        // Opposite source normals: two groups per particle.
        assert_eq!(w.normal_groups().1, 6);
    }

    #[test]
    fn seam_normals_are_smooth_and_hard_edges_stay_hard() {
        // A roof: two planes meeting at x = 1 with a 90° crease, split along the crease.
        let (mut p, i) = seamed();
        for q in &mut p {
            q.y = -(q.x - 1.0).abs();
        }
        let up_left = Vec3::new(-1.0, 1.0, 0.0).normalize();
        let up_right = Vec3::new(1.0, 1.0, 0.0).normalize();
        let particles: Vec<Vec4> = {
            let w = Weld::new(&p, None, 0.0);
            w.gather(&p).iter().map(|q| q.extend(1.0)).collect()
        };
        let tris: Vec<[u32; 3]> = i.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let drawn: Vec<u32> = (0..tris.len() as u32).collect();
        // Smooth seam (source normals agree along the crease): one averaged normal.
        let smooth_src = vec![Vec3::Y; 8];
        let w = Weld::new(&p, Some(&smooth_src), 0.0);
        let mut s = MeshShading::new(&tris, None, &p, None);
        s.update(&w, &particles, &tris, &drawn);
        // Both sides' faces count (two on the left touch the corner, one on the right).
        let both = (2.0 * up_left + up_right).normalize();
        assert!(
            (s.normals()[2] - both).length() < 1e-5,
            "{}",
            s.normals()[2]
        );
        assert_eq!(s.normals()[2], s.normals()[4]);
        // Hard edge (source normals differ by 90°): each copy keeps its side's normal.
        let mut hard_src = vec![up_left; 4];
        hard_src.extend([up_right; 4]);
        let w = Weld::new(&p, Some(&hard_src), 0.0);
        s.update(&w, &particles, &tris, &drawn);
        assert!(
            s.normals()[2].dot(up_left).abs() > 0.999,
            "{}",
            s.normals()[2]
        );
        assert!(
            s.normals()[4].dot(up_right).abs() > 0.999,
            "{}",
            s.normals()[4]
        );
    }

    #[test]
    fn tangents_from_source_frames_follow_the_deformation() {
        // One triangle in XZ with source tangent +X; rotate it 90° about Y: tangent → −Z.
        let rest = [Vec3::ZERO, Vec3::X, Vec3::new(0.0, 0.0, -1.0)];
        let tg = [Vec4::new(1.0, 0.0, 0.0, -1.0); 3];
        let tris = [[0u32, 1, 2]];
        let mut s = MeshShading::new(&tris, None, &rest, Some(&tg));
        assert!(s.has_tangents());
        let rot = glam::Quat::from_rotation_y(core::f32::consts::FRAC_PI_2);
        let moved: Vec<Vec4> = rest.iter().map(|p| (rot * *p).extend(1.0)).collect();
        s.update(&Weld::identity(3), &moved, &tris, &[0]);
        for t in s.tangents() {
            assert!((t.xyz() - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-5, "{t}");
            assert_eq!(t.w, -1.0, "handedness kept from the source");
        }
    }
}
