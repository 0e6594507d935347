//! Layout kernels: strided copies (permute, expand, narrow) and block copies along one axis
//! (concatenation and its adjoint).

use super::{bits, kernel, strided_params, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};
use crate::shape::numel;

const STRIDED_COPY: Kernel = kernel!("strided_copy", "strided_fns.wgsl", "strided_copy.wgsl");
const BLOCK_COPY: Kernel = kernel!("block_copy", "block_copy.wgsl");
const CAT: Kernel = kernel!("cat", "cat.wgsl");

/// Parts [`cat`] joins in one launch (the kernel's source bindings).
const CAT_PARTS: usize = 6;

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

/// `parts` (buffers with their entries along the axis) joined along an axis: `outer` blocks
/// of `inner` values each, the output's axis the sum of the parts' entries. One launch per
/// six parts (`cat.wgsl`).
pub(crate) fn cat(parts: &[(&DeviceBuffer, usize)], outer: usize, inner: usize) -> DeviceBuffer {
    let total: usize = parts.iter().map(|p| p.1).sum();
    let out = DeviceBuffer::uninit(outer * total * inner);
    let mut dst_start = 0;
    for chunk in parts.chunks(CAT_PARTS) {
        let mut ends = [0u32; CAT_PARTS];
        let mut end = 0;
        for (slot, &(_, len)) in ends.iter_mut().zip(chunk) {
            end += len;
            *slot = u(end);
        }
        let mut params = vec![u(outer), u(total), u(inner), u(dst_start), u(end), u(chunk.len())];
        params.extend(ends);
        let mut buffers: Vec<&wgpu::Buffer> =
            (0..CAT_PARTS).map(|j| chunk.get(j).unwrap_or(&chunk[0]).0.buffer()).collect();
        buffers.push(out.buffer());
        device().launch_1d(&CAT, &params, &buffers, outer * end * inner);
        dst_start += end;
    }
    out
}
