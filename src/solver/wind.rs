//! Wind: per-triangle drag and lift from the relative air velocity (report §3.7), with gusts.
//!
//! For a triangle of area `A`, unit normal `n`, mean vertex velocity `v` and air velocity `u`
//! (the mean of its vertices' samples), with `v_rel = v − u` and `ṽ = v_rel/|v_rel|`:
//!
//! ```text
//! F_D = −drag · |v_rel|² · A · |ṽ·n| · ṽ
//! F_L =  lift · |v_rel|² · A · (ṽ·n) · ((n × ṽ) × ṽ)
//! ```
//!
//! (the report writes `ṽ·n` for drag; its absolute value keeps drag opposed to the relative
//! velocity whichever way the triangle faces). Each vertex gets a third of its triangles'
//! force. A triangle's force is capped at what stops its relative motion within one step, so
//! a hurricane cannot overshoot the air speed and blow up.
//!
//! The air velocity at `p` and time `t` is `v_wind · (1 + a·sin(ω(p)·t + φ(p)) + b·perlin(p'))`:
//! `φ(p) = −ω₀ (p·ŵ)/|v_wind|` makes gust fronts travel downwind at the wind speed,
//! `ω(p) = ω₀ (1 + ¼ sin(p_⊥/scale))` varies the rhythm across the wind, and `p'` is `p` in the
//! wind's frame with the downwind axis dropped (the noise is constant along the wind, as in the
//! report) and time as third coordinate. Everything is deterministic for a given seed.

use glam::{Quat, Vec3, Vec4, Vec4Swizzles};
use noise::{NoiseFn, Perlin};

use super::collide::Pose;
use super::params::ParamError;

/// A wind: base velocity, aerodynamic coefficients, gusts and turbulence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindParams {
    /// Base air velocity in m/s.
    pub velocity: Vec3,
    /// Drag coefficient (½·air density·C_D), kg/m³. About 0.5 for cloth in air.
    pub drag: f32,
    /// Lift coefficient (½·air density·C_L), kg/m³.
    pub lift: f32,
    /// Gust amplitude `a` (0.3 = ±30 %).
    pub gust_amplitude: f32,
    /// Base gust angular frequency `ω₀` in rad/s.
    pub gust_frequency: f32,
    /// Turbulence strength `b` (Perlin term).
    pub turbulence: f32,
    /// Size of turbulent eddies in metres.
    pub turbulence_scale: f32,
    /// Noise seed.
    pub seed: u32,
}

impl WindParams {
    /// Checks that the wind can be sampled: a finite velocity, finite non-negative drag,
    /// lift magnitude, gust amplitude, frequency and turbulence, and a positive eddy size.
    ///
    /// # Errors
    /// A [`ParamError`] naming the first field out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !self.velocity.is_finite() {
            return Err(ParamError {
                name: "wind.velocity",
                reason: format!("{} is not finite", self.velocity),
            });
        }
        for (name, v) in [
            ("wind.drag", self.drag),
            ("wind.gust_amplitude", self.gust_amplitude),
            ("wind.gust_frequency", self.gust_frequency),
            ("wind.turbulence", self.turbulence),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ParamError {
                    name,
                    reason: format!("{v} must be finite and ≥ 0"),
                });
            }
        }
        if !self.lift.is_finite() {
            return Err(ParamError {
                name: "wind.lift",
                reason: format!("{} is not finite", self.lift),
            });
        }
        if !(self.turbulence_scale.is_finite() && self.turbulence_scale > 0.0) {
            return Err(ParamError {
                name: "wind.turbulence_scale",
                reason: format!("{} must be finite and > 0", self.turbulence_scale),
            });
        }
        Ok(())
    }
}

impl Default for WindParams {
    fn default() -> Self {
        Self {
            velocity: Vec3::new(6.0, 0.0, 0.0),
            drag: 0.6,
            lift: 0.3,
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

/// A set of winds (global ones without a region, local ones with) ready to sample.
#[derive(Clone, Debug, Default)]
pub struct WindField {
    sources: Vec<(WindParams, Option<WindRegion>, Perlin, Quat)>,
}

impl WindField {
    /// Builds the noise generators of each source.
    #[must_use]
    pub fn new(sources: impl IntoIterator<Item = (WindParams, Option<WindRegion>)>) -> Self {
        Self {
            sources: sources
                .into_iter()
                .filter(|(w, _)| w.velocity.is_finite())
                .map(|(w, r)| {
                    let frame = Quat::from_rotation_arc(
                        Vec3::X,
                        w.velocity.try_normalize().unwrap_or(Vec3::X),
                    );
                    (w, r, Perlin::new(w.seed), frame.inverse())
                })
                .collect(),
        }
    }

    /// Whether there is any wind at all.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    /// Air velocity at `p` at time `t`.
    #[must_use]
    pub fn velocity_at(&self, p: Vec3, t: f32) -> Vec3 {
        let mut u = Vec3::ZERO;
        for (w, region, perlin, to_frame) in &self.sources {
            let weight = region.map_or(1.0, |r| r.weight(p));
            if weight <= 0.0 {
                continue;
            }
            let speed = w.velocity.length();
            let local = *to_frame * p; // x is downwind
            let scale = w.turbulence_scale.max(1e-3);
            let omega = w.gust_frequency * (1.0 + 0.25 * (local.y / scale).sin());
            let phase = if speed > 0.0 {
                -w.gust_frequency * local.x / speed
            } else {
                0.0
            };
            let noise = perlin.get([
                wrap_noise(local.y / scale),
                wrap_noise(local.z / scale),
                wrap_noise(t * 0.5),
            ]) as f32;
            let factor = 1.0 + w.gust_amplitude * (omega * t + phase).sin() + w.turbulence * noise;
            u += w.velocity * factor * weight;
        }
        u
    }
}

/// Perlin noise repeats every 256 lattice units; wrapping into one period gives the same
/// value and keeps huge or non-finite coordinates (a cloth 10³⁸ m away) from overflowing the
/// noise crate's integer conversion, which panics. Non-finite input gives 0.
fn wrap_noise(x: f32) -> f64 {
    let x = f64::from(x);
    if x.is_finite() {
        x.rem_euclid(256.0)
    } else {
        0.0
    }
}

/// Drag and lift on one triangle: `(F_D, F_L)` in newtons.
#[must_use]
pub fn triangle_wind_force(x: [Vec3; 3], v_rel: Vec3, wind: &WindParams) -> (Vec3, Vec3) {
    let cross = (x[1] - x[0]).cross(x[2] - x[0]);
    let len = cross.length();
    let speed2 = v_rel.length_squared();
    if len <= 0.0 || speed2 <= 0.0 || !len.is_finite() || !speed2.is_finite() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    let area = 0.5 * len;
    let n = cross / len;
    let dir = v_rel / speed2.sqrt();
    let cos = dir.dot(n);
    let drag = -wind.drag * speed2 * area * cos.abs() * dir;
    let lift = wind.lift * speed2 * area * cos * n.cross(dir).cross(dir);
    (drag, lift)
}

/// Per-vertex acceleration from the wind over a step of `dt`, written into `out` (w = 0).
///
/// `air` is scratch for the per-vertex air velocities. Coefficients are taken from the first
/// wind source that reaches the triangle (local winds are usually alone in their region).
#[expect(
    clippy::too_many_arguments,
    reason = "plain arrays in, plain arrays out"
)]
pub fn wind_accelerations(
    positions: &[Vec4],
    velocities: &[Vec4],
    triangles: &[[u32; 3]],
    field: &WindField,
    t: f32,
    dt: f32,
    air: &mut Vec<Vec3>,
    out: &mut Vec<Vec4>,
) {
    out.clear();
    out.resize(positions.len(), Vec4::ZERO);
    if field.is_empty() || dt.is_nan() || dt <= 0.0 {
        return;
    }
    air.clear();
    air.extend(positions.iter().map(|p| field.velocity_at(p.xyz(), t)));
    for tri in triangles {
        let [i, j, k] = tri.map(|v| v as usize);
        let (pi, pj, pk) = (positions[i], positions[j], positions[k]);
        let masses: f32 = [pi.w, pj.w, pk.w]
            .iter()
            .map(|w| if *w > 0.0 { 1.0 / w } else { 0.0 })
            .sum();
        if masses <= 0.0 {
            continue;
        }
        let centroid = (pi.xyz() + pj.xyz() + pk.xyz()) / 3.0;
        let Some((wind, _, _, _)) = field
            .sources
            .iter()
            .find(|(_, r, _, _)| r.is_none_or(|r| r.weight(centroid) > 0.0))
        else {
            continue;
        };
        let v = (velocities[i] + velocities[j] + velocities[k]).xyz() / 3.0;
        let u = (air[i] + air[j] + air[k]) / 3.0;
        let v_rel = v - u;
        let (drag, lift) = triangle_wind_force([pi.xyz(), pj.xyz(), pk.xyz()], v_rel, wind);
        let mut force = drag + lift;
        // Never more than stops the relative motion of the triangle's mass within the step.
        let cap = masses * v_rel.length() / dt;
        let f = force.length();
        if f > cap {
            force *= cap / f;
        }
        if !force.is_finite() {
            continue;
        }
        let third = force / 3.0;
        for (idx, p) in [(i, pi), (j, pj), (k, pk)] {
            if p.w > 0.0 {
                out[idx] += (third * p.w).extend(0.0);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drag_opposes_relative_velocity_with_the_formula_magnitude() {
        // A unit right triangle (area ½) facing +z, air blowing along −z at 10 m/s onto it at
        // rest: v_rel = +10 z, |v_rel|² = 100, cos = 1 → |F_D| = drag·100·½, along −z... the
        // triangle is pushed downwind (−z).
        let x = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let wind = WindParams {
            drag: 0.6,
            lift: 0.3,
            ..Default::default()
        };
        let (d, l) = triangle_wind_force(x, Vec3::new(0.0, 0.0, 10.0), &wind);
        assert!((d - Vec3::new(0.0, 0.0, -30.0)).length() < 1e-4, "{d}");
        // Head-on: no lift.
        assert!(l.length() < 1e-4);
        // Flipping the triangle does not flip the drag.
        let (d2, _) = triangle_wind_force([x[0], x[2], x[1]], Vec3::new(0.0, 0.0, 10.0), &wind);
        assert!((d2 - d).length() < 1e-4);
        // At 45°: drag scales with cos, lift is perpendicular to the flow.
        let v = Vec3::new(0.0, 10.0, 10.0);
        let (d, l) = triangle_wind_force(x, v, &wind);
        let c = 0.5f32.sqrt();
        assert!((d.length() - 0.6 * 200.0 * 0.5 * c).abs() < 1e-3);
        assert!(d.dot(v) < 0.0 && l.dot(v).abs() < 1e-3 && l.length() > 0.0);
        assert!((l.length() - 0.3 * 200.0 * 0.5 * c * c).abs() < 1e-3);
    }

    /// Wind accelerations on one resting triangle with this inverse mass per vertex.
    fn resting_triangle(corners: [Vec3; 3], inv_mass: f32, wind: WindParams, dt: f32) -> Vec<Vec4> {
        let field = WindField::new([(wind, None)]);
        let pos = corners.map(|p| p.extend(inv_mass));
        let (mut air, mut out) = (Vec::new(), Vec::new());
        wind_accelerations(
            &pos,
            &[Vec4::ZERO; 3],
            &[[0, 1, 2]],
            &field,
            0.0,
            dt,
            &mut air,
            &mut out,
        );
        out
    }

    #[test]
    fn steady_wind_pushes_a_resting_sheet_downwind() {
        let wind = WindParams {
            velocity: Vec3::new(0.0, 0.0, -5.0),
            gust_amplitude: 0.0,
            turbulence: 0.0,
            ..Default::default()
        };
        let out = resting_triangle([Vec3::ZERO, Vec3::X, Vec3::Y], 1.0, wind, 1.0 / 60.0);
        // v_rel = +5 z: F_D = −0.6·25·½ z = −7.5 z, a third per vertex, unit masses.
        for a in &out {
            assert!((a.xyz() - Vec3::new(0.0, 0.0, -2.5)).length() < 1e-4, "{a}");
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
        // Turbulence is constant along the wind direction (only the travelling gust changes).
        let calm = WindField::new([(
            WindParams {
                gust_amplitude: 0.0,
                ..Default::default()
            },
            None,
        )]);
        let a = calm.velocity_at(p, 0.7);
        let b = calm.velocity_at(p + Vec3::X * 3.0, 0.7);
        assert!((a - b).length() < 1e-5);
    }

    #[test]
    fn hurricane_force_is_capped() {
        let wind = WindParams {
            velocity: Vec3::new(100.0, 0.0, 0.0),
            ..Default::default()
        };
        let dt = 1.0 / 60.0;
        let out = resting_triangle([Vec3::ZERO, Vec3::Y, Vec3::Z], 100.0, wind, dt);
        // No vertex can be accelerated past the air speed in one step.
        for a in &out {
            assert!(a.length() * dt <= 200.0, "{a}");
            assert!(a.x > 0.0);
        }
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
