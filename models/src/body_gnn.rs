//! The body-level subequivariant GNN head of `shgnn` (paper appendix "SHGNN", section
//! `sec:sgnn`): SHNN's body-level MLP replaced by message passing over each agent's
//! morphology graph, one network shared by every agent and morphology of a team.
//!
//! For agent `a` the graph `G_a = (V_a, E_a)` has the agent's root and DoF nodes as
//! vertices and an edge in both directions between every node and its parent
//! ([`ObsSpec::node_parent`]). Node `k` starts from `Z_k = Z_{a,k}` (position relative to
//! the agent's body origin, eq. (lrf): its own root by default; velocity, angular velocity)
//! and `h_k = [h_{a,k}, h'_a, p^z_{a,k}]` (its scalars, the agent's entity feature, its
//! height `-<p, g>`), as the paper writes; then `φ_b` "similar to `φ_o`":
//! 1. `Z = [Z_k, g] W_e` (4 -> `m` channels), `h = h_k W_h + b`;
//! 2. `steps` rounds of one shared [`nn::SubeqMessagePassing`] (raw edge distance, mean
//!    aggregation; `g` inside each layer only with `gravity_in_layers`, as the entity stage)
//!    with the node positions as `x`;
//! 3. per DoF node the paper's `σ_π(O_a^T Z'_k, h'_k)`, "a linear layer with bias" (appendix
//!    "Analyses of Morphology-shared Policy"): `O_a^T Z'_k` (`3 m` invariant numbers in the
//!    agent's local frame from the entity stage) and `h'_k` give `(loc, scale)` of the DoF
//!    that node actuates (the root's output is not used). Hidden layers can be added
//!    (`decoder_hidden`; none by default).
//!
//! Every step is subequivariant (or invariant) under rotations about `g` and translations,
//! so the head's outputs are invariant.

use nn::{
    Aggregation, Bound, EdgeDistance, EdgeList, Linear, MessagePassingConfig, Mlp, Scope, SubeqMessagePassing,
    VectorLinear,
};
use tensor::{Activation, Float, Tensor, Var};

use crate::error::{ModelError, Result};
use crate::frame::to_frame;
use crate::input::AgentBody;
use envs::layout::NODE_VECTORS;
use envs::layout::{N_SCALARS, ObsSpec};

/// Sizes of a [`BodyGnn`].
#[derive(Clone, Debug)]
pub struct BodyGnnConfig {
    /// Vector channels `m` of the node features.
    pub vectors: usize,
    /// Scalar features of the node features.
    pub scalars: usize,
    /// Hidden width of the message and update MLPs.
    pub hidden: usize,
    /// Hidden layers of those MLPs.
    pub layers: usize,
    /// Propagation steps of the shared layer.
    pub steps: usize,
    /// Width of the agent's entity feature `h'_a`.
    pub entity_scalars: usize,
    /// Hidden widths of the per-node decoder (none: the paper's linear `σ_π`).
    pub decoder_hidden: Vec<usize>,
    /// Gravity direction `g` (a 4th input channel).
    pub gravity: [f64; 3],
    /// Whether `g` is also appended inside every layer.
    pub gravity_in_layers: bool,
}

/// The morphology graph of one agent, in node indices local to the agent (root = 0).
#[derive(Clone, Debug)]
struct AgentGraph {
    /// Nodes `K_a`.
    nodes: usize,
    /// Neighbours of each local node (parent and children), ascending.
    neighbours: Vec<Vec<usize>>,
}

impl AgentGraph {
    /// The edges of `batch` copies (copy `b` at nodes `b K_a ..`), sorted by source.
    fn edges(&self, batch: usize) -> Result<EdgeList> {
        let (mut src, mut dst) = (Vec::new(), Vec::new());
        for b in 0..batch {
            for (i, nb) in self.neighbours.iter().enumerate() {
                for &j in nb {
                    src.push(b * self.nodes + i);
                    dst.push(b * self.nodes + j);
                }
            }
        }
        Ok(EdgeList::new(src, dst, batch * self.nodes)?)
    }
}

/// Body-level subequivariant message passing and per-node decoder (module docs).
/// Parameters under its scope: `embed_z.weight`, `embed_h.*`, `mp.*`, `decoder.*`.
#[derive(Clone, Debug)]
pub struct BodyGnn {
    /// `W_e`: `[Z_k, g]` -> `m` channels.
    pub embed_z: VectorLinear,
    /// `[h_{a,k}, h'_a, p^z]` -> scalars (affine).
    pub embed_h: Linear,
    /// The message-passing layer shared by all steps.
    pub mp: SubeqMessagePassing,
    /// Per-node decoder `σ_π`: `[O_a^T Z'_k, h'_k]` -> `(loc, scale)`.
    pub decoder: Mlp,
    config: BodyGnnConfig,
    /// Per scene agent its morphology graph (`None` for agents of other teams).
    graphs: Vec<Option<AgentGraph>>,
}

impl BodyGnn {
    /// A head for the `agents` of scenes laid out by `spec`.
    pub fn new<T: Float>(
        s: &mut Scope<'_, T>,
        config: BodyGnnConfig,
        spec: &ObsSpec,
        agents: &[usize],
    ) -> Result<Self> {
        if config.steps == 0 || config.vectors == 0 || config.scalars == 0 || config.decoder_hidden.contains(&0) {
            return Err(ModelError::Option(format!("body GNN sizes {config:?} must be positive")));
        }
        let mut graphs = vec![None; spec.n_agents];
        for &a in agents {
            let (root, k) = (spec.agent_root_node[a], 1 + spec.agent_dof[a]);
            let mut neighbours = vec![Vec::new(); k];
            for local in 1..k {
                let parent = spec.node_parent[root + local];
                let p = usize::try_from(parent).ok().filter(|&p| p >= root && p < root + k).ok_or_else(|| {
                    ModelError::Input(format!("node {} of agent {a} has parent {parent} outside it", root + local))
                })? - root;
                neighbours[local].push(p);
                neighbours[p].push(local);
            }
            neighbours.iter_mut().for_each(|n| n.sort_unstable());
            graphs[a] = Some(AgentGraph { nodes: k, neighbours });
        }
        let (m, sc) = (config.vectors, config.scalars);
        let embed_z = VectorLinear::new(&mut s.sub("embed_z"), NODE_VECTORS + 1, m)?;
        let embed_h = Linear::new(&mut s.sub("embed_h"), N_SCALARS + config.entity_scalars + 1, sc)?;
        let mp = SubeqMessagePassing::new(
            &mut s.sub("mp"),
            MessagePassingConfig {
                vectors: m,
                scalars: sc,
                hidden: config.hidden,
                layers: config.layers,
                distance: EdgeDistance::Raw,
                aggregation: Aggregation::Mean,
                gravity: if config.gravity_in_layers { Some(config.gravity) } else { None },
                edge_scalars: 0,
            },
        )?;
        let mut sizes = vec![3 * m + sc];
        sizes.extend_from_slice(&config.decoder_hidden);
        sizes.push(2);
        let decoder = Mlp::new(&mut s.sub("decoder"), &sizes, Activation::Relu)?;
        Ok(Self { embed_z, embed_h, mp, decoder, config, graphs })
    }

    /// `loc`, `scale` `[B, dof_a]` of one agent: its `body`, its entity feature `h'_a`
    /// `[B, s_e]` and its frame `O_a` `[B, 3, 3]`.
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        body: &AgentBody<T>,
        ha: Var<'t, T>,
        frame: Var<'t, T>,
    ) -> Result<(Var<'t, T>, Var<'t, T>)> {
        let graph = self
            .graphs
            .get(body.agent)
            .and_then(Option::as_ref)
            .ok_or_else(|| ModelError::Input(format!("agent {} is not one of the head's agents", body.agent)))?;
        let tape = p.tape();
        let (nb, k) = (body.z.shape()[0], graph.nodes);
        let se = self.config.entity_scalars;
        if body.z.shape() != [nb, k, 3, NODE_VECTORS] || ha.shape() != [nb, se] || frame.shape() != [nb, 3, 3] {
            return Err(ModelError::Input(format!(
                "body GNN of agent {} ({k} nodes, {se} entity scalars) got z {:?}, h' {:?}, frame {:?}",
                body.agent,
                body.z.shape(),
                ha.shape(),
                frame.shape()
            )));
        }
        let n = nb * k;
        let g = self.config.gravity;
        // Node heights -<p, g> of the world positions.
        let zv = body.z.data();
        let mut height = Vec::with_capacity(n);
        for b in 0..nb {
            for node in 0..k {
                let at = |r: usize| zv[((b * k + node) * 3 + r) * NODE_VECTORS].to_f64() + body.origin[b][r];
                height.push(T::from_f64(-(0..3).map(|r| at(r) * g[r]).sum::<f64>()));
            }
        }
        let z0 = tape.constant(body.z.reshape(&[n, 3, NODE_VECTORS])?);
        let x = z0.narrow(2, 0, 1)?;
        let mut z = self.embed_z.forward_channels(p, &[z0], Some(g))?;
        let rows: Vec<usize> = (0..nb).flat_map(|b| std::iter::repeat_n(b, k)).collect();
        let h0 = tape.cat(
            &[
                tape.constant(body.h.reshape(&[n, N_SCALARS])?),
                ha.index_select(0, &rows)?,
                tape.constant(Tensor::new(height, &[n, 1])?),
            ],
            1,
        )?;
        let mut h = self.embed_h.forward(p, h0)?;
        let edges = graph.edges(nb)?;
        if !edges.is_empty() {
            for _ in 0..self.config.steps {
                (z, h) = self.mp.forward(p, z, h, x, &edges)?;
            }
        }
        // σ_π(O_a^T Z'_k, h'_k): the output vectors in the agent's frame, and h'_k.
        let m = self.config.vectors;
        let local = to_frame(frame.index_select(0, &rows)?, z)?;
        let out = self.decoder.forward_parts(p, &[local.reshape(&[n, 3 * m])?, h])?.reshape(&[nb, k, 2])?;
        let dof = k - 1;
        let loc = out.narrow(1, 1, dof)?.narrow(2, 0, 1)?.reshape(&[nb, dof])?;
        let scale = out.narrow(1, 1, dof)?.narrow(2, 1, 1)?.reshape(&[nb, dof])?;
        Ok((loc, scale))
    }
}
