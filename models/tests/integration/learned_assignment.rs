//! The learned assignment (`models::assignment_learned`) on real MeBen scenes, called as a
//! trainer would per step: pair features from the entity inputs and the graph builder's rows
//! and columns, scores for the batch, a draw that builds the entity graph, its log-probability.

use crate::common::rng;
use envs::layout::ObsBatch;
use envs::tasks::{StartMode, VecEnv};
use models::assignment_learned::log_prob_host;
use models::{
    AssignmentMethod, AssignmentScorer, GraphBuilder, InputProcessor, NO_AGENT, PairFeatureSet, PairFeatures,
    PlackettLuceAssigner, ScorerConfig, Translation, UNASSIGNED, log_prob_and_entropy,
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
