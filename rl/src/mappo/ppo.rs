//! The PPO loss of one team on one minibatch of whole unrolls (MEBEN.md section 6; the
//! reference release's Brax PPO loss), one function read top to bottom, as Brax's
//! `compute_ppo_loss`: [`loss`] takes the model, its parameters on a tape, a normalised
//! [`Minibatch`], and returns the loss on the tape and its [`LossStats`]:
//!
//! 1. **forward**: the policy and value of the `T M` transitions on the tape, with the task
//!    assignment they were acted on when the minibatch carries it (a stochastic assignment);
//!    the rows that only bootstrap the returns (the `M` states after the unrolls, the final
//!    observations of truncated transitions) in a no-grad pass: their values are constants
//!    of the loss, so their share of the backward pass would be products with zero gradients
//!    (1/6 less backward work at the reference's `T = 5`); they draw their own assignment
//!    (they only give values, and the default critic reads no assignment; one that reads
//!    the assignment held into each step, `assign_critic=held`, is given it,
//!    [`Minibatch::held_assignment`]);
//! 2. **GAE** from those values, per minibatch under the current critic as Brax's PPO does
//!    ([`crate::mappo::gae`]): advantages `A` and value targets, held constant;
//! 3. **log-probabilities and entropy** of the taken actions: `log pi(u | s)` of the
//!    pre-squash action `u` under the policy's Normal, summed over the team's agents (the Tanh
//!    Jacobian at `u` is the same for both policies and cancels in `rho`; with a learned
//!    task assignment, plus `ln π(σ | s)` of the stored assignment, the policy's other
//!    factor, and its entropy estimate joins the bonus's), and the bonus's
//!    entropy `H`, per [`EntropyKind`]: the reference release's Tanh-Normal estimate (Brax's
//!    `NormalTanhDistribution.entropy`: the Normal's entropy plus `ln |d tanh(x)/dx|` at one
//!    reparameterised sample `x = loc + std eps` per action dimension, the gradient flowing
//!    through `x`; `eps` is drawn from the minibatch's stream, for each agent of the team in
//!    turn a `[T M, dof]` block in row order) or the Normal part's entropy alone; either
//!    summed over the team's action dimensions and averaged over the transitions;
//! 4. **the loss**
//!
//!    `L = -mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A)) + c_v mean((V - v_target)^2)
//!         - c_H mean(H)`, with `rho = exp(log pi(u | s) - log pi_old(u | s))`; with a
//!    learned assignment the bonus is `c_H (H(u) + s H(sigma))`, `s` the configuration's
//!    `assignment_entropy_scale` (1 by default: `H` above); with
//!    `assignment_gradient = expected` the drawn `σ`'s factor stays in `rho` as a constant
//!    and the surrogate gains the exact expectation over every assignment `σ'` at the steps
//!    that draw, `(1 / T M) Σ_draws Σ_σ' π(σ' | s) (V(s, σ') - b(s))`, `V(s, σ')` the value of
//!    a critic that reads the held assignment and `b(s) = Σ_σ' π(σ' | s) V(s, σ')` (constants:
//!    [`expected_assignment_term`]); with `assignment_gradient = episode` the drawn `σ`'s
//!    factor stays in `rho` as a constant, and the trainer adds the draws' own surrogate,
//!    credited with their episodes' returns ([`episode_assignment_term`]);
//! 5. **statistics** ([`LossStats`]), in f64 from the same tensors.

use envs::layout::ObsSpec;
use models::distribution::{normal_entropy, normal_log_prob, std_from_scale, tanh_normal_entropy};
use models::{AgentPolicy, AssignmentTerms, Policy};
use nn::Bound;
use rand_chacha::ChaCha8Rng;
use tensor::{Tensor, Var};

use crate::error::Result;
use crate::mappo::config::{AssignmentGradient, EntropyKind};
use crate::mappo::episode_credit::EpisodeBatch;
use crate::mappo::gae::gae;
use crate::mappo::minibatch::Minibatch;
use crate::mappo::seeding::standard_normal;

/// The loss weights and return parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PpoParams {
    /// Clip `epsilon`.
    pub clip_epsilon: f64,
    /// Value loss weight `c_v`.
    pub value_coef: f64,
    /// Entropy weight `c_H`.
    pub entropy_coef: f64,
    /// Which entropy the bonus uses.
    pub entropy: EntropyKind,
    /// The weight `s` of a learned assignment's entropy in the bonus, relative to the
    /// action's ([`crate::TrainConfig::assignment_entropy_scale`]).
    pub assignment_entropy_scale: f64,
    /// How the policy gradient reaches a learned assignment's scorer
    /// ([`crate::TrainConfig::assignment_gradient`]).
    pub assignment_gradient: AssignmentGradient,
    /// Whether a value that reads the held assignment reads the drawn one at the steps that
    /// draw ([`crate::TrainConfig::assignment_value_at_draw`]).
    pub assignment_value_at_draw: bool,
    /// Discount.
    pub discount: f64,
    /// GAE lambda.
    pub gae_lambda: f64,
}

impl PpoParams {
    /// The loss parameters of a training configuration.
    pub fn from_config(c: &crate::TrainConfig) -> Self {
        Self {
            clip_epsilon: c.clip_epsilon,
            value_coef: c.value_coef,
            entropy_coef: c.entropy_coef,
            entropy: c.entropy,
            assignment_entropy_scale: c.assignment_entropy_scale,
            assignment_gradient: c.assignment_gradient,
            assignment_value_at_draw: c.assignment_value_at_draw,
            discount: c.discount,
            gae_lambda: c.gae_lambda,
        }
    }
}

/// Declares [`LossStats`] from one list of named statistics: the struct, the names in order,
/// the averaging over minibatches, and which of them the metrics file records (one column
/// per team, [`crate::app::metrics`]). A new statistic is one line here and its formula in
/// [`statistics`].
macro_rules! loss_statistics {
    (
        recorded { $( $(#[doc = $rdoc:literal])* $rec:ident, )* }
        unrecorded { $( $(#[doc = $udoc:literal])* $unrec:ident, )* }
    ) => {
        /// Diagnostics of one loss evaluation (and, summed and scaled, their means over an
        /// iteration's minibatches).
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub struct LossStats {
            $( $(#[doc = $rdoc])* pub $rec: f64, )*
            $( $(#[doc = $udoc])* pub $unrec: f64, )*
        }

        impl LossStats {
            /// The statistics the metrics file records, in column order (suffixed `_t0`,
            /// `_t1` per team).
            pub const RECORDED: &'static [&'static str] = &[$(stringify!($rec)),*];

            /// Every statistic with its name: the recorded ones first, in column order.
            pub fn named(&self) -> Vec<(&'static str, f64)> {
                vec![$((stringify!($rec), self.$rec),)* $((stringify!($unrec), self.$unrec),)*]
            }

            /// The values of [`LossStats::RECORDED`], in that order.
            pub fn recorded(&self) -> Vec<f64> {
                vec![$(self.$rec),*]
            }

            /// Adds `other`, statistic by statistic (the sum over minibatches).
            pub fn add(&mut self, other: &LossStats) {
                $( self.$rec += other.$rec; )*
                $( self.$unrec += other.$unrec; )*
            }

            /// Every statistic times `s` (the sum over minibatches to their mean).
            pub fn scaled(&self, s: f64) -> LossStats {
                LossStats { $( $rec: self.$rec * s, )* $( $unrec: self.$unrec * s, )* }
            }
        }
    };
}

loss_statistics! {
    recorded {
        /// The clipped surrogate term `-mean(min(rho A, clip(rho) A))`.
        policy_loss,
        /// `mean((V - v_target)^2)` (before the weight).
        value_loss,
        /// Mean entropy of the bonus ([`EntropyKind`]), summed over the team's action
        /// dimensions.
        entropy,
        /// `mean((rho - 1) - ln rho)` (an estimate of KL(old, new)).
        approx_kl,
        /// Fraction of transitions with `|rho - 1| > epsilon`.
        clip_fraction,
        /// `1 - Var(v_target - V) / Var(v_target)`.
        explained_variance,
    }
    unrecorded {
        /// The total loss `L`.
        loss,
        /// Mean ratio `rho`.
        mean_ratio,
        /// Mean advantage.
        mean_advantage,
    }
}

/// The PPO loss of the team whose `model` has parameters `p` on the normalised minibatch
/// `mb` (module docs, steps 1 to 5), and its statistics; the Tanh-Normal entropy estimate
/// draws its samples from `entropy_noise`. The loss is on `p`'s tape, ready for backward.
pub fn loss<'t>(
    model: &mut dyn Policy,
    p: &Bound<'t, f32>,
    mb: &Minibatch,
    hp: &PpoParams,
    entropy_noise: &mut ChaCha8Rng,
) -> Result<(Var<'t, f32>, LossStats)> {
    let tape = p.tape();
    let n = mb.transitions();
    // 1. Forward: the transitions on the tape, the bootstrap rows without it.
    let fwd = forward(model, p, mb, hp.assignment_value_at_draw)?;
    // 2. GAE from the values of every row (constants of the loss).
    // (On a device the values come back in one explicit transfer.)
    let values: Vec<f32> = fwd.value.value().to_host()?.data().iter().chain(&fwd.bootstrap).copied().collect();
    let (advantages, targets) = gae(mb, &values, hp.discount, hp.gae_lambda);
    // 3. log pi(u | s) of the taken actions and the bonus's entropy.
    let (mut logp, mut entropy) = log_prob_and_entropy(&fwd.policy, mb, model.spec(), hp.entropy, entropy_noise)?;
    let mut bonus = entropy;
    // A learned task assignment is the policy's other factor: its log-probability joins the
    // action's (the ratio covers both) and its entropy estimate the bonus, weighted by s:
    // H = H(u) + H(sigma), the bonus H(u) + s H(sigma) (the same tensor when s = 1).
    // Held for k steps, the assignment is the policy's factor only where it was drawn: the
    // terms of the held steps are masked out, and H(sigma) is averaged over every transition.
    let mut expected = None;
    if let Some(mut a) = fwd.assignment {
        if !mb.assignment_drawn.is_empty() {
            let drawn: Vec<f32> = mb.assignment_drawn.iter().map(|&d| if d { 1.0 } else { 0.0 }).collect();
            let mask = tape.constant(Tensor::new(drawn, &[n])?);
            a.log_prob = a.log_prob.mul(mask)?;
            a.entropy = a.entropy.mul(mask)?;
        }
        // The expected gradient: the drawn σ's factor stays in the ratio without a gradient,
        // and the scorer learns from the expectation over every σ' instead.
        logp = match hp.assignment_gradient {
            AssignmentGradient::Sampled => logp.add(a.log_prob)?,
            AssignmentGradient::Expected => {
                expected = Some(expected_assignment_term(model, p, mb)?);
                logp.add(a.log_prob.detach())?
            }
            // The draw's credit is its episode's return, a term of its own
            // ([`episode_assignment_term`], added by the trainer).
            AssignmentGradient::Episode => logp.add(a.log_prob.detach())?,
        };
        let assignment_entropy = a.entropy.mean_all()?;
        let action_entropy = entropy;
        entropy = action_entropy.add(assignment_entropy)?;
        bonus = if hp.assignment_entropy_scale == 1.0 {
            entropy
        } else {
            action_entropy.add(assignment_entropy.scale(hp.assignment_entropy_scale))?
        };
    }
    let t = Terms {
        logp,
        entropy,
        bonus,
        logp_old: tape.constant(Tensor::new(mb.logp_old.clone(), &[n])?),
        advantages: tape.constant(Tensor::new(advantages, &[n])?),
        value: fwd.value,
        value_target: tape.constant(Tensor::new(targets, &[n])?),
    };
    // 4. L = -mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A)) + c_v mean((V - v_target)^2)
    //        - c_H (H(u) + s H(sigma)).
    let value_loss = t.value.sub(t.value_target)?.square().mean_all()?;
    let ratio = t.logp.sub(t.logp_old)?.exp();
    let mut policy_loss = clipped_surrogate(ratio, t.advantages, hp.clip_epsilon)?;
    if let Some(e) = expected {
        policy_loss = policy_loss.sub(e)?;
    }
    let total = policy_loss.add(value_loss.scale(hp.value_coef))?.sub(t.bonus.scale(hp.entropy_coef))?;
    // 5. Statistics.
    let stats = statistics(&t, [total, policy_loss, value_loss, ratio], hp)?;
    Ok((total, stats))
}

/// The expected assignment term of step 4 (`assignment_gradient = expected`) on the tape of
/// `p`: over the transitions of `mb` that drew their assignment (`D`),
///
/// `(1 / T M) Σ_{t ∈ D} Σ_σ' π(σ' | s_t) (V(s_t, σ') - b(s_t))`,  `b(s) = Σ_σ' π(σ' | s) V(s, σ')`,
///
/// `σ'` over the model's support ([`Policy::learned_assignment_support`]), `V(s, σ')` the
/// value with `σ'` held ([`Policy::forward_held`]) and `V` and `b` constants, so that its
/// gradient is `(1 / T M) Σ_t Σ_σ' ∇π(σ' | s_t) V(s_t, σ')`, the policy gradient of the draw
/// summed over every assignment instead of sampled (no sampling noise in `σ`; `b` changes
/// only its value, which is 0 at the current parameters, not its gradient). `V(s_t, σ')` is
/// read at a drawing step, where the critic is trained without `σ` (it drew there): it
/// extrapolates from the next steps, which hold `σ`. The `K |D|` rows (`K` the support's
/// size) go through the model in one forward pass. 0 (a constant) where nothing drew.
pub fn expected_assignment_term<'t>(
    model: &mut dyn Policy,
    p: &Bound<'t, f32>,
    mb: &Minibatch,
) -> Result<Var<'t, f32>> {
    let tape = p.tape();
    let n = mb.transitions();
    let support = model.learned_assignment_support();
    let draws: Vec<usize> = if mb.assignment_drawn.is_empty() {
        (0..n).collect()
    } else {
        (0..n).filter(|&i| mb.assignment_drawn[i]).collect()
    };
    if support.is_empty() || draws.is_empty() {
        return Ok(tape.constant(Tensor::new(vec![0.0], &[1])?).sum_all());
    }
    let (k, d) = (support.len(), draws.len());
    // The drawing rows once per σ' (block `a` holds σ'_a), every one held.
    let mut rows = envs::layout::Observation::empty(mb.obs.nodes, mb.obs.agents);
    for &i in &draws {
        rows.push_rows(mb.obs_rows(i..i + 1));
    }
    let mut obs = envs::layout::Observation::empty(mb.obs.nodes, mb.obs.agents);
    let mut assignment = Vec::with_capacity(k * d * model.assignment_width());
    for sigma in &support {
        obs.push_rows(rows.rows());
        for _ in 0..d {
            assignment.extend_from_slice(sigma);
        }
    }
    let out = model.forward_held(p, &obs.rows(), &assignment, &vec![true; k * d])?;
    let terms = out.assignment_terms.ok_or_else(|| {
        models::ModelError::Input(format!("`{}` gave no learned assignment's log-probability", model.name()))
    })?;
    // `V(s_t, σ'_a)` and `π(σ'_a | s_t)` on the host (one transfer each), for the baseline.
    let values = out.team_value()?.value().to_host()?.to_vec();
    let probs: Vec<f32> = terms.log_prob.value().to_host()?.data().iter().map(|l| l.exp()).collect();
    let mut weight = vec![0.0f32; k * d];
    for t in 0..d {
        // The probabilities' mean of the values (divided by their sum, 1 up to rounding).
        let mass: f64 = (0..k).map(|a| f64::from(probs[a * d + t])).sum();
        let b: f64 = (0..k).map(|a| f64::from(probs[a * d + t]) * f64::from(values[a * d + t])).sum::<f64>() / mass;
        for a in 0..k {
            weight[a * d + t] = ((f64::from(values[a * d + t]) - b) / n as f64) as f32;
        }
    }
    let weight = tape.constant(Tensor::new(weight, &[k * d])?);
    Ok(terms.log_prob.exp().mul(weight)?.sum_all())
}

/// `ln π(σ_e | s_e)` of the draws `range` of `batch` (their normalised observations and
/// assignments) on the tape of `p`, `[|range|]`: the policy only, the assignment given.
pub fn assignment_log_prob<'t>(
    model: &mut dyn Policy,
    p: &Bound<'t, f32>,
    batch: &EpisodeBatch,
    range: std::ops::Range<usize>,
) -> Result<Var<'t, f32>> {
    let sigma = batch.sigma_of(range.clone());
    let out = model.forward(p, &batch.obs.rows().slice(range), Some(sigma), false)?;
    let terms = out.assignment_terms.ok_or_else(|| {
        models::ModelError::Input(format!("`{}` gave no learned assignment's log-probability", model.name()))
    })?;
    Ok(terms.log_prob)
}

/// The episode-credited assignment term (`assignment_gradient = episode`, module
/// [`crate::mappo::episode_credit`], step 4) of the draws `range` of `batch` on the tape of
/// `p`: `−(1 / |range|) Σ_e min(ρ_e A_e, clip(ρ_e, 1 − ε, 1 + ε) A_e)` with
/// `ρ_e = exp(ln π(σ_e | s_e) − ln π_old(σ_e | s_e))` and `ε` the clip. `None` for an empty
/// range.
pub fn episode_assignment_term<'t>(
    model: &mut dyn Policy,
    p: &Bound<'t, f32>,
    batch: &EpisodeBatch,
    range: std::ops::Range<usize>,
    clip_epsilon: f64,
) -> Result<Option<Var<'t, f32>>> {
    let d = range.len();
    if d == 0 {
        return Ok(None);
    }
    let tape = p.tape();
    let logp = assignment_log_prob(model, p, batch, range.clone())?;
    let logp_old = tape.constant(Tensor::new(batch.logp_old[range.clone()].to_vec(), &[d])?);
    let advantages = tape.constant(Tensor::new(batch.advantages[range].to_vec(), &[d])?);
    Ok(Some(clipped_surrogate(logp.sub(logp_old)?.exp(), advantages, clip_epsilon)?))
}

/// PPO's clipped surrogate, `-mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A))`, of the ratios
/// `ratio` and advantages `advantages` (the same shape).
fn clipped_surrogate<'t>(ratio: Var<'t, f32>, advantages: Var<'t, f32>, eps: f64) -> Result<Var<'t, f32>> {
    let unclipped = ratio.mul(advantages)?;
    let clipped = ratio.clamp(1.0 - eps, 1.0 + eps).mul(advantages)?;
    Ok(unclipped.minimum(clipped)?.mean_all()?.neg())
}

/// The model's outputs on one minibatch: the policy and value of the `T M` transitions on
/// the tape, and the values of the rows that only bootstrap the returns.
struct Forward<'t> {
    /// Per agent of the team, `loc` and `scale` `[T M, dof]`.
    policy: Vec<AgentPolicy<'t, f32>>,
    /// `V(s_t)` of the transitions, `[T M]`.
    value: Var<'t, f32>,
    /// Values of rows `T M ..`: the `M` states after the unrolls, then the final observations
    /// of truncated transitions (no gradient).
    bootstrap: Vec<f32>,
    /// A learned task assignment's log-probability and entropy estimate of the transitions'
    /// stored assignments, `[T M]` each (`None` for the other methods).
    assignment: Option<AssignmentTerms<'t, f32>>,
}

/// Step 1 (module docs): the transitions on the tape of `p`, with the task assignment they
/// were acted on when the minibatch carries it; the bootstrap rows in a no-grad pass. A
/// value that reads the held assignment reads the drawn one at the drawing steps too where
/// `value_at_draw` ([`Minibatch::held_assignment`]).
fn forward<'t>(model: &mut dyn Policy, p: &Bound<'t, f32>, mb: &Minibatch, value_at_draw: bool) -> Result<Forward<'t>> {
    let spec = model.spec();
    let (n, rows) = (mb.transitions(), mb.obs.batch);
    if rows <= n || mb.obs.nodes != spec.n_nodes || mb.obs.agents != spec.n_agents {
        return Err(models::ModelError::Input(format!(
            "{rows} observation rows of {} nodes and {} agents for {n} transitions of a scene of {} nodes and {} \
             agents (needs more rows)",
            mb.obs.nodes, mb.obs.agents, spec.n_nodes, spec.n_agents
        ))
        .into());
    }
    let assigned = if mb.assignment.is_empty() { None } else { Some(mb.assignment.as_slice()) };
    // A value that reads the assignment held into each step (`assign_critic=held`) is given
    // it for every row, the bootstrap rows too (their policy then scores it unused).
    let held = (model.value_reads_held_assignment() && assigned.is_some()).then(|| mb.held_assignment(value_at_draw));
    let out = match &held {
        Some(h) => model.forward_held(p, &mb.obs_rows(0..n), &mb.assignment, &h.transitions)?,
        None => model.forward(p, &mb.obs_rows(0..n), assigned, true)?,
    };
    let bootstrap = {
        let _no_grad = p.tape().no_grad();
        let boot = match &held {
            Some(h) => model.forward_held(p, &mb.obs_rows(n..rows), &h.bootstrap, &h.bootstrap_held)?,
            None => model.forward(p, &mb.obs_rows(n..rows), None, true)?,
        };
        boot.team_value()?.value().to_host()?.to_vec()
    };
    Ok(Forward { value: out.team_value()?, policy: out.agents, bootstrap, assignment: out.assignment_terms })
}

/// Step 3 (module docs): `log pi(u | s)` of the taken pre-squash actions summed over the
/// team's agents (laid out by `spec`), `[T M]`, and the bonus's entropy summed over the
/// action dimensions and averaged over the transitions (a scalar).
fn log_prob_and_entropy<'t>(
    policy: &[AgentPolicy<'t, f32>],
    mb: &Minibatch,
    spec: &ObsSpec,
    entropy_kind: EntropyKind,
    entropy_noise: &mut ChaCha8Rng,
) -> Result<(Var<'t, f32>, Var<'t, f32>)> {
    let n = mb.transitions();
    let na = mb.actions.len() / n.max(1);
    let mut logp: Option<Var<'t, f32>> = None;
    let mut entropy: Option<Var<'t, f32>> = None;
    for a in policy {
        let tape = a.loc.tape();
        let (off, dof) = (spec.agent_action_offset[a.agent], spec.agent_dof[a.agent]);
        let mut ua = Vec::with_capacity(n * dof);
        for row in mb.actions.chunks_exact(na) {
            ua.extend_from_slice(&row[off..off + dof]);
        }
        let ua = tape.constant(Tensor::new(ua, &[n, dof])?);
        let (loc, std) = (a.loc, std_from_scale(a.scale));
        let lp = normal_log_prob(ua, loc, std)?;
        let h = match entropy_kind {
            EntropyKind::Normal => normal_entropy(std)?,
            EntropyKind::TanhNormal => {
                let eps: Vec<f32> = (0..n * dof).map(|_| standard_normal(entropy_noise) as f32).collect();
                tanh_normal_entropy(loc, std, tape.constant(Tensor::new(eps, &[n, dof])?))?
            }
        };
        logp = Some(match logp {
            None => lp,
            Some(x) => x.add(lp)?,
        });
        entropy = Some(match entropy {
            None => h,
            Some(x) => x.add(h)?,
        });
    }
    let (Some(logp), Some(entropy)) = (logp, entropy) else {
        return Err(models::ModelError::Input("a minibatch of a team without agents".into()).into());
    };
    Ok((logp, entropy.mean_all()?))
}

/// The tensors the loss is made of (`n = T M` transitions).
struct Terms<'t> {
    /// `log pi(u | s)`, `[n]`.
    logp: Var<'t, f32>,
    /// The policy's entropy `H(u) + H(sigma)` (a scalar; the statistic).
    entropy: Var<'t, f32>,
    /// What the bonus weighs by `c_H`: `H(u) + s H(sigma)` (a scalar; `entropy` when `s = 1`
    /// or the assignment is not learned).
    bonus: Var<'t, f32>,
    /// `log pi_old(u | s)`, `[n]` (constant).
    logp_old: Var<'t, f32>,
    /// Advantages `A`, `[n]` (constant).
    advantages: Var<'t, f32>,
    /// `V(s)`, `[n]`.
    value: Var<'t, f32>,
    /// Value targets, `[n]` (constant).
    value_target: Var<'t, f32>,
}

/// Step 5 (module docs): the statistics, in f64, of the terms `t` and the loss's `[total,
/// policy loss, value loss, ratios]`.
fn statistics(
    t: &Terms<'_>,
    [total, policy_loss, value_loss, ratio]: [Var<'_, f32>; 4],
    hp: &PpoParams,
) -> Result<LossStats> {
    // Every term on the host in one transfer (none where they are there already).
    let terms =
        [ratio, t.logp, t.logp_old, t.advantages, t.value_target, t.value, total, policy_loss, value_loss, t.entropy];
    let all: Vec<Tensor<f32>> = terms.iter().map(|x| x.value()).collect();
    let host = tensor::to_host_all(&all)?;
    let f64s = |x: &Tensor<f32>| x.data().iter().map(|&v| v as f64).collect::<Vec<f64>>();
    let (ratio, logp, logp_old) = (f64s(&host[0]), f64s(&host[1]), f64s(&host[2]));
    let (adv, targets, value) = (f64s(&host[3]), f64s(&host[4]), f64s(&host[5]));
    let n = ratio.len() as f64;
    let var = |xs: &[f64]| {
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64
    };
    // From the log-ratio in f64: `rho - 1 - ln rho = expm1(d) - d`. (Through the f32 ratio it
    // was infinite whenever `rho` underflowed to 0, which a few far-off-policy samples do.)
    let approx_kl = logp
        .iter()
        .zip(&logp_old)
        .map(|(&l, &o)| {
            let d = l - o;
            d.exp_m1() - d
        })
        .sum::<f64>()
        / n;
    let var_t = var(&targets);
    let resid: Vec<f64> = targets.iter().zip(&value).map(|(t, v)| t - v).collect();
    let item = |x: &Tensor<f32>| -> Result<f64> { Ok(x.item()? as f64) };
    Ok(LossStats {
        loss: item(&host[6])?,
        policy_loss: item(&host[7])?,
        value_loss: item(&host[8])?,
        entropy: item(&host[9])?,
        approx_kl,
        clip_fraction: ratio.iter().filter(|&&x| (x - 1.0).abs() > hp.clip_epsilon).count() as f64 / n,
        explained_variance: if var_t > 0.0 { 1.0 - var(&resid) / var_t } else { 0.0 },
        mean_ratio: ratio.iter().sum::<f64>() / n,
        mean_advantage: adv.iter().sum::<f64>() / n,
    })
}
