//! How each episode starts: a fresh random start (training), or the evaluation modes of the
//! paper's equivariance test (appendix): one fixed start drawn from a seed, used for every
//! episode, optionally rotated by an angle about the vertical through a point. A
//! [`SceneMotion`] (a rotation about a vertical axis, then a horizontal translation) moves
//! any start, the balls (goal balls, Sumo's centre ball) with the agents; evaluation applies
//! it to each episode's start (`VecEnv::set_start`).

use super::error::TaskError;
use super::placement::rotate_xy;
use super::placement::{Start, sample_start};
use super::scene::Scene;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A fixed start: the start drawn with `seed`, rotated by `angle` (rad) about the vertical
/// through `point` (x, y); `angle = 0` is the unrotated scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FixedStart {
    /// Seed of the start.
    pub seed: u64,
    /// Rotation about the vertical (rad).
    pub angle: f64,
    /// A point of the rotation axis (x, y) in m.
    pub point: [f64; 2],
}

/// The farthest a rotation axis or a translation of a start may lie from the origin, in m
/// (horizontally, per coordinate). Within it f64 positions keep a resolution of about 1e-10
/// m; far beyond it a moved scene is no longer the same physics (at 1e12 m, 1e-4 m).
pub const MAX_MOTION_M: f64 = 1e6;

/// Whether every coordinate is finite and within [`MAX_MOTION_M`] of the origin.
fn within_reach(xy: &[f64]) -> bool {
    xy.iter().all(|x| x.is_finite() && x.abs() <= MAX_MOTION_M)
}

/// How each episode starts.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub enum StartMode {
    /// A fresh random start every episode, from the environment's own random stream.
    #[default]
    Random,
    /// The reference release's auto-reset (Brax v1's `AutoResetWrapper`, which keeps the
    /// state of the first reset and returns to it): every environment begins each episode
    /// from the start it drew first, the same draw as its first episode under
    /// [`StartMode::Random`], so a batch of `B` environments sees `B` starts in all.
    PerSlot,
    /// The same start every episode.
    Fixed(FixedStart),
}

impl StartMode {
    /// The start drawn from `seed`, unrotated.
    pub fn fixed(seed: u64) -> StartMode {
        StartMode::Fixed(FixedStart { seed, angle: 0.0, point: [0.0, 0.0] })
    }

    /// The start drawn from `seed`, rotated by `angle` (rad) about the vertical through
    /// `point`.
    pub fn fixed_rotated(seed: u64, angle: f64, point: [f64; 2]) -> StartMode {
        StartMode::Fixed(FixedStart { seed, angle, point })
    }

    /// Errors when the angle is not finite or the point not within [`MAX_MOTION_M`].
    pub fn validate(&self) -> Result<(), TaskError> {
        if let StartMode::Fixed(f) = self
            && !(f.angle.is_finite() && within_reach(&f.point))
        {
            return Err(TaskError::BadArgument {
                what: "fixed start rotation".into(),
                value: format!("angle {} about point {:?}", f.angle, f.point),
                message: format!("the angle must be finite and the point within {MAX_MOTION_M:e} m of the origin"),
            });
        }
        Ok(())
    }
}

/// The start of a fixed mode: drawn with a ChaCha8 stream seeded by `f.seed` (the same
/// placement rules as training), then rotated.
pub fn fixed_start(scene: &Scene, f: &FixedStart) -> Start {
    let mut rng = ChaCha8Rng::seed_from_u64(f.seed);
    sample_start(scene, &mut rng).rotated(f.angle, f.point)
}

/// A rigid motion of a whole scene in the horizontal plane: a rotation by `angle` (rad) about
/// the vertical through `point` (x, y), then a translation by `shift` (x, y). Positions `p`
/// become `rotate_xy(p, angle, point) + shift`, yaws grow by `angle`; the goal balls and
/// Sumo's centre ball move with the agents (Sumo's arena follows its centre ball, so a moved
/// scene plays the same game).
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct SceneMotion {
    /// Rotation about the vertical (rad).
    pub angle: f64,
    /// A point of the rotation axis (x, y) in m.
    pub point: [f64; 2],
    /// Horizontal translation (x, y) in m, after the rotation.
    pub shift: [f64; 2],
}

impl SceneMotion {
    /// No motion.
    pub fn identity() -> SceneMotion {
        SceneMotion::default()
    }

    /// A rotation by `degrees` about the vertical through the origin (the centre of Team
    /// Reach's placement disc and Team Sumo's centre ball at the start), then the translation
    /// `shift`.
    pub fn about_origin(degrees: f64, shift: [f64; 2]) -> SceneMotion {
        SceneMotion { angle: degrees.to_radians(), point: [0.0, 0.0], shift }
    }

    /// Whether the motion leaves every start unchanged (angle and shift exactly 0).
    pub fn is_identity(&self) -> bool {
        self.angle == 0.0 && self.shift == [0.0, 0.0]
    }

    /// Errors when the angle is not finite, or the point or the shift not within
    /// [`MAX_MOTION_M`].
    pub fn validate(&self) -> Result<(), TaskError> {
        if !(self.angle.is_finite() && within_reach(&self.point) && within_reach(&self.shift)) {
            return Err(TaskError::BadArgument {
                what: "scene motion".into(),
                value: format!("rotation {} rad about {:?}, translation {:?}", self.angle, self.point, self.shift),
                message: format!(
                    "the angle must be finite, the point and the translation within {MAX_MOTION_M:e} m of the origin"
                ),
            });
        }
        Ok(())
    }

    /// The start moved: rotated about the vertical through `point`, then translated (the
    /// identity returns an exact copy).
    pub fn apply(&self, start: &Start) -> Start {
        start.rotated(self.angle, self.point).translated(self.shift)
    }

    /// A horizontal position moved.
    pub fn apply_xy(&self, p: [f64; 2]) -> [f64; 2] {
        let q = if self.angle == 0.0 { p } else { rotate_xy(p, self.angle, self.point) };
        [q[0] + self.shift[0], q[1] + self.shift[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tasks::placement::RootPlacement;

    fn start() -> Start {
        Start {
            agents: vec![RootPlacement { xy: [1.0, 2.0], yaw: 0.3 }, RootPlacement { xy: [-2.5, 0.5], yaw: -1.0 }],
            balls: vec![[0.5, -1.5], [3.0, 3.0]],
        }
    }

    #[test]
    fn motions_rotate_about_the_point_then_translate() {
        let m = SceneMotion { angle: std::f64::consts::FRAC_PI_2, point: [1.0, 1.0], shift: [10.0, -20.0] };
        let s = m.apply(&start());
        // (1, 2) - (1, 1) = (0, 1) -> (-1, 0) -> (0, 1) + shift.
        let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12;
        assert!(close(s.agents[0].xy, [10.0, -19.0]), "{:?}", s.agents[0].xy);
        assert!((s.agents[0].yaw - 0.3 - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // (0.5, -1.5) - (1, 1) = (-0.5, -2.5) -> (2.5, -0.5) -> (3.5, 0.5) + shift.
        assert!(close(s.balls[0], [13.5, -19.5]), "{:?}", s.balls[0]);
        for (a, b) in start().agents.iter().zip(&s.agents) {
            assert!(close(m.apply_xy(a.xy), b.xy));
        }
        // The identity is an exact copy; a pure translation keeps the yaws.
        assert!(SceneMotion::identity().is_identity());
        assert_eq!(SceneMotion::identity().apply(&start()), start());
        let t = SceneMotion::about_origin(0.0, [1.5, 0.0]).apply(&start());
        assert_eq!(t.agents[1].yaw, -1.0);
        assert_eq!(t.agents[1].xy, [-1.0, 0.5]);
    }

    #[test]
    fn non_finite_and_far_motions_are_errors() {
        assert!(SceneMotion::about_origin(180.0, [2.0, -3.0]).validate().is_ok());
        assert!(SceneMotion::about_origin(1e5, [MAX_MOTION_M, -MAX_MOTION_M]).validate().is_ok());
        for m in [
            SceneMotion::about_origin(f64::NAN, [0.0, 0.0]),
            SceneMotion::about_origin(0.0, [f64::INFINITY, 0.0]),
            SceneMotion { point: [0.0, f64::NAN], ..SceneMotion::identity() },
            SceneMotion::about_origin(0.0, [1e300, 0.0]),
            SceneMotion { point: [0.0, -2e6], ..SceneMotion::identity() },
        ] {
            let e = m.validate().unwrap_err().to_string();
            assert!(e.contains("scene motion") && e.contains("finite") && e.contains("1e6 m"), "{e}");
        }
        assert!(StartMode::fixed_rotated(1, 0.5, [MAX_MOTION_M, 0.0]).validate().is_ok());
        let e = StartMode::fixed_rotated(1, 0.5, [0.0, 1e7]).validate().unwrap_err().to_string();
        assert!(e.contains("fixed start rotation") && e.contains("1e6 m"), "{e}");
    }
}
