//! Policy files (`meben export-policy`, `rl::app::policy_file`): evaluating the file gives
//! the figures of evaluating its run (same seed and episodes), in Team Reach and in Team Sumo
//! with two models; the file holds the policy (no critic) as F32 with its metadata, and is the
//! same bytes when exported twice; damaged, truncated or foreign files, and unknown
//! pretrained names, are clear errors naming them, never a panic, with a non-zero exit.

use crate::common;

use std::path::Path;

use rl::app::policy_file::{self, keys};
use rl::mappo::tensor_file::{self, Dtype};
use rl::{EvalRequest, RunDir, TrainOptions, train};

use common::meben;

/// `meben` fails with a message holding every needle, without a panic.
fn fails_with(args: &[&str], needles: &[&str]) {
    let (ok, _, stderr) = meben(args);
    assert!(!ok, "{args:?} succeeded");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for n in needles {
        assert!(stderr.contains(n), "{n:?} not in: {stderr}");
    }
}

#[test]
fn evaluating_the_exported_policy_gives_the_runs_figures() {
    let dir = common::TempDir::new("policy-eval");
    let run = dir.0.join("run");
    let (run_s, file) = (run.to_str().unwrap(), dir.0.join("policy.safetensors"));
    let file_s = file.to_str().unwrap();
    let train_args = [
        "train",
        "--model",
        "shnn",
        "--num-envs",
        "8",
        "--steps",
        "80",
        "--set",
        "batch_size=4",
        "--set",
        "num_minibatches=2",
        "--set",
        "epochs=1",
        "--set",
        "num_evals=1",
        "--set",
        "eval_episodes=4",
        "--quiet",
        "--out",
        run_s,
    ];
    let (ok, _, stderr) = meben(&train_args);
    assert!(ok, "{stderr}");
    let (ok, stdout, stderr) = meben(&["export-policy", "--run", run_s, "--out", file_s]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("success rate") && stdout.contains("on 4 episodes"), "{stdout}");
    for extra in [&[][..], &["--stochastic"], &["--rotate", "90", "--translate", "1,-2"]] {
        let (a, b) = (dir.0.join("run.json"), dir.0.join("file.json"));
        let mut args = vec!["eval", "--episodes", "6", "--seed", "7"];
        args.extend_from_slice(extra);
        let with = |source: &[&str], out: &Path| {
            let mut v = args.clone();
            v.extend_from_slice(source);
            v.extend_from_slice(&["--out", out.to_str().unwrap()]);
            let (ok, stdout, stderr) = meben(&v);
            assert!(ok, "{stderr}");
            stdout
        };
        let printed = with(&["--run", run_s], &a);
        assert_eq!(with(&["--policy", file_s], &b), printed, "{extra:?}");
        assert_eq!(std::fs::read_to_string(&a).unwrap(), std::fs::read_to_string(&b).unwrap(), "{extra:?}");
    }
    // Rendering from the file: the same episode as from the run.
    let (ha, hb) = (dir.0.join("a.csv"), dir.0.join("b.csv"));
    assert!(meben(&["render", "--run", run_s, "--out", ha.to_str().unwrap(), "--steps", "15"]).0);
    assert!(meben(&["render", "--policy", file_s, "--out", hb.to_str().unwrap(), "--steps", "15"]).0);
    assert_eq!(std::fs::read(&ha).unwrap(), std::fs::read(&hb).unwrap());

    // What the file holds: the policy parameters (no critic) as F32, bit for bit the
    // run's, and the metadata; exported again, the same bytes.
    let bytes = std::fs::read(&file).unwrap();
    let (st, meta) = tensor_file::read(&bytes).unwrap();
    let (config, teams) = rl::app::run_dir::load_policies(&RunDir::new(&run)).unwrap();
    let mut n = 0;
    for (name, value) in teams[0].store.iter() {
        if name.starts_with("team0.critic.") {
            assert!(st.tensor(name).is_err(), "{name} was exported");
            continue;
        }
        n += 1;
        let (shape, data) = tensor_file::f32_values(&st, name).unwrap();
        assert_eq!(st.tensor(name).unwrap().dtype(), Dtype::F32);
        assert_eq!((shape.as_slice(), data.as_slice()), (value.shape(), value.data()), "{name}");
    }
    assert_eq!(st.len(), n);
    assert_eq!(meta[keys::FORMAT], "meben policy");
    assert_eq!(meta[keys::ENV], "team_reach/1_ant");
    assert_eq!(meta[keys::MODEL], "shnn");
    assert_eq!(meta[keys::ENV_STEPS], "80");
    assert_eq!(meta[keys::MEBEN_COMMIT], rl::app::build_info::COMMIT);
    let loaded = policy_file::load_policy(&file).unwrap();
    assert_eq!(loaded.config, config);
    assert_eq!(loaded.teams[0].norm, teams[0].norm);
    let done: rl::RunSummary = serde_json::from_str(&std::fs::read_to_string(run.join("done.json")).unwrap()).unwrap();
    assert_eq!(loaded.eval, done.final_eval);
    let again = dir.0.join("again.safetensors");
    assert!(meben(&["export-policy", "--run", run_s, "--out", again.to_str().unwrap()]).0);
    assert_eq!(std::fs::read(&again).unwrap(), bytes, "two exports differ");
    // Not over the run's own files.
    let ckpt = run.join("checkpoint.json");
    fails_with(&["export-policy", "--run", run_s, "--out", ckpt.to_str().unwrap()], &["checkpoint.json", "own"]);
}

/// Team Sumo: both teams (two models) are in the file and evaluate as in the run.
#[test]
fn a_team_sumo_policy_file_holds_both_teams() {
    let dir = common::TempDir::new("policy-sumo");
    let config = common::tiny("team_sumo/2_ants", "shnn", 1, &[("opponent", "mlp_hn")]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let file = dir.0.join("sumo.safetensors");
    let s = policy_file::export_policy(&run, &file).unwrap();
    assert!(s.sumo && s.eval.is_some());
    let loaded = policy_file::load_policy(&file).unwrap();
    assert_eq!(loaded.metadata[keys::OPPONENT], "mlp_hn");
    let (_, teams) = rl::app::run_dir::load_policies(&run).unwrap();
    let request = EvalRequest {
        episodes: 5,
        seed: 3,
        deterministic: Some(false),
        fixed: false,
        rotation_deg: None,
        translation: None,
    };
    let options = request.options(&config);
    let from_run = rl::evaluate(&config.env, &teams, &options).unwrap();
    let from_file = rl::evaluate(&loaded.config.env, &loaded.teams, &request.options(&loaded.config)).unwrap();
    assert_eq!(from_run, from_file);
}

#[test]
fn damaged_truncated_or_foreign_policy_files_are_refused_naming_them() {
    let dir = common::TempDir::new("policy-damaged");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 1, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let file = dir.0.join("p.safetensors");
    policy_file::export_policy(&run, &file).unwrap();
    let good = std::fs::read(&file).unwrap();
    let bad = dir.0.join("bad.safetensors");
    let bad_s = bad.to_str().unwrap();
    let refused = |bytes: &[u8], needle: &str| {
        std::fs::write(&bad, bytes).unwrap();
        let e = policy_file::load_policy(&bad).unwrap_err().to_string();
        assert!(e.contains(bad_s) && e.contains(needle), "{needle:?} not in: {e}");
        fails_with(&["eval", "--policy", bad_s, "--episodes", "1"], &[bad_s, needle]);
    };
    refused(&good[..good.len() / 2], "not a valid safetensors file");
    refused(&good[..5], "not a valid safetensors file");
    refused(b"", "empty");
    refused(b"{\"not\": \"safetensors\"}", "not a valid safetensors file");
    let mut flipped = good.clone();
    let i = flipped.len() - 10;
    flipped[i] ^= 1;
    refused(&flipped, "checksum mismatch");
    // A byte of the metadata: the environment's name (same length, still valid JSON).
    let text = String::from_utf8_lossy(&good).into_owned();
    let at = text.find("team_reach/1_ant").unwrap();
    let mut edited = good.clone();
    edited[at + 11] = b'2';
    refused(&edited, "checksum mismatch");
    // The checkpoint's tensors file is safetensors but not a policy.
    let tensors = std::fs::read_dir(run.root())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "safetensors"))
        .unwrap();
    refused(&std::fs::read(tensors).unwrap(), "meben export-policy");
    let missing = dir.0.join("missing.safetensors");
    fails_with(&["eval", "--policy", missing.to_str().unwrap()], &["missing.safetensors", "cannot read"]);
    fails_with(&["render", "--policy", bad_s, "--out", dir.0.join("e.gif").to_str().unwrap()], &[bad_s]);
    // Unknown pretrained names list the shipped ones.
    fails_with(&["eval", "--policy", "pretrained:team_reach/9_ants/shnn"], &["team_reach/9_ants/shnn", "shipped:"]);
    fails_with(&["eval"], &["--run", "--policy"]);
    fails_with(&["eval", "--run", "x", "--policy", "y"], &["--run", "--policy"]);
}
