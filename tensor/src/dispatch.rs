//! Every kernel of the tape, on the device its operands live on.
//!
//! The forward methods in `var_ops.rs` and the gradient rules in `backprop.rs` call these
//! functions and never a device's kernels directly. Each function checks the shapes once,
//! then runs the CPU kernel of `kernels/` (the reference, unchanged) when every operand is on
//! the host, or the GPU kernel of `gpu/ops/` when one is on the GPU; a host operand of a GPU
//! op is uploaded first (counted in [`crate::gpu::GpuStats::uploads`]). Without the `gpu`
//! feature only the CPU arms exist.

use std::sync::Arc;

use crate::device::Device;
use crate::element::Float;
use crate::error::Result;
#[cfg(feature = "gpu")]
use crate::error::{check_axis, invalid};
use crate::kernels::{elementwise, index, layout, matmul, nnops, reduce};
use crate::op::{Activation, BinaryOp, ReduceOp, UnaryOp};
#[cfg(feature = "gpu")]
use crate::shape::{broadcast_shapes, strides};
use crate::shape::{numel, split_at_axis};
use crate::tensor::Tensor;

/// The device an op with these operands runs on: the GPU if any operand is there.
pub(crate) fn device_of<T: Float>(xs: &[&Tensor<T>]) -> Device {
    if xs.iter().any(|x| x.device() == Device::Gpu) { Device::Gpu } else { Device::Cpu }
}

/// GPU helpers: operands as device buffers (uploading host ones) and outputs as tensors.
#[cfg(feature = "gpu")]
mod dev {
    use super::*;
    use crate::gpu::DeviceBuffer;

    /// `x` on the GPU (a no-op when it is there).
    pub(super) fn up<T: Float>(x: &Tensor<T>) -> Result<Tensor<T>> {
        x.to_device(Device::Gpu)
    }

    /// The device buffer of a tensor placed by [`up`].
    pub(super) fn buf<T: Float>(x: &Tensor<T>) -> &DeviceBuffer {
        x.device_buffer().expect("placed on the GPU by `up`")
    }

    /// A kernel's output as a tensor.
    pub(super) fn out<T: Float>(b: DeviceBuffer, shape: Vec<usize>) -> Tensor<T> {
        Tensor::from_device(b, shape)
    }

    /// Checks that an output of `n` values fits in a device buffer.
    pub(super) fn check(op: &'static str, n: usize) -> Result<()> {
        crate::gpu::gpu()?.check_size(op, n)
    }
}

macro_rules! on_gpu {
    ($($body:tt)*) => {{
        #[cfg(feature = "gpu")]
        {
            $($body)*
        }
        #[cfg(not(feature = "gpu"))]
        {
            unreachable!("no tensor is on the GPU without the `gpu` feature")
        }
    }};
}

// ---------------------------------------------------------------------------------------
// Forward kernels.

/// `y = op(x)` element-wise.
pub(crate) fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
    match x.device() {
        Device::Cpu => elementwise::unary(x, op),
        Device::Gpu => on_gpu! {
            dev::out(crate::gpu::ops::elementwise::unary(dev::buf(x), op), x.shape().to_vec())
        },
    }
}

/// `op(a, b)` with broadcasting.
pub(crate) fn binary<T: Float>(a: &Tensor<T>, b: &Tensor<T>, op: BinaryOp) -> Result<Tensor<T>> {
    match device_of(&[a, b]) {
        Device::Cpu => elementwise::binary(a, b, op),
        Device::Gpu => on_gpu! {
            use crate::gpu::ops::elementwise::binary;
            let shape = broadcast_shapes(op.name(), a.shape(), b.shape())?;
            dev::check(op.name(), numel(&shape))?;
            let (a, b) = (dev::up(a)?, dev::up(b)?);
            let y = binary(dev::buf(&a), a.shape(), dev::buf(&b), b.shape(), &shape, op);
            Ok(dev::out(y, shape))
        },
    }
}

/// Reduction over `axis` (or everything).
pub(crate) fn reduce<T: Float>(x: &Tensor<T>, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => reduce::reduce(x, op, axis, keepdim),
        Device::Gpu => on_gpu! {
            let (outer, len, inner) = reduce::reduce_plan(x.shape(), op, axis)?;
            let scale = if op == ReduceOp::Mean { 1.0 / len as f64 } else { 1.0 };
            let y = crate::gpu::ops::reduce::reduce_axis(dev::buf(x), outer, len, inner, op == ReduceOp::Max, scale);
            Ok(dev::out(y, reduce::reduced_shape(x.shape(), axis, keepdim)))
        },
    }
}

/// `op(a) @ op(b)` over the last two dims, batch dims broadcast.
pub(crate) fn matmul<T: Float>(a: &Tensor<T>, b: &Tensor<T>, ta: bool, tb: bool) -> Result<Tensor<T>> {
    match device_of(&[a, b]) {
        Device::Cpu => matmul::matmul(a, b, ta, tb),
        Device::Gpu => on_gpu! {
            let plan = matmul::MatMulPlan::new(a.shape(), b.shape(), ta, tb)?;
            dev::check("matmul", numel(&plan.out_shape()))?;
            let (a, b) = (dev::up(a)?, dev::up(b)?);
            let y = crate::gpu::ops::matmul::matmul(dev::buf(&a), ta, dev::buf(&b), tb, &plan);
            Ok(dev::out(y, plan.out_shape()))
        },
    }
}

/// `act(sum_i x_i @ w_i[row_i..row_i + k_i, cols] + b[cols])` for the terms `(x_i, w_i,
/// row_i)` and the output columns `cols = (start, len)` (`None`: all of them).
pub(crate) fn linear_sum<T: Float>(
    parts: &[nnops::WeightRows<'_, T>],
    b: Option<&Tensor<T>>,
    act: Activation,
    cols: Option<(usize, usize)>,
) -> Result<Tensor<T>> {
    let mut all: Vec<&Tensor<T>> = parts.iter().flat_map(|&(x, w, _)| [x, w]).collect();
    all.extend(b);
    match device_of(&all) {
        Device::Cpu => match cols {
            // Some of the outputs: the weights' and bias's columns copied out first (the
            // products then have the bits of a layer of those columns alone).
            Some((start, len)) if len != parts[0].1.shape()[1] => {
                let ws: Vec<Tensor<T>> =
                    parts.iter().map(|&(_, w, _)| layout::narrow(w, 1, start, len)).collect::<Result<_>>()?;
                let b = b.map(|b| layout::narrow(b, 0, start, len)).transpose()?;
                let terms: Vec<nnops::WeightRows<'_, T>> =
                    parts.iter().zip(&ws).map(|(&(x, _, row), w)| (x, w, row)).collect();
                nnops::linear_sum_rows(&terms, b.as_ref(), act)
            }
            _ => nnops::linear_sum_rows(parts, b, act),
        },
        Device::Gpu => on_gpu! {
            let (shape, rows, n) = nnops::linear_rows_shapes(parts, b.map(|b| b.shape()), cols)?;
            dev::check("linear", numel(&shape))?;
            let start = cols.map_or(0, |c| c.0);
            let placed: Vec<(Tensor<T>, Tensor<T>)> =
                parts.iter().map(|&(x, w, _)| Ok((dev::up(x)?, dev::up(w)?))).collect::<Result<_>>()?;
            let bias = b.map(dev::up).transpose()?;
            let terms: Vec<crate::gpu::ops::matmul::Term<'_>> = placed
                .iter()
                .zip(parts)
                .map(|((x, w), &(xh, wh, row))| {
                    let (k, ld) = (xh.shape()[xh.rank() - 1], wh.shape()[1]);
                    let w = crate::gpu::ops::matmul::Placed::block(dev::buf(w), row * ld + start, ld);
                    crate::gpu::ops::matmul::Term { x: dev::buf(x), k, w }
                })
                .collect();
            let bias = bias.as_ref().map(|b| crate::gpu::ops::matmul::Placed::at(dev::buf(b), start));
            let y = crate::gpu::ops::matmul::linear_sum(&terms, rows, n, bias, act);
            Ok(dev::out(y, shape))
        },
    }
}

/// Softmax over the last axis.
pub(crate) fn softmax<T: Float>(x: &Tensor<T>) -> Tensor<T> {
    match x.device() {
        Device::Cpu => nnops::softmax(x),
        Device::Gpu => on_gpu! {
            let n = x.shape().last().copied().unwrap_or(1);
            dev::out(crate::gpu::ops::nnops::softmax(dev::buf(x), n), x.shape().to_vec())
        },
    }
}

/// `sqrt(sum x^2 + eps)` over the last axis, kept as size 1.
pub(crate) fn norm_last<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
    match x.device() {
        Device::Cpu => nnops::norm_last(x, eps),
        Device::Gpu => on_gpu! {
            let n = x.shape().last().copied().unwrap_or(1);
            let mut shape = x.shape().to_vec();
            if let Some(l) = shape.last_mut() {
                *l = 1;
            }
            dev::out(crate::gpu::ops::nnops::norm_last(dev::buf(x), n, eps), shape)
        },
    }
}

/// `(x - mean) / sqrt(var + eps)` over the last axis.
pub(crate) fn standardize<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
    match x.device() {
        Device::Cpu => nnops::standardize(x, eps),
        Device::Gpu => on_gpu! {
            let n = x.shape().last().copied().unwrap_or(1);
            dev::out(crate::gpu::ops::nnops::standardize(dev::buf(x), n, eps), x.shape().to_vec())
        },
    }
}

/// Axis permutation (output axis `i` is input axis `perm[i]`).
pub(crate) fn permute<T: Float>(x: &Tensor<T>, perm: &[usize]) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => layout::permute(x, perm),
        Device::Gpu => on_gpu! {
            let shape = layout::permuted_shape(x.shape(), perm)?;
            let st = strides(x.shape());
            let src: Vec<usize> = perm.iter().map(|&p| st[p]).collect();
            Ok(dev::out(crate::gpu::ops::layout::strided_copy(dev::buf(x), &shape, &src, 0, 1.0), shape))
        },
    }
}

/// Broadcast to `shape` (copies).
pub(crate) fn expand<T: Float>(x: &Tensor<T>, shape: &[usize]) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => layout::expand(x, shape),
        Device::Gpu => on_gpu! {
            layout::check_expand(x.shape(), shape)?;
            dev::check("expand", numel(shape))?;
            let src = crate::shape::broadcast_strides(x.shape(), shape);
            Ok(dev::out(crate::gpu::ops::layout::strided_copy(dev::buf(x), shape, &src, 0, 1.0), shape.to_vec()))
        },
    }
}

/// Entries `start..start+len` of `axis`.
pub(crate) fn narrow<T: Float>(x: &Tensor<T>, axis: usize, start: usize, len: usize) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => layout::narrow(x, axis, start, len),
        Device::Gpu => on_gpu! {
            layout::check_narrow(x.shape(), axis, start, len)?;
            let mut shape = x.shape().to_vec();
            shape[axis] = len;
            let src = strides(x.shape());
            let offset = start * src[axis];
            Ok(dev::out(crate::gpu::ops::layout::strided_copy(dev::buf(x), &shape, &src, offset, 1.0), shape))
        },
    }
}

/// Concatenation along `axis`.
pub(crate) fn cat<T: Float>(xs: &[&Tensor<T>], axis: usize) -> Result<Tensor<T>> {
    match device_of(xs) {
        Device::Cpu => layout::cat(xs, axis),
        Device::Gpu => on_gpu! {
            let shape = layout::cat_shape(xs, axis)?;
            dev::check("cat", numel(&shape))?;
            let (outer, _, inner) = split_at_axis(&shape, axis);
            let placed = xs.iter().map(|x| dev::up(x)).collect::<Result<Vec<_>>>()?;
            let parts: Vec<_> = placed.iter().map(|x| (dev::buf(x), x.shape()[axis])).collect();
            let y = crate::gpu::ops::layout::cat(&parts, outer, inner);
            Ok(dev::out(y, shape))
        },
    }
}

/// Entries of `axis` picked by `idx`.
pub(crate) fn index_select<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize]) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => index::index_select(x, axis, idx),
        Device::Gpu => on_gpu! {
            check_axis("index_select", axis, x.shape())?;
            let (outer, n, inner) = split_at_axis(x.shape(), axis);
            index::check_indices("index_select", idx, n)?;
            let mut shape = x.shape().to_vec();
            shape[axis] = idx.len();
            dev::check("index_select", numel(&shape))?;
            Ok(dev::out(crate::gpu::ops::index::index_select(dev::buf(x), outer, n, inner, idx), shape))
        },
    }
}

/// `x` with `src` entries added at `idx` along `axis`.
pub(crate) fn index_add<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize], src: &Tensor<T>) -> Result<Tensor<T>> {
    index::check_index_add(x.shape(), src.shape(), axis, idx)?;
    let (outer, n, inner) = split_at_axis(x.shape(), axis);
    match device_of(&[x, src]) {
        Device::Cpu => {
            let mut out = x.to_vec();
            index::index_add_into(&mut out, n, src.data(), idx.len(), outer, inner, idx);
            Tensor::new(out, x.shape())
        }
        Device::Gpu => on_gpu! {
            let (x, src) = (dev::up(x)?, dev::up(src)?);
            let y = crate::gpu::ops::layout::strided_copy(dev::buf(&x), x.shape(), &strides(x.shape()), 0, 1.0);
            crate::gpu::ops::index::index_add_into(&y, n, dev::buf(&src), outer, inner, idx);
            Ok(dev::out(y, x.shape().to_vec()))
        },
    }
}

/// `out[o, j, i] = x[o, idx[o, j, i], i]` along `axis`.
pub(crate) fn gather<T: Float>(x: &Tensor<T>, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => index::gather(x, axis, idx_shape, idx),
        Device::Gpu => on_gpu! {
            index::gather_shape(x.shape(), axis, idx_shape, idx)?;
            let (outer, n, inner) = split_at_axis(x.shape(), axis);
            let y = crate::gpu::ops::index::gather(dev::buf(x), outer, n, inner, idx_shape[axis], idx);
            Ok(dev::out(y, idx_shape.to_vec()))
        },
    }
}

/// Row sums (or means) by sorted segment id.
pub(crate) fn segment_reduce<T: Float>(x: &Tensor<T>, seg: &[usize], n: usize, mean: bool) -> Result<Tensor<T>> {
    match x.device() {
        Device::Cpu => index::segment_reduce(x, seg, n, mean),
        Device::Gpu => on_gpu! {
            if x.rank() == 0 {
                return Err(invalid("segment_sum", "needs at least one dim"));
            }
            index::check_segments(seg, x.shape()[0], n)?;
            let inner = x.numel() / x.shape()[0].max(1);
            let mut shape = x.shape().to_vec();
            shape[0] = n;
            dev::check("segment_sum", numel(&shape))?;
            let y = crate::gpu::ops::index::segment_reduce(dev::buf(x), x.shape()[0], inner, seg, n, mean);
            Ok(dev::out(y, shape))
        },
    }
}

/// `mask ? a : b` over the broadcast `shape`.
pub(crate) fn where_select<T: Float>(
    mask: &Arc<Vec<bool>>,
    shape: &[usize],
    a: &Tensor<T>,
    b: &Tensor<T>,
) -> Result<Tensor<T>> {
    match device_of(&[a, b]) {
        Device::Cpu => Tensor::new(elementwise::where_select(mask, shape, a, b), shape),
        Device::Gpu => on_gpu! {
            let m: Vec<u32> = mask.iter().map(|&v| v as u32).collect();
            let m = crate::gpu::DeviceBuffer::upload_u32(&m);
            let (a, b) = (dev::up(a)?, dev::up(b)?);
            let y = crate::gpu::ops::elementwise::where_select(&m, shape, dev::buf(&a), a.shape(), dev::buf(&b), b.shape());
            Ok(dev::out(y, shape.to_vec()))
        },
    }
}

// ---------------------------------------------------------------------------------------
// Kernels of the gradient rules.

/// `g * op'(x)`.
pub(crate) fn unary_backward<T: Float>(g: &Tensor<T>, x: &Tensor<T>, y: &Tensor<T>, op: UnaryOp) -> Result<Tensor<T>> {
    match device_of(&[g, x, y]) {
        Device::Cpu => Tensor::new(elementwise::unary_backward(g.data(), x.data(), y.data(), op), g.shape()),
        Device::Gpu => on_gpu! {
            let (g, x, y) = (dev::up(g)?, dev::up(x)?, dev::up(y)?);
            let dx = crate::gpu::ops::elementwise::unary_backward(dev::buf(&g), dev::buf(&x), dev::buf(&y), op);
            Ok(dev::out(dx, g.shape().to_vec()))
        },
    }
}

/// `g * act'` of a layer's activation, through its output `y`.
pub(crate) fn activation_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>, act: Activation) -> Result<Tensor<T>> {
    match device_of(&[y, g]) {
        Device::Cpu => Tensor::new(nnops::activation_backward(y.data(), g.data(), act), g.shape()),
        Device::Gpu => {
            // relu'(x) = [y > 0] and tanh'(x) = 1 - y^2 are functions of the output alone, so
            // the unary derivative kernel reads `y` for both of its inputs.
            let op = match act {
                Activation::Identity => return Ok(g.clone()),
                Activation::Relu => UnaryOp::Relu,
                Activation::Tanh => UnaryOp::Tanh,
            };
            unary_backward(g, y, y, op)
        }
    }
}

/// The gradients of a binary op's two operands, each present when wanted.
pub(crate) type GradPair<T> = (Option<Tensor<T>>, Option<Tensor<T>>);

/// The gradients of a broadcasting binary op: `(dA, dB)` summed back to the operands'
/// shapes, each computed only when wanted.
pub(crate) fn binary_backward<T: Float>(
    g: &Tensor<T>,
    a: &Tensor<T>,
    b: &Tensor<T>,
    y: &Tensor<T>,
    op: BinaryOp,
    wants: (bool, bool),
) -> Result<GradPair<T>> {
    let (wa, wb) = wants;
    if matches!(op, BinaryOp::Add | BinaryOp::Sub) {
        // No kernel but a negation, on either device: `g` itself (its storage shared, not
        // copied) for `a` and, of an add, for `b`, summed over the broadcast dims where an
        // operand has fewer elements.
        let ga = wa.then(|| sum_to_shape(g, a.shape())).transpose()?;
        let gb = match (wb, op) {
            (false, _) => None,
            (true, BinaryOp::Add) => Some(sum_to_shape(g, b.shape())?),
            (true, _) => Some(sum_to_shape(&unary(g, UnaryOp::Neg), b.shape())?),
        };
        return Ok((ga, gb));
    }
    match device_of(&[g, a, b, y]) {
        Device::Cpu => {
            let (ga, gb) = elementwise::binary_backward(g.data(), a, b, y, op, wants);
            Ok((
                ga.map(|v| Tensor::from_parts(v, a.shape().to_vec())),
                gb.map(|v| Tensor::from_parts(v, b.shape().to_vec())),
            ))
        }
        Device::Gpu => on_gpu! {
            // The rules of `elementwise::binary_backward` (mul, div, minimum, maximum): both
            // gradients in one launch, `b` scaling rows of `a` with the rows' sums inside it
            // (as the CPU's fast path does).
            use crate::gpu::ops::elementwise as gpu;
            let shape = y.shape();
            let full = |t: Tensor<T>, target: &Tensor<T>| -> Result<Tensor<T>> { sum_to_shape(&t, target.shape()) };
            let (gd, ad, bd, yd) = (dev::up(g)?, dev::up(a)?, dev::up(b)?, dev::up(y)?);
            let (gbuf, abuf, bbuf) = (dev::buf(&gd), dev::buf(&ad), dev::buf(&bd));
            if matches!(op, BinaryOp::Div | BinaryOp::Mul) && a.numel() == y.numel() && elementwise::is_row_broadcast(b.shape(), shape) {
                let (ga, gb) = gpu::row_scale_backward(gbuf, abuf, bbuf, op == BinaryOp::Div, wants);
                return Ok((ga.map(|v| dev::out(v, a.shape().to_vec())), gb.map(|v| dev::out(v, b.shape().to_vec()))));
            }
            let (ga, gb) = gpu::binary_backward(gbuf, abuf, a.shape(), bbuf, b.shape(), dev::buf(&yd), shape, op, wants);
            let (ga, gb) = (ga.map(|v| dev::out(v, shape.to_vec())), gb.map(|v| dev::out(v, shape.to_vec())));
            Ok((ga.map(|t| full(t, a)).transpose()?, gb.map(|t| full(t, b)).transpose()?))
        },
    }
}

/// `g` (shaped like a broadcast result) summed back to `target`, a broadcast operand's shape.
pub(crate) fn sum_to_shape<T: Float>(g: &Tensor<T>, target: &[usize]) -> Result<Tensor<T>> {
    if g.shape() == target {
        return Ok(g.clone());
    }
    match g.device() {
        Device::Cpu => Ok(reduce::sum_to_shape(g.clone(), target)),
        Device::Gpu => on_gpu! {
            // The CPU's steps: leading dims as one block, then every dim where target has 1.
            let lead = g.rank() - target.len();
            let mut cur = g.clone();
            if lead > 0 {
                let outer: usize = cur.shape()[..lead].iter().product();
                let rest = cur.numel() / outer.max(1);
                let y = crate::gpu::ops::reduce::reduce_axis(dev::buf(&cur), 1, outer, rest, false, 1.0);
                cur = dev::out(y, cur.shape()[lead..].to_vec());
            }
            for (d, &t) in target.iter().enumerate() {
                if t == 1 && cur.shape()[d] != 1 {
                    let (outer, len, inner) = split_at_axis(cur.shape(), d);
                    let y = crate::gpu::ops::reduce::reduce_axis(dev::buf(&cur), outer, len, inner, false, 1.0);
                    let mut s = cur.shape().to_vec();
                    s[d] = 1;
                    cur = dev::out(y, s);
                }
            }
            Ok(cur)
        },
    }
}

/// Gradient of a reduction of `x` (output `y`) over `axis`.
pub(crate) fn reduce_backward<T: Float>(
    x: &Tensor<T>,
    y: &Tensor<T>,
    g: &Tensor<T>,
    op: ReduceOp,
    axis: Option<usize>,
) -> Result<Tensor<T>> {
    let (outer, len, inner) = match axis {
        Some(a) => split_at_axis(x.shape(), a),
        None => (1, x.numel(), 1),
    };
    match device_of(&[x, y, g]) {
        Device::Cpu => {
            Tensor::new(reduce::reduce_backward(x.data(), y.data(), g.data(), op, outer, len, inner), x.shape())
        }
        Device::Gpu => on_gpu! {
            let (x, y, g) = (dev::up(x)?, dev::up(y)?, dev::up(g)?);
            let dx = match op {
                ReduceOp::Max => crate::gpu::ops::reduce::max_backward(dev::buf(&x), dev::buf(&y), dev::buf(&g), outer, len, inner),
                ReduceOp::Sum | ReduceOp::Mean => {
                    let s = if op == ReduceOp::Mean { 1.0 / len as f64 } else { 1.0 };
                    // g [outer, inner] read with stride 0 along the reduced axis.
                    crate::gpu::ops::layout::strided_copy(dev::buf(&g), &[outer, len, inner], &[inner, 0, 1], 0, s)
                }
            };
            Ok(dev::out(dx, x.shape().to_vec()))
        },
    }
}

/// Gradient of softmax: `y * (g - sum(g * y))` row by row.
pub(crate) fn softmax_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>) -> Result<Tensor<T>> {
    let n = y.shape().last().copied().unwrap_or(1);
    match device_of(&[y, g]) {
        Device::Cpu => Tensor::new(nnops::softmax_backward(y.data(), g.data(), n), y.shape()),
        Device::Gpu => on_gpu! {
            let (y, g) = (dev::up(y)?, dev::up(g)?);
            Ok(dev::out(crate::gpu::ops::nnops::softmax_backward(dev::buf(&y), dev::buf(&g), n), y.shape().to_vec()))
        },
    }
}

/// Gradient of the last-axis norm: `g x / y` row by row.
pub(crate) fn norm_last_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>) -> Result<Tensor<T>> {
    let n = x.shape().last().copied().unwrap_or(1);
    match device_of(&[x, y, g]) {
        Device::Cpu => Tensor::new(nnops::norm_last_backward(x.data(), y.data(), g.data(), n), x.shape()),
        Device::Gpu => on_gpu! {
            let (x, y, g) = (dev::up(x)?, dev::up(y)?, dev::up(g)?);
            let dx = crate::gpu::ops::nnops::norm_last_backward(dev::buf(&x), dev::buf(&y), dev::buf(&g), n);
            Ok(dev::out(dx, x.shape().to_vec()))
        },
    }
}

/// Gradient of standardisation over the last axis.
pub(crate) fn standardize_backward<T: Float>(
    x: &Tensor<T>,
    y: &Tensor<T>,
    g: &Tensor<T>,
    eps: f64,
) -> Result<Tensor<T>> {
    let n = x.shape().last().copied().unwrap_or(1);
    match device_of(&[x, y, g]) {
        Device::Cpu => Tensor::new(nnops::standardize_backward(x.data(), y.data(), g.data(), n, eps), x.shape()),
        Device::Gpu => on_gpu! {
            let (x, y, g) = (dev::up(x)?, dev::up(y)?, dev::up(g)?);
            let dx = crate::gpu::ops::nnops::standardize_backward(dev::buf(&x), dev::buf(&y), dev::buf(&g), n, eps);
            Ok(dev::out(dx, x.shape().to_vec()))
        },
    }
}

/// Gradient of a segment sum (or mean): row `r` gets `g[seg[r]]` (divided by the count).
pub(crate) fn segment_backward<T: Float>(
    x_shape: &[usize],
    g: &Tensor<T>,
    seg: &[usize],
    mean: bool,
) -> Result<Tensor<T>> {
    let rows = x_shape[0];
    let inner = numel(x_shape) / rows.max(1);
    let segments = g.shape()[0];
    match g.device() {
        Device::Cpu => Tensor::new(index::segment_backward(g.data(), seg, segments, inner, mean), x_shape),
        Device::Gpu => on_gpu! {
            let dx = crate::gpu::ops::index::segment_backward(dev::buf(g), rows, inner, seg, segments, mean);
            Ok(dev::out(dx, x_shape.to_vec()))
        },
    }
}

/// `g` where the mask is `pick`, 0 elsewhere, summed back to `target`.
pub(crate) fn where_backward<T: Float>(
    g: &Tensor<T>,
    mask: &Arc<Vec<bool>>,
    pick: bool,
    target: &[usize],
) -> Result<Tensor<T>> {
    match g.device() {
        Device::Cpu => {
            let masked = crate::pool::zip_map(g.data(), mask, |gv, m| if m == pick { gv } else { T::ZERO });
            Ok(reduce::sum_to_shape(Tensor::from_parts(masked, g.shape().to_vec()), target))
        }
        Device::Gpu => {
            let zero = Tensor::scalar(T::ZERO);
            let (a, b) = if pick { (g, &zero) } else { (&zero, g) };
            sum_to_shape(&where_select(mask, g.shape(), a, b)?, target)
        }
    }
}
