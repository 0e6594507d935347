//! Reductions: sum, mean and max over one axis or over all elements, and the "sum back to
//! a broadcast source shape" that every broadcasting gradient needs.

use super::{PAR_CHUNK, PAR_MIN};
use crate::element::Float;
use crate::error::{Result, check_axis, invalid};
use crate::op::ReduceOp;
use crate::shape::split_at_axis;
use crate::tensor::Tensor;
use rayon::prelude::*;

/// Output shape of a reduction.
pub fn reduced_shape(shape: &[usize], axis: Option<usize>, keepdim: bool) -> Vec<usize> {
    match (axis, keepdim) {
        (None, false) => vec![],
        (None, true) => vec![1; shape.len()],
        (Some(a), true) => {
            let mut s = shape.to_vec();
            s[a] = 1;
            s
        }
        (Some(a), false) => {
            let mut s = shape.to_vec();
            s.remove(a);
            s
        }
    }
}

/// Checks a reduction of a tensor of `shape` and returns its `(outer, len, inner)` view
/// (every device's kernel reads the input that way).
pub(crate) fn reduce_plan(shape: &[usize], op: ReduceOp, axis: Option<usize>) -> Result<(usize, usize, usize)> {
    let name = match op {
        ReduceOp::Sum => "sum",
        ReduceOp::Mean => "mean",
        ReduceOp::Max => "max",
    };
    if let Some(a) = axis {
        check_axis(name, a, shape)?;
    }
    let (outer, len, inner) = match axis {
        Some(a) => split_at_axis(shape, a),
        None => (1, shape.iter().product(), 1),
    };
    if len == 0 && op != ReduceOp::Sum {
        return Err(invalid(name, format!("cannot reduce an empty axis of shape {shape:?}")));
    }
    Ok((outer, len, inner))
}

/// Reduces `x` with `op` over `axis` (or everything).
pub fn reduce<T: Float>(x: &Tensor<T>, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Tensor<T>> {
    let (outer, len, inner) = reduce_plan(x.shape(), op, axis)?;
    let out_shape = reduced_shape(x.shape(), axis, keepdim);
    let data = match (op, axis) {
        (ReduceOp::Max, _) => max_axis(x.data(), outer, len, inner),
        (_, None) => vec![sum_all(x.data())],
        (_, Some(_)) => sum_axis(x.data(), outer, len, inner),
    };
    let mut t = Tensor::from_parts(data, out_shape);
    if op == ReduceOp::Mean {
        let inv = T::ONE / T::from_f64(len as f64);
        t.data_mut().iter_mut().for_each(|v| *v *= inv);
    }
    Ok(t)
}

/// Sum of all elements: fixed-size partial sums added in order (thread-count independent).
pub fn sum_all<T: Float>(x: &[T]) -> T {
    if x.len() >= PAR_MIN {
        let partial: Vec<T> = x.par_chunks(PAR_CHUNK).map(|c| c.iter().copied().sum()).collect();
        partial.into_iter().sum()
    } else {
        x.iter().copied().sum()
    }
}

/// Rows per partial sum when a single sum over rows is split across threads.
const SUM_ROWS: usize = 256;

/// `out[o, i] = sum_k x[o, k, i]`.
pub fn sum_axis<T: Float>(x: &[T], outer: usize, len: usize, inner: usize) -> Vec<T> {
    let mut out = crate::pool::zeros(outer * inner);
    if inner == 1 {
        // Row sums: eight interleaved partial sums (a fixed order, so results do not depend on
        // the thread count) let the compiler vectorise.
        let row_sum = |row: &[T]| sum8(row.iter().copied());
        if x.len() >= PAR_MIN && len > 0 {
            out.par_iter_mut().zip(x.par_chunks(len)).for_each(|(o, row)| *o = row_sum(row));
        } else if len > 0 {
            out.iter_mut().zip(x.chunks(len)).for_each(|(o, row)| *o = row_sum(row));
        }
        return out;
    }
    let body = |o: usize, dst: &mut [T]| {
        for k in 0..len {
            let src = &x[(o * len + k) * inner..(o * len + k + 1) * inner];
            for (d, &s) in dst.iter_mut().zip(src) {
                *d += s;
            }
        }
    };
    if inner == 0 {
        return out;
    }
    if outer == 1 && x.len() >= PAR_MIN && len >= 2 * SUM_ROWS {
        // One long sum over rows (a bias gradient): fixed runs of SUM_ROWS rows summed in
        // parallel, then the partial sums added in run order; the runs depend only on the
        // shape, so the bits do not depend on the thread count.
        let partials: Vec<Vec<T>> = x
            .par_chunks(SUM_ROWS * inner)
            .map(|run| {
                let mut acc = vec![T::ZERO; inner];
                for row in run.chunks_exact(inner) {
                    acc.iter_mut().zip(row).for_each(|(a, &v)| *a += v);
                }
                acc
            })
            .collect();
        for p in &partials {
            out.iter_mut().zip(p).for_each(|(o, &v)| *o += v);
        }
        return out;
    }
    if x.len() >= PAR_MIN && outer > 1 {
        out.par_chunks_mut(inner).enumerate().for_each(|(o, d)| body(o, d));
    } else {
        out.chunks_mut(inner).enumerate().for_each(|(o, d)| body(o, d));
    }
    out
}

/// `out[o, i] = max_k x[o, k, i]`.
fn max_axis<T: Float>(x: &[T], outer: usize, len: usize, inner: usize) -> Vec<T> {
    let mut out = crate::pool::filled(outer * inner, T::neg_infinity());
    for o in 0..outer {
        let dst = &mut out[o * inner..(o + 1) * inner];
        for k in 0..len {
            let src = &x[(o * len + k) * inner..(o * len + k + 1) * inner];
            for (d, &s) in dst.iter_mut().zip(src) {
                if s > *d {
                    *d = s;
                }
            }
        }
    }
    out
}

/// Gradient of a max reduction: `g` goes to the first position that attains the maximum.
pub fn max_backward<T: Float>(x: &[T], y: &[T], g: &[T], outer: usize, len: usize, inner: usize) -> Vec<T> {
    let mut dx = crate::pool::zeros(x.len());
    for o in 0..outer {
        for i in 0..inner {
            let target = y[o * inner + i];
            for k in 0..len {
                let p = (o * len + k) * inner + i;
                if x[p] == target {
                    dx[p] = g[o * inner + i];
                    break;
                }
            }
        }
    }
    dx
}

/// Sums `g` (shaped like a broadcast result) back to `target`, the shape of a broadcast
/// operand: over leading dims `target` lacks, and over dims where `target` has 1.
pub fn sum_to_shape<T: Float>(g: Tensor<T>, target: &[usize]) -> Tensor<T> {
    if g.shape() == target {
        return g;
    }
    let lead = g.rank() - target.len();
    let mut cur = g;
    // Leading dims: view as [outer, rest] and sum the outer block.
    if lead > 0 {
        let outer: usize = cur.shape()[..lead].iter().product();
        let rest = cur.numel() / outer.max(1);
        let data = sum_axis(cur.data(), 1, outer, rest);
        cur = Tensor::from_parts(data, cur.shape()[lead..].to_vec());
    }
    for (d, &t) in target.iter().enumerate() {
        if t == 1 && cur.shape()[d] != 1 {
            let (outer, len, inner) = split_at_axis(cur.shape(), d);
            let data = sum_axis(cur.data(), outer, len, inner);
            let mut s = cur.shape().to_vec();
            s[d] = 1;
            cur = Tensor::from_parts(data, s);
        }
    }
    cur
}

/// Sum with eight interleaved partial sums combined in a fixed order: vectorisable, and the
/// same bits whatever the thread count (the order depends only on the length).
#[inline(always)]
pub(crate) fn sum8<T: Float>(values: impl ExactSizeIterator<Item = T>) -> T {
    let mut acc = [T::ZERO; 8];
    let mut it = values;
    let full = it.len() / 8;
    for _ in 0..full {
        for a in acc.iter_mut() {
            *a += it.next().expect("length checked");
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for v in it {
        s += v;
    }
    s
}

/// Gradient of a reduction of `x` (as `[outer, len, inner]`, output `y`) given `g`: a sum
/// or mean spreads `g` (times `1/len`) over the reduced axis, a max sends it to the first
/// maximal entry.
pub(crate) fn reduce_backward<T: Float>(
    x: &[T],
    y: &[T],
    g: &[T],
    op: ReduceOp,
    outer: usize,
    len: usize,
    inner: usize,
) -> Vec<T> {
    match op {
        ReduceOp::Max => max_backward(x, y, g, outer, len, inner),
        ReduceOp::Sum | ReduceOp::Mean => {
            let s = if op == ReduceOp::Mean { T::ONE / T::from_f64(len as f64) } else { T::ONE };
            let mut dx = crate::pool::for_overwrite(x.len());
            for o in 0..outer {
                let gr = &g[o * inner..(o + 1) * inner];
                for k in 0..len {
                    let d = &mut dx[(o * len + k) * inner..(o * len + k + 1) * inner];
                    d.iter_mut().zip(gr).for_each(|(d, &gv)| *d = gv * s);
                }
            }
            dx
        }
    }
}
