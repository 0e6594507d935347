//! Rewards, success and win/lose on hand-built states: every Reach and Sumo reward term
//! against hand-computed numbers; success fires exactly when every ball is covered within
//! 0.5 m at the same step; the Sumo lose condition for each team, through the environment.

use envs::tasks::outcome::{Outcome, RootState};
use envs::tasks::placement::{RootPlacement, Start};
use envs::tasks::{StartMode, VecEnv, reach, sumo};

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + b.abs())
}

#[test]
fn reach_distance_term_uses_the_nearest_root_per_ball() {
    let balls = [[0.0, 0.0], [10.0, 0.0]];
    let roots = [[3.0, 4.0], [10.0, 1.0], [0.0, 1.0]];
    // Ball 0: nearest root at distance 1 (not 5); ball 1: distance 1.
    let want = 5.0 * ((-1.0f64).exp() + (-1.0f64).exp());
    assert!(close(reach::distance_term(&balls, &roots), want));
    assert!(close(reach::distance_term(&[[0.0, 0.0]], &[[0.0, 0.0]]), 5.0));
    // Horizontal only: the term ignores heights because roots are (x, y).
    assert!(close(reach::nearest_root([1.0, 1.0], &[[4.0, 5.0]]), 5.0));
}

#[test]
fn reach_moving_term_counts_only_progress_towards_each_ball() {
    let balls = [[2.0, 0.0], [0.0, 3.0]];
    let roots = [[0.0, 0.0]];
    // v = (1, 1): towards ball 0: (1,1).(2,0) = 2; towards ball 1: (1,1).(0,3) = 3.
    assert!(close(reach::moving_term(&balls, &roots, &[[1.0, 1.0]]), 0.2 * 5.0));
    // v = (-1, 0.5): ball 0: -2 -> 0; ball 1: 1.5.
    assert!(close(reach::moving_term(&balls, &roots, &[[-1.0, 0.5]]), 0.2 * 1.5));
    // Two agents add up.
    let two = reach::moving_term(&balls, &[[0.0, 0.0], [0.0, 0.0]], &[[1.0, 1.0], [1.0, 1.0]]);
    assert!(close(two, 0.2 * 10.0));
}

#[test]
fn reach_control_term_is_minus_0_2_times_the_l2_norms() {
    assert!(close(reach::control_term(&[5.0, 1.0]), -1.2));
    let state = RootState {
        pos: vec![[9.0, 9.0]],
        vel: vec![[0.0, 0.0]],
        action_norm: vec![(3.0f64 * 3.0 + 4.0 * 4.0).sqrt()],
    };
    let (r, o) = reach::evaluate(&[[0.0, 0.0]], &state);
    assert!(close(r.control, -1.0));
    assert_eq!(o, Outcome::Running);
    assert_eq!(r.bonus, 0.0);
}

#[test]
fn reach_success_needs_every_ball_covered_within_half_a_metre() {
    let balls = [[0.0, 0.0], [4.0, 0.0]];
    assert!(reach::all_covered(&balls, &[[0.3, 0.4], [4.0, -0.49]])); // 0.5 and 0.49
    assert!(!reach::all_covered(&balls, &[[0.3, 0.41], [4.0, 0.0]])); // 0.5015
    assert!(!reach::all_covered(&balls, &[[0.0, 0.0], [0.1, 0.0]])); // ball 1 uncovered
    assert!(reach::all_covered(&balls[..1], &[[0.0, 0.0], [9.0, 9.0]])); // one ball, one idle agent
    let state = RootState { pos: vec![[0.0, 0.1], [4.2, 0.0]], vel: vec![[0.0; 2]; 2], action_norm: vec![0.0; 2] };
    let (r, o) = reach::evaluate(&balls, &state);
    assert_eq!(o, Outcome::Success);
    assert_eq!(r.bonus, 10_000.0);
    let want = 10_000.0 + 5.0 * ((-0.1f64).exp() + (-0.2f64).exp());
    assert!(close(r.total(), want));
}

fn yaw0(x: f64, y: f64) -> RootPlacement {
    RootPlacement { xy: [x, y], yaw: 0.0 }
}

#[test]
fn reach_success_fires_in_the_environment_exactly_when_all_balls_are_covered() {
    let mut env = VecEnv::from_name("team_reach/2_ants", 3, 1, StartMode::Random).unwrap();
    let na = env.n_actions();
    // env 0: both balls under the roots; env 1: one ball 2 m away; env 2: both far.
    env.set_start(0, &Start { agents: vec![yaw0(-1.5, 0.0), yaw0(1.5, 0.0)], balls: vec![[1.5, 0.1], [-1.5, 0.0]] })
        .unwrap();
    env.set_start(1, &Start { agents: vec![yaw0(-1.5, 0.0), yaw0(1.5, 0.0)], balls: vec![[1.5, 0.0], [-1.5, 2.0]] })
        .unwrap();
    env.set_start(2, &Start { agents: vec![yaw0(-1.5, 0.0), yaw0(1.5, 0.0)], balls: vec![[0.0, 2.0], [0.0, -2.0]] })
        .unwrap();
    let out = env.step(&vec![0.0; 3 * na]).unwrap().clone();
    assert_eq!(out.outcome[0], Outcome::Success);
    assert_eq!((out.terminated[0], out.truncated[0]), (true, false));
    assert!(out.reward[0] > 10_000.0 && out.reward[0] < 10_010.0, "{}", out.reward[0]);
    for e in 1..3 {
        assert_eq!(out.outcome[e], Outcome::Running);
        assert!(!out.terminated[e] && !out.truncated[e]);
        assert!(out.reward[e] < 100.0);
    }
    // The terminated episode restarted from a fresh start; the final observation shows the
    // covered balls, the new one does not.
    assert_eq!(env.episode_step(0), Some(0));
    assert_eq!(env.episode_step(1), Some(1));
    let spec = &env.scene().obs_spec;
    let ball_node = spec.entity_root_node[2];
    let fb = out.final_obs.vector(0, ball_node, 0);
    assert_eq!([fb[0], fb[1]], [1.5, 0.1]);
    assert_ne!(out.obs.vector(0, ball_node, 0), fb);
}

#[test]
fn sumo_terms_against_hand_computed_values() {
    let (c, r) = ([1.0, 1.0], 3.0);
    let own = [[1.0, 2.0], [3.0, 1.0]]; // distances 1 and 2 from the centre
    let opp = [[1.0, -1.5]]; // distance 2.5
    let edge = sumo::edge_term(&own, &opp, c, r);
    assert!(close(edge, 5.0 * ((2.5f64 - 3.0).exp() - (2.0f64 - 3.0).exp())));
    // Moving: own 0 at (1,2) with v (0,-1) towards (1,-1.5): 3.5; own 1 with v (1,0): -2 -> 0.
    let moving = sumo::moving_term(&own, &[[0.0, -1.0], [1.0, 0.0]], &opp);
    assert!(close(moving, 5.0 * 3.5));
    assert!(close(sumo::control_term(&[2.0, 0.5]), -0.25));
    // evaluate: agents 0, 1 in team 0, agent 2 in team 1; nobody out.
    let state = RootState {
        pos: vec![own[0], own[1], opp[0]],
        vel: vec![[0.0, -1.0], [1.0, 0.0], [0.0, 0.0]],
        action_norm: vec![2.0, 0.5, 1.0],
    };
    let ([r0, r1], o) = sumo::evaluate(&[0, 0, 1], c, r, &state);
    assert_eq!(o, Outcome::Running);
    assert!(close(r0.edge, edge) && close(r0.moving, moving) && close(r0.control, -0.25) && r0.sparse == 0.0);
    assert!(close(r1.edge, -edge) && r1.moving == 0.0 && close(r1.control, -0.1));
    // Curriculum: alpha blends dense and sparse.
    let w = sumo::SumoReward { edge: 1.0, moving: 2.0, control: -0.5, sparse: 1000.0 };
    assert!(close(w.total(1.0), 2.5) && close(w.total(0.0), 1000.0) && close(w.total(0.25), 0.625 + 750.0));
}

#[test]
fn sumo_lose_condition_for_each_team() {
    let (c, r) = ([0.0, 0.0], 3.0);
    let inside = [[2.9, 0.0], [0.0, -2.0]];
    let out = [[0.0, 3.01], [0.5, 0.0]];
    assert_eq!(sumo::outcome(&inside, &inside, c, r), Outcome::Running);
    assert_eq!(sumo::outcome(&out, &inside, c, r), Outcome::Win(1));
    assert_eq!(sumo::outcome(&inside, &out, c, r), Outcome::Win(0));
    assert_eq!(sumo::outcome(&out, &out, c, r), Outcome::Draw);
    // The arena follows the centre ball.
    assert_eq!(sumo::outcome(&out, &inside, [0.0, 0.1], r), Outcome::Running);
}

#[test]
fn sumo_lose_condition_in_the_environment() {
    let mut env = VecEnv::from_name("team_sumo/2_ants", 3, 2, StartMode::Random).unwrap();
    env.set_curriculum_alpha(0.0).unwrap();
    let centre = vec![[0.0, 0.0]];
    // env 0: a team-0 ant beyond R = 3; env 1: a team-1 ant beyond; env 2: everyone inside.
    let starts = [
        [yaw0(3.2, 0.0), yaw0(-1.5, 0.0), yaw0(0.0, 1.5), yaw0(0.0, -1.5)],
        [yaw0(1.5, 0.0), yaw0(-1.5, 0.0), yaw0(0.0, 1.5), yaw0(0.0, -3.3)],
        [yaw0(1.5, 0.0), yaw0(-1.5, 0.0), yaw0(0.0, 1.5), yaw0(0.0, -1.5)],
    ];
    for (e, s) in starts.iter().enumerate() {
        env.set_start(e, &Start { agents: s.to_vec(), balls: centre.clone() }).unwrap();
    }
    let out = env.step(&vec![0.0; 3 * env.n_actions()]).unwrap().clone();
    assert_eq!(out.outcome, vec![Outcome::Win(1), Outcome::Win(0), Outcome::Running]);
    assert_eq!(out.terminated, vec![true, true, false]);
    assert_eq!(&out.reward[..4], &[-1000.0, 1000.0, 1000.0, -1000.0]);
    assert_eq!(&out.reward[4..], &[0.0, 0.0]); // alpha 0: only the sparse reward
    assert!(env.set_curriculum_alpha(1.5).is_err());
}
