//! [`Tensor`]: an immutable n-dimensional array with contiguous row-major storage, on the
//! host or (feature `gpu`) on the GPU.
//!
//! Values are shared (`Arc`), so cloning a tensor or reshaping it copies no data. Tensors are
//! plain values: they record nothing. Differentiation happens on a [`crate::Tape`], whose
//! [`crate::Var`]s hold tensors; an op runs on the device its inputs live on.

use std::sync::Arc;

use crate::device::Device;
use crate::element::Float;
use crate::error::{Result, invalid, mismatch};
use crate::shape::numel;

/// An n-dimensional array of `T` in row-major (C) order.
#[derive(Clone)]
pub struct Tensor<T: Float> {
    pub(crate) shape: Vec<usize>,
    pub(crate) data: Storage<T>,
}

/// Where the elements live: the one place a tensor's storage names its device (the
/// backends, `backend/`, compute on it).
#[derive(Clone)]
pub(crate) enum Storage<T: Float> {
    /// Host memory (the CPU device).
    Host(Arc<Buffer<T>>),
    /// A GPU buffer of f32 values (`gpu::DeviceStorage`: a shared `DeviceData`; in a build
    /// without the feature `gpu` a type without values, so this variant takes no space and
    /// every match on it compiles away).
    #[allow(dead_code, reason = "constructed only by the GPU device, in builds with the feature `gpu`")]
    Device(crate::gpu::DeviceStorage<T>),
}

impl<T: Float> PartialEq for Tensor<T> {
    fn eq(&self, other: &Self) -> bool {
        self.shape == other.shape && self.data() == other.data()
    }
}

/// Element storage that returns large buffers to the pool when dropped.
#[derive(PartialEq)]
pub(crate) struct Buffer<T: Float>(pub(crate) Vec<T>);

impl<T: Float> Clone for Buffer<T> {
    fn clone(&self) -> Self {
        let mut v = crate::pool::with_capacity(self.0.len());
        v.extend_from_slice(&self.0);
        Buffer(v)
    }
}

impl<T: Float> Drop for Buffer<T> {
    fn drop(&mut self) {
        crate::pool::recycle(std::mem::take(&mut self.0));
    }
}

impl<T: Float> std::fmt::Debug for Tensor<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tensor<{}>{:?}", T::NAME, self.shape)?;
        if self.device() != Device::Cpu {
            write!(f, " on {}", self.device())?;
        }
        if let (Storage::Host(b), true) = (&self.data, self.numel() <= 16) {
            write!(f, " {:?}", b.0)?;
        }
        Ok(())
    }
}

impl<T: Float> Tensor<T> {
    /// Wraps `data` as a tensor of `shape`; fails if the element count differs.
    pub fn new(data: Vec<T>, shape: &[usize]) -> Result<Self> {
        if data.len() != numel(shape) {
            return Err(mismatch(
                "Tensor::new",
                &[shape],
                format!("{} elements given for a shape of {}", data.len(), numel(shape)),
            ));
        }
        Ok(Self { shape: shape.to_vec(), data: Storage::Host(Arc::new(Buffer(data))) })
    }

    /// Internal constructor for kernels whose output size is right by construction.
    pub(crate) fn from_parts(data: Vec<T>, shape: Vec<usize>) -> Self {
        debug_assert_eq!(data.len(), numel(&shape));
        Self { shape, data: Storage::Host(Arc::new(Buffer(data))) }
    }

    /// Converts `f64` values (handy in tests and for constants).
    pub fn from_f64(data: &[f64], shape: &[usize]) -> Result<Self> {
        Self::new(data.iter().map(|&v| T::from_f64(v)).collect(), shape)
    }

    /// A tensor of `shape` filled with `value`.
    pub fn full(shape: &[usize], value: T) -> Self {
        Self::from_parts(crate::pool::filled(numel(shape), value), shape.to_vec())
    }

    /// A tensor of zeros.
    pub fn zeros(shape: &[usize]) -> Self {
        Self::full(shape, T::ZERO)
    }

    /// A tensor of ones.
    pub fn ones(shape: &[usize]) -> Self {
        Self::full(shape, T::ONE)
    }

    /// A rank-0 tensor holding one value.
    pub fn scalar(value: T) -> Self {
        Self::from_parts(vec![value], vec![])
    }

    /// The shape.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// The number of dimensions.
    pub fn rank(&self) -> usize {
        self.shape.len()
    }

    /// The number of elements.
    pub fn numel(&self) -> usize {
        numel(&self.shape)
    }

    /// The device the elements live on.
    pub fn device(&self) -> Device {
        match &self.data {
            Storage::Host(_) => Device::Cpu,
            Storage::Device(_) => Device::Gpu,
        }
    }

    /// The elements in row-major order, of a tensor on the host. Nothing moves behind the
    /// caller's back: a tensor on another device panics here, naming [`Tensor::to_host`],
    /// the explicit transfer ([`Tensor::host_data`] asks without panicking).
    pub fn data(&self) -> &[T] {
        match &self.data {
            Storage::Host(b) => &b.0,
            Storage::Device(_) => panic!("{}", self.not_on_host("data")),
        }
    }

    /// The elements of a tensor on the host; `None` for a tensor on another device.
    pub fn host_data(&self) -> Option<&[T]> {
        match &self.data {
            Storage::Host(b) => Some(&b.0),
            Storage::Device(_) => None,
        }
    }

    /// Mutable access to the elements of a tensor on the host (copies first if the storage
    /// is shared); a tensor on another device panics, as [`Tensor::data`] does.
    pub fn data_mut(&mut self) -> &mut [T] {
        if self.device() != Device::Cpu {
            panic!("{}", self.not_on_host("data_mut"));
        }
        self.host_data_mut().expect("on the host")
    }

    /// The message of a host-only access to a tensor on another device.
    fn not_on_host(&self, what: &str) -> String {
        format!(
            "Tensor::{what} of a tensor on the {}: move it with `to_host()` (an explicit transfer) first",
            self.device()
        )
    }

    /// Mutable access to the elements of a tensor on the host (copied first if the storage is
    /// shared); `None` for a tensor on another device, whose values stay there.
    pub fn host_data_mut(&mut self) -> Option<&mut [T]> {
        match &mut self.data {
            Storage::Host(b) => Some(Arc::make_mut(b).0.as_mut_slice()),
            Storage::Device(_) => None,
        }
    }

    /// The same tensor on the host: itself when it is there, else its values downloaded (an
    /// explicit transfer; [`Tensor::to_device`] with [`Device::Cpu`]).
    pub fn to_host(&self) -> Result<Tensor<T>> {
        self.to_device(Device::Cpu)
    }

    /// The elements as a new vector (of a tensor on the host: [`Tensor::data`]).
    pub fn to_vec(&self) -> Vec<T> {
        self.data().to_vec()
    }

    /// The value of a one-element tensor.
    pub fn item(&self) -> Result<T> {
        if self.device() != Device::Cpu {
            return Err(invalid("item", self.not_on_host("item")));
        }
        if self.numel() == 1 {
            Ok(self.data()[0])
        } else {
            Err(invalid("item", format!("tensor of shape {:?} is not a single value", self.shape)))
        }
    }

    /// The same elements under another shape with the same element count (no copy).
    pub fn reshape(&self, shape: &[usize]) -> Result<Self> {
        if numel(shape) != self.numel() {
            return Err(mismatch("reshape", &[&self.shape, shape], "element counts differ"));
        }
        Ok(Self { shape: shape.to_vec(), data: self.data.clone() })
    }

    /// [`Tensor::reshape`] of a tensor the caller gives up (keeps its storage unshared).
    pub(crate) fn into_reshaped(self, shape: &[usize]) -> Result<Self> {
        if numel(shape) != self.numel() {
            return Err(mismatch("reshape", &[&self.shape, shape], "element counts differ"));
        }
        Ok(Self { shape: shape.to_vec(), data: self.data })
    }

    /// Converts the elements to another precision (on the host).
    pub fn cast<U: Float>(&self) -> Tensor<U> {
        Tensor::from_parts(self.data().iter().map(|v| U::from_f64(v.to_f64())).collect(), self.shape.clone())
    }

    /// Whether every element is finite (on the GPU, checked there: one value comes back).
    pub fn all_finite(&self) -> bool {
        match self.host_data() {
            Some(values) => values.iter().all(|v| v.is_finite()),
            None => crate::tensor_ops::first_non_finite(std::slice::from_ref(self)).is_ok_and(|i| i.is_none()),
        }
    }

    /// Whether both tensors have the same shape and every element differs by at most
    /// `atol + rtol * |other|`.
    pub fn all_close(&self, other: &Self, rtol: f64, atol: f64) -> bool {
        self.shape == other.shape
            && self.data().iter().zip(other.data().iter()).all(|(a, b)| {
                let (a, b) = (a.to_f64(), b.to_f64());
                (a - b).abs() <= atol + rtol * b.abs()
            })
    }

    /// The elements as a vector, without copying when the storage is on the host and not
    /// shared.
    pub(crate) fn into_vec(self) -> Vec<T> {
        match self.data {
            Storage::Host(b) => match Arc::try_unwrap(b) {
                Ok(mut b) => std::mem::take(&mut b.0),
                // Still shared: a copy, into a recycled buffer.
                Err(shared) => crate::pool::map(&shared.0, |v| v),
            },
            Storage::Device(d) => d.download(),
        }
    }

    /// [`Tensor::to_device`] of a tensor the caller gives up: itself when it is already there
    /// (not a clone, so storage no other tensor holds stays writable in place).
    pub fn into_device(self, device: Device) -> Result<Tensor<T>> {
        if self.device() == device { Ok(self) } else { self.to_device(device) }
    }

    /// The same tensor on `device` (no copy when it is already there). Moving to the GPU
    /// fails without the `gpu` feature, with no adapter, for `f64` (the GPU holds `f32`) and
    /// for tensors larger than a device buffer; moving to the CPU waits for the values.
    pub fn to_device(&self, device: Device) -> Result<Tensor<T>> {
        match (device, &self.data) {
            (Device::Cpu, Storage::Host(_)) | (Device::Gpu, Storage::Device(_)) => Ok(self.clone()),
            (Device::Cpu, Storage::Device(d)) => Ok(Tensor::from_parts(d.download(), self.shape.clone())),
            (Device::Gpu, Storage::Host(b)) => crate::gpu::upload(&b.0, &self.shape),
        }
    }
}

#[cfg(test)]
mod layout_tests {
    /// Without the feature `gpu` the device variant takes no space: a tensor's storage is one
    /// pointer, as it was before the GPU existed (its matches then have one arm).
    #[test]
    fn a_cpu_only_build_keeps_the_storage_one_pointer() {
        if !crate::gpu::BUILT {
            assert_eq!(std::mem::size_of::<super::Storage<f32>>(), std::mem::size_of::<usize>());
        }
    }
}
