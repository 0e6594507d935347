//! A task assignment drawn at random (`assignment=learned`, or `stochastic`) held for `k` act
//! steps ([`crate::TrainConfig::assignment_hold_steps`]): drawn at steps `0, k, 2k, ..` of an
//! act sequence (an iteration's collection, an evaluation's episodes) and given back to the
//! policy at the steps between, so that one draw decides `k` steps of actions.
//!
//! Why: the update's advantage at a step looks `T` steps ahead to its bootstrap value (the
//! unroll, MEBEN.md section 6), and the default critic does not read the assignment. A draw
//! made afresh at every step decides one action of those `T`, so its share of the advantage
//! is small; held for `k >= T` steps, a draw decides every action up to the bootstrap. The
//! policy then factorises per step as `π(a_t, σ_t | s_t) = π(σ_t | s_t) π(a_t | s_t, σ_t)` at a
//! step that draws and `π(a_t | s_t, σ_t)` at a held one (`σ_t = σ_{t-1}`): `ln π(σ | s)`
//! joins the PPO ratio, and `H(σ)` the bonus, at the drawing steps only ([`draws_at`] is the
//! one rule the act step and the update share).

/// Whether act step `step` (from 0) of a sequence holding its assignment for `every` steps
/// draws a new one (every step for `every <= 1`).
pub fn draws_at(step: usize, every: usize) -> bool {
    every <= 1 || step.is_multiple_of(every)
}

/// An act sequence's held assignment (module docs): the steps it is held for, the step
/// count, and the assignment last drawn.
#[derive(Clone, Debug)]
pub struct AssignmentHold {
    /// Steps each draw is held for (1: drawn at every step).
    every: usize,
    /// Act steps since the sequence began.
    step: usize,
    /// The assignment last drawn, `[B * width]` (empty before the first draw).
    held: Vec<u32>,
}

impl Default for AssignmentHold {
    fn default() -> Self {
        Self::new(1)
    }
}

impl AssignmentHold {
    /// A sequence holding each draw for `every` steps (0 reads as 1), not begun.
    pub fn new(every: usize) -> Self {
        Self { every: every.max(1), step: 0, held: Vec::new() }
    }

    /// The steps each draw is held for.
    pub fn every(&self) -> usize {
        self.every
    }

    /// Holds each draw for `every` steps from now on, and begins a new sequence.
    pub fn set_every(&mut self, every: usize) {
        *self = Self::new(every);
    }

    /// Begins a new sequence: its next step draws.
    pub fn restart(&mut self) {
        self.step = 0;
        self.held.clear();
    }

    /// Whether the next step draws: at steps `0, k, 2k, ..`, and whenever nothing of `len`
    /// entries is held (the first step, or a batch of another size).
    pub fn draws_next(&self, len: usize) -> bool {
        draws_at(self.step, self.every) || self.held.len() != len
    }

    /// The held assignment (valid where [`AssignmentHold::draws_next`] is false).
    pub fn held(&self) -> &[u32] {
        &self.held
    }

    /// Ends a step that acted on `assignment`, drawn at this step if `drawn`.
    pub fn record(&mut self, assignment: &[u32], drawn: bool) {
        if drawn && self.every > 1 {
            self.held.clear();
            self.held.extend_from_slice(assignment);
        }
        self.step += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hold_of_k_draws_at_multiples_of_k_and_keeps_the_draw_between() {
        assert!((0..10).all(|s| draws_at(s, 1) && draws_at(s, 0)));
        let drawn: Vec<usize> = (0..10).filter(|&s| draws_at(s, 3)).collect();
        assert_eq!(drawn, [0, 3, 6, 9]);
        let mut h = AssignmentHold::new(3);
        let mut acted = Vec::new();
        for step in 0..7u32 {
            let draws = h.draws_next(2);
            let a = if draws { vec![step, step] } else { h.held().to_vec() };
            h.record(&a, draws);
            acted.push(a[0]);
        }
        assert_eq!(acted, [0, 0, 0, 3, 3, 3, 6]);
        // Another batch size, or a restart, draws at once.
        assert!(h.draws_next(4));
        h.restart();
        assert!(h.draws_next(2));
    }
}
