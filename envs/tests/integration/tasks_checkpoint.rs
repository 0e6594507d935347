//! Exact checkpoints of `VecEnv`: a snapshot, through JSON and back, restored into an
//! environment built with another seed, continues bit for bit (across episode ends and
//! auto-resets, fixed start modes, the curriculum factor); bad states are refused with the
//! field named and nothing changed.

use envs::layout::Observation;
use envs::tasks::{StartMode, StepOutput, TaskError, TaskSpec, VecEnv, VecEnvState};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_actions(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0f32..1.0)).collect()
}

fn spec(name: &str, episode_steps: usize) -> TaskSpec {
    TaskSpec { episode_steps, ..TaskSpec::from_name(name).unwrap() }
}

fn bits(x: &[f32]) -> Vec<u32> {
    x.iter().map(|v| v.to_bits()).collect()
}

fn row(o: &Observation, e: usize) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let (v, s, h) = (o.vectors.len() / o.batch, o.scalars.len() / o.batch, o.heading.len() / o.batch);
    (bits(&o.vectors[e * v..(e + 1) * v]), bits(&o.scalars[e * s..(e + 1) * s]), bits(&o.heading[e * h..(e + 1) * h]))
}

fn assert_same_obs(a: &Observation, b: &Observation, what: &str) {
    assert_eq!((a.batch, a.nodes, a.agents), (b.batch, b.nodes, b.agents), "{what}");
    assert!(bits(&a.vectors) == bits(&b.vectors), "{what}: obs vectors differ");
    assert!(bits(&a.scalars) == bits(&b.scalars), "{what}: obs scalars differ");
    assert!(bits(&a.heading) == bits(&b.heading), "{what}: obs headings differ");
}

/// Every field of two step outputs, bit for bit (`final_obs` on the rows whose episode ended).
fn assert_same_output(a: &StepOutput, b: &StepOutput, what: &str) {
    assert_same_obs(&a.obs, &b.obs, what);
    assert!(bits(&a.reward) == bits(&b.reward), "{what}: rewards differ");
    assert_eq!(a.terminated, b.terminated, "{what}: terminated");
    assert_eq!(a.truncated, b.truncated, "{what}: truncated");
    assert_eq!(a.outcome, b.outcome, "{what}: outcome");
    assert_eq!(a.episode_len, b.episode_len, "{what}: episode_len");
    for e in 0..a.terminated.len() {
        if a.terminated[e] || a.truncated[e] {
            assert!(row(&a.final_obs, e) == row(&b.final_obs, e), "{what}: final_obs of env {e}");
        }
    }
}

struct Case {
    name: &'static str,
    episode_steps: usize,
    steps_before: usize,
    mode: StartMode,
    alpha: f64,
}

/// Steps env A `steps_before` steps, snapshots it through JSON into env B (another seed,
/// random starts, alpha 1), then steps both with the same 40 actions. Returns how many
/// episodes ended after the restore.
fn resume_case(c: &Case) -> usize {
    let batch = 8;
    let s = spec(c.name, c.episode_steps);
    let mut a = VecEnv::new(&s, batch, 11, c.mode).unwrap();
    a.set_curriculum_alpha(c.alpha).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let n = batch * a.n_actions();
    for _ in 0..c.steps_before {
        a.step(&random_actions(&mut rng, n)).unwrap();
    }
    let state = a.snapshot();
    let json = serde_json::to_string(&state).unwrap();
    let back: VecEnvState = serde_json::from_str(&json).unwrap();
    assert_eq!(back, state, "{}: JSON round trip", c.name);
    assert_eq!(VecEnvState::from_json(&state.to_json().unwrap()).unwrap(), state);

    let mut b = VecEnv::new(&s, batch, 12345, StartMode::Random).unwrap();
    assert!(bits(&b.obs().vectors) != bits(&a.obs().vectors), "{}: the other seed starts elsewhere", c.name);
    b.restore(&back).unwrap();
    assert_same_obs(a.obs(), b.obs(), &format!("{} right after restore", c.name));
    assert_same_output(a.output(), b.output(), &format!("{} output after restore", c.name));
    assert_eq!(b.snapshot(), state, "{}: snapshot of the restored env", c.name);
    assert_eq!(b.curriculum_alpha(), c.alpha);
    assert_eq!(b.start_mode(), c.mode);

    let mut ended = 0;
    for k in 0..40 {
        let act = random_actions(&mut rng, n);
        let oa = a.step(&act).unwrap().clone();
        let ob = b.step(&act).unwrap();
        assert_same_output(&oa, ob, &format!("{} step {} after restore", c.name, k + 1));
        ended += oa.terminated.iter().zip(&oa.truncated).filter(|(t, u)| **t || **u).count();
    }
    for e in 0..batch {
        let (da, db) = (a.data(e).unwrap(), b.data(e).unwrap());
        assert!(da.qpos.iter().zip(&db.qpos).all(|(x, y)| x.to_bits() == y.to_bits()), "{}: qpos of env {e}", c.name);
        assert_eq!(a.balls(e), b.balls(e));
    }
    ended
}

#[test]
fn a_restored_env_continues_bit_for_bit_mid_episode() {
    for name in ["team_reach/1_ant", "team_sumo/2_ants"] {
        resume_case(&Case { name, episode_steps: 1000, steps_before: 30, mode: StartMode::Random, alpha: 1.0 });
    }
}

#[test]
fn a_restored_env_draws_the_same_starts_when_episodes_end() {
    for name in ["team_reach/1_ant", "team_sumo/2_ants"] {
        // Snapshot mid-episode (step 10 of the second episode): episodes end 10 and 30 steps
        // after the restore, and the new starts come from the restored random streams.
        let ended =
            resume_case(&Case { name, episode_steps: 20, steps_before: 30, mode: StartMode::Random, alpha: 1.0 });
        assert!(ended >= 16, "{name}: {ended} episodes ended after the restore");
        // Snapshot at the very step the episodes ended: final_obs rows are carried too.
        resume_case(&Case { name, episode_steps: 20, steps_before: 20, mode: StartMode::Random, alpha: 1.0 });
    }
    // The release's reset: the restored streams give each environment its first start again.
    resume_case(&Case {
        name: "team_reach/2_ants",
        episode_steps: 20,
        steps_before: 30,
        mode: StartMode::PerSlot,
        alpha: 1.0,
    });
    // A fixed start mode and a curriculum factor come with the state.
    resume_case(&Case {
        name: "team_sumo/2_ants",
        episode_steps: 20,
        steps_before: 27,
        mode: StartMode::fixed_rotated(3, 0.7, [0.5, -0.25]),
        alpha: 0.25,
    });
}

#[test]
fn the_warm_starts_matter_so_the_test_would_see_them_missing() {
    // Ants on the ground in contact: dropping the solver's warm starts from the state changes
    // the future, so the bit-identity above depends on saving them.
    let s = spec("team_sumo/2_ants", 1000);
    let mut a = VecEnv::new(&s, 4, 5, StartMode::Random).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let n = 4 * a.n_actions();
    for _ in 0..15 {
        a.step(&random_actions(&mut rng, n)).unwrap();
    }
    let mut state = a.snapshot();
    assert!(state.envs.iter().all(|e| !e.physics.warm_contacts.is_empty()), "feet on the ground");
    for e in &mut state.envs {
        e.physics.warm_contacts.clear();
        e.physics.warm_limit.iter_mut().for_each(|w| *w = 0.0);
    }
    let mut b = VecEnv::new(&s, 4, 6, StartMode::Random).unwrap();
    b.restore(&state).unwrap();
    let act = random_actions(&mut rng, n);
    let (oa, ob) = (a.step(&act).unwrap().clone(), b.step(&act).unwrap());
    assert!(bits(&oa.obs.vectors) != bits(&ob.obs.vectors));
}

#[test]
fn f64_and_f32_round_trip_exactly_through_serde_json() {
    // Values where serde_json's default float parser (without `float_roundtrip`) is one ulp
    // off, plus extremes and signed zero.
    let xs = [-3.8709225839311924e-5, -1.490143767845386e129, 2.4006794711171763e-7, 0.1, -0.0, 5e-324, f64::MAX];
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let many: Vec<f64> = (0..20000)
        .map(|i| {
            let u: f64 = rng.random_range(-1.0..1.0);
            u * 10f64.powi(i % 25 - 12)
        })
        .chain(xs)
        .collect();
    let back: Vec<f64> = serde_json::from_str(&serde_json::to_string(&many).unwrap()).unwrap();
    assert!(many.iter().zip(&back).all(|(x, y)| x.to_bits() == y.to_bits()));
    let f: Vec<f32> = many.iter().map(|&x| x as f32).filter(|x| x.is_finite()).collect();
    let back: Vec<f32> = serde_json::from_str(&serde_json::to_string(&f).unwrap()).unwrap();
    assert!(f.iter().zip(&back).all(|(x, y)| x.to_bits() == y.to_bits()));
}

fn expect_bad(r: Result<(), TaskError>, field: &str) -> String {
    match r {
        Err(TaskError::BadArgument { what, value, message }) => {
            assert!(what.contains(field), "expected the field {field:?} in {what:?} ({value}: {message})");
            format!("bad {what} = {value}: {message}")
        }
        other => panic!("expected BadArgument about {field}, got {other:?}"),
    }
}

#[test]
fn mismatched_or_damaged_states_are_refused_and_change_nothing() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut reach = VecEnv::from_name("team_reach/1_ant", 4, 1, StartMode::Random).unwrap();
    for _ in 0..5 {
        let a = random_actions(&mut rng, 4 * reach.n_actions());
        reach.step(&a).unwrap();
    }
    let good = reach.snapshot();

    let mut sumo = VecEnv::from_name("team_sumo/2_ants", 4, 1, StartMode::Random).unwrap();
    let before = sumo.snapshot();
    let msg = expect_bad(sumo.restore(&good), "scene");
    assert!(msg.contains("team_reach/1_ant") && msg.contains("team_sumo/2_ants"), "{msg}");
    assert_eq!(sumo.snapshot(), before);

    let mut other_batch = VecEnv::from_name("team_reach/1_ant", 5, 1, StartMode::Random).unwrap();
    let msg = expect_bad(other_batch.restore(&good), "batch");
    assert!(msg.contains('4') && msg.contains('5'), "{msg}");
    let mut short = VecEnv::new(&spec("team_reach/1_ant", 20), 4, 1, StartMode::Random).unwrap();
    expect_bad(short.restore(&good), "spec.episode_steps");

    let mut target = VecEnv::from_name("team_reach/1_ant", 4, 2, StartMode::Random).unwrap();
    let before = target.snapshot();
    let damaged = |f: &dyn Fn(&mut VecEnvState)| {
        let mut s = good.clone();
        f(&mut s);
        s
    };
    let cases: Vec<(VecEnvState, &str)> = vec![
        (damaged(&|s| s.version = 99), "version"),
        (damaged(&|s| s.batch = 3), "batch"),
        (damaged(&|s| s.spec.radius = 4.0), "spec.radius"),
        (damaged(&|s| s.envs.truncate(3)), "envs length"),
        (damaged(&|s| s.alpha = 2.0), "alpha"),
        (damaged(&|s| s.mode = StartMode::fixed_rotated(1, f64::NAN, [0.0; 2])), "fixed start"),
        (
            damaged(&|s| {
                s.envs[3].physics.qpos.pop();
            }),
            "envs[3].physics.qpos",
        ),
        (damaged(&|s| s.envs[2].physics.qvel.push(0.0)), "envs[2].physics.qvel"),
        (damaged(&|s| s.envs[1].physics.ctrl.clear()), "envs[1].physics.ctrl"),
        (damaged(&|s| s.envs[1].physics.qfrc_applied.clear()), "envs[1].physics.qfrc_applied"),
        (damaged(&|s| s.envs[0].physics.warm_limit.push(0.0)), "envs[0].physics.warm_limit"),
        (damaged(&|s| s.envs[0].physics.warm_contacts[0].slot = 1 << 40), "envs[0].physics.warm_contacts[0].slot"),
        (damaged(&|s| s.envs[2].balls.push([0.0; 2])), "envs[2].balls"),
        (damaged(&|s| s.envs[2].step = usize::MAX), "envs[2].step"),
        (
            damaged(&|s| {
                s.last.reward.pop();
            }),
            "last.reward",
        ),
        (damaged(&|s| s.last.outcome.push(Default::default())), "last.outcome"),
        (
            damaged(&|s| {
                s.last.final_obs.push(envs::tasks::vec_env::FinalObsRow {
                    env: 9,
                    vectors: vec![],
                    scalars: vec![],
                    heading: vec![],
                })
            }),
            "final_obs",
        ),
    ];
    for (state, field) in &cases {
        expect_bad(target.restore(state), field);
        assert_eq!(target.snapshot(), before, "restore of a bad state ({field}) changed the env");
    }
    target.restore(&good).unwrap();
    assert_eq!(target.snapshot(), good);
}

#[test]
fn json_refuses_non_finite_numbers_and_reports_bad_text() {
    let env = VecEnv::from_name("team_reach/1_ant", 2, 1, StartMode::Random).unwrap();
    let mut state = env.snapshot();
    state.envs[1].physics.qvel[4] = f64::NAN;
    match state.to_json() {
        Err(TaskError::BadArgument { value, .. }) => assert_eq!(value, "envs[1].physics.qvel[4]"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(VecEnvState::from_json("{\"version\": 1"), Err(TaskError::BadArgument { .. })));
    assert!(matches!(VecEnvState::from_json("[]"), Err(TaskError::BadArgument { .. })));
}
