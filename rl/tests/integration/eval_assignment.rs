//! `meben eval --assignment RULE` (`rl::app::eval_assignment`): a trained policy evaluated
//! with another task-assignment rule on its own parameters and normaliser. With its own rule
//! it plays exactly as without the flag (so the parameters and the normaliser are carried
//! over whole); another rule plays other episodes; the summary says which rule acted and
//! goes beside the run's own; the rules that would change more than the links, and a model
//! without one, are refused by name. A policy that learned its assignment takes Algorithm 1
//! (`greedy`) only, and then plays as the greedy model with its parameters.

use crate::common;

use common::meben;

/// `meben eval --run run --episodes 4 [--assignment rule] --out out`, its summary as JSON.
fn eval(run: &std::path::Path, rule: Option<&str>, out: &std::path::Path) -> serde_json::Value {
    let mut args = vec!["eval", "--run", run.to_str().unwrap(), "--episodes", "4", "--stochastic"];
    if let Some(r) = rule {
        args.extend(["--assignment", r]);
    }
    args.extend(["--out", out.to_str().unwrap()]);
    let (ok, stdout, err) = meben(&args);
    assert!(ok, "eval {rule:?} failed: {err}");
    if let Some(r) = rule {
        assert!(stdout.contains(&format!("assignment: {r}, in place of the policy's own")), "{stdout}");
    }
    serde_json::from_slice(&std::fs::read(out).unwrap()).unwrap()
}

#[test]
fn a_policy_with_its_own_rule_plays_as_without_the_flag_and_another_rule_plays_otherwise() {
    let tmp = common::TempDir::new("eval-assignment");
    let run = tmp.0.join("run");
    common::train_2_ants("mlp_hn", &run);
    let own = eval(&run, None, &tmp.0.join("own.json"));
    let mut greedy = eval(&run, Some("greedy"), &tmp.0.join("greedy.json"));
    assert_eq!(greedy["assignment"], "greedy");
    greedy.as_object_mut().unwrap().remove("assignment");
    assert_eq!(own, greedy, "the policy's own rule, given by name, must play the same episodes");
    assert!(own.get("assignment").is_none(), "a summary without --assignment names none: {own}");
    // A random one-to-one assignment at every step plays other episodes.
    let random = eval(&run, Some("stochastic"), &tmp.0.join("random.json"));
    assert_eq!(random["assignment"], "stochastic");
    assert_ne!(random["mean_return"], own["mean_return"]);
    // Each summary has its own file in the run directory: the run's own is not replaced.
    for name in ["eval.json", "eval_assignment-greedy.json", "eval_assignment-stochastic.json"] {
        assert!(run.join(name).is_file(), "{name} missing");
    }
    let in_run: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("eval.json")).unwrap()).unwrap();
    assert_eq!(in_run, own);
}

#[test]
fn rules_that_change_more_than_the_links_and_models_without_one_are_refused() {
    let tmp = common::TempDir::new("eval-assignment-refused");
    let run = tmp.0.join("greedy");
    common::train_2_ants("mlp_hn", &run);
    let run_s = run.to_str().unwrap();
    let refused = |args: &[&str], needles: &[&str]| {
        let (ok, _, err) = meben(args);
        assert!(!ok, "{args:?} should fail");
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {n:?} not in {err}");
        }
    };
    for rule in ["none", "learned", "nearest"] {
        refused(
            &["eval", "--run", run_s, "--episodes", "2", "--assignment", rule],
            &[&format!("--assignment {rule}"), "greedy, hungarian, stochastic"],
        );
        assert!(!run.join(format!("eval_assignment-{rule}.json")).exists());
    }
    let learned = tmp.0.join("learned");
    common::train_2_ants("mlp_hn:assignment=learned", &learned);
    for rule in ["hungarian", "stochastic"] {
        refused(
            &["eval", "--run", learned.to_str().unwrap(), "--episodes", "2", "--assignment", rule],
            &[&format!("--assignment {rule}"), "mlp_hn:assignment=learned", "only greedy"],
        );
        assert!(!learned.join(format!("eval_assignment-{rule}.json")).exists());
    }
    // Algorithm 1 in place of its scorer's draws plays other episodes than its own draws.
    let own = eval(&learned, None, &tmp.0.join("learned-own.json"));
    let greedy = eval(&learned, Some("greedy"), &tmp.0.join("learned-greedy.json"));
    assert_eq!(greedy["assignment"], "greedy");
    assert_ne!(own["mean_return"], greedy["mean_return"]);
    assert!(learned.join("eval_assignment-greedy.json").is_file());
    let flat = tmp.0.join("flat");
    common::train_2_ants("mlp_hn:variant=flat", &flat);
    refused(
        &["eval", "--run", flat.to_str().unwrap(), "--episodes", "2", "--assignment", "hungarian"],
        &["--assignment hungarian", "no team's model", "mlp_hn:variant=flat"],
    );
}

/// Team 0's assignments over the first `steps` steps of an 8-episode evaluation of `team`
/// (the evaluation's own players: `rl::mappo::evaluate::evaluation_actors`).
fn assignments_played(team: &rl::Team, steps: usize) -> Vec<Vec<u32>> {
    use rl::mappo::actor::{ActMode, JointAction};
    use rl::mappo::evaluate::{EvalOptions, eval_envs, evaluation_actors};
    let mut venv =
        eval_envs("team_reach/2_ants", &EvalOptions::new(8, false, 7, envs::tasks::StartMode::Random)).unwrap();
    let mut players = evaluation_actors(std::slice::from_ref(team), 7, ActMode::Sample);
    let mut joint = JointAction::new(8, venv.n_actions(), 1);
    let mut seen = Vec::new();
    for _ in 0..steps {
        let (model, actor) = &mut players[0];
        actor.act(model.as_mut(), &team.store, &team.norm, venv.obs().rows(), &mut joint).unwrap();
        seen.push(joint.assignment[0].clone());
        venv.step(&joint.actions).unwrap();
    }
    seen
}

#[test]
fn a_held_random_assignment_stays_for_its_steps_and_no_team_to_hold_is_refused() {
    let config = common::tiny("team_reach/2_ants", "mlp_hn", 1, &[]);
    let spec = envs::tasks::Scene::from_name("team_reach/2_ants").unwrap().obs_spec;
    let greedy = vec![rl::Team::build(&config, &spec, 0).unwrap()];
    let mut random = greedy.clone();
    rl::app::eval_assignment::reassign(&config, &mut random, "stochastic").unwrap();
    // Drawn at every step, a random assignment of 8 scenes changes within 12 steps.
    let every_step = assignments_played(&random[0], 12);
    assert!(every_step.windows(2).any(|w| w[0] != w[1]), "{every_step:?}");
    // Held for 5 steps: drawn at steps 0, 5 and 10 only, and changed at one of them.
    rl::app::eval_assignment::hold(&mut random, 5).unwrap();
    let held = assignments_played(&random[0], 12);
    for (step, pair) in held.windows(2).enumerate() {
        if (step + 1) % 5 != 0 {
            assert_eq!(pair[0], pair[1], "changed at step {} while held", step + 1);
        }
    }
    assert!(held[0] != held[5] || held[5] != held[10], "{held:?}");
    // Held for the episode: one assignment throughout.
    rl::app::eval_assignment::hold(&mut random, 1000).unwrap();
    let episode = assignments_played(&random[0], 12);
    assert!(episode.iter().all(|a| *a == episode[0]), "{episode:?}");
    // Nothing to hold, or no step to hold for, is an error naming the flag.
    let mut greedy = greedy;
    let e = rl::app::eval_assignment::hold(&mut greedy, 5).unwrap_err();
    assert!(e.contains("--assignment-hold 5") && e.contains("mlp_hn") && e.contains("stochastic"), "{e}");
    let e = rl::app::eval_assignment::hold(&mut random, 0).unwrap_err();
    assert!(e.contains("--assignment-hold 0"), "{e}");
}

/// A policy that learned its assignment, given `greedy`, plays as the greedy model with the
/// same parameters but its scorer's (Algorithm 1 at every step, as in its warm-up), sampled
/// and mean actions alike; held for an episode, it acts on Algorithm 1's assignment of the
/// episode's first step throughout. Its scorer's own draws play otherwise.
#[test]
fn a_learned_policy_given_greedy_plays_as_the_greedy_model() {
    use rl::app::eval_assignment::{hold, reassign};
    use rl::mappo::evaluate::{EvalOptions, evaluate};
    let spec = envs::tasks::Scene::from_name("team_reach/2_ants").unwrap().obs_spec;
    for (learned, greedy) in [("mlp_hn:assignment=learned", "mlp_hn"), ("shnn:assignment=learned", "shnn")] {
        let lc = common::tiny("team_reach/2_ants", learned, 1, &[]);
        let gc = common::tiny("team_reach/2_ants", greedy, 1, &[]);
        let mut l = vec![rl::Team::build(&lc, &spec, 0).unwrap()];
        let g = vec![rl::Team::build(&gc, &spec, 0).unwrap()];
        let own = assignments_played(&l[0], 12);
        reassign(&lc, &mut l, "greedy").unwrap();
        let per_step = assignments_played(&l[0], 12);
        assert_eq!(per_step, assignments_played(&g[0], 12), "{learned}: not Algorithm 1's assignments");
        assert_ne!(own, per_step, "{learned}: its own draws played Algorithm 1's");
        for deterministic in [false, true] {
            let options = EvalOptions::new(4, deterministic, 9, lc.start_mode());
            let (el, eg) = (evaluate(&lc.env, &l, &options).unwrap(), evaluate(&gc.env, &g, &options).unwrap());
            assert_eq!(el, eg, "{learned}, deterministic {deterministic}: not the greedy model's episodes");
        }
        hold(&mut l, 1000).unwrap();
        let held = assignments_played(&l[0], 12);
        assert!(held.iter().all(|a| *a == per_step[0]), "{learned}: {held:?} against {:?}", per_step[0]);
        for rule in ["hungarian", "stochastic"] {
            let mut again = vec![rl::Team::build(&lc, &spec, 0).unwrap()];
            let e = reassign(&lc, &mut again, rule).unwrap_err();
            assert!(
                e.contains(&format!("--assignment {rule}")) && e.contains(learned) && e.contains("only greedy"),
                "{e}"
            );
        }
    }
}
