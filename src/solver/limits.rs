//! The accepted range of every numeric setting, in one place.
//!
//! The solver's validation ([`SolverParams::validate`](super::SolverParams::validate),
//! [`Features::validate`](super::Features::validate), [`WindParams::validate`](super::WindParams::validate),
//! [`Collider::validate`](super::Collider::validate), ...) and the plugin's checks of
//! the Bevy components (a cloth's mass, a collider's size) test values against these
//! [`Limit`]s, and the editor's sliders span exactly them: a value a slider can reach is never
//! refused. A value outside its range is a [`ParamError`], defined here beside [`Limit`].
//!
//! Every range is closed (`min ≤ v ≤ max`, NaN refused). Where a setting has to be positive,
//! `min` is a small positive number rather than an open bound, so that the bottom of a slider
//! is a value the solver takes.

use glam::Vec3;

/// A solver parameter that is out of its range.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamError {
    /// The parameter's name, e.g. `"substeps"`.
    pub name: &'static str,
    /// Why it is rejected.
    pub reason: String,
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "invalid solver parameter `{}`: {}",
            self.name, self.reason
        )
    }
}

impl std::error::Error for ParamError {}

/// Largest accepted vertex coordinate magnitude, in metres (10 000 km). At this distance an
/// `f32` resolves 1 m; keep cloth within a few km of the origin for millimetre precision.
pub const MAX_COORDINATE: f32 = 1.0e7;

/// The heaviest a single vertex may be, in kilograms. A cloth's whole mass is at most 10⁶ kg
/// ([`MASS`]); far heavier vertices make the constraints' inverse masses so small that a
/// correction's intermediate `Δλ` overflows `f32` (a 10³⁷ kg vertex did, found by the fuzzer).
pub const MAX_VERTEX_MASS: f32 = 1.0e9;

/// The most vertices a cloth may have: 2²² = 4 194 304 (a 2048 × 2048 grid). The solver keeps
/// a few hundred bytes a vertex (positions, constraints, colours, scratch), so this is about
/// 1.5 GB; a mesh, grid or scene file asking for more is refused before anything is
/// allocated, so a file from a mod folder cannot take the game down.
pub const MAX_VERTICES: usize = 1 << 22;

/// The most triangles a cloth may have: twice [`MAX_VERTICES`] (a closed surface has about two
/// triangles a vertex).
pub const MAX_TRIANGLES: usize = 2 * MAX_VERTICES;

/// Finite and within [`MAX_COORDINATE`] of the origin along every axis.
#[inline]
pub(crate) fn within_range(p: Vec3) -> bool {
    p.is_finite() && p.abs().max_element() <= MAX_COORDINATE
}

/// How a slider should spread a [`Limit`]'s range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spread {
    /// Evenly.
    Linear,
    /// By orders of magnitude (for ranges over many decades).
    Logarithmic,
}

/// The closed range `[min, max]` a setting must lie in, with its unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    /// The setting's name as errors say it, e.g. `"substeps"` or `"air.drag"`.
    pub name: &'static str,
    /// Smallest accepted value.
    pub min: f32,
    /// Largest accepted value (may be `f32::INFINITY` where "never" is meaningful).
    pub max: f32,
    /// Unit, for display (`""` for pure numbers).
    pub unit: &'static str,
    /// How a slider over the range should be spread.
    pub spread: Spread,
    /// Whether the setting is a whole number (counts, resolutions).
    pub integer: bool,
}

impl Limit {
    const fn new(
        name: &'static str,
        min: f32,
        max: f32,
        unit: &'static str,
        spread: Spread,
    ) -> Self {
        Self {
            name,
            min,
            max,
            unit,
            spread,
            integer: false,
        }
    }

    const fn count(name: &'static str, min: f32, max: f32) -> Self {
        Self {
            name,
            min,
            max,
            unit: "",
            spread: Spread::Logarithmic,
            integer: true,
        }
    }

    /// The same range under another name (stretch, shear and bending share one).
    #[must_use]
    pub const fn named(self, name: &'static str) -> Self {
        Self { name, ..self }
    }

    /// Whether `v` is accepted (`min ≤ v ≤ max`; NaN never is).
    #[must_use]
    pub fn contains(&self, v: f32) -> bool {
        v >= self.min && v <= self.max
    }

    /// `v` brought into the range (NaN becomes `min`).
    #[must_use]
    pub fn clamp(&self, v: f32) -> f32 {
        if v.is_nan() {
            self.min
        } else {
            v.clamp(self.min, self.max)
        }
    }

    /// Checks `v`.
    ///
    /// # Errors
    /// A [`ParamError`] with this limit's name when `v` is outside the range or NaN.
    pub fn check(&self, v: f32) -> Result<(), ParamError> {
        if self.contains(v) {
            Ok(())
        } else {
            Err(ParamError {
                name: self.name,
                reason: format!(
                    "{v} is outside [{}, {}]{}",
                    self.min,
                    self.max,
                    self.suffix()
                ),
            })
        }
    }

    /// Checks a count (substeps, resolutions, ...).
    ///
    /// # Errors
    /// As [`Limit::check`].
    pub fn check_count(&self, n: u32) -> Result<(), ParamError> {
        // Counts are far below 2^24: the conversion is exact.
        self.check(n as f32)
    }

    /// Checks the length of a vector (gravity, wind velocity) against `max`.
    ///
    /// # Errors
    /// A [`ParamError`] when the vector is not finite or longer than `max`.
    pub fn check_length(&self, v: glam::Vec3) -> Result<(), ParamError> {
        if v.is_finite() && v.length() <= self.max {
            Ok(())
        } else {
            Err(ParamError {
                name: self.name,
                reason: format!(
                    "{v} must be finite and at most {}{} long",
                    self.max,
                    self.suffix()
                ),
            })
        }
    }

    /// The range of each component of a vector whose length this limits: any vector with
    /// every component in `[-c, c]` is accepted (`c = max/√3`, rounded down).
    #[must_use]
    pub const fn component(&self) -> Limit {
        // 1/√3, a hair under, so that rounding never lets the diagonal exceed `max`.
        let c = self.max * 0.577_350_26 * (1.0 - 1e-6);
        Limit {
            min: -c,
            max: c,
            spread: Spread::Linear,
            ..*self
        }
    }

    fn suffix(&self) -> String {
        if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        }
    }
}

// ---- solver parameters (SolverParams / ClothConfig) ----

/// Substeps per fixed step.
pub const SUBSTEPS: Limit = Limit::count("substeps", 1.0, 10_000.0);
/// Projection iterations per substep.
pub const ITERATIONS: Limit = Limit::count("iterations", 1.0, 10_000.0);
/// Length of the gravity vector, m/s² (about 10 000 g).
pub const GRAVITY: Limit = Limit::new("gravity", 0.0, 1.0e5, "m/s²", Spread::Linear);
/// Linear velocity damping, 1/s.
pub const DAMPING: Limit = Limit::new("damping", 0.0, 1.0e4, "1/s", Spread::Logarithmic);
/// Speed limit of free vertices, m/s (up to ten times the speed of sound in air).
pub const MAX_SPEED: Limit = Limit::new("max_speed", 1.0e-3, 3.5e3, "m/s", Spread::Logarithmic);
/// Fraction of the velocity the lab solver keeps each step.
pub const LAB_VELOCITY_KEEP: Limit = Limit::new("velocity_keep", 0.0, 1.0, "", Spread::Linear);
/// PBD stiffness (stretch, shear, bending): the fraction of the error removed per projection.
pub const PBD_STIFFNESS: Limit = Limit::new("stiffness", 0.0, 1.0, "", Spread::Linear);
/// XPBD stretch and shear compliance, m/N (0 is inextensible).
pub const XPBD_COMPLIANCE: Limit = Limit::new("compliance", 0.0, 1.0e6, "m/N", Spread::Logarithmic);
/// XPBD bending compliance `1/B`, 1/(N·m). `f32::INFINITY` (no bending) is accepted too.
pub const XPBD_BENDING_COMPLIANCE: Limit =
    Limit::new("bending", 0.0, 1.0e12, "1/(N·m)", Spread::Logarithmic);
/// Air drag coefficient (½ρC), kg/m³.
pub const AIR_DRAG: Limit = Limit::new("air.drag", 0.0, 5.0e5, "kg/m³", Spread::Logarithmic);
/// Air lift coefficient (½ρC), kg/m³; negative lifts the other way.
pub const AIR_LIFT: Limit = Limit::new("air.lift", -5.0e5, 5.0e5, "kg/m³", Spread::Logarithmic);
/// Air skin-friction coefficient (½ρC), kg/m³.
pub const AIR_FRICTION: Limit =
    Limit::new("air.friction", 0.0, 5.0e5, "kg/m³", Spread::Logarithmic);
/// Mean kinetic energy per kilogram below which a cloth counts as at rest, J/kg.
pub const SLEEP_ENERGY: Limit = Limit::new("sleep.energy", 0.0, 1.0, "J/kg", Spread::Logarithmic);
/// Steps at rest before a cloth falls asleep.
pub const SLEEP_STEPS: Limit = Limit::count("sleep.steps", 0.0, 1.0e6);

// ---- the cloth (Cloth component) ----

/// Total mass of a cloth, kg.
pub const MASS: Limit = Limit::new("mass", 1.0e-6, 1.0e6, "kg", Spread::Logarithmic);
/// Teleport distance of pins and colliders, m (`f32::INFINITY`: never teleport).
pub const TELEPORT_DISTANCE: Limit = Limit::new(
    "teleport_distance",
    1.0e-3,
    f32::INFINITY,
    "m",
    Spread::Logarithmic,
);
/// Weld tolerance, as a fraction of the mesh's bounding-box diagonal. At most 0.1 %: more
/// would weld the neighbours of fine meshes into one particle.
pub const WELD_TOLERANCE: Limit =
    Limit::new("weld_tolerance", 0.0, 1.0e-3, "", Spread::Logarithmic);

// ---- opt-in features ----

/// Self-collision thickness, m.
pub const SELF_COLLISION_THICKNESS: Limit = Limit::new(
    "self_collision.thickness",
    1.0e-6,
    1.0e3,
    "m",
    Spread::Logarithmic,
);
/// The thickest self-collision a cloth takes, in its mean rest edges. Layers kept further
/// apart than an edge cross: a vertex is then kept a thickness away from triangles of its own
/// neighbourhood that rest closer than that, which pushes it through the sheet wherever the
/// cloth crumples (measured on the CPU in the crumpled-cloth and folded-over-a-bar scenes of
/// the `self_collision` tests: no edge–triangle pair crossing at the end at 0.88 and 1 mean
/// edge; up to 48 and 127 at 1.05 and 1.1; 851 at 1.4; 6847 at 1.76). The query also grows
/// with the square of thickness over edge (a 256² cloth of 1 m with a 5 cm thickness, 13
/// edges, took over a second a frame). The default thickness, the mean rest edge, is the
/// most.
pub const MAX_SELF_COLLISION_EDGES: f32 = 1.0;
/// The most uneven edges ([`Topology::rest_edge_spread`](crate::solver::Topology::rest_edge_spread):
/// the 90th over the 10th percentile of the rest lengths) self-collision was measured to hold
/// on with its one thickness: the crumpled 30² cloth of the `self_collision` tests, its grid
/// squeezed towards the middle, ended with no edge–triangle pair crossing at spreads of 1.41
/// (even), 1.65 and 1.74, and with 122 and 12 at 2.0 and 2.8 (a thinner thickness crossed
/// more: the edges of the coarse parts slip between vertices). Above it each vertex takes a
/// thickness from its own edges (the cloth's times the mean length of the edges at it over
/// the mean edge): the same cloth squeezed both ways, spun at four rates, ended with 0 to 22
/// crossing pairs at spreads of 2.1 to 3.7, where the one thickness left 4 to 10 343. The
/// plugin warns above it.
pub const EVEN_EDGE_SPREAD: f32 = 1.8;
/// Most a vertex's thickness from triangles is, in its shortest rest edges, on a mesh of
/// uneven edges ([`Topology::self_collision_triangle_scales`](crate::solver::Topology::self_collision_triangle_scales)). A skirt's tube of 12 rings of
/// 32, hung by its waist at its default thickness, stretched up to 531 % without it; 11 %
/// at 1.2 and 9 % at 1.0, but at 1.0 the crumpled squeezed cloth of `tests/self_collision.rs`
/// ended with crossing pairs in most runs (docs/experiments.md).
pub const SHORT_EDGE_THICKNESS: f32 = 1.2;
/// Most the default self-collision thickness of a mesh of even edges is, in its short edges
/// (the 10th percentile of the rest lengths;
/// [`Topology::default_self_collision_thickness`](crate::solver::Topology::default_self_collision_thickness)).
/// Measured, not derived: the `cape` example's cape (edges 0.047 m across, 0.053 m down,
/// mean 0.056 m: 1.21 short edges) on a character running at 25 speeds from 3 to 6 m/s,
/// with self-collision at its mean edge, crossed itself in 16 of the runs (12 of them in 5
/// to 116 pairs) and stretched up to 228 %; at 1.1 short edges in 6 (2 of them in 7 and 28
/// pairs), up to 116 %; at 1.05 and 1.0 (13 runs each) in 4 and 5 (up to 50 and 2 pairs).
/// Walking (1 to 2.4 m/s, eight runs), at its mean edge three crossed (5, 25, 101 pairs),
/// at 1.1 short edges none in more than one (docs/experiments.md). A grid of squares (mean
/// edge 1.14 sides) gets 1.1 sides.
pub const DEFAULT_SHORT_EDGE_THICKNESS: f32 = 1.1;
/// Most the default self-collision thickness of an open mesh is of the narrowest gap across
/// its rest shape ([`Topology::narrowest_rest_gap`](crate::solver::Topology::narrowest_rest_gap):
/// a vertex resting over a triangle it is not a corner of, such as the far wall of a sleeve,
/// or the side beyond a right-angled crease of a low-poly model's part; each vertex's gap over
/// its triangle scale on uneven meshes). Held farther off that triangle than the cloth's own
/// shape lets it be, the contacts pushed every substep against the edges. Measured on the
/// mesh parts of Bevy's glTF models (each scaled to 0.8 m and dropped on the floor with
/// self-collision, docs/experiments.md): of the 23 open parts the rule changes, 16 still moved
/// faster than 0.5 m/s after seven seconds with the edges' default (19–51 m/s, two of them
/// 120–170 m up), 7 with half the gap (at most 9 m/s). An earlier form of the rule on the
/// alien's and the cake's 25 parts: at 0.9 of the gap 5 of them moved, at half 2, at 0.3 one.
/// A flat sheet rests over none of its triangles and keeps its default.
pub const REST_GAP_THICKNESS: f32 = 0.5;
/// Gaps under this share of the default thickness are left out of
/// [`REST_GAP_THICKNESS`]'s rule: the vertex rests on the triangle (a T-junction, a face
/// modelled twice), not over another layer, and self-collision cannot keep it off anyway.
pub const REST_GAP_IGNORED: f32 = 0.1;
/// Self-collision friction.
pub const SELF_COLLISION_FRICTION: Limit = Limit::new(
    "self_collision.friction",
    0.0,
    100.0,
    "",
    Spread::Logarithmic,
);
/// Tether slack: allowed stretch beyond the rest distance to a pin (0.02 = 2 %).
pub const TETHER_SLACK: Limit = Limit::new("tethers.slack", 0.0, 100.0, "", Spread::Logarithmic);
/// Pins each vertex is tethered to.
pub const TETHER_PINS: Limit = Limit::count("tethers.pins_per_vertex", 1.0, 64.0);
/// Stretch factor at which an edge tears.
pub const TEAR_THRESHOLD: Limit =
    Limit::new("tear_threshold", 1.0001, 1.0e3, "", Spread::Logarithmic);

// ---- colliders ----

/// Collider sizes (radius, half extents, half height), m.
pub const COLLIDER_SIZE: Limit = Limit::new("size", 0.0, MAX_COORDINATE, "m", Spread::Logarithmic);
/// Gap kept between cloth and a collider's surface, m.
pub const COLLIDER_THICKNESS: Limit = Limit::new("thickness", 0.0, 100.0, "m", Spread::Logarithmic);
/// Coulomb friction between cloth and a collider.
pub const COLLIDER_FRICTION: Limit = Limit::new("friction", 0.0, 100.0, "", Spread::Logarithmic);
/// Cells along the longest side of a baked mesh collider.
pub const SDF_RESOLUTION: Limit = Limit::count("resolution", 4.0, 128.0);

// ---- wind ----

/// Wind speed (length of the velocity), m/s.
pub const WIND_SPEED: Limit = Limit::new("wind.velocity", 0.0, 3.5e3, "m/s", Spread::Linear);
/// Gust amplitude, a fraction of the wind speed.
pub const GUST_AMPLITUDE: Limit =
    Limit::new("wind.gust_amplitude", 0.0, 100.0, "", Spread::Logarithmic);
/// Gust angular frequency, rad/s.
pub const GUST_FREQUENCY: Limit = Limit::new(
    "wind.gust_frequency",
    0.0,
    1.0e3,
    "rad/s",
    Spread::Logarithmic,
);
/// Turbulence strength, a fraction of the wind speed.
pub const TURBULENCE: Limit = Limit::new("wind.turbulence", 0.0, 100.0, "", Spread::Logarithmic);
/// Size of the turbulent eddies, m.
pub const TURBULENCE_SCALE: Limit = Limit::new(
    "wind.turbulence_scale",
    1.0e-3,
    1.0e4,
    "m",
    Spread::Logarithmic,
);
/// Half size of a wind zone's box along each axis, m.
pub const ZONE_HALF_EXTENT: Limit = Limit::new(
    "half_extents",
    0.0,
    MAX_COORDINATE,
    "m",
    Spread::Logarithmic,
);
/// Distance over which a wind zone fades out, m.
pub const ZONE_FALLOFF: Limit =
    Limit::new("falloff", 0.0, MAX_COORDINATE, "m", Spread::Logarithmic);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_ranges_refuse_nan_and_the_outside() {
        assert!(SUBSTEPS.contains(1.0) && SUBSTEPS.contains(10_000.0));
        assert!(!SUBSTEPS.contains(0.0) && !SUBSTEPS.contains(10_001.0));
        assert!(!DAMPING.contains(f32::NAN));
        assert!(TELEPORT_DISTANCE.contains(f32::INFINITY));
        assert_eq!(MASS.clamp(f32::NAN), MASS.min);
        let e = TEAR_THRESHOLD.check(1.0).unwrap_err();
        assert_eq!(e.name, "tear_threshold");
        assert!(SUBSTEPS.check_count(0).is_err() && SUBSTEPS.check_count(10).is_ok());
    }

    #[test]
    fn component_ranges_keep_vectors_within_the_length() {
        let c = GRAVITY.component();
        let corner = glam::Vec3::splat(c.max);
        assert!(GRAVITY.check_length(corner).is_ok());
        assert!(GRAVITY.check_length(-corner).is_ok());
        assert!(
            GRAVITY
                .check_length(glam::Vec3::splat(GRAVITY.max))
                .is_err()
        );
        let w = WIND_SPEED.component();
        assert!(WIND_SPEED.check_length(glam::Vec3::splat(w.min)).is_ok());
    }
}
