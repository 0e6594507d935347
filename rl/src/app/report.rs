//! `meben report <root>`: the results of many runs (a sweep, or any directory tree of runs)
//! as the paper reports them: a table of final success (Team Reach) or win and draw rates
//! (Team Sumo) in percent, mean ± standard error over seeds, and learning curves.
//!
//! - Every directory under the root holding `config.toml` and `metrics.csv` is a run
//!   ([`find_run_dirs`]).
//! - Runs are grouped by environment, model, opponent and *variant*: the run directory's
//!   path relative to the root with its seed component (`seed<N>`) removed, so the runs
//!   `team_reach_1_ant/shnn+no_entropy/seed{0,1,2}` of a sweep form one group.
//! - A run's final value is its metric in the last row of `metrics.csv` that has it: Team
//!   Reach `eval_success_rate`, Team Sumo `eval_win_rate_t0` (and its loss rate, team 1's
//!   `eval_win_rate_t1`, and `eval_draw_rate`). A run set not to evaluate (`num_evals = 0`)
//!   is valued by its training rate instead (`train_success_rate`, `train_win_rate_t0`,
//!   `train_win_rate_t1`, `train_draw_rate`: episodes that ended during collection); the
//!   table marks such groups. A run set to evaluate that has no evaluation yet is listed as
//!   having no result yet, not valued by its training rate: until every environment has
//!   played a whole episode only the episodes that ended early have ended (in Team Reach
//!   all of them successes), so that rate starts far too high. In a group where some runs
//!   have evaluations, the runs without one (set not to evaluate) are left out too, rather
//!   than averaged in with a training rate. A run with neither is listed as having no result yet.
//! - A run evaluated at further rotations (`eval_rotations`, e.g. `[0.0, 180.0]` for the
//!   paper's equivariance test) adds one group per rotation with values
//!   (`eval_success_rate_rot180`, `eval_win_rate_t0_rot180` and `eval_draw_rate_rot180`),
//!   labelled `<label>, rotated 180°`: its own table row, CSV line and curve, next to the
//!   unrotated group in the environment's plot.
//! - Per group: the number of seeds, the mean and the standard error (sample standard
//!   deviation / sqrt(n); 0 for one seed) of the final values, and the env steps reached
//!   (the last row's `env_steps`, min–max over the seeds), and the machine time (the sum
//!   over the runs of the last row's `wall_s`, which counts across resumes; shown once per
//!   run, on the unrotated row) with the total over all groups; and each seed's final value
//!   with the env steps it was measured at (a run still training may have trained past its
//!   last evaluation).
//! - Curves: per group, the mean over seeds with a shaded ± s.e. band (Team Sumo: one curve
//!   each for the win, loss and draw rates of team 0). Seeds are aligned on
//!   the env steps of the seed with the fewest points; every other seed contributes its
//!   value at its last row at or before each of those env steps.
//!
//! Written under the root: `report.md` (a table per environment and its curves),
//! `report.csv` (one line per group) and `curves/<env>.svg` (env name made file-name safe).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::app::metrics;
use crate::app::plot::LinePlot;
use crate::app::run_dir::RunDir;
use crate::app::sweep::sanitize_component;
use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;

/// One point of a group's learning curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurvePoint {
    /// Env steps.
    pub env_steps: f64,
    /// Mean over the seeds, in percent.
    pub mean: f64,
    /// Standard error over the seeds, in percent.
    pub se: f64,
    /// Seeds with a value at or before this point.
    pub seeds: usize,
}

/// The runs of one group and their statistics (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct GroupReport {
    /// Environment name.
    pub env: String,
    /// Model of team 0.
    pub model: String,
    /// Model of team 1 (Team Sumo; empty: the same as `model`).
    pub opponent: String,
    /// The run path without its seed component, relative to the root (`/`-separated).
    pub variant: String,
    /// The name shown in the table and legend: `variant` without a leading environment
    /// directory, or the model if that leaves nothing.
    pub label: String,
    /// The metrics column of the final value (`eval_success_rate`, `eval_win_rate_t0`, a
    /// `train_*` fallback, or a rotated evaluation's `eval_*_rot<degrees>`).
    pub metric: String,
    /// The rotation of the evaluations (degrees; 0 unrotated).
    pub rotation_deg: f64,
    /// Whether at least one run had no evaluation rows and used the training rate.
    pub from_train: bool,
    /// The run directories, relative to the root.
    pub runs: Vec<PathBuf>,
    /// The runs' seeds, in the order of `runs`.
    pub seed_list: Vec<u64>,
    /// Final values per run, in percent, in the order of `runs`.
    pub finals: Vec<f64>,
    /// The env steps at which each run's final value was measured (its last evaluation,
    /// or the last row with a training rate), in the order of `runs`.
    pub final_steps: Vec<u64>,
    /// Mean final value, in percent.
    pub mean: f64,
    /// Standard error of the final value, in percent.
    pub se: f64,
    /// Team Sumo: mean and standard error of the final draw rate, in percent.
    pub draw: Option<(f64, f64)>,
    /// Team Sumo: mean and standard error of the final loss rate of team 0 (team 1's win
    /// rate), in percent.
    pub lose: Option<(f64, f64)>,
    /// Fewest and most env steps reached over the runs.
    pub env_steps: (u64, u64),
    /// The runs' budget (the largest `steps` of their configurations): a group whose
    /// runs stopped short of it is still training (or was stopped), and the table says so.
    pub target_steps: u64,
    /// Machine time of the runs in hours: the sum of each run's last `wall_s` (wall-clock
    /// seconds of training and evaluation, counted across resumes). Rotated groups, which
    /// are the same runs evaluated otherwise, hold 0 so that a sum over groups counts each
    /// run once.
    pub machine_hours: f64,
    /// The learning curve (mean and s.e. over seeds).
    pub curve: Vec<CurvePoint>,
    /// Team Sumo: the curves of the loss and draw rates (empty for Team Reach).
    pub curve_lose: Vec<CurvePoint>,
    /// See `curve_lose`.
    pub curve_draw: Vec<CurvePoint>,
}

/// What [`report`] found and wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The directory searched.
    pub root: PathBuf,
    /// The groups, by environment (built-in order first), then variant.
    pub groups: Vec<GroupReport>,
    /// Run directories without any value yet (relative to the root), with the reason.
    pub pending: Vec<(PathBuf, String)>,
    /// `<root>/report.md`.
    pub markdown: PathBuf,
    /// `<root>/report.csv`.
    pub csv: PathBuf,
    /// `<root>/curves/<env>.svg`, one per environment.
    pub curves: Vec<PathBuf>,
}

/// Every run directory (holding `config.toml` and `metrics.csv`) at or under `root`,
/// sorted; directories inside a run, hidden directories and symbolic links are not searched.
pub fn find_run_dirs(root: &Path) -> Result<Vec<PathBuf>> {
    if !root.is_dir() {
        return Err(RlError::file(root, "not a directory"));
    }
    let mut found = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let run = RunDir::new(&dir);
        if run.config().is_file() && run.metrics().is_file() {
            found.push(dir);
            continue;
        }
        let entries = std::fs::read_dir(&dir).map_err(|e| RlError::file(&dir, format!("cannot list: {e}")))?;
        for entry in entries {
            let entry = entry.map_err(|e| RlError::file(&dir, format!("cannot list: {e}")))?;
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if !hidden && entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(entry.path());
            }
        }
    }
    found.sort();
    Ok(found)
}

/// Mean and standard error (sample standard deviation / sqrt(n); 0 for one value) of
/// `values`; `(NaN, NaN)` for none.
pub fn mean_and_se(values: &[f64]) -> (f64, f64) {
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return (mean, 0.0);
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, (var / n as f64).sqrt())
}

/// Reads every run under `root`, writes `report.md`, `report.csv` and `curves/*.svg`
/// there (module docs), prints the path of `report.md`, and returns what it found.
pub fn report(root: &Path) -> Result<Report> {
    let dirs = find_run_dirs(root)?;
    if dirs.is_empty() {
        return Err(RlError::file(
            root,
            "no run directories found (directories holding config.toml and metrics.csv, at any depth)",
        ));
    }
    let mut pending = Vec::new();
    type Key = (usize, String, String, String, String, (bool, i64));
    let mut groups: BTreeMap<Key, Vec<RunResult>> = BTreeMap::new();
    for dir in &dirs {
        let rel = dir.strip_prefix(root).unwrap_or(dir).to_path_buf();
        match read_run(dir)? {
            Ok(results) => {
                for run in results {
                    let variant = variant_of(&rel);
                    let c = &run.config;
                    // Unrotated first, then by angle (micro-degrees: exact for any angle written).
                    let rot = (run.rotation_deg != 0.0, (run.rotation_deg * 1e6).round() as i64);
                    let key = (env_rank(&c.env), c.env.clone(), variant, c.model.clone(), c.opponent.clone(), rot);
                    groups.entry(key).or_default().push(RunResult { rel: rel.clone(), ..run });
                }
            }
            Err(reason) => pending.push((rel, reason)),
        }
    }
    // A group with evaluated runs leaves out its runs set not to evaluate: a training rate is
    // no value to average with evaluations.
    let groups: Vec<GroupReport> = groups
        .into_iter()
        .map(|((_, _, variant, _, _, _), runs)| {
            let evaluated = runs.iter().any(|r| !r.from_train);
            let (kept, waiting): (Vec<RunResult>, Vec<RunResult>) =
                runs.into_iter().partition(|r| !(evaluated && r.from_train));
            for r in waiting {
                pending.push((
                    r.rel,
                    "set not to evaluate (num_evals = 0), while the other seeds of its group are".into(),
                ));
            }
            summarise(variant, kept)
        })
        .collect();
    pending.sort();

    let markdown = root.join("report.md");
    let csv = root.join("report.csv");
    let curves_dir = root.join("curves");
    let mut curves = Vec::new();
    if !groups.is_empty() {
        std::fs::create_dir_all(&curves_dir)
            .map_err(|e| RlError::file(&curves_dir, format!("cannot create the directory: {e}")))?;
    }
    for env in envs_in_order(&groups) {
        let path = curves_dir.join(format!("{}.svg", sanitize_component(env)));
        nn::write_atomic(&path, curve_plot(env, &groups).to_svg().as_bytes())?;
        curves.push(path);
    }
    nn::write_atomic(&markdown, render_markdown(root, &groups, &pending).as_bytes())?;
    nn::write_atomic(&csv, render_csv(&groups).as_bytes())?;
    println!("{}", markdown.display());
    Ok(Report { root: root.to_path_buf(), groups, pending, markdown, csv, curves })
}

/// One run's values.
struct RunResult {
    rel: PathBuf,
    config: TrainConfig,
    metric: String,
    rotation_deg: f64,
    from_train: bool,
    final_value: f64,
    final_draw: Option<f64>,
    final_lose: Option<f64>,
    env_steps: u64,
    /// The last row's `wall_s` (0 if none).
    wall_s: f64,
    /// `(env_steps, value)`, env steps strictly increasing.
    curve: Vec<(f64, f64)>,
    curve_lose: Vec<(f64, f64)>,
    curve_draw: Vec<(f64, f64)>,
}

/// `(env_steps, value)` of every row with a finite value in `column`, env steps strictly
/// increasing (a resumed run may repeat env steps: the later rows replace the earlier ones).
fn column_curve(rows: &[BTreeMap<String, f64>], column: &str) -> Vec<(f64, f64)> {
    let mut curve: Vec<(f64, f64)> = Vec::new();
    for r in rows {
        let (Some(&x), Some(&y)) = (r.get("env_steps"), r.get(column)) else { continue };
        if !(x.is_finite() && y.is_finite()) {
            continue;
        }
        while curve.last().is_some_and(|&(px, _)| px >= x) {
            curve.pop();
        }
        curve.push((x, y));
    }
    curve
}

/// Reads a run: its result (then one per further rotation with values), or
/// `Ok(Err(reason))` if it has no value yet.
fn read_run(dir: &Path) -> Result<std::result::Result<Vec<RunResult>, String>> {
    let run = RunDir::new(dir);
    let config = TrainConfig::load(&run.config())?;
    let rows = metrics::read_csv(&run.metrics())?;
    // (success or win, loss, draw) columns of evaluations and of training.
    let (eval, train) = if config.is_sumo() {
        (
            ("eval_win_rate_t0", Some(("eval_win_rate_t1", "eval_draw_rate"))),
            ("train_win_rate_t0", Some(("train_win_rate_t1", "train_draw_rate"))),
        )
    } else {
        (("eval_success_rate", None), ("train_success_rate", None))
    };
    let has = |col: &str| rows.iter().any(|r| r.get(col).is_some_and(|v| v.is_finite()));
    let ((metric, others), from_train) = if has(eval.0) {
        (eval, false)
    } else if rows.is_empty() {
        return Ok(Err("no rows yet".into()));
    } else if config.num_evals > 0 {
        // Its training rate would start far too high (module docs): no value until the first evaluation.
        return Ok(Err(format!("no evaluation yet (it is set to {} over the run)", config.num_evals)));
    } else if has(train.0) {
        (train, true)
    } else {
        return Ok(Err(format!("no {} or {} values yet", eval.0, train.0)));
    };
    let env_steps = rows.iter().rev().find_map(|r| r.get("env_steps").copied()).unwrap_or(0.0).max(0.0) as u64;
    let wall_s = rows.iter().rev().find_map(|r| r.get("wall_s").copied()).filter(|w| w.is_finite()).unwrap_or(0.0);
    let result = |metric: String, others: Option<(String, String)>, rotation_deg: f64, from_train: bool| {
        let last = |col: &str| rows.iter().rev().find_map(|r| r.get(col).copied().filter(|v| v.is_finite()));
        let (lose, draw) = others.unzip();
        RunResult {
            rel: PathBuf::new(),
            config: config.clone(),
            final_value: last(&metric).unwrap_or(f64::NAN),
            final_draw: draw.as_deref().and_then(last),
            final_lose: lose.as_deref().and_then(last),
            curve: column_curve(&rows, &metric),
            curve_lose: lose.as_deref().map(|c| column_curve(&rows, c)).unwrap_or_default(),
            curve_draw: draw.as_deref().map(|c| column_curve(&rows, c)).unwrap_or_default(),
            metric,
            rotation_deg,
            from_train,
            env_steps,
            wall_s,
        }
    };
    let owned = |o: Option<(&str, &str)>| o.map(|(l, d)| (l.to_string(), d.to_string()));
    let mut out = vec![result(metric.to_string(), owned(others), 0.0, from_train)];
    for &deg in config.eval_rotations.iter().skip(1) {
        let rotated = metrics::eval_column(eval.0, deg);
        if has(&rotated) {
            let others = eval.1.map(|(l, d)| (metrics::eval_column(l, deg), metrics::eval_column(d, deg)));
            out.push(result(rotated, others, deg, false));
        }
    }
    Ok(Ok(out))
}

/// The run path without `seed<N>` components, `/`-separated.
fn variant_of(rel: &Path) -> String {
    let parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .filter(|c| !is_seed_component(c))
        .collect();
    parts.join("/")
}

fn is_seed_component(c: &str) -> bool {
    c.strip_prefix("seed").is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

/// Built-in environments in their order, then the others.
fn env_rank(env: &str) -> usize {
    envs::tasks::BUILTIN_NAMES.iter().position(|n| *n == env).unwrap_or(envs::tasks::BUILTIN_NAMES.len())
}

fn summarise(variant: String, mut runs: Vec<RunResult>) -> GroupReport {
    runs.sort_by(|a, b| a.config.seed.cmp(&b.config.seed).then_with(|| a.rel.cmp(&b.rel)));
    let c = &runs[0].config;
    let env_dir = sanitize_component(&c.env);
    let label = match variant.strip_prefix(&env_dir) {
        Some(rest) if rest.is_empty() || rest.starts_with('/') => rest.trim_start_matches('/').to_string(),
        _ => variant.clone(),
    };
    let label = if label.is_empty() { c.model.clone() } else { label };
    let rotation_deg = runs[0].rotation_deg;
    let label = if rotation_deg == 0.0 { label } else { format!("{label}, rotated {rotation_deg}°") };
    let finals: Vec<f64> = runs.iter().map(|r| 100.0 * r.final_value).collect();
    let final_steps: Vec<u64> = runs.iter().map(|r| r.curve.last().map_or(0, |&(x, _)| x as u64)).collect();
    let (mean, se) = mean_and_se(&finals);
    let draws: Vec<f64> = runs.iter().filter_map(|r| r.final_draw.map(|d| 100.0 * d)).collect();
    let draw = (!draws.is_empty()).then(|| mean_and_se(&draws));
    let loses: Vec<f64> = runs.iter().filter_map(|r| r.final_lose.map(|d| 100.0 * d)).collect();
    let lose = (!loses.is_empty()).then(|| mean_and_se(&loses));
    let from_train = runs.iter().any(|r| r.from_train);
    let shown = if from_train { runs.iter().find(|r| r.from_train) } else { runs.first() };
    let metric = shown.map(|r| r.metric.clone()).unwrap_or_default();
    let steps = runs.iter().map(|r| r.env_steps);
    let env_steps = (steps.clone().min().unwrap_or(0), steps.max().unwrap_or(0));
    let target_steps = runs.iter().map(|r| r.config.steps).max().unwrap_or(0);
    let machine_hours =
        if rotation_deg == 0.0 { runs.iter().map(|r| r.wall_s.max(0.0)).sum::<f64>() / 3600.0 } else { 0.0 };
    let aligned = |of: fn(&RunResult) -> &[(f64, f64)]| {
        let curves: Vec<&[(f64, f64)]> = runs.iter().map(of).collect();
        align_curves(&curves)
    };
    GroupReport {
        env: c.env.clone(),
        model: c.model.clone(),
        opponent: c.opponent.clone(),
        variant,
        label,
        metric,
        rotation_deg,
        from_train,
        runs: runs.iter().map(|r| r.rel.clone()).collect(),
        seed_list: runs.iter().map(|r| r.config.seed).collect(),
        finals,
        final_steps,
        mean,
        se,
        draw,
        lose,
        env_steps,
        target_steps,
        machine_hours,
        curve: aligned(|r| &r.curve),
        curve_lose: aligned(|r| &r.curve_lose),
        curve_draw: aligned(|r| &r.curve_draw),
    }
}

/// Mean and s.e. (in percent) over seeds of curves `(env_steps, fraction)`, aligned on the
/// env steps of the curve with the fewest points (the first of those on ties); each curve
/// contributes its value at its last point at or before each of those (none before its
/// first point).
fn align_curves(curves: &[&[(f64, f64)]]) -> Vec<CurvePoint> {
    let Some(reference) = curves.iter().filter(|c| !c.is_empty()).min_by_key(|c| c.len()) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for &(x, _) in reference.iter() {
        let values: Vec<f64> = curves
            .iter()
            .filter_map(|c| {
                let k = c.partition_point(|p| p.0 <= x);
                (k > 0).then(|| 100.0 * c[k - 1].1)
            })
            .collect();
        if values.is_empty() {
            continue;
        }
        let (mean, se) = mean_and_se(&values);
        out.push(CurvePoint { env_steps: x, mean, se, seeds: values.len() });
    }
    out
}

fn envs_in_order(groups: &[GroupReport]) -> Vec<&str> {
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

fn curve_plot(env: &str, groups: &[GroupReport]) -> LinePlot {
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

fn md_cell(s: &str) -> String {
    s.replace('|', "\\|")
}

/// `n` followed by `noun`, plural unless `n` is 1: "1 run", "3 runs".
pub(crate) fn count(n: usize, noun: &str) -> String {
    if n == 1 { format!("1 {noun}") } else { format!("{n} {noun}s") }
}

fn render_markdown(root: &Path, groups: &[GroupReport], pending: &[(PathBuf, String)]) -> String {
    let mut md = String::new();
    let runs: usize = groups.iter().map(|g| g.runs.len()).sum();
    let _ = writeln!(md, "# Report: `{}`\n", root.display());
    let _ = writeln!(
        md,
        "{} in {}. Final value of a run: its metric in the last row of `metrics.csv` that has it \
         (Team Reach `eval_success_rate`, Team Sumo `eval_win_rate_t0`, `eval_win_rate_t1` and `eval_draw_rate`), \
         in percent; \
         mean ± standard error over seeds (sample standard deviation / √n; 0 for one seed). Env steps: the last \
         row's, over the seeds (\"of N\": runs still short of their budget N). Curves: mean over seeds with a ± s.e. band. Rows \"rotated N°\" are \
         evaluations of the same runs with every start rotated by N degrees about the vertical (`eval_rotations`).\n",
        count(runs, "run"),
        count(groups.len(), "group")
    );
    for env in envs_in_order(groups) {
        let sumo = env.starts_with("team_sumo");
        let _ = writeln!(md, "## {env}\n");
        if sumo {
            let _ = writeln!(
                md,
                "| run | model | opponent | seeds | win % team 0 (mean ± s.e.) | loss % team 0 (mean ± s.e.) | \
                 draw % (mean ± s.e.) | env steps | machine h | per seed: win % (at env steps) |"
            );
            let _ = writeln!(md, "|---|---|---|---:|---:|---:|---:|---:|---:|---|");
        } else {
            let _ = writeln!(
                md,
                "| run | model | seeds | success % (mean ± s.e.) | env steps | machine h | per seed: % (at env steps) |"
            );
            let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---|");
        }
        let mut any_train = false;
        for g in groups.iter().filter(|g| g.env == env) {
            let mark = if g.from_train { " †" } else { "" };
            any_train |= g.from_train;
            let value = format!("{:.2} ± {:.2}{mark}", g.mean, g.se);
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
                    "| {} | `{}` | {} | {} | {value} | {lose} | {draw} | {} | {hours} | {per_seed} |",
                    md_cell(&g.label),
                    md_cell(&g.model),
                    md_cell(&opponent),
                    g.runs.len(),
                    steps_range(g)
                );
            } else {
                let _ = writeln!(
                    md,
                    "| {} | `{}` | {} | {value} | {} | {hours} | {per_seed} |",
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

fn render_csv(groups: &[GroupReport]) -> String {
    let mut out = String::from(
        "env,model,opponent,variant,metric,seeds,seed_list,mean_pct,se_pct,draw_mean_pct,draw_se_pct,\
         env_steps_min,env_steps_max,rotation_deg,lose_mean_pct,lose_se_pct,machine_hours\n",
    );
    for g in groups {
        let seeds: Vec<String> = g.seed_list.iter().map(|s| s.to_string()).collect();
        let (dm, ds) = g.draw.map(|(m, s)| (m.to_string(), s.to_string())).unwrap_or_default();
        let (lm, ls) = g.lose.map(|(m, s)| (m.to_string(), s.to_string())).unwrap_or_default();
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{dm},{ds},{},{},{},{lm},{ls},{}",
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
            g.machine_hours
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_standard_error() {
        let (m, s) = mean_and_se(&[10.0, 20.0, 30.0]);
        assert!((m - 20.0).abs() < 1e-12);
        // sample std 10, / sqrt(3)
        assert!((s - 10.0 / 3f64.sqrt()).abs() < 1e-12);
        assert_eq!(mean_and_se(&[7.0]), (7.0, 0.0));
        assert!(mean_and_se(&[]).0.is_nan());
    }

    #[test]
    fn curves_align_on_the_shortest_seed() {
        let a: &[(f64, f64)] = &[(100.0, 0.1), (200.0, 0.2), (300.0, 0.3)];
        let b: &[(f64, f64)] = &[(150.0, 0.5), (310.0, 0.7)];
        let c = align_curves(&[a, b]);
        // x from b; a's value at its last row at or before 150 (0.1) and 310 (0.3).
        assert_eq!(c.len(), 2);
        assert_eq!((c[0].env_steps, c[0].seeds), (150.0, 2));
        assert!((c[0].mean - 30.0).abs() < 1e-9);
        assert!((c[1].mean - 50.0).abs() < 1e-9);
        assert!((c[1].se - mean_and_se(&[30.0, 70.0]).1).abs() < 1e-9);
        // A seed without a row before the first reference x is left out there.
        let late: &[(f64, f64)] = &[(250.0, 1.0), (400.0, 1.0)];
        let c = align_curves(&[late, a]);
        assert_eq!((c[0].env_steps, c[0].seeds, c[0].mean), (250.0, 2, 60.0));
        let c = align_curves(&[b, late]);
        assert_eq!((c[0].seeds, c[0].mean), (1, 50.0));
        assert!(align_curves(&[]).is_empty());
    }

    #[test]
    fn variants_drop_the_seed_component() {
        assert_eq!(variant_of(Path::new("team_reach_1_ant/shnn+v/seed12")), "team_reach_1_ant/shnn+v");
        assert_eq!(variant_of(Path::new("a/seedling/seed0")), "a/seedling");
        assert_eq!(variant_of(Path::new("")), "");
        assert_eq!(format_steps(50_000_000), "50M");
        assert_eq!(format_steps(2_457_600), "2.46M");
        assert_eq!(format_steps(81_920), "81.9k");
    }
}
