//! The learning curve of one run, `curve.svg`, drawn from its metrics after every evaluation:
//! the evaluation success rate (Team Reach) or the win and draw rates (Team Sumo) against
//! environment steps, with the training episodes' rate beside it.

use crate::error::{Result, RlError};
use crate::metrics::parse_csv;
use crate::plot::LinePlot;
use crate::run_dir::RunDir;

/// Redraws `run`'s learning curve from its `metrics.csv`.
pub fn write_run_curve(run: &RunDir) -> Result<()> {
    let path = run.metrics();
    let text = std::fs::read_to_string(&path).map_err(|e| RlError::file(&path, format!("cannot read: {e}")))?;
    let rows = parse_csv(&text).map_err(|e| RlError::file(&path, e))?;
    let series = |col: &str| -> Vec<(f64, f64)> {
        rows.iter().filter_map(|r| Some((r.get("env_steps").copied()?, 100.0 * r.get(col).copied()?))).collect()
    };
    let sumo = rows.iter().any(|r| r.contains_key("train_win_rate_t0") || r.contains_key("eval_win_rate_t0"));
    let title = run.root().file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut plot = LinePlot::new(title).x_label("environment steps").y_label("rate (%)").y_range(0.0, 100.0);
    if sumo {
        plot = plot
            .series("eval win team 0", series("eval_win_rate_t0"))
            .series("eval win team 1", series("eval_win_rate_t1"))
            .series("eval draw", series("eval_draw_rate"));
    } else {
        plot = plot
            .series("eval success", series("eval_success_rate"))
            .series("train episodes' success", series("train_success_rate"));
    }
    nn::write_atomic(&run.curve(), plot.to_svg().as_bytes())?;
    Ok(())
}
