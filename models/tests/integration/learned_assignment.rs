//! The learned assignment (`models::assignment_learned`) on real MeBen scenes, called as a
//! trainer would per step: pair features from the entity inputs and the graph builder's rows
//! and columns, scores for the batch, a draw that builds the entity graph, its log-probability.

use crate::common::rng;
use envs::layout::ObsBatch;
use envs::tasks::{StartMode, VecEnv};
use models::assignment_learned::log_prob_host;
use models::{
    AssignmentMethod, AssignmentScorer, DRAW_SCENE, GraphBuilder, InputProcessor, NO_AGENT, PairFeatureSet,
    PairFeatures, PlackettLuceAssigner, ScorerConfig, Translation, UNASSIGNED, log_prob_and_entropy,
};
use nn::ParamStore;
use rand::RngExt;
use tensor::Tape;

const B: usize = 16;

fn to_graph_format(a: &[usize]) -> Vec<u32> {
    a.iter().map(|&i| if i == UNASSIGNED { NO_AGENT } else { i as u32 }).collect()
}

#[test]
fn on_meben_scenes_the_learned_assignment_follows_the_graph_builders_layout() {
    for (name, team) in
        [("team_reach/2_ants", 0), ("team_reach/2_ant_claw", 0), ("team_sumo/2_ants", 0), ("team_sumo/2_ants", 1)]
    {
        let mut env = VecEnv::from_name(name, B, 5, StartMode::Random).unwrap();
        let mut r = rng(5);
        for _ in 0..3 {
            let actions: Vec<f32> = (0..B * env.n_actions()).map(|_| r.random_range(-1.0..1.0)).collect();
            env.step(&actions).unwrap();
        }
        let spec = env.scene().obs_spec.clone();
        let inputs = InputProcessor::new(&spec, Translation::Assigned)
            .unwrap()
            .entities::<f32, f32>(&ObsBatch::from_observation(env.obs()))
            .unwrap();
        let mut greedy = GraphBuilder::new(&spec, AssignmentMethod::Greedy, team, 0).unwrap();
        let mut hungarian = GraphBuilder::new(&spec, AssignmentMethod::Hungarian, team, 0).unwrap();
        let (rows, cols) = greedy.assignment_entities();
        let (rows, cols) = (rows.to_vec(), cols.to_vec());
        let (n, m) = (rows.len(), cols.len());
        let gravity = spec.gravity_dir.map(f64::from);
        let x = PairFeatures::from_entities(
            PairFeatureSet::DistanceHeight,
            &inputs.positions,
            inputs.entities,
            &rows,
            &cols,
            gravity,
        )
        .unwrap();
        assert_eq!((x.batch, x.agents, x.objects), (B, n, m), "{name}");
        let mut pl = PlackettLuceAssigner::new(n, m);

        // A sharp distance prior: the draw is Algorithm 1 and the matching the Hungarian one,
        // exactly as the graph builder assigns.
        let mut store = ParamStore::<f32>::new();
        let sharp = ScorerConfig { distance_prior: 1e4, ..ScorerConfig::default() };
        let scorer = AssignmentScorer::new(&mut store.scope("assign", &mut nn::init_rng(1)), sharp).unwrap();
        let tape = Tape::<f32>::new();
        let s = scorer.scores(&store.bind(&tape), &x).unwrap().value().to_vec();
        let (mut drawn, mut best) = (vec![0; B * m], vec![0; B * m]);
        pl.sample(&s, B, n, m, &mut rng(2), &mut drawn).unwrap();
        pl.most_likely(&s, B, n, m, &mut best).unwrap();
        assert_eq!(to_graph_format(&drawn), greedy.build(&inputs).unwrap().assignment, "{name}, team {team}: greedy");
        assert_eq!(to_graph_format(&best), hungarian.build(&inputs).unwrap().assignment, "{name}, team {team}");

        // The default scorer: a draw builds the graph and its log-probability on the tape
        // (f32) is the host's (f64 from the same scores).
        let mut store = ParamStore::<f32>::new();
        let scorer =
            AssignmentScorer::new(&mut store.scope("assign", &mut nn::init_rng(3)), ScorerConfig::default()).unwrap();
        let tape = Tape::<f32>::new();
        let scores = scorer.scores(&store.bind(&tape), &x).unwrap();
        let s = scores.value().to_vec();
        pl.sample(&s, B, n, m, &mut rng(4), &mut drawn).unwrap();
        let fixed = to_graph_format(&drawn);
        assert_eq!(greedy.build_with(&inputs, Some(&fixed)).unwrap().assignment, fixed, "{name}");
        let (lp, h) = log_prob_and_entropy(scores, &drawn).unwrap();
        let host = log_prob_host(&s, B, n, m, &drawn).unwrap();
        for (b, (v, want)) in lp.value().data().iter().zip(&host).enumerate() {
            assert!((*v as f64 - want).abs() < 1e-4, "{name}, scene {b}: log-prob {v} vs {want}");
        }
        assert!(h.value().data().iter().all(|&e| e.is_finite() && e >= -1e-6), "{name}: entropy estimates");
    }
}

/// `shnn:assignment=learned` as a model: the scorer's parameters under `assign.` (created
/// last: every other parameter starts as plain `shnn`'s), a draw per scene from the seeded
/// stream (the same after the same reseed), its log-probability and entropy estimate on the
/// tape, the same terms when the draw is given back (the update's path), the most likely
/// assignment whatever the stream when deterministic, and the gradient of the
/// log-probability reaching the scorer's weights. Team Reach and both teams of Team Sumo;
/// `shnn` and the release's `mlp_hn`, each against its greedy self.
#[test]
fn a_learned_assignment_model_draws_scores_and_differentiates_its_assignment() {
    use models::{Model, ModelDescription};
    let cases = [("team_reach/2_ants", 0), ("team_sumo/2_ants", 0), ("team_sumo/2_ants", 1)];
    for (base, (name, team)) in ["shnn", "mlp_hn"].into_iter().flat_map(|m| cases.map(|c| (m, c))) {
        let mut env = VecEnv::from_name(name, B, 7, StartMode::Random).unwrap();
        let mut r = rng(7);
        for _ in 0..3 {
            let actions: Vec<f32> = (0..B * env.n_actions()).map(|_| r.random_range(-1.0..1.0)).collect();
            env.step(&actions).unwrap();
        }
        let spec = env.scene().obs_spec.clone();
        let build = |model: &str| {
            let mut store = ParamStore::<f32>::new();
            let mut init = nn::init_rng(3);
            let d = ModelDescription::parse(model).unwrap();
            let m = Model::new(&mut store.scope(&format!("team{team}"), &mut init), &d, &spec, team).unwrap();
            (store, m)
        };
        let (plain_store, _) = build(base);
        let (store, mut model) = build(&format!("{base}:assignment=learned"));
        let prefix = format!("team{team}.assign.");
        let learned: Vec<(&str, &tensor::Tensor<f32>)> = store.iter().filter(|(n, _)| n.starts_with(&prefix)).collect();
        assert!(!learned.is_empty(), "{name}");
        let rest: Vec<(&str, Vec<f32>)> =
            store.iter().filter(|(n, _)| !n.starts_with(&prefix)).map(|(n, t)| (n, t.to_vec())).collect();
        let plain: Vec<(&str, Vec<f32>)> = plain_store.iter().map(|(n, t)| (n, t.to_vec())).collect();
        assert_eq!(rest, plain, "{base} on {name}: the other parameters start as without a learned assignment");
        let extra: usize = learned.iter().map(|(_, t)| t.numel()).sum();
        assert_eq!(model.num_params(&store), plain_store.num_elements() + extra, "{name}");
        assert!(model.assignment_is_random(), "{name}");

        let width = model.assignment_width();
        let draw = |model: &mut Model, seed: u64, given: Option<&[u32]>| {
            model.reseed(seed);
            let tape = Tape::<f32>::new();
            let p = store.bind(&tape);
            let out = model.forward_batch_with(&p, &env.obs().rows(), given).unwrap();
            let terms = out.assignment_terms.expect("a learned assignment's terms");
            let (lp, h) = (terms.log_prob.value().to_vec(), terms.entropy.value().to_vec());
            let loc = out.agents[0].loc.value().to_vec();
            // The gradient of the log-probability reaches every weight of the scorer.
            let grads = p.grads(&tape.backward(terms.log_prob.sum_all()).unwrap());
            let reached = store
                .names()
                .iter()
                .zip(&grads)
                .filter(|(n, _)| n.starts_with(&prefix) && n.ends_with("weight"))
                .all(|(_, g)| g.to_vec().iter().any(|x| *x != 0.0));
            (out.assignment, lp, h, loc, reached)
        };
        let (a, lp, h, loc, reached) = draw(&mut model, 11, None);
        assert_eq!(a.len(), B * width, "{name}");
        assert!(lp.iter().all(|x| x.is_finite() && *x <= 1e-6), "{name}: {lp:?}");
        assert!(h.iter().all(|x| x.is_finite() && *x >= -1e-6), "{name}: {h:?}");
        assert!(reached, "{name}: the scorer's weights get no gradient");
        // The same stream draws the same; the draw given back is scored alike.
        assert_eq!(draw(&mut model, 11, None).0, a, "{name}");
        let (a2, lp2, h2, loc2, _) = draw(&mut model, 99, Some(&a));
        assert_eq!((a2, lp2, h2, loc2), (a.clone(), lp.clone(), h, loc), "{name}");
        // Per-scene draws (a hold per episode): scenes marked `DRAW_SCENE` are drawn from the
        // stream, the others keep what is given. Every scene marked draws what none given
        // draws; with the even scenes marked the odd ones keep their given rows, the even ones
        // get a one-to-one assignment (each agent at most once), the same for the same stream.
        let all_marked = vec![DRAW_SCENE; B * width];
        assert_eq!(draw(&mut model, 11, Some(&all_marked)).0, a, "{name}");
        let other = draw(&mut model, 12, None).0;
        let mut some_marked = other.clone();
        for scene in some_marked.chunks_mut(width).step_by(2) {
            scene.fill(DRAW_SCENE);
        }
        let (mixed, lp_mixed, ..) = draw(&mut model, 11, Some(&some_marked));
        assert_eq!(draw(&mut model, 11, Some(&some_marked)).0, mixed, "{name}");
        for (e, (got, given)) in mixed.chunks(width).zip(other.chunks(width)).enumerate() {
            if e % 2 == 1 {
                assert_eq!(got, given, "{name}, scene {e}");
            } else {
                let agents: Vec<u32> = got.iter().copied().filter(|&i| i != NO_AGENT).collect();
                let distinct: std::collections::BTreeSet<u32> = agents.iter().copied().collect();
                assert!(!agents.is_empty() && distinct.len() == agents.len(), "{name}, scene {e}: {got:?}");
            }
        }
        assert!(lp_mixed.iter().all(|x| x.is_finite() && *x <= 1e-6), "{name}: {lp_mixed:?}");
        // A scene marked in part is refused, naming it.
        let mut partly = a.clone();
        partly[width] = DRAW_SCENE;
        model.reseed(11);
        let tape = Tape::<f32>::new();
        let err = model.forward_batch_with(&store.bind(&tape), &env.obs().rows(), Some(&partly)).unwrap_err();
        assert!(err.to_string().contains("scene 1 is only partly marked"), "{name}: {err}");
        // In its warm-up (Algorithm 1, as `meben eval --assignment greedy` plays a learned
        // policy) the scenes marked are solved as with none given, the others keep theirs, a
        // scene marked in part is refused.
        model.set_assignment_warmup(true);
        let solve = |model: &mut Model, given: Option<&[u32]>| {
            let tape = Tape::<f32>::new();
            let out = model.forward_batch_with(&store.bind(&tape), &env.obs().rows(), given);
            out.map(|o| (o.assignment, o.assignment_terms.is_none()))
        };
        let (greedy, no_terms) = solve(&mut model, None).unwrap();
        assert!(no_terms, "{name}: scorer terms in the warm-up");
        assert_eq!(solve(&mut model, Some(&all_marked)).unwrap().0, greedy, "{name}");
        let (held, _) = solve(&mut model, Some(&some_marked)).unwrap();
        for (e, ((got, given), solved)) in
            held.chunks(width).zip(other.chunks(width)).zip(greedy.chunks(width)).enumerate()
        {
            assert_eq!(got, if e % 2 == 1 { given } else { solved }, "{name}, warm-up scene {e}");
        }
        let err = solve(&mut model, Some(&partly)).unwrap_err();
        assert!(err.to_string().contains("scene 1: only partly marked"), "{name}: {err}");
        model.set_assignment_warmup(false);
        // Other streams draw other assignments somewhere in the batch; the most likely one
        // does not depend on the stream.
        let others: Vec<Vec<u32>> = (0..4).map(|s| draw(&mut model, 100 + s, None).0).collect();
        assert!(others.iter().any(|o| *o != a), "{name}: every stream drew the same");
        model.set_deterministic(true);
        let best = draw(&mut model, 1, None).0;
        assert_eq!(draw(&mut model, 2, None).0, best, "{name}");
        model.set_deterministic(false);
    }
}

/// The scorer's options (`assign_hidden`, `assign_prior`) reach the built model: the
/// network's widths set its parameter count (`[Δ, Δh] -> 8 -> 1`: 33; affine: 3), and a
/// large `λ` turns every draw into Algorithm 1's assignment (the greedy `shnn`'s), whatever
/// the stream, where `λ = 0` draws differ between streams.
#[test]
fn the_scorers_options_set_its_network_and_its_distance_prior() {
    use models::{Model, ModelDescription};
    let mut env = VecEnv::from_name("team_reach/2_ants", B, 5, StartMode::Random).unwrap();
    let spec = env.scene().obs_spec.clone();
    let mut r = rng(5);
    let actions: Vec<f32> = (0..B * env.n_actions()).map(|_| r.random_range(-1.0..1.0)).collect();
    env.step(&actions).unwrap();
    let build = |model: &str| {
        let mut store = ParamStore::<f32>::new();
        let d = ModelDescription::parse(model).unwrap();
        let m = Model::new(&mut store.scope("team0", &mut nn::init_rng(3)), &d, &spec, 0).unwrap();
        (store, m)
    };
    let scorer_params = |store: &ParamStore<f32>| -> usize {
        store.iter().filter(|(n, _)| n.starts_with("team0.assign.")).map(|(_, t)| t.numel()).sum()
    };
    assert_eq!(scorer_params(&build("shnn:assignment=learned;assign_hidden=8").0), 2 * 8 + 8 + 8 + 1);
    assert_eq!(scorer_params(&build("shnn:assignment=learned;assign_hidden=none").0), 2 + 1);
    assert_eq!(scorer_params(&build("shnn:assignment=learned").0), 2 * 64 + 64 + 64 * 64 + 64 + 64 + 1);

    let draws = |model: &str, seeds: &[u64]| -> Vec<Vec<u32>> {
        let (store, mut m) = build(model);
        seeds
            .iter()
            .map(|&s| {
                m.reseed(s);
                let tape = Tape::<f32>::new();
                m.forward_batch_with(&store.bind(&tape), &env.obs().rows(), None).unwrap().assignment
            })
            .collect()
    };
    let greedy = draws("shnn", &[0]).remove(0);
    for a in draws("shnn:assignment=learned;assign_hidden=none;assign_prior=1000", &[1, 2, 3, 4]) {
        assert_eq!(a, greedy, "λ = 1000 draws Algorithm 1's assignment");
    }
    let free = draws("shnn:assignment=learned;assign_hidden=none;assign_prior=0", &[1, 2, 3, 4]);
    assert!(free.iter().any(|a| *a != free[0]), "λ = 0: every stream drew the same");
}
