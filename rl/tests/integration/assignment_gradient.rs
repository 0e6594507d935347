//! The expected assignment gradient (`assignment_gradient = expected`, TRAINING.md): at the
//! steps that draw, the scorer follows `Σ_σ' π(σ' | s) V(s, σ')` over every assignment `σ'`,
//! valued by a critic that reads the held assignment, instead of the drawn `σ`'s
//! log-probability in the PPO ratio. Where the value does not tell the assignments apart
//! (`W_σ` zero, as at the start) the scorer gets no gradient, where the sampled one gets one;
//! where it does, a step along the gradient raises that expected value as the gradient
//! predicts; runs resume exactly at any thread count, and the option is refused without a
//! critic that reads the held assignment. `assignment_value_at_draw` fits that critic at the
//! drawing steps too, on the drawn assignment: it changes the value's loss only where the
//! value reads the assignment, and is refused without the expected gradient.

use crate::assignment_hold::trained_on_one_and_two_threads;
use crate::assignment_hold_episode::{HELD_CRITIC, collect, config, short_episodes};
use crate::common;
use common::metrics;
use nn::{ParamId, ParamStore};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rl::mappo::minibatch::Minibatch;
use rl::mappo::ppo::{self, PpoParams};
use rl::mappo::seeding::minibatch_stream;
use rl::{AssignmentGradient, RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::{Tape, Tensor};

/// SHNN whose value reads the held assignment.
const SHNN_HELD_CRITIC: &str = "shnn:assignment=learned;assign_critic=held";

/// [`config`] of `model`, `iterations` long, with the expected gradient and no entropy bonus
/// (so that only the policy gradient moves the scorer).
fn expected(model: &str, iterations: u64) -> TrainConfig {
    TrainConfig { assignment_gradient: AssignmentGradient::Expected, entropy_coef: 0.0, ..config(model, iterations) }
}

/// The scorer's parameters (`team0.assign.*`).
fn scorer(store: &ParamStore<f32>) -> Vec<ParamId> {
    store.names().iter().filter(|n| n.starts_with("team0.assign.")).map(|n| store.find(n).unwrap()).collect()
}

/// The gradient of team 0's PPO loss of `config` on `mb` at the trainer's parameters, per
/// parameter.
fn loss_gradient(t: &mut Trainer, config: &TrainConfig, mb: &Minibatch) -> Vec<Vec<f32>> {
    let team = &mut t.teams[0];
    let tape = Tape::<f32>::new();
    let p = team.store.bind(&tape);
    let mut noise = minibatch_stream(config.seed, "entropy", 0, 0, 0, 0);
    let (loss, _) = ppo::loss(team.model.as_mut(), &p, mb, &PpoParams::from_config(config), &mut noise).unwrap();
    p.grads(&tape.backward(loss).unwrap()).iter().map(|g| g.to_vec()).collect()
}

/// `J = Σ_t Σ_σ' π(σ' | s_t) V(s_t, σ')` over the transitions of `mb` that drew, straight
/// from the model: each drawing row with each assignment of the support, held, one row at a
/// time, in f64.
fn expected_value(t: &mut Trainer, mb: &Minibatch) -> f64 {
    let team = &mut t.teams[0];
    let tape = Tape::<f32>::new();
    let _no_grad = tape.no_grad();
    let p = team.store.bind(&tape);
    let model = team.model.as_mut();
    let support = model.learned_assignment_support();
    assert_eq!(support.len(), 2, "two ants, two balls: two assignments");
    let mut j = 0.0;
    for i in (0..mb.transitions()).filter(|&i| mb.assignment_drawn[i]) {
        for sigma in &support {
            let out = model.forward_held(&p, &mb.obs_rows(i..i + 1), sigma, &[true]).unwrap();
            let v = f64::from(out.team_value().unwrap().value().to_vec()[0]);
            let lp = f64::from(out.assignment_terms.unwrap().log_prob.value().to_vec()[0]);
            j += lp.exp() * v;
        }
    }
    j
}

/// `W_σ` (`team0.critic.held.weight`) set to draws from `[-1, 1)`, so that the value tells
/// the assignments apart.
pub(crate) fn randomise_held_weight(store: &mut ParamStore<f32>, seed: u64) {
    let id = store.find("team0.critic.held.weight").expect("W_σ");
    let shape = store.get(id).shape().to_vec();
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    let data: Vec<f32> = (0..shape.iter().product()).map(|_| r.random_range(-1.0..1.0)).collect();
    store.set(id, Tensor::new(data, &shape).unwrap()).unwrap();
}

/// For MLP+HN and SHNN with the held critic.
#[test]
fn the_expected_gradient_follows_the_value_of_every_assignment() {
    for model in [HELD_CRITIC, SHNN_HELD_CRITIC] {
        follows_the_value_of_every_assignment(model);
    }
}

fn follows_the_value_of_every_assignment(model: &str) {
    let config = expected(model, 1);
    let mut t = short_episodes(&config);
    let (_, mb) = collect(&mut t);
    let draws = mb.assignment_drawn.iter().filter(|&&d| d).count();
    assert!(draws > 0 && draws < mb.transitions(), "{model}: {draws} draws of {}", mb.transitions());
    let ids = scorer(&t.teams[0].store);
    assert!(!ids.is_empty());
    let norm = |g: &[Vec<f32>]| {
        ids.iter().map(|id| g[id.0].iter().map(|x| f64::from(*x).powi(2)).sum::<f64>()).sum::<f64>().sqrt()
    };

    // W_σ = 0 (the start): every assignment has the same value, so the scorer gets no
    // gradient (up to the rounding of the values' f32 forward passes), where the sampled
    // gradient (the drawn σ's factor in the ratio) gives one.
    let none = norm(&loss_gradient(&mut t, &config, &mb));
    let sampled = TrainConfig { assignment_gradient: AssignmentGradient::Sampled, ..config.clone() };
    let one = norm(&loss_gradient(&mut t, &sampled, &mb));
    assert!(one > 0.0, "{model}: the sampled gradient reaches the scorer");
    assert!(
        none < 1e-6 * one,
        "{model}: the value tells no assignment apart, yet the scorer moved: {none} against {one}"
    );

    // A W_σ that tells them apart: a step of length ε along the gradient raises J by about
    // ε |∇J|, and the loss's gradient is -∇J / (T M).
    randomise_held_weight(&mut t.teams[0].store, 7);
    let g = loss_gradient(&mut t, &config, &mb);
    let gn = norm(&g);
    assert!(gn > 0.0, "{model}: the value tells the assignments apart, yet the scorer got no gradient");
    let before = expected_value(&mut t, &mb);
    let eps = 1e-2;
    for id in &ids {
        let w = t.teams[0].store.get(*id);
        let shape = w.shape().to_vec();
        let stepped: Vec<f32> =
            w.to_vec().iter().zip(&g[id.0]).map(|(x, d)| (f64::from(*x) - eps * f64::from(*d) / gn) as f32).collect();
        t.teams[0].store.set(*id, Tensor::new(stepped, &shape).unwrap()).unwrap();
    }
    let gain = expected_value(&mut t, &mb) - before;
    let predicted = eps * gn * mb.transitions() as f64;
    assert!(gain > 0.0, "{model}: a step along the gradient lowered the expected value: {gain}");
    assert!((gain - predicted).abs() < 0.01 * predicted, "{model}: gain {gain}, first-order prediction {predicted}");
}

#[test]
fn runs_with_the_expected_gradient_resume_exactly_and_differ_from_the_sampled_one() {
    let tmp = common::TempDir::new("assignment-gradient");
    let config = TrainConfig { entropy_coef: config(HELD_CRITIC, 3).entropy_coef, ..expected(HELD_CRITIC, 3) };
    let whole = trained_on_one_and_two_threads(&tmp.0, &config);
    let parts = RunDir::new(tmp.0.join("parts"));
    train(&config, &parts, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    train(&config, &parts, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&parts), metrics(&whole), "resumed");
    let written = std::fs::read_to_string(whole.config()).unwrap();
    assert!(written.contains("assignment_gradient = \"expected\""), "{written}");
    let sampled = RunDir::new(tmp.0.join("sampled"));
    let sampled_config = TrainConfig { assignment_gradient: AssignmentGradient::Sampled, ..config.clone() };
    train(&sampled_config, &sampled, &TrainOptions::default()).unwrap();
    assert_ne!(metrics(&sampled), metrics(&whole), "the sampled gradient's run");
    let default = std::fs::read_to_string(sampled.config()).unwrap();
    assert!(!default.contains("assignment_gradient"), "the default is left out of config.toml: {default}");
}

#[test]
fn the_expected_gradient_needs_a_critic_that_reads_the_held_assignment() {
    for model in ["mlp_hn:assignment=learned", "shnn:assignment=learned", "mlp_hn"] {
        let c = TrainConfig { model: model.into(), ..expected(HELD_CRITIC, 1) };
        let c = if model == "mlp_hn" { TrainConfig { assignment_hold_episode: false, ..c } } else { c };
        let e = c.validate("expected.toml").unwrap_err().to_string();
        assert!(
            e.contains("expected.toml")
                && e.contains("assignment_gradient")
                && e.contains("expected")
                && e.contains("assign_critic=held"),
            "{model}: {e}"
        );
    }
    // Team Sumo: each team that learns its assignment needs the held critic.
    let sumo = |opponent: &str| {
        let mut c = common::tiny("team_sumo/2_ants", SHNN_HELD_CRITIC, 1, &[("assignment_hold_episode", "true")]);
        c.opponent = opponent.into();
        TrainConfig { assignment_gradient: AssignmentGradient::Expected, ..c }
    };
    let e = sumo("shnn:assignment=learned").validate("sumo.toml").unwrap_err().to_string();
    assert!(e.contains("sumo.toml") && e.contains("opponent") && e.contains("assign_critic=held"), "{e}");
    assert!(sumo("mlp_hn").validate("sumo.toml").is_ok());
    for model in [HELD_CRITIC, SHNN_HELD_CRITIC, "shnn:assignment=learned;assign_critic=held;critic=shared"] {
        assert!(expected(model, 1).validate("expected.toml").is_ok(), "{model}");
    }
}

/// The loss statistics of team 0's PPO loss of `config` on `mb` at the trainer's parameters.
fn loss_stats(t: &mut Trainer, config: &TrainConfig, mb: &Minibatch) -> ppo::LossStats {
    let team = &mut t.teams[0];
    let tape = Tape::<f32>::new();
    let p = team.store.bind(&tape);
    let mut noise = minibatch_stream(config.seed, "entropy", 0, 0, 0, 0);
    ppo::loss(team.model.as_mut(), &p, mb, &PpoParams::from_config(config), &mut noise).unwrap().1
}

#[test]
fn the_value_at_the_drawing_steps_reads_the_drawn_assignment_where_asked() {
    let config = expected(HELD_CRITIC, 1);
    let at_draw = TrainConfig { assignment_value_at_draw: true, ..config.clone() };
    let mut t = short_episodes(&config);
    let (_, mb) = collect(&mut t);
    assert!(mb.assignment_drawn.iter().any(|&d| d), "no drawing step in the minibatch");
    // W_σ = 0 (the start): reading the drawn σ or none gives the same values, the same loss.
    assert_eq!(loss_stats(&mut t, &config, &mb), loss_stats(&mut t, &at_draw, &mb));
    // A W_σ that tells the assignments apart: the drawing steps' values, so the value loss
    // and the advantages, change.
    randomise_held_weight(&mut t.teams[0].store, 7);
    let (off, on) = (loss_stats(&mut t, &config, &mb), loss_stats(&mut t, &at_draw, &mb));
    assert_ne!(off.value_loss, on.value_loss);
    // Written to config.toml only when set; a run with it resumes exactly.
    let tmp = common::TempDir::new("assignment-value-at-draw");
    let run = RunDir::new(tmp.0.join("run"));
    let two = TrainConfig { assignment_value_at_draw: true, ..expected(HELD_CRITIC, 2) };
    train(&two, &run, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    train(&two, &run, &TrainOptions::default()).unwrap();
    let whole = RunDir::new(tmp.0.join("whole"));
    train(&two, &whole, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&run), metrics(&whole), "resumed");
    assert!(std::fs::read_to_string(run.config()).unwrap().contains("assignment_value_at_draw = true"));
    // Refused with the sampled gradient, naming the file, the field and what to set.
    let sampled = TrainConfig { assignment_gradient: AssignmentGradient::Sampled, ..at_draw };
    let e = sampled.validate("at_draw.toml").unwrap_err().to_string();
    assert!(
        e.contains("at_draw.toml") && e.contains("assignment_value_at_draw") && e.contains("assignment_gradient"),
        "{e}"
    );
}
