//! Operations on plain tensors, off the tape, on the device the tensors live on: what an
//! optimiser and the numerical checks need (element-wise maps, finiteness, sums of squares,
//! Adam's step), so that parameters and gradients on the GPU stay there.

use crate::device::Device;
use crate::element::Float;
use crate::error::Result;
use crate::op::{ReduceOp, UnaryOp};
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

    /// The sum of the squared elements, in f64 on the host; on the GPU the squares are summed
    /// there (in f32) and one value comes back.
    pub fn sum_of_squares(&self) -> Result<f64> {
        match self.device() {
            Device::Cpu => Ok(self.data().iter().map(|v| v.to_f64() * v.to_f64()).sum()),
            Device::Gpu => {
                let s = crate::dispatch::reduce(&self.map_unary(UnaryOp::Square), ReduceOp::Sum, None, false)?;
                Ok(s.data()[0].to_f64())
            }
        }
    }
}

/// The index of the first tensor holding a NaN or an infinity, if any. On the GPU every
/// tensor is checked there, one launch each, and only their flags come back (one transfer
/// for all of them).
pub fn first_non_finite<T: Float>(ts: &[Tensor<T>]) -> Result<Option<usize>> {
    if crate::dispatch::device_of(&ts.iter().collect::<Vec<_>>()) == Device::Cpu {
        return Ok(ts.iter().position(|t| !t.all_finite()));
    }
    #[cfg(feature = "gpu")]
    {
        // One flag per tensor comes back, in one download (a host tensor in the list is
        // uploaded first).
        let placed: Vec<Tensor<T>> = ts.iter().map(|t| t.to_device(Device::Gpu)).collect::<Result<_>>()?;
        let bufs: Vec<&crate::gpu::DeviceBuffer> =
            placed.iter().map(|t| t.device_buffer().expect("on the GPU")).collect();
        let flags = crate::gpu::ops::optim::non_finite_any(&bufs).download();
        Ok(flags.iter().position(|&f| f != 0.0))
    }
    #[cfg(not(feature = "gpu"))]
    unreachable!("no tensor is on the GPU without the `gpu` feature")
}

/// One Adam step on the GPU (`crate::gpu::AdamStep` has the formula's constants): the new
/// parameter and moments, as new tensors on the device. The moments are f32 there (f64 on
/// the host, where `nn::Adam` keeps them).
#[cfg(feature = "gpu")]
pub fn adam_update<T: Float>(
    p: &Tensor<T>,
    g: &Tensor<T>,
    m: &Tensor<f32>,
    v: &Tensor<f32>,
    step: crate::gpu::AdamStep,
) -> Result<(Tensor<T>, Tensor<f32>, Tensor<f32>)> {
    let shape = p.shape().to_vec();
    for (name, n) in [("gradient", g.numel()), ("first moment", m.numel()), ("second moment", v.numel())] {
        if n != p.numel() {
            return Err(crate::error::mismatch("adam_update", &[&shape, &[n]], format!("the {name} has {n} values")));
        }
    }
    let (p, g) = (p.to_device(Device::Gpu)?, g.to_device(Device::Gpu)?);
    let (m, v) = (m.to_device(Device::Gpu)?, v.to_device(Device::Gpu)?);
    let (p1, m1, v1) = crate::gpu::ops::optim::adam(
        p.device_buffer().expect("on the GPU"),
        g.device_buffer().expect("on the GPU"),
        m.device_buffer().expect("on the GPU"),
        v.device_buffer().expect("on the GPU"),
        step,
    );
    Ok((Tensor::from_device(p1, shape.clone()), Tensor::from_device(m1, shape.clone()), Tensor::from_device(v1, shape)))
}
