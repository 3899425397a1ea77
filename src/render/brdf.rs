//! The velvet BRDF on the CPU (report §3.4): the reference the WGSL in `velvet_brdf.wgsl`
//! is tested against, and a plain function for tools and tests. No Bevy, only `glam`.
//!
//! ```text
//! D(m) = χ⁺(n·m) / (π(1 + k_amp α²)) · (1 + k_amp·exp((n·m)²/(α²((n·m)² − 1))) / (1 − (n·m)²)²)
//! F(h, l) = F0 + (1 − F0)(1 − h·l)⁵                                   (Schlick)
//! f(l, v) = (1 − F)·ρ_ss/π + sheen·F·D(h) / (4(n·l + n·v − (n·l)(n·v)))
//! ```
//!
//! `D` is Ashikhmin's velvet distribution ("Distribution-based BRDFs", 2007; The Order: 1886
//! uses `k_amp = 4`); it is normalised (`∫ D(m)(n·m) dω = 1` for every α and `k_amp`) and has
//! no geometry term. `sheen` tints the specular lobe (white is the report's formula as
//! written). Every input is clamped to its range, so no input makes a NaN:
//! `(1 − (n·m)²)` is kept above [`MIN_SIN2`] (the exponential has already underflowed to 0
//! there, which is the true limit as `n·m → 1`), and the specular denominator above
//! [`MIN_DENOMINATOR`] (it is 0 only when both `n·l` and `n·v` are 0).

use core::f32::consts::PI;
use core::ops::RangeInclusive;

use glam::Vec3;

/// Range of the roughness `α` (the width of the grazing sheen).
pub const ALPHA_RANGE: RangeInclusive<f32> = 0.05..=1.0;
/// Range of the amplitude `k_amp` of the grazing peak.
pub const K_AMP_RANGE: RangeInclusive<f32> = 0.0..=10.0;
/// Range of the reflectance at normal incidence `F0`.
pub const F0_RANGE: RangeInclusive<f32> = 0.0..=1.0;
/// Smallest `1 − (n·m)²` used in `D`.
pub const MIN_SIN2: f32 = 1e-6;
/// Smallest `n·v` used: views at or below the horizon count as grazing (shading normals can
/// face slightly away from the eye at silhouettes). Such a view is also lifted along `n` to
/// this height before the half vector is taken, so `n·h > 0` whenever light arrives: no jump
/// of `D` where `h` would cross the tangent plane.
pub const MIN_N_DOT_V: f32 = 1e-4;
/// Smallest specular denominator `4(n·l + n·v − (n·l)(n·v))` used.
pub const MIN_DENOMINATOR: f32 = 1e-6;

/// The velvet BRDF's parameters (linear colours).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelvetBrdf {
    /// Diffuse albedo `ρ_ss` (each channel in `0..=1`).
    pub albedo: Vec3,
    /// Tint of the specular (sheen) lobe; white is the report's formula.
    pub sheen: Vec3,
    /// Roughness `α`, in [`ALPHA_RANGE`].
    pub alpha: f32,
    /// Amplitude `k_amp`, in [`K_AMP_RANGE`].
    pub k_amp: f32,
    /// Reflectance at normal incidence `F0`, in [`F0_RANGE`].
    pub f0: f32,
}

impl Default for VelvetBrdf {
    fn default() -> Self {
        Self {
            albedo: Vec3::splat(0.5),
            sheen: Vec3::ONE,
            alpha: 0.5,
            k_amp: 4.0,
            f0: 0.04,
        }
    }
}

fn clamp_range(x: f32, r: &RangeInclusive<f32>) -> f32 {
    // NaN goes to the low end (f32::clamp would keep it).
    if x >= *r.start() {
        x.min(*r.end())
    } else {
        *r.start()
    }
}

impl VelvetBrdf {
    /// The parameters clamped to their ranges (NaN to the low end), as the shader uses them.
    #[must_use]
    pub fn clamped(self) -> Self {
        let unit = 0.0..=1.0;
        let c = |v: Vec3| {
            Vec3::new(
                clamp_range(v.x, &unit),
                clamp_range(v.y, &unit),
                clamp_range(v.z, &unit),
            )
        };
        Self {
            albedo: c(self.albedo),
            sheen: c(self.sheen),
            alpha: clamp_range(self.alpha, &ALPHA_RANGE),
            k_amp: clamp_range(self.k_amp, &K_AMP_RANGE),
            f0: clamp_range(self.f0, &F0_RANGE),
        }
    }

    /// `f(l, v)` for unit normal `n`, unit view direction `v` and unit light direction `l`
    /// (both pointing away from the surface). Returns the BRDF value (multiply by `n·l` and
    /// the light's radiance for outgoing radiance); zero when `l` is below the surface, `n·v`
    /// held at [`MIN_N_DOT_V`] or above. Finite for any input. `velvet_brdf` in
    /// `velvet_brdf.wgsl` is the same function, step for step.
    #[must_use]
    pub fn eval(&self, n: Vec3, v: Vec3, l: Vec3) -> Vec3 {
        let p = self.clamped();
        let nl = clamp_range(n.dot(l), &(0.0..=1.0));
        if nl <= 0.0 {
            return Vec3::ZERO;
        }
        let nv_raw = n.dot(v);
        let nv = clamp_range(nv_raw, &(MIN_N_DOT_V..=1.0));
        // A view below the horizon band is lifted into it along n (see MIN_N_DOT_V).
        let lift = (MIN_N_DOT_V - nv_raw).max(0.0);
        let sum = (l + v) + n * lift;
        let len = sum.length();
        let h = if len > 1e-6 { sum / len } else { n };
        let f = fresnel_schlick(p.f0, h.dot(l));
        let d = distribution(clamp_range(n.dot(h), &(0.0..=1.0)), p.alpha, p.k_amp);
        let denom = (4.0 * (nl + nv - nl * nv)).max(MIN_DENOMINATOR);
        p.albedo * ((1.0 - f) / PI) + p.sheen * (f * d / denom)
    }
}

/// Ashikhmin's velvet distribution `D` at `n·m = c` (see the module docs). Zero for `c ≤ 0`.
#[must_use]
pub fn distribution(c: f32, alpha: f32, k_amp: f32) -> f32 {
    if c.is_nan() || c <= 0.0 {
        return 0.0;
    }
    let c2 = c.min(1.0) * c.min(1.0);
    let s2 = (1.0 - c2).max(MIN_SIN2);
    let a2 = alpha * alpha;
    let peak = k_amp * (-c2 / (a2 * s2)).exp() / (s2 * s2);
    (1.0 + peak) / (PI * (1.0 + k_amp * a2))
}

/// Schlick's Fresnel `F0 + (1 − F0)(1 − h·l)⁵`, `h·l` clamped to `0..=1`.
#[must_use]
pub fn fresnel_schlick(f0: f32, h_dot_l: f32) -> f32 {
    let x = 1.0 - clamp_range(h_dot_l, &(0.0..=1.0));
    let x2 = x * x;
    f0 + (1.0 - f0) * x2 * x2 * x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(theta: f32, phi: f32) -> Vec3 {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    }

    /// `∫ g(θ) sinθ dθ dφ` over the upper hemisphere for a function of θ only (midpoint rule).
    fn hemisphere(g: impl Fn(f32) -> f64, steps: usize) -> f64 {
        let dt = core::f64::consts::FRAC_PI_2 / steps as f64;
        (0..steps)
            .map(|i| {
                let t = (i as f64 + 0.5) * dt;
                g(t as f32) * t.sin() * dt
            })
            .sum::<f64>()
            * 2.0
            * core::f64::consts::PI
    }

    #[test]
    fn distribution_is_normalised() {
        // ∫ D(m)(n·m) dω_m = 1 for every α and k_amp: the (1 + k_amp α²) factor is exactly
        // the integral of the grazing term.
        for alpha in [0.1, 0.3, 0.5, 1.0] {
            for k in [0.0, 1.0, 4.0, 10.0] {
                let total = hemisphere(
                    |t| f64::from(distribution(t.cos(), alpha, k) * t.cos()),
                    20_000,
                );
                assert!((total - 1.0).abs() < 2e-3, "α {alpha} k {k}: {total}");
            }
        }
    }

    #[test]
    fn diffuse_lobe_energy() {
        // Directional albedo of the diffuse term, ∫ (1 − F)ρ/π (n·l) dω_l, for a view along the
        // normal and a grazing one: at most ρ, and within Fresnel's share of it.
        let albedo = Vec3::new(0.8, 0.5, 0.2);
        for f0 in [0.0, 0.04, 0.5] {
            let brdf = VelvetBrdf {
                albedo,
                sheen: Vec3::ZERO, // diffuse only
                f0,
                ..Default::default()
            };
            for v in [Vec3::Y, dir(1.4, 0.3)] {
                let (nt, np) = (400, 200);
                let mut total = Vec3::ZERO;
                for i in 0..nt {
                    for j in 0..np {
                        let t = (i as f32 + 0.5) / nt as f32 * core::f32::consts::FRAC_PI_2;
                        let p = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                        let l = dir(t, p);
                        let w = t.sin()
                            * (core::f32::consts::FRAC_PI_2 / nt as f32)
                            * (2.0 * PI / np as f32);
                        total += brdf.eval(Vec3::Y, v, l) * l.y * w;
                    }
                }
                let ratio = total / albedo;
                for r in ratio.to_array() {
                    assert!(r <= (1.0 - f0) + 1e-3, "f0 {f0}: {ratio}");
                    assert!(r >= 0.85 * (1.0 - f0), "f0 {f0} v {v}: {ratio}");
                }
                if f0 == 0.0 && v == Vec3::Y {
                    // Only Schlick's grazing rise takes energy: within 3 % of ρ.
                    assert!(ratio.x > 0.97, "{ratio}");
                }
            }
        }
        // All reflection at F0 = 1: no diffuse at all.
        let mirror = VelvetBrdf {
            sheen: Vec3::ZERO,
            f0: 1.0,
            ..Default::default()
        };
        assert_eq!(
            mirror.eval(Vec3::Y, dir(0.4, 0.0), dir(0.7, 2.0)),
            Vec3::ZERO
        );
    }

    #[test]
    fn continuous_as_the_half_vector_reaches_the_tangent_plane() {
        // Light a little above the horizon, the view swept below it through the mirror image
        // of the light (where l + v would lie in the tangent plane): the reflected light
        // f·(n·l) must not jump there. Without lifting the view, D(n·h) jumped from 0 to its
        // grazing peak across n·h = 0 (seen on an NVIDIA H100, rounding to the other side).
        let brdf = VelvetBrdf::default();
        for theta in [1e-3f32, 4e-3, 0.05] {
            let l = dir(core::f32::consts::FRAC_PI_2 - theta, 0.0);
            let mut last: Option<Vec3> = None;
            for i in 0..=2000 {
                // View elevation from −2θ to 0 (below the horizon), opposite azimuth.
                let e = -2.0 * theta + 2.0 * theta * i as f32 / 2000.0;
                let v = dir(core::f32::consts::FRAC_PI_2 - e, PI);
                let out = brdf.eval(Vec3::Y, v, l) * l.y;
                assert!(out.is_finite(), "{out}");
                if let Some(prev) = last {
                    let jump = (out - prev).abs().max_element();
                    assert!(
                        jump < 1e-3 * theta.max(0.01),
                        "θ {theta}, step {i}: {prev} → {out}"
                    );
                }
                last = Some(out);
            }
        }
    }

    #[test]
    fn reciprocity() {
        let brdf = VelvetBrdf {
            albedo: Vec3::new(0.3, 0.6, 0.9),
            sheen: Vec3::new(1.0, 0.8, 0.6),
            alpha: 0.35,
            k_amp: 6.0,
            f0: 0.1,
        };
        let mut x: u32 = 12345;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as f32 / u32::MAX as f32
        };
        for _ in 0..2000 {
            let v = dir(rnd() * 1.55, rnd() * core::f32::consts::TAU);
            let l = dir(rnd() * 1.55, rnd() * core::f32::consts::TAU);
            let a = brdf.eval(Vec3::Y, v, l);
            let b = brdf.eval(Vec3::Y, l, v);
            assert!(
                (a - b).abs().max_element() <= 1e-5 * a.max_element().max(1.0),
                "{a} {b}"
            );
        }
    }

    #[test]
    fn sheen_peaks_at_grazing_angles() {
        // Back-scattering (light from the eye, as on a lit fold facing the camera): at 80° from
        // the normal the sheen BRDF is more than ten times its head-on value, and even after
        // the n·l cosine the reflected radiance is more than twice head-on, where a Lambertian
        // surface falls to cos 80° ≈ 0.17 of it: the bright rim that makes velvet read as velvet.
        let brdf = VelvetBrdf {
            albedo: Vec3::ZERO,
            ..Default::default()
        };
        let f = |t: f32| {
            let d = dir(t, 0.0);
            brdf.eval(Vec3::Y, d, d).x
        };
        let grazing = 80f32.to_radians();
        assert!(f(grazing) > 10.0 * f(0.0), "{} {}", f(0.0), f(grazing));
        assert!(
            f(grazing) * grazing.cos() > 2.0 * f(0.0),
            "{} {}",
            f(0.0),
            f(grazing)
        );
        // Rising all the way from head-on to grazing.
        let mut last = 0.0;
        for deg in (0..=75).step_by(5) {
            let s = brdf
                .eval(
                    Vec3::Y,
                    dir((deg as f32).to_radians(), 0.0),
                    dir((deg as f32).to_radians(), 0.0),
                )
                .x;
            assert!(s > last, "{deg}°: {s} after {last}");
            last = s;
        }
        // And D itself peaks away from the normal; the head-on value is 1/(π(1 + k α²)).
        let alpha = 0.5;
        assert!((distribution(1.0, alpha, 4.0) - 1.0 / (PI * 2.0)).abs() < 1e-6);
        assert!(distribution(0.2, alpha, 4.0) > 4.0 * distribution(1.0, alpha, 4.0));
    }

    #[test]
    fn no_nan_anywhere() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-30,
            1.0 - f32::EPSILON,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
        ];
        for c in specials {
            for alpha in [0.05, 1.0, 0.0, f32::NAN] {
                let d = distribution(c, alpha.max(0.05), 10.0);
                assert!(d.is_finite() && d >= 0.0, "D({c}, {alpha}) = {d}");
            }
            assert!(fresnel_schlick(0.04, c).is_finite());
        }
        let brdfs = [
            VelvetBrdf::default(),
            VelvetBrdf {
                alpha: 0.0,
                k_amp: 1e9,
                f0: -3.0,
                ..Default::default()
            },
            VelvetBrdf {
                alpha: f32::NAN,
                k_amp: f32::NAN,
                f0: f32::NAN,
                albedo: Vec3::NAN,
                sheen: Vec3::INFINITY,
            },
        ];
        let dirs = [
            Vec3::Y,                               // n·m → 1 (l = v = n)
            Vec3::X,                               // n·l = 0
            Vec3::new(1.0, 1e-7, 0.0).normalize(), // n·l → 0
            -Vec3::Y,
            Vec3::ZERO,
            Vec3::NAN,
            Vec3::new(0.0, (1.0f32 - 1e-7).sqrt(), 1e-3),
        ];
        for b in brdfs {
            for v in dirs {
                for l in dirs {
                    for n in [Vec3::Y, Vec3::ZERO, Vec3::NAN] {
                        let f = b.eval(n, v, l);
                        assert!(
                            f.is_finite() && f.min_element() >= 0.0,
                            "{b:?} n {n} v {v} l {l}: {f}"
                        );
                    }
                }
            }
        }
        // l = v = n exactly: the grazing term is 0 (its limit), D is 1/(π(1 + k α²)).
        let b = VelvetBrdf {
            albedo: Vec3::ZERO,
            ..Default::default()
        };
        let f = b.eval(Vec3::Y, Vec3::Y, Vec3::Y);
        let expect = 0.04 * (1.0 / (PI * 2.0)) / 4.0;
        assert!((f.x - expect).abs() < 1e-6, "{f} vs {expect}");
    }
}
