//! The integrators: MuJoCo's semi-implicit Euler with implicit joint damping (MuJoCo
//! documentation, "Computation: numerical integration"; `mj_Euler`, `mj_integratePos`), its
//! `EulerGyro` variant and the implicit integrator.
//!
//! [`step`] = [`crate::forward::forward`] (the named stages, ending with the Euler
//! `qacc = H^-1 (f + J^T lambda)` and this module's [`integrator_qacc`]) then [`integrate`]:
//! `qvel <- qvel + h qacc` and positions integrated with the new velocity: hinges
//! `q += h qdot`; free joints `p += h v` (world frame) and
//! `quat <- normalize(quat * exp(h w / 2))` with `w` in the body frame.
//!
//! This is exactly MuJoCo's `mj_Euler` when any dof has damping: it solves
//! `(M + h D) qacc = f(q, v)` where `f` contains `-D v`, so `v' = v + h qacc` satisfies
//! `M (v' - v) / h = tau - c - D v'` (damping evaluated at the new velocity).

use crate::data::Data;
use crate::forward::forward;
use crate::math;
use crate::model::{Integrator, JointKind, Model};
use crate::{crba, kinematics, rne};

/// The integrator's own acceleration, once [`crate::forward::forward`]'s stages have found
/// the Euler `qacc = H^-1 (f + J^T lambda)`: unchanged for [`Integrator::Euler`], corrected for
/// the root spins' gyroscopic forces ([`Integrator::EulerGyro`]) or by the velocity
/// derivative of all the bias forces ([`Integrator::Implicit`]).
pub fn integrator_qacc(m: &Model, d: &mut Data) {
    match m.opt.integrator {
        Integrator::Implicit => implicit_qacc(m, d),
        Integrator::EulerGyro => root_gyro_qacc(m, d),
        _ => {}
    }
}

/// Columns of `dc/dqvel` for the three angular dofs of every floating root, into `cols`
/// (`3 nv`, column `k` at `k nv..(k + 1) nv`; rows of trees without a floating root are zero).
/// Needs the velocities and bias of the current state ([`crate::forward::velocity`]).
///
/// Forward-mode derivative of the Newton-Euler bias pass ([`rne::bias`]) in the direction
/// `e_k` of the root's angular dof `k`, whose motion axis `s_k = cdof[root + 3 + k]` is the same
/// for every body of the tree (the hinges' velocities are held fixed). With `v_b` the velocity
/// of body `b` and `v_r` the root's, the bias pass computes `f_b = I_b a_b + v_b x* I_b v_b`
/// with `a_b = a_r + sum cdof_dot_i qvel_i` over the hinges `i` between the root and `b`, and
/// `cdof_dot_i = v x cdof_i`; so, exactly (the bias is quadratic in `qvel`):
/// `da_b = cdof_dot[root + 3 + k] + s_k x (v_b - v_r)`,
/// `df_b = I_b da_b + s_k x* I_b v_b + v_b x* I_b s_k`,
/// and `dc_i = cdof_i . sum(df)` over the subtree of dof `i`'s body: one pass over the bodies
/// for the three columns.
pub fn root_spin_bias_derivative(m: &Model, d: &mut Data, cols: &mut [f64]) {
    let nv = m.nv;
    assert_eq!(cols.len(), 3 * nv, "cols must hold 3 nv entries");
    let nb = m.bodies.len();
    for b in 1..nb {
        let body = &m.bodies[b];
        d.qk_tan[b] = [[0.0; 6]; 3];
        if body.tree == crate::model::NONE {
            continue;
        }
        let root = m.trees[body.tree].root;
        let rb = &m.bodies[root];
        if rb.jnt_num != 1 || m.joints[rb.jnt_adr].kind != JointKind::Free {
            continue;
        }
        let a = rb.dof_adr + 3;
        let (vb, vr) = (&d.cvel[b], &d.cvel[root]);
        let rel = [vb[0] - vr[0], vb[1] - vr[1], vb[2] - vr[2], vb[3] - vr[3], vb[4] - vr[4], vb[5] - vr[5]];
        let ib = &d.cinert[b];
        let hb = ib.mul(vb);
        for k in 0..3 {
            let sk = &d.cdof[a + k];
            let mut da = math::cross_motion(sk, &rel);
            for (x, y) in da.iter_mut().zip(&d.cdof_dot[a + k]) {
                *x += y;
            }
            let t1 = ib.mul(&da);
            let t2 = math::cross_force(sk, &hb);
            let t3 = math::cross_force(vb, &ib.mul(sk));
            for r in 0..6 {
                d.qk_tan[b][k][r] = t1[r] + t2[r] + t3[r];
            }
        }
    }
    for b in (1..nb).rev() {
        let p = m.bodies[b].parent;
        if m.bodies[b].tree != crate::model::NONE && p != 0 && m.bodies[p].tree != crate::model::NONE {
            let f = d.qk_tan[b];
            for (dst, src) in d.qk_tan[p].iter_mut().zip(&f) {
                for (x, y) in dst.iter_mut().zip(src) {
                    *x += y;
                }
            }
        }
    }
    for i in 0..nv {
        let f = &d.qk_tan[m.dof_body[i]];
        for k in 0..3 {
            cols[k * nv + i] = math::dot6(&d.cdof[i], &f[k]);
        }
    }
}

/// [`Integrator::EulerGyro`]: corrects the Euler `qacc = H^-1 b` to `(H + h K E E^T)^-1 b`,
/// where `E` selects the three angular dofs of each floating root and `K E` are the exact
/// columns of `K = dc/dqvel` for those dofs, all rows of the tree
/// ([`root_spin_bias_derivative`]). Woodbury: `x = y - Z (I + E^T Z)^-1 (E^T y)` with
/// `y = H^-1 b` and `Z = H^-1 h K E`; trees are independent (H is block diagonal over trees,
/// so one solve per column serves every tree).
fn root_gyro_qacc(m: &Model, d: &mut Data) {
    let nv = m.nv;
    let h = m.opt.timestep;
    let is_free_root = |t: &crate::model::Tree| {
        let body = &m.bodies[t.root];
        body.jnt_num == 1 && m.joints[body.jnt_adr].kind == JointKind::Free
    };
    if !m.trees.iter().any(is_free_root) {
        return;
    }
    let damped = m.dof_damping.iter().any(|&x| x > 0.0);
    let mut cols = std::mem::take(&mut d.qk_cols);
    root_spin_bias_derivative(m, d, &mut cols);
    d.qk_cols = cols;
    d.qk_cols.iter_mut().for_each(|x| *x *= h);
    let factor = if damped { &d.qh } else { &d.qlm };
    crba::ltdl_solve3(m, factor, &mut d.qk_cols);
    for tree in m.trees.iter().filter(|t| is_free_root(t)) {
        let a = m.bodies[tree.root].dof_adr + 3;
        let mut g = [[0.0; 3]; 3];
        for (i, row) in g.iter_mut().enumerate() {
            for (k, x) in row.iter_mut().enumerate() {
                *x = d.qk_cols[k * nv + a + i] + if i == k { 1.0 } else { 0.0 };
            }
        }
        let ey = [d.qacc[a], d.qacc[a + 1], d.qacc[a + 2]];
        let Some(t) = solve3(&g, ey) else { continue };
        for &b in &tree.bodies {
            let body = &m.bodies[b];
            for i in body.dof_adr..body.dof_adr + body.dof_num {
                d.qacc[i] -= d.qk_cols[i] * t[0] + d.qk_cols[nv + i] * t[1] + d.qk_cols[2 * nv + i] * t[2];
            }
        }
    }
}

/// Solves a 3 x 3 system by Cramer's rule; `None` when (numerically) singular.
fn solve3(a: &math::Mat3, b: math::Vec3) -> Option<math::Vec3> {
    let det = math::dot(a[0], math::cross(a[1], a[2]));
    if det.is_nan() || det.abs() <= 1e-300 || det.is_infinite() {
        return None;
    }
    // Columns of a: replace one at a time by b.
    let col = |j: usize| [a[0][j], a[1][j], a[2][j]];
    let (c0, c1, c2) = (col(0), col(1), col(2));
    let d3 = |x: math::Vec3, y: math::Vec3, z: math::Vec3| math::dot(x, math::cross(y, z));
    let dc = d3(c0, c1, c2);
    Some([d3(b, c1, c2) / dc, d3(c0, b, c2) / dc, d3(c0, c1, b) / dc])
}

/// MuJoCo's `implicit` integrator: `qacc = (M + h D + h K)^-1 (f + qfrc_constraint)` with
/// `K = dc/dqvel` (backward Euler linearised in the velocity-dependent forces). The bias `c` is
/// quadratic in `qvel` plus a constant, so the central difference
/// `K e_i = (c(v + e_i) - c(v - e_i)) / 2` is exact up to round-off. The constraint forces are
/// those found with `M + h D`, as MuJoCo does.
fn implicit_qacc(m: &Model, d: &mut Data) {
    let nv = m.nv;
    let h = m.opt.timestep;
    if d.qk.len() != nv * nv {
        d.qk.resize(nv * nv, 0.0);
    }
    for i in 0..nv {
        let v0 = d.qvel[i];
        for (k, s) in [(0, 1.0), (1, -1.0)] {
            d.qvel[i] = v0 + s;
            kinematics::com_vel(m, d);
            rne::bias(m, d);
            d.qtmp[k * nv..(k + 1) * nv].copy_from_slice(&d.qfrc_bias);
        }
        d.qvel[i] = v0;
        for r in 0..nv {
            d.qk[r * nv + i] = h * 0.5 * (d.qtmp[r] - d.qtmp[nv + r]);
        }
    }
    kinematics::com_vel(m, d);
    rne::bias(m, d);
    let qk = &mut d.qk;
    crba::for_each_entry(m, &d.qm, |i, j, mij| {
        qk[i * nv + j] += mij;
        if j != i {
            qk[j * nv + i] += mij;
        }
    });
    for i in 0..nv {
        d.qk[i * nv + i] += h * m.dof_damping[i];
    }
    for i in 0..nv {
        d.qacc[i] = d.qfrc_actuator[i] + d.qfrc_applied[i] + d.qfrc_passive[i] - d.qfrc_bias[i] + d.qfrc_constraint[i];
    }
    lu_factor(nv, &mut d.qk, &mut d.qk_piv);
    lu_solve(nv, &d.qk, &d.qk_piv, &mut d.qacc);
}

/// In-place LU factorisation with partial pivoting (Golub & Van Loan, Alg. 3.4.1).
fn lu_factor(n: usize, a: &mut [f64], piv: &mut [usize]) {
    for k in 0..n {
        let mut p = k;
        for i in k + 1..n {
            if a[i * n + k].abs() > a[p * n + k].abs() {
                p = i;
            }
        }
        piv[k] = p;
        if p != k {
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
        }
        let pivot = a[k * n + k];
        if pivot == 0.0 {
            continue;
        }
        for i in k + 1..n {
            let l = a[i * n + k] / pivot;
            a[i * n + k] = l;
            for j in k + 1..n {
                a[i * n + j] -= l * a[k * n + j];
            }
        }
    }
}

/// Solves with the factorisation of [`lu_factor`] in place.
fn lu_solve(n: usize, a: &[f64], piv: &[usize], x: &mut [f64]) {
    for (k, &p) in piv.iter().enumerate().take(n) {
        x.swap(k, p);
    }
    for i in 0..n {
        for j in 0..i {
            x[i] -= a[i * n + j] * x[j];
        }
    }
    for i in (0..n).rev() {
        for j in i + 1..n {
            x[i] -= a[i * n + j] * x[j];
        }
        x[i] /= a[i * n + i];
    }
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

/// Advances the state by one time step: [`forward`] then [`integrate`]. As in MuJoCo, the
/// derived quantities in `Data` (body poses, contacts, `qacc`) then describe the state at the
/// start of the step; call [`crate::kinematics::kinematics`] (poses) or [`forward`] (all) to
/// bring them up to date with the new `qpos`/`qvel`.
pub fn step(m: &Model, d: &mut Data) {
    forward(m, d);
    integrate(m, d);
}
