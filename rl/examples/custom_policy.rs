//! Bring your own model: a policy and critic written against the public API only, trained by
//! the library's MAPPO on `team_reach/1_ant` (docs/MODELS.md, "Your own model").
//!
//! ```text
//! cargo run --release -p rl --example custom_policy -- --iterations 10
//! ```
//!
//! The model reads each scene as one flat vector (every node's vectors and scalars, every
//! agent's heading): one MLP head per agent gives the Tanh-Normal parameters of its actuated
//! DoF, one MLP critic gives the team's value. It is a plain MLP, neither invariant nor
//! equivariant: a baseline to copy and change, not a model of the paper.

use std::error::Error;

use envs::layout::{N_SCALARS, ObsRows, ObsSpec};
use envs::tasks::StartMode;
use models::{AgentPolicy, Policy, PolicyFactory, PolicyOutput};
use nn::{Bound, Mlp, Scope};
use rl::mappo::trainer::IterationStats;
use rl::{EvalOptions, Preset, TrainConfig, Trainer};
use tensor::{Activation, Tensor, Var};

/// A flat-MLP policy and critic for one team (module docs).
#[derive(Clone, Debug)]
pub struct FlatPolicy {
    team: usize,
    agents: Vec<usize>,
    spec: ObsSpec,
    /// One head per agent of the team: flat scene -> `[loc | scale]` of its DoF.
    heads: Vec<Mlp>,
    /// Flat scene -> `V(s)`.
    critic: Mlp,
}

impl FlatPolicy {
    /// Width of the flat input: per node 9 vector entries (3 vectors of 3) and `N_SCALARS`
    /// scalars, per agent its heading.
    fn input_width(spec: &ObsSpec) -> usize {
        spec.n_nodes * (9 + N_SCALARS) + spec.n_agents
    }

    /// Builds the heads and the critic in `s`: `actor.<agent>.*` and `critic.*` (the trainer
    /// counts `critic.*` as the value network).
    fn new(s: &mut Scope<'_, f32>, spec: &ObsSpec, team: usize, hidden: usize) -> models::Result<Self> {
        let agents: Vec<usize> = (0..spec.n_agents).filter(|&a| spec.agent_team[a] == team).collect();
        let width = Self::input_width(spec);
        let heads = agents
            .iter()
            .map(|&a| {
                Mlp::new(
                    &mut s.sub(format!("actor.{a}")),
                    &[width, hidden, hidden, 2 * spec.agent_dof[a]],
                    Activation::Tanh,
                )
            })
            .collect::<nn::Result<Vec<_>>>()?;
        let critic = Mlp::new(&mut s.sub("critic"), &[width, hidden, hidden, 1], Activation::Tanh)?;
        Ok(Self { team, agents, spec: spec.clone(), heads, critic })
    }

    /// The rows as one `[B, input_width]` constant on the tape of `p`, in this team's view.
    fn flat_input<'t>(&self, p: &Bound<'t, f32>, obs: &ObsRows<'_, f32>) -> models::Result<Var<'t, f32>> {
        let (b, n, na) = (obs.len(), obs.nodes, obs.agents);
        let mut scalars = obs.scalars.to_vec();
        // Team Sumo's second team sees the entity types from its own side.
        if self.team > 0 {
            self.spec.to_team_view(self.team, &mut scalars)?;
        }
        let mut x = Vec::with_capacity(b * Self::input_width(&self.spec));
        for r in 0..b {
            x.extend_from_slice(&obs.vectors[r * n * 9..(r + 1) * n * 9]);
            x.extend_from_slice(&scalars[r * n * N_SCALARS..(r + 1) * n * N_SCALARS]);
            x.extend_from_slice(&obs.heading[r * na..(r + 1) * na]);
        }
        Ok(p.tape().constant(Tensor::new(x, &[b, Self::input_width(&self.spec)])?))
    }
}

impl Policy for FlatPolicy {
    fn name(&self) -> &str {
        "flat_mlp"
    }

    fn team(&self) -> usize {
        self.team
    }

    fn agents(&self) -> &[usize] {
        &self.agents
    }

    fn spec(&self) -> &ObsSpec {
        &self.spec
    }

    fn forward<'t>(
        &mut self,
        p: &Bound<'t, f32>,
        obs: &ObsRows<'_, f32>,
        assignment: Option<&[u32]>,
        value: bool,
    ) -> models::Result<PolicyOutput<'t, f32>> {
        if assignment.is_some_and(|a| !a.is_empty()) {
            return Err(models::ModelError::Input("flat_mlp has no task assignment".into()));
        }
        let x = self.flat_input(p, obs)?;
        let mut agents = Vec::with_capacity(self.agents.len());
        for (head, &a) in self.heads.iter().zip(&self.agents) {
            let dof = self.spec.agent_dof[a];
            let hidden = head.forward_hidden(p, x)?;
            let loc = head.forward_output_columns(p, hidden, 0, dof)?;
            let scale = head.forward_output_columns(p, hidden, dof, dof)?;
            agents.push(AgentPolicy { agent: a, loc, scale });
        }
        let value = if value { Some(self.critic.forward(p, x)?.reshape(&[obs.len()])?) } else { None };
        Ok(PolicyOutput { agents, value, assignment: Vec::new(), assignment_terms: None })
    }

    fn clone_box(&self) -> Box<dyn Policy> {
        Box::new(self.clone())
    }
}

/// Builds a [`FlatPolicy`] of `hidden`-wide layers for every team.
pub struct FlatPolicies {
    /// Width of the two hidden layers of every head and of the critic.
    pub hidden: usize,
}

impl PolicyFactory for FlatPolicies {
    fn build(&self, scope: &mut Scope<'_, f32>, spec: &ObsSpec, team: usize) -> models::Result<Box<dyn Policy>> {
        Ok(Box::new(FlatPolicy::new(scope, spec, team, self.hidden)?))
    }
}

/// Trains [`FlatPolicy`] with `config`'s MAPPO for `iterations` iterations; the trainer and
/// each iteration's statistics.
pub fn train(config: &TrainConfig, iterations: u64) -> rl::Result<(Trainer, Vec<IterationStats>)> {
    let mut trainer = Trainer::with_policies(config, &FlatPolicies { hidden: 64 })?;
    let stats = (0..iterations).map(|_| trainer.iterate()).collect::<rl::Result<Vec<_>>>()?;
    Ok((trainer, stats))
}

fn main() -> Result<(), Box<dyn Error>> {
    let mut iterations = 10;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match (a.as_str(), args.next()) {
            ("--iterations", Some(v)) => {
                iterations = v.parse().map_err(|_| format!("--iterations {v}: not a count"))?
            }
            _ => return Err(format!("unknown argument `{a}` (usage: custom_policy [--iterations N])").into()),
        }
    }
    // The quick preset's hyperparameters; the model comes from the factory.
    let config = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
    let mut trainer = Trainer::with_policies(&config, &FlatPolicies { hidden: 64 })?;
    println!(
        "{} on {}: {} parameters, {} env steps per iteration",
        trainer.config.model,
        config.env,
        trainer.teams[0].store.num_elements(),
        config.steps_per_iteration()
    );
    for k in 1..=iterations {
        let s = trainer.iterate()?;
        let episodes = s.episodes.episodes.max(1) as f64;
        println!(
            "iteration {k}: {} episodes, mean return {:.1}, success {:.1}%, policy loss {:.4}, value loss {:.4}",
            s.episodes.episodes,
            s.episodes.return_sum[0] / episodes,
            100.0 * s.episodes.successes as f64 / episodes,
            s.losses[0].policy_loss,
            s.losses[0].value_loss
        );
    }
    let eval = trainer.evaluate(&EvalOptions::new(128, true, 1, StartMode::Random))?;
    println!("evaluation, 128 episodes, mean actions: success {:.1}%", 100.0 * eval.success_rate);
    Ok(())
}
