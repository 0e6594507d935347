//! The training loop (placeholder signature; being written).

use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;
use crate::error::Result;
use crate::run_dir::RunDir;

/// How [`train`] runs, beyond the configuration.
#[derive(Clone, Debug, Default)]
pub struct TrainOptions {
    /// Show a progress bar on the terminal.
    pub progress: bool,
    /// Stop (with a checkpoint) after this many iterations in total, as if interrupted.
    pub stop_after: Option<u64>,
}

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
}

/// What a finished (or stopped) run reports, also written as `done.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Iterations done.
    pub iterations: u64,
    /// Environment steps collected.
    pub env_steps: u64,
    /// Wall-clock seconds of training (summed over resumed sessions).
    pub wall_s: f64,
    /// The last evaluation.
    pub final_eval: Option<EvalSummary>,
}

/// Trains `config` in `run` (starting, or resuming from its checkpoint).
pub fn train(config: &TrainConfig, run: &RunDir, options: &TrainOptions) -> Result<RunSummary> {
    let _ = (config, run, options);
    todo!("trainer being written")
}
