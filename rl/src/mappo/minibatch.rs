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

    /// What a value that reads the learned assignment held into each step reads (models'
    /// `assign_critic=held`): whether each transition's assignment was held into it (not
    /// drawn there), and for the rows `T M ..` that bootstrap the returns, the assignment
    /// held into each and whether one is. The state after unroll `j` holds the assignment
    /// of the unroll's last transition unless that transition ended its episode (the next
    /// step draws: [`crate::mappo::assignment_hold`]); a truncated transition's final
    /// observation holds the transition's. Where every step draws (`assignment_drawn` empty:
    /// no hold, or a warm-up) nothing is held. With `at_draw`
    /// ([`crate::TrainConfig::assignment_value_at_draw`]) a transition that drew reads its
    /// drawn assignment too: every transition of a hold is marked held.
    pub fn held_assignment(&self, at_draw: bool) -> HeldAssignment {
        let n = self.transitions();
        let boot = self.obs.batch.saturating_sub(n);
        let width = self.assignment.len().checked_div(n).unwrap_or(0);
        let hold = !self.assignment_drawn.is_empty();
        let transitions =
            if hold { self.assignment_drawn.iter().map(|&d| at_draw || !d).collect() } else { vec![false; n] };
        let mut bootstrap = vec![0u32; boot * width];
        let mut bootstrap_held = vec![false; boot];
        let of = |i: usize| &self.assignment[i * width..(i + 1) * width];
        for j in 0..self.unrolls.min(boot) {
            let last = (self.steps - 1) * self.unrolls + j;
            bootstrap[j * width..(j + 1) * width].copy_from_slice(of(last));
            bootstrap_held[j] = hold && !self.terminated[last] && !self.truncated[last];
        }
        for (i, &row) in self.final_row.iter().enumerate() {
            if row != NO_FINAL {
                let r = row as usize - n;
                bootstrap[r * width..(r + 1) * width].copy_from_slice(of(i));
                bootstrap_held[r] = hold;
            }
        }
        HeldAssignment { transitions, bootstrap, bootstrap_held }
    }

    /// The normalised rows `range` (e.g. the transitions `0..T M`).
    pub fn obs_rows(&self, range: std::ops::Range<usize>) -> ObsRows<'_, f32> {
        self.obs.rows().slice(range)
    }
}

/// [`Minibatch::held_assignment`]: the held assignment a value reads, per row.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HeldAssignment {
    /// `[T M]` whether each transition's assignment was held into it.
    pub transitions: Vec<bool>,
    /// `[(M + K) width]` the assignment of each bootstrap row (rows `T M ..`).
    pub bootstrap: Vec<u32>,
    /// `[M + K]` whether each bootstrap row holds [`HeldAssignment::bootstrap`]'s.
    pub bootstrap_held: Vec<bool>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `T = 2` steps of `M = 3` unrolls, width 2 (transition `i` acted on `[i, 10 + i]`),
    /// one truncated transition (`(1, 2)`, its final row `8`), drawn where `drawn` says.
    fn minibatch(drawn: Vec<bool>, terminated: Vec<bool>) -> Minibatch {
        let (steps, unrolls) = (2, 3);
        let n = steps * unrolls;
        let mut truncated = vec![false; n];
        truncated[5] = true;
        let mut final_row = vec![NO_FINAL; n];
        final_row[5] = ((steps + 1) * unrolls) as u32;
        // Only the row count is read: T M transitions, M after the unrolls, 1 final.
        let mut obs = Observation::empty(1, 1);
        obs.batch = (steps + 1) * unrolls + 1;
        Minibatch {
            steps,
            unrolls,
            obs,
            terminated,
            truncated,
            final_row,
            assignment: (0..n as u32).flat_map(|i| [i, 10 + i]).collect(),
            assignment_drawn: drawn,
            ..Minibatch::default()
        }
    }

    /// The transitions hold where they did not draw; after each unroll its last transition's
    /// assignment is held unless that episode ended there (transition 3 terminated,
    /// transition 5 truncated); a truncated transition's final observation holds its own.
    #[test]
    fn the_bootstrap_rows_hold_the_last_assignment_of_an_episode_that_goes_on() {
        let mb = minibatch(vec![true, true, false, false, true, false], vec![false, false, false, true, false, false]);
        let h = mb.held_assignment(false);
        assert_eq!(h.transitions, [false, false, true, true, false, true]);
        // Read at the drawing steps too: every transition holds, the bootstrap rows as before.
        let at_draw = mb.held_assignment(true);
        assert_eq!(at_draw.transitions, [true; 6]);
        assert_eq!((&at_draw.bootstrap, &at_draw.bootstrap_held), (&h.bootstrap, &h.bootstrap_held));
        assert_eq!(h.bootstrap, [3, 13, 4, 14, 5, 15, 5, 15]);
        assert_eq!(h.bootstrap_held, [false, true, false, true]);
        // Drawn at every step (no record), nothing is held.
        let every = minibatch(Vec::new(), vec![false; 6]).held_assignment(true);
        assert_eq!((every.transitions, every.bootstrap_held), (vec![false; 6], vec![false; 4]));
        assert_eq!(every.bootstrap, h.bootstrap);
    }
}
