//! The forward pass: the acceleration of the current state, as MuJoCo's `mj_forward`, in
//! named stages run in order by [`forward`] (MuJoCo documentation, "Computation"):
//!
//! 1. [`position`]: kinematics (body and geom poses), centre-of-mass quantities
//!    (`cdof`, `cinert`), and the mass matrix `M` by CRBA (armature on the diagonal);
//! 2. [`velocity`]: body velocities, the bias `c = C qdot + g` by recursive Newton-Euler, and
//!    the passive force `-D qvel`;
//! 3. [`actuation`]: motor forces `gear * clamp(ctrl, ctrlrange)`;
//! 4. [`acceleration`]: the smooth force `f = tau_act + tau_applied - D qvel - c`, `M`
//!    factored (tree-sparse `L^T D L`), `qacc_smooth = M^-1 f`; with damping, `H = M + h D`
//!    factored too;
//! 5. [`constraint`]: collision detection, then limits and contacts ([`crate::constraints`]),
//!    solved with `M` as in MuJoCo, and `qacc = H^-1 (f + J^T lambda)`, to which the
//!    integrator adds its own correction ([`crate::integrator::integrator_qacc`]).
//!
//! The stages only read what earlier ones wrote into [`Data`]; none changes the state
//! (`qpos`, `qvel`, `ctrl`).

use crate::data::Data;
use crate::integrator::integrator_qacc;
use crate::model::Model;
use crate::{collision, constraints, crba, kinematics, rne};

/// Computes `d.qacc` (and everything it depends on) for the current state, without changing
/// the state: the stages of the module docs, in order.
pub fn forward(m: &Model, d: &mut Data) {
    position(m, d);
    velocity(m, d);
    actuation(m, d);
    acceleration(m, d);
    constraint(m, d);
}

/// Stage 1: poses, `cdof` and `cinert`, and the mass matrix `M`.
pub fn position(m: &Model, d: &mut Data) {
    kinematics::kinematics(m, d);
    kinematics::com_pos(m, d);
    crba::crba(m, d);
}

/// Stage 2: body velocities, the bias forces `c` and the passive forces `-D qvel`.
pub fn velocity(m: &Model, d: &mut Data) {
    kinematics::com_vel(m, d);
    rne::bias(m, d);
    for i in 0..m.nv {
        d.qfrc_passive[i] = -m.dof_damping[i] * d.qvel[i];
    }
}

/// Stage 3: the motors' joint forces `gear * clamp(ctrl, ctrlrange)`.
pub fn actuation(m: &Model, d: &mut Data) {
    d.qfrc_actuator[..m.nv].iter_mut().for_each(|x| *x = 0.0);
    for (a, act) in m.actuators.iter().enumerate() {
        let c = match act.ctrlrange {
            Some([lo, hi]) => d.ctrl[a].clamp(lo, hi),
            None => d.ctrl[a],
        };
        d.qfrc_actuator[act.dof] += act.gear * c;
    }
}

/// Stage 4: the smooth force `f`, `M` factored, the unconstrained `qacc_smooth = M^-1 f`,
/// and with damping `H = M + h D` factored.
pub fn acceleration(m: &Model, d: &mut Data) {
    for i in 0..m.nv {
        d.qfrc_smooth[i] = d.qfrc_actuator[i] + d.qfrc_applied[i] + d.qfrc_passive[i] - d.qfrc_bias[i];
    }
    // A failed factorisation means a non-finite state (build() checked positive
    // definiteness); the non-finite values then propagate to qacc and are visible to callers.
    // M (for qacc_smooth and the constraint solver, as MuJoCo) and, with damping, M + h D.
    d.qlm.copy_from_slice(&d.qm);
    let _ = crba::ltdl_factor(m, &mut d.qlm);
    d.qacc_smooth.copy_from_slice(&d.qfrc_smooth);
    crba::ltdl_solve(m, &d.qlm, &mut d.qacc_smooth);
    if is_damped(m) {
        let _ = crba::factor_h(m, d, m.opt.timestep);
    }
}

/// Stage 5: contacts and limits, their forces `J^T lambda`, and
/// `qacc = (M + h D)^-1 (f + J^T lambda)` (MuJoCo's Euler with implicit damping), then the
/// integrator's correction.
pub fn constraint(m: &Model, d: &mut Data) {
    collision::collide(m, d);
    constraints::solve(m, d);
    let damped = is_damped(m);
    if damped || d.efc.n > 0 {
        for i in 0..m.nv {
            d.qacc[i] = d.qfrc_smooth[i] + d.qfrc_constraint[i];
        }
        crba::ltdl_solve(m, if damped { &d.qh } else { &d.qlm }, &mut d.qacc);
    } else {
        d.qacc.copy_from_slice(&d.qacc_smooth);
    }
    integrator_qacc(m, d);
}

/// Whether any dof has damping (then `H = M + h D` is factored and used).
fn is_damped(m: &Model) -> bool {
    m.dof_damping.iter().any(|&x| x > 0.0)
}
