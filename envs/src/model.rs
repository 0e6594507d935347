//! The immutable simulation model (MuJoCo's `mjModel`): bodies, joints, geoms, actuators and
//! options, shared by every environment; the per-environment state is [`crate::Data`].
//!
//! # Building a model: [`crate::ModelBuilder`]
//!
//! Every loader (MJCF, Brax configs) and every test builds a model through the same small API:
//!
//! ```
//! use envs::{GeomSpec, HingeSpec, ModelBuilder, BodyId};
//! let mut b = ModelBuilder::new();
//! b.add_geom(BodyId::WORLD, GeomSpec::plane());                 // ground plane z = 0
//! let torso = b.add_body(BodyId::WORLD, [0.0, 0.0, 0.75], [1.0, 0.0, 0.0, 0.0]);
//! b.add_free_joint(torso);                                       // floating root
//! b.add_geom(torso, GeomSpec::sphere(0.25).density(5.0));
//! let leg = b.add_body(torso, [0.2, 0.2, 0.0], [1.0, 0.0, 0.0, 0.0]);
//! let hip = b.add_hinge(leg, HingeSpec::new([0.0, 0.0, 1.0])
//!     .range(-0.5, 0.5).armature(1.0).damping(1.0));
//! b.add_geom(leg, GeomSpec::capsule_fromto(0.08, [0.0; 3], [0.2, 0.2, 0.0]).density(5.0));
//! b.add_actuator(hip, 150.0, Some([-1.0, 1.0]));
//! let model = b.build().unwrap();
//! assert_eq!((model.nq, model.nv, model.nu()), (8, 7, 1));
//! ```
//!
//! - `add_body(parent, pos, quat)`: a body whose frame is `pos`/`quat` relative to its parent;
//!   parents must be added before children, so bodies are in tree order.
//! - `add_free_joint(body)`: a floating root (only for children of the world). qpos gets
//!   `x y z qw qx qy qz`, qvel `vx vy vz` (world frame) then `wx wy wz` (body frame), as MuJoCo.
//! - `add_hinge(body, HingeSpec)`: a revolute joint about `axis` (body frame) through `anchor`,
//!   with optional `range` (radians; a limited joint), `armature`, `damping` and the initial
//!   angle. Two hinges on one body make a universal joint (applied in the order added).
//! - `add_geom(body, GeomSpec)`: a sphere, capsule or plane with its frame in the body frame,
//!   density (or mass), friction and `contype`/`conaffinity` bits.
//! - `add_actuator(joint, gear, ctrlrange)`: a motor, torque = gear * clamp(ctrl, ctrlrange).
//! - `set_joint_armature_damping(joint, armature, damping)`: for free joints (all six dofs).
//! - `set_body_mass` / `set_body_inertia`: override the inertia that is otherwise computed from
//!   the geoms (MuJoCo's `inertiafromgeom`: solid spheres and capsules of the given density).
//! - `set_options(Options)`: time step, gravity, contact/limit switches, solver parameters.
//! - `build()` validates everything and returns a [`Model`] or a [`ModelError`].
//!
//! A body attached to the world without joints is static (goal balls, the ground); each
//! body attached to the world with joints starts a kinematic tree (one agent). Collisions are
//! only considered between different trees or between a tree and a static geom, never inside
//! a tree.

use crate::math::{Mat3, Quat, Vec3};
use std::fmt;

/// Index of a body in [`Model::bodies`]; body 0 is the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BodyId(pub usize);

impl BodyId {
    /// The world body (fixed, index 0).
    pub const WORLD: BodyId = BodyId(0);
}

/// Index of a joint in [`Model::joints`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct JointId(pub usize);

/// Index of a geom in [`Model::geoms`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct GeomId(pub usize);

/// Index of an actuator in [`Model::actuators`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ActuatorId(pub usize);

/// Sentinel for "no parent dof / no tree".
pub const NONE: usize = usize::MAX;

/// Numerical integrator. `Euler` (the default) is MuJoCo's semi-implicit Euler with implicit
/// joint damping; `Implicit` additionally treats the Coriolis/centrifugal forces implicitly
/// (MuJoCo's `implicit`: `(M + h D + h dc/dqvel) qacc = f`), which keeps tumbling bodies from
/// gaining energy; `EulerGyro` does so for the floating roots only, cheaply. `Rk4` and
/// `ImplicitFast` are accepted by the MJCF loader and recorded, but stepped with `Euler`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Integrator {
    /// Semi-implicit Euler (velocity first, then position), implicit damping.
    #[default]
    Euler,
    /// MuJoCo's RK4 (recorded; stepped with Euler).
    Rk4,
    /// Semi-implicit Euler with implicit damping and implicit Coriolis/centrifugal forces.
    Implicit,
    /// `Euler`, plus the implicit treatment of the bias forces' dependence on the angular
    /// velocity of every floating root: `(M + h D + h K E E^T) qacc = f`, with `K E` the exact
    /// columns of `dc/dqvel` for the root's three angular dofs (all rows of its tree), from one
    /// forward-mode pass of the Newton-Euler recursion, applied as a rank-3 Woodbury update of
    /// the factor of `M + h D`. Keeps spinning agents stable where the explicit gyroscopic term
    /// of `Euler` runs away (strong bang-bang actions at dt = 0.01); equal to `Implicit` for a
    /// single rigid body whose centre of mass is its origin. Used by the MeBen scenes
    /// (`brax::brax_options`).
    EulerGyro,
    /// MuJoCo's implicitfast (recorded; stepped with Euler).
    ImplicitFast,
}

/// Global simulation options (MuJoCo's `mjOption` subset).
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Physics time step in seconds (MuJoCo default 0.002).
    pub timestep: f64,
    /// Gravitational acceleration, world frame (default `[0, 0, -9.81]`).
    pub gravity: Vec3,
    /// Integrator named by the model (stepping is always semi-implicit Euler).
    pub integrator: Integrator,
    /// `true` disables all contacts (MJCF `<flag contact="disable"/>`).
    pub disable_contact: bool,
    /// `true` disables joint limits (MJCF `<flag limit="disable"/>`).
    pub disable_limit: bool,
    /// Constraint reference `[timeconst, dampratio]` (MuJoCo `solref`, default `[0.02, 1]`).
    /// The time constant is raised to at least `2 * timestep` at run time, as MuJoCo does.
    pub solref: [f64; 2],
    /// Constraint impedance `[dmin, dmax, width, mid, power]` (MuJoCo `solimp`,
    /// default `[0.9, 0.95, 0.001, 0.5, 2]`).
    pub solimp: [f64; 5],
    /// Projected Gauss-Seidel sweeps per step (warm-started; default 8).
    pub iterations: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            timestep: 0.002,
            gravity: [0.0, 0.0, -9.81],
            integrator: Integrator::Euler,
            disable_contact: false,
            disable_limit: false,
            solref: [0.02, 1.0],
            solimp: [0.9, 0.95, 0.001, 0.5, 2.0],
            iterations: 8,
        }
    }
}

/// A rigid body. Frames: `pos`/`quat` place the body frame in its parent's frame (before the
/// body's own joints move it); `ipos` and `inertia` describe the mass distribution in the body
/// frame.
#[derive(Clone, Debug)]
pub struct Body {
    /// Name (may be empty).
    pub name: String,
    /// Parent body index (the world is its own parent).
    pub parent: usize,
    /// Position relative to the parent frame.
    pub pos: Vec3,
    /// Orientation relative to the parent frame (unit quaternion).
    pub quat: Quat,
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the body frame.
    pub ipos: Vec3,
    /// Rotational inertia about the centre of mass, body axes.
    pub inertia: Mat3,
    /// Kinematic tree (agent) the body belongs to, or [`NONE`] for the world/static bodies.
    pub tree: usize,
    /// First joint of the body in [`Model::joints`].
    pub jnt_adr: usize,
    /// Number of joints of the body.
    pub jnt_num: usize,
    /// First dof of the body.
    pub dof_adr: usize,
    /// Number of dofs of the body.
    pub dof_num: usize,
}

/// Kind of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Six-dof floating joint: qpos `x y z qw qx qy qz`, qvel linear (world) + angular (body).
    Free,
    /// One rotational dof about an axis.
    Hinge,
}

/// A joint connecting a body to its parent.
#[derive(Clone, Debug)]
pub struct Joint {
    /// Name (may be empty).
    pub name: String,
    /// Kind.
    pub kind: JointKind,
    /// Body moved by the joint.
    pub body: usize,
    /// Unit rotation axis in the body frame (hinge).
    pub axis: Vec3,
    /// Joint anchor in the body frame (hinge).
    pub anchor: Vec3,
    /// Whether `range` is enforced (soft constraint).
    pub limited: bool,
    /// `[lower, upper]` in radians (hinge, when limited).
    pub range: [f64; 2],
    /// Armature: rotor inertia added to the mass matrix diagonal.
    pub armature: f64,
    /// Viscous damping coefficient (treated implicitly).
    pub damping: f64,
    /// First qpos index.
    pub qpos_adr: usize,
    /// First dof (qvel) index.
    pub dof_adr: usize,
}

/// Shape of a geom.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// A sphere.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// A capsule along the geom's local z axis.
    Capsule {
        /// Radius.
        radius: f64,
        /// Half the length of the cylindrical part (MuJoCo's second size).
        half_length: f64,
    },
    /// The plane z = 0 of the geom frame, normal +z (static bodies only).
    Plane,
}

/// Which ends of a capsule may touch a plane (Brax's `end`); spheres ignore it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CapsuleEnds {
    /// Both end caps (default).
    #[default]
    Both,
    /// Only the cap at local +z.
    Plus,
    /// Only the cap at local -z.
    Minus,
}

/// A collision geometry attached to a body.
#[derive(Clone, Debug)]
pub struct Geom {
    /// Name (may be empty).
    pub name: String,
    /// Owning body.
    pub body: usize,
    /// Shape.
    pub shape: Shape,
    /// Position in the body frame.
    pub pos: Vec3,
    /// Orientation in the body frame.
    pub quat: Quat,
    /// Rotation matrix of `quat`.
    pub mat: Mat3,
    /// Coulomb (sliding) friction coefficient; a contact uses the larger of the two geoms'.
    pub friction: f64,
    /// Collision type bits (MuJoCo rule: a pair may collide when
    /// `contype1 & conaffinity2 != 0 || contype2 & conaffinity1 != 0`).
    pub contype: u32,
    /// Collision affinity bits.
    pub conaffinity: u32,
    /// Capsule ends that touch planes.
    pub ends: CapsuleEnds,
    /// Radius of the bounding sphere about the geom centre (infinite for planes).
    pub rbound: f64,
    /// Tree of the owning body ([`NONE`] when static).
    pub tree: usize,
}

/// A motor on a hinge joint: torque = `gear * clamp(ctrl, ctrlrange)`.
#[derive(Clone, Debug)]
pub struct Actuator {
    /// Name (may be empty).
    pub name: String,
    /// Joint driven.
    pub joint: usize,
    /// Dof driven.
    pub dof: usize,
    /// Gear ratio (torque at ctrl = 1).
    pub gear: f64,
    /// Control clamp, or `None` for unclamped controls.
    pub ctrlrange: Option<[f64; 2]>,
}

/// A kinematic tree (one agent): a body attached to the world with joints, and its subtree.
#[derive(Clone, Debug)]
pub struct Tree {
    /// Root body (child of the world).
    pub root: usize,
    /// Bodies of the tree, in tree order.
    pub bodies: Vec<usize>,
    /// Geoms of the tree.
    pub geoms: Vec<usize>,
}

/// A candidate collision pair, fixed at build time by the filtering rules.
#[derive(Clone, Copy, Debug)]
pub struct CollisionPair {
    /// First geom (the plane, for plane pairs).
    pub g1: usize,
    /// Second geom.
    pub g2: usize,
    /// First warm-start slot of the pair (capsule-plane pairs own two slots, others one).
    pub slot: usize,
}

/// A run `geom_pairs[start..end]` of pairs between the same two trees (`tree1 < tree2`;
/// [`NONE`], i.e. static geoms, sorts last).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PairGroup {
    /// First tree.
    pub tree1: usize,
    /// Second tree (or [`NONE`] for static geoms).
    pub tree2: usize,
    /// First pair.
    pub start: usize,
    /// One past the last pair.
    pub end: usize,
}

/// The immutable model. Build it with [`crate::ModelBuilder`] or a loader.
#[derive(Clone, Debug)]
pub struct Model {
    /// Options.
    pub opt: Options,
    /// Bodies in tree order (parents first); index 0 is the world.
    pub bodies: Vec<Body>,
    /// Joints, grouped by body in body order.
    pub joints: Vec<Joint>,
    /// Geoms.
    pub geoms: Vec<Geom>,
    /// Actuators.
    pub actuators: Vec<Actuator>,
    /// Kinematic trees (agents).
    pub trees: Vec<Tree>,
    /// Number of position coordinates.
    pub nq: usize,
    /// Number of degrees of freedom (velocity coordinates).
    pub nv: usize,
    /// Default (initial) generalised position.
    pub qpos0: Vec<f64>,
    /// Parent dof of each dof ([`NONE`] for the first dof of a tree): the tree structure
    /// that makes the mass matrix factorisation fill-in free (RBDA §6.5).
    pub dof_parent: Vec<usize>,
    /// Body of each dof.
    pub dof_body: Vec<usize>,
    /// Joint of each dof.
    pub dof_joint: Vec<usize>,
    /// Armature of each dof.
    pub dof_armature: Vec<f64>,
    /// Damping of each dof.
    pub dof_damping: Vec<f64>,
    /// Last dof on the chain from each body to its tree root ([`NONE`] for static bodies):
    /// the dofs that move the body are this one and its ancestors.
    pub body_last_dof: Vec<usize>,
    /// Depth of each dof in its chain (number of ancestor dofs, itself included): the length
    /// of its row in the compact mass matrix layout.
    pub dof_depth: Vec<usize>,
    /// Start of each dof's row in the compact layout (see [`crate::crba`]) and in
    /// `dof_chain`.
    pub dof_chain_adr: Vec<usize>,
    /// Ancestor chains, concatenated: row `i` is `i`, its parent dof, ..., its tree's first dof.
    pub dof_chain: Vec<usize>,
    /// Candidate collision pairs with a plane.
    pub plane_pairs: Vec<CollisionPair>,
    /// Candidate collision pairs between two non-plane geoms, sorted by tree pair.
    pub geom_pairs: Vec<CollisionPair>,
    /// Runs of `geom_pairs` sharing the same two trees (broad phase on tree bounding spheres).
    pub pair_groups: Vec<PairGroup>,
    /// Number of contact warm-start slots.
    pub nslot: usize,
    /// Number of limited hinge joints (one potential limit row each).
    pub nlimited: usize,
    /// Diagonal of `M^-1` at `qpos0` (MuJoCo's `dof_invweight0`): the constant scale of the
    /// joint-limit regularisers.
    pub dof_invweight0: Vec<f64>,
}

impl Model {
    /// Number of actuators (length of `Data::ctrl`).
    pub fn nu(&self) -> usize {
        self.actuators.len()
    }

    /// Index of the body with this name.
    pub fn body_id(&self, name: &str) -> Option<BodyId> {
        self.bodies.iter().position(|b| b.name == name).map(BodyId)
    }

    /// Index of the joint with this name.
    pub fn joint_id(&self, name: &str) -> Option<JointId> {
        self.joints.iter().position(|j| j.name == name).map(JointId)
    }

    /// Index of the geom with this name.
    pub fn geom_id(&self, name: &str) -> Option<GeomId> {
        self.geoms.iter().position(|g| g.name == name).map(GeomId)
    }

    /// Total mass of a tree.
    pub fn tree_mass(&self, tree: usize) -> f64 {
        self.trees[tree].bodies.iter().map(|&b| self.bodies[b].mass).sum()
    }
}

/// Why a model could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum ModelError {
    /// A body, joint or geom id that does not exist.
    BadId {
        /// What kind of id.
        what: &'static str,
        /// The index.
        index: usize,
    },
    /// A free joint on a body that is not a child of the world, or not its only joint.
    BadFreeJoint {
        /// The body.
        body: usize,
    },
    /// A joint on the world body.
    JointOnWorld,
    /// A value is not finite or out of range.
    BadValue {
        /// Which item (e.g. "geom 3 radius").
        what: String,
        /// The value.
        value: f64,
    },
    /// A zero axis, quaternion or capsule direction.
    Degenerate {
        /// Which item.
        what: String,
    },
    /// A plane on a body that moves.
    PlaneOnMovingBody {
        /// The geom.
        geom: usize,
    },
    /// An actuator on a joint that is not a hinge.
    ActuatorNotOnHinge {
        /// The actuator.
        actuator: usize,
    },
    /// The mass matrix at the initial pose is not positive definite (a moving body without
    /// mass or inertia), or numerically so (a pivot below 1e-12 times the largest diagonal
    /// entry: a body far lighter than the rest of the scene).
    SingularMassMatrix {
        /// First dof where factorisation failed.
        dof: usize,
        /// The name of the body that dof moves (`body <index>` when it has none).
        body: String,
    },
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelError::BadId { what, index } => write!(f, "no {what} with index {index}"),
            ModelError::BadFreeJoint { body } => {
                write!(f, "free joint on body {body}: a free joint must be the only joint of a child of the world")
            }
            ModelError::JointOnWorld => write!(f, "the world body cannot have joints"),
            ModelError::BadValue { what, value } => write!(f, "bad value {value} for {what}"),
            ModelError::Degenerate { what } => write!(f, "degenerate {what} (zero length)"),
            ModelError::PlaneOnMovingBody { geom } => {
                write!(f, "geom {geom}: planes are only allowed on static bodies")
            }
            ModelError::ActuatorNotOnHinge { actuator } => {
                write!(f, "actuator {actuator}: motors drive hinge joints only")
            }
            ModelError::SingularMassMatrix { dof, body } => write!(
                f,
                "mass matrix not positive definite at dof {dof} (body {body:?}): a moving body lacks mass or inertia, \
                 or its mass and inertia are below 1e-12 times the largest in the scene"
            ),
        }
    }
}

impl std::error::Error for ModelError {}
