//! One team's learner: its policy and critic (a [`Policy`]: the model zoo's [`Model`], or one
//! a [`PolicyFactory`] brings), parameters, optimiser, observation
//! normaliser, its [`Actor`] (the act step with the team's action-noise streams: MEBEN.md
//! section 8, every agent and team has its own) and its minibatch-shuffling stream.

use envs::layout::{ObsRows, ObsSpec};
use models::{Model, ModelDescription, Policy, PolicyFactory};
use nn::{Adam, AdamConfig, LrSchedule, ParamStore, Scope};
use rand_chacha::ChaCha8Rng;
use tensor::Device;

use crate::error::{Result, RlError};
use crate::mappo::actor::{ActMode, Actor, JointAction};
use crate::mappo::assignment_hold::HoldRule;
use crate::mappo::config::TrainConfig;
use crate::mappo::episode_credit::EpisodeDraws;
use crate::mappo::normalizer::ObsNormalizer;
use crate::mappo::seeding::{derive_seed, stream};

/// One team's learner (module docs).
#[derive(Clone, Debug)]
pub struct Team {
    /// Team index in the scene.
    pub index: usize,
    /// The policy and critic.
    pub model: Box<dyn Policy>,
    /// Its parameters (names under `team<k>.`), on the training's device: what the updates
    /// read and write, and (unless [`Team::act_mirror`] is set) what the act step reads.
    /// Built and loaded on the host; the trainer places them ([`Team::place`]).
    pub store: ParamStore<f32>,
    /// Where the act step runs on another device than the updates (`act_device = "cpu"` on
    /// a GPU run): the parameters' one mirror there, refreshed after every update phase
    /// ([`Team::refresh_mirror`]). `None` otherwise.
    pub act_mirror: Option<ParamStore<f32>>,
    /// Its optimiser.
    pub adam: Adam,
    /// Its observation normaliser.
    pub norm: ObsNormalizer,
    /// The act step of collection, with the team's action noise (one stream per agent, in
    /// [`Policy::agents`] order).
    pub actor: Actor,
    /// Minibatch shuffling.
    pub shuffle: ChaCha8Rng,
    /// With `assignment_gradient = "episode"` and a learned assignment, the draws of the
    /// running episodes and of those that ended in the iteration (set by the trainer, which
    /// knows the environments); `None` otherwise.
    pub episode_draws: Option<EpisodeDraws>,
}

impl Team {
    /// Builds team `team`'s learner for scenes laid out by `spec`, initialised from the run
    /// seed, with the model zoo's model that `config` names for the team
    /// ([`TrainConfig::team_model`]).
    pub fn build(config: &TrainConfig, spec: &ObsSpec, team: usize) -> Result<Team> {
        let field = if team == 1 && !config.opponent.is_empty() { "opponent" } else { "model" };
        let spec_str = config.team_model(team);
        let bad = |e: models::ModelError| RlError::config("config", field, spec_str, e.to_string());
        let mut mc = ModelDescription::parse(spec_str).map_err(bad)?;
        if !spec_str.contains("seed=") {
            mc.set_seed(derive_seed(config.seed, "assign", team as u64, u64::MAX));
        }
        Self::assemble(config, spec, team, |s| Ok(Box::new(Model::new(s, &mc, spec, team).map_err(bad)?)))
    }

    /// [`Team::build`] with the policy and critic that `factory` builds instead of the zoo's.
    pub fn build_with(config: &TrainConfig, spec: &ObsSpec, team: usize, factory: &dyn PolicyFactory) -> Result<Team> {
        Self::assemble(config, spec, team, |s| Ok(factory.build(s, spec, team)?))
    }

    /// The learner around the policy `build` makes in the team's scope: its parameters come
    /// from the run's `init` stream of the team, the optimiser, normaliser and streams from
    /// the configuration.
    fn assemble(
        config: &TrainConfig,
        spec: &ObsSpec,
        team: usize,
        build: impl FnOnce(&mut Scope<'_, f32>) -> Result<Box<dyn Policy>>,
    ) -> Result<Team> {
        let mut store = ParamStore::<f32>::new();
        let mut init = stream(config.seed, "init", team as u64, 0);
        let model = build(&mut store.scope(&format!("team{team}"), &mut init))?;
        if model.team() != team || model.spec().n_agents != spec.n_agents {
            return Err(RlError::Model(models::ModelError::Input(format!(
                "a policy built for team {team} of a scene of {} agents acts for team {} of {} agents",
                spec.n_agents,
                model.team(),
                model.spec().n_agents
            ))));
        }
        let adam_config = AdamConfig { lr: lr_schedule(config), ..AdamConfig::default() };
        let adam = Adam::new(adam_config, &store);
        let norm = ObsNormalizer::new(config.obs_norm.resolve(), spec);
        let noise = model.agents().iter().map(|&a| stream(config.seed, "noise", team as u64, a as u64)).collect();
        let shuffle = stream(config.seed, "shuffle", team as u64, 0);
        let actor = Actor::new(ActMode::Sample, noise);
        Ok(Team { index: team, model, store, act_mirror: None, adam, norm, actor, shuffle, episode_draws: None })
    }

    /// The parameters the act step reads: the mirror where it runs apart from the updates,
    /// else the parameters themselves.
    pub fn acting_store(&self) -> &ParamStore<f32> {
        self.act_mirror.as_ref().unwrap_or(&self.store)
    }

    /// Places the parameters and Adam's moments on `device` (the updates'), and the act
    /// step's mirror on `act_device` where that differs: the one place a team's tensors
    /// change device.
    pub fn place(&mut self, device: Device, act_device: Device) -> Result<()> {
        self.store.to_device(device)?;
        self.adam.to_device(device)?;
        self.act_mirror = None;
        if act_device != device {
            let mut mirror = self.store.clone();
            mirror.to_device(act_device)?;
            self.act_mirror = Some(mirror);
        }
        Ok(())
    }

    /// Copies the parameters into the act step's mirror, if there is one (one transfer).
    pub fn refresh_mirror(&mut self) -> Result<()> {
        if let Some(mirror) = &mut self.act_mirror {
            let device = mirror.device();
            let mut fresh = self.store.clone();
            fresh.to_device(device)?;
            *mirror = fresh;
        }
        Ok(())
    }

    /// Puts the team's task assignment in the state of a run of `config` at `env_steps`:
    /// a learned one in its warm-up below `assignment_warmup_steps`, and an assignment drawn
    /// at random held for [`TrainConfig::assignment_hold_at`] steps (the actor's hold; 1 for
    /// the models whose assignment is not drawn). Run directories, policy files and the
    /// trainer all set it here.
    pub fn sync_assignment(&mut self, config: &TrainConfig, env_steps: u64) {
        self.model.set_assignment_warmup(config.assignment_warmup_at(env_steps));
        let hold =
            if self.model.assignment_is_random() { config.assignment_hold_at(env_steps) } else { HoldRule::Steps(1) };
        if hold != self.actor.hold.rule() {
            self.actor.hold.set_rule(hold);
        }
    }

    /// The team's actions for raw observation rows `obs`, with its own model, parameters,
    /// normaliser and noise ([`Actor::act`]).
    pub fn act(&mut self, obs: ObsRows<'_, f32>, joint: &mut JointAction) -> Result<()> {
        let store = self.act_mirror.as_ref().unwrap_or(&self.store);
        self.actor.act(self.model.as_mut(), store, &self.norm, obs, joint)
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
