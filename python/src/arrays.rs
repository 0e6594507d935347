//! Moving arrays across the boundary: observations out as a dict of numpy arrays
//! (`vectors [B, N, 3, 3]`, `scalars [B, N, S]`, `heading [B, A]`), `[B, K]` float32 arrays
//! in, checked for dtype and shape ([`read_f32`]) and finiteness ([`check_finite`]) with
//! errors that name the argument.

use envs::layout::{N_SCALARS, Observation};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::bad_argument;

/// `data` (row-major) as a numpy array of `shape`.
pub fn array<'py, T: numpy::Element + Copy>(
    py: Python<'py>,
    data: &[T],
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_slice(py, data).reshape(shape)?.into_any())
}

/// Python's `repr` of the string `s` (for the classes' `__repr__`).
pub fn py_repr(py: Python<'_>, s: &str) -> PyResult<String> {
    Ok(pyo3::types::PyString::new(py, s).repr()?.to_string())
}

/// An observation as `{"vectors", "scalars", "heading"}` (fresh arrays, owned by Python).
pub fn obs_dict<'py>(py: Python<'py>, o: &Observation) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("vectors", array(py, &o.vectors, &[o.batch, o.nodes, 3, 3])?)?;
    d.set_item("scalars", array(py, &o.scalars, &[o.batch, o.nodes, N_SCALARS])?)?;
    d.set_item("heading", array(py, &o.heading, &[o.batch, o.agents])?)?;
    Ok(d)
}

/// Copies `value`, which must be a float32 numpy array of exactly `shape`, into `out`
/// (row-major, any memory layout). `what` names the argument in errors. Non-finite entries
/// are left to the caller (the environment names the environment and action).
pub fn read_f32(value: &Bound<'_, PyAny>, what: &str, shape: &[usize], out: &mut Vec<f32>) -> PyResult<()> {
    let Ok(untyped) = value.cast::<PyUntypedArray>() else {
        let ty = value.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into());
        return Err(bad_argument(
            what,
            format!("a {ty}"),
            &format!("expected a numpy float32 array of shape {shape:?}"),
        ));
    };
    let got: Vec<usize> = untyped.shape().to_vec();
    let Ok(typed) = value.cast::<numpy::PyArrayDyn<f32>>() else {
        let dtype = untyped.dtype().str().map(|s| s.to_string()).unwrap_or_else(|_| "?".into());
        return Err(bad_argument(
            what,
            format!("an array of dtype {dtype} and shape {got:?}"),
            &format!("expected dtype float32 (e.g. x.astype(numpy.float32)) and shape {shape:?}"),
        ));
    };
    if got != shape {
        return Err(bad_argument(what, format!("an array of shape {got:?}"), &format!("expected shape {shape:?}")));
    }
    let view = typed.readonly();
    out.clear();
    out.extend(view.as_array().iter().copied());
    Ok(())
}

/// `ValueError` at the first entry of `values` (row-major, of `shape`) that is NaN or
/// infinite, naming the argument `what`, the entry's index and its value:
/// `bad obs["scalars"][1, 4, 7] = NaN: must be finite (the first non-finite entry)`.
pub fn check_finite(values: &[f32], what: &str, shape: &[usize]) -> PyResult<()> {
    let Some(flat) = values.iter().position(|x| !x.is_finite()) else {
        return Ok(());
    };
    let mut index = vec![0; shape.len()];
    let mut rest = flat;
    for (i, &d) in index.iter_mut().zip(shape).rev() {
        *i = rest % d.max(1);
        rest /= d.max(1);
    }
    let index: Vec<String> = index.iter().map(|i| i.to_string()).collect();
    Err(bad_argument(
        &format!("{what}[{}]", index.join(", ")),
        values[flat],
        "must be finite (the first non-finite entry)",
    ))
}
