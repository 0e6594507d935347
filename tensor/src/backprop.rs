//! Every gradient rule, in one place.
//!
//! `propagate` receives the gradient `g` of node `id` (same shape as its value) and adds the
//! contributions to the gradients of the node's inputs. Contributions are only computed for
//! inputs whose gradient is wanted. To add a new op: add a variant to [`Op`], a forward
//! method in `var_ops.rs`, and its rule here, then a finite-difference check in the tests.

use crate::element::Float;
use crate::kernels::{elementwise, index, layout, matmul, nnops, reduce};
use crate::op::{BinaryOp, NodeId, Op, ReduceOp};
use crate::pool;
use crate::shape::split_at_axis;
use crate::tape::Node;
use crate::tensor::Tensor;

/// Gradient buffers for the nodes of one backward pass.
pub(crate) struct GradStore<T: Float> {
    grads: Vec<Option<Vec<T>>>,
    wanted: Vec<bool>,
}

impl<T: Float> GradStore<T> {
    pub(crate) fn new(nodes: &[Node<T>]) -> Self {
        Self { grads: vec![None; nodes.len()], wanted: nodes.iter().map(|n| n.requires_grad).collect() }
    }

    /// Whether node `id` wants a gradient.
    fn wants(&self, id: NodeId) -> bool {
        self.wanted[id]
    }

    /// Adds `v` to node `id`'s gradient (takes the buffer if it is the first contribution).
    pub(crate) fn add(&mut self, id: NodeId, v: Vec<T>) {
        match &mut self.grads[id] {
            Some(g) => {
                g.iter_mut().zip(&v).for_each(|(a, &b)| *a += b);
                pool::recycle(v);
            }
            slot => *slot = Some(v),
        }
    }

    /// Node `id`'s gradient buffer, zero-initialised on first use, for in-place accumulation.
    fn slot(&mut self, id: NodeId, len: usize) -> &mut [T] {
        self.grads[id].get_or_insert_with(|| crate::pool::zeros(len))
    }

    /// Node `id`'s gradient buffer for a kernel that writes every element, and whether it
    /// must add to it: `false` on first use, when the buffer holds unspecified values to be
    /// overwritten (no zeroing pass over a buffer the kernel writes anyway).
    fn slot_to_write(&mut self, id: NodeId, len: usize) -> (&mut [T], bool) {
        let accumulate = self.grads[id].is_some();
        (self.grads[id].get_or_insert_with(|| crate::pool::for_overwrite(len)), accumulate)
    }

    /// [`GradStore::slot_to_write`] of two different nodes at once.
    #[allow(clippy::type_complexity)]
    fn slots2_to_write(&mut self, a: NodeId, la: usize, b: NodeId, lb: usize) -> ((&mut [T], bool), (&mut [T], bool)) {
        assert_ne!(a, b);
        let acc_a = self.slot_to_write(a, la).1;
        let acc_b = self.slot_to_write(b, lb).1;
        let (lo, hi, swap) = if a < b { (a, b, false) } else { (b, a, true) };
        let (first, second) = self.grads.split_at_mut(hi);
        let x = first[lo].as_deref_mut().expect("initialised above");
        let y = second[0].as_deref_mut().expect("initialised above");
        if swap { ((y, acc_a), (x, acc_b)) } else { ((x, acc_a), (y, acc_b)) }
    }

    /// Removes and returns node `id`'s gradient.
    pub(crate) fn take(&mut self, id: NodeId) -> Option<Vec<T>> {
        self.grads[id].take()
    }

    /// The gradients of leaves that wanted one, as tensors.
    pub(crate) fn into_leaf_grads(self, nodes: &[Node<T>]) -> Vec<Option<Tensor<T>>> {
        self.grads
            .into_iter()
            .zip(nodes)
            .map(|(g, n)| match (&n.op, g) {
                (Op::Leaf, Some(g)) if n.requires_grad => Some(Tensor::from_parts(g, n.value.shape().to_vec())),
                _ => None,
            })
            .collect()
    }
}

/// Adds the contributions of node `id` (with output gradient `g`) to its inputs.
/// `g` may be taken (left empty) by rules that can reuse it; the caller recycles what is left.
pub(crate) fn propagate<T: Float>(nodes: &[Node<T>], id: NodeId, g: &mut Vec<T>, store: &mut GradStore<T>) {
    let node = &nodes[id];
    let y = &node.value;
    let val = |i: NodeId| &nodes[i].value;
    let g_t = || {
        let mut v = crate::pool::with_capacity(g.len());
        v.extend_from_slice(g);
        Tensor::from_parts(v, y.shape().to_vec())
    };
    match &node.op {
        Op::Leaf => {}
        Op::Unary(x, op) => {
            if store.wants(*x) {
                store.add(*x, elementwise::unary_backward(g, val(*x).data(), y.data(), *op));
            }
        }
        Op::Binary(a, b, op) => binary_rule(nodes, *a, *b, *op, y, g, store),
        Op::Reduce { x, op, axis, keepdim: _ } => {
            if !store.wants(*x) {
                return;
            }
            let xv = val(*x);
            let (outer, len, inner) = match axis {
                Some(a) => split_at_axis(xv.shape(), *a),
                None => (1, xv.numel(), 1),
            };
            let dx = match op {
                ReduceOp::Max => reduce::max_backward(xv.data(), y.data(), g, outer, len, inner),
                ReduceOp::Sum | ReduceOp::Mean => {
                    let s = if *op == ReduceOp::Mean { T::ONE / T::from_f64(len as f64) } else { T::ONE };
                    let mut dx = crate::pool::zeros(xv.numel());
                    for o in 0..outer {
                        let gr = &g[o * inner..(o + 1) * inner];
                        for k in 0..len {
                            let d = &mut dx[(o * len + k) * inner..(o * len + k + 1) * inner];
                            d.iter_mut().zip(gr).for_each(|(d, &gv)| *d = gv * s);
                        }
                    }
                    dx
                }
            };
            store.add(*x, dx);
        }
        Op::MatMul { a, b, ta, tb } => {
            let (av, bv) = (val(*a), val(*b));
            if matmul::fused_small_backward_applies(av.shape(), bv.shape(), *ta, *tb) {
                // Many tiny products (e.g. Gram matrices Z^T Z of 3 x 32 blocks): the gradients
                // in one pass over the batch, while each block is in cache.
                let (wa, wb) = (store.wants(*a), store.wants(*b));
                let (ad, bd) = (av.data(), bv.data());
                let (la, lb) = (av.numel(), bv.numel());
                let (da, db) = match (wa, wb) {
                    (true, true) if a == b => (Some(store.slot_to_write(*a, la)), None),
                    (true, true) => {
                        let (sa, sb) = store.slots2_to_write(*a, la, *b, lb);
                        (Some(sa), Some(sb))
                    }
                    (true, false) => (Some(store.slot_to_write(*a, la)), None),
                    (false, true) => (None, Some(store.slot_to_write(*b, lb))),
                    (false, false) => (None, None),
                };
                matmul::small_batched_backward(g, ad, *ta, bd, *tb, av.shape(), bv.shape(), da, db, a == b);
                return;
            }
            let gt = g_t();
            if store.wants(*a) {
                // d op(A) = G op(B)^T; stored as A (or A^T when ta).
                let (l, r, tl, tr) = if !*ta { (&gt, bv, false, !*tb) } else { (bv, &gt, *tb, true) };
                accumulate_product(store, *a, av.shape(), l, tl, r, tr);
            }
            if store.wants(*b) {
                // d op(B) = op(A)^T G; stored as B (or B^T when tb).
                let (l, r, tl, tr) = if !*tb { (av, &gt, !*ta, false) } else { (&gt, av, true, *ta) };
                accumulate_product(store, *b, bv.shape(), l, tl, r, tr);
            }
        }
        Op::Linear { parts, b, act } => {
            // Without an activation the output gradient is used as it is (no copy).
            let owned = match act {
                crate::op::Activation::Identity => None,
                _ => Some(nnops::activation_backward(y.data(), g, *act)),
            };
            let gpre: &[T] = owned.as_deref().unwrap_or(g);
            let n = *y.shape().last().expect("a layer's output has a last dim");
            let rows = gpre.len() / n.max(1);
            // Each part as its own layer: dX_i = G' W_i^T, dW_i = X_i^T G'.
            for &(x, w) in parts {
                let (xv, wv) = (val(x), val(w));
                let k = wv.shape()[0];
                if store.wants(x) {
                    let plan =
                        matmul::MatMulPlan::new(&[rows, n], &[k, n], false, true).expect("shapes checked in forward");
                    let (slot, accumulate) = store.slot_to_write(x, rows * k);
                    matmul::matmul_into(slot, accumulate, gpre, false, wv.data(), true, &plan);
                }
                if store.wants(w) {
                    let plan = matmul::MatMulPlan::new(&[rows, k], &[rows, n], true, false)
                        .expect("shapes checked in forward");
                    let (slot, accumulate) = store.slot_to_write(w, k * n);
                    matmul::matmul_into(slot, accumulate, xv.data(), true, gpre, false, &plan);
                }
            }
            if let Some(b) = b
                && store.wants(*b)
            {
                store.add(*b, reduce::sum_axis(gpre, 1, rows, n));
            }
            if let Some(v) = owned {
                pool::recycle(v);
            }
        }
        Op::Softmax(x) => {
            if store.wants(*x) {
                let n = y.shape().last().copied().unwrap_or(1);
                store.add(*x, nnops::softmax_backward(y.data(), g, n));
            }
        }
        Op::NormLast { x, .. } => {
            if store.wants(*x) {
                let xv = val(*x);
                let n = xv.shape().last().copied().unwrap_or(1);
                store.add(*x, nnops::norm_last_backward(xv.data(), y.data(), g, n));
            }
        }
        Op::Standardize { x, eps } => {
            if store.wants(*x) {
                let xv = val(*x);
                let n = xv.shape().last().copied().unwrap_or(1);
                store.add(*x, nnops::standardize_backward(xv.data(), y.data(), g, n, *eps));
            }
        }
        Op::Reshape(x) => {
            if store.wants(*x) {
                store.add(*x, std::mem::take(g));
            }
        }
        Op::Permute(x, perm) => {
            if store.wants(*x) {
                let inv = layout::inverse_permutation(perm);
                store.add(*x, layout::permute(&g_t(), &inv).expect("valid permutation").into_vec());
            }
        }
        Op::Expand(x) => {
            if store.wants(*x) {
                store.add(*x, reduce::sum_to_shape(g_t(), val(*x).shape()).into_vec());
            }
        }
        Op::Narrow { x, axis, start } => {
            if store.wants(*x) {
                let xv = val(*x);
                let slot = store.slot(*x, xv.numel());
                layout::narrow_backward_into(slot, xv.shape(), g, *axis, *start);
            }
        }
        Op::Cat { xs, axis } => {
            let mut start = 0;
            for &x in xs {
                let xv = val(x);
                let len = xv.shape()[*axis];
                if store.wants(x) {
                    let (slot, accumulate) = store.slot_to_write(x, xv.numel());
                    layout::narrow_add_into(slot, accumulate, g, y.shape(), *axis, start, len);
                }
                start += len;
            }
        }
        Op::IndexSelect { x, axis, idx } => {
            if store.wants(*x) {
                let xv = val(*x);
                let (outer, n, inner) = split_at_axis(xv.shape(), *axis);
                let slot = store.slot(*x, xv.numel());
                index::index_add_into(slot, n, g, idx.len(), outer, inner, idx);
            }
        }
        Op::IndexAdd { x, src, axis, idx } => {
            if store.wants(*src) {
                store.add(*src, index::index_select(&g_t(), *axis, idx).expect("checked in forward").into_vec());
            }
            if store.wants(*x) {
                store.add(*x, std::mem::take(g));
            }
        }
        Op::Gather { x, axis, idx } => {
            if store.wants(*x) {
                let xv = val(*x);
                let slot = store.slot(*x, xv.numel());
                index::gather_backward_into(slot, xv.shape(), *axis, g, idx);
            }
        }
        Op::Segment { x, seg, mean } => {
            if store.wants(*x) {
                let xv = val(*x);
                let inner = xv.numel() / xv.shape()[0].max(1);
                let counts = if *mean { index::segment_counts(seg, y.shape()[0]) } else { vec![] };
                let mut dx = crate::pool::zeros(xv.numel());
                for (r, &s) in seg.iter().enumerate() {
                    let scale = if *mean { T::ONE / T::from_f64(counts[s] as f64) } else { T::ONE };
                    let src = &g[s * inner..(s + 1) * inner];
                    dx[r * inner..(r + 1) * inner].iter_mut().zip(src).for_each(|(d, &v)| *d = v * scale);
                }
                store.add(*x, dx);
            }
        }
        Op::Where { a, b, mask } => {
            for (input, pick) in [(*a, true), (*b, false)] {
                if store.wants(input) {
                    let masked = pool::zip_map(g, mask, |gv, m| if m == pick { gv } else { T::ZERO });
                    let t = Tensor::from_parts(masked, y.shape().to_vec());
                    store.add(input, reduce::sum_to_shape(t, val(input).shape()).into_vec());
                }
            }
        }
    }
}

/// Adds `op(l) @ op(r)` to the gradient of `target` (stored shape `target_shape`), summing
/// over batch dims that the target was broadcast along.
fn accumulate_product<T: Float>(
    store: &mut GradStore<T>,
    target: NodeId,
    target_shape: &[usize],
    l: &Tensor<T>,
    tl: bool,
    r: &Tensor<T>,
    tr: bool,
) {
    let plan = matmul::MatMulPlan::new(l.shape(), r.shape(), tl, tr).expect("shapes checked in forward");
    if plan.out_shape() == target_shape {
        let (slot, accumulate) = store.slot_to_write(target, target_shape.iter().product());
        matmul::matmul_into(slot, accumulate, l.data(), tl, r.data(), tr, &plan);
    } else {
        let full = matmul::matmul(l, r, tl, tr).expect("shapes checked in forward");
        store.add(target, reduce::sum_to_shape(full, target_shape).into_vec());
    }
}

/// Gradient rules of the broadcasting binary ops.
fn binary_rule<T: Float>(
    nodes: &[Node<T>],
    a: NodeId,
    b: NodeId,
    op: BinaryOp,
    y: &Tensor<T>,
    g: &[T],
    store: &mut GradStore<T>,
) {
    let (av, bv) = (&nodes[a].value, &nodes[b].value);
    let shape = y.shape();
    let with = |other: &Tensor<T>, mul: bool| {
        let (o, os) = (other.data(), other.shape());
        if mul {
            elementwise::binary_into_shape(g, shape, o, os, shape, |gv, ov| gv * ov)
        } else {
            elementwise::binary_into_shape(g, shape, o, os, shape, |gv, ov| gv / ov)
        }
    };
    let (wa, wb) = (store.wants(a), store.wants(b));
    if matches!(op, BinaryOp::Div | BinaryOp::Mul)
        && av.numel() == y.numel()
        && elementwise::is_row_broadcast(bv.shape(), shape)
    {
        // `a` scaled by one value of `b` per row (e.g. c / (||G|| + 1)): both gradients in
        // one pass, without broadcast temporaries.
        let (ga, gb) = elementwise::row_scale_backward(g, av.data(), bv.data(), op == BinaryOp::Div, wa, wb);
        if let Some(ga) = ga {
            store.add(a, ga);
        }
        if let Some(gb) = gb {
            store.add(b, gb);
        }
        return;
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
                let gb = elementwise::binary_into_shape(&gy, shape, bv.data(), bv.shape(), shape, |t, bv| -t / bv);
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
            let mask = elementwise::binary_into_shape(av.data(), av.shape(), bv.data(), bv.shape(), shape, pick_a);
            let ga = wa.then(|| pool::zip_map(g, &mask, |gv, m| gv * m));
            let gb = wb.then(|| pool::zip_map(g, &mask, |gv, m| gv * (T::ONE - m)));
            pool::recycle(mask);
            (ga, gb)
        }
    };
    for (input, grad, v) in [(a, ga, av), (b, gb, bv)] {
        if let Some(grad) = grad {
            let t = Tensor::from_parts(grad, shape.to_vec());
            store.add(input, reduce::sum_to_shape(t, v.shape()).into_vec());
        }
    }
}
