//! `assignment_gradient = "episode"` (docs/TRAINING.md): a learned task assignment drawn at
//! an episode's first step and held to its end (`assignment_hold_episode`) decides the whole
//! episode, yet PPO's per-step advantage credits its draw with a discounted return over
//! about `1 / (1 − γ)` steps, and the cost of a poor assignment (a ball reached late or not at
//! all) lies beyond that horizon (docs/RESULTS.md, "What the held value tells the scorer").
//! Here the draw is credited with what it decides, the episode's undiscounted return
//! `R = Σ_t r_t` (the team's reward, unscaled):
//!
//! 1. **Collection** ([`EpisodeDraws::record_draws`]): at each step that draws, the raw
//!    observation `s_0` the actor read and the drawn `σ` are kept for that environment. They
//!    outlive the iteration, so checkpoints keep them ([`SavedDraws`]).
//! 2. **Episode end** ([`EpisodeDraws::end_episodes`]): the draw joins the iteration's
//!    finished draws with its episode's return `R`.
//! 3. **Advantages** ([`EpisodeBatch::new`]): each finished draw's return's standard score
//!    among the iteration's finished draws, `A_e = (R_e − mean R) / (std R + 1e-8)` (the mean
//!    is the baseline; with fewer than two finished draws there is no term).
//!    `ln π_old(σ_e | s_e)` is the scorer's before the update, read in one pass without a
//!    tape: the draws were made by the scorer of up to an episode's iterations earlier, and
//!    that lag is not corrected (no importance weight).
//! 4. **The loss** ([`crate::mappo::ppo::episode_assignment_term`]): minibatch `k` of each
//!    epoch gains the clipped surrogate of the `k`-th of `num_minibatches` near-equal shares
//!    of the finished draws ([`EpisodeBatch::share`]),
//!    `−(1 / |share|) Σ_e min(ρ_e A_e, clip(ρ_e, 1 − ε, 1 + ε) A_e)`,
//!    `ρ_e = π(σ_e | s_e) / π_old(σ_e | s_e)`, so that the draws are used `epochs` times
//!    under the same trust region as the actions. The drawn `σ`'s factor of the per-step
//!    ratio stays there without a gradient (as with `expected`).

use envs::layout::Observation;
use serde::{Deserialize, Serialize};

use crate::mappo::normalizer::ObsNormalizer;

/// One team's draws of the running episodes and those that ended in the current iteration
/// (module docs, steps 1 and 2).
#[derive(Clone, Debug)]
pub struct EpisodeDraws {
    /// Entries of one assignment.
    width: usize,
    /// `[E]` rows: the raw observation at each environment's draw of its running episode.
    at_draw: Observation,
    /// `[E * width]`: the assignment drawn there.
    sigma: Vec<u32>,
    /// `[E]`: whether the running episode's draw is recorded (not before its first step).
    recorded: Vec<bool>,
    /// The draws whose episodes ended since [`EpisodeDraws::take_finished`].
    finished: FinishedDraws,
}

/// Draws whose episodes ended, with their returns (module docs, step 2).
#[derive(Clone, Debug, PartialEq)]
pub struct FinishedDraws {
    /// The raw observation at each draw, one row each.
    pub raw: Observation,
    /// `[D * width]` the assignments drawn.
    pub sigma: Vec<u32>,
    /// `[D]` the episodes' undiscounted returns `R`.
    pub returns: Vec<f64>,
}

impl FinishedDraws {
    /// None yet, of rows shaped as `like`'s.
    fn empty(like: &Observation) -> Self {
        Self { raw: Observation::empty(like.nodes, like.agents), sigma: Vec::new(), returns: Vec::new() }
    }

    /// How many.
    pub fn len(&self) -> usize {
        self.returns.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.returns.is_empty()
    }
}

/// The draws of the running episodes as a checkpoint keeps them (the finished ones never
/// outlive an iteration's update).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SavedDraws {
    /// `[E, N, 3, 3]` the observations' vectors at the draws.
    pub vectors: Vec<f32>,
    /// `[E, N, N_SCALARS]` their scalars.
    pub scalars: Vec<f32>,
    /// `[E, A]` their headings.
    pub heading: Vec<f32>,
    /// `[E * width]` the assignments drawn.
    pub sigma: Vec<u32>,
    /// `[E]` whether each is recorded.
    pub recorded: Vec<bool>,
}

impl EpisodeDraws {
    /// Nothing recorded, for the environments of `obs` (their number and row shape) and
    /// assignments of `width` entries.
    pub fn new(obs: &Observation, width: usize) -> Self {
        let mut at_draw = obs.clone();
        at_draw.vectors.fill(0.0);
        at_draw.scalars.fill(0.0);
        at_draw.heading.fill(0.0);
        Self {
            width,
            sigma: vec![0; obs.batch * width],
            recorded: vec![false; obs.batch],
            finished: FinishedDraws::empty(obs),
            at_draw,
        }
    }

    /// Step 1: keeps the observation `obs` (raw, every environment) and the assignment of
    /// each environment that drew at this step (`assignment` `[E * width]`, `drawn` `[E]`).
    pub fn record_draws(&mut self, obs: &Observation, assignment: &[u32], drawn: &[bool]) {
        let w = self.width;
        for e in (0..drawn.len()).filter(|&e| drawn[e]) {
            self.at_draw.copy_row_from(obs, e);
            self.sigma[e * w..(e + 1) * w].copy_from_slice(&assignment[e * w..(e + 1) * w]);
            self.recorded[e] = true;
        }
    }

    /// Step 2: the draws of the environments whose episodes ended at this step (`ended`
    /// `[E]`) join the finished draws, each with its episode's return `episode_return(e)`.
    pub fn end_episodes(&mut self, ended: &[bool], episode_return: impl Fn(usize) -> f64) {
        let w = self.width;
        for (e, &end) in ended.iter().enumerate() {
            if !(end && self.recorded[e]) {
                continue;
            }
            self.finished.raw.push_rows(self.at_draw.rows().slice(e..e + 1));
            self.finished.sigma.extend_from_slice(&self.sigma[e * w..(e + 1) * w]);
            self.finished.returns.push(episode_return(e));
            self.recorded[e] = false;
        }
    }

    /// The finished draws, leaving none.
    pub fn take_finished(&mut self) -> FinishedDraws {
        std::mem::replace(&mut self.finished, FinishedDraws::empty(&self.at_draw))
    }

    /// The running episodes' draws, for a checkpoint.
    pub fn saved(&self) -> SavedDraws {
        SavedDraws {
            vectors: self.at_draw.vectors.clone(),
            scalars: self.at_draw.scalars.clone(),
            heading: self.at_draw.heading.clone(),
            sigma: self.sigma.clone(),
            recorded: self.recorded.clone(),
        }
    }

    /// Takes back the running episodes' draws of a checkpoint; an error (naming what does
    /// not match) where they are of another number of environments or shape.
    pub fn restore(&mut self, saved: &SavedDraws) -> Result<(), String> {
        let o = &self.at_draw;
        let shapes = [
            ("vectors", saved.vectors.len(), o.vectors.len()),
            ("scalars", saved.scalars.len(), o.scalars.len()),
            ("heading", saved.heading.len(), o.heading.len()),
            ("sigma", saved.sigma.len(), self.sigma.len()),
            ("recorded", saved.recorded.len(), self.recorded.len()),
        ];
        if let Some((name, got, want)) = shapes.iter().find(|(_, got, want)| got != want) {
            return Err(format!(
                "the episode draws' {name} hold {got} entries, and this run's {} environments need {want}",
                o.batch
            ));
        }
        self.at_draw.vectors.clone_from(&saved.vectors);
        self.at_draw.scalars.clone_from(&saved.scalars);
        self.at_draw.heading.clone_from(&saved.heading);
        self.sigma.clone_from(&saved.sigma);
        self.recorded.clone_from(&saved.recorded);
        self.finished = FinishedDraws::empty(&self.at_draw);
        Ok(())
    }
}

/// An iteration's finished draws as the update reads them (module docs, step 3).
#[derive(Clone, Debug)]
pub struct EpisodeBatch {
    /// The observations at the draws, normalised by the team's normaliser.
    pub obs: Observation,
    /// `[D * width]` the assignments drawn.
    pub sigma: Vec<u32>,
    /// `[D]` the advantages `A_e`.
    pub advantages: Vec<f32>,
    /// `[D]` `ln π_old(σ_e | s_e)`, filled by the update before its first step.
    pub logp_old: Vec<f32>,
}

impl EpisodeBatch {
    /// The batch of `finished` (normalised by `norm`), or `None` with fewer than two draws
    /// (no baseline). `logp_old` is left empty.
    pub fn new(finished: &FinishedDraws, norm: &ObsNormalizer) -> Option<Self> {
        let d = finished.len();
        if d < 2 {
            return None;
        }
        let mut obs = Observation::empty(finished.raw.nodes, finished.raw.agents);
        norm.apply_rows(finished.raw.rows(), &mut obs);
        Some(Self {
            obs,
            sigma: finished.sigma.clone(),
            advantages: standard_scores(&finished.returns),
            logp_old: Vec::new(),
        })
    }

    /// How many draws.
    pub fn len(&self) -> usize {
        self.advantages.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.advantages.is_empty()
    }

    /// The draws of minibatch `k` of `m`: the `k`-th of `m` near-equal contiguous shares
    /// (empty where there are fewer draws than minibatches).
    pub fn share(&self, k: usize, m: usize) -> std::ops::Range<usize> {
        let d = self.len();
        (k * d / m)..((k + 1) * d / m)
    }

    /// The assignments of the draws `range`.
    pub fn sigma_of(&self, range: std::ops::Range<usize>) -> &[u32] {
        let w = self.sigma.len() / self.len().max(1);
        &self.sigma[range.start * w..range.end * w]
    }
}

/// `(x − mean x) / (std x + 1e-8)`, in f64, as f32 (the population standard deviation).
pub fn standard_scores(x: &[f64]) -> Vec<f32> {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let std = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
    x.iter().map(|v| ((v - mean) / (std + 1e-8)) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two environments of one node and one agent, rows `[e, e, ...]`.
    fn obs(value: f32) -> Observation {
        let w = envs::layout::RowWidths::new(1, 1);
        Observation {
            batch: 2,
            nodes: 1,
            agents: 1,
            vectors: (0..2 * w.vectors).map(|i| value + (i / w.vectors) as f32).collect(),
            scalars: vec![value; 2 * w.scalars],
            heading: vec![value; 2],
        }
    }

    #[test]
    fn a_draw_is_credited_at_its_episode_end_with_the_observation_it_was_drawn_at() {
        let mut d = EpisodeDraws::new(&obs(0.0), 2);
        // Both draw at the first step; environment 1 ends first.
        d.record_draws(&obs(10.0), &[0, 1, 1, 0], &[true, true]);
        d.end_episodes(&[false, true], |e| 5.0 + e as f64);
        // Environment 1 draws again (at 20), environment 0 holds: its draw stays at 10.
        d.record_draws(&obs(20.0), &[7, 7, 0, 1], &[false, true]);
        d.end_episodes(&[true, false], |e| -1.0 - e as f64);
        let f = d.take_finished();
        assert_eq!(f.returns, vec![6.0, -1.0]);
        assert_eq!(f.sigma, vec![1, 0, 0, 1]);
        let w = f.raw.row_widths().vectors;
        assert_eq!(f.raw.vectors[0], 11.0, "environment 1's row at its first draw");
        assert_eq!(f.raw.vectors[w], 10.0, "environment 0's row at its draw, not at the later step");
        assert!(d.take_finished().is_empty());
        // An episode that ends without a recorded draw (before the run's first step) adds none.
        let mut fresh = EpisodeDraws::new(&obs(0.0), 2);
        fresh.end_episodes(&[true, true], |_| 1.0);
        assert!(fresh.take_finished().is_empty());
    }

    #[test]
    fn the_running_draws_survive_a_checkpoint_and_a_mismatch_is_refused() {
        let mut d = EpisodeDraws::new(&obs(0.0), 2);
        d.record_draws(&obs(3.0), &[0, 1, 1, 0], &[true, false]);
        let saved = d.saved();
        let mut back = EpisodeDraws::new(&obs(0.0), 2);
        back.restore(&saved).unwrap();
        for x in [&mut d, &mut back] {
            x.end_episodes(&[true, true], |e| e as f64);
        }
        assert_eq!(d.take_finished(), back.take_finished());
        let mut wrong = saved.clone();
        wrong.recorded.push(true);
        let e = back.restore(&wrong).unwrap_err();
        assert!(e.contains("recorded") && e.contains("3 entries") && e.contains("need 2"), "{e}");
    }

    #[test]
    fn advantages_are_standard_scores_and_the_shares_cover_every_draw_once() {
        let a = standard_scores(&[1.0, 3.0]);
        assert!((a[0] + 1.0).abs() < 1e-6 && (a[1] - 1.0).abs() < 1e-6, "{a:?}");
        let b = standard_scores(&[2.0, 2.0, 2.0]);
        assert_eq!(b, vec![0.0; 3], "equal returns: no advantage");
        let batch = EpisodeBatch {
            obs: Observation::empty(1, 1),
            sigma: (0..14).collect(),
            advantages: vec![0.0; 7],
            logp_old: Vec::new(),
        };
        let shares: Vec<_> = (0..3).map(|k| batch.share(k, 3)).collect();
        assert_eq!(shares, vec![0..2, 2..4, 4..7]);
        assert_eq!(batch.sigma_of(2..4), &[4, 5, 6, 7]);
        assert_eq!(batch.share(0, 8), 0..0, "more minibatches than draws: some shares are empty");
    }
}
