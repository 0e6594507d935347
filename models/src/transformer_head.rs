//! The body-level Transformer head of `transformer_hn` and `shtransformer` (paper section
//! "Extended Evaluations on Transformer"; Table "Hyperparameters of Network": model dim 128,
//! feed-forward 256, 3 layers, 2 heads, LayerNorm, `condition_decoder`, no positional
//! encoding).
//!
//! One token per node: a shared `Linear` embeds each node's features to the model width,
//! a [`TransformerEncoder`] mixes the tokens, and a shared `Linear` decoder maps every
//! output token, concatenated with the token's own input features (`condition_decoder`),
//! to a few numbers: as an actor (`σ_π`) two, `loc` and `scale` of the DoF that node
//! actuates; as a critic (`σ_V`, [`crate::critic::ValueHead`]) one per token, averaged into
//! the value. The same parameters serve every node and every morphology (the paper:
//! "Transformer and GNN can share parameters across different morphologies, they have fewer
//! parameters"), so one head serves all of a team's agents.

use nn::{Bound, Linear, Scope, TransformerConfig, TransformerEncoder};
use tensor::{Float, Var};

use crate::error::{ModelError, Result};

/// Embedding, Transformer encoder and per-node decoder (module docs). Parameters under
/// its scope: `embed.*` (`F -> D`), `encoder.layers.<i>.*`, `decoder.*` (`D + F -> outputs`).
#[derive(Clone, Debug)]
pub struct TransformerHead {
    /// Token embedding `F -> D`.
    pub embed: Linear,
    /// The encoder (no positional encoding: permuting tokens permutes the outputs).
    pub encoder: TransformerEncoder,
    /// Per-node decoder on `[encoder output, token features]` -> `outputs` numbers.
    pub decoder: Linear,
    /// Token width `F`.
    pub features: usize,
}

impl TransformerHead {
    /// A head for tokens of `features` values, `outputs` numbers per token (2 for an actor,
    /// 1 for a critic), with the encoder sizes `cfg`.
    pub fn new<T: Float>(
        s: &mut Scope<'_, T>,
        features: usize,
        outputs: usize,
        cfg: TransformerConfig,
    ) -> Result<Self> {
        if features == 0 || outputs == 0 {
            return Err(ModelError::Option(format!(
                "a Transformer head needs features and outputs per token (got {features} and {outputs})"
            )));
        }
        cfg.validate()?;
        Ok(Self {
            embed: Linear::new(&mut s.sub("embed"), features, cfg.model_dim)?,
            encoder: TransformerEncoder::new(&mut s.sub("encoder"), cfg)?,
            decoder: Linear::new(&mut s.sub("decoder"), cfg.model_dim + features, outputs)?,
            features,
        })
    }

    /// Every token's outputs `[B, N, outputs]` for `tokens: [B, N, F]`.
    pub fn forward_all<'t, T: Float>(&self, p: &Bound<'t, T>, tokens: Var<'t, T>) -> Result<Var<'t, T>> {
        let shape = tokens.shape();
        if shape.len() != 3 || shape[2] != self.features || shape[1] == 0 {
            return Err(ModelError::Input(format!(
                "Transformer head of {} features got tokens {shape:?}",
                self.features
            )));
        }
        let x = self.embed.forward(p, tokens)?;
        let y = self.encoder.forward(p, x, None)?;
        Ok(self.decoder.forward(p, p.tape().cat(&[y, tokens], 2)?)?)
    }

    /// `tokens: [B, N, F]`; returns `loc`, `scale` `[B, len]` of the tokens
    /// `start..start + len` (the agent's DoF nodes).
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        tokens: Var<'t, T>,
        start: usize,
        len: usize,
    ) -> Result<(Var<'t, T>, Var<'t, T>)> {
        let shape = tokens.shape();
        if shape.len() != 3 || shape[2] != self.features || start + len > shape[1] || len == 0 {
            return Err(ModelError::Input(format!(
                "Transformer head of {} features got tokens {shape:?}, output nodes {start}..{}",
                self.features,
                start + len
            )));
        }
        if self.decoder.fan_out != 2 {
            return Err(ModelError::Input("this Transformer head is a critic (one output per token)".into()));
        }
        let nb = shape[0];
        let x = self.embed.forward(p, tokens)?;
        let y = self.encoder.forward(p, x, None)?;
        // Only the DoF nodes are decoded.
        let y = y.narrow(1, start, len)?;
        let own = tokens.narrow(1, start, len)?;
        let out = self.decoder.forward(p, p.tape().cat(&[y, own], 2)?)?;
        let loc = out.narrow(2, 0, 1)?.reshape(&[nb, len])?;
        let scale = out.narrow(2, 1, 1)?.reshape(&[nb, len])?;
        Ok((loc, scale))
    }
}
