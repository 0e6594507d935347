//! The run's random streams. Every stream is a ChaCha8 generator whose 32-byte key is the
//! run seed, a label naming the stream's job, and up to two indices (team, agent,
//! iteration...): streams never overlap and adding one never shifts another. A stream's
//! position is saved in checkpoints as [`RngState`].

use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};

/// The stream `label` (at most 8 bytes are used), indices `a`, `b`, of a run seeded with
/// `seed`.
pub fn stream(seed: u64, label: &str, a: u64, b: u64) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let l = label.as_bytes();
    key[8..8 + l.len().min(8)].copy_from_slice(&l[..l.len().min(8)]);
    key[16..24].copy_from_slice(&a.to_le_bytes());
    key[24..32].copy_from_slice(&b.to_le_bytes());
    ChaCha8Rng::from_seed(key)
}

/// A 64-bit seed drawn from the stream `label`, `a`, `b` (for components seeded by a `u64`).
pub fn derive_seed(seed: u64, label: &str, a: u64, b: u64) -> u64 {
    stream(seed, label, a, b).next_u64()
}

/// The stream `label` of one minibatch update: team `team`, iteration `iteration`, epoch
/// `epoch`, minibatch `minibatch` of a run seeded with `seed` (the key of
/// `stream(derive_seed(seed, label, team, iteration), label, epoch, minibatch)`): a fresh
/// stream per minibatch that depends on nothing else, so training stays bit-reproducible
/// and a resumed run draws what the uninterrupted one would.
pub fn minibatch_stream(seed: u64, label: &str, team: u64, iteration: u64, epoch: u64, minibatch: u64) -> ChaCha8Rng {
    stream(derive_seed(seed, label, team, iteration), label, epoch, minibatch)
}

/// One standard-normal sample (Box-Muller on two uniforms; the second normal is dropped so
/// that every sample uses exactly two words of the stream).
pub fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let u1 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The saved position of a ChaCha8 stream.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RngState {
    /// The key.
    pub seed: [u8; 32],
    /// The stream number.
    pub stream: u64,
    /// Word position, high and low 64 bits.
    pub word_pos: [u64; 2],
}

impl RngState {
    /// Captures a stream's position.
    pub fn of(rng: &ChaCha8Rng) -> Self {
        let w = rng.get_word_pos();
        Self { seed: rng.get_seed(), stream: rng.get_stream(), word_pos: [(w >> 64) as u64, w as u64] }
    }

    /// The stream at the saved position.
    pub fn restore(&self) -> Result<ChaCha8Rng> {
        let w = ((self.word_pos[0] as u128) << 64) | self.word_pos[1] as u128;
        if w >= 1u128 << 68 {
            return Err(RlError::config("checkpoint", "rng.word_pos", w, "beyond the stream's end"));
        }
        let mut r = ChaCha8Rng::from_seed(self.seed);
        r.set_stream(self.stream);
        r.set_word_pos(w);
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_differ_and_restore_exactly() {
        let mut a = stream(1, "noise", 0, 0);
        let b = stream(1, "noise", 0, 1);
        assert_ne!(RngState::of(&a), RngState::of(&b));
        for _ in 0..37 {
            a.next_u32();
        }
        let mut c = RngState::of(&a).restore().unwrap();
        let xs: Vec<u64> = (0..10).map(|_| a.next_u64()).collect();
        let ys: Vec<u64> = (0..10).map(|_| c.next_u64()).collect();
        assert_eq!(xs, ys);
    }

    #[test]
    fn normal_samples_have_unit_moments() {
        let mut r = stream(7, "test", 0, 0);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| standard_normal(&mut r)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01 && (var - 1.0).abs() < 0.01, "mean {mean} var {var}");
    }
}
