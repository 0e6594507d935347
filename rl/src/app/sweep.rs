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
//! [`sanitize_component`]: `team_reach/1_ant` -> `team_reach_1_ant`,
//! `shnn:assignment=hungarian` -> `shnn_assignment-hungarian`) lives in that directory
//! under the output directory.
//!
//! **Shards.** `--shard k/n` runs the runs whose index `i` (0-based, in the order above)
//! has `i % n == k - 1`; the `n` shards partition the sweep. `--only PATTERN` (repeatable)
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

use std::collections::BTreeSet;
use std::fmt;
use std::path::Path;
use std::str::FromStr;

use serde::Deserialize;

use crate::app::presets::Preset;
use crate::app::run::RunSummary;
use crate::app::run_dir::{RunDir, RunStatus};
use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;
use crate::mappo::config_match;

/// A sweep file as written (module docs), read by serde: an unknown key, at the top or in a
/// `[[variants]]` table, is refused, naming it and the keys there are. [`Sweep::parse`] then
/// checks what the types cannot say (non-empty lists without repeats, variant names, the
/// override tables' fields).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepFile {
    /// Environment names.
    pub envs: Vec<String>,
    /// Model specifications (`models::ModelDescription::parse` syntax).
    pub models: Vec<String>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// The preset every run starts from, `paper` (default) or `quick`.
    #[serde(default)]
    pub preset: Option<String>,
    /// Whether the runs without a variant are part of the sweep (default true).
    #[serde(default = "yes")]
    pub include_base: bool,
    /// `TrainConfig` fields set for every run.
    #[serde(default)]
    pub config: toml::Table,
    /// The `[[variants]]` tables.
    #[serde(default)]
    pub variants: Vec<VariantFile>,
}

/// A `[[variants]]` table of a sweep file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantFile {
    /// The variant's name (required: [`Sweep::parse`] names the table that lacks it).
    pub name: Option<String>,
    /// `TrainConfig` fields the variant sets.
    #[serde(default)]
    pub config: toml::Table,
}

fn yes() -> bool {
    true
}

/// Fields that the sweep's lists set and `[config]` or a variant must not.
const LIST_FIELDS: [(&str, &str); 4] =
    [("env", "envs"), ("model", "models"), ("seed", "seeds"), ("preset", "preset (a top-level key)")];

/// A named set of configuration overrides crossed with the rest of a sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// Appended to the model's directory name after a `+`.
    pub name: String,
    /// `(field, value as TOML text)` pairs.
    pub config: Vec<(String, String)>,
}

/// A parsed sweep file (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    /// Where the sweep came from (its path), named in errors.
    pub source: String,
    /// The file's text, copied to the output directory.
    pub text: String,
    /// Environment names.
    pub envs: Vec<String>,
    /// Model specifications.
    pub models: Vec<String>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// The preset every run starts from.
    pub preset: Preset,
    /// `(field, value as TOML text)` overrides of every run.
    pub config: Vec<(String, String)>,
    /// Named variants (may be empty).
    pub variants: Vec<Variant>,
    /// Whether the runs without a variant are part of the sweep.
    pub include_base: bool,
}

/// One run of a sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepRun {
    /// The run directory relative to the sweep's output directory, e.g.
    /// `team_reach_1_ant/shnn+no_entropy/seed0`.
    pub name: String,
    /// The resolved configuration.
    pub config: TrainConfig,
}

/// Shard `index` of `count` (1-based): the runs whose 0-based position `i` has
/// `i % count == index - 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, from 1 to `count`.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

/// Which runs of a sweep to run: a shard and name patterns (module docs).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RunSelection {
    /// Only this shard (all runs if `None`).
    pub shard: Option<Shard>,
    /// Only runs whose name contains one of these (all runs if empty).
    pub only: Vec<String>,
}

impl RunSelection {
    /// Every run.
    pub fn all() -> RunSelection {
        RunSelection::default()
    }

    /// The runs of one shard.
    pub fn shard(shard: Shard) -> RunSelection {
        RunSelection { shard: Some(shard), only: Vec::new() }
    }

    /// Whether the run named `name` at 0-based position `i` of the sweep is selected.
    pub fn contains(&self, i: usize, name: &str) -> bool {
        self.shard.is_none_or(|s| s.contains(i))
            && (self.only.is_empty() || self.only.iter().any(|p| name.contains(p.as_str())))
    }

    /// ` (shard k/n, only a, b)`, or empty when every run is selected: for progress lines.
    fn describe(&self) -> String {
        let mut parts = Vec::new();
        if let Some(s) = self.shard {
            parts.push(format!("shard {s}"));
        }
        if !self.only.is_empty() {
            parts.push(format!("only {}", self.only.join(", ")));
        }
        if parts.is_empty() { String::new() } else { format!(" ({})", parts.join(", ")) }
    }
}

/// What [`run_sweep`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SweepOutcome {
    /// Runs of the shard.
    pub runs: usize,
    /// Runs trained from scratch.
    pub trained: usize,
    /// Runs resumed from their checkpoint.
    pub resumed: usize,
    /// Runs already done.
    pub skipped: usize,
    /// Runs another process was training ([`RlError::RunInUse`]): left to it, not failed.
    pub taken: usize,
}

impl fmt::Display for SweepOutcome {
    /// `4 runs: 1 trained, 1 resumed, 1 already done, 1 taken by another process`, for
    /// the sweep's last line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} trained, {} resumed, {} already done",
            crate::app::report::count(self.runs, "run"),
            self.trained,
            self.resumed,
            self.skipped
        )?;
        if self.taken > 0 {
            write!(
                f,
                ", {} taken by another process (training there; `meben status` shows {})",
                self.taken,
                if self.taken == 1 { "it" } else { "them" }
            )?;
        }
        Ok(())
    }
}

impl Shard {
    /// Parses `k/n` (1 <= k <= n); errors name the value and what is expected.
    pub fn parse(s: &str) -> Result<Shard> {
        let err = |msg: String| RlError::config("command line", "--shard", s, msg);
        let usage = "expected k/n, shard k of n counted from 1 (e.g. 3/8)";
        let (k, n) = s.split_once('/').ok_or_else(|| err(usage.into()))?;
        let (Ok(index), Ok(count)) = (k.trim().parse::<usize>(), n.trim().parse::<usize>()) else {
            return Err(err(usage.into()));
        };
        if count == 0 {
            return Err(err("the number of shards n must be at least 1".into()));
        }
        if index == 0 || index > count {
            return Err(err(format!("shard {index} of {count} does not exist: k must lie in 1..={count}")));
        }
        Ok(Shard { index, count })
    }

    /// Whether the run at 0-based position `i` of the sweep belongs to this shard.
    pub fn contains(&self, i: usize) -> bool {
        i % self.count == self.index - 1
    }

    /// The items of this shard, in order.
    pub fn select<T>(&self, items: Vec<T>) -> Vec<T> {
        items.into_iter().enumerate().filter(|(i, _)| self.contains(*i)).map(|(_, x)| x).collect()
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = RlError;
    fn from_str(s: &str) -> Result<Shard> {
        Shard::parse(s)
    }
}

impl Sweep {
    /// Reads and parses a sweep file.
    pub fn load(path: &Path) -> Result<Sweep> {
        let text = crate::app::presets::read_text_file(path, crate::app::presets::MAX_SWEEP_BYTES, "a sweep file")?;
        Sweep::parse(&text, &path.display().to_string())
    }

    /// Parses a sweep file's text; `source` (its path) is named in errors.
    pub fn parse(text: &str, source: &str) -> Result<Sweep> {
        let file: SweepFile = toml::from_str(text)
            .map_err(|e| RlError::file(source, format!("invalid sweep file: {}", e.to_string().trim_end())))?;
        let envs = string_list(file.envs, "envs", source)?;
        let models = string_list(file.models, "models", source)?;
        let seeds = seed_list(file.seeds, source)?;
        let preset = match &file.preset {
            None => Preset::Paper,
            Some(s) => Preset::parse(s, source)?,
        };
        let config = overrides(&file.config, "config", source)?;
        let mut variants = Vec::new();
        for (i, v) in file.variants.iter().enumerate() {
            variants.push(check_variant(v, i, source, &variants)?);
        }
        if !file.include_base && variants.is_empty() {
            return Err(RlError::config(
                source,
                "include_base",
                false,
                "the sweep has no runs: include_base = false needs at least one [[variants]] table",
            ));
        }
        Ok(Sweep {
            source: source.into(),
            text: text.into(),
            envs,
            models,
            seeds,
            preset,
            config,
            variants,
            include_base: file.include_base,
        })
    }

    /// Every run of the sweep, in the order of the module docs, each configuration resolved
    /// and validated (errors name the sweep file and the run).
    pub fn runs(&self) -> Result<Vec<SweepRun>> {
        let mut variants: Vec<Option<&Variant>> = Vec::new();
        if self.include_base {
            variants.push(None);
        }
        variants.extend(self.variants.iter().map(Some));
        let mut runs = Vec::new();
        let mut names = BTreeSet::new();
        for env in &self.envs {
            for model in &self.models {
                for variant in &variants {
                    for &seed in &self.seeds {
                        let suffix = variant.map(|v| format!("+{}", v.name)).unwrap_or_default();
                        let name =
                            format!("{}/{}{suffix}/seed{seed}", sanitize_component(env), sanitize_component(model));
                        let mut ov = self.config.clone();
                        if let Some(v) = variant {
                            ov.extend(v.config.iter().cloned());
                        }
                        ov.push(("env".into(), toml::Value::String(env.clone()).to_string()));
                        ov.push(("model".into(), toml::Value::String(model.clone()).to_string()));
                        ov.push(("seed".into(), seed.to_string()));
                        let config = TrainConfig::resolve(Some(self.preset), None, &ov)
                            .map_err(|e| in_run(e, &self.source, &name))?;
                        if !names.insert(name.clone()) {
                            return Err(RlError::config(
                                &self.source,
                                "models",
                                model,
                                format!(
                                    "two runs would share the directory {name}: env or model names that differ \
                                     only in characters replaced in directory names (: ; = / and others)"
                                ),
                            ));
                        }
                        runs.push(SweepRun { name, config });
                    }
                }
            }
        }
        Ok(runs)
    }
}

/// Runs the runs of `sweep` chosen by `selection` under `out`, skipping finished runs,
/// resuming partial ones (module docs) and calling `train_fn` for the others; writes a copy
/// of the sweep file to `<out>/sweep.toml` if there is none.
///
/// A run that fails (its `train_fn` returns an error, or its checkpoint was made with a
/// different configuration) does not stop the others; the error then lists every failed
/// run. A run another process holds ([`RlError::RunInUse`]: a second `meben ablate` on the
/// same directory) is no failure: it is counted as taken and left to that process. A run interrupted on request ([`RlError::Interrupted`], [`crate::stop`]) stops
/// the sweep: that error is returned at once, and the same command goes on from there. Progress is printed to standard error, one line per run.
pub fn run_sweep(
    sweep: &Sweep,
    out: &Path,
    selection: &RunSelection,
    mut train_fn: impl FnMut(&TrainConfig, &RunDir) -> Result<RunSummary>,
) -> Result<SweepOutcome> {
    let all = sweep.runs()?;
    let total = all.len();
    let runs: Vec<(usize, SweepRun)> =
        all.into_iter().enumerate().filter(|(i, r)| selection.contains(*i, &r.name)).collect();
    if runs.is_empty() {
        return Err(RlError::config(
            "command line",
            "--only",
            selection.only.join(", "),
            format!("no run of the {total} in {} is selected{}", sweep.source, selection.describe()),
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| RlError::file(out, format!("cannot create the directory: {e}")))?;
    let copy = out.join("sweep.toml");
    if !copy.exists()
        && let Err(e) = nn::write_atomic(&copy, sweep.text.as_bytes())
        && !copy.exists()
    {
        // Another shard may have written it at the same moment; only a missing copy fails.
        return Err(e.into());
    }
    let mut outcome = SweepOutcome { runs: runs.len(), ..SweepOutcome::default() };
    let mut failed: Vec<String> = Vec::new();
    let shard_text = selection.describe();
    for (pos, (i, run)) in runs.iter().enumerate() {
        let dir = RunDir::new(out.join(&run.name));
        let status = dir.status();
        let head = format!("[{}/{}{shard_text}, run {} of {total}] {}", pos + 1, runs.len(), i + 1, run.name);
        let result = match status {
            RunStatus::Done => {
                if let Ok(saved) = TrainConfig::load(&dir.config()) {
                    let diff = config_differences(&saved, &run.config, &config_match::NEVER_IDENTITY_FIELDS);
                    if !diff.is_empty() {
                        eprintln!(
                            "{head}: warning: finished with a configuration that differs from the sweep's: {}",
                            diff.join("; ")
                        );
                    }
                }
                eprintln!("{head}: done, skipped");
                outcome.skipped += 1;
                continue;
            }
            RunStatus::Partial => check_resumable(&dir, &run.config).and_then(|()| {
                eprintln!("{head}: resuming");
                train_fn(&run.config, &dir)
            }),
            // `train` makes the directory once it begins (a stop before then leaves none).
            RunStatus::New => {
                eprintln!("{head}: training");
                train_fn(&run.config, &dir)
            }
        };
        match result {
            // A stop was asked for: the sweep stops too (the same command goes on from here).
            Err(e @ RlError::Interrupted { .. }) => return Err(e),
            Ok(_) if status == RunStatus::Partial => outcome.resumed += 1,
            Ok(_) => outcome.trained += 1,
            // Another `meben ablate` on this directory holds the run: it is being trained.
            Err(RlError::RunInUse { holder, .. }) => {
                eprintln!("{head}: taken by {holder}, left to it");
                outcome.taken += 1;
            }
            Err(e) => {
                eprintln!("{head}: failed: {e}");
                failed.push(format!("{}: {e}", run.name));
            }
        }
    }
    if !failed.is_empty() {
        return Err(RlError::file(
            out,
            format!(
                "{} of {} runs{shard_text} failed ({} trained, {} resumed, {} skipped, {} taken by another \
                 process):\n  {}",
                failed.len(),
                runs.len(),
                outcome.trained,
                outcome.resumed,
                outcome.skipped,
                outcome.taken,
                failed.join("\n  ")
            ),
        ));
    }
    Ok(outcome)
}

/// A path component made of `[A-Za-z0-9_.+-]` only: `/`, `:` and `;` become `_`, `=`
/// becomes `-`, anything else `_` (so `team_reach/1_ant` -> `team_reach_1_ant`,
/// `shnn:assignment=hungarian;seed=3` -> `shnn_assignment-hungarian_seed-3`).
pub fn sanitize_component(s: &str) -> String {
    let out: String = s
        .chars()
        .map(|c| match c {
            '=' => '-',
            c if c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '+' | '-') => c,
            _ => '_',
        })
        .collect();
    if out.chars().all(|c| c == '.') { format!("_{out}") } else { out }
}

/// The fields a sweep lets differ between a partial run's saved configuration and the
/// sweep's when it resumes the run: those no result depends on, and the budget `steps`
/// (raised to train longer); not `num_evals`, since the sweep file fixes each run's
/// evaluation schedule ([`crate::mappo::config_match`]).
const RESUME_MAY_DIFFER: [&str; 5] = ["steps", "checkpoint_every", "threads", "device", "act_device"];

/// Checks that a partial run's saved configuration is the sweep's ([`RESUME_MAY_DIFFER`]).
fn check_resumable(dir: &RunDir, wanted: &TrainConfig) -> Result<()> {
    let saved = TrainConfig::load(&dir.config())?;
    let diff = config_differences(&saved, wanted, &RESUME_MAY_DIFFER);
    if diff.is_empty() {
        return Ok(());
    }
    Err(RlError::file(
        dir.root(),
        format!(
            "the checkpoint was made with a different configuration than the sweep asks for ({}); use another \
             --out directory, restore the sweep file, or delete this run directory to start it again",
            diff.join("; ")
        ),
    ))
}

/// `field: saved X, sweep Y` for every field that differs but those of `may_differ`
/// ([`config_match::differences`], the comparison resuming makes too).
fn config_differences(saved: &TrainConfig, wanted: &TrainConfig, may_differ: &[&str]) -> Vec<String> {
    config_match::differences(saved, wanted, may_differ)
        .into_iter()
        .map(|d| format!("{}: saved {}, sweep {}", d.field, d.first, d.second))
        .collect()
}

/// Puts the sweep file and the run into a configuration error's source.
fn in_run(e: RlError, source: &str, run: &str) -> RlError {
    match e {
        RlError::Config { field, value, message, .. } => {
            RlError::Config { source: format!("{source} (run {run})"), field, value, message }
        }
        e => e,
    }
}

/// A non-empty list of distinct, non-empty strings (trimmed); `key` names it in errors.
fn string_list(items: Vec<String>, key: &str, source: &str) -> Result<Vec<String>> {
    if items.is_empty() {
        return Err(RlError::config(source, key, "[]", "the list is empty"));
    }
    let mut out: Vec<String> = Vec::new();
    // A set, not `out.contains`: a list of N items is checked in linear time.
    let mut seen = std::collections::HashSet::new();
    for item in items {
        let s = item.trim().to_string();
        if s.is_empty() {
            return Err(RlError::config(source, key, &item, "expected a non-empty string"));
        }
        if !seen.insert(s.clone()) {
            return Err(RlError::config(source, key, &s, "listed twice"));
        }
        out.push(s);
    }
    Ok(out)
}

/// A non-empty list of distinct seeds.
fn seed_list(seeds: Vec<u64>, source: &str) -> Result<Vec<u64>> {
    if seeds.is_empty() {
        return Err(RlError::config(source, "seeds", "[]", "the list is empty"));
    }
    // A set, not `out.contains`: 10^6 seeds took 64 s (issue 44 item 9).
    let mut seen = std::collections::HashSet::new();
    if let Some(seed) = seeds.iter().find(|&&s| !seen.insert(s)) {
        return Err(RlError::config(source, "seeds", seed, "listed twice"));
    }
    Ok(seeds)
}

/// A table of TrainConfig overrides as `(field, TOML text)` pairs; `at` names the table
/// (`config`, `variants.<name>.config`) in errors.
fn overrides(table: &toml::Table, at: &str, source: &str) -> Result<Vec<(String, String)>> {
    let known = TrainConfig::preset(Preset::Quick, "team_reach/1_ant").to_full_table();
    let mut out = Vec::new();
    for (k, value) in table {
        let field = format!("{at}.{k}");
        if let Some((_, list)) = LIST_FIELDS.iter().find(|(f, _)| f == k) {
            return Err(RlError::config(source, &field, value, format!("set by the sweep's `{list}`, not here")));
        }
        if !known.contains_key(k) {
            let names: Vec<&str> =
                known.keys().map(|s| s.as_str()).filter(|k| !matches!(*k, "env" | "model" | "seed")).collect();
            return Err(RlError::config(
                source,
                &field,
                value,
                format!("unknown TrainConfig field; known fields: {}", names.join(", ")),
            ));
        }
        out.push((k.clone(), value.to_string()));
    }
    Ok(out)
}

/// The `i`-th `[[variants]]` table, its name checked (present, fit for a directory name,
/// unlike those `before`) and its overrides too.
fn check_variant(v: &VariantFile, i: usize, source: &str, before: &[Variant]) -> Result<Variant> {
    let at = format!("variants[{i}]");
    let Some(name) = v.name.clone() else {
        return Err(RlError::config(source, &format!("{at}.name"), "", "missing (every variant needs a name)"));
    };
    if name.is_empty()
        || name.chars().all(|c| c == '.')
        || !name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
    {
        return Err(RlError::config(
            source,
            &format!("{at}.name"),
            &name,
            "a variant name is part of directory names: use letters, digits, `_`, `-` and `.` only",
        ));
    }
    if before.iter().any(|v| v.name == name) {
        return Err(RlError::config(source, &format!("{at}.name"), &name, "two variants have this name"));
    }
    let config = overrides(&v.config, &format!("variants.{name}.config"), source)?;
    Ok(Variant { name, config })
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;

    use super::*;

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

    use crate::app::test_util::TempDir;

    fn err_of(text: &str) -> String {
        Sweep::parse(text, "bad.toml").and_then(|s| s.runs()).unwrap_err().to_string()
    }

    /// Issue 44 item 9: duplicates were found by `Vec::contains` (10^6 seeds: 64 s); with a
    /// set the result is the same: the first repeated item is named, wherever it is.
    #[test]
    fn long_lists_name_their_first_duplicate() {
        let seeds: Vec<String> = (0..20_000u64).map(|s| s.to_string()).collect();
        let table = |seeds: &str| format!("envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [{seeds}]\n");
        let msg = err_of(&table(&format!("{}, 19999, 7", seeds.join(", "))));
        assert!(msg.contains("field `seeds` = \"19999\": listed twice"), "{msg}");
        let msg = err_of(&table(&format!("5, {}", seeds.join(", "))));
        assert!(msg.contains("field `seeds` = \"5\": listed twice"), "{msg}");
        let models: Vec<String> = (0..5_000).map(|i| format!("\"m{i}\"")).collect();
        let text = format!("envs = [\"team_reach/1_ant\"]\nmodels = [{}, \"m4999\"]\nseeds = [0]\n", models.join(", "));
        let msg = err_of(&text);
        assert!(msg.contains("field `models` = \"m4999\": listed twice"), "{msg}");
    }

    #[test]
    fn expands_in_the_documented_order() {
        let sweep = Sweep::parse(EXAMPLE, "example.toml").unwrap();
        let runs = sweep.runs().unwrap();
        assert_eq!(runs.len(), 2 * 3 * 2 * 3);
        assert_eq!(runs[0].name, "team_reach_1_ant/shnn/seed0");
        assert_eq!(runs[2].name, "team_reach_1_ant/shnn/seed2");
        assert_eq!(runs[3].name, "team_reach_1_ant/shnn+no_entropy/seed0");
        assert_eq!(runs[6].name, "team_reach_1_ant/mlp_hn/seed0");
        assert_eq!(runs[12].name, "team_reach_1_ant/shnn_assignment-hungarian/seed0");
        assert_eq!(runs[18].name, "team_reach_2_ants/shnn/seed0");
        let r = &runs[4];
        assert_eq!((r.config.env.as_str(), r.config.model.as_str(), r.config.seed), ("team_reach/1_ant", "shnn", 1));
        assert_eq!(r.config.entropy_coef, 0.0);
        assert_eq!(r.config.num_envs, 128);
        assert_eq!(r.config.steps, 50_000_000);
        assert_eq!(runs[0].config.entropy_coef, 1e-2);
        assert_eq!(runs[12].config.model, "shnn:assignment=hungarian");
        // The paper preset is the default.
        assert_eq!(runs[0].config.batch_size, 1024);

        let no_base = EXAMPLE.replace("preset = \"paper\"", "include_base = false");
        let runs = Sweep::parse(&no_base, "x").unwrap().runs().unwrap();
        assert_eq!(runs.len(), 2 * 3 * 3);
        assert!(runs.iter().all(|r| r.name.contains("+no_entropy")));
    }

    #[test]
    fn sanitized_names() {
        assert_eq!(sanitize_component("team_reach/1_ant"), "team_reach_1_ant");
        assert_eq!(
            sanitize_component("shnn:assignment=hungarian;translation=root_mean"),
            "shnn_assignment-hungarian_translation-root_mean"
        );
        assert_eq!(sanitize_component(".."), "_..");
        assert_eq!(sanitize_component("a b/c"), "a_b_c");
    }

    #[test]
    fn shards_parse_and_partition() {
        assert_eq!(Shard::parse("3/8").unwrap(), Shard { index: 3, count: 8 });
        assert_eq!("1/1".parse::<Shard>().unwrap().to_string(), "1/1");
        for bad in ["0/8", "9/8", "x/y", "3", "1/0", "-1/3", ""] {
            let msg = Shard::parse(bad).unwrap_err().to_string();
            assert!(msg.contains("--shard") && msg.contains(&format!("{bad:?}")), "{bad}: {msg}");
        }
        assert!(Shard::parse("9/8").unwrap_err().to_string().contains("1..=8"));
        let runs = Sweep::parse(EXAMPLE, "x").unwrap().runs().unwrap();
        let names: Vec<String> = runs.iter().map(|r| r.name.clone()).collect();
        for n in 1..=7 {
            let mut seen: Vec<String> = Vec::new();
            for k in 1..=n {
                let part = Shard { index: k, count: n }.select(names.clone());
                assert!(part.len() >= names.len() / n && part.len() <= names.len().div_ceil(n));
                seen.extend(part);
            }
            seen.sort();
            let mut all = names.clone();
            all.sort();
            assert_eq!(seen, all, "{n} shards");
        }
        assert_eq!(Shard { index: 2, count: 3 }.select((0..7).collect()), vec![1, 4]);
    }

    #[test]
    fn bad_sweep_files_name_the_file_and_field() {
        let cases: &[(&str, &[&str])] = &[
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\ncolour = 1",
                // serde's wording: the line, the key and the keys there are.
                &["line 4", "unknown field `colour`", "expected one of `envs`, `models`"],
            ),
            ("envs = []\nmodels = [\"shnn\"]\nseeds = [0]", &["envs", "empty"]),
            ("models = [\"shnn\"]\nseeds = [0]", &["envs", "missing"]),
            ("envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = []", &["seeds", "empty"]),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [-1]",
                &["seeds = [-1]", "integer `-1`, expected u64"],
            ),
            ("envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\", \"shnn\"]\nseeds = [0]", &["models", "twice"]),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"resnet\"]\nseeds = [0]",
                &["model", "resnet", "run team_reach_1_ant/resnet/seed0"],
            ),
            ("envs = [\"team_reach/nope\"]\nmodels = [\"shnn\"]\nseeds = [0]", &["env", "team_reach/nope"]),
            ("envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\npreset = \"fast\"", &["preset", "fast"]),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[config]\nenv = \"x\"",
                &["config.env", "envs"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[config]\nnum_env = 3",
                &["config.num_env", "num_envs"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[config]\nnum_envs = 0",
                &["num_envs", "at least 1"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[[variants]]\nname = \"a/b\"",
                &["variants[0].name", "a/b"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[[variants]]\nconfig = {}",
                &["variants[0].name", "missing"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[[variants]]\nname = \"v\"\nfoo = 1",
                &["line 6", "foo = 1", "unknown field `foo`, expected `name` or `config`"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\n[[variants]]\nname = \"v\"\nconfig = { seed = 3 }",
                &["variants.v.config.seed", "seeds"],
            ),
            (
                "envs = [\"team_reach/1_ant\"]\nmodels = [\"shnn\"]\nseeds = [0]\ninclude_base = false",
                &["include_base", "no runs"],
            ),
            ("envs = [\"team_reach/1_ant\"\nmodels", &["bad.toml", "invalid sweep file", "line 2", "missing comma"]),
        ];
        for (text, wanted) in cases {
            let msg = err_of(text);
            assert!(msg.contains("bad.toml"), "{text}\n-> {msg}");
            for w in *wanted {
                assert!(msg.contains(w), "{text}\n-> {msg}\n(missing {w:?})");
            }
        }
    }

    #[test]
    fn shipped_sweeps_parse_and_expand() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps");
        let mut found = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let runs = Sweep::load(&path).unwrap().runs().unwrap();
                assert!(!runs.is_empty());
                found += 1;
            }
        }
        assert!(found >= 2);
        let table = Sweep::load(&dir.join("team_reach_table.toml")).unwrap();
        let runs = table.runs().unwrap();
        assert_eq!(runs.len(), 6 * 4 * 3);
        assert!(runs.iter().all(|r| r.config.steps == 50_000_000 && r.config.num_envs == 2048));
        let reach: Vec<&str> =
            envs::tasks::BUILTIN_NAMES.iter().copied().filter(|n| n.starts_with("team_reach")).collect();
        assert_eq!(table.envs, reach);
        let ablation = Sweep::load(&dir.join("ablation_assignment.toml")).unwrap().runs().unwrap();
        assert!(ablation.iter().any(|r| r.config.model == "shnn:assignment=stochastic"));
        assert!(ablation.iter().any(|r| r.config.model == "hnn_dn"));

        // The reproduction (docs/RESULTS.md): the paper preset but for the budget and the number of
        // evaluations, sampled-action evaluation on 1024 episodes.
        let repro = |name: &str, runs: usize, steps: u64| {
            let runs_of = Sweep::load(&dir.join(name)).unwrap().runs().unwrap();
            assert_eq!(runs_of.len(), runs, "{name}");
            for r in &runs_of {
                let paper = TrainConfig::preset(Preset::Paper, &r.config.env);
                let expected = TrainConfig {
                    model: r.config.model.clone(),
                    seed: r.config.seed,
                    steps,
                    num_evals: 10,
                    checkpoint_every: 1,
                    opponent: r.config.opponent.clone(),
                    fixed_start: r.config.fixed_start,
                    eval_rotations: r.config.eval_rotations.clone(),
                    ..paper
                };
                assert_eq!(r.config, expected, "{name}: {}", r.name);
                assert!(!r.config.eval_deterministic && r.config.eval_episodes == 1024);
            }
            runs_of
        };
        for name in ["repro_reach_1_ant.toml", "repro_reach_2_ants.toml"] {
            let runs = repro(name, 6, if name.contains("2_ants") { 20_000_000 } else { 10_000_000 });
            let seeds: Vec<u64> = runs.iter().map(|r| r.config.seed).collect();
            assert_eq!(seeds, [0, 1, 2, 0, 1, 2]);
        }
        let eq = repro("repro_equivariance.toml", 9, 10_000_000);
        assert!(eq.iter().all(|r| r.config.fixed_start && r.config.eval_rotations == [0.0, 180.0]));
        let sumo = repro("repro_sumo.toml", 1, 10_000_000);
        assert_eq!((sumo[0].config.model.as_str(), sumo[0].config.opponent.as_str()), ("shnn", "mlp_hn"));

        // The diagnostics beside experiment 1b: each changes one thing of `mlp_hn` on 2_ants.
        let load = |name: &str| Sweep::load(&dir.join(name)).unwrap().runs().unwrap();
        let base = &repro("repro_reach_2_ants.toml", 6, 20_000_000)[3].config;
        assert_eq!((base.model.as_str(), base.seed), ("mlp_hn", 0));
        let no_assignment = load("repro_reach_2_ants_no_assignment.toml");
        assert_eq!(no_assignment.len(), 1);
        let expected = TrainConfig { model: "mlp_hn:assignment=none".into(), ..base.clone() };
        assert_eq!(no_assignment[0].config, expected);
        let per_slot = load("repro_reach_2_ants_per_slot_starts.toml");
        assert_eq!(per_slot.len(), 1);
        let expected = TrainConfig { train_starts: crate::mappo::config::TrainStarts::PerSlot, ..base.clone() };
        assert_eq!(per_slot[0].config, expected);
    }

    /// Writes what a trainer leaves behind: `config.toml`, then a checkpoint, then `done.json`.
    fn fake_run(dir: &RunDir, config: &TrainConfig, done: bool) {
        std::fs::create_dir_all(dir.root()).unwrap();
        config.save(&dir.config()).unwrap();
        std::fs::write(dir.checkpoint(), "{}").unwrap();
        if done {
            std::fs::write(dir.done(), "{}").unwrap();
        }
    }

    #[test]
    fn skips_done_resumes_partial_trains_new() {
        let tmp = TempDir::new("sweep-resume");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\", \"shnn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        // run 0: done; run 1: partial (started with fewer steps); runs 2, 3: new.
        fake_run(&RunDir::new(tmp.0.join(&runs[0].name)), &runs[0].config, true);
        let shorter = TrainConfig { steps: 1000, ..runs[1].config.clone() };
        fake_run(&RunDir::new(tmp.0.join(&runs[1].name)), &shorter, false);
        let calls = RefCell::new(Vec::new());
        let fake_train = |c: &TrainConfig, r: &RunDir| {
            calls.borrow_mut().push((c.model.clone(), c.seed, r.root().to_path_buf()));
            fake_run(r, c, true);
            Ok(RunSummary::default())
        };
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), fake_train).unwrap();
        assert_eq!(outcome, SweepOutcome { runs: 4, trained: 2, resumed: 1, skipped: 1, taken: 0 });
        let called: Vec<(String, u64)> = calls.borrow().iter().map(|(m, s, _)| (m.clone(), *s)).collect();
        assert_eq!(called, [("mlp_hn".to_string(), 1), ("shnn".into(), 0), ("shnn".into(), 1)]);
        assert_eq!(calls.borrow()[0].2, tmp.0.join("team_reach_1_ant/mlp_hn/seed1"));
        assert_eq!(std::fs::read_to_string(tmp.0.join("sweep.toml")).unwrap(), text);

        // Everything is done now.
        calls.borrow_mut().clear();
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), fake_train).unwrap();
        assert_eq!(outcome, SweepOutcome { runs: 4, trained: 0, resumed: 0, skipped: 4, taken: 0 });
        assert!(calls.borrow().is_empty());
    }

    /// A stop asked for between runs (the first signal, during a sweep's last iteration of
    /// a run) ends the sweep before the next run: its error says nothing was changed, and
    /// nothing is (no directory is made for it); a partial run keeps its own.
    #[test]
    fn a_stop_before_a_new_run_leaves_no_directory() {
        let tmp = TempDir::new("sweep-stop");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        let mut calls = 0;
        let e = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, r| {
            calls += 1;
            if c.seed == 0 {
                fake_run(r, c, true);
                return Ok(RunSummary::default());
            }
            Err(RlError::Interrupted { run: r.root().to_path_buf(), iteration: None })
        })
        .unwrap_err();
        assert!(matches!(e, RlError::Interrupted { iteration: None, .. }), "{e}");
        assert_eq!(calls, 2);
        assert!(tmp.0.join(&runs[0].name).join("done.json").is_file());
        assert!(!tmp.0.join(&runs[1].name).exists(), "the stopped new run left its directory");

        // A partial run stopped before its next iteration keeps its directory and checkpoint.
        let partial = RunDir::new(tmp.0.join(&runs[1].name));
        fake_run(&partial, &runs[1].config, false);
        let e = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |_, r| {
            Err(RlError::Interrupted { run: r.root().to_path_buf(), iteration: None })
        })
        .unwrap_err();
        assert!(matches!(e, RlError::Interrupted { .. }), "{e}");
        assert!(partial.checkpoint().is_file());
    }

    /// Issue 44 item 11: two `meben ablate` on one directory shared the work but both
    /// exited 1 with "2 of 4 runs failed": a run whose lock another process holds is taken,
    /// not failed, and the sweep succeeds; its last line is written for a person.
    #[test]
    fn a_run_another_process_holds_is_taken_not_failed() {
        let tmp = TempDir::new("sweep-taken");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1, 2]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        let held = RunDir::new(tmp.0.join(&runs[1].name));
        std::fs::create_dir_all(held.root()).unwrap();
        // As another `meben ablate` holds it (an flock on its own open file).
        let other = crate::app::lock::RunLock::acquire(held.root()).unwrap();
        let mut trained = Vec::new();
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, r| {
            std::fs::create_dir_all(r.root()).unwrap(); // as `train` does
            let _lock = crate::app::lock::RunLock::acquire(r.root())?;
            trained.push(c.seed);
            fake_run(r, c, true);
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(trained, [0, 2]);
        assert_eq!(outcome, SweepOutcome { runs: 3, trained: 2, resumed: 0, skipped: 0, taken: 1 });
        assert_eq!(
            outcome.to_string(),
            "3 runs: 2 trained, 0 resumed, 0 already done, 1 taken by another process (training there; `meben \
             status` shows it)"
        );
        drop(other);
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::all(), |c, r| {
            fake_run(r, c, true);
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(outcome.to_string(), "3 runs: 1 trained, 0 resumed, 2 already done");
    }

    #[test]
    fn shards_run_only_their_runs_and_mismatched_checkpoints_fail() {
        let tmp = TempDir::new("sweep-shard");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\"]\nseeds = [0, 1, 2, 3, 4]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        let mut seeds = Vec::new();
        let outcome = run_sweep(&sweep, &tmp.0, &RunSelection::shard(Shard::parse("2/2").unwrap()), |c, _| {
            seeds.push(c.seed);
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(seeds, [1, 3]);
        assert_eq!(outcome.trained, 2);

        // A partial run made with another learning rate is not resumed; the others still run.
        let other = TrainConfig { learning_rate: 1e-3, num_evals: 3, ..runs[0].config.clone() };
        fake_run(&RunDir::new(tmp.0.join(&runs[0].name)), &other, false);
        let mut seeds = Vec::new();
        let msg = run_sweep(&sweep, &tmp.0, &RunSelection::shard(Shard::parse("1/2").unwrap()), |c, _| {
            seeds.push(c.seed);
            Ok(RunSummary::default())
        })
        .unwrap_err()
        .to_string();
        assert_eq!(seeds, [2, 4]);
        for w in ["team_reach_1_ant/mlp_hn/seed0", "learning_rate", "num_evals", "1 of 3 runs"] {
            assert!(msg.contains(w), "{msg} (missing {w})");
        }
        assert!(!msg.contains("steps:"), "{msg}");
    }

    #[test]
    fn only_patterns_select_runs_and_threads_and_devices_do_not_block_a_resume() {
        let tmp = TempDir::new("sweep-only");
        let text = "envs = [\"team_reach/1_ant\"]\nmodels = [\"mlp_hn\", \"shnn\"]\nseeds = [0, 1]\npreset = \"quick\"";
        let sweep = Sweep::parse(text, "s.toml").unwrap();
        let runs = sweep.runs().unwrap();
        // A partial shnn run trained with one thread, other checkpoints and on the GPU; the
        // sweep says every core, its own checkpoint interval and the CPU.
        let one_thread =
            TrainConfig { threads: 1, checkpoint_every: 7, device: tensor::Device::Gpu, ..runs[3].config.clone() };
        fake_run(&RunDir::new(tmp.0.join(&runs[3].name)), &one_thread, false);
        let selection = RunSelection { shard: None, only: vec!["shnn/".into(), "mlp_hn/seed0".into()] };
        let mut called = Vec::new();
        let outcome = run_sweep(&sweep, &tmp.0, &selection, |c, _| {
            called.push((c.model.clone(), c.seed));
            Ok(RunSummary::default())
        })
        .unwrap();
        assert_eq!(called, [("mlp_hn".to_string(), 0), ("shnn".into(), 0), ("shnn".into(), 1)]);
        assert_eq!(outcome, SweepOutcome { runs: 3, trained: 2, resumed: 1, skipped: 0, taken: 0 });

        // A pattern that matches nothing is an error naming it, not a silent no-op.
        let none = RunSelection { shard: Some(Shard::parse("2/2").unwrap()), only: vec!["2_ants".into()] };
        let msg = run_sweep(&sweep, &tmp.0, &none, |_, _| Ok(RunSummary::default())).unwrap_err().to_string();
        for w in ["--only", "2_ants", "no run of the 4", "s.toml", "shard 2/2"] {
            assert!(msg.contains(w), "{msg} (missing {w})");
        }
    }
}
