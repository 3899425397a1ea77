//! Isometric bending (Bergou, Wardetzky, Harmon, Zorin, Grinspun 2006, "A Quadratic Bending
//! Model for Inextensible Surfaces"): the default bending model for cloth that is flat at rest.
//!
//! For a hinge — two triangles `(x0, x1, x2)` and `(x0, x1, x3)` sharing the edge `x0–x1` —
//! the discrete mean-curvature vector is linear in the positions,
//! `H = Σ K_i x_i` with the cotangent weights of the hinge's four corner angles:
//!
//! ```text
//! K = [c03 + c04,  c01 + c02,  −c01 − c03,  −c02 − c04]
//! ```
//!
//! (`c0k`: cotangent of the angle at `x0` between the shared edge and the edge to `x_k`;
//! `c0k` with `k ≥ 3` likewise at `x1`). `Σ K_i = 0` and `H = 0` for any flat configuration.
//! The bending energy of a hinge is `E = ½ B · (3/(A0 + A1)) · |H|² · κ_scale`, which for an
//! inextensible cloth converges to the continuum `½ B ∫ (2H)² dA` (`B`: flexural rigidity in
//! N·m). Its Hessian is constant, so as a vector constraint `C = Σ a_i x_i` with
//! `a_i = √(3 κ_scale/(A0 + A1))·K_i` the XPBD projection is exact and cheap:
//!
//! ```text
//! Δλ = −k (C + α̃ λ) / (Σ w_i a_i² + α̃)       (a 3-vector, one scalar division)
//! Δx_i = w_i a_i Δλ
//! ```
//!
//! with `α̃ = α/h²`, `α = 1/B`. `Σ a_i = 0`, so the correction never moves the centre of mass.
//! The weights `a_i` are computed once from the rest shape ([`hinge_coefficients`](crate::solver::mesh::hinge_coefficients)); they make
//! the stiffness a material constant, the same at any mesh resolution (where one projection per
//! substep cannot carry it, the step solves the same energy implicitly: see `implicit.rs`).

use super::lanes::{Real, V3};

/// Correction of one isometric bending constraint: `(Δx0..Δx3, Δλ)`.
///
/// `a`: the hinge's coefficients; `alpha`: `α̃`; `k`: PBD stiffness (1 for XPBD); `lambda`:
/// the accumulated multiplier (zero with one iteration).
#[inline(always)]
pub(crate) fn iso_correction<T: Real>(
    x: [V3<T>; 4],
    w: [T; 4],
    a: [T; 4],
    alpha: T,
    k: T,
    lambda: V3<T>,
) -> ([V3<T>; 4], V3<T>) {
    let zero = T::splat(0.0);
    let c = x[0].scale(a[0]) + x[1].scale(a[1]) + x[2].scale(a[2]) + x[3].scale(a[3]);
    let g = w[0] * a[0] * a[0] + w[1] * a[1] * a[1] + w[2] * a[2] * a[2] + w[3] * a[3] * a[3];
    // Nothing can move (or a shapeless hinge): no correction, and no 0/0.
    let scale = g.if_gt(T::splat(1e-20), -k / (g + alpha), zero);
    let dl = (c + lambda.scale(alpha)).scale(scale);
    (
        [
            dl.scale(w[0] * a[0]),
            dl.scale(w[1] * a[1]),
            dl.scale(w[2] * a[2]),
            dl.scale(w[3] * a[3]),
        ],
        dl,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::mesh::hinge::*;
    use crate::solver::mesh::{Grid, TopologyOptions};
    use glam::Vec3;

    fn l(v: Vec3) -> V3<f32> {
        v.into()
    }

    fn hinge(lift: f32) -> [Vec3; 4] {
        [
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.3, lift, 1.0),
            Vec3::new(0.6, lift, -0.8),
        ]
    }

    #[test]
    fn flat_hinges_have_no_curvature_and_weights_sum_to_zero() {
        let a = hinge_coefficients(hinge(0.0));
        assert!(a.iter().sum::<f32>().abs() < 1e-5);
        assert!(hinge_curvature(hinge(0.0), a).length() < 1e-5);
        // A rigid motion keeps |C|.
        let bent = hinge(0.4);
        let c = hinge_curvature(bent, a).length();
        let r = glam::Quat::from_rotation_y(1.1) * glam::Quat::from_rotation_x(0.3);
        let moved = bent.map(|p| r * p + Vec3::new(3.0, -1.0, 2.0));
        assert!((hinge_curvature(moved, a).length() - c).abs() < 1e-5);
        assert!(c > 0.1);
    }

    #[test]
    fn one_projection_flattens_a_free_hinge_and_keeps_its_centre() {
        let x = hinge(0.5);
        let a = hinge_coefficients(hinge(0.0));
        let (dx, _) = iso_correction(x.map(l), [1.0; 4], a, 0.0, 1.0, l(Vec3::ZERO));
        let after: Vec<Vec3> = (0..4)
            .map(|i| x[i] + Vec3::new(dx[i].x, dx[i].y, dx[i].z))
            .collect();
        assert!(hinge_curvature([after[0], after[1], after[2], after[3]], a).length() < 1e-5);
        let moved: Vec3 = dx.iter().map(|d| Vec3::new(d.x, d.y, d.z)).sum();
        assert!(moved.length() < 1e-5);
        // Pinned corners stay; nothing free: nothing moves.
        let (dx, dl) = iso_correction(x.map(l), [0.0; 4], a, 1e-30, 1.0, l(Vec3::ZERO));
        assert!(dx.iter().all(|d| d.x == 0.0 && d.y == 0.0 && d.z == 0.0));
        assert!(dl.x == 0.0 && dl.y == 0.0 && dl.z == 0.0);
    }

    #[test]
    fn degenerate_hinges_get_no_bending() {
        let x = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::new(0.5, 0.0, 1.0)];
        assert_eq!(hinge_coefficients(x), [0.0; 4]);
        assert_eq!(hinge_coefficients([Vec3::ZERO; 4]), [0.0; 4]);
    }

    /// `Σ_hinges |C|²` of a grid rolled into a cylinder of radius `r` around an axis at
    /// `angle` in the grid's plane, over the continuum `∫ κ² dA` of its interior.
    fn cylinder_ratio(n: u32, r: f32, angle: f32) -> f32 {
        let g = Grid::new(n, n, 1.0, 1.0);
        let t = g.topology(TopologyOptions::default()).unwrap();
        let (c, s) = (angle.cos(), angle.sin());
        let rolled: Vec<Vec3> = g
            .positions()
            .iter()
            .map(|p| {
                // u across the axis, v along it; roll u onto the circle.
                let u = p.x * c + p.z * s;
                let v = -p.x * s + p.z * c;
                let phi = u / r;
                let across = Vec3::new(c, 0.0, s);
                let along = Vec3::new(-s, 0.0, c);
                across * (r * phi.sin()) + Vec3::Y * (r * (1.0 - phi.cos())) + along * v
            })
            .collect();
        let mut sum = 0.0f64;
        let mut area = 0.0f64;
        for b in t.bends() {
            let rest = b.v.map(|i| g.positions()[i as usize]);
            let a = hinge_coefficients(rest);
            let x = b.v.map(|i| rolled[i as usize]);
            sum += f64::from(hinge_curvature(x, a).length_squared());
            let tri = |k: u32| {
                0.5 * (rest[1] - rest[0])
                    .cross(g.positions()[k as usize] - rest[0])
                    .length()
            };
            area += f64::from(tri(b.v[2]) + tri(b.v[3])) / 3.0;
        }
        (sum / (area / f64::from(r * r))) as f32
    }

    #[test]
    fn hinge_energy_matches_the_continuum_at_any_resolution_and_direction() {
        for n in [9, 17, 33] {
            for angle in [0.0, 0.4, core::f32::consts::FRAC_PI_4] {
                let ratio = cylinder_ratio(n, 0.8, angle);
                // ±15 % across directions is the triangulation's own anisotropy.
                assert!((ratio - 1.0).abs() < 0.2, "n {n}, axis {angle}: {ratio}");
            }
        }
    }
}
