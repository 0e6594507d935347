//! `envs`: an articulated-body physics simulator in reduced coordinates (f64), with MuJoCo's
//! Model/Data split, and the MeBen environments built on it.
//!
//! - [`ModelBuilder`] builds an immutable [`Model`]; [`Data`] holds one environment's state;
//! - `step` advances one `Data` by one time step (`forward`'s named stages, then the
//!   integrator); `step_batch` many in parallel;
//! - `mjcf` loads MuJoCo XML files, `brax` MeBen's agent configs; `mjcf_agent` reads an MJCF
//!   file as one agent of a task, as `brax` does a config;
//! - `tasks`: the MeBen tasks (Team Reach, Team Sumo) as batched multi-agent environments;
//! - [`rollout_tool`]: the open-loop MJCF rollout program (`--example rollout`, `meben sim`).

pub mod batch;
pub mod brax;
pub mod builder;
pub mod collision;
pub mod constraints;
pub mod crba;
pub mod data;
pub mod diagnostics;
pub mod forward;
pub mod integrator;
pub mod kinematics;
pub mod layout;
pub mod limits;
pub mod math;
pub mod memory;
pub mod memory_limits;
pub mod mjcf;
pub mod mjcf_agent;
pub mod model;
pub mod rne;
pub mod rollout_tool;
pub mod tasks;

pub use batch::{step_batch, step_batch_ctrl};
pub use builder::{GeomSpec, HingeSpec, ModelBuilder};
pub use data::{Contact, Data, DataState};
pub use forward::forward;
pub use integrator::step;
pub use model::{
    ActuatorId, BodyId, CapsuleEnds, GeomId, Integrator, JointId, JointKind, Model, ModelError, Options, Shape,
};
