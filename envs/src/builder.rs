//! [`ModelBuilder`]: the one way to make a [`Model`] (used by the MJCF and Brax loaders and by
//! tests). See the module documentation of [`crate::model`] for an overview and an example.
//!
//! The `add_*` methods record a description; [`ModelBuilder::build`] checks and compiles it
//! in named stages (module `stages`: options, bodies, geoms, inertia from geometry (module `inertia`),
//! joints and DoFs, the DoF tree, kinematic trees, actuators, contact pairs).

mod inertia;
mod stages;

use crate::math::{self, Mat3, Quat, Vec3};
use crate::model::{ActuatorId, BodyId, CapsuleEnds, GeomId, JointId, JointKind, Model, ModelError, Options, Shape};
use stages::Joints;

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

    /// Validates the description and builds the model, stage by stage as MuJoCo's compiler
    /// does (each stage is a function of the private module `stages` saying what it reads and writes).
    pub fn build(&self) -> Result<Model, ModelError> {
        stages::check_options(&self.options)?;
        let mut bodies = stages::bodies(&self.bodies)?;
        let mut geoms = stages::geoms(&self.geoms, bodies.len())?;
        stages::inertia(&self.bodies, &self.geoms, &geoms, &mut bodies)?;
        let Joints { joints, nq, nv, qpos0 } = stages::joints(&self.joints, &mut bodies)?;
        let dofs = stages::dof_tree(&bodies, &joints, nv);
        let trees = stages::trees(&mut bodies, &mut geoms)?;
        let actuators = stages::actuators(&self.actuators, &joints)?;
        let pairs = stages::contact_pairs(&geoms);
        let nlimited = joints.iter().filter(|j| j.limited).count();
        let mut model = Model {
            opt: self.options.clone(),
            bodies,
            joints,
            geoms,
            actuators,
            trees,
            nq,
            nv,
            qpos0,
            dof_parent: dofs.parent,
            dof_body: dofs.body,
            dof_joint: dofs.joint,
            dof_armature: dofs.armature,
            dof_damping: dofs.damping,
            body_last_dof: dofs.body_last_dof,
            dof_depth: dofs.depth,
            dof_chain_adr: dofs.chain_adr,
            dof_chain: dofs.chain,
            plane_pairs: pairs.plane_pairs,
            geom_pairs: pairs.geom_pairs,
            pair_groups: pairs.pair_groups,
            nslot: pairs.nslot,
            nlimited,
            dof_invweight0: Vec::new(),
        };
        // Positive definiteness at qpos0, and MuJoCo's dof_invweight0 from the same factor.
        model.dof_invweight0 = crate::crba::check_positive_definite(&model)?;
        Ok(model)
    }
}
