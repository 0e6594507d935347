//! The report's aggregation: each run's final values and curves from its record, runs
//! grouped by environment, model, opponent, variant and rotation, and each group's
//! statistics ([`super::stats`]) and seed-averaged curves ([`GroupReport`]). The rules are
//! those of the report's module docs ([`super`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::stats::{bootstrap_ci, iqm, mean, mean_and_sd, mean_and_se};
use crate::app::names::sanitize_component;
use crate::app::record::{IterationRow, Rate, RunRecord};
use crate::mappo::config::{TrainConfig, TrainStarts};

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
    /// Where the runs' training episodes start (their configuration).
    pub start: StartKind,
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
    /// Sample standard deviation of the final values over the seeds (0 for one seed), in
    /// percent: the spread the paper's tables give.
    pub sd: f64,
    /// Interquartile mean of the final values, in percent ([`super::stats::iqm`]).
    pub iqm: f64,
    /// 95% percentile-bootstrap confidence interval of the mean final value, in percent
    /// ([`super::stats::bootstrap_ci`]).
    pub mean_ci: (f64, f64),
    /// 95% percentile-bootstrap confidence interval of the interquartile mean, in percent.
    pub iqm_ci: (f64, f64),
    /// Team Sumo: mean and standard error of the final draw rate, in percent.
    pub draw: Option<(f64, f64)>,
    /// Team Sumo: mean and standard error of the final loss rate of team 0 (team 1's win
    /// rate), in percent.
    pub lose: Option<(f64, f64)>,
    /// Team Sumo: 95% percentile-bootstrap confidence interval of the mean loss rate of
    /// team 0, in percent.
    pub lose_ci: Option<(f64, f64)>,
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

/// Where a group's training episodes start, from its runs' configuration: how the paper's
/// tables tell their experiments apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartKind {
    /// A fresh random start every episode (the default).
    Random,
    /// One fixed start (`fixed_start = true`: the paper's equivariance test).
    Fixed,
    /// Random starts, each environment slot replaying its first one
    /// (`train_starts = "per_slot"`: the reference release's reset).
    RandomPerSlot,
}

impl StartKind {
    /// The start of a run configured by `config`.
    pub fn of(config: &TrainConfig) -> StartKind {
        if config.fixed_start {
            StartKind::Fixed
        } else if config.train_starts == TrainStarts::PerSlot {
            StartKind::RandomPerSlot
        } else {
            StartKind::Random
        }
    }

    /// As a table writes it: `random`, `fixed` or `random (per slot)`.
    pub fn label(self) -> &'static str {
        match self {
            StartKind::Random => "random",
            StartKind::Fixed => "fixed",
            StartKind::RandomPerSlot => "random (per slot)",
        }
    }
}

/// The groups of the runs `records` (each with its directory relative to the report's
/// root), by environment (built-in order first), then variant, model, opponent and rotation;
/// and the runs without a value yet, with the reason, sorted.
pub fn group_runs(records: &[(PathBuf, RunRecord)]) -> (Vec<GroupReport>, Vec<(PathBuf, String)>) {
    let mut pending = Vec::new();
    type Key = (usize, String, String, String, String, (bool, i64));
    let mut groups: BTreeMap<Key, Vec<RunResult>> = BTreeMap::new();
    for (rel, record) in records {
        match run_results(record) {
            Ok(results) => {
                for run in results {
                    let variant = variant_of(rel);
                    let c = &run.config;
                    // Unrotated first, then by angle (micro-degrees: exact for any angle written).
                    let rot = (run.rotation_deg != 0.0, (run.rotation_deg * 1e6).round() as i64);
                    let key = (env_rank(&c.env), c.env.clone(), variant, c.model.clone(), c.opponent.clone(), rot);
                    groups.entry(key).or_default().push(RunResult { rel: rel.clone(), ..run });
                }
            }
            Err(reason) => pending.push((rel.clone(), reason)),
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
    (groups, pending)
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

/// A rate a run is valued by: of its evaluations at a rotation (degrees), or of its
/// training episodes.
#[derive(Clone, Copy)]
struct Measure {
    rate: Rate,
    /// `None`: the training episodes.
    eval_at: Option<f64>,
}

impl Measure {
    fn value(self, row: &IterationRow) -> Option<f64> {
        match self.eval_at {
            Some(deg) => row.eval(deg)?.rate(self.rate),
            None => row.train.rate(self.rate),
        }
    }

    fn column(self) -> String {
        match self.eval_at {
            Some(deg) => self.rate.eval_column(deg),
            None => self.rate.train_column(),
        }
    }

    /// The last finite value in `rows`.
    fn last(self, rows: &[IterationRow]) -> Option<f64> {
        rows.iter().rev().find_map(|r| self.value(r).filter(|v| v.is_finite()))
    }

    /// `(env_steps, value)` of every row with a finite value, env steps strictly increasing
    /// (a resumed run may repeat env steps: the later rows replace the earlier ones).
    fn curve(self, rows: &[IterationRow]) -> Vec<(f64, f64)> {
        let mut curve: Vec<(f64, f64)> = Vec::new();
        for r in rows {
            let (x, Some(y)) = (r.env_steps as f64, self.value(r)) else { continue };
            if !y.is_finite() {
                continue;
            }
            while curve.last().is_some_and(|&(px, _)| px >= x) {
                curve.pop();
            }
            curve.push((x, y));
        }
        curve
    }
}

/// A run's results (then one per further rotation with values), or the reason it has no
/// value yet.
fn run_results(record: &RunRecord) -> Result<Vec<RunResult>, String> {
    let (config, rows) = (&record.config, record.rows());
    // The success or win rate, and the loss and draw rates.
    let (main, others) =
        if config.is_sumo() { (Rate::Win(0), Some((Rate::Win(1), Rate::Draw))) } else { (Rate::Success, None) };
    let (eval, train) = (Measure { rate: main, eval_at: Some(0.0) }, Measure { rate: main, eval_at: None });
    let has = |m: Measure| m.last(rows).is_some();
    let (source, from_train) = if has(eval) {
        (eval.eval_at, false)
    } else if rows.is_empty() {
        return Err("no rows yet".into());
    } else if config.num_evals > 0 {
        // Its training rate would start far too high (module docs): no value until the first evaluation.
        return Err(format!("no evaluation yet (it is set to {} over the run)", config.num_evals));
    } else if has(train) {
        (None, true)
    } else {
        return Err(format!("no {} or {} values yet", eval.column(), train.column()));
    };
    let env_steps = rows.last().map_or(0, |r| r.env_steps);
    let wall_s = rows.iter().rev().find_map(|r| r.wall_s).filter(|w| w.is_finite()).unwrap_or(0.0);
    let result = |eval_at: Option<f64>, from_train: bool| {
        let of = |rate: Rate| Measure { rate, eval_at };
        let (lose, draw) = others.map(|(l, d)| (of(l), of(d))).unzip();
        RunResult {
            rel: PathBuf::new(),
            config: config.clone(),
            metric: of(main).column(),
            rotation_deg: eval_at.unwrap_or(0.0),
            from_train,
            final_value: of(main).last(rows).unwrap_or(f64::NAN),
            final_draw: draw.and_then(|m| m.last(rows)),
            final_lose: lose.and_then(|m| m.last(rows)),
            env_steps,
            wall_s,
            curve: of(main).curve(rows),
            curve_lose: lose.map(|m| m.curve(rows)).unwrap_or_default(),
            curve_draw: draw.map(|m| m.curve(rows)).unwrap_or_default(),
        }
    };
    let mut out = vec![result(source, from_train)];
    for &deg in config.eval_rotations.iter().skip(1) {
        if has(Measure { rate: main, eval_at: Some(deg) }) {
            out.push(result(Some(deg), false));
        }
    }
    Ok(out)
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
    let (mean_pct, se) = mean_and_se(&finals);
    let draws: Vec<f64> = runs.iter().filter_map(|r| r.final_draw.map(|d| 100.0 * d)).collect();
    let draw = (!draws.is_empty()).then(|| mean_and_se(&draws));
    let loses: Vec<f64> = runs.iter().filter_map(|r| r.final_lose.map(|d| 100.0 * d)).collect();
    let lose = (!loses.is_empty()).then(|| mean_and_se(&loses));
    let lose_ci = (!loses.is_empty()).then(|| bootstrap_ci(&loses, mean));
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
        start: StartKind::of(c),
        from_train,
        runs: runs.iter().map(|r| r.rel.clone()).collect(),
        seed_list: runs.iter().map(|r| r.config.seed).collect(),
        sd: mean_and_sd(&finals).1,
        iqm: iqm(&finals),
        mean_ci: bootstrap_ci(&finals, mean),
        iqm_ci: bootstrap_ci(&finals, iqm),
        finals,
        final_steps,
        mean: mean_pct,
        se,
        draw,
        lose,
        lose_ci,
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

#[cfg(test)]
mod tests {
    use super::*;

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
    }
}
