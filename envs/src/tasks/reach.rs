//! Team Reach rewards, success and termination (MEBEN.md section 2). One shared team reward
//! per step:
//!
//! `r = 10000 [success] + 5 sum_b exp(-d_b) + 0.2 sum_i sum_b max(v_i . (p_b - p_i), 0)
//!      - 0.2 sum_i ||a_i||_2`
//!
//! with `d_b` the horizontal distance from ball `b` to the nearest agent root, `p`, `v`
//! horizontal root positions and velocities, `a_i` agent `i`'s clipped action. Success: every
//! ball has some root within [`COVER_RADIUS`] at the same step; the episode then terminates.

use super::outcome::{Outcome, RootState, approach, dist};

/// A ball is covered by a root within this horizontal distance (m).
pub const COVER_RADIUS: f64 = 0.5;
/// Bonus on the success step.
pub const SUCCESS_BONUS: f64 = 10000.0;
/// Weight of the distance term.
pub const DISTANCE_WEIGHT: f64 = 5.0;
/// Weight of the moving term.
pub const MOVING_WEIGHT: f64 = 0.2;
/// Weight of the control cost.
pub const CONTROL_WEIGHT: f64 = 0.2;

/// The reward of one step, term by term.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReachReward {
    /// `5 sum_b exp(-d_b)`.
    pub distance: f64,
    /// `0.2 sum_i sum_b max(v_i . (p_b - p_i), 0)`.
    pub moving: f64,
    /// `-0.2 sum_i ||a_i||`.
    pub control: f64,
    /// `10000` on the success step, else 0.
    pub bonus: f64,
}

impl ReachReward {
    /// Sum of the terms.
    pub fn total(&self) -> f64 {
        self.distance + self.moving + self.control + self.bonus
    }
}

/// Horizontal distance from `ball` to the nearest root (infinite without agents).
pub fn nearest_root(ball: [f64; 2], roots: &[[f64; 2]]) -> f64 {
    roots.iter().map(|&p| dist(ball, p)).fold(f64::INFINITY, f64::min)
}

/// `5 sum_b exp(-d_b)`.
pub fn distance_term(balls: &[[f64; 2]], roots: &[[f64; 2]]) -> f64 {
    DISTANCE_WEIGHT * balls.iter().map(|&b| (-nearest_root(b, roots)).exp()).sum::<f64>()
}

/// `0.2 sum_i sum_b max(v_i . (p_b - p_i), 0)`.
pub fn moving_term(balls: &[[f64; 2]], roots: &[[f64; 2]], vels: &[[f64; 2]]) -> f64 {
    let mut s = 0.0;
    for (&p, &v) in roots.iter().zip(vels) {
        for &b in balls {
            s += approach(v, p, b);
        }
    }
    MOVING_WEIGHT * s
}

/// `-0.2 sum_i ||a_i||`.
pub fn control_term(action_norms: &[f64]) -> f64 {
    -CONTROL_WEIGHT * action_norms.iter().sum::<f64>()
}

/// Whether every ball has a root within [`COVER_RADIUS`].
pub fn all_covered(balls: &[[f64; 2]], roots: &[[f64; 2]]) -> bool {
    balls.iter().all(|&b| nearest_root(b, roots) <= COVER_RADIUS)
}

/// Reward and outcome of a step that ended in `state` (time limit not included).
pub fn evaluate(balls: &[[f64; 2]], state: &RootState) -> (ReachReward, Outcome) {
    let success = all_covered(balls, &state.pos);
    let reward = ReachReward {
        distance: distance_term(balls, &state.pos),
        moving: moving_term(balls, &state.pos, &state.vel),
        control: control_term(&state.action_norm),
        bonus: if success { SUCCESS_BONUS } else { 0.0 },
    };
    (reward, if success { Outcome::Success } else { Outcome::Running })
}
