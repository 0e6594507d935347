//! MeBen's tasks, Team Reach and Team Sumo, as batched multi-agent environments on the
//! simulator (`../shared/reference/MEBEN.md` sections 2 to 4 and 8; `docs/TASKS.md`).
//!
//! ```
//! use envs::tasks::{StartMode, VecEnv};
//! let mut env = VecEnv::from_name("team_reach/1_ant", 4, 7, StartMode::Random).unwrap();
//! let actions = vec![0.0f32; env.batch() * env.n_actions()];
//! let out = env.step(&actions).unwrap();
//! assert_eq!(out.reward.len(), 4);
//! assert_eq!(out.obs.nodes, 1 + 8 + 1); // ant root, 8 DoF nodes, one ball
//! ```
//!
//! One module per job: [`spec`] (names, compositions), [`scene`] (one model per
//! composition), [`placement`] (random starts), [`eval_modes`] (fixed and rotated starts),
//! [`reach`] and [`sumo`] (rewards, outcomes), [`outcome`], [`observation`] (filling
//! the observation layout of [`crate::layout`]), [`vec_env`] (batched stepping), [`render`] (trajectories to CSV, HTML and GIF), [`error`].

pub mod error;
pub mod eval_modes;
pub mod observation;
pub mod outcome;
pub mod placement;
pub mod reach;
pub mod render;
pub mod scene;
pub mod spec;
pub mod sumo;
pub mod vec_env;

pub use error::TaskError;
pub use eval_modes::{FixedStart, StartMode};
pub use outcome::{Outcome, RootState};
pub use placement::Start;
pub use scene::{MAX_CONTACT_PAIRS, Scene};
pub use spec::{BUILTIN_NAMES, MAX_AGENTS, TaskKind, TaskSpec, is_morphology_file};
pub use vec_env::{MAX_ENVS, StepOutput, VecEnv, VecEnvState, check_batch_fits};
