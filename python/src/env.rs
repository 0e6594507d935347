//! `meben.VecEnv`: `B` environments of one MeBen scene, batch first like the Rust `VecEnv`
//! it wraps. Stepping releases the GIL (the environments step on rayon's threads; in a
//! forked process on a pool of its own: [`crate::pool`]).
//!
//! One environment is used by one thread at a time: its state is behind a mutex, and a
//! call made while another Python thread is stepping or resetting it raises a
//! `RuntimeError` saying so ([`ENV_IN_USE`]) instead of waiting or interleaving. Before, the
//! second call got PyO3's bare `Already borrowed`.

use std::sync::{Mutex, MutexGuard};

use envs::tasks::{Outcome, StartMode, StepOutput, TaskSpec, VecEnv};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rl::EvalOptions;

use crate::arrays::{array, obs_dict, py_repr, read_f32};
use crate::errors::{bad_argument, rl_error, task_error, try_lock};
use crate::pool;
use crate::recorder::Recorder;
use crate::spec::spec_dict;

/// The error of a call on an environment that another thread is using.
pub const ENV_IN_USE: &str = "this VecEnv is in use by another thread (a step, reset or other call on it is \
                              running there): each thread needs its own env (call meben.make in each thread)";

/// Outcome codes of `info["outcome"]` (`meben.OUTCOMES` names them).
pub fn outcome_code(o: Outcome) -> i8 {
    match o {
        Outcome::Running => 0,
        Outcome::Success => 1,
        Outcome::Win(0) => 2,
        Outcome::Win(_) => 3,
        Outcome::Draw => 4,
        Outcome::TimeLimit => 5,
        Outcome::Diverged => 6,
    }
}

/// A number of environments given as a Python int, checked to lie in `1..=MAX_ENVS`.
fn env_count(what: &str, value: i64) -> PyResult<usize> {
    if value < 1 {
        return Err(bad_argument(what, value, "must be at least 1"));
    }
    if value as u64 > envs::tasks::MAX_ENVS as u64 {
        return Err(bad_argument(what, value, &format!("must be at most {}", envs::tasks::MAX_ENVS)));
    }
    Ok(value as usize)
}

/// A seed given as a Python int, checked to lie in `0 ..= i64::MAX` ([`crate::seed`]).
fn non_negative(what: &str, value: i128) -> PyResult<u64> {
    crate::seed::seed(what, value, crate::seed::MAX_ENV_SEED)
}

/// Batched MeBen environments (see `meben.make`).
#[pyclass(name = "VecEnv", module = "meben._core", frozen)]
pub struct PyVecEnv {
    /// The environments and what changes with them (one thread at a time: module docs).
    state: Mutex<EnvState>,
    /// The scene's name, `B`, actions per environment, auto-reset: fixed at `make`, readable
    /// while another thread steps.
    name: String,
    num_envs: usize,
    num_actions: usize,
    auto_reset: bool,
}

/// What a step changes.
struct EnvState {
    env: VecEnv,
    actions: Vec<f32>,
    recorder: Option<Recorder>,
}

impl PyVecEnv {
    fn wrap(env: VecEnv, auto_reset: bool, record: bool) -> PyVecEnv {
        let recorder = record.then(|| Recorder::new(&env));
        PyVecEnv {
            name: env.scene().spec.name.clone(),
            num_envs: env.batch(),
            num_actions: env.n_actions(),
            auto_reset,
            state: Mutex::new(EnvState { env, actions: Vec::new(), recorder }),
        }
    }

    /// The environments' state; `RuntimeError` while another thread uses them.
    fn lock(&self) -> PyResult<MutexGuard<'_, EnvState>> {
        try_lock(&self.state, ENV_IN_USE)
    }
}

/// The `info` dict of a step.
fn info<'py>(py: Python<'py>, env: &VecEnv, out: &StepOutput) -> PyResult<Bound<'py, PyDict>> {
    let b = out.outcome.len();
    let info = PyDict::new(py);
    info.set_item("final_obs", obs_dict(py, &out.final_obs)?)?;
    let codes: Vec<i8> = out.outcome.iter().map(|&o| outcome_code(o)).collect();
    info.set_item("outcome", array(py, &codes, &[b])?)?;
    let success: Vec<bool> = out.outcome.iter().map(|&o| o == Outcome::Success).collect();
    info.set_item("success", PyArray1::from_vec(py, success))?;
    let win: Vec<i8> = out.outcome.iter().map(|&o| if let Outcome::Win(t) = o { t as i8 } else { -1 }).collect();
    info.set_item("win", array(py, &win, &[b])?)?;
    let draw: Vec<bool> = out.outcome.iter().map(|&o| o == Outcome::Draw).collect();
    info.set_item("draw", PyArray1::from_vec(py, draw))?;
    info.set_item("episode_len", array(py, &out.episode_len, &[b])?)?;
    info.set_item("curriculum_alpha", env.curriculum_alpha())?;
    Ok(info)
}

#[pymethods]
impl PyVecEnv {
    /// `num_envs` environments of `name` (a built-in name or a composition string; a
    /// morphology may be a Brax-config `.txt` or an MJCF `.xml` file), random streams from
    /// `seed`. Episodes start at random, or all from the start drawn with `fixed_start`
    /// rotated by `rotation_deg` about the vertical through `point`. `record=True` records
    /// environment 0 for `render`.
    ///
    /// `auto_reset=True`: an ended environment begins its next episode in the same step.
    /// `auto_reset=False`: it is not reset, and its state is not frozen either: each later
    /// `step` goes on simulating the same scene from where it ended, with the new actions,
    /// `episode_len` counting past the end, and judges it afresh as during the episode:
    /// Team Reach pays the success bonus again (outcome success, `terminated`) at every step
    /// on which the balls are still covered, Team Sumo's win or draw is judged on each new
    /// state, after the time limit every step not terminated is `truncated` (outcome
    /// time_limit), and a diverged environment stays diverged (zero reward, `terminated`).
    /// Only `reset()` begins new episodes (in every environment).
    #[new]
    #[pyo3(signature = (name, num_envs=1, seed=0, *, auto_reset=true, fixed_start=None, rotation_deg=0.0, point=(0.0, 0.0), record=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        name: &str,
        num_envs: i64,
        seed: i128,
        auto_reset: bool,
        fixed_start: Option<i128>,
        rotation_deg: f64,
        point: (f64, f64),
        record: bool,
    ) -> PyResult<PyVecEnv> {
        let b = env_count("num_envs", num_envs)?;
        let s = non_negative("seed", seed)?;
        let mode = match fixed_start {
            Some(f) => {
                StartMode::fixed_rotated(non_negative("fixed_start", f)?, rotation_deg.to_radians(), [point.0, point.1])
            }
            None if rotation_deg != 0.0 => {
                return Err(bad_argument("rotation_deg", rotation_deg, "rotates a fixed start: give fixed_start too"));
            }
            None => StartMode::Random,
        };
        let mut env = pool::detach(py, || VecEnv::new(&TaskSpec::from_name(name)?, b, s, mode))?.map_err(|e| {
            // A batch beyond the machine's memory is refused by its argument's name.
            task_error(match e {
                envs::tasks::TaskError::BadArgument { what, value, message } if what == "batch" => {
                    envs::tasks::TaskError::BadArgument { what: "num_envs".into(), value, message }
                }
                e => e,
            })
        })?;
        env.set_auto_reset(auto_reset);
        Ok(PyVecEnv::wrap(env, auto_reset, record))
    }

    /// The environments of `meben eval`: one episode each (auto-reset off), starts drawn as
    /// the Rust evaluation draws them (random from `seed`, or the fixed start of
    /// `fixed_start`), moved by `rotation_deg` about the vertical through the origin, then by
    /// `translation`.
    #[staticmethod]
    #[pyo3(signature = (name, num_envs, seed=0, *, fixed_start=None, rotation_deg=0.0, translation=(0.0, 0.0), record=false))]
    #[allow(clippy::too_many_arguments)]
    fn evaluation(
        py: Python<'_>,
        name: &str,
        num_envs: i64,
        seed: i128,
        fixed_start: Option<i128>,
        rotation_deg: f64,
        translation: (f64, f64),
        record: bool,
    ) -> PyResult<PyVecEnv> {
        let b = env_count("num_envs", num_envs)?;
        let s = non_negative("seed", seed)?;
        let mode = match fixed_start {
            Some(f) => StartMode::fixed(non_negative("fixed_start", f)?),
            None => StartMode::Random,
        };
        let options = EvalOptions {
            rotation_deg,
            translation: [translation.0, translation.1],
            ..EvalOptions::new(b, true, s, mode)
        };
        let env = pool::detach(py, || rl::mappo::evaluate::eval_envs(name, &options))?.map_err(rl_error)?;
        Ok(PyVecEnv::wrap(env, false, record))
    }

    /// Begins a new episode in every environment; returns the first observations. Raises
    /// `RuntimeError` while another thread uses the environments (each thread needs its own).
    fn reset<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let mut guard = self.lock()?;
        let state = &mut *guard;
        let env = &mut state.env;
        pool::detach(py, || env.reset())?;
        if let Some(r) = &mut state.recorder {
            r.restart(&state.env);
        }
        obs_dict(py, state.env.obs())
    }

    /// One control step of every environment with `actions` (float32 `[num_envs,
    /// total_dof]`, clipped to [-1, 1]). Returns `(obs, reward, terminated, truncated,
    /// info)`. Bad actions raise `ValueError` and change nothing; a step while another
    /// thread uses the environments raises `RuntimeError` (each thread needs its own).
    fn step<'py>(&self, py: Python<'py>, actions: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyTuple>> {
        let mut guard = self.lock()?;
        let state = &mut *guard;
        let shape = [self.num_envs, self.num_actions];
        read_f32(actions, "actions", &shape, &mut state.actions)?;
        let (env, a) = (&mut state.env, &state.actions);
        pool::detach(py, || env.step(a).map(|_| ()))?.map_err(task_error)?;
        let out = state.env.output();
        if let Some(r) = &mut state.recorder {
            r.after_step(&state.env, out.terminated[0] || out.truncated[0], self.auto_reset);
        }
        let env = &state.env;
        let out = env.output();
        let nt = env.scene().n_teams();
        let items = [
            obs_dict(py, &out.obs)?.into_any(),
            array(py, &out.reward, &[shape[0], nt])?,
            PyArray1::from_slice(py, &out.terminated).into_any(),
            PyArray1::from_slice(py, &out.truncated).into_any(),
            info(py, env, out)?.into_any(),
        ];
        PyTuple::new(py, items)
    }

    /// The current observations (as `reset` and `step` return them).
    fn observation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        obs_dict(py, self.lock()?.env.obs())
    }

    /// Writes environment 0's recorded episode (`record=True` at `make`) to `path`: `.html`
    /// (a self-contained player), `.gif` or `.csv`. Returns the number of frames.
    fn render(&self, path: &str) -> PyResult<usize> {
        match &self.lock()?.recorder {
            Some(r) => r.write(path),
            None => Err(bad_argument("record", "False", "render needs make(..., record=True)")),
        }
    }

    /// What the scene is made of: nodes, agents, teams, each agent's action slice.
    #[getter]
    fn spec<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        spec_dict(py, self.lock()?.env.scene())
    }

    /// Number of environments (`B`).
    #[getter]
    fn num_envs(&self) -> usize {
        self.num_envs
    }

    /// Actions per environment (`total_dof`).
    #[getter]
    fn num_actions(&self) -> usize {
        self.num_actions
    }

    /// The Sumo curriculum factor in [0, 1] (`r = alpha dense + (1 - alpha) sparse`; Reach
    /// ignores it). Default 1.
    #[getter]
    fn get_curriculum_alpha(&self) -> PyResult<f64> {
        Ok(self.lock()?.env.curriculum_alpha())
    }

    /// Sets the curriculum factor; outside [0, 1] raises `ValueError`.
    #[setter]
    fn set_curriculum_alpha(&self, alpha: f64) -> PyResult<()> {
        self.lock()?.env.set_curriculum_alpha(alpha).map_err(task_error)
    }

    /// Whether ended environments begin their next episode at once (`make`'s `auto_reset`:
    /// off, they go on from their last state until `reset`).
    #[getter]
    fn auto_reset(&self) -> bool {
        self.auto_reset
    }

    /// `VecEnv(name=..., num_envs=..., num_actions=..., auto_reset=...)`.
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "VecEnv(name={}, num_envs={}, num_actions={}, auto_reset={})",
            py_repr(py, &self.name)?,
            self.num_envs,
            self.num_actions,
            if self.auto_reset { "True" } else { "False" }
        ))
    }
}
