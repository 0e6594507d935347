//! A model's string form, `name:key=value;key=value` (a model of the paper, [`ModelKind`],
//! and the named options that keep every ablation runnable; the keys are [`OPTION_KEYS`]),
//! the types of the option values, and the limits on them.
//! [`ModelDescription::parse`](crate::description::ModelDescription::parse) reads the string
//! and moves each option, with the defaults, into the typed
//! [`ModelDescription`](crate::description::ModelDescription) the builders use.
//!
//! Every option's default is the paper's model as its reference release builds it (the
//! paper's equations and Algorithm 1 decide the structure; where the paper is silent the
//! release decides); the other values are the ablations and this project's earlier variants.

use crate::assignment::AssignmentMethod;
use crate::description::ShnnCritic;
use crate::error::{ModelError, Result};
use crate::input::{EntityAbstraction, Translation};
use crate::kind::ModelKind;

/// The option keys of a model string, `name` or `name:key=value;key=value`
/// ([`ModelDescription::parse`](crate::description::ModelDescription::parse)): `assignment`
/// (`greedy`, `hungarian`, `stochastic`, `none`, `learned`: the SHNN family, `mlp`,
/// `mlp_hn`), `translation` (`none`, `root_mean`, `body_mean`, `assigned`,
/// `assigned_entity`), `abstraction` (`root`, `mean`), `neighbour` (`unit`, `raw`, `none`),
/// `critic` (`separate`, `shared`), `gravity` (`input`, `every_layer`), `actor_steps` (a
/// positive integer, at most [`MAX_ACTOR_STEPS`]), `variant` (`release`, `flat`), `seed`
/// (integer), `head` and `critic_hidden` (hidden widths joined by `x`, e.g. `256x256`; at
/// most [`MAX_LAYERS`], each at most [`MAX_WIDTH`]), and with `assignment=learned` its
/// scorer's `assign_hidden` (hidden widths as `head`'s, or `none` for an affine scorer) and
/// `assign_prior` (`λ`, a number in `[0, MAX_DISTANCE_PRIOR]`), and for every model but
/// `shtransformer` `assign_critic` (`none`, `held`: whether the value reads the assignment held into each
/// step). E.g. `shnn:assignment=hungarian;critic=shared`.
pub const OPTION_KEYS: [&str; 14] = [
    "assignment",
    "translation",
    "abstraction",
    "neighbour",
    "critic",
    "gravity",
    "actor_steps",
    "variant",
    "seed",
    "head",
    "critic_hidden",
    "assign_hidden",
    "assign_prior",
    "assign_critic",
];

/// Sizes of the entity-level message passing (paper Table "Hyperparameters of Network").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MpSizes {
    /// Vector channels `m` (32).
    pub vectors: usize,
    /// Scalar features (64).
    pub scalars: usize,
    /// Hidden width of the message and update MLPs (64).
    pub hidden: usize,
    /// Hidden layers of those MLPs (2).
    pub layers: usize,
    /// Propagation steps of the critic's message passing and of the body GNN (2; the
    /// actor's entity stage takes
    /// [`EntityStage::actor_steps`](crate::description::EntityStage::actor_steps)).
    pub steps: usize,
}

impl Default for MpSizes {
    /// The paper's sizes.
    fn default() -> Self {
        Self { vectors: 32, scalars: 64, hidden: 64, layers: 2, steps: 2 }
    }
}

/// How the position of a neighbour's root enters the actor (eq. (lrf): the row
/// `O_i^T Z_{j,1}, h_{j,1}` of the entity `j` assigned to agent `i`, position
/// `p_{j,1} - p_{C(j),1} = p_{j,1} - p_{i,1}`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NeighbourOffset {
    /// The offset scaled to a unit direction, `d / (|d| + 1e-6)` (the reference release's
    /// actor, `models/SHNN.py`); the entity stage then has no edge scalar (the distance of a
    /// unit offset carries nothing).
    #[default]
    Unit,
    /// The raw offset `p_{j,1} - p_{i,1}`, with its length as the edge scalar of eq.
    /// (scalar-interaction).
    Raw,
    /// No neighbour row in the head (this project's earlier SHNN; with
    /// `translation=assigned_entity` the agent's bodies are measured from the assigned
    /// entity instead).
    None,
}

impl NeighbourOffset {
    /// Parses `unit`, `raw` or `none`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "unit" => Ok(Self::Unit),
            "raw" => Ok(Self::Raw),
            "none" => Ok(Self::None),
            _ => Err(ModelError::Option(format!("unknown neighbour `{s}` (expected unit, raw or none)"))),
        }
    }
}

/// Where the gravity direction enters the entity-level message passing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GravityMode {
    /// Once, as a 4th input vector channel (the reference release; its counts, e.g. SHNN's
    /// 0.772M, include no more).
    #[default]
    Input,
    /// Also appended before every mixing inside each layer (eq. (subeq) read literally:
    /// `[Z, g] M_g`; this project's earlier choice).
    EveryLayer,
}

impl GravityMode {
    /// Parses `input` or `every_layer`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "input" => Ok(Self::Input),
            "every_layer" => Ok(Self::EveryLayer),
            _ => Err(ModelError::Option(format!("unknown gravity `{s}` (expected input or every_layer)"))),
        }
    }
}

/// Which network `mlp` and `mlp_hn` are.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MlpVariant {
    /// The release's MLP (`models/MLP.py`, the network of the paper's MLP+HN 1.759M):
    /// per-node embeddings, then 256, 256 (module [`crate::mlp`]).
    #[default]
    Release,
    /// This project's earlier baseline: 256 x 3 on the flat agent view.
    Flat,
}

impl MlpVariant {
    /// Parses `release` or `flat`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "release" => Ok(Self::Release),
            "flat" => Ok(Self::Flat),
            _ => Err(ModelError::Option(format!("unknown variant `{s}` (expected release or flat)"))),
        }
    }
}

/// A model string's options as given (`None`: not given), before
/// [`ModelDescription::parse`](crate::description::ModelDescription::parse) moves each into
/// the field the model has for it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct GivenOptions {
    /// The model's name as given (one of [`ModelKind::ALL`]).
    pub(crate) name: String,
    /// Option `assignment`.
    pub(crate) assignment: Option<AssignmentMethod>,
    /// Option `translation`.
    pub(crate) translation: Option<Translation>,
    /// Option `abstraction`.
    pub(crate) abstraction: Option<EntityAbstraction>,
    /// Option `neighbour`.
    pub(crate) neighbour: Option<NeighbourOffset>,
    /// Option `critic`.
    pub(crate) critic: Option<ShnnCritic>,
    /// Option `gravity`.
    pub(crate) gravity: Option<GravityMode>,
    /// Option `actor_steps`.
    pub(crate) actor_steps: Option<usize>,
    /// Option `variant`.
    pub(crate) variant: Option<MlpVariant>,
    /// Option `head`.
    pub(crate) head_hidden: Option<Vec<usize>>,
    /// Option `critic_hidden`.
    pub(crate) critic_hidden: Option<Vec<usize>>,
    /// Option `assign_hidden` (`none`: empty).
    pub(crate) assign_hidden: Option<Vec<usize>>,
    /// Option `assign_prior`.
    pub(crate) assign_prior: Option<DistancePrior>,
    /// Option `assign_critic` (`held`: true, `none`: false).
    pub(crate) assign_critic: Option<bool>,
    /// Option `seed` (default 0), which every model takes.
    pub(crate) seed: u64,
}

impl GivenOptions {
    /// Parses `name` or `name:key=value;key=value`, keys and values as [`OPTION_KEYS`] lists
    /// them. Whether an option applies to the model is decided by
    /// [`ModelDescription::parse`](crate::description::ModelDescription::parse).
    pub(crate) fn parse(s: &str) -> Result<Self> {
        let (name, opts) = s.split_once(':').unwrap_or((s, ""));
        ModelKind::parse(name)?;
        let mut c = Self {
            name: name.to_string(),
            assignment: None,
            translation: None,
            abstraction: None,
            neighbour: None,
            critic: None,
            gravity: None,
            actor_steps: None,
            variant: None,
            head_hidden: None,
            critic_hidden: None,
            assign_hidden: None,
            assign_prior: None,
            assign_critic: None,
            seed: 0,
        };
        let mut seen: Vec<&str> = Vec::new();
        for item in opts.split(';').filter(|_| !opts.is_empty()) {
            if item.trim().is_empty() {
                return Err(ModelError::Option(format!(
                    "`{s}` has an empty model option (options are key=value joined by `;`)"
                )));
            }
            let (k, v) = item.split_once('=').ok_or_else(|| {
                ModelError::Option(format!("model option `{item}` is not key=value (keys: {})", OPTION_KEYS.join(", ")))
            })?;
            if seen.contains(&k) {
                return Err(ModelError::Option(format!("model option `{k}` is given twice in `{s}`")));
            }
            seen.push(k);
            match k {
                "assignment" => c.assignment = Some(AssignmentMethod::parse(v).map_err(ModelError::Option)?),
                "translation" => c.translation = Some(Translation::parse(v)?),
                "abstraction" => c.abstraction = Some(EntityAbstraction::parse(v)?),
                "neighbour" => c.neighbour = Some(NeighbourOffset::parse(v)?),
                "critic" => c.critic = Some(ShnnCritic::parse(v)?),
                "gravity" => c.gravity = Some(GravityMode::parse(v)?),
                "actor_steps" => {
                    let n = v.parse::<usize>().ok().filter(|&n| (1..=MAX_ACTOR_STEPS).contains(&n));
                    c.actor_steps = Some(n.ok_or_else(|| {
                        ModelError::Option(format!(
                            "actor_steps `{v}` is not a positive integer at most {MAX_ACTOR_STEPS}"
                        ))
                    })?);
                }
                "variant" => c.variant = Some(MlpVariant::parse(v)?),
                "seed" => {
                    c.seed = v.parse().map_err(|_| ModelError::Option(format!("seed `{v}` is not an integer")))?;
                }
                "head" => c.head_hidden = Some(parse_widths(k, v)?),
                "critic_hidden" => c.critic_hidden = Some(parse_widths(k, v)?),
                "assign_hidden" => c.assign_hidden = Some(if v == "none" { Vec::new() } else { parse_widths(k, v)? }),
                "assign_prior" => c.assign_prior = Some(DistancePrior::parse(v)?),
                "assign_critic" => {
                    c.assign_critic = Some(match v {
                        "held" => true,
                        "none" => false,
                        _ => {
                            return Err(ModelError::Option(format!(
                                "model option `assign_critic`: `{v}` is not `none` or `held`"
                            )));
                        }
                    });
                }
                _ => {
                    return Err(ModelError::Option(format!(
                        "unknown model option `{k}` (known: {})",
                        OPTION_KEYS.join(", ")
                    )));
                }
            }
        }
        Ok(c)
    }

    /// The first option still given (in [`OPTION_KEYS`] order, `seed` aside): after the
    /// model has taken its own, one it does not take.
    pub(crate) fn first_set(&self) -> Option<&'static str> {
        [
            ("assignment", self.assignment.is_some()),
            ("translation", self.translation.is_some()),
            ("abstraction", self.abstraction.is_some()),
            ("neighbour", self.neighbour.is_some()),
            ("critic", self.critic.is_some()),
            ("gravity", self.gravity.is_some()),
            ("actor_steps", self.actor_steps.is_some()),
            ("variant", self.variant.is_some()),
            ("head", self.head_hidden.is_some()),
            ("critic_hidden", self.critic_hidden.is_some()),
            ("assign_hidden", self.assign_hidden.is_some()),
            ("assign_prior", self.assign_prior.is_some()),
            ("assign_critic", self.assign_critic.is_some()),
        ]
        .into_iter()
        .find_map(|(k, set)| set.then_some(k))
    }
}

/// The widest hidden layer an option may ask for (a 8192 x 8192 layer is 67M parameters).
pub const MAX_WIDTH: usize = 8192;

/// The most hidden layers an option may ask for.
pub const MAX_LAYERS: usize = 16;

/// The largest `assign_prior`: with distances of metres, `λ = 1000` already makes the
/// learned assignment Algorithm 1 for any scores a network gives.
pub const MAX_DISTANCE_PRIOR: f64 = 1000.0;

/// `λ` of the learned assignment's scores `s_ij = f_θ(x_ij) - λ d_ij`
/// ([`crate::assignment_learned`]): a finite number in `[0, MAX_DISTANCE_PRIOR]` (option
/// `assign_prior`). It is never NaN, so it is `Eq`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistancePrior(f64);

impl Eq for DistancePrior {}

impl DistancePrior {
    /// `λ = v`, if `v` is in `[0, MAX_DISTANCE_PRIOR]` (`-0` is `0`).
    pub fn new(v: f64) -> Result<Self> {
        if (0.0..=MAX_DISTANCE_PRIOR).contains(&v) { Ok(Self(v + 0.0)) } else { Err(Self::out_of_range(v)) }
    }

    /// Parses a decimal number in `[0, MAX_DISTANCE_PRIOR]`.
    pub fn parse(v: &str) -> Result<Self> {
        v.parse::<f64>().ok().and_then(|x| Self::new(x).ok()).ok_or_else(|| Self::out_of_range(v))
    }

    fn out_of_range(v: impl std::fmt::Display) -> ModelError {
        ModelError::Option(format!("model option `assign_prior`: `{v}` is not a number in [0, {MAX_DISTANCE_PRIOR}]"))
    }

    /// `λ`.
    pub fn get(self) -> f64 {
        self.0
    }
}

/// The most message-passing steps of `actor_steps`.
pub const MAX_ACTOR_STEPS: usize = 64;

fn parse_widths(key: &str, v: &str) -> Result<Vec<usize>> {
    let w: Vec<usize> = v
        .split('x')
        .map(|x| x.parse::<usize>().ok().filter(|&n| (1..=MAX_WIDTH).contains(&n)))
        .collect::<Option<_>>()
        .filter(|w: &Vec<usize>| w.len() <= MAX_LAYERS)
        .ok_or_else(|| {
            ModelError::Option(format!(
                "model option `{key}`: hidden widths `{v}` are not at most {MAX_LAYERS} positive integers, \
                 each at most {MAX_WIDTH}, joined by x"
            ))
        })?;
    Ok(w)
}

/// `[input, hidden.., output]`.
pub(crate) fn layer_sizes(input: usize, hidden: &[usize], output: usize) -> Vec<usize> {
    let mut v = vec![input];
    v.extend_from_slice(hidden);
    v.push(output);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_repeated_and_huge_options_are_refused() {
        for (spec, needle) in [
            ("shnn:;;;", "empty model option"),
            ("shnn:critic=shared;", "empty model option"),
            ("shnn:critic=shared;critic=separate", "`critic` is given twice"),
            ("mlp:head=4000000000", "8192"),
            ("mlp:head=64x0", "head"),
            (&format!("mlp:head={}", ["8"; 17].join("x")), "at most 16"),
            ("shnn:actor_steps=100000", "actor_steps"),
        ] {
            let e = GivenOptions::parse(spec).unwrap_err().to_string();
            assert!(e.contains(needle), "{spec}: {e}");
        }
        assert!(GivenOptions::parse("shnn:").is_ok());
        assert_eq!(GivenOptions::parse("mlp:head=8192x16").unwrap().head_hidden, Some(vec![8192, 16]));
    }
}
