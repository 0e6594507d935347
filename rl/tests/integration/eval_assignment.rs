//! `meben eval --assignment RULE` (`rl::app::eval_assignment`): a trained policy evaluated
//! with another task-assignment rule on its own parameters and normaliser. With its own rule
//! it plays exactly as without the flag (so the parameters and the normaliser are carried
//! over whole); another rule plays other episodes; the summary says which rule acted and
//! goes beside the run's own; the rules that would change more than the links, a learned
//! assignment and a model without one are refused by name.

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
    refused(
        &["eval", "--run", learned.to_str().unwrap(), "--episodes", "2", "--assignment", "greedy"],
        &["--assignment greedy", "mlp_hn:assignment=learned", "scorer"],
    );
    let flat = tmp.0.join("flat");
    common::train_2_ants("mlp_hn:variant=flat", &flat);
    refused(
        &["eval", "--run", flat.to_str().unwrap(), "--episodes", "2", "--assignment", "hungarian"],
        &["--assignment hungarian", "no team's model", "mlp_hn:variant=flat"],
    );
}
