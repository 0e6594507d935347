//! Training on the GPU (feature `gpu`; CI runs these on Mesa's lavapipe, a Vulkan device on
//! the CPU where a kernel launch costs far more than on a GPU, hence the tiny sizes: 4
//! environments, 2 minibatches of 4 unrolls of 5 steps, one epoch).
//!
//! **Tolerance of GPU against CPU metrics.** With `act_device = "cpu"` the act step runs on
//! the CPU, so from the same state both devices collect the same rollout (checked exactly);
//! they differ only in the
//! update's arithmetic: the GPU's kernels round in f32 in another order (sums, matrix
//! products; the `tensor` crate's GPU tests allow 1e-4 relative per op) and Adam keeps its
//! moments in f32 there. Each metric is a mean over the iteration's 40 transitions of
//! functions of those values: measured on lavapipe, they differ by at most 6e-6 relative or
//! 7e-7 absolute (shnn and mlp_hn, three iterations each). The tests allow
//! `1e-4 |cpu| + 1e-5`, over ten times that, and for the clip fraction one transition more
//! or less clipped per minibatch (`1/20`): a ratio exactly at the clip boundary may fall on
//! either side. Parameters after an iteration may differ by at most `2 lr` per update: an
//! Adam step moves a parameter by about `lr`, and where a gradient is only rounding noise
//! the two devices may step in opposite directions (measured: at most 3e-5, a tenth of
//! `lr = 3e-4`).
#![cfg(feature = "gpu")]

use crate::common;

use std::path::Path;

use common::{TempDir, metrics};
use rl::mappo::actor::JointAction;
use rl::mappo::checkpoint::Checkpoint;
use rl::mappo::device::ActDevice;
use rl::mappo::evaluate::EvalOptions;
use rl::{RunDir, TrainConfig, TrainOptions, Trainer, train};
use tensor::Device;

/// Minibatch updates per iteration of [`tiny`].
const UPDATES: usize = 2;

/// Three iterations (120 env steps) of 4 environments: [`UPDATES`] minibatches of 4
/// unrolls of 5 steps, one epoch, no evaluation, a checkpoint every iteration.
fn tiny(model: &str, device: Device) -> TrainConfig {
    tiny_on("team_reach/1_ant", model, device)
}

/// [`tiny`] on `env`; a model ending in `+expected` trains with the expected assignment
/// gradient (`assignment_gradient = "expected"`).
fn tiny_on(env: &str, model: &str, device: Device) -> TrainConfig {
    let mut options =
        vec![("num_envs", "4"), ("num_minibatches", "2"), ("epochs", "1"), ("num_evals", "0"), ("steps", "120")];
    let model = match model.strip_suffix("+expected") {
        Some(m) => {
            options.push(("assignment_gradient", "\"expected\""));
            m
        }
        None => model,
    };
    // A value that reads the held assignment trains with a hold per episode.
    if model.contains("assign_critic=held") {
        options.push(("assignment_hold_episode", "true"));
    }
    let mut c = common::tiny(env, model, 3, &options);
    c.device = device;
    c
}

/// Whether a GPU metric is within the tolerance of the CPU's (module docs).
fn close(name: &str, gpu: f64, cpu: f64) -> bool {
    let atol = if name.starts_with("clip_fraction") { 1.0 / 20.0 + 1e-9 } else { 1e-5 };
    (gpu - cpu).abs() <= atol + 1e-4 * cpu.abs()
}

/// Three iterations of each model on the CPU; before each, the CPU's state goes to a GPU
/// trainer acting on the CPU (`act_device = "cpu"`) that does the same iteration: the same
/// rollout, the update's metrics and the parameters within the tolerance (module docs). A
/// learned task assignment (two ants, so that there are two assignments to choose from)
/// enters the update through its log-probability and entropy, and, with
/// `assign_critic=held`, through the value's held assignment (and with the expected gradient
/// through the values and probabilities of every assignment).
#[test]
fn gpu_iterations_follow_the_cpu_from_the_same_state() {
    let cases = [
        ("team_reach/1_ant", "shnn"),
        ("team_reach/1_ant", "mlp_hn"),
        ("team_reach/2_ants", "shnn:assignment=learned"),
        ("team_reach/2_ants", "mlp_hn:assignment=learned;assign_critic=held"),
        ("team_reach/2_ants", "shnn:assignment=learned;assign_critic=held"),
        ("team_reach/2_ants", "mlp_hn:assignment=learned;assign_critic=held+expected"),
    ];
    for (env, model) in cases {
        let mut cpu = Trainer::new(&tiny_on(env, model, Device::Cpu)).unwrap();
        let lr = cpu.config.learning_rate;
        let on_gpu = TrainConfig { act_device: ActDevice::Cpu, ..tiny_on(env, model, Device::Gpu) };
        for i in 0..3 {
            let state = cpu.checkpoint(0.0, &[]).unwrap();
            let mut gpu = Trainer::from_checkpoint(&state, &on_gpu, Path::new("memory")).unwrap();
            let g = gpu.iterate().unwrap();
            let c = cpu.iterate().unwrap();
            assert_eq!(g.episodes, c.episodes, "{model}, iteration {i}: the act step runs on the CPU");
            for ((name, a), (_, b)) in g.losses[0].named().iter().zip(c.losses[0].named()) {
                assert!(close(name, *a, b), "{model}, iteration {i}: {name} {a} on the GPU, {b} on the CPU");
            }
            assert_eq!(gpu.teams[0].store.device(), Device::Gpu, "the updates' parameters stay on the GPU");
            let (pg, pc) = (gpu.teams[0].acting_store().values(), cpu.teams[0].store.values());
            for (a, b) in pg.iter().zip(pc) {
                assert_eq!(a.device(), Device::Cpu, "the act step's mirror is on the host");
                assert!(a.all_close(b, 0.0, 2.0 * lr * UPDATES as f64), "{model}, iteration {i}");
            }
        }
    }
}

/// The act step with its forward pass on the GPU against the CPU's, from the same state
/// (parameters, normaliser, noise streams, observations), for one agent, for several
/// (their means and scales come back in one transfer and are cut apart on the host) and for
/// both teams of Team Sumo (each reading the scene from its own side): the
/// pre-squash actions, actions and log-probabilities within `1e-4 |cpu| + 1e-5` (the
/// forward pass rounds otherwise, the `tensor` crate's GPU tests allow 1e-4 relative per op;
/// the noise is the same draws), the task assignment the same.
#[test]
fn the_act_step_on_the_gpu_follows_the_cpu() {
    let cases = [
        ("team_reach/1_ant", "shnn"),
        ("team_reach/2_ants", "shnn"),
        ("team_reach/2_ants", "mlp_hn"),
        ("team_reach/2_ants", "shnn:assignment=learned"),
        ("team_reach/2_ants", "mlp_hn:assignment=learned"),
        ("team_sumo/2_ants", "shnn"),
    ];
    for (env, model) in cases {
        let config = common::tiny(env, model, 3, &[("num_envs", "4")]);
        let mut trainer = Trainer::new(&config).unwrap();
        // Normaliser statistics from a few steps, so that normalising is not the identity.
        trainer.collect().unwrap();
        for k in 0..trainer.teams.len() {
            let mut norm = trainer.teams[k].norm.clone();
            for rows in trainer.rollout().visited_obs() {
                norm.update(rows.vectors, rows.scalars);
            }
            trainer.teams[k].norm = norm;
        }
        assert_eq!(trainer.teams.len(), if env.starts_with("team_sumo") { 2 } else { 1 }, "{env}");
        for team in &trainer.teams {
            check_act_step_on_the_gpu(&trainer, team, &format!("{env} {model}, team {}", team.index));
        }
    }
}

/// One team's act step from the trainer's current observations, its forward pass on the GPU
/// and on the CPU ([`the_act_step_on_the_gpu_follows_the_cpu`]).
fn check_act_step_on_the_gpu(trainer: &Trainer, team: &rl::Team, case: &str) {
    let mut on_gpu = team.store.clone();
    on_gpu.to_device(Device::Gpu).unwrap();
    let (envs, na, nt) = (trainer.config.num_envs, trainer.env.n_actions(), trainer.teams.len());
    let act = |store| {
        let (mut model, mut actor) = (team.model.clone(), team.actor.clone());
        let mut joint = JointAction::new(envs, na, nt);
        actor.act(model.as_mut(), store, &team.norm, trainer.env.obs().rows(), &mut joint).unwrap();
        joint
    };
    let (g, c) = (act(&on_gpu), act(&team.store));
    let near = |a: &[f32], b: &[f32], what: &str| {
        assert_eq!(a.len(), b.len());
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            let (x, y) = (f64::from(*x), f64::from(*y));
            assert!((x - y).abs() <= 1e-5 + 1e-4 * y.abs(), "{case}: {what}[{k}] {x} on the GPU, {y} on the CPU");
        }
    };
    near(&g.pre_squash, &c.pre_squash, "pre_squash");
    near(&g.actions, &c.actions, "actions");
    near(&g.logp[team.index], &c.logp[team.index], "logp");
    assert!(c.logp[team.index].iter().all(|&l| l != 0.0), "{case}: every log-probability written");
    assert_eq!(g.assignment, c.assignment, "{case}");
}

/// A GPU run evaluates where it acts: with `act_device = "same"` its evaluation launches
/// kernels (the policy's forward pass on the GPU; one evaluation of two 1000-step episodes,
/// about 30 s on lavapipe, so the same seed's bits are left to the training test above);
/// with `act_device = "cpu"` it launches none and is the host's evaluation exactly.
#[test]
fn a_gpu_run_evaluates_where_it_acts() {
    let gpu = tiny("mlp_hn", Device::Gpu);
    let launches = || tensor::gpu::gpu().unwrap().stats().launches;
    let options = EvalOptions::new(2, false, 7, gpu.start_mode());
    let trainer = Trainer::new(&gpu).unwrap();
    let before = launches();
    let a = trainer.evaluate(&options).unwrap();
    assert!(launches() > before, "the act step's forward pass ran on the GPU");
    assert_eq!(a.episodes, 2);
    let on_cpu = Trainer::new(&TrainConfig { act_device: ActDevice::Cpu, ..gpu }).unwrap();
    let before = launches();
    let c = on_cpu.evaluate(&options).unwrap();
    assert_eq!(launches(), before, "act_device = cpu: no kernel");
    assert_eq!(c, rl::mappo::evaluate::evaluate(&on_cpu.config.env, &on_cpu.teams, &options).unwrap());
}

/// `meben eval --device gpu` names the adapter and evaluates with the policy on the GPU.
#[test]
fn the_program_evaluates_on_the_gpu() {
    let tmp = TempDir::new("gpu-eval");
    let run = RunDir::new(tmp.0.join("r"));
    let config = TrainConfig { num_evals: 0, ..tiny("mlp_hn", Device::Cpu) };
    train(&TrainConfig { steps: 40, ..config }, &run, &TrainOptions::default()).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_meben"))
        .args(["eval", "--device", "gpu", "--episodes", "2", "--run"])
        .arg(run.root())
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stderr}");
    let adapter = tensor::gpu::gpu().unwrap().adapter().to_string();
    assert!(stderr.contains(&format!("meben: evaluating on GPU: {adapter}")), "{stderr}");
    assert!(stdout.contains("episodes 2"), "{stdout}");
}

/// The same seed twice on the GPU, one run stopped after two iterations and resumed there:
/// identical metrics rows (wall-time columns aside). The checkpoint of the stopped run,
/// resumed on the CPU, finishes the run there (not bit-identical: the third iteration's
/// update rounds on the CPU; within the tolerance).
#[test]
fn the_same_seed_gives_the_same_bits_on_the_gpu_and_a_gpu_checkpoint_resumes_on_the_cpu() {
    let tmp = TempDir::new("gpu-repro");
    let gpu = tiny("mlp_hn", Device::Gpu);
    let (a, b) = (RunDir::new(tmp.0.join("a")), RunDir::new(tmp.0.join("b")));
    train(&gpu, &a, &TrainOptions { stop_after: Some(2), ..Default::default() }).unwrap();
    let on_cpu = RunDir::new(tmp.0.join("on_cpu"));
    std::fs::create_dir_all(on_cpu.root()).unwrap();
    // The checkpoint is a pair (checkpoint.json and the tensors file it names).
    for entry in std::fs::read_dir(a.root()).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.starts_with("checkpoint.") || name == "metrics.csv" || name == "config.toml" {
            std::fs::copy(a.root().join(&name), on_cpu.root().join(&name)).unwrap();
        }
    }
    // The GPU's checkpoint: the device in its configuration, the moments brought back.
    let saved = Checkpoint::load(&a.checkpoint()).unwrap();
    assert_eq!((saved.iteration, saved.config.device), (2, Device::Gpu));
    let moments = serde_json::to_value(&saved.teams[0].adam).unwrap();
    let m = moments["m"].as_array().unwrap();
    assert!(m.iter().flat_map(|b| b.as_array().unwrap()).any(|x| x.as_f64().unwrap() != 0.0));
    assert!(std::fs::read_to_string(a.config()).unwrap().contains("device = \"gpu\""));

    train(&gpu, &a, &TrainOptions::default()).unwrap();
    train(&gpu, &b, &TrainOptions::default()).unwrap();
    let (ma, mb) = (metrics(&a), metrics(&b));
    assert_eq!(ma.len(), 3);
    assert_eq!(ma, mb, "the same seed on the GPU, stopped and resumed or not");

    let cpu = TrainConfig { device: Device::Cpu, ..gpu.clone() };
    train(&cpu, &on_cpu, &TrainOptions::default()).unwrap();
    let mc = metrics(&on_cpu);
    assert_eq!(mc[..2], ma[..2]);
    assert_ne!(mc[2], ma[2], "the CPU's update rounds otherwise");
    for ((name, x), (name_gpu, y)) in mc[2].iter().zip(&ma[2]) {
        assert_eq!(name, name_gpu);
        assert!(close(name, *y, *x), "iteration 3, {name}: {y} on the GPU, {x} on the CPU after the GPU's checkpoint");
    }
    assert!(!std::fs::read_to_string(on_cpu.config()).unwrap().contains("device"));
}

/// `meben train --device gpu` says which adapter it trains on.
#[test]
fn the_program_names_the_adapter() {
    let tmp = TempDir::new("gpu-cli");
    let out = tmp.0.join("r");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_meben"))
        .args(["train", "--model", "mlp_hn", "--device", "gpu", "--steps", "40", "--num-envs", "4", "--quiet"])
        .args(["--set", "batch_size=4", "--set", "num_minibatches=2", "--set", "epochs=1", "--set", "num_evals=0"])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let adapter = tensor::gpu::gpu().unwrap().adapter().to_string();
    assert!(stderr.contains(&format!("meben: training on GPU: {adapter}")), "{stderr}");
}

/// `MEBEN_TIMINGS=gpu` prints each iteration's stages and its kernels on the GPU's clock.
#[test]
fn the_program_prints_an_iterations_kernels_on_the_gpus_clock() {
    let tmp = TempDir::new("gpu-timeline");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_meben"))
        .args(["train", "--model", "mlp_hn", "--device", "gpu", "--steps", "80", "--num-envs", "4", "--quiet"])
        .args(["--set", "batch_size=4", "--set", "num_minibatches=2", "--set", "epochs=1", "--set", "num_evals=0"])
        .arg("--out")
        .arg(tmp.0.join("r"))
        .env("MEBEN_TIMINGS", "gpu")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    for k in [1, 2] {
        assert!(stderr.contains(&format!("meben: iteration {k} took")), "{stderr}");
        assert!(stderr.contains(&format!("meben: iteration {k} on the GPU's clock: gpu timeline: ")), "{stderr}");
    }
    // The update's kernels, labelled by op: the policy's layers forward and backward, Adam's
    // step outside the tape.
    for row in ["linear / matmul", "linear (backward) / matmul", "- / adam"] {
        assert!(stderr.contains(row), "no {row:?} row:\n{stderr}");
    }
    assert!(!stderr.contains("leaf /"), "launches credited to a leaf:\n{stderr}");
}
