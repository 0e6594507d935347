//! Matrix-product throughput in f32 on every core: the rate that turns a FLOP count
//! ([`tensor::Tape::profile_flops`]) into an arithmetic floor.
//!
//! For each shape `[m x k] @ [k x n]` that training uses (plus a large square product), it
//! times the library's product (`tensor::kernels::matmul::matmul`, the kernel behind
//! `Var::matmul`, `matmul_t` and `linear`, output buffer included) and the raw faer call
//! on the same data (`faer::linalg::matmul::matmul` into a preallocated matrix), once with
//! faer's own parallelism on all rayon threads (`faer_gflops`) and once on one thread
//! (`faer1_gflops`, the per-core rate), to show the library's overhead. One sample times
//! enough calls for at least 10 ms; the figure is the median of 15 samples after warm-up,
//! at `2 m n k` flops per product. The `backward` line times the library's two products of
//! the same layer's backward pass, `dX = G W^T` and `dW = X^T G`. Prints
//!
//! ```text
//! matmul m=5120 k=256 n=256 gflops=... faer_gflops=... faer1_gflops=... ms=...
//!   backward dx_gflops=... dx_ms=... dw_gflops=... dw_ms=...
//! ...
//! matmul_rate_gflops=...
//! ```
//!
//! where the last line is the median of the library's rate over the large shapes (at least
//! 2^28 multiply-adds; the [2048x128]x[128x256] product is reported but not included).
//!
//! Run: `cargo bench -p tensor --bench matmul_rate`. With the GPU device, `cargo bench -p
//! tensor --features gpu --bench matmul_rate -- --device gpu` times the WGSL product of the
//! same shapes on the GPU instead (operands already on the device, the time to the end of
//! the kernel; `gpu_gflops=`, then `gpu_matmul_rate_gflops=` over the large shapes), after
//! checking each product against the CPU's; then the paper-size layer products of
//! [`GPU_SHAPES`] and their median, `gpu_layer_rate_gflops=`. `TENSOR_GPU_MATMUL_TILE=128`
//! times the 128 x 64 tile instead of the 64 x 64 one (the line names the tile).

use std::hint::black_box;
use std::time::{Duration, Instant};

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use faer::{Accum, Mat, MatRef, Par};
use tensor::Tensor;
use tensor::kernels::matmul::matmul;

/// `(m, k, n)`: the message-passing products of training and a large square one.
const SHAPES: [(usize, usize, usize); 7] = [
    (5120, 256, 256),
    (6144, 1153, 64),
    (5120, 64, 1088),
    (10240, 1024, 64),
    (10240, 64, 1024),
    (2048, 128, 256),
    (2048, 2048, 2048),
];

/// `(m, k, n)`: on the GPU, also the paper preset's message-passing layers of `shnn` on
/// `3_ant_claw_centipede` (153,600 and 30,720 edge rows; `docs/PERFORMANCE.md`'s products by
/// shape), timed after [`SHAPES`].
#[cfg(feature = "gpu")]
const GPU_SHAPES: [(usize, usize, usize); 4] =
    [(153600, 1024, 64), (153600, 64, 1024), (153600, 64, 64), (30720, 64, 64)];

/// Products with at least this many multiply-adds enter the final rate.
const LARGE_WORK: usize = 1 << 28;

/// Timed samples per measurement, and warm-up calls before them.
const SAMPLES: usize = 15;
const WARMUP: usize = 3;

/// Shortest sample: small products are repeated within one sample until it lasts this long.
const MIN_SAMPLE: Duration = Duration::from_millis(10);

/// A deterministic, non-trivial matrix of `rows x cols` (values in [-0.5, 0.5)).
fn matrix(rows: usize, cols: usize, seed: f32) -> Vec<f32> {
    (0..rows * cols).map(|i| ((i as f32 * 0.618_034 + seed) % 1.0) - 0.5).collect()
}

/// Median seconds per call of `f`, over [`SAMPLES`] samples after [`WARMUP`] calls.
fn time_per_call(mut f: impl FnMut()) -> f64 {
    let start = Instant::now();
    for _ in 0..WARMUP {
        f();
    }
    let per_call = start.elapsed() / WARMUP as u32;
    let reps = (MIN_SAMPLE.as_secs_f64() / per_call.as_secs_f64().max(1e-9)).ceil().max(1.0) as usize;
    let mut samples: Vec<f64> = (0..SAMPLES)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                f();
            }
            t.elapsed().as_secs_f64() / reps as f64
        })
        .collect();
    samples.sort_by(f64::total_cmp);
    samples[SAMPLES / 2]
}

/// The median of a non-empty list.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

/// The GPU half: each shape's product and its two backward products on the device, timed
/// to the end of the kernel.
#[cfg(feature = "gpu")]
fn gpu_main() {
    use tensor::Device;
    let gpu = tensor::gpu::gpu().expect("a GPU adapter");
    let config = tensor::GpuConfig::from_bench_env().unwrap_or_else(|e| panic!("matmul_rate: {e}"));
    tensor::configure_gpu(config).expect("checked above");
    let tile = config.matmul_tile.rows();
    eprintln!("matmul_rate: f32 on the GPU: {}, median of {SAMPLES} samples, {tile}-row tiles", gpu.adapter());
    let (mut large, mut layers) = (Vec::new(), Vec::new());
    for (m, k, n) in SHAPES.into_iter().chain(GPU_SHAPES) {
        let a = Tensor::new(matrix(m, k, 0.1), &[m, k]).expect("shape matches data");
        let b = Tensor::new(matrix(k, n, 0.7), &[k, n]).expect("shape matches data");
        let g = Tensor::new(matrix(m, n, 0.3), &[m, n]).expect("shape matches data");
        let (ad, bd, gd) =
            (a.to_device(Device::Gpu).unwrap(), b.to_device(Device::Gpu).unwrap(), g.to_device(Device::Gpu).unwrap());
        // Correctness first: the device's product against the host's.
        let (want, got) = (matmul(&a, &b, false, false).unwrap(), ad.matmul_t(&bd, false, false).unwrap());
        let worst = got.data().iter().zip(want.data()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-5 * k as f32, "GPU product [{m}x{k}]x[{k}x{n}] differs from the CPU's by {worst}");
        let time = |ta: bool, tb: bool, l: &Tensor<f32>, r: &Tensor<f32>| {
            time_per_call(|| {
                black_box(l.matmul_t(r, ta, tb).expect("shapes agree"));
                gpu.synchronize();
            })
        };
        let flops = 2.0 * (m * k * n) as f64;
        let (fw, dx, dw) = (time(false, false, &ad, &bd), time(false, true, &gd, &bd), time(true, false, &ad, &gd));
        println!(
            "matmul m={m} k={k} n={n} gpu_gflops={:.1} ms={:.3} dx_gflops={:.1} dw_gflops={:.1}",
            flops / fw * 1e-9,
            fw * 1e3,
            flops / dx * 1e-9,
            flops / dw * 1e-9
        );
        if !SHAPES.contains(&(m, k, n)) {
            layers.push(flops / fw * 1e-9);
        } else if m * k * n >= LARGE_WORK {
            large.push(flops / fw * 1e-9);
        }
    }
    println!("gpu_matmul_rate_gflops={:.1}", median(large));
    println!("gpu_layer_rate_gflops={:.1}", median(layers));
}

fn main() {
    if std::env::args().any(|a| a == "gpu") {
        #[cfg(feature = "gpu")]
        return gpu_main();
        #[cfg(not(feature = "gpu"))]
        panic!("--device gpu needs the bench built with --features gpu");
    }
    eprintln!("matmul_rate: f32, {} rayon threads, median of {SAMPLES} samples", rayon::current_num_threads());
    let mut large = Vec::new();
    for (m, k, n) in SHAPES {
        let (ad, bd) = (matrix(m, k, 0.1), matrix(k, n, 0.7));
        let a = Tensor::new(ad.clone(), &[m, k]).expect("shape matches data");
        let b = Tensor::new(bd.clone(), &[k, n]).expect("shape matches data");
        let lib = time_per_call(|| {
            black_box(matmul(black_box(&a), black_box(&b), false, false).expect("shapes agree"));
        });

        let (lhs, rhs) = (MatRef::from_row_major_slice(&ad, m, k), MatRef::from_row_major_slice(&bd, k, n));
        let mut dst = Mat::<f32>::zeros(m, n);
        let mut raw = |par: Par| {
            time_per_call(|| {
                faer::linalg::matmul::matmul(dst.as_mut(), Accum::Replace, black_box(lhs), black_box(rhs), 1.0, par);
                black_box(&dst);
            })
        };
        let (raw_par, raw_seq) = (raw(Par::rayon(0)), raw(Par::Seq));

        let flops = 2.0 * (m * k * n) as f64;
        let gflops = flops / lib * 1e-9;
        println!(
            "matmul m={m} k={k} n={n} gflops={gflops:.1} faer_gflops={:.1} faer1_gflops={:.1} ms={:.3}",
            flops / raw_par * 1e-9,
            flops / raw_seq * 1e-9,
            lib * 1e3,
        );
        if m * k * n >= LARGE_WORK {
            large.push(gflops);
        }
        // The two products of the same layer's backward pass: dX = G W^T and dW = X^T G.
        let g = Tensor::new(matrix(m, n, 0.3), &[m, n]).expect("shape matches data");
        let dx = time_per_call(|| {
            black_box(matmul(black_box(&g), black_box(&b), false, true).expect("shapes agree"));
        });
        let dw = time_per_call(|| {
            black_box(matmul(black_box(&a), black_box(&g), true, false).expect("shapes agree"));
        });
        println!(
            "  backward dx_gflops={:.1} dx_ms={:.3} dw_gflops={:.1} dw_ms={:.3}",
            flops / dx * 1e-9,
            dx * 1e3,
            flops / dw * 1e-9,
            dw * 1e3
        );
    }
    println!("matmul_rate_gflops={:.1}", median(large));
}
