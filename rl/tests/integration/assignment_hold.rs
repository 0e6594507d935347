//! A learned task assignment held for `k` steps (`assignment_hold_steps`, TRAINING.md): the
//! collection draws at steps `0, k, 2k, ..` of each iteration and keeps the draw between; the
//! update counts `ln π(σ | s)` at the drawing steps only, as the act step did (ratio 1 on a
//! frozen normaliser, and not without the mask); evaluations hold from each episode's start;
//! run directories and policy files hold as the run does (and not in a warm-up); a held run
//! resumes exactly and gives the same bits at any thread count.

use crate::common;

use common::metrics;
use rl::app::policy_file::{export_policy, load_policy};
use rl::app::run_dir::load_policies;
use rl::mappo::actor::{ActMode, JointAction};
use rl::mappo::assignment_hold::{HoldRule, draws_at};
use rl::mappo::evaluate::evaluation_actors;
use rl::mappo::minibatch::Minibatch;
use rl::mappo::ppo::{self, PpoParams};
use rl::mappo::seeding::minibatch_stream;
use rl::{RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::Tape;

/// The learned models.
const MODELS: [&str; 2] = ["mlp_hn:assignment=learned", "shnn:assignment=learned"];

/// Steps of one environment in one iteration of [`config`]: 2 blocks of unrolls of 5 steps.
const STEPS_PER_ENV: usize = 10;

/// `iterations` of 10 steps of 8 environments of Team Reach with two ants, each draw held
/// for `hold` steps.
fn config(model: &str, iterations: u64, hold: u64) -> TrainConfig {
    let mut c = common::tiny("team_reach/2_ants", model, iterations, &[]);
    c.threads = 1;
    c.assignment_hold_steps = hold;
    assert_eq!(c.steps_per_iteration() as usize, STEPS_PER_ENV * c.num_envs);
    c
}

/// Team 0's minibatch of every unroll of the iteration just collected, normalised by its
/// (frozen) normaliser.
fn whole_iteration(t: &Trainer) -> Minibatch {
    let ids: Vec<usize> = (0..t.rollout().unrolls()).collect();
    let mut mb = Minibatch::default();
    t.rollout().gather(&ids, 0, &mut mb);
    mb.normalise(&t.teams[0].norm);
    mb
}

/// Per environment, the assignment of each of its steps of the iteration in `mb` (unroll
/// `q` is block `q / E`, environment `q % E`; the minibatch is time-major).
fn per_env_sequences(mb: &Minibatch, envs: usize) -> Vec<Vec<Vec<u32>>> {
    let (m, t_len) = (mb.unrolls, mb.steps);
    let w = mb.assignment.len() / (m * t_len);
    let mut seq = vec![vec![Vec::new(); STEPS_PER_ENV]; envs];
    for t in 0..t_len {
        for q in 0..m {
            let i = t * m + q;
            seq[q % envs][(q / envs) * t_len + t] = mb.assignment[i * w..(i + 1) * w].to_vec();
        }
    }
    seq
}

#[test]
fn a_held_assignment_is_drawn_every_k_steps_and_kept_between() {
    for model in MODELS {
        let mut t = Trainer::new(&config(model, 1, 3)).unwrap();
        assert_eq!(t.teams[0].actor.hold.rule(), HoldRule::Steps(3), "{model}");
        t.collect().unwrap();
        let mb = whole_iteration(&t);
        let expected: Vec<bool> =
            (0..mb.steps).flat_map(|s| (0..mb.unrolls).map(move |q| draws_at((q / 8) * 5 + s, 3))).collect();
        assert_eq!(mb.assignment_drawn, expected, "{model}: the drawing steps");
        let mut redrawn = 0;
        for (e, seq) in per_env_sequences(&mb, 8).iter().enumerate() {
            for g in 1..STEPS_PER_ENV {
                if draws_at(g, 3) {
                    redrawn += usize::from(seq[g] != seq[g - 1]);
                } else {
                    assert_eq!(seq[g], seq[g - 1], "{model}: environment {e}, step {g} did not hold");
                }
            }
        }
        assert!(redrawn > 0, "{model}: no draw at steps 3, 6 and 9 changed an assignment");
    }
    // Drawn at every step (the default), the steps between change too.
    let mut t = Trainer::new(&config(MODELS[0], 1, 1)).unwrap();
    t.collect().unwrap();
    let mb = whole_iteration(&t);
    assert!(mb.assignment_drawn.is_empty());
    let changed =
        per_env_sequences(&mb, 8).iter().any(|seq| (1..STEPS_PER_ENV).any(|g| g % 3 != 0 && seq[g] != seq[g - 1]));
    assert!(changed, "drawn at every step, no assignment changed between steps 0, 3, 6 and 9");
}

/// The act step counts `ln π(σ | s)` where it draws and the update does the same: on a frozen
/// normaliser the first update's ratios are 1. Counted at every step instead (the mask
/// dropped), they are not.
#[test]
fn the_update_counts_a_held_assignment_where_it_was_drawn() {
    for model in MODELS {
        let config = config(model, 1, 3);
        let mut t = Trainer::new(&config).unwrap();
        t.collect().unwrap();
        let mb = whole_iteration(&t);
        assert_the_mask_keeps_the_first_ratio_one(&mut t, mb, model);
    }
}

/// Team 0's first update on `mb` (its iteration just collected, on a frozen normaliser):
/// with the drawing steps' mask the ratios are 1; with every step counted as drawing, not.
pub fn assert_the_mask_keeps_the_first_ratio_one(t: &mut Trainer, mut mb: Minibatch, what: &str) {
    let config = t.config.clone();
    let mut stats = |mb: &Minibatch| {
        let team = &mut t.teams[0];
        let tape = Tape::<f32>::new();
        let p = team.store.bind(&tape);
        let mut noise = minibatch_stream(config.seed, "entropy", 0, 0, 0, 0);
        ppo::loss(team.model.as_mut(), &p, mb, &PpoParams::from_config(&config), &mut noise).unwrap().1
    };
    let st = stats(&mb);
    assert!((st.mean_ratio - 1.0).abs() < 1e-4, "{what}: mean ratio {}", st.mean_ratio);
    assert!(st.clip_fraction == 0.0 && st.approx_kl < 1e-8, "{what}: {st:?}");
    mb.assignment_drawn.iter_mut().for_each(|d| *d = true);
    let unmasked = stats(&mb);
    assert!(unmasked.approx_kl > 1e-4, "{what}: the held steps' ln π(σ | s) changed nothing: {unmasked:?}");
}

/// An evaluation's act steps hold their draws from its first step, in sampled and mean mode.
#[test]
fn evaluations_hold_the_draw_from_each_episodes_start() {
    for model in MODELS {
        let t = Trainer::new(&config(model, 1, 3)).unwrap();
        let obs = t.env.obs().clone();
        for mode in [ActMode::Sample, ActMode::Mean] {
            let mut changed = false;
            for seed in 0..4 {
                let (mut policy, mut actor) = evaluation_actors(&t.teams, seed, mode).remove(0);
                assert_eq!(actor.hold.rule(), HoldRule::Steps(3));
                let mut joint = JointAction::new(8, t.env.n_actions(), 1);
                let mut acted = Vec::new();
                for _ in 0..7 {
                    actor.act(policy.as_mut(), &t.teams[0].store, &t.teams[0].norm, obs.rows(), &mut joint).unwrap();
                    acted.push(joint.assignment[0].clone());
                }
                for g in 1..7 {
                    if draws_at(g, 3) {
                        changed |= acted[g] != acted[g - 1];
                    } else {
                        assert_eq!(acted[g], acted[g - 1], "{model}, {mode:?}, seed {seed}: step {g} did not hold");
                    }
                }
            }
            // Mean mode takes the most likely assignment at every draw: the same observations
            // give the same one.
            assert_eq!(changed, mode == ActMode::Sample, "{model}, {mode:?}");
        }
    }
}

/// A held run resumed mid-way has the uninterrupted run's rows and parameters, as does the
/// same run on two threads; its run directory and policy file hold as it does, a warm-up's
/// env steps not; `config.toml` keeps the field, and a resume with another is refused.
#[test]
fn held_runs_resume_exactly_at_any_thread_count_and_their_files_hold() {
    let tmp = common::TempDir::new("assignment-hold");
    let config = config(MODELS[0], 4, 3);
    let whole = trained_on_one_and_two_threads(&tmp.0, &config);
    let parts = RunDir::new(tmp.0.join("parts"));
    train(&config, &parts, &TrainOptions { stop_after: Some(2), ..Default::default() }).unwrap();
    train(&config, &parts, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&parts), metrics(&whole), "resumed");
    let params = |run: &RunDir| {
        let c = rl::mappo::checkpoint::Checkpoint::load(&run.checkpoint()).unwrap();
        c.teams.iter().flat_map(|t| t.params.tensors.iter().map(|x| x.data.clone())).collect::<Vec<_>>()
    };
    assert_eq!(params(&parts), params(&whole));
    // Drawn at every step, the run is another one.
    let every_step = RunDir::new(tmp.0.join("every-step"));
    train(&TrainConfig { assignment_hold_steps: 1, ..config.clone() }, &every_step, &TrainOptions::default()).unwrap();
    assert_ne!(metrics(&every_step), metrics(&whole));
    // Its run directory and policy file hold as it does.
    let file = tmp.0.join("held.safetensors");
    export_policy(&whole, &file).unwrap();
    assert_eq!(load_policies(&whole).unwrap().1[0].actor.hold.rule(), HoldRule::Steps(3));
    assert_eq!(load_policy(&file).unwrap().teams[0].actor.hold.rule(), HoldRule::Steps(3));
    let written = std::fs::read_to_string(whole.config()).unwrap();
    assert!(written.contains("assignment_hold_steps = 3"), "{written}");
    let other = TrainConfig { assignment_hold_steps: 2, ..config.clone() };
    let e = train(&other, &whole, &TrainOptions::default()).unwrap_err().to_string();
    assert!(e.contains("assignment_hold_steps"), "{e}");
    // In a warm-up the assignment is Algorithm 1's at every step; after it, held.
    let warm = TrainConfig { assignment_warmup_steps: 2 * config.steps_per_iteration(), ..config.clone() };
    let mut t = Trainer::new(&warm).unwrap();
    for expected in [1, 1, 3] {
        assert_eq!(t.teams[0].actor.hold.rule(), HoldRule::Steps(expected), "at {} env steps", t.env_steps);
        t.iterate().unwrap();
    }
    let in_warmup = RunDir::new(tmp.0.join("in-warmup"));
    train(&warm, &in_warmup, &TrainOptions { stop_after: Some(1), ..Default::default() }).unwrap();
    assert_eq!(load_policies(&in_warmup).unwrap().1[0].actor.hold.rule(), HoldRule::Steps(1));
}

/// `config` trained in `dir/whole` on its one thread and in `dir/two-threads` on two: the
/// same rows (the run on one thread is returned).
pub fn trained_on_one_and_two_threads(dir: &std::path::Path, config: &TrainConfig) -> RunDir {
    let whole = RunDir::new(dir.join("whole"));
    train(config, &whole, &TrainOptions::default()).unwrap();
    let two = RunDir::new(dir.join("two-threads"));
    train(&TrainConfig { threads: 2, ..config.clone() }, &two, &TrainOptions::default()).unwrap();
    assert_eq!(metrics(&two), metrics(&whole), "two threads");
    whole
}
