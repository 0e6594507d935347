//! Rust errors as Python exceptions with the same message: input the caller got wrong
//! (names, compositions, arrays, arguments, configuration values) is a `ValueError`, a file
//! that cannot be read or written an `OSError`, a training stopped on request a
//! `KeyboardInterrupt`, an object that another thread is using a `RuntimeError` saying so
//! ([`try_lock`]), anything else a `RuntimeError`.

use envs::tasks::TaskError;
use std::sync::{Mutex, MutexGuard, TryLockError};

use pyo3::exceptions::{PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyValueError};
use pyo3::{PyErr, PyResult};
use rl::RlError;

/// A task error (every variant is caused by the caller's input) as a `ValueError`.
pub fn task_error(e: TaskError) -> PyErr {
    match e {
        TaskError::Model { .. } => PyRuntimeError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// A training or evaluation error as the matching Python exception (module docs).
pub fn rl_error(e: RlError) -> PyErr {
    match e {
        RlError::Env(t) => task_error(t),
        RlError::Config { .. } | RlError::Checkpoint { .. } | RlError::Policy { .. } => {
            PyValueError::new_err(e.to_string())
        }
        RlError::File { .. } | RlError::RunInUse { .. } => PyOSError::new_err(e.to_string()),
        RlError::Interrupted { .. } => PyKeyboardInterrupt::new_err(e.to_string()),
        RlError::NonFinite { .. } | RlError::Model(_) | RlError::Nn(_) => PyRuntimeError::new_err(e.to_string()),
    }
}

/// A `ValueError` naming the argument, its value and what is accepted.
pub fn bad_argument(what: &str, value: impl std::fmt::Display, message: &str) -> PyErr {
    PyValueError::new_err(format!("bad {what} = {value}: {message}"))
}

/// Locks `m`, or raises `RuntimeError(in_use)` when another thread holds it. A mutex
/// poisoned by a panic (a bug, raised as such then) is used as it is.
pub fn try_lock<'a, T>(m: &'a Mutex<T>, in_use: &str) -> PyResult<MutexGuard<'a, T>> {
    match m.try_lock() {
        Ok(g) => Ok(g),
        Err(TryLockError::Poisoned(e)) => Ok(e.into_inner()),
        Err(TryLockError::WouldBlock) => Err(PyRuntimeError::new_err(in_use.to_string())),
    }
}
