//! Training-step benchmark (`../shared/bench/README.md`): `mlp_step` and `shnn_step`, the
//! same arithmetic as the JAX and PyTorch peers, in f32 on every core. Prints
//! `mlp_step  median_ms=...  steps=50  loss=...  device=cpu` and `shnn_step median_ms=...`,
//! the final loss exactly (the shortest decimal that reads back as its bits).
//!
//! Run: `cargo bench -p nn --bench train_step [-- mlp_step|shnn_step]`. `DEVICE=gpu` (with
//! `--features gpu`) keeps the parameters, Adam's moments and the fixed inputs on the GPU, as
//! the JAX peer does on one, and runs every step there; each step ends by reading its loss
//! back, so its time includes the device's work (the peer waits with `block_until_ready`).
//! `GPU_TIMING=1` then times one more step on the GPU's own clock and prints its kernels'
//! timeline (busy against span, by kernel and by op; `GPU_TIMING=all`: every row).

use std::time::Instant;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use nn::message_passing::{Aggregation, EdgeDistance, EdgeList, MessagePassingConfig};
use nn::{Adam, AdamConfig, Bound, Init, Linear, Mlp, ParamStore, SubeqMessagePassing, VectorLinear, clip_elementwise};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use tensor::{Activation, Device, Tape, Tensor, Var};

/// A standard normal draw (Box–Muller).
fn normal(r: &mut ChaCha8Rng) -> f32 {
    nn::init::normal(r) as f32
}

fn randn(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f32> {
    let n = shape.iter().product();
    Tensor::new((0..n).map(|_| normal(r)).collect(), shape).unwrap()
}

/// `t` on `device` (uploaded once, before the timed steps).
fn on(device: Device, t: Tensor<f32>) -> Tensor<f32> {
    t.to_device(device).unwrap_or_else(|e| panic!("cannot place an input on the {device}: {e}"))
}

/// The parameters moved to `device` (Adam uploads its moments there at its first step).
fn placed(mut store: ParamStore<f32>, device: Device) -> ParamStore<f32> {
    store.to_device(device).unwrap_or_else(|e| panic!("cannot place the parameters on the {device}: {e}"));
    store
}

/// Runs `warmup + steps` optimisation steps and prints the median of the counted ones.
fn bench(name: &str, device: Device, warmup: usize, steps: usize, mut step: impl FnMut() -> f32) {
    let mut times = Vec::with_capacity(steps);
    let mut loss = 0.0;
    for k in 0..warmup + steps {
        let t = Instant::now();
        loss = step();
        if k >= warmup {
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    times.sort_by(f64::total_cmp);
    let median = if steps % 2 == 1 { times[steps / 2] } else { 0.5 * (times[steps / 2 - 1] + times[steps / 2]) };
    println!("{name:<9} median_ms={median:.2}  steps={steps}  loss={loss}  device={device}");
    if std::env::var_os("GPU_TIMING").is_some() {
        gpu_timed_step(name, device, step);
    }
}

/// `GPU_TIMING=1`: one more step (after the printed loss) with every kernel launch timed on
/// the GPU's clock (`tensor::gpu::timing`), and its timeline (`GPU_TIMING=all`: every row).
#[cfg(feature = "gpu")]
fn gpu_timed_step(name: &str, device: Device, mut step: impl FnMut() -> f32) {
    if device != Device::Gpu {
        fail("GPU_TIMING times the GPU's kernels: set DEVICE=gpu too");
    }
    let gpu = tensor::gpu::gpu().unwrap_or_else(|e| fail(&e.to_string()));
    let t = Instant::now();
    let (_, timeline) = gpu.timed(&mut step).unwrap_or_else(|e| fail(&e.to_string()));
    let wall = t.elapsed().as_secs_f64() * 1e3;
    eprintln!("{name} gpu-timed step: {wall:.3} ms of wall time");
    if std::env::var("GPU_TIMING").is_ok_and(|v| v == "all") {
        eprintln!("{timeline:#}");
    } else {
        eprintln!("{timeline}");
    }
}

/// `GPU_TIMING` needs the device.
#[cfg(not(feature = "gpu"))]
fn gpu_timed_step(_: &str, _: Device, _: impl FnMut() -> f32) {
    fail("GPU_TIMING needs a build with --features gpu and DEVICE=gpu")
}

/// One optimisation step on the store's device: forward and backward on a fresh tape,
/// element-wise clipping to 0.1, Adam.
fn train_step<F>(store: &mut ParamStore<f32>, adam: &mut Adam, loss_fn: F) -> f32
where
    F: for<'t> Fn(&Bound<'t, f32>) -> Var<'t, f32>,
{
    let tape = Tape::on(store.device());
    let profile = std::env::var_os("TENSOR_PROFILE").is_some();
    if profile {
        tape.enable_profiling();
    }
    let p = store.bind(&tape);
    let loss = loss_fn(&p);
    let g = tape.backward(loss).unwrap();
    if let Some(report) = tape.profile_report() {
        eprintln!("{report}");
    }
    let mut grads = p.grads(&g);
    clip_elementwise(&mut grads, 0.1);
    adam.step(store, &grads).unwrap();
    loss.value().item().unwrap()
}

fn mlp_step(rng: &mut ChaCha8Rng, device: Device) {
    const B: usize = 5120;
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(0);
    let mlp = Mlp::new(&mut store.scope("mlp", &mut init), &[128, 256, 256, 16], Activation::Relu).unwrap();
    let mut store = placed(store, device);
    let x = on(device, randn(rng, &[B, 128]));
    let u = on(device, randn(rng, &[B, 8]));
    let adv = on(device, randn(rng, &[B]));
    let logp_old = on(device, Tensor::<f32>::zeros(&[B]));
    let mut adam = Adam::new(AdamConfig::default(), &store);
    let half_log_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
    bench("mlp_step", device, 5, 50, || {
        train_step(&mut store, &mut adam, |p| {
            let t = p.tape();
            let out = mlp.forward(p, t.constant(x.clone())).unwrap();
            let loc = out.narrow(1, 0, 8).unwrap();
            let std = out.narrow(1, 8, 8).unwrap().softplus().add_scalar(0.001);
            let zs = t.constant(u.clone()).sub(loc).unwrap().div(std).unwrap();
            let logp = zs.square().scale(-0.5).sub(std.log()).unwrap().add_scalar(-half_log_2pi).sum(1, false).unwrap();
            let ratio = logp.sub(t.constant(logp_old.clone())).unwrap().exp();
            let a = t.constant(adv.clone());
            let surr = ratio.mul(a).unwrap().minimum(ratio.clamp(0.7, 1.3).mul(a).unwrap()).unwrap();
            surr.mean_all().unwrap().neg()
        })
    });
}

fn shnn_step(rng: &mut ChaCha8Rng, device: Device) {
    const B: usize = 1024;
    const E: usize = 4;
    let n = B * E;
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(0);
    let (we, emb_h, mp, wu) = {
        let mut s = store.scope("", &mut init);
        let we = VectorLinear::new(&mut s.sub("We"), 4, 32).unwrap();
        let emb_h = Linear::new(&mut s.sub("emb_h"), 12, 64).unwrap();
        let cfg = MessagePassingConfig {
            vectors: 32,
            scalars: 64,
            hidden: 64,
            layers: 2,
            distance: EdgeDistance::Raw,
            aggregation: Aggregation::Mean,
            gravity: None, // g is the 4th input channel, mixed in by We
            edge_scalars: 0,
        };
        let mp = SubeqMessagePassing::new(&mut s.sub("mp"), cfg).unwrap();
        let wu = Linear::with_options(&mut s.sub("Wu"), 32, 1, false, Init::LecunUniform).unwrap();
        (we, emb_h, mp, wu)
    };
    // Z0 [N, 3, 4]: x, v, w standard normal, g = (0, 0, -1) as the 4th channel.
    let mut z0 = randn(rng, &[n, 3, 4]);
    for node in z0.data_mut().chunks_mut(12) {
        node[3] = 0.0;
        node[7] = 0.0;
        node[11] = -1.0;
    }
    let (z0, h0) = (on(device, z0), on(device, randn(rng, &[n, 12])));
    let mut store = placed(store, device);
    let edges = EdgeList::fully_connected(B, E);
    let mut adam = Adam::new(AdamConfig::default(), &store);
    bench("shnn_step", device, 3, 20, || {
        train_step(&mut store, &mut adam, |p| {
            let t = p.tape();
            let z0v = t.constant(z0.clone());
            let x = z0v.narrow(2, 0, 1).unwrap();
            let mut z = we.forward(p, z0v).unwrap();
            let mut h = emb_h.forward(p, t.constant(h0.clone())).unwrap();
            for _ in 0..2 {
                (z, h) = mp.forward(p, z, h, x, &edges).unwrap();
            }
            let u = wu.forward(p, z).unwrap().reshape(&[n, 3]).unwrap();
            u.square().sum(1, false).unwrap().add(h.square().mean(1, false).unwrap()).unwrap().mean_all().unwrap()
        })
    });
}

fn main() {
    let which: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with('-')).collect();
    let run = |name: &str| which.is_empty() || which.iter().any(|w| w == name);
    let mut rng: ChaCha8Rng = rand::SeedableRng::seed_from_u64(0);
    let _ = rng.random::<u32>();
    let device: Device = match std::env::var("DEVICE").map(|d| d.parse::<Device>()) {
        Err(_) => Device::Cpu,
        Ok(Ok(d)) if d.is_built() => d,
        Ok(Ok(d)) => fail(&format!("DEVICE={d}: this build lacks the device (build with --features gpu)")),
        Ok(Err(e)) => fail(&format!("DEVICE: {e}")),
    };
    if run("mlp_step") {
        mlp_step(&mut rng, device);
    }
    if run("shnn_step") {
        shnn_step(&mut rng, device);
    }
}

/// Prints `message` and exits with status 2.
fn fail(message: &str) -> ! {
    eprintln!("train_step: {message}");
    std::process::exit(2)
}
