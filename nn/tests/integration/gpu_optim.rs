//! Parameters, clipping and Adam on the GPU against the host (feature `gpu`; CI runs these
//! on Mesa's lavapipe).
//!
//! Moves and clipping by a clamp are exact. Adam on the GPU keeps its moments in f32 and
//! computes the step in f32 (the host in f64), so a parameter differs from the host's by
//! the rounding of one f32 step per update: a relative 1e-6 of the step size `lr` per
//! update; the test allows `1e-5 lr` per update (the parameters are of size 1, the steps
//! of size `lr = 1e-2`).
#![cfg(feature = "gpu")]

use nn::{Adam, AdamConfig, LrSchedule, Mlp, ParamStore, clip_elementwise, clip_global_norm};
use tensor::{Activation, Device, Tape, Tensor};

/// A small MLP's parameters (seeded).
fn model() -> (ParamStore<f32>, Mlp) {
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(7);
    let mlp = Mlp::new(&mut store.scope("actor", &mut init), &[3, 16, 2], Activation::Tanh).unwrap();
    (store, mlp)
}

/// The gradients of a fixed loss of `mlp` at `store`, computed on the store's device.
fn grads(store: &ParamStore<f32>, mlp: &Mlp, k: usize) -> Vec<Tensor<f32>> {
    let tape = Tape::on(store.device());
    let p = store.bind(&tape);
    let x: Vec<f64> = (0..12).map(|i| ((i * 7 + k * 3) % 11) as f64 / 5.0 - 1.0).collect();
    let x = tape.constant(Tensor::from_f64(&x, &[4, 3]).unwrap());
    let loss = mlp.forward(&p, x).unwrap().square().mean_all().unwrap();
    p.grads(&tape.backward(loss).unwrap())
}

/// The values of `ts` on the host (an explicit transfer for those on the GPU).
fn host(ts: &[Tensor<f32>]) -> Vec<Vec<f32>> {
    ts.iter().map(|t| t.to_host().unwrap().to_vec()).collect()
}

#[test]
fn stores_move_to_the_gpu_and_back_unchanged() {
    let (mut store, _) = model();
    let before = host(store.values());
    assert_eq!(store.device(), Device::Cpu);
    store.to_device(Device::Gpu).unwrap();
    assert_eq!(store.device(), Device::Gpu);
    assert!(store.values().iter().all(|v| v.device() == Device::Gpu));
    store.to_device(Device::Cpu).unwrap();
    assert!(store.values().iter().all(|v| v.device() == Device::Cpu));
    assert_eq!(host(store.values()), before);
    assert_eq!(store.names()[0], "actor.0.weight");
}

#[test]
fn clipping_on_the_gpu_matches_the_host() {
    let (store, mlp) = model();
    let mut cpu = grads(&store, &mlp, 0);
    let mut gpu: Vec<Tensor<f32>> = cpu.iter().map(|g| g.to_device(Device::Gpu).unwrap()).collect();
    clip_elementwise(&mut cpu, 0.05);
    clip_elementwise(&mut gpu, 0.05);
    assert!(gpu.iter().all(|g| g.device() == Device::Gpu));
    assert_eq!(host(&gpu), host(&cpu), "a clamp is exact");

    let (n_cpu, n_gpu) = (clip_global_norm(&mut cpu, 0.01), clip_global_norm(&mut gpu, 0.01));
    assert!(n_cpu > 0.01 && (n_gpu - n_cpu).abs() <= 1e-5 * n_cpu, "{n_gpu} vs {n_cpu}");
    for (g, c) in gpu.iter().zip(&cpu) {
        assert_eq!(g.device(), Device::Gpu);
        assert!(g.to_host().unwrap().all_close(c, 1e-5, 1e-9));
    }
}

/// `Adam::step_clipped` is `clip_elementwise` then `Adam::step`, bit for bit, on each device
/// (on the GPU the clip runs inside the Adam kernel; `tensor`'s `gpu_ops` counts its one
/// launch a parameter, which this file's parallel tests would disturb).
#[test]
fn a_clipped_step_is_the_clip_then_the_step_on_both_devices() {
    for device in [Device::Cpu, Device::Gpu] {
        let (mut store, mlp) = model();
        store.to_device(device).unwrap();
        let (mut apart, mut fused) = (store.clone(), store.clone());
        let config = AdamConfig { lr: LrSchedule::Constant(1e-2), ..AdamConfig::default() };
        let (mut adam_apart, mut adam_fused) = (Adam::new(config, &store), Adam::new(config, &store));
        for k in 0..3 {
            let mut g = grads(&apart, &mlp, k);
            assert!(host(&g).iter().flatten().any(|v| v.abs() > 0.05), "the clip bites");
            clip_elementwise(&mut g, 0.05);
            adam_apart.step(&mut apart, &g).unwrap();
            let g = grads(&fused, &mlp, k);
            adam_fused.step_clipped(&mut fused, &g, 0.05).unwrap();
        }
        assert_eq!(host(fused.values()), host(apart.values()), "{device}: the parameters");
        assert_ne!(host(fused.values()), host(store.values()), "{device}: the steps moved them");
    }
}

#[test]
fn adam_on_the_gpu_follows_the_host_and_its_state_saves_and_resumes() {
    let lr = 1e-2;
    let config = AdamConfig { lr: LrSchedule::Constant(lr), ..AdamConfig::default() };
    let (mut cpu, mlp) = model();
    let mut gpu = cpu.clone();
    gpu.to_device(Device::Gpu).unwrap();
    let (mut adam_cpu, mut adam_gpu) = (Adam::new(config, &cpu), Adam::new(config, &gpu));
    let steps = 5;
    for k in 0..steps {
        let g = grads(&cpu, &mlp, k);
        adam_cpu.step(&mut cpu, &g).unwrap();
        let g = grads(&gpu, &mlp, k);
        assert!(g.iter().all(|g| g.device() == Device::Gpu));
        adam_gpu.step(&mut gpu, &g).unwrap();
        assert_eq!((gpu.device(), adam_gpu.device()), (Device::Gpu, Device::Gpu));
    }
    let tol = 1e-5 * lr * steps as f64;
    for (g, c) in gpu.values().iter().zip(cpu.values()) {
        let g = g.to_host().unwrap();
        assert!(g.all_close(c, 0.0, tol), "{:?} vs {:?}", g.to_vec(), c.to_vec());
    }

    // The saved state: the f32 moments in the host's f64 vectors, the same format.
    adam_gpu.sync_to_host().unwrap();
    let saved = serde_json::to_string(&adam_gpu).unwrap();
    let host_saved = serde_json::to_string(&adam_cpu).unwrap();
    let keys = |s: &str| serde_json::from_str::<serde_json::Map<String, serde_json::Value>>(s).unwrap();
    assert_eq!(keys(&saved).keys().collect::<Vec<_>>(), keys(&host_saved).keys().collect::<Vec<_>>());

    // Resumed on the GPU from the saved state: the same bits as going on.
    let mut resumed: Adam = serde_json::from_str(&saved).unwrap();
    resumed.check_fits(&gpu).unwrap();
    resumed.to_device(Device::Gpu).unwrap();
    let mut going_on = gpu.clone();
    let mut from_saved = gpu.clone();
    let g = grads(&gpu, &mlp, steps);
    adam_gpu.step(&mut going_on, &g).unwrap();
    resumed.step(&mut from_saved, &g).unwrap();
    assert_eq!(host(going_on.values()), host(from_saved.values()));

    // Resumed on the host: the host arithmetic from the GPU's moments.
    let mut on_host = gpu.clone();
    on_host.to_device(Device::Cpu).unwrap();
    let mut adam_host: Adam = serde_json::from_str(&saved).unwrap();
    let g_host = grads(&on_host, &mlp, steps);
    adam_host.step(&mut on_host, &g_host).unwrap();
    assert!(on_host.values().iter().all(|v| v.device() == Device::Cpu));
    for (h, g) in on_host.values().iter().zip(going_on.values()) {
        assert!(h.all_close(&g.to_device(Device::Cpu).unwrap(), 0.0, 1e-5 * lr));
    }

    // A host step after GPU steps brings the moments back first.
    let mut back = going_on.clone();
    back.to_device(Device::Cpu).unwrap();
    adam_gpu.step(&mut back, &g_host).unwrap();
    assert_eq!(adam_gpu.device(), Device::Cpu);
    assert_eq!(adam_gpu.t, steps as u64 + 2);
}
