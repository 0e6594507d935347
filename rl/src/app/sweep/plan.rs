//! The plan of a sweep: its runs, the cross product of its lists in a fixed order, each
//! named and its configuration resolved ([`Sweep::runs`]).

use std::collections::BTreeSet;

use crate::app::names::sanitize_component;
use crate::app::sweep::{Sweep, Variant};
use crate::error::{Result, RlError};
use crate::mappo::config::TrainConfig;

/// One run of a sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepRun {
    /// The run directory relative to the sweep's output directory, e.g.
    /// `team_reach_1_ant/shnn+no_entropy/seed0`.
    pub name: String,
    /// The resolved configuration.
    pub config: TrainConfig,
}

impl Sweep {
    /// Every run of the sweep, in the order of the module docs, each configuration resolved
    /// and validated (errors name the sweep file and the run).
    pub fn runs(&self) -> Result<Vec<SweepRun>> {
        let mut variants: Vec<Option<&Variant>> = Vec::new();
        if self.include_base {
            variants.push(None);
        }
        variants.extend(self.variants.iter().map(Some));
        let mut runs = Vec::new();
        let mut names = BTreeSet::new();
        for env in &self.envs {
            for model in &self.models {
                for variant in &variants {
                    for &seed in &self.seeds {
                        let suffix = variant.map(|v| format!("+{}", v.name)).unwrap_or_default();
                        let name =
                            format!("{}/{}{suffix}/seed{seed}", sanitize_component(env), sanitize_component(model));
                        let mut ov = self.config.clone();
                        if let Some(v) = variant {
                            ov.extend(v.config.iter().cloned());
                        }
                        ov.push(("env".into(), toml::Value::String(env.clone()).to_string()));
                        ov.push(("model".into(), toml::Value::String(model.clone()).to_string()));
                        ov.push(("seed".into(), seed.to_string()));
                        let config = TrainConfig::resolve(Some(self.preset), None, &ov)
                            .map_err(|e| in_run(e, &self.source, &name))?;
                        if !names.insert(name.clone()) {
                            return Err(RlError::config(
                                &self.source,
                                "models",
                                model,
                                format!(
                                    "two runs would share the directory {name}: env or model names that differ \
                                     only in characters replaced in directory names (: ; = / and others)"
                                ),
                            ));
                        }
                        runs.push(SweepRun { name, config });
                    }
                }
            }
        }
        Ok(runs)
    }
}

/// Puts the sweep file and the run into a configuration error's source.
fn in_run(e: RlError, source: &str, run: &str) -> RlError {
    match e {
        RlError::Config { field, value, message, .. } => {
            RlError::Config { source: format!("{source} (run {run})"), field, value, message }
        }
        e => e,
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::app::presets::Preset;
    use crate::app::sweep::EXAMPLE;

    #[test]
    fn expands_in_the_documented_order() {
        let sweep = Sweep::parse(EXAMPLE, "example.toml").unwrap();
        let runs = sweep.runs().unwrap();
        assert_eq!(runs.len(), 2 * 3 * 2 * 3);
        assert_eq!(runs[0].name, "team_reach_1_ant/shnn/seed0");
        assert_eq!(runs[2].name, "team_reach_1_ant/shnn/seed2");
        assert_eq!(runs[3].name, "team_reach_1_ant/shnn+no_entropy/seed0");
        assert_eq!(runs[6].name, "team_reach_1_ant/mlp_hn/seed0");
        assert_eq!(runs[12].name, "team_reach_1_ant/shnn_assignment-hungarian/seed0");
        assert_eq!(runs[18].name, "team_reach_2_ants/shnn/seed0");
        let r = &runs[4];
        assert_eq!((r.config.env.as_str(), r.config.model.as_str(), r.config.seed), ("team_reach/1_ant", "shnn", 1));
        assert_eq!(r.config.entropy_coef, 0.0);
        assert_eq!(r.config.num_envs, 128);
        assert_eq!(r.config.steps, 50_000_000);
        assert_eq!(runs[0].config.entropy_coef, 1e-2);
        assert_eq!(runs[12].config.model, "shnn:assignment=hungarian");
        // The paper preset is the default.
        assert_eq!(runs[0].config.batch_size, 1024);

        let no_base = EXAMPLE.replace("preset = \"paper\"", "include_base = false");
        let runs = Sweep::parse(&no_base, "x").unwrap().runs().unwrap();
        assert_eq!(runs.len(), 2 * 3 * 3);
        assert!(runs.iter().all(|r| r.name.contains("+no_entropy")));
    }

    #[test]
    fn shipped_sweeps_parse_and_expand() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps");
        let mut found = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let runs = Sweep::load(&path).unwrap().runs().unwrap();
                assert!(!runs.is_empty());
                found += 1;
            }
        }
        assert!(found >= 2);
        let table = Sweep::load(&dir.join("team_reach_table.toml")).unwrap();
        let runs = table.runs().unwrap();
        assert_eq!(runs.len(), 6 * 4 * 3);
        assert!(runs.iter().all(|r| r.config.steps == 50_000_000 && r.config.num_envs == 2048));
        let reach: Vec<&str> =
            envs::tasks::BUILTIN_NAMES.iter().copied().filter(|n| n.starts_with("team_reach")).collect();
        assert_eq!(table.envs, reach);
        let ablation = Sweep::load(&dir.join("ablation_assignment.toml")).unwrap().runs().unwrap();
        assert!(ablation.iter().any(|r| r.config.model == "shnn:assignment=stochastic"));
        assert!(ablation.iter().any(|r| r.config.model == "hnn_dn"));

        // The reproduction (docs/RESULTS.md): the paper preset but for the budget and the number of
        // evaluations, sampled-action evaluation on 1024 episodes.
        let repro_evals = |name: &str, runs: usize, steps: u64, num_evals: usize| {
            let runs_of = Sweep::load(&dir.join(name)).unwrap().runs().unwrap();
            assert_eq!(runs_of.len(), runs, "{name}");
            for r in &runs_of {
                let paper = TrainConfig::preset(Preset::Paper, &r.config.env);
                let expected = TrainConfig {
                    model: r.config.model.clone(),
                    seed: r.config.seed,
                    steps,
                    num_evals,
                    checkpoint_every: 1,
                    opponent: r.config.opponent.clone(),
                    fixed_start: r.config.fixed_start,
                    eval_rotations: r.config.eval_rotations.clone(),
                    ..paper
                };
                assert_eq!(r.config, expected, "{name}: {}", r.name);
                assert!(!r.config.eval_deterministic && r.config.eval_episodes == 1024);
            }
            runs_of
        };
        let repro = |name: &str, runs: usize, steps: u64| repro_evals(name, runs, steps, 10);
        for name in ["repro_reach_1_ant.toml", "repro_reach_2_ants.toml"] {
            let runs = repro(name, 6, if name.contains("2_ants") { 20_000_000 } else { 10_000_000 });
            let seeds: Vec<u64> = runs.iter().map(|r| r.config.seed).collect();
            assert_eq!(seeds, [0, 1, 2, 0, 1, 2]);
        }
        let eq = repro("repro_equivariance.toml", 9, 10_000_000);
        assert!(eq.iter().all(|r| r.config.fixed_start && r.config.eval_rotations == [0.0, 180.0]));
        // Its 2_ants half (issue 78): MLP and MLP+HN, an evaluation every 2M env steps.
        let eq = repro_evals("repro_equivariance_2_ants.toml", 6, 10_000_000, 5);
        assert!(eq.iter().all(|r| r.config.fixed_start && r.config.eval_rotations == [0.0, 180.0]));
        let models: Vec<&str> = eq.iter().map(|r| r.config.model.as_str()).collect();
        assert_eq!(models, ["mlp", "mlp", "mlp", "mlp_hn", "mlp_hn", "mlp_hn"]);
        let sumo = repro("repro_sumo.toml", 1, 10_000_000);
        assert_eq!((sumo[0].config.model.as_str(), sumo[0].config.opponent.as_str()), ("shnn", "mlp_hn"));
        // Issue 79's Team Sumo run: the same run but for team 0's assignment.
        let learned_sumo = repro("learned_assignment_sumo.toml", 1, 10_000_000);
        let expected = TrainConfig { model: "shnn:assignment=learned".into(), ..sumo[0].config.clone() };
        assert_eq!(learned_sumo[0].config, expected);
        assert_eq!(learned_sumo[0].name, "team_sumo_2_ants/shnn_assignment-learned/seed0");
        // Its follow-up without the assignment's entropy bonus: learned_assignment.toml's
        // MLP+HN runs but for `assignment_entropy_scale`.
        let learned = Sweep::load(&dir.join("learned_assignment.toml")).unwrap().runs().unwrap();
        let no_bonus = Sweep::load(&dir.join("learned_assignment_entropy.toml")).unwrap().runs().unwrap();
        assert_eq!(no_bonus.len(), 3);
        for (r, l) in no_bonus.iter().zip(&learned[..3]) {
            assert_eq!(l.config.model, "mlp_hn:assignment=learned");
            assert_eq!(r.config, TrainConfig { assignment_entropy_scale: 0.0, ..l.config.clone() }, "{}", r.name);
            let name = l.name.replace("/seed", "+no_assignment_bonus/seed");
            assert_eq!(r.name, name);
        }
        // Its follow-up with the draw held for an unroll: the same runs but for the hold.
        let hold = Sweep::load(&dir.join("learned_assignment_hold.toml")).unwrap().runs().unwrap();
        assert_eq!(hold.len(), 3);
        for (r, l) in hold.iter().zip(&learned[..3]) {
            assert_eq!(r.config, TrainConfig { assignment_hold_steps: 5, ..l.config.clone() }, "{}", r.name);
            assert_eq!(r.config.assignment_hold_steps as usize, r.config.unroll_length);
            assert_eq!(r.name, l.name.replace("/seed", "+hold_5/seed"));
        }
        // And with the draw held for each episode.
        let episode = Sweep::load(&dir.join("learned_assignment_episode.toml")).unwrap().runs().unwrap();
        assert_eq!(episode.len(), 3);
        for (r, l) in episode.iter().zip(&learned[..3]) {
            assert_eq!(r.config, TrainConfig { assignment_hold_episode: true, ..l.config.clone() }, "{}", r.name);
            assert_eq!(r.name, l.name.replace("/seed", "+hold_episode/seed"));
        }
        // And with a value that reads the held assignment: the same runs but for the model.
        let critic = Sweep::load(&dir.join("learned_assignment_critic.toml")).unwrap().runs().unwrap();
        assert_eq!(critic.len(), 3);
        for (r, e) in critic.iter().zip(&episode) {
            let model = "mlp_hn:assignment=learned;assign_critic=held".to_string();
            assert_eq!(r.config, TrainConfig { model, ..e.config.clone() }, "{}", r.name);
            assert_eq!(r.name, e.name.replace("learned+", "learned_assign_critic-held+"));
        }
        // And with the expected assignment gradient: the same runs but for the gradient.
        let expected = Sweep::load(&dir.join("learned_assignment_expected.toml")).unwrap().runs().unwrap();
        assert_eq!(expected.len(), 3);
        for (r, c) in expected.iter().zip(&critic) {
            let gradient = crate::AssignmentGradient::Expected;
            assert_eq!(r.config, TrainConfig { assignment_gradient: gradient, ..c.config.clone() }, "{}", r.name);
            assert_eq!(r.name, c.name.replace("+hold_episode/", "+hold_episode_expected/"));
        }
        // And with the value fitted at the drawing steps: the same runs but for that field.
        let at_draw = Sweep::load(&dir.join("learned_assignment_value_at_draw.toml")).unwrap().runs().unwrap();
        assert_eq!(at_draw.len(), 3);
        for (r, e) in at_draw.iter().zip(&expected) {
            assert_eq!(r.config, TrainConfig { assignment_value_at_draw: true, ..e.config.clone() }, "{}", r.name);
            assert_eq!(r.name, e.name.replace("_expected/", "_expected_at_draw/"));
        }
        // And with each draw credited with its episode's return: the runs held per episode
        // but for the gradient.
        let credit = Sweep::load(&dir.join("learned_assignment_episode_credit.toml")).unwrap().runs().unwrap();
        assert_eq!(credit.len(), 3);
        for (r, e) in credit.iter().zip(&episode) {
            let gradient = crate::AssignmentGradient::Episode;
            assert_eq!(r.config, TrainConfig { assignment_gradient: gradient, ..e.config.clone() }, "{}", r.name);
            assert_eq!(r.name, e.name.replace("+hold_episode/", "+hold_episode_credit/"));
        }
        // Its follow-up with a warm-up: the same runs but for the warm-up and a longer budget,
        // whose first 16M env steps are greedy MLP+HN's (the seeds of repro_reach_2_ants.toml).
        let warmup = Sweep::load(&dir.join("learned_assignment_warmup.toml")).unwrap().runs().unwrap();
        let greedy = repro("repro_reach_2_ants.toml", 6, 20_000_000);
        assert_eq!(warmup.len(), 3);
        for ((r, l), g) in warmup.iter().zip(&learned[..3]).zip(&greedy[3..]) {
            let expected = TrainConfig {
                assignment_warmup_steps: 16_000_000,
                steps: 26_000_000,
                num_evals: 13,
                ..l.config.clone()
            };
            assert_eq!(r.config, expected, "{}", r.name);
            assert_eq!(r.name, l.name.replace("/seed", "+warmup_16m/seed"));
            let as_greedy = TrainConfig { model: "mlp_hn".into(), assignment_warmup_steps: 0, ..r.config.clone() };
            assert_eq!(TrainConfig { steps: g.config.steps, num_evals: g.config.num_evals, ..as_greedy }, g.config);
        }

        // The diagnostics beside experiment 1b: each changes one thing of `mlp_hn` on 2_ants.
        let load = |name: &str| Sweep::load(&dir.join(name)).unwrap().runs().unwrap();
        let base = &repro("repro_reach_2_ants.toml", 6, 20_000_000)[3].config;
        assert_eq!((base.model.as_str(), base.seed), ("mlp_hn", 0));
        let no_assignment = load("repro_reach_2_ants_no_assignment.toml");
        assert_eq!(no_assignment.len(), 1);
        let expected = TrainConfig { model: "mlp_hn:assignment=none".into(), ..base.clone() };
        assert_eq!(no_assignment[0].config, expected);
        let per_slot = load("repro_reach_2_ants_per_slot_starts.toml");
        assert_eq!(per_slot.len(), 1);
        let expected = TrainConfig { train_starts: crate::mappo::config::TrainStarts::PerSlot, ..base.clone() };
        assert_eq!(per_slot[0].config, expected);
    }
}
