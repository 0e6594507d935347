//! Helpers shared by the `rl` integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use rl::{Preset, TrainConfig};

/// The checkpoint tensors files of a run directory (`*.safetensors`), sorted.
pub fn tensors_files(run: &rl::RunDir) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(run.root())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "safetensors"))
        .collect();
    v.sort();
    v
}

/// A tiny configuration: 8 environments, 2 blocks of 5 steps per iteration (80 env steps),
/// 4 minibatches of 4 unrolls, 2 epochs, `iterations` iterations, evaluations of 4 episodes.
pub fn tiny(env: &str, model: &str, iterations: u64, extra: &[(&str, &str)]) -> TrainConfig {
    let steps = (80 * iterations).to_string();
    let mut ov: Vec<(String, String)> = [
        ("env", format!("{env:?}")),
        ("model", format!("{model:?}")),
        ("num_envs", "8".into()),
        ("batch_size", "4".into()),
        ("num_minibatches", "4".into()),
        ("epochs", "2".into()),
        ("steps", steps),
        ("num_evals", "1".into()),
        ("eval_episodes", "2".into()),
        ("checkpoint_every", "1".into()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    ov.extend(extra.iter().map(|(k, v)| (k.to_string(), v.to_string())));
    TrainConfig::resolve(Some(Preset::Quick), None, &ov).unwrap()
}

/// A fresh directory under the system temporary directory, removed when dropped (a test
/// that fails removes it too: a test's runs can hold tens of MB, and CI runs them often).
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// Creates (empties) the directory `meben-test-<pid>-<name>`.
    pub fn new(name: &str) -> TempDir {
        let d = std::env::temp_dir().join(format!("meben-test-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        TempDir(d)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A run's metrics rows without the wall-clock columns (`rl::app::metrics::WALL_TIME_COLUMNS`),
/// as `(column, value)` in column-name order, for comparing runs row by row.
pub fn metrics(run: &rl::RunDir) -> Vec<Vec<(String, f64)>> {
    let rows = rl::app::record::MetricsTable::read(&run.metrics()).unwrap().rows;
    let wall = rl::app::metrics::WALL_TIME_COLUMNS;
    rows.iter().map(|r| r.cells().into_iter().filter(|(k, _)| !wall.contains(&k.as_str())).collect()).collect()
}

/// Runs the `meben` program with `args`: whether it succeeded, its stdout and its stderr.
pub fn meben(args: &[&str]) -> (bool, String, String) {
    outcome(std::process::Command::new(env!("CARGO_BIN_EXE_meben")).args(args).output().unwrap())
}

/// A finished process as whether it succeeded, its stdout and its stderr.
pub fn outcome(out: std::process::Output) -> (bool, String, String) {
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

/// Trains a short `team_reach/2_ants` run of `model` into `out` with the `meben` program
/// (2560 env steps in 8 iterations, no evaluation).
pub fn train_2_ants(model: &str, out: &Path) {
    train_2_ants_with(model, out, &[]);
}

/// [`train_2_ants`] with the training fields `sets` (`key=value`, each given to `--set`).
pub fn train_2_ants_with(model: &str, out: &Path, sets: &[&str]) {
    let mut args = vec![
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
    for set in sets {
        args.extend(["--set", set]);
    }
    let (ok, _, err) = meben(&args);
    assert!(ok, "train {model} {sets:?} failed: {err}");
}
