//! Errors of user-facing tensor calls: every message names the op and the shapes involved.

use std::fmt;

/// An error from a tensor operation that a caller can get wrong (shapes, axes, indices).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TensorError {
    /// Two or more shapes that the op cannot combine.
    ShapeMismatch {
        /// The operation that was called.
        op: &'static str,
        /// The shapes it was given, in argument order.
        shapes: Vec<Vec<usize>>,
        /// What the op expected.
        detail: String,
    },
    /// An axis that the tensor does not have.
    BadAxis {
        /// The operation that was called.
        op: &'static str,
        /// The axis asked for.
        axis: usize,
        /// The shape of the tensor.
        shape: Vec<usize>,
    },
    /// An index past the end of an axis.
    IndexOutOfRange {
        /// The operation that was called.
        op: &'static str,
        /// The offending index.
        index: usize,
        /// The length of the axis it indexes.
        len: usize,
    },
    /// A device problem: no GPU adapter, tensors on different devices, an op with no kernel
    /// on the device, a tensor too large for a device buffer.
    Device {
        /// The operation that was called.
        op: &'static str,
        /// What is wrong, and what to do about it.
        detail: String,
    },
    /// Any other invalid argument (empty lists, unsorted segment ids, ...).
    Invalid {
        /// The operation that was called.
        op: &'static str,
        /// What is wrong.
        detail: String,
    },
}

impl fmt::Display for TensorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TensorError::ShapeMismatch { op, shapes, detail } => {
                let shapes: Vec<String> = shapes.iter().map(|s| format!("{s:?}")).collect();
                write!(f, "{op}: incompatible shapes {}: {detail}", shapes.join(" and "))
            }
            TensorError::BadAxis { op, axis, shape } => {
                write!(f, "{op}: axis {axis} is out of range for shape {shape:?}")
            }
            TensorError::IndexOutOfRange { op, index, len } => {
                write!(f, "{op}: index {index} is out of range for an axis of length {len}")
            }
            TensorError::Invalid { op, detail } | TensorError::Device { op, detail } => write!(f, "{op}: {detail}"),
        }
    }
}

impl std::error::Error for TensorError {}

/// Result alias for tensor operations.
pub type Result<T> = std::result::Result<T, TensorError>;

/// Builds a [`TensorError::ShapeMismatch`].
pub(crate) fn mismatch(op: &'static str, shapes: &[&[usize]], detail: impl Into<String>) -> TensorError {
    TensorError::ShapeMismatch { op, shapes: shapes.iter().map(|s| s.to_vec()).collect(), detail: detail.into() }
}

/// Builds a [`TensorError::Invalid`].
pub(crate) fn invalid(op: &'static str, detail: impl Into<String>) -> TensorError {
    TensorError::Invalid { op, detail: detail.into() }
}

/// Checks that `axis` exists in `shape`.
pub(crate) fn check_axis(op: &'static str, axis: usize, shape: &[usize]) -> Result<()> {
    if axis < shape.len() { Ok(()) } else { Err(TensorError::BadAxis { op, axis, shape: shape.to_vec() }) }
}
