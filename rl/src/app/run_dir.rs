//! The layout of a run directory, shared by training, evaluation, the sweep runner and the
//! report:
//!
//! | file | written | holds |
//! |---|---|---|
//! | `config.toml` | at the start | the resolved [`crate::TrainConfig`] |
//! | `metrics.csv` | every iteration | one row per iteration (the columns of [`crate::app::metrics::MetricsLayout`]) |
//! | `checkpoint.json` | every `checkpoint_every` iterations, after evaluations, at the end | with the tensors file it names, everything needed to resume exactly ([`crate::mappo::checkpoint`]): the configuration, counters, normaliser statistics, random streams and environment states, sealed with a SHA-256 that covers the tensors file's too |
//! | `checkpoint.<digest>.safetensors` | with `checkpoint.json`, before it | every team's parameters and Adam moments (safetensors: PyTorch, JAX, numpy read it); `<digest>` is the start of its SHA-256 |
//! | `curve.svg` | after every evaluation | the learning curve |
//! | `done.json` | at the end | the [`crate::RunSummary`]; a run with it is finished |
//! | `builds.csv` | at the start and at each resume | a row per training session: the iteration it went on from, the program's version and git commit ([`crate::app::build_info`]) |
//! | `morphology.toml`, `morphologies/` | at the start, if the environment names morphology files | each file's name, source, SHA-256 and the run's copy of it ([`crate::app::morphology`]) |
//! | `lock` | at the start | the process id and host of the training that holds the directory's lock ([`crate::app::lock`]) |
//!
//! [`load_policies`] reads the trained teams of a run directory back.
//!
//! Every file is written atomically (a temporary file, then a rename), so an interrupted run
//! leaves either the old or the new version; the checkpoint's two files are atomic as a
//! pair (the tensors first under a new name, then the JSON that names them, then the old
//! tensors file removed). The temporary files of a killed run, and a tensors file that no
//! `checkpoint.json` names, are removed when training resumes, once the checkpoint has loaded (a resume that fails changes nothing). `metrics.csv` and `builds.csv` grow by appended rows, one write a
//! row (a resumed run rewrites `metrics.csv` atomically up to its checkpoint first).

use std::path::{Path, PathBuf};

use crate::error::{Result, RlError};
use crate::mappo::checkpoint::Checkpoint;
use crate::mappo::config::TrainConfig;
use crate::mappo::team::Team;

/// Where a run's files live.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

/// How far a run directory got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunStatus {
    /// No checkpoint: training starts from scratch.
    New,
    /// A checkpoint but no `done.json`: training resumes from the checkpoint.
    Partial,
    /// `done.json` exists: the run is finished.
    Done,
}

impl RunDir {
    /// A run directory at `root` (not created).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `config.toml`.
    pub fn config(&self) -> PathBuf {
        self.root.join("config.toml")
    }

    /// `metrics.csv`.
    pub fn metrics(&self) -> PathBuf {
        self.root.join("metrics.csv")
    }

    /// `checkpoint.json`.
    pub fn checkpoint(&self) -> PathBuf {
        self.root.join("checkpoint.json")
    }

    /// `curve.svg`.
    pub fn curve(&self) -> PathBuf {
        self.root.join("curve.svg")
    }

    /// `done.json`.
    pub fn done(&self) -> PathBuf {
        self.root.join("done.json")
    }

    /// `builds.csv`.
    pub fn builds(&self) -> PathBuf {
        self.root.join(crate::app::build_info::BUILDS_FILE)
    }

    /// The run's status from the files present.
    pub fn status(&self) -> RunStatus {
        if self.done().is_file() {
            RunStatus::Done
        } else if self.checkpoint().is_file() {
            RunStatus::Partial
        } else {
            RunStatus::New
        }
    }
}

/// The names of the files a run directory keeps (module docs), which no other output may
/// take: `eval*.json` (`meben eval`'s results) besides these.
pub const RUN_FILES: [&str; 8] = [
    "config.toml",
    crate::app::morphology::MORPHOLOGY_RECORD,
    "metrics.csv",
    "checkpoint.json",
    "curve.svg",
    "done.json",
    crate::app::build_info::BUILDS_FILE,
    crate::app::lock::LOCK_FILE,
];

/// Whether `name` is the name of one of a run directory's own files: [`RUN_FILES`], a
/// checkpoint's tensors file (`checkpoint.<digest>.safetensors`) or an evaluation's
/// `eval*.json`.
pub fn is_run_file_name(name: &str) -> bool {
    RUN_FILES.contains(&name)
        || crate::mappo::checkpoint::is_tensors_file_name(Path::new("checkpoint.json"), name)
        || (name.starts_with("eval") && name.ends_with(".json"))
}

/// Refuses `out` as the output of another command (`meben render --out`) when it is one of
/// a run directory's own files ([`is_run_file_name`] in a directory holding a `config.toml`
/// or a `checkpoint.json`): writing it would replace the run's metrics, configuration or
/// checkpoint. Paths are compared canonicalised (through `..` and symbolic links); the error
/// names `option`, the path and the run directory.
pub fn check_not_a_run_file(option: &str, out: &Path) -> Result<()> {
    // Where `out` leads: the file itself if it exists (a link to a run's file), else its
    // parent directory, canonicalised, and its name.
    let target = out.canonicalize().ok().or_else(|| {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        Some(parent.canonicalize().ok()?.join(out.file_name()?))
    });
    let Some(target) = target else { return Ok(()) };
    let (Some(dir), Some(name)) = (target.parent(), target.file_name().and_then(|n| n.to_str())) else {
        return Ok(());
    };
    let is_run = |d: &Path| RunDir::new(d).config().is_file() || RunDir::new(d).checkpoint().is_file();
    if is_run_file_name(name) && is_run(dir) {
        return Err(RlError::file(
            out,
            format!("{option} would overwrite the run directory {}'s own {name}; write to another file", dir.display()),
        ));
    }
    // The run's copies of its morphology files (`morphologies/`, [`crate::app::morphology`]).
    if let Some(run) = dir.parent().filter(|r| dir.ends_with(crate::app::morphology::COPIES_DIR) && is_run(r)) {
        return Err(RlError::file(
            out,
            format!(
                "{option} would overwrite the run directory {}'s own copy of a morphology file it was trained on; \
                 write to another file",
                run.display()
            ),
        ));
    }
    Ok(())
}

/// The trained teams of a run directory (its `config.toml` and `checkpoint.json`): the
/// models with their parameters and normalisers, ready for [`crate::mappo::evaluate::evaluate`] or
/// rendering. A `config.toml` that disagrees with the checkpoint's configuration is refused,
/// naming the fields ([`crate::mappo::config_match`]). For a run trained on morphology files,
/// the configuration's `env` names the run's own checked copies of them, by absolute path
/// ([`crate::app::morphology::env_with_copies`]), so that it evaluates the same bodies from
/// any directory.
pub fn load_policies(run: &RunDir) -> Result<(TrainConfig, Vec<Team>)> {
    let (config, c) = load_run(run)?;
    let teams = teams_of(&config, &c, &run.checkpoint())?;
    Ok((config, teams))
}

/// A run directory's configuration (`config.toml`) and checkpoint.
pub fn load_run(run: &RunDir) -> Result<(TrainConfig, Checkpoint)> {
    if !run.config().is_file() {
        return Err(RlError::file(
            run.config(),
            "no such file: not a run directory (expected config.toml and checkpoint.json)",
        ));
    }
    let config = TrainConfig::load(&run.config())?;
    let path = run.checkpoint();
    let c = Checkpoint::load(&path)?;
    crate::mappo::config_match::check_config_matches_checkpoint(&run.config(), &config, &path, &c.config)?;
    // The scene from the run's own copies of its morphology files.
    let config = TrainConfig { env: crate::app::morphology::env_with_copies(run, &config.env)?, ..config };
    Ok((config, c))
}

/// The teams of `config` with the parameters and normalisers of the checkpoint `c` (read
/// from `path`, which errors name).
pub fn teams_of(config: &TrainConfig, c: &Checkpoint, path: &Path) -> Result<Vec<Team>> {
    let spec = envs::tasks::Scene::from_name(&config.env)?.obs_spec;
    if c.teams.len() != spec.n_teams {
        return Err(RlError::Checkpoint {
            path: path.to_path_buf(),
            message: format!("{} teams for a scene of {} teams", c.teams.len(), spec.n_teams),
        });
    }
    let mut teams = Vec::new();
    for (k, s) in c.teams.iter().enumerate() {
        let mut t = Team::build(config, &spec, k)?;
        s.params
            .load_into(&mut t.store)
            .map_err(|e| RlError::Checkpoint { path: path.to_path_buf(), message: e.to_string() })?;
        s.normalizer.check_fits(&t.norm).map_err(|e| RlError::Checkpoint {
            path: path.to_path_buf(),
            message: format!("the observation normaliser of team {k} does not fit: {e}"),
        })?;
        t.norm = s.normalizer.clone();
        // A checkpoint taken in a learned assignment's warm-up acts as the run did then, and
        // holds its drawn assignment as the run does.
        t.sync_assignment(config, c.env_steps);
        teams.push(t);
    }
    Ok(teams)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 44 item 8: `meben render --out RUN/metrics.csv` replaced the run's metrics with
    /// body poses. Every file of a run directory is refused, by any path that leads to it.
    #[test]
    fn a_run_directorys_own_files_are_refused_as_outputs() {
        let dir = crate::app::test_util::TempDir::new("run-files");
        let run = dir.0.join("run");
        std::fs::create_dir_all(run.join("sub")).unwrap();
        std::fs::write(run.join("config.toml"), "").unwrap();
        std::fs::write(run.join("metrics.csv"), "iteration\n1\n").unwrap();
        let refused = |p: &Path| {
            let e = check_not_a_run_file("--out", p).unwrap_err().to_string();
            assert!(e.starts_with(&p.display().to_string()) && e.contains("--out") && e.contains("own"), "{e}");
        };
        for name in RUN_FILES.iter().copied().chain([
            "eval.json",
            "eval_rotate180.json",
            "checkpoint.0123456789abcdef.safetensors",
        ]) {
            refused(&run.join(name));
        }
        refused(&run.join("sub").join("..").join("metrics.csv"));
        std::fs::create_dir_all(run.join("morphologies")).unwrap();
        refused(&run.join("morphologies").join("0_body.xml"));
        #[cfg(unix)]
        {
            let link = dir.0.join("poses.csv");
            std::os::unix::fs::symlink(run.join("metrics.csv"), &link).unwrap();
            refused(&link);
        }
        // Other files of the run directory, and a metrics.csv outside any run, are fine.
        check_not_a_run_file("--out", &run.join("episode.csv")).unwrap();
        check_not_a_run_file("--out", &run.join("policy.safetensors")).unwrap();
        check_not_a_run_file("--out", &run.join("sub").join("metrics.csv")).unwrap();
        check_not_a_run_file("--out", &dir.0.join("metrics.csv")).unwrap();
        check_not_a_run_file("--out", Path::new("/no/such/dir/metrics.csv")).unwrap();
    }
}
