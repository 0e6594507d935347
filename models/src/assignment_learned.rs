//! A co-learnable task assignment (`assignment=learned`, the paper's Limitations section): a
//! distribution over one-to-one agent-object assignments whose scores come from a small
//! network, trained with the policy.
//!
//! # Scores
//! For scene `b`, agent `i` (`n` agents) and object `j` (`m` objects: goal balls or
//! opponents, as in [`crate::assignment`]) the [`AssignmentScorer`] computes
//!
//! `s_ij = f_θ(x_ij) - λ d_ij`
//!
//! where `f_θ` is an MLP (hidden `tanh` layers, one output) applied to each pair on its own and
//! `x_ij` the pair's features ([`PairFeatureSet`]): the distance `d_ij = |p_j - p_i|`
//! (invariant under all rotations, reflections and translations, E(3)), and by default also
//! the height difference along gravity `Δh_ij = -<p_j - p_i, g>` (invariant under the
//! subgroup the environment keeps: rotations about the gravity axis `g` and translations).
//! `λ >= 0` ([`ScorerConfig::distance_prior`], a constant, not learned) starts the
//! distribution near a soft Algorithm 1: with `f_θ = 0` and `λ -> ∞` sampling is exactly the
//! greedy rule (nearest free agent first). Positions and features are `f64`; the network runs
//! in the store's float type `T`.
//!
//! # The distribution (Plackett-Luce over agents, objects in Algorithm 1's order)
//! Objects `j = 0, 1, .., k - 1` (`k = min(n, m)`) choose in their fixed order, each an agent
//! among those still free, with probability the softmax of its scores over the free agents:
//!
//! `P(σ) = Π_{j<k} exp(s_{σ(j) j}) / Σ_{i ∈ F_j} exp(s_ij)`,  `F_j = {0..n} \ {σ(0), .., σ(j-1)}`.
//!
//! This is Algorithm 1 with its `argmin_i d_ij` over free agents replaced by a softmax over
//! free agents of `s_ij`. When `m > n`, objects `j >= n` find no free agent and stay
//! [`UNASSIGNED`], as the greedy and stochastic methods of [`crate::assignment`] leave them;
//! every assignment with another unassigned subset has probability 0 (and is rejected as input).
//! The output format is [`crate::Assigner::assign`]'s: for each object the agent assigned.
//!
//! Why Plackett-Luce: the log-probability of a drawn assignment is exact and in closed form
//! (a sum of `k` masked log-sum-exps), so it joins the action's log-probability in the PPO
//! ratio as another factor of the policy; sampling is exact (k categorical draws, O(m n)); the
//! log-probability is differentiable in the scores; and it contains Algorithm 1 as its
//! zero-temperature limit. Gumbel-Sinkhorn (a relaxation to doubly stochastic matrices) only
//! approximates the distribution over permutations, needs a temperature, and gives no exact
//! log-probability of a hard assignment, which the PPO ratio needs.
//!
//! # Entropy
//! The exact entropy sums over all `n! / (n - k)!` assignments. [`log_prob_and_entropy`]
//! returns instead the chain-rule estimate along the given (sampled) assignment,
//!
//! `Ĥ(σ) = Σ_{j<k} H(σ(j) | σ(<j)) = Σ_{j<k} -Σ_{i ∈ F_j} π_ij ln π_ij`,  `π_ij = softmax_{F_j}(s_·j)_i`,
//!
//! the per-step conditional entropies; by the chain rule of entropy its expectation under
//! `σ ~ P` is the exact entropy `H(P)`. Its gradient is the gradient of each conditional
//! entropy at the sampled prefix (no score-function term), the same kind of one-sample
//! estimate as the Tanh-Normal entropy bonus of [`crate::distribution`].
//!
//! # Most likely assignment (evaluation)
//! [`PlackettLuceAssigner::most_likely`] returns the maximum-total-score matching
//! `argmax_σ Σ_j s_{σ(j) j}` (the Hungarian algorithm of [`crate::Assigner`] on the cost
//! `-s`; with `m > n` on the first `n` objects, the only ones the distribution assigns). It is
//! not exactly the Plackett-Luce mode: `ln P(σ)` also subtracts the normalisers
//! `ln Σ_{F_j} exp(s_ij)`, which depend on `σ`; the two agree when the scores separate the
//! agents clearly (low temperature), and the matching is invariant and deterministic.
//!
//! # Cost per step
//! The scorer runs once over all `B n m` pairs (an MLP on `B n m` rows of 1 or 2 features);
//! sampling is O(m n) per scene on the host; the log-probability and entropy are O(B k n)
//! tape operations on the scores.

use nn::{Bound, Mlp, Scope};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use tensor::{Activation, Float, Tensor, Var};

use crate::assignment::{Assigner, AssignmentMethod, UNASSIGNED};
use crate::error::{ModelError, Result};

/// The E(3)-invariant features of an (agent, object) pair the scorer reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PairFeatureSet {
    /// `[d_ij]`: invariant under every rotation, reflection and translation.
    Distance,
    /// `[d_ij, Δh_ij]` with `Δh_ij = -<p_j - p_i, g>` (the object's height above the agent):
    /// invariant under rotations about the gravity axis and translations (the symmetry
    /// MeBen keeps).
    DistanceHeight,
}

impl PairFeatureSet {
    /// The number of features per pair.
    pub fn width(self) -> usize {
        match self {
            PairFeatureSet::Distance => 1,
            PairFeatureSet::DistanceHeight => 2,
        }
    }

    /// Parses `distance` or `distance_height`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "distance" => Ok(Self::Distance),
            "distance_height" => Ok(Self::DistanceHeight),
            _ => Err(ModelError::Option(format!(
                "unknown pair features `{s}` (expected distance or distance_height)"
            ))),
        }
    }
}

/// The scorer's options.
#[derive(Clone, Debug, PartialEq)]
pub struct ScorerConfig {
    /// Which pair features the MLP reads.
    pub features: PairFeatureSet,
    /// Hidden widths of the MLP (`tanh` after each); empty makes it affine.
    pub hidden: Vec<usize>,
    /// `λ` of `s_ij = f_θ(x_ij) - λ d_ij` (per unit of distance, `>= 0`, not learned).
    pub distance_prior: f64,
}

impl Default for ScorerConfig {
    /// `[d, Δh]`, hidden 64 x 2, `λ = 1`.
    fn default() -> Self {
        Self { features: PairFeatureSet::DistanceHeight, hidden: vec![64, 64], distance_prior: 1.0 }
    }
}

/// The features of every (agent, object) pair of a batch of scenes, in `f64`.
#[derive(Clone, Debug, PartialEq)]
pub struct PairFeatures {
    /// Scenes `B`.
    pub batch: usize,
    /// Agents per scene `n`.
    pub agents: usize,
    /// Objects per scene `m`.
    pub objects: usize,
    /// Which features `values` holds.
    pub set: PairFeatureSet,
    /// `[B, n, m, width]` row-major: scene, agent, object, feature.
    pub values: Vec<f64>,
    /// The distances `d_ij`, `[B, n, m]` (the distance matrix of [`crate::Assigner::assign`]
    /// for each scene).
    pub distances: Vec<f64>,
}

impl PairFeatures {
    /// Features of `batch` scenes from the agents' positions (`[B * n]`, scene-major) and the
    /// objects' (`[B * m]`), `gravity` the unit direction of gravity.
    pub fn new(
        set: PairFeatureSet,
        batch: usize,
        agents: &[[f64; 3]],
        objects: &[[f64; 3]],
        gravity: [f64; 3],
    ) -> Result<Self> {
        if batch == 0 || agents.is_empty() || objects.is_empty() {
            return Err(ModelError::Input(format!(
                "pair features of {batch} scenes, {} agent and {} object positions (none may be empty)",
                agents.len(),
                objects.len()
            )));
        }
        if agents.len() % batch != 0 || objects.len() % batch != 0 {
            return Err(ModelError::Input(format!(
                "{} agent and {} object positions do not split into {batch} scenes",
                agents.len(),
                objects.len()
            )));
        }
        check_gravity(gravity)?;
        if let Some(p) = agents.iter().chain(objects).find(|p| p.iter().any(|x| !x.is_finite())) {
            return Err(ModelError::Input(format!("non-finite position {p:?}")));
        }
        let (n, m, w) = (agents.len() / batch, objects.len() / batch, set.width());
        let mut values = Vec::with_capacity(batch * n * m * w);
        let mut distances = Vec::with_capacity(batch * n * m);
        for b in 0..batch {
            for a in &agents[b * n..(b + 1) * n] {
                for o in &objects[b * m..(b + 1) * m] {
                    let r = [o[0] - a[0], o[1] - a[1], o[2] - a[2]];
                    let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                    distances.push(d);
                    values.push(d);
                    if set == PairFeatureSet::DistanceHeight {
                        values.push(-(r[0] * gravity[0] + r[1] * gravity[1] + r[2] * gravity[2]));
                    }
                }
            }
        }
        Ok(Self { batch, agents: n, objects: m, set, values, distances })
    }

    /// Features from entity positions laid out as [`crate::EntityInputs::positions`]
    /// (`entities` per scene, scene-major): agent `i` is entity `agents[i]` of each scene,
    /// object `j` entity `objects[j]` (the rows and columns of the graph builder's distance
    /// matrix).
    pub fn from_entities(
        set: PairFeatureSet,
        positions: &[[f64; 3]],
        entities: usize,
        agents: &[usize],
        objects: &[usize],
        gravity: [f64; 3],
    ) -> Result<Self> {
        if entities == 0 || positions.is_empty() || positions.len() % entities != 0 {
            return Err(ModelError::Input(format!(
                "{} entity positions do not split into scenes of {entities} entities",
                positions.len()
            )));
        }
        if let Some(&e) = agents.iter().chain(objects).find(|&&e| e >= entities) {
            return Err(ModelError::Input(format!("entity {e} of a scene of {entities} entities")));
        }
        let batch = positions.len() / entities;
        let pick = |idx: &[usize]| -> Vec<[f64; 3]> {
            positions.chunks(entities).flat_map(|scene| idx.iter().map(move |&e| scene[e])).collect()
        };
        Self::new(set, batch, &pick(agents), &pick(objects), gravity)
    }
}

fn check_gravity(g: [f64; 3]) -> Result<()> {
    let norm = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
    if !norm.is_finite() || (norm - 1.0).abs() > 1e-6 {
        return Err(ModelError::Input(format!("gravity direction {g:?} is not a unit vector")));
    }
    Ok(())
}

/// The learned scorer `s_ij = f_θ(x_ij) - λ d_ij` (parameters `<scope>.mlp.<layer>.weight`
/// and `.bias`).
#[derive(Clone, Debug)]
pub struct AssignmentScorer {
    /// `f_θ`: pair features -> hidden (`tanh`) -> 1.
    pub mlp: Mlp,
    /// The options it was built with.
    pub config: ScorerConfig,
}

impl AssignmentScorer {
    /// A scorer with its parameters created in `scope`.
    pub fn new<T: Float>(scope: &mut Scope<'_, T>, config: ScorerConfig) -> Result<Self> {
        if !config.distance_prior.is_finite() || config.distance_prior < 0.0 {
            return Err(ModelError::Option(format!(
                "assignment scorer distance prior {} (expected a finite value >= 0)",
                config.distance_prior
            )));
        }
        if let Some(w) = config.hidden.iter().find(|&&w| w == 0) {
            return Err(ModelError::Option(format!(
                "assignment scorer hidden widths {:?} contain {w}",
                config.hidden
            )));
        }
        let mut sizes = vec![config.features.width()];
        sizes.extend(&config.hidden);
        sizes.push(1);
        let mlp = Mlp::new(&mut scope.sub("mlp"), &sizes, Activation::Tanh)?;
        Ok(Self { mlp, config })
    }

    /// The scores `[B, n, m]` of every pair of `x` (which must hold this scorer's feature set).
    pub fn scores<'t, T: Float>(&self, p: &Bound<'t, T>, x: &PairFeatures) -> Result<Var<'t, T>> {
        if x.set != self.config.features {
            return Err(ModelError::Input(format!(
                "pair features {:?} for a scorer that reads {:?}",
                x.set, self.config.features
            )));
        }
        let (b, n, m, w) = (x.batch, x.agents, x.objects, x.set.width());
        let rows = b * n * m;
        if x.values.len() != rows * w || x.distances.len() != rows {
            return Err(ModelError::Input(format!(
                "pair features of {} values and {} distances for {b} x {n} x {m} pairs of {w} features",
                x.values.len(),
                x.distances.len()
            )));
        }
        let tape = p.tape();
        let input = tape.constant(Tensor::new(x.values.iter().map(|&v| T::from_f64(v)).collect(), &[rows, w])?);
        let mut s = self.mlp.forward(p, input)?;
        if self.config.distance_prior != 0.0 {
            let lam = self.config.distance_prior;
            let prior = Tensor::new(x.distances.iter().map(|&d| T::from_f64(-lam * d)).collect(), &[rows, 1])?;
            s = s.add(tape.constant(prior))?;
        }
        Ok(s.reshape(&[b, n, m])?)
    }
}

/// Checks that `assignment` (`[B * m]`, object -> agent) has positive probability under the
/// Plackett-Luce distribution of `n` agents and `m` objects per scene: objects `j < min(n, m)`
/// hold distinct agents `< n`, objects `j >= n` are [`UNASSIGNED`].
pub fn check_assignment(assignment: &[usize], batch: usize, n: usize, m: usize) -> Result<()> {
    if assignment.len() != batch * m {
        return Err(ModelError::Input(format!(
            "assignment of {} entries for {batch} scenes of {m} objects",
            assignment.len()
        )));
    }
    for (b, scene) in assignment.chunks(m.max(1)).enumerate() {
        for (j, &i) in scene.iter().enumerate() {
            let ok = if j < n { i < n && !scene[..j].contains(&i) } else { i == UNASSIGNED };
            if !ok {
                let agent = if i == UNASSIGNED { "unassigned".to_string() } else { format!("agent {i}") };
                return Err(ModelError::Input(format!(
                    "assignment of scene {b}: object {j} to {agent} (objects 0..{} take distinct agents \
                     0..{n} in order, the rest are unassigned)",
                    n.min(m)
                )));
            }
        }
    }
    Ok(())
}

/// Checks the host scores (`[B, n, m]` row-major, agent rows as the distance matrix) and
/// returns them in `f64`.
fn host_scores<T: Float>(scores: &[T], batch: usize, n: usize, m: usize) -> Result<Vec<f64>> {
    if batch == 0 || n == 0 || m == 0 || scores.len() != batch * n * m {
        return Err(ModelError::Input(format!(
            "{} scores for {batch} scenes of {n} agents x {m} objects (none may be empty)",
            scores.len()
        )));
    }
    let s: Vec<f64> = scores.iter().map(|x| x.to_f64()).collect();
    if let Some(k) = s.iter().position(|x| !x.is_finite()) {
        return Err(ModelError::Input(format!(
            "non-finite score {} of scene {}, agent {}, object {}",
            s[k],
            k / (n * m),
            k / m % n,
            k % m
        )));
    }
    Ok(s)
}

/// Sampling and the most likely assignment on the host, with scratch reused across calls
/// (a batch of scenes allocates nothing beyond the first call's sizes).
#[derive(Clone, Debug)]
pub struct PlackettLuceAssigner {
    hungarian: Assigner,
    capacity: (usize, usize),
    free: Vec<bool>,
    cost: Vec<f64>,
}

impl PlackettLuceAssigner {
    /// Scratch for scenes of at most `max_agents` agents and `max_objects` objects.
    pub fn new(max_agents: usize, max_objects: usize) -> Self {
        Self {
            hungarian: Assigner::new(max_agents, max_objects),
            capacity: (max_agents, max_objects),
            free: vec![true; max_agents],
            cost: vec![0.0; max_agents * max_objects],
        }
    }

    fn check_capacity(&self, n: usize, m: usize) -> Result<()> {
        if n > self.capacity.0 || m > self.capacity.1 {
            return Err(ModelError::Input(format!(
                "scenes of {n} agents x {m} objects for an assigner of at most {} x {}",
                self.capacity.0, self.capacity.1
            )));
        }
        Ok(())
    }

    /// Draws an assignment of each of the `batch` scenes from the Plackett-Luce distribution
    /// of `scores` (`[B, n, m]` row-major, e.g. the host value of
    /// [`AssignmentScorer::scores`]), writing the agent of object `j` of scene `b` to
    /// `out[b * m + j]` ([`UNASSIGNED`] for objects `j >= n`). Consumes `min(n, m)` uniform
    /// draws of `rng` per scene, so a seed fixes the draw.
    pub fn sample<T: Float>(
        &mut self,
        scores: &[T],
        batch: usize,
        n: usize,
        m: usize,
        rng: &mut ChaCha8Rng,
        out: &mut [usize],
    ) -> Result<()> {
        self.check_capacity(n, m)?;
        let s = host_scores(scores, batch, n, m)?;
        if out.len() != batch * m {
            return Err(ModelError::Input(format!("{} outputs for {batch} scenes of {m} objects", out.len())));
        }
        for (scene, o) in s.chunks(n * m).zip(out.chunks_mut(m)) {
            let free = &mut self.free[..n];
            free.fill(true);
            for (j, oj) in o.iter_mut().enumerate() {
                if j >= n {
                    *oj = UNASSIGNED;
                    continue;
                }
                let top = (0..n).filter(|&i| free[i]).map(|i| scene[i * m + j]).fold(f64::NEG_INFINITY, f64::max);
                let total: f64 = (0..n).filter(|&i| free[i]).map(|i| (scene[i * m + j] - top).exp()).sum();
                let u = rng.random::<f64>() * total;
                let mut acc = 0.0;
                let mut pick = UNASSIGNED;
                for i in (0..n).filter(|&i| free[i]) {
                    // The last free agent takes whatever rounding leaves above the sum.
                    pick = i;
                    acc += (scene[i * m + j] - top).exp();
                    if u < acc {
                        break;
                    }
                }
                free[pick] = false;
                *oj = pick;
            }
        }
        Ok(())
    }

    /// The maximum-total-score assignment of each scene (`argmax_σ Σ_j s_{σ(j) j}`, the
    /// Hungarian algorithm on the cost `-s`), in [`PlackettLuceAssigner::sample`]'s format.
    /// With `m > n` only the first `n` objects are matched (the others have no agent under the
    /// distribution). Not exactly the Plackett-Luce mode (see the module doc).
    pub fn most_likely<T: Float>(
        &mut self,
        scores: &[T],
        batch: usize,
        n: usize,
        m: usize,
        out: &mut [usize],
    ) -> Result<()> {
        self.check_capacity(n, m)?;
        let s = host_scores(scores, batch, n, m)?;
        if out.len() != batch * m {
            return Err(ModelError::Input(format!("{} outputs for {batch} scenes of {m} objects", out.len())));
        }
        let k = n.min(m);
        // The Hungarian method only uses its rng for the stochastic method; a fixed one.
        let mut unused = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
        for (scene, o) in s.chunks(n * m).zip(out.chunks_mut(m)) {
            let cost = &mut self.cost[..n * k];
            for i in 0..n {
                for j in 0..k {
                    cost[i * k + j] = -scene[i * m + j];
                }
            }
            o.fill(UNASSIGNED);
            self.hungarian.assign(AssignmentMethod::Hungarian, cost, n, k, &mut o[..k], &mut unused);
        }
        Ok(())
    }
}

/// The log-probability of one scene's assignment under the Plackett-Luce distribution of its
/// host scores (`[n, m]`, agent rows), in `f64` (for checks and logging; the trainer uses the
/// differentiable [`log_prob_and_entropy`]).
pub fn log_prob_host(scores: &[f64], n: usize, m: usize, assignment: &[usize]) -> Result<f64> {
    let s = host_scores(scores, 1, n, m)?;
    check_assignment(assignment, 1, n, m)?;
    let mut free = vec![true; n];
    let mut lp = 0.0;
    for (j, &a) in assignment.iter().enumerate().take(n.min(m)) {
        let top = (0..n).filter(|&i| free[i]).map(|i| s[i * m + j]).fold(f64::NEG_INFINITY, f64::max);
        let lse = top + (0..n).filter(|&i| free[i]).map(|i| (s[i * m + j] - top).exp()).sum::<f64>().ln();
        lp += s[a * m + j] - lse;
        free[a] = false;
    }
    Ok(lp)
}

/// The differentiable log-probability `[B]` of the given assignments (`[B * m]`, object ->
/// agent, as drawn by [`PlackettLuceAssigner::sample`]) under the scores `[B, n, m]`, and the
/// chain-rule entropy estimate `[B]` along them (module doc, "Entropy"):
///
/// `ln P(σ) = Σ_{j<k} (s_{σ(j) j} - LSE_{i ∈ F_j} s_ij)`,
/// `Ĥ(σ) = Σ_{j<k} (LSE_{i ∈ F_j} s_ij - Σ_{i ∈ F_j} π_ij s_ij)`.
///
/// The free sets `F_j` are masks built on the host from the assignment; each log-sum-exp is
/// shifted by the (constant) maximum over its free agents, so nothing overflows. Errors name
/// a scores shape that is not `[B, n, m]`, a non-finite score, or an assignment of
/// probability 0 ([`check_assignment`]).
pub fn log_prob_and_entropy<'t, T: Float>(
    scores: Var<'t, T>,
    assignment: &[usize],
) -> Result<(Var<'t, T>, Var<'t, T>)> {
    let shape = scores.shape();
    let &[b, n, m] = shape.as_slice() else {
        return Err(ModelError::Input(format!("assignment scores of shape {shape:?} (expected [B, n, m])")));
    };
    let value = scores.value().to_host()?;
    let s = host_scores(value.data(), b, n, m)?;
    check_assignment(assignment, b, n, m)?;
    let k = n.min(m);
    // Per scene b, step j < k, agent i (row (b, j), column i of [B, k, n]): free, chosen,
    // and the step's shift.
    let mut free = vec![false; b * k * n];
    let mut chosen = vec![T::from_f64(0.0); b * k * n];
    let mut shift = Vec::with_capacity(b * k);
    for bi in 0..b {
        let scene = &s[bi * n * m..(bi + 1) * n * m];
        let sigma = &assignment[bi * m..bi * m + k];
        for j in 0..k {
            let row = (bi * k + j) * n;
            let mut top = f64::NEG_INFINITY;
            for i in 0..n {
                if !sigma[..j].contains(&i) {
                    free[row + i] = true;
                    top = top.max(scene[i * m + j]);
                }
            }
            chosen[row + sigma[j]] = T::from_f64(1.0);
            shift.push(T::from_f64(top));
        }
    }
    let tape = scores.tape();
    // x[b, j, i] = s[b, i, j] - c[b, j] over the first k objects.
    let st = scores.transpose(1, 2)?.narrow(1, 0, k)?;
    let x = st.sub(tape.constant(Tensor::new(shift, &[b, k, 1])?))?;
    let zero = tape.constant(Tensor::zeros(&[1]));
    // exp of the free entries only: masked to 0 before the exp (no overflow, no inf * 0 in
    // the backward pass) and after it.
    let x_free = tape.where_select(&free, x, zero)?;
    let e = tape.where_select(&free, x_free.exp(), zero)?;
    let z = e.sum(2, true)?; // [B, k, 1], >= 1 (the maximum contributes exp(0))
    let log_z = z.log().reshape(&[b, k])?;
    let picked = x.mul(tape.constant(Tensor::new(chosen, &[b, k, n])?))?.sum(2, false)?;
    let log_prob = picked.sub(log_z)?.sum(1, false)?;
    let mean_x = e.div(z)?.mul(x_free)?.sum(2, false)?;
    let entropy = log_z.sub(mean_x)?.sum(1, false)?;
    Ok((log_prob, entropy))
}

/// The differentiable log-probability `[B]` of the given assignments (see
/// [`log_prob_and_entropy`], which also returns the entropy estimate at little extra cost).
pub fn log_prob<'t, T: Float>(scores: Var<'t, T>, assignment: &[usize]) -> Result<Var<'t, T>> {
    Ok(log_prob_and_entropy(scores, assignment)?.0)
}

/// The chain-rule entropy estimate `[B]` along the given assignments (see
/// [`log_prob_and_entropy`]).
pub fn entropy_estimate<'t, T: Float>(scores: Var<'t, T>, assignment: &[usize]) -> Result<Var<'t, T>> {
    Ok(log_prob_and_entropy(scores, assignment)?.1)
}
