//! `meben.train`: the `meben train` trainer from Python, with the same configuration layers
//! (a preset, a TOML file, then field overrides) and the same run directory.
//!
//! A `KeyboardInterrupt` stops the training after its current iteration with a checkpoint
//! ([`crate::interrupt`]) and is raised once it has, so the same call resumes the run.

use pyo3::prelude::*;
use rl::{Preset, RlError, RunDir, StopFlag, TrainConfig, TrainOptions};

use crate::errors::{bad_argument, rl_error};
use crate::interrupt::run_interruptible;

/// Trains into the run directory `out` (resuming it if it holds a checkpoint) with the
/// configuration resolved from `preset` (`quick` or `paper`), the TOML file `config`, then
/// `overrides` (`(field, TOML value)` pairs, as `meben train --set field=value`). Returns the
/// run summary (`done.json`) as JSON text. The GIL is released while training; a
/// `KeyboardInterrupt` stops it after its current iteration with a checkpoint and is then
/// raised (module docs). An empty `out` raises `ValueError` before anything is read or
/// written (it would make the working directory the run directory).
#[pyfunction]
#[pyo3(signature = (out, overrides, preset=None, config=None, progress=false))]
pub fn train(
    py: Python<'_>,
    out: std::path::PathBuf,
    overrides: Vec<(String, String)>,
    preset: Option<&str>,
    config: Option<std::path::PathBuf>,
    progress: bool,
) -> PyResult<String> {
    if out.as_os_str().is_empty() {
        return Err(bad_argument(
            "out",
            "''",
            "expected the run directory's path (e.g. out=\"runs/x\"); an empty path would train into the working \
             directory",
        ));
    }
    let preset = preset.map(|p| Preset::parse(p, "meben.train(preset=...)")).transpose().map_err(rl_error)?;
    let config =
        TrainConfig::resolve_from(preset, config.as_deref(), &overrides, "meben.train keywords").map_err(rl_error)?;
    let stop = StopFlag::new();
    let options = TrainOptions { progress, stop: stop.clone(), ..TrainOptions::default() };
    let run = RunDir::new(out);
    let stopping = "meben.train: interrupted: stopping after the current iteration with a checkpoint";
    let (result, interrupt) = run_interruptible(py, &stop, stopping, || rl::train(&config, &run, &options))?;
    match (result, interrupt) {
        // Stopped on the interrupt: the checkpoint is written, the interrupt goes on up.
        (Err(RlError::Interrupted { .. }), Some(e)) => Err(e),
        (Err(e), _) => Err(rl_error(e)),
        // Finished before the stop took effect (the last iteration): the run is done, and
        // the interrupt is still raised, as Python would have raised it.
        (Ok(_), Some(e)) => Err(e),
        (Ok(summary), None) => {
            serde_json::to_string(&summary).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
        }
    }
}
