//! `tensor`: n-dimensional arrays and reverse-mode automatic differentiation, written for
//! the SHNN / MeBen library.
//!
//! - [`Tensor`] is a plain value: contiguous row-major storage of `f32` or `f64`
//!   ([`Float`]), shared and immutable.
//! - A [`Tape`] records operations on [`Var`]s in a flat, append-only list;
//!   [`Tape::backward`] walks it backwards once and returns [`Gradients`] for every leaf
//!   created with [`Tape::var`].
//! - Gradient rules live in one file (`backprop.rs`); forward kernels in `kernels/`.
//! - With [`Tape::enable_profiling`], the tape times every op and counts its floating-point
//!   operations ([`Tape::profile_report`], [`Tape::profile_flops`]; conventions in [`flops`]).
//! - [`gradcheck`] compares gradients with central finite differences (in `f64`).
//!
//! ```
//! use tensor::{Tape, Tensor};
//! let tape = Tape::<f64>::new();
//! let x = tape.var(Tensor::from_f64(&[1.0, 2.0, 3.0], &[3]).unwrap());
//! let loss = x.square().sum_all();
//! let grads = tape.backward(loss).unwrap();
//! assert_eq!(grads.get(x).unwrap().data(), &[2.0, 4.0, 6.0]);
//! ```

mod backend;
mod backprop;
pub mod device;
mod dispatch;
pub mod element;
pub mod error;
pub mod flops;
#[cfg(feature = "gpu")]
pub mod gpu;
#[cfg(not(feature = "gpu"))]
#[path = "gpu/absent.rs"]
mod gpu;
mod grad_store;
pub mod gradcheck;
pub mod kernels;
pub mod op;
pub mod pool;
pub mod shape;
mod tape;
mod tensor;
mod tensor_ops;
mod var_ops;

pub use backend::AdamStep;
pub use device::{Device, GpuConfig, MatMulTile, Transfers, configure_gpu, gpu_config, transfers};
pub use element::Float;
pub use error::{Result, TensorError};
pub use flops::FlopCount;
pub use op::{Activation, BinaryOp, ReduceOp, UnaryOp};
pub use tape::{Gradients, NoGradGuard, Tape, Var};
pub use tensor::Tensor;
pub use tensor_ops::{adam_update, device_of_all, first_non_finite, to_device_all, to_host_all};
