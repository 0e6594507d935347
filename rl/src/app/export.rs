//! `meben export <runs> <results>`: the evidence of a tree of runs, without its checkpoints,
//! for committing (`results/<experiment>/`, docs/RESULTS.md).
//!
//! For every run directory under `<runs>` ([`crate::app::report::find_run_dirs`]) the files
//! [`EVIDENCE_FILES`] that exist are copied to the same relative path under `<results>`
//! (each written atomically, so an interrupted export leaves whole files); a sweep's copy of
//! its file (`sweep.toml` at the root) comes along. Checkpoints and anything else stay
//! behind. A run still training is exported as far as it got (it has no `done.json`);
//! exporting again later brings its newer rows. `meben report <results>` then works from the
//! exported files alone.

use std::path::{Path, PathBuf};

use crate::app::report::find_run_dirs;
use crate::error::{Result, RlError};

/// The files of a run directory that are evidence: its configuration, its metrics, its
/// final summary, its learning curve and the builds that trained it.
pub const EVIDENCE_FILES: [&str; 5] = ["config.toml", "metrics.csv", "done.json", "curve.svg", "builds.csv"];

/// What [`export`] copied.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExportSummary {
    /// Runs exported (relative to the source root).
    pub runs: Vec<PathBuf>,
    /// Of those, the runs without `done.json` (still training or stopped early).
    pub unfinished: Vec<PathBuf>,
    /// Bytes written.
    pub bytes: u64,
}

/// Copies the evidence of every run under `from` to `to` (module docs).
pub fn export(from: &Path, to: &Path) -> Result<ExportSummary> {
    let dirs = find_run_dirs(from)?;
    if dirs.is_empty() {
        return Err(RlError::file(from, "holds no run directory (config.toml and metrics.csv)"));
    }
    let mut summary = ExportSummary::default();
    let sweep = from.join("sweep.toml");
    if sweep.is_file() {
        summary.bytes += copy_file(&sweep, &to.join("sweep.toml"))?;
    }
    for dir in dirs {
        let rel = dir.strip_prefix(from).unwrap_or(&dir).to_path_buf();
        let target = to.join(&rel);
        for name in EVIDENCE_FILES {
            let src = dir.join(name);
            if src.is_file() {
                summary.bytes += copy_file(&src, &target.join(name))?;
            }
        }
        if !dir.join("done.json").is_file() {
            summary.unfinished.push(rel.clone());
        }
        summary.runs.push(rel);
    }
    Ok(summary)
}

/// Copies `src` to `dst` atomically (creating `dst`'s directory); returns the bytes copied.
fn copy_file(src: &Path, dst: &Path) -> Result<u64> {
    let bytes = std::fs::read(src).map_err(|e| RlError::file(src, format!("cannot read: {e}")))?;
    if let Some(parent) = dst.parent() {
        std::fs::create_dir_all(parent)
            .map_err(|e| RlError::file(parent, format!("cannot create the directory: {e}")))?;
    }
    nn::write_atomic(dst, &bytes)?;
    Ok(bytes.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::test_util::TempDir;

    fn write(path: &Path, text: &str) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }

    #[test]
    fn copies_the_evidence_and_leaves_checkpoints_behind() {
        let tmp = TempDir::new("export-copy");
        let (runs, results) = (tmp.0.join("runs"), tmp.0.join("results"));
        write(&runs.join("sweep.toml"), "seeds = [0]");
        for (run, done) in [("team_reach_1_ant/shnn/seed0", true), ("team_reach_1_ant/shnn/seed1", false)] {
            let d = runs.join(run);
            write(&d.join("config.toml"), run);
            write(&d.join("metrics.csv"), "iteration\n1\n");
            write(&d.join("checkpoint.json"), "{\"big\": 1}");
            write(&d.join("checkpoint.json.tmp"), "partial");
            if done {
                write(&d.join("done.json"), "{}");
                write(&d.join("builds.csv"), "b\n");
            }
        }
        write(&runs.join("notes/scratch.txt"), "not a run");
        let s = export(&runs, &results).unwrap();
        assert_eq!(s.runs.len(), 2);
        assert_eq!(s.unfinished, [PathBuf::from("team_reach_1_ant/shnn/seed1")]);
        let d0 = results.join("team_reach_1_ant/shnn/seed0");
        assert_eq!(std::fs::read_to_string(d0.join("config.toml")).unwrap(), "team_reach_1_ant/shnn/seed0");
        assert!(d0.join("done.json").is_file() && d0.join("metrics.csv").is_file());
        assert_eq!(std::fs::read_to_string(d0.join("builds.csv")).unwrap(), "b\n");
        assert!(!results.join("team_reach_1_ant/shnn/seed1/done.json").exists());
        assert_eq!(std::fs::read_to_string(results.join("sweep.toml")).unwrap(), "seeds = [0]");
        for stray in
            ["team_reach_1_ant/shnn/seed0/checkpoint.json", "team_reach_1_ant/shnn/seed0/checkpoint.json.tmp", "notes"]
        {
            assert!(!results.join(stray).exists(), "{stray} was exported");
        }
        // sweep.toml 11 bytes; per run config.toml 27 and metrics.csv 12; one done.json 2
        // and one builds.csv 2.
        assert_eq!(s.bytes, 11 + 2 * (27 + 12) + 2 + 2);
    }

    #[test]
    fn a_directory_without_runs_is_an_error_naming_it() {
        let tmp = TempDir::new("export-empty");
        let msg = export(&tmp.0, &tmp.0.join("out")).unwrap_err().to_string();
        assert!(msg.contains(&tmp.0.display().to_string()) && msg.contains("no run directory"), "{msg}");
        let missing = tmp.0.join("missing");
        let msg = export(&missing, &tmp.0.join("out")).unwrap_err().to_string();
        assert!(msg.contains("missing") && msg.contains("not a directory"), "{msg}");
    }
}
