//! Sweeps: many training runs from one TOML file (`meben ablate --sweep sweep.toml --out
//! runs/sweep [--shard 3/8]`), restartable and split across machines.
//!
//! A sweep file:
//!
//! ```toml
//! envs = ["team_reach/1_ant", "team_reach/2_ants"]
//! models = ["shnn", "mlp_hn", "shnn:assignment=hungarian"]   # models::ModelDescription::parse syntax
//! seeds = [0, 1, 2]
//! preset = "paper"          # optional: `paper` (default) or `quick`
//! include_base = true       # optional: also run without any variant (default true)
//!
//! [config]                  # optional: TrainConfig fields set for every run
//! steps = 50000000
//!
//! [[variants]]              # optional: overrides crossed with everything else
//! name = "no_entropy"
//! config = { entropy_coef = 0.0 }
//! ```
//!
//! Keys: the fields of [`SweepFile`] (any other key is refused). `env`, `model` and `seed` come from the lists and cannot be set in
//! `[config]` or a variant. Each run's configuration is
//! `TrainConfig::resolve(Some(preset), None, overrides)` with the overrides of `[config]`,
//! then of the variant, then the run's env, model and seed.
//!
//! **Order.** The runs are the cross product env x model x variant x seed, in that nesting
//! (env outermost, seed innermost), each list in file order; the variant without overrides
//! (if `include_base`) comes before the named variants. The run named
//! `<env>/<model>[+<variant>]/seed<seed>` (env and model made file-name safe by
//! [`sanitize_component`](crate::app::names::sanitize_component): `team_reach/1_ant` -> `team_reach_1_ant`,
//! `shnn:assignment=hungarian` -> `shnn_assignment-hungarian`) lives in that directory
//! under the output directory.
//!
//! **Shards.** `--shard k/n` runs the runs whose index `i` (0-based, in the order above)
//! has `i % n == k - 1`; the `n` shards partition the sweep. A shard beyond the runs (more
//! shards than runs: a Slurm array larger than the sweep) is empty: it says so and succeeds.
//! Every run's directory name is checked when the file is read (each component a file name
//! of at most [`MAX_NAME_BYTES`] bytes). `--only PATTERN` (repeatable)
//! keeps the runs whose name contains one of the patterns (`--only mlp_hn/ --only
//! 2_ants/shnn/`), applied after the shard: cheap runs first, or one run of a sweep.
//!
//! **Threads, checkpoints and devices.** A run's results depend neither on its thread count
//! nor on how often it writes checkpoints, so `threads` and `checkpoint_every` may differ
//! between a checkpoint and the sweep (`meben ablate --threads 1`, two sweeps side by side);
//! nor is the `device` part of a run's identity: a run started on the GPU may go on on the
//! CPU and the other way round (`meben ablate --device gpu`).
//!
//! **Restarts.** A run that is done (`done.json`) is skipped; one with a checkpoint is
//! resumed, after checking that it was started with the same configuration (except
//! `steps`, which may be raised to train longer, and the fields above; `num_evals` must
//! match: [`crate::mappo::config_match`]); any other is trained from scratch. So a sweep is
//! restarted by running the same command again.
//!
//! The module in three jobs: the sweep file read and checked (`file.rs`: [`Sweep::load`],
//! [`Sweep::parse`]), the plan it expands into (`plan.rs`: [`Sweep::runs`], [`SweepRun`]),
//! and the runner (`runner.rs`: [`run_sweep`], shards and `--only` [`RunSelection`]).

mod file;
mod plan;
mod runner;

pub use file::{MAX_NAME_BYTES, MAX_SWEEP_BYTES, Sweep, SweepFile, Variant, VariantFile};
pub use plan::SweepRun;
pub use runner::{RunSelection, Shard, SweepOutcome, run_sweep};

/// A sweep file of 2 envs x 3 models x (base + 1 variant) x 3 seeds, for the tests.
#[cfg(test)]
const EXAMPLE: &str = r#"
envs = ["team_reach/1_ant", "team_reach/2_ants"]
models = ["shnn", "mlp_hn", "shnn:assignment=hungarian"]
seeds = [0, 1, 2]
preset = "paper"
[config]
steps = 50000000
num_envs = 128
[[variants]]
name = "no_entropy"
config = { entropy_coef = 0.0 }
"#;
