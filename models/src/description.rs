//! One typed description of a model ([`ModelDescription`]): a model name and its options
//! ([`ModelConfig`]) resolved once, by [`ModelConfig::describe`], into what the builders
//! ([`crate::Model::build`] and the families' modules) match on.
//!
//! Resolving checks every option against the model (one table, [`takes_option`]; an option
//! the model does not take is an error naming the model and the options it takes), applies
//! every default (the paper's model as its reference release builds it; module
//! [`crate::config`]) and gives typed fields: the kind and its family, the body-level head
//! `σ_π` of eq. (pi) with its hidden widths, the frame it reads the vectors in, the value
//! network of eq. (value) (what it reads, [`Critic`], and `σ_V`, [`ValueNet`]), the task
//! assignment and its seed, the entity stage's options ([`EntityStage`], the SHNN and HNN
//! families) and the MLP baselines' variant.

use crate::assignment::AssignmentMethod;
use crate::config::{GravityMode, MlpVariant, ModelConfig, MpSizes, NeighbourOffset};
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

/// The options of an entity stage (the SHNN and HNN families), defaults applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EntityStage {
    /// Where positions are measured from (option `translation`; default
    /// [`Translation::Assigned`], or [`Translation::RootMean`] with `assignment=none`, the
    /// paper's "w/o assignment").
    pub translation: Translation,
    /// What stands for an entity (option `abstraction`; default [`EntityAbstraction::Root`]).
    pub abstraction: EntityAbstraction,
    /// The neighbour rows of eq. (lrf) (option `neighbour`; default [`NeighbourOffset::Unit`]).
    pub neighbour: NeighbourOffset,
    /// Where the gravity direction enters the message passing (option `gravity`; default
    /// [`GravityMode::Input`]); `None` for a model without a gravity channel (`shnn_so3`, the
    /// HNN family).
    pub gravity: Option<GravityMode>,
    /// Rounds of the actor's entity-level message passing (option `actor_steps`; default 1,
    /// the release's actor).
    pub actor_steps: usize,
    /// Message-passing sizes ([`ModelConfig::mp`]; default [`MpSizes::default`], the
    /// paper's); the SHNN family's critic and body GNN take theirs too.
    pub sizes: MpSizes,
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

/// A model of the paper with its options resolved (module docs); made by
/// [`ModelConfig::describe`].
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct ModelDescription {
    /// The model.
    pub kind: ModelKind,
    /// The module that builds it ([`ModelKind::family`]).
    pub family: Family,
    /// The body-level head `σ_π` of eq. (pi) ([`ModelKind::head`]).
    pub head: Head,
    /// Hidden widths of `σ_π` (option `head`): each agent's MLP (default 256, 256; 256 x 3
    /// for `variant=flat`) or the body GNN's per-node decoder (default none: a linear
    /// layer); empty for a Transformer head (the paper's sizes).
    pub head_hidden: Vec<usize>,
    /// The frame the head reads the vectors in ([`ModelKind::frame`]).
    pub frame: Frame,
    /// What the value network reads ([`ModelKind::critic`], option `critic`; [`Critic::Nodes`]
    /// for `variant=flat`).
    pub critic: Critic,
    /// `σ_V` of eq. (value) (option `critic_hidden`: an MLP's widths, default 256, 256, or for
    /// `variant=flat` the head's).
    pub value: ValueNet,
    /// The task assignment (option `assignment`; default greedy, Algorithm 1); `None` for a
    /// model without one (`transformer_hn`, `variant=flat`).
    pub assignment: Option<AssignmentMethod>,
    /// Seed of the stochastic assignment (option `seed`, taken by every model).
    pub seed: u64,
    /// The entity stage's options (the SHNN and HNN families).
    pub entity: Option<EntityStage>,
    /// The network of `mlp` and `mlp_hn` (option `variant`; default [`MlpVariant::Release`]).
    pub variant: Option<MlpVariant>,
}

/// Whether `kind` (with the MLP `variant`, for `mlp` and `mlp_hn`) takes the option `key`:
/// the table of which options each model takes. `seed` is taken by every model; the others
/// by:
///
/// | option | models |
/// |---|---|
/// | `assignment` | the SHNN and HNN families, `mlp` and `mlp_hn` (`variant=release`) |
/// | `translation`, `abstraction`, `neighbour`, `actor_steps` | the SHNN and HNN families |
/// | `critic` | the SHNN family |
/// | `gravity` | the SHNN family but `shnn_so3` |
/// | `variant` | `mlp`, `mlp_hn` |
/// | `head`, `critic_hidden` | all but the Transformer models |
pub fn takes_option(kind: ModelKind, variant: Option<MlpVariant>, key: &str) -> bool {
    match key {
        "assignment" => kind.has_entity_stage() || variant == Some(MlpVariant::Release),
        "translation" | "abstraction" | "neighbour" | "actor_steps" => kind.has_entity_stage(),
        "critic" => kind.family() == Family::Shnn,
        "gravity" => kind.uses_gravity(),
        "variant" => kind.family() == Family::Mlp,
        "head" | "critic_hidden" => kind.head() != Head::Transformer,
        _ => key == "seed",
    }
}

impl ModelDescription {
    /// Resolves `config` (module docs): an unknown model, an option the model does not take
    /// or hidden widths that are empty or zero are errors.
    pub fn resolve(config: &ModelConfig) -> Result<Self> {
        let kind = config.kind()?;
        let family = kind.family();
        let variant = (family == Family::Mlp).then(|| config.variant.unwrap_or_default());
        if let Some((key, _)) = config.set_options().iter().find(|(k, set)| *set && !takes_option(kind, variant, k)) {
            let taken: Vec<&str> =
                config.set_options().iter().map(|&(k, _)| k).filter(|k| takes_option(kind, variant, k)).collect();
            return Err(ModelError::Option(format!(
                "model `{}` takes no option `{key}` (its options: {})",
                config.name,
                if taken.is_empty() { "none".to_string() } else { taken.join(", ") }
            )));
        }
        let head = kind.head();
        let flat = variant == Some(MlpVariant::Flat);
        let head_hidden = match head {
            Head::Transformer => Vec::new(),
            Head::Gnn => hidden_widths(&config.head_hidden, &[], true)?,
            Head::Mlp if flat => hidden_widths(&config.head_hidden, &[256, 256, 256], false)?,
            Head::Mlp => hidden_widths(&config.head_hidden, &[256, 256], false)?,
        };
        let value = match head {
            Head::Transformer => ValueNet::Transformer,
            _ if flat => ValueNet::Mlp(hidden_widths(&config.critic_hidden, &head_hidden, false)?),
            _ => ValueNet::Mlp(hidden_widths(&config.critic_hidden, &[256, 256], false)?),
        };
        let critic = if flat { Critic::Nodes } else { config.critic.unwrap_or(kind.critic()) };
        // The models that take the option `assignment` are those with a task assignment.
        let assignment =
            takes_option(kind, variant, "assignment").then(|| config.assignment.unwrap_or(AssignmentMethod::Greedy));
        let entity = kind.has_entity_stage().then(|| EntityStage {
            translation: config.translation.unwrap_or(if assignment == Some(AssignmentMethod::None) {
                Translation::RootMean
            } else {
                Translation::Assigned
            }),
            abstraction: config.abstraction.unwrap_or_default(),
            neighbour: config.neighbour.unwrap_or_default(),
            gravity: kind.uses_gravity().then(|| config.gravity.unwrap_or_default()),
            actor_steps: config.actor_steps.unwrap_or(1),
            sizes: config.mp.unwrap_or_default(),
        });
        Ok(Self {
            kind,
            family,
            head,
            head_hidden,
            frame: kind.frame(),
            critic,
            value,
            assignment,
            seed: config.seed,
            entity,
            variant,
        })
    }

    /// The model's name ([`ModelKind::name`]).
    pub fn name(&self) -> &'static str {
        self.kind.name()
    }

    /// The entity stage's options, or an error for a model without one.
    pub fn entity_stage(&self) -> Result<&EntityStage> {
        self.entity.as_ref().ok_or_else(|| ModelError::Option(format!("model `{}` has no entity stage", self.name())))
    }

    /// The task-assignment graph builder of `team` for scenes laid out by `spec` (options
    /// `assignment` and `seed`), or an error for a model without a task assignment.
    pub fn graph_builder(&self, spec: &ObsSpec, team: usize) -> Result<GraphBuilder> {
        let method = self
            .assignment
            .ok_or_else(|| ModelError::Option(format!("model `{}` has no task assignment", self.name())))?;
        GraphBuilder::new(spec, method, team, self.seed)
    }

    /// The hidden widths of `σ_V` as an MLP, or an error for a Transformer `σ_V`.
    pub fn value_mlp(&self) -> Result<&[usize]> {
        match &self.value {
            ValueNet::Mlp(hidden) => Ok(hidden),
            ValueNet::Transformer => {
                Err(ModelError::Option(format!("model `{}` has a Transformer value network", self.name())))
            }
        }
    }
}

impl ModelConfig {
    /// This model and its options resolved ([`ModelDescription::resolve`]).
    pub fn describe(&self) -> Result<ModelDescription> {
        ModelDescription::resolve(self)
    }
}

/// The hidden widths of option `h`, else `default`; positive and, unless `allow_empty`,
/// at least one.
fn hidden_widths(h: &Option<Vec<usize>>, default: &[usize], allow_empty: bool) -> Result<Vec<usize>> {
    let h = h.clone().unwrap_or_else(|| default.to_vec());
    if (h.is_empty() && !allow_empty) || h.contains(&0) {
        return Err(ModelError::Option(format!("hidden widths {h:?} must be non-empty and positive")));
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_resolve_to_the_release_and_options_fold_in() {
        let d = ModelConfig::new("shtransformer").describe().unwrap();
        assert_eq!((d.head, d.frame, d.critic), (Head::Transformer, Frame::Orthogonal, Critic::Subequivariant));
        assert_eq!((d.value.clone(), d.assignment), (ValueNet::Transformer, Some(AssignmentMethod::Greedy)));
        let e = d.entity.unwrap();
        assert_eq!(
            (e.translation, e.neighbour, e.gravity),
            (Translation::Assigned, NeighbourOffset::Unit, Some(GravityMode::Input))
        );
        let d = ModelConfig::parse("shnn:assignment=none;critic=shared").unwrap().describe().unwrap();
        assert_eq!((d.critic, d.entity.unwrap().translation), (Critic::EntityStage, Translation::RootMean));
        assert_eq!(ModelConfig::new("shnn_so3").describe().unwrap().entity.unwrap().gravity, None);
        let d = ModelConfig::parse("mlp_hn:variant=flat;head=8").unwrap().describe().unwrap();
        assert_eq!((d.critic, d.value, d.assignment), (Critic::Nodes, ValueNet::Mlp(vec![8]), None));
        let d = ModelConfig::new("shgnn").describe().unwrap();
        assert!(d.head_hidden.is_empty() && d.value == ValueNet::Mlp(vec![256, 256]));
        let d = ModelConfig::new("transformer_hn").describe().unwrap();
        assert_eq!((d.critic, d.assignment, d.entity, d.variant), (Critic::Roots, None, None, None));
    }

    #[test]
    fn an_option_the_model_does_not_take_names_the_model_and_its_options() {
        let e = ModelConfig::parse("hnn:gravity=input").unwrap().describe().unwrap_err().to_string();
        assert!(e.contains("`hnn` takes no option `gravity`"), "{e}");
        assert!(e.contains("assignment, translation, abstraction, neighbour, actor_steps, head, critic_hidden"), "{e}");
        let e = ModelConfig::parse("transformer_hn:seed=3;head=4").unwrap().describe().unwrap_err().to_string();
        assert!(e.contains("its options: none"), "{e}");
        for kind in ModelKind::ALL {
            assert!(takes_option(kind, None, "seed"), "{kind}");
        }
    }
}
