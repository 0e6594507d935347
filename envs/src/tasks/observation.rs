//! Filling the observation layout ([`crate::layout`]: [`ObsSpec`], [`Observation`](crate::layout::Observation),
//! [`N_SCALARS`], the entity-type columns) from the simulator: the [`ObsSpec`] of a scene
//! ([`obs_spec`]) and one environment's row ([`write_row`]).
//!
//! # What each part holds here
//! - `vectors`: per node the world-frame position (m), the linear velocity of the body
//!   origin clipped to +-[`VELOCITY_CLIP`] m/s per component, the angular velocity (rad/s).
//!   Balls: position of the centre, velocities 0.
//! - `scalars`: `0..3` entity type one-hot (below), `3..7` limb type one-hot (torso, thigh,
//!   leg, foot; below), `7` joint angle scaled to `[0, 1]` within its limits
//!   (`(q - lo) / (hi - lo)`, 0.5 for a DoF locked by equal limits; soft limits may let it
//!   stray slightly outside), `8, 9` the lower and upper limits scaled as
//!   `(180 + degrees) / 360`. Roots and balls have 0 in `7..10`.
//! - `heading`: each agent's root yaw in `(-pi, pi]` (the angle of the root's x axis
//!   projected on the ground, from world x towards world y).
//!
//! # Entity types (scalars `0..3`; every node of an agent, root and DoF nodes, alike)
//! | column | Team Reach | Team Sumo, seen from team `t` |
//! |---|---|---|
//! | 0 [`ENTITY_AGENT`] | agent | agent of team `t` (own) |
//! | 1 [`ENTITY_GOAL`] / [`ENTITY_OPPONENT`] | goal ball | agent of the other team |
//! | 2 [`ENTITY_CENTRE`] | unused | centre ball |
//!
//! One [`Observation`](crate::layout::Observation) serves both teams, so its arrays hold team 0's view;
//! [`ObsSpec::to_team_view`] turns them into team 1's (swaps columns 0 and 1 of the agent
//! nodes). This follows the release's Sumo observer (alpc91/SMERL,
//! `mix_colla_compe_team_tasks/procedural_envs/misc/observers.py`, `GraphObserver`:
//! `get_obs_fn(node_names, 0)` for the viewing group's bodies, `(node_names2, 1)` for the
//! other team's roots, `(node_center, 2)` for the centre), which builds one observer per team.
//! Differences: the release's Sumo observation holds only the opponents' roots, ours every
//! node of every agent (an agent's view, [`ObsSpec::agent_view`], takes only their roots);
//! its Reach observer has two columns (`jnp.eye(2)`: agent, ball), ours three with column 2
//! unused, so that one layout serves both games.
//!
//! # Limb types (scalars `3..7`)
//! Per body, from the release's AMORPHEUS table (alpc91/SMERL,
//! `mix_colla_compe_team_tasks/procedural_envs/tasks/observation_config/one_hot_limb_id.py`,
//! looked up by body name in both observers): `torso`, `torso_0` torso; `Aux 1_i`, `Aux 2_i`,
//! `torso_1` ..= `torso_10` (the centipede's later segments), `d1_limb_i` thigh;
//! `$ Body 4_i`, `$ Body 5_i`, `d2_limb_i` leg; `d3_limb_i` foot; `limb_end_i` (the unimals'
//! limb ends) and `d4_limb_i` no limb type (all four 0); plus the table's other names (the
//! MuJoCo benchmarks'). A 2-DoF joint's two nodes show the same body, hence the same type. A
//! body not in the table (only in morphologies loaded from files; the release would fail
//! there) keeps the former rule: torso for the root and any body whose name contains
//! "torso", else the number of joints down from the nearest such body, 1 thigh, 2 leg, 3 or
//! more foot.
//!
//! Under a rotation about the vertical the vectors rotate (positions about the rotation's
//! axis), the scalars do not change and the headings shift by the angle. Non-finite values
//! (a diverged simulation) are written as 0.

use crate::layout::{ENTITY_AGENT, ENTITY_CENTRE, ENTITY_GOAL, ENTITY_OPPONENT, N_SCALARS, NODE_VECTOR_LEN, ObsSpec};

use super::error::TaskError;
use super::scene::{AgentLayout, BALL_RADIUS};
use super::spec::{TaskKind, TaskSpec};
use crate::data::Data;
use crate::math::{cross, sub};
use crate::model::Model;

/// Limb types: torso, thigh, leg, foot (scalars `3..7`; per body as the release's table,
/// module docs).
pub const LIMB_TYPES: [&str; 4] = ["torso", "thigh", "leg", "foot"];
/// Clip of the linear velocities (m/s, per component).
pub const VELOCITY_CLIP: f64 = 10.0;

/// One limb type of the release's AMORPHEUS table (`None`: listed with an all-zero limb
/// type), its plain names and its indexed names (`stem{i}` for `i` in `lo..hi`, written
/// in decimal as Python's f-strings do).
type LimbRow = (Option<usize>, &'static [&'static str], &'static [(&'static str, usize, usize)]);

/// The reference release's AMORPHEUS limb-type table (alpc91/SMERL,
/// `mix_colla_compe_team_tasks/procedural_envs/tasks/observation_config/one_hot_limb_id.py`;
/// the observers of both task folders look a body up by its name without the `agentN___`
/// prefix). No name is in two rows.
const AMORPHEUS: [LimbRow; 5] = [
    (Some(0), &["$ Torso", "torso", "torso_0", "palm"], &[]),
    (
        Some(1),
        &["bthigh", "fthigh", "right_thigh", "left_thigh", "thigh", "thigh_left"],
        &[("Aux 1_", 0, 10), ("Aux 2_", 0, 10), ("thumb_proximal_", 0, 10), ("torso_", 1, 11), ("d1_limb_", 0, 22)],
    ),
    (
        Some(2),
        &["bshin", "fshin", "leg", "lower_leg", "right_shin", "left_shin", "leg_left"],
        &[("$ Body 4_", 0, 10), ("$ Body 5_", 0, 10), ("thumb_middle_", 0, 10), ("d2_limb_", 0, 22)],
    ),
    (Some(3), &["bfoot", "ffoot", "foot", "foot_left"], &[("thumb_distal_", 0, 10), ("d3_limb_", 0, 22)]),
    // The goal bodies and the "others" (all zero in the release).
    (
        None,
        &[
            "Ball",
            "Target",
            "Box",
            "Z_Target",
            "lwaist",
            "pelvis",
            "right_upper_arm",
            "right_lower_arm",
            "left_upper_arm",
            "left_lower_arm",
        ],
        &[("Ball_", 0, 3), ("Z_Target_", 0, 3), ("d4_limb_", 0, 22), ("limb_end_", 0, 22)],
    ),
];

/// Whether `name` is `stem` followed by a decimal `i` in `lo..hi` (no sign, no leading zero).
fn is_indexed(name: &str, (stem, lo, hi): (&str, usize, usize)) -> bool {
    let Some(digits) = name.strip_prefix(stem) else { return false };
    let canonical =
        !digits.is_empty() && digits.bytes().all(|c| c.is_ascii_digit()) && (digits == "0" || !digits.starts_with('0'));
    canonical && digits.parse::<usize>().is_ok_and(|i| (lo..hi).contains(&i))
}

/// The release's limb type for a body name: `Some(Some(l))` limb type `l`, `Some(None)` listed
/// with no limb type, `None` not in the table.
fn amorpheus_limb_type(name: &str) -> Option<Option<usize>> {
    AMORPHEUS
        .iter()
        .find(|(_, names, indexed)| names.contains(&name) || indexed.iter().any(|&stem| is_indexed(name, stem)))
        .map(|&(limb, _, _)| limb)
}

/// Limb type of a body (`None`: no limb type, all four scalars 0). A body whose name (without
/// the agent's prefix) is in the release's table gets the table's type; any other body (only
/// in morphologies loaded from files) the rule: `torso` for the root and any body whose name
/// contains "torso", otherwise the number of joints down from the nearest such body, 1 thigh,
/// 2 leg, 3 or more foot.
fn limb_type(model: &Model, agent: &AgentLayout, body: usize) -> Option<usize> {
    let name = &model.bodies[body].name;
    if let Some(limb) = amorpheus_limb_type(name.strip_prefix(agent.prefix.as_str()).unwrap_or(name)) {
        return limb;
    }
    let is_torso = |b: usize| b == agent.root_body || model.bodies[b].name.to_lowercase().contains("torso");
    let mut depth = 0;
    let mut b = body;
    while !is_torso(b) {
        depth += 1;
        b = model.bodies[b].parent;
    }
    Some(depth.min(3))
}

fn scaled_limit(radians: f64) -> f32 {
    ((180.0 + radians.to_degrees()) / 360.0) as f32
}

/// The observation layout of a scene: `model` with `agents` laid out for `spec`.
pub fn obs_spec(spec: &TaskSpec, model: &Model, agents: &[AgentLayout]) -> Result<ObsSpec, TaskError> {
    let mut o = ObsSpec {
        n_nodes: 0,
        n_agents: agents.len(),
        n_teams: spec.n_teams(),
        n_balls: spec.balls,
        node_agent: Vec::new(),
        node_team: Vec::new(),
        node_parent: Vec::new(),
        node_is_root: Vec::new(),
        node_body: Vec::new(),
        node_joint: Vec::new(),
        agent_team: agents.iter().map(|a| a.team).collect(),
        agent_root_node: Vec::new(),
        agent_dof: agents.iter().map(|a| a.n_actions()).collect(),
        agent_action_offset: agents.iter().map(|a| a.action_offset).collect(),
        entity_root_node: Vec::new(),
        gravity_dir: [0.0, 0.0, -1.0],
        static_scalars: Vec::new(),
    };
    let scal = |entity: usize, limb: Option<usize>, range: Option<[f64; 2]>| {
        let mut s = [0.0f32; N_SCALARS];
        s[entity] = 1.0;
        if let Some(l) = limb {
            s[3 + l] = 1.0;
        }
        if let Some([lo, hi]) = range {
            s[8] = scaled_limit(lo);
            s[9] = scaled_limit(hi);
        }
        s
    };
    let mut static_scalars: Vec<[f32; N_SCALARS]> = Vec::new();
    for (ai, a) in agents.iter().enumerate() {
        let root = o.node_agent.len();
        o.agent_root_node.push(root);
        o.entity_root_node.push(root);
        o.node_agent.push(ai as i32);
        o.node_team.push(a.team as i32);
        o.node_parent.push(-1);
        o.node_is_root.push(true);
        o.node_body.push(Some(a.root_body));
        o.node_joint.push(None);
        // Raw observation = team 0's view: Sumo's team 1 are the opponents.
        let entity = if spec.kind == TaskKind::Sumo && a.team != 0 { ENTITY_OPPONENT } else { ENTITY_AGENT };
        static_scalars.push(scal(entity, limb_type(model, a, a.root_body), None));
        // (body, joint, node) of this agent's DoF nodes so far.
        let mut dof_nodes: Vec<(usize, usize, usize)> = Vec::new();
        for &act in &a.actuators {
            let joint = model.actuators[act].joint;
            let body = model.joints[joint].body;
            dof_nodes.push((body, joint, root + dof_nodes.len() + 1));
        }
        for &(body, joint, _) in &dof_nodes {
            // Parent: the last DoF node of the same body with an earlier joint, else the
            // last DoF node of the nearest ancestor body that has one, else the root.
            let last_on = |b: usize, before: usize| {
                dof_nodes.iter().filter(|&&(b2, j2, _)| b2 == b && j2 < before).max_by_key(|t| t.1).map(|t| t.2)
            };
            let mut parent = last_on(body, joint);
            let mut b = body;
            while parent.is_none() && b != a.root_body && b != 0 {
                b = model.bodies[b].parent;
                parent = last_on(b, usize::MAX);
            }
            o.node_parent.push(parent.unwrap_or(root) as i32);
            o.node_agent.push(ai as i32);
            o.node_team.push(a.team as i32);
            o.node_is_root.push(false);
            o.node_body.push(Some(body));
            o.node_joint.push(Some(joint));
            let j = &model.joints[joint];
            let range = if j.limited { j.range } else { [0.0, 0.0] };
            static_scalars.push(scal(entity, limb_type(model, a, body), Some(range)));
        }
    }
    let ball_type = if spec.kind == TaskKind::Reach { ENTITY_GOAL } else { ENTITY_CENTRE };
    for _ in 0..spec.balls {
        o.entity_root_node.push(o.node_agent.len());
        o.node_agent.push(-1);
        o.node_team.push(-1);
        o.node_parent.push(-1);
        o.node_is_root.push(true);
        o.node_body.push(None);
        o.node_joint.push(None);
        static_scalars.push(scal(ball_type, None, None));
    }
    o.n_nodes = o.node_agent.len();
    o.static_scalars = static_scalars.concat();
    Ok(o)
}

/// Writes one environment's observation row of a scene laid out by `spec`. `data` must have
/// its kinematics and velocities computed for the current state (`kinematics`, `com_pos`,
/// `com_vel`); `balls` are the ball positions (x, y) of the episode. Slices are this
/// environment's parts of [`Observation`](crate::layout::Observation)'s arrays (`N * NODE_VECTOR_LEN`, `N * N_SCALARS`,
/// `A` long; shorter slices or fewer balls than the scene has panic: this is the
/// environment's internal writer).
pub fn write_row(
    spec: &ObsSpec,
    model: &Model,
    data: &Data,
    balls: &[[f64; 2]],
    vectors: &mut [f32],
    scalars: &mut [f32],
    heading: &mut [f32],
) {
    let fin = |x: f64| if x.is_finite() { x as f32 } else { 0.0 };
    scalars.copy_from_slice(&spec.static_scalars);
    for n in 0..spec.n_nodes {
        let v = &mut vectors[n * NODE_VECTOR_LEN..(n + 1) * NODE_VECTOR_LEN];
        match spec.node_body[n] {
            Some(b) => {
                let tree = model.bodies[b].tree;
                let cv = data.cvel[b];
                let w = [cv[0], cv[1], cv[2]];
                let lever = sub(data.xpos[b], data.tree_ref[tree]);
                let wl = cross(w, lever);
                for k in 0..3 {
                    v[k] = fin(data.xpos[b][k]);
                    v[3 + k] = fin((cv[3 + k] + wl[k]).clamp(-VELOCITY_CLIP, VELOCITY_CLIP));
                    v[6 + k] = fin(w[k]);
                }
            }
            None => {
                let ball = balls[n - (spec.n_nodes - spec.n_balls)];
                v.copy_from_slice(&[fin(ball[0]), fin(ball[1]), BALL_RADIUS as f32, 0., 0., 0., 0., 0., 0.]);
            }
        }
        if let Some(j) = spec.node_joint[n] {
            let jnt = &model.joints[j];
            let q = data.qpos[jnt.qpos_adr];
            let [lo, hi] = jnt.range;
            let x = if jnt.limited && hi > lo { (q - lo) / (hi - lo) } else { 0.5 };
            scalars[n * N_SCALARS + 7] = fin(x);
        }
    }
    for (a, &root) in spec.agent_root_node.iter().enumerate() {
        let Some(b) = spec.node_body[root] else { continue };
        let m = &data.xmat[b];
        heading[a] = fin(m[1][0].atan2(m[0][0]));
    }
}

#[cfg(test)]
mod tests {
    use super::amorpheus_limb_type;

    #[test]
    fn the_release_table_matches_whole_names_and_its_index_ranges_only() {
        for (name, want) in [
            ("torso", Some(Some(0))),
            ("torso_0", Some(Some(0))),
            ("torso_1", Some(Some(1))),
            ("torso_10", Some(Some(1))),
            ("torso_11", None),
            ("torso_01", None),
            ("Aux 2_9", Some(Some(1))),
            ("Aux 2_10", None),
            ("Aux 2_", None),
            ("Aux 2_+1", None),
            ("$ Body 5_0", Some(Some(2))),
            ("d2_limb_21", Some(Some(2))),
            ("d3_limb_0", Some(Some(3))),
            ("limb_end_21", Some(None)),
            ("limb_end_22", None),
            ("Ball_2", Some(None)),
            ("a0/torso", None),
            ("Torso", None),
        ] {
            assert_eq!(amorpheus_limb_type(name), want, "{name:?}");
        }
    }
}
