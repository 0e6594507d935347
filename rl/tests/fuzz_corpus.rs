//! Replays the committed fuzzing corpora of the `rl` readers (`fuzz/corpus/<target>`, see
//! `fuzz/README.md`) through the same calls as the fuzz targets, on the stable toolchain:
//! every input must give `Ok` or `Err`, never a panic. The corpora hold the seeds, what
//! libFuzzer kept for new coverage (minimised with `cargo fuzz cmin`) and the inputs of the
//! crashes it found (`crash-*`), so each crash stays fixed.

mod common;

use std::path::PathBuf;

use common::TempDir;

/// Every file of `fuzz/corpus/<target>`, sorted; at least one (a missing corpus fails).
fn corpus(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../fuzz/corpus")).join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{} is empty", dir.display());
    files.into_iter().map(|p| (p.clone(), std::fs::read(&p).unwrap())).collect()
}

/// Runs `f` on every input of `target`'s corpus, naming the input if it panics; returns how
/// many gave `Ok`.
fn replay(target: &str, f: impl Fn(&[u8]) -> bool) -> usize {
    let mut ok = 0;
    for (path, data) in corpus(target) {
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(&data))) {
            Ok(true) => ok += 1,
            Ok(false) => {}
            Err(_) => panic!("{target}: {} panicked", path.display()),
        }
    }
    ok
}

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
        let outcome = std::panic::catch_unwind(|| match rl::checkpoint::Checkpoint::load(&file) {
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
