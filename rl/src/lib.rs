//! `rl`: MAPPO training, evaluation, checkpoints and the `meben` command-line program.
//!
//! Not written yet: it builds on the MeBen tasks (`envs`) and the policies (`models`).
