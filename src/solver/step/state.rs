//! The simulated state of one cloth, in structure-of-arrays form.
//!
//! Each per-vertex quantity is its own array of [`Vec4`] (16 bytes, `Pod`), so an array can be
//! uploaded to a GPU storage buffer as-is (`bytemuck::cast_slice`) and a CPU kernel loads one
//! aligned vector per vertex. Positions carry the vertex's *active* inverse mass in `w`
//! (0 for pinned vertices), so a constraint kernel gets both in one load.

use crate::solver::limits::{MAX_COORDINATE, MAX_VERTEX_MASS, within_range};
use glam::{Vec3, Vec4, Vec4Swizzles};

/// Positions, velocities and pins of one cloth.
#[derive(Clone, Debug, PartialEq)]
pub struct ClothState {
    /// `xyz`: position in metres; `w`: inverse mass used by the solver (0 = pinned).
    pub positions: Vec<Vec4>,
    /// `xyz`: velocity in m/s; `w` is 0.
    pub velocities: Vec<Vec4>,
    /// Positions at the start of the current substep (`w` as in `positions`).
    pub prev: Vec<Vec4>,
    /// Inverse masses the vertices have when not pinned.
    pub(crate) inv_mass: Vec<f32>,
    /// Pinned vertices and where they must be at the end of the next step.
    pub(crate) pins: Vec<Pin>,
}

/// A vertex held at a target position (inverse mass 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pin {
    /// Vertex index.
    pub vertex: u32,
    /// Where the vertex must be at the end of the next step. Between steps the pin moves
    /// linearly over the substeps, so a moving anchor drags the cloth smoothly.
    pub target: Vec3,
}

/// A state that cannot be built or a pin that cannot be set.
#[derive(Clone, Debug, PartialEq)]
pub enum StateError {
    /// Positions and masses have different lengths.
    LengthMismatch {
        /// Number of positions.
        positions: usize,
        /// Number of masses.
        masses: usize,
    },
    /// A mass is zero, negative, NaN, infinite, so small that its inverse is infinite, or
    /// heavier than [`MAX_VERTEX_MASS`].
    BadMass {
        /// Vertex index.
        vertex: usize,
        /// The mass given.
        mass: f32,
    },
    /// A position is NaN, infinite or farther than
    /// [`MAX_COORDINATE`] from the origin along an axis.
    NonFinitePosition {
        /// Vertex index.
        vertex: usize,
    },
    /// A pin names a vertex that does not exist.
    PinOutOfRange {
        /// The pin's vertex index.
        vertex: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// A pin target is NaN, infinite or farther than
    /// [`MAX_COORDINATE`] from the origin along an axis.
    NonFinitePinTarget {
        /// The pin's vertex index.
        vertex: u32,
    },
    /// Motion targets (or backstop normals) not one per vertex.
    MotionLengthMismatch {
        /// Number given.
        targets: usize,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// A motion target or backstop normal is NaN, infinite or farther than
    /// [`MAX_COORDINATE`] from the origin along an axis, or
    /// the backstop radius is not finite.
    NonFiniteMotionTarget {
        /// Vertex index.
        vertex: usize,
    },
}

impl core::fmt::Display for StateError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StateError::LengthMismatch { positions, masses } => {
                write!(f, "{positions} positions but {masses} masses")
            }
            StateError::BadMass { vertex, mass } => {
                write!(
                    f,
                    "vertex {vertex} has mass {mass}; masses must be finite, > 0 and at most \
                     {MAX_VERTEX_MASS} kg"
                )
            }
            StateError::NonFinitePosition { vertex } => {
                write!(
                    f,
                    "vertex {vertex} has a NaN, infinite or too distant position (limit {MAX_COORDINATE} m)"
                )
            }
            StateError::PinOutOfRange {
                vertex,
                vertex_count,
            } => write!(
                f,
                "pin on vertex {vertex}, but the cloth has {vertex_count} vertices"
            ),
            StateError::NonFinitePinTarget { vertex } => {
                write!(
                    f,
                    "pin on vertex {vertex} has a NaN, infinite or too distant target (limit {MAX_COORDINATE} m)"
                )
            }
            StateError::MotionLengthMismatch {
                targets,
                vertex_count,
            } => write!(
                f,
                "{targets} motion targets (or backstop normals) for a cloth of {vertex_count} vertices"
            ),
            StateError::NonFiniteMotionTarget { vertex } => write!(
                f,
                "vertex {vertex}'s motion target or backstop normal is NaN, infinite or too distant \
                 (limit {MAX_COORDINATE} m), or the backstop radius is not finite"
            ),
        }
    }
}

impl std::error::Error for StateError {}

impl ClothState {
    /// A cloth at rest at `positions` with per-vertex `masses` in kilograms, no pins.
    ///
    /// # Errors
    /// [`StateError`] if the lengths differ, a mass is not finite and positive or is over
    /// [`MAX_VERTEX_MASS`], or a position is not finite.
    pub fn new(positions: &[Vec3], masses: &[f32]) -> Result<Self, StateError> {
        if positions.len() != masses.len() {
            return Err(StateError::LengthMismatch {
                positions: positions.len(),
                masses: masses.len(),
            });
        }
        let mut inv_mass = Vec::with_capacity(masses.len());
        for (vertex, (&m, p)) in masses.iter().zip(positions).enumerate() {
            if !(m.is_finite() && m > 0.0 && (1.0 / m).is_finite() && m <= MAX_VERTEX_MASS) {
                return Err(StateError::BadMass { vertex, mass: m });
            }
            if !within_range(*p) {
                return Err(StateError::NonFinitePosition { vertex });
            }
            inv_mass.push(1.0 / m);
        }
        let pos: Vec<Vec4> = positions
            .iter()
            .zip(&inv_mass)
            .map(|(p, &w)| p.extend(w))
            .collect();
        Ok(Self {
            prev: pos.clone(),
            velocities: vec![Vec4::ZERO; pos.len()],
            positions: pos,
            inv_mass,
            pins: Vec::new(),
        })
    }

    /// Number of vertices.
    #[must_use]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the cloth has no vertices.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Position of vertex `i`.
    #[inline]
    #[must_use]
    pub fn position(&self, i: usize) -> Vec3 {
        self.positions[i].xyz()
    }

    /// Velocity of vertex `i`.
    #[inline]
    #[must_use]
    pub fn velocity(&self, i: usize) -> Vec3 {
        self.velocities[i].xyz()
    }

    /// Inverse mass vertex `i` has when it is not pinned.
    #[must_use]
    pub fn unpinned_inverse_mass(&self, i: usize) -> f32 {
        self.inv_mass[i]
    }

    /// The current pins.
    #[must_use]
    pub fn pins(&self) -> &[Pin] {
        &self.pins
    }

    /// Replaces all pins. Vertices no longer pinned get their mass back and keep their place.
    ///
    /// # Errors
    /// [`StateError`] if a pin's vertex is out of range or its target is not finite; the old
    /// pins are then kept.
    pub fn set_pins(&mut self, pins: impl IntoIterator<Item = Pin>) -> Result<(), StateError> {
        let pins: Vec<Pin> = pins.into_iter().collect();
        for pin in &pins {
            if pin.vertex as usize >= self.len() {
                return Err(StateError::PinOutOfRange {
                    vertex: pin.vertex,
                    vertex_count: self.len(),
                });
            }
            if !within_range(pin.target) {
                return Err(StateError::NonFinitePinTarget { vertex: pin.vertex });
            }
        }
        for pin in &self.pins {
            let i = pin.vertex as usize;
            self.positions[i].w = self.inv_mass[i];
            self.prev[i].w = self.inv_mass[i];
        }
        for pin in &pins {
            let i = pin.vertex as usize;
            self.positions[i].w = 0.0;
            self.prev[i].w = 0.0;
            self.velocities[i] = Vec4::ZERO;
        }
        self.pins = pins;
        Ok(())
    }

    /// Gives the vertices new masses (one each), keeping positions, velocities and pins (a
    /// pinned vertex takes its mass when it is let go of).
    ///
    /// # Errors
    /// [`StateError::LengthMismatch`] or [`StateError::BadMass`], as [`Self::new`]; nothing
    /// changes.
    pub fn set_masses(&mut self, masses: &[f32]) -> Result<(), StateError> {
        if masses.len() != self.len() {
            return Err(StateError::LengthMismatch {
                positions: self.len(),
                masses: masses.len(),
            });
        }
        if let Some((vertex, &mass)) = masses.iter().enumerate().find(|(_, m)| {
            !(m.is_finite() && **m > 0.0 && (1.0 / **m).is_finite() && **m <= MAX_VERTEX_MASS)
        }) {
            return Err(StateError::BadMass { vertex, mass });
        }
        for (i, &m) in masses.iter().enumerate() {
            self.inv_mass[i] = 1.0 / m;
            if self.positions[i].w > 0.0 {
                self.positions[i].w = 1.0 / m;
                self.prev[i].w = 1.0 / m;
            }
        }
        Ok(())
    }

    /// Moves the targets of the existing pins, in the order [`Self::pins`] lists them.
    /// Targets that are not finite or beyond [`MAX_COORDINATE`] are ignored (the pin keeps
    /// its previous target).
    pub fn set_pin_targets(&mut self, targets: impl IntoIterator<Item = Vec3>) {
        for (pin, t) in self.pins.iter_mut().zip(targets) {
            if within_range(t) {
                pin.target = t;
            }
        }
    }

    /// Places every pinned vertex on its target at once, with zero velocity (a teleport).
    pub fn snap_pins(&mut self) {
        for pin in &self.pins {
            let i = pin.vertex as usize;
            self.positions[i] = pin.target.extend(0.0);
            self.prev[i] = self.positions[i];
            self.velocities[i] = Vec4::ZERO;
        }
    }

    /// Moves the whole cloth by `offset`, keeping its velocities (a teleport of everything the
    /// cloth hangs from). Pin targets move too.
    pub fn translate(&mut self, offset: Vec3) {
        if !offset.is_finite() {
            return;
        }
        let o = offset.extend(0.0);
        for (p, q) in self.positions.iter_mut().zip(&mut self.prev) {
            *p += o;
            *q += o;
        }
        for pin in &mut self.pins {
            pin.target += offset;
        }
    }

    /// Moves every vertex to `positions` with zero velocity (pins keep their targets).
    ///
    /// # Panics
    /// If `positions` has a different length.
    pub fn reset(&mut self, positions: &[Vec3]) {
        assert_eq!(
            positions.len(),
            self.len(),
            "reset with a different vertex count"
        );
        for (i, p) in positions.iter().enumerate() {
            let w = self.positions[i].w;
            self.positions[i] = p.extend(w);
            self.prev[i] = self.positions[i];
            self.velocities[i] = Vec4::ZERO;
        }
    }

    /// Interpolated pin positions for substep `s` (0-based) of `n`: the pin moves from where it
    /// was at the start of the step (`start`) to its target.
    pub(crate) fn place_pins(&mut self, start: &[Vec3], s: u32, n: u32) {
        let t = (s + 1) as f32 / n as f32;
        for (pin, a) in self.pins.iter().zip(start) {
            let i = pin.vertex as usize;
            self.positions[i] = a.lerp(pin.target, t).extend(0.0);
        }
    }

    /// Positions of the pinned vertices now, in pin order.
    pub(crate) fn pin_starts(&self) -> Vec<Vec3> {
        self.pins
            .iter()
            .map(|p| self.positions[p.vertex as usize].xyz())
            .collect()
    }

    /// Whether every position and velocity is finite (cheap: one pass, no counting).
    #[must_use]
    pub fn is_finite(&self) -> bool {
        // Branch-free: this runs after every step over every vertex.
        self.positions
            .iter()
            .chain(&self.velocities)
            .fold(true, |ok, v| ok & v.is_finite())
    }

    /// Number of position or velocity components that are NaN or infinite.
    #[must_use]
    pub fn non_finite_count(&self) -> usize {
        self.positions
            .iter()
            .chain(&self.velocities)
            .map(|v| v.xyz().to_array().iter().filter(|c| !c.is_finite()).count())
            .sum()
    }

    /// Kinetic energy `Σ ½ m |v|²` of the unpinned vertices, in joules.
    #[must_use]
    pub fn kinetic_energy(&self) -> f64 {
        kinetic_energy(&self.positions, &self.velocities)
    }

    /// [`Self::kinetic_energy`] over the mass of the free vertices, J/kg (0 with none free):
    /// what [`Sleep::energy`](super::Sleep::energy) is compared with.
    #[must_use]
    pub fn kinetic_energy_per_kg(&self) -> f32 {
        kinetic_energy_per_kg(&self.positions, &self.velocities)
    }

    /// The largest squared speed of a free vertex (`w > 0`), m²/s² (0 with none free; a
    /// non-finite velocity gives infinity). The GPU backend's measure of rest: the same
    /// maximum over the same vertices, which any order of evaluation gives alike.
    #[must_use]
    pub fn max_free_speed_squared(&self) -> f32 {
        self.positions
            .iter()
            .zip(&self.velocities)
            .filter(|(p, _)| p.w > 0.0)
            .map(|(_, v)| {
                let s2 = v.xyz().length_squared();
                if s2.is_finite() { s2 } else { f32::INFINITY }
            })
            .fold(0.0, f32::max)
    }
}

/// [`ClothState::kinetic_energy`] of positions and velocities laid out as a state's.
fn kinetic_energy(positions: &[Vec4], velocities: &[Vec4]) -> f64 {
    velocities
        .iter()
        .zip(positions)
        .filter(|(_, p)| p.w > 0.0)
        .map(|(v, p)| 0.5 * f64::from(v.xyz().length_squared()) / f64::from(p.w))
        .sum()
}

/// [`ClothState::kinetic_energy_per_kg`] of positions and velocities laid out as a state's
/// (a state read back from another backend).
pub(crate) fn kinetic_energy_per_kg(positions: &[Vec4], velocities: &[Vec4]) -> f32 {
    let mass: f64 = positions
        .iter()
        .filter(|p| p.w > 0.0)
        .map(|p| 1.0 / f64::from(p.w))
        .sum();
    if mass > 0.0 {
        (kinetic_energy(positions, velocities) / mass) as f32
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two() -> ClothState {
        ClothState::new(&[Vec3::ZERO, Vec3::X], &[1.0, 2.0]).unwrap()
    }

    #[test]
    fn positions_carry_inverse_mass() {
        let s = two();
        assert_eq!(s.positions[0].w, 1.0);
        assert_eq!(s.positions[1].w, 0.5);
    }

    #[test]
    fn bad_inputs_are_rejected() {
        assert!(matches!(
            ClothState::new(&[Vec3::ZERO], &[0.0]),
            Err(StateError::BadMass { vertex: 0, .. })
        ));
        let pair = [Vec3::ZERO, Vec3::X];
        assert!(ClothState::new(&pair, &[1.0, MAX_VERTEX_MASS]).is_ok());
        for heavy in [MAX_VERTEX_MASS * 1.001, 1.2e37, 1e-45] {
            assert!(matches!(
                ClothState::new(&pair, &[1.0, heavy]),
                Err(StateError::BadMass { vertex: 1, .. })
            ));
        }
        assert!(matches!(
            ClothState::new(&[Vec3::NAN], &[1.0]),
            Err(StateError::NonFinitePosition { vertex: 0 })
        ));
        assert!(matches!(
            ClothState::new(&[Vec3::ZERO], &[1.0, 1.0]),
            Err(StateError::LengthMismatch { .. })
        ));
        let mut s = two();
        assert!(matches!(
            s.set_pins([Pin {
                vertex: 2,
                target: Vec3::ZERO
            }]),
            Err(StateError::PinOutOfRange { vertex: 2, .. })
        ));
    }

    #[test]
    fn pinning_and_unpinning_restores_mass() {
        let mut s = two();
        s.set_pins([Pin {
            vertex: 1,
            target: Vec3::X,
        }])
        .unwrap();
        assert_eq!(s.positions[1].w, 0.0);
        s.set_pins([]).unwrap();
        assert_eq!(s.positions[1].w, 0.5);
    }
}
