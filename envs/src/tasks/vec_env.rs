//! `B` environments of one scene stepped in parallel on rayon.
//!
//! - Randomness: environment `e` owns a ChaCha8 stream seeded from `(run seed, e)`
//!   ([`env_rng`]); each episode's start is drawn from it when the episode begins, so every
//!   episode gets a fresh start and a run is reproducible from its seed
//!   ([`StartMode::PerSlot`]: the reference release's reset, every episode of environment `e`
//!   from its first draw).
//! - Each environment is stepped from start to end by one thread with the same sequential
//!   code: results are bit-identical whatever the number of threads.
//! - A control step applies the clipped actions for [`super::spec::PHYSICS_STEPS_PER_CONTROL`]
//!   physics steps, then computes rewards and the outcome. `terminated` (success, win, draw,
//!   divergence) and `truncated` (episode length reached) are separate. An environment whose
//!   episode ended is reset at once: `obs` holds the first observation of its next episode
//!   and `final_obs` the true last observation of the episode that ended (rows of other
//!   environments in `final_obs` are stale).
//! - Checkpoints: [`VecEnv::snapshot`] returns a serialisable [`VecEnvState`] with everything
//!   that determines the future steps; [`VecEnv::restore`] continues from it bit for bit (also
//!   in a `VecEnv` built with another seed).
//!
//! Actions: `[B, n_actions]` `f32`, each row the agents' action vectors concatenated in agent
//! order (agent `a` at `ObsSpec::agent_action_offset[a]`, length `agent_dof[a]`, in the order
//! of its DoF nodes), clipped to `[-1, 1]`. Rewards: `[B, n_teams]` (Reach: the shared team
//! reward; Sumo: team 0 then team 1).

use super::error::TaskError;
use super::eval_modes::{StartMode, fixed_start};
use super::outcome::{Outcome, RootState};
use super::placement::{Start, sample_start};
use super::scene::Scene;
use super::spec::{TaskKind, TaskSpec};
use super::{reach, sumo};
use crate::data::Data;
use crate::kinematics::{com_pos, com_vel, kinematics};
use crate::layout::{N_SCALARS, NODE_VECTOR_LEN, Observation};
use crate::step;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

mod footprint;
mod state;
pub use footprint::{PROBE_STEPS, check_batch_fits};
pub use state::{EnvState, FinalObsRow, LastOutput, RngState, VEC_ENV_STATE_VERSION, VecEnvState};

/// The random stream of environment `env` in a run seeded with `seed`.
pub fn env_rng(seed: u64, env: usize) -> ChaCha8Rng {
    let mut s = [0u8; 32];
    s[..8].copy_from_slice(&seed.to_le_bytes());
    s[8..16].copy_from_slice(&(env as u64).to_le_bytes());
    s[16..32].copy_from_slice(b"meben/tasks/env\0");
    ChaCha8Rng::from_seed(s)
}

/// Everything one step produces, batch first.
#[derive(Clone, Debug)]
pub struct StepOutput {
    /// Current observations (after auto-reset for environments whose episode ended).
    pub obs: Observation,
    /// Last observation of the episode that ended at this step (rows where
    /// `terminated || truncated`; other rows are stale).
    pub final_obs: Observation,
    /// `[B, n_teams]` rewards of this step.
    pub reward: Vec<f32>,
    /// `[B]`: the episode ended by the game's rules.
    pub terminated: Vec<bool>,
    /// `[B]`: the episode reached its length without terminating.
    pub truncated: Vec<bool>,
    /// `[B]`: how the step ended ([`Outcome::Running`] when the episode goes on).
    pub outcome: Vec<Outcome>,
    /// `[B]`: control steps of the episode so far (of the ended episode where it ended).
    pub episode_len: Vec<u32>,
}

/// One environment's state.
#[derive(Clone, Debug)]
struct Slot {
    data: Data,
    rng: ChaCha8Rng,
    balls: Vec<[f64; 2]>,
    step: usize,
    roots: RootState,
}

/// This environment's parts of the output arrays.
struct Row<'a> {
    vectors: &'a mut [f32],
    scalars: &'a mut [f32],
    heading: &'a mut [f32],
    final_vectors: &'a mut [f32],
    final_scalars: &'a mut [f32],
    final_heading: &'a mut [f32],
    reward: &'a mut [f32],
    terminated: &'a mut bool,
    truncated: &'a mut bool,
    outcome: &'a mut Outcome,
    episode_len: &'a mut u32,
}

/// `B` environments of one scene.
#[derive(Clone, Debug)]
pub struct VecEnv {
    scene: Scene,
    slots: Vec<Slot>,
    out: StepOutput,
    mode: StartMode,
    fixed: Option<Start>,
    alpha: f64,
    auto_reset: bool,
}

impl Row<'_> {
    /// Whether the observation and rewards written to this row are all finite.
    fn is_finite(&self) -> bool {
        self.vectors
            .iter()
            .chain(self.scalars.iter())
            .chain(self.heading.iter())
            .chain(self.reward.iter())
            .all(|x| x.is_finite())
    }
}

/// Recomputes poses and velocities for the observation and rewards (the step pipeline
/// computes them before integrating, so they are stale after a step).
fn refresh(scene: &Scene, d: &mut Data) {
    kinematics(&scene.model, d);
    com_pos(&scene.model, d);
    com_vel(&scene.model, d);
}

/// Where an environment's next episode starts ([`StartMode`]).
#[derive(Clone, Copy)]
enum NextStart<'a> {
    /// The next draw of the environment's stream (`Random`).
    Fresh,
    /// The environment's first draw again (`PerSlot`): drawn from a copy of its stream, which
    /// so never advances (it draws nothing else).
    FirstDraw,
    /// This start (`Fixed`, [`VecEnv::set_start`]).
    Given(&'a Start),
}

impl<'a> NextStart<'a> {
    /// The start of every episode under `mode` (`fixed`: the fixed mode's start).
    fn of(mode: &StartMode, fixed: Option<&'a Start>) -> NextStart<'a> {
        match (mode, fixed) {
            (StartMode::Random, _) => NextStart::Fresh,
            (StartMode::PerSlot, _) => NextStart::FirstDraw,
            (StartMode::Fixed(_), Some(s)) => NextStart::Given(s),
            (StartMode::Fixed(_), None) => unreachable!("a fixed mode's start is drawn with the mode"),
        }
    }
}

fn begin_episode(scene: &Scene, slot: &mut Slot, next: NextStart<'_>) {
    let start = match next {
        NextStart::Given(s) => s.clone(),
        NextStart::Fresh => sample_start(scene, &mut slot.rng),
        NextStart::FirstDraw => sample_start(scene, &mut slot.rng.clone()),
    };
    let qpos = start.to_qpos(scene);
    // The start is finite and sized from the scene's model (rotations are checked finite).
    if let Err(e) = slot.data.reset_to(&scene.model, &qpos) {
        unreachable!("start state rejected: {e}");
    }
    slot.data.ctrl.iter_mut().for_each(|c| *c = 0.0);
    slot.balls = start.balls;
    slot.step = 0;
    refresh(scene, &mut slot.data);
}

fn write_obs(scene: &Scene, slot: &Slot, vectors: &mut [f32], scalars: &mut [f32], heading: &mut [f32]) {
    super::observation::write_row(&scene.obs_spec, &scene.model, &slot.data, &slot.balls, vectors, scalars, heading);
}

/// One control step of one environment.
fn step_env(
    scene: &Scene,
    slot: &mut Slot,
    actions: &[f32],
    alpha: f64,
    next: NextStart<'_>,
    reset: bool,
    row: Row<'_>,
) {
    let m = &scene.model;
    for (i, a) in scene.agents.iter().enumerate() {
        let mut sq = 0.0;
        for (k, &act) in a.actuators.iter().enumerate() {
            let u = (actions[a.action_offset + k] as f64).clamp(-1.0, 1.0);
            slot.data.ctrl[act] = u;
            sq += u * u;
        }
        slot.roots.action_norm[i] = sq.sqrt();
    }
    for _ in 0..scene.spec.physics_steps {
        step(m, &mut slot.data);
    }
    refresh(scene, &mut slot.data);
    slot.step += 1;
    for (i, a) in scene.agents.iter().enumerate() {
        let p = slot.data.xpos[a.root_body];
        let v = slot.data.cvel[a.root_body];
        slot.roots.pos[i] = [p[0], p[1]];
        slot.roots.vel[i] = [v[3], v[4]];
    }
    let mut outcome = if slot.data.is_finite() {
        match scene.kind() {
            TaskKind::Reach => {
                let (r, o) = reach::evaluate(&slot.balls, &slot.roots);
                row.reward[0] = r.total() as f32;
                o
            }
            TaskKind::Sumo => {
                let team: Vec<usize> = scene.agents.iter().map(|a| a.team).collect();
                let (r, o) = sumo::evaluate(&team, slot.balls[0], scene.spec.radius, &slot.roots);
                row.reward[0] = r[0].total(alpha) as f32;
                row.reward[1] = r[1].total(alpha) as f32;
                o
            }
        }
    } else {
        Outcome::Diverged
    };
    write_obs(scene, slot, row.vectors, row.scalars, row.heading);
    // A state finite in f64 can still overflow the f32 observation or reward (a position
    // of 1e39 m): that step diverged, not the next one (issue 44 item 4).
    if outcome != Outcome::Diverged && !row.is_finite() {
        outcome = Outcome::Diverged;
    }
    if outcome == Outcome::Diverged {
        row.reward.iter_mut().for_each(|r| *r = 0.0);
    }
    *row.terminated = outcome.is_terminal();
    *row.truncated = !*row.terminated && slot.step >= scene.spec.episode_steps;
    if *row.truncated {
        outcome = Outcome::TimeLimit;
    }
    *row.outcome = outcome;
    *row.episode_len = slot.step as u32;
    if *row.terminated || *row.truncated {
        row.final_vectors.copy_from_slice(row.vectors);
        row.final_scalars.copy_from_slice(row.scalars);
        row.final_heading.copy_from_slice(row.heading);
        if reset {
            begin_episode(scene, slot, next);
            write_obs(scene, slot, row.vectors, row.scalars, row.heading);
        }
    }
}

/// The most environments one [`VecEnv`] holds: beyond it a batch is refused before
/// anything is allocated, so an impossible size is an error, not an aborted process.
pub const MAX_ENVS: usize = 1 << 20;

impl VecEnv {
    /// `batch` environments (1 to [`MAX_ENVS`]) of `spec` whose random streams derive from
    /// `seed`, starting as `mode` says. Every environment begins an episode; [`VecEnv::obs`]
    /// is ready. A batch whose estimated size is more than the machine's memory is refused
    /// before it is allocated ([`check_batch_fits`]).
    pub fn new(spec: &TaskSpec, batch: usize, seed: u64, mode: StartMode) -> Result<VecEnv, TaskError> {
        if !(1..=MAX_ENVS).contains(&batch) {
            return Err(TaskError::BadArgument {
                what: "batch".into(),
                value: batch.to_string(),
                message: format!("must lie in 1 ..= {MAX_ENVS} environments"),
            });
        }
        mode.validate()?;
        let scene = Scene::build(spec)?;
        // Before anything of the batch is allocated: a batch the machine cannot hold is an
        // error with the estimate, not an aborted process.
        check_batch_fits(&scene, batch)?;
        let fixed = match &mode {
            StartMode::Random | StartMode::PerSlot => None,
            StartMode::Fixed(f) => Some(fixed_start(&scene, f)),
        };
        let na = scene.n_agents();
        let roots = RootState { pos: vec![[0.0; 2]; na], vel: vec![[0.0; 2]; na], action_norm: vec![0.0; na] };
        let slots = (0..batch)
            .map(|e| Slot {
                data: Data::new(&scene.model),
                rng: env_rng(seed, e),
                balls: Vec::new(),
                step: 0,
                roots: roots.clone(),
            })
            .collect();
        let obs = Observation::zeros(&scene.obs_spec, batch);
        let out = StepOutput {
            final_obs: obs.clone(),
            obs,
            reward: vec![0.0; batch * scene.n_teams()],
            terminated: vec![false; batch],
            truncated: vec![false; batch],
            outcome: vec![Outcome::Running; batch],
            episode_len: vec![0; batch],
        };
        let mut env = VecEnv { scene, slots, out, mode, fixed, alpha: 1.0, auto_reset: true };
        env.reset();
        Ok(env)
    }

    /// Like [`VecEnv::new`] from a built-in name or custom composition string.
    pub fn from_name(name: &str, batch: usize, seed: u64, mode: StartMode) -> Result<VecEnv, TaskError> {
        VecEnv::new(&TaskSpec::from_name(name)?, batch, seed, mode)
    }

    /// Begins a new episode in every environment (the next start of each one's stream) and
    /// returns the first observations.
    pub fn reset(&mut self) -> &Observation {
        let (scene, next) = (&self.scene, NextStart::of(&self.mode, self.fixed.as_ref()));
        let o = &mut self.out.obs;
        let (nv, ns, na) = (o.nodes * NODE_VECTOR_LEN, o.nodes * N_SCALARS, o.agents);
        self.slots
            .par_iter_mut()
            .zip(o.vectors.par_chunks_mut(nv))
            .zip(o.scalars.par_chunks_mut(ns))
            .zip(o.heading.par_chunks_mut(na.max(1)))
            .for_each(|(((slot, v), s), h)| {
                begin_episode(scene, slot, next);
                write_obs(scene, slot, v, s, h);
            });
        self.out.terminated.iter_mut().for_each(|x| *x = false);
        self.out.truncated.iter_mut().for_each(|x| *x = false);
        self.out.outcome.iter_mut().for_each(|x| *x = Outcome::Running);
        self.out.episode_len.iter_mut().for_each(|x| *x = 0);
        &self.out.obs
    }

    /// One control step of every environment with `actions` (`[B, n_actions]`, module docs).
    /// Errors (and changes nothing) when the length is wrong or an entry is not finite.
    pub fn step(&mut self, actions: &[f32]) -> Result<&StepOutput, TaskError> {
        let (b, na) = (self.slots.len(), self.scene.n_actions);
        if actions.len() != b * na {
            return Err(TaskError::BadActions {
                message: format!(
                    "{} values given, expected batch {b} x {na} actions per environment = {}",
                    actions.len(),
                    b * na
                ),
            });
        }
        if let Some(i) = actions.iter().position(|x| !x.is_finite()) {
            return Err(TaskError::BadActions {
                message: format!(
                    "actions[{i}] (environment {}, action {}) = {}",
                    i / na.max(1),
                    i % na.max(1),
                    actions[i]
                ),
            });
        }
        let (scene, next, alpha, reset) =
            (&self.scene, NextStart::of(&self.mode, self.fixed.as_ref()), self.alpha, self.auto_reset);
        let out = &mut self.out;
        let (nv, ns, nh, nt) =
            (out.obs.nodes * NODE_VECTOR_LEN, out.obs.nodes * N_SCALARS, out.obs.agents.max(1), scene.n_teams());
        let rows: Vec<Row<'_>> = out
            .obs
            .vectors
            .chunks_mut(nv)
            .zip(out.obs.scalars.chunks_mut(ns))
            .zip(out.obs.heading.chunks_mut(nh))
            .zip(out.final_obs.vectors.chunks_mut(nv))
            .zip(out.final_obs.scalars.chunks_mut(ns))
            .zip(out.final_obs.heading.chunks_mut(nh))
            .zip(out.reward.chunks_mut(nt))
            .zip(out.terminated.iter_mut())
            .zip(out.truncated.iter_mut())
            .zip(out.outcome.iter_mut())
            .zip(out.episode_len.iter_mut())
            .map(
                |(
                    (((((((((vectors, scalars), heading), fv), fs), fh), reward), terminated), truncated), outcome),
                    len,
                )| {
                    Row {
                        vectors,
                        scalars,
                        heading,
                        final_vectors: fv,
                        final_scalars: fs,
                        final_heading: fh,
                        reward,
                        terminated,
                        truncated,
                        outcome,
                        episode_len: len,
                    }
                },
            )
            .collect();
        self.slots.par_iter_mut().zip(rows).enumerate().for_each(|(e, (slot, row))| {
            step_env(scene, slot, &actions[e * na..(e + 1) * na], alpha, next, reset, row);
        });
        Ok(&self.out)
    }

    /// Begins a new episode in environment `env` from a given start (hand-built scenes in
    /// tests and evaluation); its observation row is rewritten. Later episodes start as the
    /// start mode says. Errors when `env` is out of range or the start does not fit the scene
    /// (agent or ball count, non-finite numbers).
    pub fn set_start(&mut self, env: usize, start: &Start) -> Result<(), TaskError> {
        let bad = |what: &str, value: String, message: &str| TaskError::BadArgument {
            what: what.into(),
            value,
            message: message.into(),
        };
        if env >= self.slots.len() {
            return Err(bad("env", env.to_string(), &format!("there are {} environments", self.slots.len())));
        }
        let (na, nb) = (self.scene.n_agents(), self.scene.spec.balls);
        if start.agents.len() != na || start.balls.len() != nb {
            let got = format!("{} agents, {} balls", start.agents.len(), start.balls.len());
            return Err(bad("start", got, &format!("the scene has {na} agents and {nb} balls")));
        }
        let finite = start.agents.iter().all(|a| a.xy.iter().chain([&a.yaw]).all(|x| x.is_finite()))
            && start.balls.iter().flatten().all(|x| x.is_finite());
        if !finite {
            return Err(bad("start", format!("{start:?}"), "positions and yaws must be finite"));
        }
        let scene = &self.scene;
        let slot = &mut self.slots[env];
        begin_episode(scene, slot, NextStart::Given(start));
        let o = &mut self.out.obs;
        let (nv, ns, nh) = (o.nodes * NODE_VECTOR_LEN, o.nodes * N_SCALARS, o.agents);
        write_obs(
            scene,
            slot,
            &mut o.vectors[env * nv..(env + 1) * nv],
            &mut o.scalars[env * ns..(env + 1) * ns],
            &mut o.heading[env * nh..(env + 1) * nh],
        );
        Ok(())
    }

    /// Whether an environment whose episode ended begins the next one at once (default
    /// true). Off (for rendering and inspection), an ended environment keeps its last state:
    /// `obs` then equals `final_obs` and further steps continue the same episode's physics
    /// (with the episode counter past its end) until [`VecEnv::reset`] or
    /// [`VecEnv::set_start`].
    pub fn set_auto_reset(&mut self, on: bool) {
        self.auto_reset = on;
    }

    /// Sets the Sumo curriculum factor `alpha` in `[0, 1]` (`r = alpha dense + (1 - alpha)
    /// sparse`; ignored by Reach). Default 1.
    pub fn set_curriculum_alpha(&mut self, alpha: f64) -> Result<(), TaskError> {
        if !(0.0..=1.0).contains(&alpha) {
            return Err(TaskError::BadArgument {
                what: "curriculum alpha".into(),
                value: alpha.to_string(),
                message: "must lie in [0, 1]".into(),
            });
        }
        self.alpha = alpha;
        Ok(())
    }

    /// The curriculum factor.
    pub fn curriculum_alpha(&self) -> f64 {
        self.alpha
    }

    /// Current observations.
    pub fn obs(&self) -> &Observation {
        &self.out.obs
    }

    /// Everything the last step produced.
    pub fn output(&self) -> &StepOutput {
        &self.out
    }

    /// The scene (model, agents, observation layout).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Number of environments.
    pub fn batch(&self) -> usize {
        self.slots.len()
    }

    /// Actions per environment.
    pub fn n_actions(&self) -> usize {
        self.scene.n_actions
    }

    /// How episodes start.
    pub fn start_mode(&self) -> StartMode {
        self.mode
    }

    /// The simulator state of environment `env` (for tests, rendering and diagnostics).
    pub fn data(&self, env: usize) -> Option<&Data> {
        self.slots.get(env).map(|s| &s.data)
    }

    /// Ball positions (x, y) of environment `env`'s current episode.
    pub fn balls(&self, env: usize) -> Option<&[[f64; 2]]> {
        self.slots.get(env).map(|s| s.balls.as_slice())
    }

    /// Control steps taken in environment `env`'s current episode.
    pub fn episode_step(&self, env: usize) -> Option<usize> {
        self.slots.get(env).map(|s| s.step)
    }
}
