//! Every op of the tape, on the device its operands live on, through that device's
//! [`Backend`](crate::backend::Backend).
//!
//! The forward methods in `var_ops.rs` and the gradient rules in `backprop.rs` call these
//! functions and never a device directly. Each checks what it can check without the values,
//! checks that its operands share a device ([`require_on`]: no op moves a tensor; operands
//! on two devices are an error naming both), then hands them to that device's backend
//! ([`on_backend!`]). The gradient rules with no kernel of their own (add, sub,
//! where, broadcast sums) are written here as arithmetic over the other ops.

use std::sync::Arc;

use crate::backend::{Backend, GradPair, on_backend};
use crate::device::Device;
use crate::element::Float;
use crate::error::Result;
use crate::kernels::matmul::MatMulPlan;
use crate::kernels::nnops::WeightRows;
use crate::kernels::{index, layout};
use crate::op::{Activation, BinaryOp, ReduceOp, UnaryOp};
use crate::shape::{broadcast_shapes, split_at_axis};
use crate::tensor::Tensor;

/// The device an op with these operands runs on: the GPU if any operand is there.
pub(crate) fn device_of<T: Float>(xs: &[&Tensor<T>]) -> Device {
    if xs.iter().any(|x| x.device() == Device::Gpu) { Device::Gpu } else { Device::Cpu }
}

/// `x` itself where it is on `device`, the device its op runs on; an error naming both
/// devices where it is not. No op moves an operand: a tensor changes device only where the
/// caller says so (`Tensor::to_device`, `Tensor::to_host`, `to_device_all`, or a leaf
/// recorded on a `Tape::on(device)`).
pub(crate) fn require_on<T: Float>(x: &Tensor<T>, device: Device) -> Result<&Tensor<T>> {
    if x.device() == device {
        return Ok(x);
    }
    Err(crate::error::invalid(
        "operands",
        format!(
            "one is on the {} and another on the {}; tensors move between devices only when asked \
             (`Tensor::to_device`, `to_host`, or leaves recorded on a `Tape::on(device)`)",
            x.device().name(),
            device.name()
        ),
    ))
}

// ---------------------------------------------------------------------------------------
// Forward ops.

/// `y = op(x)` element-wise.
pub(crate) fn unary<T: Float>(x: &Tensor<T>, op: UnaryOp) -> Tensor<T> {
    on_backend!(x.device(), B => B::unary(x, op))
}

/// `op(a, b)` with broadcasting.
pub(crate) fn binary<T: Float>(a: &Tensor<T>, b: &Tensor<T>, op: BinaryOp) -> Result<Tensor<T>> {
    let shape =
        if a.shape() == b.shape() { a.shape().to_vec() } else { broadcast_shapes(op.name(), a.shape(), b.shape())? };
    let dev = device_of(&[a, b]);
    let (a, b) = (require_on(a, dev)?, require_on(b, dev)?);
    on_backend!(dev, B => B::binary(a, b, &shape, op))
}

/// Reduction over `axis` (or everything).
pub(crate) fn reduce<T: Float>(x: &Tensor<T>, op: ReduceOp, axis: Option<usize>, keepdim: bool) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::reduce(x, op, axis, keepdim))
}

/// `op(a) @ op(b)` over the last two dims, batch dims broadcast.
pub(crate) fn matmul<T: Float>(a: &Tensor<T>, b: &Tensor<T>, ta: bool, tb: bool) -> Result<Tensor<T>> {
    let plan = MatMulPlan::new(a.shape(), b.shape(), ta, tb)?;
    let dev = device_of(&[a, b]);
    let (a, b) = (require_on(a, dev)?, require_on(b, dev)?);
    on_backend!(dev, B => B::matmul(a, b, ta, tb, &plan))
}

/// `act(sum_i x_i @ w_i[row_i..row_i + k_i, cols] + b[cols])` for the terms `(x_i, w_i,
/// row_i)` and the output columns `cols = (start, len)` (`None`: all of them).
pub(crate) fn linear_sum<T: Float>(
    parts: &[WeightRows<'_, T>],
    b: Option<&Tensor<T>>,
    act: Activation,
    cols: Option<(usize, usize)>,
) -> Result<Tensor<T>> {
    let mut all: Vec<&Tensor<T>> = parts.iter().flat_map(|&(x, w, _)| [x, w]).collect();
    all.extend(b);
    let dev = device_of(&all);
    all.iter().try_for_each(|x| require_on(x, dev).map(|_| ()))?;
    on_backend!(dev, B => B::linear_sum(parts, b, act, cols))
}

/// Softmax over the last axis.
pub(crate) fn softmax<T: Float>(x: &Tensor<T>) -> Tensor<T> {
    on_backend!(x.device(), B => B::softmax(x))
}

/// Zeros of `shape` written on `device` (no upload).
pub(crate) fn zeros<T: Float>(device: Device, shape: &[usize]) -> Tensor<T> {
    on_backend!(device, B => B::zeros(shape))
}

/// The Gaussian radial basis `[E, K]` of host values on `device` (`Backend::gaussian_basis`).
pub(crate) fn gaussian_basis<T: Float>(device: Device, x: &[f64], centres: &[f64], coeff: f64) -> Result<Tensor<T>> {
    on_backend!(device, B => B::gaussian_basis(x, centres, coeff))
}

/// `sqrt(sum x^2 + eps)` over the last axis, kept as size 1.
pub(crate) fn norm_last<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
    on_backend!(x.device(), B => B::norm_last(x, eps))
}

/// `(x - mean) / sqrt(var + eps)` over the last axis.
pub(crate) fn standardize<T: Float>(x: &Tensor<T>, eps: f64) -> Tensor<T> {
    on_backend!(x.device(), B => B::standardize(x, eps))
}

/// Axis permutation (output axis `i` is input axis `perm[i]`).
pub(crate) fn permute<T: Float>(x: &Tensor<T>, perm: &[usize]) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::permute(x, perm))
}

/// Broadcast to `shape` (copies).
pub(crate) fn expand<T: Float>(x: &Tensor<T>, shape: &[usize]) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::expand(x, shape))
}

/// Entries `start..start+len` of `axis`.
pub(crate) fn narrow<T: Float>(x: &Tensor<T>, axis: usize, start: usize, len: usize) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::narrow(x, axis, start, len))
}

/// Concatenation along `axis`.
pub(crate) fn cat<T: Float>(xs: &[&Tensor<T>], axis: usize) -> Result<Tensor<T>> {
    let shape = layout::cat_shape(xs, axis)?;
    let dev = device_of(xs);
    xs.iter().try_for_each(|x| require_on(x, dev).map(|_| ()))?;
    on_backend!(dev, B => B::cat(xs, axis, &shape))
}

/// Entries of `axis` picked by `idx`.
pub(crate) fn index_select<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize]) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::index_select(x, axis, idx))
}

/// `x` with `src` entries added at `idx` along `axis`.
pub(crate) fn index_add<T: Float>(x: &Tensor<T>, axis: usize, idx: &[usize], src: &Tensor<T>) -> Result<Tensor<T>> {
    index::check_index_add(x.shape(), src.shape(), axis, idx)?;
    let split = split_at_axis(x.shape(), axis);
    let dev = device_of(&[x, src]);
    let (x, src) = (require_on(x, dev)?, require_on(src, dev)?);
    on_backend!(dev, B => B::index_add(x, split, idx, src))
}

/// `out[o, j, i] = x[o, idx[o, j, i], i]` along `axis`.
pub(crate) fn gather<T: Float>(x: &Tensor<T>, axis: usize, idx_shape: &[usize], idx: &[usize]) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::gather(x, axis, idx_shape, idx))
}

/// Row sums (or means) by sorted segment id.
pub(crate) fn segment_reduce<T: Float>(x: &Tensor<T>, seg: &[usize], n: usize, mean: bool) -> Result<Tensor<T>> {
    on_backend!(x.device(), B => B::segment_reduce(x, seg, n, mean))
}

/// `mask ? a : b` over the broadcast `shape`.
pub(crate) fn where_select<T: Float>(
    mask: &Arc<Vec<bool>>,
    shape: &[usize],
    a: &Tensor<T>,
    b: &Tensor<T>,
) -> Result<Tensor<T>> {
    let dev = device_of(&[a, b]);
    let (a, b) = (require_on(a, dev)?, require_on(b, dev)?);
    on_backend!(dev, B => B::where_select(mask, shape, a, b))
}

// ---------------------------------------------------------------------------------------
// Gradient kernels, and the gradient rules written as arithmetic over the ops above.

/// `g * op'(x)`.
pub(crate) fn unary_backward<T: Float>(g: &Tensor<T>, x: &Tensor<T>, y: &Tensor<T>, op: UnaryOp) -> Result<Tensor<T>> {
    let dev = device_of(&[g, x, y]);
    let (g, x, y) = (require_on(g, dev)?, require_on(x, dev)?, require_on(y, dev)?);
    Ok(on_backend!(dev, B => B::unary_backward(g, x, y, op)))
}

/// `g * act'` of a layer's activation, through its output `y`.
pub(crate) fn activation_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>, act: Activation) -> Result<Tensor<T>> {
    if act == Activation::Identity {
        return Ok(g.clone());
    }
    let dev = device_of(&[y, g]);
    let (y, g) = (require_on(y, dev)?, require_on(g, dev)?);
    Ok(on_backend!(dev, B => B::activation_backward(y, g, act)))
}

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
        // d(a ± b) = (g, ±g): `g` itself (its storage shared, not copied), summed over the
        // broadcast dims where an operand has fewer elements.
        let ga = wa.then(|| sum_to_shape(g, a.shape())).transpose()?;
        let gb = match (wb, op) {
            (false, _) => None,
            (true, BinaryOp::Add) => Some(sum_to_shape(g, b.shape())?),
            (true, _) => Some(sum_to_shape(&unary(g, UnaryOp::Neg), b.shape())?),
        };
        return Ok((ga, gb));
    }
    let dev = device_of(&[g, a, b, y]);
    let (g, a, b, y) = (require_on(g, dev)?, require_on(a, dev)?, require_on(b, dev)?, require_on(y, dev)?);
    on_backend!(dev, B => B::binary_backward(g, a, b, y, op, wants))
}

/// `g` (shaped like a broadcast result) summed back to `target`, a broadcast operand's shape.
pub(crate) fn sum_to_shape<T: Float>(g: &Tensor<T>, target: &[usize]) -> Result<Tensor<T>> {
    if g.shape() == target {
        return Ok(g.clone());
    }
    on_backend!(g.device(), B => B::sum_to_shape(g, target))
}

/// Gradient of a reduction of `x` (output `y`) over `axis`.
pub(crate) fn reduce_backward<T: Float>(
    x: &Tensor<T>,
    y: &Tensor<T>,
    g: &Tensor<T>,
    op: ReduceOp,
    axis: Option<usize>,
) -> Result<Tensor<T>> {
    let split = match axis {
        Some(a) => split_at_axis(x.shape(), a),
        None => (1, x.numel(), 1),
    };
    let dev = device_of(&[x, y, g]);
    let (x, y, g) = (require_on(x, dev)?, require_on(y, dev)?, require_on(g, dev)?);
    on_backend!(dev, B => B::reduce_backward(x, y, g, op, split))
}

/// Gradient of softmax: `y * (g - sum(g * y))` row by row.
pub(crate) fn softmax_backward<T: Float>(y: &Tensor<T>, g: &Tensor<T>) -> Result<Tensor<T>> {
    let dev = device_of(&[y, g]);
    let (y, g) = (require_on(y, dev)?, require_on(g, dev)?);
    Ok(on_backend!(dev, B => B::softmax_backward(y, g)))
}

/// Gradient of the last-axis norm: `g x / y` row by row.
pub(crate) fn norm_last_backward<T: Float>(x: &Tensor<T>, y: &Tensor<T>, g: &Tensor<T>) -> Result<Tensor<T>> {
    let dev = device_of(&[x, y, g]);
    let (x, y, g) = (require_on(x, dev)?, require_on(y, dev)?, require_on(g, dev)?);
    Ok(on_backend!(dev, B => B::norm_last_backward(x, y, g)))
}

/// Gradient of standardisation over the last axis.
pub(crate) fn standardize_backward<T: Float>(
    x: &Tensor<T>,
    y: &Tensor<T>,
    g: &Tensor<T>,
    eps: f64,
) -> Result<Tensor<T>> {
    let dev = device_of(&[x, y, g]);
    let (x, y, g) = (require_on(x, dev)?, require_on(y, dev)?, require_on(g, dev)?);
    Ok(on_backend!(dev, B => B::standardize_backward(x, y, g, eps)))
}

/// Gradient of a segment sum (or mean): row `r` gets `g[seg[r]]` (divided by the count).
pub(crate) fn segment_backward<T: Float>(
    x_shape: &[usize],
    g: &Tensor<T>,
    seg: &[usize],
    mean: bool,
) -> Result<Tensor<T>> {
    on_backend!(g.device(), B => B::segment_backward(x_shape, g, seg, mean))
}

/// `g` where the mask is `pick`, 0 elsewhere, summed back to `target`: a selection between
/// `g` and a zero, then a sum over the broadcast dims.
pub(crate) fn where_backward<T: Float>(
    g: &Tensor<T>,
    mask: &Arc<Vec<bool>>,
    pick: bool,
    target: &[usize],
) -> Result<Tensor<T>> {
    let zero = zeros(g.device(), &[]);
    let (a, b) = if pick { (g, &zero) } else { (&zero, g) };
    sum_to_shape(&where_select(mask, g.shape(), a, b)?, target)
}
