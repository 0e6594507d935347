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

/// What the binary kernel computes: a [`BinaryOp`] or one of the 0/1 masks of the min/max
/// gradients.
#[derive(Clone, Copy, Debug)]
pub(crate) enum BinaryCode {
    /// The forward op.
    Op(BinaryOp),
    /// 1 where `a <= b`, else 0.
    LessEq,
    /// 1 where `a >= b`, else 0.
    GreaterEq,
}

impl BinaryCode {
    fn code(self) -> u32 {
        match self {
            BinaryCode::Op(BinaryOp::Add) => 0,
            BinaryCode::Op(BinaryOp::Sub) => 1,
            BinaryCode::Op(BinaryOp::Mul) => 2,
            BinaryCode::Op(BinaryOp::Div) => 3,
            BinaryCode::Op(BinaryOp::Minimum) => 4,
            BinaryCode::Op(BinaryOp::Maximum) => 5,
            BinaryCode::LessEq => 6,
            BinaryCode::GreaterEq => 7,
        }
    }
}

/// `op(a, b)` over the broadcast `shape` (`a` and `b` broadcast to it).
pub(crate) fn binary(
    a: &DeviceBuffer,
    a_shape: &[usize],
    b: &DeviceBuffer,
    b_shape: &[usize],
    shape: &[usize],
    op: BinaryCode,
) -> DeviceBuffer {
    let n = numel(shape);
    let out = DeviceBuffer::uninit(n);
    let mut params = vec![u(n), op.code(), 0, 0];
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
