//! The Rust core of the `meben` Python package (`meben._core`): batched MeBen environments
//! ([`env`](mod@env)), trained policies ([`policy`]), training ([`train`](mod@train)) and run
//! metrics ([`metrics`](mod@metrics)) over the `envs` and `rl` crates, with numpy arrays
//! across the boundary ([`arrays`]), Rust errors as Python exceptions ([`errors`]) and long
//! work that Ctrl-C can stop ([`interrupt`]), parallel work in forked processes ([`pool`]).
//! The plain-Python parts (`make`, the Gymnasium and PettingZoo adapters) are in
//! `python/python/meben/`.

pub mod arrays;
pub mod env;
pub mod errors;
pub mod interrupt;
pub mod metrics;
pub mod policy;
pub mod pool;
pub mod recorder;
pub mod seed;
pub mod spec;
pub mod train;

use pyo3::prelude::*;

/// The extension module `meben._core`.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    pool::init();
    m.add_class::<env::PyVecEnv>()?;
    m.add_class::<policy::PyPolicy>()?;
    m.add_function(wrap_pyfunction!(train::train, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::read_metrics, m)?)?;
    let names: Vec<&str> = envs::tasks::BUILTIN_NAMES.to_vec();
    m.add("BUILTIN_NAMES", names)?;
    m.add("OUTCOMES", ("running", "success", "win_team0", "win_team1", "draw", "time_limit", "diverged"))?;
    m.add("__version__", rl::app::build_info::VERSION)?;
    m.add("BUILD_COMMIT", rl::app::build_info::COMMIT)?;
    Ok(())
}
