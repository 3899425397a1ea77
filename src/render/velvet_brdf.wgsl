#define_import_path bevy_cloth::velvet_brdf

// The velvet BRDF (report §3.4), the GPU twin of `src/render/brdf.rs`: the same formulas, the
// same clamps, in the same order. tests/velvet_parity.rs compiles this file on its own (after
// dropping the `#define_import_path` line) and compares it with the CPU function, so it must
// stay free of `#import` and `#ifdef`.
//
//   D(m) = χ⁺(n·m) / (π(1 + k_amp α²)) · (1 + k_amp·exp((n·m)²/(α²((n·m)² − 1))) / (1 − (n·m)²)²)
//   F    = F0 + (1 − F0)(1 − h·l)⁵
//   f    = (1 − F)·ρ_ss/π + sheen·F·D(h) / (4(n·l + n·v − (n·l)(n·v)))
//
// α, k_amp and F0 arrive clamped to their ranges (VelvetUniform is built clamped).

const VELVET_PI: f32 = 3.141592653589793;
const VELVET_MIN_SIN2: f32 = 1.0e-6;
const VELVET_MIN_DENOMINATOR: f32 = 1.0e-6;
const VELVET_MIN_N_DOT_V: f32 = 1.0e-4;

// Ashikhmin's velvet distribution at c = n·m. Zero for c ≤ 0. As c → 1 the grazing term's
// exponential underflows to 0 (its true limit) while (1 − c²) is held at VELVET_MIN_SIN2.
fn velvet_distribution(c_in: f32, alpha: f32, k_amp: f32) -> f32 {
    if !(c_in > 0.0) {
        return 0.0;
    }
    let c = min(c_in, 1.0);
    let c2 = c * c;
    let s2 = max(1.0 - c2, VELVET_MIN_SIN2);
    let a2 = alpha * alpha;
    let peak = k_amp * exp(-c2 / (a2 * s2)) / (s2 * s2);
    return (1.0 + peak) / (VELVET_PI * (1.0 + k_amp * a2));
}

// Schlick's Fresnel with h·l clamped to [0, 1].
fn velvet_fresnel(f0: f32, h_dot_l: f32) -> f32 {
    let x = 1.0 - clamp(h_dot_l, 0.0, 1.0);
    let x2 = x * x;
    return f0 + (1.0 - f0) * x2 * x2 * x;
}

// f(l, v) for unit n, v (towards the eye) and l (towards the light); not multiplied by n·l.
// Zero for light from below the surface; views at or below the horizon count as grazing
// (shading normals may face slightly away from the eye at silhouettes) and are lifted to
// n·v = VELVET_MIN_N_DOT_V for the half vector.
fn velvet_brdf(
    n: vec3<f32>,
    v: vec3<f32>,
    l: vec3<f32>,
    albedo: vec3<f32>,
    sheen: vec3<f32>,
    alpha: f32,
    k_amp: f32,
    f0: f32,
) -> vec3<f32> {
    let nl = clamp(dot(n, l), 0.0, 1.0);
    if !(nl > 0.0) {
        return vec3<f32>(0.0);
    }
    let nv_raw = dot(n, v);
    let nv = clamp(nv_raw, VELVET_MIN_N_DOT_V, 1.0);
    // A view below the horizon band is lifted into it along n, so n·h > 0 whenever light
    // arrives (D would jump where h crosses the tangent plane).
    let lift = max(VELVET_MIN_N_DOT_V - nv_raw, 0.0);
    let sum = (l + v) + n * lift;
    let len = length(sum);
    var h = n;
    if len > 1.0e-6 {
        h = sum / len;
    }
    let f = velvet_fresnel(f0, dot(h, l));
    let d = velvet_distribution(clamp(dot(n, h), 0.0, 1.0), alpha, k_amp);
    let denom = max(4.0 * (nl + nv - nl * nv), VELVET_MIN_DENOMINATOR);
    return albedo * ((1.0 - f) / VELVET_PI) + sheen * (f * d / denom);
}
