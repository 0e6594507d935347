//! Radial-basis expansion of distances: `phi_k(d) = exp(-gamma (d - mu_k)^2)` with `n`
//! Gaussians whose centres `mu_k` are evenly spaced on `[0, cutoff]` and
//! `gamma = 1 / (2 spacing^2)` (the reference release uses 64 of them for edge distances).

use tensor::{Float, Tensor, Var};

use crate::error::{NnError, Result};

/// A fixed (parameter-free) Gaussian radial-basis expansion.
#[derive(Clone, Debug)]
pub struct RadialBasis {
    /// Centres, evenly spaced on `[0, cutoff]`.
    pub centres: Vec<f64>,
    /// Width parameter.
    pub gamma: f64,
}

impl RadialBasis {
    /// `n` Gaussians on `[0, cutoff]` (`n >= 2`, `cutoff > 0`).
    pub fn new(n: usize, cutoff: f64) -> Result<Self> {
        if n < 2 || cutoff.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(NnError::Config(format!(
                "radial basis needs n >= 2 and cutoff > 0, got n = {n}, cutoff = {cutoff}"
            )));
        }
        let spacing = cutoff / (n - 1) as f64;
        let centres = (0..n).map(|k| k as f64 * spacing).collect();
        Ok(Self { centres, gamma: 0.5 / (spacing * spacing) })
    }

    /// Number of output features.
    pub fn size(&self) -> usize {
        self.centres.len()
    }

    /// Expands distances `d: [.., 1]` into `[.., n]`.
    pub fn forward<'t, T: Float>(&self, d: Var<'t, T>) -> Result<Var<'t, T>> {
        let mu = Tensor::from_f64(&self.centres, &[self.centres.len()])?;
        let mu = d.tape().constant(mu);
        Ok(d.sub(mu)?.square().scale(-self.gamma).exp())
    }
}
