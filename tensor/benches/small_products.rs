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
//! 15 samples after 3 warm-up calls.
//!
//! Run: `cargo bench -p tensor --bench small_products`.

use std::hint::black_box;
use std::time::Instant;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use tensor::Tensor;
use tensor::kernels::matmul::{matmul, small_batched_backward};

const N: usize = 10240;
const SAMPLES: usize = 15;

fn median_ms(mut f: impl FnMut()) -> f64 {
    for _ in 0..3 {
        f();
    }
    let mut t: Vec<f64> = (0..SAMPLES)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[SAMPLES / 2]
}

fn filled(shape: &[usize], seed: usize) -> Tensor<f32> {
    let n: usize = shape.iter().product();
    Tensor::new((0..n).map(|i| (((i * 7 + seed) % 101) as f32 - 50.0) * 0.01).collect(), shape).expect("sizes")
}

/// One product: name, `A`'s shape, whether it is transposed, the same for `B`, and whether
/// `B` is `A` itself.
type Case = (&'static str, [usize; 3], bool, [usize; 3], bool, bool);

fn main() {
    let cases: [Case; 4] = [
        ("gram", [N, 3, 32], true, [N, 3, 32], false, true),
        ("coef", [N, 3, 32], false, [N, 32, 32], false, false),
        ("outer", [N, 3, 32], false, [N, 3, 32], true, true),
        ("frame", [N, 3, 3], true, [N, 3, 3], false, false),
    ];
    for (name, sa, ta, sb, tb, same) in cases {
        let a = filled(&sa, 1);
        let b = if same { a.clone() } else { filled(&sb, 2) };
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
