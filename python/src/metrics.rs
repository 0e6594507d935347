//! `meben.read_metrics`: a run's `metrics.csv` as numpy columns, read by the Rust reader
//! that `meben report` uses (`rl::app::metrics::parse_columns`).

use std::path::PathBuf;

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::array;

/// The metrics of `path` (a run directory, or a metrics CSV file) as a dict of column name
/// to a float64 array with one value per iteration, in the file's column order; an empty
/// cell (a value that does not apply or was not measured, e.g. `eval_*` between
/// evaluations) is NaN. A missing file raises `OSError`, a malformed one `ValueError`, both
/// naming the file.
#[pyfunction]
pub fn read_metrics(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let file = if path.is_dir() { rl::RunDir::new(&path).metrics() } else { path };
    let text = std::fs::read_to_string(&file)
        .map_err(|e| PyOSError::new_err(format!("{}: cannot read the metrics: {e}", file.display())))?;
    let columns = rl::app::metrics::parse_columns(&text)
        .map_err(|e| PyValueError::new_err(format!("{}: {e}", file.display())))?;
    let out = PyDict::new(py);
    for (name, values) in columns {
        out.set_item(name, array(py, &values, &[values.len()])?)?;
    }
    Ok(out)
}
