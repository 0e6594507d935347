//! Fused kernels for network layers: softmax over the last axis and `act(x @ w + b)`.

use super::for_rows;
use super::matmul::{MatMulPlan, matmul_into_then};
use crate::element::Float;
use crate::error::{Result, mismatch};
use crate::op::Activation;
use crate::tensor::Tensor;

/// Softmax over the last axis (max-shifted for stability).
pub fn softmax<T: Float>(x: &Tensor<T>) -> Tensor<T> {
    let n = x.shape().last().copied().unwrap_or(1);
    let xd = x.data();
    let mut out = crate::pool::for_overwrite(x.numel());
    for_rows(&mut out, n, |r, row| {
        let src = &xd[r * n..(r + 1) * n];
        let mx = src.iter().copied().fold(T::neg_infinity(), T::max);
        let mut s = T::ZERO;
        for (o, &v) in row.iter_mut().zip(src) {
            *o = (v - mx).exp();
            s += *o;
        }
        let inv = T::ONE / s;
        row.iter_mut().for_each(|v| *v *= inv);
    });
    Tensor::from_parts(out, x.shape().to_vec())
}

/// Gradient of softmax: `dx = y * (g - sum(g * y))` row by row.
pub fn softmax_backward<T: Float>(y: &[T], g: &[T], n: usize) -> Vec<T> {
    let mut out = crate::pool::for_overwrite(y.len());
    for_rows(&mut out, n, |r, row| {
        let (yr, gr) = (&y[r * n..(r + 1) * n], &g[r * n..(r + 1) * n]);
        let dot: T = yr.iter().zip(gr).map(|(&a, &b)| a * b).sum();
        for ((o, &yv), &gv) in row.iter_mut().zip(yr).zip(gr) {
            *o = yv * (gv - dot);
        }
    });
    out
}

/// Checks shapes of a linear layer: `x [.., in]`, `w [in, out]`, `b [out]`; returns the
/// output shape and the row count.
pub fn linear_shapes(x: &[usize], w: &[usize], b: Option<&[usize]>) -> Result<(Vec<usize>, usize)> {
    let ok = !x.is_empty() && w.len() == 2 && x[x.len() - 1] == w[0] && b.is_none_or(|b| b == [w[1]]);
    if !ok {
        let mut shapes = vec![x, w];
        if let Some(b) = b {
            shapes.push(b);
        }
        return Err(mismatch("linear", &shapes, "expected x [.., in], w [in, out], b [out]"));
    }
    let mut out = x.to_vec();
    *out.last_mut().expect("non-empty") = w[1];
    Ok((out, x[..x.len() - 1].iter().product()))
}

/// `act(x @ w + b)` with the bias and activation applied in one pass over the output.
pub fn linear<T: Float>(x: &Tensor<T>, w: &Tensor<T>, b: Option<&Tensor<T>>, act: Activation) -> Result<Tensor<T>> {
    linear_sum(&[(x, w)], b, act)
}

/// `act(sum_i x_i @ w_i + b)`: every product after the first adds into the output, and the
/// bias and activation are applied to each block of rows right after the last one, while the
/// block is in cache. All `x_i` must have the same leading dims and all `w_i` the same width.
pub fn linear_sum<T: Float>(
    parts: &[(&Tensor<T>, &Tensor<T>)],
    b: Option<&Tensor<T>>,
    act: Activation,
) -> Result<Tensor<T>> {
    let terms: Vec<WeightRows<'_, T>> = parts.iter().map(|&(x, w)| (x, w, 0)).collect();
    for &(x, w, _) in &terms {
        linear_shapes(x.shape(), w.shape(), None)?;
    }
    linear_sum_rows(&terms, b, act)
}

/// One term of [`linear_sum_rows`]: `(x, w, row)`, `x [.., k]` times rows `row..row + k` of
/// `w [in, out]` (a contiguous block of the row-major weight: nothing is copied).
pub type WeightRows<'a, T> = (&'a Tensor<T>, &'a Tensor<T>, usize);

/// Checks the terms of a fused layer ([`linear_sum_rows`]) and the bias `[out]`, for the
/// output columns `cols` (`(start, len)`; `None`: all of them); returns the output shape, the
/// row count and the output width.
pub fn linear_rows_shapes<T: Float>(
    parts: &[WeightRows<'_, T>],
    b: Option<&[usize]>,
    cols: Option<(usize, usize)>,
) -> Result<(Vec<usize>, usize, usize)> {
    let Some(&(x0, w0, _)) = parts.first() else {
        return Err(mismatch("linear", &[], "needs at least one (x, w) part"));
    };
    let width = w0.shape().get(1).copied().unwrap_or(0);
    let (start, n) = cols.unwrap_or((0, width));
    if start + n > width {
        return Err(mismatch(
            "linear",
            &[w0.shape()],
            format!("output columns {start}..{} of a weight of {width} columns", start + n),
        ));
    }
    for &(x, w, row) in parts {
        let (xs, ws) = (x.shape(), w.shape());
        let k = xs.last().copied();
        let ok = w.rank() == 2
            && ws[1] == width
            && k.is_some_and(|k| row + k <= ws[0])
            && xs[..xs.len() - 1] == x0.shape()[..x0.rank() - 1];
        if !ok {
            return Err(mismatch(
                "linear",
                &[x0.shape(), w0.shape(), xs, ws],
                format!(
                    "every part must be x [.., k] with the first part's leading dims, times rows {row}..{row}+k \
                     of a weight [in, {width}]"
                ),
            ));
        }
    }
    if let Some(b) = b
        && b != [width]
    {
        return Err(mismatch("linear", &[w0.shape(), b], "expected b [out] for w [in, out]"));
    }
    let mut shape = x0.shape().to_vec();
    *shape.last_mut().expect("checked above") = n;
    let rows = x0.shape()[..x0.rank() - 1].iter().product();
    Ok((shape, rows, n))
}

/// `act(sum_i x_i @ w_i[row_i..row_i + k_i] + b)` for the terms `(x_i, w_i, row_i)`, as
/// [`linear_sum`]: the weights' row blocks are read in place.
pub fn linear_sum_rows<T: Float>(
    parts: &[WeightRows<'_, T>],
    b: Option<&Tensor<T>>,
    act: Activation,
) -> Result<Tensor<T>> {
    let (shape, rows, n) = linear_rows_shapes(parts, b.map(|b| b.shape()), None)?;
    // The first product writes every element; bias and activation follow the last.
    let mut out = crate::pool::for_overwrite(rows * n);
    let bias = b.map(|b| b.data());
    let post = |block: &mut [T]| {
        for row in block.chunks_exact_mut(n.max(1)) {
            if let Some(bias) = bias {
                row.iter_mut().zip(bias).for_each(|(o, &bv)| *o += bv);
            }
            match act {
                Activation::Identity => {}
                Activation::Relu => row.iter_mut().for_each(|v| *v = v.max(T::ZERO)),
                Activation::Tanh => row.iter_mut().for_each(|v| *v = v.tanh()),
            }
        }
    };
    let needs_post = bias.is_some() || act != Activation::Identity;
    for (i, &(x, w, row)) in parts.iter().enumerate() {
        let k = x.shape()[x.rank() - 1];
        let plan = MatMulPlan::single(rows, k, n);
        let post = (needs_post && i + 1 == parts.len()).then_some(&post as _);
        matmul_into_then(&mut out, i > 0, x.data(), false, &w.data()[row * n..(row + k) * n], false, &plan, post);
    }
    Ok(Tensor::from_parts(out, shape))
}

/// `g * act'(pre)` expressed through the output `y` of the activation (in parallel for
/// large inputs).
pub fn activation_backward<T: Float>(y: &[T], g: &[T], act: Activation) -> Vec<T> {
    let mut out = crate::pool::for_overwrite(g.len());
    super::fill_chunks(&mut out, |s, ch| {
        let n = ch.len();
        let (gs, ys) = (&g[s..s + n], &y[s..s + n]);
        match act {
            Activation::Identity => ch.copy_from_slice(gs),
            Activation::Relu => {
                for ((o, &gv), &yv) in ch.iter_mut().zip(gs).zip(ys) {
                    *o = if yv > T::ZERO { gv } else { T::ZERO };
                }
            }
            Activation::Tanh => {
                for ((o, &gv), &yv) in ch.iter_mut().zip(gs).zip(ys) {
                    *o = gv * (T::ONE - yv * yv);
                }
            }
        }
    });
    out
}

/// `sqrt(sum x^2 + eps)` over the last axis, one value per row (`[.., n] -> [.., 1]`).
pub fn norm_last<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
    let n = x.shape().last().copied().unwrap_or(1);
    let rows = x.numel().checked_div(n).unwrap_or(0);
    let xd = x.data();
    let eps = T::from_f64(eps);
    let mut out = crate::pool::for_overwrite(rows);
    let body = |r: usize, o: &mut T| {
        let s = super::reduce::sum8(xd[r * n..(r + 1) * n].iter().map(|&v| v * v));
        *o = (s + eps).sqrt();
    };
    if x.numel() >= super::PAR_MIN {
        use rayon::prelude::*;
        out.par_iter_mut().enumerate().for_each(|(r, o)| body(r, o));
    } else {
        out.iter_mut().enumerate().for_each(|(r, o)| body(r, o));
    }
    let mut shape = x.shape().to_vec();
    if let Some(l) = shape.last_mut() {
        *l = 1;
    }
    Tensor::from_parts(out, shape)
}

/// Gradient of [`norm_last`]: `dx = g x / y` row by row.
pub fn norm_last_backward<T: Float>(x: &[T], y: &[T], g: &[T], n: usize) -> Vec<T> {
    let mut out = crate::pool::for_overwrite(x.len());
    for_rows(&mut out, n, |r, row| {
        let s = g[r] / y[r];
        for (o, &xv) in row.iter_mut().zip(&x[r * n..(r + 1) * n]) {
            *o = s * xv;
        }
    });
    out
}

/// Mean and `1 / sqrt(var + eps)` (biased variance) of one row.
#[inline]
fn row_stats<T: Float>(row: &[T], eps: f64) -> (T, T) {
    let n = T::from_f64(row.len() as f64);
    let mean = super::reduce::sum8(row.iter().copied()) / n;
    let var = super::reduce::sum8(row.iter().map(|&v| (v - mean) * (v - mean))) / n;
    (mean, T::ONE / (var + T::from_f64(eps)).sqrt())
}

/// `(x - mean) / sqrt(var + eps)` over the last axis, row by row (layer normalisation
/// without the affine part).
pub fn standardize<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
    let n = x.shape().last().copied().unwrap_or(1);
    let xd = x.data();
    let mut out = crate::pool::for_overwrite(x.numel());
    for_rows(&mut out, n, |r, row| {
        let src = &xd[r * n..(r + 1) * n];
        let (mean, inv) = row_stats(src, eps);
        for (o, &v) in row.iter_mut().zip(src) {
            *o = (v - mean) * inv;
        }
    });
    Tensor::from_parts(out, x.shape().to_vec())
}

/// Gradient of [`standardize`]: with `y` the output and `s = 1/sqrt(var + eps)`,
/// `dx = s (g - mean(g) - y mean(g y))` row by row.
pub fn standardize_backward<T: Float>(x: &[T], y: &[T], g: &[T], n: usize, eps: f64) -> Vec<T> {
    let mut out = crate::pool::for_overwrite(x.len());
    let nf = T::from_f64(n as f64);
    for_rows(&mut out, n, |r, row| {
        let (xr, yr, gr) = (&x[r * n..(r + 1) * n], &y[r * n..(r + 1) * n], &g[r * n..(r + 1) * n]);
        let (_, inv) = row_stats(xr, eps);
        let mg = super::reduce::sum8(gr.iter().copied()) / nf;
        let mgy = super::reduce::sum8(gr.iter().zip(yr).map(|(&a, &b)| a * b)) / nf;
        for ((o, &gv), &yv) in row.iter_mut().zip(gr).zip(yr) {
            *o = inv * (gv - mg - yv * mgy);
        }
    });
    out
}
