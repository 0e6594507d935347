//! Kernels of the optimiser and the numerical checks: Adam's step and a count of non-finite
//! values.

use super::{bits, kernel, u};
use crate::gpu::context::Kernel;
use crate::gpu::{DeviceBuffer, device};

const ADAM: Kernel = kernel!("adam", "adam.wgsl");
const NON_FINITE_ANY: Kernel = kernel!("non_finite_any", "non_finite_any.wgsl");

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
    /// When set, each gradient element is first clipped to `[-clip, clip]` (as
    /// `nn::clip_elementwise` and the `clamp` op do: `min(max(g, -clip), clip)` in f32).
    pub clip: Option<f64>,
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
