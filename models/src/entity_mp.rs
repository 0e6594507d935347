//! Local entity-level subequivariant message passing `φ_o` (paper eq. (somp), unfolded in
//! eqs. (vector-interaction) to (update-mlp)) and the local reference frame vector
//! `u_i = Z'_i W_u` with `O_i = OP(u_i)` (eqs. (ortho), (ort_matrix)).
//!
//! A thin wrapper around [`nn::SubeqMessagePassing`], in the structure of the reference
//! release (MEBEN.md section 5):
//! 1. embedding: `Z = [Z_i, g] W_e` (the 3 input channels plus gravity as a 4th channel,
//!    mixed to `m = 32`; no bias, so `Z` stays equivariant) and `h = h_i W_h + b_h`
//!    (`ENTITY_SCALARS -> 64`);
//! 2. `steps = 2` rounds of one shared [`nn::SubeqMessagePassing`] layer (hidden 64 x 2,
//!    mean aggregation, the distance `|p_j - p_i|` as edge scalar, gravity appended inside
//!    each `φ_g`, `ψ_g` as eq. (subeq) writes `[Z, g]`) over the entity graph, with the
//!    entity root positions (the position channel of `Z_i`) as `p_{i,1}`;
//! 3. `u_i = Z'_i W_u` (`W_u ∈ R^{m×1}`) and `O_i = OP(u_i)` ([`crate::frame::local_frame`]).
//!
//! `Z'_i` and `u_i` rotate with the scene about `g` and `O_i` with them; `h'_i` is
//! invariant. With `gravity: None` (the `SO(3)` ablation) `g` enters nowhere.

use envs::tasks::ObsSpec;
use nn::{
    Aggregation, Bound, EdgeDistance, EdgeList, Linear, MessagePassingConfig, Scope, SubeqMessagePassing, VectorLinear,
};
use tensor::{Float, Var};

use crate::entity_graph::EntityGraph;
use crate::error::{ModelError, Result};
use crate::frame::local_frame;
use crate::input::{ENTITY_SCALARS, EntityInputs, NODE_VECTORS};

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
    /// Propagation steps with the shared layer (2).
    pub steps: usize,
    /// Edge scalar from the root distance (the raw distance, eq. (scalar-interaction)).
    pub distance: EdgeDistance,
    /// Message aggregation (mean, as the release).
    pub aggregation: Aggregation,
    /// Gravity direction `g` (`None`: the `SO(3)` ablation without a gravity channel).
    pub gravity: Option<[f64; 3]>,
}

impl EntityMpConfig {
    /// The paper's sizes (MEBEN.md section 5) with `g` = [`ObsSpec::gravity_dir`].
    pub fn paper(spec: &ObsSpec) -> Self {
        Self {
            vectors: 32,
            scalars: 64,
            hidden: 64,
            layers: 2,
            steps: 2,
            distance: EdgeDistance::Raw,
            aggregation: Aggregation::Mean,
            gravity: Some(spec.gravity_dir.map(f64::from)),
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
    /// `u_i = Z'_i W_u` `[B*E, 3]`.
    pub u: Var<'t, T>,
    /// `O_i = OP(u_i)` `[B*E, 3, 3]`, columns `e1, e2, e3`.
    pub frame: Var<'t, T>,
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
    /// `W_u`: `m` channels -> 1.
    pub w_u: VectorLinear,
    /// The configuration.
    pub config: EntityMpConfig,
}

impl EntityMp {
    /// Parameters `<scope>.embed_z.weight`, `<scope>.embed_h.{weight,bias}`, `<scope>.mp.*`,
    /// `<scope>.w_u.weight`.
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
                gravity: config.gravity,
            },
        )?;
        let w_u = VectorLinear::new(&mut s.sub("w_u"), config.vectors, 1)?;
        Ok(Self { embed_z, embed_h, mp, w_u, config })
    }

    /// `φ_o` on entity features `z0: [n, 3, 3]` (position relative to the scene origin,
    /// velocity, angular velocity) and `h0: [n, ENTITY_SCALARS]` over `edges` (`n` nodes),
    /// then `u` and `O`.
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z0: Var<'t, T>,
        h0: Var<'t, T>,
        edges: &EdgeList,
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
        for _ in 0..self.config.steps {
            (z, h) = self.mp.forward(p, z, h, x, edges)?;
        }
        let u = self.w_u.forward(p, z)?.reshape(&[n, 3])?;
        let frame = local_frame(u, FRAME_EPS)?;
        Ok(EntityFeatures { z, h, u, frame })
    }

    /// [`EntityMp::forward`] on processed observations and their entity graph (the inputs
    /// enter the tape as constants).
    pub fn forward_inputs<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
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
        self.forward(p, tape.constant(inputs.z.clone()), tape.constant(inputs.h.clone()), &graph.edges)
    }
}
