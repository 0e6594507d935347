//! [`ModelBuilder`]: the one way to make a [`Model`] (used by the MJCF and Brax loaders and by
//! tests). See the module documentation of [`crate::model`] for an overview and an example.
//!
//! Inertia from geometry follows MuJoCo's `inertiafromgeom`: every sphere and capsule geom of a
//! body is a solid of uniform density (or of a given mass); the body's mass, centre of mass and
//! inertia tensor are the sums (parallel-axis theorem).

#![allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x > 0.0)` deliberately rejects NaN too

use crate::math::{self, Mat3, Quat, Vec3};
use crate::model::{
    Actuator, ActuatorId, Body, BodyId, CapsuleEnds, CollisionPair, Geom, GeomId, Joint, JointId, JointKind, Model,
    ModelError, NONE, Options, PairGroup, Shape, Tree,
};

/// Description of a geom for [`ModelBuilder::add_geom`]; construct with [`GeomSpec::sphere`],
/// [`GeomSpec::capsule`], [`GeomSpec::capsule_fromto`] or [`GeomSpec::plane`] and adjust with
/// the chained setters. Defaults are MuJoCo's: density 1000, friction 1, contype 1,
/// conaffinity 1, both capsule ends.
#[derive(Clone, Debug, PartialEq)]
pub struct GeomSpec {
    /// Shape and size.
    pub shape: Shape,
    /// Position in the body frame.
    pub pos: Vec3,
    /// Orientation in the body frame (capsules lie along the local z axis).
    pub quat: Quat,
    /// Density (kg/m^3) used for the mass when `mass` is `None`.
    pub density: f64,
    /// Mass overriding `density * volume`.
    pub mass: Option<f64>,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Collision type bits.
    pub contype: u32,
    /// Collision affinity bits.
    pub conaffinity: u32,
    /// Capsule ends that touch planes.
    pub ends: CapsuleEnds,
    /// Name (may be empty).
    pub name: String,
}

impl GeomSpec {
    fn with_shape(shape: Shape) -> Self {
        GeomSpec {
            shape,
            pos: [0.0; 3],
            quat: math::QUAT_IDENTITY,
            density: 1000.0,
            mass: None,
            friction: 1.0,
            contype: 1,
            conaffinity: 1,
            ends: CapsuleEnds::Both,
            name: String::new(),
        }
    }

    /// A sphere of the given radius centred on the body origin.
    pub fn sphere(radius: f64) -> Self {
        Self::with_shape(Shape::Sphere { radius })
    }

    /// A capsule along the local z axis with the given radius and cylinder half-length.
    pub fn capsule(radius: f64, half_length: f64) -> Self {
        Self::with_shape(Shape::Capsule { radius, half_length })
    }

    /// A capsule whose segment runs from `from` to `to` (body frame), as MJCF `fromto`.
    /// A zero-length segment is reported by [`ModelBuilder::build`].
    pub fn capsule_fromto(radius: f64, from: Vec3, to: Vec3) -> Self {
        let d = math::sub(to, from);
        let len = math::norm(d);
        let mut s = Self::capsule(radius, 0.5 * len);
        s.pos = math::scale(math::add(from, to), 0.5);
        s.quat = match math::normalize(d) {
            Some(u) => math::quat_z_to(u),
            None => [0.0; 4], // flagged as degenerate by build()
        };
        s
    }

    /// The ground plane z = 0 of the geom frame (static bodies only; infinite extent).
    pub fn plane() -> Self {
        Self::with_shape(Shape::Plane)
    }

    /// Sets the position in the body frame.
    pub fn at(mut self, pos: Vec3) -> Self {
        self.pos = pos;
        self
    }

    /// Sets the orientation in the body frame.
    pub fn with_quat(mut self, quat: Quat) -> Self {
        self.quat = quat;
        self
    }

    /// Sets the density.
    pub fn density(mut self, density: f64) -> Self {
        self.density = density;
        self
    }

    /// Sets the mass (overrides density).
    pub fn mass(mut self, mass: f64) -> Self {
        self.mass = Some(mass);
        self
    }

    /// Sets the friction coefficient.
    pub fn friction(mut self, friction: f64) -> Self {
        self.friction = friction;
        self
    }

    /// Sets the collision bits.
    pub fn collision(mut self, contype: u32, conaffinity: u32) -> Self {
        self.contype = contype;
        self.conaffinity = conaffinity;
        self
    }

    /// Sets which capsule ends touch planes.
    pub fn ends(mut self, ends: CapsuleEnds) -> Self {
        self.ends = ends;
        self
    }

    /// Sets the name.
    pub fn named(mut self, name: &str) -> Self {
        self.name = name.to_string();
        self
    }
}

/// Description of a hinge for [`ModelBuilder::add_hinge`]. Defaults: anchor at the body
/// origin, unlimited, no armature, no damping, initial angle 0.
#[derive(Clone, Debug, PartialEq)]
pub struct HingeSpec {
    /// Rotation axis in the body frame (normalised by `build`).
    pub axis: Vec3,
    /// Anchor point in the body frame.
    pub anchor: Vec3,
    /// `Some([lower, upper])` (radians) makes the joint limited.
    pub range: Option<[f64; 2]>,
    /// Armature (added to the mass matrix diagonal).
    pub armature: f64,
    /// Viscous damping (implicit).
    pub damping: f64,
    /// Initial angle stored in `Model::qpos0` (the zero of the angle is unchanged).
    pub init: f64,
    /// Name (may be empty).
    pub name: String,
}

impl HingeSpec {
    /// A hinge about `axis` with the defaults.
    pub fn new(axis: Vec3) -> Self {
        HingeSpec { axis, anchor: [0.0; 3], range: None, armature: 0.0, damping: 0.0, init: 0.0, name: String::new() }
    }

    /// Sets the anchor.
    pub fn anchor(mut self, anchor: Vec3) -> Self {
        self.anchor = anchor;
        self
    }

    /// Limits the joint to `[lower, upper]` radians.
    pub fn range(mut self, lower: f64, upper: f64) -> Self {
        self.range = Some([lower, upper]);
        self
    }

    /// Sets the armature.
    pub fn armature(mut self, armature: f64) -> Self {
        self.armature = armature;
        self
    }

    /// Sets the damping.
    pub fn damping(mut self, damping: f64) -> Self {
        self.damping = damping;
        self
    }

    /// Sets the initial angle.
    pub fn init(mut self, angle: f64) -> Self {
        self.init = angle;
        self
    }

    /// Sets the name.
    pub fn named(mut self, name: &str) -> Self {
        self.name = name.to_string();
        self
    }
}

#[derive(Clone, Debug)]
enum MassOverride {
    FromGeoms,
    Mass(f64),
    Explicit { mass: f64, com: Vec3, inertia: Mat3 },
}

#[derive(Clone, Debug)]
struct BodySpec {
    name: String,
    parent: usize,
    pos: Vec3,
    quat: Quat,
    mass: MassOverride,
}

#[derive(Clone, Debug)]
struct JointSpec {
    body: usize,
    kind: JointKind,
    hinge: HingeSpec,
}

#[derive(Clone, Debug)]
struct ActSpec {
    joint: usize,
    gear: f64,
    ctrlrange: Option<[f64; 2]>,
    name: String,
}

/// Incremental construction of a [`Model`]. The `add_*` methods never fail; everything is
/// validated by [`ModelBuilder::build`]. Ids are dense indices in the order of addition and
/// stay valid in the built model.
#[derive(Clone, Debug)]
pub struct ModelBuilder {
    bodies: Vec<BodySpec>,
    joints: Vec<JointSpec>,
    geoms: Vec<(usize, GeomSpec)>,
    actuators: Vec<ActSpec>,
    options: Options,
}

impl Default for ModelBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl ModelBuilder {
    /// An empty scene holding only the world body, with default [`Options`].
    pub fn new() -> Self {
        ModelBuilder {
            bodies: vec![BodySpec {
                name: "world".into(),
                parent: 0,
                pos: [0.0; 3],
                quat: math::QUAT_IDENTITY,
                mass: MassOverride::FromGeoms,
            }],
            joints: Vec::new(),
            geoms: Vec::new(),
            actuators: Vec::new(),
            options: Options::default(),
        }
    }

    /// Adds a body whose frame is at `pos` with orientation `quat` (w, x, y, z; normalised by
    /// `build`) in its parent's frame. The parent must already exist.
    pub fn add_body(&mut self, parent: BodyId, pos: Vec3, quat: Quat) -> BodyId {
        self.bodies.push(BodySpec { name: String::new(), parent: parent.0, pos, quat, mass: MassOverride::FromGeoms });
        BodyId(self.bodies.len() - 1)
    }

    /// Names a body.
    pub fn set_body_name(&mut self, body: BodyId, name: &str) {
        if let Some(b) = self.bodies.get_mut(body.0) {
            b.name = name.to_string();
        }
    }

    /// Gives a body this total mass; the inertia computed from its geoms is scaled to match
    /// (same centre of mass and shape of the inertia ellipsoid).
    pub fn set_body_mass(&mut self, body: BodyId, mass: f64) {
        if let Some(b) = self.bodies.get_mut(body.0) {
            b.mass = MassOverride::Mass(mass);
        }
    }

    /// Gives a body an explicit mass, centre of mass (body frame) and inertia tensor about
    /// the centre of mass (body axes), ignoring its geoms.
    pub fn set_body_inertia(&mut self, body: BodyId, mass: f64, com: Vec3, inertia: Mat3) {
        if let Some(b) = self.bodies.get_mut(body.0) {
            b.mass = MassOverride::Explicit { mass, com, inertia };
        }
    }

    /// Adds a free (floating) joint to a child of the world; it must be the body's only
    /// joint. Its initial qpos is the body's `pos` and `quat`.
    pub fn add_free_joint(&mut self, body: BodyId) -> JointId {
        self.joints.push(JointSpec { body: body.0, kind: JointKind::Free, hinge: HingeSpec::new([0.0, 0.0, 1.0]) });
        JointId(self.joints.len() - 1)
    }

    /// Names a joint.
    pub fn set_joint_name(&mut self, joint: JointId, name: &str) {
        if let Some(j) = self.joints.get_mut(joint.0) {
            j.hinge.name = name.to_string();
        }
    }

    /// Sets a joint's armature and damping after creation (for free joints, whose six dofs
    /// all get them, as in MuJoCo; hinges usually set them through [`HingeSpec`]).
    pub fn set_joint_armature_damping(&mut self, joint: JointId, armature: f64, damping: f64) {
        if let Some(j) = self.joints.get_mut(joint.0) {
            j.hinge.armature = armature;
            j.hinge.damping = damping;
        }
    }

    /// Adds a hinge joint to `body`. Joints must be added in body order (all joints of a body
    /// before those of any later body); several hinges on a body apply in the order added.
    pub fn add_hinge(&mut self, body: BodyId, spec: HingeSpec) -> JointId {
        self.joints.push(JointSpec { body: body.0, kind: JointKind::Hinge, hinge: spec });
        JointId(self.joints.len() - 1)
    }

    /// Adds a geom to `body`.
    pub fn add_geom(&mut self, body: BodyId, spec: GeomSpec) -> GeomId {
        self.geoms.push((body.0, spec));
        GeomId(self.geoms.len() - 1)
    }

    /// Adds a motor on a hinge: torque = `gear * clamp(ctrl, ctrlrange)` (`None`: unclamped).
    pub fn add_actuator(&mut self, joint: JointId, gear: f64, ctrlrange: Option<[f64; 2]>) -> ActuatorId {
        self.actuators.push(ActSpec { joint: joint.0, gear, ctrlrange, name: String::new() });
        ActuatorId(self.actuators.len() - 1)
    }

    /// Names an actuator.
    pub fn set_actuator_name(&mut self, actuator: ActuatorId, name: &str) {
        if let Some(a) = self.actuators.get_mut(actuator.0) {
            a.name = name.to_string();
        }
    }

    /// Replaces the options.
    pub fn set_options(&mut self, options: Options) {
        self.options = options;
    }

    /// The current options (to adjust one field: `let mut o = b.options().clone(); ...`).
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// Number of bodies so far (world included).
    pub fn body_count(&self) -> usize {
        self.bodies.len()
    }

    /// Validates the description and builds the model.
    pub fn build(&self) -> Result<Model, ModelError> {
        let opt = self.options.clone();
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

        // Bodies.
        let nbody = self.bodies.len();
        let mut bodies = Vec::with_capacity(nbody);
        for (i, b) in self.bodies.iter().enumerate() {
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

        // Geoms and inertia from geometry.
        let mut geoms = Vec::with_capacity(self.geoms.len());
        let mut acc: Vec<Vec<(f64, Vec3, Mat3)>> = vec![Vec::new(); nbody];
        for (gi, (body, s)) in self.geoms.iter().enumerate() {
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
            if let Some((m, ic)) = solid_inertia(&s.shape, s.density, s.mass) {
                // Finite inputs can still overflow here (density * size^3, mass * size^2).
                if !(m.is_finite() && ic.iter().flatten().all(|x| x.is_finite())) {
                    return Err(bad(&format!("geom {gi} mass from its density and size"), m));
                }
                let r = math::quat_to_mat(quat);
                acc[*body].push((m, s.pos, math::rotate_tensor(&r, &ic)));
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
        for (i, b) in bodies.iter_mut().enumerate() {
            let (m, c, inertia) = combine(&acc[i]);
            match &self.bodies[i].mass {
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

        // Joints and dofs, in body order.
        let mut joints = Vec::with_capacity(self.joints.len());
        let (mut nq, mut nv) = (0usize, 0usize);
        let mut qpos0 = Vec::new();
        let mut last_body = 0usize;
        for (ji, j) in self.joints.iter().enumerate() {
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
                    // Scaled by the largest component first: the squares of 1e200 overflow
                    // and the axis would become zero.
                    let big = h.axis.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                    let axis = if big > 0.0 && big.is_finite() { math::scale(h.axis, 1.0 / big) } else { h.axis };
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
        for b in &bodies {
            if b.jnt_num > 1 && (b.jnt_adr..b.jnt_adr + b.jnt_num).any(|j| joints[j].kind == JointKind::Free) {
                let body = joints[b.jnt_adr].body;
                return Err(ModelError::BadFreeJoint { body });
            }
        }

        // Dof tree structure.
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

        // Trees: a body with joints whose parent is static starts a tree.
        let mut trees: Vec<Tree> = Vec::new();
        for i in 1..nbody {
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

        // Actuators.
        let mut actuators = Vec::with_capacity(self.actuators.len());
        for (ai, a) in self.actuators.iter().enumerate() {
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

        // Collision pairs: different trees (or tree vs static), masks compatible.
        let (mut plane_pairs, mut geom_pairs) = (Vec::new(), Vec::new());
        let mut nslot = 0;
        for a in 0..geoms.len() {
            for b in a + 1..geoms.len() {
                let (ga, gb) = (&geoms[a], &geoms[b]);
                if ga.tree == gb.tree {
                    continue; // same agent, or both static
                }
                if ga.contype & gb.conaffinity == 0 && gb.contype & ga.conaffinity == 0 {
                    continue;
                }
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
        }
        // Group the geom pairs by tree pair (for the tree-level broad phase), then give slots.
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
        let nlimited = joints.iter().filter(|j| j.limited).count();

        let model = Model {
            opt,
            bodies,
            joints,
            geoms,
            actuators,
            trees,
            nq,
            nv,
            qpos0,
            dof_parent,
            dof_body,
            dof_joint,
            dof_armature,
            dof_damping,
            body_last_dof,
            dof_depth,
            dof_chain_adr,
            dof_chain,
            plane_pairs,
            geom_pairs,
            pair_groups,
            nslot,
            nlimited,
            dof_invweight0: Vec::new(),
        };
        let mut model = model;
        model.dof_invweight0 = crate::crba::check_positive_definite(&model)?;
        Ok(model)
    }
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
    // A norm below 1e-12 is degenerate (the norm is at least the largest component); the
    // rest is scaled by the largest component first: the squares of 1e200 overflow.
    let big = q.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if big < 1e-12 && (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt() < 1e-12 {
        return Err(ModelError::Degenerate { what: what.to_string() });
    }
    let q = q.map(|x| x / big);
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    Ok([q[0] / n, q[1] / n, q[2] / n, q[3] / n])
}

/// Mass and inertia (about the centre, geom axes) of a solid sphere or capsule.
///
/// Capsule (radius r, cylinder height h = 2 * half_length, axis z): the cylinder has
/// `I_z = m r^2 / 2`, `I_x = m (3 r^2 + h^2) / 12`; each hemisphere of mass `m_s / 2` has
/// `I_z = m r^2 / 5 * ...` about the axis and, about a transverse axis through its own centre
/// of mass (at 3r/8 from the flat face), `83/320 m r^2`; moving both to the capsule centre
/// (distance h/2 + 3r/8) gives `m_s (2 r^2 / 5 + h (3 r + 2 h) / 8)` for the pair.
pub(crate) fn solid_inertia(shape: &Shape, density: f64, mass: Option<f64>) -> Option<(f64, Mat3)> {
    use std::f64::consts::PI;
    let diag = |a: f64, b: f64, c: f64| [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]];
    match *shape {
        Shape::Plane => None,
        Shape::Sphere { radius: r } => {
            let vol = 4.0 / 3.0 * PI * r * r * r;
            let m = mass.unwrap_or(density * vol);
            let i = 0.4 * m * r * r;
            Some((m, diag(i, i, i)))
        }
        Shape::Capsule { radius: r, half_length } => {
            let h = 2.0 * half_length;
            let v_sph = 4.0 / 3.0 * PI * r * r * r;
            let v_cyl = PI * r * r * h;
            let m = mass.unwrap_or(density * (v_sph + v_cyl));
            let ms = m * v_sph / (v_sph + v_cyl);
            let mc = m - ms;
            let ix = mc * (3.0 * r * r + h * h) / 12.0 + ms * (0.4 * r * r + h * (3.0 * r + 2.0 * h) / 8.0);
            let iz = mc * r * r / 2.0 + ms * 0.4 * r * r;
            Some((m, diag(ix, ix, iz)))
        }
    }
}

/// Total mass, centre of mass and inertia about it of parts `(mass, centre, inertia about
/// own centre)`.
fn combine(parts: &[(f64, Vec3, Mat3)]) -> (f64, Vec3, Mat3) {
    let m: f64 = parts.iter().map(|p| p.0).sum();
    if m <= 0.0 {
        return (0.0, [0.0; 3], [[0.0; 3]; 3]);
    }
    let mut c = [0.0; 3];
    for p in parts {
        c = math::add_scaled(c, p.1, p.0 / m);
    }
    let mut i = [[0.0; 3]; 3];
    for p in parts {
        i = math::mat_add(&i, &math::mat_add(&p.2, &math::point_inertia(p.0, math::sub(p.1, c))));
    }
    (m, c, i)
}
