//! Allocation limits: a buffer sized from a configuration is checked against the machine's
//! memory ([`envs::memory::machine_memory`]: `MemAvailable` of `/proc/meminfo`, else
//! `MemTotal`, or the process's own limit where that is smaller: `ulimit -v`, its control
//! group's) before it is allocated, so an impossible size is a clear error naming the
//! field instead of an abort in the allocator.
//!
//! [`check_run_fits`] adds up what a training holds at once, before anything of it is built:
//! its environments, its rollout and, while it evaluates, one environment per evaluation
//! episode (issue 44 item 2: `eval_episodes = 1048576` trained first and aborted at the first
//! evaluation, with no checkpoint, so that every resume repeated the crash).

use envs::layout::Observation;
use envs::memory::gigabytes;
use envs::tasks::{Scene, VecEnv};

use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;
use crate::mappo::rollout::Rollout;

/// Checks that `bytes` (`None`: more than `u128` can count) fit in this machine's memory;
/// the error gives the size and the machine's memory, saying which figure it is.
pub fn check_fits_in_memory(bytes: Option<u128>) -> std::result::Result<(), String> {
    envs::memory::check_fits(bytes)
}

/// Bytes one evaluation episode holds beside its environment: its start, its return,
/// length, outcome and liveness, its row of the joint action and of the policies' input and
/// output (`n_actions` actions; about 1 KB of the act step's own per-row buffers).
fn eval_episode_bytes(scene: &Scene) -> u128 {
    let start = scene.n_agents() * 24 + scene.spec.balls * 16 + 64;
    let tallies = 8 * scene.n_teams() + 4 + 16 + 1;
    let actions = 3 * 4 * scene.n_actions;
    (start + tallies + actions + 1024) as u128
}

/// What a training of `config` holds at once (module docs), in bytes: its environments,
/// its rollout, and its evaluation's environments (none if `num_evals` is 0). `None` past
/// `u128`.
pub struct RunFootprint {
    /// Estimated bytes of one environment of the scene ([`VecEnv::bytes_per_env`]).
    pub per_env: u128,
    /// The `num_envs` training environments.
    pub train_envs: Option<u128>,
    /// The rollout of an iteration ([`Rollout::bytes`]).
    pub rollout: Option<u128>,
    /// The `eval_episodes` environments of an evaluation, with their episodes' tallies.
    pub eval: Option<u128>,
}

impl RunFootprint {
    /// The footprint of `config` (its scene is built to probe it; nothing of the run is).
    pub fn of(config: &TrainConfig) -> Result<RunFootprint> {
        let scene = Scene::from_name(&config.env)?;
        let per_env = VecEnv::bytes_per_env(&scene) as u128;
        let train_envs = per_env.checked_mul(config.num_envs as u128);
        let rollout = Rollout::bytes(
            config.unrolls_per_iteration(),
            config.unroll_length,
            config.num_envs,
            &Observation::zeros(&scene.obs_spec, 1),
            scene.n_actions,
            scene.n_teams(),
        );
        let eval = if config.num_evals == 0 {
            Some(0)
        } else {
            (per_env + eval_episode_bytes(&scene)).checked_mul(config.eval_episodes as u128)
        };
        Ok(RunFootprint { per_env, train_envs, rollout, eval })
    }

    /// Everything together.
    pub fn total(&self) -> Option<u128> {
        self.train_envs?.checked_add(self.rollout?)?.checked_add(self.eval?)
    }
}

/// Refuses a training of `config` whose [`RunFootprint`] is more than the machine's memory,
/// before anything is built: the error names the field that asks for the most
/// (`eval_episodes`, `num_envs` or `batch_size`), each part's estimate and the machine's
/// memory.
pub fn check_run_fits(config: &TrainConfig) -> Result<()> {
    let f = RunFootprint::of(config)?;
    let Err(why) = check_fits_in_memory(f.total()) else { return Ok(()) };
    let show = |b: Option<u128>| b.map_or_else(|| "more than can be counted".to_string(), gigabytes);
    let parts = [
        ("num_envs", config.num_envs, f.train_envs),
        ("batch_size", config.batch_size, f.rollout),
        ("eval_episodes", config.eval_episodes, f.eval),
    ];
    let (field, value, _) = parts.iter().max_by_key(|(_, _, b)| b.unwrap_or(u128::MAX)).copied().unwrap_or(parts[0]);
    Err(RlError::config(
        "config",
        field,
        value,
        format!(
            "this training of {} {why}: {} environments at about {} each ({}), the rollout of an iteration of {} env \
             steps ({}), and {} evaluation episodes, one environment each ({}); all are held at once",
            config.env,
            config.num_envs,
            gigabytes(f.per_env),
            show(f.train_envs),
            config.steps_per_iteration(),
            show(f.rollout),
            if config.num_evals == 0 { 0 } else { config.eval_episodes },
            show(f.eval),
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_beyond_the_machine_are_refused() {
        check_fits_in_memory(Some(1 << 20)).unwrap();
        if let Some(m) = envs::memory::machine_memory() {
            let e = check_fits_in_memory(Some(1 << 100)).unwrap_err();
            assert!(e.contains("GB") && e.contains(&m.source), "{e}");
        }
        assert!(check_fits_in_memory(None).is_err());
    }
}
