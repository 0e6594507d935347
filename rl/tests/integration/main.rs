//! The rl crate's integration tests, one binary (one link on the 2-core CI):
//! one module per subject, each with its own doc comment.

mod assignment_diagnostics;
mod assignment_episode_credit;
mod assignment_gradient;
mod assignment_hold;
mod assignment_hold_episode;
mod assignment_sensitivity;
mod assignment_values;
mod assignment_warmup;
mod checkpoint_format;
mod checkpoint_trust;
mod cli;
mod committed_results;
mod common;
mod custom_policy;
mod device;
mod distribution;
mod eval_assignment;
mod evaluation;
mod fuzz_corpus;
mod gpu_training;
mod interrupt;
mod invariance;
mod learned_assignment;
mod learning;
mod mappo_on_presets;
mod policy_file;
mod ppo_loss;
mod pretrained;
mod properties;
mod render_assignment;
mod report;
mod repro_check;
mod results_doc;
mod resume;
mod run_identity;
