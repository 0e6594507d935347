//! The non-equivariant ablations `hnn`, `hnn_hn` and `hnn_dn` (paper section "Ablations":
//! HNN, HNN+HN, HNN+DN): SHNN's hierarchy (input processing, task-assignment entity graph,
//! entity-level message passing, per-agent body MLP heads, critic on `h'`) with every vector
//! flattened and treated as scalars, and plain MLP message passing.
//!
//! The vectors are first expressed in a frame ([`Frame`]): the world axes (`hnn`), the
//! agent's heading (`hnn_hn`), or the horizontal direction from the agent's root to its
//! assigned entity, the goal direction (`hnn_dn`; the heading when the agent has no
//! assignment or sits on it). The entity stage sees all entities in the frame of the team's
//! first agent; each agent's head sees eq. (lrf)'s rows ([`lrf`]: its own nodes and its
//! neighbours' roots) in its own frame. Positions are re-based as in `shnn` (the same
//! translation modes), so all three are translation invariant; `hnn_hn` and `hnn_dn` are
//! also invariant under rotations about the vertical, `hnn` is not.
//!
//! Message passing ([`ScalarMp`]): `h = [vec(Z_i), h_i] W + b`, then `steps` rounds of
//! `m_ij = MLP_e([h_i, h_j, x_j - x_i])`, `m_i = mean_j m_ij`, `h_i += MLP_n([h_i, m_i])`.

use nn::{Bound, EdgeList, Linear, Mlp, Scope};
use tensor::{Activation, Float, Var};

use crate::assignment::UNASSIGNED;
use crate::config::layer_sizes;
use crate::critic::critic_order;
use crate::description::{EntityStage, HnnOptions};
use crate::entity_graph::GraphBuilder;
use crate::error::{ModelError, Result};
use crate::frame::{AgentFrame, lrf, lrf_shape, to_horizontal_frame};
use crate::input::{ENTITY_SCALARS, InputProcessor};
use crate::interface::{AgentPolicy, PolicyOutput};
use crate::kind::Frame;
use envs::layout::{N_SCALARS, ObsSpec};
use envs::layout::{NODE_VECTOR_LEN, NODE_VECTORS, ObsBatch, ObsElement};

/// Sizes of [`ScalarMp`].
#[derive(Clone, Copy, Debug)]
pub struct ScalarMpSizes {
    /// Node features.
    pub scalars: usize,
    /// Hidden width of both MLPs.
    pub hidden: usize,
    /// Hidden layers of both MLPs.
    pub layers: usize,
    /// Propagation steps of the shared layer.
    pub steps: usize,
}

/// Plain (non-equivariant) message passing on flattened entity features (module docs).
/// Parameters under its scope: `embed.*`, `mlp_e.*`, `mlp_n.*`.
#[derive(Clone, Debug)]
pub struct ScalarMp {
    /// `[vec(Z_i), h_i]` -> node features.
    pub embed: Linear,
    /// Message MLP on `[h_i, h_j, x_j - x_i]`.
    pub mlp_e: Mlp,
    /// Update MLP on `[h_i, m_i]`.
    pub mlp_n: Mlp,
    /// The sizes.
    pub sizes: ScalarMpSizes,
}

impl ScalarMp {
    /// A layer for `input` features per node.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, input: usize, sizes: ScalarMpSizes) -> Result<Self> {
        let ScalarMpSizes { scalars, hidden, layers, steps } = sizes;
        if scalars == 0 || hidden == 0 || layers == 0 || steps == 0 {
            return Err(ModelError::Option(format!("HNN message passing sizes {sizes:?} must be positive")));
        }
        let mlp = |i: usize| {
            let mut v = vec![i];
            v.extend(std::iter::repeat_n(hidden, layers));
            v.push(scalars);
            v
        };
        Ok(Self {
            embed: Linear::new(&mut s.sub("embed"), input, scalars)?,
            mlp_e: Mlp::new(&mut s.sub("mlp_e"), &mlp(2 * scalars + 3), Activation::Relu)?,
            mlp_n: Mlp::new(&mut s.sub("mlp_n"), &mlp(2 * scalars), Activation::Relu)?,
            sizes,
        })
    }

    /// Node inputs `x0: [n, input]`, positions `pos: [n, 3]` -> features `[n, scalars]`.
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        x0: Var<'t, T>,
        pos: Var<'t, T>,
        edges: &EdgeList,
    ) -> Result<Var<'t, T>> {
        let tape = p.tape();
        let n = edges.num_nodes;
        let mut h = self.embed.forward(p, x0)?;
        if edges.is_empty() {
            return Ok(h);
        }
        let e = pos.index_select(0, &edges.dst)?.sub(pos.index_select(0, &edges.src)?)?;
        for _ in 0..self.sizes.steps {
            let hij = tape.cat(&[h.index_select(0, &edges.src)?, h.index_select(0, &edges.dst)?, e], 1)?;
            let m = self.mlp_e.forward(p, hij)?.segment_mean(&edges.src, n)?;
            h = h.add(self.mlp_n.forward(p, tape.cat(&[h, m], 1)?)?)?;
        }
        Ok(h)
    }
}

/// An HNN model (module docs).
#[derive(Clone, Debug)]
pub struct Hnn {
    proc: InputProcessor,
    graph: GraphBuilder,
    /// [`Frame::World`], [`Frame::Heading`] or [`Frame::Goal`].
    frame: Frame,
    /// The entity stage's options.
    stage: EntityStage,
    mp: ScalarMp,
    heads: Vec<Mlp>,
    critic: Mlp,
    /// Entity order of the critic input (own agents, other agents, balls).
    critic_entities: Vec<usize>,
}

impl Hnn {
    /// Restarts the random assignment stream ([`GraphBuilder::reseed`]).
    pub fn reseed(&mut self, seed: u64) {
        self.graph.reseed(seed);
    }

    /// The task-assignment graph builder.
    pub(crate) fn graph(&self) -> &GraphBuilder {
        &self.graph
    }

    /// Builds the model `o` describes (of the HNN family) for `agents` of `team`: the entity
    /// stage under `entity`, one head per agent under `actor.<a>` and the critic under
    /// `critic` of scope `s`.
    pub(crate) fn new<T: Float>(
        s: &mut Scope<'_, T>,
        o: &HnnOptions,
        spec: &ObsSpec,
        team: usize,
        agents: &[usize],
    ) -> Result<Self> {
        let stage = o.stage;
        let frame = o.model.kind().frame();
        let proc = stage.input_processor(spec)?;
        let graph = stage.assignment.graph_builder(spec, team)?;
        let m = stage.sizes;
        let sizes = ScalarMpSizes { scalars: m.scalars, hidden: m.hidden, layers: m.layers, steps: stage.actor_steps };
        let mp = ScalarMp::new(&mut s.sub("entity"), NODE_VECTOR_LEN + ENTITY_SCALARS, sizes)?;
        let mut actor = s.sub("actor");
        let slots = if stage.neighbour_rows() { graph.slots() } else { 0 };
        let heads = agents
            .iter()
            .map(|&a| {
                let (rows, row) = lrf_shape(spec.agent_dof[a], slots, 3);
                let sz = layer_sizes(rows * row + sizes.scalars, &o.hidden.head, 2 * spec.agent_dof[a]);
                Mlp::new(&mut actor.sub(a), &sz, Activation::Relu)
            })
            .collect::<nn::Result<Vec<_>>>()?;
        let ne = spec.entity_root_node.len();
        let sz = layer_sizes(ne * sizes.scalars, &o.hidden.critic, 1);
        let critic = Mlp::new(&mut s.sub("critic"), &sz, Activation::Relu)?;
        let critic_entities = critic_order(spec, agents);
        Ok(Self { proc, graph, frame, stage, mp, heads, critic, critic_entities })
    }

    /// Policy and (if `with_value`) value (module docs).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
        agents: &[usize],
        spec: &ObsSpec,
        fixed: Option<&[u32]>,
        with_value: bool,
    ) -> Result<PolicyOutput<'t, T>> {
        let tape = p.tape();
        let (nb, na) = (obs.batch, spec.n_agents);
        let inputs = self.proc.entities::<T, S>(obs)?;
        let graph = self.graph.build_with(&inputs, fixed)?;
        // Per agent and scene the horizontal frame (sin, cos).
        let frame_of = |a: usize, b: usize| -> (f64, f64) {
            let yaw: f64 = heading[b * na + a].into();
            match self.frame {
                Frame::Heading => yaw.sin_cos(),
                Frame::Goal => {
                    let e = graph.agent_entity[b * na + a];
                    let root = obs.vec3(b, spec.agent_root_node[a], 0);
                    let d = if e == UNASSIGNED { [0.0; 3] } else { inputs.world_position(b, e) };
                    let (dx, dy) = (d[0] - root[0], d[1] - root[1]);
                    let r = dx.hypot(dy);
                    if e == UNASSIGNED || r < 1e-9 { yaw.sin_cos() } else { (dy / r, dx / r) }
                }
                // The world axes (the learned frames are SHNN's; `Hnn::new` refuses them).
                _ => (0.0, 1.0),
            }
        };
        // Entity stage in the frame of the team's first agent.
        let ne = inputs.entities;
        let first: Vec<(f64, f64)> = (0..nb).map(|b| frame_of(agents[0], b)).collect();
        let z = self.proc.actor_entities(&inputs, &graph, agents, self.stage.neighbour)?;
        let z = to_horizontal_frame(&z, ne, &first)?;
        let n = nb * ne;
        let zv = tape.constant(z.reshape(&[n, 3, NODE_VECTORS])?);
        let pos = zv.narrow(2, 0, 1)?.reshape(&[n, 3])?;
        let x0 = tape.cat(&[zv.reshape(&[n, 3 * NODE_VECTORS])?, tape.constant(inputs.h.clone())], 1)?;
        let h = self.mp.forward(p, x0, pos, &graph.edges)?;
        // Body heads: own nodes in the agent's frame, with h'_a.
        let bodies = self.proc.bodies(obs, &inputs, &graph.agent_entity, agents)?;
        let neighbours = if self.stage.neighbour_rows() {
            self.proc.neighbours(obs, &graph, &bodies, self.stage.neighbour)?
        } else {
            Vec::new()
        };
        let mut out = Vec::with_capacity(agents.len());
        for (i, (body, head)) in bodies.iter().zip(&self.heads).enumerate() {
            let a = body.agent;
            let dof = spec.agent_dof[a];
            // Eq. (lrf): o'_i in the agent's frame, flattened.
            let frames = AgentFrame::Horizontal((0..nb).map(|b| frame_of(a, b)).collect());
            let o = lrf(tape, body, neighbours.get(i), &frames)?;
            let k = o.z.shape()[1];
            let zb = o.z.reshape(&[nb, k * 3 * NODE_VECTORS])?;
            let hb = o.h.reshape(&[nb, k * N_SCALARS])?;
            let ha = h.index_select(0, &inputs.rows_of(a))?;
            let hidden = head.forward_hidden_parts(p, &[zb, hb, ha])?;
            out.push(AgentPolicy {
                agent: a,
                loc: head.forward_output_columns(p, hidden, 0, dof)?,
                scale: head.forward_output_columns(p, hidden, dof, dof)?,
            });
        }
        if !with_value {
            return Ok(PolicyOutput { agents: out, value: None, assignment: graph.assignment, assignment_terms: None });
        }
        let rows: Vec<usize> = (0..nb).flat_map(|b| self.critic_entities.iter().map(move |&e| b * ne + e)).collect();
        let s = h.shape()[1];
        let value = self.critic.forward(p, h.index_select(0, &rows)?.reshape(&[nb, ne * s])?)?.reshape(&[nb])?;
        Ok(PolicyOutput { agents: out, value: Some(value), assignment: graph.assignment, assignment_terms: None })
    }
}
