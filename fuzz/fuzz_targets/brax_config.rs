//! The Brax config reader, the simulator model of the agent it describes, and the MeBen
//! scene an environment builds from such a file (`--env team_reach:agents=ant+FILE.txt`,
//! read from a file): Ok or Err, never a panic.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

fn file() -> &'static PathBuf {
    static FILE: OnceLock<PathBuf> = OnceLock::new();
    FILE.get_or_init(|| std::env::temp_dir().join(format!("meben-fuzz-brax-{}.txt", std::process::id())))
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(config) = envs::brax::parse_config(text, "fuzz.txt")
    {
        let _ = envs::brax::agent_model(&config, &envs::brax::BraxPhysics::default());
        std::fs::write(file(), data).unwrap();
        let _ = envs::tasks::Scene::from_name(&format!("team_reach:agents=ant+{}", file().display()));
    }
});
