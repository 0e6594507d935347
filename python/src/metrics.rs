//! `meben.read_metrics`: a run's `metrics.csv` as numpy columns, read by the Rust reader
//! of run directories that `meben report` uses (`rl::app::record::MetricsTable`).

use std::path::PathBuf;

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::array;

/// The metrics of `path` (a run directory, or a metrics CSV file) as a dict of column name
/// to a float64 array with one value per iteration, in the file's column order; an empty
/// cell (a value that does not apply or was not measured, e.g. `eval_*` between
/// evaluations) is NaN. A missing file raises `OSError`, a malformed one (a cell that is
/// not a number, a row without `iteration` or `env_steps`) `ValueError`, both naming the
/// file.
#[pyfunction]
pub fn read_metrics(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let file = if path.is_dir() { rl::RunDir::new(&path).metrics() } else { path };
    let text = std::fs::read_to_string(&file)
        .map_err(|e| PyOSError::new_err(format!("{}: cannot read the metrics: {e}", file.display())))?;
    let table = rl::app::record::MetricsTable::parse(&text)
        .map_err(|e| PyValueError::new_err(format!("{}: {e}", file.display())))?;
    let out = PyDict::new(py);
    for name in &table.columns {
        let values = table.column(name);
        out.set_item(name, array(py, &values, &[values.len()])?)?;
    }
    Ok(out)
}
