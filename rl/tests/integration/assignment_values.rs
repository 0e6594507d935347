//! `meben eval --assignment-values` (`rl::mappo::assignment_values`): the value that reads a
//! learned assignment, read for every assignment at each episode's first step, beside the
//! episode's discounted return; the episodes play as without it.

use rl::app::eval_assignment::{hold, reassign};
use rl::mappo::assignment_values::ReturnUnits;
use rl::mappo::evaluate::{EvalOptions, EvalSummary, evaluate};

use crate::assignment_gradient::randomise_held_weight;
use crate::common;

const HELD_CRITIC: &str = "mlp_hn:assignment=learned;assign_critic=held";

/// Team 0 of `model` on `team_reach/2_ants`, its draws held per episode, and its config.
fn team(model: &str) -> (rl::TrainConfig, Vec<rl::Team>) {
    let config = common::tiny("team_reach/2_ants", model, 1, &[("assignment_hold_episode", "true")]);
    let spec = envs::tasks::Scene::from_name(&config.env).unwrap().obs_spec;
    let mut teams = vec![rl::Team::build(&config, &spec, 0).unwrap()];
    teams[0].sync_assignment(&config, 0);
    (config, teams)
}

/// `options` asking for the values in `units`.
fn with_values(options: EvalOptions, discount: f64, reward_scaling: f64) -> EvalOptions {
    EvalOptions { assignment_values: Some(ReturnUnits { discount, reward_scaling }), ..options }
}

#[test]
fn every_assignments_value_is_read_at_the_first_step_beside_the_discounted_return() {
    let (config, mut teams) = team(HELD_CRITIC);
    randomise_held_weight(&mut teams[0].store, 3);
    let plain = EvalOptions::new(6, false, 9, config.start_mode());
    let without = evaluate(&config.env, &teams, &plain).unwrap();
    let summary = evaluate(&config.env, &teams, &with_values(plain, 1.0, 1.0)).unwrap();
    // The episodes play as without the probe.
    assert_eq!(EvalSummary { assignment_values: Vec::new(), ..summary.clone() }, without);
    let v = &summary.assignment_values[0];
    assert_eq!((v.team, v.support.len(), v.episodes.len()), (0, 2, 6), "two ants, two balls: {:?}", v.support);
    for e in &v.episodes {
        assert!(e.acted < 2 && e.value.len() == 2 && e.probability.len() == 2, "{e:?}");
        let total: f64 = e.probability.iter().sum();
        assert!((total - 1.0).abs() < 1e-5, "π over the support sums to {total}");
        // W_σ tells the assignments apart.
        assert_ne!(e.value[0], e.value[1], "{e:?}");
    }
    // Undiscounted and unscaled, an episode's return is its return: their mean the summary's.
    let mean = v.episodes.iter().map(|e| e.discounted_return).sum::<f64>() / 6.0;
    assert!((mean - summary.mean_return[0]).abs() <= 1e-9 * mean.abs().max(1.0), "{mean} {:?}", summary.mean_return);
    // Each episode's return and success are the summary's.
    for e in &v.episodes {
        assert_eq!(e.episode_return, e.discounted_return, "γ = c = 1");
    }
    let successes = v.episodes.iter().filter(|e| e.success).count() as f64;
    assert_eq!(successes / 6.0, summary.success_rate);
    // Scaled by 2: twice each, exactly; discounted: another figure.
    let scaled = evaluate(&config.env, &teams, &with_values(plain, 1.0, 2.0)).unwrap();
    let discounted = evaluate(&config.env, &teams, &with_values(plain, 0.9, 1.0)).unwrap();
    for ((e, s), d) in
        v.episodes.iter().zip(&scaled.assignment_values[0].episodes).zip(&discounted.assignment_values[0].episodes)
    {
        assert_eq!(s.discounted_return, 2.0 * e.discounted_return);
        assert_ne!(d.discounted_return, e.discounted_return);
        assert_eq!(
            (d.episode_return, d.success),
            (e.episode_return, e.success),
            "the return does not depend on the units"
        );
        assert_eq!((&d.value, d.unheld_value), (&e.value, e.unheld_value), "the values do not depend on the units");
    }
    // With W_σ = 0 the two assignments' values are one, and the value read without an
    // assignment does not change (it reads no W_σ).
    let (_, mut fresh) = team(HELD_CRITIC);
    fresh[0].store = teams[0].store.clone();
    let id = fresh[0].store.find("team0.critic.held.weight").unwrap();
    let zero = tensor::Tensor::zeros(fresh[0].store.get(id).shape());
    fresh[0].store.set(id, zero).unwrap();
    let flat = evaluate(&config.env, &fresh, &with_values(plain, 1.0, 1.0)).unwrap();
    for (f, e) in flat.assignment_values[0].episodes.iter().zip(&v.episodes) {
        assert_eq!(f.value[0], f.value[1], "{f:?}");
        assert_eq!((f.unheld_value, &f.probability, f.acted), (e.unheld_value, &e.probability, e.acted));
    }
}

#[test]
fn algorithm_1_held_replays_the_episodes_whose_draw_was_its_own() {
    let (config, mut teams) = team(HELD_CRITIC);
    randomise_held_weight(&mut teams[0].store, 5);
    let options = with_values(EvalOptions::new(16, false, 4, config.start_mode()), 0.97, 1.0);
    let own = evaluate(&config.env, &teams, &options).unwrap();
    reassign(&config, &mut teams, "greedy").unwrap();
    hold(&mut teams, 1000).unwrap();
    let greedy = evaluate(&config.env, &teams, &options).unwrap();
    let (o, g) = (&own.assignment_values[0], &greedy.assignment_values[0]);
    assert_eq!(o.support, g.support);
    let (mut same, mut other) = (0, 0);
    for (a, b) in o.episodes.iter().zip(&g.episodes) {
        // Episode e begins from the same state in both: the scorer and the value read the same.
        assert_eq!((&a.value, &a.probability, a.unheld_value), (&b.value, &b.probability, b.unheld_value));
        if a.acted == b.acted {
            same += 1;
            assert_eq!(a.discounted_return, b.discounted_return, "the same assignment, the same noise");
        } else {
            other += 1;
        }
    }
    assert!(same > 0 && other > 0, "{same} episodes drew Algorithm 1's assignment, {other} the other");
}

#[test]
fn a_model_without_a_value_that_reads_its_learned_assignment_is_refused() {
    for model in ["mlp_hn", "mlp_hn:assignment=learned"] {
        let config = common::tiny("team_reach/2_ants", model, 1, &[]);
        let spec = envs::tasks::Scene::from_name(&config.env).unwrap().obs_spec;
        let teams = vec![rl::Team::build(&config, &spec, 0).unwrap()];
        let options = with_values(EvalOptions::new(2, false, 1, config.start_mode()), 0.97, 1.0);
        let e = evaluate(&config.env, &teams, &options).unwrap_err().to_string();
        assert!(
            e.contains("assignment values") && e.contains("assign_critic=held") && e.contains("mlp_hn"),
            "{model}: {e}"
        );
    }
    // A policy file holds no value network.
    let (ok, _, err) = common::meben(&[
        "eval",
        "--policy",
        "pretrained:team_reach/2_ants/shnn",
        "--episodes",
        "2",
        "--assignment-values",
    ]);
    assert!(!ok && err.contains("--assignment-values") && err.contains("--run"), "{err}");
}
