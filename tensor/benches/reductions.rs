//! Reductions over one axis at the sizes of a paper-preset `shnn` minibatch on
//! `team_reach/3_ant_claw_centipede` (153,600 edge rows): a message layer's bias gradient
//! (the rows of `[N, 64]` and `[N, 1088]` summed), the row sums of `[N, 64]`, a policy layer's
//! bias gradient over a 5,120-transition minibatch, and a loss's mean over it.
//!
//! Prints `reduce <name> <device>_ms=... gb_per_s=...` per shape, medians of 15 calls after 3
//! warm-up calls, each waited for, the operand resident on the device (`gb_per_s` counts the
//! input read once). `N=<rows>` replaces the 153,600 rows.
//!
//! Run: `cargo bench -p tensor --bench reductions`; `DEVICE=gpu` (with `--features gpu`)
//! times the GPU's kernel, where `TENSOR_GPU_REDUCE_LANES=1` gives the one-thread-per-output
//! kernel of before 2026-12-01 for a paired timing in one call (docs/TENSOR.md).

use std::hint::black_box;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use tensor::{Device, Tape, Tensor};

mod common;
use common::median_ms;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(153_600);
    let device: Device = std::env::var("DEVICE").ok().and_then(|d| d.parse().ok()).unwrap_or_default();
    if !device.is_built() {
        eprintln!("reductions: DEVICE={device} needs a build with --features gpu");
        std::process::exit(2);
    }
    tensor::configure_gpu(tensor::GpuConfig::from_bench_env()?)?;
    // name, shape, axis (None: every element, as a mean)
    let cases: [(&str, Vec<usize>, Option<usize>); 5] = [
        ("bias_grad_64", vec![n, 64], Some(0)),
        ("bias_grad_1088", vec![n, 1088], Some(0)),
        ("row_sums_64", vec![n, 64], Some(1)),
        ("policy_bias_grad_256", vec![5120, 256], Some(0)),
        ("loss_mean_5120", vec![5120], None),
    ];
    for (name, shape, axis) in cases {
        let count: usize = shape.iter().product();
        let x = Tensor::new((0..count).map(|i| ((i * 7 % 101) as f32 - 50.0) * 0.01).collect(), &shape)?;
        let x = x.to_device(device)?;
        let tape = Tape::<f32>::on(device);
        let ms = median_ms(|| {
            let v = tape.constant(x.clone());
            let y = match axis {
                Some(a) => v.sum(a, false).expect("an axis of the shape"),
                None => v.mean_all().expect("a non-empty tensor"),
            };
            black_box(y.value());
            device.synchronize();
        });
        println!("reduce {name} {device}_ms={ms:.3} gb_per_s={:.0} shape={shape:?}", 4.0 * count as f64 / ms * 1e-6);
    }
    Ok(())
}
