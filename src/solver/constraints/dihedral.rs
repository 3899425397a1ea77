//! Dihedral bending constraint (report §3.1, after Müller et al. 2006, appendix A), with a
//! signed angle.
//!
//! Two triangles `(x1, x2, x3)` and `(x1, x2, x4)` share the edge `x1–x2`. With `p_i = x_i − x1`:
//!
//! ```text
//! n1 = p2×p3/|p2×p3|      n2 = p2×p4/|p2×p4|      d = n1·n2
//! q3 = (p2×n2 + (n1×p2)d)/|p2×p3|
//! q4 = (p2×n1 + (n2×p2)d)/|p2×p4|
//! q2 = −(p3×n2 + (n1×p3)d)/|p2×p3| − (p4×n1 + (n2×p4)d)/|p2×p4|
//! q1 = −q2 − q3 − q4
//! ```
//!
//! The `q_i` are `−∂d/∂p_i`; the report's angle is `θ = arccos d` (π when flat). Here the
//! constraint is the *signed bend angle* `ψ = σ(π − θ)`, `σ = sign((n1×n2)·p2)`: 0 when flat,
//! positive folding one way and negative the other, so a rest shape keeps the direction of its
//! folds as well as their size (`C = ψ − ψ0`). `θ` is taken as `atan2(|n1×n2|, d)` and
//! `√(1−d²)` as `|n1×n2|`: the same values without the rounding noise of `arccos` near a flat
//! pair. `∇ψ = −σ q_i/sin θ`; the XPBD update is written so that it stays finite as
//! `sin θ → 0`:
//!
//! ```text
//! base = k(−C − α̃λ)/(Σ w_j|q_j|² + α̃ sin²θ)      Δp_i = −σ w_i q_i sin θ · base
//! Δλ = sin²θ · base
//! ```
//!
//! The report's PBD update `Δp_i = −w_i √(1−d²)(arccos d − φ0)/Σ_j w_j|q_j|² · q_i` is the
//! `α̃ = 0` case. Each hinge's compliance is divided by its geometric weight
//! ([`dihedral_weight`](crate::solver::mesh::dihedral_weight)), so a compliance `1/B` means the same flexural rigidity `B` at any
//! resolution, as for the [isometric](super::isometric) model.

use super::lanes::{Real, V3};

/// Triangle doubled areas below this are degenerate: no normal, no bending.
pub(crate) const MIN_DOUBLE_AREA: f32 = 1e-12;

/// Correction of one bending constraint: `(Δx1..Δx4, Δλ)`; `rest` is the signed rest bend
/// angle `ψ0`.
#[inline(always)]
pub(crate) fn bend_correction<T: Real>(
    x: [V3<T>; 4],
    w: [T; 4],
    rest: T,
    alpha: T,
    k: T,
    lambda: T,
) -> ([V3<T>; 4], T) {
    let zero = T::splat(0.0);
    let one = T::splat(1.0);
    let eps = T::splat(MIN_DOUBLE_AREA);
    let p2 = x[1] - x[0];
    let p3 = x[2] - x[0];
    let p4 = x[3] - x[0];
    let c23 = p2.cross(p3);
    let c24 = p2.cross(p4);
    let l23 = c23.length_squared().sqrt();
    let l24 = c24.length_squared().sqrt();
    let inv23 = l23.if_gt(eps, one / l23, zero);
    let inv24 = l24.if_gt(eps, one / l24, zero);
    let n1 = c23.scale(inv23);
    let n2 = c24.scale(inv24);
    let d = n1.dot(n2).max(-one).min(one);
    // n1×p2 = −p2×n1 and n2×p2 = −p2×n2: eight cross products instead of ten.
    let p2n1 = p2.cross(n1);
    let p2n2 = p2.cross(n2);
    let q3 = (p2n2 - p2n1.scale(d)).scale(inv23);
    let q4 = (p2n1 - p2n2.scale(d)).scale(inv24);
    let q2 = -(p3.cross(n2) + n1.cross(p3).scale(d)).scale(inv23)
        - (p4.cross(n1) + n2.cross(p4).scale(d)).scale(inv24);
    let q1 = -(q2 + q3 + q4);
    // sin of the angle from |n1×n2|, not √(1−d²): near flat, d ≈ −1 carries a rounding error
    // of ~1e-7 that √(1−d²) and arccos(d) turn into ~5e-4 rad of noise, enough to make a
    // resting cloth jitter forever. |n1×n2| and atan2 stay accurate there.
    let n12 = n1.cross(n2);
    let s = n12.length_squared().sqrt();
    let sigma = n12.dot(p2).if_gt(zero, one, -one);
    // ψ = σ(π − θ) = σ·atan2(s, −d).
    let psi = sigma * s.atan2(-d);
    let c = psi - rest;
    let g = w[0] * q1.length_squared()
        + w[1] * q2.length_squared()
        + w[2] * q3.length_squared()
        + w[3] * q4.length_squared();
    let s2 = s * s;
    let base = k * (-c - alpha * lambda) / (g + alpha * s2);
    // Nothing can move (all four pinned, or gradients that vanish): no correction. Tested on
    // g, not the denominator: with g = 0 a tiny α̃·s² would make it overflow and 0·∞ = NaN.
    let base = g.if_gt(T::splat(1e-20), base, zero);
    // Both triangles must have an area, else the normals (and everything after) are zero.
    let base = l23.if_gt(eps, base, zero);
    let base = l24.if_gt(eps, base, zero);
    let f = -(sigma * s * base);
    (
        [
            q1.scale(w[0] * f),
            q2.scale(w[1] * f),
            q3.scale(w[2] * f),
            q4.scale(w[3] * f),
        ],
        s2 * base,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::hinge::*;
    use glam::Vec3;

    fn l(v: Vec3) -> V3<f32> {
        v.into()
    }

    fn g(v: V3<f32>) -> Vec3 {
        Vec3::new(v.x, v.y, v.z)
    }

    /// Two unit right triangles hinged on the x axis, the second lifted by `lift`.
    fn hinge(lift: f32) -> [Vec3; 4] {
        [
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.5, 0.0, 1.0),
            Vec3::new(0.5, lift, -1.0),
        ]
    }

    fn d_of(x: [Vec3; 4]) -> f32 {
        let (p2, p3, p4) = (x[1] - x[0], x[2] - x[0], x[3] - x[0]);
        p2.cross(p3).normalize().dot(p2.cross(p4).normalize())
    }

    #[test]
    fn q_is_minus_gradient_of_d() {
        // Finite differences (f64 would be nicer; f32 with h = 1e-3 is enough for 1e-2).
        let x = hinge(0.7);
        let xl = x.map(l);
        let (dx, _) = bend_correction(xl, [1.0; 4], 0.0, 0.0, 1.0, 0.0);
        // With rest 0, α̃ 0, k 1 and unit weights, Δx_i = q_i·f for one common f.
        let h = 1e-3;
        let mut grad = [Vec3::ZERO; 4];
        for i in 0..4 {
            for a in 0..3 {
                let mut xp = x;
                let mut xm = x;
                xp[i][a] += h;
                xm[i][a] -= h;
                grad[i][a] = (d_of(xp) - d_of(xm)) / (2.0 * h);
            }
        }
        // Δx_i ∝ −∇d: compare directions through the ratio on the largest component.
        let ratio = g(dx[3]).y / -grad[3].y;
        for i in 0..4 {
            let expect = -grad[i] * ratio;
            assert!(
                (g(dx[i]) - expect).length() < 1e-2 * expect.length().max(1e-3),
                "vertex {i}: {:?} vs {:?}",
                g(dx[i]),
                expect
            );
        }
    }

    #[test]
    fn projection_flattens_a_bent_pair() {
        let x = hinge(0.8);
        let before = dihedral_angle(x);
        let (dx, _) = bend_correction(x.map(l), [1.0; 4], 0.0, 0.0, 1.0, 0.0);
        let after = dihedral_angle([0, 1, 2, 3].map(|i| x[i] + g(dx[i])));
        assert!(before < 2.6, "{before}");
        assert!(
            (core::f32::consts::PI - after) < 0.5 * (core::f32::consts::PI - before),
            "{before} -> {after}"
        );
    }

    #[test]
    fn correction_conserves_momentum() {
        let (dx, _) = bend_correction(hinge(0.5).map(l), [1.0; 4], 0.0, 0.0, 1.0, 0.0);
        let sum: Vec3 = dx.iter().map(|d| g(*d)).sum();
        assert!(sum.length() < 1e-5, "{sum}");
    }

    #[test]
    fn pinned_vertices_do_not_move_and_flat_pairs_are_still() {
        let (dx, _) = bend_correction(hinge(0.5).map(l), [0.0, 0.0, 1.0, 0.0], 0.0, 0.0, 1.0, 0.0);
        assert_eq!(g(dx[0]), Vec3::ZERO);
        assert_eq!(g(dx[3]), Vec3::ZERO);
        assert!(g(dx[2]).length() > 0.0);
        let (flat, _) = bend_correction(hinge(0.0).map(l), [1.0; 4], 0.0, 0.0, 1.0, 0.0);
        assert!(flat.iter().all(|d| g(*d).length() < 1e-6));
    }

    #[test]
    fn degenerate_triangles_give_no_nan() {
        for x in [
            [Vec3::ZERO; 4],
            [Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::new(0.5, 0.0, 1.0)],
            [Vec3::ZERO, Vec3::ZERO, Vec3::Y, Vec3::Z],
        ] {
            for alpha in [0.0, 1.0, f32::MAX] {
                let (dx, dl) = bend_correction(x.map(l), [1.0; 4], 1.0, alpha, 1.0, 0.0);
                assert!(dl.is_finite());
                assert!(dx.iter().all(|d| g(*d).is_finite()), "{x:?} {alpha}");
            }
        }
    }

    #[test]
    fn all_pinned_with_a_tiny_compliance_gives_no_nan() {
        // Nothing can move: no correction, and the multiplier stays put (α̃·sin² alone must not drive it).
        let mut x = hinge(0.8).map(l);
        x[3].x = 3.0e6;
        for alpha in [1e-10, 1e-19, 0.0] {
            let (dx, dl) = bend_correction(x, [0.0; 4], 0.0, alpha, 1.0, 0.0);
            assert_eq!(dl, 0.0, "α̃ {alpha}");
            assert!(dx.iter().all(|d| g(*d) == Vec3::ZERO), "α̃ {alpha}: {dx:?}");
        }
    }

    #[test]
    fn the_signed_angle_keeps_the_direction_of_a_fold() {
        // Folded up by 0.6 rad and down by 0.6 rad: opposite signs, same size.
        let up = hinge(0.5);
        let down = hinge(-0.5);
        let (a, b) = (bend_angle(up), bend_angle(down));
        assert!((a + b).abs() < 1e-5 && a.abs() > 0.3, "{a} {b}");
        assert!(bend_angle(hinge(0.0)).abs() < 1e-6);
        // A pair resting folded down but turned up is driven back through flat, not kept up.
        let mut x = up;
        for _ in 0..40 {
            let (dx, _) = bend_correction(x.map(l), [1.0; 4], b, 0.0, 0.5, 0.0);
            for i in 0..4 {
                x[i] += g(dx[i]);
            }
        }
        assert!((bend_angle(x) - b).abs() < 0.02, "{} vs {b}", bend_angle(x));
    }

    #[test]
    fn hinge_weights_match_the_continuum_at_any_resolution() {
        use crate::solver::mesh::{Grid, TopologyOptions};
        for n in [9u32, 17, 33] {
            let g = Grid::new(n, n, 1.0, 1.0);
            let t = g.topology(TopologyOptions::default()).unwrap();
            let r = 0.8f32;
            let rolled: Vec<Vec3> = g
                .positions()
                .iter()
                .map(|p| {
                    let phi = p.x / r;
                    Vec3::new(r * phi.sin(), r * (1.0 - phi.cos()), p.z)
                })
                .collect();
            let (mut sum, mut area) = (0.0f64, 0.0f64);
            for b in t.bends() {
                let rest = b.v.map(|i| g.positions()[i as usize]);
                let psi = bend_angle(b.v.map(|i| rolled[i as usize]));
                sum += f64::from(dihedral_weight(rest) * psi * psi);
                let e = rest[1] - rest[0];
                area += f64::from(
                    0.5 * (e.cross(rest[2] - rest[0]).length()
                        + e.cross(rest[3] - rest[0]).length()),
                ) / 3.0;
            }
            let ratio = sum / (area / f64::from(r * r));
            assert!((ratio - 1.0).abs() < 0.2, "n {n}: {ratio}");
        }
    }
}
