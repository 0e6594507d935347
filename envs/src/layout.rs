//! The observation layout the models read and the environments produce: batch-first flat
//! arrays over the *nodes* of every environment, a static [`ObsSpec`] describing what each
//! node is (the same for every environment and every step), and views of whole observation
//! rows ([`ObsRows`], [`ObsBatch`]) so that no caller recomputes a stride.
//!
//! The environment owns its observations, as in Gymnasium: `envs` declares this layout and
//! fills it (`envs::tasks::observation` builds the [`ObsSpec`] of a scene and writes the
//! rows); the models (crate `models`) and the learner read it from here.
//!
//! # Nodes (MEBEN.md section 4, one global list per environment)
//! For each agent `a` in order (team 0's agents, then team 1's): its root node, then one node
//! per actuated DoF in action order (the node of action `k` of agent `a` is
//! `agent_root_node[a] + 1 + k`; it shows the body that DoF moves). Then one node per ball
//! (Reach: the goal balls; Sumo: the centre ball). `N = sum_a (1 + dof_a) + balls`.
//! Each agent's view in MeBen (its own nodes + the roots of every other entity) is a selection
//! of these nodes: [`ObsSpec::entity_root_node`] lists every entity's root node.
//!
//! # One row (one environment at one step)
//! - `vectors`: `[N, 3, 3]`, per node [`NODE_VECTORS`] world-frame 3-vectors
//!   ([`NODE_VECTOR_LEN`] numbers): `[.., 0, :]` position (m), `[.., 1, :]` linear velocity
//!   of the body origin, `[.., 2, :]` angular velocity (rad/s). Balls: position of the centre,
//!   velocities 0.
//! - `scalars`: `[N, N_SCALARS]`: `0..3` entity type one-hot (below), `3..7` limb type
//!   one-hot (torso, thigh, leg, foot), `7` joint angle scaled to `[0, 1]` within its limits,
//!   `8, 9` the lower and upper limits scaled as `(180 + degrees) / 360`. Roots and balls have
//!   0 in `7..10`.
//! - `heading`: `[A]`, each agent's root yaw in `(-pi, pi]`.
//!
//! A batch of `B` rows ([`Observation`], [`ObsRows`]) holds `B` of each, row after row.
//!
//! # Entity types (scalars `0..3`; every node of an agent, root and DoF nodes, alike)
//! | column | Team Reach | Team Sumo, seen from team `t` |
//! |---|---|---|
//! | 0 [`ENTITY_AGENT`] | agent | agent of team `t` (own) |
//! | 1 [`ENTITY_GOAL`] / [`ENTITY_OPPONENT`] | goal ball | agent of the other team |
//! | 2 [`ENTITY_CENTRE`] | unused | centre ball |
//!
//! One observation serves both teams, so its arrays hold team 0's view;
//! [`ObsSpec::to_team_view`] turns them into team 1's (swaps columns 0 and 1 of the agent
//! nodes).

use std::ops::Range;

/// An observation, spec or assignment whose shapes or contents do not fit together (the
/// message says how).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LayoutError(pub String);

impl std::fmt::Display for LayoutError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for LayoutError {}

/// `Result` with [`LayoutError`].
pub type Result<T> = std::result::Result<T, LayoutError>;

/// Scalars per node.
pub const N_SCALARS: usize = 10;

/// Vector channels per node: position, linear velocity, angular velocity.
pub const NODE_VECTORS: usize = 3;

/// Numbers of a node's vectors: three 3-vectors, `[3, 3]` (channel-major).
pub const NODE_VECTOR_LEN: usize = NODE_VECTORS * 3;

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
    /// The producer's (simulator's) body shown by each node (`None` for balls); no model
    /// reads it.
    pub node_body: Vec<Option<usize>>,
    /// The producer's hinge joint of each DoF node (`None` for roots and balls); no model
    /// reads it.
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

impl ObsSpec {
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

    /// The lengths of one observation row of this scene.
    pub fn row_widths(&self) -> RowWidths {
        RowWidths::new(self.n_nodes, self.n_agents)
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
    /// Errors ([`LayoutError`], nothing changed): `team` not below
    /// [`ObsSpec::n_teams`], or a length that is not a whole number of `N * N_SCALARS` rows.
    pub fn to_team_view<S>(&self, team: usize, scalars: &mut [S]) -> Result<()> {
        if team >= self.n_teams {
            return Err(LayoutError(format!(
                "bad team = {team}: this scene has {} team(s), numbered from 0",
                self.n_teams
            )));
        }
        let row = self.n_nodes * N_SCALARS;
        if row == 0 || !scalars.len().is_multiple_of(row) {
            return Err(LayoutError(format!(
                "bad scalars length = {}: expected a multiple of N * N_SCALARS = {} * {N_SCALARS}",
                scalars.len(),
                self.n_nodes
            )));
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
}

/// The lengths of the three parts of one observation row (one environment).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowWidths {
    /// `N * NODE_VECTOR_LEN` vector components.
    pub vectors: usize,
    /// `N * N_SCALARS` scalars.
    pub scalars: usize,
    /// `A` headings.
    pub heading: usize,
}

impl RowWidths {
    /// The widths of a row of `nodes` nodes and `agents` agents.
    pub fn new(nodes: usize, agents: usize) -> Self {
        Self { vectors: nodes * NODE_VECTOR_LEN, scalars: nodes * N_SCALARS, heading: agents }
    }
}

/// A batch of observation rows (layout in the module docs), owned. Also serves as a growable
/// buffer of rows ([`Observation::empty`], [`Observation::push_rows`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// Environments (`B`), i.e. rows.
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
        let w = spec.row_widths();
        Observation {
            batch,
            nodes: spec.n_nodes,
            agents: spec.n_agents,
            vectors: vec![0.0; batch * w.vectors],
            scalars: vec![0.0; batch * w.scalars],
            heading: vec![0.0; batch * w.heading],
        }
    }

    /// No rows yet, of `nodes` nodes and `agents` agents each.
    pub fn empty(nodes: usize, agents: usize) -> Observation {
        Observation { batch: 0, nodes, agents, vectors: Vec::new(), scalars: Vec::new(), heading: Vec::new() }
    }

    /// The lengths of one row.
    pub fn row_widths(&self) -> RowWidths {
        RowWidths::new(self.nodes, self.agents)
    }

    /// Every row, borrowed.
    pub fn rows(&self) -> ObsRows<'_, f32> {
        ObsRows {
            rows: self.batch,
            nodes: self.nodes,
            agents: self.agents,
            vectors: &self.vectors,
            scalars: &self.scalars,
            heading: &self.heading,
        }
    }

    /// Copies environment `env` of `from` into environment `env` of `self` (same shapes).
    pub fn copy_row_from(&mut self, from: &Observation, env: usize) {
        self.write_rows(env, from.rows().slice(env..env + 1));
    }

    /// Overwrites rows `at..at + rows.len()` with `rows` (same row shape). Panics when they
    /// do not fit (as slice indexing does).
    pub fn write_rows(&mut self, at: usize, rows: ObsRows<'_, f32>) {
        let w = self.row_widths();
        let n = rows.len();
        self.vectors[at * w.vectors..(at + n) * w.vectors].copy_from_slice(rows.vectors);
        self.scalars[at * w.scalars..(at + n) * w.scalars].copy_from_slice(rows.scalars);
        self.heading[at * w.heading..(at + n) * w.heading].copy_from_slice(rows.heading);
    }

    /// Appends `rows` (same row shape).
    pub fn push_rows(&mut self, rows: ObsRows<'_, f32>) {
        self.vectors.extend_from_slice(rows.vectors);
        self.scalars.extend_from_slice(rows.scalars);
        self.heading.extend_from_slice(rows.heading);
        self.batch += rows.len();
    }

    /// Forgets every row (keeps the storage).
    pub fn clear(&mut self) {
        self.vectors.clear();
        self.scalars.clear();
        self.heading.clear();
        self.batch = 0;
    }

    /// The vector `k` (0 position, 1 velocity, 2 angular velocity) of node `node` in `env`.
    /// Panics when an index is out of range (as slice indexing does).
    pub fn vector(&self, env: usize, node: usize, k: usize) -> [f32; 3] {
        let i = (env * self.nodes + node) * NODE_VECTOR_LEN + k * 3;
        [self.vectors[i], self.vectors[i + 1], self.vectors[i + 2]]
    }

    /// The scalars of node `node` in `env`. Panics when an index is out of range.
    pub fn node_scalars(&self, env: usize, node: usize) -> &[f32] {
        let i = (env * self.nodes + node) * N_SCALARS;
        &self.scalars[i..i + N_SCALARS]
    }
}

/// Element types observations can be read from (`f32`, `f64`).
pub trait ObsElement: Copy + Into<f64> {}
impl ObsElement for f32 {}
impl ObsElement for f64 {}

/// Borrowed observation rows with their three named parts (`f32` as the environments produce
/// them, or `f64` for exact equivariance tests): what a model is given.
#[derive(Clone, Copy, Debug)]
pub struct ObsRows<'a, S = f32> {
    /// Rows `R`.
    pub rows: usize,
    /// Nodes per row `N`.
    pub nodes: usize,
    /// Agents per row `A`.
    pub agents: usize,
    /// `[R, N, 3, 3]`.
    pub vectors: &'a [S],
    /// `[R, N, N_SCALARS]`.
    pub scalars: &'a [S],
    /// `[R, A]`.
    pub heading: &'a [S],
}

impl<'a, S: Copy> ObsRows<'a, S> {
    /// Checks that the arrays hold whole rows of `nodes` nodes and `agents` agents, the same
    /// number in each (with no agent the row count comes from the nodes).
    pub fn new(nodes: usize, agents: usize, vectors: &'a [S], scalars: &'a [S], heading: &'a [S]) -> Result<Self> {
        let w = RowWidths::new(nodes, agents);
        let rows = vectors.len().checked_div(w.vectors).unwrap_or(0);
        if rows * w.vectors != vectors.len() || rows * w.scalars != scalars.len() || rows * w.heading != heading.len() {
            return Err(LayoutError(format!(
                "observation arrays of {} vectors, {} scalars and {} headings are not whole rows of {nodes} nodes \
                 and {agents} agents ({} + {} + {} per row)",
                vectors.len(),
                scalars.len(),
                heading.len(),
                w.vectors,
                w.scalars,
                w.heading
            )));
        }
        Ok(Self { rows, nodes, agents, vectors, scalars, heading })
    }

    /// Rows `R`.
    pub fn len(&self) -> usize {
        self.rows
    }

    /// Whether there is no row.
    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// The lengths of one row.
    pub fn row_widths(&self) -> RowWidths {
        RowWidths::new(self.nodes, self.agents)
    }

    /// Rows `range`. Panics when the range is out of bounds (as slice indexing does).
    pub fn slice(&self, range: Range<usize>) -> ObsRows<'a, S> {
        let w = self.row_widths();
        let (r0, r1) = (range.start, range.end);
        assert!(r0 <= r1 && r1 <= self.rows, "rows {r0}..{r1} of {}", self.rows);
        ObsRows {
            rows: r1 - r0,
            nodes: self.nodes,
            agents: self.agents,
            vectors: &self.vectors[r0 * w.vectors..r1 * w.vectors],
            scalars: &self.scalars[r0 * w.scalars..r1 * w.scalars],
            heading: &self.heading[r0 * w.heading..r1 * w.heading],
        }
    }

    /// The node arrays (vectors and scalars) of the rows.
    pub fn node_batch(&self) -> ObsBatch<'a, S> {
        ObsBatch { batch: self.rows, nodes: self.nodes, vectors: self.vectors, scalars: self.scalars }
    }
}

/// Borrowed node arrays of a batch of observation rows, `vectors` `[B, N, 3, 3]` (per node
/// the position, velocity and angular velocity, each a 3-vector) and `scalars`
/// `[B, N, N_SCALARS]`: what the input processing reads ([`ObsRows`] without the headings).
#[derive(Clone, Copy, Debug)]
pub struct ObsBatch<'a, S> {
    /// Environments `B`.
    pub batch: usize,
    /// Nodes per environment `N`.
    pub nodes: usize,
    /// `[B, N, 3, 3]`.
    pub vectors: &'a [S],
    /// `[B, N, N_SCALARS]`.
    pub scalars: &'a [S],
}

impl<'a> ObsBatch<'a, f32> {
    /// Borrows the arrays of an environment observation.
    pub fn from_observation(o: &'a Observation) -> Self {
        o.rows().node_batch()
    }
}

impl<'a, S: ObsElement> ObsBatch<'a, S> {
    /// Checks that the arrays hold `batch` environments of `nodes` nodes.
    pub fn new(batch: usize, nodes: usize, vectors: &'a [S], scalars: &'a [S]) -> Result<Self> {
        let w = RowWidths::new(nodes, 0);
        if vectors.len() != batch * w.vectors || scalars.len() != batch * w.scalars {
            return Err(LayoutError(format!(
                "observation arrays of {} vectors and {} scalars do not hold {batch} x {nodes} nodes \
                 (expected {} and {})",
                vectors.len(),
                scalars.len(),
                batch * w.vectors,
                batch * w.scalars
            )));
        }
        Ok(Self { batch, nodes, vectors, scalars })
    }

    /// The [`NODE_VECTOR_LEN`] numbers of `node` in `env`: position, velocity, angular
    /// velocity.
    #[inline]
    pub fn node_vectors(&self, env: usize, node: usize) -> &'a [S] {
        let i = (env * self.nodes + node) * NODE_VECTOR_LEN;
        &self.vectors[i..i + NODE_VECTOR_LEN]
    }

    /// The [`N_SCALARS`] scalars of `node` in `env`.
    #[inline]
    pub fn node_scalars(&self, env: usize, node: usize) -> &'a [S] {
        let i = (env * self.nodes + node) * N_SCALARS;
        &self.scalars[i..i + N_SCALARS]
    }

    /// Vector `k` (0 position, 1 velocity, 2 angular velocity) of `node` in `env`.
    #[inline]
    pub fn vec3(&self, env: usize, node: usize, k: usize) -> [f64; 3] {
        let i = (env * self.nodes + node) * NODE_VECTOR_LEN + k * 3;
        [self.vectors[i].into(), self.vectors[i + 1].into(), self.vectors[i + 2].into()]
    }

    /// Scalar `s` of `node` in `env`.
    #[inline]
    pub fn scalar(&self, env: usize, node: usize, s: usize) -> f64 {
        self.scalars[(env * self.nodes + node) * N_SCALARS + s].into()
    }

    /// Checks the arrays against `spec`: whole rows of its nodes, at least one.
    pub fn check(&self, spec: &ObsSpec) -> Result<()> {
        Self::new(self.batch, self.nodes, self.vectors, self.scalars)?;
        if self.nodes != spec.n_nodes || self.batch == 0 {
            return Err(LayoutError(format!(
                "observations of {} environments x {} nodes for a scene of {} nodes",
                self.batch, self.nodes, spec.n_nodes
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(n: usize) -> Observation {
        let mut o = Observation::empty(2, 1);
        for r in 0..n {
            let v: Vec<f32> = (0..2 * NODE_VECTOR_LEN).map(|i| (r * 100 + i) as f32).collect();
            let s: Vec<f32> = (0..2 * N_SCALARS).map(|i| -((r * 100 + i) as f32)).collect();
            let h = [r as f32];
            o.push_rows(ObsRows::new(2, 1, &v, &s, &h).unwrap());
        }
        o
    }

    #[test]
    fn rows_slice_push_and_write_back_whole_rows() {
        let o = rows(4);
        assert_eq!((o.batch, o.vectors.len(), o.scalars.len(), o.heading.len()), (4, 72, 80, 4));
        let mid = o.rows().slice(1..3);
        assert_eq!(mid.len(), 2);
        assert_eq!(mid.heading, &[1.0, 2.0]);
        assert_eq!(mid.vectors[0], 100.0);
        assert_eq!(mid.scalars[2 * N_SCALARS], -200.0);
        assert_eq!(mid.node_batch().vec3(1, 1, 2), [215.0, 216.0, 217.0]);
        assert_eq!(o.vector(3, 1, 1), [312.0, 313.0, 314.0]);
        let mut copy = Observation::zeros(
            &ObsSpec {
                n_nodes: 2,
                n_agents: 1,
                n_teams: 1,
                n_balls: 0,
                node_agent: vec![0, 0],
                node_team: vec![0, 0],
                node_parent: vec![-1, 0],
                node_is_root: vec![true, false],
                node_body: vec![None, None],
                node_joint: vec![None, None],
                agent_team: vec![0],
                agent_root_node: vec![0],
                agent_dof: vec![1],
                agent_action_offset: vec![0],
                entity_root_node: vec![0],
                gravity_dir: [0.0, 0.0, -1.0],
                static_scalars: vec![0.0; 2 * N_SCALARS],
            },
            4,
        );
        copy.write_rows(1, mid);
        copy.copy_row_from(&o, 3);
        assert_eq!(copy.rows().slice(1..4).heading, &[1.0, 2.0, 3.0]);
        assert_eq!(copy.rows().slice(1..4).vectors, &o.vectors[NODE_VECTOR_LEN * 2..]);
        assert_eq!(copy.heading[0], 0.0);
        let mut cleared = o.clone();
        cleared.clear();
        assert!(cleared.rows().is_empty() && cleared.vectors.is_empty());
    }

    #[test]
    fn partial_rows_are_refused_naming_the_lengths() {
        let (v, s, h) = (vec![0.0f32; 18], vec![0.0f32; 20], vec![0.0f32; 2]);
        assert_eq!(ObsRows::new(1, 1, &v, &s, &h).unwrap().len(), 2);
        let e = ObsRows::new(1, 1, &v[..17], &s, &h).unwrap_err().to_string();
        assert!(e.contains("17 vectors") && e.contains("9 + 10 + 1"), "{e}");
        assert!(ObsRows::new(1, 1, &v, &s, &h[..1]).is_err());
        assert!(ObsRows::new(1, 1, &v, &s[..10], &h).is_err());
    }
}
