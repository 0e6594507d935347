//! Joint-space mass matrix by the composite rigid body algorithm (Featherstone, RBDA §6.2,
//! in the world-frame form MuJoCo's `mj_crb` uses) and its sparse `L^T D L` factorisation
//! exploiting the tree structure (RBDA §6.5, "LTDL": no fill-in when every dof's parent has a
//! smaller index, which body order guarantees).
//!
//! Storage: `nv x nv` row-major; only entries `(i, j)` with `j` on the ancestor chain of `i`
//! (including `i`) are meaningful. For the 14-dof ant that is 70 of 196 entries.

#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > 0.0)` deliberately rejects NaN too

use crate::data::Data;
use crate::model::{Model, ModelError, NONE};

/// Composite inertias and the mass matrix `M(q)` (with joint armature on the diagonal) into
/// `d.qm`. Needs [`crate::kinematics::com_pos`].
pub fn crba(m: &Model, d: &mut Data) {
    let nb = m.bodies.len();
    d.crb[..nb].copy_from_slice(&d.cinert[..nb]);
    for b in (1..nb).rev() {
        let p = m.bodies[b].parent;
        if p != 0 && m.bodies[p].tree != NONE {
            let c = d.crb[b];
            d.crb[p].add_assign(&c);
        }
    }
    let nv = m.nv;
    for i in 0..nv {
        // M_ij = S_j^T Ic_(body of i) S_i for every ancestor dof j of i (RBDA eq. 6.13).
        let f = d.crb[m.dof_body[i]].mul(&d.cdof[i]);
        let row = i * nv;
        let mut j = i;
        while j != NONE {
            d.qm[row + j] = crate::math::dot6(&d.cdof[j], &f);
            j = m.dof_parent[j];
        }
        d.qm[row + i] += m.dof_armature[i];
    }
}

/// Copies the mass matrix pattern into `d.qh`, adds `h * damping` on the diagonal (the
/// implicit-damping matrix of MuJoCo's Euler integrator) and factors it in place.
/// Returns the first dof with a non-positive pivot, if any.
pub fn factor_h(m: &Model, d: &mut Data, h: f64) -> Result<(), usize> {
    let nv = m.nv;
    for i in 0..nv {
        let row = i * nv;
        let mut j = i;
        while j != NONE {
            d.qh[row + j] = d.qm[row + j];
            j = m.dof_parent[j];
        }
        d.qh[row + i] += h * m.dof_damping[i];
    }
    ltdl_factor(m, &mut d.qh)
}

/// In-place `H = L^T D L` (RBDA Table 6.3): afterwards the diagonal holds D and the strict
/// lower tree pattern holds L (unit diagonal implied).
pub fn ltdl_factor(m: &Model, h: &mut [f64]) -> Result<(), usize> {
    let nv = m.nv;
    for k in (0..nv).rev() {
        let dk = h[k * nv + k];
        if !(dk > 0.0) {
            return Err(k);
        }
        let mut i = m.dof_parent[k];
        while i != NONE {
            let a = h[k * nv + i] / dk;
            let mut j = i;
            while j != NONE {
                h[i * nv + j] -= h[k * nv + j] * a;
                j = m.dof_parent[j];
            }
            h[k * nv + i] = a;
            i = m.dof_parent[i];
        }
    }
    Ok(())
}

/// First half of [`ltdl_solve`]: solves `L^T z = b` in place. Entries only move to ancestor
/// dofs, so a right-hand side supported on a few dof chains stays on them (zeros skipped).
pub fn ltdl_half_solve(m: &Model, h: &[f64], x: &mut [f64]) {
    let nv = m.nv;
    for k in (0..nv).rev() {
        let xk = x[k];
        if xk == 0.0 {
            continue;
        }
        let mut i = m.dof_parent[k];
        while i != NONE {
            x[i] -= h[k * nv + i] * xk;
            i = m.dof_parent[i];
        }
    }
}

/// Solves `H x = b` in place (`x` holds `b` on entry) with the factor of [`ltdl_factor`]
/// (RBDA Table 6.4).
pub fn ltdl_solve(m: &Model, h: &[f64], x: &mut [f64]) {
    let nv = m.nv;
    // L^T z = b, from the leaves up.
    for k in (0..nv).rev() {
        let xk = x[k];
        let mut i = m.dof_parent[k];
        while i != NONE {
            x[i] -= h[k * nv + i] * xk;
            i = m.dof_parent[i];
        }
    }
    for k in 0..nv {
        x[k] /= h[k * nv + k];
    }
    // L x = D^-1 z, from the roots down.
    for k in 0..nv {
        let mut s = x[k];
        let mut i = m.dof_parent[k];
        while i != NONE {
            s -= h[k * nv + i] * x[i];
            i = m.dof_parent[i];
        }
        x[k] = s;
    }
}

/// The full symmetric mass matrix (row-major `nv x nv`, zeros between unrelated dofs) of the
/// last [`crba`]; for tests and analysis.
pub fn dense_mass_matrix(m: &Model, d: &Data) -> Vec<f64> {
    let nv = m.nv;
    let mut out = vec![0.0; nv * nv];
    for i in 0..nv {
        let mut j = i;
        while j != NONE {
            out[i * nv + j] = d.qm[i * nv + j];
            out[j * nv + i] = d.qm[i * nv + j];
            j = m.dof_parent[j];
        }
    }
    out
}

/// Build-time constants: checks that the mass matrix at `qpos0` is positive definite and
/// returns the diagonal of `M(qpos0)^-1` (MuJoCo's `dof_invweight0`, used to scale the joint
/// limit regularisers as MuJoCo does).
pub(crate) fn check_positive_definite(m: &Model) -> Result<Vec<f64>, ModelError> {
    let mut d = Data::new(m);
    crate::kinematics::kinematics(m, &mut d);
    crate::kinematics::com_pos(m, &mut d);
    crba(m, &mut d);
    factor_h(m, &mut d, 0.0).map_err(|dof| ModelError::SingularMassMatrix { dof })?;
    // A pivot that is tiny relative to the largest one is numerically singular too.
    let nv = m.nv;
    let max = (0..nv).map(|i| d.qm[i * nv + i]).fold(0.0, f64::max);
    for i in 0..nv {
        if d.qh[i * nv + i] <= 1e-12 * max {
            return Err(ModelError::SingularMassMatrix { dof: i });
        }
    }
    let mut inv = vec![0.0; nv];
    let mut e = vec![0.0; nv];
    for i in 0..nv {
        e.iter_mut().for_each(|x| *x = 0.0);
        e[i] = 1.0;
        ltdl_solve(m, &d.qh, &mut e);
        inv[i] = e[i];
    }
    Ok(inv)
}
