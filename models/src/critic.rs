//! The SHNN family's value network as the reference release builds it (`models/SHNN.py`
//! with `out_dim == 1`; the paper's eq. (value), `V = σ_V({h'_i})`, with `h'` from a
//! subequivariant network of its own):
//!
//! 1. every entity's root, positions relative to `c`, the mean of the roots (paper section 3,
//!    "Input Processing"), `Z_i = [p_{i,1} - c, v_{i,1}, ω_{i,1}]`, `h_i = [h_{i,1}, p^z_{i,1}]`;
//! 2. a fully connected entity graph (every ordered pair `i != j`), edge scalars: the
//!    release's 64 radial-basis features of the distance (`DistanceRBF`: 62 Gaussians on
//!    `10 d` with centres evenly spaced on `[0, 20]`, plus the flags `10 d < 0` and
//!    `10 d >= 20`) and a 2-way edge-type one-hot (`[different kind, same kind]`; kinds:
//!    Reach agent / ball, Sumo own agent / opponent / centre ball);
//! 3. two rounds of the entity stage's message passing ([`EntityMp`], its own parameters,
//!    no frame);
//! 4. `σ_V`: an MLP (256, 256) on the concatenated `h'` of all entities, own agents first,
//!    then the other agents, then the balls ([`ValueHead`]); or, for the Transformer models,
//!    a Transformer over the `h'_i` as tokens (the paper: "the same backbone as Amorpheus and
//!    MxT-Bench for σ_π in eq. (pi) and σ_V in eq. (value)").
//!
//! The edge scalars are computed once per batch from the observations (they are constants of
//! the loss). Every input is invariant under rotations about `g` and translations, and the
//! message passing is subequivariant, so the value is invariant.

use nn::{Aggregation, Bound, EdgeDistance, EdgeList, Mlp, ParamId, Scope, TransformerConfig};
use tensor::{Activation, Float, Tape, Tensor, Var};

use crate::config::{GravityMode, MpSizes, layer_sizes};
use crate::description::ValueNet;
use crate::entity_mp::{EntityMp, EntityMpConfig};
use crate::error::{ModelError, Result};
use crate::input::{EntityAbstraction, EntityInputs, InputProcessor, Translation};
use crate::transformer_head::TransformerHead;
use envs::layout::{ENTITY_CENTRE, N_SCALARS, ObsSpec};
use envs::layout::{ObsBatch, ObsElement};

/// Radial-basis features of the release's `DistanceRBF(num_channels=64)`.
pub const RBF_FEATURES: usize = 64;
/// Edge-type features (`[different kind, same kind]`).
pub const EDGE_TYPES: usize = 2;

/// The release's `DistanceRBF` of a distance `d` (module docs): `[10 d < 0, exp(coeff (10 d -
/// o_k)^2) for the 62 offsets o_k = 20 k / 61, 10 d >= 20]`, `coeff = -0.5 / (20/61)^2`.
pub fn release_rbf(d: f64) -> [f64; RBF_FEATURES] {
    let (n, (start, stop), spacing, coeff) = rbf_parameters();
    let x = 10.0 * d;
    let mut out = [0.0; RBF_FEATURES];
    out[0] = f64::from(u8::from(x < start));
    for (k, o) in out[1..=n].iter_mut().enumerate() {
        let y = x - (start + spacing * k as f64);
        *o = (coeff * y * y).exp();
    }
    out[n + 1] = f64::from(u8::from(x >= stop));
    out
}

/// [`release_rbf`]'s constants: the number of Gaussians, the span `(start, stop)` of their
/// centres on `10 d`, the spacing of the centres and `coeff = -0.5 / spacing^2`.
fn rbf_parameters() -> (usize, (f64, f64), f64, f64) {
    let n = RBF_FEATURES - 2;
    let (start, stop) = (0.0, 20.0);
    let spacing = (stop - start) / (n - 1) as f64;
    (n, (start, stop), spacing, -0.5 / (spacing * spacing))
}

/// 1 for true, 0 for false.
fn flag<T: Float>(f: bool) -> T {
    T::from_f64(f64::from(u8::from(f)))
}

/// The Euclidean distance between two points.
fn distance(pi: [f64; 3], pj: [f64; 3]) -> f64 {
    ((pj[0] - pi[0]).powi(2) + (pj[1] - pi[1]).powi(2) + (pj[2] - pi[2]).powi(2)).sqrt()
}

/// `σ_V` of a critic: an MLP on the concatenated token features, or a Transformer over the
/// tokens whose per-token outputs are averaged.
#[derive(Clone, Debug)]
pub enum ValueHead {
    /// MLP on `[B, N * F]`.
    Mlp(Mlp),
    /// Transformer over `[B, N, F]`, one output per token, the value their mean.
    Transformer(Box<TransformerHead>),
}

impl ValueHead {
    /// `σ_V` as `net` describes it for `tokens` tokens of `features` features: an MLP of its
    /// hidden widths, or a Transformer (the paper's sizes).
    pub fn new<T: Float>(s: &mut Scope<'_, T>, tokens: usize, features: usize, net: &ValueNet) -> Result<Self> {
        Ok(match net {
            ValueNet::Transformer => {
                Self::Transformer(Box::new(TransformerHead::new(s, features, 1, TransformerConfig::default())?))
            }
            ValueNet::Mlp(hidden) => {
                Self::Mlp(Mlp::new(s, &layer_sizes(tokens * features, hidden, 1), Activation::Relu)?)
            }
        })
    }

    /// The value `[B]` of token features `x: [B, N, F]`; `extra`, when given, is one more
    /// term `x_σ W_σ` of an MLP's first layer (`assign_critic=held`, `held_one_hot`).
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        x: Var<'t, T>,
        extra: Option<(Var<'t, T>, Var<'t, T>)>,
    ) -> Result<Var<'t, T>> {
        let s = x.shape();
        let nb = s[0];
        match (self, extra) {
            (Self::Transformer(head), None) => Ok(head.forward_all(p, x)?.reshape(&[nb, s[1]])?.mean(1, false)?),
            (Self::Transformer(_), Some(_)) => {
                Err(ModelError::Input("a Transformer value reads no held assignment".into()))
            }
            (Self::Mlp(mlp), None) => Ok(mlp.forward(p, x.reshape(&[nb, s[1] * s[2]])?)?.reshape(&[nb])?),
            (Self::Mlp(mlp), Some(extra)) => {
                // The first layer with the term x_σ W_σ, then the others as Mlp::forward.
                let x = x.reshape(&[nb, s[1] * s[2]])?;
                let act = |i: usize| if i + 1 == mlp.layers.len() { Activation::Identity } else { mlp.activation };
                let first = &mlp.layers[0];
                let bias = first.bias.map(|b| p.get(b));
                let mut h = p.tape().linear_sum(&[(x, p.get(first.weight)), extra], bias, act(0))?;
                for (i, layer) in mlp.layers.iter().enumerate().skip(1) {
                    h = layer.forward_act(p, h, act(i))?;
                }
                Ok(h.reshape(&[nb])?)
            }
        }
    }

    /// The width of an MLP's first layer (the columns of `W_σ`); `None` for a Transformer.
    pub fn first_width(&self) -> Option<usize> {
        match self {
            Self::Mlp(mlp) => Some(mlp.layers[0].fan_out),
            Self::Transformer(_) => None,
        }
    }
}

/// `assign_critic=held`'s `W_σ` `[m n, h]` (`critic.held.weight`, zero at the start, so that
/// a model starts as without it): the term `x_σ W_σ` of a value's first layer
/// (docs/MODELS.md), the same for the release's MLPs and the SHNN family.
#[derive(Clone, Debug)]
pub(crate) struct HeldTerm {
    weight: ParamId,
    agents: usize,
}

impl HeldTerm {
    /// `W_σ` under `s` (`critic.held.weight`) for `objects` objects, `agents` agents and a
    /// first layer of `columns` outputs.
    pub(crate) fn new<T: Float>(s: &mut Scope<'_, T>, objects: usize, agents: usize, columns: usize) -> Result<Self> {
        let w = Tensor::zeros(&[objects * agents, columns]);
        Ok(Self { weight: s.sub("critic").sub("held").param("weight", w)?, agents })
    }

    /// `(x_σ, W_σ)` on the tape of `p` for the scenes' `assignment`, held where `held` says;
    /// `None` where no scene holds its assignment (the term is zero).
    pub(crate) fn term<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        assignment: &[u32],
        held: Option<&[bool]>,
    ) -> Result<Option<(Var<'t, T>, Var<'t, T>)>> {
        match held {
            Some(h) if h.iter().any(|&x| x) => {
                Ok(Some((p.tape().constant(held_one_hot(assignment, h, self.agents)?), p.get(self.weight))))
            }
            _ => Ok(None),
        }
    }
}

/// `x_σ` of `assign_critic=held` (docs/MODELS.md), `[B, m n]`: for each scene held into its
/// step, entry `j n + i` is 1 where object `j` of `assignment` (`[B m]`, for each object the
/// agent row holding it, [`crate::EntityGraph::assignment`]) is held by agent `i` of `n`;
/// the rows of the scenes that draw are zero.
fn held_one_hot<T: Float>(assignment: &[u32], held: &[bool], agents: usize) -> Result<Tensor<T>> {
    let nb = held.len();
    let width = assignment.len() / nb.max(1);
    let mut x = vec![T::ZERO; nb * width * agents];
    for (b, _) in held.iter().enumerate().filter(|(_, h)| **h) {
        for (j, &i) in assignment[b * width..(b + 1) * width].iter().enumerate() {
            if i != crate::NO_AGENT {
                let i = i as usize;
                if i >= agents {
                    return Err(ModelError::Input(format!("scene {b}: object {j} held by agent {i} of {agents}")));
                }
                x[b * width * agents + j * agents + i] = T::ONE;
            }
        }
    }
    Ok(Tensor::new(x, &[nb, width * agents])?)
}

/// An error unless `held` flags, when given, come with their assignment (`fixed`), one per
/// scene of `nb`, to a value that reads them (`reads`).
pub(crate) fn check_held(held: Option<&[bool]>, reads: bool, fixed: bool, nb: usize) -> Result<()> {
    match held {
        Some(h) if !reads || !fixed || h.len() != nb => Err(ModelError::Input(format!(
            "held flags of {} scenes for {nb} scenes{}{}",
            h.len(),
            if fixed { "" } else { " without their assignment" },
            if reads { "" } else { ", to a value that reads no assignment (assign_critic=held)" }
        ))),
        _ => Ok(()),
    }
}

/// The order of the entities in a critic's input from `agents`' team's view: own agents,
/// the other agents, the balls.
pub fn critic_order(spec: &ObsSpec, agents: &[usize]) -> Vec<usize> {
    let ne = spec.entity_root_node.len();
    let mut order = agents.to_vec();
    order.extend((0..spec.n_agents).filter(|a| !agents.contains(a)));
    order.extend(spec.n_agents..ne);
    order
}

/// Each entity's kind for the edge types, from `team`'s view: Reach agent 0, ball 1; Sumo
/// own agent 0, opponent 1, centre ball 2.
pub fn entity_kinds(spec: &ObsSpec, team: usize) -> Vec<u8> {
    let ne = spec.entity_root_node.len();
    (0..ne)
        .map(|e| {
            if e < spec.n_agents {
                u8::from(spec.agent_team[e] != team)
            } else {
                let node = spec.entity_root_node[e];
                if spec.static_scalars[node * N_SCALARS + ENTITY_CENTRE] == 1.0 { 2 } else { 1 }
            }
        })
        .collect()
}

/// The release's separate critic (module docs). Parameters under its scope:
/// `entity.*` (the message passing) and `value.*` (`σ_V`).
#[derive(Clone, Debug)]
pub struct SubeqCritic {
    proc: InputProcessor,
    mp: EntityMp,
    head: ValueHead,
    order: Vec<usize>,
    kinds: Vec<u8>,
}

impl SubeqCritic {
    /// The critic of `agents` (the team `team`) for scenes laid out by `spec`: message-passing
    /// sizes `sizes` (its `steps` rounds), gravity as `gravity` (`None`: the `SO(3)`
    /// ablation), `σ_V` as `value` says.
    pub fn new<T: Float>(
        s: &mut Scope<'_, T>,
        spec: &ObsSpec,
        team: usize,
        agents: &[usize],
        sizes: MpSizes,
        gravity: Option<GravityMode>,
        value: &ValueNet,
    ) -> Result<Self> {
        let proc = InputProcessor::new(spec, Translation::RootMean)?.with_abstraction(EntityAbstraction::Root);
        let g = spec.gravity_dir.map(f64::from);
        let config = EntityMpConfig {
            vectors: sizes.vectors,
            scalars: sizes.scalars,
            hidden: sizes.hidden,
            layers: sizes.layers,
            steps: sizes.steps,
            distance: EdgeDistance::None,
            edge_scalars: RBF_FEATURES + EDGE_TYPES,
            aggregation: Aggregation::Mean,
            gravity: gravity.map(|_| g),
            gravity_in_layers: gravity == Some(GravityMode::EveryLayer),
            frame: false,
        };
        let mp = EntityMp::new(&mut s.sub("entity"), config)?;
        let ne = spec.entity_root_node.len();
        let head = ValueHead::new(&mut s.sub("value"), ne, sizes.scalars, value)?;
        Ok(Self { proc, mp, head, order: critic_order(spec, agents), kinds: entity_kinds(spec, team) })
    }

    /// `σ_V`.
    pub fn head(&self) -> &ValueHead {
        &self.head
    }

    /// The value `[B]` of a batch of observations (`extra`: [`ValueHead::forward`]'s).
    pub fn forward<'t, T: Float, S: ObsElement>(
        &self,
        p: &Bound<'t, T>,
        obs: &ObsBatch<'_, S>,
        extra: Option<(Var<'t, T>, Var<'t, T>)>,
    ) -> Result<Var<'t, T>> {
        let inputs: EntityInputs<T> = self.proc.entities(obs)?;
        let (nb, ne) = (inputs.batch, inputs.entities);
        let edges = EdgeList::fully_connected(nb, ne);
        let tape = p.tape();
        let scalars = self.edge_scalars_on(tape, &inputs, &edges)?;
        let f = self.mp.forward(
            p,
            tape.constant(inputs.z.clone()),
            tape.constant(inputs.h.clone()),
            &edges,
            Some(scalars),
        )?;
        let rows: Vec<usize> = (0..nb).flat_map(|b| self.order.iter().map(move |&e| b * ne + e)).collect();
        let s = f.h.shape()[1];
        self.head.forward(p, f.h.index_select(0, &rows)?.reshape(&[nb, ne, s])?, extra)
    }

    /// Radial-basis features and edge types of every edge, `[E, RBF_FEATURES + EDGE_TYPES]`,
    /// as a constant of `tape`: each row is [`release_rbf`] of the edge's length followed by
    /// its edge type. The host computes `10 d`, the two flags and the edge type of each edge
    /// (5 values where the row has 66); the 62 Gaussians are the tape's
    /// [`Tape::gaussian_basis`], computed where the tape is: in f64 on the CPU, bit for bit
    /// [`release_rbf`]'s, and in f32 on a GPU, which then uploads 5 values an edge instead of
    /// 66 (the features of every edge of a paper-size minibatch were its largest upload,
    /// about 40 MB; docs/PERFORMANCE_LOG.md, "On a GPU").
    fn edge_scalars_on<'t, T: Float>(
        &self,
        tape: &'t Tape<T>,
        inputs: &EntityInputs<T>,
        edges: &EdgeList,
    ) -> Result<Var<'t, T>> {
        self.check_entities(inputs.entities)?;
        let (n_edges, ne) = (edges.len(), inputs.entities);
        let (gaussians, (start, stop), spacing, coeff) = rbf_parameters();
        let (mut x, mut flags, mut types) =
            (Vec::with_capacity(n_edges), Vec::with_capacity(2 * n_edges), Vec::with_capacity(2 * n_edges));
        for (&i, &j) in edges.src.iter().zip(&edges.dst) {
            let xd = 10.0 * distance(inputs.positions[i], inputs.positions[j]);
            x.push(xd);
            flags.extend([xd < start, xd >= stop].map(flag::<T>));
            types.extend(self.edge_type::<T>(i, j, ne));
        }
        let centres: Vec<f64> = (0..gaussians).map(|k| start + spacing * k as f64).collect();
        let flags = tape.constant(Tensor::new(flags, &[n_edges, 2])?);
        let gauss = tape.gaussian_basis(&x, &centres, coeff)?;
        Ok(tape.cat(
            &[flags.narrow(1, 0, 1)?, gauss, flags.narrow(1, 1, 1)?, tape.constant(Tensor::new(types, &[n_edges, 2])?)],
            1,
        )?)
    }

    /// The edge type of `i -> j` (rows of scenes of `ne` entities) as its one-hot
    /// `[different kind, same kind]`.
    fn edge_type<T: Float>(&self, i: usize, j: usize, ne: usize) -> [T; EDGE_TYPES] {
        let same = self.kinds[i % ne] == self.kinds[j % ne];
        [!same, same].map(flag::<T>)
    }

    /// An error unless the critic was built for `ne` entities.
    fn check_entities(&self, ne: usize) -> Result<()> {
        if ne == 0 || self.kinds.len() != ne {
            return Err(ModelError::Input(format!("critic of {} entities got {ne}", self.kinds.len())));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The critic's edge features as the tape builds them (`10 d` and the flags on the host,
    /// the Gaussians from [`Tape::gaussian_basis`]) are [`release_rbf`]'s, bit for bit on the
    /// CPU, at lengths inside, at the ends of and outside the centres' span.
    #[test]
    fn the_tapes_gaussians_are_the_release_features_bit_for_bit() {
        let (gaussians, (start, _), spacing, coeff) = rbf_parameters();
        let centres: Vec<f64> = (0..gaussians).map(|k| start + spacing * k as f64).collect();
        let lengths = [0.0, 1e-3, 0.37, 1.0, 1.9999, 2.0, 3.5];
        let x: Vec<f64> = lengths.iter().map(|d| 10.0 * d).collect();
        let tape = Tape::<f32>::new();
        let basis = tape.gaussian_basis(&x, &centres, coeff).unwrap().value();
        for (row, &d) in basis.data().chunks(gaussians).zip(&lengths) {
            let want: Vec<f32> = release_rbf(d)[1..=gaussians].iter().map(|&v| v as f32).collect();
            assert_eq!(row, &want[..], "length {d}");
        }
    }
}
