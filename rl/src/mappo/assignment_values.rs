//! The value of every task assignment at each episode's first step, beside the return the
//! episode brought (`meben eval --assignment-values`, issue 79's diagnostics).
//!
//! With `assignment_gradient = "expected"` (TRAINING.md) a learned scorer follows
//! `Σ_σ' ∇π(σ' | s) V(s, σ')` at the steps that draw, `V(s, σ')` the value that reads the
//! held assignment (`assign_critic=held`, MODELS.md). Whether that value ranks the
//! assignments as the returns they bring do is measured here. At the first control step of
//! every episode (a drawing step under every hold), for every scene, the probe reads
//!
//! - `V(s_0, σ')` and `π(σ' | s_0)` for every assignment `σ'` of the model's support
//!   ([`Policy::learned_assignment_support`]), every `σ'` held, as the expected gradient
//!   reads them ([`crate::mappo::ppo::expected_assignment_term`]);
//! - `V(s_0)`, the value read without an assignment, as it is trained at a drawing step
//!   (unless `assignment_value_at_draw`);
//! - which `σ'` the scene acted on at step 0;
//!
//! and, over the episode, its return, its success, and its discounted return `G = Σ_t γ^t c r_t` (`γ` the run's discount,
//! `c` its reward scaling: the units of the value's targets; `γ^1000` is below `1e-13` at the
//! paper's `γ = 0.97`, so an episode cut at its time limit loses nothing the value would
//! bootstrap).
//!
//! Evaluations with the same seed begin their episodes from the same states, so two of them
//! (the scorer's own draws, and Algorithm 1 held for the episode: `meben eval --assignment
//! greedy --assignment-hold 1000`) pair episode by episode: where the draw was not Algorithm
//! 1's, the difference of the two returns is what the draw brought from that state, beside
//! the value's difference of the same two assignments there
//! (`rl/sweeps/assignment_values.py`).
//!
//! The probe reads the scorer and the value of a copy of the team's model with its warm-up
//! off (so that a policy acting with Algorithm 1 in place of its draws is read as trained),
//! in passes of its own that draw nothing: an evaluation plays the same episodes with and
//! without it.

use envs::layout::{ObsRows, Observation};
use envs::tasks::Outcome;
use models::Policy;
use nn::ParamStore;
use serde::{Deserialize, Serialize};
use tensor::Tape;

use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;

/// The units of the values' targets: what an episode's rewards are discounted and scaled
/// by to be compared with them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReturnUnits {
    /// The discount `γ`.
    pub discount: f64,
    /// The reward scaling `c`.
    pub reward_scaling: f64,
}

impl ReturnUnits {
    /// The units of the values of a run trained with `config`: its discount and reward
    /// scaling.
    pub fn of(config: &TrainConfig) -> Self {
        Self { discount: config.discount, reward_scaling: config.reward_scaling }
    }
}

/// One episode's figures (module docs).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeValues {
    /// The index in [`AssignmentValues::support`] of the assignment acted on at step 0.
    pub acted: usize,
    /// `V(s_0, σ')` for every `σ'` of the support, in its order.
    pub value: Vec<f64>,
    /// `π(σ' | s_0)` for every `σ'` of the support, in its order.
    pub probability: Vec<f64>,
    /// `V(s_0)`, read without an assignment.
    pub unheld_value: f64,
    /// `Σ_t γ^t c r_t` over the episode.
    pub discounted_return: f64,
    /// `Σ_t r_t` over the episode (undiscounted and unscaled, as the summary's mean return).
    #[serde(rename = "return")]
    pub episode_return: f64,
    /// Whether the episode ended in success (Team Reach: every ball covered).
    pub success: bool,
}

/// One team's figures over an evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AssignmentValues {
    /// The team.
    pub team: usize,
    /// Every assignment `σ'` the scorer draws from (its support), each `[objects]`.
    pub support: Vec<Vec<u32>>,
    /// The units of [`EpisodeValues::discounted_return`].
    pub units: ReturnUnits,
    /// Per episode, in the evaluation's order.
    pub episodes: Vec<EpisodeValues>,
}

impl AssignmentValues {
    /// The share of episodes whose value ranks the assignment acted on first (ties count).
    pub fn acted_ranked_first(&self) -> f64 {
        let first = self.episodes.iter().filter(|e| e.value.iter().all(|&v| v <= e.value[e.acted])).count();
        first as f64 / self.episodes.len().max(1) as f64
    }

    /// The mean over episodes of `V(s_0, σ_acted)` and of the discounted return, and their
    /// Pearson correlation (0 where either is constant).
    pub fn acted_value_and_return(&self) -> (f64, f64, f64) {
        let v: Vec<f64> = self.episodes.iter().map(|e| e.value[e.acted]).collect();
        let g: Vec<f64> = self.episodes.iter().map(|e| e.discounted_return).collect();
        let n = v.len().max(1) as f64;
        let (mv, mg) = (v.iter().sum::<f64>() / n, g.iter().sum::<f64>() / n);
        let cov: f64 = v.iter().zip(&g).map(|(a, b)| (a - mv) * (b - mg)).sum();
        let (sv, sg) =
            (v.iter().map(|a| (a - mv).powi(2)).sum::<f64>(), g.iter().map(|b| (b - mg).powi(2)).sum::<f64>());
        let r = if sv > 0.0 && sg > 0.0 { cov / (sv * sg).sqrt() } else { 0.0 };
        (mv, mg, r)
    }

    /// Marks each episode's `success` from its `outcome` (one per episode, in order).
    pub fn record_outcomes(&mut self, outcome: &[Outcome]) {
        for (episode, o) in self.episodes.iter_mut().zip(outcome) {
            episode.success = *o == Outcome::Success;
        }
    }
}

/// Reads one team's values at its episodes' first step and sums their discounted returns.
#[derive(Debug)]
pub struct ValueProbe {
    model: Box<dyn Policy>,
    figures: AssignmentValues,
    /// `γ^t` of the next step's rewards.
    weight: f64,
}

impl ValueProbe {
    /// A probe of team `team`, whose model is `model` (copied, its warm-up switched off).
    /// An error unless the model learns its assignment and its value reads the held one.
    pub fn new(team: usize, model: &dyn Policy, units: ReturnUnits) -> Result<Self> {
        let mut model = model.clone_box();
        model.set_assignment_warmup(false);
        let support = model.learned_assignment_support();
        if support.is_empty() || !model.value_reads_held_assignment() {
            return Err(input(format!(
                "assignment values of team {team}: `{}` has no value that reads a learned assignment \
                 (assignment=learned;assign_critic=held)",
                model.name()
            )));
        }
        let figures = AssignmentValues { team, support, units, episodes: Vec::new() };
        Ok(Self { model, figures, weight: 1.0 })
    }

    /// Reads step 0 of every scene: `obs` the team's normalised observation rows of the `B`
    /// scenes ([`crate::mappo::actor::Actor::normalised`]), `acted` the assignment each acted
    /// on (`[B * width]`).
    pub fn first_step(&mut self, store: &ParamStore<f32>, obs: ObsRows<'_, f32>, acted: &[u32]) -> Result<()> {
        let (b, k) = (obs.len(), self.figures.support.len());
        let width = self.figures.support[0].len();
        if acted.len() != b * width {
            return Err(input(format!(
                "assignment values of team {}: {} assignment entries for {b} scenes of {width} objects",
                self.figures.team,
                acted.len()
            )));
        }
        let acted_index = acted
            .chunks(width)
            .map(|sigma| {
                self.figures.support.iter().position(|s| s == sigma).ok_or_else(|| {
                    input(format!("assignment values: the acted assignment {sigma:?} is not in the scorer's support"))
                })
            })
            .collect::<Result<Vec<usize>>>()?;
        // The scenes once per σ' (block `a` holds σ'_a), every one held; then once unheld.
        let mut rows = Observation::empty(obs.nodes, obs.agents);
        let mut assignment = Vec::with_capacity(k * b * width);
        for sigma in &self.figures.support {
            rows.push_rows(obs);
            for _ in 0..b {
                assignment.extend_from_slice(sigma);
            }
        }
        let tape = Tape::<f32>::on(store.device());
        let _no_grad = tape.no_grad();
        let p = store.bind(&tape);
        let out = self.model.forward_held(&p, &rows.rows(), &assignment, &vec![true; k * b])?;
        let values = out.team_value()?.value().to_host()?.to_vec();
        let terms = out.assignment_terms.ok_or_else(|| {
            input(format!("assignment values: `{}` gave no learned assignment's log-probability", self.model.name()))
        })?;
        let log_prob = terms.log_prob.value().to_host()?.to_vec();
        let unheld = self.model.forward_held(&p, &obs, &assignment[..b * width], &vec![false; b])?;
        let unheld = unheld.team_value()?.value().to_host()?.to_vec();
        for (s, &acted) in acted_index.iter().enumerate() {
            let at = |xs: &[f32], a: usize| f64::from(xs[a * b + s]);
            let episode = EpisodeValues {
                acted,
                value: (0..k).map(|a| at(&values, a)).collect(),
                probability: (0..k).map(|a| at(&log_prob, a).exp()).collect(),
                unheld_value: f64::from(unheld[s]),
                ..EpisodeValues::default()
            };
            if let Some(i) = episode.value.iter().chain(&episode.probability).position(|x| !x.is_finite()) {
                return Err(RlError::NonFinite {
                    message: format!("assignment values of scene {s}: entry {i} is not finite"),
                });
            }
            self.figures.episodes.push(episode);
        }
        Ok(())
    }

    /// Adds one control step's rewards (`reward[e]` the team's, counted where `alive[e]`).
    pub fn rewards(&mut self, reward: impl Fn(usize) -> f64, alive: &[bool]) {
        let units = self.figures.units;
        for (e, episode) in self.figures.episodes.iter_mut().enumerate() {
            if alive[e] {
                let r = reward(e);
                episode.discounted_return += self.weight * units.reward_scaling * r;
                episode.episode_return += r;
            }
        }
        self.weight *= units.discount;
    }

    /// The figures, each episode's `success` read from `outcome` (one per episode).
    pub fn summary(mut self, outcome: &[Outcome]) -> AssignmentValues {
        self.figures.record_outcomes(outcome);
        self.figures
    }
}

/// A model-input error with `message`.
fn input(message: String) -> RlError {
    RlError::Model(models::ModelError::Input(message))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn episode(acted: usize, value: [f64; 2], g: f64) -> EpisodeValues {
        EpisodeValues {
            acted,
            value: value.to_vec(),
            probability: vec![0.5, 0.5],
            discounted_return: g,
            ..Default::default()
        }
    }

    #[test]
    fn the_summaries_rank_the_acted_assignment_and_correlate_its_value_with_the_return() {
        let figures = AssignmentValues {
            team: 0,
            support: vec![vec![0, 1], vec![1, 0]],
            units: ReturnUnits::default(),
            episodes: vec![
                episode(0, [2.0, 1.0], 3.0),
                episode(1, [2.0, 1.0], 1.0),
                episode(1, [1.0, 1.0], 2.0),
                episode(0, [0.0, 5.0], 0.0),
            ],
        };
        // Ranked first: episodes 0 and 2 (a tie counts).
        assert_eq!(figures.acted_ranked_first(), 0.5);
        // V(acted) = 2, 1, 1, 0 (mean 1); G = 3, 1, 2, 0 (mean 1.5); r = 3 / sqrt(2 * 5).
        let (v, g, r) = figures.acted_value_and_return();
        assert_eq!((v, g), (1.0, 1.5));
        assert!((r - 3.0 / 10f64.sqrt()).abs() < 1e-15, "{r}");
        let flat = AssignmentValues { episodes: vec![episode(0, [1.0, 0.0], 1.0); 3], ..figures };
        assert_eq!(flat.acted_value_and_return().2, 0.0);
    }

    #[test]
    fn only_a_success_marks_an_episode_successful() {
        let mut figures = AssignmentValues { episodes: vec![episode(0, [0.0, 0.0], 0.0); 4], ..Default::default() };
        figures.record_outcomes(&[Outcome::TimeLimit, Outcome::Success, Outcome::Win(0), Outcome::Success]);
        let marked: Vec<bool> = figures.episodes.iter().map(|e| e.success).collect();
        assert_eq!(marked, [false, true, false, true]);
    }
}
