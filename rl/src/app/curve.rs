//! The learning curve of one run, `curve.svg`, drawn from its metrics after every evaluation:
//! the evaluation success rate (Team Reach) or the win and draw rates (Team Sumo) against
//! environment steps, with the training episodes' rate beside it, pooled over windows of
//! iterations (before every environment has had the time to finish one episode, only early
//! endings, i.e. successes, are seen: those windows are left out), and one more evaluation
//! series per further rotation of `eval_rotations` (`eval_success_rate_rot180`, ...).

use crate::app::metrics::{eval_column, read_csv, rotations_of};
use crate::app::plot::LinePlot;
use crate::app::run_dir::RunDir;
use crate::error::Result;

/// Redraws `run`'s learning curve from its `metrics.csv`.
pub fn write_run_curve(run: &RunDir) -> Result<()> {
    let rows = read_csv(&run.metrics())?;
    let series = |col: &str| -> Vec<(f64, f64)> {
        rows.iter().filter_map(|r| Some((r.get("env_steps").copied()?, 100.0 * r.get(col).copied()?))).collect()
    };
    // Training episodes pooled over about 40 windows, from the end of the first episode.
    let first_end = crate::TrainConfig::load(&run.config())
        .ok()
        .and_then(|c| Some(c.num_envs as f64 * envs::tasks::TaskSpec::from_name(&c.env).ok()?.episode_steps as f64))
        .unwrap_or(0.0);
    let pooled = |col: &str| -> Vec<(f64, f64)> {
        let used: Vec<_> = rows.iter().filter(|r| r.get("env_steps").copied().unwrap_or(0.0) >= first_end).collect();
        let width = used.len().div_ceil(40).max(1);
        used.chunks(width)
            .filter_map(|w| {
                let (mut eps, mut hits) = (0.0, 0.0);
                for r in w {
                    let n = r.get("train_episodes").copied().unwrap_or(0.0);
                    if let Some(rate) = r.get(col) {
                        eps += n;
                        hits += rate * n;
                    }
                }
                let x = w.last()?.get("env_steps").copied()?;
                (eps > 0.0).then(|| (x, 100.0 * hits / eps))
            })
            .collect()
    };
    let sumo = rows.iter().any(|r| r.contains_key("train_win_rate_t0") || r.contains_key("eval_win_rate_t0"));
    // Evaluations at further rotations (`eval_rotations`): one series each.
    let base = if sumo { "eval_win_rate_t0" } else { "eval_success_rate" };
    let rotated: Vec<f64> = rotations_of(base, rows.iter().flat_map(|r| r.keys().map(|k| k.as_str())))
        .into_iter()
        .filter(|&d| d != 0.0)
        .collect();
    let title = run.root().file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut plot = LinePlot::new(title).x_label("environment steps").y_label("rate (%)").y_range(0.0, 100.0);
    if sumo {
        plot = plot
            .series("eval win team 0", series("eval_win_rate_t0"))
            .series("eval win team 1", series("eval_win_rate_t1"))
            .series("eval draw", series("eval_draw_rate"))
            .series("training episodes' win team 0", pooled("train_win_rate_t0"));
    } else {
        plot = plot
            .series("eval success", series("eval_success_rate"))
            .series("training episodes' success", pooled("train_success_rate"));
    }
    for deg in rotated {
        let name = if sumo { "eval win team 0" } else { "eval success" };
        plot = plot.series(format!("{name}, rotated {deg}°"), series(&eval_column(base, deg)));
    }
    nn::write_atomic(&run.curve(), plot.to_svg().as_bytes())?;
    Ok(())
}
