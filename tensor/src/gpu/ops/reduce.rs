//! Reductions over one axis (sum, mean, max) in a fixed order, and the gradient of max.

use super::{bits, kernel, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};

const REDUCE_AXIS: Kernel = kernel!("reduce_axis", "reduce_axis.wgsl");
const MAX_BACKWARD: Kernel = kernel!("max_backward", "max_backward.wgsl");

/// Entries of the reduced axis one pass reduces per output before a second pass combines
/// the partials: a long axis (a sum over every element) is split into fixed chunks, so the
/// order depends on the shape only.
const CHUNK: usize = 1024;

/// Threads of one workgroup (`reduce_axis.wgsl`'s `@workgroup_size`).
const GROUP: usize = 256;

/// Outputs side by side in a workgroup when the reduced entries are `inner` apart: enough
/// neighbouring columns for a warp's reads to fill whole cache lines.
const COLUMNS: usize = 32;

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

/// The threads that share one output (a power of two, at most a workgroup): as many as
/// leave [`COLUMNS`] outputs side by side (all 256 threads on one output when `inner` is 1),
/// but no more than give each thread 4 entries of its `chunk`, nor than `cap`. From the
/// shape alone (and the process's cap), so the order of the sums is fixed.
fn lanes(chunk: usize, inner: usize, cap: usize) -> usize {
    let side_by_side = inner.next_power_of_two().min(COLUMNS);
    let by_entries = (chunk / 4).max(1);
    let by_entries = 1usize << by_entries.ilog2();
    (GROUP / side_by_side).min(by_entries).min(cap)
}

/// The most threads per output: the process's [`crate::device::GpuConfig::reduce_lanes`]
/// (a power of two from 1 to 256; 1 is one thread per output, the kernel of before
/// 2026-12-01), 256 by default.
fn lanes_cap() -> usize {
    crate::device::gpu_config().reduce_lanes as usize
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
    let lanes = lanes(chunk, inner, lanes_cap());
    // Contiguous entries (inner 1): an output's lanes side by side, else its neighbours.
    let lanes_fast = inner == 1;
    let params =
        [u(outer), u(len), u(inner), u(chunk), u(chunks), max as u32, bits(scale), u(lanes), lanes_fast as u32];
    // One workgroup for every GROUP / lanes outputs.
    let groups = n.div_ceil(GROUP / lanes);
    device().launch(&REDUCE_AXIS, &params, &[x.buffer(), out.buffer()], groups as u32);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes follow the shape: a bias gradient's 64 columns keep 32 outputs side by side
    /// (8 lanes), a sum over contiguous entries takes the whole workgroup, a short axis few
    /// lanes, and the cap bounds them all.
    #[test]
    fn lanes_follow_the_shape_and_the_cap() {
        assert_eq!(lanes(CHUNK, 64, GROUP), 8);
        assert_eq!(lanes(CHUNK, 1, GROUP), 256);
        assert_eq!(lanes(150, 64, GROUP), 8, "the second pass of a bias gradient");
        assert_eq!(lanes(5, 1, GROUP), 1);
        assert_eq!(lanes(64, 1, GROUP), 16, "at least 4 entries a lane");
        assert_eq!(lanes(CHUNK, 3, GROUP), 64);
        assert_eq!(lanes(CHUNK, 5000, GROUP), 8);
        assert_eq!(lanes(CHUNK, 1, 1), 1, "the cap of 1: one thread per output");
        assert_eq!(lanes(CHUNK, 1, 32), 32);
        for (chunk, inner) in [(1, 1), (7, 2), (1024, 17), (300, 300)] {
            let l = lanes(chunk, inner, GROUP);
            assert!(l.is_power_of_two() && l <= GROUP && GROUP.is_multiple_of(l), "{chunk} {inner}: {l}");
        }
    }
}
