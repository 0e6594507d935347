//! `meben`: train, evaluate, sweep, report and render MeBen agents, and drive the simulator
//! (the command line is [`rl::app::cli`]). `meben <command> --help` explains each command;
//! with no command, `meben` trains `shnn` on `team_reach/1_ant` with the built-in `quick`
//! budget (as `meben train`).

use std::process::ExitCode;

// mimalloc keeps freed memory for reuse (workspace Cargo.toml, beside the dependency).
#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    rl::app::cli::main()
}
