//! Element-wise kernels: unary maps and broadcasting binary maps.

use super::fill_chunks;
use crate::element::Float;
use crate::error::Result;
use crate::op::{BinaryOp, UnaryOp};
use crate::pool;
use crate::shape::{broadcast_shapes, broadcast_strides, for_each_run2, numel};
use crate::tensor::Tensor;

/// `y = op(x)` element-wise.
pub fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
    let xd = x.data();
    let mut out = crate::pool::for_overwrite(xd.len());
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
    let mut out = crate::pool::for_overwrite(g.len());
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
    let mut out = crate::pool::for_overwrite(n);
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
    if a.len() == n && !b.is_empty() && is_prefix(b_shape, shape) {
        // b holds one value per row of n / b.len() elements (e.g. a per-row scale [R, 1]).
        let m = n / b.len();
        super::for_rows(&mut out, m, |r, row| {
            let y = b[r];
            for (o, &x) in row.iter_mut().zip(&a[r * m..(r + 1) * m]) {
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

/// Whether a tensor of shape `small` holds one value per row of the broadcast shape `big`
/// (same rank, equal leading dims, 1 after them, and at least one trailing 1).
pub(crate) fn is_row_broadcast(small: &[usize], big: &[usize]) -> bool {
    is_prefix(small, big) && small != big && !small.is_empty()
}

/// Gradients of `y = a * b` (or `a / b`) where `b` has one value per row of `a`:
/// `ga = g b` (or `g / b`), `gb[r] = sum_row(g a)` (or `-sum_row(g a) / b^2`).
pub(crate) fn row_scale_backward<T: Float>(
    g: &[T],
    a: &[T],
    b: &[T],
    div: bool,
    wa: bool,
    wb: bool,
) -> (Option<Vec<T>>, Option<Vec<T>>) {
    let m = a.len() / b.len().max(1);
    let ga = wa.then(|| {
        let mut out = crate::pool::for_overwrite(g.len());
        super::for_rows(&mut out, m, |r, row| {
            let s = if div { T::ONE / b[r] } else { b[r] };
            for (o, &gv) in row.iter_mut().zip(&g[r * m..(r + 1) * m]) {
                *o = gv * s;
            }
        });
        out
    });
    let gb = wb.then(|| {
        let mut out = crate::pool::for_overwrite(b.len());
        super::fill_chunks(&mut out, |start, ch| {
            for (i, o) in ch.iter_mut().enumerate() {
                let r = start + i;
                let mut acc = [T::ZERO; 8];
                let (gr, ar) = (&g[r * m..(r + 1) * m], &a[r * m..(r + 1) * m]);
                let (cg, ca) = (gr.chunks_exact(8), ar.chunks_exact(8));
                let (rg, ra) = (cg.remainder(), ca.remainder());
                for (x, y) in cg.zip(ca) {
                    for l in 0..8 {
                        acc[l] += x[l] * y[l];
                    }
                }
                let mut sum = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
                for (&x, &y) in rg.iter().zip(ra) {
                    sum += x * y;
                }
                *o = if div { -sum / (b[r] * b[r]) } else { sum };
            }
        });
        out
    });
    (ga, gb)
}

/// Whether `small` has the rank of `big`, equals its leading dims and is 1 after them.
fn is_prefix(small: &[usize], big: &[usize]) -> bool {
    if small.len() != big.len() {
        return false;
    }
    let k = small.iter().rposition(|&d| d != 1).map_or(0, |i| i + 1);
    small[..k] == big[..k]
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
    let mut out = crate::pool::for_overwrite(n);
    for_each_run2(shape, &sa, &sb, |o, oa, ob, len, da, db| {
        for k in 0..len {
            out[o + k] = if mask[o + k] { ad[oa + k * da] } else { bd[ob + k * db] };
        }
    });
    out
}

/// The gradients `(dA, dB)` of a broadcasting binary op with output `y` and output gradient
/// `g`, summed back to the operands' shapes; each only when wanted (`wants`).
#[allow(clippy::type_complexity)]
pub fn binary_backward<T: Float>(
    g: &[T],
    av: &Tensor<T>,
    bv: &Tensor<T>,
    y: &Tensor<T>,
    op: BinaryOp,
    wants: (bool, bool),
) -> (Option<Vec<T>>, Option<Vec<T>>) {
    let shape = y.shape();
    let with = |other: &Tensor<T>, mul: bool| {
        let (o, os) = (other.data(), other.shape());
        if mul {
            binary_into_shape(g, shape, o, os, shape, |gv, ov| gv * ov)
        } else {
            binary_into_shape(g, shape, o, os, shape, |gv, ov| gv / ov)
        }
    };
    let (wa, wb) = wants;
    if matches!(op, BinaryOp::Div | BinaryOp::Mul) && av.numel() == y.numel() && is_row_broadcast(bv.shape(), shape) {
        // `a` scaled by one value of `b` per row (e.g. c / (||G|| + 1)): both gradients in
        // one pass, without broadcast temporaries.
        return row_scale_backward(g, av.data(), bv.data(), op == BinaryOp::Div, wa, wb);
    }
    let (ga, gb): (Option<Vec<T>>, Option<Vec<T>>) = match op {
        BinaryOp::Add => (wa.then(|| pool::map(g, |v| v)), wb.then(|| pool::map(g, |v| v))),
        BinaryOp::Sub => (wa.then(|| pool::map(g, |v| v)), wb.then(|| pool::map(g, |v| -v))),
        BinaryOp::Mul => (wa.then(|| with(bv, true)), wb.then(|| with(av, true))),
        BinaryOp::Div => {
            let ga = wa.then(|| with(bv, false));
            let gb = wb.then(|| {
                // d(a/b)/db = -y / b
                let gy = pool::zip_map(g, y.data(), |gv, yv| gv * yv);
                let gb = binary_into_shape(&gy, shape, bv.data(), bv.shape(), shape, |t, bv| -t / bv);
                pool::recycle(gy);
                gb
            });
            (ga, gb)
        }
        BinaryOp::Minimum | BinaryOp::Maximum => {
            let pick_a = |x: T, z: T| {
                let chosen = if op == BinaryOp::Minimum { x <= z } else { x >= z };
                if chosen { T::ONE } else { T::ZERO }
            };
            let mask = binary_into_shape(av.data(), av.shape(), bv.data(), bv.shape(), shape, pick_a);
            let ga = wa.then(|| pool::zip_map(g, &mask, |gv, m| gv * m));
            let gb = wb.then(|| pool::zip_map(g, &mask, |gv, m| gv * (T::ONE - m)));
            pool::recycle(mask);
            (ga, gb)
        }
    };
    let back = |grad: Option<Vec<T>>, v: &Tensor<T>| {
        grad.map(|grad| super::reduce::sum_to_shape(Tensor::from_parts(grad, shape.to_vec()), v.shape()).into_vec())
    };
    (back(ga, av), back(gb, bv))
}
