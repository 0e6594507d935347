//! The nn crate's integration tests, one binary (one link on the 2-core CI):
//! one module per subject, each with its own doc comment.

mod common;
mod equivariance;
mod gpu_determinism;
mod gpu_optim;
mod layers;
mod optim_state;
mod transformer;
