//! `meben status <runs>`: how far every run under a directory got, whether a process is
//! training it now, and how long its training iterations still need at the speed it has run
//! at, for watching a sweep and planning machine time.
//!
//! Per run ([`RunProgress`]): its state (finished, training now, stopped, or not started),
//! the last row's iteration, env steps and `wall_s`, the budget (`config.iterations()`
//! iterations of `config.steps_per_iteration()` env steps), the last evaluation of its
//! headline metric (Team Reach `eval_success_rate`, Team Sumo `eval_win_rate_t0`), its speed
//! (the median `steps_per_s` of the rows without an evaluation: the speed of training
//! iterations alone, as `docs/RESULTS.md` quotes it), what an evaluation costs (the median,
//! over the rows with one, of the row's duration, the difference of consecutive `wall_s`,
//! less the median duration of the rows without one) and the hours its remaining
//! iterations and evaluations need at those rates.
//!
//! When the directory is a sweep's output (it holds the copy `sweep.toml` that `meben
//! ablate` writes), the sweep's runs without a directory yet are listed too, as queued, with
//! their budget. A run without a speed or an evaluation cost of its own (queued, or not yet
//! evaluated) borrows, as an estimate, the median of the runs of the same environment, model
//! and opponent that have one (none: unknown).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use crate::app::lock::holder;
use crate::app::record::{IterationRow, Rate, RunRecord, find_run_dirs};
use crate::app::report::count;
use crate::app::run::evals_through;
use crate::app::sweep::Sweep;
use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;

/// Where a run stands.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RunState {
    /// `done.json` exists.
    Finished,
    /// A process holds the run's lock (its holder as the lock file names it).
    Training(String),
    /// Rows or a checkpoint, no `done.json`, nobody training it: the next training resumes.
    Stopped,
    /// No rows yet and nobody training it.
    NotStarted,
    /// A run of the sweep (`sweep.toml`) with no directory yet.
    Queued,
}

/// One run's progress (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct RunProgress {
    /// The run directory, relative to the root given (the root itself if it is the run).
    pub run: PathBuf,
    /// Where it stands.
    pub state: RunState,
    /// The last row's iteration (0: no rows).
    pub iteration: u64,
    /// The last row's env steps.
    pub env_steps: u64,
    /// The env steps of the whole budget (`iterations() * steps_per_iteration()`).
    pub budget_steps: u64,
    /// The last row's `wall_s` (training and evaluation, across resumes).
    pub wall_s: f64,
    /// The headline metric's column and its last evaluation `(env_steps, value)`, if any.
    pub last_eval: Option<(String, u64, f64)>,
    /// Median `steps_per_s` of the rows without an evaluation, if any (for a run with no
    /// such row, its siblings' median when `speed_estimated`).
    pub steps_per_s: Option<f64>,
    /// Whether `steps_per_s` is borrowed from the runs of the same environment, model and
    /// opponent.
    pub speed_estimated: bool,
    /// Seconds an evaluation adds to its iteration (module docs), if the run has evaluated
    /// (otherwise its siblings' median when `eval_estimated`).
    pub eval_s: Option<f64>,
    /// Whether `eval_s` is borrowed from the runs of the same environment, model and
    /// opponent.
    pub eval_estimated: bool,
    /// Evaluations still to come (`num_evals` evenly spaced, the last at the end).
    pub evals_left: u64,
}

/// The progress of every run at or under `root` (a sweep's `--out`, or one run directory),
/// sorted by path, then the sweep's queued runs (module docs).
pub fn status(root: &Path) -> Result<Vec<RunProgress>> {
    let dirs = find_run_dirs(root)?;
    let sweep_file = root.join("sweep.toml");
    let sweep = if sweep_file.is_file() { Some(Sweep::load(&sweep_file)?) } else { None };
    if dirs.is_empty() && sweep.is_none() {
        return Err(RlError::file(root, "holds no run directory (config.toml and metrics.csv) and no sweep.toml"));
    }
    let mut runs = Vec::new();
    for dir in &dirs {
        let record = RunRecord::read(dir)?;
        runs.push((run_progress(root, &record)?, record.config));
    }
    if let Some(sweep) = sweep {
        // Sets and maps keyed by name and by group, not searches of `runs`: a sweep of 10k
        // queued runs took 20 s (issue 44 item 9).
        let mut known: HashSet<PathBuf> = runs.iter().map(|(r, _)| r.run.clone()).collect();
        for queued in sweep.runs()? {
            if known.insert(PathBuf::from(&queued.name)) {
                runs.push((queued_run(&queued.name, &queued.config), queued.config));
            }
        }
    }
    // Runs without a speed or an evaluation cost of their own borrow their siblings'
    // median (runs of the same env, model and opponent), as an estimate.
    let group = |c: &TrainConfig| (c.env.clone(), c.model.clone(), c.opponent.clone());
    type Group = (String, String, String);
    let mut siblings: HashMap<Group, (Vec<f64>, Vec<f64>)> = HashMap::new();
    for (r, c) in &runs {
        let (speeds, evals) = siblings.entry(group(c)).or_default();
        speeds.extend(r.steps_per_s);
        evals.extend(r.eval_s);
    }
    let medians: HashMap<_, (Option<f64>, Option<f64>)> = siblings
        .into_iter()
        .map(|(k, (speeds, evals))| (k, (median(speeds.into_iter()), median(evals.into_iter()))))
        .collect();
    let estimates: Vec<(Option<f64>, Option<f64>)> = runs
        .iter()
        .map(|(r, c)| {
            if r.state == RunState::Finished {
                return (None, None);
            }
            let (speed, eval_s) = medians.get(&group(c)).copied().unwrap_or_default();
            (speed.filter(|_| r.steps_per_s.is_none()), eval_s.filter(|_| r.eval_s.is_none()))
        })
        .collect();
    Ok(runs
        .into_iter()
        .zip(estimates)
        .map(|((mut r, _), (speed, eval_s))| {
            if speed.is_some() {
                (r.steps_per_s, r.speed_estimated) = (speed, true);
            }
            if eval_s.is_some() {
                (r.eval_s, r.eval_estimated) = (eval_s, true);
            }
            r
        })
        .collect())
}

impl RunProgress {
    /// Hours the run's remaining env steps need at its speed, plus its remaining
    /// evaluations at their cost where that is known (0 when finished, `None` without a
    /// speed).
    pub fn hours_left(&self) -> Option<f64> {
        if self.state == RunState::Finished {
            return Some(0.0);
        }
        let training = self.budget_steps.saturating_sub(self.env_steps) as f64 / self.steps_per_s?;
        Some((training + self.evals_left as f64 * self.eval_s.unwrap_or(0.0)) / 3600.0)
    }

    /// Whether the hours left leave out evaluations whose cost is unknown.
    fn evals_uncounted(&self) -> bool {
        self.evals_left > 0 && self.eval_s.is_none()
    }
}

/// Seconds an evaluation adds to its iteration: the median, over the rows with an
/// evaluation, of the row's duration (the difference of its `wall_s` and the previous
/// row's) less the median duration of the rows without one (`None` before an evaluation).
fn evaluation_seconds(rows: &[IterationRow]) -> Option<f64> {
    let durations: Vec<(bool, f64)> = rows
        .windows(2)
        .filter_map(|w| Some((w[1].evaluated(), w[1].wall_s? - w[0].wall_s?)))
        .filter(|(_, d)| d.is_finite() && *d >= 0.0)
        .collect();
    let iteration = median(durations.iter().filter(|(e, _)| !e).map(|(_, d)| *d))?;
    median(durations.iter().filter(|(e, _)| *e).map(|(_, d)| (d - iteration).max(0.0)))
}

/// The median of `values` (`None` for none).
fn median(values: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => None,
        n if n % 2 == 1 => Some(v[n / 2]),
        n => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// A sweep run with no directory yet.
fn queued_run(name: &str, config: &TrainConfig) -> RunProgress {
    RunProgress {
        run: PathBuf::from(name),
        state: RunState::Queued,
        iteration: 0,
        env_steps: 0,
        budget_steps: config.iterations() * config.steps_per_iteration(),
        wall_s: 0.0,
        last_eval: None,
        steps_per_s: None,
        speed_estimated: false,
        eval_s: None,
        eval_estimated: false,
        evals_left: config.num_evals as u64,
    }
}

/// One run's progress, from its record.
fn run_progress(root: &Path, record: &RunRecord) -> Result<RunProgress> {
    let (config, rows, dir) = (&record.config, record.rows(), record.dir.root());
    let rate = if config.is_sumo() { Rate::Win(0) } else { Rate::Success };
    let last_eval =
        rows.iter().rev().find_map(|r| Some((rate.eval_column(0.0), r.env_steps, r.eval(0.0)?.rate(rate)?)));
    let steps_per_s = median(
        rows.iter().filter(|r| !r.evaluated()).filter_map(|r| r.steps_per_s).filter(|v| v.is_finite() && *v > 0.0),
    );
    let state = if record.finished {
        RunState::Finished
    } else if let Some(h) = holder(dir)? {
        RunState::Training(h)
    } else if rows.is_empty() && !record.dir.checkpoint().is_file() {
        RunState::NotStarted
    } else {
        RunState::Stopped
    };
    let last = rows.last();
    let iteration = last.map_or(0, |r| r.iteration);
    let evals_left = config.num_evals as u64
        - evals_through(iteration.min(config.iterations()), config.iterations(), config.num_evals as u64);
    Ok(RunProgress {
        // Relative to the root, or the directory as given when it is the root.
        run: dir.strip_prefix(root).ok().filter(|r| !r.as_os_str().is_empty()).unwrap_or(dir).to_path_buf(),
        state,
        iteration,
        env_steps: last.map_or(0, |r| r.env_steps),
        budget_steps: config.iterations() * config.steps_per_iteration(),
        wall_s: rows.iter().rev().find_map(|r| r.wall_s.filter(|w| w.is_finite())).unwrap_or(0.0),
        last_eval,
        steps_per_s,
        speed_estimated: false,
        eval_s: evaluation_seconds(rows),
        eval_estimated: false,
        evals_left: if record.finished { 0 } else { evals_left },
    })
}

/// `n` env steps in millions with two decimals (`9.01M`).
fn millions(n: u64) -> String {
    format!("{:.2}M", n as f64 / 1e6)
}

/// The table `meben status` prints: a header, a line per run, then the totals.
pub fn status_lines(runs: &[RunProgress]) -> Vec<String> {
    let mut lines = vec![format!(
        "{:<44} {:<10} {:>9} {:>18} {:>24} {:>11} {:>8} {:>10}",
        "run", "state", "iteration", "env steps", "last evaluation", "env steps/s", "wall h", "hours left"
    )];
    for r in runs {
        let state = match &r.state {
            RunState::Finished => "finished",
            RunState::Training(_) => "training",
            RunState::Stopped => "stopped",
            RunState::NotStarted => "new",
            RunState::Queued => "queued",
        };
        let eval = match &r.last_eval {
            Some((col, steps, v)) => {
                format!(
                    "{} {:.2}% at {}",
                    col.trim_start_matches("eval_").replace("_rate", ""),
                    v * 100.0,
                    millions(*steps)
                )
            }
            None => "-".into(),
        };
        let or_dash = |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |x| format!("{x:.digits$}"));
        lines.push(format!(
            "{:<44} {:<10} {:>9} {:>18} {:>24} {:>11} {:>8.1} {:>10}",
            r.run.display().to_string(),
            state,
            r.iteration,
            format!("{} of {}", millions(r.env_steps), millions(r.budget_steps)),
            eval,
            if r.speed_estimated { format!("~{}", or_dash(r.steps_per_s, 0)) } else { or_dash(r.steps_per_s, 0) },
            r.wall_s / 3600.0,
            match r.hours_left() {
                Some(h) if r.eval_estimated => format!("~{h:.1}"),
                h => or_dash(h, 1),
            },
        ));
    }
    let open: Vec<&RunProgress> = runs.iter().filter(|r| r.state != RunState::Finished).collect();
    // A fold from +0: an empty f64 sum is -0, which would print as "-0.0".
    let known = open.iter().filter_map(|r| r.hours_left()).fold(0.0, |a, h| a + h);
    let unknown = open.iter().filter(|r| r.hours_left().is_none()).count();
    let uncounted = open.iter().filter(|r| r.hours_left().is_some() && r.evals_uncounted()).count();
    let spent: f64 = runs.iter().map(|r| r.wall_s).sum::<f64>() / 3600.0;
    let mut total = format!(
        "{}, {} finished; {spent:.1} machine-hours spent (wall_s); left: {known:.1} h",
        count(runs.len(), "run"),
        runs.len() - open.len()
    );
    if unknown > 0 {
        total.push_str(&format!(" and {} with no speed yet", count(unknown, "run")));
    }
    if uncounted > 0 {
        total.push_str(&format!(" (and the evaluations of {} with no evaluation cost yet)", count(uncounted, "run")));
    }
    if runs.iter().any(|r| r.speed_estimated || r.eval_estimated) {
        total.push_str("; ~: borrowed from runs of the same env and model");
    }
    lines.push(total);
    for r in &open {
        if let RunState::Training(h) = &r.state {
            lines.push(format!("  {} is training: {h}", r.run.display()));
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::lock::RunLock;
    use crate::app::test_util::TempDir;

    /// A run directory at `root/rel` with the quick preset's config (`steps` env steps) and
    /// the given metrics rows (`iteration,env_steps,wall_s,steps_per_s,eval_episodes,eval_success_rate`).
    fn run_dir(root: &Path, rel: &str, steps: u64, rows: &[&str]) -> PathBuf {
        let mut config = TrainConfig::resolve(None, None, &[]).unwrap();
        config.steps = steps;
        run_dir_with(root, rel, &config, rows)
    }

    /// A run directory at `root/rel` with `config` and the given metrics rows.
    fn run_dir_with(root: &Path, rel: &str, config: &TrainConfig, rows: &[&str]) -> PathBuf {
        let dir = root.join(rel);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("config.toml"), config.to_toml()).unwrap();
        let mut text = "iteration,env_steps,wall_s,steps_per_s,eval_episodes,eval_success_rate\n".to_string();
        for r in rows {
            text.push_str(r);
            text.push('\n');
        }
        std::fs::write(dir.join("metrics.csv"), text).unwrap();
        dir
    }

    #[test]
    fn progress_speed_and_hours_left_of_each_run() {
        let tmp = TempDir::new("status");
        let root = tmp.0.join("runs");
        let per_iter = TrainConfig::resolve(None, None, &[]).unwrap().steps_per_iteration();
        let budget = 10 * per_iter;
        // Three iterations without an evaluation at 100, 300 and 200 env steps/s, one with
        // an evaluation (its slow speed is not training speed), which took 25 s where the
        // others took 10: an evaluation costs 15 s.
        let rows = [
            format!("1,{},10,100,,", per_iter),
            format!("2,{},20,300,,", 2 * per_iter),
            format!("3,{},45,5,128,0.25", 3 * per_iter),
            format!("4,{},55,200,,", 4 * per_iter),
        ];
        let rows: Vec<&str> = rows.iter().map(|s| s.as_str()).collect();
        run_dir(&root, "env/m/seed0", budget, &rows);
        let done = run_dir(&root, "env/m/seed1", budget, &rows);
        std::fs::write(done.join("done.json"), "{}").unwrap();
        let held = run_dir(&root, "env/m/seed2", budget, &[]);
        let mut other_model = TrainConfig::resolve(None, None, &[("model".into(), "\"mlp_hn\"".into())]).unwrap();
        other_model.steps = budget;
        run_dir_with(&root, "env/m2/seed3", &other_model, &[]);

        let runs = status(&root).unwrap();
        assert_eq!(runs.len(), 4);
        let stopped = &runs[0];
        assert_eq!(stopped.run, PathBuf::from("env/m/seed0"));
        assert_eq!(stopped.state, RunState::Stopped);
        assert_eq!((stopped.iteration, stopped.env_steps, stopped.budget_steps), (4, 4 * per_iter, budget));
        assert_eq!(stopped.last_eval, Some(("eval_success_rate".to_string(), 3 * per_iter, 0.25)));
        assert_eq!(stopped.steps_per_s, Some(200.0));
        // The quick preset evaluates after each of the 10 iterations: 6 are still to come.
        assert_eq!((stopped.eval_s, stopped.evals_left, stopped.eval_estimated), (Some(15.0), 6, false));
        let hours = ((6 * per_iter) as f64 / 200.0 + 6.0 * 15.0) / 3600.0;
        assert!((stopped.hours_left().unwrap() - hours).abs() < 1e-12);
        assert_eq!((runs[1].state.clone(), runs[1].hours_left()), (RunState::Finished, Some(0.0)));
        // A run with no speed of its own borrows that of the runs of its env and model...
        let borrowed = &runs[2];
        assert_eq!(
            (borrowed.state.clone(), borrowed.steps_per_s, borrowed.speed_estimated),
            (RunState::NotStarted, Some(200.0), true)
        );
        assert_eq!((borrowed.eval_s, borrowed.evals_left, borrowed.eval_estimated), (Some(15.0), 10, true));
        let hours_new = ((10 * per_iter) as f64 / 200.0 + 10.0 * 15.0) / 3600.0;
        assert!((borrowed.hours_left().unwrap() - hours_new).abs() < 1e-12);
        // ... and none where there is none.
        assert_eq!(
            (runs[3].state.clone(), runs[3].steps_per_s, runs[3].hours_left()),
            (RunState::NotStarted, None, None)
        );

        // A run whose lock another holder has is training; its holder is named.
        let lock = RunLock::acquire(&held).unwrap();
        let runs = status(&root).unwrap();
        let RunState::Training(h) = &runs[2].state else { panic!("{:?}", runs[2].state) };
        assert!(h.contains(&format!("process {}", std::process::id())), "{h}");
        let lines = status_lines(&runs);
        assert_eq!(lines.len(), 1 + 4 + 2, "{lines:#?}");
        assert!(lines[1].contains("stopped") && lines[1].contains("success 25.00% at"), "{}", lines[1]);
        assert!(lines[3].contains(" ~200 ") && lines[3].ends_with(&format!(" ~{hours_new:.1}")), "{}", lines[3]);
        let left = format!("left: {:.1} h and 1 run with no speed yet;", hours + hours_new);
        assert!(lines[5].contains(&left) && lines[5].contains("~: borrowed"), "{}", lines[5]);
        assert!(!lines[5].contains("no evaluation cost"), "{}", lines[5]);
        assert!(lines[6].contains("env/m/seed2 is training: process"), "{}", lines[6]);
        drop(lock);
        assert_eq!(status(&root).unwrap()[2].state, RunState::NotStarted);
        // With every run finished nothing is left (and no "-0.0").
        let finished = status(&root.join("env/m/seed1")).unwrap();
        assert!(status_lines(&finished)[2].contains("left: 0.0 h"), "{:?}", status_lines(&finished));
        assert_eq!((finished[0].evals_left, finished[0].hours_left()), (0, Some(0.0)));
        assert_eq!(finished[0].run, root.join("env/m/seed1"));
    }

    #[test]
    fn a_sweeps_runs_without_a_directory_are_queued_with_their_siblings_speed() {
        let tmp = TempDir::new("status-sweep");
        let root = tmp.0.join("out");
        std::fs::create_dir_all(&root).unwrap();
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\", \"shnn\"]\nseeds = [0, 1]\n\
                    preset = \"quick\"\n[config]\nsteps = 1000000\n";
        std::fs::write(root.join("sweep.toml"), text).unwrap();
        // Before any run has a directory, all four are queued, with no speed.
        let runs = status(&root).unwrap();
        assert_eq!(runs.len(), 4);
        assert!(runs.iter().all(|r| r.state == RunState::Queued && r.hours_left().is_none()));
        let sweep = Sweep::load(&root.join("sweep.toml")).unwrap();
        let first = &sweep.runs().unwrap()[0];
        assert_eq!(first.name, "team_reach_1_ant/mlp_hn/seed0");
        let per_iter = first.config.steps_per_iteration();
        let row = format!("1,{per_iter},10,400,,");
        run_dir_with(&root, &first.name, &first.config, &[&row]);
        let runs = status(&root).unwrap();
        let names: Vec<String> = runs.iter().map(|r| r.run.display().to_string()).collect();
        assert_eq!(
            names,
            [
                "team_reach_1_ant/mlp_hn/seed0",
                "team_reach_1_ant/mlp_hn/seed1",
                "team_reach_1_ant/shnn/seed0",
                "team_reach_1_ant/shnn/seed1"
            ]
        );
        assert_eq!(
            (runs[0].state.clone(), runs[0].steps_per_s, runs[0].speed_estimated),
            (RunState::Stopped, Some(400.0), false)
        );
        assert_eq!(
            (runs[1].state.clone(), runs[1].steps_per_s, runs[1].speed_estimated),
            (RunState::Queued, Some(400.0), true)
        );
        assert_eq!(runs[1].budget_steps, first.config.iterations() * per_iter);
        // No run has evaluated yet: the hours count training alone, and the total says so.
        assert!((runs[1].hours_left().unwrap() - runs[1].budget_steps as f64 / 400.0 / 3600.0).abs() < 1e-12);
        assert!((runs[0].eval_s, runs[1].eval_s) == (None, None) && runs[1].evals_left > 0);
        let total = status_lines(&runs)[5].clone();
        assert!(total.contains("(and the evaluations of 2 runs with no evaluation cost yet)"), "{total}");
        assert!(runs[2..].iter().all(|r| r.state == RunState::Queued && r.steps_per_s.is_none()));
        // A malformed sweep copy is an error naming it.
        std::fs::write(root.join("sweep.toml"), "envs = 3\n").unwrap();
        let msg = status(&root).unwrap_err().to_string();
        assert!(msg.contains("sweep.toml") && msg.contains("envs"), "{msg}");
    }

    #[test]
    fn the_evaluation_is_named_by_its_metric() {
        let mut r = queued_run("team_sumo_2_ants/shnn/seed0", &TrainConfig::resolve(None, None, &[]).unwrap());
        r.last_eval = Some(("eval_win_rate_t0".into(), 1_003_520, 0.1387));
        let lines = status_lines(&[r]);
        assert!(lines[1].contains(" win_t0 13.87% at 1.00M "), "{lines:?}");
    }

    #[test]
    fn a_directory_without_runs_is_an_error_naming_it() {
        let tmp = TempDir::new("status-empty");
        let msg = status(&tmp.0).unwrap_err().to_string();
        assert!(msg.contains(&tmp.0.display().to_string()) && msg.contains("no run directory"), "{msg}");
    }
}
