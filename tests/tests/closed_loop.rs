//! Cross-crate smoke test: MeBen environments (`envs`) driven by policies (`models`, on the
//! `tensor`/`nn` autodiff), with actions sampled from the Tanh-Normal heads: the pieces the
//! trainer will connect.

use envs::tasks::{StartMode, VecEnv};
use models::distribution::tanh_normal_log_prob;
use models::{Model, ModelConfig};
use nn::ParamStore;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tensor::{Tape, Tensor};

/// Runs `steps` control steps of `env_name` with one `model` per team; returns the summed
/// rewards per team and the number of ended episodes.
fn run(env_name: &str, model: &str, batch: usize, steps: usize) -> (Vec<f64>, usize) {
    let mut env = VecEnv::from_name(env_name, batch, 11, StartMode::Random).unwrap();
    let spec = env.scene().obs_spec.clone();
    let teams = 1 + spec.agent_team.iter().copied().max().unwrap_or(0);
    let mut init = nn::init_rng(5);
    let mut stores = Vec::new();
    let mut models = Vec::new();
    for t in 0..teams {
        let mut store = ParamStore::<f32>::new();
        let m =
            Model::new(&mut store.scope(&format!("team{t}"), &mut init), &ModelConfig::new(model), &spec, t).unwrap();
        assert!(m.num_params(&store) > 0);
        stores.push(store);
        models.push(m);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let n_actions = env.n_actions();
    let mut totals = vec![0.0; teams];
    let mut ended = 0;
    for _ in 0..steps {
        let mut actions = vec![0f32; batch * n_actions];
        for (t, m) in models.iter_mut().enumerate() {
            let tape = Tape::new();
            let _no_grad = tape.no_grad();
            let p = stores[t].bind(&tape);
            let out = m.forward(&p, env.obs()).unwrap();
            assert!(out.team_value().unwrap().value().all_finite(), "{model}: value");
            for head in &out.agents {
                let (loc, std) = (head.loc.value(), head.std().value());
                let dof = spec.agent_dof[head.agent];
                assert_eq!(loc.shape(), &[batch, dof]);
                // u ~ Normal(loc, std), a = tanh(u); its log-probability must be finite.
                let u: Vec<f32> = loc
                    .data()
                    .iter()
                    .zip(std.data())
                    .map(|(&l, &s)| l + s * nn::init::normal(&mut rng) as f32)
                    .collect();
                let uv = tape.constant(Tensor::new(u.clone(), &[batch, dof]).unwrap());
                let lp = tanh_normal_log_prob(uv, head.loc, head.std()).unwrap().value();
                assert!(lp.all_finite(), "{model}: log-prob");
                let off = spec.agent_action_offset[head.agent];
                for b in 0..batch {
                    for k in 0..dof {
                        let a = u[b * dof + k].tanh();
                        assert!((-1.0..=1.0).contains(&a));
                        actions[b * n_actions + off + k] = a;
                    }
                }
            }
        }
        let out = env.step(&actions).unwrap();
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
    let mut m = Model::new(&mut store.scope("team0", &mut init), &ModelConfig::new("shnn"), &spec, 0).unwrap();
    let tape = Tape::new();
    let p = store.bind(&tape);
    let out = m.forward(&p, env.obs()).unwrap();
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
