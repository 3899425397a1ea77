//! The step's spatial hash of vertices: cells, buckets, the parallel counting sort and the
//! lanes a query reads; and the small parallel helpers the query and the pass share.

use super::*;

/// Vertices a work item of the grid's sort lays out by bin ([`Grid::sort`]).
pub(super) const SORT_RUN: usize = 4096;

/// The grid's sort splits the buckets into at most `2^BIN_BITS` bins by their high bits.
const BIN_BITS: u32 = 8;

#[inline]
pub(super) fn cell_of(p: Vec3, inv_cell: Vec3) -> IVec3 {
    // floor() without a libm call (x86-64's baseline has no rounding instruction):
    // truncate, then step down for negative non-integers. The cast saturates far out (a cloth
    // flung 2³¹ cells away): the step down then wraps, as WGSL's does, and never panics.
    let v = p * inv_cell;
    let t = v.as_ivec3();
    t.wrapping_sub(IVec3::select(t.as_vec3().cmpgt(v), IVec3::ONE, IVec3::ZERO))
}

/// MurmurHash3's 32-bit finaliser: each input bit flips about half of the output bits.
#[inline]
fn fmix(mut h: u32) -> u32 {
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// The bucket of cell `c` in a table of `size` buckets, for [`count_self_crossings`]; the
/// GPU's `sc_hash` is the same function. Each coordinate goes through [`fmix`] in turn: the
/// xor of the coordinates times three odd constants (its sign dropped), which this replaced,
/// put two and a half to three times as many nearby cells into a shared bucket as chance
/// would (of the rows of a 10 × 10 block, two in five started where another of them did),
/// and a query reads every cell's vertices in a bucket it reads.
#[inline]
pub(super) fn hash(c: IVec3, size: usize) -> usize {
    fmix((row_base(c.y, c.z) as u32).wrapping_add(c.x as u32)) as usize % size
}

/// The query grid's bucket of cell `c` in a table of `mask + 1` (a power of two) buckets: the
/// cells of a row along x fall into consecutive buckets.
#[inline]
pub(super) fn grid_bucket(c: IVec3, mask: usize) -> usize {
    row_base(c.y, c.z).wrapping_add(c.x as isize as usize) & mask
}

/// The bucket of a row's cell at x = 0 (before the mask), mixed as [`hash`] mixes.
#[inline]
pub(super) fn row_base(y: i32, z: i32) -> usize {
    fmix(fmix(z as u32).wrapping_add(y as u32)) as usize
}

/// The step's grid of vertices (cells [`CELLS_PER_RADIUS`] to the query radius across the
/// rows, [`X_CELL`] of that along them), its entries in bucket order with their positions in
/// separate lanes.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Grid {
    /// A cell's size along y and z (a row's square), and along x (the row).
    pub(super) cell: f32,
    pub(super) cell_x: f32,
    /// Per bucket, its first entry; one more at the end.
    pub(super) start: Vec<u32>,
    pub(super) entries: Vec<u32>,
    pub(super) x: Vec<f32>,
    pub(super) y: Vec<f32>,
    pub(super) z: Vec<f32>,
    /// Rest positions.
    pub(super) rx: Vec<f32>,
    pub(super) ry: Vec<f32>,
    pub(super) rz: Vec<f32>,
    /// Positions [`AHEAD`] × the step on at the step's start velocities.
    pub(super) ax: Vec<f32>,
    pub(super) ay: Vec<f32>,
    pub(super) az: Vec<f32>,
    pub(super) cells: Vec<IVec3>,
    /// Cell of each vertex, and its bucket (`u32::MAX`: its position is not finite).
    vertex_cells: Vec<IVec3>,
    vertex_buckets: Vec<u32>,
    /// Working space of [`Grid::sort`]: per run of vertices its count and first place per
    /// bin, its vertices by bin; each bin's first entry.
    bin_counts: Vec<u32>,
    bin_offsets: Vec<u32>,
    by_bin: Vec<u32>,
    bin_start: Vec<u32>,
}

impl Grid {
    /// One over a cell's size along x, y and z.
    #[inline]
    pub(super) fn inv_cell(&self) -> Vec3 {
        Vec3::new(1.0 / self.cell_x, 1.0 / self.cell, 1.0 / self.cell)
    }

    /// Every vertex with a finite position into its cell's bucket, in parallel (see
    /// [`Grid::sort`]).
    pub(super) fn fill(
        &mut self,
        pos: &[Vec4],
        vel: &[Vec4],
        rest: &[Vec3],
        ahead: f32,
        cell: f32,
        par: &impl Parallel,
    ) {
        let n = pos.len();
        let size = (2 * n).next_power_of_two().max(2);
        let mask = size - 1;
        self.cell = cell;
        self.cell_x = X_CELL * cell;
        let inv = self.inv_cell();
        self.vertex_cells.resize(n, IVec3::ZERO);
        fill_each(&mut self.vertex_cells, par, |i| cell_of(pos[i].xyz(), inv));
        self.vertex_buckets.resize(n, 0);
        let cells = &self.vertex_cells;
        fill_each(&mut self.vertex_buckets, par, |i| {
            if pos[i].xyz().is_finite() {
                grid_bucket(cells[i], mask) as u32
            } else {
                u32::MAX
            }
        });
        let real = self.sort(size, par);
        let count = real + LANES;
        // The lanes, one a work item: each read through the entries in order.
        let entries = &self.entries[..real];
        let mut lanes: Vec<(usize, &mut [f32])> = [
            &mut self.x,
            &mut self.y,
            &mut self.z,
            &mut self.rx,
            &mut self.ry,
            &mut self.rz,
            &mut self.ax,
            &mut self.ay,
            &mut self.az,
        ]
        .into_iter()
        .enumerate()
        .map(|(kind, lane)| {
            lane.resize(count, 0.0);
            (kind, &mut lane[..real])
        })
        .collect();
        par.for_each_mut(&mut lanes, |(kind, out)| {
            let out = &mut **out;
            match *kind {
                0 => gather(out, entries, |i| pos[i].x),
                1 => gather(out, entries, |i| pos[i].y),
                2 => gather(out, entries, |i| pos[i].z),
                3 => gather(out, entries, |i| rest[i].x),
                4 => gather(out, entries, |i| rest[i].y),
                5 => gather(out, entries, |i| rest[i].z),
                6 => gather(out, entries, |i| pos[i].x + vel[i].x * ahead),
                7 => gather(out, entries, |i| pos[i].y + vel[i].y * ahead),
                _ => gather(out, entries, |i| pos[i].z + vel[i].z * ahead),
            }
        });
    }

    /// The entries in bucket order, the `size` buckets' starts and the entries' cells from
    /// the vertices' buckets and cells; returns the number of entries (vertices with a finite
    /// position). A parallel counting sort whose order does not depend on the threads: runs
    /// of [`SORT_RUN`] vertices are each laid out by bin (the buckets' high bits) in their own
    /// stretch, then each bin gathers its stretches in run order and sorts them by bucket
    /// (a bucket's entries in rising vertex order).
    fn sort(&mut self, size: usize, par: &impl Parallel) -> usize {
        let n = self.vertex_buckets.len();
        let cells = &self.vertex_cells;
        // About a bin per 1024 vertices, at most 2^BIN_BITS: a small cloth's sort is a few
        // items, not hundreds of tiny ones.
        let bin_bits = (n / 1024).max(1).ilog2().min(BIN_BITS);
        let log = size.trailing_zeros();
        let shift = log - log.min(bin_bits);
        let bins = size >> shift;
        let runs = n.div_ceil(SORT_RUN);
        // Per run: its count per bin, where each bin's part starts in its stretch, and its
        // vertices laid out by bin there.
        self.bin_counts.clear();
        self.bin_counts.resize(runs * bins, 0);
        self.bin_offsets.resize(runs * bins, 0);
        self.by_bin.resize(n, 0);
        let buckets = &self.vertex_buckets;
        let mut items: Vec<_> = self
            .bin_counts
            .chunks_mut(bins)
            .zip(self.bin_offsets.chunks_mut(bins))
            .zip(self.by_bin.chunks_mut(SORT_RUN))
            .enumerate()
            .map(|(r, ((counts, offsets), out))| (r * SORT_RUN, counts, offsets, out))
            .collect();
        par.for_each_mut(&mut items, |(first, counts, offsets, out)| {
            let run = &buckets[*first..*first + out.len()];
            for &b in run.iter().filter(|&&b| b != u32::MAX) {
                counts[(b >> shift) as usize] += 1;
            }
            let mut at = [0u32; 1 << BIN_BITS];
            let mut acc = 0;
            for ((a, o), &c) in at.iter_mut().zip(offsets.iter_mut()).zip(counts.iter()) {
                (*a, *o) = (acc, acc);
                acc += c;
            }
            for (k, &b) in run.iter().enumerate().filter(|&(_, &b)| b != u32::MAX) {
                let a = &mut at[(b >> shift) as usize];
                out[*a as usize] = (*first + k) as u32;
                *a += 1;
            }
        });
        // Where each bin's entries go.
        self.bin_start.clear();
        self.bin_start.push(0);
        for b in 0..bins {
            let total: u32 = (0..runs).map(|r| self.bin_counts[r * bins + b]).sum();
            self.bin_start.push(self.bin_start[b] + total);
        }
        let real = self.bin_start[bins] as usize;
        self.entries.resize(real + LANES, 0);
        self.cells.resize(real + LANES, IVec3::ZERO);
        self.start.clear();
        self.start.resize(size + 1, 0);
        self.start[size] = real as u32;
        // Each bin: its buckets' starts and its entries, in parallel.
        let (by_bin, counts, offsets) = (&self.by_bin, &self.bin_counts, &self.bin_offsets);
        let mut entries = &mut self.entries[..real];
        let mut entry_cells = &mut self.cells[..real];
        let mut items = Vec::with_capacity(bins);
        for (b, starts) in self.start[..size].chunks_mut(1 << shift).enumerate() {
            let len = (self.bin_start[b + 1] - self.bin_start[b]) as usize;
            let (e, rest) = entries.split_at_mut(len);
            entries = rest;
            let (c, rest) = entry_cells.split_at_mut(len);
            entry_cells = rest;
            items.push((b, starts, e, c));
        }
        let bin_start = &self.bin_start;
        par.for_each_mut(&mut items, |(b, starts, e, c)| {
            let b = *b;
            let low = (1u32 << shift) - 1;
            let stretch = |r: usize| {
                let at = r * SORT_RUN + offsets[r * bins + b] as usize;
                &by_bin[at..at + counts[r * bins + b] as usize]
            };
            let each = || (0..runs).flat_map(stretch);
            for &j in each() {
                starts[(buckets[j as usize] & low) as usize] += 1;
            }
            let mut acc = 0;
            for s in starts.iter_mut() {
                let count = *s;
                *s = acc;
                acc += count;
            }
            // Placed with the starts as cursors: each ends at its bucket's end, the next
            // bucket's start.
            for &j in each() {
                let s = &mut starts[(buckets[j as usize] & low) as usize];
                e[*s as usize] = j;
                *s += 1;
            }
            // The cells in the entries' order.
            for (c, &j) in c.iter_mut().zip(e.iter()) {
                *c = cells[j as usize];
            }
            starts.rotate_right(1);
            starts[0] = 0;
            for s in starts.iter_mut() {
                *s += bin_start[b];
            }
        });
        real
    }
}

/// `value` of every run of `4 × CHUNK` indices below `len` (the last one shorter), the runs
/// in parallel.
pub(super) fn per_run<R: Send + Default>(
    len: usize,
    par: &impl Parallel,
    value: impl Fn(Range<usize>) -> R + Sync,
) -> Vec<R> {
    let run = 4 * CHUNK;
    let mut runs: Vec<(Range<usize>, R)> = (0..len.div_ceil(run))
        .map(|k| (k * run..((k + 1) * run).min(len), R::default()))
        .collect();
    par.for_each_mut(&mut runs, |(range, out)| *out = value(range.clone()));
    runs.into_iter().map(|r| r.1).collect()
}

/// Whether `a` and `b` are equal, compared in runs in parallel.
pub(super) fn same<T: PartialEq + Sync>(a: &[T], b: &[T], par: &impl Parallel) -> bool {
    a.len() == b.len()
        && per_run(a.len(), par, |r| a[r.clone()] == b[r])
            .into_iter()
            .all(|equal| equal)
}

/// `each(first, run)` for every run of `4 × CHUNK` items of `out` (the last one shorter),
/// `first` its first index, the runs in parallel.
pub(super) fn each_run<T: Send>(
    out: &mut [T],
    par: &impl Parallel,
    each: impl Fn(usize, &mut [T]) + Sync,
) {
    let mut runs: Vec<(usize, &mut [T])> = out
        .chunks_mut(4 * CHUNK)
        .enumerate()
        .map(|(k, run)| (k * 4 * CHUNK, run))
        .collect();
    par.for_each_mut(&mut runs, |(first, run)| each(*first, run));
}

/// `out[i] = value(i)` for every `i`, in runs of `4 × CHUNK` in parallel.
pub(super) fn fill_each<T: Send>(
    out: &mut [T],
    par: &impl Parallel,
    value: impl Fn(usize) -> T + Sync,
) {
    each_run(out, par, |first, run| {
        for (k, o) in run.iter_mut().enumerate() {
            *o = value(first + k);
        }
    });
}

/// `out[k] = value(entries[k])` for every entry.
#[inline]
fn gather(out: &mut [f32], entries: &[u32], value: impl Fn(usize) -> f32) {
    for (o, &i) in out.iter_mut().zip(entries) {
        *o = value(i as usize);
    }
}
