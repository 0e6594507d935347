//! The morphology files inside a policy file (issue 77 item 7). A run on morphology files
//! (`team_reach:agents=body.xml`) evaluates the run's copies of them
//! ([`crate::app::morphology`]), so its configuration names them by absolute paths into the
//! run directory. A policy file that kept only those paths failed once the run moved, and
//! evaluated whatever the run's copy had become since (exit 0, where `eval --run` refused it).
//!
//! A version 2 policy file therefore carries the files themselves: its metadata key
//! `morphologies` is a JSON array with, per file the environment names, that name, the
//! SHA-256 of its contents and the contents ([`carry`]). The policy file's digest covers it.
//! Loading ([`restore`]) checks each digest, writes each file (once) to a directory named by
//! its digest under the system's temporary directory (`meben-morphologies/<sha256>/`; a file
//! already there is used only if its digest is right, else written again) and builds the
//! scene from those, so the policy evaluates the bodies it was trained on from any
//! directory, whatever became of the run.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};
use crate::mappo::checksum::sha256_hex;

/// The largest morphology file carried (64 MiB).
pub const MAX_MORPHOLOGY_BYTES: u64 = 64 << 20;

/// The directory, under the system's temporary directory, of the files [`restore`] writes.
pub const CACHE_DIR: &str = "meben-morphologies";

/// One carried file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Carried {
    /// The file as the environment names it.
    name: String,
    /// SHA-256 of `contents`.
    sha256: String,
    /// The file's text.
    contents: String,
}

/// The morphology files `env` names, each once.
fn files_of(env: &str) -> Result<Vec<String>> {
    Ok(envs::tasks::TaskSpec::from_name(env)?.morphology_files().into_iter().map(str::to_string).collect())
}

/// The `morphologies` value of a policy file of `env` (module docs): `[]` when it names no
/// morphology file. Errors name a file that cannot be read.
pub fn carry(env: &str) -> Result<String> {
    let mut carried = Vec::new();
    for name in files_of(env)? {
        let contents = crate::bounded_read::read_text(Path::new(&name), MAX_MORPHOLOGY_BYTES, "a morphology file")?;
        carried.push(Carried { sha256: sha256_hex(contents.as_bytes()), name, contents });
    }
    serde_json::to_string(&carried).map_err(|e| RlError::file("policy file", format!("cannot serialise: {e}")))
}

/// The environment of the policy file `path` whose configuration says `env` and whose
/// metadata carries `morphologies` (module docs): `env` with every morphology file replaced
/// by the carried one, written under the temporary directory. Errors name the file, the field
/// and what is wrong.
pub fn restore(path: &Path, env: &str, morphologies: &str) -> Result<String> {
    let bad = |message: String| RlError::Policy { path: path.to_path_buf(), message };
    let carried: Vec<Carried> =
        serde_json::from_str(morphologies).map_err(|e| bad(format!("its `morphologies` is not valid: {e}")))?;
    let files = files_of(env)?;
    for c in &carried {
        if !files.contains(&c.name) {
            return Err(bad(format!(
                "its parts disagree: `morphologies` carries {}, which its environment {env:?} does not name",
                c.name
            )));
        }
        let actual = sha256_hex(c.contents.as_bytes());
        if actual != c.sha256 {
            return Err(bad(format!(
                "the carried morphology file {} has SHA-256 {actual}, its `morphologies` entry records {}",
                c.name, c.sha256
            )));
        }
    }
    let mut written = Vec::with_capacity(files.len());
    for name in &files {
        let c = carried.iter().find(|c| &c.name == name).ok_or_else(|| {
            bad(format!(
                "its parts disagree: its environment {env:?} names the morphology file {name}, which `morphologies` \
                 does not carry"
            ))
        })?;
        written.push((name.clone(), materialise(c)?));
    }
    if written.is_empty() {
        return Ok(env.to_string());
    }
    let spec = envs::tasks::TaskSpec::from_name(env)?;
    let renamed = spec.with_files_renamed(|n| {
        written.iter().find(|(name, _)| name == n).map_or_else(|| n.to_string(), |(_, p)| p.display().to_string())
    });
    renamed.map(|s| s.name).map_err(|e| {
        bad(format!(
            "its morphology files were written under {}, which cannot stand in an environment string ({e}); set \
             TMPDIR to a directory without '+' or ';'",
            std::env::temp_dir().display()
        ))
    })
}

/// A version 1 policy file (`path`, of environment `env`) carries no morphology files: its
/// environment names the run's copies by absolute path. Each is checked against the run's
/// record beside it (`<run>/morphology.toml`, [`crate::app::morphology`]); a file no record
/// vouches for, or whose contents changed, is refused naming it (export the policy again to
/// carry the files).
pub fn check_v1(path: &Path, env: &str) -> Result<()> {
    use crate::app::morphology::{COPIES_DIR, MorphologyRecord};
    let bad = |message: String| RlError::Policy { path: path.to_path_buf(), message };
    for name in files_of(env)? {
        let file = Path::new(&name);
        let run = file.parent().filter(|d| d.file_name().is_some_and(|n| n == COPIES_DIR)).and_then(Path::parent);
        let record = match run {
            Some(run) => MorphologyRecord::load(&crate::app::run_dir::RunDir::new(run))?.map(|r| (run, r)),
            None => None,
        };
        let Some(entry) = record.as_ref().and_then(|(run, r)| r.file.iter().find(|f| run.join(&f.copy) == file)) else {
            return Err(bad(format!(
                "a version 1 policy file: its environment names the morphology file {name}, which it does not \
                 carry and no run record (morphology.toml) beside it vouches for; export the policy again with \
                 `meben export-policy` to carry the file"
            )));
        };
        let bytes = crate::bounded_read::read_bytes(file, MAX_MORPHOLOGY_BYTES, "a morphology file")?;
        let now = sha256_hex(&bytes);
        if now != entry.sha256 {
            return Err(bad(format!(
                "the morphology file {name} its environment names changed since the run was trained on it: sha256 \
                 {} recorded, {now} now",
                entry.sha256
            )));
        }
    }
    Ok(())
}

/// The path of `c` under the temporary directory, written there unless a file with its
/// digest already is.
fn materialise(c: &Carried) -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(CACHE_DIR).join(&c.sha256);
    let base = Path::new(&c.name).file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let target = dir.join(crate::app::names::sanitize_component(&base));
    let current = std::fs::read(&target).ok();
    if current.is_some_and(|b| sha256_hex(&b) == c.sha256) {
        return Ok(target);
    }
    std::fs::create_dir_all(&dir).map_err(|e| RlError::file(&dir, format!("cannot create: {e}")))?;
    nn::write_atomic(&target, c.contents.as_bytes())?;
    Ok(target)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn carried_files_come_back_checked_under_the_temporary_directory() {
        let tmp = crate::app::test_util::TempDir::new("policy-morphology");
        let body = crate::app::test_util::ant_body(&tmp.0);
        let env = format!("team_reach:agents={}+ant;R=3", body.display());
        let json = carry(&env).unwrap();
        std::fs::remove_file(&body).unwrap();
        let restored = restore(Path::new("p.safetensors"), &env, &json).unwrap();
        assert!(restored.contains(CACHE_DIR) && !restored.contains(&tmp.0.display().to_string()), "{restored}");
        envs::tasks::Scene::from_name(&restored).unwrap();
        // A cached file that changed is written again.
        let cached = restored.split('=').nth(1).unwrap().split('+').next().unwrap().to_string();
        std::fs::write(&cached, "<mujoco/>").unwrap();
        assert_eq!(restore(Path::new("p.safetensors"), &env, &json).unwrap(), restored);
        assert_eq!(std::fs::read(&cached).unwrap(), std::fs::read(crate::app::test_util::ANT_XML).unwrap());
        // Disagreements name the file and the field.
        let e = restore(Path::new("p.safetensors"), &env, "[]").unwrap_err().to_string();
        assert!(e.contains("p.safetensors") && e.contains("`morphologies` does not carry"), "{e}");
        let e = restore(Path::new("p.safetensors"), "team_reach/1_ant", &json).unwrap_err().to_string();
        assert!(e.contains("does not name"), "{e}");
        assert_eq!(carry("team_reach/1_ant").unwrap(), "[]");
    }
}
