//! `meben.train`: the `meben train` trainer from Python, with the same configuration layers
//! (a preset, a TOML file, then field overrides) and the same run directory.

use pyo3::prelude::*;
use rl::{Preset, RunDir, TrainConfig, TrainOptions};

use crate::errors::rl_error;

/// Trains into the run directory `out` (resuming it if it holds a checkpoint) with the
/// configuration resolved from `preset` (`quick` or `paper`), the TOML file `config`, then
/// `overrides` (`(field, TOML value)` pairs, as `meben train --set field=value`). Returns the
/// run summary (`done.json`) as JSON text. The GIL is released while training.
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
    let preset = preset.map(|p| Preset::parse(p, "meben.train(preset=...)")).transpose().map_err(rl_error)?;
    let config =
        TrainConfig::resolve_from(preset, config.as_deref(), &overrides, "meben.train keywords").map_err(rl_error)?;
    let options = TrainOptions { progress, ..TrainOptions::default() };
    let summary = py.detach(|| rl::train(&config, &RunDir::new(out), &options)).map_err(rl_error)?;
    serde_json::to_string(&summary).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}
