//! Tests of `rl::mappo` functions on the `quick` preset's configuration. The presets are
//! the application's (`rl::app::presets`) and `mappo` never uses `app`, tests included, so
//! these tests live here.

use std::path::Path;

use rl::mappo::config_match::{
    FieldDifference, NEVER_IDENTITY_FIELDS, SESSION_FIELDS, check_config_matches_checkpoint, differences,
    identity_differences,
};
use rl::mappo::memory::{RunFootprint, check_run_fits};
use rl::mappo::team::lr_schedule;
use rl::{Preset, TrainConfig, TrainStarts};

/// The `quick` preset's configuration, resolved from no file and no override.
fn quick() -> TrainConfig {
    TrainConfig::resolve(Some(Preset::Quick), None, &[]).unwrap()
}

#[test]
fn session_fields_may_differ_the_others_are_named() {
    let a = quick();
    let b = TrainConfig {
        steps: a.steps * 2,
        num_evals: 3,
        checkpoint_every: 9,
        threads: 1,
        device: tensor::Device::Gpu,
        ..a.clone()
    };
    assert!(identity_differences(&a, &b).is_empty());
    let c = TrainConfig {
        model: "shnn:assignment=stochastic".into(),
        env: "team_reach:agents=ant;R=5".into(),
        train_starts: TrainStarts::PerSlot,
        ..b
    };
    let d = identity_differences(&c, &a);
    let names: Vec<&str> = d.iter().map(|d| d.field.as_str()).collect();
    assert_eq!(names, ["env", "model", "train_starts"]);
    assert_eq!(d[1].first, "\"shnn:assignment=stochastic\"");
    assert_eq!(d[1].second, "\"shnn\"");
    let e = check_config_matches_checkpoint(Path::new("r/config.toml"), &c, Path::new("r/checkpoint.json"), &a)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("r/config.toml: does not match the configuration the checkpoint r/checkpoint.json")
            && e.contains("model = \"shnn:assignment=stochastic\" here, \"shnn\" in the checkpoint")
            && e.contains("train_starts = \"per_slot\" here, \"fresh\" in the checkpoint"),
        "{e}"
    );
}

/// The fields `config.toml` writes only away from their default (`train_starts`,
/// `device`) are compared either way round: the resume check used to list only the
/// checkpoint's written fields, and refused `train_starts = "per_slot"` against a
/// `fresh` checkpoint naming no field.
#[test]
fn fields_written_only_away_from_their_default_are_compared_both_ways() {
    let a = quick();
    let b = TrainConfig { train_starts: TrainStarts::PerSlot, ..a.clone() };
    for (x, y) in [(&a, &b), (&b, &a)] {
        let d = differences(x, y, &[]);
        assert_eq!(d.len(), 1, "{d:?}");
        assert_eq!(d[0].field, "train_starts");
    }
    let gpu = TrainConfig { device: tensor::Device::Gpu, ..a.clone() };
    assert_eq!(differences(&a, &gpu, &[])[0].describe("saved", "now"), "device = \"cpu\" saved, \"gpu\" now");
    assert!(differences(&a, &gpu, &NEVER_IDENTITY_FIELDS).is_empty());
    // What the caller allows is all that is left out.
    let more = TrainConfig { steps: a.steps + 1, num_evals: a.num_evals + 1, ..a.clone() };
    let names = |d: Vec<FieldDifference>| d.into_iter().map(|d| d.field).collect::<Vec<_>>();
    assert_eq!(names(differences(&a, &more, &NEVER_IDENTITY_FIELDS)), ["num_evals", "steps"]);
    assert_eq!(names(differences(&a, &more, &["steps"])), ["num_evals"]);
    assert!(differences(&a, &more, &SESSION_FIELDS).is_empty());
}

/// Issue 44 item 2: `--set eval_episodes=1048576` trained and aborted at the first
/// evaluation. The training's footprint counts the evaluation's environments, so it is
/// refused before anything is built, naming `eval_episodes`.
#[test]
fn a_training_whose_evaluation_cannot_fit_is_refused_naming_eval_episodes() {
    let Some(memory) = envs::memory::machine_memory() else { return };
    let quick = quick();
    check_run_fits(&quick).unwrap();
    let big = TrainConfig { env: "team_sumo/3_ants".into(), eval_episodes: envs::tasks::MAX_ENVS, ..quick.clone() };
    let f = RunFootprint::of(&big).unwrap();
    if f.total().unwrap() <= memory.bytes {
        return;
    }
    let e = check_run_fits(&big).unwrap_err().to_string();
    assert!(
        e.starts_with("config: field `eval_episodes` = \"1048576\": this training of team_sumo/3_ants needs about")
    );
    // The bound is the machine's (`/proc/meminfo`) or the process's own limit where smaller
    // (a cgroup's `memory.max`, `ulimit -v`), and the message names which.
    assert!(e.contains("1048576 evaluation episodes"), "{e}");
    assert!(e.contains("/proc/meminfo") || e.contains("this process's limit"), "{e}");
    // Without evaluations there is none to hold.
    check_run_fits(&TrainConfig { num_evals: 0, ..big }).unwrap();
}

#[test]
fn learning_rate_decays_to_zero_over_the_run_or_stays() {
    let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
    let updates = c.iterations() * (c.epochs * c.num_minibatches) as u64;
    let s = lr_schedule(&c);
    assert_eq!(s.at(0), c.learning_rate);
    assert!((s.at(updates / 2) - c.learning_rate / 2.0).abs() < 1e-9);
    assert_eq!(s.at(updates), 0.0);
    c.lr_decay = false;
    assert_eq!(lr_schedule(&c).at(updates), c.learning_rate);
}
