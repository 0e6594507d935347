//! A sweep file read and checked ([`Sweep::load`], [`Sweep::parse`]; the format is in the
//! module docs of [`crate::app::sweep`]).

use std::path::Path;

use serde::Deserialize;

use crate::app::names::sanitize_component;
use crate::app::presets::Preset;
use crate::error::{Result, RlError};
use crate::mappo::config::{TrainConfig, read_text_file};

/// The largest sweep file read: 64 MiB (some million seeds).
pub const MAX_SWEEP_BYTES: u64 = 64 << 20;

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

impl Sweep {
    /// Reads and parses a sweep file.
    pub fn load(path: &Path) -> Result<Sweep> {
        let text = read_text_file(path, MAX_SWEEP_BYTES, "a sweep file")?;
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
        check_run_names(&envs, &models, &variants, source)?;
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

/// The longest file name most file systems take, in bytes (Linux's `NAME_MAX`, NTFS's and
/// APFS's 255 characters).
pub const MAX_NAME_BYTES: usize = 255;

/// Checks, when the sweep file is read, that every component of every run's directory
/// (`<env>/<model>[+<variant>]/seed<N>`, module docs of [`crate::app::sweep`]) is a file
/// name the file system takes: at most [`MAX_NAME_BYTES`] bytes. Before, a variant name
/// too long passed and its run failed when its turn came, hours into the sweep (issue 77
/// item 14). Errors name the sweep file, the field and the value.
fn check_run_names(envs: &[String], models: &[String], variants: &[Variant], source: &str) -> Result<()> {
    let too_long = |field: &str, value: &str, component: &str| {
        RlError::config(
            source,
            field,
            value,
            format!(
                "the run directory name {component:?} would be {} bytes, beyond the {MAX_NAME_BYTES} a file name may \
                 have: shorten it",
                component.len()
            ),
        )
    };
    for env in envs {
        let component = sanitize_component(env);
        if component.len() > MAX_NAME_BYTES {
            return Err(too_long("envs", env, &component));
        }
    }
    for model in models {
        let base = sanitize_component(model);
        if base.len() > MAX_NAME_BYTES {
            return Err(too_long("models", model, &base));
        }
        for (i, v) in variants.iter().enumerate() {
            let component = format!("{base}+{}", v.name);
            if component.len() > MAX_NAME_BYTES {
                return Err(too_long(&format!("variants[{i}].name"), &v.name, &component));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// Issue 77 item 14: a variant name too long for a file name passed the sweep's checks
    /// and its run failed when its turn came. Every component of every run's directory is
    /// checked when the file is read, naming the file, the field and the value.
    #[test]
    fn run_directory_names_too_long_for_a_file_name_are_refused_when_read() {
        let head = "envs = [\"team_reach/1_ant\"]\nseeds = [0]\n";
        let long = "v".repeat(250);
        let text = format!("{head}models = [\"mlp_hn\"]\n[[variants]]\nname = \"{long}\"\n");
        let msg = Sweep::parse(&text, "bad.toml").unwrap_err().to_string();
        assert!(msg.starts_with("bad.toml") && msg.contains("variants[0].name") && msg.contains(&long), "{msg}");
        assert!(msg.contains("257 bytes") && msg.contains("255"), "{msg}");
        // Just fits: `mlp_hn+` and 248 characters.
        let fits = format!("{head}models = [\"mlp_hn\"]\n[[variants]]\nname = \"{}\"\n", "v".repeat(248));
        Sweep::parse(&fits, "ok.toml").unwrap();
        let model = format!("mlp_hn:{}", "x".repeat(300));
        let msg = Sweep::parse(&format!("{head}models = [\"{model}\"]\n"), "bad.toml").unwrap_err().to_string();
        assert!(msg.contains("`models`") && msg.contains(&model), "{msg}");
        let env = format!("team_reach:agents=ant;R={}", "5".repeat(300));
        let text = format!("envs = [\"{env}\"]\nmodels = [\"shnn\"]\nseeds = [0]\n");
        let msg = Sweep::parse(&text, "bad.toml").unwrap_err().to_string();
        assert!(msg.contains("`envs`") && msg.contains(&env), "{msg}");
    }
}
