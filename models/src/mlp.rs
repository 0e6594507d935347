//! The MLP baselines `mlp` and `mlp_hn` (paper appendix "Baselines": MLP, MLP+HN).
//!
//! # The release's MLP ([`ReleaseMlp`], the default)
//! The network of the reference release's `models/MLP.py` (the file that produced the
//! paper's MLP+HN 1.759M parameters):
//! - per node, the 9 vector components (position, velocity, angular velocity) are embedded
//!   to 64 and the scalars to 64, both affine (`embed_z`, `embed_h`, shared by the team's
//!   agents);
//! - agent `i`'s input rows are its own nodes (root first, then its DoF nodes), its own root
//!   once more, and its neighbours' roots (the entity assigned to it by the task assignment:
//!   Reach its ball; Sumo its opponent and the centre ball), positions relative to its own
//!   root (`mlp_hn`: every vector in its heading frame); with `assignment=none` the rows are
//!   its own nodes and every other entity's root (the paper's MLP-without-assignment
//!   ablation); with `assignment=learned` the assignment is drawn from the learned
//!   Plackett-Luce distribution of [`crate::assignment_learned`] (parameters `assign.*`,
//!   created last), as in the SHNN family;
//! - per agent an MLP 256, 256 (ReLU) on the concatenated embeddings gives `loc`, `scale`
//!   of its `K_i - 1` DoF ("3 linear layers" of the paper's Table "Hyperparameters of
//!   Network");
//! - the value network embeds every entity's root the same way (its own embeddings),
//!   positions relative to the mean of the roots, concatenates them (own agents first) and
//!   applies 256, 256, 1. For `mlp_hn` its vectors are in the heading frame of the team's
//!   first agent (the release's MLP file has heading normalisation commented out; without
//!   it the value would not be invariant, which MLP+HN promises);
//! - with `assign_critic=held` (and `assignment=learned`) the value also reads the learned
//!   assignment held into the step: its first layer gains the term `x_σ W_σ`, `x_σ` the
//!   one-hot `[m n]` of which of the team's `n` agents each of the `m` objects is held by
//!   (all zero where the step draws its assignment, so the value there is `V(s)`, before the
//!   draw), `W_σ` (`critic.held.weight`) zero at the start, so that the value begins as
//!   without it. A held draw's advantage then carries `V(s', σ) - V(s)` past the unroll
//!   (docs/MODELS.md, "What the value reads").
//!
//! # The flat MLP ([`FlatMlp`], `variant=flat`)
//! This project's earlier baseline: per agent an MLP 256 x 3 on the flat agent view
//! ([`ObsSpec::agent_view`]: its own nodes, then every other entity's root; 9 vector
//! components and the scalars per node; world frame for `mlp`, heading frame and positions
//! relative to its root for `mlp_hn`), the critic 256 x 3 on every node of the scene.

use nn::{Bound, Linear, Mlp, Scope};
use tensor::{Activation, Float, Tensor, Var};

use crate::assignment::{AssignmentMethod, UNASSIGNED};
use crate::assignment_learned::{LearnedAssignment, ScorerConfig, build_graph};
use crate::config::layer_sizes;
use crate::critic::{HeldTerm, check_held, critic_order};
use crate::description::HiddenWidths;
use crate::entity_graph::GraphBuilder;
use crate::error::{ModelError, Result};
use crate::input::{InputProcessor, Translation};
use crate::interface::{AgentPolicy, PolicyOutput};
use crate::transformer_head::TransformerHead;
use crate::zoo::split_head;
use envs::layout::{N_SCALARS, NODE_VECTOR_LEN, NODE_VECTORS, ObsSpec};
use envs::layout::{ObsBatch, ObsElement};

/// Per-node features: the [`NODE_VECTOR_LEN`] vector components and the scalars.
pub const NODE_FEATURES: usize = NODE_VECTOR_LEN + N_SCALARS;
/// Width of each of the release MLP's two node embeddings.
pub const EMBED: usize = 64;

/// Appends a node's features: its 3 vectors (positions relative to `origin`), rotated into
/// the frame of heading `yaw` when given (`O^T v`), then its scalars.
pub(crate) fn push_node<T: Float, S: ObsElement>(
    out: &mut Vec<T>,
    obs: &ObsBatch<'_, S>,
    b: usize,
    node: usize,
    origin: [f64; 3],
    yaw: Option<(f64, f64)>,
) {
    for k in 0..NODE_VECTORS {
        let mut v = obs.vec3(b, node, k);
        if k == 0 {
            (0..3).for_each(|r| v[r] -= origin[r]);
        }
        if let Some((s, c)) = yaw {
            v = [c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]];
        }
        out.extend(v.map(T::from_f64));
    }
    out.extend((0..N_SCALARS).map(|i| T::from_f64(obs.scalar(b, node, i))));
}

/// The heading frame `(sin, cos)` of agent `a` in scene `b`, or `None` without heading
/// normalisation.
fn yaw_of<S: ObsElement>(heading: &[S], spec: &ObsSpec, hn: bool, a: usize, b: usize) -> Option<(f64, f64)> {
    hn.then(|| {
        let yaw: f64 = heading[b * spec.n_agents + a].into();
        yaw.sin_cos()
    })
}

/// Two affine node embeddings (9 vector components -> 64, scalars -> 64).
#[derive(Clone, Debug)]
struct NodeEmbedding {
    z: Linear,
    h: Linear,
}

impl NodeEmbedding {
    fn new<T: Float>(s: &mut Scope<'_, T>) -> Result<Self> {
        Ok(Self {
            z: Linear::new(&mut s.sub("embed_z"), NODE_VECTOR_LEN, EMBED)?,
            h: Linear::new(&mut s.sub("embed_h"), N_SCALARS, EMBED)?,
        })
    }

    /// The hidden features of `mlp` on the embedded rows `x: [B, R, NODE_FEATURES]`, whose
    /// input is `[e^z_1 .. e^z_R, e^h_1 .. e^h_R]` (the release's order) with
    /// `e^z_r = x^z_r E_z + b_z`, `e^h_r = x^h_r E_h + b_h`.
    ///
    /// The embedding and the first layer are both affine with nothing between them, so the
    /// first layer is computed as the one affine map they compose to:
    /// `Σ_r x^z_r (E_z W_r^z) + Σ_r x^h_r (E_h W_r^h) + (b_1 + Σ_r b_z W_r^z + Σ_r b_h W_r^h)`,
    /// with `W_r^z`, `W_r^h` the rows of the first layer's weight that read row `r`'s
    /// embeddings. The same function and parameters (and gradients, through the products on
    /// the tape), with 19 instead of 128 inputs per row in the large product: the first layer
    /// of a 1_ant head takes 11 x 19 inputs instead of 11 x 128. `extra`, when given, is one
    /// more term `x_e W_e` of the first layer (the value's held assignment,
    /// [`ReleaseMlp::forward`]).
    fn hidden<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        mlp: &Mlp,
        x: Tensor<T>,
        extra: Option<(Var<'t, T>, Var<'t, T>)>,
    ) -> Result<Var<'t, T>> {
        let (nb, r) = (x.shape()[0], x.shape()[1]);
        let first = &mlp.layers[0];
        if mlp.layers.len() < 2 || first.fan_in != 2 * EMBED * r {
            return Err(ModelError::Input(format!(
                "an MLP of {} layers taking {} inputs for {r} embedded rows",
                mlp.layers.len(),
                first.fan_in
            )));
        }
        let tape = p.tape();
        let w = p.get(first.weight);
        let out = first.fan_out;
        let mut terms = Vec::with_capacity(2);
        let mut bias = match first.bias {
            Some(b) => p.get(b),
            None => tape.constant(Tensor::zeros(&[out])),
        };
        for (k, (emb, lo, width)) in
            [(&self.z, 0, NODE_VECTOR_LEN), (&self.h, NODE_VECTOR_LEN, N_SCALARS)].into_iter().enumerate()
        {
            // W_r for every row: [R, 64, out]; E [1, width, 64]; E W_r: [R, width, out].
            let wr = w.narrow(0, k * EMBED * r, EMBED * r)?.reshape(&[r, EMBED, out])?;
            let e = p.get(emb.weight).reshape(&[1, width, EMBED])?;
            let m = e.matmul(wr)?.reshape(&[r * width, out])?;
            if let Some(b) = emb.bias {
                let br = p.get(b).reshape(&[1, 1, EMBED])?.matmul(wr)?.reshape(&[r, out])?.sum(0, false)?;
                bias = bias.add(br)?;
            }
            let xk = tape.constant(x.clone()).narrow(2, lo, width)?.reshape(&[nb, r * width])?;
            terms.push((xk, m));
        }
        terms.extend(extra);
        let mut h = tape.linear_sum(&terms, Some(bias), mlp.activation)?;
        for layer in &mlp.layers[1..mlp.layers.len() - 1] {
            h = layer.forward_act(p, h, mlp.activation)?;
        }
        Ok(h)
    }
}

/// The release's MLP (module docs). Parameters: `actor.embed_{z,h}.*`, `actor.<a>.*`,
/// `critic.embed_{z,h}.*`, `critic.mlp.*`.
#[derive(Clone, Debug)]
pub struct ReleaseMlp {
    heading: bool,
    proc: InputProcessor,
    graph: GraphBuilder,
    /// Whether the own root is repeated after the own nodes (not with `assignment=none`).
    own_root_row: bool,
    actor_embed: NodeEmbedding,
    heads: Vec<Mlp>,
    critic_embed: NodeEmbedding,
    critic: Mlp,
    /// `assign_critic=held`: `W_σ` (`critic.held.weight`, module docs).
    held: Option<HeldTerm>,
    order: Vec<usize>,
    /// `assignment=learned`: the scorer (parameters `assign.*`) and its draws, which give
    /// the graph builder its assignment (as in [`crate::shnn`]).
    pub(crate) learned: Option<Box<LearnedAssignment>>,
}

impl ReleaseMlp {
    /// The model for `agents` (scope `s` holds `actor` and `critic`, then, with `learned`
    /// (`assignment=learned`: the scorer's configuration and the draws' seed), the scorer's
    /// `assign`, last, so that the other parameters start as without it; with
    /// `value_reads_held`, `critic.held.weight` after it, zero).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new<T: Float>(
        s: &mut Scope<'_, T>,
        spec: &ObsSpec,
        agents: &[usize],
        graph: GraphBuilder,
        heading: bool,
        hidden: &HiddenWidths,
        learned: Option<(ScorerConfig, u64)>,
        value_reads_held: bool,
    ) -> Result<Self> {
        let (head_hidden, critic_hidden) = (&hidden.head, &hidden.critic);
        let own_root_row = graph.method() != AssignmentMethod::None;
        let slots = graph.slots();
        let mut actor = s.sub("actor");
        let actor_embed = NodeEmbedding::new(&mut actor)?;
        let heads = agents
            .iter()
            .map(|&a| {
                let rows = 1 + spec.agent_dof[a] + usize::from(own_root_row) + slots;
                Mlp::new(
                    &mut actor.sub(a),
                    &layer_sizes(2 * EMBED * rows, head_hidden, 2 * spec.agent_dof[a]),
                    Activation::Relu,
                )
            })
            .collect::<nn::Result<Vec<_>>>()?;
        let mut c = s.sub("critic");
        let critic_embed = NodeEmbedding::new(&mut c)?;
        let ne = spec.entity_root_node.len();
        let critic = Mlp::new(&mut c.sub("mlp"), &layer_sizes(2 * EMBED * ne, critic_hidden, 1), Activation::Relu)?;
        let gravity = spec.gravity_dir.map(f64::from);
        let learned = learned
            .map(|(config, seed)| LearnedAssignment::new(&mut s.sub("assign"), config, &graph, gravity, seed))
            .transpose()?
            .map(Box::new);
        let held = match (value_reads_held, &learned) {
            (false, _) => None,
            (true, Some(_)) => {
                Some(HeldTerm::new(s, graph.assignment_width(), agents.len(), critic.layers[0].fan_out)?)
            }
            (true, None) => {
                return Err(ModelError::Option(
                    "assign_critic=held reads a learned assignment (give it with assignment=learned)".into(),
                ));
            }
        };
        Ok(Self {
            heading,
            proc: InputProcessor::new(spec, Translation::RootMean)?,
            graph,
            own_root_row,
            actor_embed,
            heads,
            critic_embed,
            critic,
            held,
            order: critic_order(spec, agents),
            learned,
        })
    }

    /// The task-assignment graph builder (for reseeding).
    pub(crate) fn graph_mut(&mut self) -> &mut GraphBuilder {
        &mut self.graph
    }

    /// The task-assignment graph builder.
    pub(crate) fn graph(&self) -> &GraphBuilder {
        &self.graph
    }

    /// Policy and (if `with_value`) value (module docs). `held`, with the assignment `fixed`
    /// given, says for each scene whether that assignment was held into it (the value reads
    /// it, `assign_critic=held`) or drawn there (the value reads none).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
        agents: &[usize],
        spec: &ObsSpec,
        fixed: Option<&[u32]>,
        held: Option<&[bool]>,
        with_value: bool,
    ) -> Result<PolicyOutput<'t, T>> {
        let nb = obs.batch;
        check_held(held, self.held.is_some(), fixed.is_some(), nb)?;
        let inputs = self.proc.entities::<T, S>(obs)?;
        // A learned assignment is scored on the tape and drawn (or the given one scored)
        // before the graph is built with it.
        let (graph, assignment_terms) = build_graph(&mut self.graph, self.learned.as_deref_mut(), p, &inputs, fixed)?;
        let mut out = Vec::with_capacity(agents.len());
        for (head, &a) in self.heads.iter().zip(agents) {
            let (root, k) = (spec.agent_root_node[a], 1 + spec.agent_dof[a]);
            let rows = k + usize::from(self.own_root_row) + graph.slots;
            let mut x = tensor::pool::with_capacity(nb * rows * NODE_FEATURES);
            for b in 0..nb {
                let origin = obs.vec3(b, root, 0);
                let yaw = yaw_of(heading, spec, self.heading, a, b);
                for node in root..root + k {
                    push_node(&mut x, obs, b, node, origin, yaw);
                }
                if self.own_root_row {
                    push_node(&mut x, obs, b, root, origin, yaw);
                }
                for slot in 0..graph.slots {
                    match graph.neighbour(b, a, slot) {
                        UNASSIGNED => x.extend(std::iter::repeat_n(T::ZERO, NODE_FEATURES)),
                        j => push_node(&mut x, obs, b, spec.entity_root_node[j], origin, yaw),
                    }
                }
            }
            let hidden = self.actor_embed.hidden(p, head, Tensor::new(x, &[nb, rows, NODE_FEATURES])?, None)?;
            out.push(split_head(head, p, hidden, a, spec.agent_dof[a])?);
        }
        if !with_value {
            return Ok(PolicyOutput { agents: out, value: None, assignment: graph.assignment, assignment_terms });
        }
        // The value: every entity's root, relative to the mean of the roots.
        let ne = self.order.len();
        let mut x = tensor::pool::with_capacity(nb * ne * NODE_FEATURES);
        for b in 0..nb {
            let yaw = yaw_of(heading, spec, self.heading, agents[0], b);
            for &e in &self.order {
                push_node(&mut x, obs, b, spec.entity_root_node[e], inputs.origin[b], yaw);
            }
        }
        // With assign_critic=held, the term x_σ W_σ where any scene holds its assignment.
        let extra = match &self.held {
            Some(t) => t.term(p, &graph.assignment, held)?,
            None => None,
        };
        let x = Tensor::new(x, &[nb, ne, NODE_FEATURES])?;
        let hidden = self.critic_embed.hidden(p, &self.critic, x, extra)?;
        let last = &self.critic.layers[self.critic.layers.len() - 1];
        let value = last.forward(p, hidden)?.reshape(&[nb])?;
        Ok(PolicyOutput { agents: out, value: Some(value), assignment: graph.assignment, assignment_terms })
    }
}

/// The flat baselines and `transformer_hn` (module docs): per agent an MLP on its flat view,
/// or one shared Transformer whose tokens are the view's nodes; the critic an MLP on every
/// node, or a Transformer over every entity's root (`transformer_hn`).
#[derive(Clone, Debug)]
pub struct FlatMlp {
    heading: bool,
    /// Per agent its view (node list).
    views: Vec<Vec<usize>>,
    heads: FlatHeads,
    critic: FlatCritic,
}

#[derive(Clone, Debug)]
enum FlatHeads {
    Mlp(Vec<Mlp>),
    Transformer(Box<TransformerHead>),
}

#[derive(Clone, Debug)]
enum FlatCritic {
    /// MLP on every node of the scene.
    Nodes(Mlp),
    /// Transformer over every entity's root (positions relative to the mean of the roots),
    /// in `order`.
    Roots(Box<TransformerHead>, Vec<usize>),
}

impl FlatMlp {
    /// The model for `agents`: MLP heads (`head_hidden`) or a shared Transformer head.
    pub(crate) fn new<T: Float>(
        s: &mut Scope<'_, T>,
        spec: &ObsSpec,
        agents: &[usize],
        heading: bool,
        transformer: bool,
        head_hidden: &[usize],
        critic_hidden: &[usize],
    ) -> Result<Self> {
        let views: Vec<Vec<usize>> = agents.iter().map(|&a| spec.agent_view(a)).collect();
        let mut actor = s.sub("actor");
        let cfg = nn::TransformerConfig::default();
        let heads = if transformer {
            FlatHeads::Transformer(Box::new(TransformerHead::new(&mut actor, NODE_FEATURES, 2, cfg)?))
        } else {
            FlatHeads::Mlp(
                agents
                    .iter()
                    .zip(&views)
                    .map(|(&a, v)| {
                        let sz = layer_sizes(v.len() * NODE_FEATURES, head_hidden, 2 * spec.agent_dof[a]);
                        Mlp::new(&mut actor.sub(a), &sz, Activation::Relu)
                    })
                    .collect::<nn::Result<Vec<_>>>()?,
            )
        };
        let critic = if transformer {
            let head = TransformerHead::new(&mut s.sub("critic"), NODE_FEATURES, 1, cfg)?;
            FlatCritic::Roots(Box::new(head), critic_order(spec, agents))
        } else {
            let sz = layer_sizes(spec.n_nodes * NODE_FEATURES, critic_hidden, 1);
            FlatCritic::Nodes(Mlp::new(&mut s.sub("critic"), &sz, Activation::Relu)?)
        };
        Ok(Self { heading, views, heads, critic })
    }

    /// The rows `[B, nodes * NODE_FEATURES]` of `nodes`, seen from `agent` (its heading frame
    /// and root as origin with heading normalisation, else the world frame; positions
    /// relative to `origin` instead when given).
    fn features<T: Float, S: ObsElement>(
        &self,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
        spec: &ObsSpec,
        agent: usize,
        nodes: &[usize],
        origin: Option<&[[f64; 3]]>,
    ) -> Result<Tensor<T>> {
        let nb = obs.batch;
        let mut x = tensor::pool::with_capacity(nb * nodes.len() * NODE_FEATURES);
        for b in 0..nb {
            let yaw = yaw_of(heading, spec, self.heading, agent, b);
            let o = match origin {
                Some(o) => o[b],
                None if self.heading => obs.vec3(b, spec.agent_root_node[agent], 0),
                None => [0.0; 3],
            };
            for &n in nodes {
                push_node(&mut x, obs, b, n, o, yaw);
            }
        }
        Ok(Tensor::new(x, &[nb, nodes.len() * NODE_FEATURES])?)
    }

    /// Policy and (if `with_value`) value (module docs).
    pub(crate) fn forward<'t, T: Float, S: ObsElement>(
        &self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
        agents: &[usize],
        spec: &ObsSpec,
        with_value: bool,
    ) -> Result<PolicyOutput<'t, T>> {
        let tape = p.tape();
        let nb = obs.batch;
        let mut out = Vec::with_capacity(agents.len());
        for (i, (&a, view)) in agents.iter().zip(&self.views).enumerate() {
            let x = self.features(obs, heading, spec, a, view, None)?;
            let dof = spec.agent_dof[a];
            match &self.heads {
                FlatHeads::Mlp(heads) => {
                    let hidden = heads[i].forward_hidden(p, tape.constant(x))?;
                    out.push(split_head(&heads[i], p, hidden, a, dof)?);
                }
                FlatHeads::Transformer(head) => {
                    // One token per node of the view; its DoF nodes follow its root.
                    let tokens = tape.constant(x.reshape(&[nb, view.len(), NODE_FEATURES])?);
                    let (loc, scale) = head.forward(p, tokens, 1, dof)?;
                    out.push(AgentPolicy { agent: a, loc, scale });
                }
            }
        }
        if !with_value {
            return Ok(PolicyOutput { agents: out, value: None, assignment: Vec::new(), assignment_terms: None });
        }
        // The critic, in the frame of the team's first agent.
        let value = match &self.critic {
            FlatCritic::Nodes(mlp) => {
                let all: Vec<usize> = (0..spec.n_nodes).collect();
                let x = tape.constant(self.features(obs, heading, spec, agents[0], &all, None)?);
                mlp.forward(p, x)?.reshape(&[nb])?
            }
            FlatCritic::Roots(head, order) => {
                let roots: Vec<usize> = order.iter().map(|&e| spec.entity_root_node[e]).collect();
                let c: Vec<[f64; 3]> = (0..nb)
                    .map(|b| {
                        let mut m = [0.0; 3];
                        for &n in &roots {
                            let p = obs.vec3(b, n, 0);
                            (0..3).for_each(|r| m[r] += p[r] / roots.len() as f64);
                        }
                        m
                    })
                    .collect();
                let x = self.features(obs, heading, spec, agents[0], &roots, Some(&c))?;
                let tokens = tape.constant(x.reshape(&[nb, roots.len(), NODE_FEATURES])?);
                head.forward_all(p, tokens)?.reshape(&[nb, roots.len()])?.mean(1, false)?
            }
        };
        Ok(PolicyOutput { agents: out, value: Some(value), assignment: Vec::new(), assignment_terms: None })
    }
}

/// Refuses a non-empty assignment given to a model that has no task assignment.
pub(crate) fn no_assignment(fixed: Option<&[u32]>) -> Result<()> {
    match fixed {
        Some(f) if !f.is_empty() => {
            Err(ModelError::Input(format!("an assignment of {} entries given to a model without one", f.len())))
        }
        _ => Ok(()),
    }
}
