//! The task-assignment entity-level graph (paper section 3, "Task Assignment", and
//! Algorithm 1; MEBEN.md section 5).
//!
//! Nodes are the entities of every scene of a batch (agents, then balls; entity `i` of
//! scene `b` is node `b * E + i`, the rows of [`crate::input::EntityInputs`]). An
//! [`Assigner`] links agents to objects by the root distances `D[i, j] = |p_j - p_i|`
//! (Algorithm 1's matrix) and edges join the entities of one assignment group
//! (`E = {(i, j): C(i) = C(j), i != j}`):
//! - **Team Reach**: agents -> goal balls (objects = balls in order); each ball forms a group
//!   with its agent (Algorithm 1: `C(i) = i`, `C(j) = i`); unassigned agents are alone.
//! - **Team Sumo**, seen from team `t` (each team's model builds its own graph): own agents
//!   -> opponents (objects = the other team's agents in order), each pair a group, and every
//!   agent of both teams is also linked with the centre ball.
//! - [`AssignmentMethod::None`]: every pair of entities of a scene (fully connected).
//!
//! Edges are directed both ways and sorted by source ([`nn::EdgeList`] aggregates at the
//! source). The builder owns its scratch, so a batch is built without per-scene allocation
//! (only the output lists grow).
//!
//! Besides the edges, the graph lists each agent's neighbours `N(i)` in fixed slots (the
//! rows eq. (lrf) appends to the agent's own nodes): Reach, one slot, the assigned ball;
//! Sumo, two, the assigned opponent and the centre ball; fully connected, `E - 1`, every
//! other entity in entity order. An empty slot (an agent left without an object) is
//! [`UNASSIGNED`].
//!
//! The assignment drawn for a batch is kept ([`EntityGraph::assignment`]) and can be given
//! back ([`GraphBuilder::build_with`]), so that the update of a stochastic assignment sees
//! the graph the behaviour policy acted on.

use nn::EdgeList;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tensor::Float;

use crate::assignment::{Assigner, AssignmentMethod, UNASSIGNED};
use crate::assignment_learned::DRAW_SCENE;
use crate::error::{ModelError, Result};
use crate::input::EntityInputs;
use envs::layout::{ENTITY_CENTRE, ENTITY_GOAL, ObsSpec};

/// The task of a scene, as far as the graph is concerned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GraphTask {
    /// Team Reach: agents and goal balls.
    Reach,
    /// Team Sumo: two teams and a centre ball (entity index of the ball).
    Sumo {
        /// Entity index of the centre ball.
        centre: usize,
    },
}

/// The entity graph of a batch.
#[derive(Clone, Debug)]
pub struct EntityGraph {
    /// The task the scenes were recognised as.
    pub task: GraphTask,
    /// Environments `B`.
    pub batch: usize,
    /// Entities per environment `E`.
    pub entities: usize,
    /// Directed edges over the `B*E` entity rows, sorted by source.
    pub edges: EdgeList,
    /// Assignment label `C(i)` of each entity `[B*E]` (an entity index within its scene:
    /// the agent of the group; unassigned entities carry their own index; all 0 when fully
    /// connected). In Sumo the centre ball is linked to every agent across groups.
    pub group: Vec<usize>,
    /// Entity each agent is assigned to `[B*A]` (index within the scene; Reach: its ball,
    /// Sumo: its opponent, for both teams' agents), [`UNASSIGNED`] for none.
    pub agent_entity: Vec<usize>,
    /// Neighbour slots per agent (module docs).
    pub slots: usize,
    /// Each agent's neighbours `[B*A*slots]` (entity indices within the scene, module docs),
    /// [`UNASSIGNED`] for an empty slot.
    pub neighbours: Vec<usize>,
    /// The assignment of every scene `[B*m]`: for each object of the builder's view (balls,
    /// or the opponents), the index of its agent among the viewing team's agents, or
    /// [`NO_AGENT`] (empty when the method is `none`).
    pub assignment: Vec<u32>,
}

impl EntityGraph {
    /// Neighbour `slot` of agent `a` in scene `b` (an entity index, or [`UNASSIGNED`]).
    pub fn neighbour(&self, b: usize, a: usize, slot: usize) -> usize {
        let na = self.agent_entity.len() / self.batch.max(1);
        self.neighbours[(b * na + a) * self.slots + slot]
    }
}

/// An object without an agent in [`EntityGraph::assignment`].
pub const NO_AGENT: u32 = u32::MAX;

/// Builds [`EntityGraph`]s for one scene layout, one assignment method and one team's view.
#[derive(Clone, Debug)]
pub struct GraphBuilder {
    method: AssignmentMethod,
    task: GraphTask,
    team: usize,
    n_agents: usize,
    n_entities: usize,
    /// Entity indices of the assigned agents and of the objects.
    own: Vec<usize>,
    objects: Vec<usize>,
    assigner: Assigner,
    rng: ChaCha8Rng,
    // Per-scene scratch.
    dist: Vec<f64>,
    out: Vec<usize>,
    adj: Vec<bool>,
}

impl GraphBuilder {
    /// A builder for scenes laid out by `spec`, seen from `team` (0 for Reach; 0 or 1 for
    /// Sumo). `seed` drives [`AssignmentMethod::Stochastic`].
    pub fn new(spec: &ObsSpec, method: AssignmentMethod, team: usize, seed: u64) -> Result<Self> {
        let (na, nm) = (spec.n_agents, spec.n_balls);
        let ne = na + nm;
        if spec.entity_root_node.len() != ne || spec.agent_team.len() != na {
            return Err(ModelError::Input(format!(
                "observation spec with {na} agents and {nm} balls lists {} entity roots",
                spec.entity_root_node.len()
            )));
        }
        let ball_type = |j: usize| {
            let node = spec.entity_root_node[na + j];
            let s = &spec.static_scalars[node * envs::layout::N_SCALARS..];
            (s[ENTITY_GOAL] == 1.0, s[ENTITY_CENTRE] == 1.0)
        };
        let sumo = spec.n_teams == 2 && nm == 1 && ball_type(0).1;
        let reach = spec.n_teams == 1 && (0..nm).all(|j| ball_type(j).0);
        let (task, own, objects) = if reach {
            if team != 0 {
                return Err(ModelError::Option(format!("team {team} in a Team Reach scene (only team 0)")));
            }
            (GraphTask::Reach, (0..na).collect::<Vec<_>>(), (na..ne).collect::<Vec<_>>())
        } else if sumo {
            if team > 1 {
                return Err(ModelError::Option(format!("team {team} in a Team Sumo scene (teams 0 and 1)")));
            }
            let own = (0..na).filter(|&a| spec.agent_team[a] == team).collect::<Vec<_>>();
            let objects = (0..na).filter(|&a| spec.agent_team[a] != team).collect::<Vec<_>>();
            (GraphTask::Sumo { centre: na }, own, objects)
        } else {
            return Err(ModelError::Input(format!(
                "scene with {} teams and {nm} balls is neither Team Reach (1 team, goal balls) nor \
                 Team Sumo (2 teams, one centre ball)",
                spec.n_teams
            )));
        };
        let (n, m) = (own.len(), objects.len());
        Ok(Self {
            method,
            task,
            team,
            n_agents: na,
            n_entities: ne,
            assigner: Assigner::new(n, m),
            rng: ChaCha8Rng::seed_from_u64(seed),
            dist: vec![0.0; n * m],
            out: vec![UNASSIGNED; m],
            adj: vec![false; ne * ne],
            own,
            objects,
        })
    }

    /// Restarts the random stream of the `random` assignment from `seed` (the trainer reseeds
    /// it every iteration, so that a resumed run draws the same assignments).
    pub fn reseed(&mut self, seed: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
    }

    /// The assignment method.
    pub fn method(&self) -> AssignmentMethod {
        self.method
    }

    /// The task the scene was recognised as.
    pub fn task(&self) -> GraphTask {
        self.task
    }

    /// The entities of the assignment's rows (the team's agents, in order) and columns (the
    /// objects: Reach's balls, Sumo's opponents): the layout of its distance matrix and of
    /// [`EntityGraph::assignment`] (for each column, the row assigned), which a learned
    /// assignment ([`crate::assignment_learned::PairFeatures::from_entities`]) scores alike.
    pub fn assignment_entities(&self) -> (&[usize], &[usize]) {
        (&self.own, &self.objects)
    }

    /// The team whose view the graph is built from.
    pub fn team(&self) -> usize {
        self.team
    }

    /// Objects per scene in the builder's view (the width of one scene's
    /// [`EntityGraph::assignment`]; 0 with the method `none`).
    pub fn assignment_width(&self) -> usize {
        if self.method == AssignmentMethod::None { 0 } else { self.objects.len() }
    }

    /// Neighbour slots per agent (module docs).
    pub fn slots(&self) -> usize {
        match (self.method, self.task) {
            (AssignmentMethod::None, _) => self.n_entities - 1,
            (_, GraphTask::Reach) => 1,
            (_, GraphTask::Sumo { .. }) => 2,
        }
    }

    /// The most directed edges one scene's graph can have (the output lists are reserved
    /// for this many per scene, so that they never grow while a batch is built).
    pub fn max_edges_per_scene(&self) -> usize {
        let ne = self.n_entities;
        if self.method == AssignmentMethod::None {
            return ne * (ne - 1);
        }
        let pairs = 2 * self.own.len().min(self.objects.len());
        match self.task {
            GraphTask::Reach => pairs,
            GraphTask::Sumo { .. } => pairs + 2 * self.n_agents,
        }
    }

    /// The graph of every scene of `entities` (positions from
    /// [`crate::input::InputProcessor::entities`]).
    pub fn build<T: Float>(&mut self, entities: &EntityInputs<T>) -> Result<EntityGraph> {
        self.build_with(entities, None)
    }

    /// [`GraphBuilder::build`], with the assignment of every scene given (`[B*m]`, as
    /// [`EntityGraph::assignment`] returns it) instead of solved or drawn; `None` solves it.
    /// A given assignment must match the batch and be one-to-one; the method `learned` needs
    /// one (its draws come from the model's scorer, [`crate::assignment_learned`]).
    pub fn build_with<T: Float>(&mut self, entities: &EntityInputs<T>, fixed: Option<&[u32]>) -> Result<EntityGraph> {
        if fixed.is_none() && self.method == AssignmentMethod::Learned {
            return Err(ModelError::Input(
                "assignment `learned` builds a graph only with the assignment its scorer drew (none given)".into(),
            ));
        }
        self.build_solving(entities, fixed)
    }

    /// [`GraphBuilder::build_with`], solving the assignment when none is given whatever the
    /// method: the method `learned` then takes Algorithm 1's (its warm-up,
    /// [`crate::assignment_learned::LearnedAssignment::in_warmup`], and `meben eval
    /// --assignment greedy` of a learned policy). Scenes of a given assignment marked wholly
    /// [`DRAW_SCENE`] are solved so too, the others kept: a held Algorithm 1 assignment drawn
    /// at an episode's first step.
    pub(crate) fn build_solving<T: Float>(
        &mut self,
        entities: &EntityInputs<T>,
        fixed: Option<&[u32]>,
    ) -> Result<EntityGraph> {
        let (nb, ne, na) = (entities.batch, self.n_entities, self.n_agents);
        let (n, m) = (self.own.len(), self.objects.len());
        if let Some(f) = fixed {
            let width = self.assignment_width();
            if f.len() != nb * width {
                return Err(ModelError::Input(format!(
                    "a given assignment of {} entries for {nb} scenes x {width} objects",
                    f.len()
                )));
            }
            for (b, scene) in f.chunks(width.max(1)).enumerate() {
                match scene.iter().filter(|&&i| i == DRAW_SCENE).count() {
                    0 => {}
                    k if k == scene.len() => continue,
                    _ => {
                        return Err(ModelError::Input(format!(
                            "given assignment of scene {b}: only partly marked to be solved"
                        )));
                    }
                }
                for (j, &i) in scene.iter().enumerate() {
                    let repeated = scene[..j].contains(&i);
                    if i != NO_AGENT && (i as usize >= n || repeated) {
                        return Err(ModelError::Input(format!(
                            "given assignment of scene {b}: object {j} to agent {i} (agents 0..{n}, one object each)"
                        )));
                    }
                }
            }
        }
        if entities.entities != ne || entities.positions.len() != nb * ne {
            return Err(ModelError::Input(format!(
                "entity inputs of {} entities per scene ({} positions) for a graph of {ne} entities \
                 x {nb} scenes",
                entities.entities,
                entities.positions.len()
            )));
        }
        let cap = nb * self.max_edges_per_scene();
        let slots = self.slots();
        let mut graph = EntityGraph {
            task: self.task,
            batch: nb,
            entities: ne,
            edges: EdgeList { src: Vec::with_capacity(cap), dst: Vec::with_capacity(cap), num_nodes: nb * ne },
            group: Vec::with_capacity(nb * ne),
            agent_entity: Vec::with_capacity(nb * na),
            slots,
            neighbours: Vec::with_capacity(nb * na * slots),
            assignment: Vec::with_capacity(nb * self.assignment_width()),
        };
        for b in 0..nb {
            let pos = &entities.positions[b * ne..(b + 1) * ne];
            self.adj.fill(false);
            let g0 = graph.group.len();
            let a0 = graph.agent_entity.len();
            graph.group.extend(0..ne);
            graph.agent_entity.extend(std::iter::repeat_n(UNASSIGNED, na));
            if self.method == AssignmentMethod::None {
                self.adj.fill(true);
                graph.group[g0..].fill(0);
            } else {
                // Algorithm 1's distance matrix: own agents (rows) x objects.
                for (i, &a) in self.own.iter().enumerate() {
                    for (j, &o) in self.objects.iter().enumerate() {
                        let d = [pos[o][0] - pos[a][0], pos[o][1] - pos[a][1], pos[o][2] - pos[a][2]];
                        self.dist[i * m + j] = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    }
                }
                match fixed.map(|f| &f[b * m..(b + 1) * m]) {
                    Some(f) if m == 0 || f[0] != DRAW_SCENE => {
                        for (o, &i) in self.out.iter_mut().zip(f) {
                            *o = if i == NO_AGENT { UNASSIGNED } else { i as usize };
                        }
                    }
                    _ => self.assigner.assign(self.method, &self.dist, n, m, &mut self.out, &mut self.rng),
                }
                graph.assignment.extend(self.out.iter().map(|&i| if i == UNASSIGNED { NO_AGENT } else { i as u32 }));
                for (j, &i) in self.out.iter().enumerate() {
                    if i == UNASSIGNED {
                        continue;
                    }
                    let (a, o) = (self.own[i], self.objects[j]);
                    graph.group[g0 + o] = a;
                    graph.agent_entity[a0 + a] = o;
                    if let GraphTask::Sumo { .. } = self.task {
                        graph.agent_entity[a0 + o] = a;
                    }
                    self.adj[a * ne + o] = true;
                    self.adj[o * ne + a] = true;
                }
                if let GraphTask::Sumo { centre } = self.task {
                    for a in 0..na {
                        self.adj[a * ne + centre] = true;
                        self.adj[centre * ne + a] = true;
                    }
                }
            }
            for i in 0..ne {
                for j in 0..ne {
                    if i != j && self.adj[i * ne + j] {
                        graph.edges.src.push(b * ne + i);
                        graph.edges.dst.push(b * ne + j);
                    }
                }
            }
            for a in 0..na {
                match (self.method, self.task) {
                    (AssignmentMethod::None, _) => graph.neighbours.extend((0..ne).filter(|&e| e != a)),
                    (_, GraphTask::Reach) => graph.neighbours.push(graph.agent_entity[a0 + a]),
                    (_, GraphTask::Sumo { centre }) => {
                        graph.neighbours.extend([graph.agent_entity[a0 + a], centre]);
                    }
                }
            }
        }
        Ok(graph)
    }
}
