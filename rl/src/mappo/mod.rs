//! The algorithm: MAPPO on the MeBen tasks (paper section 5; MEBEN.md section 6: Brax PPO
//! per team), one module per job:
//! - [`config`]: the hyper-parameters and run settings ([`config::TrainConfig`]), and
//!   [`config_match`]: whether two configurations are the same run (resume, sweeps);
//! - [`trainer`]: one training iteration, read top to bottom ([`trainer::Trainer::iterate`]:
//!   collect, normalise, update);
//! - [`actor`]: a team's act step (normalise, policy, sample, log-probability), used by
//!   collection, evaluation, rendering and the Python policy, and [`assignment_hold`]: a
//!   task assignment drawn every `k` steps, and [`episode_credit`]: a draw held for an
//!   episode credited with its return;
//! - [`team`]: one team's learner (model, parameters, Adam, normaliser, actor);
//! - [`rollout`]: an iteration's data, written once per step, from which the update gathers
//!   its [`minibatch`]es;
//! - [`ppo`]: the PPO loss of a minibatch, in one function (forward, [`gae`], log-probabilities
//!   and entropy, the loss, its statistics);
//! - [`normalizer`]: observation statistics; [`seeding`]: the random streams;
//! - [`evaluate`](mod@evaluate): episodes of the trained teams, and
//!   [`assignment_sensitivity`]: how much their actions depend on their task assignment,
//!   and [`assignment_values`]: the value of each assignment beside the returns;
//! - [`checkpoint`] (the exact training state) with its [`checksum`] and its tensors'
//!   [`tensor_file`] (safetensors), and [`memory`] (whether an iteration's buffers fit);
//! - [`device`]: where the updates run (`device = "cpu" | "gpu"`) and whether this build and
//!   machine have it.
//!
//! It uses nothing of the application ([`crate::app`]), tests included: it reads its
//! configuration files itself ([`config::read_config_text`]).

pub mod actor;
pub mod assignment_hold;
pub mod assignment_sensitivity;
pub mod assignment_values;
pub mod checkpoint;
pub mod checksum;
pub mod config;
pub mod config_match;
pub mod device;
pub mod episode_credit;
pub mod evaluate;
pub mod gae;
pub mod memory;
pub mod minibatch;
pub mod normalizer;
pub mod ppo;
pub mod rollout;
pub mod seeding;
pub mod team;
pub mod tensor_file;
pub mod trainer;
