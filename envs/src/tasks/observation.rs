//! Observations that a model can use without knowing the simulator: batch-first flat `f32`
//! arrays over the *nodes* of every environment, plus a static [`ObsSpec`] describing what
//! each node is (the same for every environment and every step).
//!
//! # Nodes (MEBEN.md section 4, one global list per environment)
//! For each agent `a` in order (team 0's agents, then team 1's): its root node, then one node
//! per actuated DoF in action order (the node of action `k` of agent `a` is
//! `agent_root_node[a] + 1 + k`; it shows the body that DoF moves). Then one node per ball
//! (Reach: the goal balls; Sumo: the centre ball). `N = sum_a (1 + dof_a) + balls`.
//! Each agent's view in MeBen (its own nodes + the roots of every other entity) is a selection
//! of these nodes: [`ObsSpec::entity_root_node`] lists every entity's root node.
//!
//! # Per step ([`Observation`])
//! - `vectors`: `[B, N, 3, 3]`, per node three world-frame 3-vectors: `[.., 0, :]` position
//!   (m), `[.., 1, :]` linear velocity of the body origin clipped to +-10 m/s per component,
//!   `[.., 2, :]` angular velocity (rad/s). Balls: position of the centre, velocities 0.
//! - `scalars`: `[B, N, S]` with `S = N_SCALARS = 10`: `0..3` entity type one-hot (below),
//!   `3..7` limb type one-hot (torso, thigh, leg, foot; below), `7` joint angle scaled to
//!   `[0, 1]` within its limits (`(q - lo) / (hi - lo)`, 0.5 for a DoF locked by equal
//!   limits; soft limits may let it stray slightly outside), `8, 9` the lower and upper limits
//!   scaled as `(180 + degrees) / 360`. Roots and balls have 0 in `7..10`.
//! - `heading`: `[B, A]`, each agent's root yaw in `(-pi, pi]` (the angle of the root's x
//!   axis projected on the ground, from world x towards world y).
//!
//! # Entity types (scalars `0..3`; every node of an agent, root and DoF nodes, alike)
//! | column | Team Reach | Team Sumo, seen from team `t` |
//! |---|---|---|
//! | 0 [`ENTITY_AGENT`] | agent | agent of team `t` (own) |
//! | 1 [`ENTITY_GOAL`] / [`ENTITY_OPPONENT`] | goal ball | agent of the other team |
//! | 2 [`ENTITY_CENTRE`] | unused | centre ball |
//!
//! One [`Observation`] serves both teams, so its arrays hold team 0's view;
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

use super::error::TaskError;
use super::scene::{AgentLayout, BALL_RADIUS};
use super::spec::{TaskKind, TaskSpec};
use crate::data::Data;
use crate::math::{cross, sub};
use crate::model::Model;

/// Scalars per node.
pub const N_SCALARS: usize = 10;
/// Entity type column of an agent's nodes: in Team Reach every agent; in Team Sumo an agent
/// of the viewing team ("own"; the raw observation is team 0's view, see
/// [`ObsSpec::to_team_view`]).
pub const ENTITY_AGENT: usize = 0;
/// Entity type column of a Team Sumo opponent's nodes (an agent of the other team than the
/// viewing one). The same column as [`ENTITY_GOAL`]: Reach has no opponents, Sumo no goals.
pub const ENTITY_OPPONENT: usize = 1;
/// Entity type column of a Team Reach goal ball.
pub const ENTITY_GOAL: usize = 1;
/// Entity type column of the Team Sumo centre ball.
pub const ENTITY_CENTRE: usize = 2;
/// Limb types: torso, thigh, leg, foot (scalars `3..7`; per body as the release's table,
/// module docs).
pub const LIMB_TYPES: [&str; 4] = ["torso", "thigh", "leg", "foot"];
/// Clip of the linear velocities (m/s, per component).
pub const VELOCITY_CLIP: f64 = 10.0;

/// Static description of the observation arrays of one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsSpec {
    /// Nodes per environment (`N`).
    pub n_nodes: usize,
    /// Agents per environment (`A`).
    pub n_agents: usize,
    /// Teams (1 for Reach, 2 for Sumo).
    pub n_teams: usize,
    /// Balls per environment (`M`; their nodes are the last `M`).
    pub n_balls: usize,
    /// Agent of each node, `-1` for balls.
    pub node_agent: Vec<i32>,
    /// Team of each node, `-1` for balls.
    pub node_team: Vec<i32>,
    /// Parent node of each node (the morphology graph), `-1` for roots and balls. A DoF node's
    /// parent is the previous DoF node of the same body (2-DoF joints chain), else the last
    /// DoF node of the nearest ancestor body that has one, else the agent's root node.
    pub node_parent: Vec<i32>,
    /// Whether the node is an entity root (an agent's root or a ball).
    pub node_is_root: Vec<bool>,
    /// Model body shown by each node (`None` for balls).
    pub node_body: Vec<Option<usize>>,
    /// Model hinge joint of each DoF node (`None` for roots and balls).
    pub node_joint: Vec<Option<usize>>,
    /// Team of each agent.
    pub agent_team: Vec<usize>,
    /// Root node of each agent.
    pub agent_root_node: Vec<usize>,
    /// Actuated DoF (action length) of each agent.
    pub agent_dof: Vec<usize>,
    /// First action of each agent in an environment's action row.
    pub agent_action_offset: Vec<usize>,
    /// Root node of every entity: the agents in order, then the balls.
    pub entity_root_node: Vec<usize>,
    /// Unit gravity direction (world frame): `[0, 0, -1]`.
    pub gravity_dir: [f32; 3],
    /// Scalars that never change (everything but the joint angle), `[N, N_SCALARS]`, in the
    /// raw view (team 0's; [`ObsSpec::to_team_view`] gives team 1's).
    pub static_scalars: Vec<f32>,
}

/// One batch of observations (layout in the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// Environments (`B`).
    pub batch: usize,
    /// Nodes per environment (`N`).
    pub nodes: usize,
    /// Agents per environment (`A`).
    pub agents: usize,
    /// `[B, N, 3, 3]`: position, clipped linear velocity, angular velocity (world frame).
    pub vectors: Vec<f32>,
    /// `[B, N, N_SCALARS]`, team 0's view ([`ObsSpec::to_team_view`]).
    pub scalars: Vec<f32>,
    /// `[B, A]`: root yaw of each agent (rad).
    pub heading: Vec<f32>,
}

impl Observation {
    /// Zeroed arrays for `batch` environments of `spec`.
    pub fn zeros(spec: &ObsSpec, batch: usize) -> Observation {
        Observation {
            batch,
            nodes: spec.n_nodes,
            agents: spec.n_agents,
            vectors: vec![0.0; batch * spec.n_nodes * 9],
            scalars: vec![0.0; batch * spec.n_nodes * N_SCALARS],
            heading: vec![0.0; batch * spec.n_agents],
        }
    }

    /// Copies environment `env` of `from` into environment `env` of `self` (same shapes).
    pub fn copy_row_from(&mut self, from: &Observation, env: usize) {
        let (v, s, h) = (self.nodes * 9, self.nodes * N_SCALARS, self.agents);
        self.vectors[env * v..(env + 1) * v].copy_from_slice(&from.vectors[env * v..(env + 1) * v]);
        self.scalars[env * s..(env + 1) * s].copy_from_slice(&from.scalars[env * s..(env + 1) * s]);
        self.heading[env * h..(env + 1) * h].copy_from_slice(&from.heading[env * h..(env + 1) * h]);
    }

    /// The vector `k` (0 position, 1 velocity, 2 angular velocity) of node `node` in `env`.
    /// Panics when an index is out of range (as slice indexing does).
    pub fn vector(&self, env: usize, node: usize, k: usize) -> [f32; 3] {
        let i = ((env * self.nodes + node) * 3 + k) * 3;
        [self.vectors[i], self.vectors[i + 1], self.vectors[i + 2]]
    }

    /// The scalars of node `node` in `env`. Panics when an index is out of range.
    pub fn node_scalars(&self, env: usize, node: usize) -> &[f32] {
        let i = (env * self.nodes + node) * N_SCALARS;
        &self.scalars[i..i + N_SCALARS]
    }
}

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

impl ObsSpec {
    /// The layout of a scene's observations.
    pub fn new(spec: &TaskSpec, model: &Model, agents: &[AgentLayout]) -> Result<ObsSpec, TaskError> {
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

    /// MeBen's view of agent `agent` (section 4): its own nodes (root, then one per actuated
    /// DoF in action order), then the root node of every other entity (the other agents in
    /// order, then the balls). Empty for an unknown agent.
    pub fn agent_view(&self, agent: usize) -> Vec<usize> {
        let Some(&root) = self.agent_root_node.get(agent) else {
            return Vec::new();
        };
        let own = root..root + 1 + self.agent_dof[agent];
        let others = self.entity_root_node.iter().copied().filter(|&n| n != root);
        own.chain(others).collect()
    }

    /// Turns observation scalars (`[B, N, N_SCALARS]`, any element type; a single row such as
    /// [`ObsSpec::static_scalars`] is a batch of one) from the raw view into team `team`'s
    /// view, in place. The raw observation is team 0's view. For team 1 of a Team Sumo scene
    /// it swaps the entity-type columns [`ENTITY_AGENT`] and [`ENTITY_OPPONENT`] of every
    /// agent node (roots and DoF nodes), so that team 1's agents read "own" and team 0's
    /// "opponent"; the centre ball and every other column stay. For team 0, and for Team
    /// Reach (one team), it changes nothing. Applying team 1's view twice gives the raw view
    /// back. No allocation; one swap per agent node and row.
    ///
    /// Errors ([`TaskError::BadArgument`], nothing changed): `team` not below
    /// [`ObsSpec::n_teams`], or a length that is not a whole number of `N * N_SCALARS` rows.
    pub fn to_team_view<S>(&self, team: usize, scalars: &mut [S]) -> Result<(), TaskError> {
        if team >= self.n_teams {
            return Err(TaskError::BadArgument {
                what: "team".into(),
                value: team.to_string(),
                message: format!("this scene has {} team(s), numbered from 0", self.n_teams),
            });
        }
        let row = self.n_nodes * N_SCALARS;
        if row == 0 || !scalars.len().is_multiple_of(row) {
            return Err(TaskError::BadArgument {
                what: "scalars length".into(),
                value: scalars.len().to_string(),
                message: format!("expected a multiple of N * N_SCALARS = {} * {N_SCALARS}", self.n_nodes),
            });
        }
        // Team Sumo is the only two-team game; team 0's view is the raw one.
        if team == 0 || self.n_teams != 2 {
            return Ok(());
        }
        // Agent nodes are the first N - M nodes of a row (the balls come last).
        let agent_scalars = (self.n_nodes - self.n_balls) * N_SCALARS;
        for r in scalars.chunks_exact_mut(row) {
            for node in r[..agent_scalars].chunks_exact_mut(N_SCALARS) {
                node.swap(ENTITY_AGENT, ENTITY_OPPONENT);
            }
        }
        Ok(())
    }

    /// Writes one environment's observation row. `data` must have its kinematics and
    /// velocities computed for the current state (`kinematics`, `com_pos`, `com_vel`);
    /// `balls` are the ball positions (x, y) of the episode. Slices are this environment's
    /// parts of [`Observation`]'s arrays (`N * 9`, `N * N_SCALARS`, `A` long; shorter slices
    /// or fewer balls than the scene has panic: this is the environment's internal writer).
    pub fn write_row(
        &self,
        model: &Model,
        data: &Data,
        balls: &[[f64; 2]],
        vectors: &mut [f32],
        scalars: &mut [f32],
        heading: &mut [f32],
    ) {
        let fin = |x: f64| if x.is_finite() { x as f32 } else { 0.0 };
        scalars.copy_from_slice(&self.static_scalars);
        for n in 0..self.n_nodes {
            let v = &mut vectors[n * 9..n * 9 + 9];
            match self.node_body[n] {
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
                    let ball = balls[n - (self.n_nodes - self.n_balls)];
                    v.copy_from_slice(&[fin(ball[0]), fin(ball[1]), BALL_RADIUS as f32, 0., 0., 0., 0., 0., 0.]);
                }
            }
            if let Some(j) = self.node_joint[n] {
                let jnt = &model.joints[j];
                let q = data.qpos[jnt.qpos_adr];
                let [lo, hi] = jnt.range;
                let x = if jnt.limited && hi > lo { (q - lo) / (hi - lo) } else { 0.5 };
                scalars[n * N_SCALARS + 7] = fin(x);
            }
        }
        for (a, &root) in self.agent_root_node.iter().enumerate() {
            let Some(b) = self.node_body[root] else { continue };
            let m = &data.xmat[b];
            heading[a] = fin(m[1][0].atan2(m[0][0]));
        }
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
