//! The training configuration: every hyper-parameter of MAPPO as the reference release sets
//! it (`../shared/reference/MEBEN.md` section 6), overridable from a TOML file and from the
//! command line.
//!
//! A configuration is resolved in layers, each overriding the one before:
//! 1. a preset: `quick` (the built-in default of `meben train`: `shnn` on `team_reach/1_ant`
//!    in about ten minutes on 2 cores: 256 environments, batch 128 unrolls x 8 minibatches,
//!    1.5M steps, learning rate decayed linearly to 0, entropy bonus 1e-3 (both presets take
//!    the bonus's entropy as the reference's Tanh-Normal estimate), evaluation with
//!    mean actions) or `paper` (the reference schedule: 2048 environments, 50M steps for Team
//!    Reach, 20M and batch 128 for Team Sumo, evaluation with sampled actions as the release's
//!    `run_eval`);
//! 2. a TOML file (`--config file.toml`), whose keys are the fields of [`TrainConfig`] (and
//!    `preset`);
//! 3. command-line options (`--env`, `--model`, `--set field=value`, ...).
//!
//! The resolved configuration is written to the run directory as `config.toml`; a run is
//! resumed and evaluated from it.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};

/// The most env steps of one iteration (`batch_size * num_minibatches * unroll_length`):
/// 100 times the paper's 163 840, and small enough that the checked products never overflow.
pub const MAX_STEPS_PER_ITERATION: u64 = 1 << 24;

/// Which observation normaliser to use (module [`crate::normalizer`] has the maths). Every
/// model of a comparison gets the same one unless a run says otherwise (the paper's "same
/// input" rule).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ObsNormKind {
    /// The default: `invariant` for every model.
    #[default]
    Auto,
    /// One position scale for every node (from positions relative to the entity roots' mean
    /// position, not clipped), velocities and angular velocities by a running RMS norm per
    /// node and kind (norm clipped), scalars element-wise: rotations about the vertical and
    /// horizontal translations commute with it, so the invariant models stay invariant.
    Invariant,
    /// Running mean and standard deviation of every observation element, clipped (the
    /// reference release; breaks the models' invariance).
    Elementwise,
    /// No normalisation.
    None,
}

impl ObsNormKind {
    /// The normaliser this setting builds.
    pub fn resolve(self) -> crate::normalizer::NormKind {
        use crate::normalizer::NormKind;
        match self {
            ObsNormKind::Auto | ObsNormKind::Invariant => NormKind::Invariant,
            ObsNormKind::Elementwise => NormKind::Elementwise,
            ObsNormKind::None => NormKind::Identity,
        }
    }
}

/// Which entropy the loss's bonus uses (module [`crate::ppo`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EntropyKind {
    /// The presets' choice: the reference release's, Brax's `NormalTanhDistribution.entropy`,
    /// the Normal's entropy plus the tanh log-Jacobian at one reparameterised sample per
    /// action dimension ([`models::distribution::tanh_normal_entropy`]), its noise drawn
    /// from a stream per minibatch ([`crate::seeding::minibatch_stream`]).
    TanhNormal,
    /// The Normal part's entropy alone (no sample).
    Normal,
}

/// Where the observation normaliser's statistics start (module [`crate::normalizer`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormStart {
    /// The presets' choice, the reference release's (Brax's `running_statistics.init_state`):
    /// no statistics, so the first iteration acts through the identity (mean 0, scale 1);
    /// the statistics then take in every observation collected, before each update.
    Empty,
    /// The statistics of the first observations (the starts), before the first iteration.
    /// At a start every body is at rest, so the velocity scales fall to their floor
    /// (`normalizer::MIN_SCALE`, 1e-3): the first iteration's behaviour policy reads
    /// velocities magnified a thousandfold and its data is far off-policy for the first
    /// update (measured: approx-KL 22 on `team_reach/1_ant`, 68 on `1_centipede`, 97-100% of
    /// the samples clipped, against 0.03-0.14 from the second iteration on).
    FirstObservation,
}

/// The named starting points of a configuration (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// About ten minutes on 2 cores: smaller batches, shorter schedule.
    #[default]
    Quick,
    /// The reference release's schedule (MEBEN.md section 6).
    Paper,
}

impl Preset {
    /// Parses `quick` or `paper`.
    pub fn parse(s: &str, source: &str) -> Result<Preset> {
        match s {
            "quick" => Ok(Preset::Quick),
            "paper" => Ok(Preset::Paper),
            _ => Err(RlError::config(source, "preset", s, "expected `quick` or `paper`")),
        }
    }
}

/// Everything that defines a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Environment name (`envs::tasks::BUILTIN_NAMES` or a custom composition).
    pub env: String,
    /// Model of team 0, with options: `shnn` or `shnn:assignment=hungarian;seed=3`
    /// (`models::ModelConfig::parse`).
    pub model: String,
    /// Model of team 1 in Team Sumo (default: the same as `model`); must be empty for Reach.
    pub opponent: String,
    /// Seed of everything random in the run.
    pub seed: u64,
    /// Every episode starts from the same start (drawn from `seed`) instead of a fresh random
    /// one: the training of the paper's equivariance test (evaluate with `--rotate`).
    pub fixed_start: bool,
    /// Environment steps to train for (the run stops at the first iteration boundary at or
    /// past it).
    pub steps: u64,
    /// Environments stepped together.
    pub num_envs: usize,
    /// Control steps per unroll.
    pub unroll_length: usize,
    /// Unrolls per minibatch.
    pub batch_size: usize,
    /// Minibatches per epoch (an iteration collects `batch_size * num_minibatches` unrolls).
    pub num_minibatches: usize,
    /// Passes over the iteration's data.
    pub epochs: usize,
    /// Discount `gamma`.
    pub discount: f64,
    /// GAE `lambda`.
    pub gae_lambda: f64,
    /// PPO clip `epsilon`.
    pub clip_epsilon: f64,
    /// Weight of the value loss `mean((V - V_target)^2)` (the reference's `0.5 * 0.5`).
    pub value_coef: f64,
    /// Weight of the entropy bonus.
    pub entropy_coef: f64,
    /// The entropy of the bonus: `tanh_normal` (the presets; the reference release's
    /// one-sample Tanh-Normal estimate) or `normal` (the Normal part alone). Absent from files
    /// written before it existed: `normal`, what those runs used.
    #[serde(default = "entropy_before_the_field")]
    pub entropy: EntropyKind,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// The learning rate falls linearly to 0 over the run's updates (CleanRL's `anneal_lr`;
    /// the reference keeps it constant). Absent from files written before it existed: false.
    #[serde(default)]
    pub lr_decay: bool,
    /// Every gradient element is clipped to `[-grad_clip, grad_clip]` (0 turns it off).
    pub grad_clip: f64,
    /// Observation normaliser: `auto` (default; the invariant normaliser for every model),
    /// `invariant`, `elementwise` (the reference release's) or `none`.
    pub obs_norm: ObsNormKind,
    /// Where the normaliser's statistics start: `empty` (the presets; the reference release)
    /// or `first_observation`. Absent from files written before it existed:
    /// `first_observation`, what those runs used.
    #[serde(default = "norm_start_before_the_field")]
    pub obs_norm_start: NormStart,
    /// Rewards are multiplied by this before GAE.
    pub reward_scaling: f64,
    /// Team Sumo: the curriculum factor goes linearly from 1 (dense) to 0 (sparse) over
    /// this fraction of the run.
    pub curriculum_fraction: f64,
    /// Evaluations during the run (evenly spaced, the last at the end; 0: none).
    pub num_evals: usize,
    /// Episodes per evaluation.
    pub eval_episodes: usize,
    /// Evaluate with the mean action `tanh(loc)` instead of sampling. `false` in the `paper`
    /// preset (the release samples in its `run_eval`), `true` in `quick` (its entropy bonus,
    /// 1e-3, was tuned with mean-action evaluation). The metrics column `eval_sampled` and
    /// `EvalSummary::sampled` record which was used.
    pub eval_deterministic: bool,
    /// Every periodic evaluation runs once per rotation (degrees, about the vertical through
    /// the origin: the centre of Team Reach's placement disc and Team Sumo's centre ball), on
    /// the same starts and noise streams: the first must be 0 (the plain `eval_*` metrics
    /// columns), each further one has its own columns (`eval_success_rate_rot180`, ...,
    /// [`crate::metrics::eval_column`]). With random starts every drawn start is rotated.
    /// `[0.0, 180.0]` is the paper's equivariance test (with `fixed_start = true`). Default
    /// `[0.0]` (also for files written before the field existed).
    #[serde(default = "default_eval_rotations")]
    pub eval_rotations: Vec<f64>,
    /// Write a checkpoint every this many iterations (and after every evaluation and at the
    /// end; 0: only then).
    pub checkpoint_every: usize,
    /// Worker threads (0: every core). Results do not depend on it.
    pub threads: usize,
}

impl TrainConfig {
    /// The preset's configuration for `env` (module docs).
    pub fn preset(preset: Preset, env: &str) -> TrainConfig {
        let sumo = env.starts_with("team_sumo");
        let paper = TrainConfig {
            env: env.to_string(),
            model: "shnn".into(),
            opponent: String::new(),
            seed: 0,
            fixed_start: false,
            steps: if sumo { 20_000_000 } else { 50_000_000 },
            num_envs: 2048,
            unroll_length: 5,
            batch_size: if sumo { 128 } else { 1024 },
            num_minibatches: 32,
            epochs: 4,
            discount: 0.97,
            gae_lambda: 0.95,
            clip_epsilon: 0.3,
            value_coef: 0.25,
            entropy_coef: 1e-2,
            entropy: EntropyKind::TanhNormal,
            learning_rate: 3e-4,
            lr_decay: false,
            grad_clip: 0.1,
            obs_norm: ObsNormKind::Auto,
            obs_norm_start: NormStart::Empty,
            reward_scaling: 1.0,
            curriculum_fraction: 0.25,
            num_evals: 50,
            eval_episodes: 1024,
            eval_deterministic: false,
            eval_rotations: default_eval_rotations(),
            checkpoint_every: 10,
            threads: 0,
        };
        match preset {
            Preset::Paper => paper,
            Preset::Quick => TrainConfig {
                steps: 1_500_000,
                num_envs: 256,
                batch_size: 128,
                lr_decay: true,
                // A tenth of the reference's entropy bonus: over 1.5M steps the mean action
                // (what evaluation takes) lags the sampled policy less. Quick preset, final
                // evaluation success over seeds 0-3 (128 episodes each, commit 794ad79):
                // 57.0, 67.2, 92.2, 54.7% with 1e-3 against 10.2, 78.1, 81.2, 29.7% with 1e-2.
                entropy_coef: 1e-3,
                num_minibatches: 8,
                num_evals: 10,
                eval_episodes: 128,
                // Mean actions: the entropy bonus above was tuned with them.
                eval_deterministic: true,
                checkpoint_every: 20,
                ..paper
            },
        }
    }

    /// Resolves a configuration from its layers (module docs): `preset` (else the file's
    /// `preset` key, else `quick`), the TOML `file`, then `overrides` (`field = value`
    /// pairs, values in TOML syntax or bare strings), and validates it.
    pub fn resolve(preset: Option<Preset>, file: Option<&Path>, overrides: &[(String, String)]) -> Result<TrainConfig> {
        let mut table = toml::Table::new();
        if let Some(path) = file {
            let text = std::fs::read_to_string(path).map_err(|e| RlError::file(path, format!("cannot read: {e}")))?;
            table = text.parse::<toml::Table>().map_err(|e| RlError::file(path, format!("invalid TOML: {e}")))?;
        }
        let file_source = file.map(|p| p.display().to_string()).unwrap_or_else(|| "built-in".into());
        for (field, value) in overrides {
            table.insert(field.clone(), parse_override(value));
        }
        let preset = match (preset, table.remove("preset")) {
            (Some(p), _) => p,
            (None, Some(toml::Value::String(s))) => Preset::parse(&s, &file_source)?,
            (None, Some(v)) => return Err(RlError::config(&file_source, "preset", v, "expected `quick` or `paper`")),
            (None, None) => Preset::Quick,
        };
        let env = match table.get("env") {
            Some(toml::Value::String(s)) => s.clone(),
            Some(v) => return Err(RlError::config(&file_source, "env", v, "expected a string")),
            None => "team_reach/1_ant".to_string(),
        };
        let base = TrainConfig::preset(preset, &env);
        let mut merged =
            toml::Table::try_from(&base).map_err(|e| RlError::config("built-in", "*", "", e.to_string()))?;
        let source = if overrides.is_empty() { file_source } else { format!("{file_source} + command line") };
        for (k, v) in table {
            if !merged.contains_key(&k) {
                let known: Vec<&str> = merged.keys().map(|s| s.as_str()).collect();
                return Err(RlError::config(
                    &source,
                    &k,
                    v,
                    format!("unknown field; known fields: preset, {}", known.join(", ")),
                ));
            }
            merged.insert(k, v);
        }
        let config: TrainConfig = toml::Value::Table(merged)
            .try_into()
            .map_err(|e: toml::de::Error| RlError::config(&source, "*", "", e.to_string()))?;
        config.validate(&source)?;
        Ok(config)
    }

    /// Reads a resolved configuration written by [`TrainConfig::save`] (a run's
    /// `config.toml`); every field must be present.
    pub fn load(path: &Path) -> Result<TrainConfig> {
        let text = std::fs::read_to_string(path).map_err(|e| RlError::file(path, format!("cannot read: {e}")))?;
        let config: TrainConfig =
            toml::from_str(&text).map_err(|e| RlError::file(path, format!("invalid run configuration: {e}")))?;
        config.validate(&path.display().to_string())?;
        Ok(config)
    }

    /// The configuration as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| unreachable!("a TrainConfig always serialises: {e}"))
    }

    /// Writes the configuration as TOML, atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        nn::write_atomic(path, self.to_toml().as_bytes())?;
        Ok(())
    }

    /// How training episodes start: random, or the fixed start of `seed`.
    pub fn start_mode(&self) -> envs::tasks::StartMode {
        if self.fixed_start { envs::tasks::StartMode::fixed(self.seed) } else { envs::tasks::StartMode::Random }
    }

    /// Whether the environment is a Team Sumo scene.
    pub fn is_sumo(&self) -> bool {
        self.env.starts_with("team_sumo")
    }

    /// Env steps collected per iteration: `batch_size * num_minibatches * unroll_length`.
    pub fn steps_per_iteration(&self) -> u64 {
        (self.batch_size * self.num_minibatches * self.unroll_length) as u64
    }

    /// Unrolls of all `num_envs` environments per iteration.
    pub fn unrolls_per_iteration(&self) -> usize {
        self.batch_size * self.num_minibatches / self.num_envs
    }

    /// Iterations the run does: `ceil(steps / steps_per_iteration)`.
    pub fn iterations(&self) -> u64 {
        self.steps.div_ceil(self.steps_per_iteration())
    }

    /// The model specification of `team` (team 1 of Sumo plays `opponent` if set).
    pub fn team_model(&self, team: usize) -> &str {
        if team == 1 && !self.opponent.is_empty() { &self.opponent } else { &self.model }
    }

    /// Checks every value; errors name `source`, the field and the value.
    pub fn validate(&self, source: &str) -> Result<()> {
        let err =
            |field: &str, value: &dyn ToString, msg: &str| Err(RlError::config(source, field, value.to_string(), msg));
        envs::tasks::TaskSpec::from_name(&self.env)
            .map_err(|e| RlError::config(source, "env", &self.env, e.to_string()))?;
        for (field, spec) in [("model", &self.model), ("opponent", &self.opponent)] {
            if field == "opponent" && spec.is_empty() {
                continue;
            }
            models::ModelConfig::parse(spec).map_err(|e| RlError::config(source, field, spec, e.to_string()))?;
        }
        if !self.opponent.is_empty() && !self.is_sumo() {
            return err("opponent", &self.opponent, "only Team Sumo has a second team");
        }
        for (field, v) in [
            ("num_envs", self.num_envs),
            ("unroll_length", self.unroll_length),
            ("batch_size", self.batch_size),
            ("num_minibatches", self.num_minibatches),
            ("epochs", self.epochs),
        ] {
            if v == 0 {
                return err(field, &v, "must be at least 1");
            }
        }
        // TOML integers are signed 64-bit: a larger value is written to config.toml but
        // cannot be read back, and the run could then neither resume nor be evaluated.
        for (field, v) in [
            ("seed", self.seed),
            ("steps", self.steps),
            ("epochs", self.epochs as u64),
            ("num_evals", self.num_evals as u64),
            ("checkpoint_every", self.checkpoint_every as u64),
            ("threads", self.threads as u64),
        ] {
            if v > i64::MAX as u64 {
                return err(field, &v, "at most 9223372036854775807 (TOML integers are signed 64-bit)");
            }
        }
        if self.num_envs > 1 << 20 {
            return err("num_envs", &self.num_envs, "at most 1048576 environments");
        }
        let per_iteration = (self.batch_size as u64)
            .checked_mul(self.num_minibatches as u64)
            .and_then(|u| u.checked_mul(self.unroll_length as u64))
            .filter(|&n| n <= MAX_STEPS_PER_ITERATION);
        if per_iteration.is_none() {
            return err(
                "batch_size",
                &self.batch_size,
                &format!(
                    "an iteration of batch_size x num_minibatches x unroll_length = {} x {} x {} env steps is more \
                     than the {MAX_STEPS_PER_ITERATION} this program allows",
                    self.batch_size, self.num_minibatches, self.unroll_length
                ),
            );
        }
        if self.eval_episodes > crate::evaluate::MAX_EPISODES {
            return err(
                "eval_episodes",
                &self.eval_episodes,
                &format!("at most {} (one environment per episode)", crate::evaluate::MAX_EPISODES),
            );
        }
        if !(self.batch_size * self.num_minibatches).is_multiple_of(self.num_envs) {
            return err(
                "num_envs",
                &self.num_envs,
                &format!(
                    "must divide batch_size * num_minibatches = {} x {} = {} (an iteration is a whole number of \
                     unrolls of every environment)",
                    self.batch_size,
                    self.num_minibatches,
                    self.batch_size * self.num_minibatches
                ),
            );
        }
        if self.steps == 0 {
            return err("steps", &self.steps, "must be at least 1");
        }
        for (field, v, lo, hi) in [
            ("discount", self.discount, 0.0, 1.0),
            ("gae_lambda", self.gae_lambda, 0.0, 1.0),
            ("curriculum_fraction", self.curriculum_fraction, 0.0, 1.0),
        ] {
            if !(lo..=hi).contains(&v) {
                return err(field, &v, &format!("must lie in [{lo}, {hi}]"));
            }
        }
        for (field, v) in [
            ("clip_epsilon", self.clip_epsilon),
            ("value_coef", self.value_coef),
            ("entropy_coef", self.entropy_coef),
            ("grad_clip", self.grad_clip),
            ("reward_scaling", self.reward_scaling),
        ] {
            if !v.is_finite() || v < 0.0 {
                return err(field, &v, "must be finite and non-negative");
            }
        }
        if !self.learning_rate.is_finite() || self.learning_rate <= 0.0 {
            return err("learning_rate", &self.learning_rate, "must be finite and positive");
        }
        if self.eval_rotations.first() != Some(&0.0) {
            return err(
                "eval_rotations",
                &format!("{:?}", self.eval_rotations),
                "the first rotation must be 0 (its results are the plain eval_* metrics columns), e.g. [0.0, 180.0]",
            );
        }
        for (i, r) in self.eval_rotations.iter().enumerate() {
            if !r.is_finite() {
                return err("eval_rotations", &format!("{:?}", self.eval_rotations), "every rotation must be finite");
            }
            if self.eval_rotations[..i].contains(r) {
                return err("eval_rotations", &format!("{:?}", self.eval_rotations), &format!("{r} appears twice"));
            }
        }
        if self.num_evals > 0 && self.eval_episodes == 0 {
            return err("eval_episodes", &self.eval_episodes, "must be at least 1 when num_evals > 0");
        }
        Ok(())
    }
}

/// Configurations written before the `entropy` field existed trained with the Normal part's
/// entropy.
fn entropy_before_the_field() -> EntropyKind {
    EntropyKind::Normal
}

/// Configurations written before the `obs_norm_start` field existed started the normaliser
/// from the first observations.
fn norm_start_before_the_field() -> NormStart {
    NormStart::FirstObservation
}

/// `[0.0]`: evaluation without rotation.
fn default_eval_rotations() -> Vec<f64> {
    vec![0.0]
}

/// A command-line value as TOML: numbers, booleans, arrays as written, anything else as a
/// string (so `--set model=shnn` needs no quotes).
fn parse_override(value: &str) -> toml::Value {
    let doc = format!("v = {value}");
    match doc.parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(value.into())),
        Err(_) => toml::Value::String(value.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_paper_matches_the_reference() {
        for env in ["team_reach/1_ant", "team_sumo/2_ants"] {
            for p in [Preset::Quick, Preset::Paper] {
                TrainConfig::preset(p, env).validate("test").unwrap();
            }
        }
        let p = TrainConfig::preset(Preset::Paper, "team_reach/1_ant");
        assert_eq!(p.steps_per_iteration(), 163_840);
        assert_eq!(p.unrolls_per_iteration(), 16);
        assert_eq!(TrainConfig::preset(Preset::Paper, "team_sumo/2_ants").batch_size, 128);
    }

    #[test]
    fn overrides_and_round_trip() {
        let ov = vec![("num_envs".to_string(), "128".to_string()), ("model".to_string(), "mlp_hn".to_string())];
        let c = TrainConfig::resolve(Some(Preset::Paper), None, &ov).unwrap();
        assert_eq!(c.num_envs, 128);
        assert_eq!(c.model, "mlp_hn");
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back, c);
    }

    /// Found by the property test `a_configuration_survives_its_toml_file`: a configuration
    /// built in Rust with a seed or step count above `i64::MAX` validated, was written to
    /// config.toml, and could not be read back ("u64 value was too large"), so the run could
    /// neither resume nor be evaluated. Validation now refuses it, naming the field.
    #[test]
    fn integers_beyond_toml_are_refused_before_anything_is_written() {
        for field in ["seed", "steps", "epochs", "checkpoint_every"] {
            let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
            match field {
                "seed" => c.seed = 1 << 63,
                "steps" => c.steps = u64::MAX,
                "epochs" => c.epochs = usize::MAX,
                _ => c.checkpoint_every = usize::MAX,
            }
            let e = c.validate("test").unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("signed 64-bit"), "{e}");
        }
        let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
        c.seed = i64::MAX as u64;
        c.validate("test").unwrap();
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back.seed, i64::MAX as u64);
    }

    #[test]
    fn bad_values_name_the_field() {
        let cases = [
            ("num_envs", "0", "num_envs"),
            ("env", "team_reach/no_such", "env"),
            ("model", "resnet", "model"),
            ("discount", "1.5", "discount"),
            ("num_envs", "\"many\"", "num_envs"),
            ("colour", "3", "colour"),
            ("num_envs", "100", "num_envs"),
            ("eval_rotations", "[180.0]", "eval_rotations"),
            ("eval_rotations", "[]", "eval_rotations"),
            ("eval_rotations", "[0.0, 90.0, 90.0]", "90 appears twice"),
            ("eval_rotations", "[0.0, nan]", "finite"),
            ("batch_size", "4611686018427387904", "batch_size"),
            ("batch_size", "1099511627776", "16777216"),
            ("unroll_length", "18446744073709551615", "unroll_length"),
            ("eval_episodes", "18446744073709551615", "eval_episodes"),
            ("entropy", "gaussian", "entropy"),
        ];
        for (field, value, named) in cases {
            let e = TrainConfig::resolve(None, None, &[(field.to_string(), value.to_string())]).unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains(named), "{field}={value}: {msg}");
        }
    }

    #[test]
    fn files_written_before_the_later_fields_load_with_their_defaults() {
        let c = TrainConfig::preset(Preset::Paper, "team_reach/1_ant");
        assert!(!c.eval_deterministic, "the paper preset samples in evaluation, as the release");
        assert!(TrainConfig::preset(Preset::Quick, "team_reach/1_ant").eval_deterministic);
        assert_eq!(c.entropy, EntropyKind::TanhNormal);
        assert_eq!(c.obs_norm_start, NormStart::Empty, "the release's normaliser starts empty");
        let text: String = c
            .to_toml()
            .lines()
            .filter(|l| {
                !l.starts_with("eval_rotations") && !l.starts_with("entropy =") && !l.starts_with("obs_norm_start")
            })
            .map(|l| format!("{l}\n"))
            .collect();
        let dir = std::env::temp_dir().join(format!("meben-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("config.toml");
        std::fs::write(&path, text).unwrap();
        let back = TrainConfig::load(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(back.eval_rotations, [0.0]);
        assert_eq!(back.entropy, EntropyKind::Normal, "old runs trained with the Normal entropy");
        assert_eq!(back.obs_norm_start, NormStart::FirstObservation, "old runs started from the first observations");
        assert_eq!(
            back,
            TrainConfig { entropy: EntropyKind::Normal, obs_norm_start: NormStart::FirstObservation, ..c }
        );
    }
}
