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
//! # Use per step (for the trainer)
//! 1. Collection: [`PairFeatures::from_entities`] from [`crate::EntityInputs::positions`] and
//!    [`crate::GraphBuilder::assignment_entities`]; [`AssignmentScorer::scores`] on a no-grad
//!    tape; [`PlackettLuceAssigner::sample`] with the trainer's seeded stream; the draw goes
//!    to [`crate::GraphBuilder::build_with`] (as [`crate::NO_AGENT`] / `u32`) and is stored
//!    with the transition, its [`log_prob_host`] added to the action's old log-probability.
//! 2. Update: the same features and the scores on the gradient tape;
//!    [`log_prob_and_entropy`] of the stored draw gives the `[B]` log-probability to add to
//!    the action's in the PPO ratio and the entropy estimate to add to the bonus.
//! 3. Evaluation: [`PlackettLuceAssigner::most_likely`] (or a seeded draw).
//!
//! [`LearnedAssignment`] does the three for a model: `shnn:assignment=learned` (the SHNN
//! family) holds one, its scorer's parameters under `assign.`, and returns the terms with the
//! policy's output ([`crate::PolicyOutput::assignment_terms`]).
//!
//! # Per-scene draws (a hold per episode)
//! A given assignment may mark whole scenes with [`DRAW_SCENE`]: those scenes are drawn (or
//! their most likely assignment taken) as if none were given, the others keep theirs. The
//! trainer's hold per episode (`assignment_hold_episode`) gives back every scene's held
//! assignment and marks the scenes whose episode has just begun.
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
use crate::entity_graph::{EntityGraph, GraphBuilder};
use crate::error::{ModelError, Result};
use crate::input::EntityInputs;
use crate::interface::AssignmentTerms;

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
            _ => Err(ModelError::Option(format!("unknown pair features `{s}` (expected distance or distance_height)"))),
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
        if !agents.len().is_multiple_of(batch) || !objects.len().is_multiple_of(batch) {
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
        if entities == 0 || positions.is_empty() || !positions.len().is_multiple_of(entities) {
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
            return Err(ModelError::Option(format!("assignment scorer hidden widths {:?} contain {w}", config.hidden)));
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

/// Checks the host scores (`[B, n, m]` row-major, agent rows as the distance matrix): their
/// count and that every one is finite.
fn check_scores<T: Float>(scores: &[T], batch: usize, n: usize, m: usize) -> Result<()> {
    if batch == 0 || n == 0 || m == 0 || scores.len() != batch * n * m {
        return Err(ModelError::Input(format!(
            "{} scores for {batch} scenes of {n} agents x {m} objects (none may be empty)",
            scores.len()
        )));
    }
    if let Some(k) = scores.iter().position(|x| !x.to_f64().is_finite()) {
        return Err(ModelError::Input(format!(
            "non-finite score {} of scene {}, agent {}, object {}",
            scores[k].to_f64(),
            k / (n * m),
            k / m % n,
            k % m
        )));
    }
    Ok(())
}

/// Sampling and the most likely assignment on the host, with scratch reused across calls
/// (sampling and matching a batch of scenes allocate nothing).
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

    /// Checks a call's arguments: scenes within the scratch's capacity, the scores
    /// ([`check_scores`]) and `out_len` outputs, one per object of every scene.
    fn check_call<T: Float>(&self, scores: &[T], batch: usize, n: usize, m: usize, out_len: usize) -> Result<()> {
        if n > self.capacity.0 || m > self.capacity.1 {
            return Err(ModelError::Input(format!(
                "scenes of {n} agents x {m} objects for an assigner of at most {} x {}",
                self.capacity.0, self.capacity.1
            )));
        }
        check_scores(scores, batch, n, m)?;
        if out_len != batch * m {
            return Err(ModelError::Input(format!("{out_len} outputs for {batch} scenes of {m} objects")));
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
        self.check_call(scores, batch, n, m, out.len())?;
        for (scene, o) in scores.chunks(n * m).zip(out.chunks_mut(m)) {
            let score = |i: usize, j: usize| scene[i * m + j].to_f64();
            let free = &mut self.free[..n];
            free.fill(true);
            for (j, oj) in o.iter_mut().enumerate() {
                if j >= n {
                    *oj = UNASSIGNED;
                    continue;
                }
                let top = (0..n).filter(|&i| free[i]).map(|i| score(i, j)).fold(f64::NEG_INFINITY, f64::max);
                let total: f64 = (0..n).filter(|&i| free[i]).map(|i| (score(i, j) - top).exp()).sum();
                let u = rng.random::<f64>() * total;
                let mut acc = 0.0;
                let mut pick = UNASSIGNED;
                for i in (0..n).filter(|&i| free[i]) {
                    // The last free agent takes whatever rounding leaves above the sum.
                    pick = i;
                    acc += (score(i, j) - top).exp();
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
        self.check_call(scores, batch, n, m, out.len())?;
        let k = n.min(m);
        // The Hungarian method only uses its rng for the stochastic method; a fixed one.
        let mut unused = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0);
        for (scene, o) in scores.chunks(n * m).zip(out.chunks_mut(m)) {
            let cost = &mut self.cost[..n * k];
            for i in 0..n {
                for j in 0..k {
                    cost[i * k + j] = -scene[i * m + j].to_f64();
                }
            }
            o.fill(UNASSIGNED);
            self.hungarian.assign(AssignmentMethod::Hungarian, cost, n, k, &mut o[..k], &mut unused);
        }
        Ok(())
    }
}

/// The log-probabilities `[B]` of the assignments (`[B * m]`, object -> agent) under the
/// Plackett-Luce distribution of host scores `[B, n, m]` (agent rows), in `f64`: for logging
/// and checks, or to record a drawn assignment's log-probability at collection time (the
/// update uses the differentiable [`log_prob_and_entropy`] of the same scores).
pub fn log_prob_host<T: Float>(
    scores: &[T],
    batch: usize,
    n: usize,
    m: usize,
    assignment: &[usize],
) -> Result<Vec<f64>> {
    check_scores(scores, batch, n, m)?;
    check_assignment(assignment, batch, n, m)?;
    let mut free = vec![true; n];
    let mut out = Vec::with_capacity(batch);
    for (scene, sigma) in scores.chunks(n * m).zip(assignment.chunks(m)) {
        let score = |i: usize, j: usize| scene[i * m + j].to_f64();
        free.fill(true);
        let mut lp = 0.0;
        for (j, &a) in sigma.iter().enumerate().take(n.min(m)) {
            let top = (0..n).filter(|&i| free[i]).map(|i| score(i, j)).fold(f64::NEG_INFINITY, f64::max);
            let lse = top + (0..n).filter(|&i| free[i]).map(|i| (score(i, j) - top).exp()).sum::<f64>().ln();
            lp += score(a, j) - lse;
            free[a] = false;
        }
        out.push(lp);
    }
    Ok(out)
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
    // The masks and shifts are built on the host (a download when the tape is on a device).
    let value = scores.value().to_host()?;
    check_scores(value.data(), b, n, m)?;
    check_assignment(assignment, b, n, m)?;
    let s = value.data();
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
                    top = top.max(scene[i * m + j].to_f64());
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

/// In an assignment given to [`LearnedAssignment::assign`], every entry of a scene that is
/// to be drawn (or its most likely assignment taken) as if none were given, while the other
/// scenes keep the assignment given (module docs, "Per-scene draws").
pub const DRAW_SCENE: u32 = u32::MAX - 1;

/// Every assignment of positive probability under the distribution of `n` agents and `m`
/// objects (module docs): the injective maps of objects `0..min(n, m)` to agents, later
/// objects [`UNASSIGNED`], in lexicographic order; `n! / (n - min(n, m))!` of them.
pub fn all_assignments(n: usize, m: usize) -> Vec<Vec<usize>> {
    fn extend(prefix: &mut Vec<usize>, n: usize, k: usize, m: usize, out: &mut Vec<Vec<usize>>) {
        if prefix.len() == k {
            let mut a = prefix.clone();
            a.resize(m, UNASSIGNED);
            out.push(a);
            return;
        }
        for i in 0..n {
            if !prefix.contains(&i) {
                prefix.push(i);
                extend(prefix, n, k, m, out);
                prefix.pop();
            }
        }
    }
    let mut out = Vec::new();
    extend(&mut Vec::new(), n, n.min(m), m, &mut out);
    out
}

/// How a [`LearnedAssignment`] chooses an assignment when none is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LearnedChoice {
    /// A draw from the Plackett-Luce distribution with the model's seeded stream
    /// ([`PlackettLuceAssigner::sample`]): collection, and evaluation with sampled actions.
    Sample,
    /// [`PlackettLuceAssigner::most_likely`]: deterministic evaluation.
    MostLikely,
}

/// The learned assignment as a model uses it per step (module doc, "Use per step"): the
/// scorer (its parameters in the model's scope), the graph builder's rows and columns, the
/// seeded stream of the draws and the host scratch. [`LearnedAssignment::assign`] scores the
/// pairs of a batch on the tape, draws (or takes the given) assignment of every scene and
/// returns it with its differentiable log-probability and entropy estimate.
#[derive(Clone, Debug)]
pub struct LearnedAssignment {
    /// The pair scorer.
    pub scorer: AssignmentScorer,
    assigner: PlackettLuceAssigner,
    rng: ChaCha8Rng,
    choice: LearnedChoice,
    warmup: bool,
    gravity: [f64; 3],
    agents: Vec<usize>,
    objects: Vec<usize>,
}

/// The entity graph of `inputs` with its assignment: with a learned assignment (`learned`)
/// the draw, or the given `fixed` one, scored on the tape of `p`, and its terms; otherwise,
/// and for a learned assignment in its warm-up, the graph builder's own assignment (or
/// `fixed`; a learned one in warm-up is Algorithm 1's, as the greedy model's) and no terms.
/// The SHNN family's and the release MLP's forward passes build their graphs through it.
pub(crate) fn build_graph<'t, T: Float>(
    graph: &mut GraphBuilder,
    learned: Option<&mut LearnedAssignment>,
    p: &Bound<'t, T>,
    inputs: &EntityInputs<T>,
    fixed: Option<&[u32]>,
) -> Result<(EntityGraph, Option<AssignmentTerms<'t, T>>)> {
    match learned {
        None => Ok((graph.build_with(inputs, fixed)?, None)),
        Some(l) if l.in_warmup() => Ok((graph.build_solving(inputs, fixed)?, None)),
        Some(l) => {
            let (drawn, log_prob, entropy) = l.assign(p, inputs, fixed)?;
            Ok((graph.build_with(inputs, Some(&drawn))?, Some(AssignmentTerms { log_prob, entropy })))
        }
    }
}

impl LearnedAssignment {
    /// The assignments of `batch` scenes of scores `[batch, n, m]` into `out`
    /// (`[batch * m]`), drawn or the most likely as [`LearnedAssignment::choice`] says.
    fn choose<T: Float>(&mut self, scores: &[T], batch: usize, n: usize, m: usize, out: &mut [usize]) -> Result<()> {
        match self.choice {
            LearnedChoice::Sample => self.assigner.sample(scores, batch, n, m, &mut self.rng, out),
            LearnedChoice::MostLikely => self.assigner.most_likely(scores, batch, n, m, out),
        }
    }

    /// A learned assignment over the rows and columns of `graph`
    /// ([`crate::GraphBuilder::assignment_entities`]), its scorer's parameters created in
    /// `scope`, `gravity` the unit direction of gravity, its draws seeded by `seed`.
    pub fn new<T: Float>(
        scope: &mut Scope<'_, T>,
        config: ScorerConfig,
        graph: &crate::entity_graph::GraphBuilder,
        gravity: [f64; 3],
        seed: u64,
    ) -> Result<Self> {
        check_gravity(gravity)?;
        let (agents, objects) = graph.assignment_entities();
        let scorer = AssignmentScorer::new(scope, config)?;
        Ok(Self {
            scorer,
            assigner: PlackettLuceAssigner::new(agents.len(), objects.len()),
            rng: <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed),
            choice: LearnedChoice::Sample,
            warmup: false,
            gravity,
            agents: agents.to_vec(),
            objects: objects.to_vec(),
        })
    }

    /// Restarts the stream of the draws from `seed` (the trainer reseeds it every iteration).
    pub fn reseed(&mut self, seed: u64) {
        self.rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed);
    }

    /// How an assignment is chosen when none is given.
    pub fn choice(&self) -> LearnedChoice {
        self.choice
    }

    /// Sets how an assignment is chosen when none is given.
    pub fn set_choice(&mut self, choice: LearnedChoice) {
        self.choice = choice;
    }

    /// Whether the assignment is in its warm-up: Algorithm 1's (the paper's greedy rule),
    /// solved by the graph builder as the greedy model solves it, the scorer unused.
    pub fn in_warmup(&self) -> bool {
        self.warmup
    }

    /// Puts the assignment in its warm-up (`true`) or takes it out (`false`, the default).
    pub fn set_warmup(&mut self, warmup: bool) {
        self.warmup = warmup;
    }

    /// Every assignment of positive probability ([`all_assignments`] of this scene's agents
    /// and objects), in the format of [`LearnedAssignment::assign`]'s output (object -> agent,
    /// [`crate::NO_AGENT`] for none).
    pub fn support(&self) -> Vec<Vec<u32>> {
        all_assignments(self.agents.len(), self.objects.len())
            .into_iter()
            .map(|a| {
                a.into_iter().map(|i| if i == UNASSIGNED { crate::entity_graph::NO_AGENT } else { i as u32 }).collect()
            })
            .collect()
    }

    /// The assignment of every scene of `inputs` (`[B * m]`, object -> agent index, as
    /// [`crate::EntityGraph::assignment`]: [`crate::NO_AGENT`] for none), with its
    /// log-probability `[B]` and chain-rule entropy estimate `[B]` on the tape of `p`
    /// ([`log_prob_and_entropy`]). With `given` (an assignment stored at collection) that
    /// one is scored; otherwise one is drawn or the most likely taken
    /// ([`LearnedAssignment::choice`]) from the scores' host values; a given assignment's
    /// scenes marked [`DRAW_SCENE`] are drawn so, in scene order, the others kept. Errors name
    /// a given assignment of another size, a scene only partly marked, or one of probability 0.
    pub fn assign<'t, T: Float>(
        &mut self,
        p: &Bound<'t, T>,
        inputs: &crate::input::EntityInputs<T>,
        given: Option<&[u32]>,
    ) -> Result<(Vec<u32>, Var<'t, T>, Var<'t, T>)> {
        let x = PairFeatures::from_entities(
            self.scorer.config.features,
            &inputs.positions,
            inputs.entities,
            &self.agents,
            &self.objects,
            self.gravity,
        )?;
        let scores = self.scorer.scores(p, &x)?;
        let (b, n, m) = (x.batch, x.agents, x.objects);
        let chosen: Vec<usize> = match given {
            Some(g) => {
                if g.len() != b * m {
                    return Err(ModelError::Input(format!(
                        "a given learned assignment of {} entries for {b} scenes x {m} objects",
                        g.len()
                    )));
                }
                let mut out: Vec<usize> = g
                    .iter()
                    .map(|&i| if i == crate::entity_graph::NO_AGENT { UNASSIGNED } else { i as usize })
                    .collect();
                // The scenes marked to be drawn, each wholly.
                let mut to_draw = Vec::new();
                for (e, scene) in g.chunks(m.max(1)).enumerate() {
                    match scene.iter().filter(|&&i| i == DRAW_SCENE).count() {
                        0 => {}
                        k if k == m => to_draw.push(e),
                        _ => {
                            return Err(ModelError::Input(format!(
                                "a given learned assignment whose scene {e} is only partly marked to be drawn"
                            )));
                        }
                    }
                }
                if !to_draw.is_empty() {
                    let host = scores.value().to_host()?;
                    for e in to_draw {
                        let scene = &host.data()[e * n * m..(e + 1) * n * m];
                        self.choose(scene, 1, n, m, &mut out[e * m..(e + 1) * m])?;
                    }
                }
                out
            }
            None => {
                let host = scores.value().to_host()?;
                let mut out = vec![UNASSIGNED; b * m];
                self.choose(host.data(), b, n, m, &mut out)?;
                out
            }
        };
        let (log_prob, entropy) = log_prob_and_entropy(scores, &chosen)?;
        let assignment =
            chosen.iter().map(|&i| if i == UNASSIGNED { crate::entity_graph::NO_AGENT } else { i as u32 }).collect();
        Ok((assignment, log_prob, entropy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nn::ParamStore;
    use rand::SeedableRng;
    use tensor::Tape;
    use tensor::gradcheck::check_gradients;

    fn rng(seed: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(seed)
    }

    fn random_scores(r: &mut ChaCha8Rng, len: usize, spread: f64) -> Vec<f64> {
        (0..len).map(|_| r.random_range(-spread..spread)).collect()
    }

    /// `P(σ)` straight from the definition (products of softmax ratios, no logs).
    fn probability(s: &[f64], n: usize, m: usize, sigma: &[usize]) -> f64 {
        let mut p = 1.0;
        for j in 0..n.min(m) {
            let den: f64 = (0..n).filter(|i| !sigma[..j].contains(i)).map(|i| s[i * m + j].exp()).sum();
            p *= s[sigma[j] * m + j].exp() / den;
        }
        p
    }

    /// The scores of one scene repeated for `copies` scenes, as a `[copies, n, m]` constant.
    fn repeated<'t>(tape: &'t Tape<f64>, s: &[f64], copies: usize, n: usize, m: usize) -> Var<'t, f64> {
        let data: Vec<f64> = (0..copies).flat_map(|_| s.iter().copied()).collect();
        tape.constant(Tensor::new(data, &[copies, n, m]).unwrap())
    }

    fn exact_entropy(s: &[f64], n: usize, m: usize) -> f64 {
        all_assignments(n, m).iter().map(|a| probability(s, n, m, a)).map(|p| -p * p.ln()).sum()
    }

    #[test]
    fn probabilities_sum_to_one_and_the_log_prob_var_is_their_log() {
        let mut r = rng(1);
        for n in 1..=4 {
            for m in 1..=4 {
                let s = random_scores(&mut r, n * m, 2.0);
                let all = all_assignments(n, m);
                let count: usize = (n - n.min(m) + 1..=n).product();
                assert_eq!(all.len(), count, "{n} x {m}");
                let probs: Vec<f64> = all.iter().map(|a| probability(&s, n, m, a)).collect();
                let total: f64 = probs.iter().sum();
                assert!((total - 1.0).abs() < 1e-12, "{n} agents x {m} objects: probabilities sum to {total}");
                // All assignments as one batch of the same scores.
                let tape = Tape::<f64>::new();
                let flat: Vec<usize> = all.iter().flatten().copied().collect();
                let (lp, h) = log_prob_and_entropy(repeated(&tape, &s, all.len(), n, m), &flat).unwrap();
                let (lp, h) = (lp.value(), h.value());
                assert_eq!(lp.shape(), &[all.len()]);
                for (b, (a, p)) in all.iter().zip(&probs).enumerate() {
                    assert!((lp.data()[b] - p.ln()).abs() < 1e-12, "{n} x {m}, {a:?}: {} vs ln {p}", lp.data()[b]);
                    assert!((log_prob_host(&s, 1, n, m, a).unwrap()[0] - p.ln()).abs() < 1e-12);
                }
                // The chain-rule estimate's expectation is the exact entropy (an exact sum here).
                let expected: f64 = probs.iter().zip(h.data()).map(|(p, h)| p * h).sum();
                let exact = exact_entropy(&s, n, m);
                assert!((expected - exact).abs() < 1e-12, "{n} x {m}: E[estimate] {expected} vs entropy {exact}");
            }
        }
    }

    #[test]
    fn the_sampler_draws_from_the_distribution_and_the_entropy_estimate_converges() {
        // n = m = 3: 6 assignments; 20 000 draws from one scene's scores.
        let (n, m, draws) = (3, 3, 20_000);
        let s = random_scores(&mut rng(2), n * m, 1.5);
        let all = all_assignments(n, m);
        let mut pl = PlackettLuceAssigner::new(n, m);
        let batch: Vec<f64> = (0..draws).flat_map(|_| s.iter().copied()).collect();
        let mut out = vec![0; draws * m];
        pl.sample(&batch, draws, n, m, &mut rng(3), &mut out).unwrap();
        check_assignment(&out, draws, n, m).unwrap();
        // Frequencies within 4.5 binomial standard deviations of the probabilities.
        for a in &all {
            let p = probability(&s, n, m, a);
            let freq = out.chunks(m).filter(|o| o == a).count() as f64 / draws as f64;
            let sd = (p * (1.0 - p) / draws as f64).sqrt();
            assert!((freq - p).abs() < 4.5 * sd, "{a:?}: frequency {freq} vs probability {p} (sd {sd})");
        }
        // The mean of the estimate over the draws: within 4 standard errors of the exact
        // entropy (the standard error is about 6e-4 here; the mean is 1.6615 against 1.6605).
        let tape = Tape::<f64>::new();
        let h = entropy_estimate(repeated(&tape, &s, draws, n, m), &out).unwrap().value();
        let mean = h.data().iter().sum::<f64>() / draws as f64;
        let var = h.data().iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (draws - 1) as f64;
        let se = (var / draws as f64).sqrt();
        let exact = exact_entropy(&s, n, m);
        assert!(se < 0.01, "standard error {se}");
        assert!((mean - exact).abs() < 4.0 * se, "mean estimate {mean} vs exact entropy {exact} (se {se})");
    }

    #[test]
    fn the_log_prob_and_entropy_are_stable_for_large_scores_in_f32() {
        // Spread 1e4: a naive exp overflows f32; the masked, shifted form stays finite,
        // also for agents no longer free whose scores exceed the free ones' maximum.
        let (n, m) = (4, 3);
        #[rustfmt::skip]
        let s: Vec<f32> = vec![
            9000.0, 9000.0, -8000.0,
            -5000.0, 100.0, 7000.0,
            0.0, 9500.0, 20.0,
            -9000.0, 3.0, 7000.0,
        ];
        let tape = Tape::<f32>::new();
        let v = tape.var(Tensor::new(s.clone(), &[1, n, m]).unwrap());
        let sigma = [1, 0, 2];
        let (lp, h) = log_prob_and_entropy(v, &sigma).unwrap();
        let grads = tape.backward(lp.add(h).unwrap().sum_all()).unwrap();
        let g = grads.get(v).unwrap();
        assert!(g.data().iter().all(|x| x.is_finite()), "gradient {:?}", g.data());
        let host: Vec<f64> = s.iter().map(|&x| x as f64).collect();
        let want = log_prob_host(&host, 1, n, m, &sigma).unwrap()[0];
        assert!((lp.value().data()[0] as f64 - want).abs() < 1e-2, "{:?} vs {want}", lp.value().data());
        assert!(h.value().data()[0].is_finite());
    }

    /// A small f64 scorer and its store.
    fn scorer_f64(set: PairFeatureSet, prior: f64, seed: u64) -> (ParamStore<f64>, AssignmentScorer) {
        let mut store = ParamStore::<f64>::new();
        let mut r = nn::init_rng(seed);
        let config = ScorerConfig { features: set, hidden: vec![6, 5], distance_prior: prior };
        let scorer = AssignmentScorer::new(&mut store.scope("assign", &mut r), config).unwrap();
        (store, scorer)
    }

    fn random_positions(r: &mut ChaCha8Rng, count: usize) -> Vec<[f64; 3]> {
        (0..count).map(|_| [r.random_range(-3.0..3.0), r.random_range(-3.0..3.0), r.random_range(0.0..2.0)]).collect()
    }

    #[test]
    fn the_log_prob_gradient_reaches_the_scorer_parameters() {
        for (n, m) in [(3, 2), (2, 3), (3, 3)] {
            let b = 3;
            let mut r = rng(4);
            let (agents, objects) = (random_positions(&mut r, b * n), random_positions(&mut r, b * m));
            let x = PairFeatures::new(PairFeatureSet::DistanceHeight, b, &agents, &objects, [0.0, 0.0, -1.0]).unwrap();
            let (store, scorer) = scorer_f64(PairFeatureSet::DistanceHeight, 0.5, 5);
            let names: Vec<String> = store.names().to_vec();
            assert_eq!(
                names,
                [
                    "assign.mlp.0.weight",
                    "assign.mlp.0.bias",
                    "assign.mlp.1.weight",
                    "assign.mlp.1.bias",
                    "assign.mlp.2.weight",
                    "assign.mlp.2.bias"
                ]
            );
            let mut pl = PlackettLuceAssigner::new(n, m);
            let tape = Tape::<f64>::new();
            let s = scorer.scores(&store.bind(&tape), &x).unwrap().value();
            assert_eq!(s.shape(), &[b, n, m]);
            let mut sigma = vec![0; b * m];
            pl.sample(s.data(), b, n, m, &mut rng(6), &mut sigma).unwrap();
            let params: Vec<Tensor<f64>> = store.values().to_vec();
            let report = check_gradients(
                |tape, v| {
                    let p = Bound::from_vars(v.to_vec());
                    let s = scorer.scores(&p, &x).expect("scores");
                    let (lp, h) = log_prob_and_entropy(s, &sigma).expect("log-prob");
                    tape.cat(&[lp, h], 0)
                },
                &params,
            )
            .unwrap();
            assert_eq!(report.checked, store.num_elements());
            // Every parameter tensor receives a nonzero gradient of the log-probability.
            let tape = Tape::<f64>::new();
            let p = store.bind(&tape);
            let lp = log_prob(scorer.scores(&p, &x).unwrap(), &sigma).unwrap();
            let grads = p.grads(&tape.backward(lp.sum_all()).unwrap());
            for (name, g) in names.iter().zip(&grads) {
                assert!(g.data().iter().any(|&v| v != 0.0), "{n} x {m}: no gradient reaches {name}");
            }
        }
    }

    /// Rotates `p` by `angle` about the unit axis `k` (Rodrigues) and adds `t`.
    fn move_point(p: [f64; 3], k: [f64; 3], angle: f64, t: [f64; 3]) -> [f64; 3] {
        let (s, c) = angle.sin_cos();
        let dot = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
        let cross = [k[1] * p[2] - k[2] * p[1], k[2] * p[0] - k[0] * p[2], k[0] * p[1] - k[1] * p[0]];
        std::array::from_fn(|a| p[a] * c + cross[a] * s + k[a] * dot * (1.0 - c) + t[a])
    }

    /// Scores (f32 network), a seeded draw and the most likely assignment of a batch.
    fn scores_and_assignments(
        store: &ParamStore<f32>,
        scorer: &AssignmentScorer,
        x: &PairFeatures,
    ) -> (Vec<f32>, Vec<usize>, Vec<usize>) {
        let (b, n, m) = (x.batch, x.agents, x.objects);
        let tape = Tape::<f32>::new();
        let s = scorer.scores(&store.bind(&tape), x).unwrap().value().to_vec();
        let mut pl = PlackettLuceAssigner::new(n, m);
        let (mut drawn, mut best) = (vec![0; b * m], vec![0; b * m]);
        pl.sample(&s, b, n, m, &mut rng(11), &mut drawn).unwrap();
        pl.most_likely(&s, b, n, m, &mut best).unwrap();
        (s, drawn, best)
    }

    #[test]
    fn scores_and_assignments_are_invariant_under_rotations_about_gravity_and_translations() {
        let b = 32;
        let tilted = {
            let g: [f64; 3] = [0.3, -0.4, -0.8];
            let norm = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            g.map(|x| x / norm)
        };
        for (set, gravity) in [
            (PairFeatureSet::DistanceHeight, [0.0, 0.0, -1.0]),
            (PairFeatureSet::DistanceHeight, tilted),
            (PairFeatureSet::Distance, [0.0, 0.0, -1.0]),
        ] {
            for (n, m) in [(3, 3), (4, 2), (2, 4)] {
                let mut r = rng(7);
                let (agents, objects) = (random_positions(&mut r, b * n), random_positions(&mut r, b * m));
                let mut store = ParamStore::<f32>::new();
                let config = ScorerConfig { features: set, hidden: vec![16, 16], distance_prior: 0.3 };
                let scorer = AssignmentScorer::new(&mut store.scope("assign", &mut nn::init_rng(8)), config).unwrap();
                let x = PairFeatures::new(set, b, &agents, &objects, gravity).unwrap();
                let (s, drawn, best) = scores_and_assignments(&store, &scorer, &x);
                check_assignment(&drawn, b, n, m).unwrap();
                check_assignment(&best, b, n, m).unwrap();
                let (angle, t) = (r.random_range(-3.0..3.0), [1.7, -4.2, 0.9]);
                let g = gravity;
                let moved =
                    |p: &[[f64; 3]]| -> Vec<[f64; 3]> { p.iter().map(|&q| move_point(q, g, angle, t)).collect() };
                let y = PairFeatures::new(set, b, &moved(&agents), &moved(&objects), gravity).unwrap();
                let (s2, drawn2, best2) = scores_and_assignments(&store, &scorer, &y);
                let worst = s.iter().zip(&s2).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(worst < 1e-4, "{set:?}, {n} x {m}: scores move by {worst}");
                assert_eq!(drawn, drawn2, "{set:?}, {n} x {m}: the draw of the same seed changed");
                assert_eq!(best, best2, "{set:?}, {n} x {m}: the most likely assignment changed");
                if set == PairFeatureSet::Distance {
                    // Distances alone are invariant under any rotation, e.g. about a horizontal axis.
                    let k = [1.0, 0.0, 0.0];
                    let tilt =
                        |p: &[[f64; 3]]| -> Vec<[f64; 3]> { p.iter().map(|&q| move_point(q, k, 1.1, t)).collect() };
                    let z = PairFeatures::new(set, b, &tilt(&agents), &tilt(&objects), gravity).unwrap();
                    let (s3, _, _) = scores_and_assignments(&store, &scorer, &z);
                    assert!(s.iter().zip(&s3).all(|(a, b)| (a - b).abs() < 1e-4));
                }
            }
        }
    }

    #[test]
    fn a_seed_fixes_the_draw_and_different_seeds_differ() {
        let (b, n, m) = (64, 4, 4);
        let s = random_scores(&mut rng(9), b * n * m, 1.0);
        let mut pl = PlackettLuceAssigner::new(n, m);
        let draw = |pl: &mut PlackettLuceAssigner, seed: u64| {
            let mut out = vec![0; b * m];
            pl.sample(&s, b, n, m, &mut rng(seed), &mut out).unwrap();
            out
        };
        let first = draw(&mut pl, 7);
        assert_eq!(first, draw(&mut pl, 7), "same seed, same draw");
        assert_eq!(first, draw(&mut PlackettLuceAssigner::new(5, 6), 7), "the scratch does not matter");
        let other = draw(&mut pl, 8);
        assert_ne!(first, other, "different seeds draw the same assignment in all {b} scenes");
        check_assignment(&other, b, n, m).unwrap();
    }

    #[test]
    fn sharp_distance_scores_recover_greedy_and_hungarian() {
        // s = -β d with β large: sampling is Algorithm 1, the most likely assignment the
        // minimal-total-distance one.
        let (b, n, m) = (40, 4, 3);
        let mut r = rng(10);
        let (agents, objects) = (random_positions(&mut r, b * n), random_positions(&mut r, b * m));
        let x = PairFeatures::new(PairFeatureSet::Distance, b, &agents, &objects, [0.0, 0.0, -1.0]).unwrap();
        let s: Vec<f64> = x.distances.iter().map(|d| -1e4 * d).collect();
        let mut pl = PlackettLuceAssigner::new(n, m);
        let (mut drawn, mut best) = (vec![0; b * m], vec![0; b * m]);
        pl.sample(&s, b, n, m, &mut rng(0), &mut drawn).unwrap();
        pl.most_likely(&s, b, n, m, &mut best).unwrap();
        let mut assigner = Assigner::new(n, m);
        for scene in 0..b {
            let d = &x.distances[scene * n * m..(scene + 1) * n * m];
            let mut want = vec![0; m];
            assigner.assign(AssignmentMethod::Greedy, d, n, m, &mut want, &mut rng(0));
            assert_eq!(&drawn[scene * m..(scene + 1) * m], want.as_slice(), "scene {scene}: greedy");
            assigner.assign(AssignmentMethod::Hungarian, d, n, m, &mut want, &mut rng(0));
            assert_eq!(&best[scene * m..(scene + 1) * m], want.as_slice(), "scene {scene}: Hungarian");
        }
    }

    #[test]
    fn the_most_likely_assignment_maximises_the_total_score() {
        let mut r = rng(12);
        for (n, m) in [(1, 1), (3, 2), (2, 3), (4, 4), (3, 4)] {
            let s = random_scores(&mut r, n * m, 2.0);
            let mut best = vec![0; m];
            PlackettLuceAssigner::new(n, m).most_likely(&s, 1, n, m, &mut best).unwrap();
            let total = |a: &[usize]| -> f64 { (0..n.min(m)).map(|j| s[a[j] * m + j]).sum() };
            let top = all_assignments(n, m).iter().map(|a| total(a)).fold(f64::NEG_INFINITY, f64::max);
            check_assignment(&best, 1, n, m).unwrap();
            assert!((total(&best) - top).abs() < 1e-12, "{n} x {m}: {} vs {top}", total(&best));
        }
    }

    #[test]
    fn bad_inputs_are_errors_that_name_the_value() {
        let err = |r: Result<()>| r.unwrap_err().to_string();
        let s = vec![0.0f64; 2 * 3 * 2];
        let mut pl = PlackettLuceAssigner::new(3, 2);
        let mut out = vec![0; 4];
        assert!(err(pl.sample(&s[..11], 2, 3, 2, &mut rng(0), &mut out)).contains("11 scores"));
        assert!(err(pl.sample(&s, 2, 3, 2, &mut rng(0), &mut out[..3])).contains("3 outputs"));
        assert!(err(pl.sample(&[0.0; 12], 1, 4, 3, &mut rng(0), &mut [0; 3])).contains("at most 3 x 2"));
        let mut nan = s.clone();
        nan[7] = f64::NAN;
        assert!(err(pl.most_likely(&nan, 2, 3, 2, &mut out)).contains("scene 1, agent 0, object 1"));
        assert!(err(check_assignment(&[0, 0], 1, 3, 2)).contains("object 1 to agent 0"));
        assert!(err(check_assignment(&[0, 3], 1, 3, 2)).contains("object 1 to agent 3"));
        assert!(err(check_assignment(&[1, UNASSIGNED], 1, 3, 2)).contains("object 1 to unassigned"));
        assert!(err(check_assignment(&[1, 0, 2], 1, 2, 3)).contains("object 2 to agent 2"));
        check_assignment(&[1, 0, UNASSIGNED], 1, 2, 3).unwrap();
        let tape = Tape::<f64>::new();
        let flat = tape.constant(Tensor::zeros(&[6]));
        assert!(log_prob(flat, &[0]).unwrap_err().to_string().contains("[6]"));
        let v = tape.constant(Tensor::zeros(&[1, 3, 2]));
        assert!(log_prob(v, &[2, 2]).unwrap_err().to_string().contains("object 1 to agent 2"));
        let one = [[0.0; 3]];
        let down = [0.0, 0.0, -1.0];
        let pf = |b, a: &[[f64; 3]], o: &[[f64; 3]], g| PairFeatures::new(PairFeatureSet::Distance, b, a, o, g);
        assert!(pf(2, &one, &one, down).unwrap_err().to_string().contains("2 scenes"));
        assert!(pf(1, &one, &one, [0.0, 0.0, -2.0]).unwrap_err().to_string().contains("not a unit vector"));
        assert!(pf(1, &[[f64::INFINITY, 0.0, 0.0]], &one, down).unwrap_err().to_string().contains("inf"));
        assert!(
            PairFeatures::from_entities(PairFeatureSet::Distance, &[[0.0; 3]; 6], 3, &[0, 1], &[3], down)
                .unwrap_err()
                .to_string()
                .contains("entity 3")
        );
        let mut store = ParamStore::<f64>::new();
        let mut r = nn::init_rng(0);
        let bad = ScorerConfig { distance_prior: -1.0, ..ScorerConfig::default() };
        assert!(AssignmentScorer::new(&mut store.scope("a", &mut r), bad).unwrap_err().to_string().contains("-1"));
        let bad = ScorerConfig { hidden: vec![4, 0], ..ScorerConfig::default() };
        assert!(AssignmentScorer::new(&mut store.scope("b", &mut r), bad).unwrap_err().to_string().contains("[4, 0]"));
        let (store, scorer) = scorer_f64(PairFeatureSet::DistanceHeight, 0.0, 1);
        let x = pf(1, &one, &one, down).unwrap();
        let tape = Tape::<f64>::new();
        assert!(scorer.scores(&store.bind(&tape), &x).unwrap_err().to_string().contains("Distance"));
        assert!(PairFeatureSet::parse("height").unwrap_err().to_string().contains("height"));
    }

    #[test]
    fn from_entities_picks_the_agent_and_object_rows_of_each_scene() {
        // Two scenes of 4 entities: agents 0 and 1, objects 3 and 2.
        let pos: Vec<[f64; 3]> = (0..8).map(|e| [e as f64, 0.0, 0.5 * e as f64]).collect();
        let down = [0.0, 0.0, -1.0];
        let x = PairFeatures::from_entities(PairFeatureSet::DistanceHeight, &pos, 4, &[0, 1], &[3, 2], down).unwrap();
        assert_eq!((x.batch, x.agents, x.objects), (2, 2, 2));
        let d = |a: f64, o: f64| ((o - a).powi(2) * 1.25).sqrt();
        // Scene 1, agent 1 (entity 5), object 0 (entity 7): distance, height 0.5 * 2.
        let row = (4 + 2) * 2;
        assert!((x.values[row] - d(5.0, 7.0)).abs() < 1e-12 && (x.values[row + 1] - 1.0).abs() < 1e-12);
        assert!((x.distances[4 + 2] - d(5.0, 7.0)).abs() < 1e-12);
    }
}
