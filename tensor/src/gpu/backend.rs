//! The GPU backend: [`Backend`] over the WGSL kernels of `ops/` (f32 in device buffers).
//! Operands arrive on the device (`ops.rs` places them); outputs stay there.

use std::sync::Arc;

use super::DeviceBuffer;
use super::ops::layout::Block as CopyBlock;
use super::ops::matmul::{Placed, Term, matmul_into_at};
use super::ops::{elementwise, index, layout, matmul, nnops, optim, reduce};
use crate::backend::{AdamStep, Backend, Block, GradPair, Slot};
use crate::device::Device;
use crate::element::Float;
use crate::error::{Result, check_axis, invalid};
use crate::kernels;
use crate::kernels::matmul::MatMulPlan;
use crate::kernels::nnops::WeightRows;
use crate::op::{Activation, BinaryOp, ReduceOp, UnaryOp};
use crate::shape::{numel, split_at_axis, strides};
use crate::tensor::Tensor;

/// The process's GPU.
pub(crate) struct Gpu;

/// The device buffer of an operand (placed on the GPU by `ops.rs`).
fn buf<T: Float>(x: &Tensor<T>) -> &DeviceBuffer {
    x.device_buffer().expect("an operand of a GPU op is on the GPU")
}

/// A kernel's output as a tensor.
fn out<T: Float>(b: DeviceBuffer, shape: Vec<usize>) -> Tensor<T> {
    Tensor::from_device(b, shape)
}

/// Checks that an output of `n` values fits in a device buffer.
fn check(op: &'static str, n: usize) -> Result<()> {
    super::gpu()?.check_size(op, n)
}

/// The last dim (1 for a scalar).
fn last<T: Float>(x: &Tensor<T>) -> usize {
    x.shape().last().copied().unwrap_or(1)
}

/// The slot's device buffer of `len` values: zeros on first use (`zeroed`) or unspecified
/// values to overwrite, and whether it held a gradient already. A host slot (a gradient
/// begun on the CPU) is uploaded, a shared one copied so that it can be written in place.
fn slot_buffer<T: Float>(slot: &mut Slot<T>, len: usize, zeroed: bool) -> Result<(&DeviceBuffer, bool)> {
    let existed = slot.is_some();
    let placed = match slot.take() {
        Some(t) => t.into_device(Device::Gpu)?.into_device_buffer(),
        None if zeroed => DeviceBuffer::zeros(len),
        None => DeviceBuffer::uninit(len),
    };
    let t = slot.insert(Tensor::from_device(placed, vec![len]));
    Ok((buf(t), existed))
}

impl Backend for Gpu {
    fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
        out(elementwise::unary(buf(x), op), x.shape().to_vec())
    }

    fn unary_backward<T: Float>(g: &Tensor<T>, x: &Tensor<T>, y: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
        out(elementwise::unary_backward(buf(g), buf(x), buf(y), op), g.shape().to_vec())
    }

    fn activation_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>, act: Activation) -> Tensor<T> {
        // The unary derivative kernel, reading the output `y` for both of its inputs.
        let op = match act {
            Activation::Identity => return g.clone(),
            Activation::Relu => UnaryOp::Relu,
            Activation::Tanh => UnaryOp::Tanh,
        };
        Self::unary_backward(g, y, y, op)
    }

    fn binary<T: Float>(a: &Tensor<T>, b: &Tensor<T>, shape: &[usize], op: BinaryOp) -> Result<Tensor<T>> {
        check(op.name(), numel(shape))?;
        Ok(out(elementwise::binary(buf(a), a.shape(), buf(b), b.shape(), shape, op), shape.to_vec()))
    }

    fn binary_backward<T: Float>(
        g: &Tensor<T>,
        a: &Tensor<T>,
        b: &Tensor<T>,
        y: &Tensor<T>,
        op: BinaryOp,
        wants: (bool, bool),
    ) -> Result<GradPair<T>> {
        // Both gradients in one launch, `b` scaling rows of `a` with the rows' sums inside
        // it (as the CPU's fast path does).
        let shape = y.shape();
        if matches!(op, BinaryOp::Div | BinaryOp::Mul)
            && a.numel() == y.numel()
            && kernels::elementwise::is_row_broadcast(b.shape(), shape)
        {
            let (ga, gb) = elementwise::row_scale_backward(buf(g), buf(a), buf(b), op == BinaryOp::Div, wants);
            return Ok((ga.map(|v| out(v, a.shape().to_vec())), gb.map(|v| out(v, b.shape().to_vec()))));
        }
        let (ga, gb) =
            elementwise::binary_backward(buf(g), buf(a), a.shape(), buf(b), b.shape(), buf(y), shape, op, wants);
        let back = |v: Option<DeviceBuffer>, target: &[usize]| {
            v.map(|v| Self::sum_to_shape(&out::<T>(v, shape.to_vec()), target)).transpose()
        };
        Ok((back(ga, a.shape())?, back(gb, b.shape())?))
    }

    fn where_select<T: Float>(
        mask: &Arc<Vec<bool>>,
        shape: &[usize],
        a: &Tensor<T>,
        b: &Tensor<T>,
    ) -> Result<Tensor<T>> {
        let m: Vec<u32> = mask.iter().map(|&v| v as u32).collect();
        let m = DeviceBuffer::upload_u32(&m);
        Ok(out(elementwise::where_select(&m, shape, buf(a), a.shape(), buf(b), b.shape()), shape.to_vec()))
    }

    fn reduce<T: Float>(x: &Tensor<T>, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Tensor<T>> {
        let (outer, len, inner) = kernels::reduce::reduce_plan(x.shape(), op, axis)?;
        let scale = if op == ReduceOp::Mean { 1.0 / len as f64 } else { 1.0 };
        let y = reduce::reduce_axis(buf(x), outer, len, inner, op == ReduceOp::Max, scale);
        Ok(out(y, kernels::reduce::reduced_shape(x.shape(), axis, keepdim)))
    }

    fn sum_to_shape<T: Float>(g: &Tensor<T>, target: &[usize]) -> Result<Tensor<T>> {
        // The CPU's steps: leading dims as one block, then every dim where target has 1.
        let lead = g.rank() - target.len();
        let mut cur = g.clone();
        if lead > 0 {
            let outer: usize = cur.shape()[..lead].iter().product();
            let rest = cur.numel() / outer.max(1);
            let y = reduce::reduce_axis(buf(&cur), 1, outer, rest, false, 1.0);
            cur = out(y, cur.shape()[lead..].to_vec());
        }
        for (d, &t) in target.iter().enumerate() {
            if t == 1 && cur.shape()[d] != 1 {
                let (outer, len, inner) = split_at_axis(cur.shape(), d);
                let y = reduce::reduce_axis(buf(&cur), outer, len, inner, false, 1.0);
                let mut s = cur.shape().to_vec();
                s[d] = 1;
                cur = out(y, s);
            }
        }
        Ok(cur)
    }

    fn reduce_backward<T: Float>(
        x: &Tensor<T>,
        y: &Tensor<T>,
        g: &Tensor<T>,
        op: ReduceOp,
        (outer, len, inner): (usize, usize, usize),
    ) -> Result<Tensor<T>> {
        let dx = match op {
            ReduceOp::Max => reduce::max_backward(buf(x), buf(y), buf(g), outer, len, inner),
            ReduceOp::Sum | ReduceOp::Mean => {
                let s = if op == ReduceOp::Mean { 1.0 / len as f64 } else { 1.0 };
                // g [outer, inner] read with stride 0 along the reduced axis.
                layout::strided_copy(buf(g), &[outer, len, inner], &[inner, 0, 1], 0, s)
            }
        };
        Ok(out(dx, x.shape().to_vec()))
    }

    fn matmul<T: Float>(a: &Tensor<T>, b: &Tensor<T>, ta: bool, tb: bool, plan: &MatMulPlan) -> Result<Tensor<T>> {
        check("matmul", numel(&plan.out_shape()))?;
        Ok(out(matmul::matmul(buf(a), ta, buf(b), tb, plan), plan.out_shape()))
    }

    fn linear_sum<T: Float>(
        parts: &[WeightRows<'_, T>],
        b: Option<&Tensor<T>>,
        act: Activation,
        cols: Option<(usize, usize)>,
    ) -> Result<Tensor<T>> {
        let (shape, rows, n) = kernels::nnops::linear_rows_shapes(parts, b.map(|b| b.shape()), cols)?;
        check("linear", numel(&shape))?;
        let start = cols.map_or(0, |c| c.0);
        let terms: Vec<Term<'_>> = parts
            .iter()
            .map(|&(x, w, row)| {
                let (k, ld) = (x.shape()[x.rank() - 1], w.shape()[1]);
                Term { x: buf(x), k, w: Placed::block(buf(w), row * ld + start, ld) }
            })
            .collect();
        let bias = b.map(|b| Placed::at(buf(b), start));
        Ok(out(matmul::linear_sum(&terms, rows, n, bias, act), shape))
    }

    fn permute<T: Float>(x: &Tensor<T>, perm: &[usize]) -> Result<Tensor<T>> {
        let shape = kernels::layout::permuted_shape(x.shape(), perm)?;
        let st = strides(x.shape());
        let src: Vec<usize> = perm.iter().map(|&p| st[p]).collect();
        Ok(out(layout::strided_copy(buf(x), &shape, &src, 0, 1.0), shape))
    }

    fn expand<T: Float>(x: &Tensor<T>, shape: &[usize]) -> Result<Tensor<T>> {
        kernels::layout::check_expand(x.shape(), shape)?;
        check("expand", numel(shape))?;
        let src = crate::shape::broadcast_strides(x.shape(), shape);
        Ok(out(layout::strided_copy(buf(x), shape, &src, 0, 1.0), shape.to_vec()))
    }

    fn narrow<T: Float>(x: &Tensor<T>, axis: usize, start: usize, len: usize) -> Result<Tensor<T>> {
        kernels::layout::check_narrow(x.shape(), axis, start, len)?;
        let mut shape = x.shape().to_vec();
        shape[axis] = len;
        let src = strides(x.shape());
        let offset = start * src[axis];
        Ok(out(layout::strided_copy(buf(x), &shape, &src, offset, 1.0), shape))
    }

    fn cat<T: Float>(xs: &[&Tensor<T>], axis: usize, shape: &[usize]) -> Result<Tensor<T>> {
        check("cat", numel(shape))?;
        let (outer, _, inner) = split_at_axis(shape, axis);
        let parts: Vec<_> = xs.iter().map(|x| (buf(x), x.shape()[axis])).collect();
        Ok(out(layout::cat(&parts, outer, inner), shape.to_vec()))
    }

    fn index_select<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize]) -> Result<Tensor<T>> {
        check_axis("index_select", axis, x.shape())?;
        let (outer, n, inner) = split_at_axis(x.shape(), axis);
        kernels::index::check_indices("index_select", idx, n)?;
        let mut shape = x.shape().to_vec();
        shape[axis] = idx.len();
        check("index_select", numel(&shape))?;
        Ok(out(index::index_select(buf(x), outer, n, inner, idx), shape))
    }

    fn index_add<T: Float>(
        x: &Tensor<T>,
        (outer, n, inner): (usize, usize, usize),
        idx: &[usize],
        src: &Tensor<T>,
    ) -> Result<Tensor<T>> {
        let y = layout::strided_copy(buf(x), x.shape(), &strides(x.shape()), 0, 1.0);
        index::index_add_into(&y, n, buf(src), outer, inner, idx);
        Ok(out(y, x.shape().to_vec()))
    }

    fn gather<T: Float>(x: &Tensor<T>, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Tensor<T>> {
        kernels::index::gather_shape(x.shape(), axis, idx_shape, idx)?;
        let (outer, n, inner) = split_at_axis(x.shape(), axis);
        Ok(out(index::gather(buf(x), outer, n, inner, idx_shape[axis], idx), idx_shape.to_vec()))
    }

    fn segment_reduce<T: Float>(x: &Tensor<T>, seg: &[usize], n: usize, mean: bool) -> Result<Tensor<T>> {
        if x.rank() == 0 {
            return Err(invalid("segment_sum", "needs at least one dim"));
        }
        kernels::index::check_segments(seg, x.shape()[0], n)?;
        let inner = x.numel() / x.shape()[0].max(1);
        let mut shape = x.shape().to_vec();
        shape[0] = n;
        check("segment_sum", numel(&shape))?;
        Ok(out(index::segment_reduce(buf(x), x.shape()[0], inner, seg, n, mean), shape))
    }

    fn segment_backward<T: Float>(x_shape: &[usize], g: &Tensor<T>, seg: &[usize], mean: bool) -> Result<Tensor<T>> {
        let rows = x_shape[0];
        let inner = numel(x_shape) / rows.max(1);
        Ok(out(index::segment_backward(buf(g), rows, inner, seg, g.shape()[0], mean), x_shape.to_vec()))
    }

    fn softmax<T: Float>(x: &Tensor<T>) -> Tensor<T> {
        out(nnops::softmax(buf(x), last(x)), x.shape().to_vec())
    }

    fn softmax_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>) -> Tensor<T> {
        out(nnops::softmax_backward(buf(y), buf(g), last(y)), y.shape().to_vec())
    }

    fn zeros<T: Float>(shape: &[usize]) -> Tensor<T> {
        out(DeviceBuffer::zeros(numel(shape)), shape.to_vec())
    }

    fn gaussian_basis<T: Float>(x: &[f64], centres: &[f64], coeff: f64) -> Result<Tensor<T>> {
        // E values and K centres travel; the E x K basis is four element-wise launches here.
        let column = |v: &[f64], shape: &[usize]| -> Result<Tensor<T>> {
            Tensor::new(v.iter().map(|&a| T::from_f64(a)).collect(), shape)?.to_device(Device::Gpu)
        };
        let (n, k) = (x.len(), centres.len());
        let y = Self::binary(&column(x, &[n, 1])?, &column(centres, &[1, k])?, &[n, k], BinaryOp::Sub)?;
        let exponent = Self::unary(&Self::unary(&y, UnaryOp::Square), UnaryOp::Scale(coeff));
        Ok(Self::unary(&exponent, UnaryOp::Exp))
    }

    fn norm_last<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
        let mut shape = x.shape().to_vec();
        if let Some(l) = shape.last_mut() {
            *l = 1;
        }
        out(nnops::norm_last(buf(x), last(x), eps), shape)
    }

    fn norm_last_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>) -> Tensor<T> {
        out(nnops::norm_last_backward(buf(x), buf(y), buf(g), last(x)), x.shape().to_vec())
    }

    fn standardize<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
        out(nnops::standardize(buf(x), last(x), eps), x.shape().to_vec())
    }

    fn standardize_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>, eps: f64) -> Tensor<T> {
        out(nnops::standardize_backward(buf(x), buf(y), buf(g), last(x), eps), x.shape().to_vec())
    }

    fn accumulate<T: Float>(slot: &mut Slot<T>, t: Tensor<T>) {
        match slot.take() {
            None => *slot = Some(t),
            Some(held) => match held.try_into_device_buffer() {
                // Its own buffer: `t` added in place.
                Ok(b) => {
                    elementwise::add_into(&b, buf(&t));
                    *slot = Some(Tensor::from_device(b, vec![t.numel()]));
                }
                // Still shared (the same output gradient passed to both inputs of an add):
                // `held + t` into a new buffer, one launch where a copy and an in-place add
                // would be two; the same sum, element by element.
                Err(shared) => {
                    assert_eq!(shared.numel(), t.numel(), "two contributions to one gradient differ in size");
                    let flat = [t.numel()];
                    let sum = elementwise::binary(buf(&shared), &flat, buf(&t), &flat, &flat, BinaryOp::Add);
                    *slot = Some(Tensor::from_device(sum, flat.to_vec()));
                }
            },
        }
    }

    fn product_into<T: Float>(
        slot: &mut Slot<T>,
        len: usize,
        (l, tl): (&Tensor<T>, bool),
        (r, at, tr): (&Tensor<T>, Block, bool),
        plan: &MatMulPlan,
    ) -> Result<()> {
        let (dst, accumulate) = slot_buffer(slot, len, false)?;
        let (o, r) = (Placed::whole(dst), Placed::block(buf(r), at.start, at.ld));
        matmul_into_at(o, accumulate, buf(l), tl, r, tr, plan, None, Activation::Identity);
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
        // Added into the block in place: the kernels add the finished sum to the old value,
        // so the bits are those of a product of its own added afterwards.
        let (dst, _) = slot_buffer(slot, len, true)?;
        let (o, r) = (Placed::block(dst, at.start, at.ld), Placed::whole(buf(r)));
        matmul_into_at(o, true, buf(l), tl, r, tr, plan, None, Activation::Identity);
        Ok(())
    }

    fn narrow_backward_into<T: Float>(
        slot: &mut Slot<T>,
        x_shape: &[usize],
        g: &Tensor<T>,
        axis: usize,
        start: usize,
    ) -> Result<()> {
        let (outer, n, inner) = split_at_axis(x_shape, axis);
        let len = g.shape()[axis];
        let block = CopyBlock { outer, inner, len, src_n: len, src_start: 0, dst_n: n, dst_start: start };
        let (dst, _) = slot_buffer(slot, numel(x_shape), true)?;
        layout::block_copy_into(dst, buf(g), block, true);
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
        let (outer, n, inner) = split_at_axis(g.shape(), axis);
        let block = CopyBlock { outer, inner, len, src_n: n, src_start: start, dst_n: len, dst_start: 0 };
        let (dst, accumulate) = slot_buffer(slot, len_x, false)?;
        layout::block_copy_into(dst, buf(g), block, accumulate);
        Ok(())
    }

    fn index_add_into<T: Float>(
        slot: &mut Slot<T>,
        (outer, n, inner): (usize, usize, usize),
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        let (dst, _) = slot_buffer(slot, outer * n * inner, true)?;
        index::index_add_into(dst, n, buf(g), outer, inner, idx);
        Ok(())
    }

    fn gather_backward_into<T: Float>(
        slot: &mut Slot<T>,
        x_shape: &[usize],
        axis: usize,
        g: &Tensor<T>,
        idx: &[usize],
    ) -> Result<()> {
        let (outer, n, inner) = split_at_axis(x_shape, axis);
        let m = g.shape()[axis];
        let (dst, _) = slot_buffer(slot, numel(x_shape), true)?;
        index::gather_backward_into(dst, outer, n, inner, m, buf(g), idx);
        Ok(())
    }

    fn small_batched_backward<T: Float>(
        _g: &Tensor<T>,
        _a: (&mut Slot<T>, &Tensor<T>, bool, bool),
        _b: (&mut Slot<T>, &Tensor<T>, bool, bool),
        _same: bool,
    ) -> bool {
        // The tiled and small-matrix product kernels already cover these shapes.
        false
    }

    fn to_host_all<T: Float>(ts: &[Tensor<T>]) -> Result<Vec<Tensor<T>>> {
        // One staging buffer, one wait: no kernel launch.
        let parts: Vec<(&wgpu::Buffer, usize)> = ts.iter().map(|t| (buf(t).buffer(), t.numel())).collect();
        let words = super::device().download_many(&parts);
        Ok(ts
            .iter()
            .zip(words)
            .map(|(t, w)| Tensor::from_parts(T::from_f32_vec(bytemuck::cast_vec(w)), t.shape().to_vec()))
            .collect())
    }

    fn first_non_finite<T: Float>(ts: &[Tensor<T>]) -> Result<Option<usize>> {
        // One flag per tensor comes back, in one download.
        let bufs: Vec<&DeviceBuffer> = ts.iter().map(buf).collect();
        let flags = optim::non_finite_any(&bufs).download();
        Ok(flags.iter().position(|&f| f != 0.0))
    }

    fn sum_of_squares<T: Float>(x: &Tensor<T>) -> Result<f64> {
        // Summed there (in f32); one value comes back.
        let s = Self::reduce(&Self::unary(x, UnaryOp::Square), ReduceOp::Sum, None, false)?;
        Ok(f64::from(s.device_buffer().expect("on the GPU").download()[0]))
    }

    fn adam_step<T: Float>(
        p: &Tensor<T>,
        g: &Tensor<T>,
        m: &Tensor<f32>,
        v: &Tensor<f32>,
        step: AdamStep,
    ) -> Result<(Tensor<T>, Tensor<f32>, Tensor<f32>)> {
        let shape = p.shape().to_vec();
        let (p1, m1, v1) = optim::adam(buf(p), buf(g), buf(m), buf(v), step);
        Ok((out(p1, shape.clone()), out(m1, shape.clone()), out(v1, shape)))
    }
}
