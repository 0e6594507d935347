//! Tests of SHNN's entity stage on real MeBen observations: input processing, the task
//! assignment graph, entity-level message passing and the local reference frame.

use crate::common;

use common::{max_diff, rng, transform};
use envs::layout::{NODE_VECTOR_LEN, ObsBatch, ObsSpec};
use envs::tasks::{StartMode, VecEnv};
use models::entity_graph::GraphTask;
use models::frame::to_frame;
use models::{
    AssignmentMethod, EntityAbstraction, EntityGraph, EntityInputs, EntityMp, EntityMpConfig, GraphBuilder,
    InputProcessor, Translation, UNASSIGNED,
};
use nn::{Aggregation, Bound, EdgeDistance, EdgeList, ParamStore};
use rand::RngExt;
use tensor::gradcheck::check_gradients;
use tensor::{Tape, Tensor};

const B: usize = 3;

/// Observations of `name` after a few random control steps (so that velocities are not
/// zero), converted to `f64`: `(spec, vectors, scalars)`.
fn observations(name: &str, seed: u64) -> (ObsSpec, Vec<f64>, Vec<f64>) {
    let mut env = VecEnv::from_name(name, B, seed, StartMode::Random).unwrap();
    let mut r = rng(seed);
    let na = env.n_actions();
    for _ in 0..3 {
        let actions: Vec<f32> = (0..B * na).map(|_| r.random_range(-1.0..1.0)).collect();
        env.step(&actions).unwrap();
    }
    let o = env.obs();
    let spec = env.scene().obs_spec.clone();
    (spec, o.vectors.iter().map(|&x| x as f64).collect(), o.scalars.iter().map(|&x| x as f64).collect())
}

/// Left-multiplies every `[3, m]` block of `x` by the rotation about z by `angle`.
fn rotate_rows(x: &[f64], m: usize, angle: f64) -> Vec<f64> {
    let (s, c) = angle.sin_cos();
    let mut out = x.to_vec();
    for (blk, o) in x.chunks(3 * m).zip(out.chunks_mut(3 * m)) {
        for k in 0..m {
            let (a, b) = (blk[k], blk[m + k]);
            o[k] = c * a - s * b;
            o[m + k] = s * a + c * b;
        }
    }
    out
}

struct Stage {
    inputs: EntityInputs<f64>,
    graph: EntityGraph,
    z: Vec<f64>,
    h: Vec<f64>,
    u: Vec<f64>,
    frame: Vec<f64>,
    /// Per own agent: `O_a^T Z_{a,k}` of its body nodes (eq. (lrf)), flattened.
    local_bodies: Vec<Vec<f64>>,
    bodies_h: Vec<Vec<f64>>,
}

/// The entity stage on one batch of f64 observations (team `team`'s view).
fn run_stage(
    spec: &ObsSpec,
    (mp, store): (&EntityMp, &ParamStore<f64>),
    vectors: &[f64],
    scalars: &[f64],
    method: AssignmentMethod,
    team: usize,
    abstraction: EntityAbstraction,
) -> Stage {
    let obs = ObsBatch::new(B, spec.n_nodes, vectors, scalars).unwrap();
    let proc = InputProcessor::new(spec, Translation::Assigned).unwrap().with_abstraction(abstraction);
    let inputs = proc.entities::<f64, f64>(&obs).unwrap();
    let graph = GraphBuilder::new(spec, method, team, 7).unwrap().build(&inputs).unwrap();
    let own: Vec<usize> = (0..spec.n_agents).filter(|&a| spec.agent_team[a] == team).collect();
    let bodies = proc.bodies(&obs, &inputs, &graph.agent_entity, &own).unwrap();
    let tape = Tape::new();
    let p = store.bind(&tape);
    let z = proc.actor_entities(&inputs, &graph, &own, models::NeighbourOffset::Unit).unwrap();
    let f = mp.forward_inputs(&p, z, &inputs, &graph).unwrap();
    let (frame, u) = (f.frame.unwrap(), f.u.unwrap());
    let neighbours = proc.neighbours(&obs, &graph, &bodies, models::NeighbourOffset::Unit).unwrap();
    let mut local_bodies = Vec::new();
    for (body, nr) in bodies.iter().zip(&neighbours) {
        // The frame of agent a in every scene, repeated over its K nodes and its neighbours.
        for z in [&body.z, &nr.z] {
            let k = z.shape()[1];
            let rows: Vec<usize> =
                inputs.rows_of(body.agent).into_iter().flat_map(|r| std::iter::repeat_n(r, k)).collect();
            let o = frame.index_select(0, &rows).unwrap();
            let z = tape.constant(z.reshape(&[B * k, 3, 3]).unwrap());
            local_bodies.push(to_frame(o, z).unwrap().value().to_vec());
        }
    }
    Stage {
        z: f.z.value().to_vec(),
        h: f.h.value().to_vec(),
        u: u.value().to_vec(),
        frame: frame.value().to_vec(),
        bodies_h: bodies.iter().map(|b| b.h.to_vec()).collect(),
        local_bodies,
        inputs,
        graph,
    }
}

fn paper_model(spec: &ObsSpec, seed: u64) -> (ParamStore<f64>, EntityMp) {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(seed);
    let mp = EntityMp::new(&mut store.scope("entity", &mut init), EntityMpConfig::paper(spec)).unwrap();
    (store, mp)
}

#[test]
fn entity_stage_is_invariant_under_rotations_about_gravity_and_horizontal_translations() {
    for (name, team) in [("team_reach/2_ants", 0), ("team_sumo/2_ants", 0), ("team_sumo/2_ants", 1)] {
        let (spec, vectors, scalars) = observations(name, 11);
        let (store, mp) = paper_model(&spec, 3);
        let m = mp.config.vectors;
        for (method, abstraction) in [
            (AssignmentMethod::Greedy, EntityAbstraction::Root),
            (AssignmentMethod::Hungarian, EntityAbstraction::Root),
            (AssignmentMethod::None, EntityAbstraction::Root),
            (AssignmentMethod::Greedy, EntityAbstraction::Mean),
        ] {
            let stage = |v: &[f64]| run_stage(&spec, (&mp, &store), v, &scalars, method, team, abstraction);
            let base = stage(&vectors);
            let mut r = rng(5);
            for _ in 0..3 {
                let angle = r.random_range(0.0..std::f64::consts::TAU);
                let t = [r.random_range(-5.0..5.0), r.random_range(-5.0..5.0)];
                let moved = stage(&transform(&vectors, angle, t));
                let ctx = format!("{name} team {team} {method:?} {abstraction:?} angle {angle}");
                assert_eq!(moved.graph.edges, base.graph.edges, "{ctx}");
                assert_eq!(moved.graph.agent_entity, base.graph.agent_entity, "{ctx}");
                // Inputs: h invariant, Z rotated.
                assert!(max_diff(&moved.inputs.h.to_vec(), &base.inputs.h.to_vec()) < 1e-9, "{ctx}");
                let zin = rotate_rows(&base.inputs.z.to_vec(), 3, angle);
                assert!(max_diff(&moved.inputs.z.to_vec(), &zin) < 1e-9, "{ctx}");
                // Outputs: h' invariant, Z', u and O rotated.
                assert!(max_diff(&moved.h, &base.h) < 1e-9, "{ctx}: h' {}", max_diff(&moved.h, &base.h));
                assert!(max_diff(&moved.z, &rotate_rows(&base.z, m, angle)) < 1e-9, "{ctx}: Z'");
                assert!(max_diff(&moved.u, &rotate_rows(&base.u, 1, angle)) < 1e-9, "{ctx}: u");
                assert!(max_diff(&moved.frame, &rotate_rows(&base.frame, 3, angle)) < 1e-9, "{ctx}: O");
                // Eq. (lrf): the agents' body observations in their frames are invariant.
                for (a, b) in moved.local_bodies.iter().zip(&base.local_bodies) {
                    assert!(max_diff(a, b) < 1e-9, "{ctx}: O^T Z {}", max_diff(a, b));
                }
                assert_eq!(moved.bodies_h, base.bodies_h, "{ctx}");
            }
            // The check can fail: tilting the scene (about the x axis) changes h'.
            let tilt = {
                let (s, c) = 0.3f64.sin_cos();
                let mut v = vectors.clone();
                for q in v.chunks_mut(3) {
                    let (y, z) = (q[1], q[2]);
                    q[1] = c * y - s * z;
                    q[2] = s * y + c * z;
                }
                v
            };
            let tilted = stage(&tilt);
            assert!(max_diff(&tilted.h, &base.h) > 1e-6, "{name}: a tilt should change h'");
        }
    }
}

#[test]
fn translation_modes_are_shift_invariant_but_none_and_place_the_roots_as_documented() {
    let (spec, vectors, scalars) = observations("team_reach/2_ants", 4);
    let moved = transform(&vectors, 0.0, [2.0, -1.0]);
    for (mode, invariant) in [
        (Translation::None, false),
        (Translation::RootMean, true),
        (Translation::BodyMean, true),
        (Translation::Assigned, true),
    ] {
        let proc = InputProcessor::new(&spec, mode).unwrap();
        let run = |v: &[f64]| {
            let obs = ObsBatch::new(B, spec.n_nodes, v, &scalars).unwrap();
            let e = proc.entities::<f64, f64>(&obs).unwrap();
            let g = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 0, 0).unwrap().build(&e).unwrap();
            let b = proc.bodies(&obs, &e, &g.agent_entity, &[0, 1]).unwrap();
            let mut all = e.z.to_vec();
            b.iter().for_each(|x| all.extend(x.z.to_vec()));
            all
        };
        let d = max_diff(&run(&vectors), &run(&moved));
        assert_eq!(d < 1e-12, invariant, "{}: {d}", mode.name());
    }
    // AssignedEntity (the earlier reading): an agent's root position is measured from its
    // ball's centre. Assigned (Algorithm 1's labels): from its own root, and the actor's
    // entity rows put the agent at 0 and its ball at the unit direction from it; the
    // neighbour row is that ball, at the same unit direction (raw: the offset itself).
    for mode in [Translation::AssignedEntity, Translation::Assigned] {
        let proc = InputProcessor::new(&spec, mode).unwrap();
        let obs = ObsBatch::new(B, spec.n_nodes, &vectors, &scalars).unwrap();
        let e = proc.entities::<f64, f64>(&obs).unwrap();
        let g = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 0, 0).unwrap().build(&e).unwrap();
        let bodies = proc.bodies(&obs, &e, &g.agent_entity, &[0, 1]).unwrap();
        let actor = proc.actor_entities(&e, &g, &[0, 1], models::NeighbourOffset::Unit).unwrap().to_vec();
        let unit = proc.neighbours(&obs, &g, &bodies, models::NeighbourOffset::Unit).unwrap();
        let raw = proc.neighbours(&obs, &g, &bodies, models::NeighbourOffset::Raw).unwrap();
        let ne = spec.entity_root_node.len();
        for (a, body) in bodies.iter().enumerate() {
            for b in 0..B {
                let ball = g.agent_entity[b * 2 + a];
                assert!(ball >= 2, "every agent of 2_ants has a ball");
                assert_eq!(g.neighbour(b, a, 0), ball);
                let root = obs.vec3(b, spec.agent_root_node[a], 0);
                let centre = obs.vec3(b, spec.entity_root_node[ball], 0);
                let d: Vec<f64> = (0..3).map(|r| centre[r] - root[r]).collect();
                let len = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                let z = body.z.to_vec();
                let k = body.z.shape()[1];
                for r in 0..3 {
                    let expected = if mode == Translation::Assigned { 0.0 } else { root[r] - centre[r] };
                    assert!((z[(b * k) * NODE_VECTOR_LEN + r * 3] - expected).abs() < 1e-12, "{mode:?}");
                    if mode == Translation::Assigned {
                        assert_eq!(actor[((b * ne + a) * 3 + r) * 3], 0.0);
                        let dir = d[r] / (len + models::input::UNIT_EPS);
                        assert!((actor[((b * ne + ball) * 3 + r) * 3] - dir).abs() < 1e-12);
                        assert!((unit[a].z.to_vec()[b * NODE_VECTOR_LEN + r * 3] - dir).abs() < 1e-12);
                        assert!((raw[a].z.to_vec()[b * NODE_VECTOR_LEN + r * 3] - d[r]).abs() < 1e-12);
                        // Velocities unchanged.
                        assert_eq!(
                            unit[a].z.to_vec()[b * NODE_VECTOR_LEN + r * 3 + 1],
                            obs.vec3(b, spec.entity_root_node[ball], 1)[r]
                        );
                    }
                }
                if mode == Translation::Assigned {
                    let h = unit[a].h.to_vec();
                    for sc in 0..10 {
                        assert_eq!(h[b * 10 + sc], obs.scalar(b, spec.entity_root_node[ball], sc));
                    }
                }
            }
        }
    }
    assert!(Translation::parse("dense").unwrap_err().to_string().contains("root_mean"));
    assert_eq!(Translation::parse("body_mean").unwrap(), Translation::BodyMean);
}

#[test]
fn inputs_follow_the_observation_layout() {
    let (spec, vectors, scalars) = observations("team_sumo/2_ants", 2);
    let obs = ObsBatch::new(B, spec.n_nodes, &vectors, &scalars).unwrap();
    let e = InputProcessor::new(&spec, Translation::RootMean).unwrap().entities::<f64, f64>(&obs).unwrap();
    let ne = spec.entity_root_node.len();
    assert_eq!(e.z.shape(), [B * ne, 3, 3]);
    assert_eq!(e.h.shape(), [B * ne, 11]);
    let (z, h) = (e.z.to_vec(), e.h.to_vec());
    for b in 0..B {
        let roots: Vec<[f64; 3]> = spec.entity_root_node.iter().map(|&n| obs.vec3(b, n, 0)).collect();
        let c: Vec<f64> = (0..3).map(|r| roots.iter().map(|p| p[r]).sum::<f64>() / ne as f64).collect();
        for (i, &node) in spec.entity_root_node.iter().enumerate() {
            let row = b * ne + i;
            for r in 0..3 {
                assert!((z[row * NODE_VECTOR_LEN + r * 3] - (roots[i][r] - c[r])).abs() < 1e-12);
                assert_eq!(z[row * NODE_VECTOR_LEN + r * 3 + 1], obs.vec3(b, node, 1)[r]);
                assert_eq!(z[row * NODE_VECTOR_LEN + r * 3 + 2], obs.vec3(b, node, 2)[r]);
            }
            for s in 0..10 {
                assert_eq!(h[row * 11 + s], obs.scalar(b, node, s));
            }
            assert_eq!(h[row * 11 + 10], roots[i][2], "height");
        }
    }
    // Mean abstraction: an agent's vectors are the means over its nodes.
    let em = InputProcessor::new(&spec, Translation::None)
        .unwrap()
        .with_abstraction(EntityAbstraction::Mean)
        .entities::<f64, f64>(&obs)
        .unwrap();
    let zm = em.z.to_vec();
    for b in 0..B {
        for a in 0..spec.n_agents {
            let (root, k) = (spec.agent_root_node[a], 1 + spec.agent_dof[a]);
            for (ch, r) in (0..3).flat_map(|ch| (0..3).map(move |r| (ch, r))) {
                let mean = (root..root + k).map(|n| obs.vec3(b, n, ch)[r]).sum::<f64>() / k as f64;
                assert!((zm[(b * ne + a) * NODE_VECTOR_LEN + r * 3 + ch] - mean).abs() < 1e-12);
            }
        }
        // The centre ball is its own node.
        assert_eq!(zm[(b * ne + ne - 1) * NODE_VECTOR_LEN + 2 * 3], obs.vec3(b, spec.entity_root_node[ne - 1], 0)[2]);
    }
    assert!(EntityAbstraction::parse("all").unwrap_err().to_string().contains("root or mean"));
    // Mismatched arrays are errors that say what was expected.
    let err = ObsBatch::new(B, spec.n_nodes + 1, &vectors, &scalars).unwrap_err().to_string();
    assert!(err.contains("do not hold"), "{err}");
    let short = ObsBatch { batch: B, nodes: spec.n_nodes + 1, vectors: &vectors[..], scalars: &scalars[..] };
    assert!(InputProcessor::new(&spec, Translation::Assigned).unwrap().entities::<f64, f64>(&short).is_err());
    // f32 observations straight from the environment give the same features.
    let env = VecEnv::from_name("team_sumo/2_ants", B, 2, StartMode::Random).unwrap();
    let e32 = InputProcessor::new(&spec, Translation::RootMean)
        .unwrap()
        .entities::<f32, f32>(&ObsBatch::from_observation(env.obs()))
        .unwrap();
    assert_eq!(e32.z.shape(), [B * ne, 3, 3]);
}

/// Algorithm 1 written out literally: `D[i, :] = inf` after each match.
fn algorithm_1(pos_agents: &[[f64; 3]], pos_objects: &[[f64; 3]]) -> Vec<usize> {
    let n = pos_agents.len();
    let mut d: Vec<Vec<f64>> = pos_agents
        .iter()
        .map(|a| {
            pos_objects
                .iter()
                .map(|o| ((o[0] - a[0]).powi(2) + (o[1] - a[1]).powi(2) + (o[2] - a[2]).powi(2)).sqrt())
                .collect()
        })
        .collect();
    let mut out = Vec::new();
    for j in 0..pos_objects.len() {
        let i = (0..n).min_by(|&x, &y| d[x][j].total_cmp(&d[y][j])).unwrap();
        d[i].iter_mut().for_each(|v| *v = f64::INFINITY);
        out.push(i);
    }
    out
}

/// Writes root positions (agents then balls) into environment `b` of the arrays.
fn place(spec: &ObsSpec, vectors: &mut [f64], b: usize, roots: &[[f64; 3]]) {
    for (&node, p) in spec.entity_root_node.iter().zip(roots) {
        let i = (b * spec.n_nodes + node) * NODE_VECTOR_LEN;
        vectors[i..i + 3].copy_from_slice(p);
    }
}

fn graph_of(spec: &ObsSpec, vectors: &[f64], scalars: &[f64], method: AssignmentMethod, team: usize) -> EntityGraph {
    let obs = ObsBatch::new(B, spec.n_nodes, vectors, scalars).unwrap();
    let e = InputProcessor::new(spec, Translation::Assigned).unwrap().entities::<f64, f64>(&obs).unwrap();
    GraphBuilder::new(spec, method, team, 1).unwrap().build(&e).unwrap()
}

#[test]
fn greedy_assignment_matches_algorithm_1() {
    // Hand-made: balls b0 = (0, 0), b1 = (3, 0); agents a0 = (1, 0), a1 = (0, -1.5).
    // Algorithm 1: b0 takes a0 (1 < 1.5), then b1 the only free agent a1 (3.35); the
    // optimum (Hungarian) is b0 -> a1 (1.5), b1 -> a0 (2).
    let (spec, mut vectors, scalars) = observations("team_reach/2_ants", 1);
    let roots = [[1.0, 0.0, 0.1], [0.0, -1.5, 0.1], [0.0, 0.0, 0.1], [3.0, 0.0, 0.1]];
    for b in 0..B {
        place(&spec, &mut vectors, b, &roots);
    }
    let g = graph_of(&spec, &vectors, &scalars, AssignmentMethod::Greedy, 0);
    assert_eq!(g.agent_entity, [2, 3].repeat(B));
    assert_eq!(g.group, [0, 1, 0, 1].repeat(B));
    let h = graph_of(&spec, &vectors, &scalars, AssignmentMethod::Hungarian, 0);
    assert_eq!(h.agent_entity, [3, 2].repeat(B));
    assert_eq!(h.group, [0, 1, 1, 0].repeat(B));
    assert_eq!(g.edges.src, (0..B).flat_map(|b| [0, 1, 2, 3].map(|i| 4 * b + i)).collect::<Vec<_>>());
    assert_eq!(g.edges.dst, (0..B).flat_map(|b| [2, 3, 0, 1].map(|i| 4 * b + i)).collect::<Vec<_>>());

    // Three agents, two balls, random scenes: the builder equals Algorithm 1 written out;
    // the agent left over is alone (own group, no edges, unassigned).
    let (spec3, mut v3, s3) = observations("team_reach:agents=ant+ant+ant;R=5;balls=2", 3);
    let mut r = rng(9);
    for _ in 0..50 {
        let mut all = Vec::new();
        for b in 0..B {
            let roots: Vec<[f64; 3]> = (0..5)
                .map(|_| [r.random_range(-4.0..4.0), r.random_range(-4.0..4.0), r.random_range(0.1..0.6)])
                .collect();
            place(&spec3, &mut v3, b, &roots);
            all.push(roots);
        }
        let g = graph_of(&spec3, &v3, &s3, AssignmentMethod::Greedy, 0);
        for (b, roots) in all.iter().enumerate() {
            let expect = algorithm_1(&roots[..3], &roots[3..]);
            for (j, &a) in expect.iter().enumerate() {
                assert_eq!(g.agent_entity[b * 3 + a], 3 + j);
                assert_eq!(g.group[b * 5 + 3 + j], a);
            }
            let free = (0..3).find(|a| !expect.contains(a)).unwrap();
            assert_eq!(g.agent_entity[b * 3 + free], UNASSIGNED);
            assert!(!g.edges.src.contains(&(b * 5 + free)) && !g.edges.dst.contains(&(b * 5 + free)));
        }
    }

    // Sumo, team 0's view: own agents 0, 1 -> opponents 2, 3 in order; centre ball 4.
    let (spec_s, mut vs, ss) = observations("team_sumo/2_ants", 1);
    let roots = [[0.0, 0.0, 0.5], [2.0, 0.0, 0.5], [1.5, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 0.1]];
    for b in 0..B {
        place(&spec_s, &mut vs, b, &roots);
    }
    // Opponent 2 is nearest to agent 1 (0.5 vs 1.5); opponent 3 then gets agent 0.
    let g0 = graph_of(&spec_s, &vs, &ss, AssignmentMethod::Greedy, 0);
    assert_eq!(&g0.agent_entity[..4], [3, 2, 1, 0]);
    // Team 1's view: own agents 2, 3 -> opponents 0, 1. Opponent 0 is nearest to 3 (1.0 vs
    // 1.5), opponent 1 then gets agent 2.
    let g1 = graph_of(&spec_s, &vs, &ss, AssignmentMethod::Greedy, 1);
    assert_eq!(&g1.agent_entity[..4], [3, 2, 1, 0]);
    let mut vs2 = vs.clone();
    place(&spec_s, &mut vs2, 0, &[[0.0, 0.0, 0.5], [2.0, 0.0, 0.5], [1.5, 0.0, 0.5], [0.0, 2.0, 0.5], [0.0, 0.0, 0.1]]);
    // Now opponent 0 is nearest to agent 2 (1.5 vs 2.0): team 1 pairs 2-0, 3-1.
    let g1b = graph_of(&spec_s, &vs2, &ss, AssignmentMethod::Greedy, 1);
    assert_eq!(&g1b.agent_entity[..4], [2, 3, 0, 1]);
}

fn check_edges(spec: &ObsSpec, g: &EntityGraph) {
    let ne = g.entities;
    EdgeList::new(g.edges.src.clone(), g.edges.dst.clone(), B * ne).expect("valid and sorted");
    assert!(g.edges.src.windows(2).all(|w| w[0] <= w[1]));
    let centre = match GraphBuilder::new(spec, AssignmentMethod::Greedy, 0, 0).unwrap().task() {
        GraphTask::Sumo { centre } => Some(centre),
        GraphTask::Reach => None,
    };
    for (&s, &d) in g.edges.src.iter().zip(&g.edges.dst) {
        assert_eq!(s / ne, d / ne, "edge across scenes");
        assert_ne!(s, d);
        let via_centre = centre.is_some_and(|c| s % ne == c || d % ne == c);
        assert!(
            g.group[s] == g.group[d] || via_centre,
            "edge {s} -> {d} joins groups {} and {}",
            g.group[s],
            g.group[d]
        );
    }
    // Every edge has its reverse.
    let mut pairs: Vec<(usize, usize)> = g.edges.src.iter().copied().zip(g.edges.dst.iter().copied()).collect();
    let mut rev: Vec<(usize, usize)> = pairs.iter().map(|&(a, b)| (b, a)).collect();
    pairs.sort_unstable();
    rev.sort_unstable();
    assert_eq!(pairs, rev);
}

#[test]
fn edges_are_sorted_and_stay_within_assignment_groups() {
    for name in ["team_reach/2_ants", "team_reach:agents=ant+ant+ant;R=5;balls=2", "team_sumo/2_ants"] {
        let (spec, vectors, scalars) = observations(name, 6);
        let ne = spec.entity_root_node.len();
        for team in 0..spec.n_teams {
            for method in [
                AssignmentMethod::Greedy,
                AssignmentMethod::Hungarian,
                AssignmentMethod::Stochastic,
                AssignmentMethod::None,
            ] {
                let g = graph_of(&spec, &vectors, &scalars, method, team);
                check_edges(&spec, &g);
                let per_scene = g.edges.len() / B;
                let expected = match (method, spec.n_teams) {
                    (AssignmentMethod::None, _) => ne * (ne - 1),
                    (_, 1) => 2 * spec.n_balls,
                    // Pairs within the two groups, plus each of the 4 agents with the centre.
                    _ => 2 * 2 + 2 * 4,
                };
                assert_eq!(per_scene, expected, "{name} {method:?}");
                if method == AssignmentMethod::None {
                    assert!(g.agent_entity.iter().all(|&e| e == UNASSIGNED));
                }
            }
        }
        // The check catches an edge between groups.
        let mut g = graph_of(&spec, &vectors, &scalars, AssignmentMethod::Greedy, 0);
        if spec.n_teams == 1 {
            g.group[g.edges.src[0]] = 99;
            let caught = std::panic::catch_unwind(|| check_edges(&spec, &g)).is_err();
            assert!(caught, "{name}: a relabelled group must be caught");
        }
    }
    // Errors name the problem.
    let (spec, _, _) = observations("team_reach/2_ants", 1);
    let err = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 1, 0).unwrap_err().to_string();
    assert!(err.contains("team 1"), "{err}");
    let err = AssignmentMethod::parse("optimal").unwrap_err();
    assert!(err.contains("hungarian"), "{err}");
}

#[test]
fn entity_stage_gradients_match_finite_differences() {
    let (spec, vectors, scalars) = observations("team_reach/2_ants", 8);
    let obs = ObsBatch::new(B, spec.n_nodes, &vectors, &scalars).unwrap();
    let inputs = InputProcessor::new(&spec, Translation::Assigned).unwrap().entities::<f64, f64>(&obs).unwrap();
    let graph = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 0, 0).unwrap().build(&inputs).unwrap();
    // One scene only (tiny): the rows of scene 0 and its edges.
    let ne = inputs.entities;
    let edges = EdgeList::new(
        graph.edges.src.iter().copied().filter(|&s| s < ne).collect(),
        graph.edges.dst.iter().copied().filter(|&d| d < ne).collect(),
        ne,
    )
    .unwrap();
    let z0 = Tensor::new(inputs.z.to_vec()[..ne * NODE_VECTOR_LEN].to_vec(), &[ne, 3, 3]).unwrap();
    let h0 = Tensor::new(inputs.h.to_vec()[..ne * 11].to_vec(), &[ne, 11]).unwrap();
    let config = EntityMpConfig {
        vectors: 3,
        scalars: 4,
        hidden: 5,
        layers: 1,
        steps: 2,
        distance: EdgeDistance::Raw,
        aggregation: Aggregation::Mean,
        gravity: Some([0.0, 0.0, -1.0]),
        edge_scalars: 0,
        gravity_in_layers: true,
        frame: true,
    };
    let mut store = ParamStore::<f64>::new();
    let mp = EntityMp::new(&mut store.scope("entity", &mut nn::init_rng(2)), config).unwrap();
    // Random biases, so that zero biases hide nothing.
    let mut r = rng(4);
    let mut params: Vec<Tensor<f64>> = store.values().to_vec();
    for t in params.iter_mut().filter(|t| t.rank() == 1) {
        *t = Tensor::new((0..t.numel()).map(|_| r.random_range(-0.5..0.5)).collect(), t.shape()).unwrap();
    }
    let np = params.len();
    let mut all = params;
    all.push(z0);
    all.push(h0);
    let report = check_gradients(|tape, v| stage_output(&mp, &edges, np, tape, v), &all).unwrap();
    assert!(report.checked > 400, "{report:?}");
    // The check can fail: a wrong gradient (here: a value the tape does not see) is caught.
    let wrong = check_gradients(
        |tape, v| {
            let y = stage_output(&mp, &edges, np, tape, v)?;
            // Adds x^2 in value but not in gradient: detach breaks the chain.
            let extra = v[np].detach().square().sum_all();
            y.add(extra)
        },
        &all,
    );
    assert!(wrong.is_err(), "a detached term must be caught");
}

/// `[Z', h', O]` of the entity stage flattened into one vector; `v` holds the parameters
/// (store order), then `Z_i` and `h_i`.
fn stage_output<'t>(
    mp: &EntityMp,
    edges: &EdgeList,
    np: usize,
    tape: &'t Tape<f64>,
    v: &[tensor::Var<'t, f64>],
) -> tensor::Result<tensor::Var<'t, f64>> {
    let p = Bound::from_vars(v[..np].to_vec());
    let f = mp.forward(&p, v[np], v[np + 1], edges, None).expect("entity stage");
    let flat = |x: tensor::Var<'t, f64>| x.reshape(&[x.value().numel()]);
    tape.cat(&[flat(f.z)?, flat(f.h)?, flat(f.frame.expect("a frame"))?], 0)
}

#[test]
fn entity_mp_parameters_are_named_and_counted() {
    let (spec, _, _) = observations("team_reach/2_ants", 1);
    let (store, mp) = paper_model(&spec, 0);
    let (m, s, hd) = (32, 64, 64);
    // The release's actor stage: embed_z [3 + g, m]; embed_h `hs` -> s; W1 [2m + 1, m] (the
    // edge vector, no g); MLP_e [m^2 + 2s, hd, hd, m^2 + s] (no edge scalar); W2 [2m, m];
    // MLP_n [m^2 + 2s, hd, hd, m^2 + s]; W_u [m, 1].
    let mlp = |i: usize| i * hd + hd + hd * hd + hd + hd * (m * m + s) + m * m + s;
    let count =
        |hs: usize| 4 * m + hs * s + s + (2 * m + 1) * m + mlp(m * m + 2 * s) + 2 * m * m + mlp(m * m + 2 * s) + m;
    assert_eq!(store.num_elements(), count(11));
    // With the release's 9 scalars per node (10 with the height) this is the stage of its
    // 771,916-parameter SHNN policy on 3_ant_claw_centipede (the heads are the rest).
    assert_eq!(count(10), 302_336);
    assert_eq!(store.names()[0], "entity.embed_z.weight");
    assert!(store.names().iter().all(|n| n.starts_with("entity.")));
    assert_eq!(store.num_elements_under("entity.mp"), count(11) - 4 * m - 11 * s - s - m);
    assert_eq!(mp.config.steps, 1);
    // Bad sizes are errors.
    let mut cfg = EntityMpConfig::paper(&spec);
    cfg.steps = 0;
    let mut st = ParamStore::<f64>::new();
    let err = EntityMp::new(&mut st.scope("e", &mut nn::init_rng(0)), cfg).unwrap_err().to_string();
    assert!(err.contains("0 steps"), "{err}");
}
