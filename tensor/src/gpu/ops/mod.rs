//! Rust wrappers of the WGSL kernels: each takes [`DeviceBuffer`]s and sizes, launches its
//! kernel and returns the output buffer. Shapes are checked by the callers (the same checks
//! as the CPU kernels, in `var_ops.rs` and `kernels/`).
//!
//! [`DeviceBuffer`]: super::DeviceBuffer

pub(crate) mod elementwise;
pub(crate) mod index;
pub(crate) mod layout;
pub(crate) mod matmul;
pub(crate) mod nnops;
pub(crate) mod optim;
pub(crate) mod reduce;

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

/// The shape block of a strided kernel (`strided_fns.wgsl`): rank, dims, then each operand's
/// strides. At most 8 dims.
pub(crate) fn strided_params(shape: &[usize], strides: &[&[usize]]) -> Vec<u32> {
    assert!(shape.len() <= 8, "device kernels take at most 8 dims, got shape {shape:?}");
    let mut p = vec![u(shape.len())];
    p.extend(shape.iter().map(|&d| u(d)));
    for s in strides {
        p.extend(s.iter().map(|&d| u(d)));
    }
    p
}
