//! The application around the algorithm ([`crate::mappo`]): configuration presets and
//! layers ([`presets`]), training in a run directory ([`run`], [`progress`], [`curve`],
//! [`plot`]) and stopping it on Ctrl-C or SIGTERM ([`signals`]), sweeps ([`sweep`],
//! `meben ablate`), reports ([`report`](mod@report), `meben report`), evidence export
//! ([`export`](mod@export), `meben export`), the progress of runs ([`status`](mod@status),
//! `meben status`), parameter counts ([`info`], `meben info`), episode recordings
//! ([`render`], `meben render`), policy files and the shipped pretrained policies
//! ([`policy_file`], `meben export-policy`, `--policy`), the checks of where a command
//! writes ([`outputs`]) and the command line ([`cli`]).
//!
//! **Layers.** At the bottom, the files of a run directory: its layout ([`run_dir`]), file
//! names ([`names`]), its lock ([`lock`]), the copies of its morphology files
//! ([`morphology`]), its builds ([`build_info`]), its metrics columns ([`metrics`]) and
//! reading it back ([`record`]: configuration, typed metrics rows, summary). These use nothing
//! of `app` above them (the crate-graph test in `tests/` checks); the rest builds on them.

pub mod build_info;
pub mod cli;
pub mod curve;
pub mod eval_assignment;
pub mod export;
pub mod info;
pub mod lock;
pub mod metrics;
pub mod morphology;
pub mod names;
pub mod outputs;
pub mod paper;
pub mod plot;
pub mod policy_file;
pub mod policy_morphology;
pub mod presets;
pub mod progress;
pub mod record;
pub mod render;
pub mod report;
pub mod run;
pub mod run_dir;
pub mod signals;
pub mod status;
pub mod sweep;
#[cfg(test)]
mod test_util;
