//! Checkpoints: everything a run needs to continue exactly as if it had not stopped (the
//! configuration, counters, every team's parameters, Adam moments, normaliser statistics and
//! random streams, the state of every environment, and the running episode returns).
//!
//! # Format (version 3): a pair of files
//! - `checkpoint.<digest>.safetensors` ([`crate::mappo::tensor_file`]): every team's
//!   parameters under their names (`team0.actor.0.w`, ...), and Adam's first and second
//!   moments under `adam.m.<name>` and `adam.v.<name>`; `F32` where every value is an f32
//!   value (the parameters of the f32 models), else `F64` (Adam's host moments), so that each
//!   value reads back bit for bit. `<digest>` is the first 16 hex digits of the file's
//!   SHA-256. PyTorch (`safetensors.torch.load_file`), JAX, numpy and candle read it.
//! - `checkpoint.json`: the rest (configuration, counters, normaliser statistics, random
//!   stream positions, environment states, running returns, last evaluations), each team's
//!   parameter names in store order, and the tensors file's name, size and full SHA-256;
//!   the JSON is sealed with its own SHA-256 ([`crate::mappo::checksum`]), so the one digest
//!   chain covers both files. Numbers are written in their shortest round-trip form.
//!
//! **Atomic as a pair.** [`Checkpoint::save`] writes the tensors to their digest-named file
//! (a temporary file, synced, renamed; the directory synced), then the JSON that names them
//! (the same way), and only then removes the tensors file of the previous checkpoint. A
//! crash before the JSON's rename leaves the old JSON naming the old tensors file, which
//! still exists; after it, the new JSON names the new file, which is already in place. The
//! pair is old or new, never a mix; what a crash leaves behind (a temporary file, a tensors
//! file no JSON names) is removed by [`remove_stale_tensor_files`] when training resumes
//! (`rl::app::lock::remove_stale_temporaries`). A reader that races a save (`meben eval`
//! on a training run) and finds its tensors file already removed reads the JSON again.
//! The test hook [`CRASH_ENV`] aborts a save between its steps.
//!
//! **Older formats.** Versions 1 and 2 are one JSON file holding everything (version 2
//! sealed, version 1 from before checksums, loaded without that check); both still load and
//! resume bit-identically. [`Checkpoint::save_json`] still writes version 2.
//!
//! Nothing non-finite is written: [`Checkpoint::save`] checks every parameter, Adam moment,
//! normaliser statistic and running return first and refuses (keeping the last good pair).
//! [`Checkpoint::load`] checks the JSON's digest, the tensors file's size and digest, then
//! that the counters agree with each other and with the configuration (`env_steps =
//! iteration * steps_per_iteration`, at most the configuration's iterations, Adam's update
//! count `iteration * epochs * num_minibatches`). Errors name the file and what is wrong.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use envs::tasks::VecEnvState;
use nn::{Adam, AdamConfig, SavedTensor, StateDict};
use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};
use crate::mappo::assignment_hold::SavedHold;
use crate::mappo::checksum::sha256_hex;
use crate::mappo::config::TrainConfig;
use crate::mappo::episode_credit::SavedDraws;
use crate::mappo::evaluate::EvalSummary;
use crate::mappo::normalizer::ObsNormalizer;
use crate::mappo::seeding::RngState;
use crate::mappo::tensor_file::{self, Entry};

/// Current checkpoint format version: 3, a sealed JSON and a safetensors file (module docs);
/// versions 1 and 2 (one JSON file) still load.
pub const VERSION: u32 = 3;

/// The last format version written as one JSON file ([`Checkpoint::save_json`]).
pub const JSON_VERSION: u32 = 2;

/// The last format version written without a checksum.
const UNSEALED_VERSION: u32 = 1;

/// The largest checkpoint JSON read (1 GiB: a version 3 JSON is kilobytes, a single-file
/// version 2 one of the largest models tens of MB). Its tensors file is read up to the size
/// the JSON records.
pub const MAX_CHECKPOINT_BYTES: u64 = 1 << 30;

/// The checkpoint JSON at `path`, read within [`MAX_CHECKPOINT_BYTES`].
fn read_json(path: &Path) -> Result<Vec<u8>> {
    crate::bounded_read::read_bytes(path, MAX_CHECKPOINT_BYTES, "a checkpoint")
}

/// The extension of a checkpoint's tensors file.
pub const TENSORS_EXTENSION: &str = "safetensors";

/// Hex digits of the SHA-256 in a tensors file's name.
const NAME_DIGITS: usize = 16;

/// Test hook: with `MEBEN_TEST_CRASH=<point>:<n>` in the environment, the process aborts
/// (as kill -9 would: no clean-up, no destructors) at `<point>` of its `n`-th checkpoint
/// save, where `<point>` is `checkpoint_after_tensors` (the new tensors file is in place, the
/// JSON still names the old one) or `checkpoint_after_json` (the JSON names the new file,
/// the old tensors file is not yet removed). Used by `rl/tests/integration/checkpoint_format.rs`.
pub const CRASH_ENV: &str = "MEBEN_TEST_CRASH";

/// Checkpoint saves begun in this process (for [`CRASH_ENV`]).
static SAVES: AtomicU64 = AtomicU64::new(0);

/// Aborts the process if [`CRASH_ENV`] asks for `point` of save `n`.
fn crash_point(point: &str, n: u64) {
    if std::env::var(CRASH_ENV).is_ok_and(|v| v == format!("{point}:{n}")) {
        std::process::abort();
    }
}

/// The tensors file a version 3 checkpoint's JSON names.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TensorsRef {
    /// Its file name, in the JSON's directory: `<json stem>.<16 hex digits>.safetensors`.
    pub file: String,
    /// Its size in bytes.
    pub bytes: u64,
    /// The SHA-256 of its bytes, lower-case hex.
    pub sha256: String,
}

/// The tensors file name of the checkpoint `json` for tensors of digest `sha256`.
fn tensors_file_name(json: &Path, sha256: &str) -> String {
    format!("{}.{}.{TENSORS_EXTENSION}", stem(json), &sha256[..NAME_DIGITS])
}

/// The file stem of a checkpoint's JSON (`checkpoint`).
fn stem(json: &Path) -> String {
    json.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
}

/// Whether `name` is the name of a tensors file of the checkpoint `json` (module docs).
pub fn is_tensors_file_name(json: &Path, name: &str) -> bool {
    let digest =
        name.strip_prefix(&format!("{}.", stem(json))).and_then(|r| r.strip_suffix(&format!(".{TENSORS_EXTENSION}")));
    digest
        .is_some_and(|d| d.len() == NAME_DIGITS && d.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)))
}

/// One team's learner state.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TeamState {
    /// Parameters.
    pub params: StateDict,
    /// Optimiser.
    pub adam: Adam,
    /// Observation normaliser.
    pub normalizer: ObsNormalizer,
    /// Per-agent action-noise streams.
    pub noise: Vec<RngState>,
    /// Minibatch shuffling stream.
    pub shuffle: RngState,
    /// A learned task assignment held per episode: every environment's held assignment
    /// (absent otherwise, and from checkpoints written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub assignment_hold: Option<SavedHold>,
    /// `assignment_gradient = "episode"`: the running episodes' draws, credited when their
    /// episodes end (absent otherwise, and from checkpoints written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub episode_draws: Option<SavedDraws>,
}

/// Why [`Checkpoint::from_bytes`] failed.
enum Loaded {
    /// The tensors file the JSON names is not there (a save may have replaced the pair).
    TensorsMissing(RlError),
    /// Anything else.
    Bad(RlError),
}

/// A whole run's state at an iteration boundary.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Format version ([`VERSION`]).
    pub version: u32,
    /// The run's configuration.
    pub config: TrainConfig,
    /// Iterations done.
    pub iteration: u64,
    /// Environment steps collected.
    pub env_steps: u64,
    /// Wall-clock seconds of training so far.
    pub wall_s: f64,
    /// Evaluations done.
    pub evals_done: u64,
    /// Per team.
    pub teams: Vec<TeamState>,
    /// Every environment.
    pub env: VecEnvState,
    /// `[E, teams]` returns of the running episodes.
    pub episode_returns: Vec<f64>,
    /// The last evaluation (the first rotation of `eval_rotations`).
    pub last_eval: Option<EvalSummary>,
    /// The last evaluation at each further rotation (absent from older checkpoints: none).
    #[serde(default)]
    pub last_eval_rotated: Vec<EvalSummary>,
}

/// One team's part of a version 3 JSON: its [`TeamState`] without the tensors.
#[derive(Serialize, Deserialize)]
struct StoredTeam {
    /// Parameter names in store order (the tensors are in the tensors file).
    params: Vec<String>,
    /// Adam's configuration and update count (the moments are in the tensors file).
    adam: StoredAdam,
    normalizer: ObsNormalizer,
    noise: Vec<RngState>,
    shuffle: RngState,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    assignment_hold: Option<SavedHold>,
    /// The running episodes' draws but for their observations (in the tensors file,
    /// [`draw_tensor_name`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    episode_draws: Option<StoredDraws>,
}

/// [`SavedDraws`] without its observations.
#[derive(Serialize, Deserialize)]
struct StoredDraws {
    sigma: Vec<u32>,
    recorded: Vec<bool>,
}

/// The parts of the observations of [`SavedDraws`], each a tensor of the tensors file.
const DRAW_PARTS: [&str; 3] = ["vectors", "scalars", "heading"];

/// The tensors-file name of part `part` of team `k`'s running episodes' draws (outside the
/// parameters' `team<k>.` names).
fn draw_tensor_name(k: usize, part: &str) -> String {
    format!("episode_draws.team{k}.{part}")
}

/// Adam without its moments.
#[derive(Serialize, Deserialize)]
struct StoredAdam {
    config: AdamConfig,
    t: u64,
}

/// The version 3 JSON payload (module docs).
#[derive(Serialize, Deserialize)]
struct Stored {
    version: u32,
    tensors: TensorsRef,
    config: TrainConfig,
    iteration: u64,
    env_steps: u64,
    wall_s: f64,
    evals_done: u64,
    teams: Vec<StoredTeam>,
    env: VecEnvState,
    episode_returns: Vec<f64>,
    last_eval: Option<EvalSummary>,
    #[serde(default)]
    last_eval_rotated: Vec<EvalSummary>,
}

/// What a payload says of itself before it is read whole.
#[derive(Deserialize)]
struct Peek {
    version: u32,
    #[serde(default)]
    tensors: Option<TensorsRef>,
}

/// The tensor names of Adam's moments of parameter `name`.
fn moment_names(name: &str) -> [String; 2] {
    [format!("adam.m.{name}"), format!("adam.v.{name}")]
}

/// Syncs a directory, so that the renames in it survive a power loss in order (best
/// effort: a file system that cannot sync a directory still gets the ordered renames).
fn sync_dir(dir: &Path) {
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// The directory of `path` (`.` for a bare file name).
fn dir_of(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Removes the tensors files beside the checkpoint `json` ([`is_tensors_file_name`]) but
/// `keep`; returns the paths removed. Files that cannot be removed stay (the next clean-up
/// tries again).
fn remove_tensor_files_except(json: &Path, keep: Option<&str>) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir_of(json)) else { return removed };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if is_tensors_file_name(json, &name)
            && keep != Some(name.as_str())
            && std::fs::remove_file(entry.path()).is_ok()
        {
            removed.push(entry.path());
        }
    }
    removed
}

/// Removes the tensors files beside the checkpoint `json` that it does not name: those a
/// crash left between a save's steps (module docs), or all of them when there is no JSON
/// (a first save that crashed) or it is a single-file version; returns the paths removed.
/// When the JSON cannot be read or is damaged nothing is removed (its tensors may be
/// needed to understand it). For the holder of the run directory's lock.
pub fn remove_stale_tensor_files(json: &Path) -> Result<Vec<PathBuf>> {
    let keep = match json.try_exists() {
        Ok(true) => {
            let bytes = read_json(json)?;
            use crate::mappo::checksum::{Unsealed, unseal};
            let Ok(Unsealed::Checked(payload)) = unseal(&bytes) else {
                // Damaged, or version 1 (no tensors file either way: nothing to keep).
                return Ok(match serde_json::from_slice::<Peek>(&bytes) {
                    Ok(p) if p.version == UNSEALED_VERSION => remove_tensor_files_except(json, None),
                    _ => Vec::new(),
                });
            };
            match serde_json::from_str::<Peek>(payload) {
                Ok(Peek { tensors: Some(t), .. }) if is_tensors_file_name(json, &t.file) => Some(t.file),
                // A version 2 JSON names no tensors file.
                Ok(Peek { version: JSON_VERSION, tensors: None }) => None,
                // Anything else is damaged: keep every file.
                _ => return Ok(Vec::new()),
            }
        }
        Ok(false) => None,
        Err(e) => return Err(RlError::file(json, format!("cannot read: {e}"))),
    };
    Ok(remove_tensor_files_except(json, keep.as_deref()))
}

impl Checkpoint {
    /// Writes the checkpoint as a pair (tensors, then the JSON that names them: module
    /// docs), atomically, after checking that every value is finite; a non-finite state is
    /// refused ([`RlError::NonFinite`]) and the pair at `path` (the last good checkpoint) is
    /// kept. On any error the last good pair stays loadable.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.refuse_non_finite(path)?;
        let n = SAVES.fetch_add(1, Ordering::Relaxed) + 1;
        let serialise = |e: String| RlError::file(path, format!("cannot serialise: {e}"));
        let mut entries = Vec::new();
        let mut teams = Vec::with_capacity(self.teams.len());
        for (k, t) in self.teams.iter().enumerate() {
            let (m, v) = t.adam.moments();
            if m.len() != t.params.tensors.len() || v.len() != t.params.tensors.len() {
                return Err(serialise(format!(
                    "team {k}: {} and {} Adam moment buffers for {} parameters",
                    m.len(),
                    v.len(),
                    t.params.tensors.len()
                )));
            }
            for (p, (m, v)) in t.params.tensors.iter().zip(m.iter().zip(v)) {
                let [mn, vn] = moment_names(&p.name);
                entries.push(Entry::exact(p.name.clone(), &p.shape, &p.data));
                entries.push(Entry::exact(mn, &[m.len()], m));
                entries.push(Entry::exact(vn, &[v.len()], v));
            }
            if let Some(d) = &t.episode_draws {
                for (part, values) in DRAW_PARTS.iter().zip([&d.vectors, &d.scalars, &d.heading]) {
                    entries.push(Entry::f32(draw_tensor_name(k, part), &[values.len()], values.iter().copied()));
                }
            }
            teams.push(StoredTeam {
                params: t.params.tensors.iter().map(|p| p.name.clone()).collect(),
                adam: StoredAdam { config: t.adam.config, t: t.adam.t },
                normalizer: t.normalizer.clone(),
                noise: t.noise.clone(),
                shuffle: t.shuffle.clone(),
                assignment_hold: t.assignment_hold.clone(),
                episode_draws: t
                    .episode_draws
                    .as_ref()
                    .map(|d| StoredDraws { sigma: d.sigma.clone(), recorded: d.recorded.clone() }),
            });
        }
        let meta = BTreeMap::from([("format".to_string(), format!("meben checkpoint tensors, version {VERSION}"))]);
        let tensors = tensor_file::serialize(entries, &meta).map_err(serialise)?;
        let sha256 = sha256_hex(&tensors);
        let file = tensors_file_name(path, &sha256);
        let stored = Stored {
            version: VERSION,
            tensors: TensorsRef { file: file.clone(), bytes: tensors.len() as u64, sha256 },
            config: self.config.clone(),
            iteration: self.iteration,
            env_steps: self.env_steps,
            wall_s: self.wall_s,
            evals_done: self.evals_done,
            teams,
            env: self.env.clone(),
            episode_returns: self.episode_returns.clone(),
            last_eval: self.last_eval.clone(),
            last_eval_rotated: self.last_eval_rotated.clone(),
        };
        let text = serde_json::to_vec(&stored).map_err(|e| serialise(e.to_string()))?;
        let tensors_path = path.with_file_name(&file);
        // The same tensors as the current pair's (nothing changed): the file is the live one.
        let existed = tensors_path.is_file();
        nn::write_atomic(&tensors_path, &tensors)?;
        sync_dir(dir_of(path));
        crash_point("checkpoint_after_tensors", n);
        if let Err(e) = nn::write_atomic(path, &crate::mappo::checksum::seal(&text)) {
            if !existed {
                let _ = std::fs::remove_file(&tensors_path);
            }
            return Err(e.into());
        }
        sync_dir(dir_of(path));
        crash_point("checkpoint_after_json", n);
        remove_tensor_files_except(path, Some(&file));
        Ok(())
    }

    /// Writes the checkpoint in the single-file format of version 2 (one sealed JSON,
    /// tensors included): kept for tools and tests that need a checkpoint as older versions
    /// wrote it. Checks as [`Checkpoint::save`].
    pub fn save_json(&self, path: &Path) -> Result<()> {
        self.refuse_non_finite(path)?;
        let old = Checkpoint { version: JSON_VERSION, ..self.clone() };
        let text = serde_json::to_vec(&old).map_err(|e| RlError::file(path, format!("cannot serialise: {e}")))?;
        nn::write_atomic(path, &crate::mappo::checksum::seal(&text))?;
        Ok(())
    }

    /// [`Checkpoint::check_finite`] as the error of a refused save.
    fn refuse_non_finite(&self, path: &Path) -> Result<()> {
        self.check_finite().map_err(|what| RlError::NonFinite {
            message: format!(
                "{what} at iteration {}; the checkpoint was not written ({} keeps the last good state)",
                self.iteration,
                path.display()
            ),
        })
    }

    /// Reads a checkpoint (either format: module docs) and checks its checksums, version
    /// and counters; errors name the file and what is wrong.
    pub fn load(path: &Path) -> Result<Checkpoint> {
        // A save between reading the JSON and its tensors file removes the file the JSON
        // named; the JSON then names another, so the load starts again (a few times at most).
        let mut attempt = 0;
        loop {
            let bytes = read_json(path)?;
            match Self::from_bytes(path, &bytes) {
                Err(Loaded::TensorsMissing(e)) => {
                    attempt += 1;
                    let changed = read_json(path).is_ok_and(|now| now != bytes);
                    if !changed || attempt >= 5 {
                        return Err(e);
                    }
                }
                Err(Loaded::Bad(e)) => return Err(e),
                Ok(c) => return Ok(c),
            }
        }
    }

    /// The checkpoint whose JSON at `path` holds `bytes`.
    fn from_bytes(path: &Path, bytes: &[u8]) -> std::result::Result<Checkpoint, Loaded> {
        use crate::mappo::checksum::{Unsealed, unseal};
        let bad = |message: String| Loaded::Bad(RlError::Checkpoint { path: path.to_path_buf(), message });
        let (payload, sealed) = match unseal(bytes).map_err(bad)? {
            Unsealed::Checked(p) => (p.as_bytes(), true),
            Unsealed::Unchecked(p) => (p, false),
        };
        let peek: Peek = serde_json::from_slice(payload).map_err(|e| bad(format!("not a valid checkpoint: {e}")))?;
        let c = match (peek.version, sealed) {
            (VERSION, true) => {
                let s: Stored =
                    serde_json::from_slice(payload).map_err(|e| bad(format!("not a valid checkpoint: {e}")))?;
                Self::with_tensors(path, s)?
            }
            (JSON_VERSION, true) | (UNSEALED_VERSION, false) => {
                serde_json::from_slice(payload).map_err(|e| bad(format!("not a valid checkpoint: {e}")))?
            }
            (v @ (JSON_VERSION | VERSION), false) => {
                return Err(bad(format!(
                    "format version {v} without its checksum envelope: the file was changed after it was written"
                )));
            }
            (v, _) => {
                return Err(bad(format!(
                    "format version {v} (this program reads versions {UNSEALED_VERSION} to {VERSION})"
                )));
            }
        };
        c.check_consistent().map_err(bad)?;
        c.check_finite().map_err(bad)?;
        Ok(c)
    }

    /// The checkpoint of a version 3 JSON `s` (at `path`) with its tensors file read and
    /// checked (name, size, digest, every tensor present with its shape).
    fn with_tensors(path: &Path, s: Stored) -> std::result::Result<Checkpoint, Loaded> {
        let r = &s.tensors;
        if !is_tensors_file_name(path, &r.file) {
            return Err(Loaded::Bad(RlError::Checkpoint {
                path: path.to_path_buf(),
                message: format!("names the tensors file {:?}, which is not a checkpoint tensors file name", r.file),
            }));
        }
        let tpath = path.with_file_name(&r.file);
        let bad = |message: String| {
            Loaded::Bad(RlError::Checkpoint {
                path: path.to_path_buf(),
                message: format!("its tensors file {}: {message}", tpath.display()),
            })
        };
        let size = match std::fs::metadata(&tpath) {
            Ok(m) => m.len(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(Loaded::TensorsMissing(RlError::Checkpoint {
                    path: path.to_path_buf(),
                    message: format!(
                        "its tensors file {} is missing (a checkpoint is the JSON and the tensors file it names: \
                 copy or move both)",
                        tpath.display()
                    ),
                }));
            }
            Err(e) => return Err(bad(format!("cannot read: {e}"))),
        };
        if size != r.bytes {
            return Err(bad(format!("{size} bytes, the checkpoint recorded {} (a truncated or other file)", r.bytes)));
        }
        // Read within the recorded size: a device or FIFO in its place is refused unread.
        let bytes = crate::bounded_read::read_bytes(&tpath, r.bytes, "the checkpoint's tensors file")
            .map_err(|e| bad(e.to_string()))?;
        if bytes.len() as u64 != r.bytes {
            return Err(bad(format!(
                "{} bytes, the checkpoint recorded {} (a truncated or other file)",
                bytes.len(),
                r.bytes
            )));
        }
        let actual = sha256_hex(&bytes);
        if actual != r.sha256 {
            return Err(bad(format!(
                "checksum mismatch: the file was changed or damaged after it was written (SHA-256 recorded {}, \
                 computed {actual})",
                r.sha256
            )));
        }
        let (file, _) = tensor_file::read(&bytes).map_err(bad)?;
        let expected: usize =
            s.teams.iter().map(|t| 3 * t.params.len() + if t.episode_draws.is_some() { 3 } else { 0 }).sum();
        if file.len() != expected {
            return Err(bad(format!("{} tensors, the checkpoint names {expected}", file.len())));
        }
        let mut teams = Vec::with_capacity(s.teams.len());
        for (k, t) in s.teams.into_iter().enumerate() {
            let episode_draws = match t.episode_draws {
                None => None,
                Some(d) => {
                    let mut parts = Vec::with_capacity(3);
                    for part in DRAW_PARTS {
                        parts.push(tensor_file::f32_values(&file, &draw_tensor_name(k, part)).map_err(bad)?.1);
                    }
                    let [vectors, scalars, heading]: [Vec<f32>; 3] = parts.try_into().expect("three parts");
                    Some(SavedDraws { vectors, scalars, heading, sigma: d.sigma, recorded: d.recorded })
                }
            };
            let mut params = Vec::with_capacity(t.params.len());
            let (mut m, mut v) = (Vec::with_capacity(t.params.len()), Vec::with_capacity(t.params.len()));
            for name in t.params {
                let (shape, data) = tensor_file::f64_values(&file, &name).map_err(bad)?;
                let n = data.len();
                for (moment, buf) in moment_names(&name).iter().zip([&mut m, &mut v]) {
                    let (mshape, values) = tensor_file::f64_values(&file, moment).map_err(bad)?;
                    if mshape != [n] {
                        return Err(bad(format!(
                            "tensor `{moment}` has shape {mshape:?} for a parameter of {n} elements"
                        )));
                    }
                    buf.push(values);
                }
                params.push(SavedTensor { name, shape, data });
            }
            teams.push(TeamState {
                params: StateDict { version: StateDict::VERSION, tensors: params },
                adam: Adam::from_moments(t.adam.config, t.adam.t, m, v),
                normalizer: t.normalizer,
                noise: t.noise,
                shuffle: t.shuffle,
                assignment_hold: t.assignment_hold,
                episode_draws,
            });
        }
        Ok(Checkpoint {
            version: s.version,
            config: s.config,
            iteration: s.iteration,
            env_steps: s.env_steps,
            wall_s: s.wall_s,
            evals_done: s.evals_done,
            teams,
            env: s.env,
            episode_returns: s.episode_returns,
            last_eval: s.last_eval,
            last_eval_rotated: s.last_eval_rotated,
        })
    }

    /// Checks that the counters agree with each other and with the checkpoint's
    /// configuration (module docs); the error says which do not.
    pub fn check_consistent(&self) -> std::result::Result<(), String> {
        let c = &self.config;
        c.validate("the checkpoint's configuration").map_err(|e| e.to_string())?;
        let per_iteration = c.steps_per_iteration();
        if self.iteration.checked_mul(per_iteration) != Some(self.env_steps) {
            return Err(format!(
                "iteration {} and env_steps {} disagree: the configuration collects {per_iteration} steps per \
                 iteration",
                self.iteration, self.env_steps
            ));
        }
        if self.iteration > c.iterations() {
            return Err(format!(
                "iteration {} is past the configuration's {} iterations ({} steps)",
                self.iteration,
                c.iterations(),
                c.steps
            ));
        }
        if self.evals_done > self.iteration {
            return Err(format!("{} evaluations after {} iterations", self.evals_done, self.iteration));
        }
        let updates =
            (c.epochs as u64).checked_mul(c.num_minibatches as u64).and_then(|u| u.checked_mul(self.iteration));
        for (k, t) in self.teams.iter().enumerate() {
            if Some(t.adam.t) != updates {
                return Err(format!(
                    "team {k}: Adam counts {} updates after {} iterations of {} epochs x {} minibatches",
                    t.adam.t, self.iteration, c.epochs, c.num_minibatches
                ));
            }
        }
        if !(self.wall_s.is_finite() && self.wall_s >= 0.0) {
            return Err(format!("wall_s = {} is not a duration", self.wall_s));
        }
        Ok(())
    }

    /// Checks that every parameter, Adam moment, normaliser statistic and running episode
    /// return is finite; the error names the first that is not.
    pub fn check_finite(&self) -> std::result::Result<(), String> {
        for (k, t) in self.teams.iter().enumerate() {
            if let Some(p) = t.params.tensors.iter().find(|p| !p.data.iter().all(|x| x.is_finite())) {
                return Err(format!("team {k}: parameter `{}` is not finite", p.name));
            }
            if let Some((i, moment)) = t.adam.non_finite() {
                let name = t.params.tensors.get(i).map(|p| p.name.as_str()).unwrap_or("?");
                return Err(format!("team {k}: the Adam {moment} moment of parameter `{name}` is not finite"));
            }
            if let Some(stats) = t.normalizer.non_finite() {
                return Err(format!("team {k}: the observation normaliser's {stats} statistics are not finite"));
            }
        }
        if !self.episode_returns.iter().all(|x| x.is_finite()) {
            return Err("a running episode return is not finite".into());
        }
        Ok(())
    }
}
