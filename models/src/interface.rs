//! The interface between a model and the library's MAPPO: a [`Policy`] (one team's actor and
//! critic, paper section 3 "Body-level Control", eqs. (pi) and (value)) and the
//! [`PolicyFactory`] that builds one per team.
//!
//! The trainer, the evaluator, the act step and Python's `meben.Policy` see a model only
//! through [`Policy`]; the eleven models of the paper ([`crate::Model`], module
//! [`crate::zoo`]) are one implementation of it. To try your own architecture on MeBen,
//! implement [`Policy`] for it and [`PolicyFactory`] for its builder, and hand the factory to
//! `rl::mappo::Trainer::with_policies` (`rl/examples/custom_policy.rs`, `docs/MODELS.md`).
//!
//! What a policy promises:
//! - it maps a batch of **normalised** observation rows (`B` scenes, the layout of
//!   [`ObsSpec`]) to, for each agent of its team in scene order, the Tanh-Normal parameters
//!   `loc` and `scale` `[B, dof_a]` of the agent's actuated DoF (`std = softplus(scale) +
//!   0.001`, [`crate::distribution::std_from_scale`]), and, when asked, the team's value
//!   `V(s)` `[B]` ([`PolicyOutput`]);
//! - its parameters live in the [`ParamStore`](nn::ParamStore) it was built in, under the
//!   [`Scope`] the factory was given (the trainer's optimiser, clipping and checkpoints work
//!   on that store by name); parameters whose names start with `critic.` under the scope are
//!   the value network, everything else the policy;
//! - the policy part does not read the value network: [`Policy::forward`] with `value =
//!   false` gives the same policy, to the bit, as with `value = true`.

use nn::{Bound, Scope};
use tensor::{Float, Var};

use crate::distribution::std_from_scale;
use crate::error::{ModelError, Result};
use envs::layout::{ObsRows, ObsSpec};

/// One agent's action-distribution parameters.
#[derive(Clone, Copy, Debug)]
pub struct AgentPolicy<'t, T: Float> {
    /// The agent (scene agent index; its actions are at [`ObsSpec::agent_action_offset`]).
    pub agent: usize,
    /// Mean of the pre-squash Normal, `[B, dof_a]`.
    pub loc: Var<'t, T>,
    /// Raw scale, `[B, dof_a]`; the standard deviation is [`AgentPolicy::std`].
    pub scale: Var<'t, T>,
}

impl<'t, T: Float> AgentPolicy<'t, T> {
    /// `std = softplus(scale) + 0.001` (eq. (pi), [`crate::distribution::std_from_scale`]).
    pub fn std(&self) -> Var<'t, T> {
        std_from_scale(self.scale)
    }
}

/// What a policy returns for a batch.
#[derive(Clone, Debug)]
pub struct PolicyOutput<'t, T: Float> {
    /// One entry per agent of the team, in scene order ([`Policy::agents`]).
    pub agents: Vec<AgentPolicy<'t, T>>,
    /// The team's value `[B]` (eq. (value)); `None` when the forward pass was asked for the
    /// policy only.
    pub value: Option<Var<'t, T>>,
    /// The task assignment the batch was processed with, `[B * Policy::assignment_width]`
    /// ([`crate::EntityGraph::assignment`]; empty for models without one).
    pub assignment: Vec<u32>,
    /// A learned task assignment's factor of the policy, `π(a, σ | s) = π(σ | s) π(a | s, σ)`
    /// (`assignment=learned`; `None` for the other methods and models): the log-probability
    /// and entropy estimate of [`PolicyOutput::assignment`] on the tape.
    pub assignment_terms: Option<AssignmentTerms<'t, T>>,
}

/// A learned task assignment's terms for a batch ([`crate::assignment_learned`]): the act step
/// adds `log_prob` to the action's log-probability, the PPO update adds it to the new one (so
/// that the ratio covers both factors) and `entropy` to the bonus.
#[derive(Clone, Copy, Debug)]
pub struct AssignmentTerms<'t, T: Float> {
    /// `ln π(σ | s)` of each scene's assignment, `[B]`.
    pub log_prob: Var<'t, T>,
    /// The chain-rule entropy estimate along it, `[B]`.
    pub entropy: Var<'t, T>,
}

impl<'t, T: Float> PolicyOutput<'t, T> {
    /// The team's value `[B]`; an error if this output was made without it.
    pub fn team_value(&self) -> Result<Var<'t, T>> {
        self.value.ok_or_else(|| ModelError::Input("the value was not computed (a policy-only forward pass)".into()))
    }
}

/// One team's actor and critic, as the library's MAPPO uses it (module docs).
///
/// Learning is in `f32` (the models' generic `f64` forms, [`crate::Model::forward_batch`],
/// serve the gradient checks).
pub trait Policy: std::fmt::Debug + Send + Sync {
    /// The model's name (a run trained with a custom factory records it as its `model`).
    fn name(&self) -> &str;

    /// The team the policy acts for.
    fn team(&self) -> usize;

    /// The team's agents (scene agent indices), in the order of [`PolicyOutput::agents`].
    fn agents(&self) -> &[usize];

    /// The observation layout the policy was built for.
    fn spec(&self) -> &ObsSpec;

    /// Policy and, if `value`, the team's value for normalised observation rows `obs` (whole
    /// scenes, team 0's view: a team-1 policy of Team Sumo reads the entity types from its
    /// own side itself, [`ObsSpec::to_team_view`]), on the tape of `p`. `assignment`, when
    /// given, is the task assignment of every scene (`[B * assignment_width]`, as an earlier
    /// [`PolicyOutput::assignment`] returned it) to use instead of solving or drawing one.
    fn forward<'t>(
        &mut self,
        p: &Bound<'t, f32>,
        obs: &ObsRows<'_, f32>,
        assignment: Option<&[u32]>,
        value: bool,
    ) -> Result<PolicyOutput<'t, f32>>;

    /// Whether the value reads the learned task assignment held into each step
    /// (`assign_critic=held`): the update then asks for the value with
    /// [`Policy::forward_held`]. Default: no.
    fn value_reads_held_assignment(&self) -> bool {
        false
    }

    /// [`Policy::forward`] with the value and the task assignment `assignment` of every scene
    /// given, `held[b]` saying whether scene `b`'s was held into it from an earlier step (the
    /// value reads it: `V(s, σ)`) or drawn there (the value reads none: `V(s)`, before the
    /// draw). Only for a policy whose [`Policy::value_reads_held_assignment`]; the default is
    /// an error.
    fn forward_held<'t>(
        &mut self,
        p: &Bound<'t, f32>,
        obs: &ObsRows<'_, f32>,
        assignment: &[u32],
        held: &[bool],
    ) -> Result<PolicyOutput<'t, f32>> {
        let _ = (p, obs, assignment, held);
        Err(ModelError::Input(format!("the value of `{}` reads no held task assignment", self.name())))
    }

    /// Entries per scene of [`PolicyOutput::assignment`] (0, the default, for policies
    /// without a task assignment).
    fn assignment_width(&self) -> usize {
        0
    }

    /// Whether the policy draws its task assignment at random, so that an update must be
    /// given the assignment the behaviour policy used to see the same graph (default: no).
    fn assignment_is_random(&self) -> bool {
        false
    }

    /// A learned task assignment's support: every assignment it can draw (each
    /// [`Policy::assignment_width`] entries, as [`PolicyOutput::assignment`]), which the
    /// update's expected assignment gradient sums over; empty (the default) for a policy
    /// that draws none, or none now (a warm-up).
    fn learned_assignment_support(&self) -> Vec<Vec<u32>> {
        Vec::new()
    }

    /// Restarts the policy's own random stream, if it has one, from `seed` (default: no
    /// stream, nothing to do). The trainer reseeds every iteration so that resumed runs are
    /// exact.
    fn reseed(&mut self, seed: u64) {
        let _ = seed;
    }

    /// Whether the policy's own random choices, if it has any (a learned task assignment),
    /// take their most likely value (`true`: deterministic evaluation) instead of a draw from
    /// its stream (`false`, the default: collection). Default: nothing to set.
    fn set_deterministic(&mut self, deterministic: bool) {
        let _ = deterministic;
    }

    /// Whether a learned task assignment is in its warm-up (`true`): the policy then acts as
    /// the paper's greedy model, the assignment Algorithm 1's, solved again whenever none is
    /// given, and its scorer unused (no [`PolicyOutput::assignment_terms`]). The trainer sets it
    /// while a run's env steps are below its `assignment_warmup_steps`. Default: nothing to set.
    fn set_assignment_warmup(&mut self, warmup: bool) {
        let _ = warmup;
    }

    /// A boxed copy (the evaluator acts with copies).
    fn clone_box(&self) -> Box<dyn Policy>;
}

impl Clone for Box<dyn Policy> {
    fn clone(&self) -> Self {
        self.clone_box()
    }
}

/// Builds one [`Policy`] per team (module docs).
pub trait PolicyFactory: Sync {
    /// Builds team `team`'s policy and critic for scenes laid out by `spec`, its parameters
    /// created in `scope` (names under the scope's prefix; `scope.rng()` is the run's
    /// initialisation stream of the team).
    fn build(&self, scope: &mut Scope<'_, f32>, spec: &ObsSpec, team: usize) -> Result<Box<dyn Policy>>;
}
