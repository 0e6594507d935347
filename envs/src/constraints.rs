//! Joint limits and contacts as soft constraints, MuJoCo style (MuJoCo documentation,
//! "Computation": soft constraints, solref/solimp), solved by projected Gauss-Seidel.
//!
//! Every constraint has Jacobian rows `J_k` and forces `f_k`:
//! - a joint limit: one row `J = +-e_dof`, signed distance `r` into the allowed range (negative
//!   when violated), force `f >= 0`;
//! - a contact with friction coefficient `mu`: three rows, the normal `n` (distance `r`,
//!   `f_n >= 0`) and two tangents `t1`, `t2` whose forces lie in the friction disc
//!   `|f_t| <= mu f_n` (an elliptic cone, as MuJoCo's `cone="elliptic"`). Unlike a pyramid,
//!   this keeps sliding from coupling into the normal direction (the pyramid's facet rows would
//!   push a sliding body off the ground in proportion to its speed).
//!
//! As in MuJoCo, the forces are found from the dynamics with the mass matrix `M` alone: with
//! the unconstrained acceleration `a0 = J M^-1 f` (`f` the smooth force) and `A = J M^-1 J^T`,
//! the forces solve the regularised problem `(A + R) f + a0 - aref` complementary to the cone, where
//! - `aref = -b (J v) - k imp(r) r` (normal and limit rows) or `-b (J v)` (friction rows) is
//!   the reference acceleration of a critically damped spring-damper with time constant
//!   `tau = max(solref[0], 2 h)` and damping ratio `zeta = solref[1]`:
//!   `b = 2 / (dmax tau)`, `k = 1 / (dmax^2 tau^2 zeta^2)`;
//! - `imp(r)` is MuJoCo's impedance, rising from `dmin` to `dmax` as `|r|` grows to `width`;
//! - `R_k = (1 - imp) / imp * w_k` makes the constraint soft, with `w_k = A_kk` for contact
//!   normals, the mean of the two tangent diagonal entries for both friction rows (so that the
//!   response does not depend on the orientation of the tangent frame) and MuJoCo's constant
//!   `dof_invweight0` for limits: at rest a row carrying force `f` sits
//!   at depth `r = -R f / (k imp)`, which is what the settling tests predict.
//!
//! Projected (block) Gauss-Seidel, `Options::iterations` sweeps: a limit or normal row
//! `f <- max(0, f - res / (A_kk + R_k))`; the two friction rows of a contact together,
//! `f_t <- f_t - (A_tt + R_t)^-1 res_t`, then scaled back into the disc of radius `mu f_n`.
//! Warm-started from the previous step's forces of the same contact slot (a slot is a fixed
//! geom pair and end point), which makes a few sweeps enough; the friction force is kept as a
//! world vector, so that nothing depends on how the tangent frame (built from world axes) is
//! oriented, and a scene rotated about the vertical follows the rotated trajectory.
//! The result is `d.qfrc_constraint = J^T lambda`; the integrator then applies its implicit
//! damping as MuJoCo's Euler does: `qacc = (M + h D)^-1 (f + J^T lambda)`.

#![allow(clippy::needless_range_loop)] // index loops mirror the formulas (RBDA notation)
#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > 0.0)` deliberately rejects NaN too

use crate::crba::ltdl_half_solve;
use crate::data::{Contact, Data};
use crate::math::{self, Vec3, Vec6};
use crate::model::{JointKind, Model, NONE};

/// Dot product with four partial sums (independent of threads: a fixed order).
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        s[0] += x[0] * y[0];
        s[1] += x[1] * y[1];
        s[2] += x[2] * y[2];
        s[3] += x[3] * y[3];
    }
    let mut t = (s[0] + s[1]) + (s[2] + s[3]);
    for (x, y) in ra.iter().zip(rb) {
        t += x * y;
    }
    t
}

/// Forgets the warm starts of the slots used last step (only those are non-zero), so that a
/// slot without contact this step starts from zero next time.
fn clear_warm(warm: &mut [[f64; 4]], used: &mut Vec<usize>) {
    for &s in used.iter() {
        warm[s] = [0.0; 4];
    }
    used.clear();
}

/// MuJoCo's impedance `imp(r)` for `solimp = [dmin, dmax, width, mid, power]`.
#[inline]
pub fn impedance(solimp: &[f64; 5], r: f64) -> f64 {
    let [dmin, dmax, width, mid, power] = *solimp;
    let x = r.abs() / width;
    if x >= 1.0 {
        return dmax;
    }
    // power = 2 (MuJoCo's default) without the libm call.
    let pw = |b: f64, p: f64| {
        if p == 2.0 {
            b * b
        } else if p == 1.0 {
            b
        } else {
            b.powf(p)
        }
    };
    let y = if x <= mid {
        pw(x, power) / pw(mid, power - 1.0)
    } else {
        1.0 - pw(1.0 - x, power) / pw(1.0 - mid, power - 1.0)
    };
    dmin + y * (dmax - dmin)
}

/// Adds `s * e . v(x)` over the dofs moving `body` to row `row` (length nv), where `v(x)` is
/// the velocity of the body point at world position `x` per unit dof velocity.
#[inline]
#[allow(clippy::too_many_arguments)] // a hot kernel: plain slices, no packing
fn add_point_jacobian(
    m: &Model,
    tree_ref: &[Vec3],
    cdof: &[Vec6],
    body: usize,
    x: Vec3,
    e: &[Vec3; 3],
    s: f64,
    rows: &mut [f64],
) {
    let nv = m.nv;
    let last = m.body_last_dof[body];
    if last == NONE {
        return;
    }
    let r = math::sub(x, tree_ref[m.bodies[body].tree]);
    let rxe = [math::cross(r, e[0]), math::cross(r, e[1]), math::cross(r, e[2])];
    let a = m.dof_chain_adr[last];
    for &i in &m.dof_chain[a..a + m.dof_depth[last]] {
        let c = &cdof[i];
        let w = [c[0], c[1], c[2]];
        let l = [c[3], c[4], c[5]];
        for k in 0..3 {
            rows[k * nv + i] += s * (math::dot(e[k], l) + math::dot(rxe[k], w));
        }
    }
}

/// Tangent directions of a contact with unit normal `n` (for the z normal: x and y).
#[inline]
fn tangents(n: Vec3) -> (Vec3, Vec3) {
    let a = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let t1 = math::normalize(math::add_scaled(a, n, -math::dot(a, n))).unwrap_or([0.0, 1.0, 0.0]);
    (t1, math::cross(n, t1))
}

/// Constraint rows of one step (MuJoCo's `efc_*` arrays; scratch whose capacities persist).
/// Rows are the active joint limits first, then three per contact (normal, two tangents).
#[derive(Clone, Debug, Default)]
pub(crate) struct Efc {
    /// Number of rows.
    pub n: usize,
    /// Number of joint-limit rows (the first `nlim`).
    pub nlim: usize,
    /// Joint of each limit row (`nlim` entries): where its force is kept for the warm start.
    pub limit_joint: Vec<usize>,
    /// Jacobian rows, `n x nv`.
    pub j: Vec<f64>,
    /// `W = J L^-1` (with `M = L^T D L`), row per constraint (`n x nv`).
    pub y: Vec<f64>,
    /// `1 / D`.
    pub dinv: Vec<f64>,
    /// An nv scratch vector.
    pub wd: Vec<f64>,
    /// Support `[lo, hi)` of each Jacobian row.
    pub span: Vec<(usize, usize)>,
    /// Rows coupled to each row (overlapping supports), concatenated; empty when all are.
    pub nbr: Vec<u32>,
    /// Start of each row's list in `nbr` (n + 1 entries).
    pub nbr_adr: Vec<usize>,
    /// `A = J M^-1 J^T`, `n x n`.
    pub a: Vec<f64>,
    /// Reference acceleration `aref`.
    pub aref: Vec<f64>,
    /// Signed distance `r` of each row (limits and normals; 0 for friction rows), then, from
    /// [`references`] on, the regulariser `R`.
    pub r: Vec<f64>,
    /// Unconstrained acceleration in constraint space, `J M^-1 f`.
    pub a0: Vec<f64>,
    /// Force.
    pub f: Vec<f64>,
}

impl Efc {
    /// Bytes its buffers hold (their capacities), for memory estimates.
    pub(crate) fn heap_bytes(&self) -> usize {
        use std::mem::size_of_val;
        let f64s = [&self.j, &self.y, &self.dinv, &self.wd, &self.a, &self.aref, &self.r, &self.a0, &self.f];
        f64s.iter().map(|v| v.capacity() * 8).sum::<usize>()
            + self.limit_joint.capacity() * size_of_val(&0usize)
            + self.span.capacity() * size_of_val(&(0usize, 0usize))
            + self.nbr.capacity() * 4
            + self.nbr_adr.capacity() * size_of_val(&0usize)
    }
}

/// Assembles and solves the constraints of the current state into `d.qfrc_constraint`, in
/// MuJoCo's stages. Needs the kinematics, `cdof`, the factor of `M` (`d.qlm`),
/// `d.qacc_smooth` and `d.contacts`.
pub fn solve(m: &Model, d: &mut Data) {
    d.qfrc_constraint.iter_mut().for_each(|x| *x = 0.0);
    let nlim = count_limit_rows(m, d);
    let n = nlim + 3 * d.contacts.len();
    if n == 0 {
        d.efc.n = 0;
        forget_warm_starts(d);
        return;
    }
    // The rows are the solver's own scratch: taken out of `d` (an empty `Efc` does not
    // allocate) so that the stages can read the rest of `d` while writing them.
    let mut efc = std::mem::take(&mut d.efc);
    make_rows(m, d, nlim, &mut efc);
    project(m, d, &mut efc);
    references(m, d, &mut efc);
    pgs(m, &d.contacts, &mut efc);
    d.efc = efc;
    apply(d);
}

/// Counts the active joint-limit rows: limited hinges outside their range (none when limits
/// are disabled). Reads `d.qpos`.
fn count_limit_rows(m: &Model, d: &Data) -> usize {
    if m.opt.disable_limit || m.nlimited == 0 {
        return 0;
    }
    m.joints
        .iter()
        .filter(|j| j.limited && j.kind == JointKind::Hinge)
        .filter(|j| {
            let q = d.qpos[j.qpos_adr];
            q < j.range[0] || q > j.range[1]
        })
        .count()
}

/// Rows (MuJoCo's `mj_makeConstraint`): reads `d.qpos` (limits), `d.contacts`, the
/// kinematics (`d.tree_ref`, `d.cdof`) and the warm starts; sizes every row array and writes
/// the Jacobian rows `j`, the distances into `r`, the warm-start forces `f` and each limit
/// row's joint.
fn make_rows(m: &Model, d: &Data, nlim: usize, efc: &mut Efc) {
    let nv = m.nv;
    let n = nlim + 3 * d.contacts.len();
    efc.n = n;
    efc.nlim = nlim;
    let resize = |v: &mut Vec<f64>, len: usize| {
        v.clear();
        v.resize(len, 0.0);
    };
    resize(&mut efc.j, n * nv);
    resize(&mut efc.y, n * nv);
    resize(&mut efc.a, n * n);
    resize(&mut efc.aref, n);
    resize(&mut efc.r, n);
    resize(&mut efc.a0, n);
    resize(&mut efc.f, n);
    resize(&mut efc.dinv, nv);
    resize(&mut efc.wd, nv);
    efc.limit_joint.clear();
    let mut row = 0;
    if nlim > 0 {
        for (ji, j) in m.joints.iter().enumerate() {
            if !(j.limited && j.kind == JointKind::Hinge) {
                continue;
            }
            let q = d.qpos[j.qpos_adr];
            let (dist, s) = if q < j.range[0] {
                (q - j.range[0], 1.0)
            } else if q > j.range[1] {
                (j.range[1] - q, -1.0)
            } else {
                continue;
            };
            efc.j[row * nv + j.dof_adr] = s;
            efc.r[row] = dist;
            efc.f[row] = d.warm_limit[ji];
            efc.limit_joint.push(ji);
            row += 1;
        }
    }
    for c in &d.contacts {
        let (t1, t2) = tangents(c.normal);
        let e = [c.normal, t1, t2];
        let b1 = m.geoms[c.geom1].body;
        let b2 = m.geoms[c.geom2].body;
        let rows = &mut efc.j[row * nv..(row + 3) * nv];
        add_point_jacobian(m, &d.tree_ref, &d.cdof, b2, c.pos, &e, 1.0, rows);
        add_point_jacobian(m, &d.tree_ref, &d.cdof, b1, c.pos, &e, -1.0, rows);
        // Warm start: the slot keeps the normal force and the friction force as a world
        // vector, projected on this step's tangent frame (so the frame's orientation, which
        // follows world axes, does not matter).
        let w = d.warm[c.slot];
        let ft = [w[1], w[2], w[3]];
        let warm = [w[0], math::dot(ft, t1), math::dot(ft, t2)];
        for k in 0..3 {
            efc.r[row + k] = if k == 0 { c.dist } else { 0.0 };
            efc.f[row + k] = warm[k];
        }
        row += 3;
    }
    debug_assert_eq!(row, n);
}

/// Projection (MuJoCo's `mj_projectConstraint`): reads the rows `j` and the factor of `M`
/// (`d.qlm`); writes each row's support `span`, `W = J L^-1` (`y`) and `A = J M^-1 J^T`.
///
/// With `M = L^T D L`: `A = W D^-1 W^T`, `W = J L^-1` (rows: `L^T w = J_k^T`). A Jacobian
/// row lives on one or two DoF chains and so does its `w` (the half solve only moves entries
/// to ancestors): cheap, and one full solve with `J^T f` at the end replaces a solve per row.
/// Each row's support `[lo, hi)` holds its Jacobian and its `W` (from the first DoF of the
/// trees it touches to its last non-zero). Rows of different agents do not overlap: their
/// `A` entries are zero without a dot product.
fn project(m: &Model, d: &Data, efc: &mut Efc) {
    let (n, nv) = (efc.n, m.nv);
    efc.y.copy_from_slice(&efc.j);
    efc.span.clear();
    for k in 0..n {
        let row = &efc.j[k * nv..(k + 1) * nv];
        // W fills ancestors of the non-zeros (down to their tree's first dof), never later dofs.
        let root = |i: usize| m.dof_chain[m.dof_chain_adr[i] + m.dof_depth[i] - 1];
        let lo = row.iter().enumerate().filter(|(_, x)| **x != 0.0).map(|(i, _)| root(i)).min().unwrap_or(0);
        let hi = row.iter().rposition(|&x| x != 0.0).map_or(0, |i| i + 1);
        efc.span.push((lo, hi.max(lo)));
        ltdl_half_solve(m, &d.qlm, &mut efc.y[k * nv..(k + 1) * nv]);
    }
    for i in 0..nv {
        efc.dinv[i] = 1.0 / crate::crba::diag(m, &d.qlm, i);
    }
    for k in 0..n {
        let (lk, hk) = efc.span[k];
        for ((w, y), di) in efc.wd[lk..hk].iter_mut().zip(&efc.y[k * nv + lk..k * nv + hk]).zip(&efc.dinv[lk..hk]) {
            *w = y * di;
        }
        for l in 0..=k {
            let (ll, hl) = efc.span[l];
            let (a, b) = (lk.max(ll), hk.min(hl));
            let s = if a < b { dot(&efc.wd[a..b], &efc.y[l * nv + a..l * nv + b]) } else { 0.0 };
            efc.a[k * n + l] = s;
            efc.a[l * n + k] = s;
        }
    }
}

/// References and regularisation (MuJoCo's `mj_referenceConstraint`; module docs for the
/// formulas): reads the rows, their distances in `r`, `A`, `d.qvel`, `d.qacc_smooth` and the
/// contacts' distances; writes `a0 = J qacc_smooth`, `aref`, the regulariser `R` (over the
/// distances in `r`) and clears warm-start forces outside the cone (negative normal forces,
/// non-finite friction forces).
fn references(m: &Model, d: &Data, efc: &mut Efc) {
    let (n, nv, nlim) = (efc.n, m.nv, efc.nlim);
    let [tc, zeta] = m.opt.solref;
    let dmax = m.opt.solimp[1];
    let tau = tc.max(2.0 * m.opt.timestep);
    let bb = 2.0 / (dmax * tau);
    let kk = 1.0 / (dmax * dmax * tau * tau * zeta * zeta);
    for k in 0..n {
        let (lk, hk) = efc.span[k];
        let jk = &efc.j[k * nv + lk..k * nv + hk];
        let vel = dot(jk, &d.qvel[lk..hk]);
        efc.a0[k] = dot(jk, &d.qacc_smooth[lk..hk]);
        if k < nlim || (k - nlim) % 3 == 0 {
            // Limit or normal row: spring-damper on the distance.
            let dist = efc.r[k];
            let imp = impedance(&m.opt.solimp, dist);
            efc.aref[k] = -bb * vel - kk * imp * dist;
            // Limits: MuJoCo's constant dof_invweight0; contacts: the exact diagonal of A.
            let w = if k < nlim { m.dof_invweight0[m.joints[efc.limit_joint[k]].dof_adr] } else { efc.a[k * n + k] };
            efc.r[k] = (1.0 - imp) / imp * w;
            if !(efc.f[k] >= 0.0) {
                efc.f[k] = 0.0;
            }
        } else {
            // Friction row: damper only, with the impedance of its contact's normal row.
            let kn = k - (k - nlim) % 3;
            let imp = impedance(&m.opt.solimp, d.contacts[(kn - nlim) / 3].dist);
            efc.aref[k] = -bb * vel;
            // The same regulariser for both tangents (mean of their diagonal entries): a
            // choice independent of how the tangent frame is oriented, so that the contact
            // responds the same in any rotated copy of a scene.
            let (t1, t2) = (kn + 1, kn + 2);
            let w = 0.5 * (efc.a[t1 * n + t1] + efc.a[t2 * n + t2]);
            efc.r[k] = (1.0 - imp) / imp * w;
            if !efc.f[k].is_finite() {
                efc.f[k] = 0.0;
            }
        }
    }
}

/// Projected (block) Gauss-Seidel, `Options::iterations` sweeps: reads `A`, `R`, `a0`,
/// `aref`, the spans and the contacts' friction coefficients; writes the coupling lists
/// (`nbr`) and the forces `f`, starting from the warm starts.
///
/// Rows coupled to each row (overlapping supports): all rows for one agent, only its own
/// agent's (and cross-agent contacts') rows in a multi-agent scene, so a sweep costs the sum
/// over agents of their rows squared rather than the square of all rows. (With a single tree
/// every row reaches its root dofs: all rows are coupled.)
fn pgs(m: &Model, contacts: &[Contact], efc: &mut Efc) {
    let (n, nlim) = (efc.n, efc.nlim);
    let all_coupled = m.trees.len() <= 1;
    efc.nbr.clear();
    efc.nbr_adr.clear();
    if !all_coupled {
        for k in 0..n {
            efc.nbr_adr.push(efc.nbr.len());
            let (lk, hk) = efc.span[k];
            for l in 0..n {
                let (ll, hl) = efc.span[l];
                if lk.max(ll) < hk.min(hl) {
                    efc.nbr.push(l as u32);
                }
            }
        }
        efc.nbr_adr.push(efc.nbr.len());
    }
    for _ in 0..m.opt.iterations {
        for k in 0..nlim {
            let diag = efc.a[k * n + k] + efc.r[k];
            if diag > 0.0 {
                let g = residual(efc, all_coupled, k);
                efc.f[k] = (efc.f[k] - g / diag).max(0.0);
            }
        }
        for (ci, c) in contacts.iter().enumerate() {
            let k = nlim + 3 * ci;
            let diag = efc.a[k * n + k] + efc.r[k];
            if diag > 0.0 {
                let g = residual(efc, all_coupled, k);
                efc.f[k] = (efc.f[k] - g / diag).max(0.0);
            }
            let fmax = c.friction * efc.f[k];
            if fmax <= 0.0 {
                efc.f[k + 1] = 0.0;
                efc.f[k + 2] = 0.0;
                continue;
            }
            // 2x2 block solve for the tangential forces, then projection onto the disc.
            let (g1, g2) = (residual(efc, all_coupled, k + 1), residual(efc, all_coupled, k + 2));
            let a11 = efc.a[(k + 1) * n + k + 1] + efc.r[k + 1];
            let a22 = efc.a[(k + 2) * n + k + 2] + efc.r[k + 2];
            let a12 = efc.a[(k + 1) * n + k + 2];
            let det = a11 * a22 - a12 * a12;
            if !(det > 0.0) {
                continue;
            }
            let mut f1 = efc.f[k + 1] - (a22 * g1 - a12 * g2) / det;
            let mut f2 = efc.f[k + 2] - (a11 * g2 - a12 * g1) / det;
            let ft = (f1 * f1 + f2 * f2).sqrt();
            if ft > fmax {
                f1 *= fmax / ft;
                f2 *= fmax / ft;
            }
            efc.f[k + 1] = f1;
            efc.f[k + 2] = f2;
        }
    }
}

/// Residual of row `k`, `(A + R) f + a0 - aref` (only the coupled rows' terms of `A f`
/// unless `all_coupled`).
#[inline]
fn residual(efc: &Efc, all_coupled: bool, k: usize) -> f64 {
    let n = efc.n;
    let base = efc.a0[k] - efc.aref[k] + efc.r[k] * efc.f[k];
    if all_coupled {
        return base + dot(&efc.a[k * n..(k + 1) * n], &efc.f);
    }
    let row = &efc.a[k * n..(k + 1) * n];
    base + efc.nbr[efc.nbr_adr[k]..efc.nbr_adr[k + 1]].iter().map(|&l| row[l as usize] * efc.f[l as usize]).sum::<f64>()
}

/// Apply (MuJoCo's `mj_constraintUpdate`): reads the forces and rows; writes
/// `d.qfrc_constraint = J^T f` and the warm starts for the next step (limits per joint,
/// contacts per slot with the friction force as a world vector).
fn apply(d: &mut Data) {
    let efc = &d.efc;
    let nv = d.qfrc_constraint.len();
    clear_warm(&mut d.warm, &mut d.warm_used);
    d.warm_limit.iter_mut().for_each(|w| *w = 0.0);
    for k in 0..efc.n {
        let f = efc.f[k];
        if f != 0.0 {
            let (lk, hk) = efc.span[k];
            for (q, j) in d.qfrc_constraint[lk..hk].iter_mut().zip(&efc.j[k * nv + lk..k * nv + hk]) {
                *q += j * f;
            }
        }
    }
    for (k, &ji) in efc.limit_joint.iter().enumerate() {
        d.warm_limit[ji] = efc.f[k];
    }
    for (ci, c) in d.contacts.iter().enumerate() {
        let k = efc.nlim + 3 * ci;
        let (t1, t2) = tangents(c.normal);
        let ft = math::add(math::scale(t1, efc.f[k + 1]), math::scale(t2, efc.f[k + 2]));
        d.warm[c.slot] = [efc.f[k], ft[0], ft[1], ft[2]];
        d.warm_used.push(c.slot);
    }
}

/// No constraint this step: every warm start is forgotten.
fn forget_warm_starts(d: &mut Data) {
    clear_warm(&mut d.warm, &mut d.warm_used);
    d.warm_limit.iter_mut().for_each(|w| *w = 0.0);
}
