//! One team's learner: its model (policy and critic), parameters, optimiser, observation
//! normaliser and random streams (MEBEN.md section 8: every agent and team has its own
//! action-noise stream), and the act step shared by collection, evaluation and rendering.

use models::distribution::{normal_log_prob, std_from_scale};
use models::layout::{ObsRows, ObsSpec, Observation};
use models::{Model, ModelConfig};
use nn::{Adam, AdamConfig, LrSchedule, ParamStore};
use rand_chacha::ChaCha8Rng;
use tensor::{Tape, Tensor};

use crate::config::TrainConfig;
use crate::error::{Result, RlError};
use crate::normalizer::ObsNormalizer;
use crate::seeding::{derive_seed, standard_normal, stream};

/// One team's learner (module docs).
#[derive(Clone, Debug)]
pub struct Team {
    /// Team index in the scene.
    pub index: usize,
    /// The policy and critic.
    pub model: Model,
    /// Its parameters (names under `team<k>.`).
    pub store: ParamStore<f32>,
    /// Its optimiser.
    pub adam: Adam,
    /// Its observation normaliser.
    pub norm: ObsNormalizer,
    /// Action noise, one stream per agent of the team (in [`Model::agents`] order).
    pub noise: Vec<ChaCha8Rng>,
    /// Minibatch shuffling.
    pub shuffle: ChaCha8Rng,
}

/// How actions are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActMode {
    /// `u ~ Normal(loc, std)`, action `tanh(u)`.
    Sample,
    /// `u = loc`, action `tanh(loc)`.
    Mean,
}

impl Team {
    /// Builds team `team`'s learner for scenes laid out by `spec`, initialised from the run
    /// seed.
    pub fn build(config: &TrainConfig, spec: &ObsSpec, team: usize) -> Result<Team> {
        let field = if team == 1 && !config.opponent.is_empty() { "opponent" } else { "model" };
        let spec_str = config.team_model(team);
        let mut mc =
            ModelConfig::parse(spec_str).map_err(|e| RlError::config("config", field, spec_str, e.to_string()))?;
        if !spec_str.contains("seed=") {
            mc.seed = derive_seed(config.seed, "assign", team as u64, u64::MAX);
        }
        let mut store = ParamStore::<f32>::new();
        let mut init = stream(config.seed, "init", team as u64, 0);
        let model = Model::new(&mut store.scope(&format!("team{team}"), &mut init), &mc, spec, team)
            .map_err(|e| RlError::config("config", field, spec_str, e.to_string()))?;
        let adam_config = AdamConfig { lr: lr_schedule(config), ..AdamConfig::default() };
        let adam = Adam::new(adam_config, &store);
        let norm = ObsNormalizer::new(config.obs_norm.resolve(), spec);
        let noise = model.agents().iter().map(|&a| stream(config.seed, "noise", team as u64, a as u64)).collect();
        let shuffle = stream(config.seed, "shuffle", team as u64, 0);
        Ok(Team { index: team, model, store, adam, norm, noise, shuffle })
    }
}

/// The learning-rate schedule of a run: constant, or linear to 0 over all its updates.
pub fn lr_schedule(config: &TrainConfig) -> LrSchedule {
    if config.lr_decay {
        let updates = config.iterations() * (config.epochs * config.num_minibatches) as u64;
        LrSchedule::Linear { start: config.learning_rate, end: 0.0, steps: updates }
    } else {
        LrSchedule::Constant(config.learning_rate)
    }
}

/// Reusable buffers of [`act`].
#[derive(Clone, Debug)]
pub struct ActScratch {
    normalised: Observation,
}

impl Default for ActScratch {
    fn default() -> Self {
        Self { normalised: Observation::empty(0, 0) }
    }
}

/// Chooses the actions of one team's agents for a batch of raw observations: normalises
/// them, runs the policy (no gradient), and writes for every environment row `e` and agent
/// `a` of the team the action `tanh(u)` at `actions[e * n_actions + offset_a ..]` and the
/// pre-squash `u` at the same place of `pre_squash`; `logp[e]` gets the team's log-probability
/// of `u` under the Normal (summed over its agents). `noise` (one stream per agent) is used
/// in [`ActMode::Sample`]. Returns the task assignment the policy acted on
/// ([`models::PolicyOutput::assignment`], `[B * Model::assignment_width]`).
#[allow(clippy::too_many_arguments)]
pub fn act(
    model: &mut Model,
    store: &ParamStore<f32>,
    norm: &ObsNormalizer,
    spec: &ObsSpec,
    raw: ObsRows<'_, f32>,
    mode: ActMode,
    noise: &mut [ChaCha8Rng],
    actions: &mut [f32],
    pre_squash: &mut [f32],
    logp: &mut [f32],
    scratch: &mut ActScratch,
) -> Result<Vec<u32>> {
    let b = raw.len();
    let na = actions.len() / b.max(1);
    norm.apply_rows(raw, &mut scratch.normalised);
    let tape = Tape::<f32>::new();
    let _no_grad = tape.no_grad();
    let p = store.bind(&tape);
    // Acting reads the policy only (the update recomputes values from the stored
    // observations): the value network is skipped.
    let out = model.forward_policy_batch(&p, &scratch.normalised.rows())?;
    logp.iter_mut().for_each(|x| *x = 0.0);
    for (ai, pol) in out.agents.iter().enumerate() {
        let (off, dof) = (spec.agent_action_offset[pol.agent], spec.agent_dof[pol.agent]);
        let loc = pol.loc.value();
        let std = std_from_scale(pol.scale).value();
        let (loc, std) = (loc.data(), std.data());
        if let Some(i) = loc.iter().chain(std).position(|x| !x.is_finite()) {
            return Err(RlError::NonFinite {
                message: format!("policy output of agent {} (entry {i}) is not finite", pol.agent),
            });
        }
        let mut u = vec![0.0f32; b * dof];
        match mode {
            ActMode::Mean => u.copy_from_slice(loc),
            ActMode::Sample => {
                let rng = &mut noise[ai];
                for (k, x) in u.iter_mut().enumerate() {
                    *x = loc[k] + std[k] * standard_normal(rng) as f32;
                }
            }
        }
        for e in 0..b {
            for k in 0..dof {
                let x = u[e * dof + k];
                pre_squash[e * na + off + k] = x;
                actions[e * na + off + k] = x.tanh();
            }
        }
        if mode == ActMode::Sample {
            let ut = tape.constant(Tensor::new(u, &[b, dof])?);
            let lp = normal_log_prob(ut, pol.loc, std_from_scale(pol.scale))?.value();
            for (l, x) in logp.iter_mut().zip(lp.data()) {
                *l += x;
            }
        }
    }
    Ok(out.assignment)
}

/// Records one episode of `env` from the fixed start of `seed` played by `teams` (mean
/// actions if `deterministic`), for rendering. A failure of the policy ends the episode and
/// is stored in `failure`.
pub fn record_episode(
    env: &str,
    teams: &mut [Team],
    seed: u64,
    steps: usize,
    deterministic: bool,
    failure: &mut Option<RlError>,
) -> Result<envs::tasks::render::Trajectory> {
    let spec = envs::tasks::Scene::from_name(env)?.obs_spec;
    let mode = if deterministic { ActMode::Mean } else { ActMode::Sample };
    let mut scratch = ActScratch::default();
    let mut noise: Vec<Vec<ChaCha8Rng>> = teams
        .iter()
        .map(|t| t.model.agents().iter().map(|&a| stream(seed, "rendnois", t.index as u64, a as u64)).collect())
        .collect();
    let traj = envs::tasks::render::record_episode(env, seed, steps, |obs, actions| {
        if failure.is_some() {
            return;
        }
        let mut u = vec![0.0f32; actions.len()];
        let mut logp = vec![0.0f32; obs.batch];
        for (k, t) in teams.iter_mut().enumerate() {
            let r = act(
                &mut t.model,
                &t.store,
                &t.norm,
                &spec,
                obs.rows(),
                mode,
                &mut noise[k],
                actions,
                &mut u,
                &mut logp,
                &mut scratch,
            );
            if let Err(e) = r {
                *failure = Some(e);
                actions.iter_mut().for_each(|a| *a = 0.0);
                return;
            }
        }
    })?;
    Ok(traj)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Preset;

    #[test]
    fn learning_rate_decays_to_zero_over_the_run_or_stays() {
        let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
        let updates = c.iterations() * (c.epochs * c.num_minibatches) as u64;
        let s = lr_schedule(&c);
        assert_eq!(s.at(0), c.learning_rate);
        assert!((s.at(updates / 2) - c.learning_rate / 2.0).abs() < 1e-9);
        assert_eq!(s.at(updates), 0.0);
        c.lr_decay = false;
        assert_eq!(lr_schedule(&c).at(updates), c.learning_rate);
    }
}
