//! The morphology files a run was built from (issue 44 item 7): an environment such as
//! `team_reach:agents=body.xml` names a file by a path, relative to where the command runs.
//! Before this module a run remembered that path only: a resumed run read whatever
//! `body.xml` said by then (its rows no longer those of an uninterrupted run), and `meben
//! eval` from another directory failed or loaded another `body.xml`.
//!
//! Now a run whose environment names morphology files (`.xml`, `.txt`:
//! [`envs::tasks::is_morphology_file`]) keeps, in its run directory,
//!
//! - `morphologies/<k>_<file name>`: a copy of each file as it was when the run began;
//! - `morphology.toml`: per file, the name the environment gives it, the absolute path it was
//!   read from, its copy and the SHA-256 of its contents.
//!
//! **Training** ([`record_or_verify`]): a new run writes both (before its first checkpoint).
//! A resumed run reads its files where its command names them, as before, and refuses a file
//! that is missing or whose contents changed, naming it, the recorded and the present digest
//! and the run's copy (restore the file from the copy to go on). A run begun before this
//! module, without `morphology.toml`, records its files as they are on its first resume.
//!
//! **Evaluation, rendering, `Policy.load`** ([`env_with_copies`]): the run's own copies are
//! loaded, after checking them against `morphology.toml`, so a run evaluates the same bodies
//! from any directory and whatever became of the original files. The environment string the
//! scene is built from then names the copies by absolute path. Where the run directory's own
//! path cannot stand in an environment string (it holds `+` or `;`), the files are read where
//! the environment names them, and refused if they changed. Runs without `morphology.toml`
//! read them there unchecked, as before.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::app::run_dir::RunDir;
use crate::error::{Result, RlError};
use crate::mappo::checksum::sha256_hex;

/// The record's file name in a run directory.
pub const MORPHOLOGY_RECORD: &str = "morphology.toml";

/// The directory of the copies in a run directory.
pub const COPIES_DIR: &str = "morphologies";

/// One morphology file of a run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MorphologyFile {
    /// The file as the run's environment names it (e.g. `body.xml`).
    pub name: String,
    /// The absolute path it was read from when the run recorded it.
    pub source: String,
    /// Its copy, relative to the run directory (`morphologies/0_body.xml`).
    pub copy: String,
    /// SHA-256 of its contents, in hex.
    pub sha256: String,
}

/// `morphology.toml`: every morphology file of a run.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MorphologyRecord {
    /// One entry per file, in the order the environment names them.
    #[serde(default)]
    pub file: Vec<MorphologyFile>,
}

impl MorphologyRecord {
    /// Reads `morphology.toml` of `run`; `None` if there is none.
    pub fn load(run: &RunDir) -> Result<Option<MorphologyRecord>> {
        let path = record_path(run);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(RlError::file(&path, format!("cannot read: {e}"))),
        };
        let record: MorphologyRecord =
            toml::from_str(&text).map_err(|e| RlError::file(&path, format!("not a morphology record: {e}")))?;
        Ok(Some(record))
    }

    /// The entry of the file the environment calls `name`.
    pub fn get(&self, name: &str) -> Option<&MorphologyFile> {
        self.file.iter().find(|f| f.name == name)
    }
}

/// `morphology.toml` of `run`.
pub fn record_path(run: &RunDir) -> PathBuf {
    run.root().join(MORPHOLOGY_RECORD)
}

/// The morphology files `env` names, each once ([`envs::tasks::TaskSpec::morphology_files`]).
fn files_of(env: &str) -> Result<Vec<String>> {
    let spec = envs::tasks::TaskSpec::from_name(env)?;
    Ok(spec.morphology_files().into_iter().map(str::to_string).collect())
}

/// The contents of the morphology file `name` (a path relative to the working directory),
/// or an error naming it.
fn read_file(name: &str, recorded: Option<(&RunDir, &MorphologyFile)>) -> Result<Vec<u8>> {
    std::fs::read(name).map_err(|e| {
        let hint = match recorded {
            Some((run, f)) => format!(
                "; the run was trained on {} (sha256 {}), of which {} is a copy",
                f.source,
                f.sha256,
                run.root().join(&f.copy).display()
            ),
            None => String::new(),
        };
        RlError::file(name, format!("cannot read the morphology file the environment names: {e}{hint}"))
    })
}

/// Training (module docs): a new run (`resuming` false) records every morphology file of
/// `env` with a copy; a resumed one checks each file against its record (written now if the
/// run has none). Nothing is written for an environment without morphology files.
pub fn record_or_verify(run: &RunDir, env: &str, resuming: bool) -> Result<()> {
    let files = files_of(env)?;
    if files.is_empty() {
        return Ok(());
    }
    let existing = if resuming { MorphologyRecord::load(run)? } else { None };
    let Some(record) = existing else {
        return write_record(run, &files);
    };
    for name in &files {
        let Some(f) = record.get(name) else {
            return Err(RlError::file(
                record_path(run),
                format!(
                    "the environment names the morphology file {name}, which is not among the files this run was \
                     trained on ({})",
                    record.file.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", ")
                ),
            ));
        };
        let bytes = read_file(name, Some((run, f)))?;
        check_digest(name, &bytes, run, f)?;
    }
    Ok(())
}

/// Refuses `bytes` (of the file `shown`) unless their digest is the one `f` records.
fn check_digest(shown: &str, bytes: &[u8], run: &RunDir, f: &MorphologyFile) -> Result<()> {
    let now = sha256_hex(bytes);
    if now == f.sha256 {
        return Ok(());
    }
    Err(RlError::file(
        shown,
        format!(
            "the morphology file changed since the run {} was trained on it: sha256 {} recorded in {}, {now} now; \
             restore it (the run's copy is {}) or train a new run",
            run.root().display(),
            f.sha256,
            record_path(run).display(),
            run.root().join(&f.copy).display()
        ),
    ))
}

/// Copies `files` into the run directory and writes `morphology.toml` (the copies first, the
/// record last, each atomically).
fn write_record(run: &RunDir, files: &[String]) -> Result<()> {
    let dir = run.root().join(COPIES_DIR);
    std::fs::create_dir_all(&dir).map_err(|e| RlError::file(&dir, format!("cannot create: {e}")))?;
    let mut record = MorphologyRecord::default();
    for (k, name) in files.iter().enumerate() {
        let bytes = read_file(name, None)?;
        let base = Path::new(name).file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let copy = format!("{COPIES_DIR}/{k}_{}", crate::app::names::sanitize_component(&base));
        nn::write_atomic(&run.root().join(&copy), &bytes)?;
        let source = std::fs::canonicalize(name).unwrap_or_else(|_| PathBuf::from(name));
        record.file.push(MorphologyFile {
            name: name.clone(),
            source: source.display().to_string(),
            copy,
            sha256: sha256_hex(&bytes),
        });
    }
    let text = format!(
        "# The morphology files this run was trained on: each one's name in the environment, the path it was read \
         from, the run's copy of it and the SHA-256 of its contents. A resumed run refuses a changed file; \
         evaluation loads the copies.\n{}",
        toml::to_string(&record).map_err(|e| RlError::file(record_path(run), format!("cannot serialise: {e}")))?
    );
    nn::write_atomic(&record_path(run), text.as_bytes())?;
    Ok(())
}

/// Evaluation (module docs): the environment string to build `run`'s scene from, `env` with
/// every morphology file replaced by the run's checked copy; `env` itself for an
/// environment without files or a run without `morphology.toml`.
pub fn env_with_copies(run: &RunDir, env: &str) -> Result<String> {
    let files = files_of(env)?;
    if files.is_empty() {
        return Ok(env.to_string());
    }
    let Some(record) = MorphologyRecord::load(run)? else { return Ok(env.to_string()) };
    let mut copies: Vec<(&str, &MorphologyFile, String)> = Vec::new();
    for name in &files {
        let f = record.get(name).ok_or_else(|| {
            RlError::file(
                record_path(run),
                format!("has no entry for the morphology file {name} the environment names"),
            )
        })?;
        let copy = run.root().join(&f.copy);
        let bytes = std::fs::read(&copy).map_err(|e| {
            RlError::file(&copy, format!("cannot read the run's copy of the morphology file {name}: {e}"))
        })?;
        check_digest(&copy.display().to_string(), &bytes, run, f)?;
        let absolute =
            std::path::absolute(&copy).map_err(|e| RlError::file(&copy, format!("no absolute path: {e}")))?;
        copies.push((name, f, absolute.display().to_string()));
    }
    let spec = envs::tasks::TaskSpec::from_name(env)?;
    let renamed = spec.with_files_renamed(|n| {
        copies.iter().find(|(name, _, _)| *name == n).map(|(_, _, c)| c.clone()).unwrap_or_else(|| n.to_string())
    });
    match renamed {
        Ok(spec) => Ok(spec.name),
        // The run directory's path holds `+` or `;`: the files where the environment names
        // them, checked.
        Err(_) => {
            for (name, f, _) in &copies {
                check_digest(name, &read_file(name, Some((run, f)))?, run, f)?;
            }
            Ok(env.to_string())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_records_its_files_refuses_changes_and_evaluates_its_copies() {
        let tmp = crate::app::test_util::TempDir::new("morphology");
        let body = crate::app::test_util::ant_body(&tmp.0);
        let env = format!("team_reach:agents={}+ant;R=3", body.display());
        let run = RunDir::new(tmp.0.join("run"));
        std::fs::create_dir_all(run.root()).unwrap();
        record_or_verify(&run, &env, false).unwrap();
        let record = MorphologyRecord::load(&run).unwrap().unwrap();
        assert_eq!(record.file.len(), 1);
        assert_eq!(record.file[0].copy, "morphologies/0_body.xml");
        assert_eq!(std::fs::read(run.root().join(&record.file[0].copy)).unwrap(), std::fs::read(&body).unwrap());
        record_or_verify(&run, &env, true).unwrap();
        // The copies, by absolute path.
        let evaluated = env_with_copies(&run, &env).unwrap();
        let copy = std::path::absolute(run.root().join("morphologies/0_body.xml")).unwrap();
        assert_eq!(evaluated, format!("team_reach:agents={}+ant;R=3;balls=2", copy.display()));
        envs::tasks::Scene::from_name(&evaluated).unwrap();

        // Changed, then missing: refused naming the file, both digests and the copy.
        std::fs::write(
            &body,
            std::fs::read_to_string(crate::app::test_util::ANT_XML).unwrap().replace("gear=\"350\"", "gear=\"300\""),
        )
        .unwrap();
        let e = record_or_verify(&run, &env, true).unwrap_err().to_string();
        assert!(
            e.starts_with(&body.display().to_string()) && e.contains("changed") && e.contains(&record.file[0].sha256)
        );
        assert!(e.contains("0_body.xml"), "{e}");
        // Evaluation does not read it: the copy stands.
        assert_eq!(env_with_copies(&run, &env).unwrap(), evaluated);
        std::fs::remove_file(&body).unwrap();
        let e = record_or_verify(&run, &env, true).unwrap_err().to_string();
        assert!(
            e.starts_with(&body.display().to_string()) && e.contains("cannot read") && e.contains("0_body.xml"),
            "{e}"
        );
        // An edited copy is refused by evaluation, naming the copy.
        std::fs::write(run.root().join("morphologies/0_body.xml"), "<mujoco/>").unwrap();
        let e = env_with_copies(&run, &env).unwrap_err().to_string();
        assert!(e.contains("0_body.xml") && e.contains("changed"), "{e}");
        // Built-in environments record nothing.
        let plain = RunDir::new(tmp.0.join("plain"));
        std::fs::create_dir_all(plain.root()).unwrap();
        record_or_verify(&plain, "team_reach/1_ant", false).unwrap();
        assert!(!record_path(&plain).exists() && !plain.root().join(COPIES_DIR).exists());
        assert_eq!(env_with_copies(&plain, "team_reach/1_ant").unwrap(), "team_reach/1_ant");
    }
}
