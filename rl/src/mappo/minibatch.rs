//! One team's minibatch of whole unrolls: what [`crate::mappo::rollout::Rollout::gather`]
//! writes, [`Minibatch::normalise`] normalises and [`crate::mappo::ppo::loss`] reads.
//!
//! Arrays are time-major: entry `(t, j)` of `T` steps of `M` unrolls is at `t M + j`. The
//! observation rows are `T + 1` per unroll (row `T M + j` is the state after unroll `j`),
//! then one row per truncated transition holding its final observation, `(T + 1) M + K` rows
//! for `K` truncated transitions; [`Minibatch::final_row`] points a truncated transition at
//! its row.

use envs::layout::{ObsRows, Observation};

use crate::mappo::normalizer::ObsNormalizer;

/// Marks a transition without a final observation (in [`Minibatch::final_row`]).
pub const NO_FINAL: u32 = u32::MAX;

/// One team's minibatch (module docs). Reused from one minibatch to the next: every array
/// is cleared and refilled by [`crate::mappo::rollout::Rollout::gather`].
#[derive(Clone, Debug)]
pub struct Minibatch {
    /// Steps per unroll `T`.
    pub steps: usize,
    /// Unrolls `M`.
    pub unrolls: usize,
    /// The raw observation rows, `(T + 1) M + K`, as the rollout stored them.
    pub raw: Observation,
    /// The same rows normalised by the team's normaliser ([`Minibatch::normalise`]): what the
    /// model reads.
    pub obs: Observation,
    /// `[T M, n_actions]` pre-squash actions of every agent (the scene's action layout).
    pub actions: Vec<f32>,
    /// `[T M]` the team's behaviour log-probabilities `log pi_old(u | s)`.
    pub logp_old: Vec<f32>,
    /// `[T M]` the team's rewards, scaled.
    pub rewards: Vec<f32>,
    /// `[T M]`: the episode ended by its rules at this step.
    pub terminated: Vec<bool>,
    /// `[T M]`: the episode reached its time limit at this step.
    pub truncated: Vec<bool>,
    /// `[T M]`: for a truncated transition, the row of its final observation; else
    /// [`NO_FINAL`].
    pub final_row: Vec<u32>,
    /// `[T M, width]` the task assignment each transition was acted on (empty: the model
    /// solves it again, the same for the deterministic methods).
    pub assignment: Vec<u32>,
    /// `[T M]` whether each transition drew its task assignment (`false`: held from an
    /// earlier step, [`crate::mappo::assignment_hold`]); empty when every step draws.
    pub assignment_drawn: Vec<bool>,
}

impl Default for Minibatch {
    fn default() -> Self {
        Self {
            steps: 0,
            unrolls: 0,
            raw: Observation::empty(0, 0),
            obs: Observation::empty(0, 0),
            actions: Vec::new(),
            logp_old: Vec::new(),
            rewards: Vec::new(),
            terminated: Vec::new(),
            truncated: Vec::new(),
            final_row: Vec::new(),
            assignment: Vec::new(),
            assignment_drawn: Vec::new(),
        }
    }
}

impl Minibatch {
    /// Transitions `T M`.
    pub fn transitions(&self) -> usize {
        self.steps * self.unrolls
    }

    /// Normalises the raw rows into [`Minibatch::obs`] with `norm` (frozen during the
    /// update, as in the reference).
    pub fn normalise(&mut self, norm: &ObsNormalizer) {
        norm.apply_rows(self.raw.rows(), &mut self.obs);
    }

    /// The normalised rows `range` (e.g. the transitions `0..T M`).
    pub fn obs_rows(&self, range: std::ops::Range<usize>) -> ObsRows<'_, f32> {
        self.obs.rows().slice(range)
    }
}
