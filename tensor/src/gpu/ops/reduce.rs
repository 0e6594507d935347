//! Reductions over one axis (sum, mean, max) in a fixed order, and the gradient of max.

use super::{bits, kernel, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};

const REDUCE_AXIS: Kernel = kernel!("reduce_axis", "reduce_axis.wgsl");
const MAX_BACKWARD: Kernel = kernel!("max_backward", "max_backward.wgsl");

/// Entries of the reduced axis one thread sums before a second pass adds the partial sums:
/// a long axis (a sum over every element) is split into fixed chunks, so the order depends
/// on the shape only.
const CHUNK: usize = 1024;

/// `out[o, i] = reduce_k x[o, k, i]` (`max` or a sum), times `scale`.
pub(crate) fn reduce_axis(
    x: &DeviceBuffer,
    outer: usize,
    len: usize,
    inner: usize,
    max: bool,
    scale: f64,
) -> DeviceBuffer {
    if len > CHUNK && outer * inner < 4096 {
        // Two passes: chunk partials [outer, chunks, inner], then their reduction.
        let chunks = len.div_ceil(CHUNK);
        let partial = pass(x, outer, len, inner, CHUNK, chunks, max, 1.0);
        return reduce_axis(&partial, outer, chunks, inner, max, scale);
    }
    pass(x, outer, len, inner, len.max(1), 1, max, scale)
}

#[allow(clippy::too_many_arguments)]
fn pass(
    x: &DeviceBuffer,
    outer: usize,
    len: usize,
    inner: usize,
    chunk: usize,
    chunks: usize,
    max: bool,
    scale: f64,
) -> DeviceBuffer {
    let n = outer * chunks * inner;
    let out = DeviceBuffer::uninit(n);
    let params = [u(outer), u(len), u(inner), u(chunk), u(chunks), max as u32, bits(scale)];
    device().launch_1d(&REDUCE_AXIS, &params, &[x.buffer(), out.buffer()], n);
    out
}

/// Gradient of a max over an axis: `g` to the first maximal entry.
pub(crate) fn max_backward(
    x: &DeviceBuffer,
    y: &DeviceBuffer,
    g: &DeviceBuffer,
    outer: usize,
    len: usize,
    inner: usize,
) -> DeviceBuffer {
    let dx = DeviceBuffer::uninit(outer * len * inner);
    device().launch_1d(
        &MAX_BACKWARD,
        &[u(outer), u(len), u(inner)],
        &[x.buffer(), y.buffer(), g.buffer(), dx.buffer()],
        outer * inner,
    );
    dx
}
