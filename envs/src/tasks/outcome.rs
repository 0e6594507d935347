//! How an environment's current step ended, and the horizontal root state that rewards and
//! outcomes are computed from.

use serde::{Deserialize, Serialize};

/// The state of an episode after a control step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Outcome {
    /// The episode goes on.
    #[default]
    Running,
    /// Reach: every ball covered at this step (terminated, with the success bonus).
    Success,
    /// Sumo: the given team (0 or 1) won: an opponent's root left the arena (terminated).
    Win(usize),
    /// Sumo: both teams had a root leave the arena at the same step (terminated, no sparse
    /// reward for either).
    Draw,
    /// The episode reached its length (truncated); for Sumo this is also a draw.
    TimeLimit,
    /// The simulation produced a non-finite state, or one whose observation or reward is
    /// not finite in f32 (beyond 3.4e38), at this step (terminated, zero reward); should not
    /// happen, reported so that training can count it.
    Diverged,
}

impl Outcome {
    /// Whether the episode ended by its own rules (not by the time limit).
    pub fn is_terminal(self) -> bool {
        matches!(self, Outcome::Success | Outcome::Win(_) | Outcome::Draw | Outcome::Diverged)
    }
}

/// Horizontal positions and velocities of the agents' roots, and the L2 norms of their
/// (clipped) actions, in the scene's agent order: all that the rewards need.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RootState {
    /// Root positions (x, y).
    pub pos: Vec<[f64; 2]>,
    /// Root linear velocities (vx, vy).
    pub vel: Vec<[f64; 2]>,
    /// `||a_i||_2` of each agent's action.
    pub action_norm: Vec<f64>,
}

/// Horizontal distance.
pub fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// `max(v . (target - p), 0)`: progress of a root moving at `v` from `p` towards `target`.
pub fn approach(v: [f64; 2], p: [f64; 2], target: [f64; 2]) -> f64 {
    (v[0] * (target[0] - p[0]) + v[1] * (target[1] - p[1])).max(0.0)
}
