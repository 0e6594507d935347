//! The static type scalars of the observation: limb types per body as the reference
//! release's AMORPHEUS table, and the Team Sumo entity types seen from each team.

use envs::brax::morphologies::MORPHOLOGIES;
use envs::layout::N_SCALARS;
use envs::layout::{ENTITY_AGENT, ENTITY_CENTRE, ENTITY_GOAL, ENTITY_OPPONENT};
use envs::tasks::{Scene, StartMode, VecEnv};

const TORSO: Option<usize> = Some(0);
const THIGH: Option<usize> = Some(1);
const LEG: Option<usize> = Some(2);
const FOOT: Option<usize> = Some(3);
/// Listed in the release's table with an all-zero limb type (its "others").
const NONE: Option<usize> = None;

/// Expected limb type of every body of every built-in morphology, written from alpc91/SMERL
/// `mix_colla_compe_team_tasks/procedural_envs/tasks/observation_config/one_hot_limb_id.py`
/// (the AMORPHEUS dict, looked up by the observers in `misc/observers.py` of both task
/// folders with the body name stripped of its `agentN___` prefix):
/// - torso: `'$ Torso', 'torso', 'torso_0', 'palm'`;
/// - thigh: `Aux 1_{i}`, `Aux 2_{i}` (i < 10), `torso_{i}` (1 <= i <= 10: the centipede's
///   later segments), `d1_limb_{i}` (i < 22);
/// - leg: `$ Body 4_{i}`, `$ Body 5_{i}` (i < 10), `d2_limb_{i}`;
/// - foot: `d3_limb_{i}`;
/// - all zero ("others"): `limb_end_{i}`, `d4_limb_{i}` (i < 22).
fn release_table(morphology: &str) -> Vec<(String, Option<usize>)> {
    let mut t: Vec<(String, Option<usize>)> = Vec::new();
    let mut add = |name: &str, limb: Option<usize>| t.push((name.to_string(), limb));
    match morphology {
        "ant" => {
            add("torso", TORSO);
            for i in 0..4 {
                add(&format!("Aux 1_{i}"), THIGH);
                add(&format!("$ Body 4_{i}"), LEG);
            }
        }
        "claw" => {
            add("torso", TORSO);
            for i in 0..4 {
                add(&format!("Aux 1_{i}"), THIGH);
                add(&format!("Aux 2_{i}"), THIGH);
                add(&format!("$ Body 4_{i}"), LEG);
            }
        }
        "centipede" => {
            add("torso_0", TORSO);
            add("torso_1", THIGH);
            add("torso_2", THIGH);
            for i in 0..3 {
                add(&format!("Aux 1_{i}"), THIGH);
                add(&format!("Aux 2_{i}"), THIGH);
                add(&format!("$ Body 4_{i}"), LEG);
                add(&format!("$ Body 5_{i}"), LEG);
            }
        }
        "unimal_5506-10-14-17-10-38-34" => {
            add("torso_0", TORSO);
            add("d1_limb_12", THIGH);
            add("d1_limb_13", THIGH);
            add("d2_limb_16", LEG);
            add("d2_limb_17", LEG);
            for i in 0..5 {
                add(&format!("limb_end_{i}"), NONE);
            }
        }
        "unimal_5506-12-11-17-05-56-16" => {
            add("torso_0", TORSO);
            add("d1_limb_0", THIGH);
            add("d2_limb_10", LEG);
            add("d2_limb_11", LEG);
            add("d3_limb_12", FOOT);
            add("d3_limb_13", FOOT);
            for i in 0..3 {
                add(&format!("limb_end_{i}"), NONE);
            }
        }
        "unimal_5506-13-5-02-21-35-41" => {
            add("torso_0", TORSO);
            add("d1_limb_2", THIGH);
            add("d1_limb_3", THIGH);
            for i in 0..4 {
                add(&format!("limb_end_{i}"), NONE);
            }
        }
        "unimal_5506-15-11-01-10-04-14" => {
            add("torso_0", TORSO);
            add("d1_limb_0", THIGH);
            add("d1_limb_1", THIGH);
            for i in 0..4 {
                add(&format!("limb_end_{i}"), NONE);
            }
        }
        other => panic!("no release table written for {other}"),
    }
    t
}

fn limb_of(scalars: &[f32]) -> Option<usize> {
    let limb = &scalars[3..7];
    assert!(limb.iter().all(|&x| x == 0.0 || x == 1.0) && limb.iter().sum::<f32>() <= 1.0, "{limb:?}");
    limb.iter().position(|&x| x == 1.0)
}

#[test]
fn limb_types_follow_the_release_amorpheus_table_for_every_builtin_morphology() {
    for m in &MORPHOLOGIES {
        let table = release_table(m.name);
        let scene = Scene::from_name(&format!("team_reach:agents={};R=5;balls=1", m.name)).unwrap();
        let o = &scene.obs_spec;
        let prefix = &scene.agents[0].prefix;
        let mut seen = vec![false; table.len()];
        for n in 0..o.n_nodes - o.n_balls {
            let body = o.node_body[n].unwrap();
            let name = scene.model.bodies[body].name.strip_prefix(prefix.as_str()).unwrap();
            let Some(i) = table.iter().position(|(b, _)| b == name) else {
                panic!("{}: body {name:?} (node {n}) is not in the test's table", m.name)
            };
            seen[i] = true;
            let got = limb_of(&o.static_scalars[n * N_SCALARS..(n + 1) * N_SCALARS]);
            assert_eq!(got, table[i].1, "{}: body {name:?} (node {n})", m.name);
        }
        // Every body of the morphology shows on some node: the root, or a DoF node.
        for (i, (name, _)) in table.iter().enumerate() {
            assert!(seen[i], "{}: body {name:?} has no node", m.name);
        }
        assert_eq!(table.len(), scene.agents[0].bodies.len(), "{}: bodies", m.name);
    }
    // The stepped observation carries the same limb types (2_unimals: limb ends all zero).
    let mut env = VecEnv::from_name("team_reach/2_unimals", 2, 3, StartMode::Random).unwrap();
    let o = env.scene().obs_spec.clone();
    let out = env.step(&vec![0.3; 2 * env.n_actions()]).unwrap();
    for e in 0..2 {
        for n in 0..o.n_nodes {
            let s = out.obs.node_scalars(e, n);
            assert_eq!(&s[..7], &o.static_scalars[n * N_SCALARS..n * N_SCALARS + 7], "env {e} node {n}");
        }
    }
    let zero_limb = (0..o.n_nodes - o.n_balls).filter(|&n| limb_of(out.obs.node_scalars(0, n)).is_none()).count();
    // unimal_1's limb_end_0..4 (limb_end_2 and limb_end_3 hang on 2-DoF joints: 7 nodes) and
    // unimal_2's limb_end_0..2 (3 nodes).
    assert_eq!(zero_limb, 7 + 3);
}

/// Entity-type columns `0..3` of node `n` in row `e` of `[B, N, N_SCALARS]` scalars.
fn entity(scalars: &[f32], nodes: usize, e: usize, n: usize) -> [f32; 3] {
    let i = (e * nodes + n) * N_SCALARS;
    [scalars[i], scalars[i + 1], scalars[i + 2]]
}

fn one_hot(k: usize) -> [f32; 3] {
    let mut v = [0.0; 3];
    v[k] = 1.0;
    v
}

#[test]
fn sumo_entity_types_are_team_0s_view_and_to_team_view_swaps_own_and_opponent() {
    assert_eq!((ENTITY_AGENT, ENTITY_OPPONENT, ENTITY_GOAL, ENTITY_CENTRE), (0, 1, 1, 2));
    let mut env = VecEnv::from_name("team_sumo/2_ant_claw", 3, 11, StartMode::Random).unwrap();
    let o = env.scene().obs_spec.clone();
    let out = env.step(&vec![0.5; 3 * env.n_actions()]).unwrap().clone();
    let nn = o.n_nodes;
    let raw = out.obs.scalars.clone();
    let team_of = |n: usize| o.node_team[n];
    // Raw (team 0's view): own agents column 0, opponents column 1, centre column 2.
    let mut counts = [0; 3];
    for e in 0..3 {
        for n in 0..nn {
            let want = match team_of(n) {
                0 => one_hot(ENTITY_AGENT),
                1 => one_hot(ENTITY_OPPONENT),
                _ => one_hot(ENTITY_CENTRE),
            };
            assert_eq!(entity(&raw, nn, e, n), want, "env {e} node {n}");
            assert_eq!(entity(&o.static_scalars, nn, 0, n), want, "static node {n}");
            if e == 0 {
                counts[(team_of(n) + 3) as usize % 3] += 1;
            }
        }
    }
    // Team 0: ant (9 nodes) + claw (17); team 1 the same; one centre ball.
    assert_eq!(counts, [26, 26, 1]);
    // Team 0's view is the raw observation.
    let mut v0 = raw.clone();
    o.to_team_view(0, &mut v0).unwrap();
    assert_eq!(v0, raw);
    // Team 1's view: its agents in column 0, team 0's in column 1, the centre unchanged,
    // every other scalar (limb types, angles, limits) unchanged.
    let mut v1 = raw.clone();
    o.to_team_view(1, &mut v1).unwrap();
    for e in 0..3 {
        for n in 0..nn {
            let want = match team_of(n) {
                1 => one_hot(ENTITY_AGENT),
                0 => one_hot(ENTITY_OPPONENT),
                _ => one_hot(ENTITY_CENTRE),
            };
            assert_eq!(entity(&v1, nn, e, n), want, "team 1 view, env {e} node {n}");
            let i = (e * nn + n) * N_SCALARS;
            assert_eq!(&v1[i + 3..i + N_SCALARS], &raw[i + 3..i + N_SCALARS]);
        }
    }
    // Twice is the identity; any element type works (here f64, one row = the static scalars).
    let mut back = v1.clone();
    o.to_team_view(1, &mut back).unwrap();
    assert_eq!(back, raw);
    let mut s64: Vec<f64> = o.static_scalars.iter().map(|&x| x as f64).collect();
    o.to_team_view(1, &mut s64).unwrap();
    let root1 = o.agent_root_node[2];
    assert_eq!(o.agent_team[2], 1);
    assert_eq!(&s64[root1 * N_SCALARS..root1 * N_SCALARS + 3], &[1.0, 0.0, 0.0]);
    // Bad input: a team the game does not have, a length that is not whole rows.
    assert!(matches!(o.to_team_view(2, &mut v1.clone()), Err(envs::layout::LayoutError(_))));
    let mut short = raw[..nn * N_SCALARS - 1].to_vec();
    let err = o.to_team_view(1, &mut short).unwrap_err();
    assert!(err.to_string().contains("scalars"), "{err}");
    assert_eq!(short, raw[..nn * N_SCALARS - 1]);
}

#[test]
fn reach_entity_types_are_agent_and_goal_and_no_view_changes_them() {
    let mut env = VecEnv::from_name("team_reach/2_ant_claw", 2, 5, StartMode::Random).unwrap();
    let o = env.scene().obs_spec.clone();
    let out = env.step(&vec![-0.2; 2 * env.n_actions()]).unwrap().clone();
    let nn = o.n_nodes;
    for e in 0..2 {
        for n in 0..nn {
            let want = if o.node_agent[n] >= 0 { one_hot(ENTITY_AGENT) } else { one_hot(ENTITY_GOAL) };
            assert_eq!(entity(&out.obs.scalars, nn, e, n), want, "env {e} node {n}");
        }
    }
    let mut v = out.obs.scalars.clone();
    o.to_team_view(0, &mut v).unwrap();
    assert_eq!(v, out.obs.scalars);
    // Reach has one team: team 1 is an error and leaves the array alone.
    let err = o.to_team_view(1, &mut v).unwrap_err();
    assert!(matches!(err, envs::layout::LayoutError(_)) && err.to_string().contains("team"), "{err}");
    assert_eq!(v, out.obs.scalars);
}

#[test]
fn bodies_missing_from_the_release_table_keep_the_depth_rule() {
    // The claw with `Aux 2_i` and `$ Body 4_i` renamed: no longer in the table, so they are typed by
    // the number of joints down from the torso (2 leg, 3 foot); the hips keep "Aux 1" (thigh).
    let claw = MORPHOLOGIES.iter().find(|m| m.name == "claw").unwrap();
    let text = claw.text.replace("Aux 2_", "knee_").replace("$ Body 4_", "shin_");
    let path = std::env::temp_dir().join(format!("envs_limb_rule_{}.txt", std::process::id()));
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_name(&format!("team_reach:agents={};balls=1", path.display()));
    std::fs::remove_file(&path).unwrap();
    let scene = scene.unwrap();
    let o = &scene.obs_spec;
    let prefix = &scene.agents[0].prefix;
    let mut seen = [0; 4];
    for n in 0..o.n_nodes - o.n_balls {
        let name = scene.model.bodies[o.node_body[n].unwrap()].name.strip_prefix(prefix.as_str()).unwrap();
        let want = match name.split('_').next().unwrap() {
            "torso" => TORSO,
            "Aux 1" => THIGH,
            "knee" => LEG,
            "shin" => FOOT,
            other => panic!("unexpected body {other:?}"),
        };
        assert_eq!(limb_of(&o.static_scalars[n * N_SCALARS..(n + 1) * N_SCALARS]), want, "{name}");
        seen[want.unwrap()] += 1;
    }
    // Root; 4 hips with 2 DoF each; 4 knees; 4 ankles.
    assert_eq!(seen, [1, 8, 4, 4]);
}
