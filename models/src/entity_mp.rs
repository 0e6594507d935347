//! Local entity-level subequivariant message passing `φ_o` (paper eq. (somp), unfolded in
//! eqs. (vector-interaction) to (update-mlp)) and the local reference frame vector
//! `u_i = Z'_i W_u` with `O_i = OP(u_i)` (eqs. (ortho), (ort_matrix)).
//!
//! A thin wrapper around [`nn::SubeqMessagePassing`], in the structure of the reference
//! release (`models/SHNN.py`, MEBEN.md section 5):
//! 1. embedding: `Z = [Z_i, g] W_e` (the 3 input channels plus gravity as a 4th channel,
//!    mixed to `m = 32`; no bias, so `Z` stays equivariant) and `h = h_i W_h + b_h`
//!    (`ENTITY_SCALARS -> 64`);
//! 2. `steps` rounds of one shared [`nn::SubeqMessagePassing`] layer (hidden 64 x 2, mean
//!    aggregation) over the entity graph, with the entity positions (the position channel of
//!    `Z_i`) as `p_{i,1}`; edge scalars as configured: none (the release's actor, whose
//!    offsets are unit directions), the distance `|p_j - p_i|` (eq. (scalar-interaction)),
//!    or the caller's (the critic's radial basis and edge types); `g` is appended inside
//!    each `φ_g`, `ψ_g` only with `gravity_in_layers` (eq. (subeq) read literally; the
//!    release mixes it in once, at the input);
//! 3. for the actor, `u_i = Z'_i W_u` (`W_u ∈ R^{m×1}`) and `O_i = OP(u_i)`
//!    ([`crate::frame::local_frame`]).
//!
//! `Z'_i` and `u_i` rotate with the scene about `g` and `O_i` with them; `h'_i` is
//! invariant. With `gravity: None` (the `SO(3)` ablation) `g` enters nowhere.

use nn::{
    Aggregation, Bound, EdgeDistance, EdgeList, Linear, MessagePassingConfig, Scope, SubeqMessagePassing, VectorLinear,
};
use tensor::{Float, Tensor, Var};

use crate::entity_graph::EntityGraph;
use crate::error::{ModelError, Result};
use crate::frame::local_frame;
use crate::input::{ENTITY_SCALARS, EntityInputs};
use envs::layout::NODE_VECTORS;
use envs::layout::ObsSpec;

/// `eps` under the root of the horizontal norm in `OP` (keeps a vertical `u` finite).
pub const FRAME_EPS: f64 = 1e-12;

/// Sizes and options of [`EntityMp`].
#[derive(Clone, Debug)]
pub struct EntityMpConfig {
    /// Vector channels `m` of `Z'` (32).
    pub vectors: usize,
    /// Scalar features of `h'` (64).
    pub scalars: usize,
    /// Hidden width of the message and update MLPs (64).
    pub hidden: usize,
    /// Hidden layers of those MLPs (2).
    pub layers: usize,
    /// Propagation steps with the shared layer (the release's actor 1, its critic 2).
    pub steps: usize,
    /// Edge scalar from the edge vector's length (none in the release's actor, the raw
    /// distance of eq. (scalar-interaction), or a radial basis).
    pub distance: EdgeDistance,
    /// Caller-supplied invariant scalars per edge (the release's critic: 64 radial-basis
    /// features and a 2-way edge type).
    pub edge_scalars: usize,
    /// Message aggregation (mean, as the release).
    pub aggregation: Aggregation,
    /// Gravity direction `g`, mixed in as a 4th input channel (`None`: the `SO(3)` ablation
    /// without a gravity channel).
    pub gravity: Option<[f64; 3]>,
    /// Whether `g` is also appended inside every layer (eq. (subeq) read literally).
    pub gravity_in_layers: bool,
    /// Whether the stage ends with `u_i = Z'_i W_u` and `O_i = OP(u_i)` (the actor; the
    /// critic's stage has no `W_u`).
    pub frame: bool,
}

impl EntityMpConfig {
    /// The release's actor stage (MEBEN.md section 5): 32 vectors, 64 scalars, hidden 64 x 2,
    /// one round, no edge scalar, `g` = [`ObsSpec::gravity_dir`] at the input, with the
    /// frame.
    pub fn paper(spec: &ObsSpec) -> Self {
        Self {
            vectors: 32,
            scalars: 64,
            hidden: 64,
            layers: 2,
            steps: 1,
            distance: EdgeDistance::None,
            edge_scalars: 0,
            aggregation: Aggregation::Mean,
            gravity: Some(spec.gravity_dir.map(f64::from)),
            gravity_in_layers: false,
            frame: true,
        }
    }
}

/// The entity stage's outputs (rows = entities of the batch, as in
/// [`crate::input::EntityInputs`]).
#[derive(Clone, Copy, Debug)]
pub struct EntityFeatures<'t, T: Float> {
    /// `Z'_i` `[B*E, 3, m]` (equivariant).
    pub z: Var<'t, T>,
    /// `h'_i` `[B*E, s]` (invariant).
    pub h: Var<'t, T>,
    /// `u_i = Z'_i W_u` `[B*E, 3]` (a stage built with `frame`).
    pub u: Option<Var<'t, T>>,
    /// `O_i = OP(u_i)` `[B*E, 3, 3]`, columns `e1, e2, e3` (a stage built with `frame`).
    pub frame: Option<Var<'t, T>>,
}

impl<'t, T: Float> EntityFeatures<'t, T> {
    /// `O_i`, or an error for a stage built without the frame.
    pub fn frame(&self) -> Result<Var<'t, T>> {
        self.frame.ok_or_else(|| ModelError::Input("this entity stage has no local frame (W_u)".into()))
    }
}

/// `φ_o` and the LRF vector (module docs).
#[derive(Clone, Debug)]
pub struct EntityMp {
    /// `W_e`: `[Z_i (, g)]` -> `m` channels.
    pub embed_z: VectorLinear,
    /// `h_i` -> `s` scalars (affine).
    pub embed_h: Linear,
    /// The message-passing layer shared by all steps.
    pub mp: SubeqMessagePassing,
    /// `W_u`: `m` channels -> 1 (a stage built with `frame`).
    pub w_u: Option<VectorLinear>,
    /// The configuration.
    pub config: EntityMpConfig,
}

impl EntityMp {
    /// Parameters `<scope>.embed_z.weight`, `<scope>.embed_h.{weight,bias}`, `<scope>.mp.*`,
    /// `<scope>.w_u.weight` (with `frame`).
    pub fn new<T: Float>(s: &mut Scope<'_, T>, config: EntityMpConfig) -> Result<Self> {
        if config.steps == 0 || config.vectors == 0 || config.scalars == 0 {
            return Err(ModelError::Option(format!(
                "entity message passing with {} steps, {} vectors, {} scalars",
                config.steps, config.vectors, config.scalars
            )));
        }
        let g = usize::from(config.gravity.is_some());
        let embed_z = VectorLinear::new(&mut s.sub("embed_z"), NODE_VECTORS + g, config.vectors)?;
        let embed_h = Linear::new(&mut s.sub("embed_h"), ENTITY_SCALARS, config.scalars)?;
        let mp = SubeqMessagePassing::new(
            &mut s.sub("mp"),
            MessagePassingConfig {
                vectors: config.vectors,
                scalars: config.scalars,
                hidden: config.hidden,
                layers: config.layers,
                distance: config.distance.clone(),
                aggregation: config.aggregation,
                gravity: if config.gravity_in_layers { config.gravity } else { None },
                edge_scalars: config.edge_scalars,
            },
        )?;
        let w_u = if config.frame { Some(VectorLinear::new(&mut s.sub("w_u"), config.vectors, 1)?) } else { None };
        Ok(Self { embed_z, embed_h, mp, w_u, config })
    }

    /// `φ_o` on entity features `z0: [n, 3, 3]` (position, velocity, angular velocity) and
    /// `h0: [n, ENTITY_SCALARS]` over `edges` (`n` nodes), with the caller's edge scalars
    /// `[E, edge_scalars]` if the stage takes some, then `u` and `O`.
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z0: Var<'t, T>,
        h0: Var<'t, T>,
        edges: &EdgeList,
        edge_scalars: Option<Var<'t, T>>,
    ) -> Result<EntityFeatures<'t, T>> {
        let n = edges.num_nodes;
        if z0.shape() != [n, 3, NODE_VECTORS] || h0.shape() != [n, ENTITY_SCALARS] {
            return Err(ModelError::Input(format!(
                "entity stage expects z [{n}, 3, {NODE_VECTORS}] and h [{n}, {ENTITY_SCALARS}]; got {:?} and {:?}",
                z0.shape(),
                h0.shape()
            )));
        }
        let x = z0.narrow(2, 0, 1)?; // p_{i,1}: [n, 3, 1]
        let mut z = self.embed_z.forward_channels(p, &[z0], self.config.gravity)?;
        let mut h = self.embed_h.forward(p, h0)?;
        // The positions stay put: every round reads the same edge geometry.
        let geometry = self.mp.edge_geometry(x, edges)?;
        for _ in 0..self.config.steps {
            (z, h) = self.mp.forward_over(p, z, h, &geometry, edges, edge_scalars)?;
        }
        let (u, frame) = match &self.w_u {
            Some(w_u) => {
                let u = w_u.forward(p, z)?.reshape(&[n, 3])?;
                (Some(u), Some(local_frame(u, FRAME_EPS)?))
            }
            None => (None, None),
        };
        Ok(EntityFeatures { z, h, u, frame })
    }

    /// [`EntityMp::forward`] on processed observations (`z` as
    /// [`crate::input::InputProcessor::actor_entities`] gives it, `inputs.h`) and their
    /// entity graph; the inputs enter the tape as constants.
    pub fn forward_inputs<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z: Tensor<T>,
        inputs: &EntityInputs<T>,
        graph: &EntityGraph,
    ) -> Result<EntityFeatures<'t, T>> {
        if graph.batch != inputs.batch || graph.entities != inputs.entities {
            return Err(ModelError::Input(format!(
                "entity graph of {} x {} entities for inputs of {} x {}",
                graph.batch, graph.entities, inputs.batch, inputs.entities
            )));
        }
        let tape = p.tape();
        self.forward(p, tape.constant(z), tape.constant(inputs.h.clone()), &graph.edges, None)
    }
}
