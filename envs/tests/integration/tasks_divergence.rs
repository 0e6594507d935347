//! A step whose state leaves what the f32 observations can hold is reported as
//! [`Outcome::Diverged`] at that step (issue 44 item 4): an MJCF ant with `gear="1000000"`,
//! `damping="0"` and `armature="0"` (each inside `envs/src/limits.rs`) returned observations
//! of +-infinity with outcome `Running`, and `Diverged` came one step later (the f64 state
//! was still finite; only its conversion to f32 overflowed).

use envs::tasks::outcome::Outcome;
use envs::tasks::{StartMode, VecEnv};

const ANT_XML: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/ant.xml");

/// The test ant with the strongest motors and no damping or armature the limits accept,
/// written to a temporary file (removed when dropped).
struct WildAnt(std::path::PathBuf);

impl WildAnt {
    fn new() -> WildAnt {
        let text = std::fs::read_to_string(ANT_XML)
            .unwrap()
            .replace("armature=\"0.35\" damping=\"35\"", "armature=\"0\" damping=\"0\"")
            .replace("gear=\"350\"", "gear=\"1000000\"");
        assert!(text.contains("gear=\"1000000\"") && text.contains("armature=\"0\" damping=\"0\" limited=\"true\""));
        let path = std::env::temp_dir().join(format!("meben-wild-ant-{}.xml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        WildAnt(path)
    }
}

impl Drop for WildAnt {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Whether every value of environment `e`'s observation row is finite.
fn row_finite(o: &envs::layout::Observation, e: usize) -> bool {
    let (v, s, h) = (o.vectors.len() / o.batch, o.scalars.len() / o.batch, o.heading.len() / o.batch);
    o.vectors[e * v..(e + 1) * v]
        .iter()
        .chain(&o.scalars[e * s..(e + 1) * s])
        .chain(&o.heading[e * h..(e + 1) * h])
        .all(|x| x.is_finite())
}

#[test]
fn a_step_that_leaves_f32_is_diverged_at_that_step() {
    let ant = WildAnt::new();
    let name = format!("team_reach:agents={};R=3", ant.0.display());
    let batch = 4;
    let mut env = VecEnv::from_name(&name, batch, 7, StartMode::Random).unwrap();
    let na = env.n_actions();
    // Full torque, alternating in sign every step: the limbs are whipped about at 1e6 N m.
    let mut diverged = 0;
    for t in 0..200 {
        let sign = if t % 2 == 0 { 1.0 } else { -1.0 };
        let actions: Vec<f32> = (0..batch * na).map(|i| if i % 2 == 0 { sign } else { -sign }).collect();
        let out = env.step(&actions).unwrap().clone();
        for e in 0..batch {
            let ended = out.terminated[e] || out.truncated[e];
            let seen = if ended { &out.final_obs } else { &out.obs };
            if !row_finite(seen, e) {
                assert_eq!(
                    out.outcome[e],
                    Outcome::Diverged,
                    "step {t}, environment {e}: a non-finite observation reported as {:?}",
                    out.outcome[e]
                );
            }
            if out.outcome[e] == Outcome::Diverged {
                assert!(out.terminated[e] && !out.truncated[e]);
                assert!(out.reward[e..e + 1].iter().all(|r| *r == 0.0));
                // The environment begins a fresh, finite episode.
                assert!(row_finite(&out.obs, e), "step {t}, environment {e}: the next episode's start");
                diverged += 1;
            }
            assert!(out.reward.iter().all(|r| r.is_finite()), "step {t}: rewards {:?}", out.reward);
        }
    }
    assert!(diverged > 0, "the wild ant never diverged: the test shows nothing");
}
