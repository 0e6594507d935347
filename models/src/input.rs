//! Input processing (paper section 3, "Input Processing" and the node features of "Local
//! Entity-level Subequivariant Message Passing"): batches of MeBen observations ([`ObsBatch`]
//! rows laid out by [`ObsSpec`], module [`envs::layout`]) become the tensors the networks
//! read.
//!
//! # Entities
//! The entities `Ω` are the agents (their root nodes) then the balls, in the order of
//! [`ObsSpec::entity_root_node`] (`E = A + M` per scene). Entity `i` of scene `b` is row
//! `b * E + i` of:
//! - `Z_i` `[B*E, 3, 3]`: the paper's `Z_{i,1} ∈ R^{3×3}`, spatial rows and the channels
//!   position, linear velocity, angular velocity. The position is `p_{i,1} - c` with
//!   `c = 1/(N+M) Σ_i p_{i,1}` the mean root position of all entities (translation
//!   invariance; other origins through [`Translation`]).
//! - `h_i` `[B*E, N_SCALARS + 1]`: `[h_{i,1}, p^z_{i,1}]`, the root's scalars and its height
//!   above the ground (`-<p, g>` with `g` = [`ObsSpec::gravity_dir`], i.e. `p_z`).
//!
//! With [`EntityAbstraction::Mean`] an agent's vectors (and the position used for `c`, the
//! assignment and the body origin) are the means over all its nodes instead of its root's.
//!
//! # The actor's entities
//! [`InputProcessor::actor_entities`]: with [`Translation::Assigned`] in Team Reach the
//! origin of every entity follows Algorithm 1's labels (`C(i) = i` for an agent, `C(j) = i`
//! for the object `j` assigned to agent `i`): the agents sit at their own origin (position
//! 0), an assigned ball at `p_{j,1} - p_{i,1}` (scaled to a unit direction with
//! [`NeighbourOffset::Unit`], as the reference release's actor does), and a ball left
//! without an agent at `p - c`. In Team Sumo the centre ball belongs to every group, so no
//! label gives it one origin: the entity rows stay relative to `c`, where every edge vector
//! `p_j - p_i` is the true offset. Other translation modes keep `p - c` (or world positions).
//!
//! # Bodies
//! Per agent `a` (for the body-level heads and eq. (lrf), [`crate::frame::lrf`]): its own
//! nodes (root, then one per actuated DoF in action order), `Z_{a,k}` `[B, K_a, 3, 3]` and
//! `h_{a,k}` `[B, K_a, N_SCALARS]`, `K_a = 1 + dof_a`. With [`Translation::Assigned`] the
//! positions are relative to the agent's own root, `p_{a,k} - p_{C(a),1} = p_{a,k} -
//! p_{a,1}` (eq. (lrf) with Algorithm 1's labels); with [`Translation::AssignedEntity`]
//! (this project's earlier reading) relative to the root of the entity the agent is
//! assigned to, or to `c` when it has none.
//!
//! # Neighbours
//! [`InputProcessor::neighbours`]: per agent the rows `Z_{j,1}`, `h_{j,1}` of its neighbours
//! `j ∈ N(i)` in the graph's slots ([`crate::entity_graph`]), positions relative to the
//! agent's body origin (`p_{j,1} - p_{C(j),1} = p_{j,1} - p_{i,1}` under
//! [`Translation::Assigned`]; the entity assigned to the agent unit-scaled with
//! [`NeighbourOffset::Unit`], other neighbours such as Sumo's centre ball raw); an empty
//! slot is a row of zeros.
//!
//! Observations are read through [`ObsBatch`], generic over `f32` (what the environments
//! produce) and `f64` (exact equivariance tests); all arithmetic is in `f64` and the outputs
//! are converted to the tensor type once. Only the output buffers are allocated.

use tensor::{Float, Tensor};

use crate::assignment::UNASSIGNED;
use crate::config::NeighbourOffset;
use crate::entity_graph::{EntityGraph, GraphTask};
use crate::error::{ModelError, Result};
use envs::layout::{N_SCALARS, NODE_VECTOR_LEN, NODE_VECTORS, ObsBatch, ObsElement, ObsSpec};

/// `eps` of the unit direction `d / (|d| + eps)` (the reference release's `normalize_vector`).
pub const UNIT_EPS: f64 = 1e-6;

/// Scalars per entity: the root's [`N_SCALARS`] plus its height.
pub const ENTITY_SCALARS: usize = N_SCALARS + 1;

/// Which point positions are measured from (the paper's translation ablation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Translation {
    /// World positions (not translation invariant).
    None,
    /// Entities and bodies relative to `c`, the mean root position of all entities (the
    /// paper's "sparse root mean").
    RootMean,
    /// Entities and bodies relative to the mean position of all nodes ("dense body mean").
    BodyMean,
    /// Origins by Algorithm 1's labels (eq. (lrf), the paper's "relative positions in
    /// assignment", `c = p_{C(i),1}`): an agent's bodies relative to its own root, an
    /// assigned object relative to its agent's root (module docs). SHNN's choice.
    #[default]
    Assigned,
    /// Entities relative to `c`, each agent's bodies relative to the root of the entity it is
    /// assigned to (this project's earlier reading of eq. (lrf)).
    AssignedEntity,
}

impl Translation {
    /// Parses `none`, `root_mean`, `body_mean` or `assigned`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "none" => Ok(Self::None),
            "root_mean" => Ok(Self::RootMean),
            "body_mean" => Ok(Self::BodyMean),
            "assigned" => Ok(Self::Assigned),
            "assigned_entity" => Ok(Self::AssignedEntity),
            _ => Err(ModelError::Option(format!(
                "unknown translation `{s}` (expected none, root_mean, body_mean, assigned or assigned_entity)"
            ))),
        }
    }

    /// The name [`Translation::parse`] accepts.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::RootMean => "root_mean",
            Self::BodyMean => "body_mean",
            Self::Assigned => "assigned",
            Self::AssignedEntity => "assigned_entity",
        }
    }
}

/// What stands for an entity at the entity level (the paper's entity-abstraction ablation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum EntityAbstraction {
    /// The root body: `Z_i = Z_{i,1}` (SHNN).
    #[default]
    Root,
    /// The mean of the position, velocity and angular velocity over all of the entity's
    /// nodes (the root's scalars and the height of the mean position as `h_i`).
    Mean,
}

impl EntityAbstraction {
    /// Parses `root` or `mean`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "root" => Ok(Self::Root),
            "mean" => Ok(Self::Mean),
            _ => Err(ModelError::Option(format!("unknown entity abstraction `{s}` (expected root or mean)"))),
        }
    }

    /// The name [`EntityAbstraction::parse`] accepts.
    pub fn name(self) -> &'static str {
        match self {
            Self::Root => "root",
            Self::Mean => "mean",
        }
    }
}

/// Entity-level node features of a batch (module docs).
#[derive(Clone, Debug)]
pub struct EntityInputs<T: Float> {
    /// Environments `B`.
    pub batch: usize,
    /// Entities per environment `E = A + M`.
    pub entities: usize,
    /// `Z_i` `[B*E, 3, 3]`: spatial rows; channels position (relative to the scene origin),
    /// velocity, angular velocity.
    pub z: Tensor<T>,
    /// `h_i` `[B*E, ENTITY_SCALARS]`: the root's scalars, then its height.
    pub h: Tensor<T>,
    /// Entity positions (the roots', or the means with [`EntityAbstraction::Mean`]) relative
    /// to the scene origin, `[B*E]` (in `f64`, for the assignment).
    pub positions: Vec<[f64; 3]>,
    /// The scene origin (world frame) subtracted from the entity positions, `[B]`.
    pub origin: Vec<[f64; 3]>,
}

impl<T: Float> EntityInputs<T> {
    /// The rows of entity `e` in every scene, `[b * E + e for b in 0..B]` (to gather, e.g.,
    /// an agent's frame `O_a` or features `h'_a` from the entity stage's outputs).
    pub fn rows_of(&self, e: usize) -> Vec<usize> {
        (0..self.batch).map(|b| b * self.entities + e).collect()
    }

    /// World position of entity `e` of scene `b`.
    pub fn world_position(&self, b: usize, e: usize) -> [f64; 3] {
        let (p, o) = (self.positions[b * self.entities + e], self.origin[b]);
        [p[0] + o[0], p[1] + o[1], p[2] + o[2]]
    }
}

/// One agent's neighbour rows (eq. (lrf), module docs).
#[derive(Clone, Debug)]
pub struct NeighbourRows<T: Float> {
    /// `Z_{j,1}` `[B, S, 3, 3]` (spatial rows; position relative to the agent's body origin,
    /// velocity, angular velocity), zeros for an empty slot.
    pub z: Tensor<T>,
    /// `h_{j,1}` `[B, S, N_SCALARS]`, zeros for an empty slot.
    pub h: Tensor<T>,
}

/// One agent's body-level inputs.
#[derive(Clone, Debug)]
pub struct AgentBody<T: Float> {
    /// The agent (index into the scene's agents).
    pub agent: usize,
    /// `Z_{a,k}` `[B, K_a, 3, 3]` (spatial rows; position relative to the agent's origin,
    /// velocity, angular velocity), `K_a = 1 + dof_a`, root first.
    pub z: Tensor<T>,
    /// `h_{a,k}` `[B, K_a, N_SCALARS]`.
    pub h: Tensor<T>,
    /// The origin (world frame) of the agent's positions in each scene, `[B]`.
    pub origin: Vec<[f64; 3]>,
}

/// Turns observations into entity- and body-level tensors for one scene layout.
#[derive(Clone, Debug)]
pub struct InputProcessor {
    spec: ObsSpec,
    translation: Translation,
    abstraction: EntityAbstraction,
    gravity: [f64; 3],
    /// First node and node count of each entity under the abstraction.
    entity_nodes: Vec<(usize, usize)>,
}

impl InputProcessor {
    /// For observations laid out by `spec`, positions measured as `translation` says.
    pub fn new(spec: &ObsSpec, translation: Translation) -> Result<Self> {
        let g = spec.gravity_dir.map(f64::from);
        let norm = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        if (norm - 1.0).abs() > 1e-6 {
            return Err(ModelError::Input(format!("gravity direction {g:?} is not a unit vector")));
        }
        let n_ent = spec.n_agents + spec.n_balls;
        if spec.entity_root_node.len() != n_ent
            || spec.agent_root_node.len() != spec.n_agents
            || spec.agent_dof.len() != spec.n_agents
            || spec.entity_root_node.iter().any(|&n| n >= spec.n_nodes)
            || spec.agent_root_node.iter().zip(&spec.agent_dof).any(|(&r, &d)| r + 1 + d > spec.n_nodes)
        {
            return Err(ModelError::Input(format!(
                "inconsistent observation spec: {} agents, {} balls, {} nodes, entity roots {:?}",
                spec.n_agents, spec.n_balls, spec.n_nodes, spec.entity_root_node
            )));
        }
        let mut p = Self {
            spec: spec.clone(),
            translation,
            abstraction: EntityAbstraction::Root,
            gravity: g,
            entity_nodes: Vec::new(),
        };
        p.set_entity_nodes();
        Ok(p)
    }

    /// The same processor with entities abstracted as `abstraction` (default: the root).
    pub fn with_abstraction(mut self, abstraction: EntityAbstraction) -> Self {
        self.abstraction = abstraction;
        self.set_entity_nodes();
        self
    }

    fn set_entity_nodes(&mut self) {
        let spec = &self.spec;
        self.entity_nodes = (0..spec.entity_root_node.len())
            .map(|e| match (self.abstraction, e < spec.n_agents) {
                (EntityAbstraction::Mean, true) => (spec.agent_root_node[e], 1 + spec.agent_dof[e]),
                _ => (spec.entity_root_node[e], 1),
            })
            .collect();
    }

    /// The entity abstraction.
    pub fn abstraction(&self) -> EntityAbstraction {
        self.abstraction
    }

    /// Vector `k` of entity `e` in environment `b`: its root's, or the mean over its nodes.
    fn entity_vec<S: ObsElement>(&self, obs: &ObsBatch<'_, S>, b: usize, e: usize, k: usize) -> [f64; 3] {
        let (first, count) = self.entity_nodes[e];
        if count == 1 {
            return obs.vec3(b, first, k);
        }
        let mut m = [0.0; 3];
        for node in first..first + count {
            let v = obs.vec3(b, node, k);
            (0..3).for_each(|r| m[r] += v[r]);
        }
        m.map(|x| x / count as f64)
    }

    /// The observation layout.
    pub fn spec(&self) -> &ObsSpec {
        &self.spec
    }

    /// The translation mode.
    pub fn translation(&self) -> Translation {
        self.translation
    }

    /// Entities per scene `E`.
    pub fn n_entities(&self) -> usize {
        self.spec.entity_root_node.len()
    }

    /// The scene origin of environment `b` for the entity positions.
    fn scene_origin<S: ObsElement>(&self, obs: &ObsBatch<'_, S>, b: usize) -> [f64; 3] {
        let mut c = [0.0; 3];
        let mut add = |p: [f64; 3]| (0..3).for_each(|k| c[k] += p[k]);
        let count = match self.translation {
            Translation::None => return c,
            Translation::RootMean | Translation::Assigned | Translation::AssignedEntity => {
                let ne = self.n_entities();
                (0..ne).for_each(|e| add(self.entity_vec(obs, b, e, 0)));
                ne
            }
            Translation::BodyMean => {
                (0..self.spec.n_nodes).for_each(|n| add(obs.vec3(b, n, 0)));
                self.spec.n_nodes
            }
        };
        c.map(|x| x / count as f64)
    }

    /// Entity features `Z_i`, `h_i` of every scene (module docs).
    pub fn entities<T: Float, S: ObsElement>(&self, obs: &ObsBatch<'_, S>) -> Result<EntityInputs<T>> {
        obs.check(&self.spec)?;
        let (nb, ne) = (obs.batch, self.n_entities());
        let mut z = tensor::pool::with_capacity(nb * ne * NODE_VECTOR_LEN);
        let mut h = tensor::pool::with_capacity(nb * ne * ENTITY_SCALARS);
        let mut positions = Vec::with_capacity(nb * ne);
        let mut origin = Vec::with_capacity(nb);
        let g = self.gravity;
        for b in 0..nb {
            let c = self.scene_origin(obs, b);
            origin.push(c);
            for (e, &node) in self.spec.entity_root_node.iter().enumerate() {
                let p = self.entity_vec(obs, b, e, 0);
                let rel = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                positions.push(rel);
                let (v, w) = (self.entity_vec(obs, b, e, 1), self.entity_vec(obs, b, e, 2));
                for r in 0..3 {
                    z.extend([rel[r], v[r], w[r]].map(T::from_f64));
                }
                h.extend((0..N_SCALARS).map(|s| T::from_f64(obs.scalar(b, node, s))));
                h.push(T::from_f64(-(p[0] * g[0] + p[1] * g[1] + p[2] * g[2])));
            }
        }
        Ok(EntityInputs {
            batch: nb,
            entities: ne,
            z: Tensor::new(z, &[nb * ne, 3, NODE_VECTORS])?,
            h: Tensor::new(h, &[nb * ne, ENTITY_SCALARS])?,
            positions,
            origin,
        })
    }

    /// Body-level inputs of `agents` (indices into the scene's agents). `agent_entity`
    /// `[B*A]` is the entity each agent is assigned to in each scene
    /// ([`crate::entity_graph::EntityGraph::agent_entity`]; [`UNASSIGNED`] for none); it is
    /// only read with [`Translation::AssignedEntity`], where an agent's positions are
    /// relative to that entity's root (or to `c` when unassigned). With
    /// [`Translation::Assigned`] they are relative to the agent's own root. `entities` must
    /// come from the same observations.
    pub fn bodies<T: Float, S: ObsElement>(
        &self,
        obs: &ObsBatch<'_, S>,
        entities: &EntityInputs<T>,
        agent_entity: &[usize],
        agents: &[usize],
    ) -> Result<Vec<AgentBody<T>>> {
        obs.check(&self.spec)?;
        let (nb, na, ne) = (obs.batch, self.spec.n_agents, self.n_entities());
        if entities.batch != nb || entities.entities != ne || entities.origin.len() != nb {
            return Err(ModelError::Input(format!(
                "entity inputs of {} scenes x {} entities for {nb} scenes x {ne} entities",
                entities.batch, entities.entities
            )));
        }
        if self.translation == Translation::AssignedEntity && agent_entity.len() != nb * na {
            return Err(ModelError::Input(format!(
                "{} assigned entities for {nb} scenes x {na} agents",
                agent_entity.len()
            )));
        }
        if let Some(&e) = agent_entity.iter().find(|&&e| e != UNASSIGNED && e >= ne) {
            return Err(ModelError::Input(format!("assigned entity {e} out of range for {ne} entities")));
        }
        let mut out = Vec::with_capacity(agents.len());
        for &a in agents {
            if a >= na {
                return Err(ModelError::Input(format!("agent {a} out of range for {na} agents")));
            }
            let (root, k) = (self.spec.agent_root_node[a], 1 + self.spec.agent_dof[a]);
            // Pooled storage: these arrays are as large as an activation and are rebuilt for
            // every minibatch.
            let mut z = tensor::pool::with_capacity(nb * k * NODE_VECTOR_LEN);
            let mut h = tensor::pool::with_capacity(nb * k * N_SCALARS);
            let mut origin = Vec::with_capacity(nb);
            for b in 0..nb {
                let o = match self.translation {
                    Translation::Assigned => entities.world_position(b, a),
                    Translation::AssignedEntity => match agent_entity[b * na + a] {
                        UNASSIGNED => entities.origin[b],
                        e => entities.world_position(b, e),
                    },
                    _ => entities.origin[b],
                };
                origin.push(o);
                for node in root..root + k {
                    let (v, sc) = (obs.node_vectors(b, node), obs.node_scalars(b, node));
                    // v = [p, v, w] (3 each); Z rows r = [p_r - o_r, v_r, w_r].
                    for r in 0..3 {
                        let rel = v[r].into() - o[r];
                        z.extend([rel, v[3 + r].into(), v[6 + r].into()].map(T::from_f64));
                    }
                    h.extend(sc.iter().map(|&x| T::from_f64(x.into())));
                }
            }
            out.push(AgentBody {
                agent: a,
                z: Tensor::new(z, &[nb, k, 3, NODE_VECTORS])?,
                h: Tensor::new(h, &[nb, k, N_SCALARS])?,
                origin,
            });
        }
        Ok(out)
    }

    /// The actor's entity features (module docs, "The actor's entities"): `entities.z` with
    /// the position channel re-based by Algorithm 1's labels under [`Translation::Assigned`]
    /// (`own` are the viewing team's agents, `graph` the batch's assignment graph); a copy
    /// of `entities.z` otherwise.
    pub fn actor_entities<T: Float>(
        &self,
        entities: &EntityInputs<T>,
        graph: &EntityGraph,
        own: &[usize],
        offset: NeighbourOffset,
    ) -> Result<Tensor<T>> {
        if self.translation != Translation::Assigned || graph.task != GraphTask::Reach {
            return Ok(entities.z.clone());
        }
        let (nb, ne, na) = (entities.batch, entities.entities, self.spec.n_agents);
        if graph.batch != nb || graph.entities != ne || graph.agent_entity.len() != nb * na {
            return Err(ModelError::Input(format!(
                "entity graph of {} x {} entities for inputs of {nb} x {ne}",
                graph.batch, graph.entities
            )));
        }
        let mut z = entities.z.to_vec();
        for b in 0..nb {
            for e in 0..ne {
                let rel = if own.contains(&e) {
                    [0.0; 3]
                } else if let Some(&a) = own.iter().find(|&&a| graph.agent_entity[b * na + a] == e) {
                    let (pe, pa) = (entities.positions[b * ne + e], entities.positions[b * ne + a]);
                    scale_offset([pe[0] - pa[0], pe[1] - pa[1], pe[2] - pa[2]], offset)
                } else {
                    entities.positions[b * ne + e]
                };
                for (r, x) in rel.iter().enumerate() {
                    z[((b * ne + e) * 3 + r) * NODE_VECTORS] = T::from_f64(*x);
                }
            }
        }
        Ok(Tensor::new(z, &[nb * ne, 3, NODE_VECTORS])?)
    }

    /// The neighbour rows of every agent of `bodies` (module docs, "Neighbours"), in the
    /// slots of `graph`, positions relative to each body's origin.
    pub fn neighbours<T: Float, S: ObsElement>(
        &self,
        obs: &ObsBatch<'_, S>,
        graph: &EntityGraph,
        bodies: &[AgentBody<T>],
        offset: NeighbourOffset,
    ) -> Result<Vec<NeighbourRows<T>>> {
        obs.check(&self.spec)?;
        let (nb, ns, na) = (obs.batch, graph.slots, self.spec.n_agents);
        let assigned = self.translation == Translation::Assigned;
        let mut out = Vec::with_capacity(bodies.len());
        for body in bodies {
            if body.origin.len() != nb || graph.batch != nb {
                return Err(ModelError::Input(format!(
                    "neighbours of agent {} for {nb} scenes from a body of {} and a graph of {}",
                    body.agent,
                    body.origin.len(),
                    graph.batch
                )));
            }
            let mut z = tensor::pool::with_capacity(nb * ns * NODE_VECTOR_LEN);
            let mut h = tensor::pool::with_capacity(nb * ns * N_SCALARS);
            for b in 0..nb {
                for slot in 0..ns {
                    let j = graph.neighbour(b, body.agent, slot);
                    if j == UNASSIGNED {
                        z.extend(std::iter::repeat_n(T::ZERO, NODE_VECTOR_LEN));
                        h.extend(std::iter::repeat_n(T::ZERO, N_SCALARS));
                        continue;
                    }
                    let node = *self
                        .spec
                        .entity_root_node
                        .get(j)
                        .ok_or_else(|| ModelError::Input(format!("neighbour entity {j} out of range")))?;
                    let (p, v, w) = (obs.vec3(b, node, 0), obs.vec3(b, node, 1), obs.vec3(b, node, 2));
                    let o = body.origin[b];
                    let d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
                    let own_object = graph.agent_entity.get(b * na + body.agent) == Some(&j);
                    let d = if assigned && own_object { scale_offset(d, offset) } else { d };
                    for r in 0..3 {
                        z.extend([d[r], v[r], w[r]].map(T::from_f64));
                    }
                    h.extend((0..N_SCALARS).map(|s| T::from_f64(obs.scalar(b, node, s))));
                }
            }
            out.push(NeighbourRows {
                z: Tensor::new(z, &[nb, ns, 3, NODE_VECTORS])?,
                h: Tensor::new(h, &[nb, ns, N_SCALARS])?,
            });
        }
        Ok(out)
    }
}

/// An assigned object's offset from its agent as the actor reads it: a unit direction
/// `d / (|d| + UNIT_EPS)` ([`NeighbourOffset::Unit`]) or raw.
pub fn scale_offset(d: [f64; 3], offset: NeighbourOffset) -> [f64; 3] {
    match offset {
        NeighbourOffset::Unit => {
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() + UNIT_EPS;
            d.map(|x| x / n)
        }
        NeighbourOffset::Raw | NeighbourOffset::None => d,
    }
}
