//! Wind: the velocity of the air, with gusts and turbulence that change its speed and its
//! direction. How the cloth meets that air (drag, lift, friction) is the cloth's own
//! [`Aerodynamics`](super::Aerodynamics).
//!
//! In the wind's frame (`x̂` downwind, speed `U = |velocity|`), the air velocity at `p` and
//! time `t` is
//!
//! ```text
//! u(p, t) = U · [ (1 + a·sin(ω₀·(t − x/U))) x̂  +  b · N((x − U·t)/L, y/L, z/L, t·U/(4L)) ]
//! ```
//!
//! - **Gusts** (`a`, `ω₀`): fronts that travel downwind at the wind speed. The phase at a
//!   point is `ω₀·(t − x/U)` with one `ω₀` everywhere, so the phase difference between two
//!   points never changes: gusts stay coherent over a whole cloth for hours.
//! - **Turbulence** (`b`, `L`): `N` is three independent Perlin noises (one per axis, each in
//!   about `[−1, 1]`), frozen eddies of size `L` carried along at the wind speed and slowly
//!   evolving. Its cross-wind components turn the wind by up to about `atan(b)`, its downwind
//!   one changes the speed.
//!
//! Time is `f64` seconds and every phase is reduced in `f64` before it meets `f32` (the noise
//! repeats every 256 lattice units), so the wind after ten hours is as smooth as after ten
//! seconds and nothing jumps at any hour. Everything is deterministic for a given seed.
//!
//! A cloth samples the field on a coarse [`AirGrid`] around itself once per step and reads
//! each vertex's air velocity from it (trilinear): sampling is then independent of the
//! cloth's resolution, and the GPU backend reads the same grid.

use core::f64::consts::TAU;

use glam::{Quat, Vec3, Vec4, Vec4Swizzles};
use noise::{NoiseFn, Perlin};

use crate::solver::collision::Pose;
use crate::solver::limits::{self, ParamError};

/// A wind: base velocity, gusts and turbulence.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindParams {
    /// Base air velocity in m/s.
    pub velocity: Vec3,
    /// Gust amplitude `a` (0.3 = ±30 % of the speed).
    pub gust_amplitude: f32,
    /// Gust angular frequency `ω₀` in rad/s.
    pub gust_frequency: f32,
    /// Turbulence strength `b`: the noise's share of the speed, along and across the wind.
    pub turbulence: f32,
    /// Size of turbulent eddies `L` in metres.
    pub turbulence_scale: f32,
    /// Noise seed.
    pub seed: u32,
}

impl WindParams {
    /// Largest accepted wind speed, m/s (ten times the speed of sound in air).
    pub const MAX_SPEED: f32 = limits::WIND_SPEED.max;

    /// Checks that the wind can be sampled: a finite velocity no faster than
    /// [`Self::MAX_SPEED`], gust amplitude, frequency, turbulence and eddy size within their
    /// [`limits`].
    ///
    /// # Errors
    /// A [`ParamError`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        limits::WIND_SPEED.check_length(self.velocity)?;
        limits::GUST_AMPLITUDE.check(self.gust_amplitude)?;
        limits::GUST_FREQUENCY.check(self.gust_frequency)?;
        limits::TURBULENCE.check(self.turbulence)?;
        limits::TURBULENCE_SCALE.check(self.turbulence_scale)
    }
}

impl Default for WindParams {
    fn default() -> Self {
        Self {
            velocity: Vec3::new(6.0, 0.0, 0.0),
            gust_amplitude: 0.3,
            gust_frequency: 2.0,
            turbulence: 0.3,
            turbulence_scale: 1.5,
            seed: 1,
        }
    }
}

/// Where a local wind blows: a box (in its pose's frame) with a linear fall-off outside it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindRegion {
    /// The box's pose.
    pub pose: Pose,
    /// Half size of the box.
    pub half_extents: Vec3,
    /// Distance over which the wind fades to nothing outside the box.
    pub falloff: f32,
}

impl WindRegion {
    /// 1 inside the box, fading linearly to 0 at `falloff` outside it.
    #[must_use]
    pub fn weight(&self, p: Vec3) -> f32 {
        let local = self.pose.inverse_apply(p);
        let outside = (local.abs() - self.half_extents).max(Vec3::ZERO).length() * self.pose.scale;
        if outside <= 0.0 {
            1.0
        } else if self.falloff > 0.0 {
            (1.0 - outside / self.falloff).max(0.0)
        } else {
            0.0
        }
    }
}

#[derive(Clone, Debug)]
struct Source {
    wind: WindParams,
    region: Option<WindRegion>,
    perlin: Perlin,
    /// World → wind frame (x downwind).
    to_frame: Quat,
}

/// A set of winds (global ones without a region, local ones with) ready to sample.
#[derive(Clone, Debug, Default)]
pub struct WindField {
    sources: Vec<Source>,
}

/// Lattice offsets that make the three noise channels independent.
const CHANNEL_OFFSET: [f64; 3] = [0.0, 61.3, 127.9];

/// Reduces a lattice coordinate into the noise's period (256): the same value, and no
/// overflow in the noise crate's integer conversion for huge or non-finite input (which gives
/// 0).
fn wrap_noise(x: f64) -> f64 {
    if x.is_finite() {
        x.rem_euclid(256.0)
    } else {
        0.0
    }
}

impl WindField {
    /// Builds the noise generators of each source; sources with a non-finite velocity are
    /// left out.
    #[must_use]
    pub fn new(sources: impl IntoIterator<Item = (WindParams, Option<WindRegion>)>) -> Self {
        Self {
            sources: sources
                .into_iter()
                .filter(|(w, _)| w.velocity.is_finite())
                .map(|(wind, region)| {
                    let frame = Quat::from_rotation_arc(
                        Vec3::X,
                        wind.velocity.try_normalize().unwrap_or(Vec3::X),
                    );
                    Source {
                        wind,
                        region,
                        perlin: Perlin::new(wind.seed),
                        to_frame: frame.inverse(),
                    }
                })
                .collect(),
        }
    }

    /// Whether there is any wind at all.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    /// How many winds blow (the global one and every valid zone).
    #[must_use]
    pub fn len(&self) -> usize {
        self.sources.len()
    }

    /// The smallest eddy size of the sources (the grid spacing a cloth needs), if any.
    #[must_use]
    pub fn finest_scale(&self) -> Option<f32> {
        self.sources
            .iter()
            .map(|s| s.wind.turbulence_scale)
            .reduce(f32::min)
    }

    /// Air velocity at `p` at time `t` (seconds, `f64` so that hours of play keep full
    /// precision).
    #[must_use]
    pub fn velocity_at(&self, p: Vec3, t: f64) -> Vec3 {
        let mut u = Vec3::ZERO;
        for s in &self.sources {
            let weight = s.region.map_or(1.0, |r| r.weight(p));
            if weight <= 0.0 || !p.is_finite() {
                continue;
            }
            let w = &s.wind;
            let speed = w.velocity.length();
            if speed <= 0.0 {
                continue;
            }
            let local = s.to_frame * p; // x is downwind
            let (x, y, z) = (f64::from(local.x), f64::from(local.y), f64::from(local.z));
            let speed64 = f64::from(speed);
            let phase = (f64::from(w.gust_frequency) * (t - x / speed64)).rem_euclid(TAU);
            let mut along = 1.0 + w.gust_amplitude * (phase as f32).sin();
            let mut across = Vec3::ZERO;
            if w.turbulence > 0.0 {
                let scale = f64::from(w.turbulence_scale.max(1e-3));
                let q = [
                    (x - speed64 * t) / scale,
                    y / scale,
                    z / scale,
                    t * speed64 / (4.0 * scale),
                ];
                let n = CHANNEL_OFFSET.map(|o| {
                    s.perlin.get([
                        wrap_noise(q[0] + o),
                        wrap_noise(q[1] + o),
                        wrap_noise(q[2] + o),
                        wrap_noise(q[3] + o),
                    ]) as f32
                });
                along += w.turbulence * n[0];
                across = w.turbulence * Vec3::new(0.0, n[1], n[2]);
            }
            let local_u = speed * (Vec3::X * along + across);
            u += (s.to_frame.inverse() * local_u) * weight;
        }
        u
    }
}

/// The wind sampled on a coarse box grid around a cloth, read back per vertex by trilinear
/// interpolation (clamped at the box's faces).
#[derive(Clone, Debug, Default)]
pub struct AirGrid {
    min: Vec3,
    inv_spacing: Vec3,
    dims: [usize; 3],
    values: Vec<Vec3>,
}

impl AirGrid {
    /// Most grid points along one axis.
    pub const MAX_POINTS: usize = 8;

    /// Samples `field` at time `t` on a grid covering the box `lo..hi`, with a spacing of
    /// about half the finest eddy size (at most [`Self::MAX_POINTS`] points per axis). A
    /// non-finite box or an empty field gives a grid that reads zero everywhere.
    pub fn sample(&mut self, field: &WindField, lo: Vec3, hi: Vec3, t: f64) {
        self.values.clear();
        self.dims = [0; 3];
        let Some(scale) = field.finest_scale() else {
            return;
        };
        if !(lo.is_finite() && hi.is_finite()) {
            return;
        }
        let extent = (hi - lo).max(Vec3::ZERO);
        let spacing_goal = (0.5 * scale).max(1e-3);
        let mut spacing = Vec3::ONE;
        for axis in 0..3 {
            let n = ((extent[axis] / spacing_goal).ceil() as usize + 1).clamp(2, Self::MAX_POINTS);
            self.dims[axis] = n;
            spacing[axis] = extent[axis] / (n - 1) as f32;
        }
        self.min = lo;
        self.inv_spacing = Vec3::select(spacing.cmpgt(Vec3::ZERO), spacing.recip(), Vec3::ZERO);
        let [nx, ny, nz] = self.dims;
        self.values.reserve(nx * ny * nz);
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let p = lo + spacing * Vec3::new(i as f32, j as f32, k as f32);
                    self.values.push(field.velocity_at(p, t));
                }
            }
        }
    }

    /// Grid points along each axis (zeros when the grid is empty).
    #[must_use]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// The sampled velocities, x fastest, then y, then z.
    #[must_use]
    pub fn values(&self) -> &[Vec3] {
        &self.values
    }

    /// Air velocity at `p` (trilinear; clamped to the box; zero for an empty grid).
    #[must_use]
    pub fn velocity(&self, p: Vec3) -> Vec3 {
        if self.values.is_empty() || !p.is_finite() {
            return Vec3::ZERO;
        }
        let [nx, ny, nz] = self.dims;
        let g = ((p - self.min) * self.inv_spacing).clamp(
            Vec3::ZERO,
            Vec3::new((nx - 1) as f32, (ny - 1) as f32, (nz - 1) as f32),
        );
        if !g.is_finite() {
            return Vec3::ZERO;
        }
        let i0 = (g.x as usize).min(nx - 2);
        let j0 = (g.y as usize).min(ny - 2);
        let k0 = (g.z as usize).min(nz - 2);
        let f = g - Vec3::new(i0 as f32, j0 as f32, k0 as f32);
        let at = |i: usize, j: usize, k: usize| self.values[i + nx * (j + ny * k)];
        let lerp = |a: Vec3, b: Vec3, t: f32| a + (b - a) * t;
        let x00 = lerp(at(i0, j0, k0), at(i0 + 1, j0, k0), f.x);
        let x10 = lerp(at(i0, j0 + 1, k0), at(i0 + 1, j0 + 1, k0), f.x);
        let x01 = lerp(at(i0, j0, k0 + 1), at(i0 + 1, j0, k0 + 1), f.x);
        let x11 = lerp(at(i0, j0 + 1, k0 + 1), at(i0 + 1, j0 + 1, k0 + 1), f.x);
        lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z)
    }

    /// Samples `field` around `positions` (their bounding box) at time `t` and writes each
    /// vertex's air velocity into `out` (`w = 0`).
    pub fn air_velocities(
        &mut self,
        field: &WindField,
        positions: &[Vec4],
        t: f64,
        out: &mut Vec<Vec4>,
    ) {
        let (lo, hi) = positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p.xyz()), hi.max(p.xyz())),
        );
        self.sample(field, lo, hi, t);
        out.clear();
        out.extend(positions.iter().map(|p| self.velocity(p.xyz()).extend(0.0)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn steady(velocity: Vec3) -> WindParams {
        WindParams {
            velocity,
            gust_amplitude: 0.0,
            turbulence: 0.0,
            ..Default::default()
        }
    }

    #[test]
    fn steady_wind_is_its_velocity_everywhere() {
        let field = WindField::new([(steady(Vec3::new(0.0, 0.0, -5.0)), None)]);
        for p in [Vec3::ZERO, Vec3::splat(3.0), Vec3::new(-100.0, 2.0, 7.0)] {
            assert!((field.velocity_at(p, 12.5) - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-5);
        }
    }

    #[test]
    fn gusts_are_deterministic_and_vary_in_space_and_time() {
        let field = WindField::new([(WindParams::default(), None)]);
        let again = WindField::new([(WindParams::default(), None)]);
        let p = Vec3::new(0.3, 1.2, -0.4);
        assert_eq!(field.velocity_at(p, 1.5), again.velocity_at(p, 1.5));
        assert_ne!(field.velocity_at(p, 1.5), field.velocity_at(p, 2.5));
        assert_ne!(
            field.velocity_at(p, 1.5),
            field.velocity_at(p + Vec3::Z * 2.0, 1.5)
        );
    }

    #[test]
    fn turbulence_turns_the_wind_and_is_carried_downwind() {
        let wind = WindParams {
            gust_amplitude: 0.0,
            ..Default::default()
        };
        let field = WindField::new([(wind, None)]);
        // Direction changes: the cross-wind components move over time at a fixed point.
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for i in 0..200 {
            let u = field.velocity_at(Vec3::new(0.0, 1.0, 0.0), f64::from(i) * 0.05);
            let angle = u.z.atan2(u.x).to_degrees();
            lo = lo.min(angle);
            hi = hi.max(angle);
        }
        assert!(hi - lo > 5.0, "the wind turns by {} degrees", hi - lo);
        // Frozen eddies carried at the wind speed: what blows at x at t blows at x + U·dt
        // at t + dt, but for the slow evolution.
        let a = field.velocity_at(Vec3::new(0.0, 1.0, 0.5), 3.0);
        let b = field.velocity_at(Vec3::new(0.6, 1.0, 0.5), 3.1);
        let c = field.velocity_at(Vec3::new(0.0, 1.0, 0.5), 3.1);
        assert!((a - b).length() < 0.5 * (a - c).length(), "{a} {b} {c}");
    }

    #[test]
    fn gust_phase_differences_never_drift_and_nothing_jumps_at_the_hour() {
        let wind = WindParams {
            turbulence: 0.0,
            ..Default::default()
        };
        let field = WindField::new([(wind, None)]);
        // Two points across the wind see the same gust at every time (one ω everywhere), at
        // the start and ten hours later.
        for t in [1.0, 36_000.0 + 1.0] {
            let a = field.velocity_at(Vec3::new(0.0, 0.0, 0.0), t);
            let b = field.velocity_at(Vec3::new(0.0, 3.0, 2.0), t);
            assert!((a - b).length() < 1e-4, "t {t}: {a} vs {b}");
        }
        // Smooth across the hour: one millisecond changes the wind by a millisecond's worth.
        let full = WindField::new([(WindParams::default(), None)]);
        for hour in [1.0, 2.0, 10.0] {
            let t = 3600.0 * hour;
            let p = Vec3::new(0.2, 1.0, 0.3);
            let jump = (full.velocity_at(p, t + 5e-4) - full.velocity_at(p, t - 5e-4)).length();
            assert!(jump < 0.1, "hour {hour}: jump {jump} m/s");
        }
    }

    #[test]
    fn grid_reads_back_the_field() {
        let field = WindField::new([(WindParams::default(), None)]);
        let mut grid = AirGrid::default();
        let (lo, hi) = (Vec3::new(-0.5, 0.0, -0.1), Vec3::new(0.5, 1.0, 0.1));
        grid.sample(&field, lo, hi, 4.0);
        let [nx, ny, nz] = grid.dims();
        assert!(nx >= 2 && ny >= 2 && nz >= 2 && nx <= AirGrid::MAX_POINTS);
        // Exact at the corners, close inside (eddies of 1.5 m, points 0.5 m apart).
        assert!((grid.velocity(lo) - field.velocity_at(lo, 4.0)).length() < 1e-5);
        assert!((grid.velocity(hi) - field.velocity_at(hi, 4.0)).length() < 1e-5);
        let mid = Vec3::new(0.1, 0.45, 0.0);
        let err = (grid.velocity(mid) - field.velocity_at(mid, 4.0)).length();
        assert!(err < 0.3, "interpolation error {err} m/s at 6 m/s");
        // Outside the box: clamped, finite. Garbage in: zero.
        assert!(grid.velocity(Vec3::splat(1e30)).is_finite());
        assert_eq!(grid.velocity(Vec3::NAN), Vec3::ZERO);
        grid.sample(&field, Vec3::NAN, hi, 0.0);
        assert_eq!(grid.velocity(Vec3::ZERO), Vec3::ZERO);
        grid.sample(&WindField::default(), lo, hi, 0.0);
        assert_eq!(grid.velocity(Vec3::ZERO), Vec3::ZERO);
    }

    #[test]
    fn regions_fade_out() {
        let r = WindRegion {
            pose: Pose::default(),
            half_extents: Vec3::ONE,
            falloff: 2.0,
        };
        assert_eq!(r.weight(Vec3::ZERO), 1.0);
        assert!((r.weight(Vec3::new(2.0, 0.0, 0.0)) - 0.5).abs() < 1e-6);
        assert_eq!(r.weight(Vec3::new(5.0, 0.0, 0.0)), 0.0);
    }
}
