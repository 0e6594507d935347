//! The `meben` program end to end on a tiny budget: train -> eval -> status -> report -> render produce
//! their files; bad configurations, names and files give clear errors and a non-zero exit.

use crate::common;

use std::path::Path;
use std::process::Command;

use common::meben;

const TINY: &[&str] = &[
    "--set",
    "batch_size=4",
    "--set",
    "num_minibatches=4",
    "--set",
    "epochs=1",
    "--set",
    "num_evals=2",
    "--set",
    "eval_episodes=2",
    "--num-envs",
    "8",
    "--steps",
    "160",
    "--quiet",
];

#[test]
fn train_eval_report_render_produce_their_files() {
    let tmp = common::TempDir::new("cli");
    let dir = tmp.0.clone();
    let root = dir.join("sweep");
    let run = root.join("run0");
    let run_s = run.to_str().unwrap();
    let mut args = vec!["train", "--model", "mlp_hn", "--out", run_s];
    args.extend_from_slice(TINY);
    let (ok, stdout, stderr) = meben(&args);
    assert!(ok, "train failed: {stderr}");
    assert!(stdout.contains("success_rate"), "{stdout}");
    for f in ["config.toml", "metrics.csv", "checkpoint.json", "curve.svg", "done.json"] {
        assert!(run.join(f).is_file(), "{f} missing");
    }
    let svg = std::fs::read_to_string(run.join("curve.svg")).unwrap();
    assert!(svg.starts_with("<svg") || svg.starts_with("<?xml"), "{}", &svg[..50.min(svg.len())]);

    let (ok, stdout, stderr) = meben(&["eval", "--run", run_s, "--episodes", "3", "--rotate", "180"]);
    assert!(ok, "eval failed: {stderr}");
    assert!(stdout.contains("episodes 3"), "{stdout}");
    assert!(run.join("eval_rotate180.json").is_file());
    // A rotated and translated scene, with sampled actions; the summary says so.
    let (ok, stdout, stderr) =
        meben(&["eval", "--run", run_s, "--episodes", "2", "--rotate", "-90", "--translate", "2.5,-1", "--stochastic"]);
    assert!(ok, "eval failed: {stderr}");
    assert!(stdout.contains("actions sampled"), "{stdout}");
    let json = std::fs::read_to_string(run.join("eval_rotate-90_translate2.5_-1.json")).unwrap();
    let e: rl::EvalSummary = serde_json::from_str(&json).unwrap();
    assert_eq!((e.rotation_deg, e.translation, e.sampled), (-90.0, [2.5, -1.0], true));
    // The quick preset evaluates with the mean action unless told otherwise.
    let (ok, stdout, _) = meben(&["eval", "--run", run_s, "--episodes", "1", "--translate", "0,3"]);
    assert!(ok && stdout.contains("actions mean"), "{stdout}");
    assert!(run.join("eval_translate0_3.json").is_file());

    let (ok, stdout, stderr) = meben(&["status", root.to_str().unwrap()]);
    assert!(ok, "status failed: {stderr}");
    let line = stdout.lines().find(|l| l.starts_with("run0 ")).unwrap_or_else(|| panic!("{stdout}"));
    assert!(line.contains("finished") && line.contains("success"), "{stdout}");
    assert!(stdout.contains("1 run, 1 finished"), "{stdout}");

    let (ok, stdout, stderr) = meben(&["report", root.to_str().unwrap()]);
    assert!(ok, "report failed: {stderr}");
    assert!(stdout.contains("mlp_hn"), "{stdout}");
    assert!(root.join("report.md").is_file() && root.join("report.csv").is_file());

    let html = dir.join("episode.html");
    let (ok, _, stderr) = meben(&["render", "--run", run_s, "--out", html.to_str().unwrap(), "--steps", "20"]);
    assert!(ok, "render failed: {stderr}");
    assert!(std::fs::read_to_string(&html).unwrap().contains("<canvas"));
    let gif = dir.join("episode.gif");
    let (ok, _, stderr) = meben(&["render", "--run", run_s, "--out", gif.to_str().unwrap(), "--steps", "10"]);
    assert!(ok, "render gif failed: {stderr}");
    assert!(std::fs::read(&gif).unwrap().starts_with(b"GIF89a"));
    let (ok, _, stderr) = meben(&["render", "--run", run_s, "--out", dir.join("e.mp4").to_str().unwrap()]);
    assert!(!ok && stderr.contains("e.mp4"), "{stderr}");
    // Issue 44 item 8: the run's own files are refused as the output, and left as they were.
    let metrics = std::fs::read(run.join("metrics.csv")).unwrap();
    for name in ["metrics.csv", "builds.csv", "config.toml"] {
        let out = run.join(name);
        fails_with(&["render", "--run", run_s, "--out", out.to_str().unwrap()], &[name, "--out", "own"]);
    }
    assert_eq!(std::fs::read(run.join("metrics.csv")).unwrap(), metrics);
}

fn fails_with(args: &[&str], needles: &[&str]) {
    let (ok, _, stderr) = meben(args);
    assert!(!ok, "{args:?} should fail");
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "{args:?}: {n:?} not in {stderr}");
    }
}

#[test]
fn bad_input_gives_clear_errors() {
    let tmp = common::TempDir::new("cli-bad");
    let dir = tmp.0.clone();
    let out = dir.join("r");
    let out_s = out.to_str().unwrap();
    fails_with(
        &["train", "--env", "team_reach/9_ants", "--out", out_s],
        &["env", "team_reach/9_ants", "known environments"],
    );
    fails_with(&["train", "--model", "resnet", "--out", out_s], &["model", "resnet", "shnn"]);
    fails_with(&["train", "--num-envs", "0", "--out", out_s], &["num_envs", "0"]);
    fails_with(&["train", "--set", "discount=2", "--out", out_s], &["discount", "2"]);
    fails_with(&["train", "--set", "colour=red", "--out", out_s], &["colour", "unknown field"]);
    fails_with(&["train", "--set", "nonsense", "--out", out_s], &["FIELD=VALUE"]);
    fails_with(&["train", "--preset", "fast", "--out", out_s], &["preset", "fast"]);
    fails_with(&["train", "--opponent", "mlp", "--out", out_s], &["opponent", "Team Sumo"]);
    fails_with(&["train", "--device", "tpu", "--out", out_s], &["device", "tpu", "\"cpu\" or \"gpu\""]);
    if cfg!(not(feature = "gpu")) {
        fails_with(&["train", "--device", "gpu", "--out", out_s], &["device", "rebuild with --features gpu"]);
    }
    let bad = dir.join("bad.toml");
    for (text, needles) in [
        ("num_envs = \"many\"\n", vec!["bad.toml", "num_envs"]),
        ("num_envs = 8\nnum_envs = 9\n", vec!["bad.toml", "invalid TOML"]),
        ("learning_rate = -1.0\n", vec!["bad.toml", "learning_rate"]),
    ] {
        std::fs::write(&bad, text).unwrap();
        let mut args = vec!["train", "--config", bad.to_str().unwrap(), "--out", out_s];
        args.push("--quiet");
        fails_with(&args, &needles);
    }
    fails_with(&["train", "--config", "/no/such/file.toml"], &["/no/such/file.toml", "cannot read"]);
    // Issue 44 item 10: a thread count beyond 4 per core (and 64) is refused, naming the cores.
    fails_with(&["train", "--threads", "100000", "--out", out_s, "--quiet"], &["threads", "100000", "cores"]);
    // Issue 44 item 12: an integer beyond TOML's names the bound; a file without end is refused.
    fails_with(
        &["train", "--seed", "9223372036854775808", "--out", out_s],
        &["seed", "9223372036854775808", "at most 9223372036854775807"],
    );
    if cfg!(target_os = "linux") {
        fails_with(&["train", "--config", "/dev/zero", "--out", out_s], &["/dev/zero", "not a regular file"]);
    }
    fails_with(&["eval", "--run", dir.join("nothing").to_str().unwrap()], &["config.toml", "not a run directory"]);
    fails_with(&["report", dir.join("nothing").to_str().unwrap()], &["nothing"]);
    fails_with(&["status", dir.join("nothing").to_str().unwrap()], &["nothing", "not a directory"]);
    let nowhere = dir.join("nothing");
    let nowhere = nowhere.to_str().unwrap();
    for bad in ["1,x", "1", "1,2,3", "inf,0", "NaN,1"] {
        fails_with(&["eval", "--run", nowhere, "--translate", bad], &["--translate", bad]);
    }
    fails_with(&["eval", "--run", nowhere, "--stochastic", "--mean"], &["--stochastic", "--mean"]);
    fails_with(&["eval", "--run", nowhere, "--device", "tpu"], &["--device", "tpu", "\"cpu\" or \"gpu\""]);
    if !cfg!(feature = "gpu") {
        fails_with(&["eval", "--run", nowhere, "--device", "gpu"], &["device", "rebuild with --features gpu"]);
    }
    fails_with(&["train", "--set", "eval_rotations=[90.0]", "--out", out_s], &["eval_rotations", "first rotation"]);
    assert!(!Path::new(out_s).join("checkpoint.json").exists());
}

#[test]
fn info_prints_each_teams_parameter_counts_and_rejects_bad_names() {
    let (ok, stdout, stderr) = meben(&["info", "--env", "team_sumo/2_ants", "--model", "shnn", "--opponent", "mlp_hn"]);
    assert!(ok, "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    assert!(lines[0].starts_with("shnn policy_params=") && lines[0].contains(" critic_params="), "{stdout}");
    assert!(lines[1].starts_with("mlp_hn policy_params=") && lines[1].ends_with(" team=1"), "{stdout}");
    let (ok, _, stderr) = meben(&["info", "--env", "team_reach/1_ant", "--model", "shnn:critic=huge"]);
    assert!(!ok && stderr.contains("model") && stderr.contains("critic"), "{stderr}");
}

/// A reader that stops reading (`meben status | head`) is no error: the command ends
/// quietly, its work done, where it used to panic ("failed printing to stdout").
#[test]
fn a_closed_standard_output_ends_the_report_quietly() {
    let results = concat!(env!("CARGO_MANIFEST_DIR"), "/../results/learned_assignment");
    let commands: [&[&str]; 2] = [&["info", "--env", "team_sumo/2_ants", "--model", "shnn"], &["status", results]];
    for args in commands {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_meben")).args(args).stdout(writer).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {:?} {stderr}", out.status);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

#[test]
fn a_second_training_of_a_run_directory_is_refused_naming_the_first() {
    let dir = common::TempDir::new("cli-lock");
    let out = dir.0.join("run");
    let out_s = out.to_str().unwrap();
    let mut args = vec!["train", "--model", "mlp_hn", "--out", out_s, "--steps", "40000"];
    args.extend_from_slice(&TINY[..TINY.len() - 3]);
    args.push("--quiet");
    let mut first = Command::new(env!("CARGO_BIN_EXE_meben"))
        .args(&args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lock = out.join("lock");
    let t0 = std::time::Instant::now();
    while !std::fs::read_to_string(&lock).is_ok_and(|s| s.contains("process")) {
        assert!(t0.elapsed().as_secs() < 60, "the first training never took the lock");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let (ok, _, stderr) = meben(&args);
    let still_running = first.try_wait().unwrap().is_none();
    first.kill().unwrap();
    first.wait().unwrap();
    assert!(still_running, "the first training ended before the second started");
    assert!(!ok, "the second training of one directory succeeded");
    assert!(stderr.contains(&format!("in use by process {} on host", first.id())), "{stderr}");
    // Killed, the first holds nothing: the directory resumes.
    let mut args = vec!["train", "--model", "mlp_hn", "--out", out_s];
    args.extend_from_slice(TINY);
    let (ok, _, stderr) = meben(&args);
    assert!(ok, "resume after kill failed: {stderr}");
}

#[test]
fn impossible_sizes_are_clear_errors_not_panics() {
    let dir = common::TempDir::new("cli-sizes");
    let out = dir.0.join("r");
    let out_s = out.to_str().unwrap();
    let train = |extra: &[&str], needles: &[&str]| {
        let mut args = vec!["train", "--out", out_s, "--quiet"];
        args.extend_from_slice(extra);
        fails_with(&args, needles);
    };
    train(&["--set", "batch_size=4611686018427387904", "--set", "num_minibatches=4"], &["batch_size", "16777216"]);
    train(&["--set", "batch_size=1099511627776"], &["batch_size", "1099511627776"]);
    train(&["--model", "mlp:head=4000000000"], &["model", "head", "4000000000"]);
    train(&["--env", "team_reach:agents=ant;R=1e160"], &["R", "1e160", "at most 1000"]);
    train(&["--set", "eval_episodes=18446744073709551615"], &["eval_episodes"]);
    train(&["--model", "transformer_hn:critic=shared"], &["transformer_hn", "takes no option `critic`"]);
    assert!(!out.exists(), "a run directory was created for an invalid configuration");
    let mut args = vec!["train", "--model", "mlp_hn", "--out", out_s];
    args.extend_from_slice(TINY);
    assert!(meben(&args).0);
    fails_with(&["eval", "--run", out_s, "--episodes", "18446744073709551615"], &["episodes", "18446744073709551615"]);
    // A huge but finite rotation: the evaluation is kept under a name of bounded length.
    let (ok, _, stderr) =
        meben(&["eval", "--run", out_s, "--episodes", "1", "--rotate", "1e308", "--translate", "1e-300,0"]);
    assert!(ok, "{stderr}");
    assert!(out.join("eval_rotate1e308_translate1e-300_0.json").is_file(), "{stderr}");
}

/// Issue 44 item 11: two `meben ablate` on one sweep directory shared the runs but both
/// exited 1 with "2 of 4 runs failed" (a run the other held counted as failed), and the last
/// line was `SweepOutcome { runs: 4, trained: 2, ... }`. Both succeed now, every run is
/// done, and the last line is a sentence.
#[test]
fn two_sweeps_on_one_directory_share_the_runs_and_both_succeed() {
    let dir = common::TempDir::new("cli-two-sweeps");
    let sweep = dir.0.join("sweep.toml");
    std::fs::write(
        &sweep,
        "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1, 2, 3]\npreset = \"quick\"\n[config]\n\
         num_envs = 8\nbatch_size = 4\nnum_minibatches = 4\nepochs = 1\nnum_evals = 2\neval_episodes = 2\nsteps = 320\n",
    )
    .unwrap();
    let out = dir.0.join("out");
    let args = ["ablate", "--sweep", sweep.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    let spawn = || {
        Command::new(env!("CARGO_BIN_EXE_meben"))
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let mut trained = 0;
    for child in [a, b] {
        let o = child.wait_with_output().unwrap();
        let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "a sweep failed: {stderr}");
        let last = stdout.lines().last().unwrap_or("");
        assert!(last.starts_with("meben: sweep ") && last.contains("4 runs: "), "{last}");
        assert!(!stdout.contains("SweepOutcome"), "{stdout}");
        trained += last.split(": ").nth(2).and_then(|t| t.split(' ').next()).unwrap().parse::<u32>().unwrap();
    }
    // Every run is trained by one of them (the other may then find it done and count it too).
    assert!(trained >= 4, "{trained} runs trained");
    for seed in 0..4 {
        assert!(out.join(format!("team_reach_1_ant/mlp_hn/seed{seed}/done.json")).is_file(), "seed {seed}");
    }
}

/// Issue 44 item 2: `meben eval --episodes 1048576`, `--set eval_episodes=1048576` and
/// `--num-envs 1048576 --set batch_size=1048576 --set num_minibatches=1 --set
/// unroll_length=1` were accepted (2^20 environments whatever the scene needs), then aborted
/// in the allocator (exit 134); the `eval_episodes` case only at its first evaluation, after
/// training, with no checkpoint. Each is refused now before anything is built, with the
/// estimate and the machine's memory; no run directory is created.
#[test]
fn sizes_beyond_the_machines_memory_are_refused_before_anything_is_built() {
    let Some(memory) = envs::memory::machine_memory() else { return };
    let scene = envs::tasks::Scene::from_name("team_sumo/3_ants").unwrap();
    let per_env = envs::tasks::VecEnv::bytes_per_env(&scene) as u128;
    if per_env << 20 <= memory.bytes {
        eprintln!("this machine holds 2^20 environments of team_sumo/3_ants: nothing to refuse");
        return;
    }
    let dir = common::TempDir::new("cli-memory");
    let out = dir.0.join("r");
    let out_s = out.to_str().unwrap();
    // "this machine's ... (/proc/meminfo)" or "this process's limit" (a cgroup, `ulimit -v`).
    let memory_words = ["GB, more than this ", "1048576"];
    let train = |extra: &[&str], field: &str| {
        let mut args = vec!["train", "--env", "team_sumo/3_ants", "--model", "mlp_hn", "--out", out_s, "--quiet"];
        args.extend_from_slice(extra);
        let t0 = std::time::Instant::now();
        fails_with(&args, &memory_words);
        fails_with(&args, &[&format!("field `{field}` = \"1048576\"")]);
        assert!(t0.elapsed().as_secs() < 60, "refused only after {:?}", t0.elapsed());
        assert!(!out.exists(), "a run directory was created for a training that cannot fit");
    };
    train(&["--set", "eval_episodes=1048576"], "eval_episodes");
    train(
        &[
            "--num-envs",
            "1048576",
            "--set",
            "batch_size=1048576",
            "--set",
            "num_minibatches=1",
            "--set",
            "unroll_length=1",
        ],
        "num_envs",
    );
    let mut args = vec!["train", "--env", "team_sumo/3_ants", "--model", "mlp_hn", "--out", out_s];
    args.extend_from_slice(TINY);
    let (ok, _, stderr) = meben(&args);
    assert!(ok, "{stderr}");
    let mut eval = vec!["eval", "--run", out_s, "--episodes", "1048576"];
    fails_with(&eval, &memory_words);
    fails_with(&eval, &["field `episodes` = \"1048576\"", "environments of team_sumo/3_ants at about"]);
    eval[4] = "2";
    assert!(meben(&eval).0);
}

/// Issue 77 item 1: `meben eval --run r --out r/checkpoint.json` exited 0 and replaced the
/// checkpoint with the evaluation's summary, and `eval --policy F --out F` the policy. Every
/// command that writes a file named by `--out` (eval, render, sim, export-policy) refuses a
/// run directory's own files and its own inputs, naming the path; nothing is written.
#[test]
fn no_command_writes_over_a_runs_files_or_its_own_input() {
    let tmp = common::TempDir::new("cli-outputs");
    let run = tmp.0.join("run");
    let run_s = run.to_str().unwrap();
    let mut args = vec!["train", "--model", "mlp_hn", "--out", run_s];
    args.extend_from_slice(TINY);
    let (ok, _, stderr) = meben(&args);
    assert!(ok, "train failed: {stderr}");
    let checkpoint = std::fs::read(run.join("checkpoint.json")).unwrap();
    let out = run.join("checkpoint.json");
    let out_s = out.to_str().unwrap();
    fails_with(&["eval", "--run", run_s, "--episodes", "1", "--out", out_s], &[out_s, "--out", "own checkpoint.json"]);
    assert_eq!(std::fs::read(&out).unwrap(), checkpoint, "eval --out replaced the checkpoint");
    let metrics = run.join("metrics.csv");
    let before = std::fs::read(&metrics).unwrap();
    fails_with(
        &["sim", "--mjcf", "body.xml", "--controls", "c.csv", "--out", metrics.to_str().unwrap()],
        &["metrics.csv", "--out", "own"],
    );
    assert_eq!(std::fs::read(&metrics).unwrap(), before);
    // The run's own evaluation file, which eval writes anyway, is fine.
    let own = run.join("eval.json");
    let (ok, _, stderr) = meben(&["eval", "--run", run_s, "--episodes", "1", "--out", own.to_str().unwrap()]);
    assert!(ok, "{stderr}");

    let policy = tmp.0.join("policy.safetensors");
    let policy_s = policy.to_str().unwrap();
    let (ok, _, stderr) = meben(&["export-policy", "--run", run_s, "--out", policy_s]);
    assert!(ok, "{stderr}");
    let bytes = std::fs::read(&policy).unwrap();
    let same = tmp.0.join(".").join("policy.safetensors");
    fails_with(
        &["eval", "--policy", policy_s, "--episodes", "1", "--out", same.to_str().unwrap()],
        &["--out", "--policy", "policy.safetensors"],
    );
    assert_eq!(std::fs::read(&policy).unwrap(), bytes, "eval --out replaced the policy");
    let summary = tmp.0.join("summary.json");
    let (ok, _, stderr) = meben(&["eval", "--policy", policy_s, "--episodes", "1", "--out", summary.to_str().unwrap()]);
    assert!(ok && summary.is_file(), "{stderr}");
}

/// Issue 77 item 11: `meben ablate --shard k/n` with more shards than runs exited 1 with a
/// message about `--only`, where rl/sweeps/slurm_array.sh says the extra shards are empty:
/// an empty shard exits 0 and says so. And `--device gpu` in a build without the feature is
/// refused once, before any run (it failed every run in turn).
#[test]
fn an_empty_shard_succeeds_and_a_missing_device_is_refused_before_any_run() {
    let tmp = common::TempDir::new("cli-shards");
    let sweep = tmp.0.join("sweep.toml");
    std::fs::write(
        &sweep,
        "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1]\npreset = \"quick\"\n",
    )
    .unwrap();
    let out = tmp.0.join("out");
    let base = ["ablate", "--sweep", sweep.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    let (ok, stdout, stderr) = meben(&[&base[..], &["--shard", "3/8"]].concat());
    assert!(ok, "{stderr}");
    assert!(stderr.contains("shard 3/8") && stderr.contains("empty") && stderr.contains("2 runs"), "{stderr}");
    assert!(stdout.contains("0 runs"), "{stdout}");
    assert!(!out.exists());
    if cfg!(not(feature = "gpu")) {
        let (ok, _, stderr) = meben(&[&base[..], &["--device", "gpu"]].concat());
        assert!(!ok && stderr.contains("--device") && stderr.contains("rebuild with --features gpu"), "{stderr}");
        assert_eq!(stderr.matches("rebuild with").count(), 1, "{stderr}");
        assert!(!out.exists(), "a run was started: {stderr}");
    }
}

/// Issue 77: `meben report --paper FILE` wrote `report.md` before it read the paper's
/// figures, and a line break in one of their values broke `paper.md`'s table. The file is
/// checked first, a line break refused naming the field, and nothing is written.
#[test]
fn a_bad_paper_file_is_refused_before_the_report_is_written() {
    let tmp = common::TempDir::new("cli-paper");
    let root = tmp.0.join("runs");
    let run = root.join("run0");
    let mut args = vec!["train", "--model", "mlp_hn", "--out", run.to_str().unwrap()];
    args.extend_from_slice(TINY);
    let (ok, _, stderr) = meben(&args);
    assert!(ok, "train failed: {stderr}");
    let paper = tmp.0.join("paper.toml");
    std::fs::write(
        &paper,
        "seeds = 10\n[[figure]]\ntable = \"Table 1\\nleft\"\nenv = \"team_reach/1_ant\"\nmodel = \"mlp_hn\"\n\
         mean = 50.0\nsd = 1.0\n",
    )
    .unwrap();
    fails_with(
        &["report", root.to_str().unwrap(), "--paper", paper.to_str().unwrap()],
        &["paper.toml", "figure[0].table", "line break"],
    );
    assert!(!root.join("report.md").exists() && !root.join("paper.md").exists());
}
