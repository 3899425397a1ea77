//! Shading data from the simulated positions (report §3.2): area-weighted normals and UV
//! tangents of every mesh vertex ([`MeshShading`], what the plugin writes into meshes and the
//! GPU's mesh kernel mirrors).
//!
//! Normals: each triangle adds its unnormalised normal `(x1 − x0)×(x2 − x0)` (length = twice
//! its area) to its three vertices, then each sum is normalised. Tangents: each triangle's
//! `T' = ((v2 − v0)·q0 + (v0 − v1)·q1)/((u1 − u0)(v2 − v0) − (v1 − v0)(u2 − u0))` with
//! `q0 = x1 − x0`, `q1 = x2 − x0`, summed per vertex, made orthogonal to the normal
//! (`T = T' − (T'·N)N`) and normalised; `w` is the handedness (`±1`) in Bevy's convention
//! (`bitangent = w·N×T`).

use glam::{Vec2, Vec3, Vec4, Vec4Swizzles};

use super::topology::Topology;
use super::weld::Weld;
use crate::solver::parallel::{Parallel, map_chunks};

/// Per-mesh-vertex normals and tangents from the simulated particles.
///
/// Built once per cloth from its [`Weld`], its mesh triangles and UVs (or, for a mesh with
/// tangents but no UVs, its rest shape and source tangents); [`Self::update`] then fills
/// [`Self::normals`] and [`Self::tangents`] for the mesh triangles still drawn.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshShading {
    /// UVs of each mesh triangle's corners (real or made from the source tangents).
    corner_uvs: Option<Vec<[Vec2; 3]>>,
    /// Handedness to use per mesh vertex when the UVs were made from source tangents.
    handedness: Option<Vec<f32>>,
    group_sum: Vec<Vec3>,
    tan: Vec<Vec3>,
    bit: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// Last update's normals, the fallback for vertices left in no triangle.
    old_normals: Vec<Vec3>,
    tangents: Vec<Vec4>,
    /// Each drawn triangle's unnormalised normal, and its `(T', B')` (zero where the scatter
    /// adds nothing).
    faces: Vec<Vec3>,
    frames: Vec<(Vec3, Vec3)>,
}

/// Which drawn triangles (positions in the drawn list) each normal group and each mesh vertex
/// sums, in the order [`MeshShading::update`] adds them (a triangle naming a group or vertex
/// twice is listed twice): compressed rows, offsets then entries.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct GatherLayout {
    group_offsets: Vec<u32>,
    group_entries: Vec<u32>,
    vertex_offsets: Vec<u32>,
    vertex_entries: Vec<u32>,
}

impl GatherLayout {
    /// The layout of `weld`'s sums over the `drawn` ones of `triangles`.
    pub(crate) fn new(weld: &Weld, triangles: &[[u32; 3]], drawn: &[u32]) -> Self {
        let (group, groups) = weld.normal_groups();
        let corners = || {
            drawn
                .iter()
                .enumerate()
                .flat_map(|(k, &t)| triangles[t as usize].map(|v| (k as u32, v)))
        };
        let (group_offsets, group_entries) =
            rows(groups, corners().map(|(k, v)| (group[v as usize], k)));
        let (vertex_offsets, vertex_entries) =
            rows(weld.vertex_count(), corners().map(|(k, v)| (v, k)));
        Self {
            group_offsets,
            group_entries,
            vertex_offsets,
            vertex_entries,
        }
    }
}

/// `(row, value)` pairs as compressed rows (a counting sort: each row keeps its values in
/// the order given).
fn rows(count: usize, pairs: impl Iterator<Item = (u32, u32)> + Clone) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; count + 1];
    for (r, _) in pairs.clone() {
        offsets[r as usize + 1] += 1;
    }
    for i in 0..count {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut entries = vec![0u32; offsets[count] as usize];
    for (r, value) in pairs {
        entries[fill[r as usize] as usize] = value;
        fill[r as usize] += 1;
    }
    (offsets, entries)
}

/// The sum of `values` at `entries` in order, from zero (what the scatter adds one by one).
fn sum_at(values: &[Vec3], entries: &[u32]) -> Vec3 {
    let mut s = Vec3::ZERO;
    for &k in entries {
        s += values[k as usize];
    }
    s
}

/// A triangle's unnormalised normal `(b − a) × (c − a)`; `None` where it is not finite (the
/// triangle then adds nothing to its vertices' normals).
fn face_normal([a, b, c]: [Vec3; 3]) -> Option<Vec3> {
    let face = (b - a).cross(c - a);
    face.is_finite().then_some(face)
}

/// A vertex's unit normal from its group's `sum`, or where that has no direction (a torn-off
/// vertex) its normal of the last update (`old`), or +Y.
fn vertex_normal(sum: Vec3, old: Option<&Vec3>) -> Vec3 {
    sum.try_normalize().unwrap_or_else(|| {
        old.copied()
            .filter(|v| v.is_finite() && *v != Vec3::ZERO)
            .unwrap_or(Vec3::Y)
    })
}

impl MeshShading {
    /// Shading for a mesh with these triangles (mesh indices) and, for tangents, `uvs` per
    /// mesh vertex; or, without UVs, `source_tangents` (xyz + handedness) with the mesh-space
    /// `rest` positions: tangents then follow the cloth's deformation from the source frame.
    /// Neither: no tangents.
    #[must_use]
    pub fn new(
        triangles: &[[u32; 3]],
        uvs: Option<&[Vec2]>,
        rest: &[Vec3],
        source_tangents: Option<&[Vec4]>,
    ) -> Self {
        let n = rest.len();
        let valid = |t: &[u32; 3]| t.iter().all(|&v| (v as usize) < n);
        let (corner_uvs, handedness) = match (uvs, source_tangents) {
            (Some(uv), _) if uv.len() == n => (
                Some(
                    triangles
                        .iter()
                        .map(|t| {
                            if valid(t) {
                                t.map(|v| uv[v as usize])
                            } else {
                                [Vec2::ZERO; 3]
                            }
                        })
                        .collect(),
                ),
                None,
            ),
            (_, Some(tg)) if tg.len() == n => (
                Some(
                    triangles
                        .iter()
                        .map(|t| {
                            if valid(t) {
                                frame_uvs(t.map(|v| rest[v as usize]), t.map(|v| tg[v as usize]))
                            } else {
                                [Vec2::ZERO; 3]
                            }
                        })
                        .collect(),
                ),
                Some(
                    tg.iter()
                        .map(|t| if t.w < 0.0 { -1.0 } else { 1.0 })
                        .collect(),
                ),
            ),
            _ => (None, None),
        };
        Self {
            corner_uvs,
            handedness,
            ..Default::default()
        }
    }

    /// Whether tangents are produced.
    #[must_use]
    pub fn has_tangents(&self) -> bool {
        self.corner_uvs.is_some()
    }

    /// The UVs of each mesh triangle's corners that tangents come from (real ones, or made
    /// from the source tangents); `None` without tangents.
    #[must_use]
    pub fn corner_uvs(&self) -> Option<&[[Vec2; 3]]> {
        self.corner_uvs.as_deref()
    }

    /// The handedness each mesh vertex's tangent keeps (from the source tangents), when the
    /// corner UVs were made from them; `None`: handedness follows the UVs.
    #[must_use]
    pub fn handedness(&self) -> Option<&[f32]> {
        self.handedness.as_deref()
    }

    /// The shading of `topology`'s own particles at `particles` (one mesh vertex per particle,
    /// tangents from the topology's UVs): for tests and tools that simulate a [`Topology`]
    /// without a user's mesh. The same code as a cloth's mesh is shaded with.
    #[must_use]
    pub fn of_particles(topology: &Topology, particles: &[Vec4]) -> Self {
        let triangles = topology.triangles();
        let mut shading = Self::new(triangles, topology.uvs(), topology.rest_positions(), None);
        let drawn: Vec<u32> = (0..triangles.len() as u32).collect();
        shading.update(
            &Weld::identity(particles.len()),
            particles,
            triangles,
            &drawn,
        );
        shading
    }

    /// Recomputes normals (and tangents) for every mesh vertex from `particles`, over the mesh
    /// triangles `drawn` (indices into the triangle list given to [`Self::new`]).
    pub fn update(
        &mut self,
        weld: &Weld,
        particles: &[Vec4],
        triangles: &[[u32; 3]],
        drawn: &[u32],
    ) {
        let n = weld.vertex_count();
        let (group, groups) = weld.normal_groups();
        let at = |v: u32| particles[weld.particle(v) as usize].xyz();
        self.group_sum.clear();
        self.group_sum.resize(groups, Vec3::ZERO);
        for &t in drawn {
            let tri = triangles[t as usize];
            if let Some(face) = face_normal(tri.map(at)) {
                for v in tri {
                    self.group_sum[group[v as usize] as usize] += face;
                }
            }
        }
        // Last frame's normals move to the scratch buffer (no allocation per frame).
        core::mem::swap(&mut self.normals, &mut self.old_normals);
        self.normals.clear();
        self.normals
            .extend((0..n).map(|i| {
                vertex_normal(self.group_sum[group[i] as usize], self.old_normals.get(i))
            }));
        let Some(corner_uvs) = &self.corner_uvs else {
            self.tangents.clear();
            return;
        };
        self.tan.clear();
        self.tan.resize(n, Vec3::ZERO);
        self.bit.clear();
        self.bit.resize(n, Vec3::ZERO);
        for &t in drawn {
            let tri = triangles[t as usize];
            if let Some((tp, bp)) = triangle_tangent(tri.map(at), corner_uvs[t as usize]) {
                for v in tri {
                    self.tan[v as usize] += tp;
                    self.bit[v as usize] += bp;
                }
            }
        }
        self.tangents.clear();
        for i in 0..n {
            let handedness = self.handedness.as_ref().map(|h| h[i]);
            self.tangents.push(finish_tangent(
                self.normals[i],
                self.tan[i],
                self.bit[i],
                handedness,
            ));
        }
    }

    /// [`Self::update`] with every sum gathered per group and per vertex instead of scattered
    /// per triangle, the triangles, groups and vertices in chunks on `par`: the same values bit
    /// for bit (each sum adds the same terms in the same order, from zero; a triangle the
    /// scatter skips adds zero, which changes no sum). `layout` is
    /// [`GatherLayout::new`]`(weld, triangles, drawn)`.
    pub(crate) fn update_gathered(
        &mut self,
        weld: &Weld,
        particles: &[Vec4],
        triangles: &[[u32; 3]],
        drawn: &[u32],
        layout: &GatherLayout,
        par: &impl Parallel,
    ) {
        let n = weld.vertex_count();
        let (group, groups) = weld.normal_groups();
        let at = |v: u32| particles[weld.particle(v) as usize].xyz();
        map_chunks(par, &mut self.faces, drawn.len(), |k| {
            face_normal(triangles[drawn[k] as usize].map(at)).unwrap_or(Vec3::ZERO)
        });
        let faces = &self.faces;
        map_chunks(par, &mut self.group_sum, groups, |g| {
            let r = layout.group_offsets[g] as usize..layout.group_offsets[g + 1] as usize;
            sum_at(faces, &layout.group_entries[r])
        });
        core::mem::swap(&mut self.normals, &mut self.old_normals);
        let (sums, old) = (&self.group_sum, &self.old_normals);
        map_chunks(par, &mut self.normals, n, |i| {
            vertex_normal(sums[group[i] as usize], old.get(i))
        });
        let Some(corner_uvs) = &self.corner_uvs else {
            self.tangents.clear();
            return;
        };
        map_chunks(par, &mut self.frames, drawn.len(), |k| {
            let t = drawn[k] as usize;
            triangle_tangent(triangles[t].map(at), corner_uvs[t])
                .unwrap_or((Vec3::ZERO, Vec3::ZERO))
        });
        let (frames, normals, handedness) = (&self.frames, &self.normals, &self.handedness);
        map_chunks(par, &mut self.tangents, n, |i| {
            let r = layout.vertex_offsets[i] as usize..layout.vertex_offsets[i + 1] as usize;
            let (mut tan, mut bit) = (Vec3::ZERO, Vec3::ZERO);
            for &k in &layout.vertex_entries[r] {
                let (tp, bp) = frames[k as usize];
                tan += tp;
                bit += bp;
            }
            finish_tangent(normals[i], tan, bit, handedness.as_ref().map(|h| h[i]))
        });
    }

    /// Unit normal of every mesh vertex (world space) as of the last [`Self::update`].
    #[must_use]
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// Unit tangent with handedness of every mesh vertex as of the last [`Self::update`];
    /// empty when the mesh has neither UVs nor tangents.
    #[must_use]
    pub fn tangents(&self) -> &[Vec4] {
        &self.tangents
    }
}

/// A triangle's unnormalised tangent and bitangent `(T', B')` from its corners and their UVs
/// (the formula in the module docs); `None` where the UVs are degenerate or the result is not
/// finite.
pub(crate) fn triangle_tangent(p: [Vec3; 3], uv: [Vec2; 3]) -> Option<(Vec3, Vec3)> {
    let [uv0, uv1, uv2] = uv;
    let (q0, q1) = (p[1] - p[0], p[2] - p[0]);
    let det = (uv1.x - uv0.x) * (uv2.y - uv0.y) - (uv1.y - uv0.y) * (uv2.x - uv0.x);
    if det.abs() < 1e-20 {
        return None;
    }
    let r = 1.0 / det;
    let tp = ((uv2.y - uv0.y) * q0 + (uv0.y - uv1.y) * q1) * r;
    let bp = ((uv0.x - uv2.x) * q0 + (uv1.x - uv0.x) * q1) * r;
    (tp.is_finite() && bp.is_finite()).then_some((tp, bp))
}

/// A vertex's unit tangent with handedness from its unit `normal` and its summed `tan` and
/// `bit`: `tan` made orthogonal to the normal (any orthogonal unit vector if nothing is
/// left), `w` = `handedness` if given, else the sign that makes `w·N×T` follow `bit`.
pub(crate) fn finish_tangent(normal: Vec3, tan: Vec3, bit: Vec3, handedness: Option<f32>) -> Vec4 {
    let t = (tan - normal * normal.dot(tan))
        .try_normalize()
        .unwrap_or_else(|| normal.any_orthonormal_vector());
    let w = match handedness {
        Some(h) => h,
        None if normal.cross(t).dot(bit) < 0.0 => -1.0,
        None => 1.0,
    };
    t.extend(w)
}

/// Texture-like coordinates of a rest triangle in the frame of its source tangents: `u` along
/// their mean (projected into the triangle's plane), `v` along `n × u`. The tangent-from-UV
/// formula on the deformed triangle then gives the deformed image of that tangent.
fn frame_uvs(p: [Vec3; 3], tangents: [Vec4; 3]) -> [Vec2; 3] {
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
    let mean: Vec3 = tangents.iter().map(|t| t.xyz()).sum();
    let u = (mean - n * n.dot(mean))
        .try_normalize()
        .unwrap_or_else(|| (p[1] - p[0]).normalize_or_zero());
    let v = n.cross(u);
    p.map(|q| Vec2::new((q - p[0]).dot(u), (q - p[0]).dot(v)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::{Grid, MeshAttributes, MeshBinding};

    /// A 4 × 3 grid's binding (no welding), its particles, its UVs.
    fn grid(uvs: impl Fn(Vec2) -> Vec2) -> (MeshBinding, Vec<Vec4>) {
        let g = Grid::new(4, 3, 2.0, 1.0);
        let uv: Vec<Vec2> = g.uvs().into_iter().map(uvs).collect();
        let attributes = MeshAttributes {
            uvs: Some(&uv),
            ..Default::default()
        };
        let binding = MeshBinding::new(&g.positions(), attributes, &g.indices(), 0.0).unwrap();
        let p = g.positions().iter().map(|p| p.extend(1.0)).collect();
        (binding, p)
    }

    #[test]
    fn gathered_sums_give_the_scattered_shading_bit_for_bit() {
        // A creased sheet stored as a triangle soup (every corner its own vertex, face
        // normals): welded into particles, with normal groups split along the crease; more
        // vertices than a chunk, UVs, a few broken particles, and the drawn set changed twice
        // (as tears do), on one thread and on four.
        let g = Grid::new(71, 64, 2.0, 1.5);
        let flat = g.positions();
        let mid = flat.iter().map(|p| p.x).sum::<f32>() / flat.len() as f32;
        let bent: Vec<Vec3> = flat
            .iter()
            .map(|p| Vec3::new(p.x, (p.x - mid).abs() * 2.5, p.z))
            .collect();
        let grid_uvs = g.uvs();
        let idx = g.indices();
        let positions: Vec<Vec3> = idx.iter().map(|&i| bent[i as usize]).collect();
        let uvs: Vec<Vec2> = idx.iter().map(|&i| grid_uvs[i as usize]).collect();
        let normals: Vec<Vec3> = positions
            .chunks(3)
            .flat_map(|t| [(t[1] - t[0]).cross(t[2] - t[0]).normalize(); 3])
            .collect();
        let soup: Vec<u32> = (0..positions.len() as u32).collect();
        let attributes = MeshAttributes {
            normals: Some(&normals),
            uvs: Some(&uvs),
            ..Default::default()
        };
        let binding = MeshBinding::new(&positions, attributes, &soup, 1e-6).unwrap();
        let weld = binding.weld();
        let (_, groups) = weld.normal_groups();
        assert!(weld.particles().iter().max().unwrap() + 1 < positions.len() as u32 / 4);
        assert!(
            groups > weld.gather(&positions).len(),
            "the crease splits groups: {groups} groups, {} particles, {} vertices",
            weld.gather(&positions).len(),
            positions.len()
        );
        assert!(positions.len() > 2 * crate::solver::parallel::CHUNK);
        let triangles: Vec<[u32; 3]> = soup.chunks(3).map(|t| [t[0], t[1], t[2]]).collect();
        let particles = weld.gather(&positions);
        let workers = crate::solver::Workers::new(3);
        for threads in [1, 4] {
            let mut scattered = MeshShading::new(&triangles, Some(&uvs), &positions, None);
            let mut gathered = scattered.clone();
            let mut seed = 0x9e37_79b9_u32;
            let mut drawn: Vec<u32> = (0..triangles.len() as u32).collect();
            let mut layout = GatherLayout::new(weld, &triangles, &drawn);
            for frame in 0..6 {
                if frame == 2 || frame == 4 {
                    // A tear: some triangles are no longer drawn.
                    drawn.retain(|&t| (t * 7 + frame) % 11 != 0);
                    layout = GatherLayout::new(weld, &triangles, &drawn);
                }
                let p: Vec<Vec4> = particles
                    .iter()
                    .enumerate()
                    .map(|(i, q)| {
                        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                        let jitter = (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
                        match (i + frame as usize) % 997 {
                            0 => Vec4::new(f32::NAN, 0.0, 0.0, 1.0),
                            1 => Vec4::new(3e30, -3e30, 1.0, 1.0),
                            _ => (*q + Vec3::splat(jitter * 0.01 * frame as f32)).extend(1.0),
                        }
                    })
                    .collect();
                scattered.update(weld, &p, &triangles, &drawn);
                if threads == 1 {
                    let serial = crate::solver::Serial;
                    gathered.update_gathered(weld, &p, &triangles, &drawn, &layout, &serial);
                } else {
                    gathered.update_gathered(weld, &p, &triangles, &drawn, &layout, &workers);
                }
                let bits3 = |v: &[Vec3]| {
                    v.iter()
                        .map(|v| v.to_array().map(f32::to_bits))
                        .collect::<Vec<_>>()
                };
                let bits4 = |v: &[Vec4]| {
                    v.iter()
                        .map(|v| v.to_array().map(f32::to_bits))
                        .collect::<Vec<_>>()
                };
                assert_eq!(scattered.normals().len(), positions.len());
                assert!(
                    bits3(scattered.normals()) == bits3(gathered.normals()),
                    "normals differ at frame {frame} on {threads} threads"
                );
                assert_eq!(scattered.tangents().len(), positions.len());
                assert!(
                    bits4(scattered.tangents()) == bits4(gathered.tangents()),
                    "tangents differ at frame {frame} on {threads} threads"
                );
            }
        }
    }

    #[test]
    fn flat_grid_normals_and_tangents() {
        let (mut b, p) = grid(|uv| uv);
        b.update_shading(&p);
        let s = b.shading();
        assert!(s.normals().iter().all(|v| (*v - Vec3::Y).length() < 1e-6));
        // u grows with +x, v grows with −z: T = +X, bitangent −Z = +Y×X, so w = +1.
        assert!(
            s.tangents()
                .iter()
                .all(|v| (*v - Vec4::new(1.0, 0.0, 0.0, 1.0)).length() < 1e-6)
        );
    }

    #[test]
    fn normals_are_area_weighted() {
        // A big triangle in the XY plane and a small one in the XZ plane share vertex 0.
        let x = [
            Vec3::ZERO,
            Vec3::X * 10.0,
            Vec3::Y * 10.0,
            Vec3::X,
            -Vec3::Z,
        ];
        let mut b =
            MeshBinding::new(&x, MeshAttributes::default(), &[0, 1, 2, 0, 3, 4], 0.0).unwrap();
        b.update_shading(&x.map(|v| v.extend(1.0)));
        let n = b.shading().normals();
        // Face normals 100·Z and 1·Y (twice the areas): the sum points mostly along Z.
        let expect = Vec3::new(0.0, 1.0, 100.0).normalize();
        assert!((n[0] - expect).length() < 1e-6, "{}", n[0]);
        assert_eq!(n[1], Vec3::Z);
    }

    #[test]
    fn mirrored_uvs_flip_handedness_and_degenerate_inputs_stay_finite() {
        let (mut b, p) = grid(|uv| Vec2::new(uv.x, 1.0 - uv.y));
        b.update_shading(&p);
        assert!(b.shading().tangents().iter().all(|v| v.w == -1.0));
        // All vertices coincide: nothing to go on, but no NaN.
        b.update_shading(&vec![Vec4::new(1.0, 2.0, 3.0, 1.0); p.len()]);
        let s = b.shading();
        assert!(
            s.normals()
                .iter()
                .all(|v| v.is_finite() && (v.length() - 1.0).abs() < 1e-5)
        );
        assert!(s.tangents().iter().all(|v| v.is_finite()));
    }
}
