//! Open-loop rollout of an MJCF model, to hold the simulator against another engine: a thin
//! wrapper around [`envs::rollout_tool`] (the same tool is `meben sim`).
//!
//! ```text
//! cargo run --release -p envs --example rollout -- --mjcf FILE --controls CTRL.csv \
//!     --out OUT.csv --frames 5 [--qpos q0,q1,...]
//! ```
//!
//! Writes OUT.csv: a header line `q0,q1,...`, then one row of qpos per control step, the
//! initial state first. Any bad input is reported on stderr with a non-zero exit code.

use clap::Parser;
use envs::rollout_tool::{RolloutArgs, run};
use std::process::ExitCode;

/// Open-loop rollout of an MJCF model; writes qpos per control step.
#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: RolloutArgs,
}

fn main() -> ExitCode {
    match run(&Cli::parse().args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
