//! End-to-end training throughput (`../shared/bench/TRAIN.md`): env steps per second of wall
//! time while training with the reference release's defaults (2048 environments, unroll 5,
//! batch 1024 unrolls x 32 minibatches = 163,840 env steps an iteration, 4 epochs, Adam,
//! observation normalisation), collection and updates together, on every core.
//!
//! For each pair it prints
//! `<env> <model> env_steps_per_s=<median over the measured iterations> ...`, and for the
//! arithmetic floor: the floating-point operations of the update per env step (forward and
//! backward of one minibatch counted on a profiled tape, times minibatches and epochs, divided
//! by the iteration's env steps), the f32 matmul rate measured here, and the floor
//! `floor_steps_per_s = rate / flops_per_step` with the ratio `floor / measured`
//! (`floor_ratio`, collection and update together), and the same ratio for the update alone
//! (`update_floor_ratio`: its wall seconds against its FLOPs at the matmul rate). The rate is
//! sampled before the first and after every measured iteration and the median taken: on a
//! shared VM it moves by a third within minutes (`matmul_rate_gflops=median [min..max]`).
//! `BENCH_ENVS=team_reach/2_ants BENCH_MODELS=shnn,mlp` replaces the pairs measured.
//! `minibatch_ms` is the median of `MINIBATCH_REPS` (default 5) forward-and-backward passes of
//! one minibatch, with its own ratio. `DEVICE=gpu` (a build with `--features gpu`) trains and
//! times the minibatch passes on the GPU (each pass waits for its kernels; the profile waits
//! after every op, so its times are the kernels'), and prints the launches and transfers of
//! a pass; the matmul rate and floor stay the CPU's. `PRESET=quick` uses the quick preset's
//! sizes (256 environments, minibatches of 128 unrolls) instead of the paper's.
//!
//! Run: `cargo bench -p rl --bench train_throughput [-- <filter>]` (a substring of
//! `<env> <model>`). `GPU_TIMING=1` (with `DEVICE=gpu`) times one more pass on the GPU's own
//! clock without waiting between ops (`tensor::gpu::timing`): the kernels' busy time against
//! the pass's span and wall time, by kernel and by op (`GPU_TIMING=all`: every row).
//! `ITERATIONS=k` measures k iterations (default 2) after one warm-up
//! iteration (`WARMUP=0` for none); `ITERATIONS=0` collects one iteration's data and times
//! only the minibatch passes, a quick check of the update's efficiency. `TENSOR_PROFILE=1`
//! prints the per-op profile of the counted minibatch update (`TENSOR_PROFILE=shapes`: with
//! products split by operand shapes).

use std::time::Instant;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use rl::mappo::minibatch::Minibatch;
use rl::mappo::ppo::{self, PpoParams};
use rl::{Preset, TrainConfig, Trainer};
use tensor::{Tape, Tensor};

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Median GFLOP/s of f32 products of the update's typical shape through the library.
fn matmul_rate() -> Result<f64, Box<dyn std::error::Error>> {
    let mut rates = Vec::new();
    for (m, k, n) in [(6144, 256, 256), (6144, 1153, 64), (2048, 2048, 2048)] {
        let a = Tensor::<f32>::new((0..m * k).map(|i| ((i % 97) as f32) * 0.01).collect(), &[m, k])?;
        let b = Tensor::<f32>::new((0..k * n).map(|i| ((i % 89) as f32) * 0.01).collect(), &[k, n])?;
        let mut t = Vec::new();
        for rep in 0..8 {
            let tape = Tape::<f32>::new();
            let (x, y) = (tape.constant(a.clone()), tape.constant(b.clone()));
            let s = Instant::now();
            let z = x.matmul(y)?;
            std::hint::black_box(z.value());
            if rep >= 2 {
                t.push(s.elapsed().as_secs_f64());
            }
        }
        t.sort_by(f64::total_cmp);
        rates.push(2.0 * (m * k * n) as f64 / t[t.len() / 2] / 1e9);
    }
    rates.sort_by(f64::total_cmp);
    Ok(rates[rates.len() / 2])
}

/// The median of `xs` (`NaN` if empty).
fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        k if k % 2 == 1 => v[k / 2],
        k => 0.5 * (v[k / 2 - 1] + v[k / 2]),
    }
}

/// FLOPs of one minibatch update of team 0 (forward and backward), counted on a profiled tape,
/// and the median wall seconds of `reps` unprofiled forward-and-backward passes of it (after
/// one untimed pass).
fn minibatch_flops(t: &Trainer, c: &TrainConfig, reps: usize) -> Result<(u64, f64), Box<dyn std::error::Error>> {
    let ids: Vec<usize> = (0..c.batch_size).collect();
    let mut mb = Minibatch::default();
    t.rollout().gather(&ids, 0, &mut mb);
    let team = &t.teams[0];
    mb.normalise(&team.norm);
    let hp = PpoParams::from_config(c);
    // One forward-and-backward pass of the minibatch on `tape`.
    let pass = |tape: &Tape<f32>| -> Result<(), Box<dyn std::error::Error>> {
        let p = team.store.bind(tape);
        let mut model = team.model.clone();
        let mut noise = rl::mappo::seeding::minibatch_stream(c.seed, "entropy", 0, 0, 0, 0);
        let (loss, _) = ppo::loss(model.as_mut(), &p, &mb, &hp, &mut noise)?;
        std::hint::black_box(tape.backward(loss)?);
        // A GPU pass has only queued its kernels: wait for them.
        c.device.synchronize();
        Ok(())
    };
    let mut times = Vec::new();
    let before = gpu_counts();
    for rep in 0..=reps {
        let start = Instant::now();
        pass(&Tape::on(c.device))?;
        if rep > 0 {
            times.push(start.elapsed().as_secs_f64());
        }
    }
    if let (Some(b), Some(a)) = (before, gpu_counts()) {
        let per = |i: usize| (a[i] - b[i]) as f64 / (reps + 1) as f64;
        eprintln!(
            "gpu per minibatch pass: {:.0} launches, {:.0} uploads ({:.1} MB), {:.0} downloads ({:.3} MB)",
            per(0),
            per(1),
            per(2) / 1e6,
            per(3),
            per(4) / 1e6
        );
    }
    if std::env::var_os("GPU_TIMING").is_some() {
        if c.device != tensor::Device::Gpu {
            return Err("GPU_TIMING times the GPU's kernels: set DEVICE=gpu too".into());
        }
        gpu_timeline(|| pass(&Tape::on(c.device)))?;
    }
    let tape = Tape::<f32>::on(c.device);
    if std::env::var("TENSOR_PROFILE").is_ok_and(|v| v == "shapes") {
        tape.enable_profiling_by_shape();
    } else {
        tape.enable_profiling();
    }
    pass(&tape)?;
    if std::env::var_os("TENSOR_PROFILE").is_some()
        && let Some(r) = tape.profile_report()
    {
        eprintln!("{r}");
    }
    Ok((tape.profile_flops().map(|f| f.total()).unwrap_or(0), median(&times)))
}

/// The GPU's counters (launches, uploads, bytes uploaded, downloads, bytes downloaded) when
/// this build has the device and one answers.
#[cfg(feature = "gpu")]
fn gpu_counts() -> Option<[u64; 5]> {
    let s = tensor::gpu::gpu().ok()?.stats();
    Some([s.launches, s.uploads, s.upload_bytes, s.downloads, s.download_bytes])
}

/// One more pass of `pass` with every launch timed on the GPU's clock: its wall time, and the
/// timeline of its kernels (`GPU_TIMING=all`: every op's row).
#[cfg(feature = "gpu")]
fn gpu_timeline(
    pass: impl FnOnce() -> Result<(), Box<dyn std::error::Error>>,
) -> Result<(), Box<dyn std::error::Error>> {
    let gpu = tensor::gpu::gpu()?;
    gpu.synchronize();
    let start = Instant::now();
    let (done, t) = gpu.timed(pass)?;
    done?;
    let wall = start.elapsed().as_secs_f64();
    eprintln!("gpu-timed minibatch pass: {:.3} ms of wall time", wall * 1e3);
    if std::env::var("GPU_TIMING").is_ok_and(|v| v == "all") {
        eprintln!("{t:#}");
    } else {
        eprintln!("{t}");
    }
    Ok(())
}

/// `GPU_TIMING` needs the device.
#[cfg(not(feature = "gpu"))]
fn gpu_timeline(_: impl FnOnce() -> Result<(), Box<dyn std::error::Error>>) -> Result<(), Box<dyn std::error::Error>> {
    Err("GPU_TIMING needs a build with --features gpu and DEVICE=gpu".into())
}

/// The GPU's counters: none in a build without the device.
#[cfg(not(feature = "gpu"))]
fn gpu_counts() -> Option<[u64; 5]> {
    None
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let iterations = env_usize("ITERATIONS", 2);
    let reps = env_usize("MINIBATCH_REPS", 5);
    let warmup = env_usize("WARMUP", 1);
    // The GPU's kernel choices (`TENSOR_GPU_MATMUL_TILE`, `TENSOR_GPU_REDUCE_LANES`), typed.
    tensor::configure_gpu(tensor::GpuConfig::from_bench_env()?)?;
    // `BENCH_ENVS` / `BENCH_MODELS` (comma-separated) replace the default pairs.
    let list = |var: &str, default: &[&str]| -> Vec<String> {
        std::env::var(var)
            .map(|v| v.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect())
            .unwrap_or_else(|_| default.iter().map(|s| s.to_string()).collect())
    };
    for env in list("BENCH_ENVS", &["team_reach/1_ant", "team_reach/3_ant_claw_centipede"]) {
        for model in list("BENCH_MODELS", &["shnn", "mlp_hn"]) {
            let label = format!("{env} {model}");
            if filter.as_ref().is_some_and(|f| !label.contains(f.as_str())) {
                continue;
            }
            let mut ov = vec![("env".to_string(), format!("{env:?}")), ("model".to_string(), format!("{model:?}"))];
            if let Ok(device) = std::env::var("DEVICE") {
                ov.push(("device".to_string(), format!("{device:?}")));
            }
            let preset =
                if std::env::var("PRESET").is_ok_and(|p| p == "quick") { Preset::Quick } else { Preset::Paper };
            let config = TrainConfig::resolve(Some(preset), None, &ov)?;
            let mut t = Trainer::new(&config)?;
            if iterations == 0 {
                t.collect()?;
            } else {
                for _ in 0..warmup {
                    t.iterate()?;
                }
            }
            let mut rates = vec![matmul_rate()?];
            let (mut sps, mut collect, mut update) = (Vec::new(), Vec::new(), Vec::new());
            for _ in 0..iterations {
                let s = Instant::now();
                let st = t.iterate()?;
                sps.push(config.steps_per_iteration() as f64 / s.elapsed().as_secs_f64());
                collect.push(st.timings.collect_s());
                update.push(st.timings.update_s());
                rates.push(matmul_rate()?);
            }
            let (flops, mb_s) = minibatch_flops(&t, &config, reps)?;
            rates.push(matmul_rate()?);
            let rate = median(&rates) * 1e9;
            let range = format!(
                "{:.0} [{:.0}..{:.0}]",
                rate * 1e-9,
                rates.iter().copied().fold(f64::INFINITY, f64::min),
                rates.iter().copied().fold(0.0, f64::max)
            );
            let flops = flops as f64;
            let mb_line = format!(
                "minibatch_ms={:.1} minibatch_floor_ms={:.1} minibatch_floor_ratio={:.2} matmul_rate_gflops={range}",
                mb_s * 1e3,
                flops / rate * 1e3,
                mb_s * rate / flops
            );
            let ps = tensor::pool::stats::<f32>();
            let mb_line = format!(
                "{mb_line} pool_hits={} pool_misses={} pool_evicted={} pool_peak_mb={} pool_cap_mb={}",
                ps.hits,
                ps.misses,
                ps.evicted,
                ps.peak_pooled_bytes >> 20,
                tensor::pool::max_pooled_bytes() >> 20
            );
            if iterations == 0 {
                println!("{label} {mb_line}");
                continue;
            }
            let update_flops = flops * (config.num_minibatches * config.epochs) as f64;
            let per_step = update_flops / config.steps_per_iteration() as f64;
            let floor = rate / per_step;
            let measured = median(&sps);
            let all: Vec<String> = sps.iter().map(|x| format!("{x:.0}")).collect();
            println!(
                "{label} env_steps_per_s={measured:.0} iterations=[{}] update_flops_per_step={per_step:.3e} \
                 floor_steps_per_s={floor:.0} floor_ratio={:.2} collect_s={:.1} update_s={:.1} \
                 update_floor_ratio={:.2} {mb_line}",
                all.join(","),
                floor / measured,
                median(&collect),
                median(&update),
                median(&update) * rate / update_flops,
            );
        }
    }
    Ok(())
}
