//! Signed distance fields baked from triangle meshes: the report's voxel "correction vector"
//! grid, done properly.
//!
//! [`SdfGrid::from_triangles`] samples the signed distance to a closed triangle mesh on a
//! regular grid (after Bridson's `makelevelset3`): exact point–triangle distances in a band
//! around each triangle, then fast sweeping to carry the nearest triangle to every other grid
//! point, then the sign by ray parity along +x through each grid row. Lookups interpolate
//! trilinearly; the gradient of the trilinear interpolant gives the push-out direction.
//! Baking is `O(cells + triangles × band cells)`, not `O(cells × triangles)`.
//!
//! An open mesh (some edge, after welding, belongs to one triangle or to more than two) is
//! signed by the side its triangles face instead (see [`SdfGrid`]).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

use glam::{UVec3, Vec3};

use crate::solver::mesh::Weld;
use crate::solver::parallel::{Parallel, Serial};

/// Why a mesh cannot be baked.
#[derive(Clone, Debug, PartialEq)]
pub enum SdfError {
    /// No triangles, or the index count is not a multiple of 3.
    NoTriangles,
    /// An index names a vertex that does not exist.
    IndexOutOfRange(u32),
    /// A position is NaN or infinite.
    NonFinitePosition(usize),
    /// The cell size is not finite and positive, or the grid would be too large.
    BadResolution(String),
}

impl core::fmt::Display for SdfError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SdfError::NoTriangles => write!(f, "the mesh has no triangles"),
            SdfError::IndexOutOfRange(i) => write!(f, "index {i} is out of range"),
            SdfError::NonFinitePosition(v) => write!(f, "vertex {v} is NaN or infinite"),
            SdfError::BadResolution(r) => write!(f, "bad SDF resolution: {r}"),
        }
    }
}

impl std::error::Error for SdfError {}

/// Signed distances sampled on a regular grid (negative inside).
///
/// A closed mesh (every edge shared by two triangles, once vertices that share a place are
/// welded: split along UV seams and hard edges, a closed mesh is still closed) is signed by
/// ray parity, whatever its winding. An *open* mesh (a terrain, a floor, a table top modelled
/// as one sheet, a statue without a bottom) has no inside for a ray to count: it is signed by
/// the side its triangles face. A sample is inside when it lies behind the surface by at most
/// three cells, seen from its nearest point there along that point's angle-weighted
/// pseudo-normal (Bærentzen and Aanæs, 2005), and that point is not on the mesh's rim. So
/// cloth is kept on the front of a terrain or a floor, a vertex that got a little behind is
/// pushed back to the front, and a cloth hanging over the rim of a sheet hangs down beside
/// it. [`SdfGrid::is_open`] says which way a mesh was baked.
#[derive(Clone, Debug, PartialEq)]
pub struct SdfGrid {
    origin: Vec3,
    cell: f32,
    dims: UVec3,
    phi: Vec<f32>,
    open: bool,
}

/// Largest grid accepted, in cells (about 64 MB of distances).
const MAX_CELLS: u64 = 16 << 20;

/// How deep behind an open mesh's surface (in cells) a sample counts as inside; deeper ones
/// are outside (the surface is a slab this thick behind its front side).
const OPEN_DEPTH: f32 = 3.0;

/// Vertices closer than this fraction of the mesh's size are one place when the bake looks
/// for the mesh's rim (split along UV seams and hard edges, a closed mesh is still closed).
const WELD_FRACTION: f32 = 1e-5;

/// Samples per tile of the fast sweep, along x, y and z ([`SdfGrid::sweep`]): rows of 16
/// along x, where samples lie next to each other in memory.
const TILE: [u32; 3] = [16, 8, 8];

/// The distances and nearest triangles of the samples while the sweeps run: written by the
/// tile that owns a sample, read by the tiles downwind of it in later wavefronts.
struct Field {
    phi: Vec<AtomicU32>,
    closest: Vec<AtomicU32>,
}

impl SdfGrid {
    /// Bakes the mesh on a grid whose longest side has `resolution` cells (plus a border of
    /// three cells on every side).
    ///
    /// # Errors
    /// [`SdfError`] for an empty or invalid mesh or a resolution below 4.
    pub fn from_mesh(
        positions: &[Vec3],
        indices: &[u32],
        resolution: u32,
    ) -> Result<Self, SdfError> {
        Self::from_mesh_on(positions, indices, resolution, &Serial)
    }

    /// [`SdfGrid::from_mesh`] on `par`'s threads (the plugin bakes on
    /// [`ClothWorkers`](crate::cloth::ClothWorkers)): the same field, bit for bit, in about
    /// `1 / threads` of the time.
    ///
    /// # Errors
    /// As [`SdfGrid::from_mesh`].
    pub fn from_mesh_on(
        positions: &[Vec3],
        indices: &[u32],
        resolution: u32,
        par: &impl Parallel,
    ) -> Result<Self, SdfError> {
        if resolution < 4 {
            return Err(SdfError::BadResolution(format!(
                "{resolution} cells; at least 4 are needed"
            )));
        }
        let (lo, hi) = bounds(positions, indices)?;
        let cell = (hi - lo).max_element().max(1e-6) / resolution as f32;
        Self::from_triangles_on(positions, indices, cell, 3, par)
    }

    /// Bakes the mesh with cells of `cell` metres and `padding` cells of margin around it.
    ///
    /// A closed mesh is signed by ray parity (its winding does not matter); an open one by the
    /// side its triangles face, which should then be consistent (see [`SdfGrid`]).
    ///
    /// # Errors
    /// [`SdfError`] for an empty or invalid mesh, a bad cell size or a grid over 16 M cells.
    pub fn from_triangles(
        positions: &[Vec3],
        indices: &[u32],
        cell: f32,
        padding: u32,
    ) -> Result<Self, SdfError> {
        Self::from_triangles_on(positions, indices, cell, padding, &Serial)
    }

    /// [`SdfGrid::from_triangles`] on `par`'s threads: the same field, bit for bit.
    ///
    /// # Errors
    /// As [`SdfGrid::from_triangles`].
    pub fn from_triangles_on(
        positions: &[Vec3],
        indices: &[u32],
        cell: f32,
        padding: u32,
        par: &impl Parallel,
    ) -> Result<Self, SdfError> {
        Self::bake_in_tiles(positions, indices, cell, padding, TILE, par)
    }

    /// [`SdfGrid::from_triangles_on`], sweeping in tiles of `tile` samples.
    fn bake_in_tiles(
        positions: &[Vec3],
        indices: &[u32],
        cell: f32,
        padding: u32,
        tile: [u32; 3],
        par: &impl Parallel,
    ) -> Result<Self, SdfError> {
        let (lo, hi) = bounds(positions, indices)?;
        if !(cell.is_finite() && cell > 0.0) {
            return Err(SdfError::BadResolution(format!("cell size {cell}")));
        }
        let pad = padding.max(1) as f32 * cell;
        let origin = lo - Vec3::splat(pad);
        let size = hi - lo + Vec3::splat(2.0 * pad);
        let n = (size / cell).ceil() + Vec3::ONE;
        let count = n.x as u64 * n.y as u64 * n.z as u64;
        if !n.is_finite() || count > MAX_CELLS {
            return Err(SdfError::BadResolution(format!(
                "{} × {} × {} samples is over the limit of {MAX_CELLS}",
                n.x, n.y, n.z
            )));
        }
        let dims = n.as_uvec3();
        let mut grid = Self {
            origin,
            cell,
            dims,
            phi: Vec::new(),
            open: false,
        };
        let tris: Vec<[Vec3; 3]> = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]].map(|i| positions[i as usize]))
            .collect();
        let open = OpenSurface::of(positions, indices, (hi - lo).max_element());
        grid.bake(&tris, open.as_ref(), tile, par);
        Ok(grid)
    }

    /// Whether the mesh was baked as an open surface (signed by the side its triangles face)
    /// rather than a closed one (signed by ray parity); see [`SdfGrid`].
    #[must_use]
    pub fn is_open(&self) -> bool {
        self.open
    }

    fn index(&self, i: u32, j: u32, k: u32) -> usize {
        (i + self.dims.x * (j + self.dims.y * k)) as usize
    }

    fn point(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.origin + Vec3::new(i as f32, j as f32, k as f32) * self.cell
    }

    /// Bakes the field, sweeping in tiles of `tile` samples on `par`'s threads.
    fn bake(
        &mut self,
        tris: &[[Vec3; 3]],
        open: Option<&OpenSurface>,
        tile: [u32; 3],
        par: &impl Parallel,
    ) {
        let [nx, ny, nz] = self.dims.to_array();
        let total = (nx * ny * nz) as usize;
        let far = (self.dims.as_vec3() * self.cell).length();
        let mut phi = vec![far; total];
        let mut closest = vec![u32::MAX; total];
        // 1. Exact distances in a band of one cell around each triangle.
        let band = 1.0;
        for (t, tri) in tris.iter().enumerate() {
            let lo = tri[0].min(tri[1]).min(tri[2]);
            let hi = tri[0].max(tri[1]).max(tri[2]);
            let (i0, i1) = self.cell_range(lo, hi, band);
            for k in i0.z..=i1.z {
                for j in i0.y..=i1.y {
                    for i in i0.x..=i1.x {
                        let idx = self.index(i, j, k);
                        let d = point_triangle_distance(self.point(i, j, k), tri);
                        if d < phi[idx] {
                            phi[idx] = d;
                            closest[idx] = t as u32;
                        }
                    }
                }
            }
        }
        // 2. Fast sweeping: carry the nearest triangle to the rest of the grid. Each triangle's
        // bounding sphere (centroid, farthest corner) bounds its distance from below, so a
        // neighbour's triangle that cannot come nearer is not measured (the same field).
        let spheres: Vec<(Vec3, f32)> = tris
            .iter()
            .map(|t| {
                let c = (t[0] + t[1] + t[2]) / 3.0;
                (c, t.iter().map(|v| v.distance(c)).fold(0.0, f32::max))
            })
            .collect();
        // (In place: the same sizes, so the vectors keep their allocations.)
        let field = Field {
            phi: phi
                .into_iter()
                .map(|d| AtomicU32::new(d.to_bits()))
                .collect(),
            closest: closest.into_iter().map(AtomicU32::new).collect(),
        };
        for _ in 0..2 {
            for dk in [1i32, -1] {
                for dj in [1i32, -1] {
                    for di in [1i32, -1] {
                        self.sweep(tris, &spheres, &field, [di, dj, dk], tile, par);
                    }
                }
            }
        }
        let mut phi: Vec<f32> = field
            .phi
            .into_iter()
            .map(|d| f32::from_bits(d.into_inner()))
            .collect();
        let closest: Vec<u32> = field
            .closest
            .into_iter()
            .map(AtomicU32::into_inner)
            .collect();
        // 3. Sign: an open surface by the side it faces, a closed mesh by ray parity along +x.
        if let Some(open) = open {
            let depth = OPEN_DEPTH * self.cell;
            for k in 0..nz {
                for j in 0..ny {
                    for i in 0..nx {
                        let idx = self.index(i, j, k);
                        let t = closest[idx];
                        if t != u32::MAX
                            && phi[idx] <= depth
                            && open.behind(self.point(i, j, k), t as usize, &tris[t as usize])
                        {
                            phi[idx] = -phi[idx];
                        }
                    }
                }
            }
            self.open = true;
            self.phi = phi;
            return;
        }
        let mut crossings = vec![0u32; total];
        for tri in tris {
            self.count_crossings(tri, &mut crossings);
        }
        for k in 0..nz {
            for j in 0..ny {
                let mut count = 0u32;
                for i in 0..nx {
                    let idx = self.index(i, j, k);
                    count += crossings[idx];
                    if count % 2 == 1 {
                        phi[idx] = -phi[idx];
                    }
                }
            }
        }
        self.phi = phi;
    }

    fn cell_range(&self, lo: Vec3, hi: Vec3, band: f32) -> (UVec3, UVec3) {
        let max = (self.dims - UVec3::ONE).as_vec3();
        let a = ((lo - self.origin) / self.cell - Vec3::splat(band))
            .floor()
            .clamp(Vec3::ZERO, max);
        let b = ((hi - self.origin) / self.cell + Vec3::splat(band))
            .ceil()
            .clamp(Vec3::ZERO, max);
        (a.as_uvec3(), b.as_uvec3())
    }

    /// One fast-sweeping pass in direction `[di, dj, dk]`: every sample takes the nearest of
    /// its own triangle and those of its seven upwind neighbours (the ones a step against the
    /// direction away). The grid is cut into tiles of `tile` samples; a tile's samples run
    /// in the pass's order, and tiles run in parallel in diagonal wavefronts (the tiles whose
    /// coordinates, counted along the direction, add up to the same number): a tile's
    /// upwind neighbours are all in earlier wavefronts, so every sample reads exactly what the
    /// whole grid swept row by row would give it, and the field is the same bit for bit on
    /// any number of threads.
    fn sweep(
        &self,
        tris: &[[Vec3; 3]],
        spheres: &[(Vec3, f32)],
        field: &Field,
        dir: [i32; 3],
        tile: [u32; 3],
        par: &impl Parallel,
    ) {
        let n = self.dims.to_array();
        let tiles: [u32; 3] = core::array::from_fn(|a| n[a].div_ceil(tile[a]));
        // A tile's place along the direction.
        let along = |a: usize, t: u32| if dir[a] > 0 { t } else { tiles[a] - 1 - t };
        let mut front = Vec::new();
        for wave in 0..tiles.iter().sum::<u32>() - 2 {
            front.clear();
            for tz in 0..tiles[2] {
                for ty in 0..tiles[1] {
                    let rest = wave as i64 - i64::from(along(2, tz)) - i64::from(along(1, ty));
                    if (0..i64::from(tiles[0])).contains(&rest) {
                        let ax = rest as u32;
                        let tx = if dir[0] > 0 { ax } else { tiles[0] - 1 - ax };
                        front.push([tx, ty, tz]);
                    }
                }
            }
            par.for_each_mut(&mut front, |at| {
                self.sweep_tile(tris, spheres, field, dir, (*at, tile));
            });
        }
    }

    /// [`SdfGrid::sweep`] over one tile's samples (the tile at `at`, of `size` samples).
    fn sweep_tile(
        &self,
        tris: &[[Vec3; 3]],
        spheres: &[(Vec3, f32)],
        field: &Field,
        [di, dj, dk]: [i32; 3],
        (at, size): ([u32; 3], [u32; 3]),
    ) {
        // Slack on the bound, far above its rounding: a triangle is skipped only when it is
        // surely farther than the nearest one found.
        let slack = 1e-3 * self.cell;
        let n = self.dims.as_ivec3().to_array();
        // The tile's samples along axis `a` in the pass's order, without the first sample of
        // the grid (it has no upwind neighbour that way).
        let range = |a: usize, d: i32| -> Vec<i32> {
            let lo = (at[a] * size[a]) as i32;
            let hi = (lo + size[a] as i32).min(n[a]);
            if d > 0 {
                (lo.max(1)..hi).collect()
            } else {
                (lo..hi.min(n[a] - 1)).rev().collect()
            }
        };
        let (ri, rj, rk) = (range(0, di), range(1, dj), range(2, dk));
        let neighbours = [
            (di, 0, 0),
            (0, dj, 0),
            (di, dj, 0),
            (0, 0, dk),
            (di, 0, dk),
            (0, dj, dk),
            (di, dj, dk),
        ];
        let (phi, closest) = (&field.phi, &field.closest);
        for &k in &rk {
            for &j in &rj {
                for &i in &ri {
                    let idx = self.index(i as u32, j as u32, k as u32);
                    let p = self.point(i as u32, j as u32, k as u32);
                    let mut best = f32::from_bits(phi[idx].load(Relaxed));
                    let mut best_t = closest[idx].load(Relaxed);
                    let mut changed = false;
                    // The triangles already measured here (neighbours often share one).
                    let mut seen = [u32::MAX; 7];
                    for (m, (a, b, c)) in neighbours.into_iter().enumerate() {
                        let n = self.index((i - a) as u32, (j - b) as u32, (k - c) as u32);
                        let t = closest[n].load(Relaxed);
                        if t == u32::MAX || t == best_t || seen[..m].contains(&t) {
                            continue;
                        }
                        seen[m] = t;
                        let (centre, radius) = spheres[t as usize];
                        if p.distance(centre) - radius > best + slack {
                            continue;
                        }
                        let d = point_triangle_distance(p, &tris[t as usize]);
                        if d < best {
                            best = d;
                            best_t = t;
                            changed = true;
                        }
                    }
                    if changed {
                        phi[idx].store(best.to_bits(), Relaxed);
                        closest[idx].store(best_t, Relaxed);
                    }
                }
            }
        }
    }

    /// For each grid row (j, k) the triangle's projection covers, counts a crossing in the first
    /// cell at or after the intersection along +x.
    fn count_crossings(&self, tri: &[Vec3; 3], crossings: &mut [u32]) {
        let to_grid = |p: Vec3| (p - self.origin) / self.cell;
        let [a, b, c] = tri.map(to_grid);
        let (j0, j1) = (
            a.y.min(b.y).min(c.y).ceil().max(0.0),
            a.y.max(b.y).max(c.y).floor().min((self.dims.y - 1) as f32),
        );
        let (k0, k1) = (
            a.z.min(b.z).min(c.z).ceil().max(0.0),
            a.z.max(b.z).max(c.z).floor().min((self.dims.z - 1) as f32),
        );
        if j0 > j1 || k0 > k1 {
            return;
        }
        for k in k0 as u32..=k1 as u32 {
            for j in j0 as u32..=j1 as u32 {
                let (y, z) = (f64::from(j), f64::from(k));
                let Some((wa, wb, wc)) = point_in_triangle_2d(
                    (y, z),
                    (f64::from(a.y), f64::from(a.z)),
                    (f64::from(b.y), f64::from(b.z)),
                    (f64::from(c.y), f64::from(c.z)),
                ) else {
                    continue;
                };
                let x = wa * f64::from(a.x) + wb * f64::from(b.x) + wc * f64::from(c.x);
                let i = x.ceil().max(0.0);
                if i < f64::from(self.dims.x) {
                    crossings[self.index(i as u32, j, k)] += 1;
                }
            }
        }
    }

    /// Signed distance at a point (trilinear) and the unit gradient (outward normal). Outside
    /// the grid (which has a margin of a few cells around the mesh), the distance is measured
    /// from the surface point nearest the closest border sample.
    #[must_use]
    pub fn sample(&self, p: Vec3) -> (f32, Vec3) {
        let max = (self.dims - UVec3::ONE).as_vec3();
        let g = (p - self.origin) / self.cell;
        let gc = g.clamp(Vec3::ZERO, max);
        let outside = (g - gc) * self.cell;
        let base = gc.floor().min(max - Vec3::ONE).max(Vec3::ZERO);
        let f = gc - base;
        let (i, j, k) = (base.x as u32, base.y as u32, base.z as u32);
        let v = |a: u32, b: u32, c: u32| self.phi[self.index(i + a, j + b, k + c)];
        let (c000, c100, c010, c110) = (v(0, 0, 0), v(1, 0, 0), v(0, 1, 0), v(1, 1, 0));
        let (c001, c101, c011, c111) = (v(0, 0, 1), v(1, 0, 1), v(0, 1, 1), v(1, 1, 1));
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(c000, c100, f.x);
        let c10 = lerp(c010, c110, f.x);
        let c01 = lerp(c001, c101, f.x);
        let c11 = lerp(c011, c111, f.x);
        let c0 = lerp(c00, c10, f.y);
        let c1 = lerp(c01, c11, f.y);
        let d = lerp(c0, c1, f.z);
        // Gradient of the trilinear interpolant.
        let gx = lerp(
            lerp(c100 - c000, c110 - c010, f.y),
            lerp(c101 - c001, c111 - c011, f.y),
            f.z,
        );
        let gy = lerp(
            lerp(c010 - c000, c110 - c100, f.x),
            lerp(c011 - c001, c111 - c101, f.x),
            f.z,
        );
        let gz = lerp(
            lerp(c001 - c000, c101 - c100, f.x),
            lerp(c011 - c010, c111 - c110, f.x),
            f.y,
        );
        let grad = Vec3::new(gx, gy, gz).try_normalize();
        if outside.length_squared() > 0.0 {
            // Outside the grid: step from the border sample to its nearest surface point and
            // measure from there.
            let border = self.origin + gc * self.cell;
            let surface = border - grad.unwrap_or(Vec3::ZERO) * d;
            let to_p = p - surface;
            let len = to_p.length();
            return (len, to_p.try_normalize().unwrap_or(Vec3::Y));
        }
        (d, grad.unwrap_or(Vec3::Y))
    }

    /// Grid origin (position of sample (0, 0, 0)).
    #[must_use]
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// Cell size in metres.
    #[must_use]
    pub fn cell(&self) -> f32 {
        self.cell
    }

    /// Samples along x, y, z.
    #[must_use]
    pub fn dims(&self) -> UVec3 {
        self.dims
    }

    /// Distances, x fastest, then y, then z.
    #[must_use]
    pub fn values(&self) -> &[f32] {
        &self.phi
    }

    /// Radius around the local origin that contains the whole grid.
    #[must_use]
    pub fn bounding_radius(&self) -> f32 {
        let far = self.origin + (self.dims - UVec3::ONE).as_vec3() * self.cell;
        self.origin.length().max(far.length()).max(
            Vec3::new(self.origin.x, far.y, far.z)
                .length()
                .max(Vec3::new(far.x, self.origin.y, self.origin.z).length()),
        ) + self.cell * (self.dims.as_vec3().length())
    }
}

/// The rim and pseudo-normals of an open mesh (see the module docs).
struct OpenSurface {
    /// Per triangle, its corners' places (vertices welded by position).
    corners: Vec<[u32; 3]>,
    /// Per triangle, its unit normal (zero when degenerate).
    normals: Vec<Vec3>,
    /// Per place, its angle-weighted normal (not normalised: only signs are taken).
    place_normals: Vec<Vec3>,
    /// Per place, whether it lies on the rim.
    rim: Vec<bool>,
    /// Per edge between two places (lower first): how many triangles share it and the sum of
    /// their normals.
    edges: HashMap<(u32, u32), (u32, Vec3)>,
}

impl OpenSurface {
    /// The mesh's rim and normals; `None` when it is closed (every edge between two places
    /// has exactly two triangles). `size` is its longest side.
    fn of(positions: &[Vec3], indices: &[u32], size: f32) -> Option<Self> {
        let weld = Weld::new(positions, None, size * WELD_FRACTION);
        let places = weld.particle_count();
        let mut corners = Vec::with_capacity(indices.len() / 3);
        let mut normals = Vec::with_capacity(indices.len() / 3);
        let mut place_normals = vec![Vec3::ZERO; places];
        let mut edges: HashMap<(u32, u32), (u32, Vec3)> = HashMap::new();
        for t in indices.chunks_exact(3) {
            let c = [t[0], t[1], t[2]].map(|i| weld.particle(i));
            let p = [t[0], t[1], t[2]].map(|i| positions[i as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            corners.push(c);
            normals.push(n);
            if c[0] == c[1] || c[1] == c[2] || c[0] == c[2] || n == Vec3::ZERO {
                continue; // no area: neither a side nor an edge of the surface
            }
            for k in 0..3 {
                let (a, b, o) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
                let angle = (b - a).angle_between(o - a);
                if angle.is_finite() {
                    place_normals[c[k] as usize] += angle * n;
                }
                let (u, v) = (c[k], c[(k + 1) % 3]);
                let e = edges.entry((u.min(v), u.max(v))).or_insert((0, Vec3::ZERO));
                e.0 += 1;
                e.1 += n;
            }
        }
        if edges.values().all(|&(count, _)| count == 2) {
            return None;
        }
        let mut rim = vec![false; places];
        for (&(u, v), &(count, _)) in &edges {
            if count != 2 {
                rim[u as usize] = true;
                rim[v as usize] = true;
            }
        }
        Some(Self {
            corners,
            normals,
            place_normals,
            rim,
            edges,
        })
    }

    /// Whether `p` lies behind triangle `t` (corners `tri`) as seen from its nearest point
    /// there, by the pseudo-normal of the face, edge or corner that point is on; never when
    /// that point is on the rim.
    fn behind(&self, p: Vec3, t: usize, tri: &[Vec3; 3]) -> bool {
        let c = self.corners[t];
        let (q, feature) = closest_feature_on_triangle(p, tri);
        let normal = match feature {
            Feature::Face => self.normals[t],
            Feature::Edge(k) => {
                let (u, v) = (c[k], c[(k + 1) % 3]);
                match self.edges.get(&(u.min(v), u.max(v))) {
                    Some(&(2, sum)) => sum,
                    _ => return false,
                }
            }
            Feature::Corner(k) => {
                if self.rim[c[k] as usize] {
                    return false;
                }
                self.place_normals[c[k] as usize]
            }
        };
        (p - q).dot(normal) < 0.0
    }
}

/// Which part of a triangle a point's nearest point lies on: inside it, on edge `k` (corner
/// `k` to corner `k + 1`), or at corner `k`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Feature {
    Face,
    Edge(usize),
    Corner(usize),
}

/// The point of triangle `[a, b, c]` nearest `p` (Ericson, *Real-Time Collision Detection*,
/// 5.1.5) and the part it lies on; a zero-area triangle's nearest corner.
#[inline]
fn closest_feature_on_triangle(p: Vec3, [a, b, c]: &[Vec3; 3]) -> (Vec3, Feature) {
    let (ab, ac, ap) = (*b - *a, *c - *a, p - *a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, Feature::Corner(0));
    }
    let bp = p - *b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, Feature::Corner(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (*a + ab * (d1 / (d1 - d3)), Feature::Edge(0));
    }
    let cp = p - *c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, Feature::Corner(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (*a + ac * (d2 / (d2 - d6)), Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let q = *b + (*c - *b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
        return (q, Feature::Edge(1));
    }
    let denom = va + vb + vc;
    if denom.abs() < f32::MIN_POSITIVE {
        // Degenerate (zero-area) triangle: nearest of its corners.
        let k = (0..3)
            .min_by(|&x, &y| {
                let (x, y) = ([a, b, c][x], [a, b, c][y]);
                x.distance_squared(p).total_cmp(&y.distance_squared(p))
            })
            .unwrap_or(0);
        return (*[a, b, c][k], Feature::Corner(k));
    }
    let (v, w) = (vb / denom, vc / denom);
    (*a + ab * v + ac * w, Feature::Face)
}

fn bounds(positions: &[Vec3], indices: &[u32]) -> Result<(Vec3, Vec3), SdfError> {
    if indices.len() < 3 || !indices.len().is_multiple_of(3) {
        return Err(SdfError::NoTriangles);
    }
    if let Some(&i) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        return Err(SdfError::IndexOutOfRange(i));
    }
    if let Some(v) = positions.iter().position(|p| !p.is_finite()) {
        return Err(SdfError::NonFinitePosition(v));
    }
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for &i in indices {
        lo = lo.min(positions[i as usize]);
        hi = hi.max(positions[i as usize]);
    }
    Ok((lo, hi))
}

/// Distance from `p` to the closest point of a triangle (Ericson, *Real-Time Collision
/// Detection*, 5.1.5).
#[must_use]
pub fn point_triangle_distance(p: Vec3, t: &[Vec3; 3]) -> f32 {
    (p - closest_point_on_triangle(p, t)).length()
}

pub(crate) fn closest_point_on_triangle(p: Vec3, t: &[Vec3; 3]) -> Vec3 {
    closest_feature_on_triangle(p, t).0
}

/// Sign of the orientation of the origin, `(x1, y1)`, `(x2, y2)` with consistent tie-breaking
/// (Bridson), so that a ray through an edge or vertex shared by two triangles is counted
/// exactly once. Returns the sign and twice the signed area.
fn orientation(x1: f64, y1: f64, x2: f64, y2: f64) -> (i32, f64) {
    let area = y1 * x2 - x1 * y2;
    let sign = if area > 0.0 {
        1
    } else if area < 0.0 {
        -1
    } else if y2 > y1 {
        1
    } else if y2 < y1 {
        -1
    } else if x1 > x2 {
        1
    } else if x1 < x2 {
        -1
    } else {
        0
    };
    (sign, area)
}

/// Whether `p` is inside the 2D triangle, with its barycentric weights.
fn point_in_triangle_2d(
    p: (f64, f64),
    a: (f64, f64),
    b: (f64, f64),
    c: (f64, f64),
) -> Option<(f64, f64, f64)> {
    let (x1, y1) = (a.0 - p.0, a.1 - p.1);
    let (x2, y2) = (b.0 - p.0, b.1 - p.1);
    let (x3, y3) = (c.0 - p.0, c.1 - p.1);
    let (sa, wa) = orientation(x2, y2, x3, y3);
    if sa == 0 {
        return None;
    }
    let (sb, wb) = orientation(x3, y3, x1, y1);
    if sb != sa {
        return None;
    }
    let (sc, wc) = orientation(x1, y1, x2, y2);
    if sc != sa {
        return None;
    }
    let sum = wa + wb + wc;
    if sum == 0.0 {
        return None;
    }
    Some((wa / sum, wb / sum, wc / sum))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed UV sphere of radius `r` (outward winding).
    fn uv_sphere(r: f32, rings: u32, segments: u32) -> (Vec<Vec3>, Vec<u32>) {
        let mut p = Vec::new();
        for i in 0..=rings {
            let theta = core::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let phi = core::f32::consts::TAU * j as f32 / segments as f32;
                p.push(
                    r * Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.cos(),
                        theta.sin() * phi.sin(),
                    ),
                );
            }
        }
        let mut idx = Vec::new();
        for i in 0..rings {
            for j in 0..segments {
                let a = i * segments + j;
                let b = i * segments + (j + 1) % segments;
                let (c, d) = (a + segments, b + segments);
                idx.extend_from_slice(&[a, b, c, b, d, c]);
            }
        }
        (p, idx)
    }

    /// A closed box of half extents `e` made of 12 triangles.
    fn cube(e: Vec3) -> (Vec<Vec3>, Vec<u32>) {
        let p: Vec<Vec3> = (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { -e.x } else { e.x },
                    if i & 2 == 0 { -e.y } else { e.y },
                    if i & 4 == 0 { -e.z } else { e.z },
                )
            })
            .collect();
        let idx = vec![
            0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4,
            6, 1, 3, 5, 3, 7, 5,
        ];
        (p, idx)
    }

    fn lcg(seed: &mut u32) -> f32 {
        *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (*seed >> 8) as f32 / (1u32 << 24) as f32
    }

    #[test]
    fn the_sweep_in_tiles_on_four_threads_gives_the_field_swept_row_by_row() {
        let workers = crate::solver::Workers::new(3);
        let (sphere, sphere_idx) = uv_sphere(1.0, 24, 48);
        let (cube_p, cube_idx) = cube(Vec3::new(0.7, 0.3, 0.45));
        let (land, land_idx) = terrain(24, hills);
        let open_cube = idx_without_top(&cube_p, &cube_idx);
        let cases = [
            ("sphere", &sphere, &sphere_idx, 0.05),
            ("box", &cube_p, &cube_idx, 0.037),
            ("terrain", &land, &land_idx, 0.09),
            ("open box", &cube_p, &open_cube, 0.041),
        ];
        for (name, p, idx, cell) in cases {
            // One tile as big as the grid: the sweep row by row, as it was written first.
            let rows = SdfGrid::bake_in_tiles(p, idx, cell, 3, [1 << 20; 3], &Serial).unwrap();
            let dims = rows.dims();
            assert!(
                (0..3).all(|a| dims[a] > 2 * TILE[a]),
                "{name}: {dims} samples, too few for several tiles a side"
            );
            let bits = |g: &SdfGrid| g.values().iter().map(|d| d.to_bits()).collect::<Vec<_>>();
            let serial = SdfGrid::from_triangles(p, idx, cell, 3).unwrap();
            let threads = SdfGrid::from_triangles_on(p, idx, cell, 3, &workers).unwrap();
            assert_eq!(bits(&serial), bits(&rows), "{name}: tiles in turn");
            assert_eq!(bits(&threads), bits(&rows), "{name}: tiles on four threads");
            assert_eq!(threads.is_open(), rows.is_open());
        }
    }

    #[test]
    fn sphere_sdf_matches_the_analytic_distance() {
        let (p, idx) = uv_sphere(1.0, 48, 96);
        let grid = SdfGrid::from_mesh(&p, &idx, 40).unwrap();
        let mut seed = 7;
        let mut worst = 0.0f32;
        for _ in 0..2000 {
            let q = Vec3::new(lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)) * 3.0 - 1.5;
            let (d, n) = grid.sample(q);
            let expect = q.length() - 1.0;
            worst = worst.max((d - expect).abs());
            // Sign is right away from the surface, normals point outward.
            if expect.abs() > grid.cell() {
                assert_eq!(d.signum(), expect.signum(), "{q}: {d} vs {expect}");
                assert!(n.dot(q.normalize()) > 0.9, "{q}: normal {n}");
            }
        }
        // Trilinear interpolation of a curved field: within a fraction of a cell.
        assert!(
            worst < 0.6 * grid.cell(),
            "worst error {worst}, cell {}",
            grid.cell()
        );
    }

    #[test]
    fn box_sdf_sign_and_distance() {
        let e = Vec3::new(0.5, 1.0, 0.25);
        let (p, idx) = cube(e);
        let grid = SdfGrid::from_mesh(&p, &idx, 40).unwrap();
        let shape = crate::solver::Shape::Cuboid { half_extents: e };
        let mut seed = 3;
        for _ in 0..2000 {
            let q = Vec3::new(lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)) * 3.0 - 1.5;
            let (d, _) = grid.sample(q);
            let (expect, _) = shape.distance(q);
            // Edges and corners are where a grid blurs a box most: allow 1.5 cells.
            assert!(
                (d - expect).abs() < 1.5 * grid.cell(),
                "{q}: {d} vs {expect}"
            );
            if expect.abs() > grid.cell() {
                assert_eq!(d.signum(), expect.signum(), "{q}: {d} vs {expect}");
            }
        }
    }

    /// A height field `h` over `[-2, 2]²` as `n × n` quads, triangles facing +y.
    fn terrain(n: u32, h: impl Fn(f32, f32) -> f32) -> (Vec<Vec3>, Vec<u32>) {
        let at = |i: u32| -2.0 + 4.0 * i as f32 / n as f32;
        let mut p = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, z) = (at(i), at(j));
                p.push(Vec3::new(x, h(x, z), z));
            }
        }
        let mut idx = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
                // (c - a) × (b - a) = +z × +x = +y.
                idx.extend_from_slice(&[a, c, b, b, c, d]);
            }
        }
        (p, idx)
    }

    fn hills(x: f32, z: f32) -> f32 {
        0.3 * (1.5 * x).sin() * (1.2 * z).cos() + 0.1 * x
    }

    #[test]
    fn an_open_terrain_is_solid_behind_its_front_and_nowhere_else() {
        let (p, idx) = terrain(40, hills);
        let grid = SdfGrid::from_mesh(&p, &idx, 64).unwrap();
        assert!(grid.is_open());
        let cell = grid.cell();
        let mut seed = 5;
        let (mut above, mut below) = (0, 0);
        for _ in 0..4000 {
            let (x, z) = (lcg(&mut seed) * 3.8 - 1.9, lcg(&mut seed) * 3.8 - 1.9);
            let ground = hills(x, z);
            // The slope is at most about 0.55, so the surface is within a height's
            // distance and no nearer than 0.85 of it.
            let up = ground + cell * 1.5 + lcg(&mut seed) * 1.0;
            let (d, n) = grid.sample(Vec3::new(x, up, z));
            assert!(d > 0.5 * cell, "({x}, {up}, {z}) over {ground}: {d}");
            if up - ground > 2.0 * cell {
                assert!(n.y > 0.5, "({x}, {up}, {z}): normal {n}");
            }
            above += 1;
            // Behind the front by up to a cell and a half (how far a cloth vertex gets in a
            // substep is a small part of that): inside, pushed back up.
            let down = ground - cell * (0.5 + lcg(&mut seed));
            let (d, n) = grid.sample(Vec3::new(x, down, z));
            assert!(d < 0.0, "({x}, {down}, {z}) under {ground}: {d}");
            assert!(n.y > 0.5, "({x}, {down}, {z}): normal {n}");
            below += 1;
        }
        assert_eq!((above, below), (4000, 4000));
        // Beside the rim, at any height, and far below: outside.
        for y in [-1.5f32, -0.6, -0.2, 0.0, 0.3, 1.0] {
            for (x, z) in [(2.0 + 3.0 * cell, 0.3), (-0.7, -2.0 - 3.0 * cell)] {
                let (d, _) = grid.sample(Vec3::new(x, y, z));
                assert!(d > 0.0, "({x}, {y}, {z}) beside the rim: {d}");
            }
        }
        let (d, _) = grid.sample(Vec3::new(0.5, hills(0.5, 0.2) - 8.0 * cell, 0.2));
        assert!(d > 0.0, "deep under the terrain: {d}");
    }

    #[test]
    fn a_flat_sheet_has_a_front_and_a_back_and_no_inside_beyond_its_rim() {
        let (p, idx) = terrain(8, |_, _| 0.0);
        let grid = SdfGrid::from_mesh(&p, &idx, 48).unwrap();
        let cell = grid.cell();
        for (x, z) in [(0.0, 0.0), (1.3, -0.4), (-1.9, 1.9)] {
            let (d, n) = grid.sample(Vec3::new(x, 0.1, z));
            assert!(
                (d - 0.1).abs() < 1e-3 && n.y > 0.99,
                "({x}, {z}) over: {d} {n}"
            );
            let (d, n) = grid.sample(Vec3::new(x, -cell, z));
            assert!(d < -0.5 * cell && n.y > 0.99, "({x}, {z}) under: {d} {n}");
        }
        // Below the rim and beyond it: outside, and the field leads away from the sheet.
        let (d, n) = grid.sample(Vec3::new(2.0 + 2.0 * cell, -0.2, 0.0));
        assert!(d > 0.0 && n.x > 0.5, "beside the rim: {d} {n}");
    }

    #[test]
    fn a_closed_mesh_split_along_its_seams_is_still_closed() {
        // Bevy's cuboid: four vertices of its own per face.
        let e = Vec3::new(1.0, 0.5, 0.8);
        let (corners, idx) = cube(e);
        let (mut p, mut split) = (Vec::new(), Vec::new());
        for t in idx.chunks_exact(3) {
            for &i in t {
                split.push(p.len() as u32);
                p.push(corners[i as usize]);
            }
        }
        let grid = SdfGrid::from_mesh(&p, &split, 40).unwrap();
        assert!(!grid.is_open());
        // Deeper than an open surface's slab: only parity makes it inside.
        let (d, _) = grid.sample(Vec3::ZERO);
        assert!(d < -OPEN_DEPTH * grid.cell(), "centre: {d}");
        // And the sphere with its poles' duplicated vertices.
        let (p, idx) = uv_sphere(1.0, 16, 24);
        assert!(!SdfGrid::from_mesh(&p, &idx, 24).unwrap().is_open());
        // A box without its top is open.
        let grid =
            SdfGrid::from_mesh(&corners, &idx_without_top(&corners, &cube(e).1), 40).unwrap();
        assert!(grid.is_open());
    }

    /// `idx` without the triangles whose corners all lie at the box's top.
    fn idx_without_top(p: &[Vec3], idx: &[u32]) -> Vec<u32> {
        let top = p.iter().map(|v| v.y).fold(f32::MIN, f32::max);
        idx.chunks_exact(3)
            .filter(|t| !t.iter().all(|&i| p[i as usize].y == top))
            .flatten()
            .copied()
            .collect()
    }

    #[test]
    fn bad_meshes_are_rejected() {
        assert_eq!(SdfGrid::from_mesh(&[], &[], 16), Err(SdfError::NoTriangles));
        assert_eq!(
            SdfGrid::from_mesh(&[Vec3::ZERO; 3], &[0, 1, 5], 16),
            Err(SdfError::IndexOutOfRange(5))
        );
        let (p, idx) = cube(Vec3::ONE);
        assert!(SdfGrid::from_mesh(&p, &idx, 2).is_err());
        assert!(SdfGrid::from_triangles(&p, &idx, 1e-5, 2).is_err());
    }

    #[test]
    fn triangle_distance_regions() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        assert_eq!(point_triangle_distance(Vec3::new(0.2, 0.2, 3.0), &t), 3.0);
        assert_eq!(point_triangle_distance(Vec3::new(-1.0, 0.0, 0.0), &t), 1.0);
        assert!(
            (point_triangle_distance(Vec3::new(1.0, 1.0, 0.0), &t) - 0.5f32.sqrt()).abs() < 1e-6
        );
        // Degenerate triangles do not produce NaN.
        assert!(point_triangle_distance(Vec3::ONE, &[Vec3::ZERO; 3]).is_finite());
    }
}
