//! A learned task assignment held per episode (`assignment_hold_episode`, TRAINING.md): each
//! environment draws at its episode's first step and keeps the draw to its end, across
//! iterations; the act step records where it drew and the update counts `ln π(σ | s)` there
//! only (ratio 1 on a frozen normaliser, and not without the mask); evaluations draw once an
//! episode; a run resumes exactly (the held assignments are checkpointed) and gives the same
//! bits at any thread count; its files hold per episode. A value that reads the held
//! assignment (`assign_critic=held`) learns from it, and its runs resume exactly too.

use crate::common;

use crate::assignment_hold::{assert_the_mask_keeps_the_first_ratio_one, trained_on_one_and_two_threads};
use common::metrics;
use envs::tasks::{TaskSpec, VecEnv};
use rl::app::run_dir::load_policies;
use rl::mappo::actor::{ActMode, JointAction};
use rl::mappo::assignment_hold::HoldRule;
use rl::mappo::checkpoint::Checkpoint;
use rl::mappo::evaluate::evaluation_actors;
use rl::mappo::minibatch::Minibatch;
use rl::mappo::ppo::{self, PpoParams};
use rl::mappo::seeding::minibatch_stream;
use rl::{RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::Tape;

/// The learned models, and MLP+HN whose value reads the held assignment.
const MODELS: [&str; 3] = ["mlp_hn:assignment=learned", "shnn:assignment=learned", HELD_CRITIC];

/// MLP+HN whose value reads the assignment held into each step (`assign_critic=held`).
pub(crate) const HELD_CRITIC: &str = "mlp_hn:assignment=learned;assign_critic=held";

/// Environments of [`config`].
pub(crate) const ENVS: usize = 8;

/// Steps of one environment in one iteration of [`config`]: 2 blocks of unrolls of 5 steps.
const STEPS_PER_ENV: usize = 10;

/// `iterations` of 10 steps of 8 environments of Team Reach with two ants, each draw held
/// for its episode.
pub(crate) fn config(model: &str, iterations: u64) -> TrainConfig {
    let mut c = common::tiny("team_reach/2_ants", model, iterations, &[("assignment_hold_episode", "true")]);
    c.threads = 1;
    assert_eq!(c.steps_per_iteration() as usize, STEPS_PER_ENV * ENVS);
    c
}

/// A trainer of `config` whose environments' episodes last 3 steps, so that an iteration
/// sees episodes end (MeBen's last 1000).
pub(crate) fn short_episodes(config: &TrainConfig) -> Trainer {
    let mut t = Trainer::new(config).unwrap();
    let spec = TaskSpec { episode_steps: 3, ..TaskSpec::from_name(&config.env).unwrap() };
    t.env = VecEnv::new(&spec, ENVS, 5, t.env.start_mode()).unwrap();
    t
}

/// One iteration of team 0 per environment and step: the assignment acted on, whether it
/// was drawn there, whether the episode ended there.
pub(crate) struct Steps {
    assignment: Vec<Vec<Vec<u32>>>,
    drawn: Vec<Vec<bool>>,
    ended: Vec<Vec<bool>>,
}

/// Collects one iteration of `t` and reads it back through the update's minibatch of every
/// unroll (unroll `q` is block `q / E`, environment `q % E`; time-major).
pub(crate) fn collect(t: &mut Trainer) -> (Steps, Minibatch) {
    t.collect().unwrap();
    let ids: Vec<usize> = (0..t.rollout().unrolls()).collect();
    let mut mb = Minibatch::default();
    t.rollout().gather(&ids, 0, &mut mb);
    mb.normalise(&t.teams[0].norm);
    let (m, t_len) = (mb.unrolls, mb.steps);
    let w = mb.assignment.len() / (m * t_len);
    assert_eq!(mb.assignment_drawn.len(), m * t_len, "held per episode, the update has the drawing steps");
    let mut s = Steps {
        assignment: vec![vec![Vec::new(); STEPS_PER_ENV]; ENVS],
        drawn: vec![vec![false; STEPS_PER_ENV]; ENVS],
        ended: vec![vec![false; STEPS_PER_ENV]; ENVS],
    };
    for step in 0..t_len {
        for q in 0..m {
            let (i, e, g) = (step * m + q, q % ENVS, (q / ENVS) * t_len + step);
            s.assignment[e][g] = mb.assignment[i * w..(i + 1) * w].to_vec();
            s.drawn[e][g] = mb.assignment_drawn[i];
            s.ended[e][g] = mb.terminated[i] || mb.truncated[i];
        }
    }
    (s, mb)
}

#[test]
fn an_assignment_held_per_episode_is_drawn_where_each_episode_begins() {
    for model in MODELS {
        let mut t = short_episodes(&config(model, 2));
        assert_eq!(t.teams[0].actor.hold.rule(), HoldRule::Episode, "{model}");
        let (first, _) = collect(&mut t);
        let (second, _) = collect(&mut t);
        let mut redrawn = 0;
        for e in 0..ENVS {
            assert!(first.drawn[e][0], "{model}: environment {e} did not draw at its first step");
            // Across both iterations: drawn exactly where the last step ended an episode.
            let chain = |s: &Steps, g: usize| (s.assignment[e][g].clone(), s.drawn[e][g], s.ended[e][g]);
            let steps: Vec<_> = (0..STEPS_PER_ENV)
                .map(|g| chain(&first, g))
                .chain((0..STEPS_PER_ENV).map(|g| chain(&second, g)))
                .collect();
            for g in 1..steps.len() {
                let (ref a, drawn, _) = steps[g];
                let (ref before, _, ended_before) = steps[g - 1];
                assert_eq!(drawn, ended_before, "{model}: environment {e}, step {g}");
                if drawn {
                    redrawn += usize::from(a != before);
                } else {
                    assert_eq!(a, before, "{model}: environment {e}, step {g} did not hold");
                }
            }
            assert!(steps.iter().filter(|s| s.2).count() >= 5, "{model}: episodes of 3 steps end in 20");
        }
        assert!(redrawn > 0, "{model}: no episode's draw changed an assignment");
    }
}

/// The act step counts `ln π(σ | s)` where it draws and the update does the same: on a frozen
/// normaliser the first update's ratios are 1. Counted at every step instead, they are not.
#[test]
fn the_update_counts_an_episodes_assignment_where_it_was_drawn() {
    for model in MODELS {
        let config = config(model, 1);
        let mut t = short_episodes(&config);
        let (_, mb) = collect(&mut t);
        assert!(mb.assignment_drawn.iter().any(|d| !d), "{model}: every step drew");
        assert_the_mask_keeps_the_first_ratio_one(&mut t, mb, model);
    }
}

/// An evaluation (its episodes all begin at its first step, no auto-reset) draws once and
/// holds the draw (sampled actions and assignments); other seeds draw others.
#[test]
fn evaluations_draw_once_an_episode() {
    for model in MODELS {
        let t = Trainer::new(&config(model, 1)).unwrap();
        let obs = t.env.obs().clone();
        let mut first = Vec::new();
        for seed in 0..4 {
            let (mut policy, mut actor) = evaluation_actors(&t.teams, seed, ActMode::Sample).remove(0);
            assert_eq!(actor.hold.rule(), HoldRule::Episode);
            let mut joint = JointAction::new(ENVS, t.env.n_actions(), 1);
            let mut acted = Vec::new();
            for _ in 0..7 {
                actor.act(policy.as_mut(), &t.teams[0].store, &t.teams[0].norm, obs.rows(), &mut joint).unwrap();
                acted.push(joint.assignment[0].clone());
                assert_eq!(joint.assignment_drawn[0], vec![acted.len() == 1; ENVS], "{model}, seed {seed}");
            }
            assert!(acted.iter().all(|a| *a == acted[0]), "{model}, seed {seed}: the draw changed");
            first.push(acted[0].clone());
        }
        assert!(first.iter().any(|a| *a != first[0]), "{model}: every seed drew the same");
    }
}

/// A run held per episode resumed mid-way has the uninterrupted run's rows and parameters
/// (its held assignments are in the checkpoint: drawn again on resume, the rows would
/// differ), as does the same run on two threads; it is another run than one drawn every
/// step; `config.toml` and the run directory's policies hold per episode, and a resume
/// without it is refused.
#[test]
fn runs_held_per_episode_resume_exactly_at_any_thread_count() {
    let tmp = common::TempDir::new("assignment-hold-episode");
    let config = config(MODELS[0], 4);
    let whole = trained_on_one_and_two_threads(&tmp.0, &config);
    let parts = RunDir::new(tmp.0.join("parts"));
    train(&config, &parts, &TrainOptions { stop_after: Some(2), ..Default::default() }).unwrap();
    let saved = Checkpoint::load(&parts.checkpoint()).unwrap();
    let hold = saved.teams[0].assignment_hold.as_ref().expect("the checkpoint keeps the held assignments");
    assert_eq!((hold.pending.len(), hold.held.len() % ENVS), (ENVS, 0));
    assert!(!hold.held.is_empty());
    train(&config, &parts, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&parts), metrics(&whole), "resumed");
    let params = |run: &RunDir| {
        let c = Checkpoint::load(&run.checkpoint()).unwrap();
        c.teams.iter().flat_map(|t| t.params.tensors.iter().map(|x| x.data.clone())).collect::<Vec<_>>()
    };
    assert_eq!(params(&parts), params(&whole));
    // Drawn at every step, the run is another one.
    let every_step = RunDir::new(tmp.0.join("every-step"));
    let per_step = TrainConfig { assignment_hold_episode: false, ..config.clone() };
    train(&per_step, &every_step, &TrainOptions::default()).unwrap();
    assert_ne!(metrics(&every_step), metrics(&whole));
    assert_eq!(load_policies(&whole).unwrap().1[0].actor.hold.rule(), HoldRule::Episode);
    let written = std::fs::read_to_string(whole.config()).unwrap();
    assert!(written.contains("assignment_hold_episode = true"), "{written}");
    let e = train(&per_step, &whole, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("assignment_hold_episode"), "{e}");
}

/// `assign_critic=held`: on an iteration whose episodes end, the update's value reads the
/// held assignment (MLP+HN and SHNN: the gradient reaches `W_σ`, zero at the start; with
/// every step taken as drawing it would not); an MLP+HN run trains it, resumes exactly at any thread count and is
/// another run than the plain critic's; without a hold per episode it is refused.
#[test]
fn a_value_reading_the_held_assignment_learns_from_it_and_resumes_exactly() {
    for model in [HELD_CRITIC, "shnn:assignment=learned;assign_critic=held"] {
        let config = config(model, 1);
        let mut t = short_episodes(&config);
        let (_, mb) = collect(&mut t);
        let held_grad = |t: &mut Trainer, mb: &Minibatch| {
            let team = &mut t.teams[0];
            let w = team.store.find("team0.critic.held.weight").expect("W_σ");
            let tape = Tape::<f32>::new();
            let p = team.store.bind(&tape);
            let mut noise = minibatch_stream(config.seed, "entropy", 0, 0, 0, 0);
            let hp = PpoParams::from_config(&config);
            let (loss, _) = ppo::loss(team.model.as_mut(), &p, mb, &hp, &mut noise).unwrap();
            let g = p.grads(&tape.backward(loss).unwrap());
            g[w.0].to_vec().iter().map(|x| x.abs()).sum::<f32>()
        };
        assert!(held_grad(&mut t, &mb) > 0.0, "{model}: the value read no held assignment");
        let mut drawing = mb.clone();
        drawing.assignment_drawn.iter_mut().for_each(|d| *d = true);
        assert_eq!(held_grad(&mut t, &drawing), 0.0, "{model}: every step drew, yet the value read an assignment");
    }

    let tmp = common::TempDir::new("held-critic");
    let config = self::config(HELD_CRITIC, 3);
    let whole = trained_on_one_and_two_threads(&tmp.0, &config);
    let parts = RunDir::new(tmp.0.join("parts"));
    train(&config, &parts, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    train(&config, &parts, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&parts), metrics(&whole), "resumed");
    let saved = Checkpoint::load(&whole.checkpoint()).unwrap();
    let w = saved.teams[0].params.tensors.iter().find(|x| x.name == "team0.critic.held.weight").expect("W_σ saved");
    assert!(w.data.iter().any(|&x| x != 0.0), "W_σ did not train");
    let plain = RunDir::new(tmp.0.join("plain"));
    train(&TrainConfig { model: MODELS[0].into(), ..config.clone() }, &plain, &TrainOptions::default()).unwrap();
    assert_ne!(metrics(&plain), metrics(&whole), "the plain critic's run");
    let e = TrainConfig { assignment_hold_episode: false, ..config }.validate("held.toml").unwrap_err().to_string();
    assert!(
        e.contains("held.toml") && e.contains("assign_critic=held") && e.contains("assignment_hold_episode = true"),
        "{e}"
    );
}
