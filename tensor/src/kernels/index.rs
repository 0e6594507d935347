//! Index kernels: select, add at indices (duplicates accumulate), gather, segment sums.

use crate::element::Float;
use crate::error::{Result, TensorError, check_axis, invalid, mismatch};
use crate::shape::split_at_axis;
use crate::tensor::Tensor;

/// Checks every index is below `len`.
pub(crate) fn check_indices(op: &'static str, idx: &[usize], len: usize) -> Result<()> {
    match idx.iter().find(|&&i| i >= len) {
        Some(&index) => Err(TensorError::IndexOutOfRange { op, index, len }),
        None => Ok(()),
    }
}

/// `out[.., j, ..] = x[.., idx[j], ..]` along `axis`.
pub fn index_select<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize]) -> Result<Tensor<T>> {
    check_axis("index_select", axis, x.shape())?;
    let (outer, n, inner) = split_at_axis(x.shape(), axis);
    check_indices("index_select", idx, n)?;
    let xd = x.data();
    let mut out = crate::pool::with_capacity(outer * idx.len() * inner);
    for o in 0..outer {
        for &i in idx {
            out.extend_from_slice(&xd[(o * n + i) * inner..(o * n + i + 1) * inner]);
        }
    }
    let mut shape = x.shape().to_vec();
    shape[axis] = idx.len();
    Ok(Tensor::from_parts(out, shape))
}

/// `dst[.., idx[j], ..] += src[.., j, ..]` along `axis`; `dst` has `n` entries on `axis`.
pub fn index_add_into<T: Float>(
    dst: &mut [T],
    n: usize,
    src: &[T],
    axis_len: usize,
    outer: usize,
    inner: usize,
    idx: &[usize],
) {
    debug_assert_eq!(idx.len(), axis_len);
    for o in 0..outer {
        for (j, &i) in idx.iter().enumerate() {
            let d = &mut dst[(o * n + i) * inner..(o * n + i + 1) * inner];
            let s = &src[(o * axis_len + j) * inner..(o * axis_len + j + 1) * inner];
            for (a, &b) in d.iter_mut().zip(s) {
                *a += b;
            }
        }
    }
}

/// Validates an index_add: `src` matches `x` except along `axis`, where it has `idx.len()`.
pub fn check_index_add(x: &[usize], src: &[usize], axis: usize, idx: &[usize]) -> Result<()> {
    check_axis("index_add", axis, x)?;
    let ok = x.len() == src.len()
        && src.get(axis) == Some(&idx.len())
        && x.iter().zip(src).enumerate().all(|(d, (a, b))| d == axis || a == b);
    if !ok {
        return Err(mismatch(
            "index_add",
            &[x, src],
            format!(
                "src must match the target except along axis {axis}, where it needs {} entries (one per index)",
                idx.len()
            ),
        ));
    }
    check_indices("index_add", idx, x[axis])
}

/// Validates a gather: `idx` has the output's element count, with the input's shape except
/// along `axis`; returns the output shape.
pub fn gather_shape(x: &[usize], axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<()> {
    check_axis("gather", axis, x)?;
    let ok = idx_shape.len() == x.len() && x.iter().zip(idx_shape).enumerate().all(|(d, (a, b))| d == axis || a == b);
    if !ok {
        return Err(mismatch(
            "gather",
            &[x, idx_shape],
            format!("index shape must match the input except along axis {axis}"),
        ));
    }
    if idx.len() != idx_shape.iter().product::<usize>() {
        return Err(invalid("gather", format!("{} indices given for an index shape {idx_shape:?}", idx.len())));
    }
    check_indices("gather", idx, x[axis])
}

/// `out[o, j, i] = x[o, idx[o, j, i], i]`.
pub fn gather<T: Float>(x: &Tensor<T>, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Tensor<T>> {
    gather_shape(x.shape(), axis, idx_shape, idx)?;
    let (outer, n, inner) = split_at_axis(x.shape(), axis);
    let m = idx_shape[axis];
    let xd = x.data();
    let mut out = crate::pool::for_overwrite(idx.len());
    for o in 0..outer {
        for j in 0..m {
            for i in 0..inner {
                let p = (o * m + j) * inner + i;
                out[p] = xd[(o * n + idx[p]) * inner + i];
            }
        }
    }
    Ok(Tensor::from_parts(out, idx_shape.to_vec()))
}

/// Adjoint of [`gather`]: `dst[o, idx[o, j, i], i] += g[o, j, i]`.
pub fn gather_backward_into<T: Float>(dst: &mut [T], x_shape: &[usize], axis: usize, g: &[T], idx: &[usize]) {
    let (outer, n, inner) = split_at_axis(x_shape, axis);
    let m = g.len() / (outer * inner).max(1);
    for o in 0..outer {
        for j in 0..m {
            for i in 0..inner {
                let p = (o * m + j) * inner + i;
                dst[(o * n + idx[p]) * inner + i] += g[p];
            }
        }
    }
}

/// Validates sorted segment ids for `rows` rows and `num_segments` segments.
pub fn check_segments(seg: &[usize], rows: usize, num_segments: usize) -> Result<()> {
    if seg.len() != rows {
        return Err(invalid("segment_sum", format!("{} segment ids for {rows} rows", seg.len())));
    }
    if seg.windows(2).any(|w| w[0] > w[1]) {
        return Err(invalid("segment_sum", "segment ids must be sorted (non-decreasing)"));
    }
    check_indices("segment_sum", seg, num_segments)
}

/// Row sums (or means, 0 for empty segments) grouped by sorted segment id along axis 0.
pub fn segment_reduce<T: Float>(x: &Tensor<T>, seg: &[usize], num_segments: usize, mean: bool) -> Result<Tensor<T>> {
    if x.rank() == 0 {
        return Err(invalid("segment_sum", "needs at least one dim"));
    }
    check_segments(seg, x.shape()[0], num_segments)?;
    let inner = x.numel() / x.shape()[0].max(1);
    let mut out = crate::pool::zeros(num_segments * inner);
    index_add_into(&mut out, num_segments, x.data(), seg.len(), 1, inner, seg);
    if mean {
        let counts = segment_counts(seg, num_segments);
        for (s, &c) in counts.iter().enumerate() {
            if c > 0 {
                let inv = T::ONE / T::from_f64(c as f64);
                out[s * inner..(s + 1) * inner].iter_mut().for_each(|v| *v *= inv);
            }
        }
    }
    let mut shape = x.shape().to_vec();
    shape[0] = num_segments;
    Ok(Tensor::from_parts(out, shape))
}

/// Number of rows in each segment.
pub fn segment_counts(seg: &[usize], num_segments: usize) -> Vec<usize> {
    let mut c = vec![0; num_segments];
    for &s in seg {
        c[s] += 1;
    }
    c
}

/// Gradient of [`segment_reduce`]: row `r` of `dx` is `g[seg[r]]`, divided by the segment's
/// row count for a mean (`g` has `num_segments` rows of `inner` values).
pub fn segment_backward<T: Float>(g: &[T], seg: &[usize], num_segments: usize, inner: usize, mean: bool) -> Vec<T> {
    let counts = if mean { segment_counts(seg, num_segments) } else { vec![] };
    let mut dx = crate::pool::for_overwrite(seg.len() * inner);
    for (r, &s) in seg.iter().enumerate() {
        let scale = if mean { T::ONE / T::from_f64(counts[s] as f64) } else { T::ONE };
        let src = &g[s * inner..(s + 1) * inner];
        dx[r * inner..(r + 1) * inner].iter_mut().zip(src).for_each(|(d, &v)| *d = v * scale);
    }
    dx
}
