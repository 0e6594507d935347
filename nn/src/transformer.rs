//! Transformer encoder (PyTorch's `nn.TransformerEncoderLayer` with `norm_first = false`,
//! ReLU and no dropout, stacked as `nn.TransformerEncoder` without a final norm).

use tensor::{Activation, Float, Var};

use crate::attention::MultiHeadAttention;
use crate::error::{NnError, Result};
use crate::linear::Linear;
use crate::norm::LayerNorm;
use crate::params::{Bound, Scope};

/// Sizes of a Transformer encoder. `Default` gives the paper's Transformer: model dim 128,
/// feed-forward 256, 3 layers, 2 heads, LayerNorm eps 1e-5.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransformerConfig {
    /// Token width `D` (divisible by `heads`).
    pub model_dim: usize,
    /// Hidden width `F` of the feed-forward block.
    pub ff_dim: usize,
    /// Number of encoder layers.
    pub num_layers: usize,
    /// Attention heads per layer.
    pub heads: usize,
    /// `eps` of every LayerNorm.
    pub layer_norm_eps: f64,
}

impl Default for TransformerConfig {
    fn default() -> Self {
        Self { model_dim: 128, ff_dim: 256, num_layers: 3, heads: 2, layer_norm_eps: LayerNorm::DEFAULT_EPS }
    }
}

impl TransformerConfig {
    /// Checks that all sizes are positive, `model_dim` is divisible by `heads` and `eps` is
    /// positive; the error names the offending values.
    pub fn validate(&self) -> Result<()> {
        let Self { model_dim, ff_dim, num_layers, heads, layer_norm_eps } = *self;
        if model_dim == 0 || ff_dim == 0 || num_layers == 0 || heads == 0 {
            return Err(NnError::Config(format!(
                "transformer sizes must be positive, got model_dim {model_dim}, ff_dim {ff_dim}, num_layers {num_layers}, heads {heads}"
            )));
        }
        if !model_dim.is_multiple_of(heads) {
            return Err(NnError::Config(format!(
                "transformer model_dim {model_dim} is not divisible by heads {heads}"
            )));
        }
        if !(layer_norm_eps > 0.0 && layer_norm_eps.is_finite()) {
            return Err(NnError::Config(format!("transformer layer_norm_eps must be positive, got {layer_norm_eps}")));
        }
        Ok(())
    }
}

/// One post-norm encoder layer:
/// `x = norm1(x + self_attn(x)); x = norm2(x + linear2(relu(linear1(x))))`.
///
/// Parameters: `self_attn.{q,k,v,out}.{weight,bias}`, `linear1.*` (`D -> F`),
/// `linear2.*` (`F -> D`), `norm1.{weight,bias}`, `norm2.{weight,bias}` (PyTorch's names,
/// except that the fused `in_proj` is split into `q`, `k`, `v`).
#[derive(Clone, Debug)]
pub struct TransformerEncoderLayer {
    /// Multi-head self-attention.
    pub self_attn: MultiHeadAttention,
    /// First feed-forward layer `D -> F` (followed by ReLU).
    pub linear1: Linear,
    /// Second feed-forward layer `F -> D`.
    pub linear2: Linear,
    /// Norm after the attention block.
    pub norm1: LayerNorm,
    /// Norm after the feed-forward block.
    pub norm2: LayerNorm,
}

impl TransformerEncoderLayer {
    /// A layer with the sizes of `cfg` (`cfg.num_layers` is not used).
    pub fn new<T: Float>(s: &mut Scope<'_, T>, cfg: TransformerConfig) -> Result<Self> {
        cfg.validate()?;
        let (d, f, eps) = (cfg.model_dim, cfg.ff_dim, cfg.layer_norm_eps);
        Ok(Self {
            self_attn: MultiHeadAttention::new(&mut s.sub("self_attn"), d, cfg.heads)?,
            linear1: Linear::new(&mut s.sub("linear1"), d, f)?,
            linear2: Linear::new(&mut s.sub("linear2"), f, d)?,
            norm1: LayerNorm::with_eps(&mut s.sub("norm1"), d, eps)?,
            norm2: LayerNorm::with_eps(&mut s.sub("norm2"), d, eps)?,
        })
    }

    /// `x: [B, N, D]` -> `[B, N, D]`; `key_padding_mask` as in
    /// [`MultiHeadAttention::forward`] (`B * N` entries, `true` = padded).
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        x: Var<'t, T>,
        key_padding_mask: Option<&[bool]>,
    ) -> Result<Var<'t, T>> {
        let a = self.self_attn.forward(p, x, key_padding_mask)?;
        let x = self.norm1.forward(p, x.add(a)?)?;
        let hidden = self.linear1.forward_act(p, x, Activation::Relu)?;
        let ff = self.linear2.forward(p, hidden)?;
        self.norm2.forward(p, x.add(ff)?)
    }
}

/// A stack of [`TransformerEncoderLayer`]s named `layers.<i>.…` (no final norm, as
/// PyTorch's `nn.TransformerEncoder(layer, L)` with `norm = None`).
#[derive(Clone, Debug)]
pub struct TransformerEncoder {
    /// The layers, input first.
    pub layers: Vec<TransformerEncoderLayer>,
    /// The sizes it was built with.
    pub config: TransformerConfig,
}

impl TransformerEncoder {
    /// `cfg.num_layers` independently initialised layers.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, cfg: TransformerConfig) -> Result<Self> {
        cfg.validate()?;
        let mut layers_scope = s.sub("layers");
        let layers = (0..cfg.num_layers)
            .map(|i| TransformerEncoderLayer::new(&mut layers_scope.sub(i), cfg))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { layers, config: cfg })
    }

    /// Applies every layer to `x: [B, N, D]` with the same `key_padding_mask`
    /// (`B * N` entries, `true` = padded).
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        x: Var<'t, T>,
        key_padding_mask: Option<&[bool]>,
    ) -> Result<Var<'t, T>> {
        self.layers.iter().try_fold(x, |h, layer| layer.forward(p, h, key_padding_mask))
    }
}
