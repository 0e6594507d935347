//! One typed description of a model ([`ModelDescription`]): a sum type with a variant per
//! family of the paper's models, each holding the options that family takes, defaults
//! applied, so that an option a model does not take cannot be written in Rust: `shnn_so3`
//! ([`ShnnModel::ShnnSo3`]) has no gravity field, `shtransformer` no hidden widths, the HNN
//! family no `critic`, `transformer_hn` ([`ModelDescription::TransformerHn`]) nothing at all,
//! and the MLP baselines' task assignment exists only in the release's network
//! ([`MlpNetwork::Release`]).
//!
//! The command line and configuration files name a model as a string,
//! `name:key=value;key=value` ([`ModelDescription::parse`]; the keys are
//! [`crate::config::OPTION_KEYS`]). Where strings are parsed the types decide at run time:
//! each option is moved into the field the model has for it, and an option left over (one
//! the model does not take) is an error naming the model and the options it takes
//! ([`ModelDescription::option_keys`]). Every option a string leaves out takes the paper's
//! model as its reference release builds it (module [`crate::config`]).
//!
//! The builders ([`crate::Model::new`] and the families' modules) match on the variants; what
//! the structure implies (the kind, its head `σ_π` of eq. (pi), the frame it reads the
//! vectors in, what the value network of eq. (value) reads, [`Critic`], and `σ_V`,
//! [`ValueNet`]) is asked of the description.

use crate::assignment::AssignmentMethod;
use crate::config::{DistancePrior, GivenOptions, GravityMode, MlpVariant, MpSizes, NeighbourOffset, OPTION_KEYS};
use crate::entity_graph::GraphBuilder;
use crate::error::{ModelError, Result};
use crate::input::{EntityAbstraction, InputProcessor, Translation};
use crate::kind::{Critic, Family, Frame, Head, ModelKind};
use envs::layout::ObsSpec;

/// `σ_V` of eq. (value): an MLP of the given hidden widths, or a Transformer (the paper's
/// sizes, one output per token, averaged) for the Transformer models ("the same backbone ...
/// for σ_π in eq. (pi) and σ_V in eq. (value)").
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ValueNet {
    /// An MLP with these hidden widths (option `critic_hidden`).
    Mlp(Vec<usize>),
    /// A Transformer over the tokens.
    Transformer,
}

/// A task assignment (Algorithm 1 or an ablation) and the seed of its random stream: the
/// SHNN and HNN families' and the release's MLP's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TaskAssignment {
    /// How agents are linked to objects (option `assignment`; default
    /// [`AssignmentMethod::Greedy`], Algorithm 1).
    pub method: AssignmentMethod,
    /// Seed of the stochastic assignment (option `seed`; default 0).
    pub seed: u64,
}

impl Default for TaskAssignment {
    /// Algorithm 1 (greedy), seed 0.
    fn default() -> Self {
        Self { method: AssignmentMethod::Greedy, seed: 0 }
    }
}

impl TaskAssignment {
    /// The task-assignment graph builder of `team` for scenes laid out by `spec`.
    pub fn graph_builder(&self, spec: &ObsSpec, team: usize) -> Result<GraphBuilder> {
        GraphBuilder::new(spec, self.method, team, self.seed)
    }
}

/// Hidden widths of a model's MLPs: the body-level head `σ_π` and the value network `σ_V`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HiddenWidths {
    /// Hidden widths of `σ_π` (option `head`): each agent's MLP (default 256, 256; 256 x 3
    /// for `variant=flat`), or the body GNN's per-node decoder (`shgnn`; default none, a
    /// linear layer, the only case where it may be empty).
    pub head: Vec<usize>,
    /// Hidden widths of `σ_V` as an MLP (option `critic_hidden`; default 256, 256, or for
    /// `variant=flat` the head's).
    pub critic: Vec<usize>,
}

impl Default for HiddenWidths {
    /// 256, 256 for both (the release's MLP heads and critics).
    fn default() -> Self {
        Self { head: vec![256, 256], critic: vec![256, 256] }
    }
}

impl HiddenWidths {
    /// The flat MLP's (`variant=flat`): 256 x 3 for both.
    pub fn flat() -> Self {
        Self { head: vec![256; 3], critic: vec![256; 3] }
    }

    /// `shgnn`'s: no hidden layer in the per-node decoder, 256, 256 in the critic.
    pub fn body_gnn() -> Self {
        Self { head: Vec::new(), critic: vec![256, 256] }
    }

    /// Checks the widths: positive, and at least one unless `empty_head` allows an empty
    /// head (the body GNN's decoder).
    fn check(&self, empty_head: bool) -> Result<()> {
        for (h, allow_empty) in [(&self.head, empty_head), (&self.critic, false)] {
            if (h.is_empty() && !allow_empty) || h.contains(&0) {
                return Err(ModelError::Option(format!("hidden widths {h:?} must be non-empty and positive")));
            }
        }
        Ok(())
    }
}

/// The options of an entity stage (the SHNN and HNN families), defaults applied
/// ([`EntityStage::default`]); where gravity enters is the SHNN models' own
/// ([`ShnnModel`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EntityStage {
    /// The task assignment and its seed (options `assignment`, `seed`).
    pub assignment: TaskAssignment,
    /// Where positions are measured from (option `translation`; default
    /// [`Translation::Assigned`], or, in a parsed string, [`Translation::RootMean`] with
    /// `assignment=none`, the paper's "w/o assignment").
    pub translation: Translation,
    /// What stands for an entity (option `abstraction`; default [`EntityAbstraction::Root`]).
    pub abstraction: EntityAbstraction,
    /// The neighbour rows of eq. (lrf) (option `neighbour`; default [`NeighbourOffset::Unit`]).
    pub neighbour: NeighbourOffset,
    /// Rounds of the actor's entity-level message passing (option `actor_steps`; default 1,
    /// the release's actor).
    pub actor_steps: usize,
    /// Message-passing sizes (default [`MpSizes::default`], the paper's; no string option);
    /// the SHNN family's critic and body GNN take theirs too.
    pub sizes: MpSizes,
}

impl Default for EntityStage {
    /// The release's entity stage: greedy assignment (seed 0), positions relative to the
    /// assigned roots, the root as the entity, unit neighbour offsets, one round, the paper's
    /// sizes.
    fn default() -> Self {
        Self {
            assignment: TaskAssignment::default(),
            translation: Translation::Assigned,
            abstraction: EntityAbstraction::Root,
            neighbour: NeighbourOffset::Unit,
            actor_steps: 1,
            sizes: MpSizes::default(),
        }
    }
}

impl EntityStage {
    /// The input processing (translation and abstraction) for scenes laid out by `spec`.
    pub fn input_processor(&self, spec: &ObsSpec) -> Result<InputProcessor> {
        Ok(InputProcessor::new(spec, self.translation)?.with_abstraction(self.abstraction))
    }

    /// Whether eq. (lrf)'s `o'_i` has the neighbour rows `O_i^T Z_{j,1}, h_{j,1}`, `j ∈ N(i)`
    /// (all but `neighbour=none`).
    pub fn neighbour_rows(&self) -> bool {
        self.neighbour != NeighbourOffset::None
    }

    /// The edge scalar of the actor's subequivariant message passing: none when an agent's
    /// assigned object sits at a unit direction (the release's actor: the distance of a
    /// unit offset carries nothing), else the distance of eq. (scalar-interaction).
    pub fn edge_distance(&self) -> nn::EdgeDistance {
        if self.neighbour == NeighbourOffset::Unit && self.translation == Translation::Assigned {
            nn::EdgeDistance::None
        } else {
            nn::EdgeDistance::Raw
        }
    }
}

/// What the SHNN family's value network reads (option `critic`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ShnnCritic {
    /// `critic=separate`: its own subequivariant message passing over every entity, then
    /// `σ_V` ([`Critic::Subequivariant`], the release's critic).
    #[default]
    Separate,
    /// `critic=shared`: `σ_V` on the actor's entity-stage features `h'` ([`Critic::EntityStage`],
    /// eq. (value) read literally).
    Shared,
}

impl ShnnCritic {
    /// Parses the option `critic`: `separate` or `shared`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "separate" => Ok(Self::Separate),
            "shared" => Ok(Self::Shared),
            _ => Err(ModelError::Option(format!("unknown critic `{s}` (expected separate or shared)"))),
        }
    }

    /// What the value network reads.
    pub fn critic(self) -> Critic {
        match self {
            Self::Separate => Critic::Subequivariant,
            Self::Shared => Critic::EntityStage,
        }
    }
}

/// A model of the SHNN family with the options only it takes: where gravity enters (option
/// `gravity`, default [`GravityMode::Input`]; not `shnn_so3`) and the hidden widths (options
/// `head`, `critic_hidden`; not `shtransformer`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ShnnModel {
    /// `shnn`: MLP heads reading the vectors in the local reference frame.
    Shnn {
        /// Where the gravity direction enters the message passing.
        gravity: GravityMode,
        /// The heads' and the critic's hidden widths.
        hidden: HiddenWidths,
    },
    /// `shnn_og3`: as `shnn` with the vectors read in `O = Z'`.
    ShnnOg3 {
        /// Where the gravity direction enters the message passing.
        gravity: GravityMode,
        /// The heads' and the critic's hidden widths.
        hidden: HiddenWidths,
    },
    /// `shnn_so3`: as `shnn` with no gravity channel anywhere.
    ShnnSo3 {
        /// The heads' and the critic's hidden widths.
        hidden: HiddenWidths,
    },
    /// `shtransformer`: a Transformer head and a Transformer `σ_V` (the paper's sizes).
    ShTransformer {
        /// Where the gravity direction enters the message passing.
        gravity: GravityMode,
    },
    /// `shgnn`: a body GNN for the team, each DoF node decoded by `σ_π`.
    ShGnn {
        /// Where the gravity direction enters the message passing.
        gravity: GravityMode,
        /// The decoder's hidden widths ([`HiddenWidths::body_gnn`] by default) and the
        /// critic's.
        hidden: HiddenWidths,
    },
}

impl ShnnModel {
    /// Which model it is.
    pub fn kind(&self) -> ModelKind {
        match self {
            Self::Shnn { .. } => ModelKind::Shnn,
            Self::ShnnOg3 { .. } => ModelKind::ShnnOg3,
            Self::ShnnSo3 { .. } => ModelKind::ShnnSo3,
            Self::ShTransformer { .. } => ModelKind::ShTransformer,
            Self::ShGnn { .. } => ModelKind::ShGnn,
        }
    }

    /// Where the gravity direction enters the message passing; `None` for `shnn_so3`.
    pub fn gravity(&self) -> Option<GravityMode> {
        match self {
            Self::Shnn { gravity, .. }
            | Self::ShnnOg3 { gravity, .. }
            | Self::ShTransformer { gravity }
            | Self::ShGnn { gravity, .. } => Some(*gravity),
            Self::ShnnSo3 { .. } => None,
        }
    }

    /// The hidden widths; `None` for `shtransformer` (the paper's Transformer sizes).
    pub fn hidden(&self) -> Option<&HiddenWidths> {
        match self {
            Self::Shnn { hidden, .. }
            | Self::ShnnOg3 { hidden, .. }
            | Self::ShnnSo3 { hidden }
            | Self::ShGnn { hidden, .. } => Some(hidden),
            Self::ShTransformer { .. } => None,
        }
    }

    /// `σ_V`: a Transformer for `shtransformer`, else an MLP of the critic's widths.
    pub fn value(&self) -> ValueNet {
        self.hidden().map_or(ValueNet::Transformer, |h| ValueNet::Mlp(h.critic.clone()))
    }
}

/// The options of a model of the SHNN family (`shnn`, `shnn_og3`, `shnn_so3`,
/// `shtransformer`, `shgnn`; module [`crate::shnn`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShnnOptions {
    /// Which model, with the options only it takes.
    pub model: ShnnModel,
    /// The actor's entity stage.
    pub stage: EntityStage,
    /// What the value network reads (option `critic`; default [`ShnnCritic::Separate`]).
    pub critic: ShnnCritic,
    /// The scorer of `assignment=learned` (options `assign_hidden`, `assign_prior`; unused
    /// with another assignment).
    pub scorer: LearnedScorer,
}

/// The options of the learned assignment's scorer `s_ij = f_θ(x_ij) - λ d_ij`
/// ([`crate::assignment_learned`]) of the SHNN family and the release's MLPs; its pair
/// features are the model's ([`LearnedScorer::config`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LearnedScorer {
    /// Hidden widths of `f_θ` (option `assign_hidden`; default `64x64`; `none`: affine).
    pub hidden: Vec<usize>,
    /// `λ` (option `assign_prior`; default 1).
    pub distance_prior: DistancePrior,
    /// Whether the value reads the assignment held into each step (option
    /// `assign_critic=held`; default `none`: it reads none): `mlp.rs`, `shnn.rs`, the term
    /// `x_σ W_σ` of the value's first layer (not for a Transformer value).
    pub value_reads_held: bool,
}

impl LearnedScorer {
    /// The scorer's configuration with the pair features `features`.
    pub fn config(&self, features: crate::PairFeatureSet) -> crate::ScorerConfig {
        crate::ScorerConfig { features, hidden: self.hidden.clone(), distance_prior: self.distance_prior.get() }
    }
}

impl Default for LearnedScorer {
    /// Hidden `64x64`, `λ = 1` ([`ScorerConfig::default`](crate::ScorerConfig::default)'s).
    fn default() -> Self {
        let d = crate::assignment_learned::ScorerConfig::default();
        Self {
            hidden: d.hidden,
            distance_prior: DistancePrior::new(d.distance_prior).expect("the default λ is in range"),
            value_reads_held: false,
        }
    }
}

/// A model of the HNN family: the frame its heads read the flattened vectors in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HnnModel {
    /// `hnn`: the world frame.
    Hnn,
    /// `hnn_hn`: the agent's heading frame.
    HnnHn,
    /// `hnn_dn`: the frame of the goal direction.
    HnnDn,
}

impl HnnModel {
    /// Which model it is.
    pub fn kind(self) -> ModelKind {
        match self {
            Self::Hnn => ModelKind::Hnn,
            Self::HnnHn => ModelKind::HnnHn,
            Self::HnnDn => ModelKind::HnnDn,
        }
    }
}

/// The options of a model of the HNN family (`hnn`, `hnn_hn`, `hnn_dn`; module
/// [`crate::hnn`]); its critic reads the actor's entity stage ([`Critic::EntityStage`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HnnOptions {
    /// Which model.
    pub model: HnnModel,
    /// The actor's entity stage.
    pub stage: EntityStage,
    /// The heads' and the critic's hidden widths.
    pub hidden: HiddenWidths,
}

/// An MLP baseline: the frame it reads the vectors in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MlpModel {
    /// `mlp`: the world frame.
    Mlp,
    /// `mlp_hn`: the agent's heading frame.
    MlpHn,
}

impl MlpModel {
    /// Which model it is.
    pub fn kind(self) -> ModelKind {
        match self {
            Self::Mlp => ModelKind::Mlp,
            Self::MlpHn => ModelKind::MlpHn,
        }
    }
}

/// The network of an MLP baseline (option `variant`) with the options it takes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MlpNetwork {
    /// `variant=release` (the default): the release's MLP ([`crate::mlp::ReleaseMlp`]) with
    /// its task assignment; its critic reads the entity roots ([`Critic::Roots`]).
    Release {
        /// The task assignment (options `assignment`, `seed`).
        assignment: TaskAssignment,
        /// The heads' and the critic's hidden widths.
        hidden: HiddenWidths,
        /// The scorer of `assignment=learned` (options `assign_hidden`, `assign_prior`,
        /// `assign_critic`).
        scorer: LearnedScorer,
    },
    /// `variant=flat`: this project's earlier baseline on the flat agent view
    /// ([`crate::mlp::FlatMlp`]), no task assignment; its critic reads every node
    /// ([`Critic::Nodes`]).
    Flat {
        /// The heads' and the critic's hidden widths ([`HiddenWidths::flat`] by default).
        hidden: HiddenWidths,
    },
}

impl MlpNetwork {
    /// The option `variant` it stands for.
    pub fn variant(&self) -> MlpVariant {
        match self {
            Self::Release { .. } => MlpVariant::Release,
            Self::Flat { .. } => MlpVariant::Flat,
        }
    }

    /// The hidden widths.
    pub fn hidden(&self) -> &HiddenWidths {
        match self {
            Self::Release { hidden, .. } | Self::Flat { hidden } => hidden,
        }
    }
}

/// The options of an MLP baseline (`mlp`, `mlp_hn`; module [`crate::mlp`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MlpOptions {
    /// Which model.
    pub model: MlpModel,
    /// Its network and that network's options.
    pub network: MlpNetwork,
}

/// A model of the paper with its options resolved (module docs): a variant per family, each
/// with the options that family takes.
///
/// Typed construction: start from a model's defaults ([`ModelDescription::new`]) or write
/// the options out; a string ([`ModelDescription::parse`]) gives the same value.
///
/// ```
/// use models::{AssignmentMethod, EntityStage, GravityMode, HiddenWidths, ModelDescription, ShnnCritic};
/// use models::{LearnedScorer, ShnnModel, ShnnOptions, TaskAssignment};
///
/// let d = ModelDescription::Shnn(ShnnOptions {
///     model: ShnnModel::Shnn { gravity: GravityMode::EveryLayer, hidden: HiddenWidths::default() },
///     stage: EntityStage {
///         assignment: TaskAssignment { method: AssignmentMethod::Hungarian, seed: 3 },
///         actor_steps: 2,
///         ..EntityStage::default()
///     },
///     critic: ShnnCritic::Shared,
///     scorer: LearnedScorer::default(),
/// });
/// let s = "shnn:assignment=hungarian;seed=3;actor_steps=2;gravity=every_layer;critic=shared";
/// assert_eq!(ModelDescription::parse(s).unwrap(), d);
/// assert_eq!(d.name(), "shnn");
/// ```
///
/// An option a model does not take has no field to be written in: `shnn_so3` has no gravity
/// channel, so this does not compile,
///
/// ```compile_fail
/// use models::{GravityMode, HiddenWidths, ShnnModel};
/// let so3 = ShnnModel::ShnnSo3 { gravity: GravityMode::Input, hidden: HiddenWidths::default() };
/// ```
///
/// and in a string it is an error naming the model and its options:
///
/// ```
/// let e = models::ModelDescription::parse("shnn_so3:gravity=input").unwrap_err().to_string();
/// assert!(e.contains("model `shnn_so3` takes no option `gravity`"), "{e}");
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelDescription {
    /// `shnn`, `shnn_og3`, `shnn_so3`, `shtransformer`, `shgnn` ([`Family::Shnn`]).
    Shnn(ShnnOptions),
    /// `hnn`, `hnn_hn`, `hnn_dn` ([`Family::Hnn`]).
    Hnn(HnnOptions),
    /// `mlp`, `mlp_hn` ([`Family::Mlp`]).
    Mlp(MlpOptions),
    /// `transformer_hn` ([`Family::FlatTransformer`]), which takes no option: a Transformer
    /// over the flat agent view in the heading frame, and a Transformer over the roots.
    TransformerHn,
}

/// The options of an entity stage's string form.
const ENTITY_KEYS: [&str; 5] = ["assignment", "translation", "abstraction", "neighbour", "actor_steps"];

impl ModelDescription {
    /// The model `kind` as its reference release builds it (every option at its default).
    pub fn new(kind: ModelKind) -> Self {
        let shnn = |model| {
            Self::Shnn(ShnnOptions {
                model,
                stage: EntityStage::default(),
                critic: ShnnCritic::default(),
                scorer: LearnedScorer::default(),
            })
        };
        let hnn =
            |model| Self::Hnn(HnnOptions { model, stage: EntityStage::default(), hidden: HiddenWidths::default() });
        let mlp = |model| {
            let network = MlpNetwork::Release {
                assignment: TaskAssignment::default(),
                hidden: HiddenWidths::default(),
                scorer: LearnedScorer::default(),
            };
            Self::Mlp(MlpOptions { model, network })
        };
        let (gravity, hidden) = (GravityMode::default(), HiddenWidths::default);
        match kind {
            ModelKind::Shnn => shnn(ShnnModel::Shnn { gravity, hidden: hidden() }),
            ModelKind::ShnnOg3 => shnn(ShnnModel::ShnnOg3 { gravity, hidden: hidden() }),
            ModelKind::ShnnSo3 => shnn(ShnnModel::ShnnSo3 { hidden: hidden() }),
            ModelKind::ShTransformer => shnn(ShnnModel::ShTransformer { gravity }),
            ModelKind::ShGnn => shnn(ShnnModel::ShGnn { gravity, hidden: HiddenWidths::body_gnn() }),
            ModelKind::Hnn => hnn(HnnModel::Hnn),
            ModelKind::HnnHn => hnn(HnnModel::HnnHn),
            ModelKind::HnnDn => hnn(HnnModel::HnnDn),
            ModelKind::Mlp => mlp(MlpModel::Mlp),
            ModelKind::MlpHn => mlp(MlpModel::MlpHn),
            ModelKind::TransformerHn => Self::TransformerHn,
        }
    }

    /// Parses `name` or `name:key=value;key=value` (syntax and values:
    /// [`crate::config::OPTION_KEYS`]) and resolves it: every option is moved into the field
    /// the model has for it, the others take their defaults. An unknown model, key or value,
    /// and an option the model does not take, are errors.
    pub fn parse(s: &str) -> Result<Self> {
        Self::resolve(GivenOptions::parse(s)?)
    }

    /// The description of the options `g` as given: each is taken by the field the model
    /// has for it; one left over is an error naming the model and its options.
    fn resolve(mut g: GivenOptions) -> Result<Self> {
        let kind = ModelKind::parse(&g.name)?;
        let seed = g.seed;
        let d = match Self::new(kind) {
            Self::Shnn(o) => {
                let stage = take_entity_stage(&mut g);
                let critic = g.critic.take().unwrap_or(o.critic);
                let model = match o.model {
                    ShnnModel::Shnn { gravity, hidden } => ShnnModel::Shnn {
                        gravity: g.gravity.take().unwrap_or(gravity),
                        hidden: take_hidden(&mut g, hidden),
                    },
                    ShnnModel::ShnnOg3 { gravity, hidden } => ShnnModel::ShnnOg3 {
                        gravity: g.gravity.take().unwrap_or(gravity),
                        hidden: take_hidden(&mut g, hidden),
                    },
                    ShnnModel::ShnnSo3 { hidden } => ShnnModel::ShnnSo3 { hidden: take_hidden(&mut g, hidden) },
                    ShnnModel::ShTransformer { gravity } => {
                        ShnnModel::ShTransformer { gravity: g.gravity.take().unwrap_or(gravity) }
                    }
                    ShnnModel::ShGnn { gravity, hidden } => ShnnModel::ShGnn {
                        gravity: g.gravity.take().unwrap_or(gravity),
                        hidden: take_hidden(&mut g, hidden),
                    },
                };
                // A Transformer value has no first layer for `x_σ W_σ`: its `assign_critic` is
                // left, and refused as an option it does not take.
                let held = model.value() != ValueNet::Transformer;
                let scorer = take_scorer(&mut g, stage.assignment.method, held)?;
                Self::Shnn(ShnnOptions { model, stage, critic, scorer })
            }
            Self::Hnn(o) => {
                let stage = take_entity_stage(&mut g);
                Self::Hnn(HnnOptions { model: o.model, stage, hidden: take_hidden(&mut g, o.hidden) })
            }
            Self::Mlp(o) => {
                let network = match g.variant.take().unwrap_or_default() {
                    MlpVariant::Release => {
                        let method = g.assignment.take().unwrap_or(AssignmentMethod::Greedy);
                        MlpNetwork::Release {
                            assignment: TaskAssignment { method, seed },
                            hidden: take_hidden(&mut g, o.network.hidden().clone()),
                            scorer: take_scorer(&mut g, method, true)?,
                        }
                    }
                    MlpVariant::Flat => {
                        // The critic's widths default to the head's.
                        let head = g.head_hidden.take().unwrap_or_else(|| HiddenWidths::flat().head);
                        let critic = g.critic_hidden.take().unwrap_or_else(|| head.clone());
                        MlpNetwork::Flat { hidden: HiddenWidths { head, critic } }
                    }
                };
                Self::Mlp(MlpOptions { model: o.model, network })
            }
            Self::TransformerHn => Self::TransformerHn,
        };
        if let Some(key) = g.first_set() {
            let taken = d.option_keys();
            return Err(ModelError::Option(format!(
                "model `{}` takes no option `{key}` (its options: {})",
                g.name,
                if taken.is_empty() { "none".to_string() } else { taken.join(", ") }
            )));
        }
        d.check()?;
        Ok(d)
    }

    /// The options of the string form this model takes but `seed`, which every model takes
    /// (it seeds a task assignment; a model without one ignores it), in
    /// [`crate::config::OPTION_KEYS`] order:
    ///
    /// | option | models |
    /// |---|---|
    /// | `assignment` | the SHNN and HNN families, `mlp` and `mlp_hn` ([`MlpNetwork::Release`]) |
    /// | `translation`, `abstraction`, `neighbour`, `actor_steps` | the SHNN and HNN families |
    /// | `critic` | the SHNN family |
    /// | `gravity` | the SHNN family but `shnn_so3` |
    /// | `variant` | `mlp`, `mlp_hn` |
    /// | `head`, `critic_hidden` | all but the Transformer models |
    /// | `assign_hidden`, `assign_prior` | the SHNN family, `mlp` and `mlp_hn` ([`MlpNetwork::Release`]) |
    /// | `assign_critic` | as `assign_hidden` but `shtransformer` (a Transformer value) |
    pub fn option_keys(&self) -> Vec<&'static str> {
        let mut keys: Vec<&'static str> = Vec::new();
        let hidden = ["head", "critic_hidden"];
        match self {
            Self::Shnn(o) => {
                keys.extend(ENTITY_KEYS);
                keys.extend(["critic", "assign_hidden", "assign_prior"]);
                if o.model.value() != ValueNet::Transformer {
                    keys.push("assign_critic");
                }
                if o.model.gravity().is_some() {
                    keys.push("gravity");
                }
                if o.model.hidden().is_some() {
                    keys.extend(hidden);
                }
            }
            Self::Hnn(_) => {
                keys.extend(ENTITY_KEYS);
                keys.extend(hidden);
            }
            Self::Mlp(o) => {
                if let MlpNetwork::Release { .. } = o.network {
                    keys.extend(["assignment", "assign_hidden", "assign_prior", "assign_critic"]);
                }
                keys.push("variant");
                keys.extend(hidden);
            }
            Self::TransformerHn => {}
        }
        OPTION_KEYS.into_iter().filter(|k| keys.contains(k)).collect()
    }

    /// Checks what the types leave open: hidden widths positive and, but for `shgnn`'s
    /// decoder, at least one; `assignment=learned` only in the SHNN family and the release's
    /// MLPs (the HNN family has no scorer for it).
    pub fn check(&self) -> Result<()> {
        if let Some(a) = self.assignment()
            && a.method == AssignmentMethod::Learned
            && self.scorer().is_none()
        {
            return Err(ModelError::Option(format!(
                "model `{}` takes no option value `assignment=learned` (only the SHNN family, `mlp` and `mlp_hn` do; its \
                 assignments: greedy, hungarian, stochastic, none)",
                self.name()
            )));
        }
        match self {
            Self::Shnn(o) => match &o.model {
                ShnnModel::ShGnn { hidden, .. } => hidden.check(true),
                m => m.hidden().map_or(Ok(()), |h| h.check(false)),
            },
            Self::Hnn(o) => o.hidden.check(false),
            Self::Mlp(o) => o.network.hidden().check(false),
            Self::TransformerHn => Ok(()),
        }
    }

    /// Which model it is.
    pub fn kind(&self) -> ModelKind {
        match self {
            Self::Shnn(o) => o.model.kind(),
            Self::Hnn(o) => o.model.kind(),
            Self::Mlp(o) => o.model.kind(),
            Self::TransformerHn => ModelKind::TransformerHn,
        }
    }

    /// The model's name ([`ModelKind::name`]).
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// The module that builds it ([`ModelKind::family`]).
    pub fn family(&self) -> Family {
        self.kind().family()
    }

    /// The body-level head `σ_π` of eq. (pi) ([`ModelKind::head`]).
    pub fn head(&self) -> Head {
        self.kind().head()
    }

    /// The frame the head reads the vectors in ([`ModelKind::frame`]).
    pub fn frame(&self) -> Frame {
        self.kind().frame()
    }

    /// What the value network reads: the model's default ([`ModelKind::critic`]), the SHNN
    /// family's option `critic`, or [`Critic::Nodes`] for `variant=flat`.
    pub fn critic(&self) -> Critic {
        match self {
            Self::Shnn(o) => o.critic.critic(),
            Self::Mlp(MlpOptions { network: MlpNetwork::Flat { .. }, .. }) => Critic::Nodes,
            _ => self.kind().critic(),
        }
    }

    /// `σ_V` of eq. (value).
    pub fn value(&self) -> ValueNet {
        match self {
            Self::Shnn(o) => o.model.value(),
            Self::Hnn(o) => ValueNet::Mlp(o.hidden.critic.clone()),
            Self::Mlp(o) => ValueNet::Mlp(o.network.hidden().critic.clone()),
            Self::TransformerHn => ValueNet::Transformer,
        }
    }

    /// The hidden widths of its MLPs; `None` for the Transformer models.
    pub fn hidden(&self) -> Option<&HiddenWidths> {
        match self {
            Self::Shnn(o) => o.model.hidden(),
            Self::Hnn(o) => Some(&o.hidden),
            Self::Mlp(o) => Some(o.network.hidden()),
            Self::TransformerHn => None,
        }
    }

    /// The entity stage's options (the SHNN and HNN families).
    pub fn entity_stage(&self) -> Option<&EntityStage> {
        match self {
            Self::Shnn(o) => Some(&o.stage),
            Self::Hnn(o) => Some(&o.stage),
            _ => None,
        }
    }

    /// The task assignment, if the model has one (not `transformer_hn`, `variant=flat`).
    pub fn assignment(&self) -> Option<&TaskAssignment> {
        match self {
            Self::Shnn(ShnnOptions { stage, .. }) | Self::Hnn(HnnOptions { stage, .. }) => Some(&stage.assignment),
            Self::Mlp(MlpOptions { network: MlpNetwork::Release { assignment, .. }, .. }) => Some(assignment),
            _ => None,
        }
    }

    /// The learned assignment's scorer options, if the model can learn its assignment (the
    /// SHNN family, `mlp` and `mlp_hn` with [`MlpNetwork::Release`]); they are used with
    /// `assignment=learned`.
    pub fn scorer(&self) -> Option<&LearnedScorer> {
        match self {
            Self::Shnn(o) => Some(&o.scorer),
            Self::Mlp(MlpOptions { network: MlpNetwork::Release { scorer, .. }, .. }) => Some(scorer),
            _ => None,
        }
    }

    /// Whether its value reads the learned task assignment held into each step (option
    /// `assign_critic=held`; [`crate::mlp::ReleaseMlp`], [`crate::shnn`]).
    pub fn value_reads_held(&self) -> bool {
        self.scorer().is_some_and(|s| s.value_reads_held)
    }

    /// Sets the seed of its task assignment (option `seed`); no effect on a model without one.
    pub fn set_seed(&mut self, seed: u64) {
        match self {
            Self::Shnn(ShnnOptions { stage, .. }) | Self::Hnn(HnnOptions { stage, .. }) => stage.assignment.seed = seed,
            Self::Mlp(MlpOptions { network: MlpNetwork::Release { assignment, .. }, .. }) => assignment.seed = seed,
            _ => {}
        }
    }
}

impl std::str::FromStr for ModelDescription {
    type Err = ModelError;

    /// [`ModelDescription::parse`].
    fn from_str(s: &str) -> Result<Self> {
        Self::parse(s)
    }
}

/// The entity stage of the options `g`, taking the ones it holds (defaults: module docs).
fn take_entity_stage(g: &mut GivenOptions) -> EntityStage {
    let d = EntityStage::default();
    let method = g.assignment.take().unwrap_or(d.assignment.method);
    EntityStage {
        assignment: TaskAssignment { method, seed: g.seed },
        translation: g.translation.take().unwrap_or(if method == AssignmentMethod::None {
            Translation::RootMean
        } else {
            d.translation
        }),
        abstraction: g.abstraction.take().unwrap_or(d.abstraction),
        neighbour: g.neighbour.take().unwrap_or(d.neighbour),
        actor_steps: g.actor_steps.take().unwrap_or(d.actor_steps),
        sizes: d.sizes,
    }
}

/// The learned assignment's scorer of the options `g` (`assign_hidden`, `assign_prior` and,
/// where the value can read the held assignment (`held`), `assign_critic`), taking them,
/// else [`LearnedScorer::default`]'s; an error if one is given with another assignment
/// `method` (it would be ignored).
fn take_scorer(g: &mut GivenOptions, method: AssignmentMethod, held: bool) -> Result<LearnedScorer> {
    if method != AssignmentMethod::Learned && (g.assign_hidden.is_some() || g.assign_prior.is_some()) {
        return Err(ModelError::Option(format!(
            "`{}`: the options assign_hidden and assign_prior set the learned assignment's scorer; give them with \
             assignment=learned",
            g.name
        )));
    }
    if held && method != AssignmentMethod::Learned && g.assign_critic == Some(true) {
        return Err(ModelError::Option(format!(
            "`{}`: the option assign_critic=held gives the value the learned assignment held into each step; give \
             it with assignment=learned",
            g.name
        )));
    }
    let d = LearnedScorer::default();
    Ok(LearnedScorer {
        hidden: g.assign_hidden.take().unwrap_or(d.hidden),
        distance_prior: g.assign_prior.take().unwrap_or(d.distance_prior),
        value_reads_held: if held { g.assign_critic.take().unwrap_or(false) } else { false },
    })
}

/// The hidden widths of the options `g` (`head`, `critic_hidden`), taking them, else `default`'s.
fn take_hidden(g: &mut GivenOptions, default: HiddenWidths) -> HiddenWidths {
    HiddenWidths {
        head: g.head_hidden.take().unwrap_or(default.head),
        critic: g.critic_hidden.take().unwrap_or(default.critic),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Asserts that the model string `s` is refused with a message containing `want`.
    fn assert_refused(s: &str, want: &str) {
        let e = ModelDescription::parse(s).unwrap_err().to_string();
        assert!(e.contains(want), "{s}: {e}");
    }

    #[test]
    fn defaults_resolve_to_the_release_and_options_fold_in() {
        let d = ModelDescription::parse("shtransformer").unwrap();
        assert_eq!((d.head(), d.frame(), d.critic()), (Head::Transformer, Frame::Orthogonal, Critic::Subequivariant));
        assert_eq!(
            (d.value(), d.assignment().map(|a| a.method)),
            (ValueNet::Transformer, Some(AssignmentMethod::Greedy))
        );
        let ModelDescription::Shnn(o) = &d else { panic!("{d:?}") };
        assert_eq!(
            (o.stage.translation, o.stage.neighbour, o.model.gravity()),
            (Translation::Assigned, NeighbourOffset::Unit, Some(GravityMode::Input))
        );
        assert_eq!(d, ModelDescription::new(ModelKind::ShTransformer));
        let d = ModelDescription::parse("shnn:assignment=none;critic=shared").unwrap();
        assert_eq!((d.critic(), d.entity_stage().unwrap().translation), (Critic::EntityStage, Translation::RootMean));
        let d = ModelDescription::parse("shnn_so3").unwrap();
        assert_eq!(
            d,
            ModelDescription::Shnn(ShnnOptions {
                model: ShnnModel::ShnnSo3 { hidden: HiddenWidths::default() },
                stage: EntityStage::default(),
                critic: ShnnCritic::Separate,
                scorer: LearnedScorer::default(),
            })
        );
        let d = ModelDescription::parse("mlp_hn:variant=flat;head=8").unwrap();
        assert_eq!((d.critic(), d.value(), d.assignment()), (Critic::Nodes, ValueNet::Mlp(vec![8]), None));
        let d = ModelDescription::parse("shgnn").unwrap();
        assert!(d.hidden().unwrap().head.is_empty() && d.value() == ValueNet::Mlp(vec![256, 256]));
        let d = ModelDescription::parse("transformer_hn:seed=3").unwrap();
        assert_eq!((d.critic(), d.assignment(), d.entity_stage()), (Critic::Roots, None, None));
        let mut d = ModelDescription::parse("hnn_dn:assignment=stochastic").unwrap();
        d.set_seed(9);
        assert_eq!(d.assignment(), Some(&TaskAssignment { method: AssignmentMethod::Stochastic, seed: 9 }));
        assert_eq!(d, ModelDescription::parse("hnn_dn:assignment=stochastic;seed=9").unwrap());
        for kind in ModelKind::ALL {
            assert_eq!(ModelDescription::new(kind).kind(), kind);
            assert_eq!(ModelDescription::parse(kind.name()).unwrap(), ModelDescription::new(kind), "{kind}");
        }
    }

    #[test]
    fn an_option_the_model_does_not_take_names_the_model_and_its_options() {
        let e = ModelDescription::parse("hnn:gravity=input").unwrap_err().to_string();
        assert!(e.contains("`hnn` takes no option `gravity`"), "{e}");
        assert!(e.contains("assignment, translation, abstraction, neighbour, actor_steps, head, critic_hidden"), "{e}");
        let e = ModelDescription::parse("transformer_hn:seed=3;head=4").unwrap_err().to_string();
        assert_eq!(e, "invalid option: model `transformer_hn` takes no option `head` (its options: none)");
        assert_refused(
            "mlp:variant=flat;assignment=greedy",
            "`mlp` takes no option `assignment` (its options: variant, head, critic_hidden)",
        );
        assert_refused(
            "shtransformer:critic_hidden=8;gravity=input",
            "no option `critic_hidden` (its options: assignment, translation,",
        );
        // A value error comes before an option the model does not take, as it always did.
        assert_refused("hnn:gravity=input;critic=big", "unknown critic `big`");
    }

    /// The learned assignment's scorer options: parsed into [`LearnedScorer`], refused with
    /// another assignment and by the families without a scorer, their values checked.
    #[test]
    fn the_scorer_options_go_with_a_learned_assignment() {
        let d = ModelDescription::parse("shnn:assignment=learned;assign_hidden=16x8;assign_prior=0.5").unwrap();
        let ModelDescription::Shnn(o) = &d else { panic!("{d:?}") };
        let expected = LearnedScorer {
            hidden: vec![16, 8],
            distance_prior: DistancePrior::new(0.5).unwrap(),
            value_reads_held: false,
        };
        assert_eq!(o.scorer, expected);
        let d = ModelDescription::parse("shgnn:assignment=learned;assign_hidden=none;assign_prior=0").unwrap();
        let ModelDescription::Shnn(o) = &d else { panic!("{d:?}") };
        assert_eq!((o.scorer.hidden.len(), o.scorer.distance_prior.get()), (0, 0.0));
        // The defaults are the scorer's (hidden 64x64, λ = 1).
        let d = ModelDescription::parse("shnn:assignment=learned;assign_hidden=64x64;assign_prior=1").unwrap();
        assert_eq!(d, ModelDescription::parse("shnn:assignment=learned").unwrap());
        assert_refused("shnn:assign_prior=2", "give them with assignment=learned");
        assert_refused("shnn:assignment=hungarian;assign_hidden=8", "give them with assignment=learned");
        assert_refused("hnn:assign_hidden=8", "`hnn` takes no option `assign_hidden`");
        assert_refused("mlp_hn:assign_prior=1", "give them with assignment=learned");
        assert_refused("mlp_hn:variant=flat;assign_prior=1", "`mlp_hn` takes no option `assign_prior`");
        let d = ModelDescription::parse("mlp_hn:assignment=learned;assign_hidden=none;assign_prior=3").unwrap();
        assert_eq!(d.scorer().map(|s| (s.hidden.len(), s.distance_prior.get())), Some((0, 3.0)));
        for bad in ["-1", "nan", "inf", "1e9", "one", ""] {
            let e = ModelDescription::parse(&format!("shnn:assignment=learned;assign_prior={bad}")).unwrap_err();
            assert!(e.to_string().contains(&format!("assign_prior`: `{bad}` is not a number in [0, 1000]")), "{e}");
        }
        let e = ModelDescription::parse("shnn:assignment=learned;assign_hidden=0").unwrap_err().to_string();
        assert!(e.contains("assign_hidden") && e.contains("`0`"), "{e}");
        assert_eq!(DistancePrior::new(-0.0).unwrap().get().to_bits(), 0.0f64.to_bits());
    }

    /// `assign_critic=held`: parsed with a learned assignment (the release's MLPs, the SHNN
    /// family but for its Transformer value), refused with another assignment, by the flat
    /// variant and by `shtransformer`, its value checked.
    #[test]
    fn the_held_assignment_critic_goes_with_a_learned_assignment() {
        for s in [
            "mlp_hn:assignment=learned;assign_critic=held",
            "mlp:assign_critic=held;assignment=learned",
            "shnn:assignment=learned;assign_critic=held",
            "shnn:assignment=learned;assign_critic=held;critic=shared",
        ] {
            assert!(ModelDescription::parse(s).unwrap().value_reads_held(), "{s}");
        }
        for s in ["mlp_hn:assignment=learned", "mlp_hn:assignment=learned;assign_critic=none", "mlp_hn"] {
            assert!(!ModelDescription::parse(s).unwrap().value_reads_held(), "{s}");
        }
        assert_refused("mlp_hn:assign_critic=held", "assign_critic=held gives the value the learned assignment");
        assert_refused("mlp_hn:assignment=greedy;assign_critic=held", "give it with assignment=learned");
        assert_refused("mlp_hn:variant=flat;assign_critic=held", "`mlp_hn` takes no option `assign_critic`");
        assert_refused(
            "shtransformer:assignment=learned;assign_critic=held",
            "`shtransformer` takes no option `assign_critic`",
        );
        assert_refused("shnn:assignment=hungarian;assign_critic=held", "give it with assignment=learned");
        assert_refused("mlp_hn:assignment=learned;assign_critic=yes", "`assign_critic`: `yes` is not `none` or `held`");
    }

    /// `assignment=learned` is the SHNN family's and the release's MLPs': the HNN family,
    /// which takes `assignment`, refuses the value naming the model; an unknown value lists
    /// `learned` among the others.
    #[test]
    fn a_learned_assignment_is_the_shnn_familys_and_the_release_mlps() {
        for name in ["shnn", "shnn_og3", "shnn_so3", "shtransformer", "shgnn", "mlp", "mlp_hn"] {
            let d = ModelDescription::parse(&format!("{name}:assignment=learned;seed=4")).unwrap();
            assert_eq!(d.assignment(), Some(&TaskAssignment { method: AssignmentMethod::Learned, seed: 4 }), "{name}");
            assert_eq!(d.scorer(), Some(&LearnedScorer::default()), "{name}");
        }
        for name in ["hnn", "hnn_hn", "hnn_dn"] {
            let e = ModelDescription::parse(&format!("{name}:assignment=learned")).unwrap_err().to_string();
            assert!(e.contains(&format!("model `{name}` takes no option value `assignment=learned`")), "{e}");
        }
        let e = ModelDescription::parse("shnn:assignment=learnt").unwrap_err().to_string();
        assert!(
            e.contains("unknown assignment `learnt` (expected greedy, hungarian, stochastic, none or learned)"),
            "{e}"
        );
    }

    /// The table of [`ModelDescription::option_keys`] is what the types take: for every model
    /// (and MLP network), a string with one option parses exactly when the model lists it.
    #[test]
    fn the_listed_options_are_the_ones_the_types_take() {
        let sample = |k: &str| match k {
            "assignment" => "hungarian",
            "translation" => "body_mean",
            "abstraction" => "mean",
            "neighbour" => "raw",
            "critic" => "shared",
            "gravity" => "every_layer",
            "actor_steps" => "2",
            "variant" => "release",
            "seed" => "5",
            // The scorer's options go with a learned assignment (a second option, given after).
            "assign_prior" => "2;assignment=learned",
            "assign_hidden" => "7x3;assignment=learned",
            "assign_critic" => "held;assignment=learned",
            _ => "7x3",
        };
        for kind in ModelKind::ALL {
            let bases: &[&str] = if kind.family() == Family::Mlp { &["", "variant=flat;"] } else { &[""] };
            for base in bases {
                let listed =
                    ModelDescription::parse(&format!("{kind}:{}", base.trim_end_matches(';'))).unwrap().option_keys();
                for key in OPTION_KEYS.into_iter().filter(|&k| k != "variant" || base.is_empty()) {
                    let s = format!("{kind}:{base}{key}={}", sample(key));
                    let ok = ModelDescription::parse(&s);
                    assert_eq!(ok.is_ok(), key == "seed" || listed.contains(&key), "{s}: {ok:?}");
                }
            }
        }
    }

    #[test]
    fn typed_widths_are_checked_as_the_strings_were() {
        let mut d = ModelDescription::new(ModelKind::MlpHn);
        if let ModelDescription::Mlp(MlpOptions { network: MlpNetwork::Release { hidden, .. }, .. }) = &mut d {
            hidden.head.clear();
        }
        assert_eq!(
            d.check().unwrap_err().to_string(),
            "invalid option: hidden widths [] must be non-empty and positive"
        );
        assert!(ModelDescription::new(ModelKind::ShGnn).check().is_ok());
    }
}
