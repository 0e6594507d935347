//! `rl/sweeps/assignment_diagnostics.py`, which reads what a learned task assignment learned
//! from a run's checkpoint and rendered episodes (issue 79's evidence). With the prior at
//! its largest (`assign_prior=1000`) the draw is Algorithm 1's (`models`' tests), so the
//! script must find its scores falling by 1000 a metre, the sampled assignment equal to its
//! own Algorithm 1 on every step, and the most likely one equal to the least-distance
//! matching; a run without a learned assignment is refused by name.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/assignment_diagnostics.py")
}

/// Trains a short `team_reach/2_ants` run of `model` into `out` (no evaluation).
fn train(model: &str, out: &Path) {
    let args = [
        "train",
        "--env",
        "team_reach/2_ants",
        "--model",
        model,
        "--steps",
        "2560",
        "--num-envs",
        "16",
        "--seed",
        "3",
        "--threads",
        "1",
        "--set",
        "batch_size=8",
        "--set",
        "num_evals=0",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ];
    let (ok, _, err) = common::meben(&args);
    assert!(ok, "train {model} failed: {err}");
}

/// Trains a short run of `model` in the scratch directory `scratch` (one per test: tests run
/// in parallel) and runs the script on it over `episodes` episodes; (success, stdout, stderr).
fn diagnose(scratch: &str, model: &str, episodes: &str) -> (bool, String, String) {
    let tmp = common::TempDir::new(scratch);
    let run = tmp.0.join("run");
    train(model, &run);
    let out = Command::new("python3")
        .arg(script())
        .args(["--bin", env!("CARGO_BIN_EXE_meben"), "--episodes", episodes])
        .arg(&run)
        .output()
        .expect("python3 runs the script");
    common::outcome(out)
}

/// The cells of the table row whose second column is `second` (a table of `run`).
fn row<'a>(stdout: &'a str, second: &str) -> Vec<&'a str> {
    stdout
        .lines()
        .map(|l| l.split('|').map(str::trim).filter(|c| !c.is_empty()).collect::<Vec<_>>())
        .find(|cells| cells.len() > 2 && cells[1] == second)
        .unwrap_or_else(|| panic!("no row with {second:?} in:\n{stdout}"))
}

#[test]
fn the_diagnostics_find_algorithm_1_in_a_run_with_the_largest_prior() {
    let (ok, stdout, stderr) = diagnose("assignment_diagnostics", "mlp_hn:assignment=learned;assign_prior=1000", "2");
    assert!(ok, "{stdout}{stderr}");

    // Scores: λ read from the model string, s(d + 1) - s(d) = -1000 up to the small
    // untrained f_θ, and the nearer agent always picked.
    let scores = row(&stdout, "1000");
    let s: Vec<f64> = scores[2..8].iter().map(|c| c.parse().unwrap()).collect();
    for pair in s.windows(2) {
        assert!((pair[1] - pair[0] + 1000.0).abs() < 2.0, "{scores:?}");
    }
    assert_eq!(scores[8], "1.00", "{scores:?}");

    // Sampled draws are Algorithm 1's on every step, and change when it does.
    let sampled = row(&stdout, "sampled");
    assert_eq!(sampled[2], "2002", "two whole episodes of 1000 steps: {sampled:?}");
    assert_eq!(sampled[3], "100.0%", "{sampled:?}");
    assert_eq!(sampled[5], sampled[6], "{sampled:?}");
    // The most likely assignment maximises the total score -1000 d: the least-distance
    // matching.
    let most_likely = row(&stdout, "most likely (mean actions)");
    assert_eq!(most_likely[4], "100.0%", "{most_likely:?}");
}

#[test]
fn the_diagnostics_refuse_a_run_without_a_learned_assignment() {
    let (ok, stdout, stderr) = diagnose("assignment_diagnostics_greedy", "mlp_hn", "1");
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("/run: no team0.assign.* parameters"), "the run is named: {stderr}");
}
