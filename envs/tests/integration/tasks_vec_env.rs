//! Batched stepping: names and compositions, observation layout, determinism (same seed
//! same bits, 1 vs 2 threads), fresh starts every episode (or each environment's first start
//! again, the release's reset), and the true final observation on auto-reset.

#![allow(clippy::needless_range_loop)] // index loops mirror the array layouts

use envs::layout::N_SCALARS;
use envs::tasks::outcome::Outcome;
use envs::tasks::{BUILTIN_NAMES, Scene, StartMode, StepOutput, TaskError, TaskSpec, VecEnv};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_actions(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0f32..1.0)).collect()
}

/// Runs `steps` control steps with seeded random actions; returns every output.
fn rollout(spec: &TaskSpec, batch: usize, seed: u64, steps: usize) -> Vec<StepOutput> {
    let mut env = VecEnv::new(spec, batch, seed, StartMode::Random).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xabc);
    (0..steps)
        .map(|_| {
            let a = random_actions(&mut rng, batch * env.n_actions());
            env.step(&a).unwrap().clone()
        })
        .collect()
}

fn bits(outs: &[StepOutput]) -> Vec<u32> {
    outs.iter()
        .flat_map(|o| {
            o.obs.vectors.iter().chain(&o.obs.scalars).chain(&o.obs.heading).chain(&o.reward).map(|x| x.to_bits())
        })
        .collect()
}

#[test]
fn builtin_names_build_with_the_documented_layout() {
    // (name, agents, actions, balls, teams)
    let want = [
        ("team_reach/1_ant", 1, 8, 1, 1),
        ("team_reach/1_centipede", 1, 14, 1, 1),
        ("team_reach/2_ants", 2, 16, 2, 1),
        ("team_reach/2_ant_claw", 2, 24, 2, 1),
        ("team_reach/2_unimals", 2, 23, 2, 1),
        ("team_reach/3_ant_claw_centipede", 3, 38, 3, 1),
        ("team_sumo/1_centipede", 2, 28, 1, 2),
        ("team_sumo/2_ants", 4, 32, 1, 2),
        ("team_sumo/2_ant_claw", 4, 48, 1, 2),
        ("team_sumo/3_ants", 6, 48, 1, 2),
    ];
    assert_eq!(want.len(), BUILTIN_NAMES.len());
    for (name, agents, actions, balls, teams) in want {
        let s = Scene::from_name(name).unwrap();
        let o = &s.obs_spec;
        assert_eq!((s.n_agents(), s.n_actions, o.n_balls, o.n_teams), (agents, actions, balls, teams), "{name}");
        assert_eq!(o.n_nodes, agents + actions + balls, "{name}");
        assert_eq!(o.static_scalars.len(), o.n_nodes * N_SCALARS);
        for (a, layout) in s.agents.iter().enumerate() {
            let root = o.agent_root_node[a];
            assert_eq!(o.agent_action_offset[a], layout.action_offset);
            for k in 0..o.agent_dof[a] {
                // Node of action k: its parent is an earlier-or-later node of the same agent.
                let node = root + 1 + k;
                let p = o.node_parent[node];
                assert!(p >= 0 && o.node_agent[p as usize] == a as i32, "{name}: node {node} parent {p}");
                assert_eq!(o.node_joint[node], Some(s.model.actuators[layout.actuators[k]].joint));
                // Following parents reaches the root without cycles.
                let (mut n, mut hops) = (node, 0);
                while n != root {
                    n = o.node_parent[n] as usize;
                    hops += 1;
                    assert!(hops < 64, "{name}: parent cycle");
                }
            }
            assert_eq!(o.node_parent[root], -1);
            assert_eq!(o.agent_team[a], layout.team);
        }
        // Scalars: one entity type and (for agents) at most one limb type per node (none for
        // the unimals' limb ends, as in the release: tasks_observation_types.rs); limits scaled.
        for n in 0..o.n_nodes {
            let sc = &o.static_scalars[n * N_SCALARS..(n + 1) * N_SCALARS];
            assert_eq!(sc[..3].iter().sum::<f32>(), 1.0);
            let limbs: f32 = sc[3..7].iter().sum();
            if o.node_agent[n] >= 0 {
                assert!(limbs == 1.0 || (limbs == 0.0 && name.contains("unimals")), "{name}: node {n} limbs {limbs}");
            } else {
                assert_eq!(limbs, 0.0);
            }
            assert!(sc[8] <= sc[9] && (0.0..=1.0).contains(&sc[8]) && (0.0..=1.0).contains(&sc[9]));
        }
    }
    // Agent views: own nodes, then every other entity's root.
    let s = Scene::from_name("team_sumo/2_ant_claw").unwrap();
    let o = &s.obs_spec;
    let view = o.agent_view(1); // the claw of team 0: 1 + 16 own nodes
    assert_eq!(view.len(), 17 + 3 + 1);
    assert_eq!(view[0], o.agent_root_node[1]);
    assert_eq!(&view[17..], &[o.agent_root_node[0], o.agent_root_node[2], o.agent_root_node[3], o.n_nodes - 1]);
    assert!(o.agent_view(4).is_empty());
    // The ant: torso root, four hips (thigh) and four ankles (leg).
    let s = Scene::from_name("team_reach/1_ant").unwrap();
    let limb =
        |n: usize| s.obs_spec.static_scalars[n * N_SCALARS + 3..n * N_SCALARS + 7].iter().position(|&x| x == 1.0);
    let limbs: Vec<_> = (0..9).map(limb).collect();
    assert_eq!(limbs.iter().filter(|l| **l == Some(0)).count(), 1);
    assert_eq!(limbs.iter().filter(|l| **l == Some(1)).count(), 4);
    assert_eq!(limbs.iter().filter(|l| **l == Some(2)).count(), 4);
}

#[test]
fn unknown_names_and_bad_compositions_are_clear_errors() {
    let e = TaskSpec::from_name("team_reach/4_ants").unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, TaskError::UnknownEnv { .. }));
    for n in BUILTIN_NAMES {
        assert!(msg.contains(n), "{msg}");
    }
    let s = TaskSpec::from_name("team_reach:agents=ant+claw;R=4;balls=1").unwrap();
    assert_eq!((s.teams.clone(), s.radius, s.balls), (vec![vec!["ant".to_string(), "claw".to_string()]], 4.0, 1));
    let s = TaskSpec::from_name("team_sumo:team1=centipede;team2=ant+ant").unwrap();
    assert_eq!(s.n_agents(), 3);
    assert_eq!(s.radius, 3.0);
    for (bad, needle) in [
        ("team_reach:agents=ant;balls=2", "balls"),
        ("team_reach:agents=ant;R=-1", "R"),
        ("team_reach:agents=ant;R=abc", "abc"),
        ("team_reach:agents=ant++claw", "agents"),
        ("team_reach:agents=ant;colour=red", "colour"),
        ("team_sumo:team1=ant;team2=ant;R=1.5", "R"),
        ("team_sumo:team1=ant", "team2"),
    ] {
        let e = TaskSpec::from_name(bad).unwrap_err().to_string();
        assert!(e.contains(needle), "{bad}: {e}");
    }
    let e = Scene::from_name("team_reach:agents=ant+spider").unwrap_err().to_string();
    assert!(e.contains("spider") && e.contains("centipede"), "{e}");
    // A morphology file that does not exist is a file that cannot be read, not an unknown
    // name; one without an actuated joint is refused before any network is sized for it.
    let dir = std::env::temp_dir().join(format!("envs-morphology-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("missing.txt");
    let e = Scene::from_name(&format!("team_reach:agents={}", missing.display())).unwrap_err().to_string();
    assert!(e.contains("missing.txt") && e.contains("cannot read") && !e.contains("unknown"), "{e}");
    let still = dir.join("still.txt");
    std::fs::write(&still, "bodies {\n  name: \"torso\"\n  colliders {\n    capsule {\n      radius: 0.25\n      length: 0.5\n    }\n  }\n  mass: 10.0\n}\n").unwrap();
    let e = Scene::from_name(&format!("team_reach:agents={}", still.display())).unwrap_err().to_string();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(e.contains("still.txt") && e.contains("no actuated joint"), "{e}");
    let mut env = VecEnv::from_name("team_reach/1_ant", 2, 0, StartMode::Random).unwrap();
    let e = env.step(&[0.0; 3]).unwrap_err().to_string();
    assert!(e.contains("3 values") && e.contains("16"), "{e}");
    let mut a = vec![0.0; 16];
    a[11] = f32::NAN;
    let e = env.step(&a).unwrap_err().to_string();
    assert!(e.contains("actions[11]") && e.contains("environment 1"), "{e}");
    assert!(VecEnv::from_name("team_reach/1_ant", 0, 0, StartMode::Random).is_err());
    // An impossible size is refused before anything is allocated (it used to abort the
    // process, from Python too, when the allocation failed).
    for batch in [envs::tasks::MAX_ENVS + 1, 1 << 40] {
        let e = VecEnv::from_name("team_reach/1_ant", batch, 0, StartMode::Random).unwrap_err().to_string();
        assert!(e.contains(&format!("batch = {batch}")) && e.contains("1048576"), "{e}");
    }
}

#[test]
fn same_seed_same_bits_whatever_the_thread_count() {
    let spec = TaskSpec::from_name("team_sumo/2_ants").unwrap();
    let run = |threads: usize, seed: u64| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| bits(&rollout(&spec, 5, seed, 30)))
    };
    let one = run(1, 7);
    assert_eq!(one, run(2, 7));
    assert_eq!(one, run(2, 7));
    assert_ne!(one, run(1, 8));
}

#[test]
fn every_episode_gets_a_fresh_start_and_auto_reset_keeps_the_true_final_observation() {
    let long = TaskSpec::from_name("team_reach/2_ants").unwrap();
    let short = TaskSpec { episode_steps: 12, ..long.clone() };
    let (b, seed) = (3, 21);
    let mut env = VecEnv::new(&short, b, seed, StartMode::Random).unwrap();
    let mut twin = VecEnv::new(&long, b, seed, StartMode::Random).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let first_balls: Vec<_> = (0..b).map(|e| env.balls(e).unwrap().to_vec()).collect();
    for step in 1..=12 {
        let a = random_actions(&mut rng, b * env.n_actions());
        let out = env.step(&a).unwrap().clone();
        let twin_out = twin.step(&a).unwrap();
        let last = step == 12;
        assert_eq!(out.truncated, vec![last; b]);
        assert_eq!(out.terminated, vec![false; b]);
        assert_eq!(out.episode_len, vec![step as u32; b]);
        assert_eq!(out.reward, twin_out.reward);
        if last {
            assert_eq!(out.outcome, vec![Outcome::TimeLimit; b]);
            // The final observation is what the episode would have shown had it gone on.
            assert_eq!(out.final_obs, twin_out.obs);
            assert_ne!(out.obs, twin_out.obs);
            for e in 0..b {
                assert_eq!(env.episode_step(e), Some(0));
                assert_ne!(env.balls(e).unwrap(), first_balls[e].as_slice(), "env {e}: the start repeated");
            }
        } else {
            assert_eq!(out.obs, twin_out.obs);
        }
    }
    // The new episode's observation is that of its start: stepping on from it works.
    env.step(&vec![0.0; b * env.n_actions()]).unwrap();
    assert_eq!(env.episode_step(0), Some(1));
}

#[test]
fn per_slot_starts_return_each_environment_to_its_first_start_as_the_release_resets() {
    let spec = TaskSpec { episode_steps: 6, ..TaskSpec::from_name("team_reach/2_ants").unwrap() };
    let (b, seed) = (4, 5);
    let mut kept = VecEnv::new(&spec, b, seed, StartMode::PerSlot).unwrap();
    let mut fresh = VecEnv::new(&spec, b, seed, StartMode::Random).unwrap();
    assert_eq!(kept.start_mode(), StartMode::PerSlot);
    // The first episode is the same draw as under Random: same observations and balls.
    assert_eq!(kept.obs(), fresh.obs());
    let first_balls: Vec<Vec<[f64; 2]>> = (0..b).map(|e| kept.balls(e).unwrap().to_vec()).collect();
    let first_obs = kept.obs().clone();
    for e in 1..b {
        assert_ne!(first_balls[e], first_balls[0], "environments {e} and 0 drew the same start");
    }
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for episode in 1..=3 {
        for _ in 0..6 {
            let a = random_actions(&mut rng, b * kept.n_actions());
            kept.step(&a).unwrap();
            fresh.step(&a).unwrap();
        }
        assert_eq!(kept.output().truncated, vec![true; b], "episode {episode} ends at the time limit");
        // Every environment is back at its own first start; under Random it is not.
        assert_eq!(kept.obs(), &first_obs, "episode {} did not begin at the first start", episode + 1);
        for e in 0..b {
            assert_eq!(kept.balls(e).unwrap(), first_balls[e].as_slice());
            assert_ne!(fresh.balls(e).unwrap(), first_balls[e].as_slice(), "env {e}: Random repeated its start");
        }
    }
    // reset() begins every environment at its first start too.
    kept.reset();
    assert_eq!(kept.obs(), &first_obs);
}

#[test]
fn observations_match_the_simulator_state() {
    let mut env = VecEnv::from_name("team_reach/1_ant", 2, 3, StartMode::Random).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..10 {
        let a = random_actions(&mut rng, 2 * env.n_actions());
        env.step(&a).unwrap();
    }
    let (scene, d, obs) = (env.scene(), env.data(1).unwrap(), env.obs());
    let o = &scene.obs_spec;
    let root = scene.agents[0].root_body;
    let p = obs.vector(1, o.agent_root_node[0], 0);
    for k in 0..3 {
        assert_eq!(p[k], d.xpos[root][k] as f32);
    }
    // Root linear velocity = free joint velocity; angular velocity = R * body-frame omega.
    let v = obs.vector(1, 0, 1);
    for k in 0..3 {
        assert!((v[k] as f64 - d.qvel[k].clamp(-10.0, 10.0)).abs() < 1e-5);
    }
    let w_body = [d.qvel[3], d.qvel[4], d.qvel[5]];
    let m = d.xmat[root];
    let w = obs.vector(1, 0, 2);
    for k in 0..3 {
        let wk = m[k][0] * w_body[0] + m[k][1] * w_body[1] + m[k][2] * w_body[2];
        assert!((w[k] as f64 - wk).abs() < 1e-4 * (1.0 + wk.abs()));
    }
    // Every body's linear velocity: central differences of its position along qvel.
    let eps = 1e-6;
    let moved = |sign: f64| {
        let mut d2 = d.clone();
        envs::integrator::integrate_pos(&scene.model, &mut d2.qpos, &d.qvel, sign * eps);
        envs::kinematics::kinematics(&scene.model, &mut d2);
        d2.xpos
    };
    let (plus, minus) = (moved(1.0), moved(-1.0));
    for n in 0..9 {
        let b = o.node_body[n].unwrap();
        let v = obs.vector(1, n, 1);
        for k in 0..3 {
            let fd = ((plus[b][k] - minus[b][k]) / (2.0 * eps)).clamp(-10.0, 10.0);
            assert!((v[k] as f64 - fd).abs() < 1e-4 * (1.0 + fd.abs()), "node {n}: {v:?} vs {fd}");
        }
    }
    // Joint angles and limits scaled.
    for n in 1..9 {
        let j = &scene.model.joints[o.node_joint[n].unwrap()];
        let x = (d.qpos[j.qpos_adr] - j.range[0]) / (j.range[1] - j.range[0]);
        assert!((obs.node_scalars(1, n)[7] as f64 - x).abs() < 1e-6);
        let lo = (180.0 + j.range[0].to_degrees()) / 360.0;
        assert!((obs.node_scalars(1, n)[8] as f64 - lo).abs() < 1e-6);
    }
    let yaw = m[1][0].atan2(m[0][0]);
    assert!((obs.heading[1] as f64 - yaw).abs() < 1e-6);
    // Ball node: position of the episode's ball, zero velocities.
    let ball = env.balls(1).unwrap()[0];
    let bp = obs.vector(1, o.entity_root_node[1], 0);
    assert_eq!([bp[0], bp[1]], [ball[0] as f32, ball[1] as f32]);
    assert_eq!(obs.vector(1, o.entity_root_node[1], 1), [0.0; 3]);
}

#[test]
fn every_builtin_stays_finite_under_bang_bang_actions() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for name in BUILTIN_NAMES {
        let b = 4;
        let mut env = VecEnv::from_name(name, b, 3, StartMode::Random).unwrap();
        for _ in 0..100 {
            let a: Vec<f32> = (0..b * env.n_actions()).map(|_| if rng.random_bool(0.5) { 1.0 } else { -1.0 }).collect();
            let out = env.step(&a).unwrap();
            assert!(!out.outcome.contains(&Outcome::Diverged), "{name} diverged");
            assert!(out.obs.vectors.iter().chain(&out.reward).all(|x| x.is_finite()), "{name}");
        }
    }
}

/// Values inside the loaders' ranges can still make a body numerically massless (a 1e-6 kg,
/// 0.1 mm limb without armature under a 1e6 kg torso): the simulator's refusal names the body
/// and the morphology file (before: "mass matrix not positive definite at
/// dof 7: a moving body lacks mass or inertia", nothing else).
#[test]
fn a_singular_body_is_named_with_its_morphology() {
    let ant = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/ant.txt")).unwrap();
    let foot = ant.find("name: \"$ Body 4_0\"").unwrap();
    let mass = foot + ant[foot..].find("mass: 1").unwrap();
    let mut text = format!("{}mass: 0.000001{}", &ant[..mass], &ant[mass + "mass: 1".len()..]);
    text = text.replacen("mass: 10", "mass: 1e6", 1);
    text = text.replacen(
        "radius: 0.08\n          length: 0.7256854176521301",
        "radius: 0.0001\n          length: 0.0002",
        1,
    );
    let act = text.find("joint: \"Aux 1_$ Body 4_0\"").unwrap();
    let strength = act + text[act..].find("strength: 350.0").unwrap();
    text.replace_range(strength..strength + "strength: 350.0".len(), "strength: 0.0");
    let dir = std::env::temp_dir().join(format!("envs-singular-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("feather_foot.txt");
    std::fs::write(&file, text).unwrap();
    let e = Scene::from_name(&format!("team_reach:agents=ant+{}", file.display())).unwrap_err().to_string();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(e.contains("mass matrix not positive definite"), "{e}");
    assert!(e.contains("body \"a1/$ Body 4_0\"") && e.contains("agent a1") && e.contains("feather_foot.txt"), "{e}");
}

/// Issue 77 item 9: scenes too large for the collision pairs are refused before anything is
/// built (thousands of agents used to abort the process while building them): more than
/// `MAX_AGENTS` agents by the composition, fewer agents of many bodies by counting their
/// candidate contact pairs; each error names the field and the count.
#[test]
fn scenes_beyond_the_size_limits_are_refused_before_building() {
    use envs::tasks::{MAX_AGENTS, MAX_CONTACT_PAIRS, Scene};
    let many = vec!["ant"; 3000].join("+");
    let e = Scene::from_name(&format!("team_reach:agents={many};R=50;balls=1")).unwrap_err().to_string();
    assert!(e.contains("agents") && e.contains("3000") && e.contains(&format!("at most {MAX_AGENTS}")), "{e}");
    let centipedes = vec!["centipede"; MAX_AGENTS].join("+");
    let e = Scene::from_name(&format!("team_reach:agents={centipedes};R=50;balls=1")).unwrap_err().to_string();
    assert!(e.contains("candidate contact pairs") && e.contains(&MAX_CONTACT_PAIRS.to_string()), "{e}");
}
