//! Element-wise kernels: unary maps and broadcasting binary maps.

use super::fill_chunks;
use crate::element::Float;
use crate::error::Result;
use crate::op::{BinaryOp, UnaryOp};
use crate::shape::{broadcast_shapes, broadcast_strides, for_each_run2, numel};
use crate::tensor::Tensor;

/// `y = op(x)` element-wise.
pub fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
    let xd = x.data();
    let mut out = vec![T::ZERO; xd.len()];
    fill_chunks(&mut out, |start, ch| {
        let n = ch.len();
        for (o, &v) in ch.iter_mut().zip(&xd[start..start + n]) {
            *o = op.apply(v);
        }
    });
    Tensor::from_parts(out, x.shape().to_vec())
}

/// `g * dy/dx` element-wise, the backward of [`unary`].
pub fn unary_backward<T: Float>(g: &[T], x: &[T], y: &[T], op: UnaryOp) -> Vec<T> {
    let mut out = vec![T::ZERO; g.len()];
    fill_chunks(&mut out, |s, ch| {
        let n = ch.len();
        for (((o, &gi), &xi), &yi) in ch.iter_mut().zip(&g[s..s + n]).zip(&x[s..s + n]).zip(&y[s..s + n]) {
            *o = gi * op.derivative(xi, yi);
        }
    });
    out
}

/// `op(a, b)` with NumPy broadcasting.
pub fn binary<T: Float>(a: &Tensor<T>, b: &Tensor<T>, op: BinaryOp) -> Result<Tensor<T>> {
    let shape =
        if a.shape() == b.shape() { a.shape().to_vec() } else { broadcast_shapes(op.name(), a.shape(), b.shape())? };
    let out = binary_into_shape(a.data(), a.shape(), b.data(), b.shape(), &shape, |x, y| op.apply(x, y));
    Ok(Tensor::from_parts(out, shape))
}

/// Evaluates `f(a, b)` over the broadcast `shape`, with fast paths for equal shapes and for
/// a right operand that repeats along leading dims (bias rows, scalars).
pub(crate) fn binary_into_shape<T: Float>(
    a: &[T],
    a_shape: &[usize],
    b: &[T],
    b_shape: &[usize],
    shape: &[usize],
    f: impl Fn(T, T) -> T + Sync,
) -> Vec<T> {
    let n = numel(shape);
    let mut out = vec![T::ZERO; n];
    if a.len() == n && b.len() == n {
        fill_chunks(&mut out, |s, ch| {
            let n = ch.len();
            for ((o, &x), &y) in ch.iter_mut().zip(&a[s..s + n]).zip(&b[s..s + n]) {
                *o = f(x, y);
            }
        });
        return out;
    }
    if a.len() == n && b.len() == 1 {
        let y = b[0];
        fill_chunks(&mut out, |s, ch| {
            let n = ch.len();
            for (o, &x) in ch.iter_mut().zip(&a[s..s + n]) {
                *o = f(x, y);
            }
        });
        return out;
    }
    if a.len() == n && !b.is_empty() && is_suffix(b_shape, shape) {
        // b repeats every b.len() elements (e.g. a bias row).
        let m = b.len();
        super::for_rows(&mut out, m, |r, row| {
            let ar = &a[r * m..(r + 1) * m];
            for ((o, &x), &y) in row.iter_mut().zip(ar).zip(b) {
                *o = f(x, y);
            }
        });
        return out;
    }
    let sa = broadcast_strides(a_shape, shape);
    let sb = broadcast_strides(b_shape, shape);
    for_each_run2(shape, &sa, &sb, |o, oa, ob, len, da, db| {
        for k in 0..len {
            out[o + k] = f(a[oa + k * da], b[ob + k * db]);
        }
    });
    out
}

/// Whether `small` equals the trailing dims of `big` once leading 1s are dropped.
fn is_suffix(small: &[usize], big: &[usize]) -> bool {
    let s: Vec<usize> = small.iter().copied().skip_while(|&d| d == 1).collect();
    s.len() <= big.len() && big[big.len() - s.len()..] == s[..]
}

/// `mask ? a : b` with `a` and `b` broadcast to the mask's shape.
pub fn where_select<T: Float>(mask: &[bool], shape: &[usize], a: &Tensor<T>, b: &Tensor<T>) -> Vec<T> {
    let n = numel(shape);
    let sa = broadcast_strides(a.shape(), shape);
    let sb = broadcast_strides(b.shape(), shape);
    let (ad, bd) = (a.data(), b.data());
    let mut out = vec![T::ZERO; n];
    for_each_run2(shape, &sa, &sb, |o, oa, ob, len, da, db| {
        for k in 0..len {
            out[o + k] = if mask[o + k] { ad[oa + k * da] } else { bd[ob + k * db] };
        }
    });
    out
}
