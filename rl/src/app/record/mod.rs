//! A run directory read back ([`RunRecord`]): its configuration (`config.toml`), its
//! metrics as typed rows (`metrics.csv`, [`rows`]) and its summary (`done.json`,
//! [`RunSummary`], written by [`crate::app::run::train`]), for
//! everything that reads runs rather than trains them: `meben report`, `meben status`,
//! `meben export`, a run's learning curve ([`crate::app::curve`]) and Python's
//! `meben.read_metrics`. [`find_run_dirs`] finds the runs of a directory tree.

pub mod rows;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use rows::{Episodes, IterationRow, MetricsTable, Rate};

use crate::app::run_dir::RunDir;
use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;
use crate::mappo::evaluate::EvalSummary;

/// What a run directory holds (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct RunRecord {
    /// The directory.
    pub dir: RunDir,
    /// `config.toml`, the resolved configuration of its latest training session.
    pub config: TrainConfig,
    /// `metrics.csv`.
    pub metrics: MetricsTable,
    /// Whether `done.json` exists: the run is finished.
    pub finished: bool,
    /// `done.json` ([`read_summary`]), when it exists and reads.
    pub summary: Option<RunSummary>,
}

impl RunRecord {
    /// Reads the run directory `dir`: its configuration, then its metrics (errors name the
    /// file, and the line and column of a malformed metrics file), then its summary.
    pub fn read(dir: &Path) -> Result<RunRecord> {
        let run = RunDir::new(dir);
        let config = TrainConfig::load(&run.config())?;
        let metrics = MetricsTable::read(&run.metrics())?;
        let finished = run.done().is_file();
        let summary = read_summary(&run);
        Ok(RunRecord { dir: run, config, metrics, finished, summary })
    }

    /// The rows of `metrics.csv`.
    pub fn rows(&self) -> &[IterationRow] {
        &self.metrics.rows
    }

    /// This run as it stood once it had collected `steps` env steps: only its rows with
    /// `env_steps <= steps`, and a budget of at most `steps`. A run that trained past them
    /// is no longer finished there (no `done.json` summary); one that stopped before them
    /// is unchanged. What `meben report --at-steps` reads, to compare runs at one budget.
    pub fn up_to(mut self, steps: u64) -> RunRecord {
        let before = self.metrics.rows.len();
        self.metrics.rows.retain(|r| r.env_steps <= steps);
        if self.metrics.rows.len() < before {
            self.finished = false;
            self.summary = None;
        }
        self.config.steps = self.config.steps.min(steps);
        self
    }
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
    /// The last evaluation (unrotated: the first of `eval_rotations`).
    pub final_eval: Option<EvalSummary>,
    /// The last evaluation at each further rotation of `eval_rotations`, in order.
    #[serde(default)]
    pub final_eval_rotated: Vec<EvalSummary>,
}

/// A run's summary, `done.json`, if it exists and reads as one: a damaged or foreign
/// `done.json` still marks the run finished ([`RunDir::status`]) but has no summary.
pub fn read_summary(run: &RunDir) -> Option<RunSummary> {
    let text = std::fs::read_to_string(run.done()).ok()?;
    serde_json::from_str(&text).ok()
}

/// Whether `dir` is a run directory: it holds `config.toml` and `metrics.csv`.
pub fn is_run_dir(dir: &Path) -> bool {
    let run = RunDir::new(dir);
    run.config().is_file() && run.metrics().is_file()
}

/// Every run directory ([`is_run_dir`]) at or under `root`, sorted; directories inside a
/// run, hidden directories and symbolic links are not searched.
pub fn find_run_dirs(root: &Path) -> Result<Vec<PathBuf>> {
    if !root.is_dir() {
        return Err(RlError::file(root, "not a directory"));
    }
    let mut found = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        if is_run_dir(&dir) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::test_util::TempDir;

    #[test]
    fn a_run_directory_reads_with_its_summary_and_errors_name_the_file() {
        let tmp = TempDir::new("record");
        let dir = tmp.0.join("runs/e/m/seed0");
        std::fs::create_dir_all(&dir).unwrap();
        let run = RunDir::new(&dir);
        let config = TrainConfig::resolve(None, None, &[]).unwrap();
        config.save(&run.config()).unwrap();
        std::fs::write(run.metrics(), "iteration,env_steps,wall_s\n1,100,2.5\n2,200,5\n").unwrap();
        // A run in a hidden directory is not searched.
        let hidden = tmp.0.join("runs/.hidden/seed0");
        std::fs::create_dir_all(&hidden).unwrap();
        std::fs::copy(run.config(), hidden.join("config.toml")).unwrap();
        std::fs::copy(run.metrics(), hidden.join("metrics.csv")).unwrap();
        assert_eq!(find_run_dirs(&tmp.0).unwrap(), std::slice::from_ref(&dir));

        let r = RunRecord::read(&dir).unwrap();
        assert_eq!((r.config.clone(), r.finished, r.summary.clone()), (config, false, None));
        assert_eq!(
            r.rows().iter().map(|r| (r.iteration, r.env_steps, r.wall_s)).collect::<Vec<_>>(),
            [(1, 100, Some(2.5)), (2, 200, Some(5.0))]
        );
        // A damaged done.json: finished, without a summary; a real one reads.
        std::fs::write(run.done(), "{}").unwrap();
        let r = RunRecord::read(&dir).unwrap();
        assert!(r.finished && r.summary.is_none());
        let summary = RunSummary { iterations: 2, env_steps: 200, wall_s: 5.0, ..Default::default() };
        std::fs::write(run.done(), serde_json::to_string(&summary).unwrap()).unwrap();
        assert_eq!(RunRecord::read(&dir).unwrap().summary, Some(summary));

        // Up to 150 env steps: the first row, a budget of 150, no longer finished; up to
        // 200, every row and still finished, with a budget of 200; up to more than its
        // budget, the whole run.
        let early = RunRecord::read(&dir).unwrap().up_to(150);
        assert_eq!(early.rows().iter().map(|r| r.iteration).collect::<Vec<_>>(), [1]);
        assert_eq!((early.config.steps, early.finished, early.summary.is_none()), (150, false, true));
        let whole = RunRecord::read(&dir).unwrap();
        let at_end = whole.clone().up_to(200);
        assert_eq!((at_end.rows(), at_end.finished, at_end.config.steps), (whole.rows(), true, 200));
        assert_eq!(whole.clone().up_to(u64::MAX), whole);

        std::fs::write(run.metrics(), "iteration,env_steps\n1,x\n").unwrap();
        let e = RunRecord::read(&dir).unwrap_err().to_string();
        assert!(e.starts_with(&run.metrics().display().to_string()) && e.contains("line 2: column env_steps"), "{e}");
        std::fs::write(run.config(), "steps = \"many\"\n").unwrap();
        let e = RunRecord::read(&dir).unwrap_err().to_string();
        assert!(e.contains("config.toml"), "{e}");
        let e = find_run_dirs(&tmp.0.join("missing")).unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("not a directory"), "{e}");
    }
}
