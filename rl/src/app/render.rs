//! Recording an episode of trained teams for `meben render` (an HTML animation, a GIF or a
//! CSV of body poses: `envs::tasks::render`), every team acting through its own
//! [`Actor`] with the rendering's noise streams. The task assignment each team's policy
//! acted on at every step is recorded with the frames, for the player to mark.

use crate::error::{Result, RlError};
use crate::mappo::actor::{ActMode, Actor, JointAction};
use crate::mappo::seeding::stream;
use crate::mappo::team::Team;
use models::{AssignmentMethod, GraphBuilder, NO_AGENT};

/// How team `t`'s task assignment ([`models::PolicyOutput::assignment`] of one scene: for
/// each object of the team's view, the index of its agent among the team's agents, or
/// [`NO_AGENT`]) maps onto scene entities: the entity indices of the team's agents and of
/// the objects ([`GraphBuilder::assignment_entities`]). `None` for a policy without a task
/// assignment, or one whose assignment has another layout (a custom policy's).
fn assignment_layout(t: &Team) -> Option<(Vec<usize>, Vec<usize>)> {
    let width = t.model.assignment_width();
    if width == 0 {
        return None;
    }
    let builder = GraphBuilder::new(t.model.spec(), AssignmentMethod::Greedy, t.model.team(), 0).ok()?;
    let (own, objects) = builder.assignment_entities();
    (objects.len() == width).then(|| (own.to_vec(), objects.to_vec()))
}

/// Writes into `row` (one entry per scene agent) the entity each of a team's agents is
/// assigned to by its one-scene `assignment`, laid out as `layout` says.
fn mark_assignment(row: &mut [Option<usize>], (own, objects): &(Vec<usize>, Vec<usize>), assignment: &[u32]) {
    for (&object, &i) in objects.iter().zip(assignment) {
        if let Some(&agent) = own.get(i as usize).filter(|_| i != NO_AGENT) {
            row[agent] = Some(object);
        }
    }
}

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
            let mut actor = Actor::new(mode, noise);
            actor.hold.set_rule(t.actor.hold.rule());
            actor
        })
        .collect();
    let mut joint = JointAction::new(1, scene.n_actions, teams.len());
    let layouts: Vec<Option<(Vec<usize>, Vec<usize>)>> = teams.iter().map(assignment_layout).collect();
    let mut assigned: Vec<Vec<Option<usize>>> = Vec::new();
    let mut traj = envs::tasks::render::record_episode(env, seed, steps, |obs, actions| {
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
        if layouts.iter().any(Option::is_some) {
            let mut row = vec![None; scene.n_agents()];
            for (layout, t) in layouts.iter().zip(teams.iter()) {
                if let (Some(layout), Some(assignment)) = (layout, joint.assignment.get(t.model.team())) {
                    mark_assignment(&mut row, layout, assignment);
                }
            }
            assigned.push(row);
        }
    })?;
    traj.set_assignments(assigned)?;
    Ok(traj)
}
