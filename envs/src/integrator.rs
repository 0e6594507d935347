//! The step pipeline and MuJoCo's semi-implicit Euler integrator with implicit joint damping
//! (MuJoCo documentation, "Computation: numerical integration"; `mj_Euler`, `mj_integratePos`).
//!
//! [`step`] = [`forward`] then [`integrate`]:
//! 1. kinematics (body, geom poses), `cdof`/`cinert`;
//! 2. mass matrix `M` by CRBA (armature on the diagonal);
//! 3. velocities, bias `c = C qdot + g` by recursive Newton-Euler;
//! 4. passive force `-D qvel`, motors `gear * clamp(ctrl, ctrlrange)`;
//! 5. `H = M + h D` factored (tree-sparse `L^T D L`),
//!    `qacc_smooth = H^-1 (tau_act + tau_applied - D qvel - c)`;
//! 6. collision detection, then limits and contacts (`constraints`) giving `qacc`;
//! 7. `qvel <- qvel + h qacc` and positions integrated with the new velocity: hinges
//!    `q += h qdot`; free joints `p += h v` (world frame) and
//!    `quat <- normalize(quat * exp(h w / 2))` with `w` in the body frame.
//!
//! This is exactly MuJoCo's `mj_Euler` when any dof has damping: it solves
//! `(M + h D) qacc = f(q, v)` where `f` contains `-D v`, so `v' = v + h qacc` satisfies
//! `M (v' - v) / h = tau - c - D v'` (damping evaluated at the new velocity).

use crate::data::Data;
use crate::math;
use crate::model::{JointKind, Model};
use crate::{collision, constraints, crba, kinematics, rne};

/// Computes `d.qacc` (and everything it depends on) for the current state, without changing
/// the state.
pub fn forward(m: &Model, d: &mut Data) {
    let h = m.opt.timestep;
    kinematics::kinematics(m, d);
    kinematics::com_pos(m, d);
    crba::crba(m, d);
    kinematics::com_vel(m, d);
    rne::bias(m, d);
    let nv = m.nv;
    for i in 0..nv {
        d.qfrc_passive[i] = -m.dof_damping[i] * d.qvel[i];
        d.qfrc_actuator[i] = 0.0;
    }
    for (a, act) in m.actuators.iter().enumerate() {
        let c = match act.ctrlrange {
            Some([lo, hi]) => d.ctrl[a].clamp(lo, hi),
            None => d.ctrl[a],
        };
        d.qfrc_actuator[act.dof] += act.gear * c;
    }
    // A failed factorisation means a non-finite state (build() checked positive
    // definiteness); the non-finite values then propagate to qacc and are visible to callers.
    let _ = crba::factor_h(m, d, h);
    for i in 0..nv {
        d.qacc_smooth[i] = d.qfrc_actuator[i] + d.qfrc_applied[i] + d.qfrc_passive[i] - d.qfrc_bias[i];
    }
    crba::ltdl_solve(m, &d.qh, &mut d.qacc_smooth);
    collision::collide(m, d);
    constraints::solve(m, d);
}

/// Integrates velocities then positions by one time step from `d.qacc` (semi-implicit Euler).
pub fn integrate(m: &Model, d: &mut Data) {
    let h = m.opt.timestep;
    for i in 0..m.nv {
        d.qvel[i] += h * d.qacc[i];
    }
    integrate_pos(m, &mut d.qpos, &d.qvel, h);
    d.time += h;
}

/// `qpos <- qpos (+) h qvel` on the joint manifold (MuJoCo's `mj_integratePos`).
pub fn integrate_pos(m: &Model, qpos: &mut [f64], qvel: &[f64], h: f64) {
    for j in &m.joints {
        let (a, v) = (j.qpos_adr, j.dof_adr);
        match j.kind {
            JointKind::Hinge => qpos[a] += h * qvel[v],
            JointKind::Free => {
                for k in 0..3 {
                    qpos[a + k] += h * qvel[v + k];
                }
                let w = [qvel[v + 3], qvel[v + 4], qvel[v + 5]];
                let q = [qpos[a + 3], qpos[a + 4], qpos[a + 5], qpos[a + 6]];
                // Rotation by angle |w| h about w/|w|, in the body frame (right product).
                let speed = math::norm(w);
                let q = if speed > 0.0 {
                    let r = math::quat_axis_angle(math::scale(w, 1.0 / speed), speed * h);
                    math::quat_mul(math::quat_normalize(q), r)
                } else {
                    q
                };
                let q = math::quat_normalize(q);
                qpos[a + 3..a + 7].copy_from_slice(&q);
            }
        }
    }
}

/// Advances the state by one time step: [`forward`] then [`integrate`].
pub fn step(m: &Model, d: &mut Data) {
    forward(m, d);
    integrate(m, d);
}
