//! Element-wise kernels: unary maps and their derivatives, broadcasting binary maps, masked
//! selection and in-place accumulation.

use super::{bits, kernel, strided_params, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};
use crate::op::{BinaryOp, UnaryOp};
use crate::shape::{broadcast_strides, numel};

const UNARY_FORWARD: Kernel = kernel!("unary_forward", "unary_fns.wgsl", "unary_forward.wgsl");
const UNARY_BACKWARD: Kernel = kernel!("unary_backward", "unary_fns.wgsl", "unary_backward.wgsl");

/// The kernel's code and constants of a unary op (the `switch` in `unary_fns.wgsl`).
fn unary_code(op: UnaryOp) -> [u32; 3] {
    match op {
        UnaryOp::Neg => [0, 0, 0],
        UnaryOp::Exp => [1, 0, 0],
        UnaryOp::Log => [2, 0, 0],
        UnaryOp::Sqrt => [3, 0, 0],
        UnaryOp::Square => [4, 0, 0],
        UnaryOp::Tanh => [5, 0, 0],
        UnaryOp::Sigmoid => [6, 0, 0],
        UnaryOp::Relu => [7, 0, 0],
        UnaryOp::Softplus => [8, 0, 0],
        UnaryOp::Abs => [9, 0, 0],
        UnaryOp::Powf(q) => [10, bits(q), 0],
        UnaryOp::Clamp(lo, hi) => [11, bits(lo), bits(hi)],
        UnaryOp::Scale(c) => [12, bits(c), 0],
        UnaryOp::AddScalar(c) => [13, bits(c), 0],
    }
}

/// `y = op(x)`.
pub(crate) fn unary(x: &DeviceBuffer, op: UnaryOp) -> DeviceBuffer {
    let n = x.len();
    let y = DeviceBuffer::uninit(n);
    let [code, c0, c1] = unary_code(op);
    device().launch_1d(&UNARY_FORWARD, &[u(n), code, c0, c1], &[x.buffer(), y.buffer()], n);
    y
}

/// `dx = g * op'(x)` given the forward output `y`.
pub(crate) fn unary_backward(g: &DeviceBuffer, x: &DeviceBuffer, y: &DeviceBuffer, op: UnaryOp) -> DeviceBuffer {
    let n = g.len();
    let dx = DeviceBuffer::uninit(n);
    let [code, c0, c1] = unary_code(op);
    device().launch_1d(&UNARY_BACKWARD, &[u(n), code, c0, c1], &[g.buffer(), x.buffer(), y.buffer(), dx.buffer()], n);
    dx
}

const BINARY: Kernel = kernel!("binary", "strided_fns.wgsl", "binary.wgsl");
const WHERE: Kernel = kernel!("where", "strided_fns.wgsl", "where.wgsl");
const ADD_INTO: Kernel = kernel!("add_into", "add_into.wgsl");

/// The code of a binary op in the kernels' `switch` (`binary.wgsl`, `binary_backward.wgsl`).
fn binary_code(op: BinaryOp) -> u32 {
    match op {
        BinaryOp::Add => 0,
        BinaryOp::Sub => 1,
        BinaryOp::Mul => 2,
        BinaryOp::Div => 3,
        BinaryOp::Minimum => 4,
        BinaryOp::Maximum => 5,
    }
}

/// `op(a, b)` over the broadcast `shape` (`a` and `b` broadcast to it).
pub(crate) fn binary(
    a: &DeviceBuffer,
    a_shape: &[usize],
    b: &DeviceBuffer,
    b_shape: &[usize],
    shape: &[usize],
    op: BinaryOp,
) -> DeviceBuffer {
    let n = numel(shape);
    let out = DeviceBuffer::uninit(n);
    let mut params = vec![u(n), binary_code(op), 0, 0];
    params.extend(strided_params(shape, &[&broadcast_strides(a_shape, shape), &broadcast_strides(b_shape, shape)]));
    device().launch_1d(&BINARY, &params, &[a.buffer(), b.buffer(), out.buffer()], n);
    out
}

/// `mask ? a : b` over `shape` (`mask` holds one u32 per element; `a`, `b` broadcast).
pub(crate) fn where_select(
    mask: &DeviceBuffer,
    shape: &[usize],
    a: &DeviceBuffer,
    a_shape: &[usize],
    b: &DeviceBuffer,
    b_shape: &[usize],
) -> DeviceBuffer {
    let n = numel(shape);
    let out = DeviceBuffer::uninit(n);
    let mut params = vec![u(n)];
    params.extend(strided_params(shape, &[&broadcast_strides(a_shape, shape), &broadcast_strides(b_shape, shape)]));
    device().launch_1d(&WHERE, &params, &[mask.buffer(), a.buffer(), b.buffer(), out.buffer()], n);
    out
}

const BINARY_BACKWARD: Kernel = kernel!("binary_backward", "strided_fns.wgsl", "binary_backward.wgsl");
const ROW_SCALE_BACKWARD: Kernel = kernel!("row_scale_backward", "row_scale_backward.wgsl");

/// The gradients a binary op's backward wrote: `(ga, gb)`, each present when it was wanted.
pub(crate) type GradBuffers = (Option<DeviceBuffer>, Option<DeviceBuffer>);

/// The output buffer of a gradient: `n` values when it is wanted, else a one-element
/// placeholder the kernel never writes (two writable bindings may not share a buffer).
fn grad_slot(wanted: bool, n: usize) -> DeviceBuffer {
    DeviceBuffer::uninit(if wanted { n } else { 1 })
}

/// Both gradients of `op(a, b)` (mul, div, minimum, maximum) over the broadcast `shape`, in
/// one launch (`binary_backward.wgsl`): `g` and the output `y` are contiguous over `shape`,
/// `a` and `b` broadcast to it. Each wanted gradient comes back over `shape`, for the caller
/// to sum to its operand's shape.
#[allow(clippy::too_many_arguments)]
pub(crate) fn binary_backward(
    g: &DeviceBuffer,
    a: &DeviceBuffer,
    a_shape: &[usize],
    b: &DeviceBuffer,
    b_shape: &[usize],
    y: &DeviceBuffer,
    shape: &[usize],
    op: BinaryOp,
    (wa, wb): (bool, bool),
) -> GradBuffers {
    assert!(
        matches!(op, BinaryOp::Mul | BinaryOp::Div | BinaryOp::Minimum | BinaryOp::Maximum),
        "binary_backward kernel: {op:?} needs no kernel of its own"
    );
    let n = numel(shape);
    let (ga, gb) = (grad_slot(wa, n), grad_slot(wb, n));
    let mut params = vec![u(n), binary_code(op), u32::from(wa), u32::from(wb)];
    params.extend(strided_params(shape, &[&broadcast_strides(a_shape, shape), &broadcast_strides(b_shape, shape)]));
    let buffers = [g.buffer(), a.buffer(), b.buffer(), y.buffer(), ga.buffer(), gb.buffer()];
    device().launch_1d(&BINARY_BACKWARD, &params, &buffers, n);
    (wa.then_some(ga), wb.then_some(gb))
}

/// Both gradients of `a * b` (`div`: `a / b`) where `b` holds one value per row of `m =
/// a.len() / b.len()` values of `a`, in one launch with the rows' reductions inside
/// (`row_scale_backward.wgsl`, the CPU's `row_scale_backward` rules and order): `ga` shaped
/// like `a`, `gb` like `b`.
pub(crate) fn row_scale_backward(
    g: &DeviceBuffer,
    a: &DeviceBuffer,
    b: &DeviceBuffer,
    div: bool,
    (wa, wb): (bool, bool),
) -> GradBuffers {
    let (n, rows) = (a.len(), b.len());
    assert!(rows > 0 && n % rows == 0 && g.len() == n, "row_scale_backward: {n} values are not rows of {rows}");
    let (ga, gb) = (grad_slot(wa, n), grad_slot(wb, rows));
    let na = if wa { n } else { 0 };
    let params = [u(n), u(rows), u(n / rows), u32::from(div), u(na), u32::from(wb)];
    let threads = na + if wb { rows } else { 0 };
    device().launch_1d(
        &ROW_SCALE_BACKWARD,
        &params,
        &[g.buffer(), a.buffer(), b.buffer(), ga.buffer(), gb.buffer()],
        threads,
    );
    (wa.then_some(ga), wb.then_some(gb))
}

/// `dst += src` element by element (equal lengths).
pub(crate) fn add_into(dst: &DeviceBuffer, src: &DeviceBuffer) {
    let n = dst.len();
    device().launch_1d(&ADD_INTO, &[u(n)], &[src.buffer(), dst.buffer()], n);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::elementwise as cpu;
    use crate::tensor::Tensor;

    #[test]
    fn unary_ops_match_the_cpu() {
        let xs: Vec<f32> = (0..1000).map(|i| ((i as f32) * 0.37).sin() * 3.0).collect();
        let pos: Vec<f32> = xs.iter().map(|v| v.abs() + 0.5).collect();
        let g: Vec<f32> = (0..1000).map(|i| ((i as f32) * 0.11).cos()).collect();
        for op in [
            UnaryOp::Neg,
            UnaryOp::Exp,
            UnaryOp::Log,
            UnaryOp::Sqrt,
            UnaryOp::Square,
            UnaryOp::Tanh,
            UnaryOp::Sigmoid,
            UnaryOp::Relu,
            UnaryOp::Softplus,
            UnaryOp::Abs,
            UnaryOp::Powf(3.0),
            UnaryOp::Powf(0.5),
            UnaryOp::Clamp(-1.0, 2.0),
            UnaryOp::Scale(0.3),
            UnaryOp::AddScalar(1.5),
        ] {
            let input = if matches!(op, UnaryOp::Log | UnaryOp::Sqrt | UnaryOp::Powf(0.5)) { &pos } else { &xs };
            let xt = Tensor::new(input.clone(), &[1000]).unwrap();
            let want = cpu::unary(&xt, op);
            let xd = DeviceBuffer::upload(input);
            let yd = unary(&xd, op);
            let got = yd.download();
            for (a, b) in got.iter().zip(want.data()) {
                assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "{op:?}: {a} vs {b}");
            }
            let want_dx = cpu::unary_backward(&g, input, want.data(), op);
            let got_dx = unary_backward(&DeviceBuffer::upload(&g), &xd, &yd, op).download();
            for (a, b) in got_dx.iter().zip(&want_dx) {
                assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "{op:?} backward: {a} vs {b}");
            }
        }
    }
}
