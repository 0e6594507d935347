//! The policy/critic interface the trainer uses (paper section 3 "Body-level Control",
//! eqs. (pi) and (value); appendix "Baselines"), and the models built by name.
//!
//! A [`Model`] is built from a [`ModelConfig`] for one scene layout ([`ObsSpec`]) and one
//! team: it creates its parameters in a [`Scope`] (so the trainer keeps every team's
//! parameters in one [`ParamStore`] under different prefixes, counted with
//! [`ParamStore::num_elements_under`] or [`Model::num_params`]) and maps a batch of
//! observations to, for each agent of the team, the Tanh-Normal parameters `loc`, `scale`
//! `[B, dof_a]` of its actuated DoF (`std = softplus(scale) + 0.001`,
//! [`crate::distribution::std_from_scale`]), and the team's value `[B]`
//! ([`PolicyOutput`]).
//!
//! Parameter names under the scope: `entity.*` (the entity-level message passing, shared by
//! the team's agents), `actor.<a>.*` (one MLP body head per agent `a`, scene agent index) or
//! `actor.*` (the Transformer head every agent of the team shares) and `critic.*`. With MLP
//! heads only the entity stage is shared within a team (paper section 5); the Transformer
//! head is one network for all nodes and morphologies (paper appendix "Model Comparison":
//! Transformer and GNN "share parameters across different morphologies").
//!
//! # Models
//! - `shnn` (paper section 3): the entity stage ([`EntityMp`]: input processing, task
//!   assignment graph, eq. (somp), `u_i = Z'_i W_u`, `O_i = OP(u_i)` eqs. (ortho),
//!   (ort_matrix)); per agent `a` its own nodes' vectors in its frame, `O_a^T Z_{a,k}`
//!   (eq. (lrf); positions relative to the root of the assigned entity), with their scalars
//!   `h_{a,k}` and the agent's `h'_a` into an MLP (256, 256; ReLU) giving `loc` and `scale`
//!   (eq. (pi)); the critic is an MLP (256, 256) on `h'` of all entities (eq. (value)),
//!   own agents first, then the other agents, then the balls. The neighbours' roots of
//!   eq. (lrf) reach the head through `h'_a` (and through the positions relative to the
//!   assigned entity), as in the reference release (MEBEN.md section 5).
//! - `shnn_og3` (ablation SHNN:Og3): no orthogonalisation, `O_a = Z'_a` (`[3, m]`), so the
//!   head reads `Z'_a^T Z_{a,k}` (`m x 3` per node): invariant under `O_g(3)`, reflections
//!   through vertical planes included.
//! - `shnn_so3` (ablation SHNN:SO3): `shnn` without the gravity channel in the message
//!   passing.
//! - `mlp` (appendix baseline MLP): per agent an MLP (256 x 3 hidden layers, ReLU) on the
//!   raw world-frame observation of MeBen's agent view ([`ObsSpec::agent_view`]: its own
//!   nodes, then every other entity's root; 9 vector components and the scalars per node);
//!   the critic MLP (same sizes) reads every node of the scene. Not invariant.
//! - `mlp_hn` (MLP+HN): as `mlp`, but every vector in the agent's heading frame
//!   ([`crate::frame::heading_frame`] of [`Observation::heading`]) with positions relative to
//!   the agent's root; the critic reads the scene in the frame of the team's first agent.
//!
//! - `transformer_hn` (Transformer+HN, paper section "Extended Evaluations on
//!   Transformer"): the nodes of `mlp_hn`'s agent view, each in the agent's heading frame,
//!   are the tokens of one shared [`TransformerHead`] (128/256/3/2, no positional encoding,
//!   decoder conditioned on the token); each DoF node's output gives that DoF's `loc`,
//!   `scale`. Critic as `mlp_hn`'s.
//! - `shtransformer` (SHTransformer): `shnn` with the MLP head replaced by the shared
//!   [`TransformerHead`] over the agent's own nodes, token `k` = `[O_a^T Z_{a,k}, h_{a,k},
//!   h'_a]` (`shnn`'s head input, one node per token). Critic as `shnn`'s.
//!
//! - `shgnn` (SHGNN, paper appendix section `sec:sgnn`): `shnn` with the MLP head replaced
//!   by one body-level subequivariant GNN ([`BodyGnn`]) shared by the team's agents and
//!   morphologies: message passing with gravity over each agent's morphology graph (root and
//!   DoF nodes, parent/child edges both ways), node inputs `Z_{a,k}`, `[h_{a,k}, h'_a,
//!   p^z_{a,k}]`; each DoF node decoded to `loc`, `scale` from its output vectors in `O_a`
//!   and its scalars. Critic as `shnn`'s.
//! - `hnn`, `hnn_hn`, `hnn_dn` (ablations HNN, HNN+HN, HNN+DN; [`crate::hnn`]): SHNN's
//!   hierarchy with the vectors flattened into scalars and plain MLP message passing, in the
//!   world frame, the agent's heading frame, or the frame of the goal (assigned entity)
//!   direction. Per-agent MLP heads and the critic as `shnn`'s.

use envs::tasks::{N_SCALARS, ObsSpec, Observation};
use nn::{Bound, Mlp, ParamStore, Scope, TransformerConfig};
use tensor::{Activation, Float, Tensor, Var};

use crate::assignment::AssignmentMethod;
use crate::body_gnn::{BodyGnn, BodyGnnConfig};
use crate::distribution::std_from_scale;
use crate::entity_graph::GraphBuilder;
use crate::entity_mp::{EntityMp, EntityMpConfig};
use crate::error::{ModelError, Result};
use crate::frame::to_frame;
use crate::hnn::{Hnn, HnnFrame, ScalarMpSizes};
use crate::input::{EntityAbstraction, InputProcessor, ObsBatch, ObsElement, Translation};
use crate::transformer_head::TransformerHead;

/// The models [`Model::new`] builds.
pub const MODEL_NAMES: [&str; 11] = [
    "shnn",
    "shnn_og3",
    "shnn_so3",
    "mlp",
    "mlp_hn",
    "transformer_hn",
    "shtransformer",
    "shgnn",
    "hnn",
    "hnn_hn",
    "hnn_dn",
];

/// Models of the paper that are not implemented yet (an error names them as planned).
pub const PLANNED_MODELS: [&str; 0] = [];

/// The option keys [`ModelConfig::parse`] accepts.
pub const OPTION_KEYS: [&str; 6] = ["assignment", "translation", "abstraction", "seed", "head", "critic"];

/// Per-node features of the baselines: 9 vector components and the scalars.
const NODE_FEATURES: usize = 9 + N_SCALARS;

/// Sizes of the entity-level message passing (paper Table "Hyperparameters of Network").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MpSizes {
    /// Vector channels `m` (32).
    pub vectors: usize,
    /// Scalar features (64).
    pub scalars: usize,
    /// Hidden width of the message and update MLPs (64).
    pub hidden: usize,
    /// Hidden layers of those MLPs (2).
    pub layers: usize,
    /// Propagation steps (2).
    pub steps: usize,
}

impl Default for MpSizes {
    /// The paper's sizes.
    fn default() -> Self {
        Self { vectors: 32, scalars: 64, hidden: 64, layers: 2, steps: 2 }
    }
}

/// Which model to build and its options; `None` fields take the model's defaults.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModelConfig {
    /// One of [`MODEL_NAMES`].
    pub name: String,
    /// Task assignment (SHNN models; default greedy, Algorithm 1).
    pub assignment: Option<AssignmentMethod>,
    /// Translation mode (SHNN models; default [`Translation::Assigned`]).
    pub translation: Option<Translation>,
    /// Entity abstraction (SHNN models; default [`EntityAbstraction::Root`]).
    pub abstraction: Option<EntityAbstraction>,
    /// Entity message-passing sizes (SHNN models; default [`MpSizes::default`]).
    pub mp: Option<MpSizes>,
    /// Hidden widths of each agent's MLP head (default 256, 256 for SHNN; 256 x 3 for MLPs;
    /// not an option of the Transformer models).
    pub head_hidden: Option<Vec<usize>>,
    /// Hidden widths of the critic (default as the head's; 256, 256 for `shtransformer`,
    /// 256 x 3 for `transformer_hn`).
    pub critic_hidden: Option<Vec<usize>>,
    /// Seed of the stochastic assignment.
    pub seed: u64,
}

impl ModelConfig {
    /// The model `name` with its defaults (checked when the model is built).
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_string(),
            assignment: None,
            translation: None,
            abstraction: None,
            mp: None,
            head_hidden: None,
            critic_hidden: None,
            seed: 0,
        }
    }

    /// Parses `name` or `name:key=value;key=value`, keys [`OPTION_KEYS`]: `assignment`
    /// (`greedy`, `hungarian`, `stochastic`, `none`), `translation` (`none`, `root_mean`,
    /// `body_mean`, `assigned`), `abstraction` (`root`, `mean`), `seed` (integer), `head`
    /// and `critic` (hidden widths joined by `x`, e.g. `256x256`). E.g.
    /// `shnn:assignment=hungarian;translation=root_mean`.
    pub fn parse(s: &str) -> Result<Self> {
        let (name, opts) = s.split_once(':').unwrap_or((s, ""));
        check_name(name)?;
        let mut c = Self::new(name);
        for item in opts.split(';').filter(|x| !x.is_empty()) {
            let (k, v) = item.split_once('=').ok_or_else(|| {
                ModelError::Option(format!("model option `{item}` is not key=value (keys: {})", OPTION_KEYS.join(", ")))
            })?;
            match k {
                "assignment" => c.assignment = Some(AssignmentMethod::parse(v).map_err(ModelError::Option)?),
                "translation" => c.translation = Some(Translation::parse(v)?),
                "abstraction" => c.abstraction = Some(EntityAbstraction::parse(v)?),
                "seed" => {
                    c.seed = v.parse().map_err(|_| ModelError::Option(format!("seed `{v}` is not an integer")))?;
                }
                "head" => c.head_hidden = Some(parse_widths(v)?),
                "critic" => c.critic_hidden = Some(parse_widths(v)?),
                _ => {
                    return Err(ModelError::Option(format!(
                        "unknown model option `{k}` (known: {})",
                        OPTION_KEYS.join(", ")
                    )));
                }
            }
        }
        Ok(c)
    }
}

fn parse_widths(v: &str) -> Result<Vec<usize>> {
    let w: Vec<usize> = v
        .split('x')
        .map(|x| x.parse::<usize>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .ok_or_else(|| ModelError::Option(format!("hidden widths `{v}` are not positive integers joined by x")))?;
    Ok(w)
}

/// Checks a model name against [`MODEL_NAMES`] (and names the planned ones).
fn check_name(name: &str) -> Result<()> {
    if MODEL_NAMES.contains(&name) {
        return Ok(());
    }
    let planned = if PLANNED_MODELS.contains(&name) { " is not implemented yet" } else { " is unknown" };
    let later =
        if PLANNED_MODELS.is_empty() { String::new() } else { format!("; planned: {}", PLANNED_MODELS.join(", ")) };
    Err(ModelError::Option(format!("model `{name}`{planned} (known models: {}{later})", MODEL_NAMES.join(", "))))
}

/// One agent's action-distribution parameters.
#[derive(Clone, Copy, Debug)]
pub struct AgentPolicy<'t, T: Float> {
    /// The agent (scene agent index; its actions are at [`ObsSpec::agent_action_offset`]).
    pub agent: usize,
    /// Mean of the pre-squash Normal, `[B, dof_a]`.
    pub loc: Var<'t, T>,
    /// Raw scale, `[B, dof_a]`; the standard deviation is [`AgentPolicy::std`].
    pub scale: Var<'t, T>,
}

impl<'t, T: Float> AgentPolicy<'t, T> {
    /// `std = softplus(scale) + 0.001` (eq. (pi), [`crate::distribution::std_from_scale`]).
    pub fn std(&self) -> Var<'t, T> {
        std_from_scale(self.scale)
    }
}

/// What a model returns for a batch.
#[derive(Clone, Debug)]
pub struct PolicyOutput<'t, T: Float> {
    /// One entry per agent of the team, in scene order ([`Model::agents`]).
    pub agents: Vec<AgentPolicy<'t, T>>,
    /// The team's value `[B]` (eq. (value)).
    pub value: Var<'t, T>,
}

/// How the SHNN head expresses the body vectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameKind {
    /// `O = OP(u)` (eqs. (ortho), (ort_matrix)).
    Orthogonal,
    /// `O = Z'` (SHNN:Og3).
    Channels,
}

/// Body-level heads: one MLP per agent, or one Transformer or GNN for the team.
#[derive(Clone, Debug)]
enum Heads {
    Mlp(Vec<Mlp>),
    Transformer(Box<TransformerHead>),
    Gnn(Box<BodyGnn>),
}

#[derive(Clone, Debug)]
struct Shnn {
    proc: InputProcessor,
    graph: GraphBuilder,
    mp: EntityMp,
    frame: FrameKind,
    heads: Heads,
    critic: Mlp,
    /// Entity order of the critic input (own agents, other agents, balls).
    critic_entities: Vec<usize>,
}

#[derive(Clone, Debug)]
struct MlpModel {
    heading: bool,
    /// Per agent its view (node list).
    views: Vec<Vec<usize>>,
    heads: Heads,
    critic: Mlp,
}

#[derive(Clone, Debug)]
enum Arch {
    Shnn(Box<Shnn>),
    Hnn(Box<Hnn>),
    Mlp(MlpModel),
}

/// A policy and critic for one team of one scene layout (module docs).
#[derive(Clone, Debug)]
pub struct Model {
    name: String,
    team: usize,
    agents: Vec<usize>,
    spec: ObsSpec,
    prefix: String,
    arch: Arch,
}

impl Model {
    /// Builds `config.name` for `team` of scenes laid out by `spec`, with parameters under
    /// scope `s` (module docs). Unknown names and options that do not apply are errors
    /// listing the accepted ones.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, config: &ModelConfig, spec: &ObsSpec, team: usize) -> Result<Self> {
        check_name(&config.name)?;
        if team >= spec.n_teams {
            return Err(ModelError::Option(format!("team {team} in a scene of {} teams", spec.n_teams)));
        }
        let agents: Vec<usize> = (0..spec.n_agents).filter(|&a| spec.agent_team[a] == team).collect();
        if agents.is_empty() {
            return Err(ModelError::Input(format!("team {team} has no agent")));
        }
        // The models with SHNN's entity stage, and those with a Transformer body head.
        let shnn = config.name.starts_with("sh");
        let hnn = config.name.starts_with("hnn");
        let transformer = config.name.contains("transformer");
        let gnn = config.name == "shgnn";
        if transformer && config.head_hidden.is_some() {
            return Err(ModelError::Option(format!(
                "model `{}` takes no option `head` (its body head is a Transformer; `head` applies to shnn, \
                 shnn_og3, shnn_so3, mlp, mlp_hn)",
                config.name
            )));
        }
        let hidden = |h: &Option<Vec<usize>>, default: &[usize]| -> Result<Vec<usize>> {
            let h = h.clone().unwrap_or_else(|| default.to_vec());
            if h.is_empty() || h.contains(&0) {
                return Err(ModelError::Option(format!("hidden widths {h:?} must be non-empty and positive")));
            }
            Ok(h)
        };
        let default_hidden: &[usize] = if shnn || hnn { &[256, 256] } else { &[256, 256, 256] };
        // shgnn's `head` is its per-node decoder (default one hidden layer of 64).
        let head_hidden = hidden(&config.head_hidden, if gnn { &[64] } else { default_hidden })?;
        let critic_hidden = hidden(&config.critic_hidden, if gnn { default_hidden } else { &head_hidden })?;
        let sizes = |input: usize, h: &[usize], out: usize| {
            let mut v = vec![input];
            v.extend_from_slice(h);
            v.push(out);
            v
        };
        let prefix = s.full_name("");
        let arch = if hnn {
            let proc = InputProcessor::new(spec, config.translation.unwrap_or_default())?
                .with_abstraction(config.abstraction.unwrap_or_default());
            let method = config.assignment.unwrap_or(AssignmentMethod::Greedy);
            let graph = GraphBuilder::new(spec, method, team, config.seed)?;
            let m = config.mp.unwrap_or_default();
            let sizes = ScalarMpSizes { scalars: m.scalars, hidden: m.hidden, layers: m.layers, steps: m.steps };
            let frame = match config.name.as_str() {
                "hnn_hn" => HnnFrame::Heading,
                "hnn_dn" => HnnFrame::Goal,
                _ => HnnFrame::World,
            };
            Arch::Hnn(Box::new(Hnn::new(s, proc, graph, frame, sizes, &head_hidden, &critic_hidden, spec, &agents)?))
        } else if shnn {
            let translation = config.translation.unwrap_or_default();
            let abstraction = config.abstraction.unwrap_or_default();
            let method = config.assignment.unwrap_or(AssignmentMethod::Greedy);
            let proc = InputProcessor::new(spec, translation)?.with_abstraction(abstraction);
            let graph = GraphBuilder::new(spec, method, team, config.seed)?;
            let m = config.mp.unwrap_or_default();
            let mp_config = EntityMpConfig {
                vectors: m.vectors,
                scalars: m.scalars,
                hidden: m.hidden,
                layers: m.layers,
                steps: m.steps,
                gravity: if config.name == "shnn_so3" { None } else { EntityMpConfig::paper(spec).gravity },
                ..EntityMpConfig::paper(spec)
            };
            let mp = EntityMp::new(&mut s.sub("entity"), mp_config)?;
            let frame = if config.name == "shnn_og3" { FrameKind::Channels } else { FrameKind::Orthogonal };
            let channels = match frame {
                FrameKind::Orthogonal => 3,
                FrameKind::Channels => m.vectors,
            };
            let mut actor = s.sub("actor");
            let heads = if gnn {
                let cfg = BodyGnnConfig {
                    vectors: m.vectors,
                    scalars: m.scalars,
                    hidden: m.hidden,
                    layers: m.layers,
                    steps: m.steps,
                    entity_scalars: m.scalars,
                    decoder_hidden: head_hidden.clone(),
                    gravity: spec.gravity_dir.map(f64::from),
                };
                Heads::Gnn(Box::new(BodyGnn::new(&mut actor, cfg, spec, &agents)?))
            } else if transformer {
                let features = 3 * channels + N_SCALARS + m.scalars;
                Heads::Transformer(Box::new(TransformerHead::new(&mut actor, features, TransformerConfig::default())?))
            } else {
                Heads::Mlp(
                    agents
                        .iter()
                        .map(|&a| {
                            let k = 1 + spec.agent_dof[a];
                            let input = k * (3 * channels + N_SCALARS) + m.scalars;
                            let sz = sizes(input, &head_hidden, 2 * spec.agent_dof[a]);
                            Mlp::new(&mut actor.sub(a), &sz, Activation::Relu)
                        })
                        .collect::<nn::Result<Vec<_>>>()?,
                )
            };
            let ne = spec.entity_root_node.len();
            let critic = Mlp::new(&mut s.sub("critic"), &sizes(ne * m.scalars, &critic_hidden, 1), Activation::Relu)?;
            let mut critic_entities = agents.clone();
            critic_entities.extend((0..spec.n_agents).filter(|a| !agents.contains(a)));
            critic_entities.extend(spec.n_agents..ne);
            Arch::Shnn(Box::new(Shnn { proc, graph, mp, frame, heads, critic, critic_entities }))
        } else {
            for (set, key) in [
                (config.assignment.is_some(), "assignment"),
                (config.translation.is_some(), "translation"),
                (config.abstraction.is_some(), "abstraction"),
                (config.mp.is_some(), "mp"),
            ] {
                if set {
                    return Err(ModelError::Option(format!(
                        "model `{}` takes no option `{key}` (it applies to shnn, shnn_og3, shnn_so3, shgnn, hnn, \
                         hnn_hn, hnn_dn, shtransformer; {} takes {})",
                        config.name,
                        config.name,
                        if transformer { "critic" } else { "head, critic" }
                    )));
                }
            }
            let views: Vec<Vec<usize>> = agents.iter().map(|&a| spec.agent_view(a)).collect();
            let mut actor = s.sub("actor");
            let heads = if transformer {
                Heads::Transformer(Box::new(TransformerHead::new(
                    &mut actor,
                    NODE_FEATURES,
                    TransformerConfig::default(),
                )?))
            } else {
                Heads::Mlp(
                    agents
                        .iter()
                        .zip(&views)
                        .map(|(&a, v)| {
                            let sz = sizes(v.len() * NODE_FEATURES, &head_hidden, 2 * spec.agent_dof[a]);
                            Mlp::new(&mut actor.sub(a), &sz, Activation::Relu)
                        })
                        .collect::<nn::Result<Vec<_>>>()?,
                )
            };
            let critic = Mlp::new(
                &mut s.sub("critic"),
                &sizes(spec.n_nodes * NODE_FEATURES, &critic_hidden, 1),
                Activation::Relu,
            )?;
            Arch::Mlp(MlpModel { heading: config.name.ends_with("_hn"), views, heads, critic })
        };
        Ok(Self { name: config.name.clone(), team, agents, spec: spec.clone(), prefix, arch })
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The team the model acts for.
    pub fn team(&self) -> usize {
        self.team
    }

    /// The team's agents (scene agent indices), in the order of [`PolicyOutput::agents`].
    pub fn agents(&self) -> &[usize] {
        &self.agents
    }

    /// The observation layout the model was built for.
    pub fn spec(&self) -> &ObsSpec {
        &self.spec
    }

    /// The name prefix of every parameter of the model (`""` at the top level).
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The entity-level message passing of the SHNN models (`None` for the MLPs and HNNs).
    pub fn entity_stage(&self) -> Option<&EntityMp> {
        match &self.arch {
            Arch::Shnn(m) => Some(&m.mp),
            Arch::Hnn(_) | Arch::Mlp(_) => None,
        }
    }

    /// Restarts the random stream of the `random` task assignment from `seed` (no effect on
    /// the other models): the trainer reseeds it every iteration so that resumed runs are
    /// exact.
    pub fn reseed(&mut self, seed: u64) {
        match &mut self.arch {
            Arch::Shnn(m) => m.graph.reseed(seed),
            Arch::Hnn(m) => m.reseed(seed),
            Arch::Mlp(_) => {}
        }
    }

    /// Number of scalar parameters of the model in `store` (the one it was built in).
    pub fn num_params<T: Float>(&self, store: &ParamStore<T>) -> usize {
        store.num_elements_under(&self.prefix)
    }

    /// Policy and value for a batch of environment observations.
    pub fn forward<'t, T: Float>(&mut self, p: &Bound<'t, T>, obs: &Observation) -> Result<PolicyOutput<'t, T>> {
        self.forward_batch(p, &ObsBatch::from_observation(obs), &obs.heading)
    }

    /// Policy and value for borrowed observation arrays (`f32` or `f64`) and the agents'
    /// headings `[B, A]` ([`Observation::heading`]).
    pub fn forward_batch<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
    ) -> Result<PolicyOutput<'t, T>> {
        let nb = obs.batch;
        if obs.nodes != self.spec.n_nodes || nb == 0 || heading.len() != nb * self.spec.n_agents {
            return Err(ModelError::Input(format!(
                "observations of {nb} x {} nodes with {} headings for a scene of {} nodes and {} agents",
                obs.nodes,
                heading.len(),
                self.spec.n_nodes,
                self.spec.n_agents
            )));
        }
        match &mut self.arch {
            Arch::Shnn(m) => m.forward(p, obs, &self.agents, &self.spec),
            Arch::Hnn(m) => m.forward(p, obs, heading, &self.agents, &self.spec),
            Arch::Mlp(m) => m.forward(p, obs, heading, &self.agents, &self.spec),
        }
    }
}

/// Splits a head's output into `loc` (first `dof` columns) and `scale` (next `dof`).
fn split_head<'t, T: Float>(
    head: &Mlp,
    p: &Bound<'t, T>,
    hidden: Var<'t, T>,
    agent: usize,
    dof: usize,
) -> Result<AgentPolicy<'t, T>> {
    Ok(AgentPolicy {
        agent,
        loc: head.forward_output_columns(p, hidden, 0, dof)?,
        scale: head.forward_output_columns(p, hidden, dof, dof)?,
    })
}

impl Shnn {
    fn forward<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        agents: &[usize],
        spec: &ObsSpec,
    ) -> Result<PolicyOutput<'t, T>> {
        let tape = p.tape();
        let nb = obs.batch;
        let inputs = self.proc.entities::<T, S>(obs)?;
        let graph = self.graph.build(&inputs)?;
        let f = self.mp.forward_inputs(p, &inputs, &graph)?;
        let bodies = self.proc.bodies(obs, &inputs, &graph.agent_entity, agents)?;
        let frame = match self.frame {
            FrameKind::Orthogonal => f.frame,
            FrameKind::Channels => f.z,
        };
        let channels = frame.shape()[2];
        let mut out = Vec::with_capacity(agents.len());
        for (i, body) in bodies.iter().enumerate() {
            let k = body.z.shape()[1];
            let dof = spec.agent_dof[body.agent];
            let rows = inputs.rows_of(body.agent);
            if let Heads::Gnn(head) = &self.heads {
                // The shared body GNN on the agent's morphology graph, read in O_a.
                let (ha, o) = (f.h.index_select(0, &rows)?, f.frame.index_select(0, &rows)?);
                let (loc, scale) = head.forward(p, body, ha, o)?;
                out.push(AgentPolicy { agent: body.agent, loc, scale });
                continue;
            }
            let node_rows: Vec<usize> = rows.iter().flat_map(|&r| std::iter::repeat_n(r, k)).collect();
            // Eq. (lrf): O_a^T Z_{a,k} for every node of the agent.
            let o = frame.index_select(0, &node_rows)?;
            let z = tape.constant(body.z.reshape(&[nb * k, 3, 3])?);
            let local = to_frame(o, z)?;
            let ha = f.h.index_select(0, &rows)?;
            match &self.heads {
                Heads::Mlp(heads) => {
                    // Eq. (pi): the head on [O^T Z, h, h'_a].
                    let local = local.reshape(&[nb, k * channels * 3])?;
                    let hb = tape.constant(body.h.reshape(&[nb, k * N_SCALARS])?);
                    let hidden = heads[i].forward_hidden_parts(p, &[local, hb, ha])?;
                    out.push(split_head(&heads[i], p, hidden, body.agent, dof)?);
                }
                Heads::Transformer(head) => {
                    // One token per node: [O^T Z_k, h_k, h'_a]; the DoF nodes follow the root.
                    let local = local.reshape(&[nb, k, channels * 3])?;
                    let hb = tape.constant(body.h.clone());
                    let ha = ha.reshape(&[nb, 1, ha.shape()[1]])?.expand(&[nb, k, ha.shape()[1]])?;
                    let (loc, scale) = head.forward(p, tape.cat(&[local, hb, ha], 2)?, 1, dof)?;
                    out.push(AgentPolicy { agent: body.agent, loc, scale });
                }
                // Taken before the frame transform above.
                Heads::Gnn(_) => return Err(ModelError::Input("body GNN head reached the MLP path".into())),
            }
        }
        // Eq. (value): the critic on h' of all entities.
        let ne = inputs.entities;
        let rows: Vec<usize> = (0..nb).flat_map(|b| self.critic_entities.iter().map(move |&e| b * ne + e)).collect();
        let s = f.h.shape()[1];
        let hall = f.h.index_select(0, &rows)?.reshape(&[nb, ne * s])?;
        let value = self.critic.forward(p, hall)?.reshape(&[nb])?;
        Ok(PolicyOutput { agents: out, value })
    }
}

/// Appends a node's features: its 3 vectors (positions relative to `origin`), rotated into
/// the frame of heading `yaw` when given (`O^T v`), then its scalars.
fn push_node<T: Float, S: ObsElement>(
    out: &mut Vec<T>,
    obs: &ObsBatch<'_, S>,
    b: usize,
    node: usize,
    origin: [f64; 3],
    yaw: Option<(f64, f64)>,
) {
    for k in 0..3 {
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

impl MlpModel {
    /// The input rows `[B, nodes * NODE_FEATURES]` of `nodes`, seen from `agent` (its
    /// heading frame and root as origin with heading normalisation, else the world frame).
    fn features<T: Float, S: ObsElement>(
        &self,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
        spec: &ObsSpec,
        agent: usize,
        nodes: &[usize],
    ) -> Result<Tensor<T>> {
        let nb = obs.batch;
        let mut x = tensor::pool::with_capacity(nb * nodes.len() * NODE_FEATURES);
        for b in 0..nb {
            let (origin, yaw) = if self.heading {
                let yaw: f64 = heading[b * spec.n_agents + agent].into();
                (obs.vec3(b, spec.agent_root_node[agent], 0), Some(yaw.sin_cos()))
            } else {
                ([0.0; 3], None)
            };
            for &n in nodes {
                push_node(&mut x, obs, b, n, origin, yaw);
            }
        }
        Ok(Tensor::new(x, &[nb, nodes.len() * NODE_FEATURES])?)
    }

    fn forward<'t, T: Float, S: ObsElement>(
        &self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        heading: &[S],
        agents: &[usize],
        spec: &ObsSpec,
    ) -> Result<PolicyOutput<'t, T>> {
        let tape = p.tape();
        let mut out = Vec::with_capacity(agents.len());
        for (i, (&a, view)) in agents.iter().zip(&self.views).enumerate() {
            let x = self.features(obs, heading, spec, a, view)?;
            let dof = spec.agent_dof[a];
            match &self.heads {
                Heads::Mlp(heads) => {
                    let hidden = heads[i].forward_hidden(p, tape.constant(x))?;
                    out.push(split_head(&heads[i], p, hidden, a, dof)?);
                }
                Heads::Transformer(head) => {
                    // One token per node of the view; its DoF nodes follow its root.
                    let tokens = tape.constant(x.reshape(&[obs.batch, view.len(), NODE_FEATURES])?);
                    let (loc, scale) = head.forward(p, tokens, 1, dof)?;
                    out.push(AgentPolicy { agent: a, loc, scale });
                }
                Heads::Gnn(_) => {
                    return Err(ModelError::Option("a body GNN head needs the entity stage".into()));
                }
            }
        }
        // The critic sees every node, in the frame of the team's first agent.
        let all: Vec<usize> = (0..spec.n_nodes).collect();
        let x = tape.constant(self.features(obs, heading, spec, agents[0], &all)?);
        let value = self.critic.forward(p, x)?.reshape(&[obs.batch])?;
        Ok(PolicyOutput { agents: out, value })
    }
}
