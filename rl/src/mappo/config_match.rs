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
pub const NEVER_IDENTITY_FIELDS: [&str; 4] = ["checkpoint_every", "threads", "device", "act_device"];

/// The configuration fields that may differ between a run's sessions without making it
/// another run: [`NEVER_IDENTITY_FIELDS`], the budget `steps` (raised to train longer) and
/// `num_evals`.
pub const SESSION_FIELDS: [&str; 6] = ["steps", "num_evals", "checkpoint_every", "threads", "device", "act_device"];

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mappo::config::TrainStarts;

    fn quick() -> TrainConfig {
        TrainConfig::resolve(Some(crate::app::presets::Preset::Quick), None, &[]).unwrap()
    }

    #[test]
    fn session_fields_may_differ_the_others_are_named() {
        let a = quick();
        let b = TrainConfig {
            steps: a.steps * 2,
            num_evals: 3,
            checkpoint_every: 9,
            threads: 1,
            device: tensor::Device::Gpu,
            ..a.clone()
        };
        assert!(identity_differences(&a, &b).is_empty());
        let c = TrainConfig {
            model: "shnn:assignment=stochastic".into(),
            env: "team_reach:agents=ant;R=5".into(),
            train_starts: TrainStarts::PerSlot,
            ..b
        };
        let d = identity_differences(&c, &a);
        let names: Vec<&str> = d.iter().map(|d| d.field.as_str()).collect();
        assert_eq!(names, ["env", "model", "train_starts"]);
        assert_eq!(d[1].first, "\"shnn:assignment=stochastic\"");
        assert_eq!(d[1].second, "\"shnn\"");
        let e = check_config_matches_checkpoint(Path::new("r/config.toml"), &c, Path::new("r/checkpoint.json"), &a)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("r/config.toml: does not match the configuration the checkpoint r/checkpoint.json")
                && e.contains("model = \"shnn:assignment=stochastic\" here, \"shnn\" in the checkpoint")
                && e.contains("train_starts = \"per_slot\" here, \"fresh\" in the checkpoint"),
            "{e}"
        );
    }

    /// The fields `config.toml` writes only away from their default (`train_starts`,
    /// `device`) are compared either way round: the resume check used to list only the
    /// checkpoint's written fields, and refused `train_starts = "per_slot"` against a
    /// `fresh` checkpoint naming no field.
    #[test]
    fn fields_written_only_away_from_their_default_are_compared_both_ways() {
        let a = quick();
        let b = TrainConfig { train_starts: TrainStarts::PerSlot, ..a.clone() };
        for (x, y) in [(&a, &b), (&b, &a)] {
            let d = differences(x, y, &[]);
            assert_eq!(d.len(), 1, "{d:?}");
            assert_eq!(d[0].field, "train_starts");
        }
        let gpu = TrainConfig { device: tensor::Device::Gpu, ..a.clone() };
        assert_eq!(differences(&a, &gpu, &[])[0].describe("saved", "now"), "device = \"cpu\" saved, \"gpu\" now");
        assert!(differences(&a, &gpu, &NEVER_IDENTITY_FIELDS).is_empty());
        // What the caller allows is all that is left out.
        let more = TrainConfig { steps: a.steps + 1, num_evals: a.num_evals + 1, ..a.clone() };
        let names = |d: Vec<FieldDifference>| d.into_iter().map(|d| d.field).collect::<Vec<_>>();
        assert_eq!(names(differences(&a, &more, &NEVER_IDENTITY_FIELDS)), ["num_evals", "steps"]);
        assert_eq!(names(differences(&a, &more, &["steps"])), ["num_evals"]);
        assert!(differences(&a, &more, &SESSION_FIELDS).is_empty());
    }
}
