//! The CPU backend: the reference implementation of [`Backend`], over the kernels of
//! `kernels/` (f32 and f64, parallel through rayon, the same bits whatever the thread count).

use std::sync::Arc;

use super::{AdamStep, Backend, Block, GradPair, Slot};
use crate::element::Float;
use crate::error::Result;
use crate::kernels::matmul::{self, MatMulPlan};
use crate::kernels::nnops::{self, WeightRows};
use crate::kernels::{elementwise, index, layout, reduce};
use crate::op::{Activation, BinaryOp, ReduceOp, UnaryOp};
use crate::pool;
use crate::tensor::Tensor;

/// The host device.
pub(crate) struct Cpu;

/// The slot's host values, zero-initialised on first use.
fn zeroed<T: Float>(slot: &mut Slot<T>, len: usize) -> &mut [T] {
    slot.get_or_insert_with(|| Tensor::from_parts(pool::zeros(len), vec![len])).data_mut()
}

/// The slot's host values for a kernel that writes every element, and whether it must add to
/// them: `false` on first use, when the values are unspecified and overwritten.
fn to_write<T: Float>(slot: &mut Slot<T>, len: usize) -> (&mut [T], bool) {
    let accumulate = slot.is_some();
    (slot.get_or_insert_with(|| Tensor::from_parts(pool::for_overwrite(len), vec![len])).data_mut(), accumulate)
}

impl Backend for Cpu {
    fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
        elementwise::unary(x, op)
    }

    fn unary_backward<T: Float>(g: &Tensor<T>, x: &Tensor<T>, y: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
        Tensor::from_parts(elementwise::unary_backward(g.data(), x.data(), y.data(), op), g.shape().to_vec())
    }

    fn activation_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>, act: Activation) -> Tensor<T> {
        Tensor::from_parts(nnops::activation_backward(y.data(), g.data(), act), g.shape().to_vec())
    }

    fn binary<T: Float>(a: &Tensor<T>, b: &Tensor<T>, shape: &[usize], op: BinaryOp) -> Result<Tensor<T>> {
        let out =
            elementwise::binary_into_shape(a.data(), a.shape(), b.data(), b.shape(), shape, |x, y| op.apply(x, y));
        Ok(Tensor::from_parts(out, shape.to_vec()))
    }

    fn binary_backward<T: Float>(
        g: &Tensor<T>,
        a: &Tensor<T>,
        b: &Tensor<T>,
        y: &Tensor<T>,
        op: BinaryOp,
        wants: (bool, bool),
    ) -> Result<GradPair<T>> {
        let (ga, gb) = elementwise::binary_backward(g.data(), a, b, y, op, wants);
        Ok((
            ga.map(|v| Tensor::from_parts(v, a.shape().to_vec())),
            gb.map(|v| Tensor::from_parts(v, b.shape().to_vec())),
        ))
    }

    fn where_select<T: Float>(
        mask: &Arc<Vec<bool>>,
        shape: &[usize],
        a: &Tensor<T>,
        b: &Tensor<T>,
    ) -> Result<Tensor<T>> {
        Tensor::new(elementwise::where_select(mask, shape, a, b), shape)
    }

    fn reduce<T: Float>(x: &Tensor<T>, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Tensor<T>> {
        reduce::reduce(x, op, axis, keepdim)
    }

    fn sum_to_shape<T: Float>(g: &Tensor<T>, target: &[usize]) -> Result<Tensor<T>> {
        Ok(reduce::sum_to_shape(g.clone(), target))
    }

    fn reduce_backward<T: Float>(
        x: &Tensor<T>,
        y: &Tensor<T>,
        g: &Tensor<T>,
        op: ReduceOp,
        (outer, len, inner): (usize, usize, usize),
    ) -> Result<Tensor<T>> {
        Tensor::new(reduce::reduce_backward(x.data(), y.data(), g.data(), op, outer, len, inner), x.shape())
    }

    fn matmul<T: Float>(a: &Tensor<T>, b: &Tensor<T>, ta: bool, tb: bool, _plan: &MatMulPlan) -> Result<Tensor<T>> {
        matmul::matmul(a, b, ta, tb)
    }

    fn linear_sum<T: Float>(
        parts: &[WeightRows<'_, T>],
        b: Option<&Tensor<T>>,
        act: Activation,
        cols: Option<(usize, usize)>,
    ) -> Result<Tensor<T>> {
        match cols {
            // Some of the outputs: the weights' and bias's columns copied out first (the
            // products then have the bits of a layer of those columns alone).
            Some((start, len)) if len != parts[0].1.shape()[1] => {
                let ws: Vec<Tensor<T>> =
                    parts.iter().map(|&(_, w, _)| layout::narrow(w, 1, start, len)).collect::<Result<_>>()?;
                let b = b.map(|b| layout::narrow(b, 0, start, len)).transpose()?;
                let terms: Vec<WeightRows<'_, T>> =
                    parts.iter().zip(&ws).map(|(&(x, _, row), w)| (x, w, row)).collect();
                nnops::linear_sum_rows(&terms, b.as_ref(), act)
            }
            _ => nnops::linear_sum_rows(parts, b, act),
        }
    }

    fn permute<T: Float>(x: &Tensor<T>, perm: &[usize]) -> Result<Tensor<T>> {
        layout::permute(x, perm)
    }

    fn expand<T: Float>(x: &Tensor<T>, shape: &[usize]) -> Result<Tensor<T>> {
        layout::expand(x, shape)
    }

    fn narrow<T: Float>(x: &Tensor<T>, axis: usize, start: usize, len: usize) -> Result<Tensor<T>> {
        layout::narrow(x, axis, start, len)
    }

    fn cat<T: Float>(xs: &[&Tensor<T>], axis: usize, _shape: &[usize]) -> Result<Tensor<T>> {
        layout::cat(xs, axis)
    }

    fn index_select<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize]) -> Result<Tensor<T>> {
        index::index_select(x, axis, idx)
    }

    fn index_add<T: Float>(
        x: &Tensor<T>,
        (outer, n, inner): (usize, usize, usize),
        idx: &[usize],
        src: &Tensor<T>,
    ) -> Result<Tensor<T>> {
        let mut out = x.to_vec();
        index::index_add_into(&mut out, n, src.data(), idx.len(), outer, inner, idx);
        Tensor::new(out, x.shape())
    }

    fn gather<T: Float>(x: &Tensor<T>, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Tensor<T>> {
        index::gather(x, axis, idx_shape, idx)
    }

    fn segment_reduce<T: Float>(x: &Tensor<T>, seg: &[usize], n: usize, mean: bool) -> Result<Tensor<T>> {
        index::segment_reduce(x, seg, n, mean)
    }

    fn segment_backward<T: Float>(x_shape: &[usize], g: &Tensor<T>, seg: &[usize], mean: bool) -> Result<Tensor<T>> {
        let inner = crate::shape::numel(x_shape) / x_shape[0].max(1);
        Tensor::new(index::segment_backward(g.data(), seg, g.shape()[0], inner, mean), x_shape)
    }

    fn softmax<T: Float>(x: &Tensor<T>) -> Tensor<T> {
        nnops::softmax(x)
    }

    fn softmax_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>) -> Tensor<T> {
        let n = y.shape().last().copied().unwrap_or(1);
        Tensor::from_parts(nnops::softmax_backward(y.data(), g.data(), n), y.shape().to_vec())
    }

    fn zeros<T: Float>(shape: &[usize]) -> Tensor<T> {
        Tensor::zeros(shape)
    }

    fn gaussian_basis<T: Float>(x: &[f64], centres: &[f64], coeff: f64) -> Result<Tensor<T>> {
        let mut out = pool::with_capacity(x.len() * centres.len());
        for &xe in x {
            out.extend(centres.iter().map(|&c| {
                let y = xe - c;
                T::from_f64((coeff * y * y).exp())
            }));
        }
        Tensor::new(out, &[x.len(), centres.len()])
    }

    fn norm_last<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
        nnops::norm_last(x, eps)
    }

    fn norm_last_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>) -> Tensor<T> {
        let n = x.shape().last().copied().unwrap_or(1);
        Tensor::from_parts(nnops::norm_last_backward(x.data(), y.data(), g.data(), n), x.shape().to_vec())
    }

    fn standardize<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
        nnops::standardize(x, eps)
    }

    fn standardize_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>, eps: f64) -> Tensor<T> {
        let n = x.shape().last().copied().unwrap_or(1);
        Tensor::from_parts(nnops::standardize_backward(x.data(), y.data(), g.data(), n, eps), x.shape().to_vec())
    }

    fn accumulate<T: Float>(slot: &mut Slot<T>, t: Tensor<T>) {
        match slot {
            // Read in place (`t` may share its storage: an add's gradient passed on to both
            // inputs); its buffer goes back to the pool when the last owner drops.
            Some(held) => held.data_mut().iter_mut().zip(t.data()).for_each(|(a, &b)| *a += b),
            None => *slot = Some(t),
        }
    }

    fn product_into<T: Float>(
        slot: &mut Slot<T>,
        len: usize,
        (l, tl): (&Tensor<T>, bool),
        (r, at, tr): (&Tensor<T>, Block, bool),
        plan: &MatMulPlan,
    ) -> Result<()> {
        let (r_rows, r_cols) = if tr { (plan.n, plan.k) } else { (plan.k, plan.n) };
        // A block with a row stride is copied out first (the product reads packed rows).
        let copied = (at.ld != r_cols).then(|| {
            let mut out = pool::for_overwrite(r_rows * r_cols);
            for (i, dst) in out.chunks_exact_mut(r_cols.max(1)).enumerate() {
                dst.copy_from_slice(&r.data()[at.start + i * at.ld..at.start + i * at.ld + r_cols]);
            }
            out
        });
        let rd = copied.as_deref().unwrap_or(&r.data()[at.start..]);
        let (out, accumulate) = to_write(slot, len);
        matmul::matmul_into(out, accumulate, l.data(), tl, rd, tr, plan);
        if let Some(c) = copied {
            pool::recycle(c);
        }
        Ok(())
    }

    fn product_into_block<T: Float>(
        slot: &mut Slot<T>,
        len: usize,
        at: Block,
        (l, tl): (&Tensor<T>, bool),
        (r, tr): (&Tensor<T>, bool),
        plan: &MatMulPlan,
    ) -> Result<()> {
        // Computed apart and then added, as a narrow's gradient is.
        let (m, n) = (plan.m, plan.n);
        let mut block = pool::for_overwrite(m * n);
        matmul::matmul_into(&mut block, false, l.data(), tl, r.data(), tr, plan);
        let out = zeroed(slot, len);
        for (i, src) in block.chunks_exact(n.max(1)).enumerate() {
            let dst = &mut out[at.start + i * at.ld..at.start + i * at.ld + n];
            dst.iter_mut().zip(src).for_each(|(s, &v)| *s += v);
        }
        pool::recycle(block);
        Ok(())
    }

    fn narrow_backward_into<T: Float>(
        slot: &mut Slot<T>,
        x_shape: &[usize],
        g: &Tensor<T>,
        axis: usize,
        start: usize,
    ) -> Result<()> {
        layout::narrow_backward_into(zeroed(slot, crate::shape::numel(x_shape)), x_shape, g.data(), axis, start);
        Ok(())
    }

    fn cat_part_into<T: Float>(
        slot: &mut Slot<T>,
        len_x: usize,
        g: &Tensor<T>,
        axis: usize,
        start: usize,
        len: usize,
    ) -> Result<()> {
        let (out, accumulate) = to_write(slot, len_x);
        layout::narrow_add_into(out, accumulate, g.data(), g.shape(), axis, start, len);
        Ok(())
    }

    fn index_add_into<T: Float>(
        slot: &mut Slot<T>,
        (outer, n, inner): (usize, usize, usize),
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        index::index_add_into(zeroed(slot, outer * n * inner), n, g.data(), idx.len(), outer, inner, idx);
        Ok(())
    }

    fn gather_backward_into<T: Float>(
        slot: &mut Slot<T>,
        x_shape: &[usize],
        axis: usize,
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        index::gather_backward_into(zeroed(slot, crate::shape::numel(x_shape)), x_shape, axis, g.data(), idx);
        Ok(())
    }

    fn small_batched_backward<T: Float>(
        g: &Tensor<T>,
        (sa, av, ta, wa): (&mut Slot<T>, &Tensor<T>, bool, bool),
        (sb, bv, tb, wb): (&mut Slot<T>, &Tensor<T>, bool, bool),
        same: bool,
    ) -> bool {
        if !matmul::fused_small_backward_applies(av.shape(), bv.shape(), ta, tb) {
            return false;
        }
        let (la, lb) = (av.numel(), bv.numel());
        let da = wa.then(|| to_write(sa, la));
        let db = (wb && !same).then(|| to_write(sb, lb));
        matmul::small_batched_backward(g.data(), av.data(), ta, bv.data(), tb, av.shape(), bv.shape(), da, db, same);
        true
    }

    fn to_host_all<T: Float>(ts: &[Tensor<T>]) -> Result<Vec<Tensor<T>>> {
        Ok(ts.to_vec())
    }

    fn first_non_finite<T: Float>(ts: &[Tensor<T>]) -> Result<Option<usize>> {
        Ok(ts.iter().position(|t| !t.data().iter().all(|v| v.is_finite())))
    }

    fn sum_of_squares<T: Float>(x: &Tensor<T>) -> Result<f64> {
        Ok(x.data().iter().map(|v| v.to_f64() * v.to_f64()).sum())
    }

    fn adam_step<T: Float>(
        p: &Tensor<T>,
        g: &Tensor<T>,
        m: &Tensor<f32>,
        v: &Tensor<f32>,
        s: AdamStep,
    ) -> Result<(Tensor<T>, Tensor<f32>, Tensor<f32>)> {
        // The formula of the GPU's kernel (`gpu/wgsl/adam.wgsl`), in f32, element by element.
        let f = |x: f64| x as f32;
        let (lr, b1, b2, c1, c2, eps) = (f(s.lr), f(s.beta1), f(s.beta2), f(s.c1), f(s.c2), f(s.eps));
        let clip = s.clip.map(|c| (f(-c), f(c)));
        let n = p.numel();
        let (mut p1, mut m1, mut v1) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
        for (((&pi, &gi), &mi), &vi) in p.data().iter().zip(g.data()).zip(m.data()).zip(v.data()) {
            let mut gi = f(gi.to_f64());
            if let Some((lo, hi)) = clip {
                gi = gi.max(lo).min(hi);
            }
            let mn = b1 * mi + (1.0 - b1) * gi;
            let vn = b2 * vi + (1.0 - b2) * gi * gi;
            m1.push(mn);
            v1.push(vn);
            p1.push(T::from_f64(f64::from(f(pi.to_f64()) - lr * (mn * c1) / ((vn * c2).sqrt() + eps))));
        }
        let shape = p.shape().to_vec();
        Ok((
            Tensor::from_parts(p1, shape.clone()),
            Tensor::from_parts(m1, shape.clone()),
            Tensor::from_parts(v1, shape),
        ))
    }
}
