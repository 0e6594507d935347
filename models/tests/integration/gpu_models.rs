//! Each of the eleven models' forward and backward pass on the GPU against the CPU, in f32
//! (feature `gpu`; CI runs it on Mesa's lavapipe).
//!
//! The same parameters and observations go through a CPU tape and a GPU tape
//! (`Tape::on(Device::Gpu)` uploads the parameters and inputs once); a scalar loss mixes every
//! output (each agent's action location and scale, the team value) with fixed weights, and
//! the outputs and every parameter's gradient are compared.
//!
//! Tolerance, relative to `max(1, |cpu|)`: `OUTPUT_TOL` for outputs, `GRAD_TOL` for gradients.
//! A model is a few dozen layers deep, each a sum of up to ~1200 f32 products that the GPU
//! adds in another order (tiles of 16) than the CPU (faer's blocks, eight-lane partial sums).
//! Measured on lavapipe (2026-11-27): outputs within 2.7e-6, gradients within 1.8e-5 over
//! the eleven models; the bounds leave a factor of about ten for another driver's
//! `exp`/`tanh`. The loss is well conditioned on purpose (tanh of the outputs): a loss such
//! as `ln(scale)` near its floor multiplies f32 rounding by 1/scale, and then even the CPU in
//! f32 and in f64 differ by 1e-4.
#![cfg(feature = "gpu")]

use envs::tasks::{StartMode, VecEnv};
use models::{Model, ModelDescription, ModelKind, PolicyOutput};
use nn::ParamStore;
use tensor::{Device, Tape, Tensor, Var};

const OUTPUT_TOL: f64 = 3e-5;
const GRAD_TOL: f64 = 2e-4;

/// The scalar loss: every output times fixed weights, summed.
fn loss<'t>(out: &PolicyOutput<'t, f32>) -> Var<'t, f32> {
    let mut total: Option<Var<'t, f32>> = None;
    let mut add = |v: Var<'t, f32>| {
        total = Some(match total {
            Some(t) => t.add(v).unwrap(),
            None => v,
        })
    };
    for (i, a) in out.agents.iter().enumerate() {
        add(a.loc.scale(0.5 + i as f64).tanh().sum_all());
        add(a.scale.scale(0.7).tanh().scale(0.25).sum_all());
    }
    add(out.team_value().unwrap().square().scale(0.1).sum_all());
    // A learned task assignment's log-probability and entropy, as PPO's ratio and bonus.
    if let Some(t) = &out.assignment_terms {
        add(t.log_prob.scale(0.3).tanh().sum_all());
        add(t.entropy.scale(0.2).tanh().sum_all());
    }
    total.unwrap()
}

/// The outputs (flattened) and the parameters' gradients of one pass on `device`.
fn pass(model: &mut Model, store: &ParamStore<f32>, env: &VecEnv, device: Device) -> (Vec<f64>, Vec<Tensor<f32>>) {
    pass_with(model, store, env, device, None)
}

/// [`pass`] with the task assignment of every scene given (a learned one's terms included
/// in the outputs).
fn pass_with(
    model: &mut Model,
    store: &ParamStore<f32>,
    env: &VecEnv,
    device: Device,
    assignment: Option<&[u32]>,
) -> (Vec<f64>, Vec<Tensor<f32>>) {
    let tape = Tape::on(device);
    let p = store.bind(&tape);
    let out = model.forward_batch_with(&p, &env.obs().rows(), assignment).unwrap();
    let mut flat = Vec::new();
    for a in &out.agents {
        assert_eq!(a.loc.value().device(), device, "an output left the device");
        flat.extend(a.loc.value().to_host().unwrap().data().iter().map(|&x| x as f64));
        flat.extend(a.scale.value().to_host().unwrap().data().iter().map(|&x| x as f64));
    }
    flat.extend(out.team_value().unwrap().value().to_host().unwrap().data().iter().map(|&x| x as f64));
    if let Some(t) = &out.assignment_terms {
        for v in [t.log_prob, t.entropy] {
            flat.extend(v.value().to_host().unwrap().data().iter().map(|&x| x as f64));
        }
    }
    let l = loss(&out);
    let grads = p.grads(&tape.backward(l).unwrap());
    (flat, grads.iter().map(|g| g.to_device(Device::Cpu).unwrap()).collect())
}

/// The largest difference relative to `max(1, |cpu|)`, and where.
fn worst(gpu: &[f64], cpu: &[f64]) -> (f64, usize) {
    assert_eq!(gpu.len(), cpu.len());
    gpu.iter()
        .zip(cpu)
        .map(|(g, c)| (g - c).abs() / c.abs().max(1.0))
        .enumerate()
        .fold((0.0, 0), |acc, (i, d)| if d > acc.0 || d.is_nan() { (d, i) } else { acc })
}

/// Every parameter's gradient on the GPU within [`GRAD_TOL`] of the CPU's (model `name`).
fn assert_gradients_close(name: &str, store: &ParamStore<f32>, g_gpu: &[Tensor<f32>], g_cpu: &[Tensor<f32>]) {
    let as64 = |t: &Tensor<f32>| t.data().iter().map(|&x| x as f64).collect::<Vec<_>>();
    for (k, (g, c)) in g_gpu.iter().zip(g_cpu).enumerate() {
        let (d, i) = worst(&as64(g), &as64(c));
        assert!(
            d <= GRAD_TOL,
            "{name}: gradient of {} element {i}: gpu {} vs cpu {} ({d:e})",
            store.names()[k],
            g.data()[i],
            c.data()[i]
        );
    }
}

#[test]
fn every_model_forward_and_backward_on_the_gpu_matches_the_cpu() {
    let mut env = VecEnv::from_name("team_reach/2_ants", 3, 5, StartMode::Random).unwrap();
    let na = env.n_actions();
    env.step(&(0..3 * na).map(|i| ((i as f32) * 0.37).sin()).collect::<Vec<_>>()).unwrap();
    let spec = env.scene().obs_spec.clone();
    for kind in ModelKind::ALL {
        let name = kind.name();
        let mut store = ParamStore::<f32>::new();
        let mut init = nn::init_rng(3);
        let mut model =
            Model::new(&mut store.scope("team0", &mut init), &ModelDescription::new(kind), &spec, 0).unwrap();
        let (out_cpu, g_cpu) = pass(&mut model, &store, &env, Device::Cpu);
        let (out_gpu, g_gpu) = pass(&mut model, &store, &env, Device::Gpu);
        let (d, i) = worst(&out_gpu, &out_cpu);
        assert!(d <= OUTPUT_TOL, "{name}: output {i}: gpu {} vs cpu {} ({d:e})", out_gpu[i], out_cpu[i]);
        assert_gradients_close(name, &store, &g_gpu, &g_cpu);
        // The same pass again on the GPU gives the same bits.
        let (again, g_again) = pass(&mut model, &store, &env, Device::Gpu);
        assert_eq!(again, out_gpu, "{name}: two GPU passes differ");
        assert!(g_again.iter().zip(&g_gpu).all(|(a, b)| a.data() == b.data()), "{name}: two GPU gradients differ");
    }
}

/// `shnn:assignment=learned`: the scorer's log-probability and entropy terms and every
/// gradient, the scorer's included, on the GPU against the CPU, for the assignment the CPU
/// drew (given to both passes, as an update is given the behaviour policy's).
#[test]
fn a_learned_assignment_on_the_gpu_matches_the_cpu() {
    let mut env = VecEnv::from_name("team_reach/2_ants", 3, 5, StartMode::Random).unwrap();
    let na = env.n_actions();
    env.step(&(0..3 * na).map(|i| ((i as f32) * 0.37).cos()).collect::<Vec<_>>()).unwrap();
    let spec = env.scene().obs_spec.clone();
    let mut store = ParamStore::<f32>::new();
    let mut init = nn::init_rng(4);
    let description: ModelDescription = "shnn:assignment=learned".parse().unwrap();
    let mut model = Model::new(&mut store.scope("team0", &mut init), &description, &spec, 0).unwrap();
    let drawn = {
        let tape = Tape::<f32>::new();
        let p = store.bind(&tape);
        let out = model.forward_batch(&p, &env.obs().rows()).unwrap();
        assert!(out.assignment_terms.is_some(), "a learned assignment has terms");
        out.assignment
    };
    let (out_cpu, g_cpu) = pass_with(&mut model, &store, &env, Device::Cpu, Some(&drawn));
    let (out_gpu, g_gpu) = pass_with(&mut model, &store, &env, Device::Gpu, Some(&drawn));
    let (d, i) = worst(&out_gpu, &out_cpu);
    assert!(d <= OUTPUT_TOL, "output {i}: gpu {} vs cpu {} ({d:e})", out_gpu[i], out_cpu[i]);
    assert_gradients_close("shnn:assignment=learned", &store, &g_gpu, &g_cpu);
    let scorer_moved = store
        .names()
        .iter()
        .zip(&g_cpu)
        .any(|(name, c)| name.contains(".assign.") && c.data().iter().any(|&x| x != 0.0));
    assert!(scorer_moved, "no gradient reached the scorer: {:?}", store.names());
}
