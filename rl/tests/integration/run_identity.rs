//! A run directory that only its own run can change (issue 44 items 6 and 7): an edited
//! `config.toml` is refused on load, naming the fields; a changed or missing morphology file
//! is refused on resume, naming it; evaluation loads the run's copies of its morphology files,
//! from any directory.

use crate::common;

use std::path::Path;
use std::process::Command;

use rl::{RunDir, TrainConfig, TrainOptions, train};

/// Issue 44 item 6: `model = "shnn:assignment=stochastic"` written into a run's
/// `config.toml` was evaluated as it stood (another model with the trained parameters), and
/// a bigger edit failed naming a parameter, never the file. Every field that makes the run
/// is compared with the checkpoint's now; the session fields (`steps`, ...) may differ.
#[test]
fn an_edited_config_toml_is_refused_naming_the_file_and_fields() {
    let dir = common::TempDir::new("identity-config");
    let config = common::tiny("team_reach/1_ant", "shnn", 1, &[]);
    let run = RunDir::new(dir.0.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    rl::app::run_dir::load_policies(&run).unwrap();
    let original = std::fs::read_to_string(run.config()).unwrap();
    let edit = |from: &str, to: &str| {
        assert!(original.contains(from), "{original}");
        std::fs::write(run.config(), original.replace(from, to)).unwrap();
        rl::app::run_dir::load_policies(&run).map(|_| ())
    };
    let e = edit("model = \"shnn\"", "model = \"shnn:assignment=stochastic\"").unwrap_err().to_string();
    let file = run.config().display().to_string();
    assert!(e.starts_with(&format!("{file}: does not match")), "{e}");
    assert!(e.contains("model = \"shnn:assignment=stochastic\" here, \"shnn\" in the checkpoint"), "{e}");
    assert!(e.contains(&run.checkpoint().display().to_string()), "{e}");
    // Another arena, and another model (which failed before naming a parameter).
    let e = edit("env = \"team_reach/1_ant\"", "env = \"team_reach:agents=ant;R=4\"").unwrap_err().to_string();
    assert!(e.starts_with(&file) && e.contains("env = \"team_reach:agents=ant;R=4\" here"), "{e}");
    let e = edit("model = \"shnn\"", "model = \"mlp_hn\"").unwrap_err().to_string();
    assert!(e.starts_with(&file) && e.contains("model = \"mlp_hn\" here") && !e.contains("parameter"), "{e}");
    // A session's fields may differ: a resumed run writes config.toml before its checkpoint.
    edit(&format!("steps = {}", config.steps), "steps = 1000000").unwrap();
    edit(&format!("threads = {}", config.threads), "threads = 1").unwrap();
    // Training again rewrites config.toml from the command, as before.
    std::fs::write(run.config(), original.replace("model = \"shnn\"", "model = \"mlp\"")).unwrap();
    train(&config, &run, &TrainOptions::default()).unwrap();
    assert_eq!(TrainConfig::load(&run.config()).unwrap(), config);
    rl::app::run_dir::load_policies(&run).unwrap();
}

fn meben(cwd: &Path, args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_meben")).current_dir(cwd).args(args).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

const ANT_XML: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../envs/tests/data/ant.xml");

/// Issue 44 item 7: trained with `--env "team_reach:agents=body.xml"`, stopped, `body.xml`
/// edited and resumed: accepted, and the rows were no longer those of an uninterrupted run;
/// `meben eval` from another directory failed or loaded another `body.xml`. Now the run keeps
/// `morphology.toml` (name, source, SHA-256) and a copy of the file; a resume refuses a
/// changed or missing file by name, and evaluation loads the copy from any directory.
#[test]
fn morphology_files_are_kept_by_content_and_evaluated_from_anywhere() {
    let dir = common::TempDir::new("identity-morphology");
    let (here, elsewhere) = (dir.0.join("here"), dir.0.join("elsewhere"));
    std::fs::create_dir_all(&here).unwrap();
    std::fs::create_dir_all(&elsewhere).unwrap();
    let ant = std::fs::read_to_string(ANT_XML).unwrap();
    let weaker = ant.replace("gear=\"350\"", "gear=\"300\"");
    std::fs::write(here.join("body.xml"), &ant).unwrap();
    let tiny = [
        "--set",
        "batch_size=4",
        "--set",
        "num_minibatches=4",
        "--set",
        "epochs=1",
        "--set",
        "num_evals=1",
        "--set",
        "eval_episodes=2",
        "--num-envs",
        "8",
        "--steps",
        "240",
        "--quiet",
    ];
    let mut train_args = vec!["train", "--env", "team_reach:agents=body.xml;R=3", "--model", "mlp_hn", "--out", "run"];
    train_args.extend_from_slice(&tiny);
    let stop_after = |n: &'static str| {
        let mut a = train_args.clone();
        a.extend_from_slice(&["--stop-after", n]);
        a
    };
    let (ok, _, stderr) = meben(&here, &stop_after("1"));
    assert!(ok, "{stderr}");
    let run = here.join("run");
    let record = std::fs::read_to_string(run.join("morphology.toml")).unwrap();
    let digest = rl::mappo::checksum::sha256_hex(ant.as_bytes());
    assert!(record.contains("name = \"body.xml\"") && record.contains(&digest), "{record}");
    assert_eq!(std::fs::read_to_string(run.join("morphologies/0_body.xml")).unwrap(), ant);

    // Changed, then missing: refused by name, nothing trained.
    std::fs::write(here.join("body.xml"), &weaker).unwrap();
    let (ok, _, stderr) = meben(&here, &stop_after("2"));
    assert!(!ok && stderr.contains("body.xml: the morphology file changed") && stderr.contains(&digest), "{stderr}");
    assert!(stderr.contains("0_body.xml"), "{stderr}");
    std::fs::remove_file(here.join("body.xml")).unwrap();
    let (ok, _, stderr) = meben(&here, &stop_after("2"));
    assert!(!ok && stderr.contains("body.xml: cannot read the morphology file"), "{stderr}");
    let rows = |p: &Path| std::fs::read_to_string(p.join("metrics.csv")).unwrap().lines().count();
    assert_eq!(rows(&run), 2, "a refused resume trained");

    // Restored: the run goes on and ends.
    std::fs::write(here.join("body.xml"), &ant).unwrap();
    let (ok, _, stderr) = meben(&here, &train_args);
    assert!(ok, "{stderr}");
    assert_eq!(rows(&run), 4);

    // Evaluation: here, from elsewhere without body.xml, and from elsewhere with another
    // body.xml, and here after body.xml changed: the same episodes, of the run's copy.
    let eval = |cwd: &Path| {
        let run_s = run.to_str().unwrap();
        let (ok, stdout, stderr) = meben(cwd, &["eval", "--run", run_s, "--episodes", "3"]);
        assert!(ok, "{stderr}");
        stdout
    };
    let first = eval(&here);
    assert_eq!(eval(&elsewhere), first);
    std::fs::write(elsewhere.join("body.xml"), &weaker).unwrap();
    assert_eq!(eval(&elsewhere), first);
    std::fs::write(here.join("body.xml"), &weaker).unwrap();
    assert_eq!(eval(&here), first);
    let out = elsewhere.join("episode.csv");
    let (ok, _, stderr) =
        meben(&elsewhere, &["render", "--run", run.to_str().unwrap(), "--out", out.to_str().unwrap(), "--steps", "3"]);
    assert!(ok && out.is_file(), "{stderr}");
    // An edited copy is refused, naming it.
    std::fs::write(run.join("morphologies/0_body.xml"), &weaker).unwrap();
    let (ok, _, stderr) = meben(&elsewhere, &["eval", "--run", run.to_str().unwrap(), "--episodes", "3"]);
    assert!(!ok && stderr.contains("0_body.xml") && stderr.contains("changed"), "{stderr}");
}
