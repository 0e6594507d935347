//! Layout kernels: permute, narrow (and its adjoint, pad), concatenate, expand.

use crate::element::Float;
use crate::error::{Result, TensorError, check_axis, invalid, mismatch};
use crate::shape::{broadcast_shapes, broadcast_strides, for_each_run2, numel, split_at_axis, strides};
use crate::tensor::Tensor;
use rayon::prelude::*;

/// Reorders the axes: output axis `i` is input axis `perm[i]` (copies into row-major order).
pub fn permute<T: Float>(x: &Tensor<T>, perm: &[usize]) -> Result<Tensor<T>> {
    let shape = permuted_shape(x.shape(), perm)?;
    let st = strides(x.shape());
    let src_strides: Vec<usize> = perm.iter().map(|&p| st[p]).collect();
    let mut out = crate::pool::for_overwrite(x.numel());
    copy_strided(&mut out, &shape, &src_strides, x.data());
    Ok(Tensor::from_parts(out, shape))
}

/// `out[i] = src[offset(i)]` for every row-major index `i` of `shape`, where `offset` walks
/// `src` with the strides `strides` (one per axis, 0 for a broadcast axis). Large outputs are
/// copied in parallel, in blocks of whole indices of the first axis; every element is a copy,
/// so the bits cannot depend on the split or the thread count.
fn copy_strided<T: Float>(out: &mut [T], shape: &[usize], strides: &[usize], src: &[T]) {
    let zero = vec![0; shape.len()];
    let copy = |out: &mut [T], shape: &[usize], base: usize| {
        for_each_run2(shape, strides, &zero, |o, oa, _, len, da, _| {
            let (dst, start) = (&mut out[o..o + len], base + oa);
            if da == 1 {
                dst.copy_from_slice(&src[start..start + len]);
            } else {
                dst.iter_mut().enumerate().for_each(|(k, d)| *d = src[start + k * da]);
            }
        });
    };
    if shape.is_empty() || shape[0] < 2 || out.len() < super::PAR_MIN {
        copy(out, shape, 0);
        return;
    }
    // Elements per index of the first axis, and indices per block (at least PAR_CHUNK
    // elements a block).
    let per = out.len() / shape[0];
    let rows = super::PAR_CHUNK.div_ceil(per);
    out.par_chunks_mut(rows * per).enumerate().for_each(|(b, block)| {
        let mut sub = shape.to_vec();
        sub[0] = block.len() / per;
        copy(block, &sub, b * rows * strides[0]);
    });
}

/// The shape after permuting the axes of `shape` by `perm`; fails if `perm` is not a
/// permutation of its axes.
pub(crate) fn permuted_shape(shape: &[usize], perm: &[usize]) -> Result<Vec<usize>> {
    let r = shape.len();
    let mut seen = vec![false; r];
    if perm.len() != r || perm.iter().any(|&p| p >= r || std::mem::replace(&mut seen[p], true)) {
        return Err(invalid("permute", format!("{perm:?} is not a permutation of the {r} axes of shape {shape:?}")));
    }
    Ok(perm.iter().map(|&p| shape[p]).collect())
}

/// The inverse permutation of `perm`.
pub fn inverse_permutation(perm: &[usize]) -> Vec<usize> {
    let mut inv = vec![0; perm.len()];
    for (i, &p) in perm.iter().enumerate() {
        inv[p] = i;
    }
    inv
}

/// Entries `start..start+len` of `axis`.
pub fn narrow<T: Float>(x: &Tensor<T>, axis: usize, start: usize, len: usize) -> Result<Tensor<T>> {
    check_narrow(x.shape(), axis, start, len)?;
    let (outer, n, inner) = split_at_axis(x.shape(), axis);
    let mut out = crate::pool::with_capacity(outer * len * inner);
    let xd = x.data();
    for o in 0..outer {
        out.extend_from_slice(&xd[(o * n + start) * inner..(o * n + start + len) * inner]);
    }
    let mut shape = x.shape().to_vec();
    shape[axis] = len;
    Ok(Tensor::from_parts(out, shape))
}

/// Checks that entries `start..start+len` of `axis` exist in `shape`.
pub(crate) fn check_narrow(shape: &[usize], axis: usize, start: usize, len: usize) -> Result<()> {
    check_axis("narrow", axis, shape)?;
    if start.checked_add(len).is_none_or(|end| end > shape[axis]) {
        return Err(invalid(
            "narrow",
            format!("range {start}..{} is past the end of axis {axis} of shape {shape:?}", start.saturating_add(len)),
        ));
    }
    Ok(())
}

/// Adds `g` (the gradient of a narrow) into `dst` (shaped like the narrowed input).
pub fn narrow_backward_into<T: Float>(dst: &mut [T], dst_shape: &[usize], g: &[T], axis: usize, start: usize) {
    let (outer, n, inner) = split_at_axis(dst_shape, axis);
    let len = g.len() / (outer * inner).max(1);
    for o in 0..outer {
        let d = &mut dst[(o * n + start) * inner..(o * n + start + len) * inner];
        for (a, &b) in d.iter_mut().zip(&g[o * len * inner..(o + 1) * len * inner]) {
            *a += b;
        }
    }
}

/// Adds entries `start..start+len` of `axis` of `src` (shape `src_shape`) into `dst`, which
/// has `len` entries on that axis (the adjoint of concatenation), or with `accumulate` false
/// writes them over it (every element of `dst` is written).
pub fn narrow_add_into<T: Float>(
    dst: &mut [T],
    accumulate: bool,
    src: &[T],
    src_shape: &[usize],
    axis: usize,
    start: usize,
    len: usize,
) {
    let (outer, n, inner) = split_at_axis(src_shape, axis);
    for o in 0..outer {
        let s = &src[(o * n + start) * inner..(o * n + start + len) * inner];
        let d = &mut dst[o * len * inner..(o + 1) * len * inner];
        if accumulate {
            d.iter_mut().zip(s).for_each(|(a, &b)| *a += b);
        } else {
            d.copy_from_slice(s);
        }
    }
}

/// Concatenates along `axis`; all other dims must agree.
pub fn cat<T: Float>(xs: &[&Tensor<T>], axis: usize) -> Result<Tensor<T>> {
    let shape = cat_shape(xs, axis)?;
    let first = xs[0];
    let (outer, _, inner) = split_at_axis(first.shape(), axis);
    let total: usize = xs.iter().map(|x| x.shape()[axis]).sum();
    let mut out = crate::pool::with_capacity(outer * total * inner);
    for o in 0..outer {
        for x in xs {
            let l = x.shape()[axis] * inner;
            out.extend_from_slice(&x.data()[o * l..(o + 1) * l]);
        }
    }
    Ok(Tensor::from_parts(out, shape))
}

/// The shape of the concatenation of `xs` along `axis`; fails unless every other dim agrees.
pub(crate) fn cat_shape<T: Float>(xs: &[&Tensor<T>], axis: usize) -> Result<Vec<usize>> {
    let first = xs.first().ok_or_else(|| invalid("cat", "needs at least one tensor"))?;
    check_axis("cat", axis, first.shape())?;
    for x in xs {
        let ok = x.rank() == first.rank()
            && x.shape().iter().zip(first.shape()).enumerate().all(|(d, (a, b))| d == axis || a == b);
        if !ok {
            return Err(mismatch("cat", &[first.shape(), x.shape()], format!("all dims but axis {axis} must agree")));
        }
    }
    let mut shape = first.shape().to_vec();
    shape[axis] = xs.iter().map(|x| x.shape()[axis]).sum();
    Ok(shape)
}

/// Checks that `from` broadcasts to exactly `to`.
pub(crate) fn check_expand(from: &[usize], to: &[usize]) -> Result<()> {
    let b = broadcast_shapes("expand", from, to)?;
    if b != to {
        return Err(TensorError::ShapeMismatch {
            op: "expand",
            shapes: vec![from.to_vec(), to.to_vec()],
            detail: "the first shape does not broadcast to the second".into(),
        });
    }
    Ok(())
}

/// Broadcasts `x` to `shape` (copies).
pub fn expand<T: Float>(x: &Tensor<T>, shape: &[usize]) -> Result<Tensor<T>> {
    check_expand(x.shape(), shape)?;
    let sx = broadcast_strides(x.shape(), shape);
    let mut out = crate::pool::for_overwrite(numel(shape));
    copy_strided(&mut out, shape, &sx, x.data());
    Ok(Tensor::from_parts(out, shape.to_vec()))
}
