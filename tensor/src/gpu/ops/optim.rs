//! Kernels of the optimiser and the numerical checks: Adam's step and a count of non-finite
//! values.

use super::{bits, kernel, u};
use crate::backend::AdamStep;
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};

const ADAM: Kernel = kernel!("adam", "adam.wgsl");
const NON_FINITE_ANY: Kernel = kernel!("non_finite_any", "non_finite_any.wgsl");

/// One Adam step: the new parameter and moments.
pub(crate) fn adam(
    p: &DeviceBuffer,
    g: &DeviceBuffer,
    m: &DeviceBuffer,
    v: &DeviceBuffer,
    s: AdamStep,
) -> (DeviceBuffer, DeviceBuffer, DeviceBuffer) {
    let n = p.len();
    let (p1, m1, v1) = (DeviceBuffer::uninit(n), DeviceBuffer::uninit(n), DeviceBuffer::uninit(n));
    let limit = s.clip.unwrap_or(0.0);
    let params = [
        u(n),
        bits(s.lr),
        bits(s.beta1),
        bits(s.beta2),
        bits(s.c1),
        bits(s.c2),
        bits(s.eps),
        s.clip.is_some() as u32,
        bits(-limit),
        bits(limit),
    ];
    let bufs = [p.buffer(), g.buffer(), m.buffer(), v.buffer(), p1.buffer(), m1.buffer(), v1.buffer()];
    device().launch_1d(&ADAM, &params, &bufs, n);
    (p1, m1, v1)
}

/// Whether each of `xs` holds a NaN or an infinity: one launch per tensor, every answer in one
/// buffer (1.0 where it does, else 0.0), so that one download brings them all back.
pub(crate) fn non_finite_any(xs: &[&DeviceBuffer]) -> DeviceBuffer {
    let flags = DeviceBuffer::zeros(xs.len());
    for (slot, x) in xs.iter().enumerate() {
        device().launch_1d(&NON_FINITE_ANY, &[u(x.len()), u(slot)], &[x.buffer(), flags.buffer()], x.len());
    }
    flags
}
