//! The training configuration readers: a `--config` TOML file (resolved over the preset) and
//! a run's `config.toml`. Both read a path, so the input goes through a file.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

fn file() -> &'static PathBuf {
    static FILE: OnceLock<PathBuf> = OnceLock::new();
    FILE.get_or_init(|| std::env::temp_dir().join(format!("meben-fuzz-train-config-{}.toml", std::process::id())))
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    std::fs::write(file(), data).unwrap();
    let _ = rl::TrainConfig::resolve(None, Some(file()), &[]);
    let _ = rl::TrainConfig::load(file());
});
