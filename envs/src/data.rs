//! The per-environment state (MuJoCo's `mjData`): the state proper (`time`, `qpos`, `qvel`,
//! `ctrl`, contact warm starts) plus scratch buffers, all sized once from the [`Model`] by
//! [`Data::new`] so that stepping does not allocate (the constraint buffers grow only when a
//! scene produces more simultaneous contacts than ever before, and then keep their capacity).
//!
//! [`DataState`] ([`Data::state`], [`Data::set_state`]) is the part of a `Data` that carries
//! over from one step to the next, for exact checkpoints: everything else is recomputed by
//! every step before it is read.

use crate::constraints::Efc;
use crate::math::{Mat3, Quat, SpatialInertia, Vec3, Vec6};
use crate::model::Model;
use serde::{Deserialize, Serialize};
use std::fmt;

/// One contact point found by collision detection.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Contact {
    /// Contact point (world), midway between the two surfaces.
    pub pos: Vec3,
    /// Unit normal pointing from `geom1` towards `geom2`.
    pub normal: Vec3,
    /// Signed distance between the surfaces (negative: penetration).
    pub dist: f64,
    /// First geom.
    pub geom1: usize,
    /// Second geom.
    pub geom2: usize,
    /// Friction coefficient of the contact.
    pub friction: f64,
    /// Warm-start slot.
    pub slot: usize,
}

/// Per-environment simulation state and scratch space.
#[derive(Clone, Debug)]
pub struct Data {
    /// Simulation time (s).
    pub time: f64,
    /// Generalised positions (`Model::nq`).
    pub qpos: Vec<f64>,
    /// Generalised velocities (`Model::nv`).
    pub qvel: Vec<f64>,
    /// Actuator controls (`Model::nu()`).
    pub ctrl: Vec<f64>,
    /// Generalised accelerations of the last step.
    pub qacc: Vec<f64>,
    /// External generalised forces applied by the user (kept between steps).
    pub qfrc_applied: Vec<f64>,

    /// Body positions (world) from the last kinematics pass.
    pub xpos: Vec<Vec3>,
    /// Body orientations (world).
    pub xquat: Vec<Quat>,
    /// Body rotation matrices (world).
    pub xmat: Vec<Mat3>,
    /// Body centres of mass (world).
    pub xipos: Vec<Vec3>,
    /// Geom centres (world).
    pub geom_xpos: Vec<Vec3>,
    /// Geom rotation matrices (world); not updated for spheres (their orientation does not
    /// matter to collisions: use the body's `xmat`).
    pub geom_xmat: Vec<Mat3>,
    /// Hinge axes (world), per joint.
    pub xaxis: Vec<Vec3>,
    /// Hinge anchors (world), per joint.
    pub xanchor: Vec<Vec3>,
    /// Reference point of each tree's spatial quantities: the root body's origin.
    pub tree_ref: Vec<Vec3>,
    /// Radius about `tree_ref` of a sphere holding all of the tree's geoms (broad phase).
    pub tree_rbound: Vec<f64>,

    /// Body spatial inertias about their tree's reference point.
    pub cinert: Vec<SpatialInertia>,
    /// Composite (subtree) inertias.
    pub crb: Vec<SpatialInertia>,
    /// Dof motion axes (world, about the tree reference point).
    pub cdof: Vec<Vec6>,
    /// Time derivative of each `cdof` (the axis moving with the body before that dof).
    pub cdof_dot: Vec<Vec6>,
    /// Body spatial velocities.
    pub cvel: Vec<Vec6>,
    /// Body spatial accelerations (scratch of the Newton-Euler pass).
    pub cacc: Vec<Vec6>,
    /// Body spatial forces (scratch of the Newton-Euler pass).
    pub cfrc: Vec<Vec6>,

    /// Mass matrix in the compact tree layout of [`crate::crba`] (row `i`: `M[i][j]` for the
    /// ancestors `j` of `i`, diagonal first); [`crate::crba::dense_mass_matrix`] expands it.
    pub qm: Vec<f64>,
    /// `L^T D L` factor of `M + h D_damping` in the same layout (diagonal entries: D); only
    /// computed when some dof has damping.
    pub qh: Vec<f64>,
    /// Bias forces `C(q, qdot) qdot + g(q)`.
    pub qfrc_bias: Vec<f64>,
    /// Actuator forces.
    pub qfrc_actuator: Vec<f64>,
    /// Passive (damping) forces.
    pub qfrc_passive: Vec<f64>,
    /// Total smooth force `tau_act + tau_applied - D qvel - c`.
    pub qfrc_smooth: Vec<f64>,
    /// Unconstrained acceleration `M^-1 qfrc_smooth` (MuJoCo's `qacc_smooth`).
    pub qacc_smooth: Vec<f64>,
    /// `L^T D L` factor of `M` (compact layout).
    pub qlm: Vec<f64>,
    /// Constraint forces in joint space of the last step.
    pub qfrc_constraint: Vec<f64>,

    /// Implicit integrator scratch: `M + h D + h dc/dqvel`, LU-factored in place (`nv x nv`).
    pub(crate) qk: Vec<f64>,
    /// Implicit integrator scratch: pivots of the LU factorisation.
    pub(crate) qk_piv: Vec<usize>,
    /// Implicit integrator scratch: two nv vectors.
    pub(crate) qtmp: Vec<f64>,
    /// `EulerGyro` scratch: three nv columns.
    pub(crate) qk_cols: Vec<f64>,
    /// `EulerGyro` scratch: per body, the derivatives of its subtree force in the three
    /// directions of its root's angular velocity.
    pub(crate) qk_tan: Vec<[Vec6; 3]>,

    /// Contacts of the last step.
    pub contacts: Vec<Contact>,
    /// Warm-start forces of the contact slots: normal force, then the friction force as a
    /// world-frame vector.
    pub(crate) warm: Vec<[f64; 4]>,
    /// Slots written into `warm` by the last step.
    pub(crate) warm_used: Vec<usize>,
    /// Warm-start forces of the joint limits, per joint.
    pub(crate) warm_limit: Vec<f64>,
    /// Constraint scratch.
    pub(crate) efc: Efc,
}

impl Data {
    /// A fresh state at the model's default pose (`Model::qpos0`), at rest, controls zero.
    pub fn new(m: &Model) -> Self {
        let (nb, nv) = (m.bodies.len(), m.nv);
        let z3 = [0.0; 3];
        let z6 = [0.0; 6];
        let i3 = crate::math::MAT3_IDENTITY;
        Data {
            time: 0.0,
            qpos: m.qpos0.clone(),
            qvel: vec![0.0; nv],
            ctrl: vec![0.0; m.nu()],
            qacc: vec![0.0; nv],
            qfrc_applied: vec![0.0; nv],
            xpos: vec![z3; nb],
            xquat: vec![crate::math::QUAT_IDENTITY; nb],
            xmat: vec![i3; nb],
            xipos: vec![z3; nb],
            geom_xpos: vec![z3; m.geoms.len()],
            geom_xmat: vec![i3; m.geoms.len()],
            xaxis: vec![z3; m.joints.len()],
            xanchor: vec![z3; m.joints.len()],
            tree_ref: vec![z3; m.trees.len()],
            tree_rbound: vec![0.0; m.trees.len()],
            cinert: vec![SpatialInertia::default(); nb],
            crb: vec![SpatialInertia::default(); nb],
            cdof: vec![z6; nv],
            cdof_dot: vec![z6; nv],
            cvel: vec![z6; nb],
            cacc: vec![z6; nb],
            cfrc: vec![z6; nb],
            qm: vec![0.0; m.dof_chain.len()],
            qh: vec![0.0; m.dof_chain.len()],
            qfrc_bias: vec![0.0; nv],
            qfrc_actuator: vec![0.0; nv],
            qfrc_passive: vec![0.0; nv],
            qfrc_smooth: vec![0.0; nv],
            qacc_smooth: vec![0.0; nv],
            qlm: vec![0.0; m.dof_chain.len()],
            qfrc_constraint: vec![0.0; nv],
            qk: if m.opt.integrator == crate::model::Integrator::Implicit { vec![0.0; nv * nv] } else { Vec::new() },
            qk_piv: vec![0; nv],
            qtmp: vec![0.0; 2 * nv],
            qk_cols: vec![0.0; 3 * nv],
            qk_tan: vec![[z6; 3]; nb],
            contacts: Vec::with_capacity(16 + 2 * m.plane_pairs.len()),
            warm: vec![[0.0; 4]; m.nslot],
            warm_used: Vec::with_capacity(64),
            warm_limit: vec![0.0; m.joints.len()],
            efc: Efc::default(),
        }
    }

    /// Puts the state back to `qpos` at rest: velocities, accelerations, applied forces and
    /// contact warm starts are cleared, time set to 0. Errors if `qpos` has the wrong length
    /// or a non-finite entry.
    pub fn reset_to(&mut self, m: &Model, qpos: &[f64]) -> Result<(), String> {
        if qpos.len() != m.nq {
            return Err(format!("qpos has {} entries, the model has nq = {}", qpos.len(), m.nq));
        }
        if let Some(i) = qpos.iter().position(|x| !x.is_finite()) {
            return Err(format!("qpos[{i}] = {} is not finite", qpos[i]));
        }
        self.qpos.copy_from_slice(qpos);
        self.qvel.iter_mut().for_each(|x| *x = 0.0);
        self.qacc.iter_mut().for_each(|x| *x = 0.0);
        self.qfrc_applied.iter_mut().for_each(|x| *x = 0.0);
        self.warm.iter_mut().for_each(|x| *x = [0.0; 4]);
        self.warm_used.clear();
        self.warm_limit.iter_mut().for_each(|x| *x = 0.0);
        self.contacts.clear();
        self.time = 0.0;
        Ok(())
    }

    /// Bytes this state holds beyond its own struct: the capacities of its buffers,
    /// including the constraint scratch, which grows with the most simultaneous contacts
    /// seen so far. For memory estimates ([`crate::tasks::VecEnv::bytes_per_env`]).
    pub fn heap_bytes(&self) -> usize {
        fn cap<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        let f64s = [
            &self.qpos,
            &self.qvel,
            &self.ctrl,
            &self.qacc,
            &self.qfrc_applied,
            &self.tree_rbound,
            &self.qm,
            &self.qh,
            &self.qfrc_bias,
            &self.qfrc_actuator,
            &self.qfrc_passive,
            &self.qfrc_smooth,
            &self.qacc_smooth,
            &self.qlm,
            &self.qfrc_constraint,
            &self.qk,
            &self.qtmp,
            &self.qk_cols,
            &self.warm_limit,
        ];
        let vec3s = [&self.xpos, &self.xipos, &self.geom_xpos, &self.xaxis, &self.xanchor, &self.tree_ref];
        let vec6s = [&self.cdof, &self.cdof_dot, &self.cvel, &self.cacc, &self.cfrc];
        f64s.iter().map(|v| cap(v)).sum::<usize>()
            + vec3s.iter().map(|v| cap(v)).sum::<usize>()
            + vec6s.iter().map(|v| cap(v)).sum::<usize>()
            + cap(&self.xquat)
            + cap(&self.xmat)
            + cap(&self.geom_xmat)
            + cap(&self.cinert)
            + cap(&self.crb)
            + cap(&self.qk_piv)
            + cap(&self.qk_tan)
            + cap(&self.contacts)
            + cap(&self.warm)
            + cap(&self.warm_used)
            + self.efc.heap_bytes()
    }

    /// Whether every entry of the state (qpos, qvel) is finite.
    pub fn is_finite(&self) -> bool {
        self.qpos.iter().chain(self.qvel.iter()).all(|x| x.is_finite())
    }

    /// The state that carries over to the next step ([`DataState`]): stepping a `Data` whose
    /// state was set from it with [`Data::set_state`] gives the same bits as stepping this one.
    pub fn state(&self) -> DataState {
        debug_assert!(
            self.warm.iter().enumerate().all(|(s, w)| *w == [0.0; 4] || self.warm_used.contains(&s)),
            "a contact warm start outside warm_used"
        );
        DataState {
            time: self.time,
            qpos: self.qpos.clone(),
            qvel: self.qvel.clone(),
            ctrl: self.ctrl.clone(),
            qfrc_applied: self.qfrc_applied.clone(),
            warm_contacts: self.warm_used.iter().map(|&slot| WarmStart { slot, force: self.warm[slot] }).collect(),
            warm_limit: self.warm_limit.clone(),
        }
    }

    /// Sets the state carried between steps from `s` (checked against `m` first: nothing
    /// changes on error). The derived quantities (poses, velocities, contacts, `qacc`) are left
    /// as they are: [`crate::forward()`] or [`crate::kinematics::kinematics`] brings them up to
    /// date; the next step recomputes them anyway.
    pub fn set_state(&mut self, m: &Model, s: &DataState) -> Result<(), StateMismatch> {
        s.check(m)?;
        self.time = s.time;
        self.qpos.copy_from_slice(&s.qpos);
        self.qvel.copy_from_slice(&s.qvel);
        self.ctrl.copy_from_slice(&s.ctrl);
        self.qfrc_applied.copy_from_slice(&s.qfrc_applied);
        self.warm.iter_mut().for_each(|w| *w = [0.0; 4]);
        self.warm_used.clear();
        for w in &s.warm_contacts {
            self.warm[w.slot] = w.force;
            self.warm_used.push(w.slot);
        }
        self.warm_limit.copy_from_slice(&s.warm_limit);
        Ok(())
    }
}

/// Everything of a [`Data`] that a step reads before writing it, so that
/// [`Data::set_state`] followed by stepping reproduces the original's steps bit for bit:
/// - `time`, `qpos`, `qvel`: the state proper;
/// - `ctrl`, `qfrc_applied`: inputs kept between steps (the tasks rewrite `ctrl` every
///   control step, but a plain simulator user may not);
/// - the constraint solver's warm starts: the forces of the contact slots used by the last
///   step (every other slot's warm start is zero, and only these are cleared by the next
///   step) and of the joint limits.
///
/// Everything else in `Data` (poses, inertias, mass matrix and factors, bias, contacts,
/// constraint rows, accelerations) is written by a step before it is read. Numbers are stored
/// as they are, non-finite ones included.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataState {
    /// Simulation time (s).
    pub time: f64,
    /// Generalised positions (`Model::nq`).
    pub qpos: Vec<f64>,
    /// Generalised velocities (`Model::nv`).
    pub qvel: Vec<f64>,
    /// Actuator controls (`Model::nu()`).
    pub ctrl: Vec<f64>,
    /// User-applied generalised forces (`Model::nv`).
    pub qfrc_applied: Vec<f64>,
    /// Warm starts of the contact slots used by the last step, in the order they were used.
    pub warm_contacts: Vec<WarmStart>,
    /// Warm-start forces of the joint limits, per joint (`Model::joints`).
    pub warm_limit: Vec<f64>,
}

/// The warm start of one contact slot (a fixed geom pair and capsule end).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WarmStart {
    /// The slot (`0..Model::nslot`).
    pub slot: usize,
    /// Normal force, then the friction force as a world-frame vector.
    pub force: [f64; 4],
}

/// Why a [`DataState`] does not fit a model: the field, what it holds, what the model needs.
#[derive(Clone, Debug, PartialEq)]
pub struct StateMismatch {
    /// The field (e.g. `qpos`, `warm_contacts[3].slot`).
    pub field: String,
    /// What the state holds (a length or a value).
    pub value: String,
    /// What the model expects.
    pub expected: String,
}

impl fmt::Display for StateMismatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} = {}, expected {}", self.field, self.value, self.expected)
    }
}

impl std::error::Error for StateMismatch {}

impl DataState {
    /// Checks that every array has the model's size and every warm-start slot exists.
    pub fn check(&self, m: &Model) -> Result<(), StateMismatch> {
        let len = |field: &str, got: usize, want: usize, what: &str| {
            if got == want {
                Ok(())
            } else {
                Err(StateMismatch {
                    field: field.into(),
                    value: format!("{got} entries"),
                    expected: format!("{want} ({what})"),
                })
            }
        };
        len("qpos", self.qpos.len(), m.nq, "nq")?;
        len("qvel", self.qvel.len(), m.nv, "nv")?;
        len("ctrl", self.ctrl.len(), m.nu(), "actuators")?;
        len("qfrc_applied", self.qfrc_applied.len(), m.nv, "nv")?;
        len("warm_limit", self.warm_limit.len(), m.joints.len(), "joints")?;
        if let Some((i, w)) = self.warm_contacts.iter().enumerate().find(|(_, w)| w.slot >= m.nslot) {
            return Err(StateMismatch {
                field: format!("warm_contacts[{i}].slot"),
                value: w.slot.to_string(),
                expected: format!("a contact slot below {}", m.nslot),
            });
        }
        Ok(())
    }
}
