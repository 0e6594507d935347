//! The eleven models of the paper as one enum ([`ModelKind`]) that knows each one's
//! structure: its family (which module builds it), whether it has an entity stage, its
//! body-level head, its frame, its default critic and which symmetries its outputs keep.
//! Code that needs one of these asks the kind instead of testing the model's name; a model
//! with its options resolved is a [`crate::description::ModelDescription`], which answers
//! with these types.

use crate::error::{ModelError, Result};

/// A model of the paper (its section 5 and appendix "Baselines", "Ablations").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModelKind {
    /// SHNN (paper section 3).
    Shnn,
    /// SHNN:Og3, the body vectors read in `O = Z'` (no orthogonalisation).
    ShnnOg3,
    /// SHNN:SO3, no gravity channel anywhere.
    ShnnSo3,
    /// SHTransformer: SHNN with a Transformer body head and value head.
    ShTransformer,
    /// SHGNN: SHNN with a GNN over each agent's bodies.
    ShGnn,
    /// MLP (world frame).
    Mlp,
    /// MLP+HN (heading normalisation).
    MlpHn,
    /// Transformer+HN.
    TransformerHn,
    /// HNN: SHNN's hierarchy with plain message passing, world frame.
    Hnn,
    /// HNN+HN: the same in the agent's heading frame.
    HnnHn,
    /// HNN+DN: the same in the frame of the goal direction.
    HnnDn,
}

/// Which module builds a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Subequivariant entity stage and local frames ([`crate::shnn`]).
    Shnn,
    /// SHNN's hierarchy with flattened vectors ([`crate::hnn`]).
    Hnn,
    /// The release's MLP ([`crate::mlp::ReleaseMlp`]).
    Mlp,
    /// One Transformer over the flat agent view ([`crate::mlp::FlatMlp`]).
    FlatTransformer,
}

/// The body-level head that gives each DoF's `loc`, `scale` (eq. (pi)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Head {
    /// One MLP per agent.
    Mlp,
    /// One Transformer for the team, a token per node.
    Transformer,
    /// One GNN for the team over each agent's bodies.
    Gnn,
}

/// The frame the body-level head reads the vectors in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// The local reference frame `O = OP(Z' W_u)` (eqs. (ortho), (ort_matrix), (lrf)).
    Orthogonal,
    /// `O = Z'`, the `m` channels of the entity stage (SHNN:Og3).
    Channels,
    /// The world axes.
    World,
    /// The agent's heading.
    Heading,
    /// The horizontal direction to the agent's assigned entity.
    Goal,
}

/// What the value network reads (eq. (value), `V = σ_V(..)`): a model's default
/// ([`ModelKind::critic`]), or the SHNN family's option `critic=separate|shared`
/// ([`crate::description::ShnnCritic`]), or the flat MLP's (`variant=flat`). `σ_V` itself is
/// [`crate::description::ValueNet`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Critic {
    /// Its own subequivariant message passing over every entity, then `σ_V` (the release's
    /// critic, [`crate::critic::SubeqCritic`]; `critic=separate`, the SHNN family's default).
    Subequivariant,
    /// `σ_V` on the actor's entity-stage features `h'` (eq. (value) read literally;
    /// `critic=shared`; the HNN family's critic).
    EntityStage,
    /// `σ_V` on every entity root's features (the MLP baselines: embedded roots and an MLP;
    /// `transformer_hn`: the roots as the tokens of a Transformer).
    Roots,
    /// An MLP on every node of the scene (the flat MLP, `variant=flat`).
    Nodes,
}

impl ModelKind {
    /// Every model, in the order the documentation lists them.
    pub const ALL: [ModelKind; 11] = [
        ModelKind::Shnn,
        ModelKind::ShnnOg3,
        ModelKind::ShnnSo3,
        ModelKind::Mlp,
        ModelKind::MlpHn,
        ModelKind::TransformerHn,
        ModelKind::ShTransformer,
        ModelKind::ShGnn,
        ModelKind::Hnn,
        ModelKind::HnnHn,
        ModelKind::HnnDn,
    ];

    /// The name on the command line and in configurations.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Shnn => "shnn",
            ModelKind::ShnnOg3 => "shnn_og3",
            ModelKind::ShnnSo3 => "shnn_so3",
            ModelKind::ShTransformer => "shtransformer",
            ModelKind::ShGnn => "shgnn",
            ModelKind::Mlp => "mlp",
            ModelKind::MlpHn => "mlp_hn",
            ModelKind::TransformerHn => "transformer_hn",
            ModelKind::Hnn => "hnn",
            ModelKind::HnnHn => "hnn_hn",
            ModelKind::HnnDn => "hnn_dn",
        }
    }

    /// Every name, joined by `", "` (for messages).
    pub fn names() -> String {
        Self::ALL.map(ModelKind::name).join(", ")
    }

    /// The model named `name`; an unknown name is an error listing the known ones.
    pub fn parse(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| ModelError::Option(format!("model `{name}` is unknown (known models: {})", Self::names())))
    }

    /// The module that builds it.
    pub fn family(self) -> Family {
        match self {
            ModelKind::Shnn | ModelKind::ShnnOg3 | ModelKind::ShnnSo3 | ModelKind::ShTransformer | ModelKind::ShGnn => {
                Family::Shnn
            }
            ModelKind::Hnn | ModelKind::HnnHn | ModelKind::HnnDn => Family::Hnn,
            ModelKind::Mlp | ModelKind::MlpHn => Family::Mlp,
            ModelKind::TransformerHn => Family::FlatTransformer,
        }
    }

    /// Whether it has an entity-level message-passing stage shared by the team's agents
    /// (parameters `entity.*`): subequivariant in the SHNN family, plain in the HNN one.
    pub fn has_entity_stage(self) -> bool {
        matches!(self.family(), Family::Shnn | Family::Hnn)
    }

    /// Its body-level head.
    pub fn head(self) -> Head {
        match self {
            ModelKind::ShTransformer | ModelKind::TransformerHn => Head::Transformer,
            ModelKind::ShGnn => Head::Gnn,
            _ => Head::Mlp,
        }
    }

    /// The frame its head reads the body vectors in.
    pub fn frame(self) -> Frame {
        match self {
            ModelKind::ShnnOg3 => Frame::Channels,
            ModelKind::Shnn | ModelKind::ShnnSo3 | ModelKind::ShTransformer | ModelKind::ShGnn => Frame::Orthogonal,
            ModelKind::Mlp | ModelKind::Hnn => Frame::World,
            ModelKind::MlpHn | ModelKind::TransformerHn | ModelKind::HnnHn => Frame::Heading,
            ModelKind::HnnDn => Frame::Goal,
        }
    }

    /// What its value network reads by default (its `σ_V` is a Transformer for the
    /// Transformer models, an MLP for the others).
    pub fn critic(self) -> Critic {
        match self.family() {
            Family::Shnn => Critic::Subequivariant,
            Family::Hnn => Critic::EntityStage,
            Family::Mlp | Family::FlatTransformer => Critic::Roots,
        }
    }

    /// Whether the gravity direction enters its message passing (all of the SHNN family but
    /// SHNN:SO3, which is equivariant under every rotation instead).
    pub fn uses_gravity(self) -> bool {
        self.family() == Family::Shnn && self != ModelKind::ShnnSo3
    }

    /// Whether its policy and value are unchanged when the scene is rotated about the
    /// vertical and translated horizontally (the subequivariant models, and the baselines
    /// made so by heading or goal-direction normalisation); `mlp` and `hnn`, in the world
    /// frame, are not.
    pub fn is_equivariant(self) -> bool {
        self.frame() != Frame::World
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_unknown_ones_list_the_known() {
        for k in ModelKind::ALL {
            assert_eq!(ModelKind::parse(k.name()).unwrap(), k);
        }
        let e = ModelKind::parse("resnet").unwrap_err().to_string();
        assert!(ModelKind::ALL.iter().all(|k| e.contains(k.name())) && e.contains("resnet"), "{e}");
        let world: Vec<&str> = ModelKind::ALL.into_iter().filter(|k| !k.is_equivariant()).map(|k| k.name()).collect();
        assert_eq!(world, ["mlp", "hnn"]);
    }
}
