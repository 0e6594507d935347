//! The SHNN family (paper section 3; `shnn`, `shnn_og3`, `shnn_so3`, `shtransformer`,
//! `shgnn`): input processing, the task-assignment graph, the actor's entity stage with its
//! local frames, the body-level head, and the value network.
//!
//! For agent `i` (eqs. (somp) to (pi), with Algorithm 1's labels `C(i) = i`, `C(j) = i`):
//! 1. the entities' root rows, positions re-based by the labels
//!    ([`InputProcessor::actor_entities`]: in Team Reach the agent at its own origin, its
//!    assigned ball at the unit direction to it; in Team Sumo relative to `c`), go through
//!    one round of `φ_o` over the assignment edges (the release's actor), giving `h'_i` and
//!    `O_i = OP(Z'_i W_u)`;
//! 2. eq. (lrf): `o'_i = [{O_i^T Z_{i,k}, h_{i,k}}_{k=1}^{K_i}, O_i^T Z_{j,1}, h_{j,1}]` for
//!    `j ∈ N(i)` (the neighbour rows of [`InputProcessor::neighbours`]), positions
//!    `p_{i,k} - p_{i,1}` and `p_{j,1} - p_{i,1}` (the latter a unit direction by default);
//! 3. eq. (pi): `σ_{π_i}(o'_i, h'_i)`, an MLP (256, 256) per agent giving `loc`, `scale`;
//!    `shtransformer`: one Transformer over the rows of `o'_i` as tokens, each with `h'_i`;
//!    `shgnn`: the body GNN ([`BodyGnn`]) decoded in `O_i`;
//! 4. eq. (value): the release's separate critic ([`SubeqCritic`]), or `σ_V` on the actor's
//!    `h'` (`critic=shared`).
//!
//! `shnn_og3` reads the bodies in `O_i = Z'_i` (`m` channels, no orthogonalisation),
//! `shnn_so3` has no gravity channel anywhere.

use nn::{Bound, Mlp, Scope, TransformerConfig};
use tensor::{Activation, Float};

use crate::body_gnn::{BodyGnn, BodyGnnConfig};
use crate::config::{CriticKind, GravityMode, ModelConfig, NeighbourOffset, hidden_widths, layer_sizes};
use crate::critic::{SubeqCritic, ValueHead, critic_order};
use crate::entity_graph::GraphBuilder;
use crate::entity_mp::{EntityMp, EntityMpConfig};
use crate::error::{ModelError, Result};
use crate::frame::to_frame;
use crate::input::{InputProcessor, Translation};
use crate::interface::{AgentPolicy, PolicyOutput};
use crate::kind::{Critic as KindCritic, Frame, Head, ModelKind};
use crate::transformer_head::TransformerHead;
use crate::zoo::split_head;
use envs::layout::{N_SCALARS, ObsSpec};
use envs::layout::{ObsBatch, ObsElement};

/// How the head expresses the body vectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FrameKind {
    /// `O = OP(u)` (eqs. (ortho), (ort_matrix)).
    Orthogonal,
    /// `O = Z'` (SHNN:Og3).
    Channels,
}

/// Body-level heads: one MLP per agent, or one Transformer or GNN for the team.
#[derive(Clone, Debug)]
pub(crate) enum Heads {
    Mlp(Vec<Mlp>),
    Transformer(Box<TransformerHead>),
    Gnn(Box<BodyGnn>),
}

/// The value network of the family.
#[derive(Clone, Debug)]
pub(crate) enum Critic {
    /// The release's own subequivariant critic.
    Separate(Box<SubeqCritic>),
    /// `σ_V` on the actor's `h'` of the entities in the given order.
    Shared(ValueHead, Vec<usize>),
}

/// An SHNN-family model (module docs).
#[derive(Clone, Debug)]
pub(crate) struct Shnn {
    pub(crate) proc: InputProcessor,
    pub(crate) graph: GraphBuilder,
    pub(crate) mp: EntityMp,
    pub(crate) frame: FrameKind,
    pub(crate) neighbour: NeighbourOffset,
    pub(crate) heads: Heads,
    pub(crate) critic: Critic,
}

impl Shnn {
    /// Builds `kind` (of the SHNN family) for `agents` of `team` under scope `s`: the
    /// actor's entity stage (`entity`), the body-level heads (`actor`), the critic
    /// (`critic`), in that order.
    pub(crate) fn new<T: Float>(
        s: &mut Scope<'_, T>,
        kind: ModelKind,
        config: &ModelConfig,
        spec: &ObsSpec,
        team: usize,
        agents: &[usize],
    ) -> Result<Self> {
        let head = kind.head();
        let mut allowed =
            vec!["assignment", "translation", "abstraction", "neighbour", "critic", "gravity", "actor_steps"];
        if head != Head::Transformer {
            allowed.extend(["head", "critic_hidden"]);
        }
        if !kind.uses_gravity() {
            allowed.retain(|&k| k != "gravity");
        }
        config.check_options(&allowed)?;
        let translation = config.translation_mode();
        let neighbour = config.neighbour.unwrap_or_default();
        let m = config.mp.unwrap_or_default();
        let gravity = kind.uses_gravity().then(|| config.gravity.unwrap_or_default());
        let gnn = head == Head::Gnn;
        let head_hidden = hidden_widths(&config.head_hidden, if gnn { &[] } else { &[256, 256] }, gnn)?;
        let critic_hidden = hidden_widths(&config.critic_hidden, &[256, 256], false)?;
        let proc = config.input_processor(spec)?;
        let graph = config.graph_builder(spec, team)?;
        let g = spec.gravity_dir.map(f64::from);
        let mp = EntityMp::new(
            &mut s.sub("entity"),
            EntityMpConfig {
                vectors: m.vectors,
                scalars: m.scalars,
                hidden: m.hidden,
                layers: m.layers,
                steps: config.actor_steps.unwrap_or(1),
                distance: if neighbour == NeighbourOffset::Unit && translation == Translation::Assigned {
                    nn::EdgeDistance::None
                } else {
                    nn::EdgeDistance::Raw
                },
                gravity: gravity.map(|_| g),
                gravity_in_layers: gravity == Some(GravityMode::EveryLayer),
                ..EntityMpConfig::paper(spec)
            },
        )?;
        let frame = if kind.frame() == Frame::Channels { FrameKind::Channels } else { FrameKind::Orthogonal };
        let channels = match frame {
            FrameKind::Orthogonal => 3,
            FrameKind::Channels => m.vectors,
        };
        // Rows of eq. (lrf): the agent's own nodes and its neighbours'.
        let slots = if neighbour == NeighbourOffset::None { 0 } else { graph.slots() };
        let row = 3 * channels + N_SCALARS;
        let mut actor = s.sub("actor");
        let heads = match head {
            Head::Gnn => {
                let cfg = BodyGnnConfig {
                    vectors: m.vectors,
                    scalars: m.scalars,
                    hidden: m.hidden,
                    layers: m.layers,
                    steps: m.steps,
                    entity_scalars: m.scalars,
                    decoder_hidden: head_hidden,
                    gravity: g,
                    gravity_in_layers: gravity == Some(GravityMode::EveryLayer),
                };
                Heads::Gnn(Box::new(BodyGnn::new(&mut actor, cfg, spec, agents)?))
            }
            Head::Transformer => {
                let head = TransformerHead::new(&mut actor, row + m.scalars, 2, TransformerConfig::default())?;
                Heads::Transformer(Box::new(head))
            }
            Head::Mlp => Heads::Mlp(
                agents
                    .iter()
                    .map(|&a| {
                        let input = (1 + spec.agent_dof[a] + slots) * row + m.scalars;
                        let sz = layer_sizes(input, &head_hidden, 2 * spec.agent_dof[a]);
                        Mlp::new(&mut actor.sub(a), &sz, Activation::Relu)
                    })
                    .collect::<nn::Result<Vec<_>>>()?,
            ),
        };
        let transformer = kind.critic() == KindCritic::SubequivariantTransformer;
        let mut c = s.sub("critic");
        let critic = match config.critic.unwrap_or_default() {
            CriticKind::Separate => Critic::Separate(Box::new(SubeqCritic::new(
                &mut c,
                spec,
                team,
                agents,
                m,
                gravity,
                &critic_hidden,
                transformer,
            )?)),
            CriticKind::Shared => {
                let ne = spec.entity_root_node.len();
                let head = ValueHead::new(&mut c, ne, m.scalars, &critic_hidden, transformer)?;
                Critic::Shared(head, critic_order(spec, agents))
            }
        };
        Ok(Shnn { proc, graph, mp, frame, neighbour, heads, critic })
    }

    /// Policy and (if `with_value`) value; `fixed` replaces the batch's task assignment
    /// (module [`crate::entity_graph`]).
    pub(crate) fn forward<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        agents: &[usize],
        spec: &ObsSpec,
        fixed: Option<&[u32]>,
        with_value: bool,
    ) -> Result<PolicyOutput<'t, T>> {
        let tape = p.tape();
        let nb = obs.batch;
        let inputs = self.proc.entities::<T, S>(obs)?;
        let graph = self.graph.build_with(&inputs, fixed)?;
        let z = self.proc.actor_entities(&inputs, &graph, agents, self.neighbour)?;
        let f = self.mp.forward_inputs(p, z, &inputs, &graph)?;
        let bodies = self.proc.bodies(obs, &inputs, &graph.agent_entity, agents)?;
        let neighbours = match (self.neighbour, &self.heads) {
            (NeighbourOffset::None, _) | (_, Heads::Gnn(_)) => Vec::new(),
            _ => self.proc.neighbours(obs, &graph, &bodies, self.neighbour)?,
        };
        let frame = match self.frame {
            FrameKind::Orthogonal => f.frame()?,
            FrameKind::Channels => f.z,
        };
        let channels = frame.shape()[2];
        let mut out = Vec::with_capacity(agents.len());
        for (i, body) in bodies.iter().enumerate() {
            let dof = spec.agent_dof[body.agent];
            let rows = inputs.rows_of(body.agent);
            let ha = f.h.index_select(0, &rows)?;
            if let Heads::Gnn(head) = &self.heads {
                // The shared body GNN on the agent's morphology graph, read in O_a.
                let (loc, scale) = head.forward(p, body, ha, f.frame()?.index_select(0, &rows)?)?;
                out.push(AgentPolicy { agent: body.agent, loc, scale });
                continue;
            }
            // Eq. (lrf): the agent's own rows, then its neighbours' rows.
            let (mut z, mut h) = (tape.constant(body.z.clone()), tape.constant(body.h.clone()));
            if let Some(nr) = neighbours.get(i) {
                z = tape.cat(&[z, tape.constant(nr.z.clone())], 1)?;
                h = tape.cat(&[h, tape.constant(nr.h.clone())], 1)?;
            }
            let k = z.shape()[1];
            let node_rows: Vec<usize> = rows.iter().flat_map(|&r| std::iter::repeat_n(r, k)).collect();
            let local = to_frame(frame.index_select(0, &node_rows)?, z.reshape(&[nb * k, 3, 3])?)?;
            match &self.heads {
                Heads::Mlp(heads) => {
                    // Eq. (pi): the head on [O^T Z, h, h'_i].
                    let local = local.reshape(&[nb, k * channels * 3])?;
                    let h = h.reshape(&[nb, k * N_SCALARS])?;
                    let hidden = heads[i].forward_hidden_parts(p, &[local, h, ha])?;
                    out.push(split_head(&heads[i], p, hidden, body.agent, dof)?);
                }
                Heads::Transformer(head) => {
                    // One token per row: [O^T Z_k, h_k, h'_i]; the DoF nodes follow the root.
                    let local = local.reshape(&[nb, k, channels * 3])?;
                    let s = ha.shape()[1];
                    let ha = ha.reshape(&[nb, 1, s])?.expand(&[nb, k, s])?;
                    let (loc, scale) = head.forward(p, tape.cat(&[local, h, ha], 2)?, 1, dof)?;
                    out.push(AgentPolicy { agent: body.agent, loc, scale });
                }
                Heads::Gnn(_) => return Err(ModelError::Input("body GNN head reached the row path".into())),
            }
        }
        // Eq. (value).
        let value = match &self.critic {
            _ if !with_value => None,
            Critic::Separate(c) => Some(c.forward(p, obs)?),
            Critic::Shared(head, order) => {
                let ne = inputs.entities;
                let rows: Vec<usize> = (0..nb).flat_map(|b| order.iter().map(move |&e| b * ne + e)).collect();
                let s = f.h.shape()[1];
                Some(head.forward(p, f.h.index_select(0, &rows)?.reshape(&[nb, ne, s])?)?)
            }
        };
        Ok(PolicyOutput { agents: out, value, assignment: graph.assignment })
    }
}
