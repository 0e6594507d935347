//! How much a team's actions depend on its task assignment (`meben eval
//! --assignment-sensitivity`, issue 79's diagnostics).
//!
//! A learned assignment is trained by the policy gradient of `ln π(σ | s)` (MODELS.md): its
//! expected gradient is `E_σ[∇ ln π(σ | s) Q(s, σ)]` with `Q(s, σ) = E_{a ~ π(· | s, σ)}
//! Q(s, a)`, which vanishes when the actions do not depend on `σ`. How far they do is
//! measured here, at every control step of an evaluation and for every scene still playing:
//! the Kullback-Leibler divergence, in nats, from the team's action distribution under the
//! assignment it acted on, `σ`, to that under every other one-to-one assignment `σ'` of the
//! same objects,
//!
//! `KL(π(· | s, σ) ‖ π(· | s, σ')) = Σ_{agents, dims} [ln(std'/std) + (std² + (loc - loc')²) / (2 std'²) - 1/2]`,
//!
//! over the pre-squash Normals of the team's agents (independent given `s` and `σ`, so the
//! team's divergence is the sum of theirs). Pinsker's inequality bounds the difference of
//! the two assignments' values by it: `|Q(s, σ) - Q(s, σ')| <= Q_max sqrt(KL / 2)`. A
//! scene's figure is the mean over its alternatives `σ'` (every injective map of the objects
//! `σ` assigns to the team's agents but `σ` itself: one on `team_reach/2_ants`). Models
//! whose episodes end at different lengths are measured over different states (a policy
//! that reaches its balls in 200 steps is measured while approaching them only), so the
//! mean over each episode's first [`EARLY_STEPS`] control steps is given too.
//!
//! The probe's extra forward passes are given their assignments, so they draw nothing from
//! a learned assignment's stream: an evaluation gives the same summary with and without it.

use envs::layout::ObsRows;
use models::distribution::std_from_scale;
use models::{NO_AGENT, Policy};
use nn::ParamStore;
use serde::{Deserialize, Serialize};
use tensor::Tape;

use crate::error::{Result, RlError};
use crate::mappo::actor::host_heads;

/// The most alternative assignments a scene may have (5 agents for 5 objects: 119).
pub const MAX_ALTERNATIVES: usize = 119;

/// The control steps from an episode's start over which [`AssignmentSensitivity::early_mean_kl`]
/// is taken.
pub const EARLY_STEPS: usize = 100;

/// One team's figures over an evaluation (module docs).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AssignmentSensitivity {
    /// The team.
    pub team: usize,
    /// Scene-steps measured: every control step of every scene still playing.
    pub steps: usize,
    /// Alternative assignments `σ'` per scene-step, on average.
    pub alternatives: f64,
    /// Mean over scene-steps of `KL(π(· | s, σ) ‖ π(· | s, σ'))` (nats, averaged over `σ'`).
    pub mean_kl: f64,
    /// Its median over scene-steps.
    pub median_kl: f64,
    /// Its 90th percentile over scene-steps (nearest rank).
    pub p90_kl: f64,
    /// Its mean over the first [`EARLY_STEPS`] control steps of every episode.
    pub early_mean_kl: f64,
}

/// Accumulates one team's divergences over an evaluation's steps.
#[derive(Debug)]
pub struct SensitivityProbe {
    team: usize,
    kl: Vec<f64>,
    alternatives: usize,
    early: (f64, usize),
}

impl SensitivityProbe {
    /// A probe of team `team`'s policy.
    pub fn new(team: usize) -> Self {
        Self { team, kl: Vec::new(), alternatives: 0, early: (0.0, 0) }
    }

    /// Measures control step `step` (0 at the episodes' start): `obs` the normalised
    /// observation rows of `B` scenes the team acted on ([`crate::mappo::actor::Actor::normalised`]),
    /// `acted` the assignment `model` acted on (`[B * assignment_width]`), `alive[b]` whether
    /// scene `b` still plays (only those are counted).
    pub fn observe(
        &mut self,
        model: &mut dyn Policy,
        store: &ParamStore<f32>,
        obs: ObsRows<'_, f32>,
        acted: &[u32],
        alive: &[bool],
        step: usize,
    ) -> Result<()> {
        let (b, width, n) = (obs.len(), model.assignment_width(), model.agents().len());
        if width == 0 || acted.len() != b * width || alive.len() != b {
            return Err(RlError::Model(models::ModelError::Input(format!(
                "assignment sensitivity of team {}: an assignment of {} entries ({width} objects) and {} \
                 alive flags for {b} scenes (a model with a task assignment is needed)",
                self.team,
                acted.len(),
                alive.len()
            ))));
        }
        let alternatives: Vec<Vec<Vec<u32>>> =
            acted.chunks(width).map(|sigma| alternatives_of(sigma, n)).collect::<Result<_>>()?;
        let rounds = alternatives.iter().map(Vec::len).max().unwrap_or(0);
        let reference = heads(model, store, obs, acted)?;
        let mut sum = vec![0.0f64; b];
        for r in 0..rounds {
            // The r-th alternative of every scene that has one; the others keep σ.
            let mut batch = acted.to_vec();
            for (s, alts) in alternatives.iter().enumerate() {
                if let Some(alt) = alts.get(r) {
                    batch[s * width..(s + 1) * width].copy_from_slice(alt);
                }
            }
            let other = heads(model, store, obs, &batch)?;
            for (s, alts) in alternatives.iter().enumerate() {
                if r < alts.len() {
                    sum[s] += team_kl(&reference, &other, s);
                }
            }
        }
        for (s, alts) in alternatives.iter().enumerate() {
            if alive[s] && !alts.is_empty() {
                let kl = sum[s] / alts.len() as f64;
                self.kl.push(kl);
                self.alternatives += alts.len();
                if step < EARLY_STEPS {
                    self.early.0 += kl;
                    self.early.1 += 1;
                }
            }
        }
        Ok(())
    }

    /// The team's figures so far (zeros before any scene-step).
    pub fn summary(&self) -> AssignmentSensitivity {
        let steps = self.kl.len();
        if steps == 0 {
            return AssignmentSensitivity { team: self.team, ..Default::default() };
        }
        let mut sorted = self.kl.clone();
        sorted.sort_by(f64::total_cmp);
        let rank = |q: f64| sorted[((q * steps as f64).ceil() as usize).clamp(1, steps) - 1];
        let median = if steps % 2 == 1 { sorted[steps / 2] } else { 0.5 * (sorted[steps / 2 - 1] + sorted[steps / 2]) };
        AssignmentSensitivity {
            team: self.team,
            steps,
            alternatives: self.alternatives as f64 / steps as f64,
            mean_kl: self.kl.iter().sum::<f64>() / steps as f64,
            median_kl: median,
            p90_kl: rank(0.9),
            early_mean_kl: self.early.0 / self.early.1.max(1) as f64,
        }
    }
}

/// Each agent's `(loc, std)` rows `[B, dof]` (f64, on the host) of `model` for the
/// normalised rows `obs` under `assignment`.
fn heads(
    model: &mut dyn Policy,
    store: &ParamStore<f32>,
    obs: ObsRows<'_, f32>,
    assignment: &[u32],
) -> Result<Vec<AgentNormals>> {
    let tape = Tape::<f32>::on(store.device());
    let _no_grad = tape.no_grad();
    let p = store.bind(&tape);
    let out = model.forward(&p, &obs, Some(assignment), false)?;
    let host = Tape::<f32>::new();
    let _host_no_grad = host.no_grad();
    let mut heads = Vec::new();
    for (agent, loc, scale) in host_heads(&out.agents)? {
        let dof = loc.shape().last().copied().unwrap_or(0);
        let std = std_from_scale(host.constant(scale)).value();
        let as_f64 = |d: &[f32]| d.iter().map(|&x| x as f64).collect::<Vec<f64>>();
        let (loc, std) = (as_f64(loc.data()), as_f64(std.data()));
        if let Some(i) = loc.iter().chain(&std).position(|x| !x.is_finite()) {
            return Err(RlError::NonFinite {
                message: format!("policy output of agent {agent} (entry {i}) is not finite"),
            });
        }
        heads.push(AgentNormals { loc, std, dof });
    }
    Ok(heads)
}

/// One agent's pre-squash Normals over a batch, on the host.
#[derive(Debug)]
struct AgentNormals {
    /// Means `[B, dof]`.
    loc: Vec<f64>,
    /// Standard deviations `[B, dof]`.
    std: Vec<f64>,
    /// Action dimensions.
    dof: usize,
}

/// `KL(p ‖ q)` of scene `s`'s joint action distribution, summed over the agents' dimensions.
fn team_kl(p: &[AgentNormals], q: &[AgentNormals], s: usize) -> f64 {
    let mut kl = 0.0;
    for (a, b) in p.iter().zip(q) {
        for k in s * a.dof..(s + 1) * a.dof {
            kl += gaussian_kl(a.loc[k], a.std[k], b.loc[k], b.std[k]);
        }
    }
    kl
}

/// `KL(N(μ_p, σ_p²) ‖ N(μ_q, σ_q²)) = ln(σ_q/σ_p) + (σ_p² + (μ_p - μ_q)²) / (2 σ_q²) - 1/2`.
pub fn gaussian_kl(mu_p: f64, std_p: f64, mu_q: f64, std_q: f64) -> f64 {
    (std_q / std_p).ln() + (std_p * std_p + (mu_p - mu_q).powi(2)) / (2.0 * std_q * std_q) - 0.5
}

/// Every injective map of the objects `sigma` assigns (its entries other than [`NO_AGENT`])
/// to the agents `0..n`, `sigma` itself left out, in lexicographic order of the agents
/// taken; the objects without an agent stay without one. An error past
/// [`MAX_ALTERNATIVES`], or for an assignment that is not one-to-one onto `0..n`.
pub fn alternatives_of(sigma: &[u32], n: usize) -> Result<Vec<Vec<u32>>> {
    let objects: Vec<usize> = (0..sigma.len()).filter(|&j| sigma[j] != NO_AGENT).collect();
    let k = objects.len();
    let bad =
        |why: &str| RlError::Model(models::ModelError::Input(format!("assignment {sigma:?} of {n} agents: {why}")));
    for (a, &j) in objects.iter().enumerate() {
        if sigma[j] as usize >= n || objects[..a].iter().any(|&i| sigma[i] == sigma[j]) {
            return Err(bad("not one-to-one onto the agents"));
        }
    }
    let count: usize = (0..k).map(|i| n - i).product();
    if count - 1 > MAX_ALTERNATIVES {
        return Err(bad(&format!(
            "{} other assignments, more than the {MAX_ALTERNATIVES} the probe enumerates",
            count - 1
        )));
    }
    let mut out = Vec::with_capacity(count - 1);
    let mut taken = Vec::with_capacity(k);
    let mut used = vec![false; n];
    enumerate(n, k, &mut taken, &mut used, &mut |agents| {
        let mut alt = vec![NO_AGENT; sigma.len()];
        for (&j, &i) in objects.iter().zip(agents) {
            alt[j] = i as u32;
        }
        if alt != sigma {
            out.push(alt);
        }
    });
    Ok(out)
}

/// Calls `emit` with every sequence of `k` distinct agents of `0..n`, lexicographically.
fn enumerate(n: usize, k: usize, taken: &mut Vec<usize>, used: &mut [bool], emit: &mut dyn FnMut(&[usize])) {
    if taken.len() == k {
        emit(taken);
        return;
    }
    for i in 0..n {
        if !used[i] {
            used[i] = true;
            taken.push(i);
            enumerate(n, k, taken, used, emit);
            taken.pop();
            used[i] = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_alternatives_are_every_other_one_to_one_map_of_the_assigned_objects() {
        // Two agents, two balls: the swap only.
        assert_eq!(alternatives_of(&[1, 0], 2).unwrap(), vec![vec![0, 1]]);
        // Three agents, two balls: 3 x 2 = 6 maps, σ left out; lexicographic.
        let alts = alternatives_of(&[2, 0], 3).unwrap();
        assert_eq!(alts, vec![vec![0, 1], vec![0, 2], vec![1, 0], vec![1, 2], vec![2, 1]]);
        // More balls than agents: the unassigned ball stays unassigned.
        let alts = alternatives_of(&[0, 1, NO_AGENT], 2).unwrap();
        assert_eq!(alts, vec![vec![1, 0, NO_AGENT]]);
        // One agent, one ball: nothing else to try.
        assert!(alternatives_of(&[0], 1).unwrap().is_empty());
        // 4 agents for 4 objects: 4! - 1, each one-to-one and different.
        let alts = alternatives_of(&[3, 1, 0, 2], 4).unwrap();
        assert_eq!(alts.len(), 23);
        for a in &alts {
            let mut s = a.clone();
            s.sort();
            assert_eq!(s, vec![0, 1, 2, 3]);
        }
        // Refusals: a repeated agent, an agent out of range, too many to enumerate.
        assert!(alternatives_of(&[0, 0], 2).unwrap_err().to_string().contains("not one-to-one"));
        assert!(alternatives_of(&[0, 2], 2).is_err());
        let e = alternatives_of(&[0, 1, 2, 3, 4, 5], 6).unwrap_err().to_string();
        assert!(e.contains("719 other assignments"), "{e}");
    }

    #[test]
    fn the_gaussian_divergence_is_zero_only_for_equal_normals_and_matches_its_closed_form() {
        assert_eq!(gaussian_kl(0.3, 0.7, 0.3, 0.7), 0.0);
        // A shift of one standard deviation: 1/2 nat.
        assert!((gaussian_kl(1.0, 2.0, 3.0, 2.0) - 0.5).abs() < 1e-15);
        // Scales only: ln 2 + 1/8 - 1/2 from std 1 to std 2.
        assert!((gaussian_kl(0.0, 1.0, 0.0, 2.0) - (2f64.ln() + 0.125 - 0.5)).abs() < 1e-15);
        // Against E_p[ln p(x) - ln q(x)] integrated numerically (the midpoint rule over ±12
        // standard deviations of p).
        let (mp, sp, mq, sq) = (0.4, 0.6, -0.5, 1.3);
        let ln_pdf =
            |x: f64, m: f64, s: f64| -0.5 * ((x - m) / s).powi(2) - s.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
        let (lo, hi, cells) = (mp - 12.0 * sp, mp + 12.0 * sp, 200_000);
        let h = (hi - lo) / cells as f64;
        let quad: f64 = (0..cells)
            .map(|c| {
                let x = lo + (c as f64 + 0.5) * h;
                ln_pdf(x, mp, sp).exp() * (ln_pdf(x, mp, sp) - ln_pdf(x, mq, sq)) * h
            })
            .sum();
        assert!((gaussian_kl(mp, sp, mq, sq) - quad).abs() < 1e-9, "{quad}");
        assert!(gaussian_kl(mp, sp, mq, sq) > 0.0);
    }

    #[test]
    fn the_summary_takes_the_mean_median_and_upper_decile_over_scene_steps() {
        let mut probe = SensitivityProbe::new(1);
        assert_eq!(probe.summary(), AssignmentSensitivity { team: 1, ..Default::default() });
        probe.kl = (1..=10).map(|x| x as f64).collect();
        probe.alternatives = 20;
        probe.early = (3.0, 2);
        let s = probe.summary();
        assert_eq!((s.team, s.steps, s.alternatives), (1, 10, 2.0));
        assert_eq!((s.mean_kl, s.median_kl, s.p90_kl, s.early_mean_kl), (5.5, 5.5, 9.0, 1.5));
        probe.kl.push(100.0);
        let s = probe.summary();
        assert_eq!((s.median_kl, s.p90_kl), (6.0, 10.0));
    }
}
