//! The learning tests (ignored by default: about ten minutes each on 2 cores): `shnn` (what
//! `cargo run --release` trains) and `mlp_hn` on `team_reach/1_ant` with the built-in
//! `quick` budget reach a clearly rising evaluation success rate.
//!
//! Run: `cargo test --release -p rl --test integration learning:: -- --ignored --nocapture --test-threads 1`.

use crate::common;

use rl::app::record::MetricsTable;
use rl::{RunDir, TrainConfig, TrainOptions, train};

/// Trains `model` (quick preset, seed 0) and checks that the evaluation success rises.
fn learns_team_reach_1_ant(model: &str) {
    let tmp = common::TempDir::new(&format!("learning-{model}"));
    let dir = tmp.0.clone();
    let config = TrainConfig::resolve(None, None, &[("model".into(), model.into())]).unwrap();
    assert_eq!(config.env.as_str(), "team_reach/1_ant");
    let run = RunDir::new(dir.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let rows = MetricsTable::read(&run.metrics()).unwrap().rows;
    let evals: Vec<(f64, f64)> =
        rows.iter().filter_map(|r| Some((r.env_steps as f64, r.eval(0.0)?.success_rate?))).collect();
    for (s, r) in &evals {
        println!("{model} env_steps {s} eval_success_rate {r}");
    }
    let first = evals.first().unwrap().1;
    let best_late = evals[evals.len() / 2..].iter().map(|e| e.1).fold(0.0, f64::max);
    assert!(best_late >= 0.2 && best_late >= first + 0.15, "{model}: success rate did not rise: {evals:?}");
}

#[test]
#[ignore]
fn shnn_learns_team_reach_1_ant_within_the_quick_budget() {
    let config = TrainConfig::resolve(None, None, &[]).unwrap();
    assert_eq!(config.model.as_str(), "shnn", "the default run");
    learns_team_reach_1_ant("shnn");
}

#[test]
#[ignore]
fn mlp_hn_learns_team_reach_1_ant_within_the_quick_budget() {
    learns_team_reach_1_ant("mlp_hn");
}
