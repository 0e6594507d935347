//! `meben export <runs> <results>`: the evidence of a tree of runs, without its checkpoints,
//! for committing (`results/<experiment>/`, docs/RESULTS.md).
//!
//! For every run directory under `<runs>` ([`crate::app::record::find_run_dirs`]) the files
//! [`EVIDENCE_FILES`] that exist, and its morphology record and copies (`morphology.toml`,
//! `morphologies/`: [`crate::app::morphology`]), are copied to the same relative path under
//! `<results>` (each written atomically, so an interrupted export leaves whole files); a sweep's copy of
//! its file (`sweep.toml` at the root) comes along. Checkpoints (`checkpoint.json` and the
//! `checkpoint.<digest>.safetensors` it names) and anything else stay behind. A run still training is exported as far as it got (it has no `done.json`);
//! exporting again later brings its newer rows. `meben report <results>` then works from the
//! exported files alone.
//!
//! Export never loses evidence. Where `<results>` already holds a run's `metrics.csv`, the
//! two files must agree, row for row, on every column but the wall-time ones
//! ([`crate::app::metrics::training_lines`]) as far as both go; the run's evidence is
//! replaced only if the run being exported is at least as far along. A run re-trained from
//! the start (its machine lost, say) therefore leaves the committed, longer record in place
//! until it passes it, and export checks on the way that the re-run is the same computation.
//! Any disagreement is an error, found before anything is written. The rows are compared as
//! the text the run wrote ([`crate::app::metrics::training_lines`]), not as read back by
//! [`crate::app::record`]: equal text is equal bits, with no float comparison to get wrong
//! (a NaN cell equals itself there).
//!
//! Nor does it write where it would harm: a destination inside the source (each export would
//! nest the copies again) or one that is, holds or lies inside a training's run directory
//! (its evidence overwritten, a stopped run marked finished) is refused before anything is
//! written.

use std::path::{Path, PathBuf};

use crate::app::metrics::training_lines;
use crate::app::record::find_run_dirs;
use crate::app::run_dir::RunDir;
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
    /// Runs whose evidence under the destination was left as it was, being further along
    /// than the run (which agrees with it on every row it has).
    pub kept: Vec<KeptRun>,
    /// Bytes written.
    pub bytes: u64,
}

/// A run whose exported evidence is further along than the run itself ([`export`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct KeptRun {
    /// The run (relative to the source root).
    pub run: PathBuf,
    /// Rows of the run's `metrics.csv`, every one equal to the kept file's.
    pub rows: usize,
    /// Rows of the kept `metrics.csv`.
    pub kept_rows: usize,
}

/// Copies the evidence of every run under `from` to `to` (module docs).
pub fn export(from: &Path, to: &Path) -> Result<ExportSummary> {
    let dirs = find_run_dirs(from)?;
    if dirs.is_empty() {
        return Err(RlError::file(from, "holds no run directory (config.toml and metrics.csv)"));
    }
    check_destination(from, to)?;
    // Every run is checked against what `to` holds before anything is written.
    let mut plans = Vec::with_capacity(dirs.len());
    for dir in dirs {
        let rel = dir.strip_prefix(from).unwrap_or(&dir).to_path_buf();
        let target = to.join(&rel);
        let kept = compare_with_exported(&dir, &target)?;
        plans.push((dir, rel, target, kept));
    }
    let mut summary = ExportSummary::default();
    let sweep = from.join("sweep.toml");
    if sweep.is_file() {
        summary.bytes += copy_file(&sweep, &to.join("sweep.toml"))?;
    }
    for (dir, rel, target, kept) in plans {
        if !RunDir::new(&dir).done().is_file() {
            summary.unfinished.push(rel.clone());
        }
        if let Some((rows, kept_rows)) = kept {
            summary.kept.push(KeptRun { run: rel.clone(), rows, kept_rows });
        } else {
            for name in EVIDENCE_FILES {
                let src = dir.join(name);
                if src.is_file() {
                    summary.bytes += copy_file(&src, &target.join(name))?;
                }
            }
            for rel in morphology_files(&dir)? {
                summary.bytes += copy_file(&dir.join(&rel), &target.join(&rel))?;
            }
        }
        summary.runs.push(rel);
    }
    Ok(summary)
}

/// Refuses a destination `to` that lies inside the source `from` (or is it): every export
/// would copy the copies again, nesting them (2, 4, 6 runs on repeated exports); and one
/// that is, holds or lies inside a training's run directory ([`is_training_run`]): its `done.json`
/// would mark a stopped run finished and its `metrics.csv` replace the run's. Both were
/// taken before (issue 77 item 12). Errors name both directories.
fn check_destination(from: &Path, to: &Path) -> Result<()> {
    if crate::app::outputs::is_within(to, from) {
        return Err(RlError::file(
            to,
            format!(
                "the destination lies inside the source {}: every export would copy the copies again; export to a \
                 directory outside it",
                from.display()
            ),
        ));
    }
    let inside = crate::app::outputs::resolved(to);
    if let Some(run) = inside.ancestors().skip(1).find(|d| is_training_run(d)) {
        return Err(RlError::file(
            to,
            format!(
                "the destination lies inside the run directory {}: export to a directory of exported evidence or a \
                 new one",
                run.display()
            ),
        ));
    }
    let mut stack = vec![to.to_path_buf()];
    while let Some(dir) = stack.pop() {
        if is_training_run(&dir) {
            return Err(RlError::file(
                to,
                format!(
                    "the destination {} a run directory ({} holds {}): the export would write over its evidence \
                     and could mark it finished; export to a directory of exported evidence or a new one",
                    if dir == to { "is" } else { "holds" },
                    dir.display(),
                    if RunDir::new(&dir).checkpoint().is_file() { "checkpoint.json" } else { "a training's lock" }
                ),
            ));
        }
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries.flatten() {
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if !hidden && entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(entry.path());
            }
        }
    }
    Ok(())
}

/// Whether `dir` is the directory of a training, not exported evidence: it holds a
/// `checkpoint.json` or a training's lock file, which export never copies.
fn is_training_run(dir: &Path) -> bool {
    RunDir::new(dir).checkpoint().is_file() || dir.join(crate::app::lock::LOCK_FILE).is_file()
}

/// Compares run directory `run` with its exported evidence `exported`: `None` if there is
/// none or the run is at least as far along (export copies it), `Some((rows, kept_rows))`
/// if the exported file has more rows and the run's are all equal to its first ones (export
/// keeps it), an error naming both files and the first differing row otherwise.
fn compare_with_exported(run: &Path, exported: &Path) -> Result<Option<(usize, usize)>> {
    let (run, exported) = (RunDir::new(run), RunDir::new(exported));
    let (ours, theirs) = (run.metrics(), exported.metrics());
    if !theirs.is_file() {
        return Ok(None);
    }
    let lines = |path: &Path| -> Result<Vec<String>> {
        let text = std::fs::read_to_string(path).map_err(|e| RlError::file(path, format!("cannot read: {e}")))?;
        training_lines(&text).map_err(|e| RlError::file(path, e))
    };
    let (a, b) = (lines(&ours)?, lines(&theirs)?);
    if a[0] != b[0] {
        return Err(RlError::file(
            &theirs,
            format!(
                "its columns differ from those of {}: not the same run; move it aside to export the run",
                ours.display()
            ),
        ));
    }
    if let Some(i) = (1..a.len().min(b.len())).find(|&i| a[i] != b[i]) {
        return Err(RlError::file(
            &theirs,
            format!(
                "data row {i} differs from that of {}, wall-time columns aside ({:?} against {:?}): the exported run \
                 and this one are not the same computation (another configuration or build); move it aside to \
                 export the run",
                ours.display(),
                b[i],
                a[i]
            ),
        ));
    }
    let (rows, kept_rows) = (a.len() - 1, b.len() - 1);
    let exported_finished = exported.done().is_file() && !run.done().is_file();
    Ok((kept_rows > rows || (kept_rows == rows && exported_finished)).then_some((rows, kept_rows)))
}

/// Copies `src` to `dst` atomically (creating `dst`'s directory); returns the bytes copied.
/// The morphology files of run directory `dir`, relative to it: its record
/// (`morphology.toml`) and its copies of the files its environment names (`morphologies/`,
/// [`crate::app::morphology`]), in name order. They are evidence too: the bodies the run
/// was trained on, where its `config.toml` names them only by a path on the machine that
/// trained it.
fn morphology_files(dir: &Path) -> Result<Vec<PathBuf>> {
    use crate::app::morphology::{COPIES_DIR, MORPHOLOGY_RECORD};
    let mut files = Vec::new();
    if dir.join(MORPHOLOGY_RECORD).is_file() {
        files.push(PathBuf::from(MORPHOLOGY_RECORD));
    }
    let copies = dir.join(COPIES_DIR);
    if copies.is_dir() {
        let entries = std::fs::read_dir(&copies).map_err(|e| RlError::file(&copies, format!("cannot list: {e}")))?;
        let mut names = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| RlError::file(&copies, format!("cannot list: {e}")))?;
            if entry.path().is_file() {
                names.push(Path::new(COPIES_DIR).join(entry.file_name()));
            }
        }
        names.sort();
        files.extend(names);
    }
    Ok(files)
}

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
            write(&d.join("checkpoint.0123456789abcdef.safetensors"), "tensors");
            if done {
                write(&d.join("done.json"), "{}");
                write(&d.join("builds.csv"), "b\n");
                write(&d.join("morphology.toml"), "[[files]]");
                write(&d.join("morphologies/0_body.xml"), "<mujoco/>");
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
        assert_eq!(std::fs::read_to_string(d0.join("morphology.toml")).unwrap(), "[[files]]");
        assert_eq!(std::fs::read_to_string(d0.join("morphologies/0_body.xml")).unwrap(), "<mujoco/>");
        assert!(!results.join("team_reach_1_ant/shnn/seed1/done.json").exists());
        assert_eq!(std::fs::read_to_string(results.join("sweep.toml")).unwrap(), "seeds = [0]");
        for stray in [
            "team_reach_1_ant/shnn/seed0/checkpoint.json",
            "team_reach_1_ant/shnn/seed0/checkpoint.json.tmp",
            "team_reach_1_ant/shnn/seed0/checkpoint.0123456789abcdef.safetensors",
            "notes",
        ] {
            assert!(!results.join(stray).exists(), "{stray} was exported");
        }
        // sweep.toml 11 bytes; per run config.toml 27 and metrics.csv 12; one done.json 2,
        // one builds.csv 2, one morphology.toml 9 and its copy 9.
        assert_eq!(s.bytes, 11 + 2 * (27 + 12) + 2 + 2 + 9 + 9);
    }

    const HEADER: &str = "iteration,env_steps,wall_s,steps_per_s,loss";

    /// A metrics file of `n` rows of one computation, timed by `wall`.
    fn metrics(n: usize, wall: f64) -> String {
        let rows: Vec<String> =
            (1..=n).map(|i| format!("{i},{},{},{},0.{i}", 10 * i, wall * i as f64, 10.0 / wall)).collect();
        format!("{HEADER}\n{}\n", rows.join("\n"))
    }

    /// A run directory under `root` with a config and the given metrics.
    fn run_dir(root: &Path, run: &str, metrics_text: &str) -> PathBuf {
        let d = root.join(run);
        write(&d.join("config.toml"), "seed = 0");
        write(&d.join("metrics.csv"), metrics_text);
        d
    }

    #[test]
    fn a_rerun_behind_the_exported_evidence_leaves_it_and_one_ahead_replaces_it() {
        let tmp = TempDir::new("export-rerun");
        let (runs, results) = (tmp.0.join("runs"), tmp.0.join("results"));
        // The exported run got to 5 rows and has a build record; its re-run (other
        // machine, other wall times) is at 2.
        let exported = run_dir(&results, "e/shnn/seed0", &metrics(5, 3.0));
        write(&exported.join("builds.csv"), "old build\n");
        let rerun = run_dir(&runs, "e/shnn/seed0", &metrics(2, 7.5));
        write(&rerun.join("builds.csv"), "new build\n");
        let s = export(&runs, &results).unwrap();
        assert_eq!(s.kept, [KeptRun { run: PathBuf::from("e/shnn/seed0"), rows: 2, kept_rows: 5 }]);
        assert_eq!((s.runs.len(), s.bytes), (1, 0));
        assert_eq!(std::fs::read_to_string(exported.join("metrics.csv")).unwrap(), metrics(5, 3.0));
        assert_eq!(std::fs::read_to_string(exported.join("builds.csv")).unwrap(), "old build\n");
        // Past the exported rows, the run's evidence replaces it.
        write(&rerun.join("metrics.csv"), &metrics(6, 7.5));
        let s = export(&runs, &results).unwrap();
        assert!(s.kept.is_empty());
        assert_eq!(std::fs::read_to_string(exported.join("metrics.csv")).unwrap(), metrics(6, 7.5));
        assert_eq!(std::fs::read_to_string(exported.join("builds.csv")).unwrap(), "new build\n");
        // A finished export is kept against an unfinished run of as many rows.
        write(&exported.join("done.json"), "{}");
        assert_eq!(export(&runs, &results).unwrap().kept.len(), 1);
    }

    #[test]
    fn a_rerun_that_disagrees_with_the_exported_evidence_is_an_error_and_nothing_is_written() {
        let tmp = TempDir::new("export-disagree");
        let (runs, results) = (tmp.0.join("runs"), tmp.0.join("results"));
        run_dir(&results, "e/shnn/seed0", &metrics(4, 3.0));
        run_dir(&runs, "e/mlp/seed0", &metrics(3, 1.0));
        run_dir(&runs, "e/shnn/seed0", &metrics(3, 1.0).replace("3,30,3,10,0.3", "3,30,3,10,0.30000001"));
        let msg = export(&runs, &results).unwrap_err().to_string();
        let exported = results.join("e/shnn/seed0/metrics.csv");
        assert!(msg.contains(&exported.display().to_string()) && msg.contains("data row 3"), "{msg}");
        assert!(msg.contains("0.30000001") && msg.contains("not the same computation"), "{msg}");
        assert!(!results.join("e/mlp").exists(), "a run was exported before the check failed");
        // Other columns are another run.
        run_dir(&runs, "e/shnn/seed0", &metrics(3, 1.0).replace("loss", "entropy"));
        let msg = export(&runs, &results).unwrap_err().to_string();
        assert!(msg.contains(&exported.display().to_string()) && msg.contains("columns differ"), "{msg}");
        assert_eq!(std::fs::read_to_string(&exported).unwrap(), metrics(4, 3.0));
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

    /// Issue 77 item 12: exporting into the source nested copies (2, 4, 6 runs on repeated
    /// exports), and exporting a finished run into a stopped one marked it finished. Both
    /// are refused, naming the directories, and nothing is written.
    #[test]
    fn a_destination_inside_the_source_or_holding_a_run_is_refused() {
        let tmp = TempDir::new("export-guard");
        let runs = tmp.0.join("runs");
        let run = run_dir(&runs, "e/m/seed0", &metrics(3, 1.0));
        std::fs::write(run.join("done.json"), "{}").unwrap();
        for to in [runs.join("exported"), runs.clone(), run.join("..").join("x")] {
            let msg = export(&runs, &to).unwrap_err().to_string();
            assert!(msg.contains("inside the source") && msg.contains(&runs.display().to_string()), "{msg}");
        }
        assert!(!runs.join("exported").exists());
        // A stopped run (its checkpoint, no done.json) as the destination, or under it.
        let stopped = run_dir(&tmp.0.join("other"), "e/m/seed0", &metrics(2, 1.0));
        std::fs::write(stopped.join("checkpoint.json"), "{}").unwrap();
        for to in [stopped.clone(), tmp.0.join("other")] {
            let msg = export(&run, &to).unwrap_err().to_string();
            assert!(msg.contains("run directory") && msg.contains("checkpoint.json"), "{msg}");
        }
        assert!(!stopped.join("done.json").exists(), "the stopped run was marked finished");
        let msg = export(&run, &stopped.join("sub")).unwrap_err().to_string();
        assert!(msg.contains("inside the run directory"), "{msg}");
        assert!(!stopped.join("sub").exists());
        // Exported evidence (no checkpoint, no lock) is a fine destination, again and again.
        let results = tmp.0.join("results");
        for _ in 0..3 {
            assert_eq!(export(&runs, &results).unwrap().runs.len(), 1);
        }
        assert_eq!(find_run_dirs(&results).unwrap().len(), 1);
    }
}
