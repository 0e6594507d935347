//! A tensor's storage on the GPU ([`DeviceData`]) and the tensor methods that reach it: the
//! device side of `tensor.rs`'s `Storage`.

use std::marker::PhantomData;
use std::sync::Arc;

use super::DeviceBuffer;
use crate::element::Float;
use crate::error::{Result, TensorError};
use crate::shape::numel;
use crate::tensor::{Storage, Tensor};

/// The storage of a tensor on the GPU: its values, shared between tensors.
pub(crate) type DeviceStorage<T> = Arc<DeviceData<T>>;

/// A tensor's values on the GPU.
pub(crate) struct DeviceData<T: Float> {
    /// The values on the device.
    pub(crate) buf: DeviceBuffer,
    /// The element type the tensor presents (f32 on the device).
    element: PhantomData<T>,
}

impl<T: Float> DeviceData<T> {
    /// The values copied to the host (waiting for the kernels that compute them): a
    /// transfer, counted in the device's statistics.
    pub(crate) fn download(&self) -> Vec<T> {
        T::from_f32_vec(self.buf.download())
    }
}

/// `values` (of `shape`) uploaded into a new tensor on the GPU; fails for `f64` (the GPU
/// holds `f32`), with no adapter, and for tensors larger than a device buffer.
pub(crate) fn upload<T: Float>(values: &[T], shape: &[usize]) -> Result<Tensor<T>> {
    let values = T::as_f32_slice(values).ok_or_else(|| TensorError::Device {
        op: "to_device",
        detail: format!("the GPU holds f32 tensors; this one is {}", T::NAME),
    })?;
    super::gpu()?.check_size("to_device", values.len())?;
    Ok(Tensor::from_device(DeviceBuffer::upload(values), shape.to_vec()))
}

impl<T: Float> Tensor<T> {
    /// Wraps a device buffer of `numel(shape)` values (a kernel's output).
    pub(crate) fn from_device(buf: DeviceBuffer, shape: Vec<usize>) -> Self {
        debug_assert_eq!(buf.len(), numel(&shape));
        Self { shape, data: Storage::Device(Arc::new(DeviceData { buf, element: PhantomData })) }
    }

    /// The device buffer of a tensor on the GPU if no other tensor shares it, else the tensor
    /// back unchanged.
    pub(crate) fn try_into_device_buffer(self) -> std::result::Result<DeviceBuffer, Self> {
        match self.data {
            Storage::Device(d) => match Arc::try_unwrap(d) {
                Ok(d) => Ok(d.buf),
                Err(shared) => Err(Self { shape: self.shape, data: Storage::Device(shared) }),
            },
            Storage::Host(_) => Err(self),
        }
    }

    /// The device buffer of a tensor on the GPU, taken without a copy when no other tensor
    /// shares it (else copied on the device).
    pub(crate) fn into_device_buffer(self) -> DeviceBuffer {
        self.try_into_device_buffer().unwrap_or_else(|shared| {
            let buf = shared.device_buffer().expect("on the device");
            super::ops::layout::strided_copy(buf, &shared.shape, &crate::shape::strides(&shared.shape), 0, 1.0)
        })
    }

    /// The device buffer of a tensor on the GPU.
    pub(crate) fn device_buffer(&self) -> Option<&DeviceBuffer> {
        match &self.data {
            Storage::Device(d) => Some(&d.buf),
            Storage::Host(_) => None,
        }
    }
}
