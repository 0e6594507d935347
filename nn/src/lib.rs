//! `nn`: neural-network layers, optimisers and saved state on top of the `tensor` crate.
//!
//! - Parameters live in a [`ParamStore`] under stable dotted names; layers are created in a
//!   [`Scope`] and hold [`ParamId`]s; a forward pass reads them from a [`Bound`]
//!   (the store placed on a tape).
//! - Layers: [`Linear`], [`Mlp`], [`LayerNorm`], [`MultiHeadAttention`],
//!   [`TransformerEncoderLayer`] / [`TransformerEncoder`] ([`TransformerConfig`]),
//!   [`RadialBasis`], and the subequivariant blocks of the paper
//!   ([`VectorLinear`], [`gram`], [`SubequivariantFn`], [`SubeqMessagePassing`]).
//! - Optimisation: [`Adam`], [`clip_elementwise`], [`clip_global_norm`], [`LrSchedule`].
//! - Saved state: [`StateDict`] (JSON through serde, written atomically, checked on load).
//!
//! One training step (the example of the README):
//!
//! ```
//! use nn::{Adam, AdamConfig, Mlp, ParamStore, clip_elementwise};
//! use tensor::{Activation, Tape, Tensor};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut store = ParamStore::<f32>::new();
//! let mut rng = nn::init_rng(0);
//! let mlp = Mlp::new(&mut store.scope("actor", &mut rng), &[4, 64, 2], Activation::Relu)?;
//! let mut adam = Adam::new(AdamConfig::default(), &store);
//!
//! let tape = Tape::new();
//! let params = store.bind(&tape);
//! let x = tape.constant(Tensor::zeros(&[8, 4]));
//! let loss = mlp.forward(&params, x)?.square().mean_all()?;
//! let mut grads = params.grads(&tape.backward(loss)?);
//! clip_elementwise(&mut grads, 0.1);
//! adam.step(&mut store, &grads)?;
//! assert_eq!(store.names()[0], "actor.0.weight");
//! # Ok(())
//! # }
//! ```

pub mod atomic;
pub mod attention;
pub mod equivariant;
pub mod error;
pub mod init;
pub mod linear;
pub mod message_passing;
pub mod norm;
pub mod optim;
pub mod params;
pub mod rbf;
pub mod state;
pub mod transformer;

pub use atomic::{is_temporary, write_atomic};
pub use attention::MultiHeadAttention;
pub use equivariant::{SubeqSizes, SubequivariantFn, VectorLinear, gram};
pub use error::{NnError, Result};
pub use init::Init;
pub use linear::{Linear, Mlp};
pub use message_passing::{
    Aggregation, EdgeDistance, EdgeGeometry, EdgeList, MessagePassingConfig, SubeqMessagePassing,
};
pub use norm::LayerNorm;
pub use optim::{Adam, AdamConfig, LrSchedule, clip_elementwise, clip_global_norm};
pub use params::{Bound, ParamId, ParamStore, Scope, init_rng};
pub use rbf::RadialBasis;
pub use state::{SavedTensor, StateDict};
pub use transformer::{TransformerConfig, TransformerEncoder, TransformerEncoderLayer};
