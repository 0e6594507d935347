//! Stopping long work cleanly on request: a [`StopFlag`] that whoever asks sets (the
//! `meben` program on Ctrl-C or SIGTERM, [`crate::app::signals`]; the Python binding on a
//! `KeyboardInterrupt`; a library user from another thread) and the work reads at points
//! where stopping leaves everything consistent:
//!
//! - [`crate::app::run::train`] reads it once after every iteration (and its evaluations,
//!   if one is due): once it is set, the run writes a checkpoint of that iteration and
//!   returns [`crate::RlError::Interrupted`], and the same command resumes it exactly.
//! - [`crate::mappo::evaluate::evaluate_unless_stopped`] reads it before every control
//!   step and returns no summary once it is set.
//!
//! Shared by `mappo` and `app`, like [`crate::error`].

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A request to stop, shared by clones (the requester keeps one, the work reads another).
/// A new flag is not set.
#[derive(Clone, Debug, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag that is not set.
    pub fn new() -> StopFlag {
        StopFlag::default()
    }

    /// Asks the work to stop at its next stopping point.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether a stop was asked for.
    pub fn is_requested(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}
