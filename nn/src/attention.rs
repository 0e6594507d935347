//! Multi-head scaled dot-product self-attention with an optional key padding mask.

use tensor::{Float, Tensor, Var};

use crate::error::{NnError, Result};
use crate::linear::Linear;
use crate::params::{Bound, Scope};

/// The score given to padded keys before the softmax. Finite (not `-inf`), so that a row
/// whose keys are all padded gets uniform weights instead of `NaN`; large enough that
/// `exp(MASKED_SCORE - max)` is exactly zero in `f32` and `f64` whenever some key is real.
const MASKED_SCORE: f64 = -1e9;

/// Self-attention over a set of `N` tokens with `heads` heads:
/// `out(concat_h softmax(Q_h K_h^T / sqrt(dh)) V_h)` where `Q = q(x)`, `K = k(x)`,
/// `V = v(x)` and `dh = dim / heads`.
///
/// Parameters: `q`, `k`, `v` and `out`, each a [`Linear`] `dim -> dim` with a bias
/// (LeCun-uniform weights, zero biases). There is no positional encoding: permuting the
/// tokens permutes the outputs.
#[derive(Clone, Debug)]
pub struct MultiHeadAttention {
    /// Query projection, named `q`.
    pub q: Linear,
    /// Key projection, named `k`.
    pub k: Linear,
    /// Value projection, named `v`.
    pub v: Linear,
    /// Output projection, named `out`.
    pub out: Linear,
    /// Model width `D`.
    pub dim: usize,
    /// Number of heads (divides `dim`).
    pub heads: usize,
}

impl MultiHeadAttention {
    /// A layer of width `dim` with `heads` heads; `dim` must be a positive multiple of
    /// `heads`.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, dim: usize, heads: usize) -> Result<Self> {
        if dim == 0 || heads == 0 || !dim.is_multiple_of(heads) {
            return Err(NnError::Config(format!(
                "{}: multi-head attention needs a positive model dim divisible by a positive number of heads, got dim {dim} and heads {heads}",
                s.full_name("")
            )));
        }
        let q = Linear::new(&mut s.sub("q"), dim, dim)?;
        let k = Linear::new(&mut s.sub("k"), dim, dim)?;
        let v = Linear::new(&mut s.sub("v"), dim, dim)?;
        let out = Linear::new(&mut s.sub("out"), dim, dim)?;
        Ok(Self { q, k, v, out, dim, heads })
    }

    /// Width of one head, `dim / heads`.
    pub fn head_dim(&self) -> usize {
        self.dim / self.heads
    }

    /// Self-attention of `x: [B, N, dim]` -> `[B, N, dim]`.
    ///
    /// `key_padding_mask`, if given, has `B * N` entries in row-major `[B, N]` order;
    /// `true` marks a padded token, which no query attends to. Outputs at padded positions
    /// are computed (from the real keys) but meaningless; a batch element whose tokens are
    /// all padded gets uniform attention weights, so every output stays finite.
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        x: Var<'t, T>,
        key_padding_mask: Option<&[bool]>,
    ) -> Result<Var<'t, T>> {
        let shape = x.shape();
        if shape.len() != 3 || shape[2] != self.dim {
            return Err(NnError::Config(format!(
                "multi-head attention of width {} expects an input [B, N, {}], got {shape:?}",
                self.dim, self.dim
            )));
        }
        let (b, n) = (shape[0], shape[1]);
        if let Some(m) = key_padding_mask
            && m.len() != b * n
        {
            return Err(NnError::Config(format!(
                "key padding mask has {} entries, the input {shape:?} needs B * N = {}",
                m.len(),
                b * n
            )));
        }
        let (h, dh) = (self.heads, self.head_dim());
        // [B, N, D] -> [B, H, N, dh]
        let split = |y: Var<'t, T>| -> Result<Var<'t, T>> { Ok(y.reshape(&[b, n, h, dh])?.permute(&[0, 2, 1, 3])?) };
        // The 1/sqrt(dh) scale is applied to Q (B N D products instead of B H N N).
        let q = split(self.q.forward(p, x)?.scale(1.0 / (dh as f64).sqrt()))?;
        let k = split(self.k.forward(p, x)?)?;
        let v = split(self.v.forward(p, x)?)?;
        let mut scores = q.matmul_t(k, false, true)?; // [B, H, N, N]
        if let Some(mask) = key_padding_mask {
            scores = mask_keys(scores, mask, b, h, n)?;
        }
        let ctx = scores.softmax().matmul(v)?; // [B, H, N, dh]
        let ctx = ctx.permute(&[0, 2, 1, 3])?.reshape(&[b, n, self.dim])?;
        self.out.forward(p, ctx)
    }
}

/// Replaces the scores of padded keys (`mask[b * n + j]`) by [`MASKED_SCORE`] in
/// `scores: [B, H, N, N]`; no gradient reaches the replaced entries.
fn mask_keys<'t, T: Float>(scores: Var<'t, T>, mask: &[bool], b: usize, h: usize, n: usize) -> Result<Var<'t, T>> {
    let tape = scores.tape();
    if n == 0 {
        return Ok(scores);
    }
    // `where_select` keeps `scores` where its mask is true, so the mask is "key is real".
    let mut keep = Vec::with_capacity(b * h * n * n);
    for row in mask.chunks_exact(n).take(b) {
        for _ in 0..h * n {
            keep.extend(row.iter().map(|&padded| !padded));
        }
    }
    let fill = tape.constant(Tensor::scalar(T::from_f64(MASKED_SCORE)));
    Ok(tape.where_select(&keep, scores, fill)?)
}
