//! The layout of a run directory, shared by training, evaluation, the sweep runner and the
//! report:
//!
//! | file | written | holds |
//! |---|---|---|
//! | `config.toml` | at the start | the resolved [`crate::TrainConfig`] |
//! | `metrics.csv` | every iteration | one row per iteration (the columns of [`crate::metrics::MetricsLayout`]) |
//! | `checkpoint.json` | every `checkpoint_every` iterations, after evaluations, at the end | everything needed to resume exactly ([`crate::checkpoint`]) |
//! | `curve.svg` | after every evaluation | the learning curve |
//! | `done.json` | at the end | the [`crate::RunSummary`]; a run with it is finished |
//! | `lock` | at the start | the process id and host of the training that holds the directory's lock ([`crate::lock`]) |
//!
//! Every file is written atomically (a temporary file, then a rename), so an interrupted run
//! leaves either the old or the new version; the temporary files of a killed run are removed
//! when training resumes.

use std::path::{Path, PathBuf};

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
