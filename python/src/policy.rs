//! `meben.Policy`: the trained teams of a run directory or a policy file (`meben
//! export-policy`, `rl::app::policy_file`) acting on observation dicts, with
//! the random streams of the Rust evaluation (`rl::evaluate`), so that a policy loaded with
//! seed `s` acts as `meben eval --seed s` does.
//!
//! `act` changes the policy's noise streams, so one thread acts at a time: a call while
//! another thread is acting raises a `RuntimeError` saying so ([`POLICY_IN_USE`]).
//! `evaluate` reads the trained teams only and runs alongside.

use std::sync::Mutex;

use envs::layout::{N_SCALARS, ObsSpec};
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rl::app::eval_assignment::{self, AssignmentOverride};
use rl::mappo::actor::{ActMode, Actor, JointAction};
use rl::mappo::evaluate::{evaluate_unless_stopped, evaluation_actors};
use rl::{EvalRequest, RunDir, StopFlag, Team, TrainConfig};

use crate::arrays::{array, check_finite, py_repr, read_f32};
use crate::errors::{bad_argument, rl_error, try_lock};
use crate::interrupt::run_interruptible;
use crate::pool;

/// The error of `act` on a policy that another thread is acting with.
pub const POLICY_IN_USE: &str = "this Policy is in use by another thread (Policy.act is running there): each \
                                 thread needs its own Policy (call meben.Policy.load in each thread)";

/// A trained run's policies (see `meben.Policy.load`).
#[pyclass(name = "Policy", module = "meben._core", frozen)]
pub struct PyPolicy {
    /// The run directory or policy file it was loaded from.
    run: std::path::PathBuf,
    /// The run's last evaluation as recorded (its checkpoint's, or the policy file's).
    recorded_eval: Option<rl::EvalSummary>,
    config: TrainConfig,
    teams: Vec<Team>,
    /// The task-assignment rule and hold acting in place of the run's own (`load`'s
    /// `assignment` and `assignment_hold`).
    assignment: AssignmentOverride,
    /// What acting changes (one thread at a time: module docs).
    acting: Mutex<Acting>,
    spec: ObsSpec,
    n_actions: usize,
}

/// The state `act` changes.
struct Acting {
    /// Per team a copy of its model and its actor, in sampling mode; `act` sets the mode.
    players: Vec<(Box<dyn models::Policy>, Actor)>,
    /// The observation arrays read from Python (vectors, scalars, heading).
    obs: [Vec<f32>; 3],
    /// Rows `B` of the last `act` (0 before the first).
    rows: usize,
}

/// The observation dict's array `key`.
fn item<'py>(obs: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    obs.get_item(key)?.ok_or_else(|| {
        bad_argument("obs", format!("a dict without {key:?}"), "expected the keys vectors, scalars, heading")
    })
}

#[pymethods]
impl PyPolicy {
    /// Loads the trained teams of `run`: a run directory (its `config.toml` and checkpoint,
    /// as the `meben` program writes them) or a policy file (`meben export-policy`,
    /// `.safetensors`). `seed` seeds the action noise and stochastic assignments as `meben
    /// eval --seed` does. A damaged, truncated or foreign file raises `ValueError` naming it.
    /// `assignment` (`"greedy"`, `"hungarian"` or `"stochastic"`) acts and evaluates with
    /// that task-assignment rule in place of the run's own, on the same parameters (`meben
    /// eval --assignment`; a run that learned its assignment takes `"greedy"` only, Algorithm
    /// 1 in place of its scorer's draws); one the run's models cannot take raises
    /// `ValueError` saying why.
    /// `assignment_hold=k` holds each random assignment (`"stochastic"`, or a learned one)
    /// for `k` steps in place of the run's own hold (`meben eval --assignment-hold`).
    #[staticmethod]
    #[pyo3(signature = (run, seed=0, assignment=None, assignment_hold=None))]
    fn load(
        py: Python<'_>,
        run: std::path::PathBuf,
        seed: i128,
        assignment: Option<String>,
        assignment_hold: Option<usize>,
    ) -> PyResult<PyPolicy> {
        let seed = crate::seed::seed("seed", seed, u64::MAX)?;
        if run.as_os_str().is_empty() {
            // An empty path would name the working directory as a run directory.
            return Err(crate::errors::bad_argument(
                "run",
                "''",
                "expected a run directory or a policy file (use '.' for the working directory)",
            ));
        }
        let (config, teams, recorded_eval) = pool::detach(py, || -> rl::Result<_> {
            if run.is_file() {
                let f = rl::app::policy_file::load_policy(&run)?;
                Ok((f.config, f.teams, f.eval))
            } else {
                let rd = RunDir::new(&run);
                let (config, c) = rl::app::run_dir::load_run(&rd)?;
                let teams = rl::app::run_dir::teams_of(&config, &c, &rd.checkpoint())?;
                Ok((config, teams, c.last_eval))
            }
        })?
        .map_err(rl_error)?;
        let mut teams = teams;
        let over = AssignmentOverride { rule: assignment, hold: assignment_hold };
        // `AssignmentOverride::apply`'s two steps, each error naming its argument.
        if let Some(rule) = &over.rule {
            eval_assignment::reassign(&config, &mut teams, rule)
                .map_err(|e| bad_argument("assignment", format!("{rule:?}"), &e))?;
        }
        if let Some(every) = over.hold {
            eval_assignment::hold(&mut teams, every).map_err(|e| bad_argument("assignment_hold", every, &e))?;
        }
        Self::new(py, run, config, teams, recorded_eval, seed, over)
    }

    /// The shipped pretrained policy of `model` on `env` (`policies/index.toml` in the
    /// package, e.g. `Policy.pretrained("team_reach/2_ants", "shnn")`); a name that is not
    /// shipped raises `ValueError` listing the shipped ones.
    #[staticmethod]
    #[pyo3(signature = (env, model, seed=0, assignment=None, assignment_hold=None))]
    fn pretrained(
        py: Python<'_>,
        env: &str,
        model: &str,
        seed: i128,
        assignment: Option<String>,
        assignment_hold: Option<usize>,
    ) -> PyResult<PyPolicy> {
        let seed = crate::seed::seed("seed", seed, u64::MAX)?;
        let dir = shipped_dir(py)?;
        let path = rl::app::policy_file::find_pretrained(&dir, &format!("{env}/{model}")).map_err(rl_error)?;
        Self::load(py, path, i128::from(seed), assignment, assignment_hold)
    }

    /// The last evaluation recorded with the policy (the run's checkpoint, or the policy
    /// file's metadata) as the dict `meben eval` writes, or `None` before the first.
    #[getter]
    fn recorded_eval<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = serde_json::to_string(&self.recorded_eval)
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// Actions `[B, total_dof]` (float32 in [-1, 1]) of every team for observations `obs` (a
    /// dict as `env.step` returns): the mean actions if `deterministic`, else samples.
    /// Observations that are not float32 arrays of the scene's shapes, with no row (`B` =
    /// 0), or that hold NaN or infinity raise `ValueError` naming the array (and the first
    /// non-finite entry); a call while another thread is acting with this policy raises
    /// `RuntimeError` (each thread needs its own policy). A run whose learned task assignment
    /// is held for `k` steps (`assignment_hold_steps`) draws it at this policy's calls
    /// `0, k, 2k, ..` since it was loaded, and again whenever `B` changes; one held per
    /// episode (`assignment_hold_episode`) draws each row's at its first call and again
    /// after `end_episodes` marks the row's episode ended.
    #[pyo3(signature = (obs, deterministic=true))]
    fn act<'py>(&self, py: Python<'py>, obs: &Bound<'py, PyDict>, deterministic: bool) -> PyResult<Bound<'py, PyAny>> {
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
        if b == 0 {
            return Err(bad_argument(
                "obs[\"heading\"]",
                format!("an array of shape [0, {a}]"),
                "expected at least one row (observations of B >= 1 environments)",
            ));
        }
        let mut guard = try_lock(&self.acting, POLICY_IN_USE)?;
        let Acting { players, obs: [vectors, scalars, head], rows } = &mut *guard;
        *rows = b;
        let (vs, ss, hs) = ([b, n, 3, 3], [b, n, N_SCALARS], [b, a]);
        read_f32(&item(obs, "vectors")?, "obs[\"vectors\"]", &vs, vectors)?;
        read_f32(&item(obs, "scalars")?, "obs[\"scalars\"]", &ss, scalars)?;
        read_f32(&heading, "obs[\"heading\"]", &hs, head)?;
        check_finite(vectors, "obs[\"vectors\"]", &vs)?;
        check_finite(scalars, "obs[\"scalars\"]", &ss)?;
        check_finite(head, "obs[\"heading\"]", &hs)?;
        let mode = if deterministic { ActMode::Mean } else { ActMode::Sample };
        let raw = envs::layout::ObsRows::new(n, a, vectors.as_slice(), scalars.as_slice(), head.as_slice())
            .map_err(|e| bad_argument("obs", "arrays".to_string(), &e.to_string()))?;
        let mut joint = JointAction::new(b, self.n_actions, self.teams.len());
        let teams = &self.teams;
        pool::detach(py, || {
            for (team, (model, actor)) in teams.iter().zip(players.iter_mut()) {
                actor.mode = mode;
                // Mean actions take a learned task assignment's most likely value too.
                model.set_deterministic(deterministic);
                actor.act(model.as_mut(), &team.store, &team.norm, raw, &mut joint)?;
            }
            Ok(())
        })?
        .map_err(rl_error)?;
        let actions = joint.actions;
        array(py, &actions, &[b, self.n_actions])
    }

    /// Marks the rows whose episode ended at the last `act`'s step (`ended`: one bool per row
    /// of that call, e.g. `terminated | truncated` of a vector environment that resets
    /// itself): a run whose learned task assignment is held per episode
    /// (`assignment_hold_episode`) draws those rows' assignments again at the next `act`.
    /// No effect on other runs. `ended` of another length than the last `act`'s rows (or
    /// before any) raises `ValueError`; a call while another thread is acting raises
    /// `RuntimeError`.
    fn end_episodes(&self, ended: Vec<bool>) -> PyResult<()> {
        let mut guard = try_lock(&self.acting, POLICY_IN_USE)?;
        let Acting { players, rows, .. } = &mut *guard;
        if ended.len() != *rows {
            return Err(bad_argument(
                "ended",
                format!("{} values", ended.len()),
                &format!("expected one per row of the last act ({rows} rows)"),
            ));
        }
        for (_, actor) in players.iter_mut() {
            actor.hold.end_episodes(ended.iter().copied());
        }
        Ok(())
    }

    /// Plays `episodes` evaluation episodes of the run's teams, one per environment, each to
    /// its end, exactly as `meben eval` does with the same options, and returns its summary
    /// (the dict `meben eval` writes to `eval.json`: `success_rate`, `win_rate`,
    /// `draw_rate`, `mean_return`, `mean_length`, ...). `deterministic=None` takes the run's
    /// `eval_deterministic`; `fixed`, a `rotation_deg` or a `translation` `(x, y)` plays
    /// the fixed start of the run's seed, moved (the paper's equivariance test).
    /// `assignment_sensitivity=True` also measures how much each team's actions depend on
    /// its task assignment (`meben eval --assignment-sensitivity`; the summary's
    /// `assignment_sensitivity`). `assignment_values=True` also reads, at each episode's first
    /// step, the value of every assignment of a learned one beside the episode's returns
    /// (`meben eval --assignment-values`; the summary's `assignment_values`; a run directory
    /// only: a policy file holds no value network). The policy's own noise streams (`act`) are untouched. The
    /// GIL is released while playing; a `KeyboardInterrupt` abandons the evaluation and is
    /// raised.
    #[pyo3(signature = (episodes=1024, seed=rl::mappo::evaluate::DEFAULT_EVAL_SEED as i128, deterministic=None, fixed=false, rotation_deg=None, translation=None, assignment_sensitivity=false, assignment_values=false))]
    #[allow(clippy::too_many_arguments)]
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        episodes: usize,
        seed: i128,
        deterministic: Option<bool>,
        fixed: bool,
        rotation_deg: Option<f64>,
        translation: Option<(f64, f64)>,
        assignment_sensitivity: bool,
        assignment_values: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let seed = crate::seed::seed("seed", seed, u64::MAX)?;
        if assignment_values && self.run.is_file() {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "Policy.evaluate: assignment_values=True reads the value network, which the policy file {} does not \
                 hold (export-policy keeps what acting needs): load the run directory",
                self.run.display()
            )));
        }
        let request = EvalRequest {
            episodes,
            seed,
            deterministic,
            fixed,
            rotation_deg,
            translation: translation.map(|(x, y)| [x, y]),
        };
        let options = rl::mappo::evaluate::EvalOptions {
            assignment_sensitivity,
            assignment_values: assignment_values.then(|| rl::mappo::assignment_values::ReturnUnits::of(&self.config)),
            ..request.options(&self.config)
        };
        let (env, teams) = (&self.config.env, &self.teams);
        let stop = StopFlag::new();
        let stopping = "Policy.evaluate: interrupted: abandoning the evaluation";
        let (result, interrupt) =
            run_interruptible(py, &stop, stopping, || evaluate_unless_stopped(env, teams, &options, &stop))?;
        if let Some(e) = interrupt {
            return Err(e);
        }
        let mut summary = result
            .map_err(rl_error)?
            .ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("Policy.evaluate stopped without an interrupt"))?;
        self.assignment.record(&mut summary);
        let text =
            serde_json::to_string(&summary).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// The run directory or policy file the policy was loaded from.
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

/// The directory of shipped policies: the package's `meben/policies` (the wheel carries
/// it), else the repository's `policies/` this module was built from.
fn shipped_dir(py: Python<'_>) -> PyResult<std::path::PathBuf> {
    let file: std::path::PathBuf = py.import("meben")?.getattr("__file__")?.extract()?;
    let packaged = file.parent().map(|d| d.join("policies"));
    Ok(match packaged {
        Some(d) if d.join(rl::app::policy_file::MANIFEST).is_file() => d,
        _ => rl::app::policy_file::policies_dir(),
    })
}

impl PyPolicy {
    /// A policy of `teams` acting with the noise streams of `seed`.
    fn new(
        py: Python<'_>,
        run: std::path::PathBuf,
        config: TrainConfig,
        teams: Vec<Team>,
        recorded_eval: Option<rl::EvalSummary>,
        seed: u64,
        assignment: AssignmentOverride,
    ) -> PyResult<PyPolicy> {
        let scene =
            pool::detach(py, || envs::tasks::Scene::from_name(&config.env))?.map_err(crate::errors::task_error)?;
        let players = evaluation_actors(&teams, seed, ActMode::Sample);
        Ok(PyPolicy {
            run,
            recorded_eval,
            config,
            teams,
            assignment,
            acting: Mutex::new(Acting { players, obs: Default::default(), rows: 0 }),
            spec: scene.obs_spec,
            n_actions: scene.n_actions,
        })
    }
}
