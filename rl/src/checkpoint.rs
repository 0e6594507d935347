//! Checkpoints: everything a run needs to continue exactly as if it had not stopped (the
//! configuration, counters, every team's parameters, Adam moments, normaliser statistics and
//! random streams, the state of every environment, and the running episode returns), as
//! one JSON file written atomically (a temporary file, then a rename). Numbers are written in
//! their shortest round-trip form, so loading gives back the same bits.

use std::path::Path;

use envs::tasks::VecEnvState;
use nn::{Adam, StateDict};
use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;
use crate::error::{Result, RlError};
use crate::normalizer::ObsNormalizer;
use crate::seeding::RngState;
use crate::train::EvalSummary;

/// Current checkpoint format version.
pub const VERSION: u32 = 1;

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

impl Checkpoint {
    /// Writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_vec(self).map_err(|e| RlError::file(path, format!("cannot serialise: {e}")))?;
        nn::write_atomic(path, &text)?;
        Ok(())
    }

    /// Reads a checkpoint; errors name the file and what is wrong.
    pub fn load(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|e| RlError::file(path, format!("cannot read: {e}")))?;
        let c: Checkpoint = serde_json::from_slice(&bytes).map_err(|e| RlError::Checkpoint {
            path: path.to_path_buf(),
            message: format!("not a valid checkpoint: {e}"),
        })?;
        if c.version != VERSION {
            return Err(RlError::Checkpoint {
                path: path.to_path_buf(),
                message: format!("format version {} (this program reads version {VERSION})", c.version),
            });
        }
        Ok(c)
    }
}

/// The trained teams of a run directory (its `config.toml` and `checkpoint.json`): the
/// models with their parameters and normalisers, ready for [`crate::evaluate()`] or
/// rendering.
pub fn load_policies(run: &crate::RunDir) -> Result<(TrainConfig, Vec<crate::Team>)> {
    if !run.config().is_file() {
        return Err(RlError::file(
            run.config(),
            "no such file: not a run directory (expected config.toml and checkpoint.json)",
        ));
    }
    let config = TrainConfig::load(&run.config())?;
    let path = run.checkpoint();
    let c = Checkpoint::load(&path)?;
    let spec = envs::tasks::Scene::from_name(&config.env)?.obs_spec;
    if c.teams.len() != spec.n_teams {
        return Err(RlError::Checkpoint {
            path,
            message: format!("{} teams for a scene of {} teams", c.teams.len(), spec.n_teams),
        });
    }
    let mut teams = Vec::new();
    for (k, s) in c.teams.iter().enumerate() {
        let mut t = crate::Team::build(&config, &spec, k)?;
        s.params
            .load_into(&mut t.store)
            .map_err(|e| RlError::Checkpoint { path: path.clone(), message: e.to_string() })?;
        s.normalizer.check_fits(&t.norm).map_err(|e| RlError::Checkpoint {
            path: path.clone(),
            message: format!("the observation normaliser of team {k} does not fit: {e}"),
        })?;
        t.norm = s.normalizer.clone();
        teams.push(t);
    }
    Ok((config, teams))
}
