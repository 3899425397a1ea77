//! The once-a-step query: each vertex's neighbours and the triangles it is over or beside,
//! from the grid (see the parent module's docs for what is listed and why).

use super::*;

/// Eight grid entries from `k` on, in `range` of the query's ranges, and the lanes of them of
/// the own neighbourhood (`near`) and folded (`fold`).
#[derive(Clone, Copy, Default)]
struct Group {
    k: u32,
    range: u8,
    near: u8,
    fold: u8,
}

/// How far `v` lies outside `[lo, hi)` (0 inside).
#[inline]
fn gap(v: f32, lo: f32, hi: f32) -> f32 {
    (lo - v).max(v - hi).max(0.0)
}

/// How far past a triangle's nearest point its first corner may lie: the longest rest edge
/// and a quarter for stretch, at most 4 thicknesses (so a mesh with a few long triangles does
/// not make every query cover the whole cloth; a vertex over the middle of a triangle longer
/// than that can be missed, as it is far from all three corners). The GPU backend stores the
/// same value in the cloth's record.
#[must_use]
pub fn triangle_reach(rest: &[Vec3], triangles: &[[u32; 3]], thickness: f32) -> f32 {
    reach_of_longest(longest_rest_edge(rest, triangles), thickness)
}

/// How far past a triangle's nearest point its first corner may lie before the cap of
/// [`triangle_reach`]: 1.25 × the longest rest edge (the GPU backend caps it per vertex).
pub(crate) fn first_corner_reach(rest: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    1.25 * longest_rest_edge(rest, triangles)
}

/// [`triangle_reach`] from the longest rest edge.
#[inline]
fn reach_of_longest(longest: f32, thickness: f32) -> f32 {
    (1.25 * longest).min(4.0 * thickness)
}

/// The longest finite rest edge of the triangles (0 for none).
pub(super) fn longest_rest_edge(rest: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    let at = |i: u32| rest.get(i as usize).copied().unwrap_or(Vec3::ZERO);
    let longest2 = triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.map(at);
            [
                a.distance_squared(b),
                b.distance_squared(c),
                c.distance_squared(a),
            ]
        })
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    longest2.sqrt()
}

/// A vertex's query distance: its thickness plus the step's motion margin, at most 1.5 of its
/// thicknesses (the GPU's `sc_reach` the same).
#[inline]
fn reach_of(thickness: f32, motion: f32) -> f32 {
    thickness + motion.min(1.5 * thickness)
}

/// What the query needs of a triangle at the step's start: the bound of
/// [`Frame::surely_apart`], and the normal, area and longest edge for the tests after it (the
/// rest of its [`Plane`] is made from the corners when it gets that far: a third of the
/// memory a query reads per triangle).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Frame {
    /// Unit normal, `(b - a) × (c - a)` normalised.
    n: Vec3,
    /// Twice the area; NaN for a degenerate triangle (or one not finite).
    pub(super) area2: f32,
    /// The longest edge.
    longest: f32,
    /// The centroid, and the farthest a corner lies from it: every point of the triangle lies
    /// within `spread` of `centre`.
    centre: Vec3,
    spread: f32,
}

impl Frame {
    /// The frame of `[a, b, c]`; its `area2` is NaN when the triangle is degenerate.
    #[inline]
    fn of([a, b, c]: [Vec3; 3]) -> Self {
        let plane = Plane::of([a, b, c]);
        let centre = (a + b + c) / 3.0;
        let spread = a
            .distance_squared(centre)
            .max(b.distance_squared(centre))
            .max(c.distance_squared(centre))
            .sqrt();
        let longest2 = a
            .distance_squared(b)
            .max(b.distance_squared(c))
            .max(c.distance_squared(a));
        Self {
            n: plane.n,
            area2: plane.area2,
            longest: longest2.sqrt(),
            centre,
            spread,
        }
    }

    /// Whether `p` is certainly more than `reach` from the triangle's plane or more than
    /// `slide` beside the triangle along it (measured from the centre: a conservative bound
    /// with slack for rounding, so it never rejects what [`Query::triangles_through`]'s exact
    /// tests keep). Cheaper than projecting; about half the triangles a query looks at end here.
    #[inline]
    fn surely_apart(&self, p: Vec3, slide: f32, reach: f32) -> bool {
        let dc = p - self.centre;
        let dn = dc.dot(self.n);
        let along2 = dc.length_squared() - dn * dn;
        let limit = slide + self.spread;
        along2 > limit * limit * 1.001 + 1e-4 * reach * reach || dn.abs() > 1.001 * reach
    }
}

/// What projecting onto a triangle needs of it (the same operations in the same order as the
/// GPU's `sc_project`, so the results are the same bits).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Plane {
    /// Unit normal, `(b - a) × (c - a)` normalised.
    pub(super) n: Vec3,
    pub(super) e1: Vec3,
    pub(super) e2: Vec3,
    pub(super) d00: f32,
    pub(super) d01: f32,
    pub(super) d11: f32,
    pub(super) denom: f32,
    /// Twice the area; NaN for a degenerate triangle (or one not finite).
    pub(super) area2: f32,
}

impl Plane {
    /// The plane of `[a, b, c]`; its `area2` is NaN when the triangle is degenerate.
    #[inline]
    pub(super) fn of([a, b, c]: [Vec3; 3]) -> Self {
        let nn = (b - a).cross(c - a);
        let len = nn.length();
        let plane = Self::with_normal([a, b, c], nn / len, len);
        let denom = plane.denom;
        let ok = !(len.is_nan() || len <= 1e-12 || denom.is_nan() || denom <= 0.0);
        Self {
            area2: if ok { len } else { f32::NAN },
            ..plane
        }
    }

    /// The plane of `[a, b, c]` with the normal and `area2` of its [`Plane::of`] (or
    /// [`Frame::of`]) given: the same bits, without the cross product and square root again.
    #[inline]
    fn with_normal([a, b, c]: [Vec3; 3], n: Vec3, area2: f32) -> Self {
        let e1 = b - a;
        let e2 = c - a;
        let d00 = e1.dot(e1);
        let d01 = e1.dot(e2);
        let d11 = e2.dot(e2);
        Self {
            n,
            e1,
            e2,
            d00,
            d01,
            d11,
            denom: d00 * d11 - d01 * d01,
            area2,
        }
    }

    /// `p`'s signed distance along the normal and its projection's barycentric weights (all
    /// ≥ 0 inside), `a` being the first corner; `None` for a degenerate triangle.
    #[inline]
    pub(super) fn project(&self, p: Vec3, a: Vec3) -> Option<(f32, Vec3)> {
        if self.area2.is_nan() {
            return None;
        }
        let ap = p - a;
        let d = ap.dot(self.n);
        let d20 = ap.dot(self.e1);
        let d21 = ap.dot(self.e2);
        let v = (self.d11 * d20 - self.d01 * d21) / self.denom;
        let w = (self.d00 * d21 - self.d01 * d20) / self.denom;
        Some((d, Vec3::new(1.0 - v - w, v, w)))
    }
}

/// A triangle's slot: `triangle << 2 | side`, with [`BESIDE`] set for a triangle the vertex is
/// not over yet, so that a full list keeps the triangles it is over first.
#[inline]
pub(super) fn slot(t: u32, code: u32) -> u32 {
    let beside = if code == SIDE_FREE { BESIDE } else { 0 };
    beside | (t << 2) | code
}

/// The high bit of a slot: the vertex is beside the triangle.
pub(super) const BESIDE: u32 = 1 << 31;

/// Keeps the `max` smallest values of a list in increasing order (insertion, as the GPU does).
#[inline]
fn keep_smallest(list: &mut [u32], count: &mut usize, value: u32) {
    let max = list.len();
    if *count == max && value >= list[max - 1] {
        return;
    }
    let mut k = (*count).min(max - 1);
    while k > 0 && list[k - 1] > value {
        list[k] = list[k - 1];
        k -= 1;
    }
    list[k] = value;
    *count = (*count + 1).min(max);
}

/// What a step's query reads; `thickness`, `reach`, `radius` and `skip` are the querying
/// vertex's (see [`Query::vertex`]).
#[derive(Clone, Copy)]
pub(super) struct Query<'a> {
    /// Per vertex, its thickness over `cloth_thickness` (none: 1).
    scale: &'a [f32],
    cloth_thickness: f32,
    /// The step's motion margin (twice the fastest vertex's travel).
    motion: f32,
    longest: f32,
    pos: &'a [Vec4],
    vel: &'a [Vec4],
    dt: f32,
    rest: &'a [Vec3],
    triangles: &'a [[u32; 3]],
    grid: &'a Grid,
    first_start: &'a [u32],
    first_tris: &'a [u32],
    frames: &'a [Frame],
    /// Per vertex: see [`SelfCollisionScratch::corner_speeds`]; whether to use them.
    corner_speeds: &'a [f32],
    slide_bounds: bool,
    /// The triangles put into some list (see [`Listed`]).
    listed: &'a [AtomicU32],
    thickness: f32,
    reach: f32,
    radius: f32,
    skip: f32,
}

/// A vertex's query in progress.
struct Found<'a> {
    neighbours: &'a mut [u32],
    nc: usize,
    tris: &'a mut [u32],
    tc: usize,
    folded: bool,
}

/// What one look at eight grid entries found, as bit masks: within the radius and resting
/// farther than 2.5 thicknesses, and neither a neighbour nor through a fold (`far` is only a
/// candidate: the row is checked after); of the own neighbourhood and within the radius
/// (`near`); of it and folded (`fold`).
struct Lanes {
    far: u32,
    near: u32,
    fold: u32,
}

impl Query<'_> {
    /// Vertex `i`'s neighbours and triangles into its slots; returns their counts. `ranges`
    /// is working space. `WALK_TWICE` takes the path of a crowd too big for [`NEAR_GROUPS`]
    /// (a second walk for the own neighbourhood) for every vertex, as the tests compare.
    fn vertex<const WALK_TWICE: bool>(
        &self,
        i: usize,
        neighbours: &mut [u32],
        tris: &mut [u32],
        ranges: &mut Vec<(Row, usize, usize)>,
    ) -> (usize, usize) {
        // The vertex's own thickness and the distances that follow from it.
        let thickness = self.cloth_thickness * self.scale.get(i).copied().unwrap_or(1.0);
        let reach = reach_of(thickness, self.motion);
        let own = Query {
            thickness,
            reach,
            radius: reach + reach_of_longest(self.longest, thickness),
            skip: SKIP * thickness,
            ..*self
        };
        own.vertex_with::<WALK_TWICE>(i, neighbours, tris, ranges)
    }

    /// [`Query::vertex`] with the vertex's own distances in `self`.
    fn vertex_with<const WALK_TWICE: bool>(
        &self,
        i: usize,
        neighbours: &mut [u32],
        tris: &mut [u32],
        ranges: &mut Vec<(Row, usize, usize)>,
    ) -> (usize, usize) {
        let p = self.pos[i].xyz();
        if !p.is_finite() {
            return (0, 0);
        }
        ranges.clear();
        self.ranges(p, ranges);
        let mut found = Found {
            neighbours,
            nc: 0,
            tris,
            tc: 0,
            folded: false,
        };
        let ahead = AHEAD * self.dt;
        let pa = p + self.vel[i].xyz() * ahead;
        let rest_i = self.rest[i];
        // The groups of eight entries with some of the own neighbourhood in them, kept for
        // after the walk (stored whether or not they have, to keep the walk free of branches);
        // more than the buffer holds and the walk is repeated for them.
        let mut groups = [Group::default(); NEAR_GROUPS];
        let mut ng = 0usize;
        for (r, &(row, k0, k1)) in ranges.iter().enumerate() {
            let mut k = k0;
            while k < k1 {
                let m = (k1 - k).min(LANES);
                let keep = (1u32 << m) - 1;
                let lanes = self.lanes(k, p, pa, rest_i);
                let mut far = lanes.far & keep;
                while far != 0 {
                    let l = far.trailing_zeros() as usize;
                    far &= far - 1;
                    self.far_hit(i, p, row, k + l, &mut found);
                }
                let near = lanes.near & keep;
                if let Some(g) = groups.get_mut(ng) {
                    *g = Group {
                        k: k as u32,
                        range: r as u8,
                        near: near as u8,
                        fold: (lanes.fold & keep) as u8,
                    };
                }
                ng += usize::from(near != 0);
                k += LANES;
            }
        }
        // The own neighbourhood's triangles, where it has folded.
        if !WALK_TWICE && ng <= NEAR_GROUPS && ranges.len() <= 256 {
            let groups = &groups[..ng];
            let row = |g: &Group| ranges[g.range as usize].0;
            found.folded = groups.iter().any(|g| {
                bits(g.fold.into()).any(|l| self.in_row(i, row(g), g.k as usize + l).is_some())
            });
            if found.folded {
                for g in groups {
                    for l in bits(g.near.into()) {
                        self.near_hit(i, p, rest_i, row(g), g.k as usize + l, &mut found);
                    }
                }
            }
        } else {
            self.near_walk(i, p, pa, rest_i, ranges, &mut found);
        }
        (found.nc, found.tc)
    }

    /// The triangles through the own-neighbourhood vertex of grid entry `k`, when it is read
    /// through its own row.
    #[inline]
    fn near_hit(&self, i: usize, p: Vec3, rest_i: Vec3, row: Row, k: usize, found: &mut Found) {
        if let Some(j) = self.in_row(i, row, k) {
            let rest2 = (self.rest[j] - rest_i).length_squared();
            self.triangles_through(i, p, j, rest2, found);
        }
    }

    /// The own neighbourhood's fold test and triangles from a second walk (a crowd too big
    /// for [`NEAR_GROUPS`]).
    fn near_walk(
        &self,
        i: usize,
        p: Vec3,
        pa: Vec3,
        rest_i: Vec3,
        ranges: &[(Row, usize, usize)],
        found: &mut Found,
    ) {
        let each = |f: &mut dyn FnMut(Row, usize, Lanes)| {
            for &(row, k0, k1) in ranges {
                for k in (k0..k1).step_by(LANES) {
                    let keep = (1u32 << (k1 - k).min(LANES)) - 1;
                    let lanes = self.lanes(k, p, pa, rest_i);
                    let masked = Lanes {
                        far: lanes.far & keep,
                        near: lanes.near & keep,
                        fold: lanes.fold & keep,
                    };
                    f(row, k, masked);
                }
            }
        };
        let mut folded = false;
        each(&mut |row, k, lanes| {
            folded |= bits(lanes.fold).any(|l| self.in_row(i, row, k + l).is_some());
        });
        found.folded = folded;
        if folded {
            each(&mut |row, k, lanes| {
                for l in bits(lanes.near) {
                    self.near_hit(i, p, rest_i, row, k + l, found);
                }
            });
        }
    }

    /// The grid ranges within the radius of `p`: rows (cells along x) whose y–z square comes
    /// within it, each trimmed to the cells of the x range it leaves there (a hundredth of a
    /// cell of slack against rounding): whole buckets, read from start to end.
    fn ranges(&self, p: Vec3, out: &mut Vec<(Row, usize, usize)>) {
        let g = self.grid;
        let (cell, inv) = (g.cell, g.inv_cell());
        let big2 = self.radius * self.radius;
        let size = g.start.len() - 1;
        let mask = size - 1;
        let lo = cell_of(p - Vec3::splat(self.radius), inv);
        let hi = cell_of(p + Vec3::splat(self.radius), inv);
        // Slack for the rounding of cell bounds; more than four million cells out (or beyond
        // an `i32`, where the cells saturate) whole rows are read.
        let far = p.abs().max_element();
        let slack = 0.01 * cell + far * 1e-6;
        let exact = (far + self.radius) * inv.max_element() < 4.0e6;
        let bounds = |c: i32| (c as f32 * cell, (c as f32 + 1.0) * cell);
        for z in lo.z..=hi.z {
            let (z0, z1) = bounds(z);
            let gz = if exact {
                (gap(p.z, z0, z1) - slack).max(0.0)
            } else {
                0.0
            };
            for y in lo.y..=hi.y {
                let (y0, y1) = bounds(y);
                let gy = if exact {
                    (gap(p.y, y0, y1) - slack).max(0.0)
                } else {
                    0.0
                };
                let left = big2 - gy * gy - gz * gz;
                if left < 0.0 {
                    continue;
                }
                // The x range the row's entries within the radius lie in.
                let half = if exact {
                    left.sqrt() + slack
                } else {
                    f32::INFINITY
                };
                let (x0, x1) = if exact {
                    (
                        cell_of(Vec3::splat(p.x - half), inv).x.max(lo.x),
                        cell_of(Vec3::splat(p.x + half), inv).x.min(hi.x),
                    )
                } else {
                    (lo.x, hi.x)
                };
                if x0 > x1 {
                    continue;
                }
                let row = Row { y, z, x0, x1 };
                let cells = (i64::from(x1) - i64::from(x0) + 1) as u64;
                if cells >= size as u64 {
                    out.push((row, g.start[0] as usize, g.start[size] as usize));
                    continue;
                }
                let base = row_base(y, z);
                let b0 = base.wrapping_add(x0 as isize as usize) & mask;
                let b1 = base.wrapping_add(x1 as isize as usize) & mask;
                let first = g.start[b0] as usize;
                let last = g.start[b1 + 1] as usize;
                if b0 <= b1 {
                    out.push((row, first, last.max(first)));
                } else {
                    out.push((row, first, g.start[size] as usize));
                    out.push((row, g.start[0] as usize, last));
                }
            }
        }
    }

    /// Grid entries `k..k + 8` against vertex `i` at `p` (`pa` ahead, resting at `rest_i`):
    /// plain arithmetic on the grid's lanes, which the compiler vectorises.
    #[inline(always)]
    fn lanes(&self, k: usize, p: Vec3, pa: Vec3, rest_i: Vec3) -> Lanes {
        let g = self.grid;
        let big2 = self.radius * self.radius;
        let r2 = self.reach * self.reach;
        let skip2 = self.skip * self.skip;
        let tri_skip = TRIANGLE_SKIP * self.thickness;
        let tri_skip2 = tri_skip * tri_skip;
        let at = |lane: &[f32]| -> [f32; LANES] {
            lane[k..k + LANES].try_into().unwrap_or([f32::NAN; LANES])
        };
        let (x, y, z) = (at(&g.x), at(&g.y), at(&g.z));
        // Every mask needs the entry within the radius: a group with none there is done
        // before its rest and ahead positions are read (on the first frames of the 256²
        // `--scene-costs` scene a tenth of the self-collision frame).
        let d2: [f32; LANES] = core::array::from_fn(|l| {
            let (dx, dy, dz) = (x[l] - p.x, y[l] - p.y, z[l] - p.z);
            dx * dx + dy * dy + dz * dz
        });
        if !d2.iter().any(|&d2| d2 < big2) {
            return Lanes {
                far: 0,
                near: 0,
                fold: 0,
            };
        }
        let (rx, ry, rz) = (at(&g.rx), at(&g.ry), at(&g.rz));
        let (ax, ay, az) = (at(&g.ax), at(&g.ay), at(&g.az));
        let (mut far, mut near, mut fold) = (0u32, 0u32, 0u32);
        for (l, &d2) in d2.iter().enumerate() {
            let (ex, ey, ez) = (rx[l] - rest_i.x, ry[l] - rest_i.y, rz[l] - rest_i.z);
            let rest2 = ex * ex + ey * ey + ez * ez;
            let (fx, fy, fz) = (ax[l] - pa.x, ay[l] - pa.y, az[l] - pa.z);
            let a2 = fx * fx + fy * fy + fz * fz;
            let inside = d2 < big2;
            let is_far = rest2 > skip2;
            let is_near = rest2 > tri_skip2 && !is_far;
            let f2 = NEAR_FOLDED2 * rest2;
            far |= u32::from(inside & is_far & ((d2 < r2) | (d2 < FOLDED2 * rest2))) << l;
            near |= u32::from(inside & is_near) << l;
            fold |= u32::from(inside & is_near & ((d2 < f2) | (a2 < f2))) << l;
        }
        Lanes { far, near, fold }
    }

    /// The vertex of grid entry `k` when it is not `i` and read through its own row (cells of
    /// other rows hashed into these buckets are read through theirs: each vertex is seen once).
    #[inline]
    fn in_row(&self, i: usize, row: Row, k: usize) -> Option<usize> {
        let c = self.grid.cells[k];
        let j = self.grid.entries[k] as usize;
        (c.y == row.y && c.z == row.z && c.x >= row.x0 && c.x <= row.x1 && j != i).then_some(j)
    }

    /// Grid entry `k` within the radius of vertex `i` at `p`, resting more than 2.5
    /// thicknesses from it, and close enough to be a neighbour or to have folded towards it.
    fn far_hit(&self, i: usize, p: Vec3, row: Row, k: usize, found: &mut Found) {
        let Some(j) = self.in_row(i, row, k) else {
            return;
        };
        let g = self.grid;
        let d2 = (Vec3::new(g.x[k], g.y[k], g.z[k]) - p).length_squared();
        let rest2 = (self.rest[j] - self.rest[i]).length_squared();
        if d2 < self.reach * self.reach {
            keep_smallest(found.neighbours, &mut found.nc, j as u32);
        }
        // Triangles through a `j` resting farther than 2.5 thicknesses away: only where the
        // cloth has come closer to itself than it is at rest (a fold, a pile), never across a
        // flat or stretched sheet, whose own triangles lie beside its vertices.
        if d2 < FOLDED2 * rest2 {
            self.triangles_through(i, p, j, rest2, found);
        }
    }

    /// The triangles whose first corner is `j` (resting `rest2` from vertex `i` at `p`) that
    /// `i` is over, or beside by no more than it can slide over in the step, into its list.
    fn triangles_through(&self, i: usize, p: Vec3, j: usize, rest2: f32, found: &mut Found) {
        let rest_i = self.rest[i];
        let tri_skip = TRIANGLE_SKIP * self.thickness;
        let tri_skip2 = tri_skip * tri_skip;
        let margin = self.reach - self.thickness;
        let r2 = self.reach * self.reach;
        let v = self.vel[i];
        let first =
            &self.first_tris[self.first_start[j] as usize..self.first_start[j + 1] as usize];
        let near = rest2 <= self.skip * self.skip;
        // How far it can slide over any of them at most: over the own neighbourhood's, each
        // corner moves relative to it at most as fast as `j` does plus the fastest a corner
        // moves relative to `j` (widened against the roundings of the two sums).
        let slide_bound = if near && self.slide_bounds {
            let bound = (self.vel[j] - v).xyz().length() + self.corner_speeds[j];
            (2.0 * self.dt * (bound * 1.0001) + 0.25 * self.thickness).min(margin)
        } else {
            margin
        };
        for &t in first {
            let frame = &self.frames[t as usize];
            if frame.surely_apart(p, slide_bound, self.reach) {
                continue;
            }
            let tri = self.triangles[t as usize];
            if !tri[1..]
                .iter()
                .all(|&k| (self.rest[k as usize] - rest_i).length_squared() > tri_skip2)
            {
                continue;
            }
            let corners = tri.map(|k| self.pos[k as usize].xyz());
            if !corners.iter().all(|c| c.is_finite()) {
                continue;
            }
            // Over the triangle, or beside it by no more than it can slide over in the step
            // (the sheet's own triangles around the vertex are beside it, in its plane).
            let plane = Plane::with_normal(corners, frame.n, frame.area2);
            let Some((d, bary)) = plane.project(p, corners[0]) else {
                continue;
            };
            if d.is_nan() || d.abs() >= self.reach {
                continue;
            }
            let code = if bary.min_element() >= 0.0 {
                if d >= 0.0 { SIDE_FRONT } else { SIDE_BACK }
            } else {
                // How far it can slide over the triangle in the step: the margin; over its
                // own neighbourhood (which moves with it) twice its fastest speed relative to
                // a corner and a quarter thickness.
                let slide = if !near {
                    margin
                } else {
                    let rel = tri
                        .iter()
                        .map(|&k| (self.vel[k as usize] - v).xyz().length_squared())
                        .fold(0.0f32, f32::max);
                    (2.0 * self.dt * rel.sqrt() + 0.25 * self.thickness).min(margin)
                };
                // At least −(the negative weight) altitudes from the triangle (an altitude is
                // at least twice the area over the longest edge): most of a sheet's own
                // triangles end here.
                let below = -bary.min_element() * frame.area2 / frame.longest;
                if below > slide {
                    continue;
                }
                let q = crate::solver::collision::sdf::closest_point_on_triangle(p, &corners);
                let near2 = q.distance_squared(p);
                if !(near2 < r2 && near2 - d * d <= slide * slide) {
                    continue;
                }
                SIDE_FREE
            };
            Listed::mark(self.listed, t as usize);
            keep_smallest(found.tris, &mut found.tc, slot(t, code));
        }
    }
}

/// A row of the query grid: cells `x0..=x1` at `y`, `z`.
#[derive(Clone, Copy)]
struct Row {
    y: i32,
    z: i32,
    x0: i32,
    x1: i32,
}

/// One parallel work item of the query: a run of vertices and their slots.
struct QueryChunk<'a> {
    first: usize,
    neighbour_count: &'a mut [u32],
    neighbours: &'a mut [u32],
    triangle_count: &'a mut [u32],
    triangles: &'a mut [u32],
    /// Its vertices with something in their lists, rising.
    active: Vec<u32>,
}

impl SelfCollisionScratch {
    /// Whether the query bounds the own neighbourhood's slides by the corners' speeds.
    #[cfg(test)]
    fn slide_bounds(&self) -> bool {
        !self.margin_slides
    }

    #[cfg(not(test))]
    #[expect(clippy::unused_self)]
    fn slide_bounds(&self) -> bool {
        true
    }

    /// Fills the grid with the current positions and every vertex's lists (see the module
    /// docs), the vertices in parallel (`WALK_TWICE`: see [`Query::vertex`]).
    #[expect(clippy::too_many_arguments)]
    pub(super) fn find<const WALK_TWICE: bool>(
        &mut self,
        pos: &[Vec4],
        vel: &[Vec4],
        dt: f32,
        rest: &[Vec3],
        triangles: &[[u32; 3]],
        scales: &[f32],
        thickness: f32,
        motion: f32,
        par: &impl Parallel,
    ) {
        let n = pos.len();
        self.caps_ready = false;
        self.mesh.update(rest, triangles, par);
        // The grid's cells from the thickest vertex's radius (scales only on uneven meshes).
        let thickest = thickness * scales.iter().copied().fold(1.0, f32::max);
        let radius = reach_of(thickest, motion) + reach_of_longest(self.mesh.longest, thickest);
        self.grid
            .fill(pos, vel, rest, AHEAD * dt, radius / CELLS_PER_RADIUS, par);
        let valid = |t: &[u32; 3]| t.iter().all(|&k| (k as usize) < n);

        self.frames.resize(triangles.len(), Frame::default());
        fill_each(&mut self.frames, par, |t| {
            let tri = triangles[t];
            if valid(&tri) {
                Frame::of(tri.map(|k| pos[k as usize].xyz()))
            } else {
                Frame {
                    area2: f32::NAN,
                    ..Frame::default()
                }
            }
        });

        self.corner_speeds.resize(n, 0.0);
        let (first_start, first_tris) = (&self.mesh.first_start, &self.mesh.first_tris);
        fill_each(&mut self.corner_speeds, par, |j| {
            let first = &first_tris[first_start[j] as usize..first_start[j + 1] as usize];
            first
                .iter()
                .flat_map(|&t| triangles[t as usize])
                .map(|k| (vel[k as usize] - vel[j]).xyz().length_squared())
                .fold(0.0f32, f32::max)
                .sqrt()
        });

        self.neighbour_count.clear();
        self.neighbour_count.resize(n, 0);
        self.neighbours.resize(n * MAX_SELF_NEIGHBOURS, 0);
        self.triangle_count.clear();
        self.triangle_count.resize(n, 0);
        self.triangles.resize(n * MAX_SELF_TRIANGLES, 0);
        // The triangles put into a list (one that is later pushed out of a full list too:
        // its plane is made for nothing).
        let listed: Vec<AtomicU32> = (0..triangles.len().div_ceil(32))
            .map(|_| AtomicU32::new(0))
            .collect();
        let query = Query {
            scale: scales,
            cloth_thickness: thickness,
            motion,
            longest: self.mesh.longest,
            pos,
            vel,
            dt,
            rest,
            triangles,
            grid: &self.grid,
            first_start: &self.mesh.first_start,
            first_tris: &self.mesh.first_tris,
            frames: &self.frames,
            corner_speeds: &self.corner_speeds,
            slide_bounds: self.slide_bounds(),
            listed: &listed,
            // The querying vertex's, set per vertex.
            thickness,
            reach: reach_of(thickness, motion),
            radius,
            skip: SKIP * thickness,
        };
        let chunk = chunk_for(n, par.threads());
        let mut chunks: Vec<QueryChunk> = self
            .neighbour_count
            .chunks_mut(chunk)
            .zip(self.neighbours.chunks_mut(chunk * MAX_SELF_NEIGHBOURS))
            .zip(self.triangle_count.chunks_mut(chunk))
            .zip(self.triangles.chunks_mut(chunk * MAX_SELF_TRIANGLES))
            .enumerate()
            .map(|(k, (((nc, nl), tc), tl))| QueryChunk {
                first: k * chunk,
                neighbour_count: nc,
                neighbours: nl,
                triangle_count: tc,
                triangles: tl,
                active: Vec::new(),
            })
            .collect();
        par.for_each_mut(&mut chunks, |c| {
            let mut ranges = Vec::new();
            for k in 0..c.neighbour_count.len() {
                let (nc, tc) = query.vertex::<WALK_TWICE>(
                    c.first + k,
                    &mut c.neighbours[k * MAX_SELF_NEIGHBOURS..(k + 1) * MAX_SELF_NEIGHBOURS],
                    &mut c.triangles[k * MAX_SELF_TRIANGLES..(k + 1) * MAX_SELF_TRIANGLES],
                    &mut ranges,
                );
                c.neighbour_count[k] = nc as u32;
                c.triangle_count[k] = tc as u32;
                if nc + tc > 0 {
                    c.active.push((c.first + k) as u32);
                }
            }
        });
        self.active.clear();
        for c in &chunks {
            self.active.extend_from_slice(&c.active);
        }
        self.listed.set(listed);
    }
}

/// The step's motion margin: twice the fastest vertex's travel in `dt` (a vertex's reach adds
/// it to its thickness, at most 1.5 thicknesses: [`reach_of`]); `None` when off.
pub(super) fn motion_margin(
    vel: &[Vec4],
    params: SelfCollision,
    dt: f32,
    par: &impl Parallel,
) -> Option<f32> {
    let thickness = params.thickness;
    if !(thickness.is_finite() && thickness > 0.0) {
        return None;
    }
    let fastest2 = |run: &[Vec4]| {
        run.iter()
            .map(|v| v.xyz().length_squared())
            .filter(|s| s.is_finite())
            .fold(0.0f32, f32::max)
    };
    // A maximum per run in parallel: the same whatever the order.
    let fastest = per_run(vel.len(), par, |r| fastest2(&vel[r]))
        .into_iter()
        .fold(0.0f32, f32::max)
        .sqrt();
    Some(2.0 * fastest * dt)
}

/// Collects the candidates for this step: vertices and triangles closer than `thickness` plus
/// a margin for how far they can move in `dt` (see the module docs), as per-vertex lists for
/// [`self_collide`] (the GPU kernels' CPU twin).
#[expect(clippy::too_many_arguments)]
pub(crate) fn find_self_collision_candidates(
    pos: &[Vec4],
    vel: &[Vec4],
    rest: &[Vec3],
    triangles: &[[u32; 3]],
    scales: &[f32],
    params: SelfCollision,
    dt: f32,
    scratch: &mut SelfCollisionScratch,
    par: &impl Parallel,
) {
    if let Some(motion) = motion_margin(vel, params, dt, par) {
        let t = params.thickness;
        scratch.find::<false>(pos, vel, dt, rest, triangles, scales, t, motion, par);
    } else {
        scratch.neighbour_count.clear();
        scratch.neighbour_count.resize(pos.len(), 0);
        scratch.triangle_count.clear();
        scratch.triangle_count.resize(pos.len(), 0);
        scratch.active.clear();
        scratch.listed.set(Vec::new());
        scratch.caps_ready = false;
    }
}
