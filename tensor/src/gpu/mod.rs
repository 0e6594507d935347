//! The GPU device (cargo feature `gpu`): f32 tensors in `wgpu` buffers and WGSL compute
//! kernels for every op of the tape, forward and backward.
//!
//! - [`context`]: the process's one device ([`gpu`]), its buffer pool and kernel launches.
//! - [`timing`]: every launch timed on the GPU's clock ([`Gpu::start_timing`]).
//! - [`DeviceBuffer`]: the storage of a tensor on the device (f32 values).
//! - `list_cache`: index lists (and what the index ops derive from them) kept on the device
//!   while they recur.
//! - `ops/`: one module per kernel family, each a thin Rust wrapper around a WGSL file in
//!   `wgsl/` that computes every output element in one thread, in a fixed order: no
//!   floating-point atomics, so a kernel gives the same bits on the same GPU and driver.
//!
//! Kernels follow one convention: binding 0 is `p: array<u32>` (sizes, and `f32` constants as
//! bits), bindings 1.. the buffers in the order the Rust wrapper passes them, the output last;
//! one-dimensional kernels use `@workgroup_size(256)` and the linear thread index
//! `gid.x + gid.y * num_workgroups.x * 256` (see `wgsl/common.wgsl`).

pub(crate) mod backend;
pub mod context;
pub(crate) mod list_cache;
pub(crate) mod ops;
mod storage;
pub mod timing;

pub use crate::backend::AdamStep;
pub use context::{AdapterInfo, Gpu, GpuStats, gpu};
pub(crate) use storage::{DeviceStorage, upload};
pub use timing::{KernelTimeline, OpLabel, TimelineRow};

/// Whether this build has the GPU device.
pub(crate) const BUILT: bool = true;

/// The process's GPU adapter, described (starting the device if needed).
pub(crate) fn adapter_description() -> crate::error::Result<String> {
    Ok(gpu()?.adapter().to_string())
}

/// Waits for every queued kernel, if the device was started (nothing to wait for otherwise).
pub(crate) fn synchronize() {
    if let Ok(gpu) = gpu() {
        gpu.synchronize();
    }
}

/// The device's transfer and launch counts so far (zeros before the device was started).
pub(crate) fn transfers() -> crate::device::Transfers {
    let Some(gpu) = context::started() else { return crate::device::Transfers::default() };
    let s = gpu.stats();
    crate::device::Transfers {
        uploads: s.uploads,
        upload_bytes: s.upload_bytes,
        downloads: s.downloads,
        download_bytes: s.download_bytes,
        launches: s.launches,
    }
}

/// While the GPU times its launches ([`Gpu::start_timing`]), gives the launches of the op
/// just run its name and direction (`None`: no op's, shown as `-`); nothing otherwise.
pub(crate) fn label_launches(op: Option<(&'static str, bool)>) {
    if timing::active()
        && let Ok(gpu) = gpu()
    {
        gpu.label_launches(op);
    }
}

/// The storage of one tensor on the GPU: `len` f32 values in a buffer that goes back to the
/// device's pool when dropped.
pub struct DeviceBuffer {
    buf: Option<wgpu::Buffer>,
    len: usize,
}

impl DeviceBuffer {
    /// Wraps a buffer holding `len` values.
    pub(crate) fn from_raw(buf: wgpu::Buffer, len: usize) -> Self {
        Self { buf: Some(buf), len }
    }

    /// A buffer of `len` values with unspecified contents, for a kernel that writes all of
    /// them.
    pub(crate) fn uninit(len: usize) -> Self {
        Self::from_raw(device().alloc(len), len)
    }

    /// A buffer of `len` zeros.
    pub(crate) fn zeros(len: usize) -> Self {
        Self::from_raw(device().alloc_zeroed(len), len)
    }

    /// Uploads f32 values.
    pub(crate) fn upload(values: &[f32]) -> Self {
        Self::from_raw(device().upload_words(bytemuck::cast_slice(values)), values.len())
    }

    /// Uploads u32 values (indices, masks): `len` counts the words.
    pub(crate) fn upload_u32(values: &[u32]) -> Self {
        Self::from_raw(device().upload_words(values), values.len())
    }

    /// The values, copied to the host.
    pub(crate) fn download(&self) -> Vec<f32> {
        let words = device().download_words(self.buffer(), self.len);
        bytemuck::cast_slice(&words).to_vec()
    }

    /// The number of values.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// The wgpu buffer.
    pub(crate) fn buffer(&self) -> &wgpu::Buffer {
        self.buf.as_ref().expect("a live buffer")
    }
}

impl Drop for DeviceBuffer {
    fn drop(&mut self) {
        if let (Some(b), Ok(g)) = (self.buf.take(), gpu()) {
            g.recycle(b);
        }
    }
}

impl std::fmt::Debug for DeviceBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "DeviceBuffer({} f32)", self.len)
    }
}

/// The device, for code that only runs once a tensor is on it (so [`gpu`] succeeded).
pub(crate) fn device() -> &'static Gpu {
    gpu().expect("a tensor is on the GPU, so the device was created")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::op::UnaryOp;

    /// An upload may land in a pooled buffer that a recorded, not yet submitted launch still
    /// reads: the staged copy runs after that launch, in the batch's order. Small uploads
    /// share a staging chunk; one larger than a chunk gets its own; each size twice, so the
    /// second goes through recycled staging memory.
    #[test]
    fn uploads_into_recycled_buffers_keep_the_batch_order() {
        for (round, len) in [1000usize, 1000, 5 << 20, 5 << 20].into_iter().enumerate() {
            let first: Vec<f32> = (0..len).map(|i| (i % 251) as f32 + round as f32).collect();
            let x = DeviceBuffer::upload(&first);
            let y = ops::elementwise::unary(&x, UnaryOp::Neg);
            drop(x);
            // The pool hands x's buffer to this upload while the negation still reads it.
            let second = vec![-7.0f32; len];
            let z = DeviceBuffer::upload(&second);
            let want: Vec<f32> = first.iter().map(|v| -v).collect();
            assert!(y.download() == want, "length {len}: the negation read the later upload's values");
            assert!(z.download() == second, "length {len}: the upload's values");
        }
    }
}
