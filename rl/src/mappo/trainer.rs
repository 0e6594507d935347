//! MAPPO training (paper section 5; MEBEN.md section 6: Brax PPO per team), read top to
//! bottom in [`Trainer::iterate`]:
//!
//! 1. **Collect** ([`Trainer::collect`]) `U = batch_size * num_minibatches / num_envs`
//!    blocks of `unroll_length` steps of all environments. Every team acts on the raw
//!    observations through its [`crate::mappo::actor::Actor`] (its own normaliser and policy, its
//!    own per-agent noise streams); the environments step together; the rollout records each
//!    step ([`Rollout::push`]: actions, log-probabilities, rewards scaled, terminations,
//!    truncations and the final observations of truncated episodes, MEBEN.md section 8:
//!    bootstrap from the true final observation). Team Sumo: the curriculum factor goes from
//!    1 to 0 over the first `curriculum_fraction` of the run.
//! 2. **Normalise**: every team's observation statistics absorb the iteration's
//!    observations (then stay frozen for the update, as in the reference).
//! 3. **Update** every team: `epochs` passes, each over a fresh permutation of the
//!    iteration's unrolls cut into `num_minibatches` minibatches of `batch_size` whole unrolls;
//!    per minibatch (`Trainer::update`, top to bottom): gather -> normalise -> the PPO loss
//!    ([`ppo::loss`]: forward, GAE, log-probabilities and entropy, the loss and its
//!    statistics; the entropy estimate's noise from the minibatch's own stream) -> backward ->
//!    every gradient element clipped to `+-grad_clip` -> one Adam step. A non-finite loss or gradient stops the run
//!    ([`RlError::NonFinite`]); the last checkpoint is kept.
//!
//! **Devices** ([`crate::mappo::device`]). With `device = "gpu"` the update runs on the GPU:
//! every team's parameters and Adam moments live there from the trainer's construction (or
//! resumption) on ([`Team::place`]), each minibatch goes to a GPU tape (`Tape::on`: uploaded
//! once), and the gradients' non-finite check (one value back), the clipping and the Adam
//! step (f32 moments, [`nn::Adam`]) run there. The act step of collection runs there too
//! (`act_device = "same"`, the default): the policy's forward pass reads the updates'
//! parameters on the GPU, and each step's means and scales come back in one transfer for
//! sampling on the host ([`crate::mappo::actor`]); with `act_device = "cpu"` it reads the
//! team's host mirror ([`Team::act_mirror`], refreshed after each update phase) and runs on
//! the CPU, as the simulator always does. Values come to the host by explicit transfers
//! only: GAE's values, the loss statistics (one transfer a minibatch), and a checkpoint's
//! parameters and moments ([`nn::Adam::sync_to_host`]), so a checkpoint is the same file
//! whichever device wrote it. With `device = "cpu"` (the default) nothing of this happens:
//! the same code as before the GPU existed, bit for bit.
//!
//! The application drives a [`Trainer`] in a run directory ([`crate::app::run`]).

use std::time::Instant;

use envs::layout::ObsSpec;
use envs::tasks::{Outcome, StepOutput, TaskKind, TaskSpec, VecEnv};
use models::PolicyFactory;
use tensor::Tape;

use crate::error::{Result, RlError};
use crate::mappo::actor::JointAction;
use crate::mappo::assignment_hold::HoldRule;
use crate::mappo::checkpoint::{Checkpoint, TeamState, VERSION};
use crate::mappo::config::{AssignmentGradient, NormStart, TrainConfig};
use crate::mappo::config_match;
use crate::mappo::device::check_device;
use crate::mappo::episode_credit::{EpisodeBatch, EpisodeDraws};
use crate::mappo::evaluate::{EvalOptions, EvalSummary, evaluate};
use crate::mappo::minibatch::Minibatch;
use crate::mappo::ppo::{self, LossStats, PpoParams};
use crate::mappo::rollout::Rollout;
use crate::mappo::seeding::{RngState, derive_seed, minibatch_stream};
use crate::mappo::team::Team;

/// Episodes that ended during one iteration's collection.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EpisodeStats {
    /// Episodes ended.
    pub episodes: usize,
    /// Sum of their returns per team.
    pub return_sum: Vec<f64>,
    /// Reach successes.
    pub successes: usize,
    /// Sumo wins per team.
    pub wins: [usize; 2],
    /// Sumo draws (including time limits).
    pub draws: usize,
    /// Sum of their lengths.
    pub length_sum: u64,
}

impl EpisodeStats {
    /// Nothing ended yet, for `teams` teams.
    pub fn new(teams: usize) -> Self {
        Self { return_sum: vec![0.0; teams], ..Default::default() }
    }

    /// Adds one step's rewards to the running episodes' returns (`[E, teams]`) and counts the
    /// episodes that ended at it (their returns then restart from 0).
    pub fn record(&mut self, out: &StepOutput, returns: &mut [f64]) {
        let nt = self.return_sum.len();
        for e in 0..out.terminated.len() {
            for k in 0..nt {
                returns[e * nt + k] += out.reward[e * nt + k] as f64;
            }
            if out.terminated[e] || out.truncated[e] {
                self.episodes += 1;
                self.length_sum += out.episode_len[e] as u64;
                for k in 0..nt {
                    self.return_sum[k] += returns[e * nt + k];
                    returns[e * nt + k] = 0.0;
                }
                match out.outcome[e] {
                    Outcome::Success => self.successes += 1,
                    Outcome::Win(k) if k < 2 => self.wins[k] += 1,
                    Outcome::Draw | Outcome::TimeLimit if nt > 1 => self.draws += 1,
                    _ => {}
                }
            }
        }
    }
}

/// One iteration's figures.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IterationStats {
    /// Episodes ended while collecting.
    pub episodes: EpisodeStats,
    /// Per team, the mean of the minibatch loss statistics.
    pub losses: Vec<LossStats>,
    /// The curriculum factor used.
    pub alpha: f64,
    /// Where the iteration's seconds went, stage by stage.
    pub timings: Timings,
}

/// Wall seconds of an iteration's stages, summed over its steps and minibatches (printed
/// per iteration with `MEBEN_TIMINGS=1`, and with `MEBEN_TIMINGS=gpu` the kernels' own
/// times too; docs/PERFORMANCE.md). On the GPU a stage's time
/// is the host's: kernels run asynchronously until something comes back, so the loss's time
/// includes the forward pass (GAE reads the values), `backward` includes the gradient pass
/// (the non-finite check reads its verdict), and `optimizer` only queues clipping and Adam,
/// whose kernels run during the next minibatch's stages.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// The act step: every team's policy on the current observations, actions sampled.
    pub act_s: f64,
    /// The simulator's batched step of every environment.
    pub simulate_s: f64,
    /// Storing the step in the rollout and the episode statistics.
    pub store_s: f64,
    /// Updating the observation normalisers from the iteration's rows.
    pub normalise_s: f64,
    /// Gathering and normalising the minibatches on the host.
    pub minibatch_s: f64,
    /// The PPO loss (forward pass, GAE, log-probabilities; the upload of the minibatch).
    pub loss_s: f64,
    /// The backward pass and the non-finite check of the gradients.
    pub backward_s: f64,
    /// Clipping and the Adam step.
    pub optimizer_s: f64,
    /// The act step's mirror of the parameters refreshed (`act_device` apart from `device`).
    pub parameters_back_s: f64,
}

impl Timings {
    /// Seconds spent collecting (acting, stepping the environments, storing the steps).
    pub fn collect_s(&self) -> f64 {
        self.act_s + self.simulate_s + self.store_s
    }

    /// Seconds spent normalising and updating.
    pub fn update_s(&self) -> f64 {
        self.normalise_s + self.minibatch_s + self.loss_s + self.backward_s + self.optimizer_s + self.parameters_back_s
    }

    /// One line: the stages with their seconds.
    pub fn describe(&self) -> String {
        format!(
            "collect: act {:.3} s, simulate {:.3} s, store {:.3} s; normalisers {:.3} s; update: minibatches \
             {:.3} s, loss {:.3} s, backward {:.3} s, clip+adam {:.3} s, parameters back {:.3} s",
            self.act_s,
            self.simulate_s,
            self.store_s,
            self.normalise_s,
            self.minibatch_s,
            self.loss_s,
            self.backward_s,
            self.optimizer_s,
            self.parameters_back_s
        )
    }
}

/// Adds the seconds since `*mark` to `slot` and moves the mark to now.
fn lap(mark: &mut Instant, slot: &mut f64) {
    let now = Instant::now();
    *slot += (now - *mark).as_secs_f64();
    *mark = now;
}

/// The whole training state (module docs).
pub struct Trainer {
    /// The configuration.
    pub config: TrainConfig,
    /// The training environments.
    pub env: VecEnv,
    /// Their observation layout.
    pub spec: ObsSpec,
    /// One learner per team.
    pub teams: Vec<Team>,
    /// Iterations done.
    pub iteration: u64,
    /// Environment steps collected.
    pub env_steps: u64,
    /// Evaluations done.
    pub evals_done: u64,
    /// `[E, teams]` returns of running episodes.
    pub episode_returns: Vec<f64>,
    rollout: Rollout,
    joint: JointAction,
    mb: Minibatch,
}

impl Trainer {
    /// A fresh run of `config`, its teams played by the model zoo's models that `config`
    /// names.
    pub fn new(config: &TrainConfig) -> Result<Trainer> {
        config.validate("config")?;
        Self::build(config, None)
    }

    /// A fresh run of `config` whose teams' policies and critics `factory` builds (bring your
    /// own model: `rl/examples/custom_policy.rs`). The run's `model` (and Team Sumo's
    /// `opponent`) become the names of the policies built.
    pub fn with_policies(config: &TrainConfig, factory: &dyn PolicyFactory) -> Result<Trainer> {
        config.validate_except_models("config")?;
        Self::build(config, Some(factory))
    }

    fn build(config: &TrainConfig, factory: Option<&dyn PolicyFactory>) -> Result<Trainer> {
        check_device(config.device)?;
        // The GPU's kernel choices of this configuration.
        tensor::configure_gpu(config.gpu_config("config")?).expect("checked by gpu_config");
        let spec = TaskSpec::from_name(&config.env)?;
        let env_seed = derive_seed(config.seed, "envs", 0, 0);
        let mut env = VecEnv::new(&spec, config.num_envs, env_seed, config.train_start_mode())?;
        env.reset();
        let obs_spec = env.scene().obs_spec.clone();
        let mut teams = (0..obs_spec.n_teams)
            .map(|k| match factory {
                None => Team::build(config, &obs_spec, k),
                Some(f) => Team::build_with(config, &obs_spec, k, f),
            })
            .collect::<Result<Vec<_>>>()?;
        let mut config = config.clone();
        if factory.is_some() {
            config.model = teams[0].model.name().to_string();
            config.opponent = match teams.get(1) {
                Some(t) if t.model.name() != config.model => t.model.name().to_string(),
                _ => String::new(),
            };
        }
        let config = &config;
        // `obs_norm_start`: empty statistics (the release), or those of the starts.
        if config.obs_norm_start == NormStart::FirstObservation {
            for t in &mut teams {
                t.norm.update(&env.obs().vectors, &env.obs().scalars);
            }
        }
        let nt = obs_spec.n_teams;
        // A stochastic task assignment is stored with each transition (the update must see the
        // graph the behaviour policy acted on); the deterministic ones are solved again.
        let widths: Vec<usize> =
            teams.iter().map(|t| if t.model.assignment_is_random() { t.model.assignment_width() } else { 0 }).collect();
        let bytes = Rollout::bytes(
            config.unrolls_per_iteration(),
            config.unroll_length,
            config.num_envs,
            env.obs(),
            env.n_actions(),
            widths.len(),
        );
        crate::mappo::memory::check_fits_in_memory(bytes).map_err(|e| {
            RlError::config(
                "config",
                "batch_size",
                config.batch_size,
                format!(
                    "an iteration of batch_size x num_minibatches x unroll_length = {} env steps on {}: its rollout \
                     {e}",
                    config.steps_per_iteration(),
                    config.env
                ),
            )
        })?;
        let rollout = Rollout::new(
            config.unrolls_per_iteration(),
            config.unroll_length,
            config.num_envs,
            env.obs(),
            env.n_actions(),
            &widths,
        );
        let na = env.n_actions();
        place_teams(config, &mut teams)?;
        // A draw held for an episode credited with its return: every learning team keeps its
        // draws across iterations (`episode_credit`).
        if config.assignment_gradient == AssignmentGradient::Episode {
            for t in &mut teams {
                if !t.model.learned_assignment_support().is_empty() {
                    t.episode_draws = Some(EpisodeDraws::new(env.obs(), t.model.assignment_width()));
                }
            }
        }
        let mut trainer = Trainer {
            config: config.clone(),
            spec: obs_spec,
            teams,
            iteration: 0,
            env_steps: 0,
            evals_done: 0,
            episode_returns: vec![0.0; config.num_envs * nt],
            rollout,
            joint: JointAction::new(config.num_envs, na, nt),
            mb: Minibatch::default(),
            env,
        };
        trainer.sync_assignment_state();
        Ok(trainer)
    }

    /// Puts every team's learned task assignment in its warm-up while the env steps are below
    /// the configuration's `assignment_warmup_steps`, and takes it out from there on (no
    /// effect on the other methods), with the hold of its draws at those env steps
    /// ([`Team::sync_assignment`]). Kept in step with [`Trainer::env_steps`]: at the start
    /// and end of every iteration and when a run is built or restored, so that collection,
    /// the update and the evaluations after an iteration all see the env steps' state.
    fn sync_assignment_state(&mut self) {
        for t in &mut self.teams {
            t.sync_assignment(&self.config, self.env_steps);
        }
    }

    /// The run restored from a checkpoint (its configuration, except the
    /// [`config_match::SESSION_FIELDS`]: `steps`, `num_evals`, `checkpoint_every` and
    /// `threads`, which may be changed to extend a run, and `device`: a run resumes on either
    /// device).
    pub fn from_checkpoint(c: &Checkpoint, config: &TrainConfig, path: &std::path::Path) -> Result<Trainer> {
        config.validate("config")?;
        Self::restore(c, config, path, None)
    }

    /// [`Trainer::from_checkpoint`] of a run started by [`Trainer::with_policies`]: `factory`
    /// builds the same policies again (the checkpoint's parameters are loaded into them by
    /// name).
    pub fn from_checkpoint_with_policies(
        c: &Checkpoint,
        config: &TrainConfig,
        path: &std::path::Path,
        factory: &dyn PolicyFactory,
    ) -> Result<Trainer> {
        config.validate_except_models("config")?;
        Self::restore(c, config, path, Some(factory))
    }

    fn restore(
        c: &Checkpoint,
        config: &TrainConfig,
        path: &std::path::Path,
        factory: Option<&dyn PolicyFactory>,
    ) -> Result<Trainer> {
        let bad = |m: String| RlError::Checkpoint { path: path.to_path_buf(), message: m };
        // The checkpoint's configuration but for the fields a session may change (the one
        // comparison of `config_match`, which sweeps and run directories make too).
        let same_config = |now: &TrainConfig| {
            let diff = config_match::differences(&c.config, now, &config_match::SESSION_FIELDS);
            if diff.is_empty() {
                return Ok(());
            }
            let fields: Vec<String> = diff.iter().map(|d| d.describe("in the checkpoint", "now")).collect();
            Err(bad(format!("was written by another configuration: {}", fields.join("; "))))
        };
        // A zoo model is named by the configuration: a mismatch is refused before anything is
        // built. A factory's policies name the models the run records, known once built.
        if factory.is_none() {
            same_config(config)?;
        }
        let mut t = Trainer::build(config, factory)?;
        let config = &t.config.clone();
        if factory.is_some() {
            same_config(config)?;
        }
        if c.teams.len() != t.teams.len() || c.episode_returns.len() != t.episode_returns.len() {
            return Err(bad(format!(
                "{} teams and {} returns do not fit the scene",
                c.teams.len(),
                c.episode_returns.len()
            )));
        }
        for (team, s) in t.teams.iter_mut().zip(&c.teams) {
            s.params.load_into(&mut team.store).map_err(|e| bad(e.to_string()))?;
            s.adam.check_fits(&team.store).map_err(|e| bad(e.to_string()))?;
            // The moments and count from the checkpoint; the schedule of this configuration
            // (its length follows `steps`, which may have been extended).
            let schedule = team.adam.config.lr;
            team.adam = s.adam.clone();
            team.adam.config.lr = schedule;
            s.normalizer.check_fits(&team.norm).map_err(|e| {
                bad(format!(
                    "the observation normaliser of team {} does not fit: {e} (obs_norm = {:?}; checkpoints written \
                     before `auto` became the invariant normaliser cannot be resumed)",
                    team.index, config.obs_norm
                ))
            })?;
            team.norm = s.normalizer.clone();
            if s.noise.len() != team.actor.noise.len() {
                return Err(bad(format!("{} noise streams for {} agents", s.noise.len(), team.actor.noise.len())));
            }
            team.actor.noise = s.noise.iter().map(|r| r.restore()).collect::<Result<Vec<_>>>()?;
            team.shuffle = s.shuffle.restore()?;
        }
        // The restored parameters and moments to the update's device.
        place_teams(config, &mut t.teams)?;
        t.env.restore(&c.env).map_err(|e| bad(e.to_string()))?;
        t.iteration = c.iteration;
        t.env_steps = c.env_steps;
        t.evals_done = c.evals_done;
        t.episode_returns = c.episode_returns.clone();
        t.sync_assignment_state();
        // A learned assignment held per episode goes on with the environments' episodes.
        for (team, s) in t.teams.iter_mut().zip(&c.teams) {
            match (&s.assignment_hold, team.actor.hold.rule()) {
                (Some(saved), _) => {
                    team.actor.hold.restore(saved).map_err(|e| bad(format!("team {}: {e}", team.index)))?
                }
                (None, HoldRule::Episode) if c.iteration > 0 => {
                    return Err(bad(format!(
                        "team {} holds its learned task assignment per episode, and the checkpoint keeps no held \
                         assignment",
                        team.index
                    )));
                }
                (None, _) => {}
            }
            // So do the draws credited with their episodes' returns.
            match (&s.episode_draws, team.episode_draws.as_mut()) {
                (Some(saved), Some(draws)) => {
                    draws.restore(saved).map_err(|e| bad(format!("team {}: {e}", team.index)))?
                }
                (None, Some(_)) if c.iteration > 0 => {
                    return Err(bad(format!(
                        "team {} credits its learned task assignment with its episodes' returns, and the checkpoint \
                         keeps none of its running episodes' draws",
                        team.index
                    )));
                }
                _ => {}
            }
        }
        Ok(t)
    }

    /// The state to save; `last_evals` is the last scheduled evaluation, one summary per
    /// rotation of `eval_rotations` (empty before the first). On the GPU the Adam moments
    /// come back to the host for it (one transfer per team).
    pub fn checkpoint(&self, wall_s: f64, last_evals: &[EvalSummary]) -> Result<Checkpoint> {
        let mut adams = Vec::with_capacity(self.teams.len());
        let mut params = Vec::with_capacity(self.teams.len());
        for t in &self.teams {
            let mut adam = t.adam.clone();
            adam.sync_to_host()?;
            adams.push(adam);
            // The parameters on the host (one transfer where they are elsewhere).
            params.push(nn::StateDict::from_store(&t.store)?);
        }
        Ok(Checkpoint {
            version: VERSION,
            config: self.config.clone(),
            iteration: self.iteration,
            env_steps: self.env_steps,
            wall_s,
            evals_done: self.evals_done,
            teams: self
                .teams
                .iter()
                .zip(adams.into_iter().zip(params))
                .map(|(t, (adam, params))| TeamState {
                    params,
                    adam,
                    normalizer: t.norm.clone(),
                    noise: t.actor.noise.iter().map(RngState::of).collect(),
                    shuffle: RngState::of(&t.shuffle),
                    assignment_hold: t.actor.hold.saved(),
                    episode_draws: t.episode_draws.as_ref().map(EpisodeDraws::saved),
                })
                .collect(),
            env: self.env.snapshot(),
            episode_returns: self.episode_returns.clone(),
            last_eval: last_evals.first().cloned(),
            last_eval_rotated: last_evals.iter().skip(1).cloned().collect(),
        })
    }

    /// The Team Sumo curriculum factor at the current step (1 for Reach).
    pub fn curriculum_alpha(&self) -> f64 {
        if self.env.scene().kind() != TaskKind::Sumo {
            return 1.0;
        }
        // A zero fraction makes the span 0 and the factor 0 from the start (sparse only).
        let span = self.config.curriculum_fraction * self.config.steps as f64;
        if span == 0.0 { 0.0 } else { (1.0 - self.env_steps as f64 / span).clamp(0.0, 1.0) }
    }

    /// One iteration: collect, normalise, update (module docs).
    pub fn iterate(&mut self) -> Result<IterationStats> {
        let alpha = self.curriculum_alpha();
        self.env.set_curriculum_alpha(alpha)?;
        for t in &mut self.teams {
            t.model.reseed(derive_seed(self.config.seed, "assign", t.index as u64, self.iteration));
        }
        self.sync_assignment_state();
        let mut timings = Timings::default();
        let episodes = self.collect_timed(&mut timings)?;
        let mut mark = Instant::now();
        for t in &mut self.teams {
            for rows in self.rollout.visited_obs() {
                t.norm.update(rows.vectors, rows.scalars);
            }
        }
        lap(&mut mark, &mut timings.normalise_s);
        let losses = self.update(&mut timings)?;
        self.iteration += 1;
        self.env_steps += self.config.steps_per_iteration();
        self.sync_assignment_state();
        Ok(IterationStats { episodes, losses, alpha, timings })
    }

    /// The current iteration's data (after [`Trainer::collect`]).
    pub fn rollout(&self) -> &Rollout {
        &self.rollout
    }

    /// Step 1 of [`Trainer::iterate`]: plays one iteration's unrolls with the current
    /// policies and normalisers, storing them in [`Trainer::rollout`].
    pub fn collect(&mut self) -> Result<EpisodeStats> {
        self.collect_timed(&mut Timings::default())
    }

    /// [`Trainer::collect`], adding its stages' seconds to `timings`.
    fn collect_timed(&mut self, timings: &mut Timings) -> Result<EpisodeStats> {
        let scale = self.config.reward_scaling as f32;
        let mut stats = EpisodeStats::new(self.spec.n_teams);
        // Every iteration's collection begins with a draw of each assignment held for `k`
        // steps; one held for an episode goes on with it.
        let held: Vec<bool> = self
            .teams
            .iter_mut()
            .map(|t| {
                t.actor.hold.restart();
                !t.actor.hold.rule().every_step()
            })
            .collect();
        self.rollout.begin(self.env.obs(), &held);
        let mut mark = Instant::now();
        while !self.rollout.is_full() {
            for team in self.teams.iter_mut() {
                // The parameters where the act step runs (`Team::acting_store`).
                team.act(self.env.obs().rows(), &mut self.joint)?;
            }
            // The draws credited with their episodes' returns: where each was drawn.
            for team in self.teams.iter_mut() {
                if let Some(d) = team.episode_draws.as_mut() {
                    let k = team.index;
                    d.record_draws(self.env.obs(), &self.joint.assignment[k], &self.joint.assignment_drawn[k]);
                }
            }
            lap(&mut mark, &mut timings.act_s);
            let out = self.env.step(&self.joint.actions)?;
            lap(&mut mark, &mut timings.simulate_s);
            self.rollout.push(&self.joint, out, scale);
            let ended: Vec<bool> = out.terminated.iter().zip(&out.truncated).map(|(&t, &u)| t || u).collect();
            let nt = self.spec.n_teams;
            for team in self.teams.iter_mut() {
                team.actor.hold.end_episodes(ended.iter().copied());
                if let Some(d) = team.episode_draws.as_mut() {
                    // The ended episode's return: its running sum and this step's reward.
                    let k = team.index;
                    let returns = &self.episode_returns;
                    d.end_episodes(&ended, |e| returns[e * nt + k] + out.reward[e * nt + k] as f64);
                }
            }
            stats.record(out, &mut self.episode_returns);
            lap(&mut mark, &mut timings.store_s);
        }
        Ok(stats)
    }

    /// Step 3 of [`Trainer::iterate`]: `epochs` passes of minibatch updates of every team,
    /// on the configuration's device (module docs).
    fn update(&mut self, timings: &mut Timings) -> Result<Vec<LossStats>> {
        let c = &self.config;
        let hp = PpoParams::from_config(c);
        // In a learned assignment's warm-up the update solves Algorithm 1 again from the
        // minibatch, as the greedy model's does, instead of taking the stored assignment
        // (also Algorithm 1's, from the observations before the normaliser's update: the
        // same in every test run so far, so this keeps the greedy run's path by construction).
        let warmup = c.assignment_warmup_at(self.env_steps);
        let mut all = Vec::with_capacity(self.teams.len());
        for team in self.teams.iter_mut() {
            // The parameters the update reads and writes, on the configuration's device.
            let store = &mut team.store;
            let mut sum = LossStats::default();
            let mut count = 0.0;
            // The draws whose episodes ended in this iteration, credited with their returns
            // (`episode_credit`): their advantages, and `ln π_old` before the first step.
            let mut episodes =
                team.episode_draws.as_mut().and_then(|d| EpisodeBatch::new(&d.take_finished(), &team.norm));
            if let Some(batch) = episodes.as_mut() {
                let tape = Tape::<f32>::on(c.device);
                let _no_grad = tape.no_grad();
                let p = store.bind(&tape);
                let logp = ppo::assignment_log_prob(team.model.as_mut(), &p, batch, 0..batch.len())?;
                batch.logp_old = logp.value().to_host()?.to_vec();
            }
            for epoch in 0..c.epochs {
                let perm = permutation(self.rollout.unrolls(), &mut team.shuffle);
                for (k, ids) in perm.chunks_exact(c.batch_size).enumerate() {
                    let mut mark = Instant::now();
                    let at = Where { team: team.index, iteration: self.iteration, epoch, minibatch: k };
                    // Gather the minibatch's unrolls (time-major) and normalise them.
                    self.rollout.gather(ids, team.index, &mut self.mb);
                    if warmup {
                        self.mb.assignment.clear();
                    }
                    self.mb.normalise(&team.norm);
                    lap(&mut mark, &mut timings.minibatch_s);
                    // The PPO loss; the entropy estimate draws from the minibatch's stream.
                    let tape = Tape::<f32>::on(c.device);
                    let p = store.bind(&tape);
                    let mut noise =
                        minibatch_stream(c.seed, "entropy", at.team as u64, at.iteration, epoch as u64, k as u64);
                    let (mut loss, stats) = ppo::loss(team.model.as_mut(), &p, &self.mb, &hp, &mut noise)?;
                    // Minibatch k's share of the episode-credited draws.
                    if let Some(batch) = &episodes {
                        let share = batch.share(k, c.num_minibatches);
                        if let Some(term) =
                            ppo::episode_assignment_term(team.model.as_mut(), &p, batch, share, c.clip_epsilon)?
                        {
                            loss = loss.add(term)?;
                        }
                    }
                    if !stats.loss.is_finite() {
                        return Err(RlError::NonFinite {
                            message: format!("loss {} of {}", stats.loss, at.describe(&stats)),
                        });
                    }
                    lap(&mut mark, &mut timings.loss_s);
                    // Backward, every gradient element clipped, one Adam step.
                    let grads = p.grads(&tape.backward(loss)?);
                    if let Some(i) = tensor::first_non_finite(&grads)? {
                        return Err(RlError::NonFinite {
                            message: format!("gradient of {} of {}", store.names()[i], at.describe(&stats)),
                        });
                    }
                    lap(&mut mark, &mut timings.backward_s);
                    if c.grad_clip > 0.0 {
                        team.adam.step_clipped(store, &grads, c.grad_clip)?;
                    } else {
                        team.adam.step(store, &grads)?;
                    }
                    lap(&mut mark, &mut timings.optimizer_s);
                    sum.add(&stats);
                    count += 1.0;
                }
            }
            all.push(sum.scaled(1.0 / count));
        }
        // Where the act step runs apart from the updates, its mirror (one transfer a team).
        let mut mark = Instant::now();
        for team in self.teams.iter_mut() {
            team.refresh_mirror()?;
        }
        lap(&mut mark, &mut timings.parameters_back_s);
        Ok(all)
    }

    /// Evaluates the current policies (module [`crate::mappo::evaluate`](mod@crate::mappo::evaluate)),
    /// acting where collection acts (`act_device`).
    pub fn evaluate(&self, options: &EvalOptions) -> Result<EvalSummary> {
        evaluate(&self.config.env, &self.teams, options)
    }

    /// The evaluation options of the run's `k`-th scheduled evaluation, one per rotation of
    /// `eval_rotations` (the same seed, so the same starts, rotated, and the same noise).
    pub fn scheduled_evals(&self, k: u64) -> Vec<EvalOptions> {
        let c = &self.config;
        let base =
            EvalOptions::new(c.eval_episodes, c.eval_deterministic, derive_seed(c.seed, "eval", k, 0), c.start_mode());
        c.eval_rotations.iter().map(|&rotation_deg| EvalOptions { rotation_deg, ..base }).collect()
    }
}

/// Every team's parameters and moments on the configuration's device, with the act step's
/// mirror where `act_device` puts it elsewhere ([`Team::place`]).
fn place_teams(config: &TrainConfig, teams: &mut [Team]) -> Result<()> {
    let act_device = config.act_device.resolve(config.device);
    teams.iter_mut().try_for_each(|t| t.place(config.device, act_device))
}

/// Where a minibatch update is, for error messages.
struct Where {
    team: usize,
    iteration: u64,
    epoch: usize,
    minibatch: usize,
}

impl Where {
    /// `team t at iteration i, epoch e, minibatch k (policy loss .., value loss .., entropy ..)`.
    fn describe(&self, stats: &LossStats) -> String {
        format!(
            "team {} at iteration {}, epoch {}, minibatch {} (policy loss {}, value loss {}, entropy {})",
            self.team, self.iteration, self.epoch, self.minibatch, stats.policy_loss, stats.value_loss, stats.entropy
        )
    }
}

/// A uniformly random permutation of `0..n` (Fisher-Yates, from the end).
fn permutation(n: usize, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<usize> {
    use rand::RngExt;
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        p.swap(i, j);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutations_are_permutations() {
        let mut r = crate::mappo::seeding::stream(0, "t", 0, 0);
        let mut p = permutation(100, &mut r);
        p.sort();
        assert_eq!(p, (0..100).collect::<Vec<_>>());
    }
}
