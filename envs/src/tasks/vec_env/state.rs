//! Exact checkpoints of a [`VecEnv`]: [`VecEnv::snapshot`] and [`VecEnv::restore`].
//!
//! A [`VecEnvState`] holds everything that influences the future steps of every environment,
//! so that a `VecEnv` restored from it (even one built with another seed or start mode) then
//! produces the same [`super::StepOutput`]s bit for bit as the original would have:
//! - per environment ([`EnvState`]): the simulator state carried between steps
//!   ([`DataState`]: time, qpos, qvel, ctrl, applied forces, the constraint solver's warm
//!   starts), the position in its ChaCha8 random stream (the next episode starts are drawn
//!   from it), the episode's balls and its control-step counter;
//! - for the batch: the start mode (a fixed start is recomputed from it), the curriculum
//!   factor `alpha`, auto-reset, and the last step's outputs ([`LastOutput`]).
//!
//! Not stored, because every step rewrites it before reading it: the rest of `Data` (poses,
//! mass matrix, contacts, constraint rows) and the per-environment `RootState` (root
//! positions, velocities and action norms, all set from the step's own state and actions).
//! The observations are not stored either: they are a function of the state (the step
//! refreshes the kinematics, then writes them), and [`VecEnv::restore`] recomputes them the
//! same way, so `obs()` after a restore equals the original's bit for bit.
//!
//! The state is `serde`-serialisable. [`VecEnvState::to_json`] and [`VecEnvState::from_json`]
//! round-trip it exactly: serde_json prints the shortest representation that reads back to
//! the same `f64`, and this crate enables serde_json's `float_roundtrip` so that it does read
//! back exactly (without it one value in five comes back one ulp off). JSON has no NaN or
//! infinity: `to_json` refuses a state holding one (only possible when a diverged environment
//! was kept with auto-reset off).

use super::{VecEnv, refresh, write_obs};
use crate::data::DataState;
use crate::layout::{N_SCALARS, NODE_VECTOR_LEN};
use crate::tasks::error::TaskError;
use crate::tasks::eval_modes::{StartMode, fixed_start};
use crate::tasks::outcome::Outcome;
use crate::tasks::spec::TaskSpec;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Version of the [`VecEnvState`] layout; [`VecEnv::restore`] refuses other versions.
pub const VEC_ENV_STATE_VERSION: u32 = 1;

/// Everything that determines the future of a [`VecEnv`] (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VecEnvState {
    /// Layout version ([`VEC_ENV_STATE_VERSION`]).
    pub version: u32,
    /// The composition (its `name` is the scene name); must equal the restoring env's.
    pub spec: TaskSpec,
    /// Number of environments; must equal the restoring env's.
    pub batch: usize,
    /// How episodes start.
    pub mode: StartMode,
    /// The curriculum factor.
    pub alpha: f64,
    /// Whether ended episodes reset at once.
    pub auto_reset: bool,
    /// Per environment, `batch` entries.
    pub envs: Vec<EnvState>,
    /// What the last step returned, apart from the observations.
    pub last: LastOutput,
}

/// One environment's part of a [`VecEnvState`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvState {
    /// The simulator state carried between steps.
    pub physics: DataState,
    /// Position in the environment's random stream.
    pub rng: RngState,
    /// Ball positions (x, y) of the current episode.
    pub balls: Vec<[f64; 2]>,
    /// Control steps taken in the current episode.
    pub step: usize,
}

/// The exact position of a ChaCha8 stream (`rand_chacha`'s `get_seed`, `get_stream`,
/// `get_word_pos`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RngState {
    /// The 32-byte key.
    pub seed: [u8; 32],
    /// The stream (nonce).
    pub stream: u64,
    /// Offset from the start of the stream in 32-bit words.
    pub word_pos: u128,
}

impl RngState {
    /// The position of `rng`.
    pub fn of(rng: &ChaCha8Rng) -> RngState {
        RngState { seed: rng.get_seed(), stream: rng.get_stream(), word_pos: rng.get_word_pos() }
    }

    /// A generator at this position: its outputs are those `rng` would have produced next.
    pub fn to_rng(&self) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::from_seed(self.seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(self.word_pos);
        rng
    }
}

/// The last step's outputs other than the observations (see [`super::StepOutput`]), so that
/// [`VecEnv::output`] after a restore equals the original's (except `final_obs` rows of
/// environments that did not end, which are stale in both).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LastOutput {
    /// `[B, n_teams]` rewards.
    pub reward: Vec<f32>,
    /// `[B]` terminated flags.
    pub terminated: Vec<bool>,
    /// `[B]` truncated flags.
    pub truncated: Vec<bool>,
    /// `[B]` outcomes.
    pub outcome: Vec<Outcome>,
    /// `[B]` episode lengths.
    pub episode_len: Vec<u32>,
    /// The final observations of the environments whose episode ended at the last step.
    pub final_obs: Vec<FinalObsRow>,
}

/// The final observation of one environment whose episode ended at the last step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FinalObsRow {
    /// The environment.
    pub env: usize,
    /// `[N, 3, 3]` vectors.
    pub vectors: Vec<f32>,
    /// `[N, N_SCALARS]` scalars.
    pub scalars: Vec<f32>,
    /// `[A]` headings.
    pub heading: Vec<f32>,
}

fn bad(what: impl Into<String>, value: impl ToString, message: impl Into<String>) -> TaskError {
    TaskError::BadArgument { what: what.into(), value: value.to_string(), message: message.into() }
}

/// Errors when `got` and `want` differ, naming the field and both values.
fn same<T: PartialEq + std::fmt::Debug>(field: &str, got: &T, want: &T) -> Result<(), TaskError> {
    if got == want {
        Ok(())
    } else {
        Err(bad(format!("state {field}"), format!("{got:?}"), format!("this environment has {want:?}")))
    }
}

fn same_len(field: &str, got: usize, want: usize) -> Result<(), TaskError> {
    if got == want { Ok(()) } else { Err(bad(format!("state {field} length"), got, format!("expected {want}"))) }
}

impl VecEnvState {
    /// Compact JSON; errors when a number is NaN or infinite (JSON cannot hold it).
    pub fn to_json(&self) -> Result<String, TaskError> {
        if let Some(field) = self.first_non_finite() {
            return Err(bad(
                "state",
                field,
                "is not finite, which JSON cannot hold (a diverged environment kept with auto-reset off?)",
            ));
        }
        serde_json::to_string(self).map_err(|e| bad("state", "JSON", e.to_string()))
    }

    /// Reads a state written by [`VecEnvState::to_json`].
    pub fn from_json(text: &str) -> Result<VecEnvState, TaskError> {
        serde_json::from_str(text)
            .map_err(|e| bad("state JSON", format!("line {} column {}", e.line(), e.column()), e.to_string()))
    }

    /// The first field holding a NaN or an infinity, if any.
    pub fn first_non_finite(&self) -> Option<String> {
        fn find<T: Copy + Into<f64>>(field: &str, xs: &[T]) -> Option<String> {
            let i = xs.iter().position(|&x| !x.into().is_finite())?;
            Some(format!("{field}[{i}]"))
        }
        let mut found = find("alpha", &[self.alpha]).or_else(|| find("spec.radius", &[self.spec.radius]));
        if let StartMode::Fixed(f) = &self.mode {
            found = found.or_else(|| find("mode.angle", &[f.angle])).or_else(|| find("mode.point", &f.point));
        }
        for (e, s) in self.envs.iter().enumerate() {
            let p = &s.physics;
            let field = |name: &str| format!("envs[{e}].{name}");
            found = found
                .or_else(|| find(&field("physics.time"), &[p.time]))
                .or_else(|| find(&field("physics.qpos"), &p.qpos))
                .or_else(|| find(&field("physics.qvel"), &p.qvel))
                .or_else(|| find(&field("physics.ctrl"), &p.ctrl))
                .or_else(|| find(&field("physics.qfrc_applied"), &p.qfrc_applied))
                .or_else(|| find(&field("physics.warm_limit"), &p.warm_limit))
                .or_else(|| {
                    p.warm_contacts
                        .iter()
                        .enumerate()
                        .find_map(|(i, w)| find(&field(&format!("physics.warm_contacts[{i}].force")), &w.force))
                })
                .or_else(|| find(&field("balls (flattened)"), s.balls.as_flattened()));
        }
        let l = &self.last;
        found.or_else(|| find("last.reward", &l.reward)).or_else(|| {
            l.final_obs.iter().find_map(|r| {
                let field = |name: &str| format!("last.final_obs[env {}].{name}", r.env);
                find(&field("vectors"), &r.vectors)
                    .or_else(|| find(&field("scalars"), &r.scalars))
                    .or_else(|| find(&field("heading"), &r.heading))
            })
        })
    }
}

impl VecEnv {
    /// Everything that determines this batch's future (module docs of [`VecEnvState`]):
    /// [`VecEnv::restore`] of it, here or in another `VecEnv` of the same composition and
    /// batch size, continues exactly where this one is.
    pub fn snapshot(&self) -> VecEnvState {
        let o = &self.out;
        let (nv, ns, nh) = (o.obs.nodes * NODE_VECTOR_LEN, o.obs.nodes * N_SCALARS, o.obs.agents);
        let final_obs = (0..self.slots.len())
            .filter(|&e| o.terminated[e] || o.truncated[e])
            .map(|e| FinalObsRow {
                env: e,
                vectors: o.final_obs.vectors[e * nv..(e + 1) * nv].to_vec(),
                scalars: o.final_obs.scalars[e * ns..(e + 1) * ns].to_vec(),
                heading: o.final_obs.heading[e * nh..(e + 1) * nh].to_vec(),
            })
            .collect();
        VecEnvState {
            version: VEC_ENV_STATE_VERSION,
            spec: self.scene.spec.clone(),
            batch: self.slots.len(),
            mode: self.mode,
            alpha: self.alpha,
            auto_reset: self.auto_reset,
            envs: self
                .slots
                .iter()
                .map(|s| EnvState {
                    physics: s.data.state(),
                    rng: RngState::of(&s.rng),
                    balls: s.balls.clone(),
                    step: s.step,
                })
                .collect(),
            last: LastOutput {
                reward: o.reward.clone(),
                terminated: o.terminated.clone(),
                truncated: o.truncated.clone(),
                outcome: o.outcome.clone(),
                episode_len: o.episode_len.clone(),
                final_obs,
            },
        }
    }

    /// Continues from `state` (taken by [`VecEnv::snapshot`] of a `VecEnv` of the same
    /// composition and batch size): the environments, random streams, start mode, curriculum
    /// factor, auto-reset and last outputs become the snapshot's, and the observations are
    /// recomputed from the restored states exactly as a step writes them. Errors, changing
    /// nothing, when the state is of another version, composition (name or any setting) or
    /// batch size, or when an array has the wrong length, a warm-start slot does not exist or
    /// a setting is out of range; the error names the field and both values.
    pub fn restore(&mut self, state: &VecEnvState) -> Result<(), TaskError> {
        self.check_state(state)?;
        let scene = &self.scene;
        for (slot, s) in self.slots.iter_mut().zip(&state.envs) {
            // Checked above: cannot fail.
            slot.data.set_state(&scene.model, &s.physics).map_err(|e| bad("state", e.field, e.expected))?;
            slot.rng = s.rng.to_rng();
            slot.balls.clone_from(&s.balls);
            slot.step = s.step;
        }
        self.fixed = match &state.mode {
            StartMode::Random | StartMode::PerSlot => None,
            StartMode::Fixed(f) => Some(fixed_start(scene, f)),
        };
        self.mode = state.mode;
        self.alpha = state.alpha;
        self.auto_reset = state.auto_reset;
        let out = &mut self.out;
        let (nv, ns, nh) = (out.obs.nodes * NODE_VECTOR_LEN, out.obs.nodes * N_SCALARS, out.obs.agents);
        for (e, slot) in self.slots.iter_mut().enumerate() {
            refresh(scene, &mut slot.data);
            let o = &mut out.obs;
            write_obs(
                scene,
                slot,
                &mut o.vectors[e * nv..(e + 1) * nv],
                &mut o.scalars[e * ns..(e + 1) * ns],
                &mut o.heading[e * nh..(e + 1) * nh],
            );
        }
        let l = &state.last;
        out.reward.copy_from_slice(&l.reward);
        out.terminated.copy_from_slice(&l.terminated);
        out.truncated.copy_from_slice(&l.truncated);
        out.outcome.copy_from_slice(&l.outcome);
        out.episode_len.copy_from_slice(&l.episode_len);
        for r in &l.final_obs {
            let (e, f) = (r.env, &mut out.final_obs);
            f.vectors[e * nv..(e + 1) * nv].copy_from_slice(&r.vectors);
            f.scalars[e * ns..(e + 1) * ns].copy_from_slice(&r.scalars);
            f.heading[e * nh..(e + 1) * nh].copy_from_slice(&r.heading);
        }
        Ok(())
    }

    /// Every check of [`VecEnv::restore`], before anything changes.
    fn check_state(&self, state: &VecEnvState) -> Result<(), TaskError> {
        same("version", &state.version, &VEC_ENV_STATE_VERSION)?;
        let (spec, mine): (&TaskSpec, &TaskSpec) = (&state.spec, &self.scene.spec);
        same("scene", &spec.name, &mine.name)?;
        same("spec.kind", &spec.kind, &mine.kind)?;
        same("spec.teams", &spec.teams, &mine.teams)?;
        same("spec.radius", &spec.radius.to_bits(), &mine.radius.to_bits())
            .map_err(|_| bad("state spec.radius", spec.radius, format!("this environment has {}", mine.radius)))?;
        same("spec.balls", &spec.balls, &mine.balls)?;
        same("spec.episode_steps", &spec.episode_steps, &mine.episode_steps)?;
        same("spec.physics_steps", &spec.physics_steps, &mine.physics_steps)?;
        let b = self.slots.len();
        same("batch", &state.batch, &b)?;
        same_len("envs", state.envs.len(), b)?;
        state.mode.validate()?;
        if !(0.0..=1.0).contains(&state.alpha) {
            return Err(bad("state alpha", state.alpha, "must lie in [0, 1]"));
        }
        let m = &self.scene.model;
        for (e, s) in state.envs.iter().enumerate() {
            s.physics.check(m).map_err(|x| {
                bad(format!("state envs[{e}].physics.{}", x.field), x.value, format!("expected {}", x.expected))
            })?;
            same_len(&format!("envs[{e}].balls"), s.balls.len(), self.scene.spec.balls)?;
            if s.step > u32::MAX as usize {
                return Err(bad(format!("state envs[{e}].step"), s.step, "episode lengths are u32"));
            }
        }
        let l = &state.last;
        same_len("last.reward", l.reward.len(), b * self.scene.n_teams())?;
        same_len("last.terminated", l.terminated.len(), b)?;
        same_len("last.truncated", l.truncated.len(), b)?;
        same_len("last.outcome", l.outcome.len(), b)?;
        same_len("last.episode_len", l.episode_len.len(), b)?;
        let o = &self.out.obs;
        for r in &l.final_obs {
            if r.env >= b {
                return Err(bad("state last.final_obs env", r.env, format!("there are {b} environments")));
            }
            let e = r.env;
            same_len(&format!("last.final_obs[env {e}].vectors"), r.vectors.len(), o.nodes * NODE_VECTOR_LEN)?;
            same_len(&format!("last.final_obs[env {e}].scalars"), r.scalars.len(), o.nodes * N_SCALARS)?;
            same_len(&format!("last.final_obs[env {e}].heading"), r.heading.len(), o.agents)?;
        }
        Ok(())
    }
}
