//! `meben.Policy`: the trained teams of a run directory acting on observation dicts, with
//! the random streams of the Rust evaluation (`rl::evaluate`), so that a policy loaded with
//! seed `s` acts as `meben eval --seed s` does.

use envs::tasks::{N_SCALARS, ObsSpec};
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rand_chacha::ChaCha8Rng;
use rl::seeding::{derive_seed, stream};
use rl::team::{ActMode, ActScratch, act};
use rl::{RunDir, Team, TrainConfig};

use crate::arrays::{array, read_f32};
use crate::errors::{bad_argument, rl_error};

/// A trained run's policies (see `meben.Policy.load`).
#[pyclass(name = "Policy", module = "meben._core")]
pub struct PyPolicy {
    config: TrainConfig,
    teams: Vec<Team>,
    models: Vec<models::Model>,
    noise: Vec<Vec<ChaCha8Rng>>,
    spec: ObsSpec,
    n_actions: usize,
    scratch: ActScratch,
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
        let (config, teams) = py.detach(|| rl::checkpoint::load_policies(&RunDir::new(run))).map_err(rl_error)?;
        let scene = py.detach(|| envs::tasks::Scene::from_name(&config.env)).map_err(crate::errors::task_error)?;
        let mut models: Vec<_> = teams.iter().map(|t| t.model.clone()).collect();
        for (k, m) in models.iter_mut().enumerate() {
            m.reseed(derive_seed(seed, "evalasgn", k as u64, 0));
        }
        let noise = teams
            .iter()
            .map(|t| t.model.agents().iter().map(|&a| stream(seed, "evalnois", t.index as u64, a as u64)).collect())
            .collect();
        Ok(PyPolicy {
            config,
            teams,
            models,
            noise,
            spec: scene.obs_spec,
            n_actions: scene.n_actions,
            scratch: ActScratch::default(),
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
        let mut actions = vec![0.0f32; b * self.n_actions];
        let (teams, models, noise, spec, scratch) =
            (&self.teams, &mut self.models, &mut self.noise, &self.spec, &mut self.scratch);
        let raw = models::ObsRows::new(n, a, vectors.as_slice(), scalars.as_slice(), head.as_slice())
            .map_err(|e| bad_argument("obs", "arrays".to_string(), &e.to_string()))?;
        py.detach(|| {
            let (mut u, mut logp) = (vec![0.0f32; actions.len()], vec![0.0f32; b]);
            for (k, team) in teams.iter().enumerate() {
                act(
                    &mut models[k],
                    &team.store,
                    &team.norm,
                    spec,
                    raw,
                    mode,
                    &mut noise[k],
                    &mut actions,
                    &mut u,
                    &mut logp,
                    scratch,
                )?;
            }
            Ok(())
        })
        .map_err(rl_error)?;
        array(py, &actions, &[b, self.n_actions])
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
}
