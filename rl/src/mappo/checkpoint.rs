//! Checkpoints: everything a run needs to continue exactly as if it had not stopped (the
//! configuration, counters, every team's parameters, Adam moments, normaliser statistics and
//! random streams, the state of every environment, and the running episode returns), as
//! one JSON file written atomically (a temporary file, then a rename). Numbers are written in
//! their shortest round-trip form, so loading gives back the same bits.
//!
//! Nothing non-finite is written: [`Checkpoint::save`] checks every parameter, Adam moment,
//! normaliser statistic and running return first and refuses (keeping the last good file).
//! The payload is sealed with its SHA-256 digest ([`crate::mappo::checksum`]); [`Checkpoint::load`]
//! checks the digest, then that the counters agree with each other and with the
//! configuration (`env_steps = iteration * steps_per_iteration`, at most the configuration's
//! iterations, Adam's update count `iteration * epochs * num_minibatches`). Version 1 files,
//! written before checksums, load unchecked by the digest but with every other check.

use std::path::Path;

use envs::tasks::VecEnvState;
use nn::{Adam, StateDict};
use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;
use crate::mappo::evaluate::EvalSummary;
use crate::mappo::normalizer::ObsNormalizer;
use crate::mappo::seeding::RngState;

/// Current checkpoint format version: 2, the payload sealed with its checksum
/// ([`crate::mappo::checksum`]); version 1 files (no checksum) still load.
pub const VERSION: u32 = 2;

/// The last format version written without a checksum.
const UNSEALED_VERSION: u32 = 1;

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
    /// Writes the checkpoint atomically, sealed with its checksum, after checking that
    /// every value is finite; a non-finite state is refused ([`RlError::NonFinite`]) and
    /// the file at `path` (the last good checkpoint) is kept.
    pub fn save(&self, path: &Path) -> Result<()> {
        if let Err(what) = self.check_finite() {
            return Err(RlError::NonFinite {
                message: format!(
                    "{what} at iteration {}; the checkpoint was not written ({} keeps the last good state)",
                    self.iteration,
                    path.display()
                ),
            });
        }
        let text = serde_json::to_vec(self).map_err(|e| RlError::file(path, format!("cannot serialise: {e}")))?;
        nn::write_atomic(path, &crate::mappo::checksum::seal(&text))?;
        Ok(())
    }

    /// Reads a checkpoint and checks its checksum, version and counters (module docs);
    /// errors name the file and what is wrong.
    pub fn load(path: &Path) -> Result<Checkpoint> {
        use crate::mappo::checksum::{Unsealed, unseal};
        let bad = |message: String| RlError::Checkpoint { path: path.to_path_buf(), message };
        let bytes = std::fs::read(path).map_err(|e| RlError::file(path, format!("cannot read: {e}")))?;
        let (payload, sealed) = match unseal(&bytes).map_err(bad)? {
            Unsealed::Checked(p) => (p.as_bytes(), true),
            Unsealed::Unchecked(p) => (p, false),
        };
        let c: Checkpoint = serde_json::from_slice(payload).map_err(|e| bad(format!("not a valid checkpoint: {e}")))?;
        match (c.version, sealed) {
            (VERSION, true) | (UNSEALED_VERSION, false) => {}
            (VERSION, false) => {
                return Err(bad(format!(
                    "format version {VERSION} without its checksum envelope: the file was changed after it was                      written"
                )));
            }
            (v, _) => {
                return Err(bad(format!(
                    "format version {v} (this program reads versions {UNSEALED_VERSION} and {VERSION})"
                )));
            }
        }
        c.check_consistent().map_err(bad)?;
        c.check_finite().map_err(bad)?;
        Ok(c)
    }

    /// Checks that the counters agree with each other and with the checkpoint's
    /// configuration (module docs); the error says which do not.
    pub fn check_consistent(&self) -> std::result::Result<(), String> {
        let c = &self.config;
        c.validate("the checkpoint's configuration").map_err(|e| e.to_string())?;
        let per_iteration = c.steps_per_iteration();
        if self.iteration.checked_mul(per_iteration) != Some(self.env_steps) {
            return Err(format!(
                "iteration {} and env_steps {} disagree: the configuration collects {per_iteration} steps per                  iteration",
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
