//! The ranges of physical values the loaders accept, in one place.
//!
//! The MJCF loader, the Brax config loader and the rollout tool's controls file check every
//! number they read against one of these ranges and refuse a value outside it with an error
//! naming the file, the line, the field and the value. Without them an absurd value (a mass
//! of 1e300 kg, an offset of 1e160 m, a time step of 1e9 s) passed the loader and surfaced
//! later as something else: an overflowing inertia reported as "mass matrix not positive
//! definite", a non-finite state after some control step, or a non-finite gradient in
//! training.
//!
//! The bounds are six or more orders of magnitude around the values of the MeBen agents and
//! MuJoCo's models (masses 0.03 to 10 kg, lengths 0.05 to 1 m, torques 150 to 500 N m,
//! joint limits within +-90 degrees, time steps 0.002 to 0.01 s), so they refuse no physical
//! model while keeping every derived quantity finite in f64: a body inertia is at most
//! `mass * length^2` = 1e12 kg m^2, a torque at most `gear * control` = 1e12 N m, and
//! positions stay far inside what the f32 observations represent. A combination of values
//! inside the ranges can still describe a numerically singular body (a 1e-6 kg limb on a
//! 1e6 kg torso): [`crate::ModelBuilder::build`] reports that as a singular mass matrix
//! naming the body.

/// A closed range of accepted values of one kind of physical quantity (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limit {
    /// What the quantity is, for messages ("a mass").
    pub what: &'static str,
    /// Its unit, for messages ("kg"; empty when it has none).
    pub unit: &'static str,
    /// The smallest accepted value.
    pub min: f64,
    /// The largest accepted value.
    pub max: f64,
    /// Whether 0 is accepted although it lies outside `min..=max` (a massless geom).
    pub zero: bool,
}

/// Positions, offsets, anchors, capsule half-lengths (m): within +-1 km, the largest arena
/// ([`crate::tasks::spec::MAX_RADIUS`]).
pub const LENGTH: Limit = Limit { what: "a length or position", unit: "m", min: -1e3, max: 1e3, zero: true };
/// Radii and capsule lengths (m): 0.1 mm to 1 km.
pub const SIZE: Limit = Limit { what: "a size", unit: "m", min: 1e-4, max: 1e3, zero: false };
/// Masses (kg): 1 mg to 1000 t, or 0 (a massless geom in MJCF).
pub const MASS: Limit = Limit { what: "a mass", unit: "kg", min: 1e-6, max: 1e6, zero: true };
/// Densities (kg/m^3): up to 50 times osmium's, or 0 (a massless geom).
pub const DENSITY: Limit = Limit { what: "a density", unit: "kg/m^3", min: 1e-6, max: 1e6, zero: true };
/// Brax's `inertia` field (kg m^2; kept but unused): positive, at most `MASS.max * SIZE.max^2`.
pub const INERTIA: Limit = Limit { what: "an inertia", unit: "kg m^2", min: 1e-12, max: 1e12, zero: false };
/// Motor gears and Brax strengths (N m at control 1).
pub const TORQUE: Limit = Limit { what: "a gear or strength", unit: "N m", min: -1e6, max: 1e6, zero: true };
/// Joint damping (N m s/rad).
pub const DAMPING: Limit = Limit { what: "a damping", unit: "N m s/rad", min: 0.0, max: 1e6, zero: true };
/// Joint armature (kg m^2).
pub const ARMATURE: Limit = Limit { what: "an armature", unit: "kg m^2", min: 0.0, max: 1e6, zero: true };
/// Coulomb friction coefficients.
pub const FRICTION: Limit = Limit { what: "a friction coefficient", unit: "", min: 0.0, max: 1e3, zero: true };
/// Angles in degrees (Euler angles, joint limits): ten turns either way. Any orientation
/// needs at most 180 degrees; beyond ~1e15 degrees an angle has lost every digit to the
/// period and its sine means nothing.
pub const ANGLE_DEGREES: Limit = Limit { what: "an angle", unit: "degrees", min: -3600.0, max: 3600.0, zero: true };
/// Hinge angles in a state (rad, `qpos`): the same ten turns either way as
/// [`ANGLE_DEGREES`], `+-20 pi`.
pub const HINGE_ANGLE: Limit = Limit {
    what: "a hinge angle",
    unit: "rad",
    min: -20.0 * std::f64::consts::PI,
    max: 20.0 * std::f64::consts::PI,
    zero: true,
};
/// Quaternion components in a state (`qpos` of a free joint; normalised before use): within
/// +-1000, so that the norm stays finite and meaningful. A zero quaternion is refused apart.
pub const QUATERNION: Limit = Limit { what: "a quaternion component", unit: "", min: -1e3, max: 1e3, zero: true };
/// The physics time step (s): 1 us to 1 s.
pub const TIMESTEP: Limit = Limit { what: "a time step", unit: "s", min: 1e-6, max: 1.0, zero: false };
/// Gravity components (m/s^2): 100 g.
pub const GRAVITY: Limit = Limit { what: "a gravity component", unit: "m/s^2", min: -1e3, max: 1e3, zero: true };
/// Controls and control ranges (multiplied by the gear).
pub const CONTROL: Limit = Limit { what: "a control", unit: "", min: -1e6, max: 1e6, zero: true };

impl Limit {
    /// Whether `x` is accepted (never for NaN).
    pub fn contains(&self, x: f64) -> bool {
        (self.min..=self.max).contains(&x) || (self.zero && x == 0.0)
    }

    /// `Ok(x)` when accepted, else a message such as `1e300 is out of range: a mass must be 0
    /// or between 1e-6 and 1e6 kg`.
    pub fn check(&self, x: f64) -> Result<f64, String> {
        if self.contains(x) {
            return Ok(x);
        }
        let zero = if self.zero && self.min > 0.0 { "0 or " } else { "" };
        let unit = if self.unit.is_empty() { String::new() } else { format!(" {}", self.unit) };
        Err(format!(
            "{} is out of range: {} must be {zero}between {} and {}{unit}",
            number(x),
            self.what,
            number(self.min),
            number(self.max)
        ))
    }
}

/// `x` in a short form: plain for ordinary magnitudes, scientific beyond (`1e300`, not 301
/// digits).
pub fn number(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-3..1e6).contains(&a) || !a.is_finite() { format!("{x}") } else { format!("{x:e}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_zero_and_nan() {
        assert!(MASS.contains(0.0) && MASS.contains(1e-6) && MASS.contains(1e6));
        assert!(!MASS.contains(1e-7) && !MASS.contains(1.1e6) && !MASS.contains(f64::NAN));
        assert!(!SIZE.contains(0.0) && SIZE.contains(0.08));
        assert!(!TIMESTEP.contains(0.0) && !TIMESTEP.contains(1e9) && TIMESTEP.contains(0.01));
        assert!(!LENGTH.contains(f64::INFINITY) && LENGTH.contains(-1e3));
    }

    #[test]
    fn messages_name_the_value_and_the_range() {
        assert_eq!(
            MASS.check(1e300).unwrap_err(),
            "1e300 is out of range: a mass must be 0 or between 1e-6 and 1e6 kg"
        );
        assert_eq!(
            LENGTH.check(-2e3).unwrap_err(),
            "-2000 is out of range: a length or position must be between -1000 and 1000 m"
        );
        assert_eq!(
            FRICTION.check(-1.0).unwrap_err(),
            "-1 is out of range: a friction coefficient must be between 0 and 1000"
        );
        assert_eq!(number(0.5), "0.5");
        assert_eq!(number(f64::NAN), "NaN");
    }
}
