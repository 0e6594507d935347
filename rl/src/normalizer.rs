//! Observation normalisation (MEBEN.md sections 6 and 8).
//!
//! - [`RunningStats`]: running mean and variance of a fixed-width vector, updated a batch at a
//!   time with the parallel-variance merge of Chan, Golub and LeVeque: for two sets with
//!   counts `n_a`, `n_b`, means `mu_a`, `mu_b` and sums of squared deviations `M_a`, `M_b`,
//!   `n = n_a + n_b`, `delta = mu_b - mu_a`, `mu = mu_a + delta n_b / n`,
//!   `M = M_a + M_b + delta^2 n_a n_b / n`. Sums are in f64, in a fixed order: the result
//!   does not depend on the thread count.
//! - [`ObsNormalizer`]: the reference's element-wise normaliser (every vector component and
//!   scalar of every node: `(x - mu) / sigma`), or the rotation-preserving one for the
//!   equivariant models: every 3-vector divided by the running root-mean-square norm of its
//!   node and kind, `v / sqrt(E|v|^2)`, with no mean subtracted, so `R v` maps to `R` times the
//!   image of `v` for every rotation or reflection `R`; the (invariant) scalars element-wise.
//!   Normalised values are clipped to `[-CLIP, CLIP]` (the rotation-preserving normaliser
//!   clips the norm, which is again equivariant). The agents' headings are not normalised.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use envs::tasks::N_SCALARS;

/// Normalised values (element-wise) or norms (vectors) are clipped to this bound.
pub const CLIP: f32 = 10.0;

/// Standard deviations and RMS norms below this are raised to it (constant features).
pub const MIN_SCALE: f64 = 1e-3;

/// Running count, mean and sum of squared deviations of each of `dim` features.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningStats {
    /// Samples seen.
    pub count: f64,
    /// Mean of each feature.
    pub mean: Vec<f64>,
    /// Sum of squared deviations from the mean of each feature.
    pub m2: Vec<f64>,
}

impl RunningStats {
    /// No samples yet: mean 0, variance taken as 1 (see [`RunningStats::std`]).
    pub fn new(dim: usize) -> Self {
        Self { count: 0.0, mean: vec![0.0; dim], m2: vec![0.0; dim] }
    }

    /// Number of features.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Statistics of `rows` (row-major, `dim` columns), computed in one pass per feature in
    /// row order.
    pub fn from_rows(data: &[f32], dim: usize) -> Self {
        assert!(dim > 0 && data.len().is_multiple_of(dim), "{} values are not rows of {dim}", data.len());
        let n = data.len() / dim;
        let mut s = RunningStats::new(dim);
        if n == 0 {
            return s;
        }
        s.count = n as f64;
        let cols: Vec<(f64, f64)> = (0..dim)
            .into_par_iter()
            .map(|j| {
                let mean = data.iter().skip(j).step_by(dim).map(|&x| x as f64).sum::<f64>() / n as f64;
                let m2 = data.iter().skip(j).step_by(dim).map(|&x| (x as f64 - mean).powi(2)).sum::<f64>();
                (mean, m2)
            })
            .collect();
        for (j, (mean, m2)) in cols.into_iter().enumerate() {
            s.mean[j] = mean;
            s.m2[j] = m2;
        }
        s
    }

    /// Merges the statistics of another set into these (module docs).
    pub fn merge(&mut self, other: &RunningStats) {
        assert_eq!(self.dim(), other.dim(), "merging statistics of different widths");
        if other.count == 0.0 {
            return;
        }
        let n = self.count + other.count;
        for j in 0..self.dim() {
            let delta = other.mean[j] - self.mean[j];
            self.mean[j] += delta * other.count / n;
            self.m2[j] += other.m2[j] + delta * delta * self.count * other.count / n;
        }
        self.count = n;
    }

    /// Adds the rows of `data` (`dim` columns).
    pub fn update(&mut self, data: &[f32]) {
        let batch = RunningStats::from_rows(data, self.dim());
        self.merge(&batch);
    }

    /// Population variance of feature `j` (1 before any sample).
    pub fn variance(&self, j: usize) -> f64 {
        if self.count == 0.0 { 1.0 } else { self.m2[j] / self.count }
    }

    /// Standard deviation of feature `j`, at least [`MIN_SCALE`].
    pub fn std(&self, j: usize) -> f64 {
        self.variance(j).sqrt().max(MIN_SCALE)
    }
}

/// Which transformation an [`ObsNormalizer`] applies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum NormKind {
    /// Everything element-wise.
    Elementwise,
    /// Vectors by a norm statistic, scalars element-wise.
    Rotation,
    /// Identity.
    Identity,
}

/// The running statistics of one team's observations and the map they define (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsNormalizer {
    /// The transformation.
    pub kind: NormKind,
    /// Nodes per observation.
    pub nodes: usize,
    /// Element-wise: the `N * 9` vector components; rotation: the `N * 3` squared norms (of
    /// which the mean is used).
    pub vectors: RunningStats,
    /// The `N * N_SCALARS` scalars.
    pub scalars: RunningStats,
}

impl ObsNormalizer {
    /// A normaliser of observations of `nodes` nodes that has seen nothing (identity on
    /// vectors, mean 0 and variance 1 on scalars).
    pub fn new(kind: NormKind, nodes: usize) -> Self {
        let vdim = match kind {
            NormKind::Rotation => nodes * 3,
            _ => nodes * 9,
        };
        Self { kind, nodes, vectors: RunningStats::new(vdim), scalars: RunningStats::new(nodes * N_SCALARS) }
    }

    /// Adds a batch of raw observations (`[B, N, 3, 3]` vectors, `[B, N, N_SCALARS]` scalars).
    pub fn update(&mut self, vectors: &[f32], scalars: &[f32]) {
        match self.kind {
            NormKind::Identity => {}
            NormKind::Elementwise => {
                self.vectors.update(vectors);
                self.scalars.update(scalars);
            }
            NormKind::Rotation => {
                let sq: Vec<f32> = vectors.chunks_exact(3).map(|v| v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).collect();
                self.vectors.update(&sq);
                self.scalars.update(scalars);
            }
        }
    }

    /// Normalises a batch into `out_vectors`, `out_scalars` (resized to fit).
    pub fn apply(&self, vectors: &[f32], scalars: &[f32], out_vectors: &mut Vec<f32>, out_scalars: &mut Vec<f32>) {
        out_vectors.clear();
        out_vectors.extend_from_slice(vectors);
        out_scalars.clear();
        out_scalars.extend_from_slice(scalars);
        if self.kind == NormKind::Identity {
            return;
        }
        let ns = self.nodes * N_SCALARS;
        let (smean, sinv) = affine(&self.scalars);
        out_scalars.par_chunks_mut(ns.max(1)).for_each(|row| {
            for (j, x) in row.iter_mut().enumerate() {
                *x = (((*x as f64 - smean[j]) * sinv[j]) as f32).clamp(-CLIP, CLIP);
            }
        });
        let nv = self.nodes * 9;
        match self.kind {
            NormKind::Elementwise => {
                let (vmean, vinv) = affine(&self.vectors);
                out_vectors.par_chunks_mut(nv.max(1)).for_each(|row| {
                    for (j, x) in row.iter_mut().enumerate() {
                        *x = (((*x as f64 - vmean[j]) * vinv[j]) as f32).clamp(-CLIP, CLIP);
                    }
                });
            }
            NormKind::Rotation => {
                // 1 / RMS norm of each node's vector kind.
                let inv: Vec<f32> = (0..self.nodes * 3)
                    .map(|j| {
                        let ms = if self.vectors.count == 0.0 { 1.0 } else { self.vectors.mean[j] };
                        (1.0 / ms.sqrt().max(MIN_SCALE)) as f32
                    })
                    .collect();
                out_vectors.par_chunks_mut(nv.max(1)).for_each(|row| {
                    for (j, v) in row.chunks_exact_mut(3).enumerate() {
                        let s = inv[j];
                        let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() * s;
                        let s = if norm > CLIP { s * CLIP / norm } else { s };
                        v.iter_mut().for_each(|x| *x *= s);
                    }
                });
            }
            NormKind::Identity => {}
        }
    }
}

/// Means and inverse standard deviations of every feature.
fn affine(s: &RunningStats) -> (Vec<f64>, Vec<f64>) {
    let mean = if s.count == 0.0 { vec![0.0; s.dim()] } else { s.mean.clone() };
    let inv = (0..s.dim()).map(|j| 1.0 / s.std(j)).collect();
    (mean, inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn welford_merge_equals_full_batch_statistics() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let dim = 5;
        let data: Vec<f32> = (0..dim * 1000).map(|i| rng.random_range(-3.0..4.0f32) * (1 + i % dim) as f32).collect();
        let full = RunningStats::from_rows(&data, dim);
        let mut merged = RunningStats::new(dim);
        // Uneven chunks, including an empty one.
        for (a, b) in [(0, 7), (7, 7), (7, 500), (500, 999), (999, 1000)] {
            merged.update(&data[a * dim..b * dim]);
        }
        assert_eq!(merged.count, 1000.0);
        for j in 0..dim {
            // Naive two-pass statistics in f64.
            let xs: Vec<f64> = data.iter().skip(j).step_by(dim).map(|&x| x as f64).collect();
            let mean = xs.iter().sum::<f64>() / xs.len() as f64;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
            assert!((full.mean[j] - mean).abs() < 1e-12 && (merged.mean[j] - mean).abs() < 1e-12);
            assert!((full.variance(j) - var).abs() < 1e-9 * var && (merged.variance(j) - var).abs() < 1e-9 * var);
        }
    }

    #[test]
    fn rotation_normaliser_commutes_with_rotations_and_elementwise_does_not() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (b, nodes) = (64, 3);
        let vectors: Vec<f32> = (0..b * nodes * 9).map(|_| rng.random_range(-2.0..2.0f32) + 0.7).collect();
        let scalars: Vec<f32> = (0..b * nodes * N_SCALARS).map(|_| rng.random_range(-1.0..1.0f32)).collect();
        let (c, s) = (0.6f32, 0.8f32); // rotation about z
        let rot = |v: &[f32]| -> Vec<f32> {
            v.chunks_exact(3).flat_map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]).collect()
        };
        for (kind, equivariant) in [(NormKind::Rotation, true), (NormKind::Elementwise, false)] {
            let mut n = ObsNormalizer::new(kind, nodes);
            n.update(&vectors, &scalars);
            let (mut v1, mut s1, mut v2, mut s2) = (vec![], vec![], vec![], vec![]);
            n.apply(&vectors, &scalars, &mut v1, &mut s1);
            n.apply(&rot(&vectors), &scalars, &mut v2, &mut s2);
            let diff = rot(&v1).iter().zip(&v2).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert_eq!(diff < 1e-5, equivariant, "{kind:?}: max difference {diff}");
            assert_eq!(s1, s2);
        }
    }

    #[test]
    fn elementwise_output_is_standardised() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (b, nodes) = (4000, 1);
        let vectors: Vec<f32> = (0..b * 9).map(|i| rng.random_range(0.0..1.0f32) * 3.0 + (i % 9) as f32).collect();
        let scalars: Vec<f32> = (0..b * N_SCALARS).map(|_| rng.random_range(-5.0..5.0f32)).collect();
        let mut n = ObsNormalizer::new(NormKind::Elementwise, nodes);
        n.update(&vectors, &scalars);
        let (mut v, mut s) = (vec![], vec![]);
        n.apply(&vectors, &scalars, &mut v, &mut s);
        let st = RunningStats::from_rows(&v, 9);
        for j in 0..9 {
            assert!(st.mean[j].abs() < 1e-5 && (st.variance(j) - 1.0).abs() < 1e-4, "{j}: {st:?}");
        }
    }
}
