//! The tensor crate's integration tests, one binary (one link on the 2-core CI):
//! one module per subject, each with its own doc comment.

mod common;
mod flops;
mod forward_values;
mod gpu_ops;
mod gradcheck_ops;
mod properties;
