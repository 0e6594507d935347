//! Helpers shared by the models tests: seeded streams and the rigid motions applied to the
//! observation arrays.

#![allow(dead_code)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Rotates every 3-vector of the observation arrays (`[.., node, 3 vectors, 3]`) about the
/// vertical by `angle` and translates the positions (the first vector of each node) by
/// `(tx, ty, 0)`.
pub fn transform(vectors: &[f64], angle: f64, t: [f64; 2]) -> Vec<f64> {
    let (s, c) = angle.sin_cos();
    let mut out = vectors.to_vec();
    for (i, v) in out.chunks_mut(3).enumerate() {
        let (x, y) = (v[0], v[1]);
        v[0] = c * x - s * y;
        v[1] = s * x + c * y;
        if i % 3 == 0 {
            v[0] += t[0];
            v[1] += t[1];
        }
    }
    out
}

/// Largest difference relative to `max(1, |a|)`.
pub fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs() / x.abs().max(1.0)).fold(0.0, f64::max)
}
