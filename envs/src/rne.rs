//! Recursive Newton-Euler (Featherstone, RBDA §5.3, in MuJoCo's world-frame form `mj_rne`):
//! bias forces `c(q, qdot) = C qdot + g` (with zero joint acceleration) and inverse dynamics.
//! Gravity enters as a fictitious base acceleration `-g` (RBDA §5.3, "a_0 = -a_g").

#![allow(clippy::needless_range_loop)] // index loops mirror the formulas (RBDA notation)

use crate::data::Data;
use crate::math::{self, Vec6};
use crate::model::{Model, NONE};

/// Fills `d.cacc` and `d.cfrc` (subtree forces) for joint accelerations `qacc` (`None`: zero).
/// Needs [`crate::kinematics::com_vel`].
fn rne_forces(m: &Model, d: &mut Data, qacc: Option<&[f64]>) {
    let g = m.opt.gravity;
    let base: Vec6 = [0.0, 0.0, 0.0, -g[0], -g[1], -g[2]];
    let nb = m.bodies.len();
    for b in 1..nb {
        let body = &m.bodies[b];
        if body.tree == NONE {
            continue;
        }
        let p = body.parent;
        let mut a = if m.bodies[p].tree == body.tree { d.cacc[p] } else { base };
        for i in body.dof_adr..body.dof_adr + body.dof_num {
            let qv = d.qvel[i];
            let qa = qacc.map_or(0.0, |q| q[i]);
            for r in 0..6 {
                a[r] += d.cdof_dot[i][r] * qv + d.cdof[i][r] * qa;
            }
        }
        d.cacc[b] = a;
        let ci = &d.cinert[b];
        let h = ci.mul(&d.cvel[b]);
        let ia = ci.mul(&a);
        let vxh = math::cross_force(&d.cvel[b], &h);
        let mut f = [0.0; 6];
        for r in 0..6 {
            f[r] = ia[r] + vxh[r];
        }
        d.cfrc[b] = f;
    }
    for b in (1..nb).rev() {
        let p = m.bodies[b].parent;
        if m.bodies[b].tree != NONE && p != 0 && m.bodies[p].tree != NONE {
            let f = d.cfrc[b];
            for r in 0..6 {
                d.cfrc[p][r] += f[r];
            }
        }
    }
}

/// Bias forces `c(q, qdot)` into `d.qfrc_bias`. Needs [`crate::kinematics::com_vel`].
pub fn bias(m: &Model, d: &mut Data) {
    rne_forces(m, d, None);
    for i in 0..m.nv {
        d.qfrc_bias[i] = math::dot6(&d.cdof[i], &d.cfrc[m.dof_body[i]]);
    }
}

/// Inverse dynamics: the generalised force `M(q) qacc + c(q, qdot)` (armature included) that
/// produces `qacc` at the current `qpos`, `qvel` without constraints, damping or actuators.
/// Runs the kinematics itself.
pub fn inverse_dynamics(m: &Model, d: &mut Data, qacc: &[f64]) -> Vec<f64> {
    assert_eq!(qacc.len(), m.nv, "qacc length must be nv");
    crate::kinematics::kinematics(m, d);
    crate::kinematics::com_pos(m, d);
    crate::kinematics::com_vel(m, d);
    rne_forces(m, d, Some(qacc));
    (0..m.nv).map(|i| math::dot6(&d.cdof[i], &d.cfrc[m.dof_body[i]]) + m.dof_armature[i] * qacc[i]).collect()
}
