//! `meben info`: each team's parameter counts by part (the paper's Table "Comparison of
//! Models": its figures are the policies'), without training anything.

use envs::tasks::Scene;
use models::{Model, ModelDescription, ParamCounts};
use nn::ParamStore;

use crate::error::{Result, RlError};

/// The parameter counts of `model` (a model specification, e.g. `shnn:critic=shared`) built
/// for team `team` of `env`.
pub fn param_counts(env: &str, model: &str, team: usize) -> Result<ParamCounts> {
    let spec = Scene::from_name(env).map_err(|e| RlError::config("command line", "env", env, e.to_string()))?.obs_spec;
    let config =
        ModelDescription::parse(model).map_err(|e| RlError::config("command line", "model", model, e.to_string()))?;
    let mut store = ParamStore::<f32>::new();
    let mut init = nn::init_rng(0);
    let built = Model::new(&mut store.scope(&format!("team{team}"), &mut init), &config, &spec, team)
        .map_err(|e| RlError::config("command line", "model", model, e.to_string()))?;
    Ok(built.param_counts(&store))
}

/// One line per model and team of `env`: `<model> policy_params=N critic_params=M` (with
/// ` team=1` for Team Sumo's second team, which plays `opponent` if given, else the model).
pub fn info_lines(env: &str, models: &[String], opponent: Option<&str>) -> Result<Vec<String>> {
    let teams =
        Scene::from_name(env).map_err(|e| RlError::config("command line", "env", env, e.to_string()))?.obs_spec.n_teams;
    if opponent.is_some() && teams < 2 {
        return Err(RlError::config(
            "command line",
            "opponent",
            opponent.unwrap_or(""),
            "only Team Sumo has a second team",
        ));
    }
    let mut lines = Vec::new();
    for model in models {
        for team in 0..teams {
            let m = if team == 1 { opponent.unwrap_or(model) } else { model.as_str() };
            let c = param_counts(env, m, team)?;
            let tag = if team > 0 { format!(" team={team}") } else { String::new() };
            lines.push(format!("{m} policy_params={} critic_params={}{tag}", c.policy, c.critic));
        }
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_of_the_paper_table_and_errors() {
        let models = ["shnn".to_string(), "mlp_hn".to_string()];
        let lines = info_lines("team_reach/3_ant_claw_centipede", &models, None).unwrap();
        assert_eq!(
            lines,
            ["shnn policy_params=783244 critic_params=471201", "mlp_hn policy_params=1759116 critic_params=264257"]
        );
        let sumo = info_lines("team_sumo/2_ants", &["shnn".into()], Some("mlp_hn")).unwrap();
        assert_eq!(sumo.len(), 2);
        assert!(
            sumo[0].starts_with("shnn policy_params=")
                && sumo[1].starts_with("mlp_hn ")
                && sumo[1].ends_with(" team=1")
        );
        let e = info_lines("team_reach/9_ants", &models, None).unwrap_err().to_string();
        assert!(e.contains("env") && e.contains("9_ants"), "{e}");
        let e = info_lines("team_reach/1_ant", &["resnet".into()], None).unwrap_err().to_string();
        assert!(e.contains("model") && e.contains("resnet"), "{e}");
        assert!(info_lines("team_reach/1_ant", &models, Some("mlp")).is_err());
    }
}
