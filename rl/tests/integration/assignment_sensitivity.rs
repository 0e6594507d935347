//! How much a team's actions depend on its task assignment (`meben eval
//! --assignment-sensitivity`, `rl::mappo::assignment_sensitivity`): the probe's divergence
//! is the closed-form KL of the policy's own outputs under the two assignments, scene by
//! scene; the evaluation plays the same episodes with and without it (a learned
//! assignment's stream untouched); every scene-step of a playing scene is counted; and a
//! model without an assignment is refused by name.

use crate::common;

use envs::layout::Observation;
use envs::tasks::StartMode;
use models::distribution::std_from_scale;
use rl::Team;
use rl::mappo::assignment_sensitivity::{SensitivityProbe, gaussian_kl};
use rl::mappo::evaluate::{EvalOptions, eval_envs};
use tensor::Tape;

/// Team 0 of `model` on `env`, its normaliser fed a few steps of fixed actions.
fn team(env: &str, model: &str) -> Team {
    let config = common::tiny(env, model, 1, &[]);
    let spec = envs::tasks::Scene::from_name(env).unwrap().obs_spec;
    let mut team = Team::build(&config, &spec, 0).unwrap();
    let mut warm = eval_envs(env, &EvalOptions::new(3, true, 2, StartMode::Random)).unwrap();
    let na = warm.n_actions();
    for k in 0..10 {
        team.norm.update(&warm.obs().vectors, &warm.obs().scalars);
        warm.step(&vec![if k % 2 == 0 { 0.6 } else { -0.3 }; 3 * na]).unwrap();
    }
    team
}

/// Each agent's `(loc, std)` of `team` under `assignment` for the normalised rows `obs`.
fn heads(team: &mut Team, obs: &Observation, assignment: &[u32]) -> Vec<(Vec<f32>, Vec<f32>, usize)> {
    let tape = Tape::<f32>::new();
    let _no_grad = tape.no_grad();
    let p = team.store.bind(&tape);
    let out = team.model.forward(&p, &obs.rows(), Some(assignment), false).unwrap();
    out.agents
        .iter()
        .map(|a| {
            let dof = a.loc.value().shape()[1];
            (a.loc.value().data().to_vec(), std_from_scale(a.scale).value().data().to_vec(), dof)
        })
        .collect()
}

#[test]
fn the_probe_gives_each_scenes_closed_form_divergence_to_the_other_assignment() {
    for model in ["shnn:assignment=learned", "mlp_hn"] {
        let mut team = team("team_reach/2_ants", model);
        let venv = eval_envs("team_reach/2_ants", &EvalOptions::new(3, true, 5, StartMode::Random)).unwrap();
        // Scenes acting on different assignments, so that each scene's alternative differs.
        let acted = [0u32, 1, 1, 0, 0, 1];
        let alive = [true, false, true];
        let mut obs = Observation::empty(0, 0);
        team.norm.apply_rows(venv.obs().rows(), &mut obs);
        let mut probe = SensitivityProbe::new(0);
        probe.observe(team.model.as_mut(), &team.store, obs.rows(), &acted, &alive, 0).unwrap();
        // By hand: the swap of every scene, the KL summed over agents and dimensions.
        let swapped = [1u32, 0, 0, 1, 1, 0];
        let (p, q) = (heads(&mut team, &obs, &acted), heads(&mut team, &obs, &swapped));
        let kl = |s: usize| -> f64 {
            let mut sum = 0.0;
            for ((lp, sp, dof), (lq, sq, _)) in p.iter().zip(&q) {
                for k in s * dof..(s + 1) * dof {
                    sum += gaussian_kl(lp[k] as f64, sp[k] as f64, lq[k] as f64, sq[k] as f64);
                }
            }
            sum
        };
        let (k0, k2) = (kl(0), kl(2));
        // The actions depend on the assignment (the graph links each agent to its ball).
        assert!(k0 > 1e-6 && k2 > 1e-6 && (k0 - k2).abs() > 1e-9, "{model}: {k0} {k2}");
        let s = probe.summary();
        assert_eq!((s.team, s.steps, s.alternatives), (0, 2, 1.0), "{model}: the dead scene 1 is not counted");
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        assert!(close(s.mean_kl, 0.5 * (k0 + k2)), "{model}: {} against {}", s.mean_kl, 0.5 * (k0 + k2));
        assert!(close(s.median_kl, 0.5 * (k0 + k2)) && close(s.p90_kl, k0.max(k2)), "{model}: {s:?}");
        assert!(close(s.early_mean_kl, s.mean_kl));
        // Past the early steps a scene-step counts in the whole mean only.
        probe.observe(team.model.as_mut(), &team.store, obs.rows(), &acted, &alive, 100).unwrap();
        let s = probe.summary();
        assert_eq!(s.steps, 4);
        assert!(close(s.early_mean_kl, 0.5 * (k0 + k2)) && close(s.mean_kl, 0.5 * (k0 + k2)));
        // An assignment that is not one-to-one is refused.
        let e = probe
            .observe(team.model.as_mut(), &team.store, obs.rows(), &[0, 0, 1, 0, 0, 1], &alive, 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not one-to-one"), "{e}");
    }
}

#[test]
fn an_evaluation_plays_the_same_episodes_with_the_probe_and_counts_every_scene_step() {
    for (model, sampled) in [("shnn:assignment=learned", true), ("shnn:assignment=learned", false), ("mlp_hn", true)] {
        let teams = [team("team_reach/2_ants", model)];
        let plain = EvalOptions::new(3, !sampled, 11, StartMode::Random);
        let probed = EvalOptions { assignment_sensitivity: true, ..plain };
        let a = rl::evaluate("team_reach/2_ants", &teams, &plain).unwrap();
        let mut b = rl::evaluate("team_reach/2_ants", &teams, &probed).unwrap();
        assert!(a.assignment_sensitivity.is_empty());
        let s = b.assignment_sensitivity.pop().expect("team 0 has an assignment");
        assert!(b.assignment_sensitivity.is_empty());
        assert_eq!(a, b, "{model}: the probe changed the episodes");
        // Every scene counts once per control step it plays, its last included.
        assert_eq!(s.steps as f64, a.mean_length * 3.0, "{model}");
        assert_eq!(s.alternatives, 1.0);
        assert!(s.mean_kl.is_finite() && s.mean_kl > 0.0 && s.median_kl <= s.p90_kl, "{model}: {s:?}");
        assert!(s.early_mean_kl > 0.0);
        // The summary's JSON carries the field only when measured (eval.json unchanged).
        let text = serde_json::to_string(&a).unwrap();
        assert!(!text.contains("assignment_sensitivity"), "{text}");
        let with =
            serde_json::to_string(&rl::mappo::evaluate::EvalSummary { assignment_sensitivity: vec![s], ..a }).unwrap();
        assert!(with.contains("\"early_mean_kl\""));
    }
    // One ant for one ball: no other one-to-one assignment, no scene-step measured.
    let teams = [team("team_reach/1_ant", "shnn")];
    let probed = EvalOptions { assignment_sensitivity: true, ..EvalOptions::new(2, true, 1, StartMode::Random) };
    let s = rl::evaluate("team_reach/1_ant", &teams, &probed).unwrap().assignment_sensitivity;
    assert_eq!((s.len(), s[0].steps), (1, 0));
}

#[test]
fn meben_eval_measures_the_sensitivity_and_refuses_a_model_without_an_assignment() {
    let tmp = common::TempDir::new("assignment-sensitivity");
    for (model, ok) in [("mlp_hn", true), ("mlp_hn:assignment=none", false)] {
        let run = tmp.0.join(model.replace([':', '='], "_"));
        let run_s = run.to_str().unwrap();
        common::train_2_ants(model, &run);
        let (status, out, err) =
            common::meben(&["eval", "--run", run_s, "--episodes", "2", "--assignment-sensitivity"]);
        if ok {
            assert!(status, "{err}");
            assert!(
                out.contains("team 0 assignment sensitivity: KL(") && out.contains("1 other assignment(s) a step"),
                "{out}"
            );
            let json = std::fs::read_to_string(run.join("eval.json")).unwrap();
            assert!(json.contains("\"assignment_sensitivity\"") && json.contains("\"mean_kl\""), "{json}");
        } else {
            assert!(
                !status && err.contains("assignment sensitivity: no team's model") && err.contains("mlp_hn"),
                "{err}"
            );
            assert!(!run.join("eval.json").exists(), "a refused evaluation wrote nothing");
        }
    }
}
