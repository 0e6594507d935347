//! `meben.VecEnv`: `B` environments of one MeBen scene, batch first like the Rust `VecEnv`
//! it wraps. Stepping releases the GIL (the environments step on rayon's threads).

use envs::tasks::{Outcome, StartMode, StepOutput, TaskSpec, VecEnv};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rl::EvalOptions;

use crate::arrays::{array, obs_dict, py_repr, read_f32};
use crate::errors::{bad_argument, rl_error, task_error};
use crate::recorder::Recorder;
use crate::spec::spec_dict;

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

/// A seed given as a Python int, checked to be non-negative.
fn non_negative(what: &str, value: i64) -> PyResult<u64> {
    if value < 0 {
        return Err(bad_argument(what, value, "must be a non-negative integer"));
    }
    Ok(value as u64)
}

/// Batched MeBen environments (see `meben.make`).
#[pyclass(name = "VecEnv", module = "meben._core")]
pub struct PyVecEnv {
    env: VecEnv,
    auto_reset: bool,
    actions: Vec<f32>,
    recorder: Option<Recorder>,
}

impl PyVecEnv {
    fn wrap(env: VecEnv, auto_reset: bool, record: bool) -> PyVecEnv {
        let recorder = record.then(|| Recorder::new(&env));
        PyVecEnv { env, auto_reset, actions: Vec::new(), recorder }
    }

    fn info<'py>(&self, py: Python<'py>, out: &StepOutput) -> PyResult<Bound<'py, PyDict>> {
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
        info.set_item("curriculum_alpha", self.env.curriculum_alpha())?;
        Ok(info)
    }
}

#[pymethods]
impl PyVecEnv {
    /// `num_envs` environments of `name` (a built-in name or a composition string; a
    /// morphology may be a Brax-config `.txt` or an MJCF `.xml` file), random streams from
    /// `seed`. Episodes
    /// start at random, or all from the start drawn with `fixed_start` rotated by
    /// `rotation_deg` about the vertical through `point`. `auto_reset=False` keeps an ended
    /// environment in its last state; `record=True` records environment 0 for `render`.
    #[new]
    #[pyo3(signature = (name, num_envs=1, seed=0, *, auto_reset=true, fixed_start=None, rotation_deg=0.0, point=(0.0, 0.0), record=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        name: &str,
        num_envs: i64,
        seed: i64,
        auto_reset: bool,
        fixed_start: Option<i64>,
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
        let mut env = py.detach(|| VecEnv::new(&TaskSpec::from_name(name)?, b, s, mode)).map_err(task_error)?;
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
        seed: i64,
        fixed_start: Option<i64>,
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
        let env = py.detach(|| rl::evaluate::eval_envs(name, &options)).map_err(rl_error)?;
        Ok(PyVecEnv::wrap(env, false, record))
    }

    /// Begins a new episode in every environment; returns the first observations.
    fn reset<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let env = &mut self.env;
        py.detach(|| {
            env.reset();
        });
        if let Some(r) = &mut self.recorder {
            r.restart(&self.env);
        }
        obs_dict(py, self.env.obs())
    }

    /// One control step of every environment with `actions` (float32 `[num_envs,
    /// total_dof]`, clipped to [-1, 1]). Returns `(obs, reward, terminated, truncated,
    /// info)`. Bad actions raise `ValueError` and change nothing.
    fn step<'py>(&mut self, py: Python<'py>, actions: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyTuple>> {
        let shape = [self.env.batch(), self.env.n_actions()];
        read_f32(actions, "actions", &shape, &mut self.actions)?;
        let (env, a) = (&mut self.env, &self.actions);
        py.detach(|| env.step(a).map(|_| ())).map_err(task_error)?;
        let out = self.env.output();
        if let Some(r) = &mut self.recorder {
            r.after_step(&self.env, out.terminated[0] || out.truncated[0], self.auto_reset);
        }
        let out = self.env.output();
        let nt = self.env.scene().n_teams();
        let items = [
            obs_dict(py, &out.obs)?.into_any(),
            array(py, &out.reward, &[shape[0], nt])?,
            PyArray1::from_slice(py, &out.terminated).into_any(),
            PyArray1::from_slice(py, &out.truncated).into_any(),
            self.info(py, out)?.into_any(),
        ];
        PyTuple::new(py, items)
    }

    /// The current observations (as `reset` and `step` return them).
    fn observation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        obs_dict(py, self.env.obs())
    }

    /// Writes environment 0's recorded episode (`record=True` at `make`) to `path`: `.html`
    /// (a self-contained player), `.gif` or `.csv`. Returns the number of frames.
    fn render(&self, path: &str) -> PyResult<usize> {
        match &self.recorder {
            Some(r) => r.write(path),
            None => Err(bad_argument("record", "False", "render needs make(..., record=True)")),
        }
    }

    /// What the scene is made of: nodes, agents, teams, each agent's action slice.
    #[getter]
    fn spec<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        spec_dict(py, self.env.scene())
    }

    /// Number of environments (`B`).
    #[getter]
    fn num_envs(&self) -> usize {
        self.env.batch()
    }

    /// Actions per environment (`total_dof`).
    #[getter]
    fn num_actions(&self) -> usize {
        self.env.n_actions()
    }

    /// The Sumo curriculum factor in [0, 1] (`r = alpha dense + (1 - alpha) sparse`; Reach
    /// ignores it). Default 1.
    #[getter]
    fn get_curriculum_alpha(&self) -> f64 {
        self.env.curriculum_alpha()
    }

    /// Sets the curriculum factor; outside [0, 1] raises `ValueError`.
    #[setter]
    fn set_curriculum_alpha(&mut self, alpha: f64) -> PyResult<()> {
        self.env.set_curriculum_alpha(alpha).map_err(task_error)
    }

    /// Whether ended environments begin their next episode at once.
    #[getter]
    fn auto_reset(&self) -> bool {
        self.auto_reset
    }

    /// `VecEnv(name=..., num_envs=..., num_actions=..., auto_reset=...)`.
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "VecEnv(name={}, num_envs={}, num_actions={}, auto_reset={})",
            py_repr(py, &self.env.scene().spec.name)?,
            self.env.batch(),
            self.env.n_actions(),
            if self.auto_reset { "True" } else { "False" }
        ))
    }
}
