//! `models`: SHNN and its baselines (paper section 3, appendix A). So far:
//! - model-independent components: task assignment (Algorithm 1 and the Hungarian
//!   alternative), the local reference frame (eqs. (ortho)-(lrf)) and the Tanh-Normal action
//!   distribution;
//! - SHNN's entity stage: input processing ([`input`]), the task-assignment entity graph
//!   ([`entity_graph`]) and the entity-level subequivariant message passing with the LRF
//!   vector ([`entity_mp`]);
//! - the policy/critic interface and the models built by name ([`policy`]: `shnn`,
//!   `shnn_og3`, `shnn_so3`, `mlp`, `mlp_hn`, `transformer_hn`, `shtransformer`, `shgnn`, `hnn`, `hnn_hn`, `hnn_dn`; the Transformer
//!   body head in [`transformer_head`], the body GNN in [`body_gnn`]).

pub mod assignment;
pub mod body_gnn;
pub mod config;
pub mod critic;
pub mod distribution;
pub mod entity_graph;
pub mod entity_mp;
pub mod error;
pub mod frame;
pub mod hnn;
pub mod input;
pub mod layout;
pub mod mlp;
pub mod policy;
pub mod shnn;
pub mod transformer_head;

pub use assignment::{Assigner, AssignmentMethod, UNASSIGNED, distance_matrix};
pub use body_gnn::{BodyGnn, BodyGnnConfig};
pub use config::{CriticKind, GravityMode, MlpVariant, NeighbourOffset, OPTION_KEYS};
pub use critic::{SubeqCritic, ValueHead};
pub use entity_graph::{EntityGraph, GraphBuilder, GraphTask, NO_AGENT};
pub use entity_mp::{EntityFeatures, EntityMp, EntityMpConfig};
pub use error::{ModelError, Result};
pub use input::{AgentBody, EntityAbstraction, EntityInputs, InputProcessor, NeighbourRows, Translation};
pub use layout::{
    N_SCALARS, NODE_VECTOR_LEN, NODE_VECTORS, ObsBatch, ObsElement, ObsRows, ObsSpec, Observation, RowWidths,
};
pub use policy::{AgentPolicy, MODEL_NAMES, Model, ModelConfig, MpSizes, ParamCounts, PolicyOutput};
pub use transformer_head::TransformerHead;
