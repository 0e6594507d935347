//! Which build trained a run: the program's version and git commit, and the run directory's
//! `builds.csv`, where every training session of a run (its start and each resume) adds a
//! row. A run is re-trained with "the same binary" by building the commit its rows name
//! (`docs/RESULTS.md`); a run resumed by several builds names each, with the iteration it
//! went on from.
//!
//! The commit is recorded at build time by `rl/build.rs`: the checkout's commit, with
//! `+modified` when the program's sources differ from it, or `unknown` outside git.

use std::io::Write;
use std::path::Path;

use crate::error::{Result, RlError};

/// The git commit the program was built from (`rl/build.rs`): 40 hex digits, with
/// `+modified` if its sources differed from it (`+unknown-status` if git could not say),
/// or `unknown`.
pub const COMMIT: &str = env!("MEBEN_COMMIT");

/// The package version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The name of the build record in a run directory.
pub const BUILDS_FILE: &str = "builds.csv";

/// The header of `builds.csv`.
pub const BUILDS_HEADER: &str = "from_iteration,version,commit,unix_time_s";

/// `meben --version`: the version and the commit.
pub const LONG_VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("MEBEN_COMMIT"), ")");

/// Adds this build's row to the build record at `path` (a run's `builds.csv`, created with
/// its header): training of the run goes on from `iteration` (0 for a new run). The row is
/// appended in one write, so an interrupted write loses at most that row, never an earlier
/// one.
pub fn record_build(path: &Path, iteration: u64) -> Result<()> {
    let io = |what: &str, e: std::io::Error| RlError::file(path, format!("cannot {what}: {e}"));
    let mut file = std::fs::OpenOptions::new().create(true).append(true).open(path).map_err(|e| io("open", e))?;
    let len = file.metadata().map_err(|e| io("read the size of", e))?.len();
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let mut text = String::new();
    if len == 0 {
        text.push_str(BUILDS_HEADER);
        text.push('\n');
    }
    text.push_str(&format!("{iteration},{VERSION},{COMMIT},{now}\n"));
    file.write_all(text.as_bytes()).map_err(|e| io("write", e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_commit_is_a_git_commit_or_says_it_is_unknown() {
        let sha = COMMIT.split('+').next().unwrap();
        let hex = sha.len() == 40 && sha.bytes().all(|b| b.is_ascii_hexdigit());
        assert!(hex || COMMIT == "unknown", "MEBEN_COMMIT = {COMMIT:?}");
        assert!(LONG_VERSION.contains(COMMIT) && LONG_VERSION.starts_with(VERSION));
    }

    #[test]
    fn each_session_adds_a_row_under_one_header() {
        let dir = crate::app::test_util::TempDir::new("builds");
        let path = dir.0.join(BUILDS_FILE);
        record_build(&path, 0).unwrap();
        record_build(&path, 7).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        assert_eq!(lines[0], BUILDS_HEADER);
        assert!(lines[1].starts_with(&format!("0,{VERSION},{COMMIT},")), "{}", lines[1]);
        assert!(lines[2].starts_with(&format!("7,{VERSION},{COMMIT},")), "{}", lines[2]);
    }
}
