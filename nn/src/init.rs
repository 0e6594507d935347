//! Weight initialisers: LeCun-uniform (the default) and orthogonal with a gain.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use tensor::{Float, Tensor};

/// How a weight matrix `[fan_in, fan_out]` is initialised.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Init {
    /// U(-sqrt(3 / fan_in), sqrt(3 / fan_in)) (variance 1 / fan_in), as Flax/JAX's default.
    LecunUniform,
    /// A (semi-)orthogonal matrix times `gain`, as `torch.nn.init.orthogonal_`.
    Orthogonal {
        /// Scale of the orthogonal matrix.
        gain: f64,
    },
    /// All zeros.
    Zeros,
}

impl Init {
    /// A `[fan_in, fan_out]` weight drawn from `rng`.
    pub fn matrix<T: Float>(self, fan_in: usize, fan_out: usize, rng: &mut ChaCha8Rng) -> Tensor<T> {
        let data: Vec<f64> = match self {
            Init::LecunUniform => {
                let lim = (3.0 / fan_in.max(1) as f64).sqrt();
                (0..fan_in * fan_out).map(|_| rng.random_range(-lim..lim)).collect()
            }
            Init::Orthogonal { gain } => orthogonal(fan_in, fan_out, rng).into_iter().map(|v| v * gain).collect(),
            Init::Zeros => vec![0.0; fan_in * fan_out],
        };
        Tensor::new(data.into_iter().map(T::from_f64).collect(), &[fan_in, fan_out]).expect("size by construction")
    }
}

/// A standard normal draw (Box–Muller).
pub fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// A `rows x cols` row-major matrix with orthonormal rows (if rows <= cols) or columns:
/// Gram–Schmidt (twice, for stability) on Gaussian vectors along the longer side.
pub fn orthogonal(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    // Build `k` orthonormal vectors of length `n`, then lay them out as rows or columns.
    let (k, n) = if rows <= cols { (rows, cols) } else { (cols, rows) };
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(k);
    while basis.len() < k {
        let mut v: Vec<f64> = (0..n).map(|_| normal(rng)).collect();
        for _ in 0..2 {
            for b in &basis {
                let d: f64 = v.iter().zip(b).map(|(x, y)| x * y).sum();
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= d * y);
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-6 {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
        }
    }
    let mut out = vec![0.0; rows * cols];
    for (i, b) in basis.iter().enumerate() {
        for (j, &x) in b.iter().enumerate() {
            if rows <= cols {
                out[i * cols + j] = x;
            } else {
                out[j * cols + i] = x;
            }
        }
    }
    out
}
