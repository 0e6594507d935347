//! The envs crate's integration tests, one binary (one link on the 2-core CI):
//! one module per subject, each with its own doc comment.
//! Two stay binaries of their own: `tests/no_alloc.rs`, whose global allocator counts every
//! allocation of the process, and `tests/memory_estimate.rs`, which measures the resident
//! memory (VmRSS) of the whole process.

mod brax_loader;
mod contacts;
mod dynamics;
mod fuzz_corpus;
mod load_scaling;
mod mjcf;
mod rollout_tool;
mod stress;
mod tasks_checkpoint;
mod tasks_divergence;
mod tasks_equivariance;
mod tasks_gif;
mod tasks_mjcf;
mod tasks_observation_types;
mod tasks_placement;
mod tasks_render;
mod tasks_rewards;
mod tasks_vec_env;
