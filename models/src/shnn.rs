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
//! 2. eq. (lrf) ([`lrf`]): `o'_i = [{O_i^T Z_{i,k}, h_{i,k}}_{k=1}^{K_i}, O_i^T Z_{j,1},
//!    h_{j,1}]` for `j ∈ N(i)` (the neighbour rows of [`InputProcessor::neighbours`]),
//!    positions `p_{i,k} - p_{i,1}` and `p_{j,1} - p_{i,1}` (the latter a unit direction by
//!    default);
//! 3. eq. (pi): `σ_{π_i}(o'_i, h'_i)`, an MLP (256, 256) per agent giving `loc`, `scale`;
//!    `shtransformer`: one Transformer over the rows of `o'_i` as tokens, each with `h'_i`;
//!    `shgnn`: the body GNN ([`BodyGnn`]) decoded in `O_i`;
//! 4. eq. (value): the release's separate critic ([`SubeqCritic`]), or `σ_V` on the actor's
//!    `h'` (`critic=shared`).
//!
//! With `assignment=learned` the task assignment is drawn from a Plackett-Luce distribution
//! over learned pair scores ([`crate::assignment_learned`], parameters `assign.*`) and its
//! log-probability and entropy come with the output ([`PolicyOutput::assignment_terms`]);
//! with `assign_critic=held` too, `σ_V`'s first layer also reads the assignment held into
//! the step (`x_σ W_σ`; docs/MODELS.md).
//!
//! `shnn_og3` reads the bodies in `O_i = Z'_i` (`m` channels, no orthogonalisation),
//! `shnn_so3` has no gravity channel anywhere.

use nn::{Bound, Mlp, Scope, TransformerConfig};
use tensor::{Activation, Float};

use crate::assignment::AssignmentMethod;
use crate::assignment_learned::{LearnedAssignment, PairFeatureSet, build_graph};
use crate::body_gnn::{BodyGnn, BodyGnnConfig};
use crate::config::{GravityMode, NeighbourOffset, layer_sizes};
use crate::critic::{HeldTerm, SubeqCritic, ValueHead, check_held, critic_order};
use crate::description::{EntityStage, ShnnCritic, ShnnModel, ShnnOptions};
use crate::entity_graph::GraphBuilder;
use crate::entity_mp::{EntityMp, EntityMpConfig};
use crate::error::{ModelError, Result};
use crate::frame::{AgentFrame, lrf, lrf_shape};
use crate::input::InputProcessor;
use crate::interface::{AgentPolicy, PolicyOutput};
use crate::kind::Frame;
use crate::transformer_head::TransformerHead;
use crate::zoo::split_head;
use envs::layout::{N_SCALARS, ObsSpec};
use envs::layout::{ObsBatch, ObsElement};

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
    /// The release's own subequivariant critic ([`crate::kind::Critic::Subequivariant`]).
    Separate(Box<SubeqCritic>),
    /// `σ_V` on the actor's `h'` of the entities in the given order
    /// ([`crate::kind::Critic::EntityStage`]).
    Shared(ValueHead, Vec<usize>),
}

impl Critic {
    /// `σ_V`.
    fn head(&self) -> &ValueHead {
        match self {
            Self::Separate(c) => c.head(),
            Self::Shared(head, _) => head,
        }
    }
}

/// An SHNN-family model (module docs).
#[derive(Clone, Debug)]
pub(crate) struct Shnn {
    pub(crate) proc: InputProcessor,
    pub(crate) graph: GraphBuilder,
    pub(crate) mp: EntityMp,
    /// `O_i`: [`Frame::Orthogonal`] or [`Frame::Channels`].
    pub(crate) frame: Frame,
    pub(crate) neighbour: NeighbourOffset,
    pub(crate) heads: Heads,
    pub(crate) critic: Critic,
    /// `assignment=learned`: the scorer (parameters `assign.*`) and its draws, which give
    /// the graph builder its assignment.
    pub(crate) learned: Option<Box<LearnedAssignment>>,
    /// `assign_critic=held`: `W_σ` of `σ_V`'s first layer (`critic.held.weight`, zero at the
    /// start; docs/MODELS.md).
    held: Option<HeldTerm>,
}

impl Shnn {
    /// Builds the model `o` describes (of the SHNN family) for `agents` of `team` under scope
    /// `s`: the actor's entity stage (`entity`), the body-level heads (`actor`), the critic
    /// (`critic`), in that order, then with `assignment=learned` the assignment's scorer
    /// (`assign`; last, so that the other parameters start as without it), then with
    /// `assign_critic=held` `critic.held.weight` (zero). The scorer reads
    /// the pair distances and, but in `shnn_so3` (no gravity anywhere), the heights along
    /// gravity ([`PairFeatureSet`]).
    pub(crate) fn new<T: Float>(
        s: &mut Scope<'_, T>,
        o: &ShnnOptions,
        spec: &ObsSpec,
        team: usize,
        agents: &[usize],
    ) -> Result<Self> {
        let stage: &EntityStage = &o.stage;
        let gravity = o.model.gravity();
        let m = stage.sizes;
        let proc = stage.input_processor(spec)?;
        let graph = stage.assignment.graph_builder(spec, team)?;
        let g = spec.gravity_dir.map(f64::from);
        let mp = EntityMp::new(
            &mut s.sub("entity"),
            EntityMpConfig {
                vectors: m.vectors,
                scalars: m.scalars,
                hidden: m.hidden,
                layers: m.layers,
                steps: stage.actor_steps,
                distance: stage.edge_distance(),
                gravity: gravity.map(|_| g),
                gravity_in_layers: gravity == Some(GravityMode::EveryLayer),
                ..EntityMpConfig::paper(spec)
            },
        )?;
        // `O_i`: the local reference frame, or the `m` channels of `Z'` (SHNN:Og3).
        let frame = o.model.kind().frame();
        let axes = if frame == Frame::Channels { m.vectors } else { 3 };
        // The rows of eq. (lrf): the agent's own nodes and its neighbours'.
        let slots = if stage.neighbour_rows() { graph.slots() } else { 0 };
        let mut actor = s.sub("actor");
        let heads = match &o.model {
            ShnnModel::ShGnn { hidden, .. } => {
                let cfg = BodyGnnConfig {
                    vectors: m.vectors,
                    scalars: m.scalars,
                    hidden: m.hidden,
                    layers: m.layers,
                    steps: m.steps,
                    entity_scalars: m.scalars,
                    decoder_hidden: hidden.head.clone(),
                    gravity: g,
                    gravity_in_layers: gravity == Some(GravityMode::EveryLayer),
                };
                Heads::Gnn(Box::new(BodyGnn::new(&mut actor, cfg, spec, agents)?))
            }
            ShnnModel::ShTransformer { .. } => {
                let (_, row) = lrf_shape(0, 0, axes);
                let head = TransformerHead::new(&mut actor, row + m.scalars, 2, TransformerConfig::default())?;
                Heads::Transformer(Box::new(head))
            }
            ShnnModel::Shnn { hidden, .. } | ShnnModel::ShnnOg3 { hidden, .. } | ShnnModel::ShnnSo3 { hidden } => {
                Heads::Mlp(
                    agents
                        .iter()
                        .map(|&a| {
                            let (rows, row) = lrf_shape(spec.agent_dof[a], slots, axes);
                            let sz = layer_sizes(rows * row + m.scalars, &hidden.head, 2 * spec.agent_dof[a]);
                            Mlp::new(&mut actor.sub(a), &sz, Activation::Relu)
                        })
                        .collect::<nn::Result<Vec<_>>>()?,
                )
            }
        };
        let mut c = s.sub("critic");
        let value = o.model.value();
        let critic = match o.critic {
            ShnnCritic::Separate => {
                Critic::Separate(Box::new(SubeqCritic::new(&mut c, spec, team, agents, m, gravity, &value)?))
            }
            ShnnCritic::Shared => {
                let ne = spec.entity_root_node.len();
                Critic::Shared(ValueHead::new(&mut c, ne, m.scalars, &value)?, critic_order(spec, agents))
            }
        };
        let learned = if stage.assignment.method == AssignmentMethod::Learned {
            let features = if gravity.is_some() { PairFeatureSet::DistanceHeight } else { PairFeatureSet::Distance };
            let config = o.scorer.config(features);
            let l = LearnedAssignment::new(&mut s.sub("assign"), config, &graph, g, stage.assignment.seed)?;
            Some(Box::new(l))
        } else {
            None
        };
        let held = match (o.scorer.value_reads_held, &learned, critic.head().first_width()) {
            (false, ..) => None,
            (true, Some(_), Some(columns)) => Some(HeldTerm::new(s, graph.assignment_width(), agents.len(), columns)?),
            _ => {
                return Err(ModelError::Option(
                    "assign_critic=held reads a learned assignment with an MLP value (give it with assignment=learned)"
                        .into(),
                ));
            }
        };
        Ok(Shnn { proc, graph, mp, frame, neighbour: stage.neighbour, heads, critic, learned, held })
    }

    /// Policy and (if `with_value`) value; `fixed` replaces the batch's task assignment
    /// (module [`crate::entity_graph`]); `held`, with it, says for each scene whether that
    /// assignment was held into it (the value reads it, `assign_critic=held`) or drawn there.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        agents: &[usize],
        spec: &ObsSpec,
        fixed: Option<&[u32]>,
        held: Option<&[bool]>,
        with_value: bool,
    ) -> Result<PolicyOutput<'t, T>> {
        let tape = p.tape();
        let nb = obs.batch;
        check_held(held, self.held.is_some(), fixed.is_some(), nb)?;
        let inputs = self.proc.entities::<T, S>(obs)?;
        // A learned assignment is scored on the tape and drawn (or the given one scored)
        // before the graph is built with it.
        let (graph, assignment_terms) = build_graph(&mut self.graph, self.learned.as_deref_mut(), p, &inputs, fixed)?;
        let z = self.proc.actor_entities(&inputs, &graph, agents, self.neighbour)?;
        let f = self.mp.forward_inputs(p, z, &inputs, &graph)?;
        let bodies = self.proc.bodies(obs, &inputs, &graph.agent_entity, agents)?;
        let neighbours = match (self.neighbour, &self.heads) {
            (NeighbourOffset::None, _) | (_, Heads::Gnn(_)) => Vec::new(),
            _ => self.proc.neighbours(obs, &graph, &bodies, self.neighbour)?,
        };
        let frame = match self.frame {
            Frame::Channels => f.z,
            _ => f.frame()?,
        };
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
            // Eq. (lrf): o'_i, the agent's own rows and its neighbours' in O_i.
            let o = lrf(tape, body, neighbours.get(i), &AgentFrame::Learned(frame.index_select(0, &rows)?))?;
            let (k, axes) = (o.z.shape()[1], o.z.shape()[2]);
            match &self.heads {
                Heads::Mlp(heads) => {
                    // Eq. (pi): the head on [O^T Z, h, h'_i].
                    let local = o.z.reshape(&[nb, k * axes * 3])?;
                    let h = o.h.reshape(&[nb, k * N_SCALARS])?;
                    let hidden = heads[i].forward_hidden_parts(p, &[local, h, ha])?;
                    out.push(split_head(&heads[i], p, hidden, body.agent, dof)?);
                }
                Heads::Transformer(head) => {
                    // One token per row: [O^T Z_k, h_k, h'_i]; the DoF nodes follow the root.
                    let local = o.z.reshape(&[nb, k, axes * 3])?;
                    let s = ha.shape()[1];
                    let ha = ha.reshape(&[nb, 1, s])?.expand(&[nb, k, s])?;
                    let (loc, scale) = head.forward(p, tape.cat(&[local, o.h, ha], 2)?, 1, dof)?;
                    out.push(AgentPolicy { agent: body.agent, loc, scale });
                }
                Heads::Gnn(_) => return Err(ModelError::Input("body GNN head reached the row path".into())),
            }
        }
        // Eq. (value), with assign_critic=held the term x_σ W_σ where a scene holds its σ.
        let extra = match &self.held {
            Some(t) if with_value => t.term(p, &graph.assignment, held)?,
            _ => None,
        };
        let value = match &self.critic {
            _ if !with_value => None,
            Critic::Separate(c) => Some(c.forward(p, obs, extra)?),
            Critic::Shared(head, order) => {
                let ne = inputs.entities;
                let rows: Vec<usize> = (0..nb).flat_map(|b| order.iter().map(move |&e| b * ne + e)).collect();
                let s = f.h.shape()[1];
                Some(head.forward(p, f.h.index_select(0, &rows)?.reshape(&[nb, ne, s])?, extra)?)
            }
        };
        Ok(PolicyOutput { agents: out, value, assignment: graph.assignment, assignment_terms })
    }
}
