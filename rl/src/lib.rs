//! `rl`: MAPPO training on the MeBen tasks (paper section 5, `../shared/reference/MEBEN.md`
//! section 6), evaluation, checkpoints, and the `meben` program.
//!
//! ```no_run
//! use rl::{RunDir, TrainConfig, TrainOptions, train};
//! let config = TrainConfig::resolve(None, None, &[("model".into(), "mlp_hn".into())]).unwrap();
//! let summary = train(&config, &RunDir::new("runs/example"), &TrainOptions::default()).unwrap();
//! println!("{summary:?}");
//! ```
//!
//! One module per job: [`config`] (hyper-parameters and their layers), [`seeding`] (random
//! streams), [`normalizer`] (observation statistics), [`actor`] (a team's act step),
//! [`team`] (one team's learner), [`rollout`] (an iteration's data and minibatches), [`gae`],
//! [`ppo`] (the loss),
//! [`train`](mod@train) (the loop and the run directory), [`evaluate`](mod@evaluate), [`checkpoint`], [`metrics`],
//! [`run_dir`], [`progress`], [`curve`], [`plot`] (SVG line plots), [`sweep`] (`meben ablate`),
//! [`report`](mod@report) (`meben report`), [`export`](mod@export) (`meben export`: a run tree's
//! evidence without checkpoints), [`info`] (`meben info`: parameter counts).

pub mod actor;
pub mod checkpoint;
pub mod checksum;
pub mod config;
pub mod curve;
pub mod error;
pub mod evaluate;
pub mod export;
pub mod gae;
pub mod info;
pub mod lock;
pub mod memory;
pub mod metrics;
pub mod normalizer;
pub mod plot;
pub mod ppo;
pub mod progress;
pub mod report;
pub mod rollout;
pub mod run_dir;
pub mod seeding;
pub mod sweep;
pub mod team;
#[cfg(test)]
mod test_util;
pub mod train;

pub use config::{EntropyKind, NormStart, ObsNormKind, Preset, TrainConfig};
pub use error::{Result, RlError};
pub use evaluate::{EvalOptions, evaluate};
pub use lock::RunLock;
pub use plot::LinePlot;
pub use report::{Report, report};
pub use run_dir::{RunDir, RunStatus};
pub use sweep::{RunSelection, Shard, Sweep, SweepOutcome, SweepRun, run_sweep};
pub use team::Team;
pub use train::{EvalSummary, RunSummary, TrainOptions, Trainer, train};
