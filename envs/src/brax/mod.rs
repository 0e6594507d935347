//! Loader of MeBen's agents, described as Brax v1 system configs (protobuf text format).
//!
//! The pipeline, one module per step:
//! 1. [`prototext`]: text -> generic tree of fields with line numbers;
//! 2. [`config`]: tree -> typed, checked [`SystemConfig`] (bodies, joints, actuators);
//! 3. [`morphologies`]: the seven MeBen configs compiled in, looked up by name, or any file.
//!
//! Semantics follow `../shared/reference/MEBEN.md` section 1; `docs/ARCHITECTURE.md`
//! ("Brax v1 configs") documents them and the physical constants.

pub mod config;
pub mod error;
pub mod morphologies;
pub mod prototext;
pub mod rotation;

pub use config::SystemConfig;
pub use error::BraxError;
pub use morphologies::{load_config_file, load_morphology, morphology, parse_config};
