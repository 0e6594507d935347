//! A draw held for an episode credited with the episode's return (`assignment_gradient =
//! "episode"`, TRAINING.md, `rl::mappo::episode_credit`): each finished draw carries the
//! observation and assignment it was drawn at and its episode's return; the per-step ratio
//! gives the scorer no gradient, the episode term gives it one towards the draws of the
//! better episodes and reaches nothing else; runs resume exactly (the running episodes'
//! draws are checkpointed) at any thread count; the option is refused where it cannot work.

use crate::assignment_hold_episode::{ENVS, HELD_CRITIC, collect, config, short_episodes};
use crate::common;
use envs::tasks::{TaskSpec, VecEnv};
use nn::{ParamId, ParamStore};
use rl::mappo::checkpoint::Checkpoint;
use rl::mappo::episode_credit::{EpisodeBatch, FinishedDraws};
use rl::mappo::ppo;
use rl::{AssignmentGradient, RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::Tape;

/// [`config`] of `model` credited per episode, `iterations` long, with no entropy bonus (so
/// that only the policy gradient moves the scorer).
fn episode(model: &str, iterations: u64) -> TrainConfig {
    TrainConfig { assignment_gradient: AssignmentGradient::Episode, entropy_coef: 0.0, ..config(model, iterations) }
}

/// Every parameter's id, by store order.
fn ids(store: &ParamStore<f32>) -> Vec<ParamId> {
    store.names().iter().map(|n| store.find(n).unwrap()).collect()
}

/// Every parameter's values, by store order.
fn params(store: &ParamStore<f32>) -> Vec<Vec<f32>> {
    ids(store).into_iter().map(|id| store.get(id).to_vec()).collect()
}

/// Whether parameter `name` is the scorer's.
fn is_scorer(name: &str) -> bool {
    name.starts_with("team0.assign.")
}

/// Where each environment's episodes were drawn in one collection of `t` (3-step episodes),
/// the finished draws are those episodes', in the order they ended: the observation the act
/// step read and the assignment at the drawing step, and the return their rewards sum to.
#[test]
fn each_finished_draw_carries_its_drawing_step_and_its_episodes_return() {
    for model in ["mlp_hn:assignment=learned", "shnn:assignment=learned"] {
        let mut t = short_episodes(&episode(model, 1));
        let (_, mb) = collect(&mut t);
        let finished: FinishedDraws = t.teams[0].episode_draws.as_mut().expect("kept").take_finished();
        // The rollout's rows, per (environment, step), and the episodes they make.
        let (m, len) = (mb.unrolls, mb.steps);
        let envs = ENVS;
        let mut expected = Vec::new(); // (end step, env, drawing transition, return)
        for e in 0..envs {
            let mut start = None;
            let mut ret = 0.0;
            for g in 0..2 * len {
                let (block, step) = (g / len, g % len);
                let i = step * m + block * envs + e;
                if mb.assignment_drawn[i] {
                    start = Some(i);
                    ret = 0.0;
                }
                ret += f64::from(mb.rewards[i]) / t.config.reward_scaling;
                if mb.terminated[i] || mb.truncated[i] {
                    expected.push((g, e, start.expect("an episode draws at its first step"), ret));
                }
            }
        }
        expected.sort_by_key(|&(g, e, _, _)| (g, e));
        assert_eq!(finished.len(), expected.len(), "{model}: one draw per ended episode");
        assert!(finished.len() >= envs * 3, "{model}: 3-step episodes end three times in 10 steps");
        let w = finished.sigma.len() / finished.len();
        let row = finished.raw.row_widths();
        for (d, &(_, _, i, ret)) in expected.iter().enumerate() {
            assert_eq!(&finished.sigma[d * w..(d + 1) * w], &mb.assignment[i * w..(i + 1) * w], "{model}");
            assert_eq!(
                &finished.raw.vectors[d * row.vectors..(d + 1) * row.vectors],
                &mb.raw.vectors[i * row.vectors..(i + 1) * row.vectors],
                "{model}: the observation the draw was made at"
            );
            assert!(
                (finished.returns[d] - ret).abs() < 1e-3 * ret.abs().max(1.0),
                "{model}: {} {ret}",
                finished.returns[d]
            );
        }
    }
}

/// The episode term at ratio 1 (`ln π_old` the current scorer's): its gradient reaches the
/// scorer and nothing else, and a small step along it raises `Σ_e A_e ln π(σ_e | s_e)`;
/// with every advantage 0 it gives no gradient.
#[test]
fn the_episode_term_moves_the_scorer_towards_the_draws_of_the_better_episodes() {
    let config = episode("mlp_hn:assignment=learned", 1);
    let mut t = short_episodes(&config);
    collect(&mut t);
    let finished = t.teams[0].episode_draws.as_mut().unwrap().take_finished();
    let team = &mut t.teams[0];
    let mut batch = EpisodeBatch::new(&finished, &team.norm).expect("two or more draws");
    let d = batch.len();
    let objective = |store: &ParamStore<f32>, model: &mut dyn models::Policy, batch: &EpisodeBatch| {
        let tape = Tape::<f32>::new();
        let _no_grad = tape.no_grad();
        let p = store.bind(&tape);
        let lp = ppo::assignment_log_prob(model, &p, batch, 0..batch.len()).unwrap().value().to_vec();
        lp.iter().zip(&batch.advantages).map(|(l, a)| f64::from(*l) * f64::from(*a)).sum::<f64>()
    };
    {
        let tape = Tape::<f32>::new();
        let _no_grad = tape.no_grad();
        let p = team.store.bind(&tape);
        batch.logp_old = ppo::assignment_log_prob(team.model.as_mut(), &p, &batch, 0..d).unwrap().value().to_vec();
    }
    let gradient = |store: &ParamStore<f32>, model: &mut dyn models::Policy, batch: &EpisodeBatch| {
        let tape = Tape::<f32>::new();
        let p = store.bind(&tape);
        let term = ppo::episode_assignment_term(model, &p, batch, 0..batch.len(), 0.2).unwrap().unwrap();
        let value = f64::from(term.value().to_vec()[0]);
        (value, p.grads(&tape.backward(term).unwrap()).iter().map(|g| g.to_vec()).collect::<Vec<_>>())
    };
    let (value, g) = gradient(&team.store, team.model.as_mut(), &batch);
    let mean_a = batch.advantages.iter().map(|&a| f64::from(a)).sum::<f64>() / d as f64;
    assert!((value + mean_a).abs() < 1e-5, "at ratio 1 the term is -mean(A): {value} {mean_a}");
    let names = team.store.names().to_vec();
    for (name, gi) in names.iter().zip(&g) {
        let norm: f32 = gi.iter().map(|x| x.abs()).sum();
        if is_scorer(name) {
            assert!(norm > 0.0, "the scorer's {name} got no gradient");
        } else {
            assert_eq!(norm, 0.0, "{name} is not the scorer's, yet the episode term moved it");
        }
    }
    let before = objective(&team.store, team.model.as_mut(), &batch);
    let mut stepped = team.store.clone();
    for (id, gi) in ids(&stepped).into_iter().zip(&g) {
        let x = stepped.get(id);
        let moved: Vec<f32> = x.to_vec().iter().zip(gi).map(|(v, dg)| v - 1e-3 * dg).collect();
        stepped.set(id, tensor::Tensor::new(moved, x.shape()).unwrap()).unwrap();
    }
    let after = objective(&stepped, team.model.as_mut(), &batch);
    assert!(after > before, "a step against the term's gradient lowered Σ A ln π: {before} -> {after}");
    // Equal returns: no advantage, no gradient.
    batch.advantages.iter_mut().for_each(|a| *a = 0.0);
    let (_, flat) = gradient(&team.store, team.model.as_mut(), &batch);
    assert!(flat.iter().all(|gi| gi.iter().all(|&x| x == 0.0)));
}

/// With no episode ending in the iteration (MeBen's 1000-step episodes, 10 steps), the
/// update leaves the scorer as it was (the drawn `σ`'s factor of the per-step ratio has no
/// gradient), where the sampled gradient moves it; with 3-step episodes the episode term
/// moves it.
#[test]
fn only_the_episodes_that_ended_move_the_scorer() {
    let scorer = |t: &Trainer| {
        let s = &t.teams[0].store;
        ids(s)
            .into_iter()
            .zip(s.names())
            .filter(|(_, n)| is_scorer(n))
            .map(|(id, _)| s.get(id).to_vec())
            .collect::<Vec<_>>()
    };
    let config = episode("mlp_hn:assignment=learned", 1);
    let mut long = Trainer::new(&config).unwrap();
    let start = scorer(&long);
    long.iterate().unwrap();
    assert_eq!(scorer(&long), start, "no episode ended, yet the scorer moved");
    let mut sampled =
        Trainer::new(&TrainConfig { assignment_gradient: AssignmentGradient::Sampled, ..config.clone() }).unwrap();
    sampled.iterate().unwrap();
    assert_ne!(scorer(&sampled), start, "the sampled gradient moves the scorer at its draws");
    let mut short = short_episodes(&config);
    short.iterate().unwrap();
    assert_ne!(scorer(&short), start, "the ended episodes' draws moved no scorer");
    assert!(short.teams[0].episode_draws.as_mut().unwrap().take_finished().is_empty(), "the update used them");
}

/// A run of 3-step episodes interrupted after 2 iterations and resumed from its checkpoint
/// file (the running episodes' draws in it) has the uninterrupted run's parameters, as does
/// the run on two threads; without the draws in the checkpoint, the resumed run is refused.
#[test]
fn runs_credited_per_episode_resume_exactly_at_any_thread_count() {
    let tmp = common::TempDir::new("episode-credit");
    let config = episode(HELD_CRITIC, 4);
    let short_env = |t: &mut Trainer, state: Option<&envs::tasks::VecEnvState>| {
        let spec = TaskSpec { episode_steps: 3, ..TaskSpec::from_name(&config.env).unwrap() };
        let mut env = VecEnv::new(&spec, t.config.num_envs, 5, t.env.start_mode()).unwrap();
        if let Some(s) = state {
            env.restore(s).unwrap();
        }
        t.env = env;
    };
    let run = |threads: usize, iterations: u64| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut t = short_episodes(&config);
            for _ in 0..iterations {
                t.iterate().unwrap();
            }
            t
        })
    };
    let whole = run(1, 4);
    assert_eq!(params(&run(2, 4).teams[0].store), params(&whole.teams[0].store), "two threads");
    let half = run(1, 2);
    let path = tmp.0.join("checkpoint.json");
    half.checkpoint(0.0, &[]).unwrap().save(&path).unwrap();
    let saved = Checkpoint::load(&path).unwrap();
    let draws = saved.teams[0].episode_draws.as_ref().expect("the checkpoint keeps the running episodes' draws");
    assert!(draws.recorded.iter().any(|&r| r));
    // The trainer is restored with MeBen's environments (their state names the episode
    // length), then given the 3-step ones in the saved state.
    let mut long_env = saved.clone();
    long_env.env = Trainer::new(&config).unwrap().env.snapshot();
    let mut resumed = Trainer::from_checkpoint(&long_env, &config, &path).unwrap();
    short_env(&mut resumed, Some(&saved.env));
    for _ in 0..2 {
        resumed.iterate().unwrap();
    }
    assert_eq!(params(&resumed.teams[0].store), params(&whole.teams[0].store), "resumed");
    // Without the draws, the running episodes would be credited with nothing: refused.
    let mut without = long_env.clone();
    without.teams[0].episode_draws = None;
    let e = Trainer::from_checkpoint(&without, &config, &path).err().expect("refused").to_string();
    assert!(e.contains("checkpoint.json") && e.contains("draws"), "{e}");
    // The sampled gradient's run on the same data is another run.
    let sampled_config = TrainConfig { assignment_gradient: AssignmentGradient::Sampled, ..config.clone() };
    let mut sampled = short_episodes(&sampled_config);
    for _ in 0..4 {
        sampled.iterate().unwrap();
    }
    assert_ne!(params(&sampled.teams[0].store), params(&whole.teams[0].store));
}

/// `config.toml` names the option; it is refused without a hold per episode or with a
/// warm-up, and a run directory of it trains.
#[test]
fn the_option_is_written_and_refused_where_it_cannot_work() {
    let config = episode("mlp_hn:assignment=learned", 1);
    let tmp = common::TempDir::new("episode-credit-config");
    let run = RunDir::new(tmp.0.join("run"));
    train(&config, &run, &TrainOptions::default()).unwrap();
    let written = std::fs::read_to_string(run.config()).unwrap();
    assert!(written.contains("assignment_gradient = \"episode\""), "{written}");
    let e =
        TrainConfig { assignment_hold_episode: false, ..config.clone() }.validate("e.toml").unwrap_err().to_string();
    assert!(
        e.contains("e.toml") && e.contains("assignment_gradient") && e.contains("assignment_hold_episode = true"),
        "{e}"
    );
    let e = TrainConfig { assignment_warmup_steps: 80, ..config.clone() }.validate("w.toml").unwrap_err().to_string();
    assert!(e.contains("w.toml") && e.contains("assignment_warmup_steps") && e.contains("80"), "{e}");
    let e = TrainConfig { model: "mlp_hn".into(), ..config }.validate("m.toml").unwrap_err().to_string();
    assert!(e.contains("m.toml") && e.contains("assignment=learned"), "{e}");
}
