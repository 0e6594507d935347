//! `rl/sweeps/assignment_diagnostics.py`, which reads what a learned task assignment learned
//! from a run's checkpoint and rendered episodes (issue 79's evidence). With the prior at
//! its largest (`assign_prior=1000`) the draw is Algorithm 1's (`models`' tests), so the
//! script must find its scores falling by 1000 a metre, the sampled assignment equal to its
//! own Algorithm 1 on every step, and the most likely one equal to the least-distance
//! matching; a run without a learned assignment, and bad input (a missing run or program, a
//! cut checkpoint, no episodes), are refused by name, with no partial table.
//! `rl/sweeps/assignment_substitution.py` evaluates a learned run with its own draws and with
//! Algorithm 1 in their place: where the draws are Algorithm 1's, the same episodes.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/assignment_diagnostics.py")
}

/// Trains a short run of `model` in the scratch directory `scratch` (one per test: tests run
/// in parallel) and runs the script on it over `episodes` episodes; (success, stdout, stderr).
fn diagnose(scratch: &str, model: &str, episodes: &str) -> (bool, String, String) {
    let tmp = common::TempDir::new(scratch);
    let run = tmp.0.join("run");
    common::train_2_ants(model, &run);
    run_script(&["--bin", env!("CARGO_BIN_EXE_meben"), "--episodes", episodes, run.to_str().unwrap()])
}

/// The cells of the table row whose second column is `second` (a table of `run`).
fn row<'a>(stdout: &'a str, second: &str) -> Vec<&'a str> {
    stdout
        .lines()
        .map(|l| l.split('|').map(str::trim).filter(|c| !c.is_empty()).collect::<Vec<_>>())
        .find(|cells| cells.len() > 2 && cells[1] == second)
        .unwrap_or_else(|| panic!("no row with {second:?} in:\n{stdout}"))
}

#[test]
fn the_diagnostics_find_algorithm_1_in_a_run_with_the_largest_prior() {
    let (ok, stdout, stderr) = diagnose("assignment_diagnostics", "mlp_hn:assignment=learned;assign_prior=1000", "2");
    assert!(ok, "{stdout}{stderr}");

    // Scores: λ read from the model string, s(d + 1) - s(d) = -1000 up to the small
    // untrained f_θ, and the nearer agent always picked.
    let scores = row(&stdout, "1000");
    let s: Vec<f64> = scores[2..8].iter().map(|c| c.parse().unwrap()).collect();
    for pair in s.windows(2) {
        assert!((pair[1] - pair[0] + 1000.0).abs() < 2.0, "{scores:?}");
    }
    assert_eq!(scores[8], "1.00", "{scores:?}");

    // Sampled draws are Algorithm 1's on every step, and change when it does.
    let sampled = row(&stdout, "sampled");
    assert_eq!(sampled[2], "2002", "two whole episodes of 1000 steps: {sampled:?}");
    assert_eq!(sampled[3], "100.0%", "{sampled:?}");
    assert_eq!(sampled[5], sampled[6], "{sampled:?}");
    // The most likely assignment maximises the total score -1000 d: the least-distance
    // matching.
    let most_likely = row(&stdout, "most likely (mean actions)");
    assert_eq!(most_likely[4], "100.0%", "{most_likely:?}");

    // The actions' dependence on the assignment, from `meben eval --assignment-sensitivity`
    // over the default 32 episodes: every scene-step counted, a positive divergence (the
    // head reads the assigned ball).
    let kl = row(&stdout, "32 episodes, sampled actions");
    assert!(kl[3].parse::<usize>().unwrap() > 32, "{kl:?}");
    let figures: Vec<f64> = kl[4..8].iter().map(|c| c.parse().unwrap()).collect();
    assert!(figures.iter().all(|&x| x > 0.0) && figures[1] <= figures[2], "{kl:?}");
}

/// Asserts a refusal: a failure with nothing on stdout (no partial table), `expected` on
/// stderr, and no Python traceback.
fn assert_refused((ok, stdout, stderr): (bool, String, String), expected: &str) {
    assert!(!ok, "{stdout}");
    assert!(stdout.is_empty(), "no partial table: {stdout}");
    assert!(stderr.contains(expected), "expected {expected:?} in: {stderr}");
    assert!(!stderr.contains("Traceback"), "a message, not a traceback: {stderr}");
}

/// Runs the script with `args` (no training).
fn run_script(args: &[&str]) -> (bool, String, String) {
    common::outcome(Command::new("python3").arg(script()).args(args).output().expect("python3 runs the script"))
}

#[test]
fn the_diagnostics_refuse_a_run_without_a_learned_assignment() {
    let refusal = diagnose("assignment_diagnostics_greedy", "mlp_hn", "1");
    assert_refused(refusal, "/run: no team0.assign.* parameters");
}

#[test]
fn the_diagnostics_refuse_bad_input_by_name() {
    let tmp = common::TempDir::new("assignment_diagnostics_bad_input");
    let meben = env!("CARGO_BIN_EXE_meben");
    let missing = tmp.0.join("no_such_run");
    let missing = missing.to_str().unwrap();
    assert_refused(run_script(&["--bin", meben, missing]), &format!("{missing}: not a run directory"));
    assert_refused(run_script(&["--bin", meben, "--episodes", "0", missing]), "--episodes 0: at least 1");
    let zero = ["--bin", meben, "--sensitivity-episodes", "0", missing];
    assert_refused(run_script(&zero), "--sensitivity-episodes 0: at least 1");
    let no_bin = tmp.0.join("no_meben");
    let no_bin = no_bin.to_str().unwrap();
    assert_refused(run_script(&["--bin", no_bin, missing]), &format!("--bin {no_bin}: not an executable file"));
    // A checkpoint cut short: its header's JSON ends early.
    let cut = tmp.0.join("cut");
    std::fs::create_dir(&cut).unwrap();
    let mut blob = 200u64.to_le_bytes().to_vec();
    blob.extend_from_slice(br#"{"team0.assign.mlp.0.weight": {"dtype": "F32", "sha"#);
    let cut_file = cut.join("checkpoint.0123.safetensors");
    std::fs::write(&cut_file, blob).unwrap();
    let expected = format!("{}: not a readable safetensors file", cut_file.display());
    assert_refused(run_script(&["--bin", meben, cut.to_str().unwrap()]), &expected);
}

fn trace_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/sensitivity_trace.py")
}

#[test]
fn the_sensitivity_trace_appends_one_row_per_new_checkpoint() {
    let tmp = common::TempDir::new("sensitivity_trace");
    let (learned, greedy) = (tmp.0.join("learned"), tmp.0.join("greedy"));
    common::train_2_ants("mlp_hn:assignment=learned;assign_prior=1000", &learned);
    common::train_2_ants("mlp_hn", &greedy);
    let out = tmp.0.join("trace.csv");
    let meben = env!("CARGO_BIN_EXE_meben");
    let run = |args: &[&str]| {
        common::outcome(
            Command::new("python3").arg(trace_script()).args(args).output().expect("python3 runs the script"),
        )
    };
    let args = ["--bin", meben, "--episodes", "2", "--out", out.to_str().unwrap()];
    let runs = [learned.to_str().unwrap(), greedy.to_str().unwrap()];
    let (ok, _, err) = run(&[&args[..], &runs[..]].concat());
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&out).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0].join(","), "run,iteration,env_steps,success,kl_mean,kl_median,kl_p90,kl_early,p_nearer");
    assert_eq!(rows.len(), 3, "{text}");
    // 2560 env steps, 320 an iteration (16 environments x 20 steps): 8 iterations.
    for (row, run) in rows[1..].iter().zip(runs) {
        assert_eq!((row[0], row[1], row[2]), (run, "8", "2560"), "{text}");
        let kl: f64 = row[4].parse().unwrap();
        assert!(kl > 0.0, "{text}");
    }
    // λ = 1000: the nearer agent always; greedy: no scorer.
    assert_eq!((rows[1][8], rows[2][8]), ("1.0000", ""), "{text}");
    // Looking again at unchanged checkpoints adds nothing.
    let (ok, _, err) = run(&[&args[..], &runs[..]].concat());
    assert!(ok, "{err}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), text);
    // The trace as Markdown: a row per traced checkpoint, the rates as percents.
    let (ok, table, err) = run(&["--out", out.to_str().unwrap(), "--table"]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 4, "{table}");
    assert!(
        lines[2].starts_with(&format!("| `{}` | 8 | 0.00M |", runs[0])) && lines[2].ends_with("| 100.0% |"),
        "{table}"
    );
    assert!(lines[3].ends_with("| – |"), "{table}");
    // Another file is not appended to; a missing run is refused by name.
    let other = tmp.0.join("other.csv");
    std::fs::write(&other, "a,b\n").unwrap();
    let (ok, _, err) = run(&["--bin", meben, "--out", other.to_str().unwrap(), runs[0]]);
    assert!(!ok && err.contains("not a trace of this script") && !err.contains("Traceback"), "{err}");
    let missing = tmp.0.join("no_run");
    let (ok, _, err) = run(&["--bin", meben, "--out", out.to_str().unwrap(), missing.to_str().unwrap()]);
    assert!(!ok && err.contains("no_run: not a run directory"), "{err}");
}

fn substitution_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/assignment_substitution.py")
}

/// Runs `assignment_substitution.py` with `args`.
fn substitute(args: &[&str]) -> (bool, String, String) {
    let script = substitution_script();
    common::outcome(Command::new("python3").arg(script).args(args).output().expect("python3 runs the script"))
}

/// The numeric cells of the row of `run` (success, interval, return per evaluation).
fn substitution_row<'a>(stdout: &'a str, run: &str) -> Vec<&'a str> {
    let name = format!("`{run}`");
    stdout
        .lines()
        .map(|l| l.split('|').map(str::trim).filter(|c| !c.is_empty()).collect::<Vec<_>>())
        .find(|cells| cells.first() == Some(&name.as_str()))
        .unwrap_or_else(|| panic!("no row of {run} in:\n{stdout}"))
}

#[test]
fn the_substitution_plays_the_same_episodes_where_the_draws_are_algorithm_1s() {
    let tmp = common::TempDir::new("assignment_substitution");
    let meben = env!("CARGO_BIN_EXE_meben");
    // λ = 1000, drawn every step: the draws are Algorithm 1's, so Algorithm 1 in their place
    // plays the same episodes (the same success and mean return, to the printed digit).
    let sharp = tmp.0.join("sharp");
    common::train_2_ants("mlp_hn:assignment=learned;assign_prior=1000", &sharp);
    // λ = 1, held per episode: other episodes, and the third evaluation (Algorithm 1 held).
    let held = tmp.0.join("held");
    common::train_2_ants_with("mlp_hn:assignment=learned", &held, &["assignment_hold_episode=true"]);
    let runs = [sharp.to_str().unwrap(), held.to_str().unwrap()];
    let (ok, stdout, stderr) = substitute(&["--bin", meben, "--episodes", "3", runs[0], runs[1]]);
    assert!(ok, "{stdout}{stderr}");
    let s = substitution_row(&stdout, runs[0]);
    assert_eq!(s.len(), 11, "{s:?}");
    assert_eq!(s[1], "1.00", "P(nearer) of λ = 1000: {s:?}");
    assert_eq!(s[2..5], s[5..8], "the draws were Algorithm 1's: {s:?}");
    assert_eq!(s[8..], ["–", "–", "–"], "a run drawn every step has no held evaluation: {s:?}");
    let h = substitution_row(&stdout, runs[1]);
    assert_ne!(h[4], h[7], "the scorer's draws played Algorithm 1's episodes: {h:?}");
    assert!(h[8..].iter().all(|c| *c != "–"), "{h:?}");
    for rates in [&h[2], &h[5], &h[8]] {
        let r: f64 = rates.parse().unwrap();
        assert!((0.0..=100.0).contains(&r), "{h:?}");
    }
    // Bad input is refused by name, with no partial table.
    assert_refused(substitute(&["--bin", meben, "--episodes", "0", runs[0]]), "--episodes 0: at least 1");
    let greedy = tmp.0.join("greedy");
    common::train_2_ants("mlp_hn", &greedy);
    let refused = substitute(&["--bin", meben, runs[0], greedy.to_str().unwrap()]);
    assert_refused(refused, "/greedy: no team0.assign.* parameters");
    let missing = tmp.0.join("no_run");
    assert_refused(substitute(&["--bin", meben, missing.to_str().unwrap()]), "no_run: not a run directory");
}

/// Runs `assignment_values.py` with `args`.
fn values_script(args: &[&str]) -> (bool, String, String) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/assignment_values.py");
    common::outcome(Command::new("python3").arg(script).args(args).output().expect("python3 runs the script"))
}

#[test]
fn the_values_pair_each_episode_with_algorithm_1_held_and_replay_it_where_the_draw_was_its_own() {
    let tmp = common::TempDir::new("assignment_values_script");
    let meben = env!("CARGO_BIN_EXE_meben");
    let held = tmp.0.join("held");
    let hold = ["assignment_hold_episode=true"];
    common::train_2_ants_with("mlp_hn:assignment=learned;assign_critic=held", &held, &hold);
    let run = held.to_str().unwrap();
    let before: Vec<_> = std::fs::read_dir(&held).unwrap().map(|e| e.unwrap().file_name()).collect();
    let (ok, stdout, stderr) = values_script(&["--bin", meben, "--episodes", "24", run]);
    assert!(ok, "{stdout}{stderr}");
    let after: Vec<_> = std::fs::read_dir(&held).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(before, after, "nothing is written to the run");
    // The first table (paired by episode), then the second (every episode).
    let s = substitution_row(&stdout, run);
    assert_eq!(s.len(), 13, "{s:?}");
    let (other, same): (usize, usize) = (s[1].parse().unwrap(), s[10].parse().unwrap());
    assert_eq!(other + same, 24, "every episode is one or the other: {s:?}");
    assert!(other > 0 && same > 0, "both kinds of episode at this seed: {s:?}");
    // Where the draw was Algorithm 1's, the two evaluations played the same episode.
    assert_eq!(s[11..13], ["0.00", "±0.00"], "{s:?}");
    // Success differences lie in ±100 points.
    let points: f64 = s[8].parse().unwrap();
    assert!((-100.0..=100.0).contains(&points), "{s:?}");
    let second = stdout.split("Over every episode").nth(1).expect("the second table");
    let v = substitution_row(second, run);
    assert_eq!(v.len(), 7, "{v:?}");
    let (first, pi): (f64, f64) = (v[1].trim_end_matches('%').parse().unwrap(), v[2].parse().unwrap());
    assert!((0.0..=100.0).contains(&first) && (0.0..=1.0).contains(&pi), "{v:?}");
    // Bad input is refused by name, with no partial table: no episodes; a run that drew at
    // every step; a value that reads no assignment.
    assert_refused(values_script(&["--bin", meben, "--episodes", "0", run]), "--episodes 0: at least 1");
    let every = tmp.0.join("every");
    common::train_2_ants("mlp_hn:assignment=learned", &every);
    assert_refused(values_script(&["--bin", meben, every.to_str().unwrap()]), "not held per episode");
    let plain = tmp.0.join("plain");
    common::train_2_ants_with("mlp_hn:assignment=learned", &plain, &hold);
    assert_refused(values_script(&["--bin", meben, "--episodes", "2", plain.to_str().unwrap()]), "assign_critic=held");
}
