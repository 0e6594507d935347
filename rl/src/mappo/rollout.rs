//! The data of one iteration: `U` blocks, each one unroll of `T` control steps of all `E`
//! environments, and the minibatches of whole unrolls cut from it.
//!
//! Observation rows (raw, not normalised) are stored block by block, `T + 1` per block:
//! row `(b, t, e)` at `(b (T + 1) + t) E + e`, row `t = T` being the state after the block.
//! Transitions `(b, t, e)` are at `(b T + t) E + e`. A transition truncated by the time limit
//! keeps its final observation (a row of `finals`). A team whose model draws its task
//! assignment at random keeps the assignment each transition was acted on, so that the
//! update sees the same entity graph, and whether it was drawn there (the update's mask where
//! a drawn assignment is held: [`crate::mappo::assignment_hold`]).
//!
//! The collection writes it through two methods only: [`Rollout::begin`] with the first
//! observations of the iteration, then [`Rollout::push`] once per control step (the joint
//! action and the environments' outcome), until [`Rollout::is_full`]; the update reads it
//! through [`Rollout::gather`] and [`Rollout::visited_obs`]. Nothing else indexes its
//! arrays.

use envs::layout::{ObsRows, Observation, RowWidths};
use envs::tasks::StepOutput;

use crate::mappo::actor::JointAction;
use crate::mappo::minibatch::{Minibatch, NO_FINAL};

/// One iteration's data (module docs).
#[derive(Clone, Debug)]
pub struct Rollout {
    /// Blocks `U`.
    blocks: usize,
    /// Steps per unroll `T`.
    steps: usize,
    /// Environments `E`.
    envs: usize,
    /// Actions per environment.
    n_actions: usize,
    /// Teams.
    teams: usize,
    /// Steps pushed since [`Rollout::begin`] (block `cursor / T`, step `cursor % T`).
    cursor: usize,
    /// `U (T + 1) E` raw observation rows.
    obs: Observation,
    /// `[U T E, n_actions]` pre-squash actions.
    actions: Vec<f32>,
    /// `[U T E, teams]` behaviour log-probabilities.
    logp: Vec<f32>,
    /// `[U T E, teams]` scaled rewards.
    rewards: Vec<f32>,
    /// `[U T E]`.
    terminated: Vec<bool>,
    /// `[U T E]`.
    truncated: Vec<bool>,
    /// `[U T E]` row of `finals`, or [`NO_FINAL`].
    final_index: Vec<u32>,
    /// Final observations of truncated transitions, one row each.
    finals: Observation,
    /// Per team, the assignment width (entries per transition; 0: not stored).
    assignment_width: Vec<usize>,
    /// Per team, `[U T E, width]` the task assignment each transition was acted on.
    assignment: Vec<Vec<u32>>,
    /// Per team, `[U T E]` whether each transition's assignment was drawn there.
    assignment_drawn: Vec<Vec<bool>>,
    /// Per team, whether its collection held a drawn assignment (the update then masks the
    /// assignment's terms to the drawing steps; [`crate::mappo::assignment_hold`]), set by
    /// [`Rollout::begin`].
    assignment_held: Vec<bool>,
}

impl Rollout {
    /// Bytes the buffers of [`Rollout::new`] take for these sizes (`None` past `u128`).
    pub fn bytes(
        blocks: usize,
        steps: usize,
        envs: usize,
        obs: &Observation,
        n_actions: usize,
        teams: usize,
    ) -> Option<u128> {
        let (blocks, steps, envs) = (blocks as u128, steps as u128, envs as u128);
        let rows = blocks.checked_mul(steps + 1)?.checked_mul(envs)?;
        let tr = blocks.checked_mul(steps)?.checked_mul(envs)?;
        let w = obs.row_widths();
        let per_row = 4 * (w.vectors as u128 + w.scalars as u128 + w.heading as u128);
        let per_tr = 4 * (n_actions as u128 + 2 * teams as u128) + 2 + 4 + 9 * teams as u128;
        rows.checked_mul(per_row)?.checked_add(tr.checked_mul(per_tr)?)
    }

    /// Storage for `blocks` unrolls of `steps` steps of `envs` environments; team `k` stores
    /// `assignment_width[k]` assignment entries per transition.
    pub fn new(
        blocks: usize,
        steps: usize,
        envs: usize,
        obs: &Observation,
        n_actions: usize,
        assignment_width: &[usize],
    ) -> Self {
        let teams = assignment_width.len();
        let (nodes, agents) = (obs.nodes, obs.agents);
        let rows = blocks * (steps + 1) * envs;
        let tr = blocks * steps * envs;
        Self {
            blocks,
            steps,
            envs,
            n_actions,
            teams,
            cursor: 0,
            obs: Observation {
                batch: rows,
                nodes,
                agents,
                vectors: vec![0.0; rows * RowWidths::new(nodes, agents).vectors],
                scalars: vec![0.0; rows * RowWidths::new(nodes, agents).scalars],
                heading: vec![0.0; rows * agents],
            },
            actions: vec![0.0; tr * n_actions],
            logp: vec![0.0; tr * teams],
            rewards: vec![0.0; tr * teams],
            terminated: vec![false; tr],
            truncated: vec![false; tr],
            final_index: vec![NO_FINAL; tr],
            finals: Observation::empty(nodes, agents),
            assignment: assignment_width.iter().map(|&w| vec![0; tr * w]).collect(),
            assignment_drawn: assignment_width.iter().map(|&w| vec![true; if w > 0 { tr } else { 0 }]).collect(),
            assignment_width: assignment_width.to_vec(),
            assignment_held: vec![false; teams],
        }
    }

    /// Unrolls of the iteration (`U E`; unroll `q` is block `q / E`, environment `q % E`).
    pub fn unrolls(&self) -> usize {
        self.blocks * self.envs
    }

    /// Whether every step of the iteration has been pushed.
    pub fn is_full(&self) -> bool {
        self.cursor == self.blocks * self.steps
    }

    /// Starts an iteration's collection from the environments' current observations `obs`
    /// (the previous iteration's data is forgotten), team `k` holding a drawn task
    /// assignment between draws where `assignment_held[k]` (else drawn at every step).
    pub fn begin(&mut self, obs: &Observation, assignment_held: &[bool]) {
        assert_eq!(assignment_held.len(), self.teams, "one assignment hold per team");
        self.assignment_held.copy_from_slice(assignment_held);
        self.cursor = 0;
        self.finals.clear();
        self.final_index.iter_mut().for_each(|x| *x = NO_FINAL);
        self.obs.write_rows(self.obs_row(0, 0), obs.rows());
    }

    /// Records the next step: the teams' `joint` action (pre-squash actions, log-probabilities
    /// and the assignments of the teams that store theirs) on the current observations, and
    /// what the environments did with it (`out`: rewards, scaled by `reward_scaling`,
    /// ends, final observations of truncated episodes, the next observations). Panics when the
    /// rollout is full or the shapes differ (the trainer's internal writer).
    pub fn push(&mut self, joint: &JointAction, out: &StepOutput, reward_scaling: f32) {
        assert!(!self.is_full(), "a full rollout takes no step");
        let (b, t) = (self.cursor / self.steps, self.cursor % self.steps);
        let (e_n, nt, na) = (self.envs, self.teams, self.n_actions);
        let tr = self.transition(b, t);
        self.actions[tr * na..(tr + e_n) * na].copy_from_slice(&joint.pre_squash);
        for (k, (logp, assignment)) in joint.logp.iter().zip(&joint.assignment).enumerate() {
            for (e, &l) in logp.iter().enumerate() {
                self.logp[(tr + e) * nt + k] = l;
            }
            let w = self.assignment_width[k];
            if w > 0 {
                self.assignment[k][tr * w..(tr + e_n) * w].copy_from_slice(assignment);
                self.assignment_drawn[k][tr..tr + e_n].copy_from_slice(&joint.assignment_drawn[k]);
            }
        }
        for e in 0..e_n {
            let i = tr + e;
            for k in 0..nt {
                self.rewards[i * nt + k] = out.reward[e * nt + k] * reward_scaling;
            }
            self.terminated[i] = out.terminated[e];
            self.truncated[i] = out.truncated[e];
            if out.truncated[e] && !out.terminated[e] {
                self.final_index[i] = self.finals.batch as u32;
                self.finals.push_rows(out.final_obs.rows().slice(e..e + 1));
            } else {
                self.final_index[i] = NO_FINAL;
            }
        }
        // The next observations end this block's unroll at t + 1 = T and begin the next one.
        self.obs.write_rows(self.obs_row(b, t + 1), out.obs.rows());
        if t + 1 == self.steps && b + 1 < self.blocks {
            self.obs.write_rows(self.obs_row(b + 1, 0), out.obs.rows());
        }
        self.cursor += 1;
    }

    /// First observation row of block `b`, step `t`.
    fn obs_row(&self, b: usize, t: usize) -> usize {
        (b * (self.steps + 1) + t) * self.envs
    }

    /// First transition of block `b`, step `t`.
    fn transition(&self, b: usize, t: usize) -> usize {
        (b * self.steps + t) * self.envs
    }

    /// Observation rows of the iteration without the rows after each block: what the
    /// normaliser is updated with, one slice of rows per block.
    pub fn visited_obs(&self) -> Vec<ObsRows<'_, f32>> {
        (0..self.blocks).map(|b| self.obs.rows().slice(self.obs_row(b, 0)..self.obs_row(b, self.steps))).collect()
    }

    /// Gathers team `team`'s minibatch of unrolls `ids` (unroll `q` is block `q / E`,
    /// environment `q % E`) into `mb`, time-major, its raw observation rows in
    /// [`Minibatch::raw`] (module docs of [`crate::mappo::minibatch`]).
    pub fn gather(&self, ids: &[usize], team: usize, mb: &mut Minibatch) {
        let (t_len, m, e_n) = (self.steps, ids.len(), self.envs);
        let (nt, nact) = (self.teams, self.n_actions);
        mb.unrolls = m;
        mb.steps = t_len;
        mb.raw.clear();
        (mb.raw.nodes, mb.raw.agents) = (self.obs.nodes, self.obs.agents);
        for v in [&mut mb.actions, &mut mb.logp_old, &mut mb.rewards] {
            v.clear();
        }
        mb.terminated.clear();
        mb.truncated.clear();
        mb.final_row.clear();
        mb.assignment.clear();
        mb.assignment_drawn.clear();
        let w = self.assignment_width[team];
        // Where a drawn assignment was held, which steps drew it (the act step's record).
        let held = w > 0 && self.assignment_held[team];
        for t in 0..=t_len {
            for &q in ids {
                let r = self.obs_row(q / e_n, t) + q % e_n;
                mb.raw.push_rows(self.obs.rows().slice(r..r + 1));
            }
        }
        let mut next_row = ((t_len + 1) * m) as u32;
        for t in 0..t_len {
            for &q in ids {
                let i = self.transition(q / e_n, t) + q % e_n;
                mb.actions.extend_from_slice(&self.actions[i * nact..(i + 1) * nact]);
                mb.logp_old.push(self.logp[i * nt + team]);
                mb.rewards.push(self.rewards[i * nt + team]);
                mb.terminated.push(self.terminated[i]);
                mb.truncated.push(self.truncated[i]);
                mb.assignment.extend_from_slice(&self.assignment[team][i * w..(i + 1) * w]);
                if held {
                    mb.assignment_drawn.push(self.assignment_drawn[team][i]);
                }
                let f = self.final_index[i];
                if f == NO_FINAL {
                    mb.final_row.push(NO_FINAL);
                } else {
                    let f = f as usize;
                    mb.raw.push_rows(self.finals.rows().slice(f..f + 1));
                    mb.final_row.push(next_row);
                    next_row += 1;
                }
            }
        }
    }
}
