//! `shnn:assignment=learned` and `mlp_hn:assignment=learned` trained by PPO: a short training
//! has finite metrics and the same rows on 1 and 2 threads; an update moves the scorer's parameters (the gradient reaches them
//! through the PPO loss); deterministic evaluation takes the most likely assignment. (Resumed
//! runs: `resume.rs`; the stored assignment's ratio 1: `ppo_loss.rs`.)

use crate::common;

use common::metrics;
use rl::mappo::actor::ActMode;
use rl::mappo::checkpoint::Checkpoint;
use rl::mappo::evaluate::evaluation_actors;
use rl::{RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::Tape;

/// The models that learn their assignment: the SHNN family's and the release's MLP's.
const MODELS: [&str; 2] = ["shnn:assignment=learned", "mlp_hn:assignment=learned"];

/// `iterations` of 80 steps of 16 environments of Team Reach with two ants.
fn config(model: &str, iterations: u64, threads: usize) -> TrainConfig {
    let mut c = common::tiny("team_reach/2_ants", model, iterations, &[]);
    c.num_envs = 16;
    c.threads = threads;
    c
}

fn params(run: &RunDir) -> Vec<Vec<f64>> {
    let c = Checkpoint::load(&run.checkpoint()).unwrap();
    c.teams.iter().flat_map(|t| t.params.tensors.iter().map(|x| x.data.clone())).collect()
}

#[test]
fn a_learned_assignment_trains_with_finite_metrics_the_same_on_1_and_2_threads() {
    let tmp = common::TempDir::new("learned-threads");
    for model in MODELS {
        let mut rows = Vec::new();
        let mut trained = Vec::new();
        for threads in [1, 2] {
            let run = RunDir::new(tmp.0.join(format!("{}-t{threads}", model.replace([':', '='], "-"))));
            let s = train(&config(model, 25, threads), &run, &TrainOptions::default()).unwrap();
            assert_eq!((s.iterations, s.env_steps), (25, 2000));
            let m = metrics(&run);
            assert_eq!(m.len(), 25);
            for row in &m {
                for (k, v) in row {
                    assert!(v.is_finite(), "{model}, {threads} threads: {k} = {v}");
                }
                let entropy = row.iter().find(|(k, _)| k == "entropy_t0").unwrap().1;
                assert!(entropy != 0.0, "{model}: {row:?}");
            }
            rows.push(m);
            trained.push(params(&run));
        }
        assert_eq!(rows[0], rows[1], "{model}: metrics differ between 1 and 2 threads");
        assert_eq!(trained[0], trained[1], "{model}: parameters differ between 1 and 2 threads");
    }
}

/// One iteration's updates change every weight of the scorer: the gradient of the PPO loss
/// reaches it through the assignment's log-probability (the ratio) and entropy (the bonus).
/// (The last layer's bias shifts every score of an object alike, which the distribution
/// ignores: its gradient is 0.)
#[test]
fn an_update_moves_the_scorers_parameters() {
    for model in MODELS {
        let mut t = Trainer::new(&config(model, 2, 1)).unwrap();
        let scorer = |t: &Trainer| -> Vec<(String, Vec<f32>)> {
            let s = &t.teams[0].store;
            s.iter().filter(|(n, _)| n.starts_with("team0.assign.")).map(|(n, x)| (n.to_string(), x.to_vec())).collect()
        };
        let before = scorer(&t);
        assert!(before.len() >= 4, "{model}: {before:?}");
        t.iterate().unwrap();
        let after = scorer(&t);
        for ((name, b), (_, a)) in before.iter().zip(&after) {
            if name.ends_with("weight") {
                assert_ne!(a, b, "{model}: {name} did not move");
            }
        }
        // The other parameters move too, and the rollout kept the drawn assignments.
        assert!(!t.rollout().visited_obs().is_empty());
    }
}

/// Deterministic evaluation acts on the most likely assignment (the same whatever the
/// evaluation's stream); sampled evaluation draws from the stream.
#[test]
fn deterministic_evaluation_takes_the_most_likely_assignment() {
    for model in MODELS {
        let t = Trainer::new(&config(model, 1, 1)).unwrap();
        let obs = t.env.obs().clone();
        let mut norm_rows = envs::layout::Observation::empty(0, 0);
        t.teams[0].norm.apply_rows(obs.rows(), &mut norm_rows);
        let assignment = |seed: u64, mode: ActMode| {
            let (mut model, _) = evaluation_actors(&t.teams, seed, mode).remove(0);
            let tape = Tape::<f32>::new();
            let _no_grad = tape.no_grad();
            let p = t.teams[0].store.bind(&tape);
            let out = model.forward(&p, &norm_rows.rows(), None, false).unwrap();
            assert!(out.assignment_terms.is_some());
            out.assignment
        };
        let best = assignment(1, ActMode::Mean);
        assert_eq!(best.len(), 16 * 2, "{model}");
        for seed in 2..5 {
            assert_eq!(assignment(seed, ActMode::Mean), best, "{model}");
        }
        let drawn: Vec<Vec<u32>> = (1..5).map(|s| assignment(s, ActMode::Sample)).collect();
        assert!(drawn.iter().any(|d| *d != drawn[0]), "{model}: sampled evaluations drew the same assignments");
    }
}
