//! Replays the committed fuzzing corpora of the `rl` readers (`fuzz/corpus/<target>`, see
//! `fuzz/README.md`) through the same calls as the fuzz targets, on the stable toolchain:
//! every input must give `Ok` or `Err`, never a panic. The corpora hold the seeds, what
//! libFuzzer kept for new coverage (minimised with `cargo fuzz cmin`) and the inputs of the
//! crashes it found (`crash-*`), so each crash stays fixed.

use crate::common;
#[path = "../../../fuzz/replay.rs"]
mod replay;

use common::TempDir;
use replay::{corpus, replay};

#[test]
fn the_train_config_corpus_reads_or_fails_cleanly() {
    let dir = TempDir::new("fuzz-train-config");
    let file = dir.0.join("config.toml");
    let ok = replay("train_config", |data| {
        std::fs::write(&file, data).unwrap();
        let resolved = rl::TrainConfig::resolve(None, Some(&file), &[]).is_ok();
        let loaded = rl::TrainConfig::load(&file).is_ok();
        resolved || loaded
    });
    eprintln!("train_config: {ok} inputs read");
    assert!(ok >= 4, "only {ok} inputs read: the corpus lost its valid configurations");
}

#[test]
fn the_sweep_corpus_reads_or_fails_cleanly() {
    let ok = replay("sweep", |data| {
        std::str::from_utf8(data)
            .ok()
            .and_then(|text| rl::Sweep::parse(text, "fuzz.toml").ok())
            .is_some_and(|sweep| sweep.runs().is_ok())
    });
    eprintln!("sweep: {ok} inputs expand");
    assert!(ok >= 4, "only {ok} inputs expand: the corpus lost its valid sweeps");
}

#[test]
fn the_checkpoint_corpus_loads_or_fails_cleanly() {
    let dir = TempDir::new("fuzz-checkpoint");
    let file = dir.0.join("checkpoint.json");
    let (mut loaded, mut restored) = (0, 0);
    for (path, data) in corpus("checkpoint") {
        std::fs::write(&file, &data).unwrap();
        let outcome = std::panic::catch_unwind(|| match rl::mappo::checkpoint::Checkpoint::load(&file) {
            Ok(c) if c.config.num_envs <= 64 && c.config.steps_per_iteration() <= 4096 => {
                (true, rl::Trainer::from_checkpoint(&c, &c.config, &file).is_ok())
            }
            Ok(_) => (true, false),
            Err(_) => (false, false),
        });
        let (l, r) = outcome.unwrap_or_else(|_| panic!("checkpoint: {} panicked", path.display()));
        loaded += usize::from(l);
        restored += usize::from(r);
    }
    eprintln!("checkpoint: {loaded} inputs load, {restored} restore into a trainer");
    assert!(
        loaded >= 3 && restored >= 1,
        "{loaded} inputs load and {restored} restore: the corpus lost its checkpoints"
    );
}
