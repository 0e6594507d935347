//! Hands an agent ([`AgentTree`], from a Brax config or an MJCF file) to the simulator's
//! [`ModelBuilder`].
//!
//! [`add_agent`] adds one agent to a scene under construction (several agents, goal balls
//! and the ground are the scene's business); [`agent_model`] builds the common case of one
//! agent standing on the ground plane at its rest pose.

use super::config::SystemConfig;
use super::error::BraxError;
use super::physics::BraxPhysics;
use super::rotation::{Quat, Vec3};
use super::tree::{AgentTree, TreeShape};
use crate::model::{ActuatorId, BodyId, GeomId, Integrator, JointId, Model, Options};
use crate::{GeomSpec, HingeSpec, ModelBuilder};

/// Time step of the MeBen scenes (s): 5 steps per 0.05 s control step (`bench/SIM.md`).
pub const BRAX_TIMESTEP: f64 = 0.01;

/// Ids of one agent's parts in the model being built.
#[derive(Clone, Debug, PartialEq)]
pub struct AgentIds {
    /// The root body (carries the free joint).
    pub root: BodyId,
    /// The free joint of the root.
    pub free_joint: JointId,
    /// Model body of each tree body (same order as [`AgentTree::bodies`]).
    pub bodies: Vec<BodyId>,
    /// Model joint of each hinge, in the tree's hinge (qpos) order.
    pub hinges: Vec<JointId>,
    /// Model actuator of each motor, in action order.
    pub actuators: Vec<ActuatorId>,
    /// Model geoms of the agent.
    pub geoms: Vec<GeomId>,
}

/// Adds `tree` to `builder` with its root frame at `pos`, orientation `quat` (world) and every
/// hinge at its rest angle (mid-range) in the model's `qpos0`. Names get `prefix` prepended
/// (use distinct prefixes for several agents in one scene).
pub fn add_agent(
    builder: &mut ModelBuilder,
    tree: &AgentTree,
    physics: &BraxPhysics,
    prefix: &str,
    pos: Vec3,
    quat: Quat,
) -> AgentIds {
    let mut bodies: Vec<BodyId> = Vec::with_capacity(tree.bodies.len());
    let mut hinges = Vec::new();
    let mut geoms = Vec::new();
    let mut free_joint = None;
    for b in &tree.bodies {
        let id = match b.parent {
            None => builder.add_body(BodyId::WORLD, pos, quat),
            Some(p) => builder.add_body(bodies[p], b.pos, b.quat),
        };
        builder.set_body_name(id, &format!("{prefix}{}", b.name));
        if b.parent.is_none() {
            let fj = builder.add_free_joint(id);
            builder.set_joint_name(fj, &format!("{prefix}{}", b.name));
            free_joint = Some(fj);
        }
        for h in &b.hinges {
            let spec = HingeSpec::new(h.axis)
                .anchor(h.anchor)
                .range(h.range[0], h.range[1])
                .armature(h.armature)
                .damping(h.damping)
                .init(h.rest_angle())
                .named(&format!("{prefix}{}", h.name));
            hinges.push(builder.add_hinge(id, spec));
        }
        for g in &b.geoms {
            let spec = match g.shape {
                TreeShape::Sphere { radius } => GeomSpec::sphere(radius),
                TreeShape::Capsule { radius, half_length } => GeomSpec::capsule(radius, half_length),
            };
            let spec = spec.at(g.pos).with_quat(g.quat).ends(g.ends).friction(physics.friction);
            geoms.push(builder.add_geom(id, spec));
        }
        match &b.inertia {
            Some(i) => builder.set_body_inertia(id, b.mass, i.com, i.inertia),
            // Mass from the config; the inertia of the geoms (uniform density) scaled to it.
            None => builder.set_body_mass(id, b.mass),
        }
        bodies.push(id);
    }
    let actuators = tree
        .motors
        .iter()
        .map(|m| {
            let a = builder.add_actuator(hinges[m.hinge], m.gear, Some(physics.ctrlrange));
            builder.set_actuator_name(a, &format!("{prefix}{}", m.name));
            a
        })
        .collect();
    AgentIds { root: bodies[0], free_joint: free_joint.unwrap_or(JointId(0)), bodies, hinges, actuators, geoms }
}

/// The simulator options of MeBen scenes: MuJoCo's defaults with the 0.01 s time step and
/// the [`Integrator::EulerGyro`] integrator (MuJoCo's Euler plus the exact implicit derivative
/// of the bias forces with respect to each floating root's angular velocity). Under bang-bang
/// actions at the Brax strengths, plain `Euler`'s explicit gyroscopic term lets an agent lying
/// on its back spin up to a numerical blow-up (2 of 704 four-ant Team Sumo scenes over 1000
/// control steps; `docs/SIMULATOR.md`, "Why `EulerGyro`").
pub fn brax_options() -> Options {
    Options { timestep: BRAX_TIMESTEP, integrator: Integrator::EulerGyro, ..Options::default() }
}

/// One agent on the ground plane (friction `physics.friction`) with [`brax_options`], its
/// `qpos0` the rest pose ([`AgentTree::rest_qpos`]). Returns the model and the tree.
pub fn agent_model(config: &SystemConfig, physics: &BraxPhysics) -> Result<(Model, AgentTree), BraxError> {
    let tree = AgentTree::from_config(config, physics);
    let mut builder = ModelBuilder::new();
    builder.set_options(brax_options());
    builder.add_geom(BodyId::WORLD, GeomSpec::plane().friction(physics.friction).named("ground"));
    let height = tree.rest_height();
    add_agent(&mut builder, &tree, physics, "", [0.0, 0.0, height], [1.0, 0.0, 0.0, 0.0]);
    let model =
        builder.build().map_err(|e| BraxError::Model { source: config.source.clone(), message: e.to_string() })?;
    Ok((model, tree))
}
