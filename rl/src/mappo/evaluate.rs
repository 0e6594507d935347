//! Evaluation: `N` episodes of the trained teams, one per environment of a batch, each
//! played to its end (success, win, draw or the time limit), with sampled or mean actions,
//! from random starts or the fixed start of `envs::tasks::StartMode`, every start moved by
//! an optional rotation about the vertical through the origin and a horizontal translation
//! (the paper's equivariance test).
//!
//! Environment `e`'s start is drawn as the `VecEnv` would draw it (a random start from the
//! stream `env_rng(seed, e)`, or the fixed start), then moved
//! ([`envs::tasks::eval_modes::SceneMotion`]) and set with `VecEnv::set_start`: evaluations
//! with the same seed and different motions play the same scenes moved, with the same action
//! noise streams, so their results are paired.

use envs::tasks::eval_modes::{SceneMotion, fixed_start};
use envs::tasks::placement::sample_start;
use envs::tasks::vec_env::env_rng;
use envs::tasks::{Outcome, Scene, Start, StartMode, TaskSpec, VecEnv};
use models::Policy;
use nn::ParamStore;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::mappo::actor::{ActMode, Actor, JointAction};
use crate::mappo::assignment_sensitivity::{AssignmentSensitivity, SensitivityProbe};
use crate::mappo::assignment_values::{AssignmentValues, ReturnUnits, ValueProbe};
use crate::mappo::config::TrainConfig;
use crate::mappo::seeding::stream;
use crate::mappo::team::Team;
use crate::stop::StopFlag;

/// Results of one evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalSummary {
    /// Episodes played.
    pub episodes: usize,
    /// Team Reach: fraction of episodes where every ball was covered.
    pub success_rate: f64,
    /// Team Sumo: fraction of episodes won by team 0 and by team 1.
    pub win_rate: Vec<f64>,
    /// Team Sumo: fraction of draws (both out at once, or the time limit).
    pub draw_rate: f64,
    /// Mean undiscounted episode return per team.
    pub mean_return: Vec<f64>,
    /// Mean episode length in control steps.
    pub mean_length: f64,
    /// Whether actions were sampled (else the mean action was taken).
    #[serde(default)]
    pub sampled: bool,
    /// Rotation of every start about the vertical through the origin, in degrees.
    #[serde(default)]
    pub rotation_deg: f64,
    /// Horizontal translation of every start (x, y) in m.
    #[serde(default)]
    pub translation: [f64; 2],
    /// How much each team's actions depend on its task assignment, for the teams that have
    /// one ([`crate::mappo::assignment_sensitivity`]); measured only when
    /// [`EvalOptions::assignment_sensitivity`] asks (empty otherwise, and then not written).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub assignment_sensitivity: Vec<AssignmentSensitivity>,
    /// Each learned assignment's values at every episode's first step beside the episode's
    /// discounted return ([`crate::mappo::assignment_values`]); measured only when
    /// [`EvalOptions::assignment_values`] asks (empty otherwise, and then not written).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub assignment_values: Vec<AssignmentValues>,
    /// The task-assignment rule the teams acted with in place of their own (`meben eval
    /// --assignment`, [`crate::app::eval_assignment`]); `None`, and not written, for their own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub assignment: Option<String>,
    /// The steps each random task assignment was held for in place of the run's own hold
    /// (`meben eval --assignment-hold`); `None`, and not written, for the run's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub assignment_hold: Option<usize>,
}

/// What to evaluate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvalOptions {
    /// Episodes (environments).
    pub episodes: usize,
    /// Mean actions instead of samples.
    pub deterministic: bool,
    /// Seed of the starts and the action noise.
    pub seed: u64,
    /// How episodes start.
    pub mode: StartMode,
    /// Every start rotated by this many degrees about the vertical through the origin
    /// (then translated).
    pub rotation_deg: f64,
    /// Every start translated horizontally by this (x, y) in m, after the rotation; the
    /// balls (goal balls, Sumo's centre ball) move with the agents.
    pub translation: [f64; 2],
    /// Also measure, at every step, how much each team's actions depend on its task
    /// assignment ([`EvalSummary::assignment_sensitivity`]; the episodes play as without).
    pub assignment_sensitivity: bool,
    /// Also read, at every episode's first step, the value of each assignment a learned
    /// scorer draws from, and sum each episode's return discounted and scaled by these units
    /// ([`EvalSummary::assignment_values`]; the episodes play as without).
    pub assignment_values: Option<ReturnUnits>,
}

impl EvalOptions {
    /// `episodes` episodes from `mode` with seed `seed`, unmoved.
    pub fn new(episodes: usize, deterministic: bool, seed: u64, mode: StartMode) -> Self {
        EvalOptions {
            episodes,
            deterministic,
            seed,
            mode,
            rotation_deg: 0.0,
            translation: [0.0, 0.0],
            assignment_sensitivity: false,
            assignment_values: None,
        }
    }

    /// The motion applied to every start.
    pub fn motion(&self) -> SceneMotion {
        SceneMotion::about_origin(self.rotation_deg, self.translation)
    }
}

/// The seed of an evaluation when none is given (`meben eval --seed`, `Policy.evaluate`).
pub const DEFAULT_EVAL_SEED: u64 = 12345;

/// An evaluation of a trained run as `meben eval` and Python's `Policy.evaluate` ask for
/// it, the run's own settings filling what the request leaves open ([`EvalRequest::options`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvalRequest {
    /// Episodes (environments).
    pub episodes: usize,
    /// Seed of the starts and the action noise.
    pub seed: u64,
    /// Mean actions (`Some(true)`) or samples (`Some(false)`); `None`: the run's
    /// `eval_deterministic`.
    pub deterministic: Option<bool>,
    /// Every start from the fixed start of the run's seed (implied by a rotation or a
    /// translation).
    pub fixed: bool,
    /// Every start rotated by this many degrees about the vertical through the origin: the
    /// paper's equivariance test.
    pub rotation_deg: Option<f64>,
    /// Every start translated horizontally by this (x, y) in m after the rotation.
    pub translation: Option<[f64; 2]>,
}

impl EvalRequest {
    /// The request made concrete for a run trained with `config`: a moved evaluation (a
    /// rotation or a translation) or a `fixed` one plays the fixed start of the run's seed,
    /// any other the random starts; the action mode is the request's or the run's.
    pub fn options(&self, config: &TrainConfig) -> EvalOptions {
        let moved = self.rotation_deg.is_some() || self.translation.is_some();
        let mode = if self.fixed || moved { StartMode::fixed(config.seed) } else { StartMode::Random };
        EvalOptions {
            rotation_deg: self.rotation_deg.unwrap_or(0.0),
            translation: self.translation.unwrap_or([0.0, 0.0]),
            ..EvalOptions::new(self.episodes, self.deterministic.unwrap_or(config.eval_deterministic), self.seed, mode)
        }
    }
}

/// The most episodes of one evaluation (one environment each, as `num_envs` at most).
pub const MAX_EPISODES: usize = envs::tasks::MAX_ENVS;

/// The start of evaluation episode `e` (module docs).
pub fn episode_start(scene: &Scene, options: &EvalOptions, e: usize) -> Start {
    let base = match &options.mode {
        // One episode per environment: keeping each environment's first start changes nothing.
        StartMode::Random | StartMode::PerSlot => sample_start(scene, &mut env_rng(options.seed, e)),
        StartMode::Fixed(f) => fixed_start(scene, f),
    };
    options.motion().apply(&base)
}

/// The environments of an evaluation, auto-reset off, every episode begun from its
/// [`episode_start`].
pub fn eval_envs(env: &str, options: &EvalOptions) -> Result<VecEnv> {
    if !(1..=MAX_EPISODES).contains(&options.episodes) {
        return Err(crate::RlError::config(
            "evaluation",
            "episodes",
            options.episodes,
            format!("must lie in 1 ..= {MAX_EPISODES} (one environment per episode)"),
        ));
    }
    options.mode.validate()?;
    options.motion().validate()?;
    let spec = TaskSpec::from_name(env)?;
    let mut venv = VecEnv::new(&spec, options.episodes, options.seed, options.mode).map_err(|e| match e {
        // More episodes than the machine holds environments ([`envs::tasks::check_batch_fits`]).
        envs::tasks::TaskError::BadArgument { what, message, .. } if what == "batch" => {
            crate::RlError::config("evaluation", "episodes", options.episodes, message)
        }
        e => e.into(),
    })?;
    venv.set_auto_reset(false);
    let starts: Vec<Start> = (0..options.episodes).map(|e| episode_start(venv.scene(), options, e)).collect();
    for (e, s) in starts.iter().enumerate() {
        venv.set_start(e, s)?;
    }
    Ok(venv)
}

/// Plays `options.episodes` episodes of `env` with `teams` (not changed: their models are
/// cloned so that the training's random streams are untouched) and summarises them.
pub fn evaluate(env: &str, teams: &[Team], options: &EvalOptions) -> Result<EvalSummary> {
    let summary = evaluate_unless_stopped(env, teams, options, &StopFlag::new())?;
    Ok(summary.expect("a flag that is never set never stops an evaluation"))
}

/// [`evaluate`], reading `stop` before every control step: `Ok(None)` once it is set (the
/// episodes are abandoned; nothing else changes, since an evaluation leaves the teams as it
/// found them). For callers that must be able to interrupt a long evaluation (Python's
/// `Policy.evaluate` on a `KeyboardInterrupt`).
pub fn evaluate_unless_stopped(
    env: &str,
    teams: &[Team],
    options: &EvalOptions,
    stop: &StopFlag,
) -> Result<Option<EvalSummary>> {
    let stores: Vec<&ParamStore<f32>> = teams.iter().map(|t| t.acting_store()).collect();
    play(env, teams, &stores, options, stop)
}

/// The evaluation's episodes, each team acting with the parameters `stores[k]`.
fn play(
    env: &str,
    teams: &[Team],
    stores: &[&ParamStore<f32>],
    options: &EvalOptions,
    stop: &StopFlag,
) -> Result<Option<EvalSummary>> {
    if stores.len() != teams.len() {
        return Err(crate::RlError::Model(models::ModelError::Input(format!(
            "{} parameter stores for {} teams",
            stores.len(),
            teams.len()
        ))));
    }
    let spec = TaskSpec::from_name(env)?;
    let mut venv = eval_envs(env, options)?;
    let (b, na, nt) = (options.episodes, venv.n_actions(), venv.scene().n_teams());
    let mode = if options.deterministic { ActMode::Mean } else { ActMode::Sample };
    let mut players = evaluation_actors(teams, options.seed, mode);
    // The teams with a task assignment, when their sensitivity to it is asked for.
    let mut probes: Vec<Option<SensitivityProbe>> = players
        .iter()
        .enumerate()
        .map(|(k, (model, _))| {
            (options.assignment_sensitivity && model.assignment_width() > 0).then(|| SensitivityProbe::new(k))
        })
        .collect();
    if options.assignment_sensitivity && probes.iter().all(Option::is_none) {
        let models: Vec<&str> = players.iter().map(|(m, _)| m.name()).collect();
        return Err(crate::RlError::Model(models::ModelError::Input(format!(
            "assignment sensitivity: no team's model has a task assignment to vary ({})",
            models.join(", ")
        ))));
    }
    // The teams whose assignments' values are asked for: every one whose value reads its
    // learned assignment (the first team's refusal where none does).
    let mut values: Vec<Option<ValueProbe>> = Vec::new();
    if let Some(units) = options.assignment_values {
        let probes: Vec<Result<ValueProbe>> =
            teams.iter().enumerate().map(|(k, t)| ValueProbe::new(k, t.model.as_ref(), units)).collect();
        if probes.iter().all(|p| p.is_err()) {
            let no_team = || crate::RlError::Model(models::ModelError::Input("assignment values: no team".into()));
            return Err(probes.into_iter().find_map(Result::err).unwrap_or_else(no_team));
        }
        values = probes.into_iter().map(Result::ok).collect();
    }
    let mut joint = JointAction::new(b, na, nt);
    let mut alive = vec![true; b];
    let mut returns = vec![0.0f64; b * nt];
    let mut outcome = vec![Outcome::Running; b];
    let mut length = vec![0u32; b];
    let mut remaining = b;
    let max_steps = spec.episode_steps + 1;
    for step in 0..max_steps {
        if remaining == 0 {
            break;
        }
        if stop.is_requested() {
            return Ok(None);
        }
        for ((team, store), (model, actor)) in teams.iter().zip(stores).zip(&mut players) {
            actor.act(model.as_mut(), store, &team.norm, venv.obs().rows(), &mut joint)?;
        }
        for (k, probe) in probes.iter_mut().enumerate() {
            if let Some(probe) = probe {
                let (model, actor) = &mut players[k];
                probe.observe(
                    model.as_mut(),
                    stores[k],
                    actor.normalised().rows(),
                    &joint.assignment[k],
                    &alive,
                    step,
                )?;
            }
        }
        if step == 0 {
            for (k, probe) in values.iter_mut().enumerate() {
                if let Some(probe) = probe {
                    probe.first_step(stores[k], players[k].1.normalised().rows(), &joint.assignment[k])?;
                }
            }
        }
        let out = venv.step(&joint.actions)?;
        for (k, probe) in values.iter_mut().enumerate() {
            if let Some(probe) = probe {
                probe.rewards(|e| out.reward[e * nt + k] as f64, &alive);
            }
        }
        for e in 0..b {
            if !alive[e] {
                continue;
            }
            for k in 0..nt {
                returns[e * nt + k] += out.reward[e * nt + k] as f64;
            }
            if out.terminated[e] || out.truncated[e] {
                alive[e] = false;
                remaining -= 1;
                outcome[e] = out.outcome[e];
                length[e] = out.episode_len[e];
            }
        }
    }
    Ok(Some(EvalSummary {
        sampled: !options.deterministic,
        rotation_deg: options.rotation_deg,
        translation: options.translation,
        assignment_sensitivity: probes.iter().flatten().map(SensitivityProbe::summary).collect(),
        assignment_values: values.into_iter().flatten().map(|p| p.summary(&outcome)).collect(),
        ..summarise(&outcome, &returns, &length, nt)
    }))
}

/// The players of an evaluation with seed `seed`: per team a copy of its model (so that the
/// team's own random streams are untouched) with its stochastic assignment reseeded (a
/// learned one drawn from the same stream, or its most likely value with [`ActMode::Mean`]),
/// and an actor with the evaluation's noise streams. The Python policy acts through the same, so
/// that `meben.Policy.load(run, seed=s)` acts as `meben eval --seed s` does.
pub fn evaluation_actors(teams: &[Team], seed: u64, mode: ActMode) -> Vec<(Box<dyn Policy>, Actor)> {
    teams
        .iter()
        .enumerate()
        .map(|(k, t)| {
            let mut model = t.model.clone();
            model.reseed(crate::mappo::seeding::derive_seed(seed, "evalasgn", k as u64, 0));
            // Mean actions take a learned assignment's most likely value too.
            model.set_deterministic(mode == ActMode::Mean);
            let noise = t.model.agents().iter().map(|&a| stream(seed, "evalnois", t.index as u64, a as u64)).collect();
            let mut actor = Actor::new(mode, noise);
            // A held assignment is held as in training, from each evaluation's first step.
            actor.hold.set_rule(t.actor.hold.rule());
            (model, actor)
        })
        .collect()
}

/// Rates, mean returns and lengths of ended episodes.
pub fn summarise(outcome: &[Outcome], returns: &[f64], length: &[u32], teams: usize) -> EvalSummary {
    let n = outcome.len();
    if n == 0 {
        return EvalSummary {
            episodes: 0,
            win_rate: vec![0.0; 2],
            mean_return: vec![0.0; teams],
            ..Default::default()
        };
    }
    let frac = |f: &dyn Fn(&Outcome) -> bool| outcome.iter().filter(|o| f(o)).count() as f64 / n as f64;
    EvalSummary {
        episodes: n,
        success_rate: frac(&|o| *o == Outcome::Success),
        win_rate: (0..2).map(|k| frac(&|o| *o == Outcome::Win(k))).collect(),
        draw_rate: if teams > 1 { frac(&|o| matches!(o, Outcome::Draw | Outcome::TimeLimit)) } else { 0.0 },
        mean_return: (0..teams).map(|k| (0..n).map(|e| returns[e * teams + k]).sum::<f64>() / n as f64).collect(),
        mean_length: length.iter().map(|&l| l as f64).sum::<f64>() / n as f64,
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_takes_the_runs_settings_where_it_leaves_them_open() {
        let mut config = TrainConfig::resolve(None, None, &[]).unwrap();
        config.seed = 9;
        let plain = EvalRequest {
            episodes: 4,
            seed: 1,
            deterministic: None,
            fixed: false,
            rotation_deg: None,
            translation: None,
        };
        for run_mean in [true, false] {
            config.eval_deterministic = run_mean;
            let o = plain.options(&config);
            assert_eq!((o.episodes, o.seed, o.deterministic, o.mode), (4, 1, run_mean, StartMode::Random));
            assert_eq!((o.rotation_deg, o.translation), (0.0, [0.0, 0.0]));
            let o = EvalRequest { deterministic: Some(!run_mean), ..plain }.options(&config);
            assert_eq!(o.deterministic, !run_mean);
        }
        // A moved or fixed evaluation plays the fixed start of the run's seed (not the
        // evaluation's), moved.
        let fixed = StartMode::fixed(9);
        assert_eq!(EvalRequest { fixed: true, ..plain }.options(&config).mode, fixed);
        let o = EvalRequest { rotation_deg: Some(180.0), ..plain }.options(&config);
        assert_eq!((o.mode, o.rotation_deg), (fixed, 180.0));
        let o = EvalRequest { translation: Some([2.5, -1.0]), ..plain }.options(&config);
        assert_eq!((o.mode, o.rotation_deg, o.translation), (fixed, 0.0, [2.5, -1.0]));
    }
}
