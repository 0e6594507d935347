//! The PPO loss of one team on one minibatch of whole unrolls (MEBEN.md section 6; the
//! reference release's Brax PPO loss), in the steps the trainer takes in order:
//! [`forward`] (values of every state of the unrolls under the current critic, the policy of
//! the transitions), [`advantages`] (advantages and value targets by GAE from those values,
//! [`crate::mappo::gae`], held constant), [`LossTerms::new`] (log-probabilities and entropy of the
//! taken actions), [`ppo_loss`] (a short function of those tensors) and [`loss_stats`]:
//!
//! `L = -mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A)) + c_v mean((V - v_target)^2)
//!      - c_H mean(H)`,
//!
//! with `rho = exp(log pi(u | s) - log pi_old(u | s))`. The log-probabilities are those of
//! the pre-squash action `u` under the policy's Normal: the Tanh Jacobian at `u` is the same
//! for both policies and cancels in `rho`. `H` is, per [`EntropyKind`], the reference
//! release's Tanh-Normal estimate (Brax's `NormalTanhDistribution.entropy`: the Normal's
//! entropy plus `ln |d tanh(x)/dx|` at one reparameterised sample `x = loc + std eps` per
//! action dimension, the gradient flowing through `x`; `eps` is drawn from the minibatch's
//! stream, for each agent of the team in turn a `[T M, dof]` block in row order) or the
//! Normal part's entropy alone; either is summed over the team's action dimensions and
//! averaged over the transitions. The observation rows are
//! time-major: `T + 1` rows per unroll (the last is the state after the unroll), then one
//! row per truncated transition holding its final observation. Only the first `T M` rows
//! (the transitions) go through the model on the tape; the rest only bootstrap the returns
//! and go through it in a no-grad pass (same values, no backward work: 1/6 less backward at
//! the reference's `T = 5`). The transitions go through the model with the task assignment
//! they were acted on when the minibatch carries it (a stochastic assignment); the bootstrap
//! rows draw their own (they only give values, and the default critic reads no assignment).

use models::distribution::{normal_entropy, normal_log_prob, std_from_scale, tanh_normal_entropy};
use models::{AgentPolicy, Model, ObsRows, ObsSpec};
use nn::Bound;
use rand_chacha::ChaCha8Rng;
use tensor::{Tensor, Var};

use crate::error::Result;
use crate::mappo::config::EntropyKind;
use crate::mappo::gae::{Unrolls, gae};
use crate::mappo::rollout::NO_FINAL;
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
            discount: c.discount,
            gae_lambda: c.gae_lambda,
        }
    }
}

/// One team's minibatch: normalised observations and the behaviour data.
#[derive(Clone, Copy, Debug)]
pub struct Minibatch<'a> {
    /// Steps per unroll `T`.
    pub steps: usize,
    /// Unrolls `M`.
    pub unrolls: usize,
    /// Normalised observation rows `(T + 1) M + K` (K truncated transitions).
    pub obs: ObsRows<'a, f32>,
    /// `[T M, n_actions]` pre-squash actions of every agent (the scene's action layout).
    pub actions: &'a [f32],
    /// `[T M]` the team's behaviour log-probabilities.
    pub logp_old: &'a [f32],
    /// `[T M]` the team's rewards, scaled.
    pub rewards: &'a [f32],
    /// `[T M]`.
    pub terminated: &'a [bool],
    /// `[T M]`.
    pub truncated: &'a [bool],
    /// `[T M]`: for truncated transitions, the row of their final observation.
    pub final_row: &'a [u32],
    /// `[T M, width]` the task assignment each transition was acted on (empty: the model
    /// solves it again, the same for the deterministic methods).
    pub assignment: &'a [u32],
}

/// Diagnostics of one loss evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossStats {
    /// The total loss.
    pub loss: f64,
    /// The clipped surrogate term.
    pub policy_loss: f64,
    /// `mean((V - v_target)^2)` (before the weight).
    pub value_loss: f64,
    /// Mean entropy of the bonus ([`EntropyKind`]), summed over the team's action
    /// dimensions.
    pub entropy: f64,
    /// `mean((rho - 1) - ln rho)` (an estimate of KL(old, new)).
    pub approx_kl: f64,
    /// Fraction of transitions with `|rho - 1| > epsilon`.
    pub clip_fraction: f64,
    /// `1 - Var(v_target - V) / Var(v_target)`.
    pub explained_variance: f64,
    /// Mean ratio `rho`.
    pub mean_ratio: f64,
    /// Mean advantage.
    pub mean_advantage: f64,
}

/// The model's outputs on one minibatch: the policy and value of the `T M` transitions on
/// the tape, and the values of the rows that only bootstrap the returns.
pub struct Forward<'t> {
    /// Per agent of the team, `loc` and `scale` `[T M, dof]`.
    pub policy: Vec<AgentPolicy<'t, f32>>,
    /// `V(s_t)` of the transitions, `[T M]`.
    pub value: Var<'t, f32>,
    /// Values of rows `T M ..`: the `M` states after the unrolls, then the final observations
    /// of truncated transitions (no gradient).
    pub bootstrap: Vec<f32>,
}

/// Forward (module docs): the transitions on the tape of `p`, with the task assignment they
/// were acted on when the minibatch carries it; the bootstrap rows in a no-grad pass (their
/// values are constants of the loss, so their share of the backward pass would be products
/// with zero gradients).
pub fn forward<'t>(model: &mut Model, p: &Bound<'t, f32>, mb: &Minibatch<'_>) -> Result<Forward<'t>> {
    let spec = model.spec();
    let (n, rows) = (mb.steps * mb.unrolls, mb.obs.len());
    if rows <= n || mb.obs.nodes != spec.n_nodes || mb.obs.agents != spec.n_agents {
        return Err(models::ModelError::Input(format!(
            "{rows} observation rows of {} nodes and {} agents for {n} transitions of a scene of {} nodes and {} \
             agents (needs more rows)",
            mb.obs.nodes, mb.obs.agents, spec.n_nodes, spec.n_agents
        ))
        .into());
    }
    let assigned = if mb.assignment.is_empty() { None } else { Some(mb.assignment) };
    let out = model.forward_batch_with(p, &mb.obs.slice(0..n), assigned)?;
    let bootstrap = {
        let _no_grad = p.tape().no_grad();
        model.forward_batch(p, &mb.obs.slice(n..rows))?.team_value()?.value().to_vec()
    };
    Ok(Forward { value: out.team_value()?, policy: out.agents, bootstrap })
}

/// GAE per minibatch under the current critic, as Brax's PPO computes it ([`crate::mappo::gae`]):
/// `V(s_t)` of the transitions, `V(s_T)` after each unroll and `V(s_final)` of truncated
/// transitions from [`forward`]. Returns the advantages and value targets, `[T M]` each,
/// constants of the loss.
pub fn advantages(mb: &Minibatch<'_>, fwd: &Forward<'_>, hp: &PpoParams) -> (Vec<f32>, Vec<f32>) {
    let (t_len, m) = (mb.steps, mb.unrolls);
    let n = t_len * m;
    let values: Vec<f32> = fwd.value.value().data().iter().chain(&fwd.bootstrap).copied().collect();
    let final_values: Vec<f32> =
        (0..n).map(|i| if mb.final_row[i] != NO_FINAL { values[mb.final_row[i] as usize] } else { 0.0 }).collect();
    let u = Unrolls {
        steps: t_len,
        unrolls: m,
        rewards: mb.rewards,
        terminated: mb.terminated,
        truncated: mb.truncated,
        values: &values[..(t_len + 1) * m],
        final_values: &final_values,
    };
    gae(&u, hp.discount, hp.gae_lambda)
}

/// The tensors of the PPO loss on one minibatch (`n = T M` transitions).
pub struct LossTerms<'t> {
    /// `log pi(u | s)` of the taken pre-squash actions, summed over the team's agents, `[n]`.
    pub logp: Var<'t, f32>,
    /// `log pi_old(u | s)`, the behaviour policy's, `[n]` (constant).
    pub logp_old: Var<'t, f32>,
    /// Advantages `A`, `[n]` (constant).
    pub advantages: Var<'t, f32>,
    /// `V(s)`, `[n]`.
    pub value: Var<'t, f32>,
    /// Value targets, `[n]` (constant).
    pub value_target: Var<'t, f32>,
    /// The bonus's entropy ([`EntropyKind`]), summed over the action dimensions and averaged
    /// over the transitions (a scalar).
    pub entropy: Var<'t, f32>,
}

impl<'t> LossTerms<'t> {
    /// The terms from the model's outputs `fwd` on `mb` (agents laid out by `spec`), the
    /// advantages and value targets of [`advantages`]; the Tanh-Normal entropy estimate
    /// draws its samples from `entropy_noise` (module docs).
    pub fn new(
        fwd: &Forward<'t>,
        mb: &Minibatch<'_>,
        spec: &ObsSpec,
        (advantages, targets): (Vec<f32>, Vec<f32>),
        entropy_kind: EntropyKind,
        entropy_noise: &mut ChaCha8Rng,
    ) -> Result<Self> {
        let tape = fwd.value.tape();
        let n = mb.steps * mb.unrolls;
        let na = mb.actions.len() / n.max(1);
        let mut logp: Option<Var<'t, f32>> = None;
        let mut entropy: Option<Var<'t, f32>> = None;
        for a in &fwd.policy {
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
        Ok(Self {
            logp,
            entropy: entropy.mean_all()?,
            logp_old: tape.constant(Tensor::new(mb.logp_old.to_vec(), &[n])?),
            advantages: tape.constant(Tensor::new(advantages, &[n])?),
            value: fwd.value,
            value_target: tape.constant(Tensor::new(targets, &[n])?),
        })
    }
}

/// The PPO loss and its parts, on the tape.
pub struct PpoLoss<'t> {
    /// `L`.
    pub total: Var<'t, f32>,
    /// The clipped surrogate term `-mean(min(rho A, clip(rho) A))`.
    pub policy: Var<'t, f32>,
    /// `mean((V - v_target)^2)`.
    pub value: Var<'t, f32>,
    /// The ratios `rho`, `[n]`.
    pub ratio: Var<'t, f32>,
}

/// `L = -mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A)) + c_v mean((V - v_target)^2)
/// - c_H H` with `rho = exp(log pi - log pi_old)` (module docs).
pub fn ppo_loss<'t>(t: &LossTerms<'t>, hp: &PpoParams) -> Result<PpoLoss<'t>> {
    let value = t.value.sub(t.value_target)?.square().mean_all()?;
    let ratio = t.logp.sub(t.logp_old)?.exp();
    let eps = hp.clip_epsilon;
    let unclipped = ratio.mul(t.advantages)?;
    let clipped = ratio.clamp(1.0 - eps, 1.0 + eps).mul(t.advantages)?;
    let policy = unclipped.minimum(clipped)?.mean_all()?.neg();
    let total = policy.add(value.scale(hp.value_coef))?.sub(t.entropy.scale(hp.entropy_coef))?;
    Ok(PpoLoss { total, policy, value, ratio })
}

/// The diagnostics of a loss evaluation.
pub fn loss_stats(loss: &PpoLoss<'_>, t: &LossTerms<'_>, hp: &PpoParams) -> Result<LossStats> {
    let f64s = |x: Var<'_, f32>| x.value().data().iter().map(|&v| v as f64).collect::<Vec<f64>>();
    let (ratio, logp, logp_old) = (f64s(loss.ratio), f64s(t.logp), f64s(t.logp_old));
    let (adv, targets, value) = (f64s(t.advantages), f64s(t.value_target), f64s(t.value));
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
    let item = |x: Var<'_, f32>| -> Result<f64> { Ok(x.value().item()? as f64) };
    Ok(LossStats {
        loss: item(loss.total)?,
        policy_loss: item(loss.policy)?,
        value_loss: item(loss.value)?,
        entropy: item(t.entropy)?,
        approx_kl,
        clip_fraction: ratio.iter().filter(|&&x| (x - 1.0).abs() > hp.clip_epsilon).count() as f64 / n,
        explained_variance: if var_t > 0.0 { 1.0 - var(&resid) / var_t } else { 0.0 },
        mean_ratio: ratio.iter().sum::<f64>() / n,
        mean_advantage: adv.iter().sum::<f64>() / n,
    })
}
