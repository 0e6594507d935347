//! A learned task assignment's warm-up (`assignment_warmup_steps`, TRAINING.md): until `W`
//! env steps the run is the greedy model's run to the bit (its every parameter but the
//! scorer's, its metrics and its evaluations) and the scorer does not move; from the first
//! iteration at or past `W` the scorer's draws act and it learns; a run resumed across `W`
//! is the uninterrupted run; a checkpoint or policy file taken in the warm-up acts as the run
//! did then.

use crate::common;

use common::metrics;
use rl::app::policy_file::{export_policy, load_policy};
use rl::app::run_dir::load_policies;
use rl::{RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::Tape;

/// Each learned model and its greedy counterpart (the paper's Algorithm 1).
const PAIRS: [(&str, &str); 2] = [("shnn:assignment=learned", "shnn"), ("mlp_hn:assignment=learned", "mlp_hn")];

/// Env steps of one iteration of [`config`].
const ITERATION: u64 = 80;

/// `iterations` of 80 steps of 16 environments of Team Reach with two ants, the warm-up
/// `warmup` iterations long (0: none).
fn config(model: &str, iterations: u64, warmup: u64) -> TrainConfig {
    let mut c = common::tiny("team_reach/2_ants", model, iterations, &[]);
    c.num_envs = 16;
    c.threads = 1;
    if warmup > 0 {
        c.assignment_warmup_steps = warmup * ITERATION;
    }
    c
}

/// Every parameter of `t`'s team 0 by name, but the scorer's (`assign.`).
fn shared_params(t: &Trainer) -> Vec<(String, Vec<f32>)> {
    let s = &t.teams[0].store;
    s.iter().filter(|(n, _)| !n.contains(".assign.")).map(|(n, x)| (n.to_string(), x.to_vec())).collect()
}

/// The scorer's parameters of `t`'s team 0.
fn scorer(t: &Trainer) -> Vec<Vec<f32>> {
    t.teams[0].store.iter().filter(|(n, _)| n.contains(".assign.")).map(|(_, x)| x.to_vec()).collect()
}

#[test]
fn in_its_warmup_a_learned_assignment_trains_as_the_greedy_model_and_its_scorer_waits() {
    for (learned, greedy) in PAIRS {
        let mut l = Trainer::new(&config(learned, 5, 2)).unwrap();
        let mut g = Trainer::new(&config(greedy, 5, 0)).unwrap();
        let start = scorer(&l);
        assert!(!start.is_empty(), "{learned}");
        assert_eq!(shared_params(&l), shared_params(&g), "{learned}: the other parameters start as {greedy}'s");
        for i in 0..2 {
            let (sl, sg) = (l.iterate().unwrap(), g.iterate().unwrap());
            assert_eq!(sl.losses, sg.losses, "{learned}, warm-up iteration {i}: losses");
            assert_eq!(sl.episodes, sg.episodes, "{learned}, warm-up iteration {i}: episodes");
            assert_eq!(shared_params(&l), shared_params(&g), "{learned}, warm-up iteration {i}: parameters");
            assert_eq!(scorer(&l), start, "{learned}, warm-up iteration {i}: the scorer moved");
        }
        // The warm-up's last iteration ends at W: the evaluation after it is the learned
        // policy's, whose draws differ from Algorithm 1's.
        assert_eq!(l.env_steps, 2 * ITERATION);
        let options = rl::mappo::evaluate::EvalOptions::new(8, false, 11, l.config.start_mode());
        let (el, eg) = (l.evaluate(&options).unwrap(), g.evaluate(&options).unwrap());
        assert_ne!(el, eg, "{learned}: the evaluation at W acted as {greedy}");
        // From W on the scorer's draws act: the stats and parameters part, the scorer learns.
        let (sl, sg) = (l.iterate().unwrap(), g.iterate().unwrap());
        assert_ne!(sl.losses, sg.losses, "{learned}: the first iteration after the warm-up trained as {greedy}");
        assert_ne!(shared_params(&l), shared_params(&g), "{learned}");
        assert_ne!(scorer(&l), start, "{learned}: the scorer did not move after the warm-up");
    }
}

/// Evaluations in the warm-up are the greedy model's, sampled and mean actions alike.
#[test]
fn evaluations_in_the_warmup_are_the_greedy_models() {
    for (learned, greedy) in PAIRS {
        let mut l = Trainer::new(&config(learned, 3, 3)).unwrap();
        let mut g = Trainer::new(&config(greedy, 3, 0)).unwrap();
        l.iterate().unwrap();
        g.iterate().unwrap();
        for deterministic in [false, true] {
            let options = rl::mappo::evaluate::EvalOptions::new(8, deterministic, 5, l.config.start_mode());
            assert_eq!(l.evaluate(&options).unwrap(), g.evaluate(&options).unwrap(), "{learned}, {deterministic}");
        }
    }
}

/// A run resumed in its warm-up and again after it has the uninterrupted run's rows and
/// parameters; its checkpoints, run directory and policy file act as the run did at their
/// env steps.
#[test]
fn resumed_runs_cross_the_warmup_exactly_and_checkpoints_keep_its_state() {
    let tmp = common::TempDir::new("assignment-warmup");
    let (learned, _) = PAIRS[1];
    let whole = RunDir::new(tmp.0.join("whole"));
    let config = config(learned, 5, 2);
    train(&config, &whole, &TrainOptions::default()).unwrap();
    let parts = RunDir::new(tmp.0.join("parts"));
    let in_warmup = tmp.0.join("in-warmup.safetensors");
    let after = tmp.0.join("after.safetensors");
    for (stop, warm) in [(1, true), (3, false)] {
        train(&config, &parts, &TrainOptions { stop_after: Some(stop), ..Default::default() }).unwrap();
        // The run directory and its policy file act in the state of their env steps: in the
        // warm-up Algorithm 1's assignment and no scorer terms; after it, the scorer's.
        let (_, teams) = load_policies(&parts).unwrap();
        let file = if warm { &in_warmup } else { &after };
        export_policy(&parts, file).unwrap();
        let from_file = load_policy(file).unwrap().teams;
        for (source, team) in [("run directory", &teams[0]), ("policy file", &from_file[0])] {
            assert_eq!(scored(team), !warm, "{source} after iteration {stop}");
        }
    }
    train(&config, &parts, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&parts), metrics(&whole));
    let params = |run: &RunDir| {
        let c = rl::mappo::checkpoint::Checkpoint::load(&run.checkpoint()).unwrap();
        c.teams.iter().flat_map(|t| t.params.tensors.iter().map(|x| x.data.clone())).collect::<Vec<_>>()
    };
    assert_eq!(params(&parts), params(&whole));
    // The field is written to the run's config.toml, and a resume with another is refused.
    let written = std::fs::read_to_string(whole.config()).unwrap();
    assert!(written.contains(&format!("assignment_warmup_steps = {}", 2 * ITERATION)), "{written}");
    let other = TrainConfig { assignment_warmup_steps: ITERATION, ..config.clone() };
    let e = train(&other, &parts, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("assignment_warmup_steps"), "{e}");
}

/// Whether `team`'s policy scores its assignment (a learned one out of its warm-up) when it
/// acts on the starts of its scene.
fn scored(team: &rl::Team) -> bool {
    let obs = Trainer::new(&config(PAIRS[1].0, 1, 0)).unwrap().env.obs().clone();
    let mut rows = envs::layout::Observation::empty(0, 0);
    team.norm.apply_rows(obs.rows(), &mut rows);
    let mut model = team.model.clone();
    let tape = Tape::<f32>::new();
    let _no_grad = tape.no_grad();
    let p = team.store.bind(&tape);
    let out = model.forward(&p, &rows.rows(), None, false).unwrap();
    assert_eq!(out.assignment.len(), 16 * 2);
    out.assignment_terms.is_some()
}
