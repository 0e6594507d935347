//! Long Rust work that Ctrl-C can stop from Python: the work runs on a thread of its own
//! while the calling thread, holding the GIL a moment every 50 ms (`SIGNAL_POLL`), lets Python
//! run its signal handlers. A `KeyboardInterrupt` (Ctrl-C, or a notebook's interrupt) sets
//! the work's [`StopFlag`] (`rl::stop`: a training stops after its current iteration with a
//! checkpoint, an evaluation before its next step), and is returned once the work has
//! stopped, to be raised in its place. Before, the work held the thread until it finished
//! and an interrupt waited for it.

use std::sync::{Condvar, Mutex};
use std::time::Duration;

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use rl::StopFlag;

/// How often the waiting thread takes the GIL to run Python's signal handlers.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Runs `work` on a scoped thread until it returns (its parallel loops on the pool of
/// [`crate::pool::forked_pool`]); a `KeyboardInterrupt` meanwhile sets
/// `stop` and prints `stopping` (what happens now) to standard error. Returns the work's
/// result and the interrupt, if one came.
pub fn run_interruptible<T: Send>(
    py: Python<'_>,
    stop: &StopFlag,
    stopping: &str,
    work: impl FnOnce() -> T + Send,
) -> PyResult<(T, Option<PyErr>)> {
    // The worker says when it is done (also if it panics: the guard's drop), so that short
    // work returns at once rather than after a whole poll interval.
    let done = Finished::default();
    let pool = crate::pool::forked_pool()?;
    std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            let _guard = FinishGuard(&done);
            crate::pool::run_on(pool.as_deref(), work)
        });
        let mut interrupt: Option<PyErr> = None;
        while !py.detach(|| done.wait(SIGNAL_POLL)) {
            if interrupt.is_none()
                && let Err(e) = py.check_signals()
            {
                stop.request();
                eprintln!("{stopping}");
                interrupt = Some(e);
            }
        }
        // A panic is a bug in the Rust core (bad input is an error, not a panic).
        let result = worker.join().map_err(|_| PyRuntimeError::new_err("meben: the Rust core panicked (a bug)"))?;
        Ok((result, interrupt))
    })
}

/// Whether the work is done, and a way to wait for it.
#[derive(Default)]
struct Finished {
    done: Mutex<bool>,
    changed: Condvar,
}

impl Finished {
    /// Waits at most `timeout` for the work to be done; whether it is.
    fn wait(&self, timeout: Duration) -> bool {
        let done = self.done.lock().unwrap_or_else(|e| e.into_inner());
        let (done, _) = self.changed.wait_timeout_while(done, timeout, |d| !*d).unwrap_or_else(|e| e.into_inner());
        *done
    }
}

/// Marks the work done when dropped: when the work returns or unwinds.
struct FinishGuard<'a>(&'a Finished);

impl Drop for FinishGuard<'_> {
    fn drop(&mut self) {
        *self.0.done.lock().unwrap_or_else(|e| e.into_inner()) = true;
        self.0.changed.notify_all();
    }
}
