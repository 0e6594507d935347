//! Whether a run directory's `config.toml` is the configuration its checkpoint was trained
//! with (issue 44 item 6).
//!
//! Evaluation, rendering and Python's `Policy.load` build the models from `config.toml` and
//! fill them from the checkpoint. Before this check an edited `config.toml` (`model =
//! "shnn:assignment=stochastic"`, another `R`) was used as it stood: a small edit evaluated
//! another model or scene with the trained parameters, a bigger one failed with a parameter
//! name that never mentioned the file. Now every field that makes a run what it is must
//! agree, and the error names the file and every field that does not.
//!
//! The fields a run may change from one training session to the next
//! ([`SESSION_FIELDS`]: the budget, the number of evaluations, the checkpoint interval, the
//! threads and the device, as `Trainer::from_checkpoint` allows) are not compared: a resumed
//! run writes its new `config.toml` before its next checkpoint, so the two may differ there.
//! Resuming compares the training command's configuration with the checkpoint's (in
//! `Trainer::from_checkpoint`) and then rewrites `config.toml` from the command.

use std::path::Path;

use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;

/// The configuration fields that may differ between a run's sessions without making it
/// another run (module docs).
pub const SESSION_FIELDS: [&str; 5] = ["steps", "num_evals", "checkpoint_every", "threads", "device"];

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

/// The fields outside [`SESSION_FIELDS`] on which `a` and `b` disagree, in field order.
pub fn identity_differences(a: &TrainConfig, b: &TrainConfig) -> Vec<FieldDifference> {
    let (ta, tb) = (a.to_full_table(), b.to_full_table());
    let show = |v: Option<&toml::Value>| v.map_or_else(|| "(absent)".to_string(), |v| v.to_string());
    let mut fields: Vec<&String> = ta.keys().chain(tb.keys().filter(|k| !ta.contains_key(*k))).collect();
    fields.retain(|k| !SESSION_FIELDS.contains(&k.as_str()) && ta.get(*k) != tb.get(*k));
    fields
        .into_iter()
        .map(|k| FieldDifference { field: k.clone(), first: show(ta.get(k)), second: show(tb.get(k)) })
        .collect()
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
    let fields: Vec<String> =
        diff.iter().map(|d| format!("{} = {} here, {} in the checkpoint", d.field, d.first, d.second)).collect();
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
            train_starts: crate::mappo::config::TrainStarts::PerSlot,
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
}
