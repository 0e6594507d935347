//! Every gradient rule, in one place, for every device.
//!
//! `propagate` receives the gradient `g` of node `id` (a tensor shaped like its value, on its
//! device) and adds the contributions to the gradients of the node's inputs. Contributions
//! are only computed for inputs whose gradient is wanted. The rules are written once, as
//! tensor arithmetic: the kernels they call (`dispatch.rs`) and the in-place accumulations of
//! [`GradStore`] (`grad_store.rs`) run on the device the values live on. To add a new op: add
//! a variant to [`Op`], a forward method in `var_ops.rs`, its kernels in `dispatch.rs`, and its
//! rule here, then a finite-difference check and a GPU-against-CPU check in the tests.

use crate::dispatch as k;
use crate::element::Float;
use crate::error::Result;
use crate::kernels::matmul::MatMulPlan;
use crate::op::{Activation, LinearTerm, NodeId, Op, UnaryOp};
use crate::shape::split_at_axis;
use crate::tape::Node;
use crate::tensor::Tensor;

use crate::grad_store::Block;
pub(crate) use crate::grad_store::GradStore;

/// Adds the contributions of node `id` (with output gradient `g`) to its inputs.
pub(crate) fn propagate<T: Float>(nodes: &[Node<T>], id: NodeId, g: Tensor<T>, store: &mut GradStore<T>) -> Result<()> {
    let node = &nodes[id];
    let y = &node.value;
    let val = |i: NodeId| &nodes[i].value;
    match &node.op {
        Op::Leaf => {}
        Op::Unary(x, op) => {
            if store.wants(*x) {
                // d(x + c)/dx = 1: the gradient passes as it is (no kernel; `g * 1` is `g`).
                let dx = if matches!(op, UnaryOp::AddScalar(_)) { g } else { k::unary_backward(&g, val(*x), y, *op)? };
                store.add(*x, dx)?;
            }
        }
        Op::Binary(a, b, op) => {
            let wants = (store.wants(*a), store.wants(*b));
            let (ga, gb) = k::binary_backward(&g, val(*a), val(*b), y, *op, wants)?;
            // An add may hand `g`'s own storage to its inputs: released here, so the last of
            // them to be stored takes it without a copy.
            drop(g);
            if let Some(ga) = ga {
                store.add(*a, ga)?;
            }
            if let Some(gb) = gb {
                store.add(*b, gb)?;
            }
        }
        Op::Reduce { x, op, axis, keepdim: _ } => {
            if store.wants(*x) {
                store.add(*x, k::reduce_backward(val(*x), y, &g, *op, *axis)?)?;
            }
        }
        Op::MatMul { a, b, ta, tb } => {
            let (av, bv) = (val(*a), val(*b));
            if store.small_batched_backward(&g, (*a, av, *ta), (*b, bv, *tb)) {
                return Ok(());
            }
            if store.wants(*a) {
                // d op(A) = G op(B)^T; stored as A (or A^T when ta).
                let (l, r, tl, tr) = if !*ta { (&g, bv, false, !*tb) } else { (bv, &g, *tb, true) };
                store.add_product(*a, av.shape(), l, tl, r, tr)?;
            }
            if store.wants(*b) {
                // d op(B) = op(A)^T G; stored as B (or B^T when tb).
                let (l, r, tl, tr) = if !*tb { (av, &g, !*ta, false) } else { (&g, av, true, *ta) };
                store.add_product(*b, bv.shape(), l, tl, r, tr)?;
            }
        }
        Op::Linear { parts, b, col, act } => {
            // G' = G act'(pre), through the output (no copy without an activation).
            let gpre = if *act == Activation::Identity { g } else { k::activation_backward(y, &g, *act)? };
            let n = *y.shape().last().expect("a layer's output has a last dim");
            let rows = gpre.numel() / n.max(1);
            // Each part as its own layer of weight W_i = w[row..row + k, col..col + n]:
            // dX_i = G' W_i^T, dW_i = X_i^T G' (added into that block of dw).
            for &LinearTerm { x, w, row } in parts {
                let (xv, wv) = (val(x), val(w));
                let kdim = *xv.shape().last().expect("a layer's input has a last dim");
                let width = wv.shape()[1];
                let block = Block { start: row * width + col, ld: width };
                let whole = row == 0 && kdim == wv.shape()[0] && n == width;
                if store.wants(x) {
                    let plan = MatMulPlan::single(rows, n, kdim);
                    store.add_product_rows(x, rows * kdim, (&gpre, false), (wv, block, true), &plan)?;
                }
                if store.wants(w) {
                    let plan = MatMulPlan::single(kdim, rows, n);
                    if whole {
                        store.add_product_planned(w, kdim * n, xv, true, &gpre, false, &plan)?;
                    } else {
                        store.add_product_to_block(w, wv.numel(), block, (xv, true), (&gpre, false), &plan)?;
                    }
                }
            }
            if let Some(b) = b
                && store.wants(*b)
            {
                // The bias gradient: G' summed over rows (entries col..col + n of it).
                let rows_view = gpre.reshape(&[rows, n])?;
                let sum = k::reduce(&rows_view, crate::op::ReduceOp::Sum, Some(0), false)?;
                let b_shape = val(*b).shape();
                if b_shape == [n] {
                    store.add(*b, sum)?;
                } else {
                    store.add_narrow_backward(*b, b_shape, &sum, 0, *col)?;
                }
            }
        }
        Op::Softmax(x) => {
            if store.wants(*x) {
                store.add(*x, k::softmax_backward(y, &g)?)?;
            }
        }
        Op::NormLast { x, .. } => {
            if store.wants(*x) {
                store.add(*x, k::norm_last_backward(val(*x), y, &g)?)?;
            }
        }
        Op::Standardize { x, eps } => {
            if store.wants(*x) {
                store.add(*x, k::standardize_backward(val(*x), y, &g, *eps)?)?;
            }
        }
        Op::Reshape(x) => {
            if store.wants(*x) {
                store.add(*x, g.into_reshaped(val(*x).shape())?)?;
            }
        }
        Op::Permute(x, perm) => {
            if store.wants(*x) {
                let inv = crate::kernels::layout::inverse_permutation(perm);
                store.add(*x, k::permute(&g, &inv)?)?;
            }
        }
        Op::Expand(x) => {
            if store.wants(*x) {
                store.add(*x, k::sum_to_shape(&g, val(*x).shape())?)?;
            }
        }
        Op::Narrow { x, axis, start } => {
            if store.wants(*x) {
                store.add_narrow_backward(*x, val(*x).shape(), &g, *axis, *start)?;
            }
        }
        Op::Cat { xs, axis } => {
            let mut start = 0;
            for &x in xs {
                let len = val(x).shape()[*axis];
                if store.wants(x) {
                    store.add_cat_part(x, val(x).numel(), &g, *axis, start, len)?;
                }
                start += len;
            }
        }
        Op::IndexSelect { x, axis, idx } => {
            if store.wants(*x) {
                let (outer, n, inner) = split_at_axis(val(*x).shape(), *axis);
                store.add_index_add(*x, (outer, n, inner), &g, idx)?;
            }
        }
        Op::IndexAdd { x, src, axis, idx } => {
            if store.wants(*src) {
                store.add(*src, k::index_select(&g, *axis, idx)?)?;
            }
            if store.wants(*x) {
                store.add(*x, g)?;
            }
        }
        Op::Gather { x, axis, idx } => {
            if store.wants(*x) {
                store.add_gather_backward(*x, val(*x).shape(), *axis, &g, idx)?;
            }
        }
        Op::Segment { x, seg, mean } => {
            if store.wants(*x) {
                store.add(*x, k::segment_backward(val(*x).shape(), &g, seg, *mean)?)?;
            }
        }
        Op::Where { a, b, mask } => {
            for (input, pick) in [(*a, true), (*b, false)] {
                if store.wants(input) {
                    store.add(input, k::where_backward(&g, mask, pick, val(input).shape())?)?;
                }
            }
        }
    }
    Ok(())
}
