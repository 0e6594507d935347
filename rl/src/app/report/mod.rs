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
//!   deviation / sqrt(n); 0 for one seed) of the final values (and their sample standard
//!   deviation, which the paper's tables give: [`crate::app::paper`]), their interquartile mean
//!   and the 95% percentile-bootstrap confidence intervals of the mean and of the IQM
//!   ([`stats`]: what rliable recommends for few runs), and the env steps reached
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
//!
//! At a matched budget ([`report_at`], `meben report ROOT --at-steps N`): every run is read
//! as it stood after N env steps ([`RunRecord::up_to`]: its rows up to then, a budget of at
//! most N), so that groups whose runs are at different points compare at one budget: each
//! final value is the run's last evaluation at or before N. The same files are written
//! under `ROOT/at_<N>/` ([`at_steps_dir`]), leaving the whole runs' report as it is.
//!
//! The runs are read by [`crate::app::record`]; [`aggregate`] makes the groups and their
//! statistics ([`stats`]), [`render`] writes them as Markdown, CSV and SVG.

pub mod aggregate;
pub mod render;
pub mod stats;

use std::io::Write;
use std::path::{Path, PathBuf};

pub use aggregate::{CurvePoint, GroupReport, StartKind, group_runs};
pub(crate) use render::{count, md_cell};
use render::{curve_plot, render_csv, render_markdown};

use crate::app::names::sanitize_component;
use crate::app::record::{RunRecord, find_run_dirs};
use crate::error::{Result, RlError};

/// What [`report`] found and wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The directory searched.
    pub root: PathBuf,
    /// The directory written: the root, or [`at_steps_dir`] at a matched budget.
    pub dir: PathBuf,
    /// The groups, by environment (built-in order first), then variant.
    pub groups: Vec<GroupReport>,
    /// Run directories without any value yet (relative to the root), with the reason.
    pub pending: Vec<(PathBuf, String)>,
    /// `<dir>/report.md`.
    pub markdown: PathBuf,
    /// `<dir>/report.csv`.
    pub csv: PathBuf,
    /// `<dir>/curves/<env>.svg`, one per environment.
    pub curves: Vec<PathBuf>,
}

/// Reads every run under `root`, writes `report.md`, `report.csv` and `curves/*.svg`
/// there (module docs), prints the path of `report.md`, and returns what it found.
pub fn report(root: &Path) -> Result<Report> {
    report_at(root, None)
}

/// Where [`report_at`] writes the report at `steps` env steps: `<root>/at_<steps>`.
pub fn at_steps_dir(root: &Path, steps: u64) -> PathBuf {
    root.join(format!("at_{steps}"))
}

/// The env steps of a directory named as [`at_steps_dir`] names it (`at_7208960`), or
/// `None` for any other name.
pub fn at_steps_of(dir_name: &str) -> Option<u64> {
    dir_name.strip_prefix("at_")?.parse().ok()
}

/// [`report`], or with `at_steps` the report of every run as it stood after that many env
/// steps, written under [`at_steps_dir`] (module docs). Zero steps is an error.
pub fn report_at(root: &Path, at_steps: Option<u64>) -> Result<Report> {
    if at_steps == Some(0) {
        return Err(RlError::config("meben report", "--at-steps", 0, "a number of env steps above 0"));
    }
    let dirs = find_run_dirs(root)?;
    if dirs.is_empty() {
        return Err(RlError::file(
            root,
            "no run directories found (directories holding config.toml and metrics.csv, at any depth)",
        ));
    }
    let mut records = Vec::with_capacity(dirs.len());
    for dir in &dirs {
        let record = RunRecord::read(dir)?;
        let record = match at_steps {
            Some(steps) => record.up_to(steps),
            None => record,
        };
        records.push((dir.strip_prefix(root).unwrap_or(dir).to_path_buf(), record));
    }
    let (groups, pending) = group_runs(&records);

    let out = at_steps.map_or_else(|| root.to_path_buf(), |steps| at_steps_dir(root, steps));
    let markdown = out.join("report.md");
    let csv = out.join("report.csv");
    let curves_dir = out.join("curves");
    let mut curves = Vec::new();
    let needed = if groups.is_empty() { &out } else { &curves_dir };
    std::fs::create_dir_all(needed).map_err(|e| RlError::file(needed, format!("cannot create the directory: {e}")))?;
    for env in render::envs_in_order(&groups) {
        let path = curves_dir.join(format!("{}.svg", sanitize_component(env)));
        nn::write_atomic(&path, curve_plot(env, &groups).to_svg().as_bytes())?;
        curves.push(path);
    }
    nn::write_atomic(&markdown, render_markdown(root, at_steps, &groups, &pending).as_bytes())?;
    nn::write_atomic(&csv, render_csv(&groups).as_bytes())?;
    // The report's path on standard output; a reader that stopped reading is no error here.
    let _ = writeln!(std::io::stdout(), "{}", markdown.display());
    Ok(Report { root: root.to_path_buf(), dir: out, groups, pending, markdown, csv, curves })
}
