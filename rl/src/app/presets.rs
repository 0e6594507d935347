//! The configuration presets and the layers a [`TrainConfig`] is resolved from, each
//! overriding the one before:
//! 1. a preset: `quick` (the built-in default of `meben train`: `shnn` on `team_reach/1_ant`
//!    in about ten minutes on 2 cores: 256 environments, batch 128 unrolls x 8 minibatches,
//!    1.5M steps, learning rate decayed linearly to 0, entropy bonus 1e-3 (both presets take
//!    the bonus's entropy as the reference's Tanh-Normal estimate), evaluation with
//!    mean actions) or `paper` (the reference schedule: 2048 environments, 50M steps for Team
//!    Reach, 20M and batch 128 for Team Sumo, evaluation with sampled actions as the release's
//!    `run_eval`);
//! 2. a TOML file (`--config file.toml`), whose keys are the fields of [`TrainConfig`] (and
//!    `preset`);
//! 3. command-line options (`--env`, `--model`, `--set field=value`, ...).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};
use crate::mappo::config::{
    EntropyKind, NormStart, ObsNormKind, TrainConfig, TrainStarts, default_eval_rotations, read_config_text,
};

/// The named starting points of a configuration (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// About ten minutes on 2 cores: smaller batches, shorter schedule.
    #[default]
    Quick,
    /// The reference release's schedule (MEBEN.md section 6).
    Paper,
}

impl Preset {
    /// Parses `quick` or `paper`.
    pub fn parse(s: &str, source: &str) -> Result<Preset> {
        match s {
            "quick" => Ok(Preset::Quick),
            "paper" => Ok(Preset::Paper),
            _ => Err(RlError::config(source, "preset", s, "expected `quick` or `paper`")),
        }
    }
}

impl TrainConfig {
    /// The preset's configuration for `env` (module docs).
    pub fn preset(preset: Preset, env: &str) -> TrainConfig {
        let sumo = env.starts_with("team_sumo");
        let paper = TrainConfig {
            env: env.to_string(),
            model: "shnn".into(),
            opponent: String::new(),
            seed: 0,
            fixed_start: false,
            train_starts: TrainStarts::Fresh,
            steps: if sumo { 20_000_000 } else { 50_000_000 },
            num_envs: 2048,
            unroll_length: 5,
            batch_size: if sumo { 128 } else { 1024 },
            num_minibatches: 32,
            epochs: 4,
            discount: 0.97,
            gae_lambda: 0.95,
            clip_epsilon: 0.3,
            value_coef: 0.25,
            entropy_coef: 1e-2,
            entropy: EntropyKind::TanhNormal,
            assignment_entropy_scale: 1.0,
            assignment_warmup_steps: 0,
            assignment_hold_steps: 1,
            assignment_hold_episode: false,
            assignment_gradient: crate::AssignmentGradient::Sampled,
            assignment_value_at_draw: false,
            learning_rate: 3e-4,
            lr_decay: false,
            grad_clip: 0.1,
            obs_norm: ObsNormKind::Auto,
            obs_norm_start: NormStart::Empty,
            reward_scaling: 1.0,
            curriculum_fraction: 0.25,
            num_evals: 50,
            eval_episodes: 1024,
            eval_deterministic: false,
            eval_rotations: default_eval_rotations(),
            checkpoint_every: 10,
            threads: 0,
            device: tensor::Device::Cpu,
            act_device: crate::mappo::device::ActDevice::Same,
            gpu_matmul_tile: tensor::GpuConfig::default().matmul_tile.rows(),
            gpu_reduce_lanes: tensor::GpuConfig::default().reduce_lanes,
        };
        match preset {
            Preset::Paper => paper,
            Preset::Quick => TrainConfig {
                steps: 1_500_000,
                num_envs: 256,
                batch_size: 128,
                lr_decay: true,
                // A tenth of the reference's entropy bonus: over 1.5M steps the mean action
                // (what evaluation takes) lags the sampled policy less. Quick preset, final
                // evaluation success over seeds 0-3 (128 episodes each, commit 794ad79):
                // 57.0, 67.2, 92.2, 54.7% with 1e-3 against 10.2, 78.1, 81.2, 29.7% with 1e-2.
                entropy_coef: 1e-3,
                num_minibatches: 8,
                num_evals: 10,
                eval_episodes: 128,
                // Mean actions: the entropy bonus above was tuned with them.
                eval_deterministic: true,
                checkpoint_every: 20,
                ..paper
            },
        }
    }

    /// Resolves a configuration from its layers (module docs): `preset` (else the file's
    /// `preset` key, else `quick`), the TOML `file`, then `overrides` (`field = value`
    /// pairs, values in TOML syntax or bare strings), and validates it. Errors name the
    /// overrides "command line" ([`TrainConfig::resolve_from`] names them otherwise).
    pub fn resolve(preset: Option<Preset>, file: Option<&Path>, overrides: &[(String, String)]) -> Result<TrainConfig> {
        Self::resolve_from(preset, file, overrides, "command line")
    }

    /// [`TrainConfig::resolve`] with errors naming the overrides' origin `origin` (Python's
    /// `meben.train` keyword arguments, for one).
    pub fn resolve_from(
        preset: Option<Preset>,
        file: Option<&Path>,
        overrides: &[(String, String)],
        origin: &str,
    ) -> Result<TrainConfig> {
        let mut table = toml::Table::new();
        if let Some(path) = file {
            let text = read_config_text(path)?;
            table = text.parse::<toml::Table>().map_err(|e| RlError::file(path, format!("invalid TOML: {e}")))?;
        }
        let file_source = file.map(|p| p.display().to_string()).unwrap_or_else(|| "built-in".into());
        let source = if overrides.is_empty() { file_source } else { format!("{file_source} + {origin}") };
        for (field, value) in overrides {
            table.insert(field.clone(), parse_override(value));
        }
        let preset = match (preset, table.remove("preset")) {
            (Some(p), _) => p,
            (None, Some(toml::Value::String(s))) => Preset::parse(&s, &source)?,
            (None, Some(v)) => {
                return Err(RlError::config(&source, "preset", value_text(&v), "expected `quick` or `paper`"));
            }
            (None, None) => Preset::Quick,
        };
        let env = match table.get("env") {
            Some(toml::Value::String(s)) => s.clone(),
            Some(v) => return Err(RlError::config(&source, "env", value_text(v), "expected a string")),
            None => "team_reach/1_ant".to_string(),
        };
        let base = TrainConfig::preset(preset, &env).to_full_table();
        let mut merged = base.clone();
        for (k, v) in &table {
            if !merged.contains_key(k) {
                let known: Vec<&str> = merged.keys().map(|s| s.as_str()).collect();
                return Err(RlError::config(
                    &source,
                    k,
                    value_text(v),
                    format!("unknown field; known fields: preset, {}", known.join(", ")),
                ));
            }
            merged.insert(k.clone(), v.clone());
        }
        let config: TrainConfig =
            toml::Value::Table(merged).try_into().map_err(|e| wrong_type(&source, &base, &table, e))?;
        config.validate(&source)?;
        Ok(config)
    }
}

/// The error for a given field whose value does not have the field's type (`steps = -1`,
/// `num_evals = "abc"`): the serde error alone names neither field nor value, so each given
/// field is tried alone on the (valid) preset `base` and the first that fails is named.
fn wrong_type(source: &str, base: &toml::Table, given: &toml::Table, e: toml::de::Error) -> RlError {
    for (k, v) in given {
        let mut one = base.clone();
        one.insert(k.clone(), v.clone());
        if let Err(e) = toml::Value::Table(one).try_into::<TrainConfig>() {
            // An integer beyond TOML's (`--seed 9223372036854775808`) arrives as a string:
            // serde's "invalid type: string" would hide the bound.
            if let (Some(toml::Value::Integer(_)), toml::Value::String(s)) = (base.get(k), v)
                && is_integer_text(s)
            {
                return RlError::config(
                    source,
                    k,
                    s,
                    "out of range: at most 9223372036854775807 (TOML integers are signed 64-bit)",
                );
            }
            // A choice given as a number, a boolean or an array: serde says only "invalid
            // type: unit variant, expected string only"; the choices are named instead.
            if let (Some(toml::Value::String(_)), false) = (base.get(k), v.is_str()) {
                return RlError::config(source, k, value_text(v), expected_string(base, k));
            }
            return RlError::config(source, k, value_text(v), e.message());
        }
    }
    RlError::config(source, "(several)", "", e.message())
}

/// "expected a string" for field `k` of `base`, with the values it takes when it is a choice
/// (an enum): those serde lists for a string that is none of them.
fn expected_string(base: &toml::Table, k: &str) -> String {
    let mut probe = base.clone();
    probe.insert(k.to_string(), toml::Value::String("\u{1}".into()));
    match toml::Value::Table(probe).try_into::<TrainConfig>() {
        Err(e) => match e.message().split_once("expected ") {
            Some((_, choices)) => format!("expected a string: {choices}"),
            None => "expected a string".into(),
        },
        Ok(_) => "expected a string".into(),
    }
}

/// Whether `s` is an integer in decimal (an optional sign, then digits), of any size.
fn is_integer_text(s: &str) -> bool {
    let digits = s.strip_prefix(['-', '+']).unwrap_or(s);
    !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit())
}

/// A TOML value as the user wrote it, strings without their quotes.
fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// A command-line value as TOML: numbers, booleans, arrays as written, anything else as a
/// string (so `--set model=shnn` needs no quotes).
fn parse_override(value: &str) -> toml::Value {
    let doc = format!("v = {value}");
    match doc.parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(value.into())),
        Err(_) => toml::Value::String(value.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mappo::assignment_hold::HoldRule;
    use crate::mappo::config::MAX_CONFIG_BYTES;

    #[test]
    fn presets_are_valid_and_paper_matches_the_reference() {
        for env in ["team_reach/1_ant", "team_sumo/2_ants"] {
            for p in [Preset::Quick, Preset::Paper] {
                TrainConfig::preset(p, env).validate("test").unwrap();
            }
        }
        let p = TrainConfig::preset(Preset::Paper, "team_reach/1_ant");
        assert_eq!(p.steps_per_iteration(), 163_840);
        assert_eq!(p.unrolls_per_iteration(), 16);
        assert_eq!(TrainConfig::preset(Preset::Paper, "team_sumo/2_ants").batch_size, 128);
    }

    /// A value of the wrong type names its field and value (it used to say "field `*` = \"\"",
    /// leaving the user to find the field in serde's message).
    #[test]
    fn a_value_of_the_wrong_type_names_its_field_and_value() {
        let cases = [
            ("steps", "-1", "field `steps` = \"-1\"", "u64"),
            ("num_evals", "abc", "field `num_evals` = \"abc\"", "usize"),
        ];
        for (field, value, named, expected) in cases {
            let ov = vec![("seed".to_string(), "3".to_string()), (field.to_string(), value.to_string())];
            let e = TrainConfig::resolve(None, None, &ov).unwrap_err().to_string();
            assert!(e.starts_with(&format!("built-in + command line: {named}: ")), "{e}");
            assert!(e.contains(expected), "{e}");
        }
        // A choice given as another type names its choices (serde said "invalid type: unit
        // variant, expected string only").
        for (field, value, choices) in [
            ("entropy", "5", "`tanh_normal` or `normal`"),
            ("assignment_gradient", "true", "one of `sampled`, `expected`, `episode`"),
            ("train_starts", "[1]", "`fresh` or `per_slot`"),
        ] {
            let ov = vec![(field.to_string(), value.to_string())];
            let e = TrainConfig::resolve(None, None, &ov).unwrap_err().to_string();
            let named = format!("built-in + command line: field `{field}` = \"{value}\": expected a string: {choices}");
            assert_eq!(e, named);
        }
        // So does a bad `env` or `preset`, which are read before the rest.
        let e = TrainConfig::resolve(None, None, &[("env".to_string(), "[1]".to_string())]).unwrap_err().to_string();
        assert!(e.starts_with("built-in + command line: field `env` = \"[1]\": expected a string"), "{e}");
        let dir = crate::app::test_util::TempDir::new("wrong-type");
        let path = dir.0.join("bad.toml");
        std::fs::write(&path, "model = \"mlp_hn\"\nepochs = \"four\"\n").unwrap();
        let e = TrainConfig::resolve(None, Some(&path), &[]).unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}: field `epochs` = \"four\": ", path.display())), "{e}");
    }

    /// Issue 44 item 12: `--seed 9223372036854775808` said "invalid type: string, expected
    /// u64"; the bound is now named with the field and the value.
    #[test]
    fn an_integer_beyond_toml_names_the_bound() {
        for (field, value) in [("seed", "9223372036854775808"), ("steps", "99999999999999999999999")] {
            let ov = vec![(field.to_string(), value.to_string())];
            let e = TrainConfig::resolve(None, None, &ov).unwrap_err().to_string();
            assert!(e.contains(&format!("field `{field}` = \"{value}\"")), "{e}");
            assert!(e.contains("at most 9223372036854775807"), "{e}");
        }
        // A string that is not a number keeps serde's message.
        let ov = vec![("seed".to_string(), "12a".to_string())];
        let e = TrainConfig::resolve(None, None, &ov).unwrap_err().to_string();
        assert!(e.contains("field `seed` = \"12a\"") && e.contains("u64"), "{e}");
    }

    /// Issue 44 item 12: `--config /dev/zero` was read until memory ran out. A file above
    /// 1 MiB is refused, named; one of 1 MiB is read. Issue 77 item 8: a device or a FIFO
    /// (which hung) is refused before it is opened.
    #[test]
    fn a_configuration_file_above_one_mib_is_refused() {
        let dir = crate::app::test_util::TempDir::new("big-config");
        let path = dir.0.join("big.toml");
        let line = "# padding\n";
        let fill = line.repeat((MAX_CONFIG_BYTES as usize) / line.len());
        let exact = format!("{fill}{}", "#".repeat(MAX_CONFIG_BYTES as usize - fill.len()));
        std::fs::write(&path, &exact).unwrap();
        assert_eq!(read_config_text(&path).unwrap().len() as u64, MAX_CONFIG_BYTES);
        std::fs::write(&path, format!("{exact}\n")).unwrap();
        let e = TrainConfig::resolve(None, Some(&path), &[]).unwrap_err().to_string();
        assert!(e.starts_with(&path.display().to_string()) && e.contains("1 MiB"), "{e}");
        #[cfg(target_os = "linux")]
        {
            let e = TrainConfig::resolve(None, Some(Path::new("/dev/zero")), &[]).unwrap_err().to_string();
            assert!(e.starts_with("/dev/zero: not a regular file"), "{e}");
            let fifo = dir.0.join("fifo.toml");
            assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
            let e = TrainConfig::resolve(None, Some(&fifo), &[]).unwrap_err().to_string();
            assert!(e.contains("fifo.toml") && e.contains("not a regular file"), "{e}");
        }
    }

    #[test]
    fn overrides_and_round_trip() {
        let ov = vec![("num_envs".to_string(), "128".to_string()), ("model".to_string(), "mlp_hn".to_string())];
        let c = TrainConfig::resolve(Some(Preset::Paper), None, &ov).unwrap();
        assert_eq!(c.num_envs, 128);
        assert_eq!(c.model, "mlp_hn");
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back, c);
    }

    /// Found by the property test `a_configuration_survives_its_toml_file`: a configuration
    /// built in Rust with a seed or step count above `i64::MAX` validated, was written to
    /// config.toml, and could not be read back ("u64 value was too large"), so the run could
    /// neither resume nor be evaluated. Validation now refuses it, naming the field.
    #[test]
    fn integers_beyond_toml_are_refused_before_anything_is_written() {
        for field in ["seed", "steps", "epochs", "checkpoint_every"] {
            let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
            match field {
                "seed" => c.seed = 1 << 63,
                "steps" => c.steps = u64::MAX,
                "epochs" => c.epochs = usize::MAX,
                _ => c.checkpoint_every = usize::MAX,
            }
            let e = c.validate("test").unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("signed 64-bit"), "{e}");
        }
        let mut c = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
        c.seed = i64::MAX as u64;
        c.validate("test").unwrap();
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back.seed, i64::MAX as u64);
    }

    #[test]
    fn bad_values_name_the_field() {
        let cases = [
            ("num_envs", "0", "num_envs"),
            ("env", "team_reach/no_such", "env"),
            ("model", "resnet", "model"),
            ("discount", "1.5", "discount"),
            ("num_envs", "\"many\"", "num_envs"),
            ("colour", "3", "colour"),
            ("num_envs", "100", "num_envs"),
            ("num_envs", "1099511627776", "at most 1048576 environments"),
            ("eval_rotations", "[180.0]", "eval_rotations"),
            ("eval_rotations", "[]", "eval_rotations"),
            ("eval_rotations", "[0.0, 90.0, 90.0]", "90 appears twice"),
            ("eval_rotations", "[0.0, nan]", "finite"),
            ("batch_size", "4611686018427387904", "batch_size"),
            ("batch_size", "1099511627776", "16777216"),
            ("unroll_length", "18446744073709551615", "unroll_length"),
            ("eval_episodes", "18446744073709551615", "eval_episodes"),
            ("entropy", "gaussian", "entropy"),
        ];
        for (field, value, named) in cases {
            let e = TrainConfig::resolve(None, None, &[(field.to_string(), value.to_string())]).unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains(named), "{field}={value}: {msg}");
        }
    }

    #[test]
    fn files_written_before_the_later_fields_load_with_their_defaults() {
        let c = TrainConfig::preset(Preset::Paper, "team_reach/1_ant");
        assert!(!c.eval_deterministic, "the paper preset samples in evaluation, as the release");
        assert!(TrainConfig::preset(Preset::Quick, "team_reach/1_ant").eval_deterministic);
        assert_eq!(c.entropy, EntropyKind::TanhNormal);
        assert_eq!(c.obs_norm_start, NormStart::Empty, "the release's normaliser starts empty");
        let text: String = c
            .to_toml()
            .lines()
            .filter(|l| {
                !l.starts_with("eval_rotations") && !l.starts_with("entropy =") && !l.starts_with("obs_norm_start")
            })
            .map(|l| format!("{l}\n"))
            .collect();
        let dir = std::env::temp_dir().join(format!("meben-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("config.toml");
        std::fs::write(&path, text).unwrap();
        let back = TrainConfig::load(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(back.eval_rotations, [0.0]);
        assert_eq!(back.entropy, EntropyKind::Normal, "old runs trained with the Normal entropy");
        assert_eq!(back.obs_norm_start, NormStart::FirstObservation, "old runs started from the first observations");
        assert_eq!(
            back,
            TrainConfig { entropy: EntropyKind::Normal, obs_norm_start: NormStart::FirstObservation, ..c }
        );
    }

    #[test]
    fn train_starts_per_slot_is_written_only_when_set_and_refused_with_a_fixed_start() {
        use envs::tasks::StartMode;
        let c = TrainConfig::preset(Preset::Paper, "team_reach/2_ants");
        assert_eq!(c.train_starts, TrainStarts::Fresh);
        assert!(!c.to_toml().contains("train_starts"), "the default is left out of config.toml");
        assert_eq!((c.train_start_mode(), c.start_mode()), (StartMode::Random, StartMode::Random));

        let set = |pairs: &[(&str, &str)]| {
            let ov: Vec<(String, String)> = pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
            TrainConfig::resolve(Some(Preset::Paper), None, &ov)
        };
        let kept = set(&[("env", "\"team_reach/2_ants\""), ("train_starts", "per_slot")]).unwrap();
        assert_eq!(kept.train_starts, TrainStarts::PerSlot);
        assert!(kept.to_toml().contains("train_starts = \"per_slot\""));
        // Training keeps each slot's first start; evaluation draws fresh ones (the release).
        assert_eq!((kept.train_start_mode(), kept.start_mode()), (StartMode::PerSlot, StartMode::Random));
        let back: TrainConfig = toml::from_str(&kept.to_toml()).unwrap();
        assert_eq!(back, kept);

        let both = set(&[("fixed_start", "true"), ("train_starts", "per_slot")]).unwrap_err().to_string();
        assert!(both.contains("train_starts") && both.contains("fixed_start"), "{both}");
        let unknown = set(&[("train_starts", "cached")]).unwrap_err().to_string();
        assert!(unknown.contains("train_starts") && unknown.contains("cached"), "{unknown}");
    }

    /// The paper preset with the fields `pairs` set (as `--set` gives them).
    fn paper_with(pairs: &[(&str, &str)]) -> crate::Result<TrainConfig> {
        let ov: Vec<(String, String)> = pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        TrainConfig::resolve(Some(Preset::Paper), None, &ov)
    }

    /// [`paper_with`] refuses `pairs` with an error that says each of `says`.
    fn assert_paper_refuses(pairs: &[(&str, &str)], says: &[&str]) {
        let e = paper_with(pairs).unwrap_err().to_string();
        for s in says {
            assert!(e.contains(s), "{pairs:?}: {e}");
        }
    }

    /// `assignment_entropy_scale`: 1 by default and then left out of `config.toml` (the files
    /// of earlier runs read as before); another value is written, read back, and taken only
    /// where a team's model learns its assignment, as a finite non-negative number.
    #[test]
    fn the_assignment_entropy_scale_is_written_only_when_set_and_only_for_a_learned_assignment() {
        let set = paper_with;
        let learned = ("model", "shnn:assignment=learned");
        let c = set(&[("env", "team_reach/2_ants"), learned]).unwrap();
        assert_eq!(c.assignment_entropy_scale, 1.0);
        assert!(!c.to_toml().contains("assignment_entropy_scale"), "the default is left out of config.toml");
        for (value, expected) in [("0", 0.0), ("0.5", 0.5), ("2", 2.0)] {
            let kept = set(&[("env", "team_reach/2_ants"), learned, ("assignment_entropy_scale", value)]).unwrap();
            assert_eq!(kept.assignment_entropy_scale, expected);
            assert!(kept.to_toml().contains("assignment_entropy_scale = "), "{value}");
            let back: TrainConfig = toml::from_str(&kept.to_toml()).unwrap();
            assert_eq!(back, kept);
        }
        // Team Sumo: either team's model may be the one that learns.
        for (model, opponent) in [("shnn:assignment=learned", "mlp_hn"), ("mlp_hn", "mlp_hn:assignment=learned")] {
            let sumo = [
                ("env", "team_sumo/2_ants"),
                ("model", model),
                ("opponent", opponent),
                ("assignment_entropy_scale", "0"),
            ];
            assert_eq!(set(&sumo).unwrap().assignment_entropy_scale, 0.0, "{model} against {opponent}");
        }
        let refused = assert_paper_refuses;
        refused(
            &[("assignment_entropy_scale", "0")],
            &["assignment_entropy_scale", "`shnn` does not", "assignment=learned"],
        );
        refused(
            &[("env", "team_sumo/2_ants"), ("model", "shnn:assignment=hungarian"), ("assignment_entropy_scale", "0.5")],
            &["assignment_entropy_scale", "`shnn:assignment=hungarian` does not"],
        );
        refused(
            &[("env", "team_sumo/2_ants"), ("opponent", "mlp_hn"), ("assignment_entropy_scale", "0.5")],
            &["neither `shnn` nor `mlp_hn`"],
        );
        for bad in ["-1", "nan", "inf"] {
            refused(
                &[learned, ("assignment_entropy_scale", bad)],
                &["assignment_entropy_scale", "finite and non-negative"],
            );
        }
    }

    /// `assignment_warmup_steps`: 0 by default and then left out of `config.toml`; another
    /// value is written, read back, and taken only where a team's model learns its
    /// assignment, as a whole number of env steps.
    #[test]
    fn the_assignment_warmup_is_written_only_when_set_and_only_for_a_learned_assignment() {
        let set = paper_with;
        let learned = ("model", "mlp_hn:assignment=learned");
        let c = set(&[("env", "team_reach/2_ants"), learned]).unwrap();
        assert_eq!(c.assignment_warmup_steps, 0);
        assert!(!c.assignment_warmup_at(0));
        assert!(!c.to_toml().contains("assignment_warmup_steps"), "the default is left out of config.toml");
        let kept = set(&[("env", "team_reach/2_ants"), learned, ("assignment_warmup_steps", "5000000")]).unwrap();
        assert_eq!(kept.assignment_warmup_steps, 5_000_000);
        assert!(kept.assignment_warmup_at(4_999_999) && !kept.assignment_warmup_at(5_000_000));
        assert!(kept.to_toml().contains("assignment_warmup_steps = 5000000"));
        let back: TrainConfig = toml::from_str(&kept.to_toml()).unwrap();
        assert_eq!(back, kept);
        let sumo =
            [("env", "team_sumo/2_ants"), ("opponent", "shnn:assignment=learned"), ("assignment_warmup_steps", "1")];
        assert_eq!(set(&sumo).unwrap().assignment_warmup_steps, 1);
        let refused = assert_paper_refuses;
        refused(&[("assignment_warmup_steps", "100")], &["assignment_warmup_steps", "100", "`shnn` does not"]);
        for bad in ["-1", "1.5", "soon"] {
            refused(&[learned, ("assignment_warmup_steps", bad)], &["assignment_warmup_steps", bad]);
        }
    }

    /// `assignment_hold_steps`: 1 by default (drawn at every step) and then left out of
    /// `config.toml`; another value is written, read back, held at 1 in a warm-up, and taken
    /// only where a team's model learns its assignment; 0 is refused.
    #[test]
    fn the_assignment_hold_is_written_only_when_set_and_only_for_a_learned_assignment() {
        let set = paper_with;
        let learned = ("model", "mlp_hn:assignment=learned");
        let c = set(&[("env", "team_reach/2_ants"), learned]).unwrap();
        assert_eq!((c.assignment_hold_steps, c.assignment_hold_at(0)), (1, HoldRule::Steps(1)));
        assert!(!c.to_toml().contains("assignment_hold"), "the defaults are left out of config.toml");
        let kept = set(&[("env", "team_reach/2_ants"), learned, ("assignment_hold_steps", "5")]).unwrap();
        assert_eq!((kept.assignment_hold_steps, kept.assignment_hold_at(0)), (5, HoldRule::Steps(5)));
        assert!(kept.to_toml().contains("assignment_hold_steps = 5"));
        let back: TrainConfig = toml::from_str(&kept.to_toml()).unwrap();
        assert_eq!(back, kept);
        let warm = set(&[
            ("env", "team_reach/2_ants"),
            learned,
            ("assignment_hold_steps", "5"),
            ("assignment_warmup_steps", "100"),
        ]);
        let warm = warm.unwrap();
        assert_eq!(
            (warm.assignment_hold_at(99), warm.assignment_hold_at(100)),
            (HoldRule::Steps(1), HoldRule::Steps(5))
        );
        // Held per episode: written, read back, Algorithm 1's in a warm-up.
        let episode = [("env", "team_reach/2_ants"), learned, ("assignment_hold_episode", "true")];
        let per_episode = set(&episode).unwrap();
        assert_eq!(per_episode.assignment_hold_at(0), HoldRule::Episode);
        assert!(per_episode.to_toml().contains("assignment_hold_episode = true"));
        let back: TrainConfig = toml::from_str(&per_episode.to_toml()).unwrap();
        assert_eq!(back, per_episode);
        let warm = set(&[episode[0], learned, episode[2], ("assignment_warmup_steps", "100")]).unwrap();
        assert_eq!(
            (warm.assignment_hold_at(99), warm.assignment_hold_at(100)),
            (HoldRule::Steps(1), HoldRule::Episode)
        );
        let refused = assert_paper_refuses;
        refused(&[("assignment_hold_episode", "true")], &["assignment_hold_episode", "true", "`shnn` does not"]);
        refused(
            &[learned, ("assignment_hold_episode", "true"), ("assignment_hold_steps", "5")],
            &["assignment_hold_steps", "5", "must be 1 with assignment_hold_episode"],
        );
        refused(&[learned, ("assignment_hold_episode", "sometimes")], &["assignment_hold_episode", "sometimes"]);
        refused(&[("assignment_hold_steps", "5")], &["assignment_hold_steps", "5", "`shnn` does not"]);
        refused(&[learned, ("assignment_hold_steps", "0")], &["assignment_hold_steps", "0", "at least 1"]);
        for bad in ["-1", "1.5", "often"] {
            refused(&[learned, ("assignment_hold_steps", bad)], &["assignment_hold_steps", bad]);
        }
    }
}
