//! `models`: SHNN and its baselines (paper section 3, appendix A). This first part holds the
//! model-independent components: task assignment (Algorithm 1 and the Hungarian
//! alternative), the local reference frame (eqs. (ortho)-(lrf)) and the Tanh-Normal action
//! distribution. The policies themselves build on the MeBen observations of `envs`.

pub mod assignment;
pub mod distribution;
pub mod frame;

pub use assignment::{Assigner, AssignmentMethod, UNASSIGNED, distance_matrix};
