//! The checkpoint reader (checksum envelope, JSON, format version, counters, finiteness),
//! then, as a resume does, the restore of the checkpoint into a trainer of its own
//! configuration (parameters, Adam moments, normaliser, random streams, environments). It
//! reads a path, so the input goes through a file. The restore is tried for small
//! configurations only: a trainer allocates what its configuration asks for.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

fn file() -> &'static PathBuf {
    static FILE: OnceLock<PathBuf> = OnceLock::new();
    FILE.get_or_init(|| std::env::temp_dir().join(format!("meben-fuzz-checkpoint-{}.json", std::process::id())))
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    std::fs::write(file(), data).unwrap();
    if let Ok(c) = rl::mappo::checkpoint::Checkpoint::load(file())
        && c.config.num_envs <= 64
        && c.config.steps_per_iteration() <= 4096
    {
        let _ = rl::Trainer::from_checkpoint(&c, &c.config, file());
    }
});
