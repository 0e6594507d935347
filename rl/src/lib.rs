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
//! Two parts: [`mappo`], the algorithm (configuration, trainer, actor, rollout, GAE, PPO,
//! normaliser, evaluation, checkpoints), and [`app`], the application around it (presets,
//! the run directory, metrics, progress, curves and plots, sweeps, reports, export, render,
//! the command line); [`error`] and [`stop`] (stopping on request) are shared. `app` uses `mappo`, never the other way.

pub mod app;
pub mod bounded_read;
pub mod error;
pub mod mappo;
pub mod stop;

pub use app::presets::Preset;
pub use app::record::RunSummary;
pub use app::report::{Report, report, report_at};
pub use app::run::{TrainOptions, train};
pub use app::run_dir::{RunDir, RunStatus};
pub use app::sweep::{RunSelection, Shard, Sweep, SweepOutcome, SweepRun, run_sweep};
pub use app::{lock::RunLock, plot::LinePlot};
pub use error::{Result, RlError};
pub use mappo::config::{AssignmentGradient, EntropyKind, NormStart, ObsNormKind, TrainConfig, TrainStarts};
pub use mappo::evaluate::{EvalOptions, EvalRequest, EvalSummary, evaluate};
pub use mappo::team::Team;
pub use mappo::trainer::Trainer;
pub use stop::StopFlag;
