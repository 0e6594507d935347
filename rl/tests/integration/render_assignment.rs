//! The task assignment recorded with a rendered episode (`meben render`'s HTML player marks
//! it): greedy as Algorithm 1 computes it from each frame's positions, one-to-one onto the
//! right kind of entity, for every assignment method (the release's MLPs read the assigned
//! ball too); nothing for a model without one.

use crate::common;

use envs::tasks::render::Trajectory;
use rl::Trainer;
use rl::app::render::record_episode;

/// A freshly initialised `model` on `env` recording `steps` steps (mean actions).
fn recorded(env: &str, model: &str, steps: usize) -> Trajectory {
    let mut t = Trainer::new(&common::tiny(env, model, 1, &[])).unwrap();
    let mut failure = None;
    let traj = record_episode(env, &mut t.teams, 5, steps, true, &mut failure).unwrap();
    assert!(failure.is_none(), "{failure:?}");
    traj
}

/// Agent `a`'s root position at frame `f`.
fn root(traj: &Trajectory, f: usize, a: usize) -> [f64; 3] {
    traj.bodies[f][traj.scene.agents[a].root_body].0
}

fn distance(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

#[test]
fn greedy_is_algorithm_1_on_every_frames_positions() {
    let steps = 12;
    let traj = recorded("team_reach/2_ants", "shnn", steps);
    assert_eq!(traj.assigned.len(), steps, "one assignment per step");
    let na = traj.scene.n_agents();
    for (f, row) in traj.assigned.iter().enumerate() {
        // Algorithm 1: balls in order, each takes the nearest agent still free.
        let mut expected = vec![None; na];
        for (j, b) in traj.balls[f].iter().enumerate() {
            let ball = [b[0], b[1], envs::tasks::scene::BALL_RADIUS];
            let nearest = (0..na)
                .filter(|&a| expected[a].is_none())
                .min_by(|&x, &y| distance(root(&traj, f, x), ball).total_cmp(&distance(root(&traj, f, y), ball)));
            if let Some(a) = nearest {
                expected[a] = Some(na + j);
            }
        }
        assert_eq!(row, &expected, "step {f}");
    }
    let html = traj.to_html();
    assert!(html.contains("\"captions\":[\"agent 0 → ball"), "no caption of the first frame");
    assert!(html.contains("<div id=\"assigned\">"));
}

#[test]
fn every_method_marks_a_one_to_one_assignment_onto_its_objects() {
    let methods =
        ["shnn:assignment=hungarian", "shnn:assignment=stochastic", "shnn:assignment=learned", "mlp", "mlp_hn"];
    for model in methods {
        let traj = recorded("team_reach/2_ants", model, 6);
        assert_eq!(traj.assigned.len(), 6, "{model}");
        for row in &traj.assigned {
            let mut balls: Vec<usize> = row.iter().map(|e| e.expect("every agent has a ball")).collect();
            balls.sort();
            assert_eq!(balls, vec![2, 3], "{model}: {row:?}");
        }
    }
    // Sumo: each team's agents are assigned to the other team's.
    let traj = recorded("team_sumo/2_ants", "shnn", 4);
    let teams: Vec<usize> = traj.scene.agents.iter().map(|a| a.team).collect();
    for row in &traj.assigned {
        for (a, e) in row.iter().enumerate() {
            let e = e.expect("every agent has an opponent");
            assert!(e < teams.len() && teams[e] != teams[a], "agent {a} -> {e}: {row:?}");
        }
    }
    // No assignment: nothing recorded, no marks drawn.
    for model in ["transformer_hn", "shnn:assignment=none", "mlp_hn:assignment=none"] {
        let traj = recorded("team_reach/2_ants", model, 3);
        assert!(traj.assigned.is_empty(), "{model}");
        assert!(traj.to_html().contains("\"captions\":[\"\",\"\""), "{model}");
    }
}
