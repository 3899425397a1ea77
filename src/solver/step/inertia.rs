//! Inertia: how much of its anchor's motion a cloth feels.
//!
//! A cloth is simulated in world space, so a character that sprints drags its cape through
//! the air at full speed and a turn swings it round: realistic, and often more than a game
//! wants (a cape stretched to twice its length by a dash). Engines scale the motion a cloth
//! feels (Unity's world velocity and acceleration scales, NvCloth's inertia multipliers): each
//! step the part of the anchor's motion the cloth should *not* feel is applied to every
//! vertex as a rigid motion ([`Carry`]), so that part moves the cloth as if it were glued to
//! its anchor and only the rest drives its dynamics.
//!
//! A carry can also change the cloth's size with its entity ([`Stretch`]): an entity scaled
//! at runtime (a banner that pops in by growing from nothing) takes its cloth with it.

use glam::{Mat3, Quat, Vec3, Vec4};

use super::state::ClothState;
use super::substeps::clamp_speed;

/// A motion applied to a whole cloth: `x ↦ rotation·(x − pivot) + pivot + translation`, then
/// the [`Stretch`] if there is one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Carry {
    /// Rotation about `pivot`.
    pub rotation: Quat,
    /// The point the rotation turns about.
    pub pivot: Vec3,
    /// Translation after the rotation.
    pub translation: Vec3,
    /// A change of size and shape after the rigid motion (its entity scaled); `None` for a
    /// rigid carry.
    pub stretch: Option<Stretch>,
}

/// A change of a cloth's size and shape about a point: `x ↦ center + linear·(x − center)`
/// (`linear` a scale along the entity's axes, turned into world space).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stretch {
    /// The point that stays.
    pub center: Vec3,
    /// The linear map about it.
    pub linear: Mat3,
}

impl Stretch {
    /// The stretch by `linear` about the point a change of an entity's pose holds still, its
    /// origin having moved from `was` to `now` meanwhile: where `x ↦ c + linear·(x − c)` takes
    /// `was` to `now`. A parent scaled about its own origin holds that still, not the child's
    /// origin (which the scale moves): a banner hanging from a scaled mount grows from the
    /// mount, as its pins do, instead of being shifted against them at every step of the
    /// growth. Where the point lies outside `bounds` (the cloth's extent; `None`: its origin
    /// now) it is brought to the nearest point of them: an entity that moves while its scale
    /// changes (a walk, whose motion a small change of scale would explain only about a point
    /// far away) still moves its cloth through the pins, as it does at a constant scale,
    /// instead of carrying it along. A direction `linear` does not scale keeps the origin's
    /// coordinate.
    #[must_use]
    pub fn holding(linear: Mat3, was: Vec3, now: Vec3, bounds: Option<(Vec3, Vec3)>) -> Self {
        // c = now + δ with (I − L)·δ = L·(now − was), in regularised least squares: a
        // direction L does not change (I − L ≈ 0 there) gives δ nothing along it.
        let a = Mat3::IDENTITY - linear;
        let normal = a.transpose() * a;
        let size = (normal.x_axis.x + normal.y_axis.y + normal.z_axis.z) / 3.0;
        let regular = normal + Mat3::from_diagonal(Vec3::splat(1e-6 * size + f32::MIN_POSITIVE));
        let delta = regular.inverse() * (a.transpose() * (linear * (now - was)));
        let held = now + delta;
        let center = match bounds {
            Some((lo, hi)) if held.is_finite() && lo.cmple(hi).all() => held.clamp(lo, hi),
            _ => now,
        };
        Self { center, linear }
    }
}

impl Carry {
    /// No motion.
    pub const IDENTITY: Self = Self {
        rotation: Quat::IDENTITY,
        pivot: Vec3::ZERO,
        translation: Vec3::ZERO,
        stretch: None,
    };

    /// This motion followed by `stretch`.
    #[must_use]
    pub fn then_stretch(self, stretch: Stretch) -> Self {
        Self {
            stretch: Some(stretch),
            ..self
        }
    }

    /// This carry, then `next`, as one: the same map (to rounding) as applying the two in
    /// turn. Rigid when both are; otherwise the whole map is its stretch (about the origin,
    /// after a translation), so a velocity is turned by it and kept no faster, as one stretch
    /// does. The GPU backend folds the carries of a frame's steps into its first this way
    /// when the frame changed the cloth's rest shape (see `queue_gpu_steps`).
    #[must_use]
    pub fn then(self, next: Self) -> Self {
        let (m1, b1) = self.affine();
        let (m2, b2) = next.affine();
        let (m, b) = (m2 * m1, m2 * b1 + b2);
        if self.stretch.is_none() && next.stretch.is_none() {
            Self {
                rotation: next.rotation * self.rotation,
                pivot: Vec3::ZERO,
                translation: b,
                stretch: None,
            }
        } else {
            // x ↦ m·(x + m⁻¹·b).
            Self {
                rotation: Quat::IDENTITY,
                pivot: Vec3::ZERO,
                translation: m.inverse() * b,
                stretch: Some(Stretch {
                    center: Vec3::ZERO,
                    linear: m,
                }),
            }
        }
    }

    /// The motion as `x ↦ m·x + b`: the rotation's matrix (times the stretch's) and the
    /// offset, the form both the CPU ([`ClothState::carry`]) and the GPU's `teleport` kernel
    /// apply, in the same order.
    #[must_use]
    pub fn affine(&self) -> (Mat3, Vec3) {
        let m = Mat3::from_quat(self.rotation);
        let b = self.pivot + self.translation - m * self.pivot;
        match self.stretch {
            None => (m, b),
            Some(s) => (
                s.linear * m,
                rotate(&s.linear, b) + s.center - rotate(&s.linear, s.center),
            ),
        }
    }

    /// Whether every part of the motion is finite (a carry that is not is never applied).
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite()
            && self.pivot.is_finite()
            && self.translation.is_finite()
            && self
                .stretch
                .is_none_or(|s| s.center.is_finite() && s.linear.is_finite())
    }

    /// The velocity the rigid part of this motion (its rotation and translation; a stretch
    /// is a change of the cloth's size, not a motion through the air) gives the points it
    /// moves, spread over a step of `dt` seconds; `None` for no motion, a non-finite one or
    /// a step that is not positive.
    #[must_use]
    pub fn velocity(&self, dt: f32) -> Option<CarriedVelocity> {
        if !(self.is_finite() && dt.is_finite() && dt > 0.0) {
            return None;
        }
        let back = Mat3::from_quat(self.rotation).transpose();
        let v = CarriedVelocity {
            turn: (Mat3::IDENTITY - back) * (1.0 / dt),
            pivot: self.pivot + self.translation,
            along: self.translation / dt,
        };
        (v.turn.is_finite()
            && v.along.is_finite()
            && (v.turn != Mat3::ZERO || v.along != Vec3::ZERO))
            .then_some(v)
    }

    /// Where `p` goes.
    #[must_use]
    pub fn apply(&self, p: Vec3) -> Vec3 {
        let (m, b) = self.affine();
        rotate(&m, p) + b
    }

    /// The part of an anchor's motion from `(from, from_rotation)` to `(to, to_rotation)` a
    /// cloth with inertia `linear` and `angular` (each in `0..=1`: 1 feels all of it, 0
    /// none) does not feel: `1 − linear` of the translation, and `1 − angular` of the
    /// rotation about the anchor's old position. `None` when nothing is to be carried (both
    /// inertias 1, or an anchor that did not move) or when an input is not finite.
    #[must_use]
    pub fn unfelt(
        (from, from_rotation): (Vec3, Quat),
        (to, to_rotation): (Vec3, Quat),
        linear: f32,
        angular: f32,
    ) -> Option<Self> {
        let finite = from.is_finite()
            && to.is_finite()
            && from_rotation.is_finite()
            && to_rotation.is_finite()
            && linear.is_finite()
            && angular.is_finite();
        if !finite || (linear >= 1.0 && angular >= 1.0) {
            return None;
        }
        let delta = (to_rotation * from_rotation.inverse()).normalize();
        let rotation = Quat::IDENTITY
            .slerp(delta, (1.0 - angular).clamp(0.0, 1.0))
            .normalize();
        let translation = (1.0 - linear).clamp(0.0, 1.0) * (to - from);
        let carry = Self {
            rotation,
            pivot: from,
            translation,
            stretch: None,
        };
        (carry.rotation != Quat::IDENTITY || carry.translation != Vec3::ZERO).then_some(carry)
    }
}

/// `m·p` summed column by column in a fixed order (`m.x_axis·p.x + m.y_axis·p.y +
/// m.z_axis·p.z`), as the GPU twin writes it.
#[inline]
fn rotate(m: &Mat3, p: Vec3) -> Vec3 {
    m.x_axis * p.x + m.y_axis * p.y + m.z_axis * p.z
}

/// The velocity a carried motion gives the points it moves over a step ([`Carry::velocity`]):
/// at a point's carried position `y`, `(y − C⁻¹(y)) / dt`, which for a rotation `R` about
/// `p` then a translation `t` is `turn·(y − p − t) + along` with `turn = (I − Rᵀ)/dt` and
/// `along = t / dt` (differences from the carried pivot `p + t`, small near the cloth even
/// far from the origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarriedVelocity {
    /// `(I − Rᵀ) / dt`.
    pub turn: Mat3,
    /// Where the rotation's pivot was carried to.
    pub pivot: Vec3,
    /// The velocity at the carried pivot, `t / dt`.
    pub along: Vec3,
}

impl CarriedVelocity {
    /// The velocity at the carried position `y`.
    #[must_use]
    #[inline]
    pub fn at(&self, y: Vec3) -> Vec3 {
        rotate(&self.turn, y - self.pivot) + self.along
    }
}

impl ClothState {
    /// Moves every vertex by `carry` (positions and substep starts; velocities turn with the
    /// rotation and stretch with the stretch, but a stretch never makes a vertex faster: a
    /// cloth grown in from a small scale would otherwise swing with its speeds multiplied by
    /// the growth), leaving pin targets where they are: the motion a cloth does not feel. A
    /// non-finite carry is ignored.
    pub fn carry(&mut self, carry: &Carry) {
        if !carry.is_finite() {
            return;
        }
        let (m, b) = carry.affine();
        let moved = |p: Vec4| (rotate(&m, p.truncate()) + b).extend(p.w);
        for (p, q) in self.positions.iter_mut().zip(&mut self.prev) {
            *p = moved(*p);
            *q = moved(*q);
        }
        let stretched = carry.stretch.is_some();
        for v in &mut self.velocities {
            let was = v.truncate();
            let turned = rotate(&m, was);
            let turned = if stretched {
                no_faster(turned, was)
            } else {
                turned
            };
            *v = turned.extend(v.w);
        }
    }
}

/// A velocity `was` carried through a stretch to `turned`, shortened to `was`'s speed where
/// the stretch made it faster ([`clamp_speed`]; the GPU's `teleport` kernel does the same). A
/// cloth grown in from a small scale (a pop-in) would otherwise have its speeds multiplied by
/// the growth: a 64² banner grown from scale 0.05 to 1 in half a second swung at 4.3 m/s half
/// a second later, 14 % stretched and with 34 edge–triangle pairs through itself, against
/// 1.1 m/s, 4 % and none with the speeds kept. A shrink still slows it down with its size. (A
/// velocity so large that the stretch overflows it comes out at rest.)
#[inline]
fn no_faster(turned: Vec3, was: Vec3) -> Vec3 {
    let kept = clamp_speed(turned.extend(0.0), was.length()).truncate();
    if kept.is_finite() { kept } else { Vec3::ZERO }
}

#[cfg(test)]
mod tests {
    use super::super::state::Pin;
    use super::*;

    const FROM: (Vec3, Quat) = (Vec3::new(1.0, 2.0, 3.0), Quat::IDENTITY);

    #[test]
    fn full_inertia_carries_nothing_and_none_carries_the_whole_motion() {
        let to = (Vec3::new(4.0, 2.0, -1.0), Quat::from_rotation_y(0.7));
        assert_eq!(Carry::unfelt(FROM, to, 1.0, 1.0), None);
        assert_eq!(Carry::unfelt(FROM, FROM, 0.3, 0.3), None);
        // Inertia 0: a point fixed to the anchor goes exactly where the anchor takes it.
        let glued = Carry::unfelt(FROM, to, 0.0, 0.0).unwrap();
        let offset = Vec3::new(0.2, -0.5, 0.4);
        let expected = to.0 + to.1 * (FROM.1.inverse() * offset);
        assert!(glued.apply(FROM.0 + offset).distance(expected) < 1e-5);
        // Inertia 0.25 in translation only: three quarters of the move carried.
        let linear = Carry::unfelt(FROM, (to.0, FROM.1), 0.25, 1.0).unwrap();
        assert!(
            linear
                .apply(FROM.0)
                .distance(FROM.0 + 0.75 * (to.0 - FROM.0))
                < 1e-6
        );
        // Half the turn about the anchor, none of the move.
        let turn = Carry::unfelt(FROM, (FROM.0, to.1), 1.0, 0.5).unwrap();
        assert!(turn.rotation.angle_between(Quat::from_rotation_y(0.35)) < 1e-5);
        assert_eq!(turn.apply(FROM.0), FROM.0);
        // Not finite: nothing.
        assert_eq!(
            Carry::unfelt((Vec3::NAN, Quat::IDENTITY), to, 0.0, 0.0),
            None
        );
    }

    /// The carried velocity at a carried point is how far the carry moved it over the step:
    /// `(C(x) − x) / dt` at `y = C(x)`, for a turn, a move and both (within the f32 rounding
    /// of the positions' difference over `dt`); a stretch alone moves nothing through the air.
    #[test]
    fn the_carried_velocity_is_the_carried_points_travel_over_the_step() {
        let dt = 1.0 / 60.0;
        let turn = Carry::unfelt(
            (Vec3::new(1.0, 2.0, 3.0), Quat::IDENTITY),
            (Vec3::new(1.3, 2.0, 2.6), Quat::from_rotation_y(0.4)),
            0.0,
            0.0,
        )
        .unwrap();
        let cases = [
            turn,
            Carry {
                translation: Vec3::ZERO,
                ..turn
            },
            Carry {
                rotation: Quat::IDENTITY,
                ..turn
            },
        ];
        for carry in cases {
            let v = carry.velocity(dt).unwrap();
            for x in [Vec3::new(1.5, 1.0, 3.2), Vec3::new(0.2, 2.5, 2.0)] {
                let y = carry.apply(x);
                let want = (y - x) / dt;
                let bound = 8.0 * f32::EPSILON * (x.abs().max_element() + 1.0) / dt;
                assert!(
                    (v.at(y) - want).length() < bound,
                    "{carry:?} at {x}: {} against {want}",
                    v.at(y)
                );
            }
        }
        let stretch = Carry::IDENTITY.then_stretch(Stretch {
            center: Vec3::ONE,
            linear: Mat3::from_diagonal(Vec3::splat(2.0)),
        });
        assert_eq!(stretch.velocity(dt), None);
        assert_eq!(turn.velocity(0.0), None);
    }

    #[test]
    fn a_carried_state_keeps_its_shape_its_pin_targets_and_its_own_velocity() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::new(0.0, 1.0, 1.0)];
        let mut s = ClothState::new(&positions, &[1.0; 3]).unwrap();
        s.set_pins([Pin {
            vertex: 0,
            target: Vec3::new(0.0, 0.5, 0.0),
        }])
        .unwrap();
        s.velocities[1] = Vec4::new(0.0, 0.0, 2.0, 0.0);
        let carry = Carry {
            rotation: Quat::from_rotation_x(0.5),
            pivot: Vec3::new(0.5, 0.0, 0.0),
            translation: Vec3::new(0.0, 0.0, 3.0),
            stretch: None,
        };
        let before = s.clone();
        s.carry(&carry);
        for i in 0..3 {
            let (a, b) = (before.position(i), s.position(i));
            assert!(b.distance(carry.apply(a)) < 1e-6, "vertex {i}");
        }
        assert!(
            (s.position(1).distance(s.position(2)) - positions[1].distance(positions[2])).abs()
                < 1e-6
        );
        assert_eq!(s.pins(), before.pins(), "pin targets stay");
        let v = s.velocities[1].truncate();
        assert!(v.distance(carry.rotation * Vec3::new(0.0, 0.0, 2.0)) < 1e-6);
        // Not finite: nothing moves.
        let mut t = before.clone();
        t.carry(&Carry {
            translation: Vec3::NAN,
            ..carry
        });
        assert_eq!(t.positions, before.positions);
    }

    #[test]
    fn a_stretch_follows_the_rigid_motion_and_stretches_velocities_never_faster() {
        let carry = Carry {
            rotation: Quat::from_rotation_y(0.3),
            pivot: Vec3::new(1.0, 0.0, 0.0),
            translation: Vec3::new(0.0, 2.0, 0.0),
            stretch: None,
        };
        let stretch = Stretch {
            center: Vec3::new(0.0, 1.0, 0.0),
            linear: Mat3::from_diagonal(Vec3::new(2.0, 1.0, 0.5)),
        };
        let both = carry.then_stretch(stretch);
        for p in [Vec3::ZERO, Vec3::new(0.3, -1.0, 2.0), Vec3::splat(5.0)] {
            let rigid = carry.apply(p);
            let expected = stretch.center + stretch.linear * (rigid - stretch.center);
            assert!(both.apply(p).distance(expected) < 1e-5, "{p}");
        }
        let mut s = ClothState::new(&[Vec3::ZERO, Vec3::X], &[1.0; 2]).unwrap();
        // Stretched to (2, 0, 0.5), faster than before: turned that way at its old speed.
        let v = Vec3::new(1.0, 0.0, 1.0);
        s.velocities[1] = v.extend(0.0);
        s.carry(&Carry::IDENTITY.then_stretch(stretch));
        let expected = Vec3::new(2.0, 0.0, 0.5).normalize() * v.length();
        assert!(
            s.velocities[1].truncate().distance(expected) < 1e-6,
            "{} against {expected}",
            s.velocities[1]
        );
        // A shrink slows it down with the size; a rigid carry turns it as it is.
        let shrink = Stretch {
            center: Vec3::ZERO,
            linear: Mat3::from_diagonal(Vec3::splat(0.5)),
        };
        s.velocities[1] = v.extend(0.0);
        s.carry(&Carry::IDENTITY.then_stretch(shrink));
        assert!(s.velocities[1].truncate().distance(0.5 * v) < 1e-7);
        s.velocities[1] = v.extend(0.0);
        s.carry(&carry);
        assert_eq!(
            s.velocities[1].truncate(),
            rotate(&Mat3::from_quat(carry.rotation), v)
        );
        // A growth that overflows a huge velocity leaves it at rest, not NaN.
        s.velocities[1] = Vec4::new(3.0e38, 0.0, 0.0, 0.0);
        s.carry(&Carry::IDENTITY.then_stretch(Stretch {
            center: Vec3::ZERO,
            linear: Mat3::from_diagonal(Vec3::splat(4.0)),
        }));
        assert!(s.velocities[1].is_finite(), "{}", s.velocities[1]);
        // Not finite: nothing moves.
        let before = s.positions.clone();
        s.carry(&Carry::IDENTITY.then_stretch(Stretch {
            linear: Mat3::from_diagonal(Vec3::new(f32::NAN, 1.0, 1.0)),
            ..stretch
        }));
        assert_eq!(s.positions, before);
    }

    /// Two carries folded into one move every point as the two in turn do: rigid ones into a
    /// rigid one, with a stretch into one whose stretch turns velocities (and keeps them no
    /// faster).
    #[test]
    fn carries_folded_into_one_move_points_as_the_two_in_turn() {
        let turn = Carry {
            rotation: Quat::from_rotation_y(0.4),
            pivot: Vec3::new(1.0, 0.0, -2.0),
            translation: Vec3::new(0.0, 0.3, 0.1),
            stretch: None,
        };
        let walk = Carry {
            rotation: Quat::from_rotation_x(-0.2),
            pivot: Vec3::new(0.0, 2.0, 0.0),
            translation: Vec3::new(0.5, 0.0, 0.0),
            stretch: None,
        };
        let grow = Carry::IDENTITY.then_stretch(Stretch {
            center: Vec3::new(0.0, 2.6, 0.0),
            linear: Mat3::from_diagonal(Vec3::new(1.5, 1.5, 1.2)),
        });
        let points = [
            Vec3::ZERO,
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-4.0, 0.5, 2.0),
        ];
        for (a, b) in [(turn, walk), (turn, grow), (grow, walk), (grow, grow)] {
            let both = a.then(b);
            assert_eq!(
                both.stretch.is_some(),
                a.stretch.is_some() || b.stretch.is_some()
            );
            for p in points {
                let expected = b.apply(a.apply(p));
                assert!(
                    both.apply(p).distance(expected) < 1e-5 * (1.0 + expected.length()),
                    "{p}: {} against {expected}",
                    both.apply(p)
                );
            }
        }
        assert_eq!(Carry::IDENTITY.then(Carry::IDENTITY), Carry::IDENTITY);
    }

    #[test]
    fn a_stretch_holds_still_the_point_its_change_of_pose_holds_still_within_the_cloth() {
        let close = |a: Vec3, b: Vec3| a.distance(b) < 1e-5 * (1.0 + b.length());
        let box_around = |c: Vec3, half: f32| Some((c - Vec3::splat(half), c + Vec3::splat(half)));
        // Scaled about its own origin: the origin.
        let o = Vec3::new(3.0, 2.0, -1.0);
        let grow = Mat3::from_diagonal(Vec3::splat(1.5));
        assert!(close(
            Stretch::holding(grow, o, o, box_around(o, 1.0)).center,
            o
        ));
        // A child hanging 0.7 m below a mount scaled from 0.4 to 0.6: the mount, which the
        // growth moved the child's origin away from.
        let mount = Vec3::new(-2.0, 2.6, 0.5);
        let below = Vec3::new(0.0, -0.7, 0.0);
        let (was, now) = (mount + 0.4 * below, mount + 0.6 * below);
        let held = Stretch::holding(grow, was, now, box_around(now, 0.6));
        assert!(close(held.center, mount), "{}", held.center);
        // The child's old origin goes where the new pose puts it.
        assert!(close(held.center + held.linear * (was - held.center), now));
        // The same growth scaled unevenly, along x only: the origin's offset along y is not
        // scaled, so the point held is the origin's, whatever its x.
        let wide = Mat3::from_diagonal(Vec3::new(1.5, 1.0, 1.0));
        let held = Stretch::holding(wide, now, now, box_around(now, 0.6));
        assert!(close(held.center, now), "{}", held.center);
        // Walking 2 cm while growing by 1 %: the point that explains it lies 2 m behind, out
        // of the cloth; the nearest point of its bounds is taken, so the stretch carries the
        // cloth by no more than the growth moves a point of it, and the walk is left to the pins.
        let walk = Vec3::new(0.02, 0.0, 0.0);
        let slight = Mat3::from_diagonal(Vec3::splat(1.01));
        let held = Stretch::holding(slight, o, o + walk, box_around(o + walk, 0.5));
        assert!(
            (held.center.x - (o.x + walk.x - 0.5)).abs() < 1e-5,
            "{}",
            held.center
        );
        let moved = held.center + held.linear * (o - held.center) - o;
        assert!(moved.length() < 0.011, "{moved}");
        // No bounds, or input that is not finite: the origin now.
        assert!(close(Stretch::holding(grow, was, now, None).center, now));
        let nan = Vec3::splat(f32::NAN);
        assert_eq!(
            Stretch::holding(grow, nan, now, box_around(now, 1.0)).center,
            now
        );
    }
}
