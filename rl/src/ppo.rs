//! The PPO loss of one team on one minibatch of whole unrolls (MEBEN.md section 6; the
//! reference release's Brax PPO loss): values of every state of the unrolls under the
//! current critic, advantages and value targets by GAE from them ([`crate::gae`], held
//! constant), then
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

use envs::tasks::ObsSpec;
use models::distribution::{normal_entropy, normal_log_prob, std_from_scale, tanh_normal_entropy};
use models::{Model, ObsRows};
use nn::Bound;
use rand_chacha::ChaCha8Rng;
use tensor::{Tensor, Var};

use crate::config::EntropyKind;
use crate::error::Result;
use crate::gae::{Unrolls, gae};
use crate::seeding::standard_normal;

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

/// The loss on the tape of `p` and its diagnostics (module docs). `entropy_noise` supplies
/// the Tanh-Normal entropy estimate's samples (unused for [`EntropyKind::Normal`]).
pub fn ppo_loss<'t>(
    model: &mut Model,
    spec: &ObsSpec,
    p: &Bound<'t, f32>,
    mb: &Minibatch<'_>,
    hp: &PpoParams,
    entropy_noise: &mut ChaCha8Rng,
) -> Result<(Var<'t, f32>, LossStats)> {
    let tape = p.tape();
    let (t_len, m) = (mb.steps, mb.unrolls);
    let n = t_len * m;
    let rows = mb.obs.len();
    if rows <= n || mb.obs.nodes != spec.n_nodes || mb.obs.agents != spec.n_agents {
        return Err(models::ModelError::Input(format!(
            "{rows} observation rows of {} nodes and {} agents for {n} transitions of a scene of {} nodes and {} \
             agents (needs more rows)",
            mb.obs.nodes, mb.obs.agents, spec.n_nodes, spec.n_agents
        ))
        .into());
    }
    // The transitions on the tape; the rows that only bootstrap the returns (the state after
    // each unroll, final observations of truncated episodes) in a no-grad pass: their values
    // are constants of the loss, so their share of the backward pass would be products with
    // zero gradients.
    let assigned = if mb.assignment.is_empty() { None } else { Some(mb.assignment) };
    let out = model.forward_batch_with(p, &mb.obs.slice(0..n), assigned)?;
    let bootstrap = {
        let _no_grad = tape.no_grad();
        model.forward_batch(p, &mb.obs.slice(n..rows))?.team_value()?.value()
    };

    // GAE from the current critic, held constant.
    let values = out.team_value()?.value();
    let vals: Vec<f32> = values.data().iter().chain(bootstrap.data()).copied().collect();
    let final_values: Vec<f32> =
        (0..n).map(|i| if mb.final_row[i] != u32::MAX { vals[mb.final_row[i] as usize] } else { 0.0 }).collect();
    let u = Unrolls {
        steps: t_len,
        unrolls: m,
        rewards: mb.rewards,
        terminated: mb.terminated,
        truncated: mb.truncated,
        values: &vals[..(t_len + 1) * m],
        final_values: &final_values,
    };
    let (adv, targets) = gae(&u, hp.discount, hp.gae_lambda);

    // Value loss on the T M transitions.
    let v = out.team_value()?;
    let mean_advantage = adv.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
    let var = |xs: &mut dyn Iterator<Item = f64>| {
        let xs: Vec<f64> = xs.collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64
    };
    let var_t = var(&mut targets.iter().map(|&x| x as f64));
    let target_values: Vec<f64> = targets.iter().map(|&x| x as f64).collect();
    let target = tape.constant(Tensor::new(targets, &[n])?);
    let value_loss = v.sub(target)?.square().mean_all()?;

    // Log-probabilities and entropy of the team's agents.
    let na = mb.actions.len() / n.max(1);
    let mut logp: Option<Var<'t, f32>> = None;
    let mut entropy: Option<Var<'t, f32>> = None;
    for a in &out.agents {
        let (off, dof) = (spec.agent_action_offset[a.agent], spec.agent_dof[a.agent]);
        let mut ua = Vec::with_capacity(n * dof);
        for row in mb.actions.chunks_exact(na) {
            ua.extend_from_slice(&row[off..off + dof]);
        }
        let ua = tape.constant(Tensor::new(ua, &[n, dof])?);
        let (loc, std) = (a.loc, std_from_scale(a.scale));
        let lp = normal_log_prob(ua, loc, std)?;
        let h = match hp.entropy {
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
    let (logp, entropy) = match (logp, entropy) {
        (Some(l), Some(h)) => (l, h.mean_all()?),
        _ => unreachable!("a model acts for at least one agent"),
    };
    let logp_old = tape.constant(Tensor::new(mb.logp_old.to_vec(), &[n])?);
    let ratio = logp.sub(logp_old)?.exp();
    let adv_t = tape.constant(Tensor::new(adv, &[n])?);
    let eps = hp.clip_epsilon;
    let s1 = ratio.mul(adv_t)?;
    let s2 = ratio.clamp(1.0 - eps, 1.0 + eps).mul(adv_t)?;
    let policy_loss = s1.minimum(s2)?.mean_all()?.neg();
    let loss = policy_loss.add(value_loss.scale(hp.value_coef))?.sub(entropy.scale(hp.entropy_coef))?;

    // Diagnostics.
    let r = ratio.value();
    let rs = r.data();
    // From the log-ratio in f64: `rho - 1 - ln rho = expm1(d) - d`. (Through the f32 ratio it
    // was infinite whenever `rho` underflowed to 0, which a few far-off-policy samples do.)
    let lp = logp.value();
    let approx_kl = lp
        .data()
        .iter()
        .zip(mb.logp_old)
        .map(|(&l, &o)| {
            let d = l as f64 - o as f64;
            d.exp_m1() - d
        })
        .sum::<f64>()
        / n as f64;
    let clip_fraction = rs.iter().filter(|&&x| ((x as f64) - 1.0).abs() > eps).count() as f64 / n as f64;
    let vv = v.value();
    let resid: Vec<f64> = target_values.iter().zip(vv.data()).map(|(&t, &v)| t - v as f64).collect();
    let explained_variance = if var_t > 0.0 { 1.0 - var(&mut resid.into_iter()) / var_t } else { 0.0 };
    let item = |x: Var<'t, f32>| -> Result<f64> { Ok(x.value().item()? as f64) };
    let stats = LossStats {
        loss: item(loss)?,
        policy_loss: item(policy_loss)?,
        value_loss: item(value_loss)?,
        entropy: item(entropy)?,
        approx_kl,
        clip_fraction,
        explained_variance,
        mean_ratio: rs.iter().map(|&x| x as f64).sum::<f64>() / n as f64,
        mean_advantage,
    };
    Ok((loss, stats))
}
