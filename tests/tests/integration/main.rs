//! The workspace's cross-crate tests, one binary (one link on the 2-core CI):
//! one module per subject, each with its own doc comment.

mod closed_loop;
mod crate_graph;
