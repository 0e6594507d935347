//! Recording an episode of trained teams for `meben render` (an HTML animation, a GIF or a
//! CSV of body poses: `envs::tasks::render`), every team acting through its own
//! [`Actor`] with the rendering's noise streams.

use crate::error::{Result, RlError};
use crate::mappo::actor::{ActMode, Actor, JointAction};
use crate::mappo::seeding::stream;
use crate::mappo::team::Team;

/// Records one episode of `env` from the fixed start of `seed` played by `teams` (mean
/// actions if `deterministic`), for rendering. A failure of the policy ends the episode and
/// is stored in `failure`.
pub fn record_episode(
    env: &str,
    teams: &mut [Team],
    seed: u64,
    steps: usize,
    deterministic: bool,
    failure: &mut Option<RlError>,
) -> Result<envs::tasks::render::Trajectory> {
    let scene = envs::tasks::Scene::from_name(env)?;
    let mode = if deterministic { ActMode::Mean } else { ActMode::Sample };
    // Mean actions take a learned task assignment's most likely value too.
    teams.iter_mut().for_each(|t| t.model.set_deterministic(deterministic));
    let mut actors: Vec<Actor> = teams
        .iter()
        .map(|t| {
            let noise = t.model.agents().iter().map(|&a| stream(seed, "rendnois", t.index as u64, a as u64)).collect();
            Actor::new(mode, noise)
        })
        .collect();
    let mut joint = JointAction::new(1, scene.n_actions, teams.len());
    let traj = envs::tasks::render::record_episode(env, seed, steps, |obs, actions| {
        if failure.is_some() {
            return;
        }
        for (actor, t) in actors.iter_mut().zip(teams.iter_mut()) {
            if let Err(e) = actor.act(t.model.as_mut(), &t.store, &t.norm, obs.rows(), &mut joint) {
                *failure = Some(e);
                actions.iter_mut().for_each(|a| *a = 0.0);
                return;
            }
        }
        actions.copy_from_slice(&joint.actions);
    })?;
    Ok(traj)
}
