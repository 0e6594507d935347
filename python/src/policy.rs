//! `meben.Policy`: the trained teams of a run directory acting on observation dicts, with
//! the random streams of the Rust evaluation (`rl::evaluate`), so that a policy loaded with
//! seed `s` acts as `meben eval --seed s` does.

use envs::tasks::{N_SCALARS, ObsSpec};
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rl::actor::{ActMode, Actor, JointAction};
use rl::evaluate::{evaluate_unless_stopped, evaluation_actors};
use rl::{EvalRequest, RunDir, StopFlag, Team, TrainConfig};

use crate::arrays::{array, py_repr, read_f32};
use crate::errors::{bad_argument, rl_error};
use crate::interrupt::run_interruptible;

/// A trained run's policies (see `meben.Policy.load`).
#[pyclass(name = "Policy", module = "meben._core")]
pub struct PyPolicy {
    /// The run directory it was loaded from.
    run: std::path::PathBuf,
    config: TrainConfig,
    teams: Vec<Team>,
    /// Per team a copy of its model and its actor, in sampling mode; `act` sets the mode.
    players: Vec<(models::Model, Actor)>,
    spec: ObsSpec,
    n_actions: usize,
    obs: [Vec<f32>; 3],
}

/// The observation dict's array `key`.
fn item<'py>(obs: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    obs.get_item(key)?.ok_or_else(|| {
        bad_argument("obs", format!("a dict without {key:?}"), "expected the keys vectors, scalars, heading")
    })
}

#[pymethods]
impl PyPolicy {
    /// Loads the trained teams of the run directory `run` (its `config.toml` and
    /// `checkpoint.json`, as the `meben` program writes them). `seed` seeds the action noise
    /// and stochastic assignments as `meben eval --seed` does.
    #[staticmethod]
    #[pyo3(signature = (run, seed=0))]
    fn load(py: Python<'_>, run: std::path::PathBuf, seed: u64) -> PyResult<PyPolicy> {
        let (config, teams) = py.detach(|| rl::checkpoint::load_policies(&RunDir::new(&run))).map_err(rl_error)?;
        let scene = py.detach(|| envs::tasks::Scene::from_name(&config.env)).map_err(crate::errors::task_error)?;
        let players = evaluation_actors(&teams, seed, ActMode::Sample);
        Ok(PyPolicy {
            run,
            config,
            teams,
            players,
            spec: scene.obs_spec,
            n_actions: scene.n_actions,
            obs: Default::default(),
        })
    }

    /// Actions `[B, total_dof]` (float32 in [-1, 1]) of every team for observations `obs` (a
    /// dict as `env.step` returns): the mean actions if `deterministic`, else samples.
    #[pyo3(signature = (obs, deterministic=true))]
    fn act<'py>(
        &mut self,
        py: Python<'py>,
        obs: &Bound<'py, PyDict>,
        deterministic: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (n, a) = (self.spec.n_nodes, self.spec.n_agents);
        let heading = item(obs, "heading")?;
        let b = match heading.cast::<numpy::PyUntypedArray>() {
            Ok(h) if h.shape().len() == 2 => h.shape()[0],
            _ => {
                return Err(bad_argument(
                    "obs[\"heading\"]",
                    heading.repr()?,
                    &format!("expected a float32 array [B, {a}]"),
                ));
            }
        };
        let [vectors, scalars, head] = &mut self.obs;
        read_f32(&item(obs, "vectors")?, "obs[\"vectors\"]", &[b, n, 3, 3], vectors)?;
        read_f32(&item(obs, "scalars")?, "obs[\"scalars\"]", &[b, n, N_SCALARS], scalars)?;
        read_f32(&heading, "obs[\"heading\"]", &[b, a], head)?;
        let mode = if deterministic { ActMode::Mean } else { ActMode::Sample };
        let raw = models::ObsRows::new(n, a, vectors.as_slice(), scalars.as_slice(), head.as_slice())
            .map_err(|e| bad_argument("obs", "arrays".to_string(), &e.to_string()))?;
        let mut joint = JointAction::new(b, self.n_actions, self.teams.len());
        let (teams, players) = (&self.teams, &mut self.players);
        py.detach(|| {
            for (team, (model, actor)) in teams.iter().zip(players.iter_mut()) {
                actor.mode = mode;
                actor.act(model, &team.store, &team.norm, raw, &mut joint)?;
            }
            Ok(())
        })
        .map_err(rl_error)?;
        let actions = joint.actions;
        array(py, &actions, &[b, self.n_actions])
    }

    /// Plays `episodes` evaluation episodes of the run's teams, one per environment, each to
    /// its end, exactly as `meben eval` does with the same options, and returns its summary
    /// (the dict `meben eval` writes to `eval.json`: `success_rate`, `win_rate`,
    /// `draw_rate`, `mean_return`, `mean_length`, ...). `deterministic=None` takes the run's
    /// `eval_deterministic`; `fixed`, a `rotation_deg` or a `translation` `(x, y)` plays
    /// the fixed start of the run's seed, moved (the paper's equivariance test). The
    /// policy's own noise streams (`act`) are untouched. The GIL is released while playing;
    /// a `KeyboardInterrupt` abandons the evaluation and is raised.
    #[pyo3(signature = (episodes=1024, seed=rl::evaluate::DEFAULT_EVAL_SEED, deterministic=None, fixed=false, rotation_deg=None, translation=None))]
    #[allow(clippy::too_many_arguments)]
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        episodes: usize,
        seed: u64,
        deterministic: Option<bool>,
        fixed: bool,
        rotation_deg: Option<f64>,
        translation: Option<(f64, f64)>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let request = EvalRequest {
            episodes,
            seed,
            deterministic,
            fixed,
            rotation_deg,
            translation: translation.map(|(x, y)| [x, y]),
        };
        let options = request.options(&self.config);
        let (env, teams) = (&self.config.env, &self.teams);
        let stop = StopFlag::new();
        let stopping = "Policy.evaluate: interrupted: abandoning the evaluation";
        let (result, interrupt) =
            run_interruptible(py, &stop, stopping, || evaluate_unless_stopped(env, teams, &options, &stop))?;
        if let Some(e) = interrupt {
            return Err(e);
        }
        let summary = result
            .map_err(rl_error)?
            .ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("Policy.evaluate stopped without an interrupt"))?;
        let text =
            serde_json::to_string(&summary).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// The run directory the policy was loaded from.
    #[getter]
    fn run(&self) -> std::path::PathBuf {
        self.run.clone()
    }

    /// The run's environment name.
    #[getter]
    fn env(&self) -> &str {
        &self.config.env
    }

    /// The run's model (team 0's; `opponent` is team 1's when set).
    #[getter]
    fn model(&self) -> &str {
        &self.config.model
    }

    /// The run's resolved configuration as TOML text (`config.toml`).
    #[getter]
    fn config(&self) -> String {
        self.config.to_toml()
    }

    /// `Policy(run=..., env=..., model=...[, opponent=...])`.
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let opponent = match self.config.opponent.as_str() {
            "" => String::new(),
            o => format!(", opponent={}", py_repr(py, o)?),
        };
        Ok(format!(
            "Policy(run={}, env={}, model={}{opponent})",
            py_repr(py, &self.run.display().to_string())?,
            py_repr(py, &self.config.env)?,
            py_repr(py, &self.config.model)?
        ))
    }
}
