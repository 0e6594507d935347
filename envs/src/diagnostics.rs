//! Physical diagnostics of a state: energies and momenta (for tests and monitoring). Each
//! function runs the kinematics it needs on `d`, leaving `qpos`/`qvel` untouched.

use crate::data::Data;
use crate::math::{self, Vec3};
use crate::model::{Model, NONE};
use crate::{crba, kinematics};

/// Kinetic energy `1/2 qvel^T M qvel` (armature included: it is the rotors' energy).
pub fn kinetic_energy(m: &Model, d: &mut Data) -> f64 {
    kinematics::kinematics(m, d);
    kinematics::com_pos(m, d);
    crba::crba(m, d);
    let mut e = 0.0;
    crba::for_each_entry(m, &d.qm, |i, j, mij| {
        e += if i == j { 0.5 * mij * d.qvel[i] * d.qvel[i] } else { mij * d.qvel[i] * d.qvel[j] };
    });
    e
}

/// Gravitational potential energy `-sum m g . x_com` (zero at the world origin).
pub fn potential_energy(m: &Model, d: &mut Data) -> f64 {
    kinematics::kinematics(m, d);
    let g = m.opt.gravity;
    (1..m.bodies.len())
        .filter(|&b| m.bodies[b].tree != NONE)
        .map(|b| -m.bodies[b].mass * math::dot(g, d.xipos[b]))
        .sum()
}

/// Total linear momentum and angular momentum about the world origin of the moving bodies.
pub fn momentum(m: &Model, d: &mut Data) -> (Vec3, Vec3) {
    kinematics::kinematics(m, d);
    kinematics::com_pos(m, d);
    kinematics::com_vel(m, d);
    let (mut p, mut l) = ([0.0; 3], [0.0; 3]);
    for b in 1..m.bodies.len() {
        let t = m.bodies[b].tree;
        if t == NONE {
            continue;
        }
        let h = d.cinert[b].mul(&d.cvel[b]);
        let f = [h[3], h[4], h[5]];
        p = math::add(p, f);
        // Angular momentum about the tree reference point, moved to the origin.
        l = math::add(l, math::add([h[0], h[1], h[2]], math::cross(d.tree_ref[t], f)));
    }
    (p, l)
}
