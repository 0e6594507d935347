//! Shared helpers for the tensor tests: seeded random tensors.

#![allow(dead_code)]

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tensor::Tensor;

/// A seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Uniform values in [-1, 1].
pub fn uniform(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f64> {
    let n = shape.iter().product();
    Tensor::new((0..n).map(|_| r.random_range(-1.0..1.0)).collect(), shape).unwrap()
}

/// Values with |x| in [0.1, 1] and a random sign: at least 0.1 away from the kinks at 0.
pub fn away_from_zero(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f64> {
    let n = shape.iter().product();
    let v = (0..n)
        .map(|_| {
            let m: f64 = r.random_range(0.1..1.0);
            if r.random_bool(0.5) { m } else { -m }
        })
        .collect();
    Tensor::new(v, shape).unwrap()
}

/// Positive values in [0.5, 2] (for log, sqrt, powf, division).
pub fn positive(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f64> {
    let n = shape.iter().product();
    Tensor::new((0..n).map(|_| r.random_range(0.5..2.0)).collect(), shape).unwrap()
}

/// Distinct values (a random permutation of a spaced grid): no ties for max reductions.
pub fn distinct(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f64> {
    let n: usize = shape.iter().product();
    let mut v: Vec<f64> = (0..n).map(|i| i as f64 * 0.1 - n as f64 * 0.05).collect();
    for i in (1..n).rev() {
        let j = r.random_range(0..=i);
        v.swap(i, j);
    }
    Tensor::new(v, shape).unwrap()
}
