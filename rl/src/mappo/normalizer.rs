//! Observation normalisation (MEBEN.md sections 6 and 8).
//!
//! - [`RunningStats`]: running mean and variance of a fixed-width vector, updated a batch at a
//!   time with the parallel-variance merge of Chan, Golub and LeVeque: for two sets with
//!   counts `n_a`, `n_b`, means `mu_a`, `mu_b` and sums of squared deviations `M_a`, `M_b`,
//!   `n = n_a + n_b`, `delta = mu_b - mu_a`, `mu = mu_a + delta n_b / n`,
//!   `M = M_a + M_b + delta^2 n_a n_b / n`. Sums are in f64, in a fixed order: the result
//!   does not depend on the thread count.
//! - [`ObsNormalizer`]: one of three maps ([`NormKind`]), applied to `f32` or `f64` arrays
//!   (the arithmetic is in f64 either way). The agents' headings are never normalised.
//!
//! **Invariant** ([`NormKind::Invariant`], the default for every model). An observation has,
//! per node `n`, a position `p_n`, a velocity `v_n`, an angular velocity `w_n` and scalars
//! `h_n`; let `c = (1/|E|) sum_{r in E} p_r` be the mean position of the entity roots `E`
//! (agents' roots and balls, [`envs::layout::ObsSpec::entity_root_node`]). The statistics are
//!
//! - one position scale for the whole observation, `sigma_p = sqrt(E[(1/N) sum_n |p_n - c|^2])`
//!   (the expectation over every observation seen);
//! - per node `n` and kind `k` (velocity, angular velocity) `sigma_nk = sqrt(E[|x_nk|^2])`;
//! - per scalar `j` its mean `mu_j` and standard deviation `s_j`;
//!
//! (each raised to at least [`MIN_SCALE`]), and the map is
//!
//! ```text
//! p_n  -> p_n / sigma_p                                   (no clipping)
//! x_nk -> (x_nk / sigma_nk) min(1, CLIP / |x_nk / sigma_nk|)   (the norm clipped to CLIP)
//! h_nj -> clamp((h_nj - mu_j) / s_j, -CLIP, CLIP)
//! ```
//!
//! Let `g = (Q, t)` be a rotation `Q` about the vertical followed by a horizontal translation
//! `t` (a rotation about the vertical through any point is one of these), acting on a raw
//! observation by `p -> Q p + t`, `v -> Q v`, `w -> Q w`, `h -> h`, headings `+ angle`. Then
//! `(Q p_n + t) / sigma_p = Q (p_n / sigma_p) + t / sigma_p`, `|Q x| = |x|` (so the clipping
//! factor is unchanged) and the scalars are unchanged: `N(g x) = g' N(x)` with
//! `g' = (Q, t / sigma_p)`, the same rotation and a scaled translation. A model `f` invariant
//! under every rotation about the vertical and horizontal translation (its origin
//! subtraction removes `t / sigma_p`) therefore gives `f(N(g x)) = f(g' N(x)) = f(N(x))`: the
//! normaliser and the model together are invariant (`rl/tests/integration/invariance.rs`). The statistics
//! themselves do not depend on where the scene is: `|(Q p_n + t) - (Q c + t)| = |p_n - c|` and
//! `|Q x| = |x|`, so a rotated or translated copy of the training data gives the same
//! normaliser. Positions are not clipped because clipping does not commute with translations,
//! and one scale serves every node because per-node scales `sigma_n` turn a translation `t`
//! into different shifts `t / sigma_n` per node, which no origin subtraction removes (the
//! per-node normaliser used before did that, and clipped absolute positions). Distances
//! between nodes all scale by the same `1 / sigma_p`, so nearest-entity decisions (the greedy
//! task assignment) are unchanged.
//!
//! **Element-wise** ([`NormKind::Elementwise`], the reference release's): every vector
//! component and scalar of every node `(x - mu) / sigma`, clipped to `[-CLIP, CLIP]`. It
//! commutes with neither rotations nor translations.
//!
//! **Identity** ([`NormKind::Identity`]): the raw observations.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tensor::Float;

use envs::layout::{N_SCALARS, NODE_VECTOR_LEN, ObsRows, ObsSpec, Observation};

/// Normalised values (element-wise) or norms (velocities) are clipped to this bound.
pub const CLIP: f32 = 10.0;

/// Standard deviations and RMS norms below this are raised to it (constant features).
pub const MIN_SCALE: f64 = 1e-3;

/// Running count, mean and sum of squared deviations of each of `dim` features.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
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

    /// Statistics of `rows` (row-major, `dim` columns, `f32` or `f64`), computed in one pass
    /// per feature in row order.
    pub fn from_rows<S: Float>(data: &[S], dim: usize) -> Self {
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
                let mean = data.iter().skip(j).step_by(dim).map(|&x| x.to_f64()).sum::<f64>() / n as f64;
                let m2 = data.iter().skip(j).step_by(dim).map(|&x| (x.to_f64() - mean).powi(2)).sum::<f64>();
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
    pub fn update<S: Float>(&mut self, data: &[S]) {
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

    /// Root of the mean of feature `j` (the features are squared norms), at least
    /// [`MIN_SCALE`]; 1 before any sample.
    pub fn rms(&self, j: usize) -> f64 {
        if self.count == 0.0 { 1.0 } else { self.mean[j].max(0.0).sqrt().max(MIN_SCALE) }
    }

    /// Whether the statistics have `dim` features and finite values (a checkpoint's may not).
    fn is_valid(&self, dim: usize) -> bool {
        self.mean.len() == dim
            && self.m2.len() == dim
            && self.count.is_finite()
            && self.count >= 0.0
            && self.mean.iter().chain(&self.m2).all(|x| x.is_finite())
    }
}

/// Which transformation an [`ObsNormalizer`] applies (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum NormKind {
    /// Everything element-wise (the reference release).
    Elementwise,
    /// One position scale from positions relative to the entity roots' mean, velocities by
    /// a norm statistic per node and kind, scalars element-wise: commutes with rotations
    /// about the vertical and horizontal translations.
    Invariant,
    /// Identity.
    Identity,
}

impl NormKind {
    /// The name used in messages and configurations.
    pub fn name(self) -> &'static str {
        match self {
            NormKind::Elementwise => "elementwise",
            NormKind::Invariant => "invariant",
            NormKind::Identity => "none",
        }
    }
}

/// The running statistics of one team's observations and the map they define (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsNormalizer {
    /// The transformation.
    pub kind: NormKind,
    /// Nodes per observation.
    pub nodes: usize,
    /// Invariant: the entity root nodes whose mean position centres the position statistic
    /// (empty for the other kinds).
    #[serde(default)]
    pub roots: Vec<usize>,
    /// Invariant: one feature, per observation `(1/N) sum_n |p_n - c|^2` (no features for
    /// the other kinds).
    #[serde(default)]
    pub positions: RunningStats,
    /// Element-wise: the `N * NODE_VECTOR_LEN` vector components; invariant: the `N * 2` squared norms of
    /// every node's velocity and angular velocity; identity: no features.
    pub vectors: RunningStats,
    /// The `N * N_SCALARS` scalars (no features for the identity).
    pub scalars: RunningStats,
}

impl ObsNormalizer {
    /// A normaliser of observations laid out by `spec` that has seen nothing (identity on
    /// vectors, mean 0 and variance 1 on scalars).
    pub fn new(kind: NormKind, spec: &ObsSpec) -> Self {
        let nodes = spec.n_nodes;
        let (roots, pdim, vdim, sdim) = match kind {
            NormKind::Invariant => (spec.entity_root_node.clone(), 1, nodes * 2, nodes * N_SCALARS),
            NormKind::Elementwise => (Vec::new(), 0, nodes * NODE_VECTOR_LEN, nodes * N_SCALARS),
            NormKind::Identity => (Vec::new(), 0, 0, 0),
        };
        Self {
            kind,
            nodes,
            roots,
            positions: RunningStats::new(pdim),
            vectors: RunningStats::new(vdim),
            scalars: RunningStats::new(sdim),
        }
    }

    /// One line: the kind, nodes and samples seen.
    pub fn describe(&self) -> String {
        format!(
            "{} normaliser of {} nodes ({} vector and {} scalar features, {} samples)",
            self.kind.name(),
            self.nodes,
            self.positions.dim() + self.vectors.dim(),
            self.scalars.dim(),
            self.vectors.count
        )
    }

    /// Checks that this normaliser (e.g. read from a checkpoint) has the layout of `expected`
    /// (the one a configuration builds): the same kind, nodes, root nodes and widths, and
    /// finite statistics. The error says what differs.
    pub fn check_fits(&self, expected: &ObsNormalizer) -> std::result::Result<(), String> {
        if self.kind != expected.kind || self.nodes != expected.nodes || self.roots != expected.roots {
            return Err(format!(
                "it is the {}, this configuration builds the {}",
                self.describe(),
                expected.describe()
            ));
        }
        for (name, s, e) in [
            ("positions", &self.positions, &expected.positions),
            ("vectors", &self.vectors, &expected.vectors),
            ("scalars", &self.scalars, &expected.scalars),
        ] {
            if !s.is_valid(e.dim()) {
                return Err(format!(
                    "its {name} statistics have {} means and {} sums of squares for {} features (or are not finite)",
                    s.mean.len(),
                    s.m2.len(),
                    e.dim()
                ));
            }
        }
        Ok(())
    }

    /// The first statistics (`positions`, `vectors` or `scalars`) holding a NaN or an
    /// infinity, if any.
    pub fn non_finite(&self) -> Option<&'static str> {
        [("positions", &self.positions), ("vectors", &self.vectors), ("scalars", &self.scalars)]
            .into_iter()
            .find(|(_, s)| !(s.count.is_finite() && s.mean.iter().chain(&s.m2).all(|x| x.is_finite())))
            .map(|(name, _)| name)
    }

    /// The first statistics (`positions`, `vectors` or `scalars`) with a negative count or
    /// sum of squared deviations (impossible in statistics of data: a hand-made file), if any.
    pub fn negative(&self) -> Option<&'static str> {
        [("positions", &self.positions), ("vectors", &self.vectors), ("scalars", &self.scalars)]
            .into_iter()
            .find(|(_, s)| s.count < 0.0 || s.m2.iter().any(|&x| x < 0.0))
            .map(|(name, _)| name)
    }

    /// Adds a batch of raw observations (`[B, N, 3, 3]` vectors, `[B, N, N_SCALARS]` scalars).
    pub fn update<S: Float>(&mut self, vectors: &[S], scalars: &[S]) {
        match self.kind {
            NormKind::Identity => {}
            NormKind::Elementwise => {
                self.vectors.update(vectors);
                self.scalars.update(scalars);
            }
            NormKind::Invariant => {
                let nv = self.nodes * NODE_VECTOR_LEN;
                let roots = &self.roots;
                // Per observation: (1/N) sum_n |p_n - c|^2, then the squared norms of the
                // velocity and angular velocity of every node.
                let per_row: Vec<(f64, Vec<f64>)> = vectors
                    .par_chunks(nv.max(1))
                    .map(|row| {
                        let p = |n: usize, i: usize| row[n * NODE_VECTOR_LEN + i].to_f64();
                        let mut c = [0.0f64; 3];
                        for &r in roots {
                            for (i, ci) in c.iter_mut().enumerate() {
                                *ci += p(r, i);
                            }
                        }
                        c.iter_mut().for_each(|ci| *ci /= roots.len().max(1) as f64);
                        let nodes = row.len() / NODE_VECTOR_LEN;
                        let spread =
                            (0..nodes).map(|n| (0..3).map(|i| (p(n, i) - c[i]).powi(2)).sum::<f64>()).sum::<f64>();
                        let sq = row
                            .chunks_exact(NODE_VECTOR_LEN)
                            .flat_map(|node| {
                                [1, 2].map(|k| node[3 * k..3 * k + 3].iter().map(|x| x.to_f64().powi(2)).sum::<f64>())
                            })
                            .collect();
                        (spread / nodes.max(1) as f64, sq)
                    })
                    .collect();
                let spread: Vec<f64> = per_row.iter().map(|r| r.0).collect();
                let sq: Vec<f64> = per_row.into_iter().flat_map(|r| r.1).collect();
                self.positions.update(&spread);
                self.vectors.update(&sq);
                self.scalars.update(scalars);
            }
        }
    }

    /// The position scale `sigma_p` of the invariant normaliser (1 before any sample and for
    /// the other kinds).
    pub fn position_scale(&self) -> f64 {
        if self.kind == NormKind::Invariant { self.positions.rms(0) } else { 1.0 }
    }

    /// Normalises a batch (`f32` or `f64`) into `out_vectors`, `out_scalars` (resized to
    /// fit).
    pub fn apply<S: Float>(&self, vectors: &[S], scalars: &[S], out_vectors: &mut Vec<S>, out_scalars: &mut Vec<S>) {
        out_vectors.clear();
        out_vectors.extend_from_slice(vectors);
        out_scalars.clear();
        out_scalars.extend_from_slice(scalars);
        if self.kind == NormKind::Identity {
            return;
        }
        let clip = CLIP as f64;
        let ns = self.nodes * N_SCALARS;
        let (smean, sinv) = affine(&self.scalars);
        out_scalars.par_chunks_mut(ns.max(1)).for_each(|row| {
            for (j, x) in row.iter_mut().enumerate() {
                *x = S::from_f64(((x.to_f64() - smean[j]) * sinv[j]).clamp(-clip, clip));
            }
        });
        let nv = self.nodes * NODE_VECTOR_LEN;
        match self.kind {
            NormKind::Elementwise => {
                let (vmean, vinv) = affine(&self.vectors);
                out_vectors.par_chunks_mut(nv.max(1)).for_each(|row| {
                    for (j, x) in row.iter_mut().enumerate() {
                        *x = S::from_f64(((x.to_f64() - vmean[j]) * vinv[j]).clamp(-clip, clip));
                    }
                });
            }
            NormKind::Invariant => {
                let pinv = 1.0 / self.position_scale();
                let inv: Vec<f64> = (0..self.nodes * 2).map(|j| 1.0 / self.vectors.rms(j)).collect();
                out_vectors.par_chunks_mut(nv.max(1)).for_each(|row| {
                    for (n, node) in row.chunks_exact_mut(NODE_VECTOR_LEN).enumerate() {
                        for x in &mut node[..3] {
                            *x = S::from_f64(x.to_f64() * pinv);
                        }
                        for k in 1..3 {
                            let v = &mut node[3 * k..3 * k + 3];
                            let mut s = inv[n * 2 + k - 1];
                            let norm = v.iter().map(|x| x.to_f64().powi(2)).sum::<f64>().sqrt() * s;
                            if norm > clip {
                                s *= clip / norm;
                            }
                            v.iter_mut().for_each(|x| *x = S::from_f64(x.to_f64() * s));
                        }
                    }
                });
            }
            NormKind::Identity => {}
        }
    }

    /// Normalises observation rows into `out` (resized to fit; the headings are copied
    /// unchanged: no normaliser changes them).
    pub fn apply_rows(&self, rows: ObsRows<'_, f32>, out: &mut Observation) {
        self.apply(rows.vectors, rows.scalars, &mut out.vectors, &mut out.scalars);
        out.heading.clear();
        out.heading.extend_from_slice(rows.heading);
        (out.batch, out.nodes, out.agents) = (rows.len(), rows.nodes, rows.agents);
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

    fn spec(name: &str) -> ObsSpec {
        envs::tasks::Scene::from_name(name).unwrap().obs_spec
    }

    /// `b` random observations of `nodes` nodes: positions spread over a few metres around
    /// an offset, velocities of varied size per node, scalars.
    fn random_obs(rng: &mut ChaCha8Rng, b: usize, nodes: usize) -> (Vec<f64>, Vec<f64>) {
        let mut v = Vec::with_capacity(b * nodes * NODE_VECTOR_LEN);
        for _ in 0..b {
            for n in 0..nodes {
                for k in 0..3 {
                    let size = [3.0, 0.5 + n as f64 * 0.3, 2.0][k];
                    for i in 0..3 {
                        let offset = if k == 0 && i < 2 { 4.0 } else { 0.0 };
                        v.push(offset + size * rng.random_range(-1.0..1.0f64));
                    }
                }
            }
        }
        let s = (0..b * nodes * N_SCALARS).map(|_| rng.random_range(-1.0..1.0f64)).collect();
        (v, s)
    }

    /// Rotation by `angle` about the vertical, then a horizontal translation of the positions.
    fn motion(v: &[f64], angle: f64, t: [f64; 2]) -> Vec<f64> {
        let (s, c) = angle.sin_cos();
        let mut out = v.to_vec();
        for (i, q) in out.chunks_exact_mut(3).enumerate() {
            let (x, y) = (q[0], q[1]);
            q[0] = c * x - s * y;
            q[1] = s * x + c * y;
            if i % 3 == 0 {
                q[0] += t[0];
                q[1] += t[1];
            }
        }
        out
    }

    fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

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
    fn invariant_statistics_are_the_hand_computed_ones() {
        let sp = spec("team_reach/1_ant");
        let (b, nodes) = (50, sp.n_nodes);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let (v, s) = random_obs(&mut rng, b, nodes);
        let mut n = ObsNormalizer::new(NormKind::Invariant, &sp);
        n.update(&v[..20 * nodes * NODE_VECTOR_LEN], &s[..20 * nodes * N_SCALARS]);
        n.update(&v[20 * nodes * NODE_VECTOR_LEN..], &s[20 * nodes * N_SCALARS..]);
        // sigma_p^2 = mean over observations and nodes of |p_n - c|^2.
        let (mut spread, mut vel) = (0.0, vec![0.0; nodes * 2]);
        for row in v.chunks_exact(nodes * NODE_VECTOR_LEN) {
            let c: Vec<f64> = (0..3)
                .map(|i| {
                    sp.entity_root_node.iter().map(|&r| row[r * NODE_VECTOR_LEN + i]).sum::<f64>()
                        / sp.entity_root_node.len() as f64
                })
                .collect();
            for node in 0..nodes {
                spread += (0..3).map(|i| (row[node * NODE_VECTOR_LEN + i] - c[i]).powi(2)).sum::<f64>();
                for k in 1..3 {
                    vel[node * 2 + k - 1] +=
                        (0..3).map(|i| row[node * NODE_VECTOR_LEN + 3 * k + i].powi(2)).sum::<f64>();
                }
            }
        }
        let sigma_p = (spread / (b * nodes) as f64).sqrt();
        assert!((n.position_scale() - sigma_p).abs() < 1e-12 * sigma_p, "{} vs {sigma_p}", n.position_scale());
        for (j, x) in vel.iter().enumerate() {
            let rms = (x / b as f64).sqrt();
            assert!((n.vectors.rms(j) - rms).abs() < 1e-12 * rms, "{j}");
        }
        // The positions are divided by sigma_p, nothing else happens to them (no clipping,
        // no mean): one far-away node stays far away.
        let mut far = v[..nodes * NODE_VECTOR_LEN].to_vec();
        far[NODE_VECTOR_LEN] += 1e4; // node 1's position, x
        let (mut ov, mut os) = (vec![], vec![]);
        n.apply(&far, &s[..nodes * N_SCALARS], &mut ov, &mut os);
        for node in 0..nodes {
            for i in 0..3 {
                let want = far[node * NODE_VECTOR_LEN + i] / sigma_p;
                assert!((ov[node * NODE_VECTOR_LEN + i] - want).abs() < 1e-12 * want.abs().max(1.0));
            }
        }
    }

    #[test]
    fn invariant_normaliser_commutes_with_rigid_motions_about_gravity_and_elementwise_does_not() {
        let sp = spec("team_reach/2_ants");
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (v, s) = random_obs(&mut rng, 64, sp.n_nodes);
        let (angle, t) = (2.3, [7.5, -3.25]);
        let moved = motion(&v, angle, t);
        for kind in [NormKind::Invariant, NormKind::Elementwise] {
            let mut n = ObsNormalizer::new(kind, &sp);
            n.update(&v, &s);
            // The statistics of the moved observations are the same (invariant kind).
            let mut m = ObsNormalizer::new(kind, &sp);
            m.update(&moved, &s);
            let (mut v1, mut s1, mut v2, mut s2) = (vec![], vec![], vec![], vec![]);
            n.apply(&v, &s, &mut v1, &mut s1);
            n.apply(&moved, &s, &mut v2, &mut s2);
            // N(g x) = g' N(x), g' the same rotation and the translation t / sigma_p.
            let st = 1.0 / n.position_scale();
            let d = max_abs_diff(&motion(&v1, angle, [t[0] * st, t[1] * st]), &v2);
            assert_eq!(s1, s2);
            if kind == NormKind::Invariant {
                assert!(d < 1e-12, "{kind:?}: {d}");
                assert!((m.position_scale() - n.position_scale()).abs() < 1e-12 * n.position_scale());
                assert!(max_abs_diff(&m.vectors.mean, &n.vectors.mean) < 1e-9);
            } else {
                assert!(d > 1e-3, "{kind:?}: {d}");
            }
        }
    }

    #[test]
    fn velocity_norms_are_clipped_and_f32_agrees_with_f64() {
        let sp = spec("team_reach/1_ant");
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let (v, s) = random_obs(&mut rng, 32, sp.n_nodes);
        let mut n = ObsNormalizer::new(NormKind::Invariant, &sp);
        n.update(&v, &s);
        let mut big = v[..sp.n_nodes * NODE_VECTOR_LEN].to_vec();
        big[3..6].copy_from_slice(&[300.0, -400.0, 0.0]); // node 0's velocity, norm 500
        let (mut ov, mut os) = (vec![], vec![]);
        n.apply(&big, &s[..sp.n_nodes * N_SCALARS], &mut ov, &mut os);
        let norm = ov[3..6].iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((norm - CLIP as f64).abs() < 1e-12, "{norm}");
        assert!((ov[3] / ov[4] - 300.0 / -400.0).abs() < 1e-12, "direction kept");
        // The same map on f32 arrays, to f32 precision.
        let v32: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        let s32: Vec<f32> = s.iter().map(|&x| x as f32).collect();
        let (mut a64, mut b64, mut a32, mut b32) = (vec![], vec![], vec![], vec![]);
        let v64: Vec<f64> = v32.iter().map(|&x| x as f64).collect();
        let s64: Vec<f64> = s32.iter().map(|&x| x as f64).collect();
        n.apply(&v64, &s64, &mut a64, &mut b64);
        n.apply(&v32, &s32, &mut a32, &mut b32);
        for (x, y) in a32.iter().chain(&b32).zip(a64.iter().chain(&b64)) {
            assert!((*x as f64 - y).abs() <= 1e-6 * y.abs().max(1.0), "{x} vs {y}");
        }
    }

    #[test]
    fn elementwise_output_is_standardised() {
        let sp = spec("team_reach/1_ant");
        let nodes = sp.n_nodes;
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let b = 4000;
        let vectors: Vec<f32> = (0..b * nodes * NODE_VECTOR_LEN)
            .map(|i| rng.random_range(0.0..1.0f32) * 3.0 + (i % NODE_VECTOR_LEN) as f32)
            .collect();
        let scalars: Vec<f32> = (0..b * nodes * N_SCALARS).map(|_| rng.random_range(-5.0..5.0f32)).collect();
        let mut n = ObsNormalizer::new(NormKind::Elementwise, &sp);
        n.update(&vectors, &scalars);
        let (mut v, mut s) = (vec![], vec![]);
        n.apply(&vectors, &scalars, &mut v, &mut s);
        let st = RunningStats::from_rows(&v, nodes * NODE_VECTOR_LEN);
        for j in 0..nodes * NODE_VECTOR_LEN {
            assert!(st.mean[j].abs() < 1e-5 && (st.variance(j) - 1.0).abs() < 1e-4, "{j}: {st:?}");
        }
    }

    #[test]
    fn normalisers_of_another_layout_do_not_fit() {
        let (a, b) = (spec("team_reach/1_ant"), spec("team_reach/2_ants"));
        let inv = ObsNormalizer::new(NormKind::Invariant, &a);
        assert!(inv.check_fits(&inv).is_ok());
        let e = ObsNormalizer::new(NormKind::Elementwise, &a).check_fits(&inv).unwrap_err();
        assert!(e.contains("elementwise") && e.contains("invariant"), "{e}");
        assert!(ObsNormalizer::new(NormKind::Invariant, &b).check_fits(&inv).is_err());
        let mut damaged = inv.clone();
        damaged.vectors.m2.pop();
        assert!(damaged.check_fits(&inv).unwrap_err().contains("vectors"));
        let mut nan = inv.clone();
        nan.positions.mean[0] = f64::NAN;
        assert!(nan.check_fits(&inv).unwrap_err().contains("positions"));
    }
}
