//! Stopping on request (`rl::stop`): a set `StopFlag` ends `train` after a finished
//! iteration with a checkpoint of it and `RlError::Interrupted`, and the run then resumes
//! bit-identically; a flag set before training changes nothing; a sweep stops at the
//! interrupted run; the `meben` program does the same on Ctrl-C (SIGINT) and SIGTERM, with
//! exit status 130; an evaluation stops with no summary.

use crate::common;

use common::metrics;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use rl::mappo::checkpoint::Checkpoint;
use rl::{RlError, RunDir, RunSelection, StopFlag, Sweep, TrainOptions, run_sweep, train};

/// Data rows of a metrics file (0 if it does not exist yet).
fn rows_written(path: &Path) -> usize {
    std::fs::read_to_string(path).map(|t| t.lines().count().saturating_sub(1)).unwrap_or(0)
}

/// Waits (at most a minute) until `path` holds `rows` data rows.
fn wait_for_rows(path: &Path, rows: usize) {
    let start = Instant::now();
    while rows_written(path) < rows {
        assert!(start.elapsed() < Duration::from_secs(60), "{} never reached {rows} rows", path.display());
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn a_stopped_run_ends_with_a_checkpoint_of_its_last_iteration_and_resumes_exactly() {
    let dir = common::TempDir::new("interrupt-lib");
    // Far more iterations than the test waits for, and a checkpoint only when asked (no
    // periodic ones, one evaluation at the very end): the stop must write its own.
    let iterations = 10_000;
    let config = common::tiny("team_reach/1_ant", "mlp_hn", iterations, &[("checkpoint_every", "0")]);
    let run = RunDir::new(dir.0.join("run"));
    let flag = StopFlag::new();
    let options = TrainOptions { stop: flag.clone(), ..Default::default() };
    let watcher = {
        let (metrics, flag) = (run.metrics(), flag.clone());
        std::thread::spawn(move || {
            wait_for_rows(&metrics, 2);
            flag.request();
        })
    };
    let err = train(&config, &run, &options).unwrap_err();
    watcher.join().unwrap();
    let stopped = match err {
        RlError::Interrupted { iteration: Some(i), ref run } => {
            assert_eq!(run, &dir.0.join("run"));
            i
        }
        other => panic!("expected an interruption, got {other}"),
    };
    assert!((2..iterations).contains(&stopped), "stopped after iteration {stopped}");
    assert!(err.to_string().contains(&format!("interrupted after iteration {stopped}")), "{err}");
    // The checkpoint holds the iteration it stopped after, and the metrics end there.
    assert_eq!(Checkpoint::load(&run.checkpoint()).unwrap().iteration, stopped);
    assert_eq!(metrics(&run).len() as u64, stopped);
    assert!(!run.done().exists());

    // Resumed (to 2 iterations past the stop), it gives the rows of a run never stopped.
    let reference = RunDir::new(dir.0.join("reference"));
    let upto = TrainOptions { stop_after: Some(stopped + 2), ..Default::default() };
    train(&config, &reference, &upto).unwrap();
    let resumed = train(&config, &run, &upto).unwrap();
    assert_eq!(resumed.iterations, stopped + 2);
    assert_eq!(metrics(&run), metrics(&reference));
}

#[test]
fn a_stop_asked_for_before_training_changes_nothing() {
    let dir = common::TempDir::new("interrupt-before");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[]);
    let run = RunDir::new(dir.0.join("run"));
    let flag = StopFlag::new();
    flag.request();
    let err = train(&config, &run, &TrainOptions { stop: flag, ..Default::default() }).unwrap_err();
    assert!(matches!(err, RlError::Interrupted { iteration: None, .. }), "{err}");
    assert!(err.to_string().contains("interrupted before training began"), "{err}");
    assert!(!run.root().exists(), "the run directory was created");
}

#[test]
fn an_interrupted_sweep_stops_at_the_interrupted_run() {
    let dir = common::TempDir::new("interrupt-sweep");
    let file = dir.0.join("sweep.toml");
    std::fs::write(
        &file,
        "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1, 2]\npreset = \"quick\"\n\
         [config]\nsteps = 160\nnum_envs = 8\nbatch_size = 4\nnum_minibatches = 4\nepochs = 1\n\
         num_evals = 1\neval_episodes = 2\n",
    )
    .unwrap();
    let sweep = Sweep::load(&file).unwrap();
    let flag = StopFlag::new();
    let mut calls = 0;
    let result = run_sweep(&sweep, &dir.0.join("out"), &RunSelection::default(), |c, r| {
        calls += 1;
        // The first run trains and finishes; the stop is asked for during the second.
        let options = TrainOptions { stop: flag.clone(), ..Default::default() };
        if calls == 2 {
            flag.request();
        }
        train(c, r, &options)
    });
    let err = result.unwrap_err();
    assert!(matches!(err, RlError::Interrupted { iteration: None, .. }), "{err}");
    assert_eq!(calls, 2, "the sweep went on after the interrupted run");
}

/// `meben train` of a long tiny run into `out`, its output piped.
fn spawn_training(out: &Path) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_meben"))
        .args(["train", "--model", "mlp_hn", "--threads", "1", "--quiet", "--out"])
        .arg(out)
        .args(["--set", "num_envs=8", "--set", "batch_size=4", "--set", "num_minibatches=4", "--set", "epochs=1"])
        .args(["--set", "steps=800000", "--set", "num_evals=1", "--set", "eval_episodes=2"])
        .args(["--set", "checkpoint_every=0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn the_program_stops_with_a_checkpoint_on_sigint_and_sigterm() {
    let dir = common::TempDir::new("interrupt-cli");
    for signal in ["INT", "TERM"] {
        let out = dir.0.join(signal);
        let child = spawn_training(&out);
        let run = RunDir::new(&out);
        wait_for_rows(&run.metrics(), 1);
        let sent = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
        assert!(sent.success());
        let done = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&done.stderr);
        assert_eq!(done.status.code(), Some(130), "SIG{signal}: {stderr}");
        assert!(stderr.contains("stopping after the current iteration"), "SIG{signal}: {stderr}");
        assert!(stderr.contains("interrupted after iteration"), "SIG{signal}: {stderr}");
        assert!(!stderr.contains("error"), "SIG{signal}: {stderr}");
        let saved = Checkpoint::load(&run.checkpoint()).unwrap().iteration;
        assert_eq!(metrics(&run).len() as u64, saved, "SIG{signal}");
        assert!(!run.done().exists());
    }
}

#[test]
fn a_stopped_evaluation_returns_no_summary_and_an_unstopped_one_the_same_as_evaluate() {
    use rl::mappo::evaluate::{evaluate, evaluate_unless_stopped};
    let dir = common::TempDir::new("interrupt-eval");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 1, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let (config, teams) = rl::app::run_dir::load_policies(&run).unwrap();
    let request = rl::EvalRequest {
        episodes: 6,
        seed: 3,
        deterministic: Some(false),
        fixed: false,
        rotation_deg: None,
        translation: None,
    };
    let options = request.options(&config);
    let flag = StopFlag::new();
    let whole = evaluate_unless_stopped(&config.env, &teams, &options, &flag).unwrap();
    assert_eq!(whole, Some(evaluate(&config.env, &teams, &options).unwrap()));
    flag.request();
    assert_eq!(evaluate_unless_stopped(&config.env, &teams, &options, &flag).unwrap(), None);
}
