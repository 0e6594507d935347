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
    let tensors = common::tensors_files(&run).remove(0);
    refused(&std::fs::read(tensors).unwrap(), "meben export-policy");
    let missing = dir.0.join("missing.safetensors");
    fails_with(&["eval", "--policy", missing.to_str().unwrap()], &["missing.safetensors", "cannot read"]);
    fails_with(&["render", "--policy", bad_s, "--out", dir.0.join("e.gif").to_str().unwrap()], &[bad_s]);
    // Unknown pretrained names list the shipped ones.
    fails_with(&["eval", "--policy", "pretrained:team_reach/9_ants/shnn"], &["team_reach/9_ants/shnn", "shipped:"]);
    fails_with(&["eval"], &["--run", "--policy"]);
    fails_with(&["eval", "--run", "x", "--policy", "y"], &["--run", "--policy"]);
}

/// The committed version 1 policy of `team_reach/1_ant` (issue 77: the files `policies/`
/// ships stay loadable).
fn committed_v1() -> Vec<u8> {
    std::fs::read(policy_file::policies_dir().join("team_reach_1_ant-shnn.safetensors")).unwrap()
}

/// `bytes` with its header JSON changed by `edit`, padded with spaces to a multiple of 8
/// bytes as the writer pads.
fn with_header(bytes: &[u8], edit: impl FnOnce(&mut serde_json::Map<String, serde_json::Value>)) -> Vec<u8> {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let mut header: serde_json::Map<String, serde_json::Value> = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    edit(&mut header);
    let mut head = serde_json::to_vec(&header).unwrap();
    head.resize(head.len().next_multiple_of(8), b' ');
    let mut out = (head.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&head);
    out.extend_from_slice(&bytes[8 + n..]);
    out
}

/// Two tensors of `bytes` of the same dtype and shape (their names).
fn twins(bytes: &[u8]) -> (String, String) {
    let (file, _) = tensor_file::read(bytes).unwrap();
    let entries = tensor_file::entries_of(&file);
    // Two of different values where there are (an untrained model's biases are all zero).
    for differ in [true, false] {
        for (i, a) in entries.iter().enumerate() {
            let twin =
                |b: &&tensor_file::Entry| b.shape == a.shape && b.dtype == a.dtype && (b.data != a.data || !differ);
            if let Some(b) = entries[i + 1..].iter().find(twin) {
                return (a.name.clone(), b.name.clone());
            }
        }
    }
    panic!("no two tensors of one shape");
}

/// The digest of `meta` and the data section of `bytes` as version 1 computed it (what
/// anyone can recompute: the format is documented).
fn digest_v1(meta: &std::collections::BTreeMap<String, String>, bytes: &[u8]) -> String {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let mut all = Vec::new();
    for (k, v) in meta.iter().filter(|(k, _)| k.as_str() != keys::SHA256) {
        all.extend_from_slice(k.as_bytes());
        all.push(0);
        all.extend_from_slice(v.as_bytes());
        all.push(0);
    }
    all.extend_from_slice(&bytes[8 + n..]);
    rl::mappo::checksum::sha256_hex(&all)
}

/// Issue 77 item 4: swapping the data offsets of two tensors of one shape (the digest of
/// version 1 did not cover the header) is refused, in the committed version 1 files and in
/// version 2 ones, naming the file; an untouched file of either version loads.
#[test]
fn swapped_tensor_offsets_are_refused_in_both_versions() {
    let dir = common::TempDir::new("policy-header");
    let file = dir.0.join("p.safetensors");
    let file_s = file.to_str().unwrap();
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 1, &[]);
    let spec = envs::tasks::Scene::from_name(&config.env).unwrap().obs_spec;
    let teams: Vec<rl::Team> = (0..spec.n_teams).map(|k| rl::Team::build(&config, &spec, k).unwrap()).collect();
    let v2 = policy_file::policy_bytes(&config, &teams, 0, 0, &[]).unwrap();
    let v1 = committed_v1();
    for (version, good) in [("1", &v1), ("2", &v2)] {
        std::fs::write(&file, good).unwrap();
        let loaded = policy_file::load_policy(&file).unwrap();
        assert_eq!(loaded.metadata[keys::FORMAT_VERSION], version);
        let (a, b) = twins(good);
        let swapped = with_header(good, |h| {
            let oa = h[&a]["data_offsets"].clone();
            let ob = std::mem::replace(h.get_mut(&b).unwrap().get_mut("data_offsets").unwrap(), oa);
            *h.get_mut(&a).unwrap().get_mut("data_offsets").unwrap() = ob;
        });
        assert_eq!(swapped.len(), good.len());
        std::fs::write(&file, &swapped).unwrap();
        let e = policy_file::load_policy(&file).unwrap_err().to_string();
        assert!(e.contains(file_s) && e.contains("its header is not the layout"), "version {version}: {e}");
        fails_with(&["eval", "--policy", file_s, "--episodes", "1"], &[file_s, "header"]);
    }
}

/// Issue 77 item 5: a file whose metadata says another environment and model than its
/// configuration (its digest recomputed, as anyone can) is refused naming the file, the field
/// and both values.
#[test]
fn metadata_that_contradicts_the_configuration_is_refused() {
    let dir = common::TempDir::new("policy-disagree");
    let file = dir.0.join("p.safetensors");
    let file_s = file.to_str().unwrap();
    let good = committed_v1();
    let (parsed, mut meta) = tensor_file::read(&good).unwrap();
    let entries = tensor_file::entries_of(&parsed);
    meta.insert(keys::ENV.into(), "team_reach/2_ants".into());
    meta.insert(keys::MODEL.into(), "mlp".into());
    meta.remove(keys::SHA256);
    let unsigned = tensor_file::serialize(entries.clone(), &meta).unwrap();
    meta.insert(keys::SHA256.into(), digest_v1(&meta, &unsigned));
    std::fs::write(&file, tensor_file::serialize(entries, &meta).unwrap()).unwrap();
    let needles = [file_s, "its parts disagree", "`env` = \"team_reach/2_ants\"", "env = \"team_reach/1_ant\""];
    let e = policy_file::load_policy(&file).unwrap_err().to_string();
    assert!(needles.iter().all(|n| e.contains(n)), "{e}");
    fails_with(&["eval", "--policy", file_s, "--episodes", "1"], &needles);
}

/// Issue 77 item 6: a manifest entry (`MEBEN_POLICIES`) naming the file of another
/// environment, or a file whose SHA-256 is not the recorded one, is refused naming the file,
/// the manifest, the field and both values.
#[test]
fn a_manifest_entry_must_match_its_files_digest_environment_and_model() {
    let dir = common::TempDir::new("policy-manifest");
    let shipped = policy_file::policies_dir();
    let m = policy_file::Manifest::load(&shipped).unwrap();
    let one = m.policy.iter().find(|p| p.name() == "team_reach/1_ant/shnn").unwrap();
    let two = m.policy.iter().find(|p| p.name() == "team_reach/2_ants/shnn").unwrap();
    std::fs::copy(shipped.join(&two.file), dir.0.join(&two.file)).unwrap();
    // The 1_ant entry names the 2_ants file, with that file's true digest.
    let entry = policy_file::ShippedPolicy { file: two.file.clone(), sha256: two.sha256.clone(), ..one.clone() };
    let write = |entry: &policy_file::ShippedPolicy| {
        let text = toml::to_string(&policy_file::Manifest { policy: vec![entry.clone()] }).unwrap();
        std::fs::write(dir.0.join(policy_file::MANIFEST), text).unwrap();
    };
    write(&entry);
    let e = policy_file::find_pretrained(&dir.0, "team_reach/1_ant/shnn").unwrap_err().to_string();
    assert!(e.contains(&two.file) && e.contains("index.toml"), "{e}");
    assert!(e.contains("env = \"team_reach/2_ants\"") && e.contains("env = \"team_reach/1_ant\""), "{e}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_meben"))
        .args(["eval", "--policy", "pretrained:team_reach/1_ant/shnn", "--episodes", "1"])
        .env("MEBEN_POLICIES", &dir.0)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && !stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains(&two.file) && stderr.contains("team_reach/2_ants"), "{stderr}");
    // The right entry with another digest.
    write(&policy_file::ShippedPolicy { sha256: "0".repeat(64), ..two.clone() });
    let e = policy_file::find_pretrained(&dir.0, "team_reach/2_ants/shnn").unwrap_err().to_string();
    assert!(e.contains(&two.sha256) && e.contains(&"0".repeat(64)) && e.contains("sha256"), "{e}");
    write(two);
    policy_file::find_pretrained(&dir.0, "team_reach/2_ants/shnn").unwrap();
}

/// Issue 77 item 7: a policy file of a run on a morphology file carries the file, so it
/// evaluates the bodies it was trained on after the run moved and whatever became of the
/// run's copy; `eval --run` of the moved run refuses the edited copy.
#[test]
fn a_policy_file_carries_its_morphology_files() {
    let dir = common::TempDir::new("policy-morphology");
    let body = dir.0.join("body.xml");
    let ant = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../envs/tests/data/ant.xml")).unwrap();
    std::fs::write(&body, &ant).unwrap();
    let env = format!("team_reach:agents={}+ant;R=3", body.display());
    let config = common::tiny(&env, "mlp_hn", 1, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let file = dir.0.join("p.safetensors");
    let file_s = file.to_str().unwrap();
    policy_file::export_policy(&run, &file).unwrap();
    let eval = |args: &[&str]| {
        let mut v = vec!["eval", "--episodes", "2", "--seed", "3"];
        v.extend_from_slice(args);
        meben(&v)
    };
    let (ok, before, stderr) = eval(&["--policy", file_s]);
    assert!(ok, "{stderr}");
    // Move the run, delete the original file, weaken the run's copy.
    let moved = dir.0.join("moved");
    std::fs::rename(run.root(), &moved).unwrap();
    std::fs::remove_file(&body).unwrap();
    std::fs::write(moved.join("morphologies/0_body.xml"), ant.replace("gear=\"350\"", "gear=\"30\"")).unwrap();
    let (ok, after, stderr) = eval(&["--policy", file_s]);
    assert!(ok, "{stderr}");
    assert_eq!(after, before);
    let loaded = policy_file::load_policy(&file).unwrap();
    let carried = loaded.config.env.split('=').nth(1).unwrap().split('+').next().unwrap().to_string();
    assert_eq!(std::fs::read_to_string(&carried).unwrap(), ant, "{carried}");
    fails_with(&["eval", "--run", moved.to_str().unwrap(), "--episodes", "1"], &["0_body.xml", "changed"]);
    // A version 1 file (no `morphologies`; its digest as version 1 computed it) of the run is
    // checked against the run's record: the weakened copy is refused, the restored one loads.
    std::fs::rename(&moved, run.root()).unwrap();
    let v2 = std::fs::read(&file).unwrap();
    let (parsed, mut meta) = tensor_file::read(&v2).unwrap();
    let entries = tensor_file::entries_of(&parsed);
    meta.remove(keys::MORPHOLOGIES);
    meta.remove(keys::SHA256);
    meta.insert(keys::FORMAT_VERSION.into(), "1".into());
    let unsigned = tensor_file::serialize(entries.clone(), &meta).unwrap();
    meta.insert(keys::SHA256.into(), digest_v1(&meta, &unsigned));
    let v1 = dir.0.join("v1.safetensors");
    std::fs::write(&v1, tensor_file::serialize(entries, &meta).unwrap()).unwrap();
    let v1_s = v1.to_str().unwrap();
    fails_with(&["eval", "--policy", v1_s, "--episodes", "1"], &[v1_s, "0_body.xml", "changed since the run"]);
    std::fs::write(run.root().join("morphologies/0_body.xml"), &ant).unwrap();
    let (ok, again, stderr) = eval(&["--policy", v1_s]);
    assert!(ok, "{stderr}");
    assert_eq!(again, before);
}

/// Issue 77 item 8: a policy file that is a device, FIFO or directory is refused before it
/// is read (`/dev/zero` used to be read until memory ran out), naming it.
#[test]
fn a_policy_file_that_is_not_a_regular_file_is_refused_unread() {
    let e = policy_file::load_policy(Path::new("/dev/zero")).unwrap_err().to_string();
    assert!(e.contains("/dev/zero") && e.contains("not a regular file"), "{e}");
    fails_with(&["eval", "--policy", "/dev/zero", "--episodes", "1"], &["/dev/zero", "not a regular file"]);
    let e = rl::app::paper::PaperFigures::load(Path::new("/dev/zero")).unwrap_err().to_string();
    assert!(e.contains("/dev/zero") && e.contains("not a regular file"), "{e}");
}

/// Issue 77 (smaller): a normaliser with a negative sum of squares (its digest recomputed as
/// version 2 computes it) is refused naming the file and the field.
#[test]
fn a_normaliser_with_negative_sums_of_squares_is_refused() {
    let dir = common::TempDir::new("policy-negative");
    let file = dir.0.join("p.safetensors");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 1, &[]);
    let spec = envs::tasks::Scene::from_name(&config.env).unwrap().obs_spec;
    let teams: Vec<rl::Team> = (0..spec.n_teams).map(|k| rl::Team::build(&config, &spec, k).unwrap()).collect();
    let good = policy_file::policy_bytes(&config, &teams, 0, 0, &[]).unwrap();
    let (parsed, mut meta) = tensor_file::read(&good).unwrap();
    let entries = tensor_file::entries_of(&parsed);
    let mut norms: serde_json::Value = serde_json::from_str(&meta[keys::NORMALIZERS]).unwrap();
    let m2 = &mut norms[0]["scalars"]["m2"];
    m2[0] = serde_json::json!(-4.0);
    meta.insert(keys::NORMALIZERS.into(), norms.to_string());
    meta.remove(keys::SHA256);
    let mut all = Vec::new();
    for (k, v) in &meta {
        all.extend_from_slice(k.as_bytes());
        all.push(0);
        all.extend_from_slice(v.as_bytes());
        all.push(0);
    }
    all.extend_from_slice(&tensor_file::serialize(entries.clone(), &Default::default()).unwrap());
    meta.insert(keys::SHA256.into(), rl::mappo::checksum::sha256_hex(&all));
    std::fs::write(&file, tensor_file::serialize(entries, &meta).unwrap()).unwrap();
    let e = policy_file::load_policy(&file).unwrap_err().to_string();
    assert!(e.contains(file.to_str().unwrap()) && e.contains("negative") && e.contains("scalars"), "{e}");
}
