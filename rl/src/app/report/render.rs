//! The report's rendering: `report.md` (a table per environment, with its curves),
//! `report.csv` (a line per group) and the curves' SVG plots ([`LinePlot`]), from the groups
//! [`super::aggregate`] made.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::aggregate::{CurvePoint, GroupReport};
use super::stats::BOOTSTRAP_RESAMPLES;
use crate::app::names::sanitize_component;
use crate::app::plot::LinePlot;

/// The environments of `groups`, in the groups' order.
pub fn envs_in_order(groups: &[GroupReport]) -> Vec<&str> {
    let mut envs: Vec<&str> = Vec::new();
    for g in groups {
        if !envs.contains(&g.env.as_str()) {
            envs.push(&g.env);
        }
    }
    envs
}

fn metric_title(sumo: bool) -> &'static str {
    if sumo { "win % (team 0)" } else { "success %" }
}

/// The learning curves of the groups of `env`, one series per rate (with its ± s.e. band).
pub fn curve_plot(env: &str, groups: &[GroupReport]) -> LinePlot {
    let sumo = env.starts_with("team_sumo");
    let y_label = if sumo { "win / loss / draw % (team 0)" } else { metric_title(sumo) };
    let mut plot = LinePlot::new(env).x_label("env steps").y_label(y_label).y_range(0.0, 100.0);
    for g in groups.iter().filter(|g| g.env == env) {
        let mut name = format!("{} (n={})", g.label, g.runs.len());
        if g.from_train {
            name.push_str(" [train]");
        }
        let series: Vec<(String, &[CurvePoint])> = if sumo {
            vec![
                (format!("{name} win"), g.curve.as_slice()),
                (format!("{name} loss"), g.curve_lose.as_slice()),
                (format!("{name} draw"), g.curve_draw.as_slice()),
            ]
        } else {
            vec![(name, g.curve.as_slice())]
        };
        for (name, curve) in series {
            let points = curve.iter().map(|p| (p.env_steps, p.mean)).collect();
            let band = curve.iter().map(|p| (p.mean - p.se, p.mean + p.se)).collect();
            plot = plot.series_with_band(name, points, band);
        }
    }
    plot
}

/// `12.5M`, `800k`, `999`.
fn format_steps(steps: u64) -> String {
    let s = steps as f64;
    let trim = |v: f64, d: usize| {
        let t = format!("{v:.d$}");
        if t.contains('.') { t.trim_end_matches('0').trim_end_matches('.').to_string() } else { t }
    };
    if s >= 1e9 {
        format!("{}G", trim(s / 1e9, 2))
    } else if s >= 1e6 {
        format!("{}M", trim(s / 1e6, 2))
    } else if s >= 1e3 {
        format!("{}k", trim(s / 1e3, 1))
    } else {
        steps.to_string()
    }
}

/// The env steps reached, with ` of <budget>` when a run stopped short of its budget (the
/// last iteration may overshoot `steps`, never fall short, in a finished run).
fn steps_range(g: &GroupReport) -> String {
    let (lo, hi) = g.env_steps;
    let reached = if lo == hi { format_steps(lo) } else { format!("{}–{}", format_steps(lo), format_steps(hi)) };
    if lo < g.target_steps { format!("{reached} of {}", format_steps(g.target_steps)) } else { reached }
}

/// Each seed's final value and where it was measured: `seed 0: 12.50 (3M); seed 1: ...`.
fn per_seed_cell(g: &GroupReport) -> String {
    let cells: Vec<String> = g
        .seed_list
        .iter()
        .zip(&g.finals)
        .zip(&g.final_steps)
        .map(|((seed, value), &steps)| format!("seed {seed}: {value:.2} ({})", format_steps(steps)))
        .collect();
    cells.join("; ")
}

/// The machine-time cell: hours with one decimal, or "same runs" on a rotated row.
fn machine_hours_cell(g: &GroupReport) -> String {
    if g.rotation_deg == 0.0 { format!("{:.1}", g.machine_hours) } else { "(same runs)".into() }
}

/// `s` fit for a Markdown table cell: `|` escaped, a line break (which would end the row)
/// a space.
pub(crate) fn md_cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\r', '\n'], " ")
}

/// `n` followed by `noun`, plural unless `n` is 1: "1 run", "3 runs".
pub(crate) fn count(n: usize, noun: &str) -> String {
    if n == 1 { format!("1 {noun}") } else { format!("{n} {noun}s") }
}

/// `report.md`: the runs under `root` in `groups`, and those `pending` without a value yet;
/// with `at_steps`, a report at that budget ([`super::report_at`]), which its heading says.
pub fn render_markdown(
    root: &Path,
    at_steps: Option<u64>,
    groups: &[GroupReport],
    pending: &[(PathBuf, String)],
) -> String {
    let mut md = String::new();
    let runs: usize = groups.iter().map(|g| g.runs.len()).sum();
    match at_steps {
        None => {
            let _ = writeln!(md, "# Report: `{}`\n", root.display());
        }
        Some(steps) => {
            let _ = writeln!(
                md,
                "# Report: `{}` at {steps} env steps\n\nEvery run as it stood after {steps} env steps \
                 (`meben report --at-steps {steps}`): its rows of `metrics.csv` up to then, its budget at most \
                 {steps}; the rows after them are left out of every figure and curve below.\n",
                root.display()
            );
        }
    }
    let _ = writeln!(
        md,
        "{} in {}. Final value of a run: its metric in the last row of `metrics.csv` that has it \
         (Team Reach `eval_success_rate`, Team Sumo `eval_win_rate_t0`, `eval_win_rate_t1` and `eval_draw_rate`), \
         in percent; \
         mean ± standard error over seeds (sample standard deviation / √n; 0 for one seed); IQM: the \
         interquartile mean over seeds (rliable's: the mean once a quarter of the seeds is cut from each end, \
         the plain mean below 4 seeds); 95% CI: percentile bootstrap over seeds ({} resamples, a fixed seed). Env \
         steps: the last \
         row's, over the seeds (\"of N\": runs still short of their budget N). Curves: mean over seeds with a ± s.e. band. Rows \"rotated N°\" are \
         evaluations of the same runs with every start rotated by N degrees about the vertical (`eval_rotations`).\n",
        count(runs, "run"),
        count(groups.len(), "group"),
        BOOTSTRAP_RESAMPLES
    );
    for env in envs_in_order(groups) {
        let sumo = env.starts_with("team_sumo");
        let _ = writeln!(md, "## {env}\n");
        if sumo {
            let _ = writeln!(
                md,
                "| run | model | opponent | seeds | win % team 0 (mean ± s.e.) | win % IQM [95% CI] | \
                 win % mean's 95% CI | loss % team 0 (mean ± s.e.) | draw % (mean ± s.e.) | env steps | machine h | \
                 per seed: win % (at env steps) |"
            );
            let _ = writeln!(md, "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|");
        } else {
            let _ = writeln!(
                md,
                "| run | model | seeds | success % (mean ± s.e.) | IQM [95% CI] | mean's 95% CI | env steps | machine h \
                 | per seed: % (at env steps) |"
            );
            let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|---|");
        }
        let mut any_train = false;
        for g in groups.iter().filter(|g| g.env == env) {
            let mark = if g.from_train { " †" } else { "" };
            any_train |= g.from_train;
            let value = format!("{:.2} ± {:.2}{mark}", g.mean, g.se);
            let iqm = format!("{:.2} [{:.2}, {:.2}]{mark}", g.iqm, g.iqm_ci.0, g.iqm_ci.1);
            let ci = format!("[{:.2}, {:.2}]{mark}", g.mean_ci.0, g.mean_ci.1);
            let hours = machine_hours_cell(g);
            let per_seed = per_seed_cell(g);
            if sumo {
                let cell = |v: Option<(f64, f64)>| {
                    v.map(|(m, s)| format!("{m:.2} ± {s:.2}{mark}")).unwrap_or_else(|| "–".into())
                };
                let (lose, draw) = (cell(g.lose), cell(g.draw));
                let opponent = if g.opponent.is_empty() { "same".to_string() } else { format!("`{}`", g.opponent) };
                let _ = writeln!(
                    md,
                    "| {} | `{}` | {} | {} | {value} | {iqm} | {ci} | {lose} | {draw} | {} | {hours} | {per_seed} |",
                    md_cell(&g.label),
                    md_cell(&g.model),
                    md_cell(&opponent),
                    g.runs.len(),
                    steps_range(g)
                );
            } else {
                let _ = writeln!(
                    md,
                    "| {} | `{}` | {} | {value} | {iqm} | {ci} | {} | {hours} | {per_seed} |",
                    md_cell(&g.label),
                    md_cell(&g.model),
                    g.runs.len(),
                    steps_range(g)
                );
            }
        }
        if any_train {
            let _ = writeln!(
                md,
                "\n† at least one run has no evaluation rows: its final value is the training rate \
                 (`{}`: episodes that ended during collection), not an evaluation.",
                if sumo { "train_win_rate_t0`, `train_win_rate_t1`, `train_draw_rate" } else { "train_success_rate" }
            );
        }
        let _ = writeln!(md, "\n![{env}](curves/{}.svg)\n", sanitize_component(env));
    }
    // Rust's float `sum` of nothing is -0.0; the report says 0.0.
    let total: f64 = 0.0 + groups.iter().map(|g| g.machine_hours).sum::<f64>();
    let _ = writeln!(
        md,
        "Machine time: {total:.1} h over the {} above (each run's last `wall_s`, summed; the threads \
         of each run are in its `config.toml`).\n",
        count(groups.iter().filter(|g| g.rotation_deg == 0.0).map(|g| g.runs.len()).sum::<usize>(), "run")
    );
    if !pending.is_empty() {
        let _ = writeln!(md, "## Runs without a result yet\n");
        for (dir, reason) in pending {
            let _ = writeln!(md, "- `{}`: {reason}", dir.display());
        }
        md.push('\n');
    }
    md
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

/// `report.csv`: a line per group.
pub fn render_csv(groups: &[GroupReport]) -> String {
    let mut out = String::from(
        "env,model,opponent,variant,metric,seeds,seed_list,mean_pct,se_pct,draw_mean_pct,draw_se_pct,\
         env_steps_min,env_steps_max,rotation_deg,lose_mean_pct,lose_se_pct,machine_hours,iqm_pct,iqm_ci_low_pct,\
         iqm_ci_high_pct,mean_ci_low_pct,mean_ci_high_pct\n",
    );
    for g in groups {
        let seeds: Vec<String> = g.seed_list.iter().map(|s| s.to_string()).collect();
        let (dm, ds) = g.draw.map(|(m, s)| (m.to_string(), s.to_string())).unwrap_or_default();
        let (lm, ls) = g.lose.map(|(m, s)| (m.to_string(), s.to_string())).unwrap_or_default();
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{dm},{ds},{},{},{},{lm},{ls},{},{},{},{},{},{}",
            csv_field(&g.env),
            csv_field(&g.model),
            csv_field(&g.opponent),
            csv_field(&g.variant),
            g.metric,
            g.runs.len(),
            seeds.join(" "),
            g.mean,
            g.se,
            g.env_steps.0,
            g.env_steps.1,
            g.rotation_deg,
            g.machine_hours,
            g.iqm,
            g.iqm_ci.0,
            g.iqm_ci.1,
            g.mean_ci.0,
            g.mean_ci.1
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_are_shown_short() {
        assert_eq!(format_steps(50_000_000), "50M");
        assert_eq!(format_steps(2_457_600), "2.46M");
        assert_eq!(format_steps(81_920), "81.9k");
    }
}
