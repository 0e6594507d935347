//! `rl`: MAPPO training on the MeBen tasks (paper section 5, `../shared/reference/MEBEN.md`
//! section 6), evaluation, checkpoints, and the `meben` program.
//!
//! ```no_run
//! use rl::{RunDir, TrainConfig, TrainOptions, train};
//! let config = TrainConfig::resolve(None, None, &[("model".into(), "mlp_hn".into())]).unwrap();
//! let summary = train(&config, &RunDir::new("runs/example"), &TrainOptions::default()).unwrap();
//! println!("{summary:?}");
//! ```

pub mod config;
pub mod error;
pub mod metrics;
pub mod run_dir;
pub mod train;

pub use config::{ObsNormKind, Preset, TrainConfig};
pub use error::{Result, RlError};
pub use run_dir::{RunDir, RunStatus};
pub use train::{EvalSummary, RunSummary, TrainOptions, train};
