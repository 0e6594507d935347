//! Subequivariant building blocks (paper section 3, eq. (subeq), appendix A.1 eq. (subeq2)).
//!
//! Vector features are stored as `[.., 3, m]`: 3 spatial rows, `m` channels, exactly the
//! paper's `Z ∈ R^{3×m}`. A rotation or reflection `R` acts as `Z -> R Z`. Everything here is
//! built from channel mixing (`Z W`, which commutes with `R`) and inner products (`Z^T Z`,
//! invariant), so outputs rotate with the inputs; appending gravity `g` as a channel makes
//! the layer equivariant only to the transformations that fix `g` (subequivariance,
//! `O_g(3)`).

use tensor::{Activation, Float, Tensor, Var};

use crate::error::{NnError, Result};
use crate::init::Init;
use crate::linear::{Linear, Mlp};
use crate::params::{Bound, Scope};

/// Channel mixing of vector features without bias: `[.., 3, m_in] -> [.., 3, m_out]`,
/// `Z -> Z W`. (A bias would break equivariance.)
#[derive(Clone, Debug)]
pub struct VectorLinear {
    /// The mixing matrix `[m_in, m_out]`.
    pub linear: Linear,
}

impl VectorLinear {
    /// LeCun-uniform mixing weights named `<scope>.weight`.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, m_in: usize, m_out: usize) -> Result<Self> {
        Ok(Self { linear: Linear::with_options(s, m_in, m_out, false, Init::LecunUniform)? })
    }

    /// `Z W`.
    pub fn forward<'t, T: Float>(&self, p: &Bound<'t, T>, z: Var<'t, T>) -> Result<Var<'t, T>> {
        self.linear.forward(p, z)
    }

    /// `[Z_1 | Z_2 | .. (| g)] W` for vector features `z_i: [N.., 3, m_i]` joined along the
    /// channels and, with `gravity`, the gravity direction as the last channel: the same as
    /// [`VectorLinear::forward`] of the concatenation (after [`append_gravity`]), without
    /// building it. Each part is multiplied by its block of rows of `W` and the products are
    /// added in one op that reads the blocks in place (`tensor::Tape::linear_rows`).
    pub fn forward_channels<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        parts: &[Var<'t, T>],
        gravity: Option<[f64; 3]>,
    ) -> Result<Var<'t, T>> {
        let first = *parts.first().ok_or_else(|| NnError::Config("vector mixing of no inputs".into()))?;
        let mut inputs = parts.to_vec();
        if let Some(g) = gravity {
            inputs.push(gravity_channel(first, g)?);
        }
        let widths: Vec<usize> = inputs.iter().map(|z| z.shape().last().copied().unwrap_or(0)).collect();
        if widths.iter().sum::<usize>() != self.linear.fan_in {
            return Err(NnError::Config(format!(
                "vector mixing of {widths:?} channels (gravity included), the layer takes {}",
                self.linear.fan_in
            )));
        }
        let w = p.get(self.linear.weight);
        Ok(w.tape().linear_rows(&inputs, w, None, Activation::Identity)?)
    }
}

/// The gravity direction `g` as one vector channel beside `z: [N.., 3, m]`: a constant
/// `[N.., 3, 1]` holding `g` in every row.
fn gravity_channel<'t, T: Float>(z: Var<'t, T>, g: [f64; 3]) -> Result<Var<'t, T>> {
    let mut s = z.shape();
    *s.last_mut().ok_or_else(|| NnError::Config("vector features without dims".into()))? = 1;
    let rows = s.iter().product::<usize>() / 3;
    let data: Vec<T> = (0..rows).flat_map(|_| g.map(T::from_f64)).collect();
    Ok(z.tape().constant(Tensor::new(data, &s)?))
}

/// Gram matrices `Z^T Z` of vector features `[.., 3, m]`, flattened to `[.., m*m]`
/// (invariant under any orthogonal transform of the rows).
pub fn gram<'t, T: Float>(z: Var<'t, T>) -> Result<Var<'t, T>> {
    let s = z.shape();
    let m = s[s.len() - 1];
    let g = z.matmul_t(z, true, false)?;
    let mut flat = s[..s.len() - 2].to_vec();
    flat.push(m * m);
    Ok(g.reshape(&flat)?)
}

/// `||x||_F + 1` over the last dim, `[.., k] -> [.., 1]`, the normaliser of the release's
/// subequivariant layers. A `1e-12` inside the root keeps the gradient finite at `x = 0`.
pub fn norm_plus_one<'t, T: Float>(x: Var<'t, T>) -> Result<Var<'t, T>> {
    Ok(x.norm_last(1e-12).add_scalar(1.0))
}

/// `||Z^T Z||_F + 1` of vector features `z: [N, 3, m]`, `[N, 1]`: the normaliser of eq.
/// (subeq2), equal to [`norm_plus_one`] of [`gram`]`(z)` but computed from the `3 x 3` matrix
/// `Z Z^T`, since `||Z^T Z||_F^2 = tr(Z^T Z Z^T Z) = tr(Z Z^T Z Z^T) = ||Z Z^T||_F^2`. It reads
/// `3 m` numbers a row instead of the `m^2` of the Gram matrix (whose pass over memory cost
/// more than the rest of the normaliser), and it is as invariant: `Z -> R Z` maps `Z Z^T` to
/// `R Z Z^T R^T`, of the same norm.
pub fn gram_norm_plus_one<'t, T: Float>(z: Var<'t, T>) -> Result<Var<'t, T>> {
    let n = z.shape()[0];
    let outer = z.matmul_t(z, false, true)?.reshape(&[n, 9])?;
    norm_plus_one(outer)
}

/// Appends the gravity direction as one more vector channel: `[N.., 3, m] -> [N.., 3, m+1]`.
pub fn append_gravity<'t, T: Float>(z: Var<'t, T>, g: [f64; 3]) -> Result<Var<'t, T>> {
    let last = z.shape().len().checked_sub(1).ok_or_else(|| NnError::Config("vector features without dims".into()))?;
    Ok(z.tape().cat(&[z, gravity_channel(z, g)?], last)?)
}

/// The subequivariant function of eq. (subeq2):
/// `M = [Z, g] W`, `(W_g, h') = MLP([M^T M, h]) / (||M^T M|| + 1)`, `Z' = M W_g`.
///
/// Vector outputs are linear combinations of the (mixed) input vectors with invariant
/// coefficients, so they rotate with the inputs about `g`; scalar outputs are invariant.
#[derive(Clone, Debug)]
pub struct SubequivariantFn {
    /// Channel mixing `W: [(m_in (+1)), m_mid]`.
    pub mix: VectorLinear,
    /// `σ: R^{m_mid^2 + s_in} -> R^{m_mid m_out + s_out}`.
    pub mlp: Mlp,
    /// Gravity channel, if any (`None` gives full O(3) equivariance).
    pub gravity: Option<[f64; 3]>,
    /// Mixed vector channels.
    pub m_mid: usize,
    /// Output vector channels.
    pub m_out: usize,
    /// Output scalars.
    pub s_out: usize,
}

/// Sizes of a [`SubequivariantFn`].
#[derive(Clone, Copy, Debug)]
pub struct SubeqSizes {
    /// Input vector channels.
    pub m_in: usize,
    /// Input scalars.
    pub s_in: usize,
    /// Mixed vector channels (the Gram is `m_mid x m_mid`).
    pub m_mid: usize,
    /// Output vector channels.
    pub m_out: usize,
    /// Output scalars.
    pub s_out: usize,
    /// Hidden width of the MLP.
    pub hidden: usize,
    /// Hidden layers of the MLP.
    pub layers: usize,
}

impl SubequivariantFn {
    /// Parameters `<scope>.mix.weight` and `<scope>.mlp.<i>.{weight,bias}`.
    pub fn new<T: Float>(s: &mut Scope<'_, T>, sz: SubeqSizes, gravity: Option<[f64; 3]>) -> Result<Self> {
        if sz.m_in == 0 || sz.m_mid == 0 || sz.layers == 0 {
            return Err(NnError::Config(format!("subequivariant function with sizes {sz:?}")));
        }
        let m_in = sz.m_in + usize::from(gravity.is_some());
        let mix = VectorLinear::new(&mut s.sub("mix"), m_in, sz.m_mid)?;
        let mut sizes = vec![sz.m_mid * sz.m_mid + sz.s_in];
        sizes.extend(std::iter::repeat_n(sz.hidden, sz.layers));
        sizes.push(sz.m_mid * sz.m_out + sz.s_out);
        let mlp = Mlp::new(&mut s.sub("mlp"), &sizes, Activation::Relu)?;
        Ok(Self { mix, mlp, gravity, m_mid: sz.m_mid, m_out: sz.m_out, s_out: sz.s_out })
    }

    /// `z: [N, 3, m_in]`, `h: [N, s_in]` -> `(z': [N, 3, m_out], h': [N, s_out])`.
    pub fn forward<'t, T: Float>(
        &self,
        p: &Bound<'t, T>,
        z: Var<'t, T>,
        h: Var<'t, T>,
    ) -> Result<(Var<'t, T>, Var<'t, T>)> {
        let m = self.mix.forward_channels(p, &[z], self.gravity)?;
        mix_by_invariants(p, &self.mlp, m, &[h], self.m_out, self.s_out)
    }
}

/// The common core of every subequivariant map: from mixed vectors `m: [N, 3, k]` and extra
/// invariant scalars, `c = MLP([m^T m, scalars..]) / (||m^T m|| + 1)`; returns
/// `(m c[.., :k*m_out] as [N, 3, m_out], c[.., k*m_out..])`.
pub fn mix_by_invariants<'t, T: Float>(
    p: &Bound<'t, T>,
    mlp: &Mlp,
    m: Var<'t, T>,
    scalars: &[Var<'t, T>],
    m_out: usize,
    s_out: usize,
) -> Result<(Var<'t, T>, Var<'t, T>)> {
    let shape = m.shape();
    let n = shape[0];
    let k = shape[2];
    let g = gram(m)?;
    let mut parts = vec![g];
    parts.extend_from_slice(scalars);
    let hidden = mlp.forward_hidden_parts(p, &parts)?;
    let norm = gram_norm_plus_one(m)?; // [N, 1], = ||g|| + 1
    // The output layer is applied in two column blocks (vector coefficients, scalars): the
    // same arithmetic as one layer followed by slicing, without copying the large output.
    // The division by the norm is applied after the product with `m` (one scalar per row
    // commutes with it), on [N, 3, m_out] instead of the k x m_out coefficients.
    let w = mlp.forward_output_columns(p, hidden, 0, k * m_out)?.reshape(&[n, k, m_out])?;
    let z_out = m.matmul(w)?.div(norm.reshape(&[n, 1, 1])?)?;
    let h_out = if s_out > 0 {
        mlp.forward_output_columns(p, hidden, k * m_out, s_out)?.div(norm)?
    } else {
        m.tape().constant(Tensor::zeros(&[n, 0]))
    };
    Ok((z_out, h_out))
}
