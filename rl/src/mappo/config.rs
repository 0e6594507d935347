//! The training configuration: every hyper-parameter of MAPPO as the reference release sets
//! it (`../shared/reference/MEBEN.md` section 6), and the run's other settings (environment,
//! models, evaluations, checkpoints), each checked by [`TrainConfig::validate`]. The presets
//! and the layers a configuration is resolved from are the application's
//! ([`crate::app::presets`]); the resolved configuration is written to the run directory as
//! `config.toml` ([`TrainConfig::save`]), and a run is resumed and evaluated from it
//! ([`TrainConfig::load`]). Configuration files are read here, of bounded size
//! ([`read_config_text`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};
use crate::mappo::assignment_hold::HoldRule;
use crate::mappo::device::ActDevice;

/// The most env steps of one iteration (`batch_size * num_minibatches * unroll_length`):
/// 100 times the paper's 163 840, and small enough that the checked products never overflow.
pub const MAX_STEPS_PER_ITERATION: u64 = 1 << 24;

/// Which observation normaliser to use (module [`crate::mappo::normalizer`] has the maths). Every
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
    pub fn resolve(self) -> crate::mappo::normalizer::NormKind {
        use crate::mappo::normalizer::NormKind;
        match self {
            ObsNormKind::Auto | ObsNormKind::Invariant => NormKind::Invariant,
            ObsNormKind::Elementwise => NormKind::Elementwise,
            ObsNormKind::None => NormKind::Identity,
        }
    }
}

/// Which entropy the loss's bonus uses (module [`crate::mappo::ppo`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EntropyKind {
    /// The presets' choice: the reference release's, Brax's `NormalTanhDistribution.entropy`,
    /// the Normal's entropy plus the tanh log-Jacobian at one reparameterised sample per
    /// action dimension ([`models::distribution::tanh_normal_entropy`]), its noise drawn
    /// from a stream per minibatch ([`crate::mappo::seeding::minibatch_stream`]).
    TanhNormal,
    /// The Normal part's entropy alone (no sample).
    Normal,
}

/// How the update's policy gradient reaches a learned task assignment's scorer (module
/// [`crate::mappo::ppo`], [`TrainConfig::assignment_gradient`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AssignmentGradient {
    /// Issue 79's formulation: `ln π(σ | s)` of the drawn `σ` joins the action's in the PPO
    /// ratio, a one-sample (score-function) estimate.
    #[default]
    Sampled,
    /// At each step that draws, the exact expectation over every assignment `σ'` the scorer
    /// can draw, `Σ_σ' π(σ' | s) (V(s, σ') − b(s))`, with the values of a critic that reads
    /// the held assignment (`assign_critic=held`); the drawn `σ`'s factor stays in the
    /// ratio without a gradient. No sampling noise in `σ`.
    Expected,
    /// A draw held for an episode is credited with the episode's undiscounted return: when
    /// the episode ends (iterations after its draw), `ln π(σ | s_0)` of its draw joins a
    /// clipped surrogate of its own, its advantage the return's standard score among the
    /// episodes that ended in the same iteration ([`crate::mappo::episode_credit`]); the
    /// drawn `σ`'s factor stays in the per-step ratio without a gradient. Only with
    /// `assignment_hold_episode = true`.
    Episode,
}

/// Where the observation normaliser's statistics start (module [`crate::mappo::normalizer`]).
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

/// Where training episodes begin when `fixed_start` is off.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainStarts {
    /// A fresh random start every episode (the presets; MEBEN.md section 8 counts the
    /// release's reset among the weak points this library fixes).
    #[default]
    Fresh,
    /// The reference release's reset (Brax v1's `AutoResetWrapper`): every environment slot
    /// begins each episode from the start it drew first, so training sees `num_envs` starts
    /// in all ([`envs::tasks::StartMode::PerSlot`]). Evaluations draw fresh starts either
    /// way, as the release's evaluator does.
    PerSlot,
}

impl TrainStarts {
    /// Whether this is the default (the field is then left out of `config.toml`, so the
    /// files of runs that do not use it read as before, also in earlier builds).
    pub fn is_fresh(&self) -> bool {
        *self == TrainStarts::Fresh
    }
}

/// Everything that defines a training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Environment name (`envs::tasks::BUILTIN_NAMES` or a custom composition).
    pub env: String,
    /// Model of team 0, with options: `shnn` or `shnn:assignment=hungarian;seed=3`
    /// (`models::ModelDescription::parse`).
    pub model: String,
    /// Model of team 1 in Team Sumo (default: the same as `model`); must be empty for Reach.
    pub opponent: String,
    /// Seed of everything random in the run.
    pub seed: u64,
    /// Every episode starts from the same start (drawn from `seed`) instead of a fresh random
    /// one: the training of the paper's equivariance test (evaluate with `--rotate`).
    pub fixed_start: bool,
    /// Where training episodes begin without `fixed_start`: `fresh` (default) or `per_slot`
    /// (the reference release's reset, [`TrainStarts::PerSlot`]). Written to `config.toml`
    /// only when not `fresh`.
    #[serde(default, skip_serializing_if = "TrainStarts::is_fresh")]
    pub train_starts: TrainStarts,
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
    /// The weight `s` of a learned task assignment's entropy in the bonus, relative to the
    /// action's: the bonus is `c_H (H(u) + s H(sigma))` ([`crate::mappo::ppo::loss`]). 1 (the
    /// default) is issue 79's formulation, the assignment a factor of the policy like the
    /// action; 0 leaves the assignment out of the bonus. Only with a model of
    /// `assignment=learned`; written to `config.toml` only when not 1, so earlier files read
    /// as before.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub assignment_entropy_scale: f64,
    /// The env steps of a learned task assignment's warm-up, `W` (0, the default: none).
    /// While a run's env steps are below `W` its learned assignments act as the paper's greedy
    /// rule (Algorithm 1, the scorer unused: no `ln π(σ | s)` in the ratio, no entropy of σ in
    /// the bonus, the scorer's parameters unchanged), so that the policy first learns to act on
    /// its assignment; from the first iteration that starts at or past `W`, the scorer's
    /// draws. Evaluations and checkpoints follow the env steps they are taken at. Only with a
    /// model of `assignment=learned`; written to `config.toml` only when set.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub assignment_warmup_steps: u64,
    /// A learned task assignment is drawn every `k` control steps and held in between (1,
    /// the default: drawn afresh at every step). Each iteration's collection draws at its
    /// steps `0, k, 2k, ..` of every environment (an iteration begins with a draw, so no
    /// assignment outlives a checkpoint); `ln π(σ | s)` joins the PPO ratio and `H(σ)` the
    /// bonus only at the steps that draw, and a held step's action is `π(a | s, σ)` of the
    /// held `σ`. Evaluations draw at their episodes' steps `0, k, 2k, ..`. In a warm-up the
    /// assignment is Algorithm 1's at every step. Only with a model of `assignment=learned`;
    /// written to `config.toml` only when not 1.
    #[serde(default = "one_step", skip_serializing_if = "is_one_step")]
    pub assignment_hold_steps: u64,
    /// A learned task assignment is drawn at the first step of each environment's episode
    /// and held to its end (`false`, the default: as `assignment_hold_steps` says), as the
    /// paper's greedy rule keeps one assignment through an episode when nothing moves.
    /// `ln π(σ | s)` joins the PPO ratio and `H(σ)` the bonus at the step that draws; the
    /// held assignments outlive an iteration, so checkpoints keep them. Evaluations draw at
    /// their episodes' first steps. In a warm-up the assignment is Algorithm 1's at every
    /// step. Only with a model of `assignment=learned` and `assignment_hold_steps = 1`;
    /// written to `config.toml` only when set.
    #[serde(default, skip_serializing_if = "is_false")]
    pub assignment_hold_episode: bool,
    /// How the policy gradient reaches a learned task assignment's scorer: `sampled` (the
    /// default, issue 79's formulation: the drawn assignment's log-probability in the PPO
    /// ratio) or `expected` (the exact expectation over every assignment at each step that
    /// draws, valued by a critic that reads the held assignment: docs/TRAINING.md). Only with
    /// a model of `assignment=learned;assign_critic=held`; or `episode` (each draw held for
    /// an episode credited with that episode's undiscounted return: docs/TRAINING.md; only
    /// with `assignment_hold_episode = true`). Written to `config.toml` only when set.
    #[serde(default, skip_serializing_if = "is_sampled")]
    pub assignment_gradient: AssignmentGradient,
    /// The value that reads the held assignment (`assign_critic=held`) reads it at the
    /// steps that draw too, as the drawn `σ` (`false`, the default: it reads none there,
    /// `V(s_t)`), so that `V(s_t, σ)` is fitted to the drawn `σ`'s return where the expected
    /// assignment gradient reads `V(s_t, σ')` (docs/TRAINING.md). Only with
    /// `assignment_gradient = "expected"`: the sampled gradient's advantage of a draw would
    /// subtract the drawn `σ`'s own value. Written to `config.toml` only when set.
    #[serde(default, skip_serializing_if = "is_false")]
    pub assignment_value_at_draw: bool,
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
    /// [`crate::app::metrics::eval_column`]). With random starts every drawn start is rotated.
    /// `[0.0, 180.0]` is the paper's equivariance test (with `fixed_start = true`). Default
    /// `[0.0]` (also for files written before the field existed).
    #[serde(default = "default_eval_rotations")]
    pub eval_rotations: Vec<f64>,
    /// Write a checkpoint every this many iterations (and after every evaluation and at the
    /// end; 0: only then).
    pub checkpoint_every: usize,
    /// Worker threads (0: every core). Results do not depend on it. Training refuses more
    /// than [`crate::app::run::max_threads`] (4 per core, at least 64).
    pub threads: usize,
    /// Where the updates run: `cpu` (default) or `gpu` (a build with the feature `gpu`;
    /// [`crate::mappo::device`]). Like `threads`, not part of the run's identity: a run
    /// resumes on either device (GPU results differ from the CPU's by f32 rounding). Written
    /// to `config.toml` only when not `cpu`; absent from files written before it existed.
    #[serde(default, skip_serializing_if = "crate::mappo::device::is_cpu", with = "crate::mappo::device")]
    pub device: tensor::Device,
    /// Where the act step of collection runs ([`ActDevice`]): `same` (default: on
    /// `device`) or `cpu`. Like `device`, not part of the run's identity. Written to
    /// `config.toml` only when not `same`.
    #[serde(default, skip_serializing_if = "ActDevice::is_same")]
    pub act_device: ActDevice,
    /// The GPU's tiled product's output rows, 64 (default) or 128 ([`tensor::GpuConfig`]):
    /// the same bits either way, a speed choice. Like `device`, not part of the run's
    /// identity; written to `config.toml` only when not 64.
    #[serde(default = "default_gpu_matmul_tile", skip_serializing_if = "is_default_gpu_matmul_tile")]
    pub gpu_matmul_tile: usize,
    /// The most GPU threads that share one reduction output, a power of two from 1 to 256
    /// (default 256; [`tensor::GpuConfig`]). It fixes the order of the GPU's sums, so a GPU
    /// run's bits depend on it; written to `config.toml` when not 256. Not part of the
    /// run's identity (GPU runs differ from CPU runs by rounding anyway).
    #[serde(default = "default_gpu_reduce_lanes", skip_serializing_if = "is_default_gpu_reduce_lanes")]
    pub gpu_reduce_lanes: u32,
}

/// [`TrainConfig::gpu_matmul_tile`]'s default.
fn default_gpu_matmul_tile() -> usize {
    tensor::GpuConfig::default().matmul_tile.rows()
}

/// Whether the tile is the default (left out of `config.toml`).
fn is_default_gpu_matmul_tile(rows: &usize) -> bool {
    *rows == default_gpu_matmul_tile()
}

/// [`TrainConfig::gpu_reduce_lanes`]'s default.
fn default_gpu_reduce_lanes() -> u32 {
    tensor::GpuConfig::default().reduce_lanes
}

/// Whether the lanes are the default (left out of `config.toml`).
fn is_default_gpu_reduce_lanes(lanes: &u32) -> bool {
    *lanes == default_gpu_reduce_lanes()
}

impl TrainConfig {
    /// Reads a resolved configuration written by [`TrainConfig::save`] (a run's
    /// `config.toml`); every field must be present.
    pub fn load(path: &Path) -> Result<TrainConfig> {
        let text = read_config_text(path)?;
        let config: TrainConfig =
            toml::from_str(&text).map_err(|e| RlError::file(path, format!("invalid run configuration: {e}")))?;
        config.validate(&path.display().to_string())?;
        Ok(config)
    }

    /// Every field as a TOML table, including those `config.toml` leaves out at their
    /// default (`train_starts`, `device`): the fields a preset, a file or `--set` may name.
    pub fn to_full_table(&self) -> toml::Table {
        let mut table =
            toml::Table::try_from(self).unwrap_or_else(|e| unreachable!("a TrainConfig always serialises: {e}"));
        let starts = toml::Value::try_from(self.train_starts)
            .unwrap_or_else(|e| unreachable!("a TrainStarts always serialises: {e}"));
        table.entry("train_starts").or_insert(starts);
        table.entry("assignment_entropy_scale").or_insert(toml::Value::Float(self.assignment_entropy_scale));
        table.entry("assignment_warmup_steps").or_insert(toml::Value::Integer(self.assignment_warmup_steps as i64));
        table.entry("assignment_hold_steps").or_insert(toml::Value::Integer(self.assignment_hold_steps as i64));
        table.entry("assignment_hold_episode").or_insert(toml::Value::Boolean(self.assignment_hold_episode));
        table.entry("assignment_gradient").or_insert_with(|| toml::Value::String("sampled".into()));
        table.entry("assignment_value_at_draw").or_insert(toml::Value::Boolean(self.assignment_value_at_draw));
        table.entry("device").or_insert_with(|| toml::Value::String(self.device.name().into()));
        table.entry("act_device").or_insert_with(|| toml::Value::String(self.act_device.name().into()));
        table.entry("gpu_matmul_tile").or_insert_with(|| toml::Value::Integer(self.gpu_matmul_tile as i64));
        table.entry("gpu_reduce_lanes").or_insert_with(|| toml::Value::Integer(i64::from(self.gpu_reduce_lanes)));
        table
    }

    /// The GPU's kernel choices this configuration asks for; an error naming `source`, the
    /// field and the value when one is out of range.
    pub fn gpu_config(&self, source: &str) -> Result<tensor::GpuConfig> {
        let matmul_tile = tensor::MatMulTile::from_rows(self.gpu_matmul_tile).map_err(|_| {
            RlError::config(source, "gpu_matmul_tile", self.gpu_matmul_tile.to_string(), "must be 64 or 128")
        })?;
        let config = tensor::GpuConfig { matmul_tile, reduce_lanes: self.gpu_reduce_lanes };
        config.validate().map_err(|_| {
            RlError::config(
                source,
                "gpu_reduce_lanes",
                self.gpu_reduce_lanes.to_string(),
                "must be a power of two from 1 to 256",
            )
        })?;
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

    /// How evaluation episodes start: the fixed start of `seed`, or fresh random starts.
    pub fn start_mode(&self) -> envs::tasks::StartMode {
        if self.fixed_start { envs::tasks::StartMode::fixed(self.seed) } else { envs::tasks::StartMode::Random }
    }

    /// How training episodes start: the fixed start of `seed`, fresh random starts, or
    /// (`train_starts = "per_slot"`) each environment's first start again.
    pub fn train_start_mode(&self) -> envs::tasks::StartMode {
        match (self.fixed_start, self.train_starts) {
            (true, _) => envs::tasks::StartMode::fixed(self.seed),
            (false, TrainStarts::Fresh) => envs::tasks::StartMode::Random,
            (false, TrainStarts::PerSlot) => envs::tasks::StartMode::PerSlot,
        }
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
        let mut learns_an_assignment = false;
        let mut value_reads_held = false;
        for (field, spec) in [("model", &self.model), ("opponent", &self.opponent)] {
            if field == "opponent" && spec.is_empty() {
                continue;
            }
            // Parsed and resolved: an option the model does not take fails here, not at build.
            let d = models::ModelDescription::parse(spec)
                .map_err(|e| RlError::config(source, field, spec, e.to_string()))?;
            let learns = d.assignment().is_some_and(|a| a.method == models::AssignmentMethod::Learned);
            learns_an_assignment |= learns;
            value_reads_held |= d.value_reads_held();
            // Every team that learns its assignment values the support with its held critic.
            if self.assignment_gradient == AssignmentGradient::Expected && learns && !d.value_reads_held() {
                return Err(RlError::config(
                    source,
                    field,
                    spec,
                    "assignment_gradient = \"expected\" values every assignment with a critic that reads the held \
                     assignment: add assign_critic=held",
                ));
            }
            // The update tells the value which steps hold their assignment by the episode
            // ends (Minibatch::held_assignment), which is the hold of a whole episode.
            if d.value_reads_held() && !self.assignment_hold_episode {
                return Err(RlError::config(
                    source,
                    field,
                    spec,
                    "assign_critic=held reads the assignment held for an episode: set assignment_hold_episode = true",
                ));
            }
        }
        self.validate_except_models(source)?;
        let models = || {
            if self.opponent.is_empty() {
                format!("the model `{}` does not", self.model)
            } else {
                format!("neither `{}` nor `{}` does", self.model, self.opponent)
            }
        };
        if !is_one(&self.assignment_entropy_scale) && !learns_an_assignment {
            return Err(RlError::config(
                source,
                "assignment_entropy_scale",
                self.assignment_entropy_scale.to_string(),
                format!("weighs a learned task assignment's entropy, and {} learn one (assignment=learned)", models()),
            ));
        }
        if self.assignment_warmup_steps != 0 && !learns_an_assignment {
            return Err(RlError::config(
                source,
                "assignment_warmup_steps",
                self.assignment_warmup_steps,
                format!("is a learned task assignment's warm-up, and {} learn one (assignment=learned)", models()),
            ));
        }
        if self.assignment_gradient == AssignmentGradient::Expected && !value_reads_held {
            return Err(RlError::config(
                source,
                "assignment_gradient",
                "expected",
                format!(
                    "values every assignment with a critic that reads the held assignment, and {} have one \
                     (assignment=learned;assign_critic=held)",
                    models()
                ),
            ));
        }
        if self.assignment_value_at_draw && self.assignment_gradient != AssignmentGradient::Expected {
            return Err(RlError::config(
                source,
                "assignment_value_at_draw",
                "true",
                "fits the held critic at the drawing steps for the expected assignment gradient: set \
                 assignment_gradient = \"expected\" (the sampled gradient's advantage of a draw would subtract its \
                 own value)",
            ));
        }
        if self.assignment_hold_episode && !learns_an_assignment {
            return Err(RlError::config(
                source,
                "assignment_hold_episode",
                self.assignment_hold_episode,
                format!(
                    "holds a learned task assignment for an episode, and {} learn one (assignment=learned)",
                    models()
                ),
            ));
        }
        if self.assignment_hold_steps != 1 && !learns_an_assignment {
            return Err(RlError::config(
                source,
                "assignment_hold_steps",
                self.assignment_hold_steps,
                format!(
                    "holds a learned task assignment for that many steps, and {} learn one (assignment=learned)",
                    models()
                ),
            ));
        }
        Ok(())
    }

    /// How long a learned task assignment is held at `env_steps`: 1 step (drawn at every
    /// step) in its warm-up, where it is Algorithm 1's, else an episode
    /// ([`TrainConfig::assignment_hold_episode`]) or [`TrainConfig::assignment_hold_steps`].
    pub fn assignment_hold_at(&self, env_steps: u64) -> HoldRule {
        if self.assignment_warmup_at(env_steps) {
            HoldRule::Steps(1)
        } else if self.assignment_hold_episode {
            HoldRule::Episode
        } else {
            HoldRule::Steps(self.assignment_hold_steps as usize)
        }
    }

    /// Whether a learned task assignment is in its warm-up at `env_steps`
    /// ([`TrainConfig::assignment_warmup_steps`]).
    pub fn assignment_warmup_at(&self, env_steps: u64) -> bool {
        env_steps < self.assignment_warmup_steps
    }

    /// [`TrainConfig::validate`] but for `model` and `opponent` naming models of the zoo: a
    /// run whose policies a `models::PolicyFactory` builds
    /// ([`crate::mappo::trainer::Trainer::with_policies`]) names its own.
    pub fn validate_except_models(&self, source: &str) -> Result<()> {
        let err =
            |field: &str, value: &dyn ToString, msg: &str| Err(RlError::config(source, field, value.to_string(), msg));
        envs::tasks::TaskSpec::from_name(&self.env)
            .map_err(|e| RlError::config(source, "env", &self.env, e.to_string()))?;
        if !self.opponent.is_empty() && !self.is_sumo() {
            return err("opponent", &self.opponent, "only Team Sumo has a second team");
        }
        self.gpu_config(source)?;
        if self.fixed_start && self.train_starts != TrainStarts::Fresh {
            return err(
                "train_starts",
                &"per_slot",
                "with fixed_start = true every episode begins at the one fixed start: leave train_starts unset",
            );
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
        if self.assignment_hold_steps == 0 {
            return err(
                "assignment_hold_steps",
                &0,
                "must be at least 1 (1: a learned assignment drawn at every step)",
            );
        }
        if self.assignment_hold_episode && self.assignment_hold_steps != 1 {
            return err(
                "assignment_hold_steps",
                &self.assignment_hold_steps,
                "must be 1 with assignment_hold_episode = true (a draw is held for its episode)",
            );
        }
        if self.assignment_gradient == AssignmentGradient::Episode {
            if !self.assignment_hold_episode {
                return err(
                    "assignment_gradient",
                    &"episode",
                    "credits a draw held for an episode with its return: set assignment_hold_episode = true",
                );
            }
            if self.assignment_warmup_steps != 0 {
                return err(
                    "assignment_warmup_steps",
                    &self.assignment_warmup_steps,
                    "must be 0 with assignment_gradient = \"episode\" (a warm-up's draws are Algorithm 1's, \
                     not the scorer's, and an episode may span its end)",
                );
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
            ("assignment_hold_steps", self.assignment_hold_steps),
        ] {
            if v > i64::MAX as u64 {
                return err(field, &v, "at most 9223372036854775807 (TOML integers are signed 64-bit)");
            }
        }
        if self.num_envs > envs::tasks::MAX_ENVS {
            return err("num_envs", &self.num_envs, &format!("at most {} environments", envs::tasks::MAX_ENVS));
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
        if self.eval_episodes > crate::mappo::evaluate::MAX_EPISODES {
            return err(
                "eval_episodes",
                &self.eval_episodes,
                &format!("at most {} (one environment per episode)", crate::mappo::evaluate::MAX_EPISODES),
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
            ("assignment_entropy_scale", self.assignment_entropy_scale),
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

/// 1: [`TrainConfig::assignment_entropy_scale`]'s default.
fn one() -> f64 {
    1.0
}

/// Whether a count is its default, 0 (left out of `config.toml`).
fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// [`TrainConfig::assignment_gradient`]'s default, left out of `config.toml`.
fn is_sampled(v: &AssignmentGradient) -> bool {
    *v == AssignmentGradient::Sampled
}

/// Whether a switch is off, its default (left out of `config.toml`).
fn is_false(v: &bool) -> bool {
    !*v
}

/// 1: [`TrainConfig::assignment_hold_steps`]'s default.
fn one_step() -> u64 {
    1
}

/// Whether a hold is its default, 1 step (left out of `config.toml`).
fn is_one_step(v: &u64) -> bool {
    *v == 1
}

/// Whether the scale is its default, 1 (left out of `config.toml`).
fn is_one(v: &f64) -> bool {
    *v == 1.0
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
pub(crate) fn default_eval_rotations() -> Vec<f64> {
    vec![0.0]
}

/// The largest configuration file read: 1 MiB (the built-in files are a few hundred bytes).
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// The text of a configuration file of at most [`MAX_CONFIG_BYTES`] ([`read_text_file`]).
pub fn read_config_text(path: &Path) -> Result<String> {
    read_text_file(path, MAX_CONFIG_BYTES, "a configuration file")
}

/// The text of the regular file `path` of at most `max_bytes`, else an error naming the
/// file and the limit, and saying what the file was expected to be (`what`): a file without
/// end (`--config /dev/zero`, which used to be read until memory ran out) or a FIFO (which
/// hung) is refused before it is read ([`crate::bounded_read::read_text`]).
pub fn read_text_file(path: &Path, max_bytes: u64, what: &str) -> Result<String> {
    crate::bounded_read::read_text(path, max_bytes, what)
}
