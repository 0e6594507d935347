//! Forward kinematics and the world-frame ("com-based" in MuJoCo's terms) spatial quantities
//! the dynamics use.
//!
//! Conventions (MuJoCo's `mj_kinematics` / `mj_comPos` / `mj_comVel`):
//! - a body's frame is its parent's frame moved by the body's `pos`/`quat`, then by each of its
//!   joints in order: a hinge rotates the frame about `axis` through `anchor` (both in the
//!   frame as moved by the previous joints); a free joint sets the world pose from qpos;
//! - spatial vectors are `[angular; linear]` in world axes about a reference point per tree,
//!   the tree root's origin (keeps lever arms short wherever the agent wanders);
//! - free joint dofs: three world-axis translations of the body origin, then three rotations
//!   about the body's own axes (qvel angular velocity in the body frame).

#![allow(clippy::needless_range_loop)] // index loops mirror the formulas (RBDA notation)

use crate::data::Data;
use crate::math::{self, SpatialInertia};
use crate::model::{JointKind, Model, NONE};

/// Computes body and geom poses, hinge axes/anchors and tree reference points from `qpos`.
pub fn kinematics(m: &Model, d: &mut Data) {
    for b in 1..m.bodies.len() {
        let body = &m.bodies[b];
        let p = body.parent;
        let mut xq = math::quat_mul(d.xquat[p], body.quat);
        let mut xp = math::add(d.xpos[p], math::mat_vec(&d.xmat[p], body.pos));
        for j in body.jnt_adr..body.jnt_adr + body.jnt_num {
            let jnt = &m.joints[j];
            let a = jnt.qpos_adr;
            match jnt.kind {
                JointKind::Free => {
                    xp = [d.qpos[a], d.qpos[a + 1], d.qpos[a + 2]];
                    xq = math::quat_normalize([d.qpos[a + 3], d.qpos[a + 4], d.qpos[a + 5], d.qpos[a + 6]]);
                    d.xanchor[j] = xp;
                    d.xaxis[j] = [0.0, 0.0, 1.0];
                }
                JointKind::Hinge => {
                    let centred = jnt.anchor == [0.0; 3];
                    let anchor = if centred { xp } else { math::add(xp, math::quat_rotate(xq, jnt.anchor)) };
                    d.xaxis[j] = math::quat_rotate(xq, jnt.axis);
                    d.xanchor[j] = anchor;
                    xq = math::quat_mul(xq, math::quat_axis_angle(jnt.axis, d.qpos[a]));
                    if !centred {
                        xp = math::sub(anchor, math::quat_rotate(xq, jnt.anchor));
                    }
                }
            }
        }
        let r = math::quat_to_mat(xq);
        d.xquat[b] = xq;
        d.xpos[b] = xp;
        d.xipos[b] = math::add(xp, math::mat_vec(&r, body.ipos));
        d.xmat[b] = r;
    }
    for (g, geom) in m.geoms.iter().enumerate() {
        let b = geom.body;
        d.geom_xpos[g] = math::add(d.xpos[b], math::mat_vec(&d.xmat[b], geom.pos));
        // A sphere's orientation is irrelevant to collisions: its geom_xmat is not updated.
        if !matches!(geom.shape, crate::model::Shape::Sphere { .. }) {
            d.geom_xmat[g] = math::mat_mul(&d.xmat[b], &geom.mat);
        }
    }
    for (t, tree) in m.trees.iter().enumerate() {
        d.tree_ref[t] = d.xpos[tree.root];
    }
}

/// Computes body spatial inertias (`cinert`) and dof motion axes (`cdof`) about each tree's
/// reference point. Needs [`kinematics`].
pub fn com_pos(m: &Model, d: &mut Data) {
    for b in 1..m.bodies.len() {
        let body = &m.bodies[b];
        if body.tree == NONE {
            continue;
        }
        let p = d.tree_ref[body.tree];
        let ic = math::rotate_tensor(&d.xmat[b], &body.inertia);
        d.cinert[b] = SpatialInertia::from_com(body.mass, math::sub(d.xipos[b], p), &ic);
        for j in body.jnt_adr..body.jnt_adr + body.jnt_num {
            let jnt = &m.joints[j];
            let v = jnt.dof_adr;
            match jnt.kind {
                JointKind::Free => {
                    let off = math::sub(p, d.xanchor[j]);
                    for k in 0..3 {
                        let mut t = [0.0; 6];
                        t[3 + k] = 1.0;
                        d.cdof[v + k] = t;
                        // Column k of the body rotation: body axis k in world axes.
                        let w = [d.xmat[b][0][k], d.xmat[b][1][k], d.xmat[b][2][k]];
                        let l = math::cross(w, off);
                        d.cdof[v + 3 + k] = [w[0], w[1], w[2], l[0], l[1], l[2]];
                    }
                }
                JointKind::Hinge => {
                    let w = d.xaxis[j];
                    let l = math::cross(w, math::sub(p, d.xanchor[j]));
                    d.cdof[v] = [w[0], w[1], w[2], l[0], l[1], l[2]];
                }
            }
        }
    }
}

/// Computes body spatial velocities (`cvel`) and `cdof_dot` (MuJoCo's `mj_comVel`): a dof axis
/// fixed in the frame moving with velocity `v` changes at `v x cdof` (RBDA eq. 2.31), where
/// `v` is the velocity of the body before that dof's own motion. For a free joint the
/// translations are constant and the rotations move with the translated frame. Needs
/// [`com_pos`].
pub fn com_vel(m: &Model, d: &mut Data) {
    for b in 1..m.bodies.len() {
        let body = &m.bodies[b];
        if body.tree == NONE {
            d.cvel[b] = [0.0; 6];
            continue;
        }
        let p = body.parent;
        let mut v = if m.bodies[p].tree == body.tree { d.cvel[p] } else { [0.0; 6] };
        for j in body.jnt_adr..body.jnt_adr + body.jnt_num {
            let jnt = &m.joints[j];
            let a = jnt.dof_adr;
            match jnt.kind {
                JointKind::Free => {
                    for k in 0..3 {
                        d.cdof_dot[a + k] = [0.0; 6];
                        v[3 + k] += d.qvel[a + k];
                    }
                    for k in 3..6 {
                        d.cdof_dot[a + k] = math::cross_motion(&v, &d.cdof[a + k]);
                    }
                    for k in 3..6 {
                        let q = d.qvel[a + k];
                        for r in 0..6 {
                            v[r] += d.cdof[a + k][r] * q;
                        }
                    }
                }
                JointKind::Hinge => {
                    d.cdof_dot[a] = math::cross_motion(&v, &d.cdof[a]);
                    let q = d.qvel[a];
                    for r in 0..6 {
                        v[r] += d.cdof[a][r] * q;
                    }
                }
            }
        }
        d.cvel[b] = v;
    }
}
