//! [`GradStore`]: the gradient buffers of one backward pass, one per node, on the device of
//! the node's value, and the in-place accumulations the gradient rules use.
//!
//! A rule adds a contribution with [`GradStore::add`] or, for products and scatters, writes
//! it straight into the node's buffer ([`GradStore::add_product`] and the `add_*` methods):
//! the first contribution overwrites a fresh buffer and later ones accumulate in place, which
//! keeps a training step free of extra passes over memory. The accumulations are the
//! backend's ([`Backend`]); this file only decides where each runs: on the GPU when the
//! node's buffer or an operand is there (the others placed there first), else on the CPU.

use crate::backend::{Backend, Slot, on_backend};
use crate::device::Device;
use crate::dispatch::{device_of, require_on};
use crate::element::Float;
use crate::error::Result;
use crate::kernels::matmul;
use crate::op::{NodeId, Op};
use crate::shape::numel;
use crate::tape::Node;
use crate::tensor::Tensor;

pub(crate) use crate::backend::Block;

/// Gradient buffers for the nodes of one backward pass.
pub(crate) struct GradStore<T: Float> {
    grads: Vec<Slot<T>>,
    wanted: Vec<bool>,
    shapes: Vec<Vec<usize>>,
}

/// Where an accumulation into `slot` with these operands runs: the GPU if the slot or an
/// operand is there (`dispatch::device_of`'s rule).
fn device_for<T: Float>(slot: &Slot<T>, operands: &[&Tensor<T>]) -> Device {
    match slot {
        Some(held) if held.device() == Device::Gpu => Device::Gpu,
        _ => device_of(operands),
    }
}

impl<T: Float> GradStore<T> {
    pub(crate) fn new(nodes: &[Node<T>]) -> Self {
        Self {
            grads: nodes.iter().map(|_| None).collect(),
            wanted: nodes.iter().map(|n| n.requires_grad).collect(),
            shapes: nodes.iter().map(|n| n.value.shape().to_vec()).collect(),
        }
    }

    /// Whether node `id` wants a gradient.
    pub(crate) fn wants(&self, id: NodeId) -> bool {
        self.wanted[id]
    }

    /// Adds `t` to node `id`'s gradient (takes its buffer if it is the first contribution).
    pub(crate) fn add(&mut self, id: NodeId, t: Tensor<T>) -> Result<()> {
        let slot = &mut self.grads[id];
        let dev = device_for(slot, &[&t]);
        if let Some(held) = slot.as_ref() {
            require_on(held, dev)?;
        }
        require_on(&t, dev)?;
        on_backend!(dev, B => B::accumulate(slot, t));
        Ok(())
    }

    /// Adds `op(l) @ op(r)` to the gradient of `target` (stored shape `target_shape`), summing
    /// over batch dims that the target was broadcast along.
    pub(crate) fn add_product(
        &mut self,
        target: NodeId,
        target_shape: &[usize],
        l: &Tensor<T>,
        tl: bool,
        r: &Tensor<T>,
        tr: bool,
    ) -> Result<()> {
        let plan = matmul::MatMulPlan::new(l.shape(), r.shape(), tl, tr)?;
        if plan.out_shape() == target_shape {
            self.add_product_planned(target, numel(target_shape), l, tl, r, tr, &plan)
        } else {
            let full = crate::dispatch::matmul(l, r, tl, tr)?;
            self.add(target, crate::dispatch::sum_to_shape(&full, target_shape)?)
        }
    }

    /// Adds `op(l) @ op(r)` (following `plan`, `len` values) to the gradient of `target`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn add_product_planned(
        &mut self,
        target: NodeId,
        len: usize,
        l: &Tensor<T>,
        tl: bool,
        r: &Tensor<T>,
        tr: bool,
        plan: &matmul::MatMulPlan,
    ) -> Result<()> {
        let packed = Block { start: 0, ld: if tr { plan.k } else { plan.n } };
        self.add_product_rows(target, len, (l, tl), (r, packed, tr), plan)
    }

    /// Adds `op(l) @ op(R)` (following `plan`, `len` values) to the gradient of `target`,
    /// where `R` is the [`Block`] of `r` (a block of a weight, read in place where the
    /// device can).
    pub(crate) fn add_product_rows(
        &mut self,
        target: NodeId,
        len: usize,
        (l, tl): (&Tensor<T>, bool),
        (r, block, tr): (&Tensor<T>, Block, bool),
        plan: &matmul::MatMulPlan,
    ) -> Result<()> {
        let slot = &mut self.grads[target];
        let dev = device_for(slot, &[l, r]);
        let (l, r) = (require_on(l, dev)?, require_on(r, dev)?);
        on_backend!(dev, B => B::product_into(slot, len, (l, tl), (r, block, tr), plan))
    }

    /// Adds `op(l) @ op(r)` (following `plan`) into the [`Block`] of the gradient of `target`
    /// (`target_len` values in all): the gradient of a block of a weight.
    pub(crate) fn add_product_to_block(
        &mut self,
        target: NodeId,
        target_len: usize,
        block: Block,
        (l, tl): (&Tensor<T>, bool),
        (r, tr): (&Tensor<T>, bool),
        plan: &matmul::MatMulPlan,
    ) -> Result<()> {
        let slot = &mut self.grads[target];
        let dev = device_for(slot, &[l, r]);
        let (l, r) = (require_on(l, dev)?, require_on(r, dev)?);
        on_backend!(dev, B => B::product_into_block(slot, target_len, block, (l, tl), (r, tr), plan))
    }

    /// The gradients of a batch of tiny products in one pass where the device has such a
    /// path (the CPU: `matmul::small_batched_backward`); `false` when the general rule must
    /// run.
    pub(crate) fn small_batched_backward(
        &mut self,
        g: &Tensor<T>,
        (a, av, ta): (NodeId, &Tensor<T>, bool),
        (b, bv, tb): (NodeId, &Tensor<T>, bool),
    ) -> bool {
        let dev = device_for(&None, &[g, av, bv]);
        let (wa, wb) = (self.wants(a), self.wants(b));
        if (wa && self.grads[a].as_ref().is_some_and(|s| s.device() != dev))
            || (wb && self.grads[b].as_ref().is_some_and(|s| s.device() != dev))
        {
            return false;
        }
        let same = a == b;
        let mut spare = None;
        let (sa, sb) = if same {
            (&mut self.grads[a], &mut spare)
        } else {
            let (lo, hi) = (a.min(b), a.max(b));
            let (first, second) = self.grads.split_at_mut(hi);
            let (x, y) = (&mut first[lo], &mut second[0]);
            if a < b { (x, y) } else { (y, x) }
        };
        on_backend!(dev, B => B::small_batched_backward(g, (sa, av, ta, wa), (sb, bv, tb, wb), same))
    }

    /// Adds `g` (the gradient of a narrow of `axis` from `start`) into the gradient of `x`.
    pub(crate) fn add_narrow_backward(
        &mut self,
        x: NodeId,
        x_shape: &[usize],
        g: &Tensor<T>,
        axis: usize,
        start: usize,
    ) -> Result<()> {
        let slot = &mut self.grads[x];
        let dev = device_for(slot, &[g]);
        let g = require_on(g, dev)?;
        on_backend!(dev, B => B::narrow_backward_into(slot, x_shape, g, axis, start))
    }

    /// Adds entries `start..start+len` of `axis` of `g` (a concatenation's gradient) to the
    /// gradient of the part `x` (`len_x` values).
    pub(crate) fn add_cat_part(
        &mut self,
        x: NodeId,
        len_x: usize,
        g: &Tensor<T>,
        axis: usize,
        start: usize,
        len: usize,
    ) -> Result<()> {
        let slot = &mut self.grads[x];
        let dev = device_for(slot, &[g]);
        let g = require_on(g, dev)?;
        on_backend!(dev, B => B::cat_part_into(slot, len_x, g, axis, start, len))
    }

    /// Adds `g` at the entries `idx` of an axis (`(outer, n, inner)` of `x`'s shape) to the
    /// gradient of `x`: the adjoint of an index selection.
    pub(crate) fn add_index_add(
        &mut self,
        x: NodeId,
        split: (usize, usize, usize),
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        let slot = &mut self.grads[x];
        let dev = device_for(slot, &[g]);
        let g = require_on(g, dev)?;
        on_backend!(dev, B => B::index_add_into(slot, split, g, idx))
    }

    /// Adds `g` to the gradient of `x` at the gathered positions: the adjoint of a gather.
    pub(crate) fn add_gather_backward(
        &mut self,
        x: NodeId,
        x_shape: &[usize],
        axis: usize,
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        let slot = &mut self.grads[x];
        let dev = device_for(slot, &[g]);
        let g = require_on(g, dev)?;
        on_backend!(dev, B => B::gather_backward_into(slot, x_shape, axis, g, idx))
    }

    /// Removes and returns node `id`'s gradient, shaped like its value.
    pub(crate) fn take(&mut self, id: NodeId) -> Option<Tensor<T>> {
        let shape = self.shapes[id].clone();
        self.grads[id].take().map(|g| shaped(g, &shape))
    }

    /// The gradients of leaves that wanted one, as tensors.
    pub(crate) fn into_leaf_grads(self, nodes: &[Node<T>]) -> Vec<Option<Tensor<T>>> {
        self.grads
            .into_iter()
            .zip(nodes)
            .map(|(g, n)| match (&n.op, g) {
                (Op::Leaf, Some(g)) if n.requires_grad => Some(shaped(g, n.value.shape())),
                _ => None,
            })
            .collect()
    }
}

/// A gradient buffer as a tensor of `shape` (a contribution holds its node's values).
fn shaped<T: Float>(g: Tensor<T>, shape: &[usize]) -> Tensor<T> {
    g.into_reshaped(shape).expect("a gradient holds its node's values")
}
