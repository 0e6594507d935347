//! Layer normalisation over the last dim (PyTorch's `nn.LayerNorm(dim)` semantics).

use tensor::{Float, Tensor, Var};

use crate::error::{NnError, Result};
use crate::params::{Bound, ParamId, Scope};

/// `y = (x - mean) / sqrt(var + eps) * weight + bias` over the last dim, with the biased
/// variance (divided by `dim`, as PyTorch) and learnable `weight` (ones) and `bias` (zeros).
#[derive(Clone, Debug)]
pub struct LayerNorm {
    /// The per-feature scale `[dim]`, named `weight`, initialised to ones.
    pub weight: ParamId,
    /// The per-feature shift `[dim]`, named `bias`, initialised to zeros.
    pub bias: ParamId,
    /// Size of the normalised (last) dim.
    pub dim: usize,
    /// Added to the variance before the square root.
    pub eps: f64,
}

impl LayerNorm {
    /// PyTorch's default `eps`.
    pub const DEFAULT_EPS: f64 = 1e-5;

    /// A layer over a last dim of size `dim` with `eps = 1e-5`.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, dim: usize) -> Result<Self> {
        Self::with_eps(s, dim, Self::DEFAULT_EPS)
    }

    /// A layer with an explicit `eps` (must be positive and finite).
    pub fn with_eps<T: Float>(s: &mut Scope<'_, T>, dim: usize, eps: f64) -> Result<Self> {
        if dim == 0 || !(eps > 0.0 && eps.is_finite()) {
            return Err(NnError::Config(format!(
                "{}: layer norm over dim {dim} with eps {eps}",
                s.full_name("weight")
            )));
        }
        let weight = s.param("weight", Tensor::ones(&[dim]))?;
        let bias = s.param("bias", Tensor::zeros(&[dim]))?;
        Ok(Self { weight, bias, dim, eps })
    }

    /// Normalises `x: [.., dim]` row by row, then scales and shifts.
    pub fn forward<'t, T: Float>(&self, p: &Bound<'t, T>, x: Var<'t, T>) -> Result<Var<'t, T>> {
        let shape = x.shape();
        if shape.last() != Some(&self.dim) {
            return Err(NnError::Config(format!(
                "layer norm over dim {} applied to an input of shape {shape:?}",
                self.dim
            )));
        }
        let normed = x.standardize(self.eps);
        Ok(normed.mul(p.get(self.weight))?.add(p.get(self.bias))?)
    }
}
