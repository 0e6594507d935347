//! `meben report` on synthetic run directories, and a sweep followed by a report (with a
//! fake trainer that writes what a run leaves behind).

use std::path::Path;

use rl::app::metrics::{MetricsLayout, MetricsRow};
use rl::{Preset, RunDir, RunSelection, RunSummary, Sweep, TrainConfig, report, run_sweep};

use crate::common;

use common::TempDir;

/// Writes `config.toml` and a `metrics.csv` of `rows` (each a list of column values).
fn write_run(dir: &Path, config: &TrainConfig, rows: &[&[(&'static str, f64)]]) {
    std::fs::create_dir_all(dir).unwrap();
    let run = RunDir::new(dir);
    config.save(&run.config()).unwrap();
    let layout = MetricsLayout::new(&config.eval_rotations);
    let mut text = layout.header();
    text.push('\n');
    for (i, cells) in rows.iter().enumerate() {
        let mut row = MetricsRow::default();
        row.set("iteration", (i + 1) as f64);
        for &(column, value) in cells.iter() {
            row.set(column, value);
        }
        text.push_str(&layout.to_csv(&row));
        text.push('\n');
    }
    std::fs::write(run.metrics(), text).unwrap();
}

fn config(env: &str, model: &str, seed: u64) -> TrainConfig {
    TrainConfig { model: model.into(), seed, ..TrainConfig::preset(Preset::Quick, env) }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn report_of_synthetic_runs() {
    let tmp = TempDir::new("synthetic");
    let root = &tmp.0;
    // Team Reach, shnn, three seeds: final eval successes 0.5, 0.6, 0.9; seed 2 has an
    // extra evaluation, and rows without an evaluation in between. Their last rows' wall
    // times add up to 2 hours (an earlier row's does not count).
    let finals = [0.5, 0.6, 0.9];
    let walls = [3600.0, 1800.0, 1800.0];
    for (seed, f) in finals.iter().enumerate() {
        let dir = root.join(format!("team_reach_1_ant/shnn/seed{seed}"));
        let mut rows: Vec<Vec<(&'static str, f64)>> = vec![
            vec![("env_steps", 1000.0), ("wall_s", 9999.0), ("train_success_rate", 0.0), ("eval_success_rate", 0.1)],
            vec![("env_steps", 2000.0), ("train_success_rate", 0.3)],
            vec![("env_steps", 3000.0), ("wall_s", walls[seed]), ("eval_success_rate", *f)],
        ];
        if seed == 2 {
            rows.insert(2, vec![("env_steps", 2500.0), ("eval_success_rate", 0.2)]);
        }
        let rows: Vec<&[(&'static str, f64)]> = rows.iter().map(|r| r.as_slice()).collect();
        write_run(&dir, &config("team_reach/1_ant", "shnn", seed as u64), &rows);
    }
    // A variant of it, one seed.
    let variant = TrainConfig { entropy_coef: 0.0, ..config("team_reach/1_ant", "shnn", 0) };
    write_run(
        &root.join("team_reach_1_ant/shnn+no_entropy/seed0"),
        &variant,
        &[&[("env_steps", 1000.0), ("eval_success_rate", 0.25)]],
    );
    // mlp_hn set not to evaluate: valued by the training success rate (last row having it).
    write_run(
        &root.join("team_reach_1_ant/mlp_hn/seed0"),
        &TrainConfig { num_evals: 0, ..config("team_reach/1_ant", "mlp_hn", 0) },
        &[
            &[("env_steps", 1000.0), ("train_success_rate", 0.1)],
            &[("env_steps", 2000.0), ("train_success_rate", 0.25)],
            &[("env_steps", 3000.0)],
        ],
    );
    // Team Sumo, two seeds: wins 0.4 and 0.7, losses 0.5 and 0.0, draws 0.1 and 0.3.
    for (seed, (win, lose, draw)) in [(0.4, 0.5, 0.1), (0.7, 0.0, 0.3)].into_iter().enumerate() {
        write_run(
            &root.join(format!("team_sumo_2_ants/shnn/seed{seed}")),
            &config("team_sumo/2_ants", "shnn", seed as u64),
            &[
                &[("env_steps", 2500.0), ("eval_win_rate_t0", 0.0), ("eval_win_rate_t1", 1.0), ("eval_draw_rate", 0.0)],
                &[
                    ("env_steps", 5000.0),
                    ("eval_win_rate_t0", win),
                    ("eval_win_rate_t1", lose),
                    ("eval_draw_rate", draw),
                ],
            ],
        );
    }
    // A run that has not written a row yet; one set to evaluate that has only training rows
    // (its early training rate, 100%, counts only the episodes that succeeded early), alone in
    // its group; and a directory that is no run.
    write_run(&root.join("team_reach_1_ant/shnn/seed9"), &config("team_reach/1_ant", "shnn", 9), &[]);
    write_run(
        &root.join("team_reach_1_ant/mlp/seed0"),
        &config("team_reach/1_ant", "mlp", 0),
        &[&[("env_steps", 1000.0), ("train_success_rate", 1.0)]],
    );
    std::fs::create_dir_all(root.join("notes/empty")).unwrap();

    let r = report(root).unwrap();
    let labels: Vec<(&str, &str)> = r.groups.iter().map(|g| (g.env.as_str(), g.label.as_str())).collect();
    assert_eq!(
        labels,
        [
            ("team_reach/1_ant", "mlp_hn"),
            ("team_reach/1_ant", "shnn"),
            ("team_reach/1_ant", "shnn+no_entropy"),
            ("team_sumo/2_ants", "shnn"),
        ]
    );
    assert_eq!(r.pending.len(), 2, "{:?}", r.pending);
    assert_eq!(r.pending[0].0, Path::new("team_reach_1_ant/mlp/seed0"));
    assert!(r.pending[0].1.starts_with("no evaluation yet"), "{}", r.pending[0].1);
    assert_eq!(r.pending[1].0, Path::new("team_reach_1_ant/shnn/seed9"));

    let mlp = &r.groups[0];
    assert!(mlp.from_train);
    assert_eq!(mlp.metric, "train_success_rate");
    assert!(close(mlp.mean, 25.0) && mlp.se == 0.0);
    assert_eq!(mlp.env_steps, (3000, 3000));
    assert_eq!(mlp.final_steps, [2000]);

    let shnn = &r.groups[1];
    assert_eq!(shnn.runs.len(), 3);
    assert_eq!(shnn.seed_list, [0, 1, 2]);
    assert!(!shnn.from_train);
    // mean 66.667, sample std sqrt(((-16.667)^2 + (-6.667)^2 + 23.333^2) / 2) = 20.817, s.e. 12.019
    assert!(close(shnn.mean, 200.0 / 3.0), "{}", shnn.mean);
    let sd =
        ((50.0f64 - 200.0 / 3.0).powi(2) + (60.0f64 - 200.0 / 3.0).powi(2) + (90.0f64 - 200.0 / 3.0).powi(2)) / 2.0;
    assert!(close(shnn.se, (sd / 3.0).sqrt()), "{}", shnn.se);
    assert!((shnn.se - 12.0185).abs() < 1e-4, "{}", shnn.se);
    // Curve on the env steps of seed 0 (2 evaluations): 1000 and 3000.
    let xs: Vec<f64> = shnn.curve.iter().map(|p| p.env_steps).collect();
    assert_eq!(xs, [1000.0, 3000.0]);
    assert!(close(shnn.curve[0].mean, 10.0) && close(shnn.curve[0].se, 0.0));
    assert!(close(shnn.curve[1].mean, shnn.mean));
    assert!(close(shnn.iqm, shnn.mean));
    assert_eq!((shnn.mean_ci, shnn.iqm_ci), ((50.0, 90.0), (50.0, 90.0)));

    let sumo = &r.groups[3];
    assert_eq!(sumo.metric, "eval_win_rate_t0");
    assert!(close(sumo.mean, 55.0) && close(sumo.se, 15.0));
    let (dm, ds) = sumo.draw.unwrap();
    assert!(close(dm, 20.0) && close(ds, 10.0));
    let (lm, ls) = sumo.lose.unwrap();
    assert!(close(lm, 25.0) && close(ls, 25.0));
    // Win, loss and draw curves over training.
    let at = |c: &[rl::app::report::CurvePoint]| c.iter().map(|p| (p.env_steps, p.mean)).collect::<Vec<_>>();
    assert_eq!(at(&sumo.curve), [(2500.0, 0.0), (5000.0, 55.0)]);
    assert_eq!(at(&sumo.curve_lose), [(2500.0, 100.0), (5000.0, 25.0)]);
    assert!(close(sumo.curve_draw[1].mean, 20.0));
    assert!(shnn.curve_lose.is_empty() && shnn.lose.is_none());
    assert!(close(shnn.machine_hours, 2.0), "{}", shnn.machine_hours);
    assert_eq!(sumo.machine_hours, 0.0);

    // Files.
    assert_eq!(r.markdown, root.join("report.md"));
    let md = std::fs::read_to_string(&r.markdown).unwrap();
    for want in [
        "## team_reach/1_ant",
        "## team_sumo/2_ants",
        // Beside mean ± s.e., the IQM (all 3 seeds below 4) and the bootstrap intervals,
        // which with 3 seeds span them (each resample of only the lowest has odds 1/27).
        "| run | model | seeds | success % (mean ± s.e.) | IQM [95% CI] | mean's 95% CI | env steps |",
        "| shnn | `shnn` | 3 | 66.67 ± 12.02 | 66.67 [50.00, 90.00] | [50.00, 90.00] | 3k of 1.5M | 2.0 |",
        "25.00 ± 0.00 † | 25.00 [25.00, 25.00] † | [25.00, 25.00] † |",
        "| shnn | `shnn` | same | 2 | 55.00 ± 15.00 | 55.00 [40.00, 70.00] | [40.00, 70.00] | 25.00 ± 25.00 | \
         20.00 ± 10.00 | 5k of 1.5M | 0.0 |",
        "Machine time: 2.0 h over the 7 runs above",
        "| 2.0 | seed 0: 50.00 (3k); seed 1: 60.00 (3k); seed 2: 90.00 (3k) |",
        // The training-rate fallback: measured at the last row having it, not the last row.
        "| 0.0 | seed 0: 25.00 (2k) |",
        "| 0.0 | seed 0: 40.00 (5k); seed 1: 70.00 (5k) |",
        "curves/team_reach_1_ant.svg",
        "team_reach_1_ant/shnn/seed9",
    ] {
        assert!(md.contains(want), "report.md lacks {want:?}:\n{md}");
    }
    let csv = std::fs::read_to_string(&r.csv).unwrap();
    assert_eq!(csv.lines().count(), 1 + 4);
    assert!(
        csv.lines()
            .any(|l| l.starts_with("team_sumo/2_ants,shnn,,team_sumo_2_ants/shnn,eval_win_rate_t0,2,0 1,55,15,20,10,")
                && l.ends_with(",0,25,25,0,55,40,70,40,70"))
    );
    assert_eq!(r.curves, [root.join("curves/team_reach_1_ant.svg"), root.join("curves/team_sumo_2_ants.svg")]);
    for path in &r.curves {
        let svg = std::fs::read_to_string(path).unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("<path") && svg.contains("fill-opacity"), "no band in {}", path.display());
    }
    let sumo_svg = std::fs::read_to_string(&r.curves[1]).unwrap();
    for series in ["shnn (n=2) win", "shnn (n=2) loss", "shnn (n=2) draw"] {
        assert!(sumo_svg.contains(series), "the Sumo plot lacks {series}");
    }
}

#[test]
fn report_has_a_group_and_a_curve_per_evaluation_rotation() {
    let tmp = TempDir::new("rotations");
    let root = &tmp.0;
    // The paper's equivariance test: fixed start, evaluated unrotated and at 180 degrees.
    for (model, finals) in [("shnn", [(0.4, 0.42), (0.5, 0.48)]), ("mlp", [(0.4, 0.0), (0.6, 0.02)])] {
        for (seed, (plain, rotated)) in finals.into_iter().enumerate() {
            let c = TrainConfig {
                fixed_start: true,
                eval_rotations: vec![0.0, 180.0],
                // Finished runs: the budget is the last row's env steps.
                steps: 200,
                ..config("team_reach/1_centipede", model, seed as u64)
            };
            write_run(
                &root.join(format!("{model}/seed{seed}")),
                &c,
                &[
                    &[("env_steps", 100.0), ("eval_success_rate", 0.1), ("eval_success_rate_rot180", 0.1)],
                    &[
                        ("env_steps", 200.0),
                        ("wall_s", 900.0),
                        ("eval_success_rate", plain),
                        ("eval_success_rate_rot180", rotated),
                    ],
                ],
            );
        }
    }
    // A third mlp seed, just started: a training rate but no evaluation yet. It is left out
    // of its group (listed as without a result), not averaged in.
    let c = TrainConfig {
        fixed_start: true,
        eval_rotations: vec![0.0, 180.0],
        steps: 200,
        ..config("team_reach/1_centipede", "mlp", 2)
    };
    write_run(&root.join("mlp/seed2"), &c, &[&[("env_steps", 100.0), ("train_success_rate", 1.0)]]);
    let r = report(root).unwrap();
    assert_eq!(r.pending.len(), 1, "{:?}", r.pending);
    assert_eq!(r.pending[0].0, Path::new("mlp/seed2"));
    assert!(r.groups.iter().all(|g| g.runs.len() == 2 && !g.from_train));
    let groups: Vec<(&str, &str, f64)> =
        r.groups.iter().map(|g| (g.label.as_str(), g.metric.as_str(), g.rotation_deg)).collect();
    assert_eq!(
        groups,
        [
            ("mlp", "eval_success_rate", 0.0),
            ("mlp, rotated 180°", "eval_success_rate_rot180", 180.0),
            ("shnn", "eval_success_rate", 0.0),
            ("shnn, rotated 180°", "eval_success_rate_rot180", 180.0),
        ]
    );
    assert!(close(r.groups[1].mean, 1.0) && close(r.groups[3].mean, 45.0), "{:?}", r.groups);
    assert_eq!(r.groups[3].curve.len(), 2);
    let csv = std::fs::read_to_string(&r.csv).unwrap();
    assert!(csv.lines().next().unwrap().ends_with(
        ",rotation_deg,lose_mean_pct,lose_se_pct,machine_hours,iqm_pct,iqm_ci_low_pct,iqm_ci_high_pct,\
         mean_ci_low_pct,mean_ci_high_pct"
    ));
    // Team Reach has no loss rate: the loss fields are empty. A rotated group is the same
    // runs: its machine time is 0, so that summing the column counts each run once.
    assert!(
        csv.lines().any(|l| l.contains("eval_success_rate_rot180") && l.ends_with(",180,,,0,45,42,48,42,48")),
        "{csv}"
    );
    assert!(close(r.groups[0].machine_hours, 0.5) && r.groups[1].machine_hours == 0.0);
    let svg = std::fs::read_to_string(&r.curves[0]).unwrap();
    assert!(svg.contains("shnn, rotated 180°") && svg.contains("mlp, rotated 180°"));
    // Runs that reached their budget show the steps alone.
    let md = std::fs::read_to_string(&r.markdown).unwrap();
    assert!(md.contains("| 2 | 45.00 ± 3.00 | 45.00 [42.00, 48.00] | [42.00, 48.00] | 200 | (same runs) |"), "{md}");
    assert!(md.contains("| 2 | 50.00 ± 10.00 | 50.00 [40.00, 60.00] | [40.00, 60.00] | 200 | 0.5 |"), "{md}");
    assert!(md.contains("Machine time: 1.0 h over the 4 runs above"), "{md}");
    assert!(md.lines().filter(|l| l.starts_with('|')).all(|l| !l.contains(" of ")), "{md}");
}

#[test]
fn report_counts_in_words_and_never_writes_negative_zero() {
    // The only run has no evaluation yet although it is set to evaluate: no result, so no
    // group; the machine time of no runs is 0.0, not the -0.0 of Rust's empty float sum.
    let tmp = TempDir::new("counts");
    let pending = tmp.0.join("pending/team_reach_1_ant/shnn/seed0");
    let cfg = TrainConfig { num_evals: 3, ..config("team_reach/1_ant", "shnn", 0) };
    write_run(&pending, &cfg, &[&[("env_steps", 1000.0), ("wall_s", 60.0), ("train_success_rate", 1.0)]]);
    let r = report(&tmp.0.join("pending")).unwrap();
    let md = std::fs::read_to_string(&r.markdown).unwrap();
    assert!(md.contains("0 runs in 0 groups.") && md.contains("Machine time: 0.0 h over the 0 runs above"), "{md}");
    assert!(!md.contains("-0.0"), "{md}");
    // One run, one group: singular.
    let one = tmp.0.join("one/team_reach_1_ant/shnn/seed0");
    write_run(&one, &cfg, &[&[("env_steps", 1000.0), ("wall_s", 3600.0), ("eval_success_rate", 0.5)]]);
    let md = std::fs::read_to_string(report(&tmp.0.join("one")).unwrap().markdown).unwrap();
    assert!(md.contains("1 run in 1 group.") && md.contains("Machine time: 1.0 h over the 1 run above"), "{md}");
}

#[test]
fn a_report_at_a_budget_values_every_run_by_its_last_evaluation_up_to_it() {
    // Two groups at different points: `mlp` finished at 3M env steps, `shnn` stopped at 2M.
    // At 2M env steps both are valued by their evaluation at 2M, the group rows say 2M
    // with no "of", and the whole runs' report is left as it was.
    let tmp = TempDir::new("at-steps");
    let root = &tmp.0;
    for (model, rows) in [("mlp", vec![(1e6, 0.1), (2e6, 0.2), (3e6, 0.9)]), ("shnn", vec![(1e6, 0.3), (2e6, 0.4)])] {
        let cfg = TrainConfig { steps: 3_000_000, num_evals: 3, ..config("team_reach/1_ant", model, 0) };
        let rows: Vec<Vec<(&'static str, f64)>> =
            rows.iter().map(|&(x, y)| vec![("env_steps", x), ("wall_s", x / 1e3), ("eval_success_rate", y)]).collect();
        let rows: Vec<&[(&'static str, f64)]> = rows.iter().map(|r| r.as_slice()).collect();
        write_run(&root.join(format!("team_reach_1_ant/{model}/seed0")), &cfg, &rows);
    }
    let whole = report(root).unwrap();
    let finals = |r: &rl::Report| r.groups.iter().map(|g| (g.model.clone(), g.finals.clone())).collect::<Vec<_>>();
    assert_eq!(finals(&whole), [("mlp".into(), vec![90.0]), ("shnn".into(), vec![40.0])]);
    let whole_md = std::fs::read_to_string(&whole.markdown).unwrap();

    let at = rl::report_at(root, Some(2_000_000)).unwrap();
    assert_eq!(at.dir, root.join("at_2000000"));
    let name = |n: &str| rl::app::report::at_steps_of(n);
    assert_eq!((name("at_2000000"), name("at_"), name("curves"), name("at_2M")), (Some(2_000_000), None, None, None));
    assert_eq!((at.markdown.clone(), at.csv.clone()), (at.dir.join("report.md"), at.dir.join("report.csv")));
    assert_eq!(finals(&at), [("mlp".into(), vec![20.0]), ("shnn".into(), vec![40.0])]);
    assert!(at.groups.iter().all(|g| g.env_steps == (2_000_000, 2_000_000) && g.target_steps == 2_000_000));
    let md = std::fs::read_to_string(&at.markdown).unwrap();
    assert!(
        md.contains("at 2000000 env steps") && md.lines().filter(|l| l.starts_with('|')).all(|l| !l.contains(" of "))
    );
    assert!(at.curves.iter().all(|c| c.starts_with(&at.dir) && c.is_file()));
    assert_eq!(std::fs::read_to_string(&whole.markdown).unwrap(), whole_md);
    // Before any evaluation, every run is pending; zero steps is refused by name.
    let early = rl::report_at(root, Some(500_000)).unwrap();
    assert!(early.groups.is_empty() && early.pending.len() == 2, "{:?}", early.pending);
    let e = rl::report_at(root, Some(0)).unwrap_err().to_string();
    assert!(e.contains("--at-steps") && e.contains("\"0\""), "{e}");

    // The program: `--at-steps` with `--paper` writes both tables under at_<N>/.
    let paper = root.join("paper.toml");
    std::fs::write(
        &paper,
        "seeds = 10\n[[figure]]\ntable = \"t\"\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nmean = 60.0\nsd = 3.0\n",
    )
    .unwrap();
    let (ok, _, err) =
        common::meben(&["report", root.to_str().unwrap(), "--at-steps", "1000000", "--paper", paper.to_str().unwrap()]);
    assert!(ok, "{err}");
    let table = std::fs::read_to_string(root.join("at_1000000/paper.md")).unwrap();
    assert!(
        table.contains("| `shnn` | random | success | 30.00 (one run) | – | 1 | 1M | 60.00 ± 3.00 | 10 |"),
        "{table}"
    );
}

#[test]
fn report_errors_name_the_directory_and_the_damaged_file() {
    let tmp = TempDir::new("errors");
    let msg = report(&tmp.0).unwrap_err().to_string();
    assert!(msg.contains("no run directories") && msg.contains(&tmp.0.display().to_string()), "{msg}");
    let missing = tmp.0.join("missing");
    assert!(report(&missing).unwrap_err().to_string().contains("not a directory"));
    // A damaged metrics file is named.
    let dir = tmp.0.join("run");
    write_run(&dir, &config("team_reach/1_ant", "shnn", 0), &[]);
    std::fs::write(dir.join("metrics.csv"), "iteration,env_steps\n1,x\n").unwrap();
    let msg = report(&tmp.0).unwrap_err().to_string();
    assert!(msg.contains("metrics.csv") && msg.contains("env_steps"), "{msg}");
}

#[test]
fn a_sweep_trains_every_run_and_the_report_groups_them_with_mean_and_se() {
    let tmp = TempDir::new("sweep");
    let text = r#"
envs = ["team_reach/1_ant", "team_sumo/2_ants"]
models = ["mlp_hn", "shnn:assignment=hungarian"]
seeds = [0, 1]
preset = "quick"
[[variants]]
name = "lr_high"
config = { learning_rate = 1e-3 }
"#;
    let sweep = Sweep::parse(text, "sweep.toml").unwrap();
    // The fake trainer's final success depends on the seed and the learning rate.
    let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, run| {
        let value = 0.1 * (c.seed + 1) as f64 + if c.learning_rate > 5e-4 { 0.5 } else { 0.0 };
        let column = if c.is_sumo() { "eval_win_rate_t0" } else { "eval_success_rate" };
        write_run(
            run.root(),
            c,
            &[&[("env_steps", 100.0), (column, value / 2.0)], &[("env_steps", 200.0), (column, value)]],
        );
        std::fs::write(run.done(), "{}").unwrap();
        Ok(RunSummary::default())
    })
    .unwrap();
    assert_eq!(outcome.trained, 16);
    let r = report(&tmp.0).unwrap();
    assert_eq!(r.groups.len(), 8);
    assert!(r.groups.iter().all(|g| g.runs.len() == 2));
    let g =
        r.groups.iter().find(|g| g.label == "shnn_assignment-hungarian+lr_high" && !g.env.contains("sumo")).unwrap();
    assert_eq!(g.model, "shnn:assignment=hungarian");
    assert!(close(g.mean, 65.0) && close(g.se, 5.0), "{} {}", g.mean, g.se);
    assert!(tmp.0.join("sweep.toml").is_file());
}
