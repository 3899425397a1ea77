//! Hinge geometry: the shape of two triangles sharing an edge, measured once from the rest
//! shape (bend angles, dihedral weights, isometric coefficients) and by the metrics.
//!
//! The bending constraints (`constraints/dihedral.rs`, `constraints/isometric.rs`) project
//! with these values; they live here, with the topology that stores them.

use glam::Vec3;

/// Calibration of the hinge energy against the continuum `½ B ∫ κ² dA` for cylindrical
/// bending: measured on regular grids (one diagonal per quad) rolled into cylinders, the
/// uncalibrated sum is 2.4–3.3 × the continuum depending on the roll's direction against the
/// diagonals (2.85 on average, the same at 9², 17² and 33²); see the tests.
pub(crate) const KAPPA_SCALE: f32 = 1.0 / 2.85;

/// Triangle areas below this: the hinge has no shape and gets no bending.
const MIN_AREA: f32 = 1e-12;

/// `a_i` of the hinge `(x0, x1, x2, x3)` (shared edge `x0–x1`) in its rest shape; zero for a
/// hinge with a degenerate triangle.
#[must_use]
pub fn hinge_coefficients(x: [Vec3; 4]) -> [f32; 4] {
    let cot = |o: Vec3, a: Vec3, b: Vec3| -> Option<f32> {
        let (u, v) = (a - o, b - o);
        let s = u.cross(v).length();
        (s > MIN_AREA).then(|| u.dot(v) / s)
    };
    let area0 = 0.5 * (x[1] - x[0]).cross(x[2] - x[0]).length();
    let area1 = 0.5 * (x[1] - x[0]).cross(x[3] - x[0]).length();
    let (Some(c01), Some(c02), Some(c03), Some(c04)) = (
        cot(x[0], x[1], x[2]),
        cot(x[0], x[1], x[3]),
        cot(x[1], x[0], x[2]),
        cot(x[1], x[0], x[3]),
    ) else {
        return [0.0; 4];
    };
    if area0 <= MIN_AREA || area1 <= MIN_AREA {
        return [0.0; 4];
    }
    let s = (3.0 * KAPPA_SCALE / (area0 + area1)).sqrt();
    let k = [c03 + c04, c01 + c02, -c01 - c03, -c02 - c04];
    let out = k.map(|k| k * s);
    if out.iter().all(|v| v.is_finite()) {
        out
    } else {
        [0.0; 4]
    }
}

/// The hinge's curvature vector `C = Σ a_i x_i` (zero when flat), for measuring.
#[must_use]
pub fn hinge_curvature(x: [Vec3; 4], a: [f32; 4]) -> Vec3 {
    x[0] * a[0] + x[1] * a[1] + x[2] * a[2] + x[3] * a[3]
}

/// Calibration of [`dihedral_weight`] against the continuum `½ B ∫ κ² dA` (cylinders rolled
/// from regular grids, as for the isometric model, measured 2.86 × before this factor at 9²,
/// 17² and 33²; see the tests).
pub(crate) const DIHEDRAL_SCALE: f32 = 1.0 / 2.85;

/// Geometric weight of a hinge for the dihedral model: the hinge's energy is
/// `½ B · weight · (ψ − ψ0)²`, with `weight = DIHEDRAL_SCALE · 3|e|²/(A1 + A2)` (the discrete
/// shells weight, Grinspun et al. 2003); 0 for a degenerate hinge.
#[must_use]
pub fn dihedral_weight(x: [Vec3; 4]) -> f32 {
    let e = x[1] - x[0];
    let a = 0.5 * (e.cross(x[2] - x[0]).length() + e.cross(x[3] - x[0]).length());
    let w = DIHEDRAL_SCALE * 3.0 * e.length_squared() / a;
    if a > 1e-12 && w.is_finite() { w } else { 0.0 }
}

/// Signed bend angle `ψ` of the pair `(x1, x2, x3)`, `(x1, x2, x4)` in `(−π, π]`: 0 when flat,
/// its sign telling which way the pair folds (`sign((n1×n2)·(x2 − x1))`).
#[must_use]
pub fn bend_angle(x: [Vec3; 4]) -> f32 {
    let (p2, p3, p4) = (x[1] - x[0], x[2] - x[0], x[3] - x[0]);
    let n1 = p2.cross(p3).normalize_or_zero();
    let n2 = p2.cross(p4).normalize_or_zero();
    let n12 = n1.cross(n2);
    let sigma = if n12.dot(p2) > 0.0 { 1.0 } else { -1.0 };
    sigma * n12.length().atan2(-n1.dot(n2))
}

/// Unsigned dihedral angle `arccos(n1·n2)` in `[0, π]` of the pair `(x1, x2, x3)`,
/// `(x1, x2, x4)`; π when flat. Zero-area triangles give π/2 (their normal is zero).
#[must_use]
pub fn dihedral_angle(x: [Vec3; 4]) -> f32 {
    let (p2, p3, p4) = (x[1] - x[0], x[2] - x[0], x[3] - x[0]);
    let n1 = p2.cross(p3).normalize_or_zero();
    let n2 = p2.cross(p4).normalize_or_zero();
    n1.cross(n2).length().atan2(n1.dot(n2))
}
