//! Ctrl-C and SIGTERM in the `meben` program's training commands: the first sets the
//! training's [`StopFlag`] ([`crate::stop`]), so the run stops after its current iteration
//! with a checkpoint and the program exits with [`INTERRUPTED_EXIT_CODE`]; the second ends
//! the program at once, which loses at most the iterations since the last checkpoint (every
//! file is written atomically, so the run directory stays consistent either way).

use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::{Result, RlError};
use crate::stop::StopFlag;

/// Exit status of the `meben` program after an interruption (128 + SIGINT, as shells report
/// a process ended by Ctrl-C).
pub const INTERRUPTED_EXIT_CODE: u8 = 130;

/// Makes Ctrl-C (SIGINT) and SIGTERM set `flag`, saying so on standard error; the second
/// signal ends the process at once with [`INTERRUPTED_EXIT_CODE`]. A process has one such
/// handler, so a second call fails.
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
