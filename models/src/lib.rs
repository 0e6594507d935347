//! `models`: SHNN and its baselines (paper section 3, appendices "Baselines" and
//! "Ablations"), one module per job:
//! - they read the environment's observation layout (`envs::layout`: `ObsSpec`,
//!   `Observation`, `ObsRows`);
//! - which model and its options ([`kind`]: the eleven models of the paper and the types
//!   that describe them; [`config`]: a model string's syntax and option values;
//!   [`description`]: the [`ModelDescription`] the builders match on, a variant per family
//!   with the options that family takes, typed or parsed from a model string);
//! - the interface the trainer uses: a team's actor and critic [`Policy`], built by a
//!   [`PolicyFactory`] ([`interface`]; bring your own model by implementing them);
//! - the model zoo [`Model`] ([`zoo`]), the eleven models as one [`Policy`], built by its
//!   family's module:
//!   [`shnn`] (`shnn`, `shnn_og3`, `shnn_so3`, `shtransformer`, `shgnn`), [`hnn`] (`hnn`,
//!   `hnn_hn`, `hnn_dn`), [`mlp`] (`mlp`, `mlp_hn`, `transformer_hn`);
//! - their stages: input processing ([`input`]), the task assignment (Algorithm 1 and the
//!   Hungarian alternative, [`assignment`]; the co-learnable Plackett-Luce assignment over
//!   learned pair scores, [`assignment_learned`]) and its entity graph ([`entity_graph`]), the
//!   entity-level subequivariant message passing with the LRF vector ([`entity_mp`]), the
//!   local reference frame and an agent's observation in it (eqs. (ortho)-(lrf),
//!   [`frame`]), the body heads ([`transformer_head`], [`body_gnn`]), the value networks ([`critic`]) and the
//!   Tanh-Normal action distribution ([`distribution`]).

pub mod assignment;
pub mod assignment_learned;
pub mod body_gnn;
pub mod config;
pub mod critic;
pub mod description;
pub mod distribution;
pub mod entity_graph;
pub mod entity_mp;
pub mod error;
pub mod frame;
pub mod hnn;
pub mod input;
pub mod interface;
pub mod kind;
pub mod mlp;
pub mod shnn;
pub mod transformer_head;
pub mod zoo;

pub use assignment::{Assigner, AssignmentMethod, UNASSIGNED, distance_matrix};
pub use assignment_learned::{
    AssignmentScorer, DRAW_SCENE, LearnedAssignment, LearnedChoice, PairFeatureSet, PairFeatures, PlackettLuceAssigner,
    ScorerConfig, all_assignments, log_prob_and_entropy,
};
pub use body_gnn::{BodyGnn, BodyGnnConfig};
pub use config::{DistancePrior, GravityMode, MAX_DISTANCE_PRIOR, MlpVariant, MpSizes, NeighbourOffset, OPTION_KEYS};
pub use critic::{SubeqCritic, ValueHead};
pub use description::{
    EntityStage, HiddenWidths, HnnModel, HnnOptions, LearnedScorer, MlpModel, MlpNetwork, MlpOptions, ModelDescription,
    ShnnCritic, ShnnModel, ShnnOptions, TaskAssignment, ValueNet,
};
pub use entity_graph::{EntityGraph, GraphBuilder, GraphTask, NO_AGENT};
pub use entity_mp::{EntityFeatures, EntityMp, EntityMpConfig};
pub use error::{ModelError, Result};
pub use input::{AgentBody, EntityAbstraction, EntityInputs, InputProcessor, NeighbourRows, Translation};
pub use interface::{AgentPolicy, AssignmentTerms, Policy, PolicyFactory, PolicyOutput};
pub use kind::ModelKind;
pub use transformer_head::TransformerHead;
pub use zoo::{Model, ParamCounts};
