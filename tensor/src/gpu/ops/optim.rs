//! Kernels of the optimiser and the numerical checks: Adam's step and a count of non-finite
//! values.

use super::{bits, kernel, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};

const ADAM: Kernel = kernel!("adam", "adam.wgsl");
const NON_FINITE: Kernel = kernel!("non_finite", "non_finite.wgsl");

/// Adam's constants for one step: the learning rate, the decays and the bias corrections
/// `c1 = 1/(1-b1^t)`, `c2 = 1/(1-b2^t)`.
#[derive(Clone, Copy, Debug)]
pub struct AdamStep {
    /// Learning rate of this step.
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// `1 / (1 - beta1^t)`.
    pub c1: f64,
    /// `1 / (1 - beta2^t)`.
    pub c2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
}

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
    let params = [u(n), bits(s.lr), bits(s.beta1), bits(s.beta2), bits(s.c1), bits(s.c2), bits(s.eps)];
    let bufs = [p.buffer(), g.buffer(), m.buffer(), v.buffer(), p1.buffer(), m1.buffer(), v1.buffer()];
    device().launch_1d(&ADAM, &params, &bufs, n);
    (p1, m1, v1)
}

/// 1 where a value is NaN or infinite, else 0.
pub(crate) fn non_finite_flags(x: &DeviceBuffer) -> DeviceBuffer {
    let n = x.len();
    let out = DeviceBuffer::uninit(n);
    device().launch_1d(&NON_FINITE, &[u(n)], &[x.buffer(), out.buffer()], n);
    out
}
