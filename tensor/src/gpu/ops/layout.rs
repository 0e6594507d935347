//! Layout kernels: strided copies (permute, expand, narrow) and block copies along one axis
//! (concatenation and its adjoint).

use super::{bits, kernel, strided_params, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};
use crate::shape::numel;

const STRIDED_COPY: Kernel = kernel!("strided_copy", "strided_fns.wgsl", "strided_copy.wgsl");
const BLOCK_COPY: Kernel = kernel!("block_copy", "block_copy.wgsl");

/// `out[i] = scale * x[offset + sum_d idx_d(i) * strides[d]]` over `shape` (row-major).
pub(crate) fn strided_copy(
    x: &DeviceBuffer,
    shape: &[usize],
    strides: &[usize],
    offset: usize,
    scale: f64,
) -> DeviceBuffer {
    let n = numel(shape);
    let out = DeviceBuffer::uninit(n);
    let mut params = vec![u(n), u(offset), bits(scale)];
    params.extend(strided_params(shape, &[strides]));
    device().launch_1d(&STRIDED_COPY, &params, &[x.buffer(), out.buffer()], n);
    out
}

/// Where a block copy reads and writes along the axis: `len` entries from `src_start` of an
/// axis of `src_n` entries to `dst_start` of an axis of `dst_n` entries, for `outer` blocks
/// of `inner` values each.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Block {
    /// Product of the dims before the axis.
    pub outer: usize,
    /// Product of the dims after the axis.
    pub inner: usize,
    /// Entries copied.
    pub len: usize,
    /// The source's axis length.
    pub src_n: usize,
    /// First source entry.
    pub src_start: usize,
    /// The destination's axis length.
    pub dst_n: usize,
    /// First destination entry.
    pub dst_start: usize,
}

/// Copies (or with `accumulate` adds) a block of `src` into `dst` in place.
pub(crate) fn block_copy_into(dst: &DeviceBuffer, src: &DeviceBuffer, b: Block, accumulate: bool) {
    let n = b.outer * b.len * b.inner;
    let params =
        [u(b.outer), u(b.len), u(b.inner), u(b.src_n), u(b.src_start), u(b.dst_n), u(b.dst_start), accumulate as u32];
    device().launch_1d(&BLOCK_COPY, &params, &[src.buffer(), dst.buffer()], n);
}
