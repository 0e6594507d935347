//! The rollout tool (`envs::rollout_tool`, behind `--example rollout` and `meben sim`): its
//! arguments parse as a flattened clap `Args`, its output file replays the simulator exactly,
//! and every bad input is an error naming the flag or the file and line.

use clap::Parser;
use envs::rollout_tool::{RolloutArgs, RolloutError, run};
use std::path::PathBuf;

const ANT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/mujoco_ant.xml");

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: RolloutArgs,
}

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("envs-rollout-tool-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn args(dir: &std::path::Path, extra: &[&str]) -> RolloutArgs {
    let (c, o) = (dir.join("controls.csv"), dir.join("out.csv"));
    let mut argv = vec!["rollout", "--mjcf", ANT, "--controls", c.to_str().unwrap(), "--out", o.to_str().unwrap()];
    argv.extend_from_slice(extra);
    Cli::try_parse_from(argv).unwrap().args
}

#[test]
fn the_output_replays_the_simulator_exactly() {
    let dir = scratch("replay");
    let rows: Vec<Vec<f64>> = (0..4).map(|k| (0..8).map(|i| ((k * 8 + i) as f64 * 0.37).sin()).collect()).collect();
    let text: Vec<String> =
        rows.iter().map(|r| r.iter().map(|x| format!("{x:e}")).collect::<Vec<_>>().join(", ")).collect();
    // A blank line is skipped.
    std::fs::write(dir.join("controls.csv"), format!("{}\n\n{}\n", text[..2].join("\n"), text[2..].join("\n")))
        .unwrap();
    let a = args(&dir, &["--frames", "3"]);
    assert_eq!(a.frames, 3);
    assert_eq!(a.qpos, None);
    run(&a).unwrap();

    let model = envs::mjcf::load_file(ANT).unwrap();
    let mut d = envs::Data::new(&model);
    let mut want = vec![d.qpos.clone()];
    for r in &rows {
        d.ctrl.copy_from_slice(r);
        for _ in 0..3 {
            envs::step(&model, &mut d);
        }
        want.push(d.qpos.clone());
    }
    let out = std::fs::read_to_string(dir.join("out.csv")).unwrap();
    let mut lines = out.lines();
    let header: Vec<String> = (0..model.nq).map(|i| format!("q{i}")).collect();
    assert_eq!(lines.next().unwrap(), header.join(","));
    let got: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(&want) {
        assert!(g.iter().zip(w).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_initial_qpos_is_used_and_the_default_frames_is_five() {
    let dir = scratch("qpos");
    std::fs::write(dir.join("controls.csv"), "0,0,0,0,0,0,0,0\n").unwrap();
    let q = "0,0,0.75,1,0,0,0,0,1,0,-1,0,-1,0,1";
    let a = args(&dir, &["--qpos", q]);
    assert_eq!(a.frames, 5);
    run(&a).unwrap();
    let out = std::fs::read_to_string(dir.join("out.csv")).unwrap();
    let first: Vec<f64> = out.lines().nth(1).unwrap().split(',').map(|x| x.parse().unwrap()).collect();
    let want: Vec<f64> = q.split(',').map(|x| x.parse().unwrap()).collect();
    assert_eq!(first, want);
    assert_eq!(out.lines().count(), 3);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_inputs_name_the_flag_or_the_file_and_line() {
    let dir = scratch("errors");
    let controls = dir.join("controls.csv");
    std::fs::write(&controls, "0,0,0,0,0,0,0,0\n").unwrap();
    let err = |extra: &[&str]| run(&args(&dir, extra)).unwrap_err();

    let e = err(&["--frames", "0"]);
    assert!(matches!(&e, RolloutError::Argument { flag, .. } if flag == "--frames"), "{e}");
    let e = err(&["--qpos", "0,x"]);
    assert!(e.to_string().contains("--qpos") && e.to_string().contains("column 2"), "{e}");
    let e = err(&["--qpos", "0,0,0"]);
    assert!(e.to_string().contains("--qpos") && e.to_string().contains("nq = 15"), "{e}");

    std::fs::write(&controls, "0,0,0,0,0,0,0,0\n0,0,0\n").unwrap();
    let e = err(&[]);
    assert!(e.to_string().contains("controls.csv:2") && e.to_string().contains("8 actuators"), "{e}");
    std::fs::write(&controls, "0,0,0,0,0,nan,0,0\n").unwrap();
    let e = err(&[]);
    assert!(e.to_string().contains("controls.csv:1") && e.to_string().contains("column 6"), "{e}");
    // An absurd control is refused with its line and column: before, it
    // was accepted (the ant's motors clamp it; a motor without a control range multiplied
    // 1e300 by its gear).
    std::fs::write(&controls, "0,0,0,0,0,0,0,0\n0,0,1e300,0,0,0,0,0\n").unwrap();
    let e = err(&[]);
    let text = e.to_string();
    assert!(text.contains("controls.csv:2") && text.contains("column 3") && text.contains("1e300"), "{e}");
    assert!(text.contains("a control must be between -1e6 and 1e6"), "{e}");
    std::fs::remove_file(&controls).unwrap();
    let e = err(&[]);
    assert!(e.to_string().contains("cannot read"), "{e}");

    let mut a = args(&dir, &[]);
    a.mjcf = dir.join("missing.xml");
    assert!(matches!(run(&a), Err(RolloutError::Model(_))));
    std::fs::write(&controls, "0,0,0,0,0,0,0,0\n").unwrap();
    a = args(&dir, &[]);
    a.out = dir.join("no/such/dir/out.csv");
    let e = run(&a).unwrap_err();
    assert!(e.to_string().contains("cannot write") && e.to_string().contains("out.csv"), "{e}");
    assert!(!dir.join("no").exists());
    // A required flag missing is clap's error.
    assert!(Cli::try_parse_from(["rollout", "--mjcf", ANT]).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_output_never_overwrites_an_input() {
    let dir = scratch("inputs");
    let controls = dir.join("controls.csv");
    std::fs::write(&controls, "0,0,0,0,0,0,0,0\n").unwrap();
    let mjcf = dir.join("ant.xml");
    std::fs::copy(ANT, &mjcf).unwrap();
    let before = std::fs::read(&mjcf).unwrap();
    for (out, flag) in [(dir.join("controls.csv"), "--controls"), (dir.join(".").join("ant.xml"), "--mjcf")] {
        let mut a = args(&dir, &[]);
        a.mjcf = mjcf.clone();
        a.out = out;
        let e = run(&a).unwrap_err();
        assert!(matches!(&e, RolloutError::Argument { flag: f, .. } if f == "--out"), "{e}");
        assert!(e.to_string().contains(flag), "{e}");
    }
    assert_eq!(std::fs::read_to_string(&controls).unwrap(), "0,0,0,0,0,0,0,0\n");
    assert_eq!(std::fs::read(&mjcf).unwrap(), before);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 44 item 12: `--qpos 1e300,...` went past `envs/src/limits.rs` (a position of
/// 1e300 m, a hinge at 1e300 rad, a quaternion of 1e300 silently read as the identity), and
/// `--frames 18446744073709551615` was taken and never ended. Both are refused, naming the
/// flag, the entry and the bound, before anything is written.
#[test]
fn qpos_and_frames_outside_their_limits_are_refused() {
    let dir = scratch("limits");
    std::fs::write(dir.join("controls.csv"), "0,0,0,0,0,0,0,0\n").unwrap();
    let err = |extra: &[&str]| run(&args(&dir, extra)).unwrap_err().to_string();
    let ok = "0,0,0.75,1,0,0,0,0,1,0,-1,0,-1,0,1";
    let with = |i: usize, v: &str| {
        let mut q: Vec<&str> = ok.split(',').collect();
        q[i] = v;
        q.join(",")
    };
    let e = err(&["--qpos", &with(0, "1e300")]);
    assert!(e.contains("--qpos") && e.contains("qpos[0]") && e.contains("1e300") && e.contains("1000 m"), "{e}");
    let e = err(&["--qpos", &with(7, "1e300")]);
    assert!(e.contains("qpos[7]") && e.contains("hip_1") && e.contains("rad"), "{e}");
    let e = err(&["--qpos", &with(4, "1e300")]);
    assert!(e.contains("qpos[4]") && e.contains("quaternion"), "{e}");
    let e = err(&["--qpos", "0,0,0.75,0,0,0,0,0,1,0,-1,0,-1,0,1"]);
    assert!(e.contains("qpos[3..7]") && e.contains("zero"), "{e}");
    // At the bounds, accepted.
    run(&args(&dir, &["--qpos", &with(0, "1000")])).unwrap();
    run(&args(&dir, &["--qpos", &with(7, "-62.8")])).unwrap();

    let e = err(&["--frames", "18446744073709551615"]);
    assert!(e.contains("--frames") && e.contains("at most 10000"), "{e}");
    run(&args(&dir, &["--frames", "10000"])).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}
