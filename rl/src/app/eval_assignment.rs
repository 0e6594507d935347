//! `meben eval --assignment RULE`: a trained policy evaluated with another task-assignment
//! rule than the one it was trained with, on the same parameters and normaliser. It asks
//! how much a trained policy relies on its rule (the paper's Limitations: assignment and
//! equivariance depend on each other): an SHNN trained with Algorithm 1's greedy rule,
//! evaluated with the least-total-distance matching or with a random one-to-one assignment.
//!
//! [`hold`] (`--assignment-hold K`) holds a random assignment for `K` steps: with
//! `stochastic` and `K` the episode's length, one random assignment an episode.
//!
//! Only the one-to-one rules that change nothing but the links are offered: `greedy`,
//! `hungarian` and `stochastic`. `none` is refused (it changes the graph and the model's
//! translation default, not only the links) and so is `learned` (its scorer is parameters
//! a policy trained without it does not have). A policy trained with `learned` takes
//! `greedy` only: Algorithm 1 in place of its scorer's draws, as in its warm-up (the scorer
//! kept, unused), which asks whether what its scorer learned helps the actions it learned
//! with; with [`hold`], Algorithm 1's assignment at the drawing steps, held (per episode as
//! a run that held its draws per episode acted).

use models::{AssignmentMethod, ModelDescription};

use crate::mappo::assignment_hold::HoldRule;
use crate::mappo::config::TrainConfig;
use crate::mappo::team::Team;

/// The rules `--assignment` takes.
pub const RULES: [&str; 3] = ["greedy", "hungarian", "stochastic"];

/// An error naming the flag and the value unless `rule` is one of [`RULES`].
pub fn check_rule(rule: &str) -> Result<(), String> {
    if RULES.contains(&rule) {
        return Ok(());
    }
    Err(format!(
        "--assignment {rule}: expected one of {} (the one-to-one rules that change only the links)",
        RULES.join(", ")
    ))
}

/// `model` (a model string, `name` or `name:key=value;...`) with its `assignment` option set
/// to `rule`, every other option kept. `None` where the model has no task assignment.
pub fn with_assignment(model: &str, rule: &str) -> Result<Option<String>, String> {
    let d = ModelDescription::parse(model).map_err(|e| format!("model `{model}`: {e}"))?;
    let Some(own) = d.assignment() else { return Ok(None) };
    if own.method == AssignmentMethod::Learned {
        return Err(format!(
            "--assignment {rule}: model `{model}` learned its assignment; its parameters include the scorer, \
             so it is evaluated with its own draws only"
        ));
    }
    let (name, options) = model.split_once(':').unwrap_or((model, ""));
    let mut kept: Vec<&str> = options
        .split(';')
        .filter(|o| !o.is_empty() && o.split('=').next().map(str::trim) != Some("assignment"))
        .collect();
    let set = format!("assignment={rule}");
    kept.push(&set);
    Ok(Some(format!("{name}:{}", kept.join(";"))))
}

/// Whether `model` (a model string) learns its task assignment (`assignment=learned`).
fn learns(model: &str) -> Result<bool, String> {
    let d = ModelDescription::parse(model).map_err(|e| format!("model `{model}`: {e}"))?;
    Ok(d.assignment().is_some_and(|a| a.method == AssignmentMethod::Learned))
}

/// `teams` (of a run or policy file of `config`) with the assignment rule `rule` in place of
/// their own: only each team's model is rebuilt; its parameters (checked to fit the new
/// model), normaliser and streams stay. A team that learned its assignment takes `greedy`
/// only, by its warm-up (Algorithm 1 at every step, its scorer unused; module docs). Teams
/// without a task assignment are kept as they are; errors name the flag, the rule and the
/// model.
pub fn reassign(config: &TrainConfig, teams: &mut [Team], rule: &str) -> Result<(), String> {
    check_rule(rule)?;
    let mut swapped = config.clone();
    let mut any = false;
    let mut fields = vec![(&config.model, &mut swapped.model)];
    if !config.opponent.is_empty() {
        fields.push((&config.opponent, &mut swapped.opponent));
    }
    for (own, new) in fields {
        if learns(own)? {
            if rule != "greedy" {
                return Err(format!(
                    "--assignment {rule}: model `{own}` learned its assignment; only greedy (Algorithm 1, \
                     as in its warm-up) takes the place of its scorer's draws"
                ));
            }
            any = true;
        } else if let Some(m) = with_assignment(own, rule)? {
            *new = m;
            any = true;
        }
    }
    if !any {
        return Err(format!("--assignment {rule}: no team's model (`{}`) has a task assignment", config.model));
    }
    let spec = envs::tasks::Scene::from_name(&config.env).map_err(|e| e.to_string())?.obs_spec;
    for team in teams.iter_mut() {
        let k = team.index;
        if learns(config.team_model(k))? {
            team.model.set_assignment_warmup(true);
            team.actor.hold.set_rule(HoldRule::Steps(1));
            continue;
        }
        if swapped.team_model(k) == config.team_model(k) {
            continue;
        }
        let mut fresh = Team::build(&swapped, &spec, k).map_err(|e| e.to_string())?;
        let state = nn::StateDict::from_store(&team.store).map_err(|e| e.to_string())?;
        state.load_into(&mut fresh.store).map_err(|e| {
            format!("--assignment {rule}: team {k}'s parameters do not fit `{}`: {e}", swapped.team_model(k))
        })?;
        team.model = fresh.model;
    }
    Ok(())
}

/// What `meben eval --assignment` and `--assignment-hold` (Python: `Policy.load`'s
/// `assignment` and `assignment_hold`) change of a trained policy: one place applies them to
/// its teams and records them in an evaluation's summary.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AssignmentOverride {
    /// The rule in place of the teams' own ([`reassign`]).
    pub rule: Option<String>,
    /// The steps a random assignment is held for in place of the run's own ([`hold`]).
    pub hold: Option<usize>,
}

impl AssignmentOverride {
    /// Applies the rule, then the hold, to `teams` of a run of `config`.
    pub fn apply(&self, config: &TrainConfig, teams: &mut [Team]) -> Result<(), String> {
        if let Some(rule) = &self.rule {
            reassign(config, teams, rule)?;
        }
        if let Some(every) = self.hold {
            hold(teams, every)?;
        }
        Ok(())
    }

    /// Records the override in an evaluation's summary (its `assignment` and
    /// `assignment_hold`, not written when absent).
    pub fn record(&self, summary: &mut crate::mappo::evaluate::EvalSummary) {
        summary.assignment = self.rule.clone();
        summary.assignment_hold = self.hold;
    }
}

/// Holds each random task assignment of `teams` (a `stochastic` or `learned` one) for
/// `every` steps instead of their own hold (`meben eval --assignment-hold`): drawn at an
/// evaluation's steps `0, every, 2 every, ...` and given back in between, so `every` at
/// least the episode's length draws one assignment an episode. Errors name the flag and
/// the value, or the models, where no team draws its assignment.
pub fn hold(teams: &mut [Team], every: usize) -> Result<(), String> {
    if every == 0 {
        return Err("--assignment-hold 0: an assignment is held for at least 1 step".into());
    }
    let mut any = false;
    for t in teams.iter_mut().filter(|t| t.model.assignment_is_random()) {
        t.actor.hold.set_rule(HoldRule::Steps(every));
        any = true;
    }
    if !any {
        let models: Vec<&str> = teams.iter().map(|t| t.model.name()).collect();
        return Err(format!(
            "--assignment-hold {every}: no team draws its assignment at random ({}); \
             give --assignment stochastic, or a run with assignment=learned",
            models.join(", ")
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_assignment_option_is_set_and_the_others_kept() {
        assert_eq!(with_assignment("shnn", "hungarian").unwrap().as_deref(), Some("shnn:assignment=hungarian"));
        assert_eq!(
            with_assignment("mlp_hn:assignment=hungarian;seed=3", "stochastic").unwrap().as_deref(),
            Some("mlp_hn:seed=3;assignment=stochastic")
        );
        // The result parses, to the rule asked for.
        let m = with_assignment("shnn:gravity=every_layer", "stochastic").unwrap().unwrap();
        let d = ModelDescription::parse(&m).unwrap();
        assert_eq!(d.assignment().unwrap().method, AssignmentMethod::Stochastic);
    }

    #[test]
    fn a_model_without_an_assignment_or_with_a_learned_one_is_not_swapped() {
        // (A learned one takes `greedy` by its warm-up instead, [`reassign`].)
        assert_eq!(with_assignment("transformer_hn", "greedy").unwrap(), None);
        let e = with_assignment("mlp_hn:assignment=learned", "greedy").unwrap_err();
        assert!(
            e.contains("--assignment greedy") && e.contains("mlp_hn:assignment=learned") && e.contains("scorer"),
            "{e}"
        );
    }
}
