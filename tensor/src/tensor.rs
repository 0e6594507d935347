//! [`Tensor`]: an immutable n-dimensional array with contiguous row-major storage.
//!
//! Values are shared (`Arc`), so cloning a tensor or reshaping it copies no data. Tensors are
//! plain values: they record nothing. Differentiation happens on a [`crate::Tape`], whose
//! [`crate::Var`]s hold tensors.

use std::sync::Arc;

use crate::element::Float;
use crate::error::{Result, invalid, mismatch};
use crate::shape::numel;

/// An n-dimensional array of `T` in row-major (C) order.
#[derive(Clone, PartialEq)]
pub struct Tensor<T: Float> {
    shape: Vec<usize>,
    data: Arc<Buffer<T>>,
}

/// Element storage that returns large buffers to the pool when dropped.
#[derive(PartialEq)]
struct Buffer<T: Float>(Vec<T>);

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
        if self.data.0.len() <= 16 {
            write!(f, " {:?}", self.data.0)?;
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
        Ok(Self { shape: shape.to_vec(), data: Arc::new(Buffer(data)) })
    }

    /// Internal constructor for kernels whose output size is right by construction.
    pub(crate) fn from_parts(data: Vec<T>, shape: Vec<usize>) -> Self {
        debug_assert_eq!(data.len(), numel(&shape));
        Self { shape, data: Arc::new(Buffer(data)) }
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
        self.data.0.len()
    }

    /// The elements in row-major order.
    pub fn data(&self) -> &[T] {
        &self.data.0
    }

    /// Mutable access to the elements (copies first if the storage is shared).
    pub fn data_mut(&mut self) -> &mut [T] {
        Arc::make_mut(&mut self.data).0.as_mut_slice()
    }

    /// The elements as a new vector.
    pub fn to_vec(&self) -> Vec<T> {
        self.data.0.to_vec()
    }

    /// The value of a one-element tensor.
    pub fn item(&self) -> Result<T> {
        if self.data.0.len() == 1 {
            Ok(self.data.0[0])
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

    /// Converts the elements to another precision.
    pub fn cast<U: Float>(&self) -> Tensor<U> {
        Tensor::from_parts(self.data.0.iter().map(|v| U::from_f64(v.to_f64())).collect(), self.shape.clone())
    }

    /// Whether every element is finite.
    pub fn all_finite(&self) -> bool {
        self.data.0.iter().all(|v| v.is_finite())
    }

    /// Whether both tensors have the same shape and every element differs by at most
    /// `atol + rtol * |other|`.
    pub fn all_close(&self, other: &Self, rtol: f64, atol: f64) -> bool {
        self.shape == other.shape
            && self.data.0.iter().zip(other.data.0.iter()).all(|(a, b)| {
                let (a, b) = (a.to_f64(), b.to_f64());
                (a - b).abs() <= atol + rtol * b.abs()
            })
    }

    /// The elements as a vector, without copying when the storage is not shared.
    pub(crate) fn into_vec(self) -> Vec<T> {
        match Arc::try_unwrap(self.data) {
            Ok(mut b) => std::mem::take(&mut b.0),
            Err(shared) => shared.0.clone(),
        }
    }
}
