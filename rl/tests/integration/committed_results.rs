//! The committed reproduction evidence (`results/<experiment>/`, issue 15) regenerates its
//! committed reports: `meben report results/<experiment>`, run on a copy of each
//! experiment's run files alone (`config.toml`, `metrics.csv`, `done.json`, `curve.svg`;
//! the committed `report.md`, `report.csv` and `curves/` left out of the copy), writes
//! `report.md`, `report.csv`, every `curves/*.svg` and, with `--paper results/paper.toml`,
//! the paper-versus-here table `paper.md` byte for byte as committed; and each committed
//! report at a matched budget, `results/<experiment>/at_<N>/`, regenerates the same way with
//! `--at-steps N`. It fails when a report was edited by hand, when the evidence changed
//! without its report being redrawn, or when `meben report` changed what it draws without
//! the reports being redrawn.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common;

use common::TempDir;

/// The files `meben report --paper` writes into an experiment's directory (and, with
/// `--at-steps N`, into its `at_<N>` directory).
fn is_report_output(rel: &Path) -> bool {
    let rel = match at_steps_of(rel) {
        Some(_) => rel.strip_prefix(rel.components().next().unwrap()).unwrap(),
        None => rel,
    };
    ["report.md", "report.csv", "paper.md"].iter().any(|f| rel == Path::new(f)) || rel.starts_with("curves")
}

/// N when `rel` lies under an `at_<N>` directory at the top of an experiment.
fn at_steps_of(rel: &Path) -> Option<u64> {
    rl::app::report::at_steps_of(rel.components().next()?.as_os_str().to_str()?)
}

/// Every file under `dir`, as paths relative to it, sorted.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn every_committed_report_regenerates_from_the_committed_run_files() {
    let results = Path::new(env!("CARGO_MANIFEST_DIR")).join("../results");
    let mut experiments: Vec<PathBuf> = std::fs::read_dir(&results)
        .expect("results/ holds the committed reproduction evidence")
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    experiments.sort();
    assert!(!experiments.is_empty(), "no experiment under {}", results.display());

    let scratch = TempDir::new("committed-results");
    for exp in &experiments {
        let name = exp.file_name().unwrap().to_str().unwrap();
        let files = files_under(exp);
        // An experiment of evaluations only (`results/assignment_swap`: summaries of a
        // shipped policy and the diagnostics.md its script draws from them) has no run to
        // report on; one with a run always has its report.
        if !files.iter().any(|f| f.ends_with("metrics.csv"))
            && files.iter().any(|f| f.as_path() == Path::new("diagnostics.md"))
        {
            continue;
        }
        let outputs: Vec<&PathBuf> = files.iter().filter(|f| is_report_output(f)).collect();
        assert!(
            outputs.iter().any(|f| f.as_path() == Path::new("report.md")),
            "results/{name} has no committed report.md"
        );

        // The run files alone, at the same relative path (the report names the directory it
        // was given, so it is given `results/<experiment>` from the copy's parent).
        let copy = scratch.0.join("results").join(name);
        for rel in files.iter().filter(|f| !is_report_output(f)) {
            let to = copy.join(rel);
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(exp.join(rel), &to).unwrap();
        }
        // The whole runs' report, then one per committed matched budget.
        let budgets: std::collections::BTreeSet<u64> = files.iter().filter_map(|f| at_steps_of(f)).collect();
        for at in std::iter::once(None).chain(budgets.into_iter().map(Some)) {
            let mut cmd = Command::new(env!("CARGO_BIN_EXE_meben"));
            cmd.current_dir(&scratch.0).args(["report", &format!("results/{name}"), "--paper"]);
            cmd.arg(results.join("paper.toml"));
            if let Some(n) = at {
                cmd.args(["--at-steps", &n.to_string()]);
            }
            let out = cmd.output().unwrap();
            assert!(
                out.status.success(),
                "meben report results/{name} (at {at:?} env steps) failed: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }

        let regenerated: Vec<PathBuf> = files_under(&copy).into_iter().filter(|f| is_report_output(f)).collect();
        let committed: Vec<PathBuf> = outputs.into_iter().cloned().collect();
        assert_eq!(regenerated, committed, "results/{name}: the report files written differ from those committed");
        for rel in &committed {
            let want = std::fs::read(exp.join(rel)).unwrap();
            let got = std::fs::read(copy.join(rel)).unwrap();
            let at = at_steps_of(rel).map_or_else(String::new, |n| format!(" --at-steps {n}"));
            assert!(
                want == got,
                "results/{name}/{}: regenerated from the run files, it differs from the committed file \
                 (redraw with `meben report results/{name} --paper results/paper.toml{at}` from the repository root)",
                rel.display()
            );
        }
    }
}
