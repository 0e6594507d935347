//! Evaluation of moved scenes (`EvalOptions::rotation_deg`, `translation`; `meben eval
//! --rotate --translate`; `eval_rotations`): a rotated and translated start is the moved
//! scene (observations rotated and translated, balls included), an invariant policy plays it
//! as it plays the unmoved one, and periodic evaluation at several rotations writes one set
//! of metrics columns per rotation, resumed exactly.

use crate::common;

use envs::layout::Observation;
use envs::tasks::StartMode;
use rl::Team;
use rl::mappo::actor::{ActMode, Actor, JointAction};
use rl::mappo::evaluate::{EvalOptions, episode_start, eval_envs};
use rl::{RunDir, TrainOptions, train};

/// Largest deviation of `moved` from `base` rotated by `deg` about the vertical through the
/// origin and translated by `t`: positions, velocities, angular velocities, headings (mod 2
/// pi), and scalars (unchanged).
fn motion_error(base: &Observation, moved: &Observation, deg: f64, t: [f64; 2]) -> f64 {
    let (s, c) = deg.to_radians().sin_cos();
    let mut err = 0.0f64;
    for (i, (a, b)) in base.vectors.chunks_exact(3).zip(moved.vectors.chunks_exact(3)).enumerate() {
        let (x, y, z) = (a[0] as f64, a[1] as f64, a[2] as f64);
        let shift = if i % 3 == 0 { t } else { [0.0, 0.0] };
        let want = [c * x - s * y + shift[0], s * x + c * y + shift[1], z];
        for k in 0..3 {
            err = err.max((b[k] as f64 - want[k]).abs());
        }
    }
    for (a, b) in base.heading.iter().zip(&moved.heading) {
        let d = (*b as f64 - *a as f64 - deg.to_radians()).rem_euclid(std::f64::consts::TAU);
        err = err.max(d.min(std::f64::consts::TAU - d));
    }
    for (a, b) in base.scalars.iter().zip(&moved.scalars) {
        err = err.max((a - b).abs() as f64);
    }
    err
}

#[test]
fn moved_starts_are_the_moved_scenes() {
    for (env, mode) in [
        ("team_reach/2_ants", StartMode::fixed(4)),
        ("team_reach/2_ants", StartMode::Random),
        ("team_sumo/2_ants", StartMode::fixed(4)),
    ] {
        let plain = EvalOptions::new(3, true, 7, mode);
        let moved = EvalOptions { rotation_deg: 135.0, translation: [2.5, -1.25], ..plain };
        let (a, b) = (eval_envs(env, &plain).unwrap(), eval_envs(env, &moved).unwrap());
        assert_eq!(a.obs().scalars, b.obs().scalars);
        for e in 0..3 {
            // The balls (goal balls, Sumo's centre ball) move with the agents.
            let m = moved.motion();
            let want: Vec<[f64; 2]> = a.balls(e).unwrap().iter().map(|&p| m.apply_xy(p)).collect();
            for (p, q) in want.iter().zip(b.balls(e).unwrap()) {
                assert!((p[0] - q[0]).abs() < 1e-12 && (p[1] - q[1]).abs() < 1e-12, "{env}: ball {p:?} vs {q:?}");
            }
            assert_eq!(episode_start(a.scene(), &moved, e), m.apply(&episode_start(a.scene(), &plain, e)));
        }
        // f32 observations of positions of a few metres: round-off below 1e-5.
        let err = motion_error(a.obs(), b.obs(), 135.0, [2.5, -1.25]);
        assert!(err < 1e-5, "{env} {mode:?}: {err}");
        // The test can fail: another translation is not this one.
        assert!(motion_error(a.obs(), b.obs(), 135.0, [2.5, -1.0]) > 0.2);
    }
    // Non-finite motions are refused.
    let bad = EvalOptions { translation: [f64::NAN, 0.0], ..EvalOptions::new(1, true, 0, StartMode::Random) };
    let e = eval_envs("team_reach/2_ants", &bad).unwrap_err().to_string();
    assert!(e.contains("translation") && e.contains("finite"), "{e}");
}

#[test]
fn an_invariant_policy_plays_the_moved_scene_as_the_unmoved_one() {
    let config = common::tiny("team_reach/2_ants", "mlp_hn", 1, &[]);
    let spec = envs::tasks::Scene::from_name(&config.env).unwrap().obs_spec;
    let mut team = Team::build(&config, &spec, 0).unwrap();
    // A normaliser with statistics of a few steps.
    let plain = EvalOptions::new(2, true, 3, StartMode::fixed(5));
    let moved = EvalOptions { rotation_deg: -100.0, translation: [-3.0, 4.0], ..plain };
    let (mut a, mut b) = (eval_envs(&config.env, &plain).unwrap(), eval_envs(&config.env, &moved).unwrap());
    let na = a.n_actions();
    let mut warm = eval_envs(&config.env, &plain).unwrap();
    for k in 0..20 {
        team.norm.update(&warm.obs().vectors, &warm.obs().scalars);
        warm.step(&vec![if k % 2 == 0 { 0.7 } else { -0.4 }; 2 * na]).unwrap();
    }
    let mut actor = Actor::new(ActMode::Mean, Vec::new());
    let mut actions = |team: &mut Team, o: &Observation| {
        let mut joint = JointAction::new(2, na, 1);
        actor.act(team.model.as_mut(), &team.store, &team.norm, o.rows(), &mut joint).unwrap();
        joint.actions
    };
    // f32 observations and policy: the two scenes differ by round-off (about 1e-7 of a few
    // metres, radians or metres per second), which contacts amplify a little; measured over 40
    // steps: actions 1.0e-6, observations 1.4e-5. A wrong motion (e.g. balls left behind)
    // would move the normalised inputs, and the actions, by far more.
    for step in 0..40 {
        let (xa, xb) = (actions(&mut team, a.obs()), actions(&mut team, b.obs()));
        let d = xa.iter().zip(&xb).map(|(p, q)| (p - q).abs() as f64).fold(0.0, f64::max);
        let e = motion_error(a.obs(), b.obs(), -100.0, [-3.0, 4.0]);
        assert!(d < 1e-4 && e < 1e-3, "step {step}: actions differ by {d}, observations by {e}");
        a.step(&xa).unwrap();
        b.step(&xb).unwrap();
    }
    // Whole episodes: the same outcomes and lengths, returns equal but for round-off (measured
    // relative difference 2e-5 over 1000 steps; the distance reward would show a ball left
    // behind at once).
    let teams = [team];
    let sa = rl::evaluate(&config.env, &teams, &plain).unwrap();
    let sb = rl::evaluate(&config.env, &teams, &moved).unwrap();
    assert_eq!((sa.success_rate, sa.mean_length), (sb.success_rate, sb.mean_length));
    let r = (sa.mean_return[0] - sb.mean_return[0]).abs() / sa.mean_return[0].abs();
    assert!(r < 1e-3, "returns {:?} and {:?}", sa.mean_return, sb.mean_return);
    assert_eq!((sb.rotation_deg, sb.translation), (-100.0, [-3.0, 4.0]));
}

#[test]
fn periodic_evaluation_at_several_rotations_has_its_columns_and_resumes_exactly() {
    let tmp = common::TempDir::new("eval-rotations");
    let dir = tmp.0.clone();
    let config = common::tiny(
        "team_reach/1_ant",
        "mlp_hn",
        2,
        &[
            ("fixed_start", "true"),
            ("eval_rotations", "[0.0, 180.0]"),
            ("num_evals", "2"),
            ("eval_deterministic", "false"),
        ],
    );
    let run = RunDir::new(dir.join("run"));
    let s = train(&config, &run, &TrainOptions::default()).unwrap();
    let text = std::fs::read_to_string(run.metrics()).unwrap();
    let rows = rl::app::record::MetricsTable::parse(&text).unwrap().rows;
    assert_eq!(rows.len(), 2);
    for r in &rows {
        assert_eq!(r.eval_sampled, Some(true));
        assert_eq!(r.eval(0.0).unwrap().episodes, Some(2));
        assert_eq!(r.eval(180.0).unwrap().episodes, Some(2));
        assert!(r.get("eval_success_rate").is_some() && r.get("eval_success_rate_rot180").is_some());
    }
    let e = s.final_eval.as_ref().unwrap();
    assert!(e.sampled && e.rotation_deg == 0.0);
    assert_eq!(s.final_eval_rotated.len(), 1);
    assert_eq!(s.final_eval_rotated[0].rotation_deg, 180.0);
    let done: rl::RunSummary = serde_json::from_str(&std::fs::read_to_string(run.done()).unwrap()).unwrap();
    assert_eq!(done, s);
    let svg = std::fs::read_to_string(run.curve()).unwrap();
    assert!(svg.contains("rotated 180°"), "no rotated series in the run's curve");
    // Stopped after the first iteration (and evaluation) and resumed: the same file and
    // summary (the checkpoint keeps the rotated evaluations).
    let parts = RunDir::new(dir.join("parts"));
    train(&config, &parts, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    let resumed = train(&config, &parts, &TrainOptions::default()).unwrap();
    let strip = |text: &str| -> Vec<Vec<(String, f64)>> {
        let rows = rl::app::record::MetricsTable::parse(text).unwrap().rows;
        rows.iter()
            .map(|r| r.cells().into_iter().filter(|(k, _)| k != "wall_s" && k != "steps_per_s").collect())
            .collect()
    };
    assert_eq!(strip(&std::fs::read_to_string(parts.metrics()).unwrap()), strip(&text));
    assert_eq!((resumed.final_eval, resumed.final_eval_rotated), (s.final_eval.clone(), s.final_eval_rotated.clone()));
}
