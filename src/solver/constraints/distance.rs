//! Distance (stretch and shear) constraint: `C = |xa − xb| − rest`.
//!
//! One formula serves both solvers: the correction multiplier is
//! `s = k·(−C − α̃λ)/(wa + wb + α̃)`, then `xa += wa·s·n`, `xb −= wb·s·n`, `λ += s`, with
//! `n = (xa − xb)/|xa − xb|`. Gauss–Seidel PBD uses `α̃ = 0` and `k` = stiffness; XPBD uses
//! `k = 1` and `α̃ = compliance/h²` (Macklin et al. 2016, eq. 18).

use super::lanes::{Real, V3};

/// Lengths below this are treated as zero: the constraint has no direction and is skipped.
pub(crate) const MIN_LENGTH: f32 = 1e-9;

/// Correction of one distance constraint: `(Δxa, Δxb, Δλ)`.
#[inline(always)]
#[expect(
    clippy::too_many_arguments,
    reason = "one lane of a SoA batch, kept flat for SIMD"
)]
pub(crate) fn distance_correction<T: Real>(
    xa: V3<T>,
    wa: T,
    xb: V3<T>,
    wb: T,
    rest: T,
    alpha: T,
    k: T,
    lambda: T,
) -> (V3<T>, V3<T>, T) {
    let zero = T::splat(0.0);
    let d = xa - xb;
    let len = d.length_squared().sqrt();
    let denom = wa + wb + alpha;
    // One division: `f = Δλ/len` scales the unnormalised direction `d`; `Δλ = f·len`.
    let f = k * (-(len - rest) - alpha * lambda) / (denom * len);
    // No direction or nothing can move: no correction (and no NaN from 0/0). The test is on
    // wa + wb, not the denominator: with both ends pinned and a tiny (even denormal) α̃,
    // −C/α̃ overflows to ∞ and 0·∞ would be NaN. A huge α̃ makes `denom·len` infinite and
    // `f` zero.
    let f = len.if_gt(T::splat(MIN_LENGTH), f, zero);
    let f = (wa + wb).if_gt(zero, f, zero);
    (d.scale(wa * f), d.scale(-(wb * f)), f * len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::constraints::lanes::V3;

    fn v(x: f32, y: f32, z: f32) -> V3<f32> {
        V3 { x, y, z }
    }

    #[test]
    fn equal_masses_meet_halfway() {
        // Rest 1, stretched to 3 along x: each end moves 1 towards the other.
        let (da, db, s) = distance_correction(
            v(0.0, 0.0, 0.0),
            1.0,
            v(3.0, 0.0, 0.0),
            1.0,
            1.0,
            0.0,
            1.0,
            0.0,
        );
        assert_eq!((da.x, da.y, da.z), (1.0, 0.0, 0.0));
        assert_eq!((db.x, db.y, db.z), (-1.0, 0.0, 0.0));
        assert_eq!(s, -1.0);
    }

    #[test]
    fn pinned_end_does_not_move() {
        // wa = 0: b takes the whole correction; compressed from 2 to 0.5 along y.
        let (da, db, _) = distance_correction(
            v(0.0, 0.0, 0.0),
            0.0,
            v(0.0, 0.5, 0.0),
            2.0,
            2.0,
            0.0,
            1.0,
            0.0,
        );
        assert_eq!((da.x, da.y, da.z), (0.0, 0.0, 0.0));
        assert!((db.y - 1.5).abs() < 1e-6 && db.x == 0.0 && db.z == 0.0);
    }

    #[test]
    fn stiffness_scales_pbd_correction() {
        let (da, _, _) = distance_correction(
            v(0.0, 0.0, 0.0),
            1.0,
            v(2.0, 0.0, 0.0),
            1.0,
            1.0,
            0.0,
            0.25,
            0.0,
        );
        assert!((da.x - 0.125).abs() < 1e-7);
    }

    #[test]
    fn compliance_softens_xpbd_correction() {
        // α̃ = 2: s = −C/(wa+wb+α̃) = −1/4.
        let (da, _, s) = distance_correction(
            v(0.0, 0.0, 0.0),
            1.0,
            v(2.0, 0.0, 0.0),
            1.0,
            1.0,
            2.0,
            1.0,
            0.0,
        );
        assert!((s + 0.25).abs() < 1e-7 && (da.x - 0.25).abs() < 1e-7);
        // With the multiplier already at the solution, a second pass does not move.
        let x = 2.0 - 0.5;
        let (da2, _, s2) =
            distance_correction(v(0.0, 0.0, 0.0), 1.0, v(x, 0.0, 0.0), 1.0, 1.0, 2.0, 1.0, s);
        // C = 0.5, −C − α̃λ = −0.5 + 0.5 = 0.
        assert!(s2.abs() < 1e-7 && da2.x.abs() < 1e-7);
    }

    #[test]
    fn degenerate_inputs_give_no_correction() {
        for (xa, wa, wb) in [
            (v(1.0, 1.0, 1.0), 1.0, 1.0), // coincident
            (v(0.0, 0.0, 0.0), 0.0, 0.0), // both pinned
        ] {
            let (da, db, s) = distance_correction(xa, wa, v(1.0, 1.0, 1.0), wb, 1.0, 0.0, 1.0, 0.0);
            for c in [da.x, da.y, da.z, db.x, db.y, db.z, s] {
                assert_eq!(c, 0.0);
            }
        }
    }

    #[test]
    fn pinned_ends_with_a_tiny_compliance_give_no_nan() {
        // Both ends pinned, stretched by 1e6 m, α̃ a denormal: −C/α̃ is −∞, and the
        // correction must still be zero (the fuzzer found 0·∞ = NaN here).
        let far = v(-1.1e6, 6.9, -0.7);
        for alpha in [2.56e-36, 1e-45, 0.0] {
            let (da, db, s) =
                distance_correction(v(28.0, -13.8, 47.4), 0.0, far, 0.0, 50.0, alpha, 1.0, 0.0);
            for c in [da.x, da.y, da.z, db.x, db.y, db.z, s] {
                assert_eq!(c, 0.0, "α̃ {alpha}");
            }
        }
    }
}
