//! The layout of a run directory, shared by training, evaluation, the sweep runner and the
//! report:
//!
//! | file | written | holds |
//! |---|---|---|
//! | `config.toml` | at the start | the resolved [`crate::TrainConfig`] |
//! | `metrics.csv` | every iteration | one row per iteration (the columns of [`crate::app::metrics::MetricsLayout`]) |
//! | `checkpoint.json` | every `checkpoint_every` iterations, after evaluations, at the end | everything needed to resume exactly ([`crate::mappo::checkpoint`]) |
//! | `curve.svg` | after every evaluation | the learning curve |
//! | `done.json` | at the end | the [`crate::RunSummary`]; a run with it is finished |
//! | `builds.csv` | at the start and at each resume | a row per training session: the iteration it went on from, the program's version and git commit ([`crate::app::build_info`]) |
//! | `lock` | at the start | the process id and host of the training that holds the directory's lock ([`crate::app::lock`]) |
//!
//! [`load_policies`] reads the trained teams of a run directory back.
//!
//! Every file is written atomically (a temporary file, then a rename), so an interrupted run
//! leaves either the old or the new version; the temporary files of a killed run are removed
//! when training resumes. `metrics.csv` and `builds.csv` grow by appended rows, one write a
//! row (a resumed run rewrites `metrics.csv` atomically up to its checkpoint first).

use std::path::{Path, PathBuf};

use crate::error::{Result, RlError};
use crate::mappo::checkpoint::Checkpoint;
use crate::mappo::config::TrainConfig;
use crate::mappo::team::Team;

/// Where a run's files live.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

/// How far a run directory got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunStatus {
    /// No checkpoint: training starts from scratch.
    New,
    /// A checkpoint but no `done.json`: training resumes from the checkpoint.
    Partial,
    /// `done.json` exists: the run is finished.
    Done,
}

impl RunDir {
    /// A run directory at `root` (not created).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `config.toml`.
    pub fn config(&self) -> PathBuf {
        self.root.join("config.toml")
    }

    /// `metrics.csv`.
    pub fn metrics(&self) -> PathBuf {
        self.root.join("metrics.csv")
    }

    /// `checkpoint.json`.
    pub fn checkpoint(&self) -> PathBuf {
        self.root.join("checkpoint.json")
    }

    /// `curve.svg`.
    pub fn curve(&self) -> PathBuf {
        self.root.join("curve.svg")
    }

    /// `done.json`.
    pub fn done(&self) -> PathBuf {
        self.root.join("done.json")
    }

    /// `builds.csv`.
    pub fn builds(&self) -> PathBuf {
        self.root.join(crate::app::build_info::BUILDS_FILE)
    }

    /// The run's status from the files present.
    pub fn status(&self) -> RunStatus {
        if self.done().is_file() {
            RunStatus::Done
        } else if self.checkpoint().is_file() {
            RunStatus::Partial
        } else {
            RunStatus::New
        }
    }
}

/// The trained teams of a run directory (its `config.toml` and `checkpoint.json`): the
/// models with their parameters and normalisers, ready for [`crate::mappo::evaluate::evaluate`] or
/// rendering.
pub fn load_policies(run: &RunDir) -> Result<(TrainConfig, Vec<Team>)> {
    if !run.config().is_file() {
        return Err(RlError::file(
            run.config(),
            "no such file: not a run directory (expected config.toml and checkpoint.json)",
        ));
    }
    let config = TrainConfig::load(&run.config())?;
    let path = run.checkpoint();
    let c = Checkpoint::load(&path)?;
    let spec = envs::tasks::Scene::from_name(&config.env)?.obs_spec;
    if c.teams.len() != spec.n_teams {
        return Err(RlError::Checkpoint {
            path,
            message: format!("{} teams for a scene of {} teams", c.teams.len(), spec.n_teams),
        });
    }
    let mut teams = Vec::new();
    for (k, s) in c.teams.iter().enumerate() {
        let mut t = Team::build(&config, &spec, k)?;
        s.params
            .load_into(&mut t.store)
            .map_err(|e| RlError::Checkpoint { path: path.clone(), message: e.to_string() })?;
        s.normalizer.check_fits(&t.norm).map_err(|e| RlError::Checkpoint {
            path: path.clone(),
            message: format!("the observation normaliser of team {k} does not fit: {e}"),
        })?;
        t.norm = s.normalizer.clone();
        teams.push(t);
    }
    Ok((config, teams))
}
