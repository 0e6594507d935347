//! Team Sumo rewards, win/lose/draw and the curriculum (MEBEN.md section 3).
//!
//! A team loses as soon as any of its agents' roots is farther than `R` (horizontally) from
//! the centre ball; the other team wins and the episode terminates (both at once: a draw).
//! Reward of team `t` (own team `O`, opponents `P`, `R` the arena radius):
//!
//! - dense: `5 exp(d_P - R) - 5 exp(d_O - R)` with `d_X` the distance of team X's farthest
//!   root from the centre, plus moving `5 sum_{i in O} sum_{j in P} max(v_i . (p_j - p_i), 0)`
//!   (horizontal), plus control `-0.1 sum_{i in O} ||a_i||_2`;
//! - sparse: `+1000` on a win, `-1000` on a loss, 0 otherwise;
//! - `r = alpha dense + (1 - alpha) sparse`, `alpha` the curriculum factor in `[0, 1]`
//!   (annealed by the trainer from 1 to 0 over the first quarter of training).

use super::outcome::{Outcome, RootState, approach, dist};

/// Weight of the dense distance terms.
pub const EDGE_WEIGHT: f64 = 5.0;
/// Weight of the moving term.
pub const MOVING_WEIGHT: f64 = 5.0;
/// Weight of the control cost.
pub const CONTROL_WEIGHT: f64 = 0.1;
/// Sparse reward of a win (a loss is its negative).
pub const WIN_REWARD: f64 = 1000.0;

/// One team's reward of one step, term by term.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SumoReward {
    /// `5 exp(d_opp - R) - 5 exp(d_own - R)`.
    pub edge: f64,
    /// `5 sum_own sum_opp max(v_i . (p_j - p_i), 0)`.
    pub moving: f64,
    /// `-0.1 sum_own ||a_i||`.
    pub control: f64,
    /// `+1000` win, `-1000` loss, 0 otherwise.
    pub sparse: f64,
}

impl SumoReward {
    /// Dense part: edge + moving + control.
    pub fn dense(&self) -> f64 {
        self.edge + self.moving + self.control
    }

    /// `alpha dense + (1 - alpha) sparse`.
    pub fn total(&self, alpha: f64) -> f64 {
        alpha * self.dense() + (1.0 - alpha) * self.sparse
    }
}

/// Distance of the farthest of `roots` from `centre` (0 for none).
pub fn farthest(roots: &[[f64; 2]], centre: [f64; 2]) -> f64 {
    roots.iter().map(|&p| dist(p, centre)).fold(0.0, f64::max)
}

/// Whether any of `roots` is farther than `radius` from `centre`.
pub fn out_of_arena(roots: &[[f64; 2]], centre: [f64; 2], radius: f64) -> bool {
    farthest(roots, centre) > radius
}

/// `5 exp(d_opp - R) - 5 exp(d_own - R)`.
pub fn edge_term(own: &[[f64; 2]], opp: &[[f64; 2]], centre: [f64; 2], radius: f64) -> f64 {
    EDGE_WEIGHT * ((farthest(opp, centre) - radius).exp() - (farthest(own, centre) - radius).exp())
}

/// `5 sum_own sum_opp max(v_i . (p_j - p_i), 0)`.
pub fn moving_term(own: &[[f64; 2]], own_vel: &[[f64; 2]], opp: &[[f64; 2]]) -> f64 {
    let mut s = 0.0;
    for (&p, &v) in own.iter().zip(own_vel) {
        for &q in opp {
            s += approach(v, p, q);
        }
    }
    MOVING_WEIGHT * s
}

/// `-0.1 sum_own ||a_i||`.
pub fn control_term(own_action_norms: &[f64]) -> f64 {
    -CONTROL_WEIGHT * own_action_norms.iter().sum::<f64>()
}

/// The outcome given the roots of each team (time limit not included).
pub fn outcome(team0: &[[f64; 2]], team1: &[[f64; 2]], centre: [f64; 2], radius: f64) -> Outcome {
    match (out_of_arena(team0, centre, radius), out_of_arena(team1, centre, radius)) {
        (true, true) => Outcome::Draw,
        (true, false) => Outcome::Win(1),
        (false, true) => Outcome::Win(0),
        (false, false) => Outcome::Running,
    }
}

/// Both teams' rewards and the outcome of a step that ended in `state`; `team[i]` is agent
/// `i`'s team (0 or 1).
pub fn evaluate(team: &[usize], centre: [f64; 2], radius: f64, state: &RootState) -> ([SumoReward; 2], Outcome) {
    let pick = |t: usize, xs: &[[f64; 2]]| -> Vec<[f64; 2]> {
        xs.iter().zip(team).filter(|(_, tt)| **tt == t).map(|(x, _)| *x).collect()
    };
    let pos = [pick(0, &state.pos), pick(1, &state.pos)];
    let vel = [pick(0, &state.vel), pick(1, &state.vel)];
    let out = outcome(&pos[0], &pos[1], centre, radius);
    let mut rewards = [SumoReward::default(); 2];
    for t in 0..2 {
        let norms: Vec<f64> = state.action_norm.iter().zip(team).filter(|(_, tt)| **tt == t).map(|(n, _)| *n).collect();
        rewards[t] = SumoReward {
            edge: edge_term(&pos[t], &pos[1 - t], centre, radius),
            moving: moving_term(&pos[t], &vel[t], &pos[1 - t]),
            control: control_term(&norms),
            sparse: match out {
                Outcome::Win(w) if w == t => WIN_REWARD,
                Outcome::Win(_) => -WIN_REWARD,
                _ => 0.0,
            },
        };
    }
    (rewards, out)
}
