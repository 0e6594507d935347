//! The learning test (ignored by default: about ten to fifteen minutes on 2 cores): `shnn` on
//! `team_reach/1_ant` with the built-in `quick` budget (what `cargo run --release` trains)
//! reaches a clearly rising evaluation success rate.
//!
//! Run: `cargo test --release -p rl --test learning -- --ignored --nocapture`.

mod common;

use rl::metrics::parse_csv;
use rl::{RunDir, TrainConfig, TrainOptions, train};

#[test]
#[ignore]
fn shnn_learns_team_reach_1_ant_within_the_quick_budget() {
    let dir = common::temp_dir("learning");
    let config = TrainConfig::resolve(None, None, &[]).unwrap();
    assert_eq!((config.model.as_str(), config.env.as_str()), ("shnn", "team_reach/1_ant"));
    let run = RunDir::new(dir.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let rows = parse_csv(&std::fs::read_to_string(run.metrics()).unwrap()).unwrap();
    let evals: Vec<(f64, f64)> =
        rows.iter().filter_map(|r| Some((r["env_steps"], *r.get("eval_success_rate")?))).collect();
    for (s, r) in &evals {
        println!("env_steps {s} eval_success_rate {r}");
    }
    let first = evals.first().unwrap().1;
    let best_late = evals[evals.len() / 2..].iter().map(|e| e.1).fold(0.0, f64::max);
    assert!(best_late >= 0.2 && best_late >= first + 0.15, "success rate did not rise: {evals:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
