//! The GPU device's stand-ins in a build without the cargo feature `gpu` (compiled as the
//! module `gpu` then): no tensor can be on the GPU, moving one there fails with an error
//! that says how to get the device, and the GPU's storage type has no values, so every
//! device arm elsewhere is statically unreachable.

use std::marker::PhantomData;

use crate::element::Float;
use crate::error::{Result, TensorError};
use crate::tensor::Tensor;

/// A type without values.
pub(crate) enum Never {}

/// The GPU storage of a tensor: none exists in this build (a zero-sized type without
/// values, so `Storage` keeps the host variant's size and its matches have one arm).
pub(crate) struct DeviceStorage<T: Float>(Never, PhantomData<T>);

impl<T: Float> Clone for DeviceStorage<T> {
    fn clone(&self) -> Self {
        match self.0 {}
    }
}

impl<T: Float> DeviceStorage<T> {
    /// Never called: no value of this type exists.
    pub(crate) fn download(&self) -> Vec<T> {
        match self.0 {}
    }
}

/// Moving a tensor to the GPU: an error in this build.
pub(crate) fn upload<T: Float>(_values: &[T], _shape: &[usize]) -> Result<Tensor<T>> {
    Err(TensorError::Device {
        op: "to_device",
        detail: "this build has no GPU device: rebuild with the cargo feature `gpu`".into(),
    })
}

/// The GPU's backend in this build: the name resolves to the CPU's so that the device's arm
/// of `backend::on_backend!` compiles; it is never taken, as no tensor is on the GPU.
pub(crate) mod backend {
    pub(crate) use crate::backend::cpu::Cpu as Gpu;
}

/// Whether this build has the GPU device.
pub(crate) const BUILT: bool = false;

/// No adapter: an error saying how to get the device.
pub(crate) fn adapter_description() -> Result<String> {
    Err(TensorError::Device {
        op: "gpu",
        detail: "this build has no GPU device: rebuild with the cargo feature `gpu`".into(),
    })
}

/// Nothing to wait for.
pub(crate) fn synchronize() {}

/// Nothing to label.
pub(crate) fn label_launches(_op: Option<(&'static str, bool)>) {}

/// Nothing crossed: there is no device.
pub(crate) fn transfers() -> crate::device::Transfers {
    crate::device::Transfers::default()
}
