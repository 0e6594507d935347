//! A team's act step, the one place where a policy chooses actions: normalise the raw
//! observation rows -> the policy forward without gradients ([`Policy::forward`] with `value = false`,
//! the value network skipped) on the device the parameters are on -> sample
//! `u ~ Normal(loc, std)` (or take `u = loc`) -> the log-probability of `u`, both on the
//! host; the action sent to the environment is `tanh(u)`. Training (collection),
//! evaluation, rendering, the Python policy and the closed-loop test all act
//! through an [`Actor`], which holds the team's action-noise streams (one per agent,
//! MEBEN.md section 8) and its scratch. A policy with a learned task assignment
//! (`assignment=learned`) draws it in its forward pass; its log-probability `ln π(σ | s)` is
//! added to the action's (the policy factorises as `π(a, σ | s) = π(σ | s) π(a | s, σ)`). A
//! drawn assignment held for `k` steps or an episode ([`AssignmentHold`]) is given back to the
//! policy at the steps between draws, and its log-probability added only where it is drawn.

use envs::layout::{ObsRows, Observation};
use models::distribution::{normal_log_prob, std_from_scale};
use models::{AgentPolicy, Policy};
use nn::ParamStore;
use rand_chacha::ChaCha8Rng;
use tensor::{Tape, Tensor};

use crate::error::{Result, RlError};
use crate::mappo::assignment_hold::AssignmentHold;
use crate::mappo::normalizer::ObsNormalizer;
use crate::mappo::seeding::standard_normal;

/// How actions are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActMode {
    /// `u ~ Normal(loc, std)`, action `tanh(u)`.
    Sample,
    /// `u = loc`, action `tanh(loc)`.
    Mean,
}

/// What every team chose at one step for `B` environments: each team writes its own agents'
/// columns of the joint action and its own log-probabilities and task assignment.
#[derive(Clone, Debug)]
pub struct JointAction {
    /// Actions per environment (the scene's action layout).
    pub n_actions: usize,
    /// `[B, n_actions]` actions `tanh(u)`, what the environments step with.
    pub actions: Vec<f32>,
    /// `[B, n_actions]` pre-squash actions `u`, what the update evaluates.
    pub pre_squash: Vec<f32>,
    /// Per team, `[B]` its log-probability of `u` under the Normal, summed over its agents,
    /// plus that of a learned task assignment (0 when acting with [`ActMode::Mean`]).
    pub logp: Vec<Vec<f32>>,
    /// Per team, the task assignment it acted on (`[B * Model::assignment_width]`).
    pub assignment: Vec<Vec<u32>>,
    /// Per team, `[B]` whether the environment's task assignment was drawn at this step
    /// (true everywhere unless a drawn one is held: [`AssignmentHold`]).
    pub assignment_drawn: Vec<Vec<bool>>,
}

impl JointAction {
    /// Zeros for `envs` environments of `n_actions` actions and `teams` teams.
    pub fn new(envs: usize, n_actions: usize, teams: usize) -> Self {
        Self {
            n_actions,
            actions: vec![0.0; envs * n_actions],
            pre_squash: vec![0.0; envs * n_actions],
            logp: vec![vec![0.0; envs]; teams],
            assignment: vec![Vec::new(); teams],
            assignment_drawn: vec![vec![true; envs]; teams],
        }
    }

    /// Environments `B`.
    pub fn envs(&self) -> usize {
        self.actions.len() / self.n_actions.max(1)
    }
}

/// One team's act step with its noise streams and scratch (module docs).
#[derive(Clone, Debug)]
pub struct Actor {
    /// Sampled or mean actions.
    pub mode: ActMode,
    /// Action noise, one stream per agent of the team (in [`Policy::agents`] order).
    pub noise: Vec<ChaCha8Rng>,
    /// The normalised observation rows of the last step.
    normalised: Observation,
    /// A task assignment drawn at random, held between draws (1 step by default: drawn at
    /// every step; or `k` steps, or an episode: the trainer marks episode ends).
    pub hold: AssignmentHold,
}

impl Actor {
    /// An actor choosing actions as `mode` says, with one noise stream per agent.
    pub fn new(mode: ActMode, noise: Vec<ChaCha8Rng>) -> Self {
        Self { mode, noise, normalised: Observation::empty(0, 0), hold: AssignmentHold::default() }
    }

    /// The normalised observation rows the last [`Actor::act`] gave the policy (empty before
    /// the first).
    pub fn normalised(&self) -> &Observation {
        &self.normalised
    }

    /// Chooses the actions of `model`'s agents (its team `k = model.team()`) for raw
    /// observation rows `obs`, through the observation normaliser `norm` and the parameters
    /// `store` (the forward pass runs on their device; from the GPU the means and scales
    /// come back in one transfer): writes their columns of `joint.actions` (`tanh(u)`) and
    /// `joint.pre_squash` (`u`), `joint.logp[k]`, `joint.assignment[k]` and
    /// `joint.assignment_drawn[k]`. Errors on a non-finite policy output and on a joint action
    /// of another shape.
    pub fn act(
        &mut self,
        model: &mut dyn Policy,
        store: &ParamStore<f32>,
        norm: &ObsNormalizer,
        obs: ObsRows<'_, f32>,
        joint: &mut JointAction,
    ) -> Result<()> {
        let (b, na, team) = (obs.len(), joint.n_actions, model.team());
        if joint.envs() != b || joint.pre_squash.len() != joint.actions.len() || team >= joint.logp.len() {
            return Err(RlError::Model(models::ModelError::Input(format!(
                "a joint action of {} environments and {} teams for {b} observation rows of team {team}",
                joint.envs(),
                joint.logp.len()
            ))));
        }
        // Normalise.
        norm.apply_rows(obs, &mut self.normalised);
        // Forward without gradients, on the device the parameters are on; acting reads the
        // policy only (the update recomputes the values from the stored observations).
        let tape = Tape::<f32>::on(store.device());
        let _no_grad = tape.no_grad();
        let p = store.bind(&tape);
        // A held assignment is given back (`assignment_hold`), the environments that draw
        // marked in it; the others are drawn or solved.
        let width = model.assignment_width();
        // Which environments draw, in the joint action's buffer (no allocation per step).
        let mut drawn = std::mem::take(&mut joint.assignment_drawn[team]);
        if model.assignment_is_random() {
            self.hold.draws_next(b, width, &mut drawn);
        } else {
            drawn.clear();
            drawn.resize(b, true);
        }
        let given = if drawn.iter().all(|&d| d) { None } else { Some(self.hold.given(&drawn, width)) };
        let out = model.forward(&p, &self.normalised.rows(), given.as_deref(), false)?;
        let heads = host_heads(&out.agents)?;
        // A learned task assignment's log-probability `ln π(σ | s)` (`[B]`), the policy's
        // other factor: `π(a, σ | s) = π(σ | s) π(a | s, σ)`.
        let assignment_logp = match &out.assignment_terms {
            Some(terms) => Some(terms.log_prob.value().to_host()?),
            None => None,
        };
        // Sampling and log-probabilities on the host, whatever the forward's device.
        let host = Tape::<f32>::new();
        let _host_no_grad = host.no_grad();
        let spec = model.spec();
        let logp = &mut joint.logp[team];
        logp.clear();
        logp.resize(b, 0.0);
        for (ai, (agent, loc, scale)) in heads.into_iter().enumerate() {
            let (off, dof) = (spec.agent_action_offset[agent], spec.agent_dof[agent]);
            let (loc, scale) = (host.constant(loc), host.constant(scale));
            let std_t = std_from_scale(scale);
            let (loc_v, std_v) = (loc.value(), std_t.value());
            let (loc_d, std_d) = (loc_v.data(), std_v.data());
            if let Some(i) = loc_d.iter().chain(std_d).position(|x| !x.is_finite()) {
                return Err(RlError::NonFinite {
                    message: format!("policy output of agent {agent} (entry {i}) is not finite"),
                });
            }
            // Sample.
            let mut u = vec![0.0f32; b * dof];
            match self.mode {
                ActMode::Mean => u.copy_from_slice(loc_d),
                ActMode::Sample => {
                    let rng = &mut self.noise[ai];
                    for (k, x) in u.iter_mut().enumerate() {
                        *x = loc_d[k] + std_d[k] * standard_normal(rng) as f32;
                    }
                }
            }
            for e in 0..b {
                for k in 0..dof {
                    let x = u[e * dof + k];
                    joint.pre_squash[e * na + off + k] = x;
                    joint.actions[e * na + off + k] = x.tanh();
                }
            }
            // Log-probability of the pre-squash action (the tanh Jacobian cancels in PPO's
            // ratio).
            if self.mode == ActMode::Sample {
                let ut = host.constant(Tensor::new(u, &[b, dof])?);
                let lp = normal_log_prob(ut, loc, std_t)?.value();
                for (l, x) in logp.iter_mut().zip(lp.data()) {
                    *l += x;
                }
            }
        }
        // A held assignment's `π(σ | s)` was counted at the step that drew it.
        if let (Some(lp), ActMode::Sample) = (&assignment_logp, self.mode) {
            if lp.numel() != b {
                return Err(RlError::Model(models::ModelError::Input(format!(
                    "{} assignment log-probabilities for {b} observation rows of team {team}",
                    lp.numel()
                ))));
            }
            if let Some(i) = lp.data().iter().position(|x| !x.is_finite()) {
                return Err(RlError::NonFinite {
                    message: format!("task-assignment log-probability of team {team} (scene {i}) is not finite"),
                });
            }
            for ((l, x), _) in logp.iter_mut().zip(lp.data()).zip(&drawn).filter(|(_, d)| **d) {
                *l += x;
            }
        }
        self.hold.record(&out.assignment, &drawn);
        joint.assignment[team] = out.assignment;
        joint.assignment_drawn[team] = drawn;
        Ok(())
    }
}

/// One agent's policy head on the host: its scene index, `loc` and raw `scale` (`[B, dof_a]`).
type HostHead = (usize, Tensor<f32>, Tensor<f32>);

/// Every agent's `(agent, loc, scale)` on the host: from another device all of them in one
/// transfer (`tensor::to_host_all`: one staging buffer, one wait, no kernel); on the host
/// they are already there.
pub(crate) fn host_heads(agents: &[AgentPolicy<'_, f32>]) -> Result<Vec<HostHead>> {
    let values: Vec<Tensor<f32>> = agents.iter().flat_map(|a| [a.loc.value(), a.scale.value()]).collect();
    let host = tensor::to_host_all(&values)?;
    Ok(agents.iter().zip(host.chunks_exact(2)).map(|(a, ls)| (a.agent, ls[0].clone(), ls[1].clone())).collect())
}
