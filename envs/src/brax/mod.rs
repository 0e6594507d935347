//! Loader of MeBen's agents, described as Brax v1 system configs (protobuf text format).
//!
//! The pipeline, one module per step:
//! 1. [`prototext`]: text -> generic tree of fields with line numbers;
//! 2. [`config`]: tree -> typed, checked [`SystemConfig`] (bodies, joints, actuators);
//! 3. [`morphologies`]: the seven MeBen configs compiled in, looked up by name, or any file;
//! 4. [`tree`]: config -> kinematic tree in the simulator's conventions (hinges, geoms, masses,
//!    motors, rest pose), with the constants of [`physics::BraxPhysics`];
//! 5. [`to_model`]: tree -> the simulator's `ModelBuilder` / `Model`.
//!
//! ```
//! use envs::brax::{BraxPhysics, agent_model, load_morphology};
//! let ant = load_morphology("ant").unwrap();
//! let (model, tree) = agent_model(&ant, &BraxPhysics::default()).unwrap();
//! assert_eq!(model.nu(), 8);
//! assert_eq!(model.qpos0, tree.rest_qpos());
//! ```
//!
//! Semantics follow `../shared/reference/MEBEN.md` section 1; `docs/SIMULATOR.md`
//! ("Brax v1 configs") documents them and the physical constants.

pub mod config;
pub mod error;
pub mod morphologies;
pub mod physics;
pub mod prototext;
pub mod rotation;
pub mod to_model;
pub mod tree;

pub use config::SystemConfig;
pub use error::BraxError;
pub use morphologies::{load_config_file, load_morphology, morphology, parse_config};
pub use physics::BraxPhysics;
pub use to_model::{AgentIds, add_agent, agent_model, brax_options};
pub use tree::AgentTree;
