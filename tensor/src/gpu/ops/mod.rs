//! Rust wrappers of the WGSL kernels: each takes [`DeviceBuffer`]s and sizes, launches its
//! kernel and returns the output buffer. Shapes are checked by the callers (the same checks
//! as the CPU kernels, in `var_ops.rs` and `kernels/`).
//!
//! [`DeviceBuffer`]: super::DeviceBuffer

pub(crate) mod elementwise;

/// A kernel whose module is `common.wgsl` followed by the given files of `wgsl/`, with entry
/// point `main`.
macro_rules! kernel {
    ($name:literal, $($file:literal),+) => {
        $crate::gpu::context::Kernel {
            name: $name,
            source: concat!(include_str!("../wgsl/common.wgsl"), $(include_str!(concat!("../wgsl/", $file))),+),
            entry: "main",
        }
    };
}
pub(crate) use kernel;

/// The bits of an f32 constant, as kernels read it (`pf(i)` in WGSL).
pub(crate) fn bits(v: f64) -> u32 {
    (v as f32).to_bits()
}

/// A size as a kernel parameter (device tensors hold fewer than 2^32 values: checked on upload).
pub(crate) fn u(n: usize) -> u32 {
    u32::try_from(n).expect("device sizes fit in u32 (checked when the tensor was placed)")
}
