//! Batches of tiny matrix products, the memory-bound part of the SHNN update: for each
//! product of the subequivariant layers at the size of one `team_reach/1_ant` minibatch
//! (`N = 10240` entity or edge rows), the forward kernel and the fused backward kernel
//! (both gradients in one pass), against the time to fill the largest operand once (a
//! bandwidth yardstick: these kernels cannot beat a pass over their largest array).
//!
//! - `gram`: `Z^T Z`, `[N, 3, 32] -> [N, 32, 32]` (eq. (subeq2)'s invariants).
//! - `coef`: `M C`, `[N, 3, 32] x [N, 32, 32] -> [N, 3, 32]` (the mixed output vectors).
//! - `outer`: `Z Z^T`, `[N, 3, 32] -> [N, 3, 3]` (the normaliser).
//! - `frame`: `O^T Z`, `[N, 3, 3] x [N, 3, 3]` (eq. (lrf)).
//!
//! Prints one line per product, `small <name> fwd_ms=... bwd_ms=... fill_ms=...`, medians of
//! 15 samples after 3 warm-up calls. `N=<rows>` replaces the 10,240 rows (153,600 are the
//! edge rows of a `3_ant_claw_centipede` minibatch).
//!
//! `DEVICE=gpu` (with `--features gpu`) times the forward product on the GPU instead, the
//! operands resident there, each call waited for (`small <name> gpu_fwd_ms=... plan_ms=...
//! gb_per_s=...`: `plan_ms` is the host's share, planning the batch; `gb_per_s` counts each
//! operand read once and the output written once).
//!
//! Run: `cargo bench -p tensor --bench small_products`.

use std::hint::black_box;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use tensor::kernels::matmul::{MatMulPlan, matmul, small_batched_backward};
use tensor::{Device, Tensor};

mod common;
use common::median_ms;

fn filled(shape: &[usize], seed: usize) -> Tensor<f32> {
    let n: usize = shape.iter().product();
    Tensor::new((0..n).map(|i| (((i * 7 + seed) % 101) as f32 - 50.0) * 0.01).collect(), shape).expect("sizes")
}

/// One product: name, `A`'s shape, whether it is transposed, the same for `B`, and whether
/// `B` is `A` itself.
type Case = (&'static str, [usize; 3], bool, [usize; 3], bool, bool);

/// The forward product on `device` (the GPU): operands placed there once, each call waited
/// for; and the host's time to plan the batch.
fn on_device(device: Device, name: &str, a: &Tensor<f32>, ta: bool, b: &Tensor<f32>, tb: bool) {
    let (da, db) = (a.to_device(device).expect("upload"), b.to_device(device).expect("upload"));
    let y = da.matmul_t(&db, ta, tb).expect("shapes");
    let fwd = median_ms(|| {
        black_box(da.matmul_t(&db, ta, tb).expect("shapes"));
        device.synchronize();
    });
    let plan = median_ms(|| {
        black_box(MatMulPlan::new(a.shape(), b.shape(), ta, tb).expect("shapes"));
    });
    let bytes = 4.0 * (a.numel() + b.numel() + y.numel()) as f64;
    println!("small {name} {device}_fwd_ms={fwd:.3} plan_ms={plan:.3} gb_per_s={:.0}", bytes / fwd * 1e-6);
}

fn main() {
    let n: usize = std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(10240);
    let device: Device = std::env::var("DEVICE").ok().and_then(|d| d.parse().ok()).unwrap_or_default();
    if !device.is_built() {
        eprintln!("small_products: DEVICE={device} needs a build with --features gpu");
        std::process::exit(2);
    }
    let cases: [Case; 4] = [
        ("gram", [n, 3, 32], true, [n, 3, 32], false, true),
        ("coef", [n, 3, 32], false, [n, 32, 32], false, false),
        ("outer", [n, 3, 32], false, [n, 3, 32], true, true),
        ("frame", [n, 3, 3], true, [n, 3, 3], false, false),
    ];
    for (name, sa, ta, sb, tb, same) in cases {
        let a = filled(&sa, 1);
        let b = if same { a.clone() } else { filled(&sb, 2) };
        if device != Device::Cpu {
            on_device(device, name, &a, ta, &b, tb);
            continue;
        }
        let y = matmul(&a, &b, ta, tb).expect("shapes");
        let g = filled(y.shape(), 3);
        let fwd = median_ms(|| {
            black_box(matmul(&a, &b, ta, tb).expect("shapes"));
        });
        let mut da = vec![0.0f32; a.numel()];
        let mut db = vec![0.0f32; b.numel()];
        let bwd = median_ms(|| {
            let db = if same { None } else { Some((&mut db[..], false)) };
            small_batched_backward(
                g.data(),
                a.data(),
                ta,
                b.data(),
                tb,
                a.shape(),
                b.shape(),
                Some((&mut da[..], false)),
                db,
                same,
            );
            black_box(&da);
        });
        let largest = a.numel().max(b.numel()).max(y.numel());
        let mut buf = vec![0.0f32; largest];
        let mut k = 0.0f32;
        let fill = median_ms(|| {
            k += 1.0;
            buf.iter_mut().for_each(|x| *x = k);
            black_box(&buf);
        });
        println!(
            "small {name} fwd_ms={fwd:.2} bwd_ms={bwd:.2} fill_ms={fill:.2} largest_mb={:.1}",
            largest as f64 * 4e-6
        );
    }
}
