//! The host's cost of one kernel launch: a chain of small element-wise ops on a tape
//! (`z <- z * y + x`, 64 values, `CHAIN` times), its backward pass, then one wait, on
//! `DEVICE=gpu` (with `--features gpu`). The kernels are tiny, so the time is the host's:
//! recording each op on the tape, taking its output buffer, its bind group and dispatch.
//!
//! Prints `launch_overhead launches=... wall_us_per_launch=... host_cpu_us_per_launch=...`,
//! medians of 9 samples after 2 warm-up passes: wall time and the calling thread's CPU
//! time (Linux `/proc/thread-self/schedstat`; the driver's own threads, lavapipe's kernels
//! among them, are not counted) over the launches of one pass.
//!
//! Run: `DEVICE=gpu cargo bench -p tensor --features gpu --bench launch_overhead`.

use std::time::Instant;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use tensor::{Device, Tape, Tensor};

/// Multiply-adds in the chain.
const CHAIN: usize = 400;
const SAMPLES: usize = 9;

/// Nanoseconds the calling thread has run on a CPU (`None` off Linux).
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn filled(n: usize, seed: usize) -> Tensor<f32> {
    Tensor::new((0..n).map(|i| (((i * 7 + seed) % 11) as f32 - 5.0) * 0.01).collect(), &[n]).expect("sizes")
}

/// One pass: the chain forward, its backward, one wait.
fn pass(device: Device, x: &Tensor<f32>, y: &Tensor<f32>) -> Result<(), Box<dyn std::error::Error>> {
    let tape = Tape::on(device);
    let (xv, yv) = (tape.var(x.clone()), tape.var(y.clone()));
    let mut z = xv;
    for _ in 0..CHAIN {
        z = z.mul(yv)?.add(xv)?;
    }
    let loss = z.sum(0, false)?;
    let grads = tape.backward(loss)?;
    std::hint::black_box(grads.get(xv).map(|g| g.to_vec()));
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let device: Device = std::env::var("DEVICE").map(|d| d.parse()).unwrap_or(Ok(Device::Cpu))?;
    let x = filled(64, 1).to_device(device)?;
    let y = filled(64, 2).to_device(device)?;
    for _ in 0..2 {
        pass(device, &x, &y)?;
    }
    let launches = || launch_count(device);
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    let before = launches();
    for _ in 0..SAMPLES {
        let (t0, c0) = (Instant::now(), thread_cpu_ns());
        pass(device, &x, &y)?;
        wall.push(t0.elapsed().as_secs_f64() * 1e6);
        if let (Some(a), Some(b)) = (c0, thread_cpu_ns()) {
            cpu.push((b - a) as f64 / 1e3);
        }
    }
    let per_pass = (launches() - before) as f64 / SAMPLES as f64;
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let per = |t: Option<f64>| t.map(|t| format!("{:.2}", t / per_pass.max(1.0))).unwrap_or_else(|| "n/a".into());
    println!(
        "launch_overhead launches={per_pass:.0} wall_us_per_launch={} host_cpu_us_per_launch={} device={device}",
        per(median(&mut wall)),
        per(median(&mut cpu)),
    );
    Ok(())
}

#[cfg(feature = "gpu")]
fn launch_count(device: Device) -> u64 {
    match device {
        Device::Gpu => tensor::gpu::gpu().map(|g| g.stats().launches).unwrap_or(0),
        Device::Cpu => 0,
    }
}

#[cfg(not(feature = "gpu"))]
fn launch_count(_: Device) -> u64 {
    0
}
