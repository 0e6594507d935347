//! One simulator [`Model`] for a composition: the ground plane and every agent, each a
//! kinematic tree (from a built-in or file Brax config, or an MJCF file) added with
//! [`crate::brax::add_agent`] at its rest pose.
//!
//! The goal balls (Reach) and the centre ball (Sumo) are not bodies of the model: they are
//! fixed, collide with nothing and so never influence the physics, while their positions
//! change every episode; the [`Model`] is shared by all environments and immutable. Their
//! positions live in each environment's state ([`super::placement::Start::balls`]) and appear
//! in the observation, the rewards and the rendered trajectories.

use super::error::TaskError;
use super::spec::{TaskKind, TaskSpec};
use crate::brax::rotation::{add, quat_rotate};
use crate::brax::tree::TreeShape;
use crate::brax::{AgentTree, BraxPhysics, add_agent, brax_options, load_config_file, load_morphology};
use crate::layout::ObsSpec;
use crate::mjcf_agent::load_agent_file;
use crate::model::{JointKind, Model, ModelError};
use crate::{BodyId, GeomSpec, ModelBuilder};

/// Radius of the goal and centre balls (m).
pub const BALL_RADIUS: f64 = 0.1;

/// Where one agent lives in the scene's model and in the action and state arrays.
#[derive(Clone, Debug, PartialEq)]
pub struct AgentLayout {
    /// Morphology name or file path (Brax config or MJCF), as in the spec.
    pub morphology: String,
    /// Team index (0-based; Reach has only team 0).
    pub team: usize,
    /// Name prefix of its bodies and joints in the model (`a<index>/`).
    pub prefix: String,
    /// Root body (carries the free joint).
    pub root_body: usize,
    /// Model bodies of the agent, in tree order (the root first).
    pub bodies: Vec<usize>,
    /// First qpos entry (the free joint's `x y z qw qx qy qz`, then the hinges).
    pub qpos_adr: usize,
    /// Number of qpos entries (7 + hinges).
    pub nq: usize,
    /// First qvel entry.
    pub dof_adr: usize,
    /// Number of qvel entries (6 + hinges).
    pub nv: usize,
    /// Model actuators in action order.
    pub actuators: Vec<usize>,
    /// First entry of this agent's actions in an environment's action row.
    pub action_offset: usize,
    /// Height of the root at rest (joints mid-range, lowest point on the ground).
    pub rest_height: f64,
    /// Radius of a vertical cylinder about the root that holds the agent at rest (placement).
    pub footprint: f64,
}

impl AgentLayout {
    /// Number of actuated DoF (= length of the agent's action vector).
    pub fn n_actions(&self) -> usize {
        self.actuators.len()
    }
}

/// A built scene: the shared model, the agents' layouts and the observation layout.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The composition it was built from.
    pub spec: TaskSpec,
    /// The simulator model (ground and agents; `qpos0` is every agent at rest at the origin).
    pub model: Model,
    /// Agents: team 0's in spec order, then team 1's.
    pub agents: Vec<AgentLayout>,
    /// Actions per environment (sum of the agents' actuated DoF).
    pub n_actions: usize,
    /// Layout of the observation arrays.
    pub obs_spec: ObsSpec,
}

/// Loads a morphology by built-in name, or from a file when the name ends in `.txt` (a Brax
/// config) or `.xml` (MJCF, the subset of [`crate::mjcf_agent`]). A missing file is reported
/// as a file that cannot be read, not as an unknown name.
fn load_tree(name: &str, physics: &BraxPhysics) -> Result<AgentTree, TaskError> {
    let bad = |message: String| TaskError::Morphology { name: name.to_string(), message };
    let is_file = super::spec::is_morphology_file(name);
    if is_file {
        let path = std::path::Path::new(name);
        if !path.is_file() {
            let why = match std::fs::metadata(path) {
                Ok(_) => "not a regular file".to_string(),
                Err(e) => e.to_string(),
            };
            return Err(bad(format!("cannot read the morphology file: {why}")));
        }
    }
    let tree = if name.ends_with(".xml") {
        load_agent_file(name, physics).map_err(|e| bad(e.to_string()))?
    } else {
        let config = if is_file { load_config_file(name) } else { load_morphology(name) };
        AgentTree::from_config(&config.map_err(|e| bad(e.to_string()))?, physics)
    };
    if tree.motors.is_empty() {
        return Err(bad("has no actuated joint: every agent needs at least one action".into()));
    }
    Ok(tree)
}

/// Horizontal radius about the root of every geom at rest.
fn footprint(tree: &AgentTree) -> f64 {
    let poses = tree.body_poses(([0.0; 3], [1.0, 0.0, 0.0, 0.0]), &tree.rest_angles());
    let mut r: f64 = 0.0;
    for (b, (p, q)) in tree.bodies.iter().zip(&poses) {
        for g in &b.geoms {
            let c = add(*p, quat_rotate(*q, g.pos));
            let extent = match g.shape {
                TreeShape::Sphere { radius } => radius,
                TreeShape::Capsule { radius, half_length } => radius + half_length,
            };
            r = r.max(c[0].hypot(c[1]) + extent);
        }
    }
    r
}

/// The most candidate contact pairs between the geoms of different agents in one scene
/// (4,194,304: about 100 MB of pairs, and one warm-start slot each in every environment).
/// [`Scene::build`] counts them from the agents' geoms before building anything and refuses
/// more, naming the count (a few hundred agents of many bodies each used to abort the
/// process, and a Python interpreter with it, while the pairs were built).
pub const MAX_CONTACT_PAIRS: usize = 1 << 22;

impl Scene {
    /// Builds the scene of a (validated) composition with MeBen's physical constants.
    pub fn build(spec: &TaskSpec) -> Result<Scene, TaskError> {
        spec.validate()?;
        let physics = BraxPhysics::default();
        let mut builder = ModelBuilder::new();
        builder.set_options(brax_options());
        builder.add_geom(BodyId::WORLD, GeomSpec::plane().friction(physics.friction).named("ground"));
        let mut agents = Vec::new();
        let mut n_actions = 0;
        let (mut geoms, mut pairs) = (0usize, 0usize);
        for (team, members) in spec.teams.iter().enumerate() {
            for name in members {
                let tree = load_tree(name, &physics)?;
                let g: usize = tree.bodies.iter().map(|b| b.geoms.len()).sum();
                pairs = pairs.saturating_add(g.saturating_mul(geoms));
                geoms = geoms.saturating_add(g);
                if pairs > MAX_CONTACT_PAIRS {
                    return Err(TaskError::BadSpec {
                        what: "agents".into(),
                        value: spec.n_agents().to_string(),
                        message: format!(
                            "the first {} agents already have {pairs} candidate contact pairs between their {geoms} \
                             geoms, more than {MAX_CONTACT_PAIRS} (the collision detection's memory grows with their \
                             square): use fewer or simpler agents",
                            agents.len() + 1
                        ),
                    });
                }
                let prefix = format!("a{}/", agents.len());
                let rest_height = tree.rest_height();
                let ids =
                    add_agent(&mut builder, &tree, &physics, &prefix, [0.0, 0.0, rest_height], [1.0, 0.0, 0.0, 0.0]);
                let layout = AgentLayout {
                    morphology: name.clone(),
                    team,
                    prefix,
                    root_body: ids.root.0,
                    bodies: ids.bodies.iter().map(|b| b.0).collect(),
                    qpos_adr: 0,
                    nq: 0,
                    dof_adr: 0,
                    nv: 0,
                    actuators: ids.actuators.iter().map(|a| a.0).collect(),
                    action_offset: n_actions,
                    rest_height,
                    footprint: footprint(&tree),
                };
                n_actions += layout.actuators.len();
                agents.push(layout);
            }
        }
        let model = builder.build().map_err(|e| {
            // Name the morphology of the body the simulator blames (its name starts with the
            // agent's prefix).
            let owner = match &e {
                ModelError::SingularMassMatrix { body, .. } => agents.iter().find(|a| body.starts_with(&a.prefix)),
                _ => None,
            };
            let message = match owner {
                Some(a) => format!("{e} (agent {}: morphology {:?})", a.prefix.trim_end_matches('/'), a.morphology),
                None => e.to_string(),
            };
            TaskError::Model { message }
        })?;
        for a in &mut agents {
            let root = &model.bodies[a.root_body];
            let free = &model.joints[root.jnt_adr];
            if root.jnt_num != 1 || free.kind != JointKind::Free {
                return Err(TaskError::Model { message: format!("agent {} has no free root joint", a.prefix) });
            }
            a.qpos_adr = free.qpos_adr;
            a.dof_adr = free.dof_adr;
            // add_agent adds an agent's bodies (hence joints, qpos and dofs) contiguously.
            let last = &model.bodies[*a.bodies.last().unwrap_or(&a.root_body)];
            let end_joint = last.jnt_adr + last.jnt_num;
            let (q_end, v_end) = match model.joints.get(end_joint) {
                Some(j) => (j.qpos_adr, j.dof_adr),
                None => (model.nq, model.nv),
            };
            a.nq = q_end - a.qpos_adr;
            a.nv = v_end - a.dof_adr;
        }
        let obs_spec = super::observation::obs_spec(spec, &model, &agents)?;
        Ok(Scene { spec: spec.clone(), model, agents, n_actions, obs_spec })
    }

    /// Builds the scene of a built-in name or custom composition string.
    pub fn from_name(name: &str) -> Result<Scene, TaskError> {
        Scene::build(&TaskSpec::from_name(name)?)
    }

    /// Number of agents.
    pub fn n_agents(&self) -> usize {
        self.agents.len()
    }

    /// Number of teams.
    pub fn n_teams(&self) -> usize {
        self.spec.n_teams()
    }

    /// Whether this is Team Reach or Team Sumo.
    pub fn kind(&self) -> TaskKind {
        self.spec.kind
    }
}
