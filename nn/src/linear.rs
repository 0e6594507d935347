//! Linear layers and multi-layer perceptrons.

use tensor::{Activation, Float, Tensor, Var};

use crate::error::{NnError, Result};
use crate::init::Init;
use crate::params::{Bound, ParamId, Scope};

/// `y = x W + b` over the last dim, `W: [in, out]`, `b: [out]` (zero-initialised).
#[derive(Clone, Debug)]
pub struct Linear {
    /// The weight `[in, out]`, named `weight`.
    pub weight: ParamId,
    /// The bias `[out]`, named `bias`, if any.
    pub bias: Option<ParamId>,
    /// Input width.
    pub fan_in: usize,
    /// Output width.
    pub fan_out: usize,
}

impl Linear {
    /// A layer with a bias and LeCun-uniform weights.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, fan_in: usize, fan_out: usize) -> Result<Self> {
        Self::with_options(s, fan_in, fan_out, true, Init::LecunUniform)
    }

    /// A layer with an explicit bias choice and initialiser.
    pub fn with_options<T: Float>(
        s: &mut Scope<'_, T>,
        fan_in: usize,
        fan_out: usize,
        bias: bool,
        init: Init,
    ) -> Result<Self> {
        if fan_in == 0 || fan_out == 0 {
            return Err(NnError::Config(format!(
                "{}: linear layer of size {fan_in} -> {fan_out}",
                s.full_name("weight")
            )));
        }
        let w = init.matrix::<T>(fan_in, fan_out, s.rng());
        let weight = s.param("weight", w)?;
        let bias = if bias { Some(s.param("bias", Tensor::zeros(&[fan_out]))?) } else { None };
        Ok(Self { weight, bias, fan_in, fan_out })
    }

    /// `act(x W + b)`, fused; `x: [.., in]`.
    pub fn forward_act<'t, T: Float>(&self, p: &Bound<'t, T>, x: Var<'t, T>, act: Activation) -> Result<Var<'t, T>> {
        Ok(x.linear(p.get(self.weight), self.bias.map(|b| p.get(b)), act)?)
    }

    /// `x W + b`.
    pub fn forward<'t, T: Float>(&self, p: &Bound<'t, T>, x: Var<'t, T>) -> Result<Var<'t, T>> {
        self.forward_act(p, x, Activation::Identity)
    }
}

/// A multi-layer perceptron: hidden layers with an activation, a linear output layer.
/// Parameters are named `<scope>.<i>.weight` / `<scope>.<i>.bias`.
#[derive(Clone, Debug)]
pub struct Mlp {
    /// The layers, input first.
    pub layers: Vec<Linear>,
    /// The activation after every hidden layer.
    pub activation: Activation,
}

impl Mlp {
    /// `sizes = [in, h1, .., out]` with LeCun-uniform weights.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, sizes: &[usize], activation: Activation) -> Result<Self> {
        Self::with_init(s, sizes, activation, Init::LecunUniform, Init::LecunUniform)
    }

    /// `sizes = [in, h1, .., out]` with separate initialisers for hidden and output layers
    /// (e.g. orthogonal with gain sqrt(2) for hidden layers, 0.01 for a policy head).
    pub fn with_init<T: Float>(
        s: &mut Scope<'_, T>,
        sizes: &[usize],
        activation: Activation,
        hidden_init: Init,
        out_init: Init,
    ) -> Result<Self> {
        if sizes.len() < 2 {
            return Err(NnError::Config(format!(
                "{}: an MLP needs at least input and output sizes, got {sizes:?}",
                s.full_name("")
            )));
        }
        let n = sizes.len() - 1;
        let layers = (0..n)
            .map(|i| {
                let init = if i + 1 == n { out_init } else { hidden_init };
                Linear::with_options(&mut s.sub(i), sizes[i], sizes[i + 1], true, init)
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { layers, activation })
    }

    /// Input width.
    pub fn fan_in(&self) -> usize {
        self.layers[0].fan_in
    }

    /// Output width.
    pub fn fan_out(&self) -> usize {
        self.layers[self.layers.len() - 1].fan_out
    }

    /// Applies the layers to `x: [.., in]`.
    pub fn forward<'t, T: Float>(&self, p: &Bound<'t, T>, x: Var<'t, T>) -> Result<Var<'t, T>> {
        let h = self.forward_hidden(p, x)?;
        self.layers[self.layers.len() - 1].forward(p, h)
    }

    /// Like [`Mlp::forward_hidden`] for the input `cat(parts, last axis)`, without building the
    /// concatenation: the first layer is one op computing `act(sum_i part_i W[rows_i] + b)`,
    /// the same product split by input rows (no copy of large inputs such as Gram matrices,
    /// and no intermediate sums).
    pub fn forward_hidden_parts<'t, T: Float>(&self, p: &Bound<'t, T>, parts: &[Var<'t, T>]) -> Result<Var<'t, T>> {
        let first = &self.layers[0];
        let mut widths = Vec::with_capacity(parts.len());
        for part in parts {
            widths.push(*part.shape().last().ok_or_else(|| NnError::Config("an MLP input part has no dims".into()))?);
        }
        let total: usize = widths.iter().sum();
        if total != first.fan_in {
            return Err(NnError::Config(format!(
                "MLP input parts have {total} features in all, the first layer takes {}",
                first.fan_in
            )));
        }
        let w = p.get(first.weight);
        let b = first.bias.map(|b| p.get(b));
        let mut h = w.tape().linear_rows(parts, w, b, self.activation)?;
        for layer in &self.layers[1..self.layers.len() - 1] {
            h = layer.forward_act(p, h, self.activation)?;
        }
        Ok(h)
    }

    /// [`Mlp::forward`] of `cat(parts, last axis)` without building the concatenation (also
    /// for a single layer, which then has no activation).
    pub fn forward_parts<'t, T: Float>(&self, p: &Bound<'t, T>, parts: &[Var<'t, T>]) -> Result<Var<'t, T>> {
        if self.layers.len() > 1 {
            let h = self.forward_hidden_parts(p, parts)?;
            return self.layers[self.layers.len() - 1].forward(p, h);
        }
        let only = &self.layers[0];
        let w = p.get(only.weight);
        let widths: Vec<usize> = parts.iter().map(|x| x.shape().last().copied().unwrap_or(0)).collect();
        if parts.iter().any(|x| x.shape().is_empty()) || widths.iter().sum::<usize>() != only.fan_in {
            return Err(NnError::Config(format!(
                "MLP input parts of widths {widths:?} for a layer of {} inputs",
                only.fan_in
            )));
        }
        let b = only.bias.map(|b| p.get(b));
        Ok(w.tape().linear_rows(parts, w, b, Activation::Identity)?)
    }

    /// Applies every layer but the last (each followed by the activation): the features the
    /// output layer reads.
    pub fn forward_hidden<'t, T: Float>(&self, p: &Bound<'t, T>, x: Var<'t, T>) -> Result<Var<'t, T>> {
        let mut h = x;
        for layer in &self.layers[..self.layers.len() - 1] {
            h = layer.forward_act(p, h, self.activation)?;
        }
        Ok(h)
    }

    /// The output layer restricted to output columns `start..start+len`, applied to hidden
    /// features from [`Mlp::forward_hidden`]. Splitting the output this way computes only
    /// those columns, reading them from the weight in place (`tensor::Var::linear_columns`),
    /// instead of slicing the large output.
    pub fn forward_output_columns<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        hidden: Var<'t, T>,
        start: usize,
        len: usize,
    ) -> Result<Var<'t, T>> {
        let last = &self.layers[self.layers.len() - 1];
        let b = last.bias.map(|b| p.get(b));
        Ok(hidden.linear_columns(p.get(last.weight), b, start, len, Activation::Identity)?)
    }
}
