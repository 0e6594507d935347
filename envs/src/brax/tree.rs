//! An agent as a kinematic tree in the simulator's conventions (MEBEN.md section 1):
//! bodies placed in their parent's frame, hinges with axes and anchors in the body frame,
//! geoms, masses, motors, all in SI units and radians. No simulator types are needed here
//! except [`CapsuleEnds`]; [`super::to_model`] hands the tree to the `ModelBuilder`. The
//! MeBen tasks build every agent from one: [`AgentTree::from_config`] makes it from a Brax
//! config, [`crate::mjcf_agent`] from an MJCF file.
//!
//! Semantics of [`AgentTree::from_config`]:
//! - the root body (the one that is no joint's child) gets a free joint; its frame is the
//!   config's root frame;
//! - a joint places its child at `pos = parent_offset - R(reference_rotation) * child_offset`
//!   with orientation `reference_rotation` in the parent frame, so that the joint point
//!   coincides in both bodies at zero angle;
//! - the joint frame is `rotation` (Euler degrees, intrinsic x-y'-z'') in the child frame; the
//!   1st DoF is a hinge about the joint frame's x axis, the 2nd about its y axis, both through
//!   `child_offset`; applied in that order (the 1st axis is fixed in the parent, the 2nd turns
//!   with the child: a Cardan joint). Positive angles turn the child right-handedly about the
//!   axis. Limits are `angle_limit` in radians;
//! - a body that is the child of several joints from the same parent at the same point (the
//!   sumo unimal `5506-13-5-02-21-35-41` has one) gets all their hinges, in file order;
//! - colliders become geoms: a capsule's axis is the collider's local z and `length` is the
//!   total length, so the cylinder half-length is `length / 2 - radius`; a capsule of length
//!   2 * radius is a sphere;
//! - bodies are ordered depth first from the root, children in the order of their first joint
//!   in the file; hinges (qpos after the free joint) follow that order; motors follow the
//!   actuators' file order, one per DoF of the driven joint.

use super::config::{ColliderShape, SystemConfig, first_index};
use super::physics::BraxPhysics;
use super::rotation::{
    IDENTITY, Quat, Vec3, add, euler_degrees_to_quat, quat_from_axis_angle, quat_mul, quat_rotate, sub,
};
use crate::model::CapsuleEnds;
use std::collections::{HashMap, HashSet};

/// The agent as a tree of bodies, ready for a model builder.
#[derive(Clone, Debug, PartialEq)]
pub struct AgentTree {
    /// Bodies depth first; `bodies[0]` is the root.
    pub bodies: Vec<TreeBody>,
    /// Motors in the order of the action vector.
    pub motors: Vec<TreeMotor>,
}

/// One rigid body of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeBody {
    /// The config's body name.
    pub name: String,
    /// Index of the body in [`SystemConfig::bodies`] (MJCF: the body's index in the file's
    /// model, world = 0).
    pub config_index: usize,
    /// Parent index in [`AgentTree::bodies`] (`None` for the root).
    pub parent: Option<usize>,
    /// Body frame origin in the parent frame at zero joint angles (m; zero for the root).
    pub pos: Vec3,
    /// Body frame orientation in the parent frame at zero joint angles.
    pub quat: Quat,
    /// Mass (kg), from the config.
    pub mass: f64,
    /// The mass distribution when it is known exactly (MJCF: from each geom's own density or
    /// mass); `None` (Brax): the geoms' inertia at uniform density, scaled to `mass`.
    pub inertia: Option<TreeInertia>,
    /// Hinges moving this body relative to its parent, applied in order.
    pub hinges: Vec<TreeHinge>,
    /// Collision geometry, which also gives the inertia.
    pub geoms: Vec<TreeGeom>,
}

/// A body's mass distribution in its own frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeInertia {
    /// Centre of mass in the body frame (m).
    pub com: Vec3,
    /// Rotational inertia about the centre of mass, body axes (kg m^2).
    pub inertia: [[f64; 3]; 3],
}

/// A hinge (one DoF of a Brax joint, or an MJCF hinge).
#[derive(Clone, Debug, PartialEq)]
pub struct TreeHinge {
    /// Joint name, with `.1`/`.2` appended for the DoFs of a 2-DoF joint.
    pub name: String,
    /// Index of the Brax joint in [`SystemConfig::joints`] (MJCF: the joint's index in the
    /// file's model).
    pub config_joint: usize,
    /// Which DoF of the Brax joint (0: about the joint frame's x, 1: about its y).
    pub dof: usize,
    /// Unit axis in the body frame.
    pub axis: Vec3,
    /// A point of the axis in the body frame (the joint point, `child_offset`).
    pub anchor: Vec3,
    /// Limits in radians.
    pub range: [f64; 2],
    /// Armature (kg m^2).
    pub armature: f64,
    /// Viscous damping (N m s / rad).
    pub damping: f64,
}

impl TreeHinge {
    /// The middle of the range: the rest angle.
    pub fn rest_angle(&self) -> f64 {
        0.5 * (self.range[0] + self.range[1])
    }
}

/// Shape of a geom, in the simulator's terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TreeShape {
    /// A sphere.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// A capsule along the geom's local z axis.
    Capsule {
        /// Radius (m).
        radius: f64,
        /// Half-length of the cylindrical part (m).
        half_length: f64,
    },
}

/// A collision geom in the body frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeGeom {
    /// Shape.
    pub shape: TreeShape,
    /// Centre in the body frame.
    pub pos: Vec3,
    /// Orientation in the body frame.
    pub quat: Quat,
    /// Capsule ends that touch planes (Brax's `end`).
    pub ends: CapsuleEnds,
}

/// A torque motor on one hinge.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeMotor {
    /// Actuator name, with `.1`/`.2` appended for 2-DoF joints.
    pub name: String,
    /// Index of the hinge in the tree's hinge order ([`AgentTree::hinges`]).
    pub hinge: usize,
    /// Torque at action 1 (N m).
    pub gear: f64,
}

impl AgentTree {
    /// Builds the tree of a checked config with the given constants.
    pub fn from_config(config: &SystemConfig, physics: &BraxPhysics) -> AgentTree {
        let root = config.root_body();
        // Lookups by name, built once (linear in the size of the config): the children of
        // each parent name in the order of their first joint, the joints of each child name,
        // the first actuator of each joint name.
        let body_of = first_index(config.bodies.iter().map(|b| b.name.as_str()));
        let mut children_of: HashMap<&str, Vec<usize>> = HashMap::new();
        let mut joints_of: HashMap<&str, Vec<usize>> = HashMap::new();
        let mut linked: HashSet<(&str, usize)> = HashSet::new();
        for (ji, j) in config.joints.iter().enumerate() {
            if let Some(&c) = body_of.get(j.child.as_str())
                && linked.insert((j.parent.as_str(), c))
            {
                children_of.entry(j.parent.as_str()).or_default().push(c);
            }
            joints_of.entry(j.child.as_str()).or_default().push(ji);
        }
        let actuator_of = first_index(config.actuators.iter().map(|a| a.joint.as_str()));
        let strength_of = |joint: &str| actuator_of.get(joint).map(|&a| config.actuators[a].strength);

        // Depth-first order, children in the order of their first joint.
        let mut order: Vec<(usize, Option<usize>)> = Vec::new();
        let mut stack = vec![(root, None)];
        while let Some((b, parent)) = stack.pop() {
            let me = order.len();
            order.push((b, parent));
            let children = children_of.get(config.bodies[b].name.as_str()).map_or(&[][..], |c| &c[..]);
            stack.extend(children.iter().rev().map(|&c| (c, Some(me))));
        }

        let mut bodies = Vec::with_capacity(order.len());
        for &(b, parent) in &order {
            let body = &config.bodies[b];
            let joints: &[usize] = joints_of.get(body.name.as_str()).map_or(&[], |j| &j[..]);
            let (pos, quat) = match joints.first() {
                Some(&j) => {
                    let j = &config.joints[j];
                    let q = euler_degrees_to_quat(j.reference_rotation);
                    (sub(j.parent_offset, quat_rotate(q, j.child_offset)), q)
                }
                None => ([0.0; 3], IDENTITY),
            };
            let mut hinges = Vec::new();
            for &ji in joints {
                let j = &config.joints[ji];
                let frame = euler_degrees_to_quat(j.rotation);
                let axes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
                for (k, limit) in j.angle_limits.iter().enumerate() {
                    let name = if j.angle_limits.len() == 1 { j.name.clone() } else { format!("{}.{}", j.name, k + 1) };
                    hinges.push(TreeHinge {
                        name,
                        config_joint: ji,
                        dof: k,
                        axis: quat_rotate(frame, axes[k]),
                        anchor: j.child_offset,
                        range: [limit.min.to_radians(), limit.max.to_radians()],
                        armature: physics.armature(strength_of(&j.name)),
                        damping: physics.damping(j.angular_damping),
                    });
                }
            }
            let geoms = body
                .colliders
                .iter()
                .map(|c| {
                    let (shape, end) = match c.shape {
                        ColliderShape::Sphere { radius } => (TreeShape::Sphere { radius }, 0),
                        ColliderShape::Capsule { radius, length, end } => {
                            let half_length = 0.5 * length - radius;
                            if half_length <= 1e-9 * radius {
                                (TreeShape::Sphere { radius }, 0)
                            } else {
                                (TreeShape::Capsule { radius, half_length }, end)
                            }
                        }
                    };
                    let ends = match (physics.capsule_ends, end) {
                        (true, 1) => CapsuleEnds::Plus,
                        (true, -1) => CapsuleEnds::Minus,
                        _ => CapsuleEnds::Both,
                    };
                    TreeGeom { shape, pos: c.position, quat: euler_degrees_to_quat(c.rotation), ends }
                })
                .collect();
            bodies.push(TreeBody {
                name: body.name.clone(),
                config_index: b,
                parent,
                pos,
                quat,
                mass: body.mass,
                inertia: None,
                hinges,
                geoms,
            });
        }

        let mut tree = AgentTree { bodies, motors: Vec::new() };
        let mut hinge_of: HashMap<(usize, usize), usize> = HashMap::new();
        for (h, hinge) in tree.hinges().iter().enumerate() {
            hinge_of.entry((hinge.config_joint, hinge.dof)).or_insert(h);
        }
        let joint_of = first_index(config.joints.iter().map(|j| j.name.as_str()));
        for a in &config.actuators {
            let Some(&ji) = joint_of.get(a.joint.as_str()) else {
                continue;
            };
            let ndof = config.joints[ji].angle_limits.len();
            for k in 0..ndof {
                if let Some(&h) = hinge_of.get(&(ji, k)) {
                    tree.motors.push(TreeMotor {
                        name: if ndof == 1 { a.name.clone() } else { format!("{}.{}", a.name, k + 1) },
                        hinge: h,
                        gear: physics.gear(a.strength),
                    });
                }
            }
        }
        tree
    }

    /// All hinges in qpos order (bodies depth first, each body's hinges in order).
    pub fn hinges(&self) -> Vec<&TreeHinge> {
        self.bodies.iter().flat_map(|b| b.hinges.iter()).collect()
    }

    /// Hinge angles at rest: the middle of every range, in qpos order.
    pub fn rest_angles(&self) -> Vec<f64> {
        self.hinges().iter().map(|h| h.rest_angle()).collect()
    }

    /// World pose (origin, orientation) of every body for the root pose `root` and hinge
    /// `angles` in qpos order (missing angles count as 0). Same conventions as the simulator:
    /// each hinge turns the body frame about its axis through its anchor, in order.
    pub fn body_poses(&self, root: (Vec3, Quat), angles: &[f64]) -> Vec<(Vec3, Quat)> {
        let mut poses: Vec<(Vec3, Quat)> = Vec::with_capacity(self.bodies.len());
        let mut k = 0;
        for b in &self.bodies {
            let (mut p, mut q) = match b.parent {
                None => root,
                Some(parent) => {
                    let (pp, pq) = poses[parent];
                    (add(pp, quat_rotate(pq, b.pos)), quat_mul(pq, b.quat))
                }
            };
            for h in &b.hinges {
                let angle = angles.get(k).copied().unwrap_or(0.0);
                k += 1;
                let anchor = add(p, quat_rotate(q, h.anchor));
                q = quat_mul(q, quat_from_axis_angle(h.axis, angle));
                p = sub(anchor, quat_rotate(q, h.anchor));
            }
            poses.push((p, q));
        }
        poses
    }

    /// Lowest z of any geom surface for the root pose `root` and hinge `angles`.
    pub fn lowest_point(&self, root: (Vec3, Quat), angles: &[f64]) -> f64 {
        let poses = self.body_poses(root, angles);
        let mut lowest = f64::INFINITY;
        for (b, (p, q)) in self.bodies.iter().zip(&poses) {
            for g in &b.geoms {
                let centre = add(*p, quat_rotate(*q, g.pos));
                let z = match g.shape {
                    TreeShape::Sphere { radius } => centre[2] - radius,
                    TreeShape::Capsule { radius, half_length } => {
                        let axis = quat_rotate(quat_mul(*q, g.quat), [0.0, 0.0, 1.0]);
                        centre[2] - half_length * axis[2].abs() - radius
                    }
                };
                lowest = lowest.min(z);
            }
        }
        lowest
    }

    /// Height of the root origin at rest: joints at mid-range, root upright (identity
    /// orientation), lifted until the lowest collider point touches z = 0.
    pub fn rest_height(&self) -> f64 {
        -self.lowest_point(([0.0; 3], IDENTITY), &self.rest_angles())
    }

    /// The rest pose as qpos of this agent alone (MuJoCo layout: free joint `x y z qw qx qy
    /// qz` with the root at (0, 0, rest height) and identity orientation, then the hinge
    /// angles at mid-range in qpos order).
    pub fn rest_qpos(&self) -> Vec<f64> {
        let mut q = vec![0.0, 0.0, self.rest_height(), 1.0, 0.0, 0.0, 0.0];
        q.extend(self.rest_angles());
        q
    }
}
