//! A task assignment drawn at random (`assignment=learned`, or `stochastic`) and held
//! ([`HoldRule`]): for `k` act steps ([`crate::TrainConfig::assignment_hold_steps`]), drawn at
//! steps `0, k, 2k, ..` of an act sequence (an iteration's collection, an evaluation's
//! episodes), or for each environment's whole episode
//! ([`crate::TrainConfig::assignment_hold_episode`]), drawn at its first step. Between draws
//! the held assignment is given back to the policy, so that one draw decides many steps of
//! actions.
//!
//! Why: the update's advantage at a step looks `T` steps ahead to its bootstrap value (the
//! unroll, MEBEN.md section 6), and the default critic does not read the assignment. A draw
//! made afresh at every step decides one action of those `T`, so its share of the advantage
//! is small; held for `k >= T` steps, a draw decides every action up to the bootstrap; held
//! for an episode, the agents also act on one assignment from start to end, as Algorithm 1's
//! (and an evaluation's `--assignment-hold` per episode) does, instead of on a new one every
//! `k` steps. The policy then factorises per step as
//! `π(a_t, σ_t | s_t) = π(σ_t | s_t) π(a_t | s_t, σ_t)` at a step that draws and
//! `π(a_t | s_t, σ_t)` at a held one (`σ_t = σ_{t-1}`): `ln π(σ | s)` joins the PPO ratio, and
//! `H(σ)` the bonus, at the drawing steps only. The act step records which environments drew
//! ([`crate::mappo::actor::JointAction::assignment_drawn`]) and the rollout keeps it for the
//! update's mask: the one record both read.
//!
//! A hold per episode outlives an iteration: the trainer marks the environments whose episode
//! ended ([`AssignmentHold::end_episodes`]) and checkpoints the held assignments
//! ([`AssignmentHold::saved`]), so that a resumed run acts on the same ones.

use models::DRAW_SCENE;
use serde::{Deserialize, Serialize};

/// How long a drawn assignment is held (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HoldRule {
    /// Drawn at act steps `0, k, 2k, ..` of a sequence (`Steps(1)`: every step).
    Steps(usize),
    /// Drawn at the first step of each environment's episode, held to its end.
    Episode,
}

impl HoldRule {
    /// Whether every step draws (`Steps(1)`, or `Steps(0)` read as 1): nothing is held.
    pub fn every_step(self) -> bool {
        matches!(self, HoldRule::Steps(k) if k <= 1)
    }
}

/// Whether act step `step` (from 0) of a sequence holding its assignment for `every` steps
/// draws a new one (every step for `every <= 1`).
pub fn draws_at(step: usize, every: usize) -> bool {
    every <= 1 || step.is_multiple_of(every)
}

/// A hold per episode as a checkpoint keeps it: the held assignment of every environment
/// (`[B * width]`) and which environments draw at their next step (`[B]`).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SavedHold {
    /// The assignment each environment acts on, `B * width` entries.
    pub held: Vec<u32>,
    /// Per environment, whether its next step draws (its episode has just begun).
    pub pending: Vec<bool>,
}

/// An act sequence's held assignment (module docs): its rule, the step count, the
/// assignment last drawn per environment and, for a hold per episode, the environments whose
/// next step draws.
#[derive(Clone, Debug)]
pub struct AssignmentHold {
    /// How long a draw is held.
    rule: HoldRule,
    /// Act steps since the sequence began.
    step: usize,
    /// The assignment held, `[B * width]` (empty before the first draw).
    held: Vec<u32>,
    /// `[B]`, a hold per episode: the environments whose next step draws.
    pending: Vec<bool>,
}

impl Default for AssignmentHold {
    fn default() -> Self {
        Self::new(HoldRule::Steps(1))
    }
}

impl AssignmentHold {
    /// A sequence holding each draw as `rule` says, not begun.
    pub fn new(rule: HoldRule) -> Self {
        let rule = match rule {
            HoldRule::Steps(k) => HoldRule::Steps(k.max(1)),
            r => r,
        };
        Self { rule, step: 0, held: Vec::new(), pending: Vec::new() }
    }

    /// How long a draw is held.
    pub fn rule(&self) -> HoldRule {
        self.rule
    }

    /// Holds each draw as `rule` says from now on, and begins a new sequence (every
    /// environment draws at its next step).
    pub fn set_rule(&mut self, rule: HoldRule) {
        *self = Self::new(rule);
    }

    /// Begins an iteration's act sequence: a hold of `k` steps draws at its next step; a hold
    /// per episode keeps every environment's (its episodes go on).
    pub fn restart(&mut self) {
        self.step = 0;
        if let HoldRule::Steps(_) = self.rule {
            self.held.clear();
        }
    }

    /// Writes to `out`, per environment of a batch of `envs` with `width` entries each,
    /// whether its next step draws: every one at steps `0, k, 2k, ..` of a hold of `k` steps;
    /// those whose episode has just begun for a hold per episode; and all whenever nothing of
    /// this size is held (the first step, or a batch of another size).
    pub fn draws_next(&self, envs: usize, width: usize, out: &mut Vec<bool>) {
        out.clear();
        let all = self.held.len() != envs * width || self.rule.every_step();
        match self.rule {
            HoldRule::Episode if !all && self.pending.len() == envs => out.extend_from_slice(&self.pending),
            HoldRule::Steps(k) if !all => out.resize(envs, draws_at(self.step, k)),
            _ => out.resize(envs, true),
        }
    }

    /// The assignment to give the policy where `drawn` (from [`AssignmentHold::draws_next`])
    /// is not all true: the held one, every entry of a drawing environment [`DRAW_SCENE`].
    pub fn given(&self, drawn: &[bool], width: usize) -> Vec<u32> {
        let mut given = self.held.clone();
        for (scene, &d) in given.chunks_mut(width.max(1)).zip(drawn) {
            if d {
                scene.fill(DRAW_SCENE);
            }
        }
        given
    }

    /// Ends a step that acted on `assignment` (`[B * width]`), drawn in the environments
    /// where `drawn`.
    pub fn record(&mut self, assignment: &[u32], drawn: &[bool]) {
        if !self.rule.every_step() {
            if self.held.len() != assignment.len() {
                self.held = assignment.to_vec();
            } else {
                let width = assignment.len() / drawn.len().max(1);
                for ((held, new), &d) in
                    self.held.chunks_mut(width.max(1)).zip(assignment.chunks(width.max(1))).zip(drawn)
                {
                    if d {
                        held.copy_from_slice(new);
                    }
                }
            }
            if self.rule == HoldRule::Episode {
                self.pending.clear();
                self.pending.resize(drawn.len(), false);
            }
        }
        self.step += 1;
    }

    /// Marks the environments whose episode ended at the last step (`ended[e]`): a hold per
    /// episode draws theirs at their next step. No effect on a hold of `k` steps.
    pub fn end_episodes(&mut self, ended: impl IntoIterator<Item = bool>) {
        if self.rule == HoldRule::Episode {
            for (p, e) in self.pending.iter_mut().zip(ended) {
                *p |= e;
            }
        }
    }

    /// What a checkpoint keeps of a hold per episode (`None` for a hold of `k` steps, which
    /// begins again with every iteration).
    pub fn saved(&self) -> Option<SavedHold> {
        (self.rule == HoldRule::Episode).then(|| SavedHold { held: self.held.clone(), pending: self.pending.clone() })
    }

    /// Restores a hold per episode from a checkpoint's [`SavedHold`] (with its rule set
    /// first). Errors, as a message, on a saved hold whose sizes do not agree.
    pub fn restore(&mut self, saved: &SavedHold) -> std::result::Result<(), String> {
        if self.rule != HoldRule::Episode {
            return Err("a held assignment saved for a run that does not hold one per episode".into());
        }
        let envs = saved.pending.len();
        if envs == 0 && !saved.held.is_empty() || envs > 0 && !saved.held.len().is_multiple_of(envs) {
            return Err(format!("a held assignment of {} entries for {envs} environments", saved.held.len()));
        }
        self.held = saved.held.clone();
        self.pending = saved.pending.clone();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One act step of a hold on a batch of `envs` of width 1: environment `e` draws
    /// `100 * step + e` where it draws.
    fn act(h: &mut AssignmentHold, step: u32, envs: usize) -> Vec<u32> {
        let drawn = next(h, envs);
        let given = if drawn.iter().all(|&d| d) { vec![DRAW_SCENE; envs] } else { h.given(&drawn, 1) };
        let a: Vec<u32> =
            given.iter().enumerate().map(|(e, &g)| if g == DRAW_SCENE { 100 * step + e as u32 } else { g }).collect();
        h.record(&a, &drawn);
        a
    }

    /// [`AssignmentHold::draws_next`] for a batch of `envs` of width 1.
    fn next(h: &AssignmentHold, envs: usize) -> Vec<bool> {
        let mut out = vec![false; 7];
        h.draws_next(envs, 1, &mut out);
        out
    }

    #[test]
    fn a_hold_of_k_draws_at_multiples_of_k_and_keeps_the_draw_between() {
        assert!((0..10).all(|s| draws_at(s, 1) && draws_at(s, 0)));
        let drawn: Vec<usize> = (0..10).filter(|&s| draws_at(s, 3)).collect();
        assert_eq!(drawn, [0, 3, 6, 9]);
        let mut h = AssignmentHold::new(HoldRule::Steps(3));
        let acted: Vec<u32> = (0..7).map(|s| act(&mut h, s, 2)[0]).collect();
        assert_eq!(acted, [0, 0, 0, 300, 300, 300, 600]);
        // Another batch size, or a restart, draws at once; episode ends change nothing.
        assert_eq!(next(&h, 4), [true; 4]);
        h.end_episodes([true, true]);
        assert_eq!(next(&h, 2), [false; 2]);
        h.restart();
        assert_eq!(next(&h, 2), [true; 2]);
        assert_eq!(h.saved(), None);
    }

    #[test]
    fn a_hold_per_episode_draws_where_an_episode_begins_and_survives_a_restart() {
        let mut h = AssignmentHold::new(HoldRule::Episode);
        assert_eq!(act(&mut h, 0, 3), [0, 1, 2]);
        assert_eq!(act(&mut h, 1, 3), [0, 1, 2]);
        // Environment 1's episode ends: only it draws at its next step.
        h.end_episodes([false, true, false]);
        assert_eq!(next(&h, 3), [false, true, false]);
        assert_eq!(h.given(&[false, true, false], 1), [0, DRAW_SCENE, 2]);
        assert_eq!(act(&mut h, 2, 3), [0, 201, 2]);
        // A new iteration goes on with the episodes.
        h.restart();
        assert_eq!(act(&mut h, 3, 3), [0, 201, 2]);
        // A checkpoint's copy restores the same hold, and the same next draws.
        h.end_episodes([true, false, false]);
        let saved = h.saved().expect("a hold per episode is saved");
        let mut back = AssignmentHold::new(HoldRule::Episode);
        back.restore(&saved).unwrap();
        assert_eq!(act(&mut back, 4, 3), act(&mut h, 4, 3));
        assert_eq!(back.saved(), h.saved());
        let bad = SavedHold { held: vec![0; 4], pending: vec![false; 3] };
        assert!(back.restore(&bad).unwrap_err().contains("4 entries for 3 environments"));
        assert!(AssignmentHold::new(HoldRule::Steps(5)).restore(&saved).is_err());
        // Another batch size draws everywhere.
        assert_eq!(next(&h, 2), [true; 2]);
    }
}
