//! Implicit isometric bending: stiff bending that holds at any resolution.
//!
//! The isometric bending energy (see [`hinge_coefficients`](crate::solver::mesh::hinge_coefficients)) is
//! quadratic in the positions, `E = ½ x·K x` with a constant matrix
//! `K = B Σ_hinges a aᵀ` (one scalar per vertex pair, the same for x, y and z). Projecting
//! it hinge by hinge (XPBD) enforces it only while a substep can carry the stiffness:
//! a hinge's projection weight `g = Σ w_i a_i²` against its compliance `α̃ = 1/(B h²)` is the
//! *saturation* `R = B h² g`. With `R ≪ 1` one projection per substep applies the hinge's
//! force exactly; with `R ≫ 1` each projection flattens its hinge locally but the stiffness
//! cannot travel across the cloth in one Gauss–Seidel sweep, and the cloth is far softer than
//! set (a 1 m strip of 16 × 64 vertices droops the same at any `B`). `R` grows with the
//! fourth power of the resolution (`g ∝ 1/(ρ d⁴)` at spacing `d`).
//!
//! Implicit Euler on the bending alone removes the limit: each substep solves
//!
//! ```text
//! (M + h² K) δ = −h² K x̃      (free vertices; pins fixed)
//! ```
//!
//! for the correction `δ` of the predicted positions `x̃`, then the distance constraints are
//! projected as usual. `M + h² K` only changes with the pins, masses, `B`, `h` or the
//! topology, so it is factored once (banded `L D Lᵀ` in a reverse Cuthill–McKee order, f64)
//! and each substep costs two triangular sweeps: `2 · n · b` multiply–adds per coordinate for
//! `n` free vertices and band `b` (a hinge spans three rows of a grid, so `b` is about twice
//! the grid's short side).

use glam::{Vec4, Vec4Swizzles};

use super::solver::BendingSolve;
use crate::solver::mesh::Topology;

/// Saturation `R` above which [`BendingSolve::Auto`] solves bending implicitly. Measured on
/// the cantilever (`tests/stiffness.rs`): below it the projected droop is within a few per
/// cent of the implicit one.
pub const IMPLICIT_BENDING_SATURATION: f32 = 0.5;

/// Largest *gravity number* `ρ g L³ / B` at which [`BendingSolve::Auto`] solves bending
/// implicitly: `ρ` the cloth's mass over its rest area, `g` gravity's magnitude, `L` the
/// longest side of its rest shape's bounding box, `B` its rigidity (the cantilever's
/// `q L³ / B` of `tests/stiffness.rs`). Past it the cloth's weight shapes it and its
/// bending barely does: measured on the cantilever (1 m strip, 16 × 64 and 8 × 32, 10
/// substeps), the projected and implicit droops differ by 11 % of the free length at 30, 4 %
/// at 100, 1.3 % at 300 and 0.3 % at 1000, while the implicit step costs 2.5–9 times the
/// projected one. The plugin's default cloth, 1 m square (0.2 kg, `B` = 1e-4 N·m), is at about
/// 20 000: projected, at any resolution.
pub const IMPLICIT_BENDING_GRAVITY_NUMBER: f32 = 300.0;

/// Largest `n · b` (free vertices × band) [`BendingSolve::Auto`] solves implicitly: a 64 × 64
/// grid (4096 free vertices, band 129). Beyond it the solve costs more than the rest of the step, and the
/// projected bending is used (softer than set; [`Simulation::bending_saturation`] says by how
/// much).
///
/// [`Simulation::bending_saturation`]: crate::solver::Simulation::bending_saturation
pub const IMPLICIT_BENDING_AUTO_WORK: usize = 600_000;

/// Largest `n · b` [`BendingSolve::Implicit`] takes (64 MB of factor, a 160 × 160 grid).
pub const IMPLICIT_BENDING_MAX_WORK: usize = 8_000_000;

/// Saturation the implicit solve is built for at most (200 000 times the one where it starts):
/// a stiffer setting is solved as if its `B` gave this `R`, a plate that bends 1e5 times less
/// per substep than one projection could. Beyond it the right-hand side `−h² K x̃`, summed
/// in `f32`, would carry rounding errors of about `R·1e-7` times the substep's motion into
/// the directions `K` does not stiffen (the proptest suite found a 1 mm cloth with
/// `B` = 1e9 N·m, `R` ≈ 1e14, thrown 1e17 m and reset every step).
pub const IMPLICIT_BENDING_MAX_SATURATION: f32 = 1e5;

/// `h` may drift this much (relative) before the factor is rebuilt: a variable frame time
/// does not refactor every step, and implicit Euler is stable for any `h`.
const H_SLACK: f32 = 0.1;

const NONE: u32 = u32::MAX;

/// What the factor was built for.
#[derive(Clone, Debug, PartialEq)]
struct Key {
    vertices: usize,
    bends: usize,
    rigidity: f32,
    h: f32,
    solve: BendingSolve,
    /// Gravity's magnitude.
    gravity: f32,
    /// Inverse masses, bit for bit (pins are zero).
    inv_mass: Vec<u32>,
}

impl Key {
    /// Whether a factor built for `self` serves this step (no allocation).
    fn serves(
        &self,
        positions: &[Vec4],
        bends: usize,
        rigidity: f32,
        h: f32,
        (solve, gravity): (BendingSolve, f32),
    ) -> bool {
        self.vertices == positions.len()
            && self.bends == bends
            && self.rigidity == rigidity
            && self.solve == solve
            && self.gravity == gravity
            && (h / self.h - 1.0).abs() <= H_SLACK
            && self.inv_mass.len() == positions.len()
            // Branch-free: this runs every step over every vertex.
            && !self
                .inv_mass
                .iter()
                .zip(positions)
                .fold(false, |changed, (&w, p)| changed | (w != p.w.to_bits()))
    }
}

/// The factored `M + h² K` of one cloth and the scratch of its solves.
#[derive(Clone, Debug, Default)]
pub(crate) struct ImplicitBending {
    key: Option<Key>,
    active: bool,
    saturation: f32,
    /// The `B` the factor was built with (capped at [`IMPLICIT_BENDING_MAX_SATURATION`]).
    rigidity: f32,
    /// Vertex → row (free vertices), [`NONE`] for pins.
    row: Vec<u32>,
    /// Band width.
    band: usize,
    /// Row `i` holds `L[i][i−band..i]` at `i·band ..` (factored in f64, kept in f32: the
    /// sweeps run four lanes at a time).
    lower: Vec<f32>,
    inv_diag: Vec<f32>,
    rhs: Vec<Vec4>,
}

impl ImplicitBending {
    /// Forgets the factor (the topology changed).
    pub(crate) fn invalidate(&mut self) {
        self.key = None;
        self.active = false;
    }

    /// Largest saturation `R` of the cloth's hinges at the last prepared step.
    pub(crate) fn saturation(&self) -> f32 {
        self.saturation
    }

    /// Whether the last prepared step solved bending implicitly.
    pub(crate) fn active(&self) -> bool {
        self.active
    }

    /// Decides whether this step solves bending implicitly and (re)factors if anything the
    /// matrix depends on changed. `rigidity` is `B` (0 or non-finite: no bending), `gravity`
    /// gravity's magnitude.
    pub(crate) fn prepare(
        &mut self,
        topology: &Topology,
        positions: &[Vec4],
        rigidity: f32,
        h: f32,
        (solve, gravity): (BendingSolve, f32),
    ) -> bool {
        let bends = topology.bends().len();
        if self
            .key
            .as_ref()
            .is_some_and(|k| k.serves(positions, bends, rigidity, h, (solve, gravity)))
        {
            return self.active;
        }
        let key = Key {
            vertices: positions.len(),
            bends,
            rigidity,
            h,
            solve,
            gravity,
            inv_mass: positions.iter().map(|p| p.w.to_bits()).collect(),
        };
        self.saturation = saturation(topology, positions, rigidity, h);
        self.active = false;
        let weight = match solve {
            BendingSolve::Auto => gravity_number(topology, positions, rigidity, gravity),
            _ => 0.0,
        };
        if wants_implicit(self.saturation, weight, rigidity, solve) {
            let limit = match solve {
                BendingSolve::Auto => IMPLICIT_BENDING_AUTO_WORK,
                _ => IMPLICIT_BENDING_MAX_WORK,
            };
            self.rigidity = if self.saturation > IMPLICIT_BENDING_MAX_SATURATION {
                rigidity * (IMPLICIT_BENDING_MAX_SATURATION / self.saturation)
            } else {
                rigidity
            };
            self.active = self.factor(topology, positions, self.rigidity, h, limit);
        }
        self.key = Some(key);
        self.active
    }

    /// Whether a step would want the implicit solve (before trying to
    /// factor: a system too big to factor falls back to projection).
    pub(crate) fn wanted(
        topology: &Topology,
        positions: &[Vec4],
        rigidity: f32,
        h: f32,
        (solve, gravity): (BendingSolve, f32),
    ) -> bool {
        // The saturation and the weight only matter (and are only computed) for `Auto`.
        let (s, weight) = match solve {
            BendingSolve::Auto => (
                saturation(topology, positions, rigidity, h),
                gravity_number(topology, positions, rigidity, gravity),
            ),
            _ => (0.0, 0.0),
        };
        wants_implicit(s, weight, rigidity, solve)
    }

    /// Orders the free vertices, assembles `M + h² K` in band form and factors it. False if
    /// it is too big or not positive definite (it always is with positive masses).
    fn factor(
        &mut self,
        topology: &Topology,
        positions: &[Vec4],
        rigidity: f32,
        h: f32,
        limit: usize,
    ) -> bool {
        let n_all = positions.len();
        let free = |v: u32| positions[v as usize].w > 0.0;
        // Adjacency of the free vertices through hinges (CSR), for the ordering.
        let mut degree = vec![0u32; n_all + 1];
        for b in topology.bends() {
            for i in 0..4 {
                for j in 0..4 {
                    if i != j && free(b.v[i]) && free(b.v[j]) {
                        degree[b.v[i] as usize + 1] += 1;
                    }
                }
            }
        }
        for i in 0..n_all {
            degree[i + 1] += degree[i];
        }
        let start = degree;
        let mut fill = start.clone();
        let mut adj = vec![0u32; start[n_all] as usize];
        for b in topology.bends() {
            for i in 0..4 {
                for j in 0..4 {
                    if i != j && free(b.v[i]) && free(b.v[j]) {
                        let f = &mut fill[b.v[i] as usize];
                        adj[*f as usize] = b.v[j];
                        *f += 1;
                    }
                }
            }
        }
        let neighbours = |v: u32| &adj[start[v as usize] as usize..start[v as usize + 1] as usize];
        // Reverse Cuthill–McKee, or the mesh's own order if that has the narrower band (a
        // grid stored along its short side already has the narrowest).
        let band_of = |order: &[u32]| -> usize {
            let mut row = vec![NONE; n_all];
            for (r, &v) in order.iter().enumerate() {
                row[v as usize] = r as u32;
            }
            let mut band = 0usize;
            for b in topology.bends() {
                for i in 0..4 {
                    for j in 0..4 {
                        let (ri, rj) = (row[b.v[i] as usize], row[b.v[j] as usize]);
                        if ri != NONE && rj != NONE {
                            band = band.max(ri.abs_diff(rj) as usize);
                        }
                    }
                }
            }
            band
        };
        let rcm = reverse_cuthill_mckee(n_all, &free, &neighbours);
        let natural: Vec<u32> = (0..n_all as u32).filter(|&v| free(v)).collect();
        let (rcm_band, natural_band) = (band_of(&rcm), band_of(&natural));
        let (order, band) = if rcm_band <= natural_band {
            (rcm, rcm_band)
        } else {
            (natural, natural_band)
        };
        self.row.clear();
        self.row.resize(n_all, NONE);
        for (r, &v) in order.iter().enumerate() {
            self.row[v as usize] = r as u32;
        }
        let n = order.len();
        let band = band.max(1);
        if n.saturating_mul(band) > limit {
            return false;
        }
        self.band = band;
        // Assemble: diag = m + h²B Σ a², lower[i][j] = h²B Σ a_i a_j.
        let s = f64::from(h) * f64::from(h) * f64::from(rigidity);
        let mut lower = vec![0.0f64; n * band];
        let mut diag: Vec<f64> = order
            .iter()
            .map(|&v| 1.0 / f64::from(positions[v as usize].w))
            .collect();
        for b in topology.bends() {
            for i in 0..4 {
                let ri = self.row[b.v[i] as usize];
                if ri == NONE {
                    continue;
                }
                let ai = f64::from(b.coeffs[i]);
                for j in 0..4 {
                    let rj = self.row[b.v[j] as usize];
                    if rj == NONE {
                        continue;
                    }
                    let k = s * ai * f64::from(b.coeffs[j]);
                    if ri == rj {
                        diag[ri as usize] += k;
                    } else if rj < ri {
                        let (ri, rj) = (ri as usize, rj as usize);
                        lower[ri * band + rj + band - ri] += k;
                    }
                }
            }
        }
        // Banded L D Lᵀ, row by row: L[i][j] = (A[i][j] − Σ_k L[i][k] L[j][k] D[k]) / D[j].
        let mut d = vec![0.0f64; n];
        for i in 0..n {
            let lo = i.saturating_sub(band);
            for j in lo..i {
                let klo = lo.max(j.saturating_sub(band));
                let mut sum = lower[i * band + j + band - i];
                for k in klo..j {
                    sum -= lower[i * band + k + band - i] * lower[j * band + k + band - j] * d[k];
                }
                lower[i * band + j + band - i] = sum / d[j];
            }
            let mut di = diag[i];
            for k in lo..i {
                let l = lower[i * band + k + band - i];
                di -= l * l * d[k];
            }
            if !(di.is_finite() && di > 0.0) {
                return false;
            }
            d[i] = di;
        }
        self.lower = lower.iter().map(|&l| l as f32).collect();
        self.inv_diag = d.iter().map(|d| (1.0 / d) as f32).collect();
        self.rhs.clear();
        self.rhs.resize(n, Vec4::ZERO);
        true
    }

    /// One implicit bending solve: moves the free vertices of `positions` (the predicted
    /// positions of this substep) by `δ` with `(M + h²K) δ = −h² K x̃`. Call only after
    /// [`Self::prepare`] returned true for the same cloth.
    pub(crate) fn solve(&mut self, topology: &Topology, positions: &mut [Vec4], h: f32) {
        let s = f64::from(h) * f64::from(h) * f64::from(self.rigidity);
        self.rhs.fill(Vec4::ZERO);
        // −h² K x̃, hinge by hinge; C = Σ a_i (x_i − x_0) (Σ a_i = 0) keeps far-away cloths
        // exact.
        for b in topology.bends() {
            let x0 = positions[b.v[0] as usize].xyz();
            let mut c = [0.0f64; 3];
            for i in 1..4 {
                let d = positions[b.v[i] as usize].xyz() - x0;
                let a = f64::from(b.coeffs[i]);
                c[0] += a * f64::from(d.x);
                c[1] += a * f64::from(d.y);
                c[2] += a * f64::from(d.z);
            }
            for i in 0..4 {
                let r = self.row[b.v[i] as usize];
                if r != NONE {
                    let f = -s * f64::from(b.coeffs[i]);
                    let c = Vec4::new((f * c[0]) as f32, (f * c[1]) as f32, (f * c[2]) as f32, 0.0);
                    self.rhs[r as usize] += c;
                }
            }
        }
        let (band, n) = (self.band, self.rhs.len());
        // L y = r.
        for i in 0..n {
            let lo = i.saturating_sub(band);
            let row = &self.lower[i * band + lo + band - i..i * band + band];
            let mut acc = self.rhs[i];
            for (&l, y) in row.iter().zip(&self.rhs[lo..i]) {
                acc -= *y * l;
            }
            self.rhs[i] = acc;
        }
        // D z = y.
        for (r, &d) in self.rhs.iter_mut().zip(&self.inv_diag) {
            *r *= d;
        }
        // Lᵀ δ = z, row by row from the end: δ_i is final, then pushed into the rows above.
        for i in (0..n).rev() {
            let lo = i.saturating_sub(band);
            let xi = self.rhs[i];
            let row = &self.lower[i * band + lo + band - i..i * band + band];
            for (&l, y) in row.iter().zip(&mut self.rhs[lo..i]) {
                *y -= xi * l;
            }
        }
        for (p, &r) in positions.iter_mut().zip(&self.row) {
            if r != NONE {
                let d = self.rhs[r as usize];
                p.x += d.x;
                p.y += d.y;
                p.z += d.z;
            }
        }
    }
}

/// Largest `B h² Σ w_i a_i²` over the hinges.
/// The implicit solve is wanted: asked for, or under `Auto` with bending saturated past
/// [`IMPLICIT_BENDING_SATURATION`] on a cloth whose bending shapes it against its weight
/// (`weight`, its gravity number, under [`IMPLICIT_BENDING_GRAVITY_NUMBER`]); never without a
/// finite, positive rigidity.
fn wants_implicit(saturation: f32, weight: f32, rigidity: f32, solve: BendingSolve) -> bool {
    let wanted = match solve {
        BendingSolve::Projected => false,
        BendingSolve::Implicit => true,
        BendingSolve::Auto => {
            saturation > IMPLICIT_BENDING_SATURATION && weight < IMPLICIT_BENDING_GRAVITY_NUMBER
        }
    };
    wanted && rigidity.is_finite() && rigidity > 0.0
}

/// The cloth's gravity number `ρ g L³ / B` (see [`IMPLICIT_BENDING_GRAVITY_NUMBER`]), `ρ`
/// from its free vertices' masses over their share of the rest area (a third of each
/// triangle's); zero without gravity, rigidity, free vertices or area.
fn gravity_number(topology: &Topology, positions: &[Vec4], rigidity: f32, gravity: f32) -> f32 {
    if !(rigidity.is_finite() && rigidity > 0.0 && gravity.is_finite() && gravity > 0.0) {
        return 0.0;
    }
    let rest = topology.rest_positions();
    let free = |v: u32| positions.get(v as usize).is_some_and(|p| p.w > 0.0);
    let mut area = 0.0f64;
    for t in topology.triangles() {
        let [a, b, c] = t.map(|v| rest[v as usize]);
        let third = f64::from((b - a).cross(c - a).length()) / 6.0;
        area += third * t.iter().filter(|&&v| free(v)).count() as f64;
    }
    let mass: f64 = positions
        .iter()
        .filter(|p| p.w > 0.0)
        .map(|p| 1.0 / f64::from(p.w))
        .sum();
    let (lo, hi) = rest.iter().fold(
        (
            glam::Vec3::splat(f32::INFINITY),
            glam::Vec3::splat(f32::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let size = f64::from((hi - lo).max_element());
    let number = mass / area * f64::from(gravity) * size.powi(3) / f64::from(rigidity);
    if number.is_finite() {
        number as f32
    } else {
        0.0
    }
}

fn saturation(topology: &Topology, positions: &[Vec4], rigidity: f32, h: f32) -> f32 {
    if !(rigidity.is_finite() && rigidity > 0.0) {
        return 0.0;
    }
    let g = topology
        .bends()
        .iter()
        .map(|b| {
            (0..4)
                .map(|i| positions[b.v[i] as usize].w * b.coeffs[i] * b.coeffs[i])
                .sum::<f32>()
        })
        .fold(0.0f32, f32::max);
    rigidity * h * h * g
}

/// Reverse Cuthill–McKee order of the vertices `keep` accepts: each connected piece
/// breadth-first from a far-out vertex (the end of a breadth-first search from one of least
/// degree), neighbours by rising degree, the whole order reversed. Gives a band about twice
/// a grid's short side.
fn reverse_cuthill_mckee<'a>(
    n: usize,
    keep: &impl Fn(u32) -> bool,
    neighbours: &impl Fn(u32) -> &'a [u32],
) -> Vec<u32> {
    let mut seen = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut by_degree: Vec<u32> = (0..n as u32).filter(|&v| keep(v)).collect();
    by_degree.sort_by_key(|&v| neighbours(v).len());
    let mut level = vec![0u32; n];
    let mut queue = Vec::new();
    let mut next = Vec::new();
    for &seed in &by_degree {
        if seen[seed as usize] {
            continue;
        }
        // A far-out start: the last vertex a breadth-first search from `seed` reaches.
        queue.clear();
        queue.push(seed);
        level[seed as usize] = 1;
        let mut head = 0;
        while head < queue.len() {
            let v = queue[head];
            head += 1;
            for &u in neighbours(v) {
                if level[u as usize] == 0 {
                    level[u as usize] = 1;
                    queue.push(u);
                }
            }
        }
        let start = *queue.last().unwrap_or(&seed);
        for &v in &queue {
            level[v as usize] = 0;
        }
        let first = order.len();
        order.push(start);
        seen[start as usize] = true;
        let mut head = first;
        while head < order.len() {
            let v = order[head];
            head += 1;
            next.clear();
            next.extend(neighbours(v).iter().copied().filter(|&u| !seen[u as usize]));
            next.sort_unstable();
            next.dedup();
            next.sort_by_key(|&u| neighbours(u).len());
            for &u in &next {
                seen[u as usize] = true;
                order.push(u);
            }
        }
    }
    order.reverse();
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::{Grid, TopologyOptions};
    use glam::Vec3;

    fn sheet(cols: u32, rows: u32) -> (Topology, Vec<Vec4>) {
        let g = Grid::new(cols, rows, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let p = g
            .positions()
            .iter()
            .enumerate()
            .map(|(i, p)| p.extend(if i < cols as usize { 0.0 } else { 50.0 }))
            .collect();
        (t, p)
    }

    /// The band solve gives the same δ as the dense equations it stands for.
    #[test]
    fn solve_satisfies_the_implicit_equations() {
        let (t, mut p) = sheet(5, 7);
        // Bend it.
        for (i, x) in p.iter_mut().enumerate() {
            x.y = 0.1 * ((i * 7) % 5) as f32 * (x.z + 0.3);
        }
        let before = p.clone();
        let (b, h) = (0.03f32, 0.01f32);
        let mut ib = ImplicitBending::default();
        assert!(ib.prepare(&t, &p, b, h, (BendingSolve::Implicit, 0.0)));
        assert!(ib.band <= 11, "band {} for a 5-wide sheet", ib.band);
        ib.solve(&t, &mut p, h);
        // Residual of (M + h²K) δ + h²K x̃ = 0 per free vertex, with K applied hinge by hinge.
        let delta: Vec<Vec3> = p
            .iter()
            .zip(&before)
            .map(|(a, b)| (*a - *b).xyz())
            .collect();
        let mut k_after = vec![Vec3::ZERO; p.len()];
        for bend in t.bends() {
            let c: Vec3 = (0..4)
                .map(|i| p[bend.v[i] as usize].xyz() * bend.coeffs[i])
                .sum();
            for i in 0..4 {
                k_after[bend.v[i] as usize] += c * bend.coeffs[i] * b;
            }
        }
        let mut worst = 0.0f32;
        for (i, x) in before.iter().enumerate() {
            if x.w == 0.0 {
                assert_eq!(delta[i], Vec3::ZERO, "pins stay");
                continue;
            }
            let r = delta[i] / x.w + k_after[i] * h * h;
            worst = worst.max(r.length() / (delta[i] / x.w).length().max(1e-6));
        }
        assert!(worst < 1e-3, "relative residual {worst}");
        assert!(
            delta.iter().any(|d| d.length() > 1e-4),
            "the solve moved nothing"
        );
    }

    #[test]
    fn the_factor_is_kept_until_something_it_depends_on_changes() {
        let (t, p) = sheet(6, 6);
        let mut ib = ImplicitBending::default();
        assert!(
            ib.prepare(&t, &p, 1.0, 0.01, (BendingSolve::Auto, 0.0)),
            "stiff: implicit"
        );
        let band = ib.band;
        ib.band = 0;
        assert!(ib.prepare(&t, &p, 1.0, 0.0105, (BendingSolve::Auto, 0.0)));
        assert_eq!(ib.band, 0, "h within the slack: no refactor");
        assert!(ib.prepare(&t, &p, 1.0, 0.02, (BendingSolve::Auto, 0.0)));
        assert_eq!(ib.band, band, "h doubled: refactored");
        assert!(
            !ib.prepare(&t, &p, 1e-9, 0.01, (BendingSolve::Auto, 0.0)),
            "soft: projected"
        );
        assert!(ib.saturation() < IMPLICIT_BENDING_SATURATION);
        assert!(!ib.prepare(&t, &p, 1.0, 0.01, (BendingSolve::Projected, 0.0)));
        let mut pinned = p.clone();
        pinned[20].w = 0.0;
        assert!(ib.prepare(&t, &pinned, 1.0, 0.01, (BendingSolve::Implicit, 0.0)));
        assert_eq!(ib.row[20], NONE, "a new pin leaves the system");
    }

    /// The sheet of [`sheet`] (1 m square, row 0 pinned, 0.02 kg a free vertex): 0.6 kg free
    /// over 0.9 m² (the free corners' thirds of 50 triangles of 0.02 m², the top row's 15
    /// corners left out), so `ρ g L³ / B` = 0.6 / 0.9 · g / B. Stiff (`B` = 1) under
    /// Earth's gravity it is solved implicitly; under a hundred times that its weight shapes
    /// it, and `Auto` projects it (still saturated); asked for, it is solved implicitly.
    #[test]
    fn auto_projects_a_cloth_its_weight_shapes() {
        let (t, p) = sheet(6, 6);
        let want = 0.6 / 0.9 * 9.81;
        let got = gravity_number(&t, &p, 1.0, 9.81);
        assert!((got / want - 1.0).abs() < 1e-4, "{got} against {want}");
        assert_eq!(gravity_number(&t, &p, 1.0, 0.0), 0.0, "no gravity");
        let mut ib = ImplicitBending::default();
        assert!(ib.prepare(&t, &p, 1.0, 0.01, (BendingSolve::Auto, 9.81)));
        let heavy = 100.0 * 9.81;
        assert!(gravity_number(&t, &p, 1.0, heavy) > IMPLICIT_BENDING_GRAVITY_NUMBER);
        assert!(
            !ib.prepare(&t, &p, 1.0, 0.01, (BendingSolve::Auto, heavy)),
            "a new gravity is decided again: projected"
        );
        assert!(ib.saturation() > IMPLICIT_BENDING_SATURATION);
        assert!(ib.prepare(&t, &p, 1.0, 0.01, (BendingSolve::Implicit, heavy)));
    }

    #[test]
    fn a_grid_orders_to_a_band_twice_as_wide_as_its_short_side() {
        let (t, p) = sheet(40, 8);
        let mut ib = ImplicitBending::default();
        assert!(ib.prepare(&t, &p, 1.0, 0.01, (BendingSolve::Implicit, 0.0)));
        assert!(ib.band <= 17, "band {} for an 8-wide strip", ib.band);
    }
}
