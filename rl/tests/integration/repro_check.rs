//! `rl/sweeps/repro_check.sh`, the reproduction's check that a committed run re-trains to
//! the same `metrics.csv` rows: it passes on an untouched run (whatever the thread count),
//! fails on a run whose committed rows were altered, and refuses bad usage.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/repro_check.sh")
}

/// Runs the script on `run` with `args`; returns (exit code, stdout, stderr).
fn check(run: &Path, args: &[&str], threads: &str) -> (i32, String, String) {
    let out = Command::new("bash")
        .arg(script())
        .arg(run)
        .args(args)
        .env("BIN", env!("CARGO_BIN_EXE_meben"))
        .env("THREADS", threads)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn repro_check_passes_on_a_run_and_fails_on_altered_rows() {
    let tmp = common::TempDir::new("repro_check");
    let dir = tmp.0.clone();
    let run = dir.join("run");
    // A tiny run with the equivariance test's evaluation (fixed start, 0 and 180 degrees,
    // sampled actions), as the reproduction's runs have.
    let config = common::tiny(
        "team_reach/1_centipede",
        "mlp",
        3,
        &[
            ("fixed_start", "true"),
            ("eval_rotations", "[0.0, 180.0]"),
            ("eval_deterministic", "false"),
            ("num_evals", "2"),
        ],
    );
    let config_path = dir.join("config.toml");
    config.save(&config_path).unwrap();
    let args = ["train", "--config", config_path.to_str().unwrap(), "--out", run.to_str().unwrap(), "--quiet"];
    let out = Command::new(env!("CARGO_BIN_EXE_meben")).args(args).output().unwrap();
    assert!(out.status.success(), "train failed: {}", String::from_utf8_lossy(&out.stderr));
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    let rows = metrics.lines().count() - 1;
    assert!(rows >= 3, "{metrics}");
    assert!(metrics.lines().next().unwrap().contains("eval_success_rate_rot180"));

    // The whole run, then its first row, re-train to the same rows; the thread count
    // changes nothing.
    let (code, stdout, stderr) = check(&run, &[], "1");
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains(&format!("identical: {rows} rows")), "{stdout}");
    let (code, stdout, stderr) = check(&run, &["1"], "2");
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains("identical: 1 rows"), "{stdout}");

    // Altered committed rows: a different loss in the last row is found; a different wall
    // time is not a difference.
    let last = metrics.lines().last().unwrap();
    let cells: Vec<&str> = last.split(',').collect();
    let altered = |column: usize, value: &str| {
        let mut c = cells.clone();
        c[column] = value;
        let mut text: Vec<&str> = metrics.lines().collect();
        let joined = c.join(",");
        *text.last_mut().unwrap() = &joined;
        std::fs::write(run.join("metrics.csv"), text.join("\n") + "\n").unwrap();
    };
    let header: Vec<&str> = metrics.lines().next().unwrap().split(',').collect();
    let wall = header.iter().position(|h| *h == "wall_s").unwrap();
    let loss = header.iter().position(|h| *h == "policy_loss_t0").unwrap();
    altered(wall, "12345.6");
    let (code, stdout, stderr) = check(&run, &[], "1");
    assert_eq!(code, 0, "a wall time is not a difference: {stdout}{stderr}");
    altered(loss, "0.123456789");
    let (code, stdout, _) = check(&run, &[], "1");
    assert_eq!(code, 1, "{stdout}");
    assert!(stdout.contains("DIFFERENT") && stdout.contains("0.123456789"), "{stdout}");

    // Bad usage: exit 2 with a message naming what is wrong.
    for (args, needle) in [
        (vec!["x"], "expected a positive integer"),
        (vec!["0"], "expected a positive integer"),
        (vec!["1000"], "has only"),
    ] {
        let (code, _, stderr) = check(&run, &args, "1");
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
    let (code, _, stderr) = check(&dir.join("missing"), &[], "1");
    assert_eq!(code, 2);
    assert!(stderr.contains("missing/config.toml"), "{stderr}");
}
