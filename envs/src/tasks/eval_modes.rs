//! How each episode starts: a fresh random start (training), or the evaluation modes of the
//! paper's equivariance test (appendix): one fixed start drawn from a seed, used for every
//! episode, optionally rotated by an angle about the vertical through a point.

use super::error::TaskError;
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

/// How each episode starts.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub enum StartMode {
    /// A fresh random start every episode, from the environment's own random stream.
    #[default]
    Random,
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

    /// Errors when the angle or point is not finite.
    pub fn validate(&self) -> Result<(), TaskError> {
        if let StartMode::Fixed(f) = self
            && !(f.angle.is_finite() && f.point.iter().all(|x| x.is_finite()))
        {
            return Err(TaskError::BadArgument {
                what: "fixed start rotation".into(),
                value: format!("angle {} about point {:?}", f.angle, f.point),
                message: "the angle and the point must be finite".into(),
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
