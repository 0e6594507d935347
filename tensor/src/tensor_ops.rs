//! Operations on plain tensors, off the tape, on the device the tensors live on: what an
//! optimiser and the numerical checks need (element-wise maps, finiteness, sums of squares,
//! Adam's step), so that parameters and gradients on the GPU stay there.

use crate::backend::{AdamStep, Backend, on_backend};
use crate::dispatch::require_on;
use crate::element::Float;
use crate::error::Result;
use crate::op::UnaryOp;
use crate::tensor::Tensor;

impl<T: Float> Tensor<T> {
    /// `op` applied to every element, on the tensor's device (no tape).
    pub fn map_unary(&self, op: UnaryOp) -> Tensor<T> {
        crate::dispatch::unary(self, op)
    }

    /// `op(self) @ op(other)` over the last two dims (transposes read as strides), on the
    /// operands' device, off the tape (benchmarks, inference).
    pub fn matmul_t(&self, other: &Tensor<T>, ta: bool, tb: bool) -> Result<Tensor<T>> {
        crate::dispatch::matmul(self, other, ta, tb)
    }

    /// The concatenation of `xs` along `axis`, on their device (no tape).
    pub fn cat(xs: &[&Tensor<T>], axis: usize) -> Result<Tensor<T>> {
        crate::dispatch::cat(xs, axis)
    }

    /// Entries `start..start + len` of `axis`, copied, on the tensor's device (no tape).
    pub fn narrow(&self, axis: usize, start: usize, len: usize) -> Result<Tensor<T>> {
        crate::dispatch::narrow(self, axis, start, len)
    }

    /// The sum of the squared elements, in f64 on the host; on the GPU the squares are summed
    /// there (in f32) and one value comes back.
    pub fn sum_of_squares(&self) -> Result<f64> {
        on_backend!(self.device(), B => B::sum_of_squares(self))
    }
}

/// The index of the first tensor holding a NaN or an infinity, if any. On the GPU every
/// tensor is checked there, one launch each, and only their flags come back (one transfer
/// for all of them); a list on both devices is checked where each tensor is.
pub fn first_non_finite<T: Float>(ts: &[Tensor<T>]) -> Result<Option<usize>> {
    let dev = device_of_all(ts);
    if ts.iter().all(|t| t.device() == dev) {
        return on_backend!(dev, B => B::first_non_finite(ts));
    }
    let (host, away): (Vec<usize>, Vec<usize>) = (0..ts.len()).partition(|&i| ts[i].device().is_host());
    let mut first = None;
    for group in [host, away] {
        let members: Vec<Tensor<T>> = group.iter().map(|&i| ts[i].clone()).collect();
        if let Some(k) = on_backend!(device_of_all(&members), B => B::first_non_finite(&members))? {
            first = Some(first.map_or(group[k], |f: usize| f.min(group[k])));
        }
    }
    Ok(first)
}

/// One Adam step with f32 moments on the parameter's device ([`AdamStep`] has the formula's
/// constants): the new parameter and moments, as new tensors there. (`nn::Adam` keeps f64
/// moments on the host, for an exact resume, and calls this on the GPU.)
pub fn adam_update<T: Float>(
    p: &Tensor<T>,
    g: &Tensor<T>,
    m: &Tensor<f32>,
    v: &Tensor<f32>,
    step: AdamStep,
) -> Result<(Tensor<T>, Tensor<f32>, Tensor<f32>)> {
    let shape = p.shape().to_vec();
    for (name, n) in [("gradient", g.numel()), ("first moment", m.numel()), ("second moment", v.numel())] {
        if n != p.numel() {
            return Err(crate::error::mismatch("adam_update", &[&shape, &[n]], format!("the {name} has {n} values")));
        }
    }
    let dev = p.device();
    let (g, m, v) = (require_on(g, dev)?, require_on(m, dev)?, require_on(v, dev)?);
    on_backend!(dev, B => B::adam_step(p, g, m, v, step))
}

/// The device ops over `ts` run on: the GPU if any of them is there, else the CPU (also for
/// none).
pub fn device_of_all<'a, T: Float>(ts: impl IntoIterator<Item = &'a Tensor<T>>) -> crate::device::Device {
    use crate::device::Device;
    if ts.into_iter().any(|t| t.device() == Device::Gpu) { Device::Gpu } else { Device::Cpu }
}

/// The tensors `ts` on `device`: to the host, every tensor on another device comes back in
/// one transfer (one staging buffer, one wait, no kernel); elsewhere, each one is moved on
/// its own. Tensors already there are returned as they are. The one place a batch of
/// tensors changes device.
pub fn to_device_all<T: Float>(ts: &[Tensor<T>], device: crate::device::Device) -> Result<Vec<Tensor<T>>> {
    use crate::device::Device;
    let away: Vec<usize> = (0..ts.len()).filter(|&i| ts[i].device() != device).collect();
    if device != Device::Cpu || away.is_empty() {
        return ts.iter().map(|t| t.to_device(device)).collect();
    }
    let moving: Vec<Tensor<T>> = away.iter().map(|&i| ts[i].clone()).collect();
    let from = device_of_all(&moving);
    let arrived = on_backend!(from, B => B::to_host_all(&moving))?;
    let mut out: Vec<Tensor<T>> = ts.to_vec();
    for (&i, t) in away.iter().zip(arrived) {
        out[i] = t;
    }
    Ok(out)
}

/// The tensors `ts` on the host, every one on another device in one transfer
/// ([`to_device_all`] to the CPU).
pub fn to_host_all<T: Float>(ts: &[Tensor<T>]) -> Result<Vec<Tensor<T>>> {
    to_device_all(ts, crate::device::Device::Cpu)
}
