//! Forward kernels on plain [`Tensor`](crate::Tensor) values. The tape calls these to
//! compute values and `backprop.rs` calls them to compute gradients.
//!
//! Parallel work is split into chunks whose size does not depend on the number of threads,
//! and every output element is computed by one thread in a fixed order, so results are the
//! same bits whatever the thread count.

pub mod elementwise;
pub mod index;
pub mod layout;
pub mod matmul;
pub mod nnops;
pub mod reduce;
pub mod simd;

use rayon::prelude::*;

/// Element counts at or above this are processed in parallel.
pub(crate) const PAR_MIN: usize = 1 << 15;
/// Fixed chunk length for parallel element-wise work.
pub(crate) const PAR_CHUNK: usize = 1 << 13;

/// Fills `out[i] = f(i)` chunk by chunk, in parallel when large. `f` gets the chunk's start
/// offset and the chunk.
pub(crate) fn fill_chunks<T: Send>(out: &mut [T], f: impl Fn(usize, &mut [T]) + Sync) {
    if out.len() >= PAR_MIN {
        out.par_chunks_mut(PAR_CHUNK).enumerate().for_each(|(c, ch)| f(c * PAR_CHUNK, ch));
    } else {
        f(0, out);
    }
}

/// Runs `f(row_index, row)` for every row of length `row_len`, in parallel when large.
pub(crate) fn for_rows<T: Send>(out: &mut [T], row_len: usize, f: impl Fn(usize, &mut [T]) + Sync) {
    if row_len == 0 {
        return;
    }
    if out.len() >= PAR_MIN && out.len() / row_len > 1 {
        out.par_chunks_mut(row_len).enumerate().for_each(|(r, row)| f(r, row));
    } else {
        out.chunks_mut(row_len).enumerate().for_each(|(r, row)| f(r, row));
    }
}
