//! Row kernels of network layers on the device (the CPU's `kernels/nnops.rs`): softmax,
//! the norm of the last axis and standardisation (layer norm without the affine part), with
//! their gradients.
//!
//! A tensor is seen as rows of length `n` (its last axis): `rows = len / n`. Each row is
//! computed by one thread (rows are short in this library), except the gradient of
//! [`norm_last`], which is element-wise. The maths is the CPU's step for step: the same
//! max-shift, the same order of the softmax sums, and `sum8`'s eight interleaved partial
//! sums where the CPU uses them, so results differ from the CPU only by the device's
//! rounding of `exp`, `sqrt` and division and by fused multiply-adds (a few ulps). Every
//! launch is deterministic (no atomics). `n = 0` or no rows launches nothing and gives an
//! empty buffer. Callers have checked that the buffers' lengths agree (debug builds assert
//! them).

use super::{bits, kernel, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};

const SOFTMAX: Kernel = kernel!("nn_softmax", "nn_softmax.wgsl");
const SOFTMAX_BACKWARD: Kernel = kernel!("nn_softmax_backward", "nn_softmax_backward.wgsl");
const NORM_LAST: Kernel = kernel!("nn_norm_last", "nn_fns.wgsl", "nn_norm_last.wgsl");
const NORM_LAST_BACKWARD: Kernel = kernel!("nn_norm_last_backward", "nn_norm_last_backward.wgsl");
const STANDARDIZE: Kernel = kernel!("nn_standardize", "nn_fns.wgsl", "nn_row_stats.wgsl", "nn_standardize.wgsl");
const STANDARDIZE_BACKWARD: Kernel =
    kernel!("nn_standardize_backward", "nn_fns.wgsl", "nn_row_stats.wgsl", "nn_standardize_backward.wgsl");

/// The number of rows of length `n` in `len` values (0 when `n` is 0).
fn rows(len: usize, n: usize) -> usize {
    len.checked_div(n).unwrap_or(0)
}

/// Softmax over the last axis (length `n`), max-shifted: `exp(x - max)` divided by the row's
/// sum (times its inverse, as the CPU's `softmax`). Same length as `x`.
pub(crate) fn softmax(x: &DeviceBuffer, n: usize) -> DeviceBuffer {
    let r = rows(x.len(), n);
    debug_assert_eq!(x.len(), r * n);
    let y = DeviceBuffer::uninit(x.len());
    device().launch_1d(&SOFTMAX, &[u(r), u(n)], &[x.buffer(), y.buffer()], r);
    y
}

/// Gradient of [`softmax`] given its output `y` and the output's gradient `g`:
/// `dx = y * (g - sum(g * y))` row by row (the CPU's `softmax_backward`).
pub(crate) fn softmax_backward(y: &DeviceBuffer, g: &DeviceBuffer, n: usize) -> DeviceBuffer {
    let r = rows(y.len(), n);
    debug_assert_eq!(g.len(), y.len());
    let dx = DeviceBuffer::uninit(y.len());
    device().launch_1d(&SOFTMAX_BACKWARD, &[u(r), u(n)], &[y.buffer(), g.buffer(), dx.buffer()], r);
    dx
}

/// `sqrt(sum x^2 + eps)` over the last axis (length `n`): `[rows, n] -> [rows]` (the CPU's
/// `norm_last`, whose shape keeps the axis as 1). With `n = 0` the rows cannot be counted
/// from the buffer and the result is empty, as on the CPU.
pub(crate) fn norm_last(x: &DeviceBuffer, n: usize, eps: f64) -> DeviceBuffer {
    let r = rows(x.len(), n);
    let y = DeviceBuffer::uninit(r);
    device().launch_1d(&NORM_LAST, &[u(r), u(n), bits(eps)], &[x.buffer(), y.buffer()], r);
    y
}

/// Gradient of [`norm_last`] given its input `x` (`[rows, n]`), output `y` and the output's
/// gradient `g` (both `[rows]`): `dx = (g / y) x` row by row, one thread per element (the
/// CPU's `norm_last_backward`).
pub(crate) fn norm_last_backward(x: &DeviceBuffer, y: &DeviceBuffer, g: &DeviceBuffer, n: usize) -> DeviceBuffer {
    let total = rows(x.len(), n) * n;
    debug_assert_eq!(y.len(), rows(x.len(), n));
    debug_assert_eq!(g.len(), y.len());
    let dx = DeviceBuffer::uninit(x.len());
    device().launch_1d(
        &NORM_LAST_BACKWARD,
        &[u(total), u(n)],
        &[x.buffer(), y.buffer(), g.buffer(), dx.buffer()],
        total,
    );
    dx
}

/// `(x - mean) / sqrt(var + eps)` over the last axis (length `n`), with the biased variance
/// (the CPU's `standardize`). Same length as `x`.
pub(crate) fn standardize(x: &DeviceBuffer, n: usize, eps: f64) -> DeviceBuffer {
    let r = rows(x.len(), n);
    let y = DeviceBuffer::uninit(x.len());
    device().launch_1d(&STANDARDIZE, &[u(r), u(n), bits(eps)], &[x.buffer(), y.buffer()], r);
    y
}

/// Gradient of [`standardize`] given its input `x`, output `y` and the output's gradient `g`:
/// with `s = 1 / sqrt(var + eps)` recomputed from `x`, `dx = s (g - mean(g) - y mean(g y))`
/// row by row (the CPU's `standardize_backward`).
pub(crate) fn standardize_backward(
    x: &DeviceBuffer,
    y: &DeviceBuffer,
    g: &DeviceBuffer,
    n: usize,
    eps: f64,
) -> DeviceBuffer {
    let r = rows(x.len(), n);
    debug_assert_eq!(y.len(), x.len());
    debug_assert_eq!(g.len(), x.len());
    let dx = DeviceBuffer::uninit(x.len());
    device().launch_1d(
        &STANDARDIZE_BACKWARD,
        &[u(r), u(n), bits(eps)],
        &[x.buffer(), y.buffer(), g.buffer(), dx.buffer()],
        r,
    );
    dx
}

#[cfg(test)]
mod tests {
    //! Every op against the CPU kernel within |gpu - cpu| <= 1e-5 (1 + |cpu|) (the device's
    //! exp, sqrt and division are not correctly rounded), on rows of length 1, short, not a
    //! multiple of 8 (sum8's tail) and long; each op also runs twice and must give the same
    //! bits both times.

    use super::*;
    use crate::kernels::nnops as cpu;
    use crate::tensor::Tensor;

    /// Deterministic pseudo-random values in [-scale, scale) (a 64-bit LCG).
    fn values(len: usize, seed: u64, scale: f32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 * scale - scale
            })
            .collect()
    }

    /// (rows, n) of the cases.
    const SHAPES: [(usize, usize); 6] = [(4, 1), (3, 3), (5, 8), (7, 19), (2, 1000), (1, 5)];

    fn bits_of(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn assert_close(got: &[f32], want: &[f32], what: &str) {
        assert_eq!(got.len(), want.len(), "{what}: lengths");
        for (k, (a, b)) in got.iter().zip(want).enumerate() {
            assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "{what} [{k}]: gpu {a} vs cpu {b}");
        }
    }

    /// Runs `f` twice: the two results must be the same bits; returns them.
    fn twice(f: impl Fn() -> DeviceBuffer, what: &str) -> Vec<f32> {
        let a = f().download();
        assert_eq!(bits_of(&f().download()), bits_of(&a), "{what}: rerun");
        a
    }

    #[test]
    fn softmax_and_its_gradient_match_the_cpu() {
        for (k, (r, n)) in SHAPES.into_iter().enumerate() {
            let xv = values(r * n, k as u64, 8.0);
            let gv = values(r * n, 100 + k as u64, 1.0);
            let want = cpu::softmax(&Tensor::new(xv.clone(), &[r, n]).unwrap());
            let x = DeviceBuffer::upload(&xv);
            let got = twice(|| softmax(&x, n), "softmax");
            assert_close(&got, want.data(), &format!("softmax {r}x{n}"));
            let want_dx = cpu::softmax_backward(want.data(), &gv, n);
            let (y, g) = (DeviceBuffer::upload(want.data()), DeviceBuffer::upload(&gv));
            let got_dx = twice(|| softmax_backward(&y, &g, n), "softmax_backward");
            assert_close(&got_dx, &want_dx, &format!("softmax_backward {r}x{n}"));
        }
    }

    #[test]
    fn norm_last_and_its_gradient_match_the_cpu() {
        for (k, (r, n)) in SHAPES.into_iter().enumerate() {
            let xv = values(r * n, 200 + k as u64, 2.0);
            let gv = values(r, 300 + k as u64, 1.0);
            for eps in [0.0, 1e-6] {
                let want = cpu::norm_last(&Tensor::new(xv.clone(), &[r, n]).unwrap(), eps);
                let x = DeviceBuffer::upload(&xv);
                let got = twice(|| norm_last(&x, n, eps), "norm_last");
                assert_close(&got, want.data(), &format!("norm_last {r}x{n} eps {eps}"));
                let want_dx = cpu::norm_last_backward(&xv, want.data(), &gv, n);
                let (y, g) = (DeviceBuffer::upload(want.data()), DeviceBuffer::upload(&gv));
                let got_dx = twice(|| norm_last_backward(&x, &y, &g, n), "norm_last_backward");
                assert_close(&got_dx, &want_dx, &format!("norm_last_backward {r}x{n} eps {eps}"));
            }
        }
    }

    #[test]
    fn standardize_and_its_gradient_match_the_cpu() {
        for (k, (r, n)) in SHAPES.into_iter().enumerate() {
            // An offset mean, so that the mean subtraction matters.
            let xv: Vec<f32> = values(r * n, 400 + k as u64, 2.0).iter().map(|v| v + 3.0).collect();
            let gv = values(r * n, 500 + k as u64, 1.0);
            let eps = 1e-5;
            let want = cpu::standardize(&Tensor::new(xv.clone(), &[r, n]).unwrap(), eps);
            let x = DeviceBuffer::upload(&xv);
            let got = twice(|| standardize(&x, n, eps), "standardize");
            assert_close(&got, want.data(), &format!("standardize {r}x{n}"));
            let want_dx = cpu::standardize_backward(&xv, want.data(), &gv, n, eps);
            let (y, g) = (DeviceBuffer::upload(want.data()), DeviceBuffer::upload(&gv));
            let got_dx = twice(|| standardize_backward(&x, &y, &g, n, eps), "standardize_backward");
            assert_close(&got_dx, &want_dx, &format!("standardize_backward {r}x{n}"));
        }
    }

    #[test]
    fn empty_rows_launch_nothing() {
        let empty = DeviceBuffer::upload(&[]);
        for n in [0, 4] {
            assert_eq!(softmax(&empty, n).len(), 0);
            assert_eq!(softmax_backward(&empty, &empty, n).len(), 0);
            assert_eq!(norm_last(&empty, n, 1e-6).len(), 0);
            assert_eq!(norm_last_backward(&empty, &empty, &empty, n).len(), 0);
            assert_eq!(standardize(&empty, n, 1e-5).len(), 0);
            assert_eq!(standardize_backward(&empty, &empty, &empty, n, 1e-5).len(), 0);
        }
    }
}
