//! Random starts (MEBEN.md sections 2, 3), their rotation about a vertical axis and their
//! horizontal translation.
//!
//! - Team Reach: every ball at radius `sqrt(U(0, R^2))`, angle `U[0, 2 pi)` (uniform over the
//!   disc of radius `R`); every agent the same, with a uniform yaw, except that an agent whose
//!   footprint (the horizontal radius of its rest pose) overlaps an already placed agent's is
//!   drawn again (up to [`MAX_TRIES`] times; then the draw with the largest clearance is kept):
//!   agents never start interpenetrating, which the reference release allowed. A single agent
//!   is therefore exactly uniform over the disc.
//! - Team Sumo: the centre ball at the origin; every agent at radius `U(1, min(2, R - 1))`
//!   (the release's ring, inside `R - 1`), angle `U[0, 2 pi)`, uniform yaw, redrawn in the
//!   same way when footprints overlap.
//!
//! A [`Start`] is in the horizontal plane; [`Start::to_qpos`] stands every agent at its rest
//! pose (joints mid-range, lowest point [`START_CLEARANCE`] above the ground) with the drawn root position and yaw.

use super::scene::Scene;
use super::spec::TaskKind;
use rand::{Rng, RngExt};
use std::f64::consts::TAU;

/// Height (m) above its rest height at which every agent starts: the feet then touch down at a
/// generic instant, so which contacts exist at a step never hangs on round-off (at exactly
/// the rest height the lowest points sit at distance +-1e-17 from the ground, and a rotated
/// copy of the scene could start with a different set of contacts).
pub const START_CLEARANCE: f64 = 0.01;

/// Redraws of an agent whose footprint overlaps another's.
pub const MAX_TRIES: usize = 64;

/// Horizontal placement of one agent's root.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RootPlacement {
    /// Root position (x, y) in m.
    pub xy: [f64; 2],
    /// Yaw about the vertical (rad).
    pub yaw: f64,
}

/// The start of an episode: agent roots and ball centres in the horizontal plane.
#[derive(Clone, Debug, PartialEq)]
pub struct Start {
    /// One per agent, in the scene's agent order.
    pub agents: Vec<RootPlacement>,
    /// Ball centres (x, y): Reach goal balls, or the Sumo centre ball.
    pub balls: Vec<[f64; 2]>,
}

/// A point uniform over the disc of radius `r` about the origin.
pub fn uniform_disc<R: Rng + ?Sized>(rng: &mut R, r: f64) -> [f64; 2] {
    let rho = (rng.random::<f64>() * r * r).sqrt();
    let phi = rng.random::<f64>() * TAU;
    [rho * phi.cos(), rho * phi.sin()]
}

/// A point at radius `U(r0, r1)` and a uniform angle.
fn uniform_ring<R: Rng + ?Sized>(rng: &mut R, r0: f64, r1: f64) -> [f64; 2] {
    let rho = r0 + rng.random::<f64>() * (r1 - r0);
    let phi = rng.random::<f64>() * TAU;
    [rho * phi.cos(), rho * phi.sin()]
}

/// Draws a random start for `scene`.
pub fn sample_start<R: Rng + ?Sized>(scene: &Scene, rng: &mut R) -> Start {
    let r = scene.spec.radius;
    let (balls, ring) = match scene.kind() {
        TaskKind::Reach => ((0..scene.spec.balls).map(|_| uniform_disc(rng, r)).collect(), None),
        TaskKind::Sumo => (vec![[0.0, 0.0]], Some((1.0, (r - 1.0).min(2.0)))),
    };
    let mut agents: Vec<RootPlacement> = Vec::with_capacity(scene.agents.len());
    for (i, a) in scene.agents.iter().enumerate() {
        let mut best: Option<(f64, RootPlacement)> = None;
        for _ in 0..MAX_TRIES {
            let xy = match ring {
                None => uniform_disc(rng, r),
                Some((r0, r1)) => uniform_ring(rng, r0, r1),
            };
            let p = RootPlacement { xy, yaw: rng.random::<f64>() * TAU };
            // Clearance: the smallest gap between this footprint and the placed ones.
            let clearance = agents
                .iter()
                .zip(&scene.agents[..i])
                .map(|(o, oa)| (p.xy[0] - o.xy[0]).hypot(p.xy[1] - o.xy[1]) - a.footprint - oa.footprint)
                .fold(f64::INFINITY, f64::min);
            if best.is_none_or(|(c, _)| clearance > c) {
                best = Some((clearance, p));
            }
            if clearance >= 0.0 {
                break;
            }
        }
        if let Some((_, p)) = best {
            agents.push(p);
        }
    }
    Start { agents, balls }
}

/// `p` rotated by `angle` about the vertical through `point`.
pub fn rotate_xy(p: [f64; 2], angle: f64, point: [f64; 2]) -> [f64; 2] {
    let (s, c) = angle.sin_cos();
    let (dx, dy) = (p[0] - point[0], p[1] - point[1]);
    [point[0] + c * dx - s * dy, point[1] + s * dx + c * dy]
}

impl Start {
    /// The same scene rotated by `angle` (rad) about the vertical through `point` (x, y):
    /// positions rotate about the point, yaws grow by `angle` (`angle = 0`: an exact copy).
    pub fn rotated(&self, angle: f64, point: [f64; 2]) -> Start {
        if angle == 0.0 {
            return self.clone(); // exactly, without round-off
        }
        Start {
            agents: self
                .agents
                .iter()
                .map(|a| RootPlacement { xy: rotate_xy(a.xy, angle, point), yaw: a.yaw + angle })
                .collect(),
            balls: self.balls.iter().map(|&b| rotate_xy(b, angle, point)).collect(),
        }
    }

    /// The same scene translated horizontally by `shift` (x, y) in m: positions move, yaws do
    /// not (`shift = [0, 0]`: an exact copy).
    pub fn translated(&self, shift: [f64; 2]) -> Start {
        if shift == [0.0, 0.0] {
            return self.clone(); // exactly, without round-off
        }
        let add = |p: [f64; 2]| [p[0] + shift[0], p[1] + shift[1]];
        Start {
            agents: self.agents.iter().map(|a| RootPlacement { xy: add(a.xy), yaw: a.yaw }).collect(),
            balls: self.balls.iter().map(|&b| add(b)).collect(),
        }
    }

    /// Generalised positions: the model's rest pose with each agent's root at its placement
    /// (height: the agent's rest height plus [`START_CLEARANCE`]; orientation: the yaw about the
    /// vertical).
    pub fn to_qpos(&self, scene: &Scene) -> Vec<f64> {
        let mut q = scene.model.qpos0.clone();
        for (a, p) in scene.agents.iter().zip(&self.agents) {
            let (s, c) = (0.5 * p.yaw).sin_cos();
            q[a.qpos_adr..a.qpos_adr + 7].copy_from_slice(&[
                p.xy[0],
                p.xy[1],
                a.rest_height + START_CLEARANCE,
                c,
                0.0,
                0.0,
                s,
            ]);
        }
        q
    }
}
