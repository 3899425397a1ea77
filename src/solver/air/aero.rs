//! Air: how a cloth meets the air it moves through, with or without wind; see
//! [`Aerodynamics`].

use glam::{Vec3, Vec4, Vec4Swizzles};
use wide::{CmpGt, CmpLt, f32x4};

use crate::solver::limits::{self, ParamError};

/// How a cloth meets the air: `½·ρ·C` coefficients in kg/m³.
///
/// Each free vertex `i` carries a share of the surface: its *area vector* `A_i`, a third of
/// the area-weighted normals `½(x₁ − x₀) × (x₂ − x₀)` of its triangles (computed at the start
/// of each step). With `a = |A_i|`, `n = A_i/a`, the vertex velocity `v`, the air velocity `u`
/// (zero without wind), `v_rel = v − u`, `s = |v_rel|`, `ṽ = v_rel/s` and `c = ṽ·n`, the
/// force on the vertex is (report §3.7, plus skin friction):
///
/// ```text
/// F_D = −drag     · s² · a · |c| · ṽ                 pressure drag, against the relative flow
/// F_L =  lift     · s² · a ·  c  · ((n × ṽ) × ṽ)      lift, across the relative flow
/// F_F = −friction · s  · a · (v_rel − (v_rel·n) n)   skin friction, along the surface
/// ```
///
/// The coefficients are `½·ρ·C` in kg/m³ (air: ρ ≈ 1.2 kg/m³). None of the terms depends on
/// which way `n` points. The force is applied every substep with that substep's velocity, as
/// a velocity change `Δv = F·h/m` damped to `Δv/(1 + |Δv|/s)`: it never carries a vertex past
/// the air's speed, whatever the wind or the time step, and is the plain force when
/// `|Δv| ≪ s`.
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aerodynamics {
    /// Pressure drag against the relative flow, scaled by how squarely the surface faces it.
    /// Default 0.6 (a flat plate across the flow, `C_D ≈ 1`): a 1 m², 100 g sheet falling
    /// flat settles at about 1.3 m/s.
    pub drag: f32,
    /// Lift across the relative flow, largest at 45°. Default 0.3.
    pub lift: f32,
    /// Skin friction along the surface: what a flag streaming edge-on in the wind still
    /// feels. Default 0.02.
    pub friction: f32,
}

impl Aerodynamics {
    /// No air: the cloth moves as in a vacuum.
    pub const NONE: Aerodynamics = Aerodynamics {
        drag: 0.0,
        lift: 0.0,
        friction: 0.0,
    };

    /// Largest accepted coefficient, kg/m³ (a thousand times water's `½ρ`).
    pub const MAX: f32 = limits::AIR_DRAG.max;

    /// Whether every coefficient is zero (no air pass at all).
    #[must_use]
    pub fn is_none(&self) -> bool {
        self.drag == 0.0 && self.lift == 0.0 && self.friction == 0.0
    }

    /// Checks the coefficients: drag and friction in `[0, MAX]`, lift in `[−MAX, MAX]`.
    ///
    /// # Errors
    /// A [`ParamError`] naming the first coefficient out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        limits::AIR_DRAG.check(self.drag)?;
        limits::AIR_LIFT.check(self.lift)?;
        limits::AIR_FRICTION.check(self.friction)
    }
}

impl Default for Aerodynamics {
    fn default() -> Self {
        Self {
            drag: 0.6,
            lift: 0.3,
            friction: 0.02,
        }
    }
}

/// The air force on a surface element with area vector `area` (normal times area, m²)
/// moving at `v_rel` relative to the air: `F_D + F_L + F_F` of [`Aerodynamics`], N.
#[must_use]
#[inline]
pub fn air_force(area: Vec3, v_rel: Vec3, air: &Aerodynamics) -> Vec3 {
    let a = area.length();
    let s2 = v_rel.length_squared();
    if !(a > 0.0 && s2 > 0.0 && a.is_finite() && s2.is_finite()) {
        return Vec3::ZERO;
    }
    let n = area / a;
    let s = s2.sqrt();
    let dir = v_rel / s;
    let c = dir.dot(n);
    // (n × ṽ) × ṽ = c·ṽ − n.
    let pressure = -air.drag * c.abs() * dir + air.lift * c * (c * dir - n);
    let tangential = v_rel - v_rel.dot(n) * n;
    a * (s2 * pressure - air.friction * s * tangential)
}

/// The velocity change of a vertex of inverse mass `inv_mass` over a substep of `h` seconds:
/// [`air_force`]`·h·inv_mass`, damped to `Δv/(1 + |Δv|/|v_rel|)` so it never overshoots the
/// air's speed.
#[must_use]
#[inline]
pub fn air_velocity_change(
    area: Vec3,
    v_rel: Vec3,
    inv_mass: f32,
    h: f32,
    air: &Aerodynamics,
) -> Vec3 {
    let dv = air_force(area, v_rel, air) * (h * inv_mass);
    let s = v_rel.length();
    let m = dv.length();
    if !(m > 0.0 && m.is_finite()) {
        return Vec3::ZERO;
    }
    dv / (1.0 + m / s)
}

/// [`air_velocity_change`] for four vertices at once, each lane the same operations in the
/// same order (IEEE `sqrt` and division, no fused multiply–add), so every lane equals the
/// one-vertex function's result bit for bit, zeros where it returns zero included. The step's
/// integration runs it four free vertices at a time: one vertex's chain of square roots and
/// divisions waits on itself, four in lanes do not.
#[must_use]
#[inline]
pub(crate) fn air_velocity_changes4(
    area: [Vec3; 4],
    v_rel: [Vec3; 4],
    inv_mass: [f32; 4],
    h: f32,
    air: &Aerodynamics,
) -> [Vec3; 4] {
    let lane = |v: [Vec3; 4], f: fn(Vec3) -> f32| f32x4::new(v.map(f));
    let (ax, ay, az) = (
        lane(area, |v| v.x),
        lane(area, |v| v.y),
        lane(area, |v| v.z),
    );
    let (vx, vy, vz) = (
        lane(v_rel, |v| v.x),
        lane(v_rel, |v| v.y),
        lane(v_rel, |v| v.z),
    );
    let (zero, inf) = (f32x4::ZERO, f32x4::splat(f32::INFINITY));
    // air_force
    let a = (ax * ax + ay * ay + az * az).sqrt();
    let s2 = vx * vx + vy * vy + vz * vz;
    let force_on = a.cmp_gt(zero) & s2.cmp_gt(zero) & a.cmp_lt(inf) & s2.cmp_lt(inf);
    let (nx, ny, nz) = (ax / a, ay / a, az / a);
    let s = s2.sqrt();
    let (dx, dy, dz) = (vx / s, vy / s, vz / s);
    let c = dx * nx + dy * ny + dz * nz;
    let k_drag = f32x4::splat(-air.drag) * c.abs();
    let k_lift = f32x4::splat(air.lift) * c;
    let (px, py, pz) = (
        k_drag * dx + k_lift * (c * dx - nx),
        k_drag * dy + k_lift * (c * dy - ny),
        k_drag * dz + k_lift * (c * dz - nz),
    );
    let t = vx * nx + vy * ny + vz * nz;
    let (tx, ty, tz) = (vx - t * nx, vy - t * ny, vz - t * nz);
    let k_friction = f32x4::splat(air.friction) * s;
    let fx = force_on.blend(a * (s2 * px - k_friction * tx), zero);
    let fy = force_on.blend(a * (s2 * py - k_friction * ty), zero);
    let fz = force_on.blend(a * (s2 * pz - k_friction * tz), zero);
    // air_velocity_change
    let k = f32x4::splat(h) * f32x4::new(inv_mass);
    let (dvx, dvy, dvz) = (fx * k, fy * k, fz * k);
    let m = (dvx * dvx + dvy * dvy + dvz * dvz).sqrt();
    let on = m.cmp_gt(zero) & m.cmp_lt(inf);
    let q = f32x4::ONE + m / s;
    let (rx, ry, rz) = (
        on.blend(dvx / q, zero).to_array(),
        on.blend(dvy / q, zero).to_array(),
        on.blend(dvz / q, zero).to_array(),
    );
    core::array::from_fn(|i| Vec3::new(rx[i], ry[i], rz[i]))
}

/// Each vertex's area vector (`w = 0`): a third of the area-weighted normals of its
/// triangles, `Σ ⅙ (x₁ − x₀) × (x₂ − x₀)`, written into `out`. Triangles must be wound
/// consistently (the topology's are); degenerate or non-finite triangles add nothing.
pub fn vertex_area_vectors(positions: &[Vec4], triangles: &[[u32; 3]], out: &mut Vec<Vec4>) {
    out.clear();
    out.resize(positions.len(), Vec4::ZERO);
    for tri in triangles {
        let [i, j, k] = tri.map(|v| v as usize);
        let (a, b, c) = (positions[i].xyz(), positions[j].xyz(), positions[k].xyz());
        let third = ((b - a).cross(c - a) / 6.0).extend(0.0);
        if !third.is_finite() {
            continue;
        }
        out[i] += third;
        out[j] += third;
        out[k] += third;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn head_on_drag_has_the_formula_magnitude_and_no_lift() {
        // 0.5 m² facing +z, moving at 10 m/s along +z through still air: F = −0.6·100·0.5 z.
        let air = Aerodynamics::default();
        let f = air_force(Vec3::Z * 0.5, Vec3::Z * 10.0, &air);
        assert!((f - Vec3::new(0.0, 0.0, -30.0)).length() < 1e-3, "{f}");
        // The normal's sign does not matter.
        let g = air_force(-Vec3::Z * 0.5, Vec3::Z * 10.0, &air);
        assert!((f - g).length() < 1e-4);
    }

    #[test]
    fn oblique_flow_gives_drag_lift_and_friction() {
        let air = Aerodynamics::default();
        let v = Vec3::new(0.0, 10.0, 10.0);
        let area = Vec3::Z * 0.5;
        let f = air_force(area, v, &air);
        let c = 0.5f32.sqrt();
        let s2 = 200.0;
        let dir = v.normalize();
        // Along the flow: drag plus friction's share; across it: lift minus friction's share.
        let tangential = Vec3::new(0.0, 10.0, 0.0);
        let expect = 0.5
            * (s2 * (-0.6 * c * dir + 0.3 * c * (c * dir - Vec3::Z))
                - 0.02 * s2.sqrt() * tangential);
        assert!((f - expect).length() < 1e-3, "{f} vs {expect}");
        assert!(
            f.dot(v) < 0.0,
            "the air takes energy out of the relative motion"
        );
        // Lift is perpendicular to the flow.
        let lift = 0.5 * s2 * 0.3 * c * (c * dir - Vec3::Z);
        assert!(lift.dot(v).abs() < 1e-3 && lift.length() > 1.0);
    }

    #[test]
    fn four_lanes_give_the_one_vertex_results_bit_for_bit() {
        // Ordinary values and every kind of edge: zero, subnormal, huge, infinite and NaN
        // areas and speeds, masses from pinned to overflowing, air off, lift negative.
        let special = [
            0.0,
            -0.0,
            1e-40,
            -3e-39,
            1e-20,
            1e20,
            -1e25,
            3e38,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let value = |next: &mut dyn FnMut() -> u64| -> f32 {
            let r = next();
            if r.is_multiple_of(5) {
                special[(r >> 8) as usize % special.len()]
            } else {
                // Spread over magnitudes 1e-6..1e3, both signs.
                let m = (r >> 16) as f32 / (1u64 << 48) as f32;
                let e = ((r >> 8) % 10) as i32 - 6;
                if r & 0x80 == 0 {
                    m * 10f32.powi(e)
                } else {
                    -m * 10f32.powi(e)
                }
            }
        };
        let airs = [
            Aerodynamics::default(),
            Aerodynamics::NONE,
            Aerodynamics {
                drag: 2.0,
                lift: -1.5,
                friction: 0.3,
            },
        ];
        let (mut compared, mut moving) = (0, 0);
        for round in 0..20_000 {
            let air = airs[round % airs.len()];
            let v3 =
                |next: &mut dyn FnMut() -> u64| Vec3::new(value(next), value(next), value(next));
            let area: [Vec3; 4] = core::array::from_fn(|_| v3(&mut next));
            let v_rel: [Vec3; 4] = core::array::from_fn(|_| v3(&mut next));
            let inv_mass: [f32; 4] = core::array::from_fn(|_| value(&mut next).abs());
            let h = [1.0 / 600.0, 0.1, 1e-4][round % 3];
            let four = air_velocity_changes4(area, v_rel, inv_mass, h, &air);
            for k in 0..4 {
                let one = air_velocity_change(area[k], v_rel[k], inv_mass[k], h, &air);
                assert_eq!(
                    one.to_array().map(f32::to_bits),
                    four[k].to_array().map(f32::to_bits),
                    "lane {k} of round {round}: {one} one at a time, {} in lanes \
                     (area {}, v_rel {}, 1/m {}, h {h}, {air:?})",
                    four[k],
                    area[k],
                    v_rel[k],
                    inv_mass[k],
                );
                compared += 1;
                moving += usize::from(one != Vec3::ZERO);
            }
        }
        // The comparison covered real forces, not only the zeros of the edge cases.
        assert_eq!(compared, 80_000);
        assert!(moving > 20_000, "{moving} lanes with a force");
    }

    #[test]
    fn edge_on_flow_feels_only_skin_friction() {
        let air = Aerodynamics::default();
        let f = air_force(Vec3::Y, Vec3::X * 8.0, &air);
        assert!(
            (f - Vec3::new(-0.02 * 8.0 * 8.0, 0.0, 0.0)).length() < 1e-4,
            "{f}"
        );
        let none = air_force(Vec3::Y, Vec3::X * 8.0, &Aerodynamics::NONE);
        assert_eq!(none, Vec3::ZERO);
    }

    #[test]
    fn the_velocity_change_never_overshoots_the_air() {
        let air = Aerodynamics {
            drag: 1000.0,
            ..Default::default()
        };
        for h in [1e-4, 1e-2, 1.0, 100.0] {
            let v_rel = Vec3::new(0.0, 0.0, 7.0);
            let dv = air_velocity_change(Vec3::Z, v_rel, 10.0, h, &air);
            assert!(dv.z < 0.0 && dv.z > -7.0, "h {h}: {dv}");
        }
        // Small forces pass unchanged (to first order).
        let dv = air_velocity_change(Vec3::Z * 1e-3, Vec3::Z, 1.0, 1e-3, &Aerodynamics::default());
        let plain = air_force(Vec3::Z * 1e-3, Vec3::Z, &Aerodynamics::default()) * 1e-3;
        assert!((dv - plain).length() < 1e-9 + plain.length() * 1e-5);
        // Garbage in, nothing out.
        let nan = air_velocity_change(Vec3::NAN, Vec3::Z, 1.0, 0.01, &air);
        assert_eq!(nan, Vec3::ZERO);
        let inf = air_velocity_change(Vec3::Z, Vec3::INFINITY, 1.0, 0.01, &air);
        assert_eq!(inf, Vec3::ZERO);
    }

    #[test]
    fn area_vectors_sum_to_the_sheet_area() {
        // Two triangles making the unit square in the xy plane, wound towards +z.
        let p = [
            Vec4::new(0.0, 0.0, 0.0, 1.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::new(1.0, 1.0, 0.0, 1.0),
            Vec4::new(0.0, 1.0, 0.0, 1.0),
        ];
        let mut out = Vec::new();
        vertex_area_vectors(&p, &[[0, 1, 2], [0, 2, 3]], &mut out);
        let total: Vec4 = out.iter().copied().sum();
        assert!(
            (total - Vec4::new(0.0, 0.0, 1.0, 0.0)).length() < 1e-6,
            "{total}"
        );
        // Vertex 0 touches both triangles: a third of the whole square.
        assert!((out[0].z - 1.0 / 3.0).abs() < 1e-6);
        assert!((out[1].z - 1.0 / 6.0).abs() < 1e-6);
    }

    #[test]
    fn validation_names_the_coefficient() {
        assert!(Aerodynamics::default().validate().is_ok());
        assert!(Aerodynamics::NONE.validate().is_ok());
        for (bad, name) in [
            (
                Aerodynamics {
                    drag: -0.1,
                    ..Default::default()
                },
                "air.drag",
            ),
            (
                Aerodynamics {
                    lift: f32::NAN,
                    ..Default::default()
                },
                "air.lift",
            ),
            (
                Aerodynamics {
                    friction: f32::INFINITY,
                    ..Default::default()
                },
                "air.friction",
            ),
        ] {
            assert_eq!(bad.validate().unwrap_err().name, name);
        }
    }
}
