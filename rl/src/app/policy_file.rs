//! Policy files (`meben export-policy`): what acting needs, in one safetensors file
//! ([`crate::mappo::tensor_file`]) that `meben eval --policy`, `meben render --policy` and
//! Python's `meben.Policy.load` take, and that any safetensors reader opens
//! (`safetensors.numpy.load_file`).
//!
//! **Tensors:** every team's policy parameters (all but its critic's, `team<k>.critic.*`),
//! under their names (`team0.entity...`, `team0.actor...`), as `F32`: the models' own
//! precision, so acting from the file is bit-identical to acting from the run.
//!
//! **Metadata** (`__metadata__`, strings; [`keys`]): `format` (`meben policy`),
//! `format_version` (`1`), `env`, `model`, `opponent` (Team Sumo's team 1 model, empty
//! otherwise), `config` (the run's resolved `config.toml`), `normalizers` (every team's
//! observation normaliser as JSON: kind, layout and statistics, f64 numbers in their
//! round-trip form; a JSON array, one per team), `eval` (the run's last evaluation as the
//! JSON `meben eval` writes, `null` before the first) and `eval_rotated` (its further
//! rotations), `iteration` and `env_steps` (how far the run trained), `meben_version` and
//! `meben_commit` (the program that exported it), `morphologies` (the morphology files the
//! environment names, with their contents: [`crate::app::policy_morphology`]) and `sha256`:
//! the SHA-256 of the other metadata (each key and value, in key order, each followed by a
//! zero byte) followed by the tensors alone as a safetensors file (its header: every
//! tensor's name, dtype, shape and data offsets; then the data), so that a changed byte
//! anywhere that matters is found.
//!
//! **Versions.** Version 2 (written since issue 77) is the above. Version 1 (the committed
//! `policies/` files) had no `morphologies` and its digest covered the metadata and the
//! tensor data but not the header, so swapping the offsets of two tensors of one shape went
//! unseen. It is still read, its digest checked as it was computed (and the morphology
//! files its environment names checked against the run's record beside them:
//! [`crate::app::policy_morphology::check_v1`]), because of the check both versions pass: a file must be byte for byte the file this program writes for its
//! tensors and metadata (the tensors in the writer's order, contiguous, the header padded as
//! it pads). The header is then a function of the tensors' names and shapes, which must be
//! the model's, so nothing in it can change unseen.
//!
//! **Agreement.** The metadata's `env`, `model` and `opponent` must be those of its `config`
//! (a file whose parts disagree is refused, naming the field and both values).
//!
//! A damaged, truncated or foreign file is refused by [`load_policy`] with an error naming
//! it and what is wrong. `pretrained:<env>/<model>` names a policy shipped in the
//! repository's `policies/` directory (its manifest `policies/index.toml`:
//! [`Manifest`], [`resolve_policy`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::app::run_dir::{RunDir, load_run, teams_of};
use crate::error::{Result, RlError};
use crate::mappo::checksum::sha256_hex;
use crate::mappo::config::TrainConfig;
use crate::mappo::evaluate::EvalSummary;
use crate::mappo::normalizer::ObsNormalizer;
use crate::mappo::team::Team;
use crate::mappo::tensor_file::{self, Entry};

/// The metadata keys of a policy file (module docs).
pub mod keys {
    /// `meben policy`.
    pub const FORMAT: &str = "format";
    /// [`super::FORMAT_VERSION`].
    pub const FORMAT_VERSION: &str = "format_version";
    /// The environment's name.
    pub const ENV: &str = "env";
    /// Team 0's model specification.
    pub const MODEL: &str = "model";
    /// Team 1's model specification (Team Sumo), empty when it is `model`'s.
    pub const OPPONENT: &str = "opponent";
    /// The run's resolved configuration, TOML.
    pub const CONFIG: &str = "config";
    /// The observation normalisers, a JSON array.
    pub const NORMALIZERS: &str = "normalizers";
    /// The run's last evaluation, JSON (`null` if none).
    pub const EVAL: &str = "eval";
    /// The last evaluation's further rotations, a JSON array.
    pub const EVAL_ROTATED: &str = "eval_rotated";
    /// Iterations trained.
    pub const ITERATION: &str = "iteration";
    /// Env steps trained.
    pub const ENV_STEPS: &str = "env_steps";
    /// The exporting program's version.
    pub const MEBEN_VERSION: &str = "meben_version";
    /// The exporting program's git commit.
    pub const MEBEN_COMMIT: &str = "meben_commit";
    /// The morphology files the environment names, with their contents (version 2).
    pub const MORPHOLOGIES: &str = "morphologies";
    /// The digest (module docs).
    pub const SHA256: &str = "sha256";
}

/// The value of the `format` key.
pub const FORMAT: &str = "meben policy";

/// The policy file version this program writes (it reads this one and [`FORMAT_VERSION_1`]).
pub const FORMAT_VERSION: &str = "2";

/// The first version (module docs: its digest does not cover the header), still read.
pub const FORMAT_VERSION_1: &str = "1";

/// The largest policy file read (1 GiB; the shipped ones are about 2 MB).
pub const MAX_POLICY_BYTES: u64 = 1 << 30;

/// The prefix of a shipped policy's name on the command line: `pretrained:<env>/<model>`.
pub const PRETRAINED_PREFIX: &str = "pretrained:";

/// A loaded policy file: the teams ready to act, and what the file says of their run.
#[derive(Clone, Debug)]
pub struct PolicyFile {
    /// The run's configuration (environment, models, evaluation settings, seed).
    pub config: TrainConfig,
    /// Every team, its policy parameters and normaliser from the file (the critic keeps its
    /// initial values: acting does not read it).
    pub teams: Vec<Team>,
    /// The run's last evaluation, if it had one.
    pub eval: Option<EvalSummary>,
    /// The last evaluation at the run's further rotations.
    pub eval_rotated: Vec<EvalSummary>,
    /// The whole metadata map.
    pub metadata: BTreeMap<String, String>,
}

/// Whether a parameter of team `k` belongs to its critic (not exported).
fn is_critic(k: usize, name: &str) -> bool {
    name.starts_with(&format!("team{k}.critic."))
}

/// The metadata (without [`keys::SHA256`]) as the digest reads it: each key and value
/// followed by a zero byte.
fn metadata_bytes(metadata: &BTreeMap<String, String>) -> Vec<u8> {
    let mut bytes = Vec::new();
    for (k, v) in metadata.iter().filter(|(k, _)| k.as_str() != keys::SHA256) {
        bytes.extend_from_slice(k.as_bytes());
        bytes.push(0);
        bytes.extend_from_slice(v.as_bytes());
        bytes.push(0);
    }
    bytes
}

/// The digest of a version 2 file (module docs): its metadata and its tensors as a
/// safetensors file of their own (names, dtypes, shapes, offsets and data).
fn digest(metadata: &BTreeMap<String, String>, entries: &[Entry]) -> std::result::Result<String, String> {
    let mut bytes = metadata_bytes(metadata);
    bytes.extend_from_slice(&tensor_file::serialize(entries.to_vec(), &BTreeMap::new())?);
    Ok(sha256_hex(&bytes))
}

/// The digest of a version 1 file: its metadata and its tensor data, not its header.
fn digest_v1(metadata: &BTreeMap<String, String>, data: &[u8]) -> String {
    let mut bytes = metadata_bytes(metadata);
    bytes.extend_from_slice(data);
    sha256_hex(&bytes)
}

/// The tensor data of safetensors `bytes` (after the header).
fn data_section(bytes: &[u8]) -> &[u8] {
    let n = bytes.get(..8).map_or(0, |b| u64::from_le_bytes(b.try_into().unwrap_or_default()) as usize);
    bytes.get(8usize.saturating_add(n)..).unwrap_or_default()
}

/// The bytes of the policy file of `config`'s `teams`, trained `iteration` iterations
/// (`env_steps` steps), last evaluated as `evals` (one per rotation).
pub fn policy_bytes(
    config: &TrainConfig,
    teams: &[Team],
    iteration: u64,
    env_steps: u64,
    evals: &[EvalSummary],
) -> Result<Vec<u8>> {
    let mut entries = Vec::new();
    for t in teams {
        for (name, value) in t.store.iter().filter(|(n, _)| !is_critic(t.index, n)) {
            entries.push(Entry::f32(name, value.shape(), value.data().iter().copied()));
        }
    }
    let normalizers: Vec<&ObsNormalizer> = teams.iter().map(|t| &t.norm).collect();
    let mut meta = BTreeMap::new();
    let mut put = |k: &str, v: String| meta.insert(k.to_string(), v);
    put(keys::FORMAT, FORMAT.into());
    put(keys::FORMAT_VERSION, FORMAT_VERSION.into());
    put(keys::ENV, config.env.clone());
    put(keys::MODEL, config.model.clone());
    put(keys::OPPONENT, config.opponent.clone());
    put(keys::CONFIG, config.to_toml());
    put(keys::NORMALIZERS, to_json(&normalizers)?);
    put(keys::EVAL, to_json(&evals.first())?);
    put(keys::EVAL_ROTATED, to_json(evals.get(1..).unwrap_or_default())?);
    put(keys::ITERATION, iteration.to_string());
    put(keys::ENV_STEPS, env_steps.to_string());
    put(keys::MEBEN_VERSION, crate::app::build_info::VERSION.into());
    put(keys::MEBEN_COMMIT, crate::app::build_info::COMMIT.into());
    put(keys::MORPHOLOGIES, crate::app::policy_morphology::carry(&config.env)?);
    let serialise = |e: String| RlError::file("policy file", format!("cannot serialise: {e}"));
    meta.insert(keys::SHA256.into(), digest(&meta, &entries).map_err(serialise)?);
    tensor_file::serialize(entries, &meta).map_err(serialise)
}

/// `v` as JSON.
fn to_json<T: Serialize + ?Sized>(v: &T) -> Result<String> {
    serde_json::to_string(v).map_err(|e| RlError::file("policy file", format!("cannot serialise: {e}")))
}

/// What [`export_policy`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportedPolicy {
    /// Bytes written.
    pub bytes: u64,
    /// Env steps the run had trained.
    pub env_steps: u64,
    /// Its last evaluation.
    pub eval: Option<EvalSummary>,
    /// Whether it is a Team Sumo run (the evaluation's figure is a win rate).
    pub sumo: bool,
}

/// Writes the policy file of the run directory `run` (its `config.toml` and checkpoint) to
/// `out`, atomically (module docs). `out` may not be one of a run directory's own files.
pub fn export_policy(run: &RunDir, out: &Path) -> Result<ExportedPolicy> {
    crate::app::outputs::check_output("--out", out, &[])?;
    let (config, c) = load_run(run)?;
    let teams = teams_of(&config, &c, &run.checkpoint())?;
    let evals: Vec<EvalSummary> = c.last_eval.iter().chain(&c.last_eval_rotated).cloned().collect();
    let bytes = policy_bytes(&config, &teams, c.iteration, c.env_steps, &evals)?;
    nn::write_atomic(out, &bytes)?;
    Ok(ExportedPolicy { bytes: bytes.len() as u64, env_steps: c.env_steps, eval: c.last_eval, sumo: config.is_sumo() })
}

/// Reads the policy file at `path` (module docs); errors name the file and what is wrong.
pub fn load_policy(path: &Path) -> Result<PolicyFile> {
    let bytes = crate::bounded_read::read_bytes(path, MAX_POLICY_BYTES, "a policy file")?;
    if bytes.is_empty() {
        return Err(RlError::Policy { path: path.to_path_buf(), message: "an empty file".into() });
    }
    policy_from_bytes(path, &bytes)
}

/// [`load_policy`] of a file's `bytes` (`path` names it in errors).
pub fn policy_from_bytes(path: &Path, bytes: &[u8]) -> Result<PolicyFile> {
    let bad = |message: String| RlError::Policy { path: path.to_path_buf(), message };
    let (file, meta) = tensor_file::read(bytes).map_err(bad)?;
    let get = |k: &str| meta.get(k).ok_or_else(|| bad(format!("its metadata has no `{k}`")));
    if meta.get(keys::FORMAT).map(String::as_str) != Some(FORMAT) {
        return Err(bad(format!(
            "a safetensors file without `{}` = \"{FORMAT}\" in its metadata (export one with `meben export-policy`)",
            keys::FORMAT
        )));
    }
    let version = get(keys::FORMAT_VERSION)?;
    if version != FORMAT_VERSION && version != FORMAT_VERSION_1 {
        return Err(bad(format!(
            "format version {version} (this program reads versions {FORMAT_VERSION_1} and {FORMAT_VERSION})"
        )));
    }
    let entries = tensor_file::entries_of(&file);
    if tensor_file::serialize(entries.clone(), &meta).map_err(bad)? != bytes {
        return Err(bad(
            "its header is not the layout `meben export-policy` writes for its tensors (their order, data offsets \
             or padding were changed after it was written)"
                .into(),
        ));
    }
    let recorded = get(keys::SHA256)?;
    let actual = if version == FORMAT_VERSION {
        digest(&meta, &entries).map_err(bad)?
    } else {
        digest_v1(&meta, data_section(bytes))
    };
    if *recorded != actual {
        return Err(bad(format!(
            "checksum mismatch: the file was changed or damaged after it was written (SHA-256 recorded {recorded}, \
             computed {actual})"
        )));
    }
    let config: TrainConfig =
        toml::from_str(get(keys::CONFIG)?).map_err(|e| bad(format!("its `config` is not a run configuration: {e}")))?;
    config.validate(&format!("{} (metadata `config`)", path.display()))?;
    for (key, value) in [(keys::ENV, &config.env), (keys::MODEL, &config.model), (keys::OPPONENT, &config.opponent)] {
        let said = get(key)?;
        if said != value {
            return Err(bad(format!(
                "its parts disagree: metadata `{key}` = {said:?}, its `config` has {key} = {value:?}"
            )));
        }
    }
    let mut config = config;
    if version == FORMAT_VERSION {
        config.env = crate::app::policy_morphology::restore(path, &config.env, get(keys::MORPHOLOGIES)?)?;
    } else {
        crate::app::policy_morphology::check_v1(path, &config.env)?;
    }
    let json_err = |k: &str, e: serde_json::Error| bad(format!("its `{k}` is not valid: {e}"));
    let normalizers: Vec<ObsNormalizer> =
        serde_json::from_str(get(keys::NORMALIZERS)?).map_err(|e| json_err(keys::NORMALIZERS, e))?;
    let eval: Option<EvalSummary> = serde_json::from_str(get(keys::EVAL)?).map_err(|e| json_err(keys::EVAL, e))?;
    let eval_rotated: Vec<EvalSummary> =
        serde_json::from_str(get(keys::EVAL_ROTATED)?).map_err(|e| json_err(keys::EVAL_ROTATED, e))?;
    let spec = envs::tasks::Scene::from_name(&config.env)?.obs_spec;
    if normalizers.len() != spec.n_teams {
        return Err(bad(format!("{} normalisers for a scene of {} teams", normalizers.len(), spec.n_teams)));
    }
    let mut teams = Vec::with_capacity(spec.n_teams);
    let mut expected = 0;
    for (k, norm) in normalizers.into_iter().enumerate() {
        let mut t = Team::build(&config, &spec, k)?;
        let mut values = Vec::new();
        for (name, value) in t.store.iter().filter(|(n, _)| !is_critic(k, n)) {
            let (shape, data) = tensor_file::f32_values(&file, name).map_err(bad)?;
            if shape != value.shape() {
                return Err(bad(format!("tensor `{name}` has shape {shape:?}, the model's is {:?}", value.shape())));
            }
            values.push((name.to_string(), tensor::Tensor::new(data, &shape).map_err(|e| bad(e.to_string()))?));
        }
        expected += values.len();
        for (name, value) in values {
            let id = t.store.find(&name).ok_or_else(|| bad(format!("no parameter `{name}`")))?;
            t.store.set(id, value).map_err(|e| bad(e.to_string()))?;
        }
        norm.check_fits(&t.norm)
            .map_err(|e| bad(format!("the observation normaliser of team {k} does not fit: {e}")))?;
        if let Some(stats) = norm.non_finite() {
            return Err(bad(format!("the observation normaliser of team {k} has non-finite {stats} statistics")));
        }
        if let Some(stats) = norm.negative() {
            return Err(bad(format!(
                "the observation normaliser of team {k} has a negative count or sum of squares in its {stats} \
                 statistics (field `normalizers`)"
            )));
        }
        t.norm = norm;
        teams.push(t);
    }
    if file.len() != expected {
        return Err(bad(format!(
            "{} tensors, the policy of {} on {} has {expected}",
            file.len(),
            config.model,
            config.env
        )));
    }
    if let Some(t) = teams.iter().find(|t| t.store.iter().any(|(_, v)| !v.data().iter().all(|x| x.is_finite()))) {
        return Err(bad(format!("team {}'s parameters are not finite", t.index)));
    }
    // A policy exported in a learned assignment's warm-up acts as its run did then, and
    // holds its drawn assignment as the run does.
    let env_steps = if config.assignment_warmup_steps != 0 {
        let said = get(keys::ENV_STEPS)?;
        said.parse().map_err(|_| {
            bad(format!("its metadata `{}` = {said:?} is not a whole number of env steps", keys::ENV_STEPS))
        })?
    } else {
        0
    };
    for t in &mut teams {
        t.sync_assignment(&config, env_steps);
    }
    Ok(PolicyFile { config, teams, eval, eval_rotated, metadata: meta })
}

/// One shipped policy: an entry of `policies/index.toml` ([`Manifest`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShippedPolicy {
    /// The environment, e.g. `team_reach/2_ants`.
    pub env: String,
    /// Team 0's model name, e.g. `shnn` (the name in `pretrained:<env>/<model>`).
    pub model: String,
    /// Team 1's model in Team Sumo (empty: none or the same).
    #[serde(default)]
    pub opponent: String,
    /// The policy file, relative to the manifest's directory.
    pub file: String,
    /// The provenance file (configuration, commit, how it was trained and evaluated),
    /// relative to the manifest's directory.
    pub provenance: String,
    /// The SHA-256 of the policy file.
    pub sha256: String,
    /// The recorded figure's metric: `success_rate` (Team Reach) or `win_rate` (Team Sumo,
    /// team 0's).
    pub metric: String,
    /// The recorded figure: the policy's evaluation on `episodes` episodes.
    pub figure: f64,
    /// Episodes of the recorded evaluation (1024).
    pub episodes: usize,
    /// Seed of the recorded evaluation.
    pub eval_seed: u64,
    /// Whether the recorded evaluation sampled actions (else mean actions).
    pub sampled: bool,
}

impl ShippedPolicy {
    /// `<env>/<model>`, the name after `pretrained:`.
    pub fn name(&self) -> String {
        format!("{}/{}", self.env, self.model)
    }
}

/// `policies/index.toml`: the shipped policies, as `[[policy]]` tables ([`ShippedPolicy`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// The entries.
    #[serde(default)]
    pub policy: Vec<ShippedPolicy>,
}

/// The manifest's file name in a policies directory.
pub const MANIFEST: &str = "index.toml";

impl Manifest {
    /// Reads `<dir>/index.toml`; errors name the file (and line).
    pub fn load(dir: &Path) -> Result<Manifest> {
        let path = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| RlError::file(&path, format!("cannot read the manifest of shipped policies: {e}")))?;
        let m: Manifest = toml::from_str(&text).map_err(|e| RlError::file(&path, format!("invalid manifest: {e}")))?;
        let mut names: Vec<String> = m.policy.iter().map(ShippedPolicy::name).collect();
        names.sort();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(RlError::file(&path, format!("two entries for {}", w[0])));
        }
        Ok(m)
    }

    /// The shipped policies' names (`<env>/<model>`), for messages.
    pub fn names(&self) -> String {
        if self.policy.is_empty() {
            "none yet".into()
        } else {
            self.policy.iter().map(ShippedPolicy::name).collect::<Vec<_>>().join(", ")
        }
    }
}

/// The directory of shipped policies: `$MEBEN_POLICIES` if set, else the repository's
/// `policies/` (where this program was built from).
pub fn policies_dir() -> PathBuf {
    match std::env::var_os("MEBEN_POLICIES") {
        Some(d) if !d.is_empty() => PathBuf::from(d),
        _ => {
            let rl = Path::new(env!("CARGO_MANIFEST_DIR"));
            rl.parent().unwrap_or(rl).join("policies")
        }
    }
}

/// The file of the shipped policy `name` (`<env>/<model>`, e.g. `team_reach/2_ants/shnn`)
/// in `dir`, checked against its manifest entry ([`check_against_entry`]); an unknown name is
/// an error listing the shipped ones.
pub fn find_pretrained(dir: &Path, name: &str) -> Result<PathBuf> {
    let m = Manifest::load(dir)?;
    match m.policy.iter().find(|p| p.name() == name) {
        Some(p) => {
            let file = dir.join(&p.file);
            check_against_entry(&dir.join(MANIFEST), p, &file)?;
            Ok(file)
        }
        None => Err(RlError::Policy {
            path: dir.join(MANIFEST),
            message: format!(
                "no pretrained policy `{name}` is shipped (a name is <env>/<model>); shipped: {}",
                m.names()
            ),
        }),
    }
}

/// Refuses the policy file `file` of the manifest entry `entry` (of the manifest `manifest`)
/// unless its SHA-256 is the entry's and its metadata's `env`, `model` and `opponent` are
/// the entry's: an index that names a file of another environment or model is not
/// evaluated under the entry's name. Errors name both files, the field and both values.
pub fn check_against_entry(manifest: &Path, entry: &ShippedPolicy, file: &Path) -> Result<()> {
    let bytes = crate::bounded_read::read_bytes(file, MAX_POLICY_BYTES, "a policy file")?;
    let bad = |message: String| RlError::Policy { path: file.to_path_buf(), message };
    let actual = sha256_hex(&bytes);
    if actual != entry.sha256 {
        return Err(bad(format!(
            "its SHA-256 is {actual}, the entry {} of {} records sha256 = {:?}",
            entry.name(),
            manifest.display(),
            entry.sha256
        )));
    }
    let (_, meta) = tensor_file::read(&bytes).map_err(bad)?;
    for (key, listed) in [(keys::ENV, &entry.env), (keys::MODEL, &entry.model), (keys::OPPONENT, &entry.opponent)] {
        let said = meta.get(key).map_or("", String::as_str);
        if said != listed {
            return Err(bad(format!(
                "its metadata has {key} = {said:?}, the entry {} of {} has {key} = {listed:?}",
                entry.name(),
                manifest.display()
            )));
        }
    }
    Ok(())
}

/// A `--policy` argument as a file: `pretrained:<env>/<model>` ([`find_pretrained`] in
/// [`policies_dir`]) or a path.
pub fn resolve_policy(arg: &str) -> Result<PathBuf> {
    match arg.strip_prefix(PRETRAINED_PREFIX) {
        Some(name) => find_pretrained(&policies_dir(), name),
        None => Ok(PathBuf::from(arg)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_manifest_reads_and_unknown_names_list_the_shipped_ones() {
        let dir = policies_dir();
        let m = Manifest::load(&dir).unwrap();
        let e = find_pretrained(&dir, "team_reach/9_ants/shnn").unwrap_err().to_string();
        assert!(e.contains("index.toml") && e.contains("team_reach/9_ants/shnn") && e.contains("shipped:"), "{e}");
        assert!(e.contains(&m.names()), "{e}");
        let tmp = crate::app::test_util::TempDir::new("manifest");
        std::fs::write(
            tmp.0.join(MANIFEST),
            "[[policy]]\nenv = \"team_reach/1_ant\"\nmodel = \"shnn\"\nfile = \"a.safetensors\"\nprovenance = \"a.md\"\n\
             sha256 = \"0\"\nmetric = \"success_rate\"\nfigure = 0.9\nepisodes = 1024\neval_seed = 1\nsampled = true\n",
        )
        .unwrap();
        // An entry whose file is missing or not the one it records is refused, naming it.
        let e = find_pretrained(&tmp.0, "team_reach/1_ant/shnn").unwrap_err().to_string();
        assert!(e.contains("a.safetensors") && e.contains("cannot read"), "{e}");
        let e = find_pretrained(&tmp.0, "team_reach/1_ant/mlp").unwrap_err().to_string();
        assert!(e.contains("shipped: team_reach/1_ant/shnn"), "{e}");
        std::fs::write(tmp.0.join(MANIFEST), "[[policy]]\nenv = 3\n").unwrap();
        let e = Manifest::load(&tmp.0).unwrap_err().to_string();
        assert!(e.contains("index.toml") && e.contains("line"), "{e}");
    }
}
