//! The fused gradient kernels against the same gradients written as tensor arithmetic over
//! the forward kernels (what `backprop.rs` would do without them), on the CPU, at the sizes
//! of a paper-preset `shnn` or transformer minibatch: the figures behind the list of fused
//! kernels kept (docs/TENSOR.md, "Fused gradient kernels kept").
//!
//! Prints `fused_backward <kernel> fused_ms=... composed_ms=... ratio=... passes=<composed>`
//! per case: medians of 15 calls after 3 warm-up calls, the two forms alternating, f32, the process's threads (rayon's
//! default; `RAYON_NUM_THREADS=1` for one). `passes` is the number of kernels the composed
//! form runs (each one pass over memory and, on the GPU, one launch) where the fused one
//! runs one. `N=<rows>` replaces the 153,600 edge rows.
//!
//! Run: `cargo bench -p tensor --bench fused_backward`.

use std::hint::black_box;

#[global_allocator]
static ALLOC: mimalloc::MiMalloc = mimalloc::MiMalloc;

use tensor::kernels::{elementwise as ew, index, layout, nnops, reduce};
use tensor::{BinaryOp, ReduceOp, Tensor, UnaryOp};

use std::time::Instant;

mod common;
use common::SAMPLES;

type R = Result<Tensor<f32>, tensor::TensorError>;

/// Deterministic values in `[lo, hi)`.
fn values(seed: u32, shape: &[usize], lo: f32, hi: f32) -> Tensor<f32> {
    let n: usize = shape.iter().product();
    let mut s = seed.wrapping_mul(2_654_435_761).max(1);
    let data = (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            lo + (hi - lo) * (s as f32 / u32::MAX as f32)
        })
        .collect();
    Tensor::new(data, shape).expect("shape")
}

fn un(x: &Tensor<f32>, op: UnaryOp) -> Tensor<f32> {
    ew::unary(x, op)
}

fn bin(a: &Tensor<f32>, b: &Tensor<f32>, op: BinaryOp) -> R {
    ew::binary(a, b, op)
}

fn row(x: &Tensor<f32>, op: ReduceOp) -> R {
    reduce::reduce(x, op, Some(x.shape().len() - 1), true)
}

/// Times `fused` and `composed`, alternating (so a busy machine slows both alike), and
/// prints the line with the medians.
fn case(
    name: &str,
    passes: usize,
    fused: impl Fn() -> Vec<f32>,
    composed: impl Fn() -> R,
) -> Result<(), tensor::TensorError> {
    composed()?;
    let time = |f: &dyn Fn()| {
        let s = Instant::now();
        f();
        s.elapsed().as_secs_f64() * 1e3
    };
    let (mut tf, mut tc) = (Vec::with_capacity(SAMPLES), Vec::with_capacity(SAMPLES));
    for k in 0..SAMPLES + 3 {
        let f = time(&|| {
            black_box(fused());
        });
        let c = time(&|| {
            black_box(composed().expect("composed"));
        });
        if k >= 3 {
            tf.push(f);
            tc.push(c);
        }
    }
    let (f, c) = (median(tf), median(tc));
    println!("fused_backward {name} fused_ms={f:.3} composed_ms={c:.3} ratio={:.2} passes={passes}", c / f);
    Ok(())
}

/// The median of the samples.
fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(153_600);
    let threads = rayon::current_num_threads();
    println!("fused_backward: CPU, f32, {threads} threads, {n} edge rows");
    // Element-wise: a message layer's [N, 64] hidden values.
    let shape = [n, 64];
    let x = values(1, &shape, -2.0, 2.0);
    let g = values(2, &shape, -1.0, 1.0);
    for (op, passes) in [(UnaryOp::Tanh, 4), (UnaryOp::Sigmoid, 4), (UnaryOp::Softplus, 2), (UnaryOp::Sqrt, 2)] {
        let x = if op == UnaryOp::Sqrt { un(&x, UnaryOp::Abs) } else { x.clone() };
        let y = un(&x, op);
        let composed = || -> R {
            match op {
                // g (1 - y^2)
                UnaryOp::Tanh => bin(
                    &g,
                    &un(&un(&un(&y, UnaryOp::Square), UnaryOp::Scale(-1.0)), UnaryOp::AddScalar(1.0)),
                    BinaryOp::Mul,
                ),
                // g y (1 - y)
                UnaryOp::Sigmoid => bin(
                    &g,
                    &bin(&y, &un(&un(&y, UnaryOp::Scale(-1.0)), UnaryOp::AddScalar(1.0)), BinaryOp::Mul)?,
                    BinaryOp::Mul,
                ),
                // g sigmoid(x)
                UnaryOp::Softplus => bin(&g, &un(&x, UnaryOp::Sigmoid), BinaryOp::Mul),
                // g / (2 y)
                _ => Ok(un(&bin(&g, &y, BinaryOp::Div)?, UnaryOp::Scale(0.5))),
            }
        };
        let name = format!("unary_{op:?}").to_lowercase();
        case(&name, passes, || ew::unary_backward(g.data(), x.data(), y.data(), op), composed)?;
    }
    // Both gradients of a product and a quotient of [N, 64] values, and of a block divided
    // by one value a row (c / (||G|| + 1)).
    let b = values(3, &shape, 0.5, 2.0);
    for (op, passes) in [(BinaryOp::Mul, 2), (BinaryOp::Div, 3)] {
        let y = bin(&x, &b, op)?;
        let composed = || -> R {
            if op == BinaryOp::Mul {
                black_box(bin(&g, &b, BinaryOp::Mul)?);
                bin(&g, &x, BinaryOp::Mul)
            } else {
                // dA = g / b, dB = -dA y
                let da = bin(&g, &b, BinaryOp::Div)?;
                black_box(&da);
                Ok(un(&bin(&da, &y, BinaryOp::Mul)?, UnaryOp::Neg))
            }
        };
        let fused = || {
            let (da, db) = ew::binary_backward(g.data(), &x, &b, &y, op, (true, true));
            black_box(db);
            da.unwrap_or_default()
        };
        case(&format!("binary_{op:?}").to_lowercase(), passes, fused, composed)?;
    }
    let per_row = values(4, &[n, 1], 0.5, 2.0);
    let y = bin(&x, &per_row, BinaryOp::Div)?;
    let composed = || -> R {
        let da = bin(&g, &per_row, BinaryOp::Div)?;
        black_box(&da);
        Ok(un(&row(&bin(&da, &y, BinaryOp::Mul)?, ReduceOp::Sum)?, UnaryOp::Neg))
    };
    let fused = || {
        let (da, db) = ew::binary_backward(g.data(), &x, &per_row, &y, BinaryOp::Div, (true, true));
        black_box(db);
        da.unwrap_or_default()
    };
    case("binary_div_per_row", 4, fused, composed)?;
    // The max over a row of [N, 64] (its gradient to the first maximal entry).
    let ymax = row(&x, ReduceOp::Max)?;
    let gmax = values(5, &[n, 1], -1.0, 1.0);
    let composed = || -> R {
        let ye = layout::expand(&ymax, &shape)?;
        let mask: Vec<bool> = x.data().iter().zip(ye.data()).map(|(a, b)| a == b).collect();
        let ge = layout::expand(&gmax, &shape)?;
        Tensor::new(ew::where_select(&mask, &shape, &ge, &Tensor::zeros(&shape)), &shape)
    };
    case("max_row", 4, || reduce::max_backward(x.data(), ymax.data(), gmax.data(), n, 64, 1), composed)?;
    // The mean of each node's incoming messages: N edge rows of 64 into N / 16 nodes.
    let nodes = (n / 16).max(1);
    let seg: Vec<usize> = (0..n).map(|r| (r * 7919) % nodes).collect();
    let gseg = values(6, &[nodes, 64], -1.0, 1.0);
    let composed = || -> R {
        let counts = index::segment_counts(&seg, nodes);
        let scale: Vec<f32> = seg.iter().map(|&s| 1.0 / counts[s] as f32).collect();
        bin(&index::index_select(&gseg, 0, &seg)?, &Tensor::new(scale, &[n, 1])?, BinaryOp::Mul)
    };
    case("segment_mean", 2, || index::segment_backward(gseg.data(), &seg, nodes, 64, true), composed)?;
    // Attention's softmax over rows of 16 keys (N rows).
    let s = nnops::softmax(&values(7, &[n, 16], -3.0, 3.0));
    let gs = values(8, &[n, 16], -1.0, 1.0);
    let composed = || -> R {
        // y (g - sum(g y))
        let sum = row(&bin(&gs, &s, BinaryOp::Mul)?, ReduceOp::Sum)?;
        bin(&s, &bin(&gs, &sum, BinaryOp::Sub)?, BinaryOp::Mul)
    };
    case("softmax_16", 4, || nnops::softmax_backward(s.data(), gs.data(), 16), composed)?;
    // The norms of 3-vectors: [16 N, 3] rows (16 vector channels an edge row).
    let v = values(9, &[16 * n, 3], -1.0, 1.0);
    let nv = nnops::norm_last(&v, 1e-8);
    let gn = values(10, &[16 * n, 1], -1.0, 1.0);
    let composed = || -> R { bin(&v, &bin(&gn, &nv, BinaryOp::Div)?, BinaryOp::Mul) };
    case("norm_3", 2, || nnops::norm_last_backward(v.data(), nv.data(), gn.data(), 3), composed)?;
    // A layer normalisation of a transformer's [N / 8, 128] tokens.
    let t = values(11, &[n / 8, 128], -2.0, 2.0);
    let ys = nnops::standardize(&t, 1e-5);
    let gt = values(12, &[n / 8, 128], -1.0, 1.0);
    let composed = || -> R {
        // (g - mean(g) - y mean(g y)) / sqrt(var(x) + eps)
        let centred = bin(&t, &row(&t, ReduceOp::Mean)?, BinaryOp::Sub)?;
        let sigma =
            un(&un(&row(&un(&centred, UnaryOp::Square), ReduceOp::Mean)?, UnaryOp::AddScalar(1e-5)), UnaryOp::Sqrt);
        let mgy = row(&bin(&gt, &ys, BinaryOp::Mul)?, ReduceOp::Mean)?;
        let u =
            bin(&bin(&gt, &row(&gt, ReduceOp::Mean)?, BinaryOp::Sub)?, &bin(&ys, &mgy, BinaryOp::Mul)?, BinaryOp::Sub)?;
        bin(&u, &sigma, BinaryOp::Div)
    };
    case("standardize_128", 13, || nnops::standardize_backward(t.data(), ys.data(), gt.data(), 128, 1e-5), composed)?;
    Ok(())
}
