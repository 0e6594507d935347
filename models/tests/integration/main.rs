//! The models crate's integration tests, one binary (one link on the 2-core CI):
//! one module per subject, each with its own doc comment.
//! `tests/no_alloc.rs` stays a binary of its own: its global allocator counts every
//! allocation of the process.

mod common;
mod components;
mod entity_stage;
mod gpu_models;
mod held_critic;
mod learned_assignment;
mod policies;
