//! [`GradStore`]: the gradient buffers of one backward pass, one per node, on the device of
//! the node's value, and the in-place accumulations the gradient rules use.
//!
//! A rule adds a contribution with [`GradStore::add`] or, for products and scatters, writes
//! it straight into the node's buffer ([`GradStore::add_product`] and the `add_*` methods):
//! on the CPU the first contribution overwrites a recycled buffer and later ones accumulate in
//! place, which keeps a training step free of extra passes over memory; on the GPU the same
//! accumulations run as kernels on device buffers.

use crate::element::Float;
use crate::error::Result;
use crate::kernels::{index, layout, matmul};
use crate::op::{NodeId, Op};
use crate::pool;
use crate::shape::numel;
#[cfg(feature = "gpu")]
use crate::shape::split_at_axis;
use crate::tape::Node;
use crate::tensor::Tensor;

/// One node's gradient buffer.
enum Grad<T: Float> {
    /// On the host.
    Host(Vec<T>),
    /// On the GPU.
    #[cfg(feature = "gpu")]
    Device(crate::gpu::DeviceBuffer),
    /// On the GPU, a contribution whose storage other tensors still share (the same output
    /// gradient passed to both inputs of an add, say): kept as it is, copied only if an
    /// in-place rule must write it, and added out of place when another contribution comes.
    #[cfg(feature = "gpu")]
    Shared(Tensor<T>),
}

/// A matrix inside a row-major buffer: it starts at element `start` and its stored rows are
/// `ld` elements apart (a block of rows and columns of a weight `[in, ld]`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Block {
    /// The first element.
    pub start: usize,
    /// The elements between stored rows.
    pub ld: usize,
}

impl Block {
    /// The block's `rows x cols` values out of `data`, packed.
    fn gather<T: Float>(&self, data: &[T], rows: usize, cols: usize) -> Vec<T> {
        let mut out = pool::for_overwrite(rows * cols);
        for (i, dst) in out.chunks_exact_mut(cols.max(1)).enumerate() {
            dst.copy_from_slice(&data[self.start + i * self.ld..self.start + i * self.ld + cols]);
        }
        out
    }
}

/// Gradient buffers for the nodes of one backward pass.
pub(crate) struct GradStore<T: Float> {
    grads: Vec<Option<Grad<T>>>,
    wanted: Vec<bool>,
    shapes: Vec<Vec<usize>>,
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
    pub(crate) fn add(&mut self, id: NodeId, t: Tensor<T>) {
        match (&mut self.grads[id], on_device(&t)) {
            (Some(Grad::Host(g)), false) => {
                // Read in place (`t` may share its storage: an add's gradient passed on to
                // both inputs); its buffer goes back to the pool when the last owner drops.
                g.iter_mut().zip(t.data()).for_each(|(a, &b)| *a += b);
            }
            #[cfg(feature = "gpu")]
            (Some(Grad::Device(g)), true) => {
                crate::gpu::ops::elementwise::add_into(g, t.device_buffer().expect("on the device"));
            }
            #[cfg(feature = "gpu")]
            (Some(Grad::Device(g)), false) => {
                let up = t.to_device(crate::Device::Gpu).expect("a gradient the device already holds fits");
                crate::gpu::ops::elementwise::add_into(g, up.device_buffer().expect("uploaded"));
            }
            #[cfg(feature = "gpu")]
            (Some(Grad::Host(g)), true) => {
                g.iter_mut().zip(t.data()).for_each(|(a, &b)| *a += b);
            }
            #[cfg(feature = "gpu")]
            (slot @ Some(Grad::Shared(_)), _) => {
                // `held + t` into a new buffer: one launch, where a copy of the shared one and
                // an in-place add were two; the same sum, element by element.
                use crate::gpu::ops::elementwise::binary;
                let Some(Grad::Shared(held)) = slot.take() else { unreachable!("matched above") };
                let t = t.to_device(crate::Device::Gpu).expect("a gradient the device already holds fits");
                let (a, b) = (held.device_buffer().expect("on the device"), t.device_buffer().expect("uploaded"));
                assert_eq!(held.numel(), t.numel(), "two contributions to one gradient differ in size");
                let flat = [held.numel()];
                *slot = Some(Grad::Device(binary(a, &flat, b, &flat, &flat, crate::op::BinaryOp::Add)));
            }
            (slot @ None, _) => *slot = Some(into_grad(t)),
            #[cfg(not(feature = "gpu"))]
            _ => unreachable!("no device tensors without the gpu feature"),
        }
    }

    /// Node `id`'s gradient buffer on the host, zero-initialised on first use.
    fn host_slot(&mut self, id: NodeId, len: usize) -> &mut [T] {
        match self.grads[id].get_or_insert_with(|| Grad::Host(pool::zeros(len))) {
            Grad::Host(v) => v,
            #[cfg(feature = "gpu")]
            Grad::Device(_) | Grad::Shared(_) => unreachable!("host rules run on host gradients"),
        }
    }

    /// Node `id`'s host buffer for a kernel that writes every element, and whether it must add
    /// to it: `false` on first use, when the buffer holds unspecified values to be overwritten.
    fn host_slot_to_write(&mut self, id: NodeId, len: usize) -> (&mut [T], bool) {
        let accumulate = self.grads[id].is_some();
        match self.grads[id].get_or_insert_with(|| Grad::Host(pool::for_overwrite(len))) {
            Grad::Host(v) => (v, accumulate),
            #[cfg(feature = "gpu")]
            Grad::Device(_) | Grad::Shared(_) => unreachable!("host rules run on host gradients"),
        }
    }

    /// Whether node `id`'s gradient lives (or, on first use, will live) on the GPU: where its
    /// contribution `g` is computed.
    fn on_gpu(&self, id: NodeId, g: &Tensor<T>) -> bool {
        match &self.grads[id] {
            Some(Grad::Host(_)) => false,
            #[cfg(feature = "gpu")]
            Some(Grad::Device(_) | Grad::Shared(_)) => true,
            None => on_device(g),
        }
    }

    /// Node `id`'s device buffer of `len` values: zeros on first use (`zeroed`) or unspecified
    /// values to overwrite, and whether it held a gradient already.
    #[cfg(feature = "gpu")]
    fn device_slot(&mut self, id: NodeId, len: usize, zeroed: bool) -> (&crate::gpu::DeviceBuffer, bool) {
        use crate::gpu::DeviceBuffer;
        let existed = self.grads[id].is_some();
        if let Some(Grad::Host(v)) = &self.grads[id] {
            let up = DeviceBuffer::upload(T::as_f32_slice(v).expect("device gradients are f32"));
            self.grads[id] = Some(Grad::Device(up));
        }
        if let Some(Grad::Shared(_)) = &self.grads[id] {
            // Written in place from here on: its own buffer (a copy only if still shared).
            let Some(Grad::Shared(t)) = self.grads[id].take() else { unreachable!("matched above") };
            self.grads[id] = Some(Grad::Device(t.into_device_buffer()));
        }
        let slot = self.grads[id].get_or_insert_with(|| {
            Grad::Device(if zeroed { DeviceBuffer::zeros(len) } else { DeviceBuffer::uninit(len) })
        });
        match slot {
            Grad::Device(b) => (b, existed),
            Grad::Host(_) | Grad::Shared(_) => unreachable!("made a device buffer above"),
        }
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
            self.add(target, crate::dispatch::sum_to_shape(&full, target_shape)?);
            Ok(())
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
    /// where `R` is the [`Block`] of `r` (a block of a weight, read in place; on the CPU a
    /// block with a row stride is copied out first).
    pub(crate) fn add_product_rows(
        &mut self,
        target: NodeId,
        len: usize,
        (l, tl): (&Tensor<T>, bool),
        (r, at, tr): (&Tensor<T>, Block, bool),
        plan: &matmul::MatMulPlan,
    ) -> Result<()> {
        let (r_rows, r_cols) = if tr { (plan.n, plan.k) } else { (plan.k, plan.n) };
        let gpu = self.on_gpu(target, l) || on_device(r);
        if !gpu {
            let copied = (at.ld != r_cols).then(|| at.gather(r.data(), r_rows, r_cols));
            let r = copied.as_deref().unwrap_or(&r.data()[at.start..]);
            let (slot, accumulate) = self.host_slot_to_write(target, len);
            matmul::matmul_into(slot, accumulate, l.data(), tl, r, tr, plan);
            return Ok(());
        }
        #[cfg(feature = "gpu")]
        {
            use crate::gpu::ops::matmul::{Placed, matmul_into_at};
            let (l, r) = (l.to_device(crate::Device::Gpu)?, r.to_device(crate::Device::Gpu)?);
            let (slot, accumulate) = self.device_slot(target, len, false);
            let (lb, rb) = (l.device_buffer().expect("placed"), r.device_buffer().expect("placed"));
            let (out, r) = (Placed::whole(slot), Placed::block(rb, at.start, at.ld));
            matmul_into_at(out, accumulate, lb, tl, r, tr, plan, None, crate::op::Activation::Identity);
        }
        Ok(())
    }

    /// Adds `op(l) @ op(r)` (following `plan`) into the [`Block`] of the gradient of `target`
    /// (`target_len` values in all): the gradient of a block of a weight. On the GPU the
    /// product adds into the block in place (its kernels add the finished sum to the old
    /// value, so the bits are those of a product of its own added afterwards); on the CPU it
    /// is computed apart and then added, as a narrow's gradient is.
    pub(crate) fn add_product_to_block(
        &mut self,
        target: NodeId,
        target_len: usize,
        at: Block,
        (l, tl): (&Tensor<T>, bool),
        (r, tr): (&Tensor<T>, bool),
        plan: &matmul::MatMulPlan,
    ) -> Result<()> {
        let (m, n) = (plan.m, plan.n);
        if !(self.on_gpu(target, l) || on_device(r)) {
            let mut block = pool::for_overwrite(m * n);
            matmul::matmul_into(&mut block, false, l.data(), tl, r.data(), tr, plan);
            let slot = self.host_slot(target, target_len);
            for (i, src) in block.chunks_exact(n.max(1)).enumerate() {
                let dst = &mut slot[at.start + i * at.ld..at.start + i * at.ld + n];
                dst.iter_mut().zip(src).for_each(|(s, &v)| *s += v);
            }
            pool::recycle(block);
            return Ok(());
        }
        #[cfg(feature = "gpu")]
        {
            use crate::gpu::ops::matmul::{Placed, matmul_into_at};
            let (l, r) = (l.to_device(crate::Device::Gpu)?, r.to_device(crate::Device::Gpu)?);
            let (slot, _) = self.device_slot(target, target_len, true);
            let (lb, rb) = (l.device_buffer().expect("placed"), r.device_buffer().expect("placed"));
            let (out, r) = (Placed::block(slot, at.start, at.ld), Placed::whole(rb));
            matmul_into_at(out, true, lb, tl, r, tr, plan, None, crate::op::Activation::Identity);
        }
        Ok(())
    }

    /// The gradients of a batch of tiny products on the host in one pass (a CPU fast path:
    /// `matmul::small_batched_backward`); `false` when it does not apply and the general rule
    /// must run.
    pub(crate) fn small_batched_backward(
        &mut self,
        g: &Tensor<T>,
        (a, av, ta): (NodeId, &Tensor<T>, bool),
        (b, bv, tb): (NodeId, &Tensor<T>, bool),
    ) -> bool {
        if on_device(g)
            || on_device(av)
            || on_device(bv)
            || !matmul::fused_small_backward_applies(av.shape(), bv.shape(), ta, tb)
        {
            return false;
        }
        let (wa, wb) = (self.wants(a), self.wants(b));
        let (ad, bd) = (av.data(), bv.data());
        let (la, lb) = (av.numel(), bv.numel());
        let (da, db) = match (wa, wb) {
            (true, true) if a == b => (Some(self.host_slot_to_write(a, la)), None),
            (true, true) => {
                let (sa, sb) = self.host_slots2_to_write(a, la, b, lb);
                (Some(sa), Some(sb))
            }
            (true, false) => (Some(self.host_slot_to_write(a, la)), None),
            (false, true) => (None, Some(self.host_slot_to_write(b, lb))),
            (false, false) => (None, None),
        };
        matmul::small_batched_backward(g.data(), ad, ta, bd, tb, av.shape(), bv.shape(), da, db, a == b);
        true
    }

    /// [`GradStore::host_slot_to_write`] of two different nodes at once.
    #[allow(clippy::type_complexity)]
    fn host_slots2_to_write(
        &mut self,
        a: NodeId,
        la: usize,
        b: NodeId,
        lb: usize,
    ) -> ((&mut [T], bool), (&mut [T], bool)) {
        assert_ne!(a, b);
        let acc_a = self.host_slot_to_write(a, la).1;
        let acc_b = self.host_slot_to_write(b, lb).1;
        let (lo, hi, swap) = if a < b { (a, b, false) } else { (b, a, true) };
        let (first, second) = self.grads.split_at_mut(hi);
        let (x, y) = (host_mut(&mut first[lo]), host_mut(&mut second[0]));
        if swap { ((y, acc_a), (x, acc_b)) } else { ((x, acc_a), (y, acc_b)) }
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
        if !self.on_gpu(x, g) {
            let slot = self.host_slot(x, numel(x_shape));
            layout::narrow_backward_into(slot, x_shape, g.data(), axis, start);
            return Ok(());
        }
        #[cfg(feature = "gpu")]
        {
            let g = g.to_device(crate::Device::Gpu)?;
            let (outer, n, inner) = split_at_axis(x_shape, axis);
            let len = g.shape()[axis];
            let block = crate::gpu::ops::layout::Block {
                outer,
                inner,
                len,
                src_n: len,
                src_start: 0,
                dst_n: n,
                dst_start: start,
            };
            let (slot, _) = self.device_slot(x, numel(x_shape), true);
            crate::gpu::ops::layout::block_copy_into(slot, g.device_buffer().expect("placed"), block, true);
        }
        Ok(())
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
        if !self.on_gpu(x, g) {
            let (slot, accumulate) = self.host_slot_to_write(x, len_x);
            layout::narrow_add_into(slot, accumulate, g.data(), g.shape(), axis, start, len);
            return Ok(());
        }
        #[cfg(feature = "gpu")]
        {
            let g = g.to_device(crate::Device::Gpu)?;
            let (outer, n, inner) = split_at_axis(g.shape(), axis);
            let block = crate::gpu::ops::layout::Block {
                outer,
                inner,
                len,
                src_n: n,
                src_start: start,
                dst_n: len,
                dst_start: 0,
            };
            let (slot, accumulate) = self.device_slot(x, len_x, false);
            crate::gpu::ops::layout::block_copy_into(slot, g.device_buffer().expect("placed"), block, accumulate);
        }
        Ok(())
    }

    /// Adds `g` at the entries `idx` of an axis (`(outer, n, inner)` of `x`'s shape) to the
    /// gradient of `x`: the adjoint of an index selection.
    pub(crate) fn add_index_add(
        &mut self,
        x: NodeId,
        (outer, n, inner): (usize, usize, usize),
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        let len = outer * n * inner;
        if !self.on_gpu(x, g) {
            let slot = self.host_slot(x, len);
            index::index_add_into(slot, n, g.data(), idx.len(), outer, inner, idx);
            return Ok(());
        }
        #[cfg(feature = "gpu")]
        {
            let g = g.to_device(crate::Device::Gpu)?;
            let (slot, _) = self.device_slot(x, len, true);
            crate::gpu::ops::index::index_add_into(slot, n, g.device_buffer().expect("placed"), outer, inner, idx);
        }
        Ok(())
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
        if !self.on_gpu(x, g) {
            let slot = self.host_slot(x, numel(x_shape));
            index::gather_backward_into(slot, x_shape, axis, g.data(), idx);
            return Ok(());
        }
        #[cfg(feature = "gpu")]
        {
            let g = g.to_device(crate::Device::Gpu)?;
            let (outer, n, inner) = split_at_axis(x_shape, axis);
            let m = g.shape()[axis];
            let (slot, _) = self.device_slot(x, numel(x_shape), true);
            crate::gpu::ops::index::gather_backward_into(
                slot,
                outer,
                n,
                inner,
                m,
                g.device_buffer().expect("placed"),
                idx,
            );
        }
        Ok(())
    }

    /// Removes and returns node `id`'s gradient, shaped like its value.
    pub(crate) fn take(&mut self, id: NodeId) -> Option<Tensor<T>> {
        let shape = self.shapes[id].clone();
        self.grads[id].take().map(|g| from_grad(g, shape))
    }

    /// The gradients of leaves that wanted one, as tensors.
    pub(crate) fn into_leaf_grads(self, nodes: &[Node<T>]) -> Vec<Option<Tensor<T>>> {
        self.grads
            .into_iter()
            .zip(nodes)
            .map(|(g, n)| match (&n.op, g) {
                (Op::Leaf, Some(g)) if n.requires_grad => Some(from_grad(g, n.value.shape().to_vec())),
                _ => None,
            })
            .collect()
    }
}

/// The host buffer of an initialised host gradient.
fn host_mut<T: Float>(g: &mut Option<Grad<T>>) -> &mut [T] {
    match g.as_mut().expect("initialised") {
        Grad::Host(v) => v,
        #[cfg(feature = "gpu")]
        Grad::Device(_) | Grad::Shared(_) => unreachable!("host slots"),
    }
}

/// Whether `t` is on the GPU.
fn on_device<T: Float>(t: &Tensor<T>) -> bool {
    t.device() == crate::Device::Gpu
}

/// A contribution as a gradient: its buffer when no other tensor shares it; on the device a
/// shared one is kept as it is ([`Grad::Shared`]), on the host copied.
fn into_grad<T: Float>(t: Tensor<T>) -> Grad<T> {
    #[cfg(feature = "gpu")]
    if on_device(&t) {
        return match t.try_into_device_buffer() {
            Ok(b) => Grad::Device(b),
            Err(shared) => Grad::Shared(shared),
        };
    }
    Grad::Host(t.into_vec())
}

/// A gradient buffer as a tensor of `shape`.
fn from_grad<T: Float>(g: Grad<T>, shape: Vec<usize>) -> Tensor<T> {
    match g {
        Grad::Host(v) => Tensor::from_parts(v, shape),
        #[cfg(feature = "gpu")]
        Grad::Device(b) => Tensor::from_device(b, shape),
        #[cfg(feature = "gpu")]
        Grad::Shared(t) => t.into_reshaped(&shape).expect("a contribution holds its node's values"),
    }
}
