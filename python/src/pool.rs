//! Parallel work in a process forked from the one that loaded the module.
//!
//! The environments, the policies and the evaluation run their parallel loops on rayon's
//! global thread pool. `fork` copies a process with its calling thread only: in a child
//! forked after the parent used the pool (`multiprocessing`'s `fork` start method, the
//! default on Linux before Python 3.14), the global pool's state says its threads exist, but
//! none runs there, and the first parallel loop waits for them for ever (issue 44, item 1).
//!
//! So the module records the id of the process that loaded it ([`init`]); work started in
//! another process (a forked child, or its own children) runs on a pool of that process's
//! own, built there on first use ([`detach`], [`run_on`]) with rayon's default number of
//! threads (`RAYON_NUM_THREADS`, else one per CPU). The process that loaded the module keeps
//! the global pool. Results do not depend on the pool: each environment and each row of the
//! policies' kernels is computed by one thread with the same code.

use std::sync::{Arc, Mutex, OnceLock};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use rayon::ThreadPool;

/// The id of the process that loaded the module (whose rayon global pool works).
static LOADED_IN: OnceLock<u32> = OnceLock::new();

/// The pool of a forked process, with that process's id (a pool copied into a grandchild
/// by a second `fork` has no threads there either, and is replaced).
static FORKED_POOL: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

/// Records the current process as the one that loaded the module (at module init).
pub fn init() {
    LOADED_IN.get_or_init(std::process::id);
}

/// The pool this process's parallel work must run on: `None` in the process that loaded
/// the module (rayon's global pool), else this process's own pool, built on first use.
/// A pool that cannot be built (no thread could be started) is a `RuntimeError`.
pub fn forked_pool() -> PyResult<Option<Arc<ThreadPool>>> {
    let pid = std::process::id();
    if *LOADED_IN.get_or_init(|| pid) == pid {
        return Ok(None);
    }
    let mut slot = FORKED_POOL.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((owner, pool)) = slot.as_ref()
        && *owner == pid
    {
        return Ok(Some(pool.clone()));
    }
    let pool = rayon::ThreadPoolBuilder::new().thread_name(|i| format!("meben-forked-{i}")).build().map_err(|e| {
        PyRuntimeError::new_err(format!("meben: cannot start the thread pool of this forked process: {e}"))
    })?;
    let pool = Arc::new(pool);
    // A pool inherited from the parent by a second fork has no threads here: dropping it
    // would signal threads that do not exist, so it is left alone (leaked).
    if let Some(stale) = slot.replace((pid, pool.clone())) {
        std::mem::forget(stale);
    }
    Ok(Some(pool))
}

/// Runs `work` on `pool` (see [`forked_pool`]), or on the calling thread with rayon's global
/// pool when there is none.
pub fn run_on<R: Send>(pool: Option<&ThreadPool>, work: impl FnOnce() -> R + Send) -> R {
    match pool {
        Some(p) => p.install(work),
        None => work(),
    }
}

/// Runs `work` with the GIL released, on the pool this process must use ([`forked_pool`]).
pub fn detach<R: Send>(py: Python<'_>, work: impl FnOnce() -> R + Send) -> PyResult<R> {
    let pool = forked_pool()?;
    Ok(py.detach(|| run_on(pool.as_deref(), work)))
}
