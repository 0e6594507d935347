//! The model zoo: the eleven models of the paper (section 3 "Body-level Control", eqs. (pi)
//! and (value); appendices "Baselines" and "Ablations") as one [`Policy`] implementation,
//! [`Model`], built for a [`ModelKind`] by its family's module.
//!
//! A [`Model`] is built from a [`ModelDescription`] (written out, or parsed from a model
//! string) for one scene layout ([`ObsSpec`]) and one team: it creates its parameters in a
//! [`Scope`] (so the trainer keeps every team's parameters in one [`ParamStore`] under
//! different prefixes, counted with [`Model::num_params`] and [`Model::param_counts`]) and
//! maps a batch of observations to, for each agent of the team, the Tanh-Normal parameters
//! `loc`, `scale` `[B, dof_a]` of its actuated DoF (`std = softplus(scale) + 0.001`,
//! [`crate::distribution::std_from_scale`]), the team's value `[B]`, and the task
//! assignment it used ([`PolicyOutput`]).
//!
//! Parameter names under the scope: `entity.*` (the actor's entity-level message passing,
//! shared by the team's agents), `actor.*` (the body-level heads: `actor.<a>.*` one MLP per
//! agent `a`, scene agent index, or one Transformer or GNN for the team, plus the MLP
//! baselines' node embeddings) and `critic.*` (the value network: the SHNN family's own
//! message passing `critic.entity.*` and `critic.value.*`). The policy is everything but
//! `critic.*` ([`ParamCounts`]).
//!
//! # Models
//! - `shnn`, `shnn_og3`, `shnn_so3`, `shtransformer`, `shgnn`: the SHNN family, module
//!   [`crate::shnn`] (eqs. (somp) to (value); the ablations SHNN:Og3, SHNN:SO3; the
//!   Transformer and GNN body heads of the sections "Extended Evaluations on Transformer" and
//!   "Analyses of Morphology-shared Policy");
//! - `mlp`, `mlp_hn`: the MLP baselines, module [`crate::mlp`] (the release's MLP by
//!   default; `variant=flat` the earlier 256 x 3);
//! - `transformer_hn` (Transformer+HN): the nodes of `mlp_hn`'s flat agent view, each in the
//!   agent's heading frame, are the tokens of one shared [`crate::TransformerHead`] (128/256/3/2, no
//!   positional encoding, decoder conditioned on the token); each DoF node's output gives that
//!   DoF's `loc`, `scale`; its critic is a Transformer over every entity's root (the paper:
//!   "the same backbone ... for σ_π in eq. (pi) and σ_V in eq. (value)");
//! - `hnn`, `hnn_hn`, `hnn_dn` (ablations HNN, HNN+HN, HNN+DN; [`crate::hnn`]): SHNN's
//!   hierarchy with the vectors flattened into scalars and plain MLP message passing, in the
//!   world frame, the agent's heading frame, or the frame of the goal direction.
//!
//! Every model reads the observation from its team's view: in Team Sumo the entity-type
//! columns of team 1's model are swapped to `[own, opponent, centre]`
//! ([`ObsSpec::to_team_view`]; the raw observation is team 0's view).

use nn::{Bound, Mlp, ParamStore, Scope};
use tensor::{Float, Var};

use crate::assignment::AssignmentMethod;
use crate::assignment_learned::{LearnedAssignment, LearnedChoice, PairFeatureSet};
use crate::description::{MlpModel, MlpNetwork, ModelDescription};
use crate::entity_graph::GraphBuilder;
use crate::entity_mp::EntityMp;
use crate::error::{ModelError, Result};
use crate::hnn::Hnn;
use crate::interface::{AgentPolicy, Policy, PolicyOutput};
use crate::kind::ModelKind;
use crate::mlp::{FlatMlp, ReleaseMlp, no_assignment};
use crate::shnn::Shnn;
use envs::layout::{ObsBatch, ObsElement, ObsRows, ObsSpec};

/// A model's parameter count by part (`meben info`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamCounts {
    /// Everything that acts: the entity stage and the body-level heads.
    pub policy: usize,
    /// The value network (`critic.*`).
    pub critic: usize,
}

/// The model's architecture.
#[derive(Clone, Debug)]
enum Arch {
    Shnn(Box<Shnn>),
    Hnn(Box<Hnn>),
    Mlp(Box<ReleaseMlp>),
    Flat(Box<FlatMlp>),
}

/// A policy and critic for one team of one scene layout (module docs).
#[derive(Clone, Debug)]
pub struct Model {
    description: ModelDescription,
    team: usize,
    agents: Vec<usize>,
    spec: ObsSpec,
    prefix: String,
    arch: Arch,
}

impl Model {
    /// Builds the model `d` describes for `team` of scenes laid out by `spec`, with parameters
    /// under scope `s` (module docs), by its family's module. Hidden widths that are empty or
    /// zero ([`ModelDescription::check`]) and a team the scene does not have are errors.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, d: &ModelDescription, spec: &ObsSpec, team: usize) -> Result<Self> {
        d.check()?;
        if team >= spec.n_teams {
            return Err(ModelError::Option(format!("team {team} in a scene of {} teams", spec.n_teams)));
        }
        let agents: Vec<usize> = (0..spec.n_agents).filter(|&a| spec.agent_team[a] == team).collect();
        if agents.is_empty() {
            return Err(ModelError::Input(format!("team {team} has no agent")));
        }
        let prefix = s.full_name("");
        let arch = match d {
            ModelDescription::Shnn(o) => Arch::Shnn(Box::new(Shnn::new(s, o, spec, team, &agents)?)),
            ModelDescription::Hnn(o) => Arch::Hnn(Box::new(Hnn::new(s, o, spec, team, &agents)?)),
            ModelDescription::Mlp(o) => {
                let heading = o.model == MlpModel::MlpHn;
                match &o.network {
                    MlpNetwork::Release { assignment, hidden, scorer } => {
                        let graph = assignment.graph_builder(spec, team)?;
                        let learned = (assignment.method == AssignmentMethod::Learned)
                            .then(|| (scorer.config(PairFeatureSet::DistanceHeight), assignment.seed));
                        let m = ReleaseMlp::new(
                            s,
                            spec,
                            &agents,
                            graph,
                            heading,
                            hidden,
                            learned,
                            scorer.value_reads_held,
                        )?;
                        Arch::Mlp(Box::new(m))
                    }
                    MlpNetwork::Flat { hidden } => {
                        let m = FlatMlp::new(s, spec, &agents, heading, false, &hidden.head, &hidden.critic)?;
                        Arch::Flat(Box::new(m))
                    }
                }
            }
            ModelDescription::TransformerHn => {
                Arch::Flat(Box::new(FlatMlp::new(s, spec, &agents, true, true, &[], &[])?))
            }
        };
        Ok(Self { description: d.clone(), team, agents, spec: spec.clone(), prefix, arch })
    }

    /// The model's name.
    pub fn name(&self) -> &str {
        self.description.name()
    }

    /// The model and its options, resolved.
    pub fn description(&self) -> &ModelDescription {
        &self.description
    }

    /// Which model of the paper it is.
    pub fn kind(&self) -> ModelKind {
        self.description.kind()
    }

    /// The team the model acts for.
    pub fn team(&self) -> usize {
        self.team
    }

    /// The team's agents (scene agent indices), in the order of [`PolicyOutput::agents`].
    pub fn agents(&self) -> &[usize] {
        &self.agents
    }

    /// The observation layout the model was built for.
    pub fn spec(&self) -> &ObsSpec {
        &self.spec
    }

    /// The name prefix of every parameter of the model (`""` at the top level).
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The actor's entity-level message passing of the SHNN family (`None` for the others).
    pub fn entity_stage(&self) -> Option<&EntityMp> {
        match &self.arch {
            Arch::Shnn(m) => Some(&m.mp),
            _ => None,
        }
    }

    /// Restarts the random stream of the stochastic or learned task assignment from `seed` (no
    /// effect on the other methods): the trainer reseeds it every iteration so that resumed runs are
    /// exact.
    pub fn reseed(&mut self, seed: u64) {
        match &mut self.arch {
            Arch::Shnn(m) => m.graph.reseed(seed),
            Arch::Hnn(m) => m.reseed(seed),
            Arch::Mlp(m) => m.graph_mut().reseed(seed),
            Arch::Flat(_) => {}
        }
        if let Some(l) = self.learned_mut() {
            l.reseed(seed);
        }
    }

    /// The learned task assignment, if the model has one (`assignment=learned`).
    fn learned_mut(&mut self) -> Option<&mut LearnedAssignment> {
        match &mut self.arch {
            Arch::Shnn(m) => m.learned.as_deref_mut(),
            Arch::Mlp(m) => m.learned.as_deref_mut(),
            _ => None,
        }
    }

    /// The learned task assignment, if the model has one (`assignment=learned`).
    fn learned(&self) -> Option<&LearnedAssignment> {
        match &self.arch {
            Arch::Shnn(m) => m.learned.as_deref(),
            Arch::Mlp(m) => m.learned.as_deref(),
            _ => None,
        }
    }

    /// Every task assignment a learned assignment can draw (its support,
    /// [`LearnedAssignment::support`]); empty for the other methods and for a learned
    /// assignment in its warm-up (Algorithm 1's, nothing drawn).
    pub fn learned_assignment_support(&self) -> Vec<Vec<u32>> {
        self.learned().filter(|l| !l.in_warmup()).map_or_else(Vec::new, LearnedAssignment::support)
    }

    /// The task-assignment graph builder, if the model has one.
    fn graph(&self) -> Option<&GraphBuilder> {
        match &self.arch {
            Arch::Shnn(m) => Some(&m.graph),
            Arch::Hnn(m) => Some(m.graph()),
            Arch::Mlp(m) => Some(m.graph()),
            Arch::Flat(_) => None,
        }
    }

    /// Entries per scene of [`PolicyOutput::assignment`] (0 for models without a task
    /// assignment).
    pub fn assignment_width(&self) -> usize {
        self.graph().map_or(0, GraphBuilder::assignment_width)
    }

    /// Whether the model draws its task assignment at random (`assignment=stochastic` or
    /// `learned`), so that an update must be given the assignment the behaviour policy used
    /// ([`Model::forward_batch_with`]) to see the same graph (and, when learned, to score it).
    pub fn assignment_is_random(&self) -> bool {
        self.graph().is_some_and(|g| matches!(g.method(), AssignmentMethod::Stochastic | AssignmentMethod::Learned))
    }

    /// Whether a learned task assignment takes its most likely value (`true`, deterministic
    /// evaluation) or is drawn (`false`, the default); no effect on the other methods.
    pub fn set_deterministic(&mut self, deterministic: bool) {
        if let Some(l) = self.learned_mut() {
            l.set_choice(if deterministic { LearnedChoice::MostLikely } else { LearnedChoice::Sample });
        }
    }

    /// Whether a learned task assignment is in its warm-up ([`Policy::set_assignment_warmup`]):
    /// Algorithm 1's assignment, the scorer unused; no effect on the other methods.
    pub fn set_assignment_warmup(&mut self, warmup: bool) {
        if let Some(l) = self.learned_mut() {
            l.set_warmup(warmup);
        }
    }

    /// Number of scalar parameters of the model in `store` (the one it was built in).
    pub fn num_params<T: Float>(&self, store: &ParamStore<T>) -> usize {
        store.num_elements_under(&self.prefix)
    }

    /// The parameter count by part: the policy (all but `critic.*`) and the critic.
    pub fn param_counts<T: Float>(&self, store: &ParamStore<T>) -> ParamCounts {
        let critic = store.num_elements_under(&format!("{}critic.", self.prefix));
        ParamCounts { policy: self.num_params(store) - critic, critic }
    }

    /// Policy and value for borrowed observation rows (`f32` or `f64`).
    pub fn forward_batch<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsRows<'_, S>,
    ) -> Result<PolicyOutput<'t, T>> {
        self.forward_batch_with(p, obs, None)
    }

    /// [`Model::forward_batch`] with the task assignment of every scene given (`[B *
    /// assignment_width]`, as an earlier [`PolicyOutput::assignment`] returned it) instead of
    /// solved or drawn.
    pub fn forward_batch_with<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsRows<'_, S>,
        assignment: Option<&[u32]>,
    ) -> Result<PolicyOutput<'t, T>> {
        self.forward_parts(p, obs, assignment, None, true)
    }

    /// [`Model::forward_batch_with`] with `held[b]` saying whether scene `b`'s given
    /// assignment was held into it, which a value that reads the held assignment reads
    /// (`assign_critic=held`, [`Model::value_reads_held`]), or drawn there (it then reads
    /// none). An error for a model whose value reads no assignment.
    pub fn forward_batch_held<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsRows<'_, S>,
        assignment: &[u32],
        held: &[bool],
    ) -> Result<PolicyOutput<'t, T>> {
        self.forward_parts(p, obs, Some(assignment), Some(held), true)
    }

    /// Whether its value reads the learned assignment held into each step
    /// (`assign_critic=held`).
    pub fn value_reads_held(&self) -> bool {
        self.description.value_reads_held()
    }

    /// [`Model::forward_batch`] without the value network (`PolicyOutput::value` is `None`):
    /// acting (collection, evaluation) needs only the policy, and the SHNN family's critic
    /// is most of a forward pass. The policy is the same, to the bit: no part of it reads the
    /// value network.
    pub fn forward_policy_batch<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        obs: &ObsRows<'_, S>,
    ) -> Result<PolicyOutput<'t, T>> {
        self.forward_parts(p, obs, None, None, false)
    }

    fn forward_parts<'t, T: Float, S: ObsElement>(
        &mut self,
        p: &Bound<'t, T>,
        rows: &ObsRows<'_, S>,
        assignment: Option<&[u32]>,
        held: Option<&[bool]>,
        with_value: bool,
    ) -> Result<PolicyOutput<'t, T>> {
        let (nb, heading) = (rows.len(), rows.heading);
        if held.is_some() && !matches!(self.arch, Arch::Mlp(_) | Arch::Shnn(_)) {
            return Err(ModelError::Input(format!(
                "held assignment flags given to `{}`, whose value reads no assignment (assign_critic=held)",
                self.name()
            )));
        }
        if rows.nodes != self.spec.n_nodes || rows.agents != self.spec.n_agents || nb == 0 {
            return Err(ModelError::Input(format!(
                "observations of {nb} x {} nodes with {} headings for a scene of {} nodes and {} agents",
                rows.nodes,
                heading.len(),
                self.spec.n_nodes,
                self.spec.n_agents
            )));
        }
        let obs = rows.node_batch();
        // Team Sumo's team 1 reads the entity types from its own view (own team, opponent,
        // centre; the release's Sumo observer): the raw observation is team 0's.
        let viewed: Vec<S>;
        let obs = &if self.team > 0 {
            let mut s = obs.scalars.to_vec();
            self.spec.to_team_view(self.team, &mut s)?;
            viewed = s;
            ObsBatch::new(nb, obs.nodes, obs.vectors, &viewed)?
        } else {
            obs
        };
        match &mut self.arch {
            Arch::Shnn(m) => m.forward(p, obs, &self.agents, &self.spec, assignment, held, with_value),
            Arch::Hnn(m) => m.forward(p, obs, heading, &self.agents, &self.spec, assignment, with_value),
            Arch::Mlp(m) => m.forward(p, obs, heading, &self.agents, &self.spec, assignment, held, with_value),
            Arch::Flat(m) => {
                no_assignment(assignment)?;
                m.forward(p, obs, heading, &self.agents, &self.spec, with_value)
            }
        }
    }
}

impl Policy for Model {
    fn name(&self) -> &str {
        Model::name(self)
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
    ) -> Result<PolicyOutput<'t, f32>> {
        self.forward_parts(p, obs, assignment, None, value)
    }

    fn value_reads_held_assignment(&self) -> bool {
        self.value_reads_held()
    }

    fn forward_held<'t>(
        &mut self,
        p: &Bound<'t, f32>,
        obs: &ObsRows<'_, f32>,
        assignment: &[u32],
        held: &[bool],
    ) -> Result<PolicyOutput<'t, f32>> {
        self.forward_batch_held(p, obs, assignment, held)
    }

    fn assignment_width(&self) -> usize {
        Model::assignment_width(self)
    }

    fn assignment_is_random(&self) -> bool {
        Model::assignment_is_random(self)
    }

    fn learned_assignment_support(&self) -> Vec<Vec<u32>> {
        Model::learned_assignment_support(self)
    }

    fn reseed(&mut self, seed: u64) {
        Model::reseed(self, seed)
    }

    fn set_deterministic(&mut self, deterministic: bool) {
        Model::set_deterministic(self, deterministic)
    }

    fn set_assignment_warmup(&mut self, warmup: bool) {
        Model::set_assignment_warmup(self, warmup)
    }

    fn clone_box(&self) -> Box<dyn Policy> {
        Box::new(self.clone())
    }
}

/// Splits a head's output into `loc` (first `dof` columns) and `scale` (next `dof`).
pub(crate) fn split_head<'t, T: Float>(
    head: &Mlp,
    p: &Bound<'t, T>,
    hidden: Var<'t, T>,
    agent: usize,
    dof: usize,
) -> Result<AgentPolicy<'t, T>> {
    Ok(AgentPolicy {
        agent,
        loc: head.forward_output_columns(p, hidden, 0, dof)?,
        scale: head.forward_output_columns(p, hidden, dof, dof)?,
    })
}
