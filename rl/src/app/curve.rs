//! The learning curve of one run, `curve.svg`, drawn from its metrics after every evaluation:
//! the evaluation success rate (Team Reach) or the win and draw rates (Team Sumo) against
//! environment steps, with the training episodes' rate beside it, pooled over windows of
//! iterations (before every environment has had the time to finish one episode, only early
//! endings, i.e. successes, are seen: those windows are left out), and one more evaluation
//! series per further rotation of `eval_rotations` (`eval_success_rate_rot180`, ...).

use crate::app::metrics::rotations_of;
use crate::app::plot::LinePlot;
use crate::app::record::{IterationRow, MetricsTable, Rate};
use crate::app::run_dir::RunDir;
use crate::error::Result;

/// Redraws `run`'s learning curve from its `metrics.csv`. The configuration only places the
/// end of the first episode, and is optional: a run of one's own policies
/// (`Trainer::with_policies`) has a `config.toml` whose models `TrainConfig::load` refuses.
pub fn write_run_curve(run: &RunDir) -> Result<()> {
    let rows = MetricsTable::read(&run.metrics())?.rows;
    let series = |rate: Rate, degrees: f64| -> Vec<(f64, f64)> {
        rows.iter().filter_map(|r| Some((r.env_steps as f64, 100.0 * r.eval(degrees)?.rate(rate)?))).collect()
    };
    // Training episodes pooled over about 40 windows, from the end of the first episode.
    let first_end = crate::TrainConfig::load(&run.config())
        .ok()
        .and_then(|c| Some(c.num_envs as f64 * envs::tasks::TaskSpec::from_name(&c.env).ok()?.episode_steps as f64))
        .unwrap_or(0.0);
    let pooled = |rate: Rate| -> Vec<(f64, f64)> {
        let used: Vec<&IterationRow> = rows.iter().filter(|r| r.env_steps as f64 >= first_end).collect();
        let width = used.len().div_ceil(40).max(1);
        used.chunks(width)
            .filter_map(|w| {
                let (mut eps, mut hits) = (0.0, 0.0);
                for r in w {
                    let n = r.train.episodes.unwrap_or(0) as f64;
                    if let Some(rate) = r.train.rate(rate) {
                        eps += n;
                        hits += rate * n;
                    }
                }
                let x = w.last()?.env_steps as f64;
                (eps > 0.0).then(|| (x, 100.0 * hits / eps))
            })
            .collect()
    };
    let sumo =
        rows.iter().any(|r| r.train.win_rate[0].is_some() || r.eval(0.0).is_some_and(|e| e.win_rate[0].is_some()));
    // Evaluations at further rotations (`eval_rotations`): one series each.
    let rate = if sumo { Rate::Win(0) } else { Rate::Success };
    let evaluated = rows
        .iter()
        .flat_map(|r| r.evals.iter().filter(|(_, e)| e.rate(rate).is_some()).map(|(d, _)| rate.eval_column(*d)));
    let columns: Vec<String> = evaluated.collect();
    let rotated: Vec<f64> = rotations_of(&rate.eval_column(0.0), columns.iter().map(|c| c.as_str()))
        .into_iter()
        .filter(|&d| d != 0.0)
        .collect();
    let title = run.root().file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut plot = LinePlot::new(title).x_label("environment steps").y_label("rate (%)").y_range(0.0, 100.0);
    if sumo {
        plot = plot
            .series("eval win team 0", series(Rate::Win(0), 0.0))
            .series("eval win team 1", series(Rate::Win(1), 0.0))
            .series("eval draw", series(Rate::Draw, 0.0))
            .series("training episodes' win team 0", pooled(Rate::Win(0)));
    } else {
        plot = plot
            .series("eval success", series(Rate::Success, 0.0))
            .series("training episodes' success", pooled(Rate::Success));
    }
    for deg in rotated {
        let name = if sumo { "eval win team 0" } else { "eval success" };
        plot = plot.series(format!("{name}, rotated {deg}°"), series(rate, deg));
    }
    nn::write_atomic(&run.curve(), plot.to_svg().as_bytes())?;
    Ok(())
}
