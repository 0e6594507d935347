//! Whether two configurations describe the same run: the one comparison that resuming
//! ([`crate::mappo::trainer::Trainer::from_checkpoint`]), a run directory's `config.toml`
//! against its checkpoint ([`check_config_matches_checkpoint`], issue 44 item 6) and sweeps
//! (`crate::app::sweep`: a run directory against the sweep's run) make.
//!
//! [`differences`] compares every field of the two configurations as TOML (all fields,
//! those written only when not at their default included), but those the caller allows to
//! differ, and names each field that differs with both values. What may differ is the
//! caller's:
//! - resuming, and a run's `config.toml` against its checkpoint: [`SESSION_FIELDS`], which a
//!   run may change from one training session to the next (the budget, the number of
//!   evaluations, the checkpoint interval, the threads and the devices). A resumed run
//!   writes its new `config.toml` before its next checkpoint, so the two may differ there;
//! - a sweep resuming one of its runs: [`NEVER_IDENTITY_FIELDS`] and `steps`, but not
//!   `num_evals`: the sweep file fixes each run's evaluation schedule, which its report reads;
//! - a sweep's finished run, for its warning: [`NEVER_IDENTITY_FIELDS`] alone.
//!
//! Evaluation, rendering and Python's `Policy.load` build the models from `config.toml` and
//! fill them from the checkpoint: an edited `config.toml` (`model =
//! "shnn:assignment=stochastic"`, another `R`) would evaluate another model or scene with
//! the trained parameters, so [`check_config_matches_checkpoint`] refuses it, naming the
//! file and every field that differs.

use std::path::Path;

use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;

/// The fields no run's results depend on, which are never part of its identity: the
/// checkpoint interval, the threads and the devices of the updates and of the act step (a
/// run resumes on either; the GPU's results differ from the CPU's by f32 rounding).
pub const NEVER_IDENTITY_FIELDS: [&str; 6] =
    ["checkpoint_every", "threads", "device", "act_device", "gpu_matmul_tile", "gpu_reduce_lanes"];

/// The configuration fields that may differ between a run's sessions without making it
/// another run: [`NEVER_IDENTITY_FIELDS`], the budget `steps` (raised to train longer) and
/// `num_evals`.
pub const SESSION_FIELDS: [&str; 8] = [
    "steps",
    "num_evals",
    "checkpoint_every",
    "threads",
    "device",
    "act_device",
    "gpu_matmul_tile",
    "gpu_reduce_lanes",
];

/// One field on which two configurations disagree.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldDifference {
    /// The field's name.
    pub field: String,
    /// Its value in the first configuration, as TOML (`(absent)` if it has none).
    pub first: String,
    /// Its value in the second configuration.
    pub second: String,
}

impl FieldDifference {
    /// `<field> = <first> <first_where>, <second> <second_where>`: `model = "shnn" here,
    /// "mlp_hn" in the checkpoint`.
    pub fn describe(&self, first_where: &str, second_where: &str) -> String {
        format!("{} = {} {first_where}, {} {second_where}", self.field, self.first, self.second)
    }
}

/// The fields of `a` and `b`, other than those in `may_differ`, on which they disagree, in
/// field-name order; every field is compared, including those `config.toml` leaves out at
/// their default ([`TrainConfig::to_full_table`]).
pub fn differences(a: &TrainConfig, b: &TrainConfig, may_differ: &[&str]) -> Vec<FieldDifference> {
    let (ta, tb) = (a.to_full_table(), b.to_full_table());
    let show = |v: Option<&toml::Value>| v.map_or_else(|| "(absent)".to_string(), |v| v.to_string());
    let mut fields: Vec<&String> = ta.keys().chain(tb.keys().filter(|k| !ta.contains_key(*k))).collect();
    fields.sort();
    fields.retain(|k| !may_differ.contains(&k.as_str()) && ta.get(*k) != tb.get(*k));
    fields
        .into_iter()
        .map(|k| FieldDifference { field: k.clone(), first: show(ta.get(k)), second: show(tb.get(k)) })
        .collect()
}

/// The fields outside [`SESSION_FIELDS`] on which `a` and `b` disagree ([`differences`]).
pub fn identity_differences(a: &TrainConfig, b: &TrainConfig) -> Vec<FieldDifference> {
    differences(a, b, &SESSION_FIELDS)
}

/// Refuses a run's `config.toml` (`config`, read from `config_path`) that disagrees with the
/// configuration `saved` of the checkpoint at `checkpoint_path` on a field outside
/// [`SESSION_FIELDS`]; the error names `config.toml`, the checkpoint and every such field
/// with both values.
pub fn check_config_matches_checkpoint(
    config_path: &Path,
    config: &TrainConfig,
    checkpoint_path: &Path,
    saved: &TrainConfig,
) -> Result<()> {
    let diff = identity_differences(config, saved);
    if diff.is_empty() {
        return Ok(());
    }
    let fields: Vec<String> = diff.iter().map(|d| d.describe("here", "in the checkpoint")).collect();
    Err(RlError::file(
        config_path,
        format!(
            "does not match the configuration the checkpoint {} was trained with: {}; the checkpoint's values are \
             the run's (put them back, or run the run's training command again, which rewrites config.toml)",
            checkpoint_path.display(),
            fields.join("; ")
        ),
    ))
}
