//! Seed arguments (issue 77): a seed is taken from Python as an `i128`, so that a negative
//! or too large one is a `ValueError` naming it and the accepted range, not pyo3's
//! `OverflowError` (which a seed of 2^63 or more used to raise).

use pyo3::PyResult;

use crate::errors::bad_argument;

/// The largest seed `meben.make` takes (the largest integer a TOML configuration holds, as
/// `meben train --seed`).
pub const MAX_ENV_SEED: u64 = i64::MAX as u64;

/// `value` as a seed in `0 ..= max`, else `ValueError("bad <what> = <value>: ...")`.
pub fn seed(what: &str, value: i128, max: u64) -> PyResult<u64> {
    if value < 0 || value > i128::from(max) {
        return Err(bad_argument(what, value, &format!("must be an integer in 0 ..= {max}")));
    }
    Ok(value as u64)
}
