//! The checkpoint format of version 3 (`rl::mappo::checkpoint`): a sealed `checkpoint.json`
//! and the `checkpoint.<digest>.safetensors` it names. A round trip keeps every bit; a crash
//! between the two files' writes (the `MEBEN_TEST_CRASH` hook aborts the `meben` program
//! there, as kill -9 would) leaves a pair that loads and resumes to the rows of an
//! uninterrupted run; checkpoints of the single-JSON versions 1 and 2 resume to the same
//! rows; a damaged, truncated, missing or foreign tensors file is refused, naming it.

use crate::common;

use std::path::Path;
use std::process::Command;

use common::{metrics, tensors_files};
use rl::mappo::checkpoint::{CRASH_ENV, Checkpoint, TensorsRef};
use rl::mappo::checksum::{Unsealed, seal, unseal};
use rl::mappo::tensor_file::{self, Dtype, Entry};
use rl::{RunDir, TrainOptions, train};

/// The JSON payload of a sealed checkpoint.
fn payload(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap();
    let Unsealed::Checked(p) = unseal(&bytes).unwrap() else { panic!("{} is not sealed", path.display()) };
    serde_json::from_str(p).unwrap()
}

/// Every parameter and Adam moment of a checkpoint as bits.
fn bits(c: &Checkpoint) -> Vec<Vec<u64>> {
    let mut out = Vec::new();
    for t in &c.teams {
        out.extend(t.params.tensors.iter().map(|p| p.data.iter().map(|x| x.to_bits()).collect()));
        let (m, v) = t.adam.moments();
        out.extend(m.iter().chain(v).map(|b| b.iter().map(|x| x.to_bits()).collect()));
    }
    out
}

#[test]
fn a_checkpoint_round_trips_through_the_pair_bit_for_bit() {
    let dir = common::TempDir::new("ckpt-format-roundtrip");
    let config = common::tiny("team_sumo/2_ants", "shnn", 2, &[("opponent", "mlp_hn")]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    let files = tensors_files(&run);
    assert_eq!(files.len(), 1, "{files:?}");
    let c = Checkpoint::load(&run.checkpoint()).unwrap();
    assert_eq!(c.version, rl::mappo::checkpoint::VERSION);

    // The tensors file: every parameter (F32: the models are f32) and both Adam moments
    // (F64 where they are not f32 values), under their names, readable by the crate.
    let bytes = std::fs::read(&files[0]).unwrap();
    let (file, meta) = tensor_file::read(&bytes).unwrap();
    assert!(meta["format"].contains("checkpoint"), "{meta:?}");
    let mut f64_moments = 0;
    for t in &c.teams {
        for p in &t.params.tensors {
            assert_eq!(file.tensor(&p.name).unwrap().dtype(), Dtype::F32, "{}", p.name);
            for m in [format!("adam.m.{}", p.name), format!("adam.v.{}", p.name)] {
                f64_moments += usize::from(file.tensor(&m).unwrap().dtype() == Dtype::F64);
            }
        }
    }
    assert!(f64_moments > 0, "Adam's moments are f64 values");
    let n_params: usize = c.teams.iter().map(|t| t.params.tensors.len()).sum();
    assert_eq!(file.len(), 3 * n_params);
    // The JSON names the file, its size and digest, and holds no tensor.
    let json = payload(&run.checkpoint());
    let r: TensorsRef = serde_json::from_value(json["tensors"].clone()).unwrap();
    assert_eq!(run.root().join(&r.file), files[0]);
    assert_eq!((r.bytes, r.sha256.as_str()), (bytes.len() as u64, rl::mappo::checksum::sha256_hex(&bytes).as_str()));
    assert!(std::fs::metadata(run.checkpoint()).unwrap().len() < bytes.len() as u64 / 4);

    // Saved elsewhere and loaded again: the same state, every bit; saved again: the same
    // bytes in both files.
    let copy = dir.0.join("copy").join("checkpoint.json");
    std::fs::create_dir_all(copy.parent().unwrap()).unwrap();
    c.save(&copy).unwrap();
    let back = Checkpoint::load(&copy).unwrap();
    assert_eq!(bits(&back), bits(&c));
    assert_eq!(serde_json::to_string(&back).unwrap(), serde_json::to_string(&c).unwrap());
    assert_eq!(std::fs::read(&copy).unwrap(), std::fs::read(run.checkpoint()).unwrap());
    let copy_run = RunDir::new(copy.parent().unwrap());
    assert_eq!(tensors_files(&copy_run).len(), 1);
    assert_eq!(std::fs::read(&tensors_files(&copy_run)[0]).unwrap(), bytes);
    // Saving a changed state replaces the pair: one tensors file, the new one.
    let mut changed = back.clone();
    changed.teams[0].params.tensors[0].data[0] += 1.0;
    changed.save(&copy).unwrap();
    let now = tensors_files(&copy_run);
    assert_eq!(now.len(), 1);
    assert_ne!(std::fs::read(&now[0]).unwrap(), bytes);
    assert_eq!(bits(&Checkpoint::load(&copy).unwrap()), bits(&changed));
}

fn meben(args: &[String], crash: Option<&str>) -> std::process::Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_meben"));
    cmd.args(args).env_remove(CRASH_ENV);
    if let Some(c) = crash {
        cmd.env(CRASH_ENV, c);
    }
    cmd.output().unwrap()
}

/// `meben train` of 4 tiny iterations, a checkpoint after each, into `out`.
fn train_args(out: &Path) -> Vec<String> {
    let args = [
        "train",
        "--model",
        "mlp_hn",
        "--num-envs",
        "8",
        "--steps",
        "160",
        "--set",
        "batch_size=4",
        "--set",
        "num_minibatches=2",
        "--set",
        "epochs=1",
        "--set",
        "num_evals=2",
        "--set",
        "eval_episodes=2",
        "--set",
        "checkpoint_every=1",
        "--quiet",
        "--out",
    ];
    let mut v: Vec<String> = args.iter().map(|s| s.to_string()).collect();
    v.push(out.to_str().unwrap().to_string());
    v
}

/// A kill between the two files' writes, at either side of the JSON's rename: the pair on
/// disk is the old one or the new one and loads; the run resumes to the rows of an
/// uninterrupted run; the tensors file the crash left over is removed on resume.
#[test]
fn a_crash_between_the_two_files_leaves_a_loadable_pair() {
    let dir = common::TempDir::new("ckpt-format-crash");
    let whole = RunDir::new(dir.0.join("whole"));
    let out = meben(&train_args(whole.root()), None);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let iterations = metrics(&whole).len();
    assert!(iterations >= 3, "{iterations} iterations");
    for (point, loads_iteration) in [("checkpoint_after_tensors", 1), ("checkpoint_after_json", 2)] {
        let run = RunDir::new(dir.0.join(point));
        let out = meben(&train_args(run.root()), Some(&format!("{point}:2")));
        assert!(!out.status.success(), "{point}: the hook did not stop the program");
        assert!(!run.done().exists());
        // Two tensors files: the old pair's and the new one.
        assert_eq!(tensors_files(&run).len(), 2, "{point}");
        let c = Checkpoint::load(&run.checkpoint()).unwrap_or_else(|e| panic!("{point}: {e}"));
        assert_eq!(c.iteration, loads_iteration, "{point}");
        let out = meben(&train_args(run.root()), None);
        assert!(out.status.success(), "{point}: {}", String::from_utf8_lossy(&out.stderr));
        assert_eq!(metrics(&run), metrics(&whole), "{point}: the resumed run's rows differ");
        assert_eq!(
            bits(&Checkpoint::load(&run.checkpoint()).unwrap()),
            bits(&Checkpoint::load(&whole.checkpoint()).unwrap())
        );
        assert_eq!(tensors_files(&run).len(), 1, "{point}: the left-over tensors file stayed");
    }
}

/// Checkpoints as versions 1 and 2 wrote them (one JSON file, tensors included) resume to
/// the rows and parameters of an uninterrupted run, and the next checkpoint is a pair.
#[test]
fn single_json_checkpoints_of_versions_1_and_2_resume_to_the_same_rows() {
    let dir = common::TempDir::new("ckpt-format-old");
    let config = common::tiny("team_reach/1_ant", "shnn", 3, &[]);
    let whole = RunDir::new(dir.0.join("whole"));
    train(&config, &whole, &TrainOptions::default()).unwrap();

    let run = RunDir::new(dir.0.join("old"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    // Rewritten as version 2 by the old writer; the pair's tensors file goes.
    let c = Checkpoint::load(&run.checkpoint()).unwrap();
    for f in tensors_files(&run) {
        std::fs::remove_file(f).unwrap();
    }
    c.save_json(&run.checkpoint()).unwrap();
    assert_eq!(payload(&run.checkpoint())["version"], 2);
    assert_eq!(bits(&Checkpoint::load(&run.checkpoint()).unwrap()), bits(&c));
    train(&config, &run, &TrainOptions { stop_after: Some(2), ..Default::default() }).unwrap();
    assert_eq!(payload(&run.checkpoint())["version"], 3);
    assert_eq!(tensors_files(&run).len(), 1);

    // Version 1: the unsealed payload, written before checksums.
    let c = Checkpoint::load(&run.checkpoint()).unwrap();
    c.save_json(&run.checkpoint()).unwrap();
    let bytes = std::fs::read(run.checkpoint()).unwrap();
    let Unsealed::Checked(p) = unseal(&bytes).unwrap() else { panic!("unsealed") };
    let v1 = p.replacen("{\"version\":2,", "{\"version\":1,", 1);
    std::fs::write(run.checkpoint(), v1).unwrap();
    assert_eq!(Checkpoint::load(&run.checkpoint()).unwrap().version, 1);
    train(&config, &run, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&run), metrics(&whole));
    assert_eq!(
        bits(&Checkpoint::load(&run.checkpoint()).unwrap()),
        bits(&Checkpoint::load(&whole.checkpoint()).unwrap())
    );
    assert_eq!(tensors_files(&run).len(), 1, "the tensors file the pair replaced stayed");
}

/// The tensors file's checks: its name, presence, size, digest and contents; each refusal
/// names the file, in training and in evaluation, and `meben eval` exits non-zero.
#[test]
fn damaged_missing_or_foreign_tensors_files_are_refused_naming_them() {
    let dir = common::TempDir::new("ckpt-format-damaged");
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    let json = std::fs::read(run.checkpoint()).unwrap();
    let tensors = tensors_files(&run).remove(0);
    let good = std::fs::read(&tensors).unwrap();
    let name = tensors.file_name().unwrap().to_str().unwrap().to_string();
    let refused = |needles: &[&str]| {
        let e = train(&config, &run, &TrainOptions::default()).unwrap_err().to_string();
        for n in needles {
            assert!(e.contains(n), "{n:?} not in: {e}");
        }
        let e = rl::app::run_dir::load_policies(&run).unwrap_err().to_string();
        assert!(e.contains("checkpoint.json") && e.contains(needles[0]), "{e}");
    };
    // One flipped byte in the data.
    let mut flipped = good.clone();
    let last = flipped.len() - 3;
    flipped[last] ^= 0x40;
    std::fs::write(&tensors, &flipped).unwrap();
    refused(&[&name, "checksum mismatch"]);
    // Truncated.
    std::fs::write(&tensors, &good[..good.len() / 2]).unwrap();
    refused(&[&name, "bytes, the checkpoint recorded"]);
    let out = meben(&["eval".into(), "--run".into(), run.root().to_str().unwrap().into()], None);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains(&name) && !stderr.contains("panicked"), "{stderr}");
    // Missing.
    std::fs::remove_file(&tensors).unwrap();
    refused(&[&name, "is missing"]);
    std::fs::write(&tensors, &good).unwrap();

    // A JSON, sealed anew, that names a file outside the run, or a tensors file whose
    // contents do not fit (a moment one element short, rewritten with its digest).
    let Unsealed::Checked(p) = unseal(&json).unwrap() else { panic!("unsealed") };
    let mut v: serde_json::Value = serde_json::from_str(p).unwrap();
    let mut foreign = v.clone();
    foreign["tensors"]["file"] = "../checkpoint.0123456789abcdef.safetensors".into();
    std::fs::write(run.checkpoint(), seal(foreign.to_string().as_bytes())).unwrap();
    refused(&["not a checkpoint tensors file name"]);
    let (file, meta) = tensor_file::read(&good).unwrap();
    let short = format!("adam.v.{}", v["teams"][0]["params"][1].as_str().unwrap());
    let entries: Vec<Entry> = file
        .names()
        .into_iter()
        .map(|n| {
            let (shape, data) = tensor_file::f64_values(&file, n).unwrap();
            if n == short { Entry::f64(n, &[data.len() - 1], &data[1..]) } else { Entry::exact(n, &shape, &data) }
        })
        .collect();
    let bytes = tensor_file::serialize(entries, &meta).unwrap();
    let digest = rl::mappo::checksum::sha256_hex(&bytes);
    let other = format!("checkpoint.{}.safetensors", &digest[..16]);
    std::fs::write(run.root().join(&other), &bytes).unwrap();
    v["tensors"] = serde_json::json!({ "file": other, "bytes": bytes.len(), "sha256": digest });
    std::fs::write(run.checkpoint(), seal(v.to_string().as_bytes())).unwrap();
    refused(&[&short, "shape"]);

    // The good pair resumes (the other tensors file, named by no JSON, is removed). The
    // failed resumes removed nothing (issue 77 item 2: they used to remove the good tensors
    // file as stale while the JSON named the other one).
    assert_eq!(std::fs::read(&tensors).unwrap(), good, "a failed resume removed the good tensors file");
    assert!(run.root().join(&other).is_file(), "a failed resume removed a tensors file");
    std::fs::write(run.checkpoint(), &json).unwrap();
    std::fs::write(&tensors, &good).unwrap();
    assert_eq!(train(&config, &run, &TrainOptions::default()).unwrap().iterations, 2);
    assert_eq!(tensors_files(&run).len(), 1);
}
