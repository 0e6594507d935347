//! The corpus replay shared by `envs/tests/integration/fuzz_corpus.rs` and `rl/tests/integration/fuzz_corpus.rs`
//! (included by path: the two test crates live in different packages).

use std::path::PathBuf;

/// Every file of `fuzz/corpus/<target>`, sorted; at least one (a missing corpus fails).
pub fn corpus(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
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
pub fn replay(target: &str, f: impl Fn(&[u8]) -> bool) -> usize {
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
