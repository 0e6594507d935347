//! `env.spec`: what a scene is made of, as a plain dict (nodes, agents, teams, each agent's
//! action slice), read from the Rust `Scene` and its `ObsSpec`.

use envs::layout::N_SCALARS;
use envs::tasks::spec::CONTROL_DT;
use envs::tasks::{Scene, TaskKind};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The scene's description (keys documented in `meben.VecEnv.spec`).
pub fn spec_dict<'py>(py: Python<'py>, scene: &Scene) -> PyResult<Bound<'py, PyDict>> {
    let s = &scene.obs_spec;
    let d = PyDict::new(py);
    d.set_item("name", &scene.spec.name)?;
    d.set_item("kind", if scene.kind() == TaskKind::Reach { "team_reach" } else { "team_sumo" })?;
    d.set_item("num_nodes", s.n_nodes)?;
    d.set_item("num_scalars", N_SCALARS)?;
    d.set_item("num_agents", s.n_agents)?;
    d.set_item("num_teams", s.n_teams)?;
    d.set_item("num_balls", s.n_balls)?;
    d.set_item("total_dof", scene.n_actions)?;
    d.set_item("radius", scene.spec.radius)?;
    d.set_item("episode_steps", scene.spec.episode_steps)?;
    d.set_item("control_dt", CONTROL_DT)?;
    let morph: Vec<&str> = scene.agents.iter().map(|a| a.morphology.as_str()).collect();
    d.set_item("agent_morphology", morph)?;
    d.set_item("agent_team", &s.agent_team)?;
    d.set_item("agent_dof", &s.agent_dof)?;
    d.set_item("agent_action_offset", &s.agent_action_offset)?;
    let slices: Vec<(usize, usize)> =
        s.agent_action_offset.iter().zip(&s.agent_dof).map(|(&o, &n)| (o, o + n)).collect();
    d.set_item("agent_action_slice", slices)?;
    d.set_item("agent_root_node", &s.agent_root_node)?;
    let teams: Vec<Vec<usize>> =
        (0..s.n_teams).map(|t| (0..s.n_agents).filter(|&a| s.agent_team[a] == t).collect()).collect();
    d.set_item("team_agents", teams)?;
    d.set_item("entity_root_node", &s.entity_root_node)?;
    d.set_item("node_agent", &s.node_agent)?;
    d.set_item("node_team", &s.node_team)?;
    d.set_item("node_parent", &s.node_parent)?;
    d.set_item("node_is_root", &s.node_is_root)?;
    Ok(d)
}
