//! Checkpoints: a run stopped and resumed gives the same bits as an uninterrupted run (Team
//! Reach and Team Sumo with two teams, different models and the curriculum), whatever the
//! thread count; each session is recorded in `builds.csv`; damaged checkpoints and changed
//! configurations are refused with the file named.

use crate::common;

use common::metrics;

use rl::mappo::checkpoint::Checkpoint;
use rl::mappo::normalizer::{NormKind, ObsNormalizer};
use rl::{RunDir, TrainConfig, TrainOptions, train};

fn params(run: &RunDir) -> Vec<Vec<f64>> {
    let c = Checkpoint::load(&run.checkpoint()).unwrap();
    c.teams.iter().flat_map(|t| t.params.tensors.iter().map(|x| x.data.clone())).collect()
}

/// The `from_iteration` of each row of a run's `builds.csv`, after checking that every row
/// names this build.
fn build_rows(run: &RunDir) -> Vec<String> {
    use rl::app::build_info::{BUILDS_HEADER, COMMIT, VERSION};
    let text = std::fs::read_to_string(run.builds()).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(BUILDS_HEADER));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f[1..3], [VERSION, COMMIT], "{l}");
            f[0].to_string()
        })
        .collect()
}

#[test]
fn resumed_runs_are_bit_identical_to_uninterrupted_ones() {
    let tmp = common::TempDir::new("resume");
    let dir = tmp.0.clone();
    for (env, model, extra) in [
        ("team_reach/1_ant", "shnn", vec![]),
        ("team_reach/2_ants", "shnn:assignment=learned", vec![]),
        ("team_reach/2_ants", "mlp_hn:assignment=learned", vec![]),
        ("team_sumo/2_ants", "shnn", vec![("opponent", "mlp_hn"), ("curriculum_fraction", "0.5")]),
    ] {
        let config = common::tiny(env, model, 4, &extra);
        let name = format!("{env}-{model}").replace(['/', ':', '='], "_");
        let whole = RunDir::new(dir.join(format!("{name}-whole")));
        let s1 = train(&config, &whole, &TrainOptions::default()).unwrap();
        assert_eq!(s1.iterations, 4);

        // Stopped after 1 and after 3 iterations, on 1 thread, then finished on 2.
        let parts = RunDir::new(dir.join(format!("{name}-parts")));
        let mut c1 = config.clone();
        c1.threads = 1;
        let s = train(&c1, &parts, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
        assert_eq!(s.iterations, 1);
        assert!(!parts.done().exists());
        train(&c1, &parts, &TrainOptions { stop_after: Some(3), ..Default::default() }).unwrap();
        let mut c2 = config.clone();
        c2.threads = 2;
        let s2 = train(&c2, &parts, &TrainOptions::default()).unwrap();
        assert!(parts.done().exists());

        assert_eq!(metrics(&whole), metrics(&parts), "{name}: metrics differ");
        assert_eq!(params(&whole), params(&parts), "{name}: parameters differ");
        assert_eq!(s1.final_eval, s2.final_eval, "{name}: final evaluations differ");
        let m = metrics(&whole);
        assert_eq!(m.len(), 4);
        if env.starts_with("team_sumo") {
            let alpha: Vec<f64> =
                m.iter().map(|r| r.iter().find(|(k, _)| k == "curriculum_alpha").unwrap().1).collect();
            assert_eq!(alpha, vec![1.0, 0.5, 0.0, 0.0], "curriculum over the first half of 4 iterations");
        }
        // A finished run returns its summary without training.
        let again = train(&config, &whole, &TrainOptions::default()).unwrap();
        assert_eq!(again, s1);
        // builds.csv: a row per session that trained, naming the iteration it went on from
        // and this build; returning a finished run's summary adds none.
        assert_eq!(build_rows(&whole), ["0"]);
        assert_eq!(build_rows(&parts), ["0", "1", "3"]);
    }
}

#[test]
fn bad_checkpoints_and_changed_configurations_are_refused() {
    let tmp = common::TempDir::new("badckpt");
    let dir = tmp.0.clone();
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[]);
    let run = RunDir::new(dir.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();

    let mut other = config.clone();
    other.entropy_coef = 0.5;
    let e = train(&other, &run, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json") && e.contains("entropy_coef"), "{e}");

    let good = std::fs::read(run.checkpoint()).unwrap();
    for damaged in [&good[..good.len() / 2], b"not json" as &[u8]] {
        std::fs::write(run.checkpoint(), damaged).unwrap();
        let e = train(&config, &run, &TrainOptions::default()).unwrap_err().to_string();
        assert!(e.contains("checkpoint.json") && e.contains("not a valid checkpoint"), "{e}");
    }
    // A normaliser of another kind (an element-wise one, as `auto` built for `mlp_hn` before
    // it meant the invariant normaliser), and the per-node kind that was removed: refused by
    // training and by evaluation, naming the normaliser.
    std::fs::write(run.checkpoint(), &good).unwrap();
    let mut c = Checkpoint::load(&run.checkpoint()).unwrap();
    let spec = envs::tasks::Scene::from_name(&config.env).unwrap().obs_spec;
    c.teams[0].normalizer = ObsNormalizer::new(NormKind::Elementwise, &spec);
    c.save(&run.checkpoint()).unwrap();
    let e = train(&config, &run, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json") && e.contains("normaliser") && e.contains("elementwise"), "{e}");
    let e = rl::app::run_dir::load_policies(&run).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json") && e.contains("normaliser"), "{e}");
    let text = String::from_utf8(good.clone()).unwrap();
    assert!(text.contains("\"kind\":\"Invariant\""));
    let rl::mappo::checksum::Unsealed::Checked(payload) = rl::mappo::checksum::unseal(&good).unwrap() else {
        panic!("unsealed")
    };
    let renamed = payload.replace("\"kind\":\"Invariant\"", "\"kind\":\"Rotation\"");
    std::fs::write(run.checkpoint(), rl::mappo::checksum::seal(renamed.as_bytes())).unwrap();
    let e = train(&config, &run, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json") && e.contains("Rotation"), "{e}");
    // The checkpoint of another model.
    std::fs::write(run.checkpoint(), &good).unwrap();
    let mut shnn = config.clone();
    shnn.model = "shnn".into();
    let e = train(&shnn, &run, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json") && e.contains("model"), "{e}");
}

/// Damaged files other than the checkpoint ("a corrupted file"): `metrics.csv`
/// keeps its good rows when another line holds bytes that are not UTF-8 (before, one such
/// byte made the whole file unreadable and every earlier row was dropped on resume); a
/// damaged `config.toml` is refused by evaluation naming the file, and running the training
/// again rewrites it, also for a finished run (before, a finished run returned without
/// writing it, so it stayed unreadable); a damaged `done.json` is written again.
#[test]
fn damaged_metrics_config_and_done_files_are_repaired_or_refused_by_name() {
    let dir = common::TempDir::new("damaged-files");
    let config = common::tiny("team_reach/1_ant", "mlp", 2, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    let mut metrics = std::fs::read(run.metrics()).unwrap();
    let row1 = String::from_utf8(metrics.clone()).unwrap().lines().nth(1).unwrap().to_string();
    assert!(row1.starts_with("1,"), "{row1}");
    metrics.extend_from_slice(b"\xff\xfe garbage\n");
    std::fs::write(run.metrics(), &metrics).unwrap();
    train(&config, &run, &TrainOptions::default()).unwrap();
    let text = std::fs::read_to_string(run.metrics()).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{text}");
    assert_eq!(rows[0], row1);
    assert!(rows[1].starts_with("2,"), "{text}");

    // The run is finished; its config.toml is damaged.
    std::fs::write(run.config(), "env = [broken").unwrap();
    let e = rl::app::run_dir::load_policies(&run).unwrap_err().to_string();
    assert!(e.contains("config.toml") && e.contains("line 1"), "{e}");
    assert_eq!(train(&config, &run, &TrainOptions::default()).unwrap().iterations, 2);
    assert_eq!(TrainConfig::load(&run.config()).unwrap(), config);
    rl::app::run_dir::load_policies(&run).unwrap();

    std::fs::write(run.done(), "{\"iterations\": 2, broken").unwrap();
    assert_eq!(train(&config, &run, &TrainOptions::default()).unwrap().iterations, 2);
    let done: rl::RunSummary = serde_json::from_str(&std::fs::read_to_string(run.done()).unwrap()).unwrap();
    assert_eq!(done.iterations, 2);
}

/// Issue 44 item 5: a run stopped after 2 of its 6 iterations and resumed with a budget of
/// 2 iterations ended at once without its final evaluation (`done.json` with
/// `"final_eval": null`); a finished run resumed with a smaller budget had its `config.toml`
/// rewritten to it (`meben status`: `0.02M of 0.01M`). Both are refused, naming the
/// checkpoint, the budget and the steps done, and nothing is written.
#[test]
fn a_budget_not_above_the_steps_done_is_refused() {
    let dir = common::TempDir::new("resume-budget");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 6, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(2), ..Default::default() }).unwrap();
    let before = std::fs::read(run.config()).unwrap();
    let refused = |steps: u64, done: u64| {
        let smaller = TrainConfig { steps, ..config.clone() };
        let e = train(&smaller, &run, &TrainOptions::default()).unwrap_err().to_string();
        let ckpt = run.checkpoint().display().to_string();
        assert!(e.starts_with(&format!("{ckpt}: field `steps` = \"{steps}\": ")), "{e}");
        assert!(e.contains(&format!("{done} env steps")), "{e}");
        assert!(!run.done().exists(), "{e}");
        assert_eq!(std::fs::read(run.config()).unwrap(), before, "config.toml was rewritten");
    };
    // Equal to the steps done (2 iterations of 80), and below them.
    refused(160, 160);
    refused(80, 160);
    // One step more is one more iteration: the run ends with its final evaluation.
    let s = train(&TrainConfig { steps: 161, ..config.clone() }, &run, &TrainOptions::default()).unwrap();
    assert_eq!(s.iterations, 3);
    assert!(s.final_eval.is_some());
    // A finished run keeps its budget: a smaller one is refused, its own passes.
    let before = std::fs::read(run.config()).unwrap();
    let smaller = TrainConfig { steps: 80, ..config.clone() };
    let e = train(&smaller, &run, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("240 env steps") && e.contains("\"80\""), "{e}");
    assert_eq!(std::fs::read(run.config()).unwrap(), before, "config.toml was rewritten");
    let again = train(&TrainConfig { steps: 161, ..config.clone() }, &run, &TrainOptions::default()).unwrap();
    assert_eq!(again.iterations, 3);
}

/// The names of the files in a run directory and their bytes (the lock file aside: every
/// training writes its holder there).
fn snapshot(run: &RunDir) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(run.root())
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_name() != "lock")
        .map(|e| {
            let bytes = if e.path().is_file() { std::fs::read(e.path()).unwrap() } else { Vec::new() };
            (e.file_name().to_string_lossy().into_owned(), bytes)
        })
        .collect();
    files.sort();
    files
}

/// Issue 77 item 2: an older `checkpoint.json` put back (its tensors file long gone) made
/// the resume fail, correctly, but it first removed the tensors file of the newer
/// checkpoint as stale, so putting the newer JSON back failed too and the run was lost. A
/// resume that fails now changes nothing, and the newer pair resumes.
#[test]
fn a_failed_resume_leaves_the_newer_checkpoint_whole() {
    let dir = common::TempDir::new("resume-older-json");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 3, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    let older = std::fs::read(run.checkpoint()).unwrap();
    train(&config, &run, &TrainOptions { stop_after: Some(2), ..Default::default() }).unwrap();
    let newer = std::fs::read(run.checkpoint()).unwrap();
    std::fs::write(run.checkpoint(), &older).unwrap();
    let before = snapshot(&run);
    let e = train(&config, &run, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("checkpoint.json") && e.contains("missing"), "{e}");
    assert!(snapshot(&run) == before, "the failed resume changed the run directory");
    std::fs::write(run.checkpoint(), &newer).unwrap();
    let s = train(&config, &run, &TrainOptions::default()).unwrap();
    assert_eq!(s.iterations, 3);
    let text = std::fs::read_to_string(run.metrics()).unwrap();
    let kept: Vec<&str> = text.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(kept, ["1", "2", "3"]);
}

/// Issue 77 item 3: a `metrics.csv` that cannot be read was taken as empty, and the resume
/// rewrote it without the rows before the checkpoint. It is refused naming the file, and
/// nothing is written (as root, permissions do not stop reads: a directory stands in).
#[test]
fn an_unreadable_metrics_file_stops_the_resume_with_nothing_written() {
    let dir = common::TempDir::new("resume-unreadable-metrics");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    let aside = dir.0.join("metrics.csv");
    std::fs::rename(run.metrics(), &aside).unwrap();
    std::fs::create_dir(run.metrics()).unwrap();
    let before = snapshot(&run);
    let e = train(&config, &run, &TrainOptions::default()).unwrap_err().to_string();
    let path = run.metrics().display().to_string();
    assert!(e.starts_with(&path) && e.contains("cannot read"), "{e}");
    assert!(snapshot(&run) == before, "the refused resume changed the run directory");
    std::fs::remove_dir(run.metrics()).unwrap();
    std::fs::rename(&aside, run.metrics()).unwrap();
    assert_eq!(train(&config, &run, &TrainOptions::default()).unwrap().iterations, 2);
    assert_eq!(common::metrics(&run).len(), 2);
}
