//! Scalar/SIMD-generic arithmetic for the constraint kernels.
//!
//! Each kernel's math is written once over [`Real`] and [`V3`]. With `f32` it is the scalar
//! reference (and handles batch tails); with [`wide::f32x4`] it projects four independent
//! constraints of one colour at once. Both share every formula, so they agree up to the
//! rounding of `sqrt`/`atan2`.

use core::ops::{Add, Div, Mul, Neg, Sub};
use glam::Vec4;
use wide::{CmpGt, f32x4};

/// A lane type: `f32` or `f32x4`.
pub(crate) trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    fn splat(v: f32) -> Self;
    fn sqrt(self) -> Self;
    /// `atan2(self, x)`: the angle of `(x, self)`.
    fn atan2(self, x: Self) -> Self;
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    /// Per lane: `if self > limit { a } else { b }`.
    fn if_gt(self, limit: Self, a: Self, b: Self) -> Self;
}

impl Real for f32 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        f32::atan2(self, x)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        f32::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32::max(self, o)
    }
    #[inline(always)]
    fn if_gt(self, limit: Self, a: Self, b: Self) -> Self {
        if self > limit { a } else { b }
    }
}

impl Real for f32x4 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        f32x4::splat(v)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32x4::sqrt(self)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        f32x4::atan2(self, x)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        f32x4::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32x4::max(self, o)
    }
    #[inline(always)]
    fn if_gt(self, limit: Self, a: Self, b: Self) -> Self {
        self.cmp_gt(limit).blend(a, b)
    }
}

/// A 3-vector of lanes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct V3<T> {
    pub x: T,
    pub y: T,
    pub z: T,
}

impl From<glam::Vec3> for V3<f32> {
    fn from(v: glam::Vec3) -> Self {
        Self {
            x: v.x,
            y: v.y,
            z: v.z,
        }
    }
}

impl<T: Real> V3<T> {
    #[inline(always)]
    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        V3 {
            x: self.y * o.z - self.z * o.y,
            y: self.z * o.x - self.x * o.z,
            z: self.x * o.y - self.y * o.x,
        }
    }
    #[inline(always)]
    pub fn scale(self, s: T) -> Self {
        V3 {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
    #[inline(always)]
    pub fn length_squared(self) -> T {
        self.dot(self)
    }
}

impl<T: Real> Add for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        V3 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl<T: Real> Sub for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        V3 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

impl<T: Real> Neg for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        V3 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// Scalar load: `(xyz, w)` of one vertex.
#[inline(always)]
pub(crate) fn load1(p: Vec4) -> (V3<f32>, f32) {
    (
        V3 {
            x: p.x,
            y: p.y,
            z: p.z,
        },
        p.w,
    )
}

/// Scalar store of a position change.
#[inline(always)]
pub(crate) fn add1(p: &mut Vec4, d: V3<f32>) {
    p.x += d.x;
    p.y += d.y;
    p.z += d.z;
}

/// Four consecutive values of a slice chunk as lanes.
#[inline(always)]
pub(crate) fn lanes(s: &[f32]) -> f32x4 {
    f32x4::new([s[0], s[1], s[2], s[3]])
}

/// Four consecutive indices of a slice chunk.
#[inline(always)]
pub(crate) fn idx(s: &[u32]) -> [u32; 4] {
    [s[0], s[1], s[2], s[3]]
}
