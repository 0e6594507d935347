//! Cross-crate smoke test: MeBen environments (`envs`) driven by policies (`models`, on the
//! `tensor`/`nn` autodiff) through the trainer's act step (`rl::mappo::actor::Actor`: sampled
//! Tanh-Normal actions and their log-probabilities), with every value finite.

use envs::tasks::{StartMode, VecEnv};
use models::{Model, ModelDescription};
use nn::ParamStore;
use rl::mappo::actor::{ActMode, Actor, JointAction};
use rl::mappo::normalizer::{NormKind, ObsNormalizer};
use rl::mappo::seeding::stream;
use tensor::Tape;

/// Runs `steps` control steps of `env_name` with one `model` per team; returns the summed
/// rewards per team and the number of ended episodes.
fn run(env_name: &str, model: &str, batch: usize, steps: usize) -> (Vec<f64>, usize) {
    let mut env = VecEnv::from_name(env_name, batch, 11, StartMode::Random).unwrap();
    let spec = env.scene().obs_spec.clone();
    let teams = spec.n_teams;
    let mut init = nn::init_rng(5);
    let mut players = Vec::new();
    for t in 0..teams {
        let mut store = ParamStore::<f32>::new();
        let m = Model::new(
            &mut store.scope(&format!("team{t}"), &mut init),
            &ModelDescription::parse(model).unwrap(),
            &spec,
            t,
        )
        .unwrap();
        assert!(m.num_params(&store) > 0);
        let noise = m.agents().iter().map(|&a| stream(3, "noise", t as u64, a as u64)).collect();
        players.push((m, store, Actor::new(ActMode::Sample, noise)));
    }
    let identity = ObsNormalizer::new(NormKind::Identity, &spec);
    let n_actions = env.n_actions();
    let mut joint = JointAction::new(batch, n_actions, teams);
    let mut totals = vec![0.0; teams];
    let mut ended = 0;
    for _ in 0..steps {
        joint.actions.iter_mut().for_each(|a| *a = f32::NAN);
        for (t, (m, store, actor)) in players.iter_mut().enumerate() {
            // The value too is finite (acting skips it).
            let tape = Tape::new();
            let _no_grad = tape.no_grad();
            let out = m.forward_batch(&store.bind(&tape), &env.obs().rows()).unwrap();
            assert!(out.team_value().unwrap().value().all_finite(), "{model}: value");
            actor.act(m, store, &identity, env.obs().rows(), &mut joint).unwrap();
            // u ~ Normal(loc, std), a = tanh(u); its log-probability is finite.
            assert!(joint.logp[t].iter().all(|l| l.is_finite() && *l != 0.0), "{model}: log-prob");
        }
        // Every team wrote its agents' actions, each in [-1, 1], tanh of the pre-squash one.
        for (a, u) in joint.actions.iter().zip(&joint.pre_squash) {
            assert!((-1.0..=1.0).contains(a) && *a == u.tanh(), "{model}: action {a} of {u}");
        }
        let out = env.step(&joint.actions).unwrap();
        for b in 0..batch {
            for (t, total) in totals.iter_mut().enumerate() {
                let r = out.reward[b * teams + t];
                assert!(r.is_finite());
                *total += f64::from(r);
            }
            ended += usize::from(out.terminated[b] || out.truncated[b]);
        }
        assert!(out.obs.vectors.iter().all(|v| v.is_finite()));
    }
    (totals, ended)
}

#[test]
fn shnn_drives_team_reach_and_both_sumo_teams() {
    let (reach, _) = run("team_reach/2_ants", "shnn", 3, 8);
    assert_eq!(reach.len(), 1);
    let (sumo, _) = run("team_sumo/2_ants", "shnn", 2, 8);
    assert_eq!(sumo.len(), 2);
}

#[test]
fn baselines_drive_the_same_loop() {
    for model in ["mlp", "mlp_hn"] {
        let (r, _) = run("team_reach/1_ant", model, 2, 5);
        assert!(r[0].is_finite());
    }
}

#[test]
fn the_value_loss_reaches_every_parameter_of_an_shnn_critic() {
    let env = VecEnv::from_name("team_reach/2_ants", 2, 1, StartMode::Random).unwrap();
    let spec = env.scene().obs_spec.clone();
    let mut store = ParamStore::<f32>::new();
    let mut init = nn::init_rng(9);
    let mut m =
        Model::new(&mut store.scope("team0", &mut init), &ModelDescription::new(models::ModelKind::Shnn), &spec, 0)
            .unwrap();
    let tape = Tape::new();
    let p = store.bind(&tape);
    let out = m.forward_batch(&p, &env.obs().rows()).unwrap();
    let loss = out.team_value().unwrap().square().mean_all().unwrap();
    let grads = p.grads(&tape.backward(loss).unwrap());
    let mut reached = 0;
    for ((name, _), g) in store.iter().zip(&grads) {
        assert!(g.all_finite(), "{name}");
        if name.contains("critic") {
            assert!(g.data().iter().any(|&v| v != 0.0), "no gradient reaches {name}");
            reached += 1;
        }
    }
    assert!(reached > 0);
}
