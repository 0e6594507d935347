//! Typed Brax v1 system configs: the subset MeBen's morphologies use.
//!
//! [`SystemConfig::from_message`] converts a parsed text-format tree
//! ([`super::prototext::Message`]) into [`SystemConfig`], checking every field and the
//! structure of the agent (one connected tree of bodies). Errors name the source, the line and
//! column, the field path and the offending value.
//!
//! What happens to each field (see also `docs/SIMULATOR.md`, "Brax v1 configs"):
//!
//! | message | kept and used | kept, unused | ignored on purpose | refused |
//! |---|---|---|---|---|
//! | top level | `bodies`, `joints`, `actuators` | | scene and solver settings ([`IGNORED_TOP_LEVEL`]) | `forces`, `frozen` |
//! | body | `name`, `mass`, `colliders` | `inertia` (always 1,1,1: an artefact of Brax's spring solver) | | `frozen` |
//! | collider | `position`, `rotation`, `sphere`, `capsule` (`radius`, `length`, `end`) | | `material` | other shapes, `no_contact` |
//! | joint | `name`, `parent`, `child`, offsets, `rotation`, `reference_rotation`, `angle_limit`, `angular_damping` | `stiffness` | `spring_damping`, `limit_strength` | |
//! | actuator | `name`, `joint`, `strength`, `torque {}` | | | `angle {}` (position servos) |
//!
//! Any other field name is an error, so that typos do not pass silently. Every number is
//! checked against its physical range ([`crate::limits`]: masses, sizes, offsets, angles,
//! damping, strengths), so that an absurd value is refused at its line rather than reported
//! later as a singular mass matrix or a non-finite gradient.

use super::error::{BraxError, Location};
use super::prototext::{Field, Message, Value};
use super::rotation::Vec3;
use crate::limits::{self, Limit};
use std::collections::{HashMap, HashSet};

/// Top-level fields of Brax v1's `Config` that describe the scene or Brax's own solver
/// (friction, gravity, time step, ...). The project's simulator sets these itself, so they
/// are accepted and ignored.
pub const IGNORED_TOP_LEVEL: &[&str] = &[
    "friction",
    "gravity",
    "angular_damping",
    "velocity_damping",
    "baumgarte_erp",
    "spring_baumgarte_erp",
    "elasticity",
    "collide_include",
    "dt",
    "substeps",
    "defaults",
    "dynamics_mode",
    "solver_scale_pos",
    "solver_scale_ang",
    "solver_scale_collide",
];

/// A position in the config text (1-based line and column), kept for error messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct TextPos {
    /// 1-based line.
    pub line: usize,
    /// 1-based column.
    pub column: usize,
}

impl TextPos {
    /// The position of a field's name.
    pub fn of(field: &Field) -> TextPos {
        TextPos { line: field.line, column: field.column }
    }
}

/// A whole agent: bodies, the joints between them and the motors on the joints.
#[derive(Clone, Debug, PartialEq)]
pub struct SystemConfig {
    /// Where the config came from (file path or built-in name), for messages.
    pub source: String,
    /// Bodies in file order.
    pub bodies: Vec<BodyConfig>,
    /// Joints in file order.
    pub joints: Vec<JointConfig>,
    /// Actuators in file order.
    pub actuators: Vec<ActuatorConfig>,
}

/// A rigid body.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyConfig {
    /// Unique name.
    pub name: String,
    /// Mass in kg (used as is).
    pub mass: f64,
    /// Collision shapes, which also give the inertia (see `to_model`).
    pub colliders: Vec<ColliderConfig>,
    /// Brax's `inertia` field when present; kept for completeness but never used (it is
    /// always (1, 1, 1) in these files, an artefact of Brax's spring solver).
    pub inertia: Option<Vec3>,
    /// Where the `bodies` field starts.
    pub at: TextPos,
}

/// A collision shape attached to a body.
#[derive(Clone, Debug, PartialEq)]
pub struct ColliderConfig {
    /// Centre in the body frame (m).
    pub position: Vec3,
    /// Orientation in the body frame: Euler angles in degrees, intrinsic x-y'-z''.
    pub rotation: Vec3,
    /// The shape.
    pub shape: ColliderShape,
    /// Where the `colliders` field starts.
    pub at: TextPos,
}

/// The shape of a collider.
#[derive(Clone, Debug, PartialEq)]
pub enum ColliderShape {
    /// A sphere.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// A capsule along the collider frame's local z axis.
    Capsule {
        /// Radius (m).
        radius: f64,
        /// Total length including both caps (m); at least 2 * radius.
        length: f64,
        /// Brax's `end`: 0 both caps collide with the ground, 1 only the +z cap, -1 only the
        /// -z cap. Passed to the simulator when `BraxPhysics::capsule_ends` is set.
        end: i32,
    },
}

/// A joint of 1 or 2 rotational degrees of freedom between two bodies.
#[derive(Clone, Debug, PartialEq)]
pub struct JointConfig {
    /// Unique name.
    pub name: String,
    /// Parent body name.
    pub parent: String,
    /// Child body name.
    pub child: String,
    /// The joint point in the parent frame (m).
    pub parent_offset: Vec3,
    /// The joint point in the child frame (m).
    pub child_offset: Vec3,
    /// Joint frame in the child frame: Euler degrees, intrinsic x-y'-z''. The 1st DoF turns
    /// about this frame's x axis, the 2nd about its y axis.
    pub rotation: Vec3,
    /// The child's orientation relative to the parent at zero joint angles (Euler degrees).
    pub reference_rotation: Vec3,
    /// One range per DoF, in degrees.
    pub angle_limits: Vec<AngleLimit>,
    /// Brax's relative angular velocity damping (N m s / rad).
    pub angular_damping: f64,
    /// Brax's joint spring stiffness; kept but meaningless in reduced coordinates.
    pub stiffness: f64,
    /// Where the `joints` field starts.
    pub at: TextPos,
    /// Where its `parent` field is.
    pub parent_at: TextPos,
    /// Where its `child` field is.
    pub child_at: TextPos,
}

/// The range of one joint DoF, in degrees (a missing bound is 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AngleLimit {
    /// Lower bound (degrees).
    pub min: f64,
    /// Upper bound (degrees).
    pub max: f64,
}

/// A torque motor on every DoF of one joint.
#[derive(Clone, Debug, PartialEq)]
pub struct ActuatorConfig {
    /// Name.
    pub name: String,
    /// The joint driven.
    pub joint: String,
    /// Torque at action 1 (N m), the same for each DoF of the joint.
    pub strength: f64,
    /// Where the `actuators` field starts.
    pub at: TextPos,
    /// Where its `joint` field is.
    pub joint_at: TextPos,
}

impl SystemConfig {
    /// Converts a parsed tree into a checked config. `source` names the text in errors.
    pub fn from_message(message: &Message, source: &str) -> Result<SystemConfig, BraxError> {
        let top = Reader { msg: message, source, path: String::new() };
        top.check_names(&["bodies", "joints", "actuators"], IGNORED_TOP_LEVEL, &["forces", "frozen"])?;
        let mut config =
            SystemConfig { source: source.to_string(), bodies: Vec::new(), joints: Vec::new(), actuators: Vec::new() };
        for (i, f) in message.fields_named("bodies").enumerate() {
            config.bodies.push(read_body(&top.child(f, "bodies", i)?, f)?);
        }
        for (i, f) in message.fields_named("joints").enumerate() {
            config.joints.push(read_joint(&top.child(f, "joints", i)?, f)?);
        }
        for (i, f) in message.fields_named("actuators").enumerate() {
            config.actuators.push(read_actuator(&top.child(f, "actuators", i)?, f)?);
        }
        config.check_structure()?;
        Ok(config)
    }

    /// Index of the body with this name.
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    /// Index of the joint with this name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Index of the root body: the only body that is no joint's child (checked on load).
    pub fn root_body(&self) -> usize {
        let children: HashSet<&str> = self.joints.iter().map(|j| j.child.as_str()).collect();
        (0..self.bodies.len()).find(|&b| !children.contains(self.bodies[b].name.as_str())).unwrap_or(0)
    }

    /// Total number of joint DoFs (hinges).
    pub fn dof(&self) -> usize {
        self.joints.iter().map(|j| j.angle_limits.len()).sum()
    }

    /// Number of actuated DoFs: the length of the action vector.
    pub fn actuated_dof(&self) -> usize {
        let joints = first_index(self.joints.iter().map(|j| j.name.as_str()));
        self.actuators
            .iter()
            .filter_map(|a| joints.get(a.joint.as_str()).copied())
            .map(|j| self.joints[j].angle_limits.len())
            .sum()
    }

    /// Checks that the bodies and joints form one tree and that actuators name joints, in
    /// this order: bodies (present, names unique), joints (names unique, known bodies, one
    /// parent per body), one root, no cycle, actuators (known joints, each driven once). Names
    /// are looked up in maps built once, so the checks are linear in the size of the config.
    fn check_structure(&self) -> Result<(), BraxError> {
        let body_of = first_index(self.bodies.iter().map(|b| b.name.as_str()));
        self.check_bodies(&body_of)?;
        let parent_joint = self.check_joints(&body_of)?;
        let root = self.check_one_root(&parent_joint)?;
        self.check_no_cycle(&body_of, &parent_joint, root)?;
        self.check_actuators()
    }

    /// A structure error at `at`.
    fn structure_error(&self, at: TextPos, field: String, value: Option<String>, message: String) -> BraxError {
        BraxError::Config {
            location: Location { source: self.source.clone(), line: at.line, column: at.column },
            field,
            value,
            message,
        }
    }

    /// At least one body; no body name given twice (the second is reported).
    fn check_bodies(&self, body_of: &HashMap<&str, usize>) -> Result<(), BraxError> {
        if self.bodies.is_empty() {
            let start = TextPos { line: 1, column: 1 };
            return Err(self.structure_error(start, "bodies".into(), None, "the config has no bodies".into()));
        }
        for (i, b) in self.bodies.iter().enumerate() {
            let first = body_of[b.name.as_str()];
            if first != i {
                return Err(self.structure_error(
                    b.at,
                    "bodies.name".into(),
                    Some(format!("{:?}", b.name)),
                    format!("duplicate body name (first defined at line {})", self.bodies[first].at.line),
                ));
            }
        }
        Ok(())
    }

    /// Joints in file order: unique names, known parent and child, not a body to itself, and
    /// several joints on one child only from the same parent at the same point. Returns the
    /// joints of each body as a child.
    fn check_joints(&self, body_of: &HashMap<&str, usize>) -> Result<Vec<Vec<usize>>, BraxError> {
        let joint_of = first_index(self.joints.iter().map(|j| j.name.as_str()));
        let known_bodies = || self.bodies.iter().map(|b| format!("{:?}", b.name)).collect::<Vec<_>>().join(", ");
        let mut parent_joint: Vec<Vec<usize>> = vec![Vec::new(); self.bodies.len()];
        for (ji, j) in self.joints.iter().enumerate() {
            let first = joint_of[j.name.as_str()];
            if first != ji {
                return Err(self.structure_error(
                    j.at,
                    format!("joints[{:?}].name", j.name),
                    Some(format!("{:?}", j.name)),
                    format!("duplicate joint name (first defined at line {})", self.joints[first].at.line),
                ));
            }
            let index = |field: &str, name: &str, at: TextPos| {
                body_of.get(name).copied().ok_or_else(|| {
                    self.structure_error(
                        at,
                        format!("joints[{:?}].{field}", j.name),
                        Some(format!("{name:?}")),
                        format!("unknown body name; known bodies: {}", known_bodies()),
                    )
                })
            };
            let p = index("parent", &j.parent, j.parent_at)?;
            let c = index("child", &j.child, j.child_at)?;
            let child_error = |message: String| {
                self.structure_error(
                    j.child_at,
                    format!("joints[{:?}].child", j.name),
                    Some(format!("{:?}", j.child)),
                    message,
                )
            };
            if p == c {
                return Err(child_error("a joint cannot connect a body to itself".into()));
            }
            if let Some(&other) = parent_joint[c].first() {
                let o = &self.joints[other];
                if o.parent != j.parent {
                    return Err(child_error(format!(
                        "body has two parents: it is already the child of joint {:?} (line {}) whose parent is {:?}",
                        o.name, o.at.line, o.parent
                    )));
                }
                if !same(o.parent_offset, j.parent_offset)
                    || !same(o.child_offset, j.child_offset)
                    || !same(o.reference_rotation, j.reference_rotation)
                {
                    return Err(child_error(format!(
                        "body is already the child of joint {:?} (line {}) from the same parent: several joints on one child must share parent_offset, child_offset and reference_rotation",
                        o.name, o.at.line
                    )));
                }
            }
            parent_joint[c].push(ji);
        }
        Ok(parent_joint)
    }

    /// Exactly one body without a parent joint (one connected agent); returns it.
    fn check_one_root(&self, parent_joint: &[Vec<usize>]) -> Result<usize, BraxError> {
        let roots: Vec<usize> = (0..self.bodies.len()).filter(|&b| parent_joint[b].is_empty()).collect();
        if roots.len() == 1 {
            return Ok(roots[0]);
        }
        let names: Vec<String> = roots.iter().map(|&b| format!("{:?}", self.bodies[b].name)).collect();
        let (at, message) = match roots.first() {
            Some(&b) => (
                self.bodies[b].at,
                format!(
                    "a config must describe one connected agent, but several bodies have no parent joint: {}",
                    names.join(", ")
                ),
            ),
            None => (
                self.joints.first().map_or(TextPos { line: 1, column: 1 }, |j| j.at),
                "every body has a parent joint: the joints form a cycle".into(),
            ),
        };
        Err(self.structure_error(at, "joints".into(), None, message))
    }

    /// Every body reaches the root by following parents: the first body (in file order) that
    /// does not is reported, at the joint taken at the step after as many steps as bodies. A
    /// walk stops at a body already known to reach the root, so each body is walked through
    /// once.
    fn check_no_cycle(
        &self,
        body_of: &HashMap<&str, usize>,
        parent_joint: &[Vec<usize>],
        root: usize,
    ) -> Result<(), BraxError> {
        let mut reaches_root = vec![false; self.bodies.len()];
        let mut path = Vec::new();
        for start in 0..self.bodies.len() {
            let mut b = start;
            let mut steps = 0;
            path.clear();
            while !reaches_root[b]
                && let Some(&j) = parent_joint[b].first()
            {
                path.push(b);
                b = body_of.get(self.joints[j].parent.as_str()).copied().unwrap_or(root);
                steps += 1;
                if steps > self.bodies.len() {
                    return Err(self.structure_error(
                        self.joints[j].parent_at,
                        format!("joints[{:?}].parent", self.joints[j].name),
                        Some(format!("{:?}", self.joints[j].parent)),
                        format!("the joints form a cycle: body {:?} is its own ancestor", self.bodies[start].name),
                    ));
                }
            }
            for &p in &path {
                reaches_root[p] = true;
            }
        }
        Ok(())
    }

    /// Actuators in file order: each names a known joint, and no joint is driven twice (the
    /// second actuator is reported).
    fn check_actuators(&self) -> Result<(), BraxError> {
        let joint_of = first_index(self.joints.iter().map(|j| j.name.as_str()));
        let mut driven: HashMap<&str, usize> = HashMap::new();
        for (ai, a) in self.actuators.iter().enumerate() {
            let error = |message: String| {
                self.structure_error(
                    a.joint_at,
                    format!("actuators[{:?}].joint", a.name),
                    Some(format!("{:?}", a.joint)),
                    message,
                )
            };
            if !joint_of.contains_key(a.joint.as_str()) {
                let known: Vec<String> = self.joints.iter().map(|j| format!("{:?}", j.name)).collect();
                return Err(error(format!("unknown joint name; known joints: {}", known.join(", "))));
            }
            if let Some(&first) = driven.get(a.joint.as_str()) {
                let first = &self.actuators[first];
                return Err(error(format!(
                    "joint already driven by actuator {:?} (line {})",
                    first.name, first.at.line
                )));
            }
            driven.insert(a.joint.as_str(), ai);
        }
        Ok(())
    }
}

/// Index of the first occurrence of each name.
pub(crate) fn first_index<'a>(names: impl Iterator<Item = &'a str>) -> HashMap<&'a str, usize> {
    let mut map = HashMap::new();
    for (i, name) in names.enumerate() {
        map.entry(name).or_insert(i);
    }
    map
}

/// Whether two vectors agree to 1e-9 (offsets and angles written by the same generator).
fn same(a: Vec3, b: Vec3) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= 1e-9)
}

/// Reads a `bodies` message.
fn read_body(r: &Reader<'_>, field: &Field) -> Result<BodyConfig, BraxError> {
    r.check_names(&["name", "mass", "colliders", "inertia"], &[], &["frozen"])?;
    let name = r.string(r.required("name")?)?;
    let r = r.renamed(&name);
    let mass_field = r.required("mass")?;
    let mass = r.number(mass_field)?;
    if mass <= 0.0 {
        return Err(r.bad(mass_field, "mass must be positive"));
    }
    r.within(mass_field, mass, &Limit { zero: false, ..limits::MASS })?;
    let mut colliders = Vec::new();
    for (i, f) in r.msg.fields_named("colliders").enumerate() {
        colliders.push(read_collider(&r.child(f, "colliders", i)?, f)?);
    }
    let inertia = r.optional("inertia")?.map(|f| r.vec3(f, &limits::INERTIA)).transpose()?;
    Ok(BodyConfig { name, mass, colliders, inertia, at: TextPos::of(field) })
}

/// Reads a `colliders` message.
fn read_collider(r: &Reader<'_>, field: &Field) -> Result<ColliderConfig, BraxError> {
    r.check_names(
        &["position", "rotation", "sphere", "capsule"],
        &["material"],
        &["box", "plane", "heightMap", "mesh", "clipped_plane", "no_contact"],
    )?;
    let position = r.vec3_or_zero("position", &limits::LENGTH)?;
    let rotation = r.vec3_or_zero("rotation", &limits::ANGLE_DEGREES)?;
    let sphere = r.optional("sphere")?;
    let capsule = r.optional("capsule")?;
    let shape = match (sphere, capsule) {
        (Some(s), None) => {
            let s = r.child(s, "sphere", 0)?;
            s.check_names(&["radius"], &[], &[])?;
            let radius = s.positive(s.required("radius")?, &limits::SIZE)?;
            ColliderShape::Sphere { radius }
        }
        (None, Some(c)) => {
            let c = r.child(c, "capsule", 0)?;
            c.check_names(&["radius", "length", "end"], &[], &[])?;
            let radius = c.positive(c.required("radius")?, &limits::SIZE)?;
            let length_field = c.required("length")?;
            let length = c.positive(length_field, &limits::SIZE)?;
            if length < 2.0 * radius * (1.0 - 1e-9) {
                return Err(c.bad(
                    length_field,
                    &format!("capsule length (total, caps included) must be at least 2 * radius = {}", 2.0 * radius),
                ));
            }
            let end = match c.optional("end")? {
                None => 0,
                Some(f) => {
                    let v = c.number(f)?;
                    if v != 0.0 && v != 1.0 && v != -1.0 {
                        return Err(c.bad(f, "capsule `end` must be -1, 0 or 1"));
                    }
                    v as i32
                }
            };
            ColliderShape::Capsule { radius, length, end }
        }
        (Some(_), Some(c)) => {
            return Err(r.bad(c, "a collider has exactly one shape, found both `sphere` and `capsule`"));
        }
        (None, None) => {
            return Err(r.missing("sphere` or `capsule"));
        }
    };
    Ok(ColliderConfig { position, rotation, shape, at: TextPos::of(field) })
}

/// Reads a `joints` message.
fn read_joint(r: &Reader<'_>, field: &Field) -> Result<JointConfig, BraxError> {
    r.check_names(
        &[
            "name",
            "parent",
            "child",
            "parent_offset",
            "child_offset",
            "rotation",
            "reference_rotation",
            "angle_limit",
            "angular_damping",
            "stiffness",
        ],
        &["spring_damping", "limit_strength"],
        &[],
    )?;
    let name = r.string(r.required("name")?)?;
    let r = r.renamed(&name);
    let parent_field = r.required("parent")?;
    let child_field = r.required("child")?;
    let parent = r.string(parent_field)?;
    let child = r.string(child_field)?;
    let mut angle_limits = Vec::new();
    for (i, f) in r.msg.fields_named("angle_limit").enumerate() {
        let l = r.child(f, "angle_limit", i)?;
        l.check_names(&["min", "max"], &[], &[])?;
        let angle = |f: &Field| l.number(f).and_then(|x| l.within(f, x, &limits::ANGLE_DEGREES));
        let min = l.optional("min")?.map(angle).transpose()?.unwrap_or(0.0);
        let max_field = l.optional("max")?;
        let max = max_field.map(angle).transpose()?.unwrap_or(0.0);
        if min > max {
            return Err(l.bad(max_field.unwrap_or(f), &format!("angle limit has min {min} > max {max}")));
        }
        angle_limits.push(AngleLimit { min, max });
    }
    if angle_limits.is_empty() || angle_limits.len() > 2 {
        let message = format!(
            "a joint needs 1 or 2 `angle_limit` entries (one per DoF; 3-DoF spherical joints are not supported), found {}",
            angle_limits.len()
        );
        return Err(BraxError::Config {
            location: r.location(field.line, field.column),
            field: format!("{}.angle_limit", r.path),
            value: None,
            message,
        });
    }
    let angular_damping = r.non_negative_or_zero("angular_damping", &limits::DAMPING)?;
    // Unused (Brax's joint spring); any finite non-negative value is accepted.
    let unbounded = Limit { min: 0.0, max: f64::MAX, ..limits::DAMPING };
    let stiffness = r.non_negative_or_zero("stiffness", &unbounded)?;
    Ok(JointConfig {
        name,
        parent,
        child,
        parent_offset: r.vec3_or_zero("parent_offset", &limits::LENGTH)?,
        child_offset: r.vec3_or_zero("child_offset", &limits::LENGTH)?,
        rotation: r.vec3_or_zero("rotation", &limits::ANGLE_DEGREES)?,
        reference_rotation: r.vec3_or_zero("reference_rotation", &limits::ANGLE_DEGREES)?,
        angle_limits,
        angular_damping,
        stiffness,
        at: TextPos::of(field),
        parent_at: TextPos::of(parent_field),
        child_at: TextPos::of(child_field),
    })
}

/// Reads an `actuators` message.
fn read_actuator(r: &Reader<'_>, field: &Field) -> Result<ActuatorConfig, BraxError> {
    r.check_names(&["name", "joint", "strength", "torque"], &[], &["angle"])?;
    let joint_field = r.required("joint")?;
    let joint_at = TextPos::of(joint_field);
    let joint = r.string(joint_field)?;
    let name = match r.optional("name")? {
        Some(f) => r.string(f)?,
        None => joint.clone(),
    };
    let r = r.renamed(&name);
    if let Some(t) = r.optional("torque")? {
        r.message(t)?;
    }
    let strength = r.non_negative(r.required("strength")?, &limits::TORQUE)?;
    Ok(ActuatorConfig { name, joint, strength, at: TextPos::of(field), joint_at })
}

/// A message being read, with its source and dotted path for error messages.
struct Reader<'a> {
    msg: &'a Message,
    source: &'a str,
    path: String,
}

impl<'a> Reader<'a> {
    fn location(&self, line: usize, column: usize) -> Location {
        Location { source: self.source.to_string(), line, column }
    }

    fn field_path(&self, name: &str) -> String {
        if self.path.is_empty() { name.to_string() } else { format!("{}.{name}", self.path) }
    }

    /// An error about the value of `field`.
    fn bad(&self, field: &Field, message: &str) -> BraxError {
        BraxError::Config {
            location: self.location(field.line, field.column),
            field: self.field_path(&field.name),
            value: Some(field.value.describe()),
            message: message.to_string(),
        }
    }

    /// An error about a missing field `name` in this message.
    fn missing(&self, name: &str) -> BraxError {
        BraxError::Config {
            location: self.location(self.msg.line, self.msg.column),
            field: self.field_path(name),
            value: None,
            message: format!("missing required field `{name}`"),
        }
    }

    /// The reader of the nested message in `field` (the i-th of its name).
    fn child(&self, field: &'a Field, name: &str, i: usize) -> Result<Reader<'a>, BraxError> {
        let msg = self.message(field)?;
        Ok(Reader { msg, source: self.source, path: format!("{}[{i}]", self.field_path(name)) })
    }

    /// The same reader with the last path element's index replaced by a name.
    fn renamed(&self, name: &str) -> Reader<'a> {
        let base = match self.path.rfind('[') {
            Some(k) => &self.path[..k],
            None => &self.path,
        };
        Reader { msg: self.msg, source: self.source, path: format!("{base}[{name:?}]") }
    }

    /// Rejects unknown and unsupported field names; `ignored` names are accepted.
    fn check_names(&self, known: &[&str], ignored: &[&str], refused: &[&str]) -> Result<(), BraxError> {
        for f in &self.msg.fields {
            let name = f.name.as_str();
            if known.contains(&name) || ignored.contains(&name) {
                continue;
            }
            let message = if refused.contains(&name) {
                format!("`{name}` is a Brax feature this loader does not support")
            } else {
                format!("unknown field `{name}`; expected one of: {}", known.join(", "))
            };
            return Err(BraxError::Config {
                location: self.location(f.line, f.column),
                field: self.field_path(name),
                value: Some(f.value.describe()),
                message,
            });
        }
        Ok(())
    }

    /// The field `name` if present; an error if it is given more than once.
    fn optional(&self, name: &str) -> Result<Option<&'a Field>, BraxError> {
        let mut it = self.msg.fields.iter().filter(|f| f.name == name);
        let first = it.next();
        if let (Some(first), Some(second)) = (first, it.next()) {
            return Err(self.bad(second, &format!("field given twice (first at line {})", first.line)));
        }
        Ok(first)
    }

    /// The field `name`; an error if it is absent or repeated.
    fn required(&self, name: &str) -> Result<&'a Field, BraxError> {
        self.optional(name)?.ok_or_else(|| self.missing(name))
    }

    fn message(&self, field: &'a Field) -> Result<&'a Message, BraxError> {
        match &field.value {
            Value::Message(m) => Ok(m),
            _ => Err(self.bad(field, "expected a message `{ ... }`")),
        }
    }

    fn string(&self, field: &Field) -> Result<String, BraxError> {
        match &field.value {
            Value::String(s) => Ok(s.clone()),
            _ => Err(self.bad(field, "expected a quoted string")),
        }
    }

    fn number(&self, field: &Field) -> Result<f64, BraxError> {
        match &field.value {
            Value::Number { value, .. } if value.is_finite() => Ok(*value),
            Value::Number { .. } => Err(self.bad(field, "expected a finite number")),
            _ => Err(self.bad(field, "expected a number")),
        }
    }

    /// `value` (read from `field`) if `limit` accepts it, else an error naming its range.
    fn within(&self, field: &Field, value: f64, limit: &Limit) -> Result<f64, BraxError> {
        limit.check(value).map_err(|m| self.bad(field, &m))
    }

    fn positive(&self, field: &Field, limit: &Limit) -> Result<f64, BraxError> {
        let v = self.number(field)?;
        if v > 0.0 { self.within(field, v, limit) } else { Err(self.bad(field, "expected a positive number")) }
    }

    fn non_negative(&self, field: &Field, limit: &Limit) -> Result<f64, BraxError> {
        let v = self.number(field)?;
        if v >= 0.0 { self.within(field, v, limit) } else { Err(self.bad(field, "expected a number >= 0")) }
    }

    fn non_negative_or_zero(&self, name: &str, limit: &Limit) -> Result<f64, BraxError> {
        Ok(self.optional(name)?.map(|f| self.non_negative(f, limit)).transpose()?.unwrap_or(0.0))
    }

    /// A `{ x: .. y: .. z: .. }` message, each component within `limit`; missing components
    /// are 0 (an error, at the message, when `limit` refuses 0).
    fn vec3(&self, field: &'a Field, limit: &Limit) -> Result<Vec3, BraxError> {
        let v = self.child(field, &field.name, 0)?;
        let v = Reader { path: self.field_path(&field.name), ..v };
        v.check_names(&["x", "y", "z"], &[], &[])?;
        let mut out = [0.0; 3];
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            match v.optional(axis)? {
                Some(f) => out[k] = v.within(f, v.number(f)?, limit)?,
                None => {
                    if let Err(m) = limit.check(0.0) {
                        return Err(self.bad(field, &format!("`{axis}` is missing, so 0: {m}")));
                    }
                }
            }
        }
        Ok(out)
    }

    fn vec3_or_zero(&self, name: &str, limit: &Limit) -> Result<Vec3, BraxError> {
        Ok(self.optional(name)?.map(|f| self.vec3(f, limit)).transpose()?.unwrap_or([0.0; 3]))
    }
}
