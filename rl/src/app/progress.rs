//! The training progress display: a bar with env steps, steps/s, the latest success (or win)
//! rate and the ETA on a terminal; a plain line per evaluation when the output is not a
//! terminal (logs, cluster jobs).

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

use crate::app::metrics::MetricsRow;
use crate::mappo::config::TrainConfig;

/// The progress display of one run.
pub struct Progress {
    bar: Option<ProgressBar>,
    lines: bool,
    sumo: bool,
    rate: Option<f64>,
}

impl Progress {
    /// A display for `config` starting at `steps` (nothing at all if `enabled` is false).
    pub fn new(enabled: bool, config: &TrainConfig, steps: u64) -> Self {
        let total = config.iterations() * config.steps_per_iteration();
        let tty = std::io::stderr().is_terminal();
        let bar = (enabled && tty).then(|| {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template("{bar:30} {human_pos}/{human_len} steps  {msg}  ETA {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b.set_position(steps);
            b
        });
        Self { bar, lines: enabled && !tty, sumo: config.is_sumo(), rate: None }
    }

    /// Shows an iteration's row.
    pub fn update(&self, row: &MetricsRow, steps: u64) {
        let sps = row.get("steps_per_s").unwrap_or(0.0);
        let (name, eval, train) = if self.sumo {
            ("win", row.get("eval_win_rate_t0"), row.get("train_win_rate_t0"))
        } else {
            ("success", row.get("eval_success_rate"), row.get("train_success_rate"))
        };
        let shown = eval
            .map(|r| format!("eval {name} {:.1}%", 100.0 * r))
            .or(train.map(|r| format!("train {name} {:.1}%", 100.0 * r)));
        let ret = row.get("train_return_t0").map(|r| format!("  return {r:.0}")).unwrap_or_default();
        let msg = format!("{sps:.0} steps/s  {}{ret}", shown.unwrap_or_else(|| format!("{name} -")));
        if let Some(b) = &self.bar {
            b.set_position(steps);
            if eval.is_some() || train.is_some() || self.rate.is_none() {
                b.set_message(msg);
            }
        } else if self.lines && eval.is_some() {
            eprintln!("iteration {} steps {steps}: {msg}", row.get("iteration").unwrap_or(0.0));
        }
    }

    /// Ends the bar.
    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish();
        }
    }
}
