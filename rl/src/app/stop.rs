//! Stopping a training cleanly on request: a [`StopFlag`] that [`crate::app::run::train`]
//! reads once after every iteration. Once it is set, the run writes a checkpoint of the
//! iteration it just finished and returns [`RlError::Interrupted`]; the same command (or
//! call) resumes it exactly. Whoever asks sets the flag: the `meben` program on Ctrl-C or
//! SIGTERM ([`install_signal_handler`]), the Python binding on a `KeyboardInterrupt`, a
//! library user from another thread.
//!
//! An iteration (with its evaluations, if one is due) is not cut short, so a stop takes
//! effect within one iteration: a second Ctrl-C ends the `meben` program at once, which
//! loses at most the iterations since the last checkpoint (every file is written
//! atomically, so the run directory stays consistent either way).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::error::{Result, RlError};

/// A request to stop, shared by clones (the requester keeps one, the training reads
/// another). A new flag is not set.
#[derive(Clone, Debug, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag that is not set.
    pub fn new() -> StopFlag {
        StopFlag::default()
    }

    /// Asks the training to stop after its current iteration.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether a stop was asked for.
    pub fn is_requested(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// Exit status of the `meben` program after an interruption (128 + SIGINT, as shells report
/// a process ended by Ctrl-C).
pub const INTERRUPTED_EXIT_CODE: u8 = 130;

/// Makes Ctrl-C (SIGINT) and SIGTERM set `flag`, saying so on standard error; the second
/// signal ends the process at once with [`INTERRUPTED_EXIT_CODE`]. For the `meben` program's
/// training commands; a process has one such handler, so a second call fails.
pub fn install_signal_handler(flag: &StopFlag) -> Result<()> {
    let flag = flag.clone();
    let signals = AtomicUsize::new(0);
    ctrlc::set_handler(move || {
        if signals.fetch_add(1, Ordering::SeqCst) == 0 {
            flag.request();
            eprintln!(
                "\nmeben: interrupted: stopping after the current iteration with a checkpoint \
                 (the same command resumes the run); interrupt again to quit at once"
            );
        } else {
            std::process::exit(i32::from(INTERRUPTED_EXIT_CODE));
        }
    })
    .map_err(|e| RlError::config("meben", "signal handler", "Ctrl-C", e.to_string()))
}
