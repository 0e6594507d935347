//! An MJCF (MuJoCo XML) file as one MeBen agent: an [`AgentTree`], the type the tasks build
//! every agent from, so that a composition may name an MJCF morphology
//! (`team_reach:agents=ant+path/to/agent.xml`) as it names a Brax config (`.txt`).
//!
//! The file is loaded by [`crate::mjcf`] (which refuses what the simulator cannot represent),
//! then `subset` refuses what an agent cannot be, then the model becomes a tree.
//!
//! # The subset
//! Read: `<compiler>` (`angle`, `eulerseq`, `inertiafromgeom` true/auto, `coordinate`
//! local), `<default>` classes, one top-level `<body>` in `<worldbody>` with a free joint
//! (`<freejoint/>` or `<joint type="free"/>`, at the body origin, no armature or damping) and
//! no orientation, the bodies below it (`pos`, `quat`, `euler`), sphere and capsule geoms
//! (`size` or `fromto`, `pos`, `quat`, `euler`, `density`, `mass`; `friction` equal to the
//! scene's 1, `condim` 3), hinge joints with ranges (`axis`, `pos`, `range`, `limited`,
//! `armature`, `damping`), and `<motor>`s on hinges (`joint`, `gear`, `ctrlrange` -1 1 or
//! none, `ctrllimited`), one per hinge at most.
//!
//! Ignored on purpose: the root body's `pos` (the task places every agent, standing at its
//! rest height); `<option>` (time step, integrator, gravity are the scene's, as a Brax config's
//! `dt` and `gravity` are); a floor plane in `<worldbody>` (the scene has its own ground);
//! visual and solver-tuning attributes (`rgba`, `material`, `group`, `margin`, `gap`, `solref`,
//! `solimp`, ...); `contype`/`conaffinity` unless both are 0 (the scene makes every agent
//! geom collide with the ground and the other agents: MuJoCo's `ant.xml` sets `conaffinity`
//! 0 only because it is alone); `site`, `camera`, `light`, `asset`, `visual`, `sensor`, ...
//!
//! Everything else is an [`MjcfError`] naming the file, line, element, attribute and value:
//! other geom, joint and actuator types, `<inertial>`, `<tendon>`, `<equality>`, `<contact>`,
//! joint stiffness, springs, `ref` or friction loss, a hinge without range, a second agent,
//! a root without a free joint, two motors on one hinge, a control range other than [-1, 1].
//!
//! # Semantics
//! - A body without joints is fused into its parent (as MuJoCo's `fusestatic`): its geoms and
//!   children move into the parent's frame, masses add. MuJoCo's own `ant.xml` welds each
//!   thigh capsule to the torso this way, so its 13 bodies make a tree of 9.
//! - Masses and inertias are MuJoCo's, from each geom's own `mass` or `density` (default
//!   1000), combined exactly ([`TreeInertia`]), not rescaled as a Brax config's are.
//! - Armature, damping and gear are the file's (a Brax config's come from
//!   [`BraxPhysics`]); friction and the control range must equal the scene's
//!   ([`BraxPhysics::friction`], [`BraxPhysics::ctrlrange`]), which [`crate::brax::add_agent`]
//!   gives every agent.
//! - Capsules touch the ground with both ends (MJCF has no Brax `end`).
//! - The rest pose is the tasks' rule for every agent: every hinge at the middle of its
//!   range, root upright, lowest point on the ground ([`AgentTree::rest_qpos`]); MuJoCo's
//!   `qpos0` (hinges at 0) is not used.
//! - Bodies and hinges keep the file's order (depth first), motors the `<actuator>` order;
//!   a motor without a name takes its joint's.

#![allow(clippy::result_large_err)] // errors carry file/line/element/attribute/value; cold path

mod subset;

use subset::error as err;

use std::path::Path;

use crate::brax::BraxPhysics;
use crate::brax::tree::{AgentTree, TreeBody, TreeGeom, TreeHinge, TreeInertia, TreeMotor, TreeShape};
use crate::math::{self, Mat3, Quat, Vec3};
use crate::mjcf::{self, MjcfError, MjcfSources};
use crate::model::{CapsuleEnds, JointKind, Model, Shape};

/// Reads an MJCF file as one agent; errors name the path.
pub fn load_agent_file(path: impl AsRef<Path>, physics: &BraxPhysics) -> Result<AgentTree, MjcfError> {
    let (text, file) = mjcf::read_file(path.as_ref())?;
    load_agent_str(&text, &file, physics)
}

/// Reads MJCF text as one agent; `file` names it in error messages. `physics` holds the
/// scene's friction and control range, which the file must agree with (module docs).
pub fn load_agent_str(text: &str, file: &str, physics: &BraxPhysics) -> Result<AgentTree, MjcfError> {
    let (model, sources) = mjcf::load_str_with_sources(text, file)?;
    subset::check_elements(text, file)?;
    subset::check_attributes(&model, &sources, file, physics)?;
    agent_tree(&model, &sources, file, physics)
}

/// An error about the file as a whole (no element to point at).
fn file_error(file: &str, element: &str, message: &str) -> MjcfError {
    MjcfError {
        file: file.to_string(),
        line: 0,
        element: element.to_string(),
        attribute: None,
        value: None,
        message: message.to_string(),
    }
}

/// The model of a checked file as an agent tree (module docs).
fn agent_tree(model: &Model, sources: &MjcfSources, file: &str, physics: &BraxPhysics) -> Result<AgentTree, MjcfError> {
    for (g, geom) in model.geoms.iter().enumerate() {
        if geom.body == 0 && geom.shape != Shape::Plane {
            let message = "a geom fixed to the world is not part of an agent (a floor plane is allowed and ignored: \
                           the task has its own ground)";
            return Err(err(file, &sources.geoms[g], Some("type"), message));
        }
    }
    let tops: Vec<usize> = (1..model.bodies.len()).filter(|&b| model.bodies[b].parent == 0).collect();
    let root = match tops.as_slice() {
        [] => return Err(file_error(file, "worldbody", "holds no body: an agent morphology is one tree of bodies")),
        [root] => *root,
        [_, second, ..] => {
            let message = "a second top-level body: an agent morphology holds exactly one agent (one tree of bodies \
                           with a free joint at its root)";
            return Err(err(file, &sources.bodies[second - 1], None, message));
        }
    };
    check_root(model, sources, file, root)?;

    // Bodies, in the file's (depth-first) order; a body without joints is fused into the
    // nearest ancestor that has some. `place[b]`: the tree body holding model body `b` and
    // `b`'s frame in that tree body's frame.
    let mut place: Vec<Option<(usize, Vec3, Quat)>> = vec![None; model.bodies.len()];
    let mut bodies: Vec<TreeBody> = Vec::new();
    let mut masses: Vec<Vec<MassPart>> = Vec::new();
    for b in root..model.bodies.len() {
        let body = &model.bodies[b];
        let (tree_parent, pos, quat) = if b == root {
            (None, [0.0; 3], math::QUAT_IDENTITY)
        } else {
            let Some((t, p, q)) = place[body.parent] else { continue };
            (Some(t), math::add(p, math::quat_rotate(q, body.pos)), math::quat_mul(q, body.quat))
        };
        let here = match tree_parent {
            Some(t) if body.jnt_num == 0 => (t, pos, quat),
            _ => {
                // The root's free joint is the scene's to add (`add_agent`).
                let hinges = if b == root { Vec::new() } else { hinges_of(model, sources, file, b)? };
                bodies.push(TreeBody {
                    name: body.name.clone(),
                    config_index: b,
                    parent: tree_parent,
                    pos,
                    quat,
                    mass: 0.0,
                    inertia: None,
                    hinges,
                    geoms: Vec::new(),
                });
                masses.push(Vec::new());
                (bodies.len() - 1, [0.0; 3], math::QUAT_IDENTITY)
            }
        };
        place[b] = Some(here);
        let (t, p, q) = here;
        let r = math::quat_to_mat(q);
        masses[t].push(MassPart {
            mass: body.mass,
            com: math::add(p, math::mat_vec(&r, body.ipos)),
            inertia: math::rotate_tensor(&r, &body.inertia),
        });
    }
    for geom in &model.geoms {
        let Some((t, p, q)) = place.get(geom.body).copied().flatten() else { continue };
        let shape = match geom.shape {
            Shape::Sphere { radius } => TreeShape::Sphere { radius },
            Shape::Capsule { radius, half_length } => TreeShape::Capsule { radius, half_length },
            Shape::Plane => continue, // refused on bodies by the loader
        };
        bodies[t].geoms.push(TreeGeom {
            shape,
            pos: math::add(p, math::quat_rotate(q, geom.pos)),
            quat: math::quat_mul(q, geom.quat),
            ends: CapsuleEnds::Both,
        });
    }
    for (body, parts) in bodies.iter_mut().zip(&masses) {
        let (mass, inertia) = combine(parts);
        if !(mass > 0.0 && mass.is_finite()) {
            let message = "a moving body without mass (no geom with mass in it or in a jointless body fused into it)";
            return Err(err(file, &sources.bodies[body.config_index - 1], None, message));
        }
        body.mass = mass;
        body.inertia = Some(inertia);
    }

    let mut tree = AgentTree { bodies, motors: Vec::new() };
    let hinge_joints: Vec<usize> = tree.hinges().iter().map(|h| h.config_joint).collect();
    let mut driven = vec![false; hinge_joints.len()];
    for (u, act) in model.actuators.iter().enumerate() {
        let source = &sources.actuators[u];
        // The loader only accepts motors on hinges; a hinge outside the agent cannot exist.
        let Some(hinge) = hinge_joints.iter().position(|&j| j == act.joint) else {
            return Err(err(file, source, Some("joint"), "not a hinge of the agent"));
        };
        if std::mem::replace(&mut driven[hinge], true) {
            let message = "a second motor on this hinge: each actuated hinge has one motor (one action, one \
                           observation node)";
            return Err(err(file, source, Some("joint"), message));
        }
        if act.ctrlrange.is_some_and(|r| r != physics.ctrlrange) {
            let [lo, hi] = physics.ctrlrange;
            let message = format!(
                "must be \"{lo} {hi}\" or absent: a MeBen action is in [{lo}, {hi}] and the torque at action 1 is \
                 the gear"
            );
            return Err(err(file, source, Some("ctrlrange"), message));
        }
        let name = if act.name.is_empty() { model.joints[act.joint].name.clone() } else { act.name.clone() };
        tree.motors.push(TreeMotor { name, hinge, gear: act.gear });
    }
    Ok(tree)
}

/// The root must float freely and stand upright.
fn check_root(model: &Model, sources: &MjcfSources, file: &str, root: usize) -> Result<(), MjcfError> {
    let body = &model.bodies[root];
    let source = &sources.bodies[root - 1];
    let free = (body.jnt_num == 1).then_some(body.jnt_adr).filter(|&j| model.joints[j].kind == JointKind::Free);
    let Some(j) = free else {
        let message = "the agent's root body needs a free joint (<freejoint/>): MeBen agents move freely";
        return Err(match body.jnt_num {
            0 => err(file, source, None, message),
            _ => err(file, &sources.joints[body.jnt_adr], Some("type"), message),
        });
    };
    for (attribute, value) in [("armature", model.joints[j].armature), ("damping", model.joints[j].damping)] {
        if value != 0.0 {
            let message = "must be 0 on the free joint (a MeBen agent's root has no armature or damping)";
            return Err(err(file, &sources.joints[j], Some(attribute), message));
        }
    }
    if body.quat != math::QUAT_IDENTITY {
        let attribute = if source.get("euler").is_some() { "euler" } else { "quat" };
        let message = "the root body must not be rotated: the task stands every agent upright with a random heading";
        return Err(err(file, source, Some(attribute), message));
    }
    Ok(())
}

/// The hinges of model body `b`; every one needs a range.
fn hinges_of(model: &Model, sources: &MjcfSources, file: &str, b: usize) -> Result<Vec<TreeHinge>, MjcfError> {
    let body = &model.bodies[b];
    let mut hinges = Vec::with_capacity(body.jnt_num);
    for j in body.jnt_adr..body.jnt_adr + body.jnt_num {
        let joint = &model.joints[j];
        if joint.kind != JointKind::Hinge || !joint.limited {
            let message = "every hinge needs a range (limited): the rest pose is the middle of each range and the \
                           observation scales each angle by it";
            let attribute = if sources.joints[j].get("limited").is_some() { "limited" } else { "range" };
            return Err(err(file, &sources.joints[j], Some(attribute), message));
        }
        hinges.push(TreeHinge {
            name: joint.name.clone(),
            config_joint: j,
            dof: 0,
            axis: joint.axis,
            anchor: joint.anchor,
            range: joint.range,
            armature: joint.armature,
            damping: joint.damping,
        });
    }
    Ok(hinges)
}

/// One body's mass distribution in the frame of the tree body it is fused into.
struct MassPart {
    mass: f64,
    com: Vec3,
    inertia: Mat3,
}

/// Total mass and inertia about the joint centre of mass (parallel axes); one part is kept
/// as it is, bit for bit.
fn combine(parts: &[MassPart]) -> (f64, TreeInertia) {
    if let [one] = parts {
        return (one.mass, TreeInertia { com: one.com, inertia: one.inertia });
    }
    let mass: f64 = parts.iter().map(|p| p.mass).sum();
    let mut com = [0.0; 3];
    if mass > 0.0 {
        for p in parts {
            com = math::add_scaled(com, p.com, p.mass / mass);
        }
    }
    let mut inertia = [[0.0; 3]; 3];
    for p in parts {
        inertia =
            math::mat_add(&inertia, &math::mat_add(&p.inertia, &math::point_inertia(p.mass, math::sub(p.com, com))));
    }
    (mass, TreeInertia { com, inertia })
}
