//! The stages of [`super::ModelBuilder::build`], in MuJoCo's compiler order: options, bodies,
//! geoms, inertia, joints and DoFs, the DoF tree, the kinematic trees, actuators, contact
//! pairs. Each stage validates what it reads (errors name the item and the value) and
//! returns or fills in its part of the [`Model`]; [`super::ModelBuilder::build`] lists them.

#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > 0.0)` deliberately rejects NaN too

use super::inertia::{combine, solid_inertia};
use super::{ActSpec, BodySpec, GeomSpec, JointSpec, MassOverride};
use crate::math::{self, Mat3, Quat, Vec3};
use crate::model::{
    Actuator, Body, CollisionPair, Geom, Joint, JointKind, ModelError, NONE, Options, PairGroup, Shape, Tree,
};

/// Options: reads the timestep, gravity, `solref` and `solimp`; checks that they are finite
/// and in MuJoCo's ranges. Writes nothing.
pub(super) fn check_options(opt: &Options) -> Result<(), ModelError> {
    check_finite("option timestep", opt.timestep)?;
    if opt.timestep <= 0.0 {
        return Err(bad("option timestep", opt.timestep));
    }
    for (k, g) in opt.gravity.iter().enumerate() {
        check_finite(&format!("option gravity[{k}]"), *g)?;
    }
    if !(opt.solref[0] > 0.0 && opt.solref[1] > 0.0) {
        return Err(bad("option solref", opt.solref[0].min(opt.solref[1])));
    }
    let [dmin, dmax, width, mid, power] = opt.solimp;
    if !(0.0 < dmin && dmin <= dmax && dmax < 1.0 && width > 0.0 && mid > 0.0 && mid < 1.0 && power >= 1.0) {
        return Err(bad("option solimp", dmin));
    }
    Ok(())
}

/// Bodies: reads each body's parent and frame; checks that parents come first and that the
/// frame is finite with a non-zero quaternion. Returns the bodies with their frames (unit
/// quaternions); mass, joints, DoFs and tree are left empty for the later stages.
pub(super) fn bodies(specs: &[BodySpec]) -> Result<Vec<Body>, ModelError> {
    let mut bodies = Vec::with_capacity(specs.len());
    for (i, b) in specs.iter().enumerate() {
        if i > 0 && b.parent >= i {
            return Err(ModelError::BadId { what: "parent body", index: b.parent });
        }
        check_vec(&format!("body {i} pos"), b.pos)?;
        let quat = unit_quat(&format!("body {i} quat"), b.quat)?;
        bodies.push(Body {
            name: b.name.clone(),
            parent: if i == 0 { 0 } else { b.parent },
            pos: b.pos,
            quat,
            mass: 0.0,
            ipos: [0.0; 3],
            inertia: [[0.0; 3]; 3],
            tree: NONE,
            jnt_adr: 0,
            jnt_num: 0,
            dof_adr: 0,
            dof_num: 0,
        });
    }
    Ok(bodies)
}

/// Geoms: reads each geom's body, frame, shape, density, mass and friction; checks them all.
/// Returns the geoms with their unit quaternion, rotation matrix and bounding radius
/// (`rbound`); their tree is set by [`trees`].
pub(super) fn geoms(specs: &[(usize, GeomSpec)], nbody: usize) -> Result<Vec<Geom>, ModelError> {
    let mut geoms = Vec::with_capacity(specs.len());
    for (gi, (body, s)) in specs.iter().enumerate() {
        if *body >= nbody {
            return Err(ModelError::BadId { what: "body", index: *body });
        }
        check_vec(&format!("geom {gi} pos"), s.pos)?;
        let quat = unit_quat(&format!("geom {gi} quat"), s.quat)?;
        let positive = |what: &str, v: f64| -> Result<(), ModelError> {
            if v.is_finite() && v > 0.0 { Ok(()) } else { Err(bad(&format!("geom {gi} {what}"), v)) }
        };
        let rbound = match s.shape {
            Shape::Sphere { radius } => {
                positive("radius", radius)?;
                radius
            }
            Shape::Capsule { radius, half_length } => {
                positive("radius", radius)?;
                if !(half_length.is_finite() && half_length >= 0.0) {
                    return Err(bad(&format!("geom {gi} half_length"), half_length));
                }
                radius + half_length
            }
            Shape::Plane => f64::INFINITY,
        };
        if !(s.density.is_finite() && s.density >= 0.0) {
            return Err(bad(&format!("geom {gi} density"), s.density));
        }
        if let Some(m) = s.mass
            && !(m.is_finite() && m >= 0.0)
        {
            return Err(bad(&format!("geom {gi} mass"), m));
        }
        if !(s.friction.is_finite() && s.friction >= 0.0) {
            return Err(bad(&format!("geom {gi} friction"), s.friction));
        }
        geoms.push(Geom {
            name: s.name.clone(),
            body: *body,
            shape: s.shape,
            pos: s.pos,
            quat,
            mat: math::quat_to_mat(quat),
            friction: s.friction,
            contype: s.contype,
            conaffinity: s.conaffinity,
            ends: s.ends,
            rbound,
            tree: NONE,
        });
    }
    Ok(geoms)
}

/// Inertia (MuJoCo's `inertiafromgeom`): reads the geoms' solids (density or mass, position
/// and rotation from [`geoms`]) and each body's mass override; checks the overrides. Writes
/// every body's `mass`, centre of mass `ipos` and `inertia` about it (world: none).
pub(super) fn inertia(
    body_specs: &[BodySpec],
    geom_specs: &[(usize, GeomSpec)],
    geoms: &[Geom],
    bodies: &mut [Body],
) -> Result<(), ModelError> {
    let mut parts: Vec<Vec<(f64, Vec3, Mat3)>> = vec![Vec::new(); bodies.len()];
    for (gi, ((body, s), g)) in geom_specs.iter().zip(geoms).enumerate() {
        if let Some((m, ic)) = solid_inertia(&s.shape, s.density, s.mass) {
            // Finite inputs can still overflow here (density * size^3, mass * size^2).
            if !(m.is_finite() && ic.iter().flatten().all(|x| x.is_finite())) {
                return Err(bad(&format!("geom {gi} mass from its density and size"), m));
            }
            parts[*body].push((m, s.pos, math::rotate_tensor(&g.mat, &ic)));
        }
    }
    for (i, b) in bodies.iter_mut().enumerate() {
        let (m, c, inertia) = combine(&parts[i]);
        match &body_specs[i].mass {
            MassOverride::FromGeoms => {
                b.mass = m;
                b.ipos = c;
                b.inertia = inertia;
            }
            MassOverride::Mass(target) => {
                if !(target.is_finite() && *target >= 0.0) {
                    return Err(bad(&format!("body {i} mass"), *target));
                }
                if m <= 0.0 && *target > 0.0 {
                    return Err(bad(&format!("body {i} mass (the body has no solid geom to carry it)"), *target));
                }
                let s = if m > 0.0 { target / m } else { 0.0 };
                b.mass = *target;
                b.ipos = c;
                b.inertia = inertia.map(|row| row.map(|x| x * s));
                if !b.inertia.iter().flatten().all(|x| x.is_finite()) {
                    return Err(bad(
                        &format!("body {i} mass (its inertia, scaled from its geoms, overflows)"),
                        *target,
                    ));
                }
            }
            MassOverride::Explicit { mass, com, inertia } => {
                if !(mass.is_finite() && *mass >= 0.0) {
                    return Err(bad(&format!("body {i} mass"), *mass));
                }
                check_vec(&format!("body {i} com"), *com)?;
                for row in inertia {
                    check_vec(&format!("body {i} inertia"), *row)?;
                }
                b.mass = *mass;
                b.ipos = *com;
                b.inertia = *inertia;
            }
        }
    }
    if bodies[0].mass != 0.0 {
        // Geoms on the world are static: they carry no mass.
        bodies[0].mass = 0.0;
        bodies[0].inertia = [[0.0; 3]; 3];
    }
    Ok(())
}

/// What [`joints`] returns: the joints and the sizes of the position and velocity vectors.
pub(super) struct Joints {
    /// The joints, with their qpos and DoF addresses.
    pub joints: Vec<Joint>,
    /// Number of position coordinates.
    pub nq: usize,
    /// Number of DoFs.
    pub nv: usize,
    /// Initial positions: a free joint's body frame, a hinge's initial angle.
    pub qpos0: Vec<f64>,
}

/// Joints and DoFs: reads the joint specs and the bodies' parents and frames; checks body
/// order, axes, anchors, ranges, armature and damping, and that a free joint is the only
/// joint of a child of the world. Writes each body's joint and DoF addresses and counts;
/// returns the joints, `nq`, `nv` and `qpos0`.
pub(super) fn joints(specs: &[JointSpec], bodies: &mut [Body]) -> Result<Joints, ModelError> {
    let nbody = bodies.len();
    let mut joints = Vec::with_capacity(specs.len());
    let (mut nq, mut nv) = (0usize, 0usize);
    let mut qpos0 = Vec::new();
    let mut last_body = 0usize;
    for (ji, j) in specs.iter().enumerate() {
        if j.body >= nbody {
            return Err(ModelError::BadId { what: "body", index: j.body });
        }
        if j.body == 0 {
            return Err(ModelError::JointOnWorld);
        }
        if j.body < last_body {
            return Err(ModelError::BadValue {
                what: format!("joint {ji} order (joints must be added in body order)"),
                value: j.body as f64,
            });
        }
        last_body = j.body;
        let b = &mut bodies[j.body];
        if b.jnt_num == 0 {
            b.jnt_adr = ji;
            b.dof_adr = nv;
        }
        b.jnt_num += 1;
        let h = &j.hinge;
        let (axis, limited, range) = match j.kind {
            JointKind::Free => {
                if b.parent != 0 {
                    return Err(ModelError::BadFreeJoint { body: j.body });
                }
                qpos0.extend_from_slice(&b.pos);
                qpos0.extend_from_slice(&b.quat);
                ([0.0, 0.0, 1.0], false, [0.0, 0.0])
            }
            JointKind::Hinge => {
                // Huge components (1e200) overflow the squared norm: such an axis is scaled
                // by its largest component first. Ordinary axes take the direct path, so
                // their bits are those of a plain normalisation.
                let big = h.axis.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                let overflows = !math::dot(h.axis, h.axis).is_finite() && big.is_finite();
                let axis = if overflows { math::scale(h.axis, 1.0 / big) } else { h.axis };
                let axis = math::normalize(axis).filter(|a| a.iter().all(|x| x.is_finite()));
                let axis = axis.ok_or_else(|| ModelError::Degenerate { what: format!("joint {ji} axis") })?;
                check_vec(&format!("joint {ji} anchor"), h.anchor)?;
                check_finite(&format!("joint {ji} initial angle"), h.init)?;
                let range = h.range.unwrap_or([0.0, 0.0]);
                if let Some([lo, hi]) = h.range {
                    check_finite(&format!("joint {ji} range lower"), lo)?;
                    check_finite(&format!("joint {ji} range upper"), hi)?;
                    if lo > hi {
                        return Err(bad(&format!("joint {ji} range (lower > upper)"), lo));
                    }
                }
                qpos0.push(h.init);
                (axis, h.range.is_some(), range)
            }
        };
        for (what, v) in [("armature", h.armature), ("damping", h.damping)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(&format!("joint {ji} {what}"), v));
            }
        }
        let (q, v) = if j.kind == JointKind::Free { (7, 6) } else { (1, 1) };
        joints.push(Joint {
            name: h.name.clone(),
            kind: j.kind,
            body: j.body,
            axis,
            anchor: h.anchor,
            limited,
            range,
            armature: h.armature,
            damping: h.damping,
            qpos_adr: nq,
            dof_adr: nv,
        });
        b.dof_num += v;
        nq += q;
        nv += v;
    }
    for b in bodies.iter() {
        if b.jnt_num > 1 && (b.jnt_adr..b.jnt_adr + b.jnt_num).any(|j| joints[j].kind == JointKind::Free) {
            let body = joints[b.jnt_adr].body;
            return Err(ModelError::BadFreeJoint { body });
        }
    }
    Ok(Joints { joints, nq, nv, qpos0 })
}

/// What [`dof_tree`] returns: the per-DoF arrays of [`Model`] (same names without `dof_`).
pub(super) struct DofTree {
    /// [`Model::dof_parent`].
    pub parent: Vec<usize>,
    /// [`Model::dof_body`].
    pub body: Vec<usize>,
    /// [`Model::dof_joint`].
    pub joint: Vec<usize>,
    /// [`Model::dof_armature`].
    pub armature: Vec<f64>,
    /// [`Model::dof_damping`].
    pub damping: Vec<f64>,
    /// [`Model::body_last_dof`].
    pub body_last_dof: Vec<usize>,
    /// [`Model::dof_depth`].
    pub depth: Vec<usize>,
    /// [`Model::dof_chain_adr`].
    pub chain_adr: Vec<usize>,
    /// [`Model::dof_chain`].
    pub chain: Vec<usize>,
}

/// The DoF tree (RBDA §6.5's parent array, MuJoCo's `dof_parentid`): reads the bodies' DoF
/// addresses and parents and the joints' armature and damping. Returns each DoF's parent,
/// body, joint, armature and damping, each body's last DoF, and each DoF's ancestor chain
/// (the rows of the compact mass matrix layout of [`crate::crba`]).
pub(super) fn dof_tree(bodies: &[Body], joints: &[Joint], nv: usize) -> DofTree {
    let nbody = bodies.len();
    let mut dof_parent = vec![NONE; nv];
    let mut dof_body = vec![0; nv];
    let mut dof_joint = vec![0; nv];
    let mut dof_armature = vec![0.0; nv];
    let mut dof_damping = vec![0.0; nv];
    for (ji, j) in joints.iter().enumerate() {
        let n = if j.kind == JointKind::Free { 6 } else { 1 };
        for k in 0..n {
            dof_body[j.dof_adr + k] = j.body;
            dof_joint[j.dof_adr + k] = ji;
            dof_armature[j.dof_adr + k] = j.armature;
            dof_damping[j.dof_adr + k] = j.damping;
        }
    }
    for i in 1..nbody {
        let b = &bodies[i];
        if b.dof_num == 0 {
            continue;
        }
        // Last dof of the nearest ancestor with dofs.
        let mut p = b.parent;
        let mut parent_dof = NONE;
        while p != 0 {
            if bodies[p].dof_num > 0 {
                parent_dof = bodies[p].dof_adr + bodies[p].dof_num - 1;
                break;
            }
            p = bodies[p].parent;
        }
        for k in 0..b.dof_num {
            dof_parent[b.dof_adr + k] = if k == 0 { parent_dof } else { b.dof_adr + k - 1 };
        }
    }
    let mut body_last_dof = vec![NONE; nbody];
    for i in 1..nbody {
        let b = &bodies[i];
        body_last_dof[i] = if b.dof_num > 0 { b.dof_adr + b.dof_num - 1 } else { body_last_dof[b.parent] };
    }
    let mut dof_depth = vec![0; nv];
    let mut dof_chain_adr = vec![0; nv];
    let mut dof_chain = Vec::new();
    for i in 0..nv {
        dof_depth[i] = if dof_parent[i] == NONE { 1 } else { dof_depth[dof_parent[i]] + 1 };
        dof_chain_adr[i] = dof_chain.len();
        let mut j = i;
        while j != NONE {
            dof_chain.push(j);
            j = dof_parent[j];
        }
    }
    DofTree {
        parent: dof_parent,
        body: dof_body,
        joint: dof_joint,
        armature: dof_armature,
        damping: dof_damping,
        body_last_dof,
        depth: dof_depth,
        chain_adr: dof_chain_adr,
        chain: dof_chain,
    }
}

/// Kinematic trees (agents): a body with joints whose parent is static starts a tree, its
/// descendants join it. Reads the bodies' parents and joint counts and the geoms' bodies;
/// checks that planes are static. Writes each body's and geom's `tree` and returns the trees.
pub(super) fn trees(bodies: &mut [Body], geoms: &mut [Geom]) -> Result<Vec<Tree>, ModelError> {
    let mut trees: Vec<Tree> = Vec::new();
    for i in 1..bodies.len() {
        let ptree = bodies[bodies[i].parent].tree;
        bodies[i].tree = if ptree != NONE {
            ptree
        } else if bodies[i].jnt_num > 0 {
            trees.push(Tree { root: i, bodies: Vec::new(), geoms: Vec::new() });
            trees.len() - 1
        } else {
            NONE
        };
        if bodies[i].tree != NONE {
            trees[bodies[i].tree].bodies.push(i);
        }
    }
    for (gi, g) in geoms.iter_mut().enumerate() {
        g.tree = bodies[g.body].tree;
        if g.tree != NONE {
            if g.shape == Shape::Plane {
                return Err(ModelError::PlaneOnMovingBody { geom: gi });
            }
            trees[g.tree].geoms.push(gi);
        }
    }
    Ok(trees)
}

/// Actuators: reads each motor's joint, gear and control range; checks that the joint is a
/// hinge and the numbers finite. Returns the actuators with the DoF they drive.
pub(super) fn actuators(specs: &[ActSpec], joints: &[Joint]) -> Result<Vec<Actuator>, ModelError> {
    let mut actuators = Vec::with_capacity(specs.len());
    for (ai, a) in specs.iter().enumerate() {
        let j = joints.get(a.joint).ok_or(ModelError::BadId { what: "joint", index: a.joint })?;
        if j.kind != JointKind::Hinge {
            return Err(ModelError::ActuatorNotOnHinge { actuator: ai });
        }
        check_finite(&format!("actuator {ai} gear"), a.gear)?;
        if let Some([lo, hi]) = a.ctrlrange
            && !(lo.is_finite() && hi.is_finite() && lo <= hi)
        {
            return Err(bad(&format!("actuator {ai} ctrlrange"), lo));
        }
        actuators.push(Actuator {
            name: a.name.clone(),
            joint: a.joint,
            dof: j.dof_adr,
            gear: a.gear,
            ctrlrange: a.ctrlrange,
        });
    }
    Ok(actuators)
}

/// What [`contact_pairs`] returns: the candidate pairs of [`Model`] and their warm-start
/// slots.
pub(super) struct ContactPairs {
    /// [`Model::plane_pairs`].
    pub plane_pairs: Vec<CollisionPair>,
    /// [`Model::geom_pairs`].
    pub geom_pairs: Vec<CollisionPair>,
    /// [`Model::pair_groups`].
    pub pair_groups: Vec<PairGroup>,
    /// [`Model::nslot`].
    pub nslot: usize,
}

/// Contact pairs (MuJoCo's broad-phase filter, fixed at build time): reads the geoms' trees,
/// shapes and `contype`/`conaffinity` bits. Keeps the pairs of geoms in different trees (or a
/// tree and a static geom) whose bits match; plane pairs come first, in geom order, with two
/// warm-start slots per capsule (one per end) and one otherwise; the other pairs follow,
/// grouped by tree pair (for the tree-level broad phase), one slot each.
pub(super) fn contact_pairs(geoms: &[Geom]) -> ContactPairs {
    let (mut plane_pairs, mut geom_pairs) = (Vec::new(), Vec::new());
    let mut nslot = 0;
    for (a, b) in candidate_pairs(geoms) {
        let (ga, gb) = (&geoms[a], &geoms[b]);
        let (pa, pb) = (ga.shape == Shape::Plane, gb.shape == Shape::Plane);
        if pa || pb {
            let (p, o) = if pa { (a, b) } else { (b, a) };
            let n = if matches!(geoms[o].shape, Shape::Capsule { .. }) { 2 } else { 1 };
            plane_pairs.push(CollisionPair { g1: p, g2: o, slot: nslot });
            nslot += n;
        } else {
            geom_pairs.push(CollisionPair { g1: a, g2: b, slot: 0 });
        }
    }
    let tree_key = |p: &CollisionPair| {
        let (t1, t2) = (geoms[p.g1].tree, geoms[p.g2].tree);
        (t1.min(t2), t1.max(t2))
    };
    geom_pairs.sort_by_key(|p| (tree_key(p), p.g1, p.g2));
    let mut pair_groups: Vec<PairGroup> = Vec::new();
    for (i, p) in geom_pairs.iter_mut().enumerate() {
        p.slot = nslot;
        nslot += 1;
        let (t1, t2) = tree_key(p);
        match pair_groups.last_mut() {
            Some(g) if (g.tree1, g.tree2) == (t1, t2) => g.end = i + 1,
            _ => pair_groups.push(PairGroup { tree1: t1, tree2: t2, start: i, end: i + 1 }),
        }
    }
    ContactPairs { plane_pairs, geom_pairs, pair_groups, nslot }
}

/// The geom pairs `(a, b)`, `a < b`, in different trees (static geoms count as one tree)
/// whose bits match (`contype_a & conaffinity_b` or `contype_b & conaffinity_a` non-zero),
/// in increasing order.
///
/// Testing every pair would cost the square of the number of geoms even when few pairs are
/// kept (one large agent, or many bodies that only touch the ground). Instead the geoms are
/// grouped by their two bit masks (few distinct values), each group sorted by tree; for each
/// geom and each matching group, the geoms of the other trees are the group minus one run
/// (found by binary search). The cost is `O(G log G + P log P)` for `G` geoms and `P` kept
/// pairs (`P` itself is quadratic when every pair of agents' geoms may collide).
fn candidate_pairs(geoms: &[Geom]) -> Vec<(usize, usize)> {
    // Masks -> geoms sorted by (tree, index); a BTreeMap for a fixed group order.
    let mut groups: std::collections::BTreeMap<(u32, u32), Vec<usize>> = Default::default();
    for (g, geom) in geoms.iter().enumerate() {
        groups.entry((geom.contype, geom.conaffinity)).or_default().push(g);
    }
    let groups: Vec<((u32, u32), Vec<usize>)> = groups
        .into_iter()
        .map(|(masks, mut members)| {
            members.sort_by_key(|&g| (geoms[g].tree, g));
            (masks, members)
        })
        .collect();
    let mut pairs = Vec::new();
    for (i, ((type_i, aff_i), members_i)) in groups.iter().enumerate() {
        for (j, ((type_j, aff_j), members_j)) in groups.iter().enumerate().skip(i) {
            if type_i & aff_j == 0 && type_j & aff_i == 0 {
                continue;
            }
            let same_group = i == j;
            for &a in members_i {
                let tree = geoms[a].tree;
                let lo = members_j.partition_point(|&g| geoms[g].tree < tree);
                let hi = members_j.partition_point(|&g| geoms[g].tree <= tree);
                for &b in members_j[..lo].iter().chain(&members_j[hi..]) {
                    // Within one group every pair is seen twice: keep it once.
                    if !same_group || a < b {
                        pairs.push((a.min(b), a.max(b)));
                    }
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

fn bad(what: &str, value: f64) -> ModelError {
    ModelError::BadValue { what: what.to_string(), value }
}

fn check_finite(what: &str, v: f64) -> Result<(), ModelError> {
    if v.is_finite() { Ok(()) } else { Err(bad(what, v)) }
}

fn check_vec(what: &str, v: Vec3) -> Result<(), ModelError> {
    for x in v {
        check_finite(what, x)?;
    }
    Ok(())
}

fn unit_quat(what: &str, q: Quat) -> Result<Quat, ModelError> {
    for x in q {
        check_finite(what, x)?;
    }
    let norm = |q: Quat| (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let n = norm(q);
    if n.is_finite() {
        if n < 1e-12 {
            return Err(ModelError::Degenerate { what: what.to_string() });
        }
        return Ok([q[0] / n, q[1] / n, q[2] / n, q[3] / n]);
    }
    // The squares of huge components (1e200) overflow: scale by the largest component first
    // (only then, so that ordinary quaternions keep the bits of the direct path).
    let big = q.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let q = q.map(|x| x / big);
    let n = norm(q);
    Ok([q[0] / n, q[1] / n, q[2] / n, q[3] / n])
}
