//! Finite-difference gradient checking in `f64`.
//!
//! [`check_gradients`] evaluates a function of some input tensors on a tape, takes its
//! analytic gradient with [`Tape::backward`], and compares every element with the central
//! difference `(L(x + h) - L(x - h)) / 2h`.
//!
//! Tolerances (the defaults of [`GradCheck`]): with `h = 1e-6 * max(1, |x|)` the truncation
//! error of a central difference is `h^2 |L'''| / 6`, about 1e-13 for smooth O(1) functions,
//! and the rounding error is about `2^-52 |L| / h`, about 2e-10 |L|. A check therefore
//! passes when `|analytic - numeric| <= atol + rtol * max(|analytic|, |numeric|)` with
//! `atol = 1e-6` and `rtol = 1e-5`: three orders of magnitude above both error sources for
//! losses up to |L| ~ 1e3, and far below any real mistake in a gradient rule (those are
//! errors of order the gradient itself). Non-smooth functions (relu, abs, max, clamp,
//! minimum/maximum) are only checked at inputs at least 1e-3 away from their kinks.

use crate::error::Result;
use crate::tape::{Tape, Var};
use crate::tensor::Tensor;

/// Settings of a finite-difference gradient check.
#[derive(Clone, Copy, Debug)]
pub struct GradCheck {
    /// Relative step: `h = step * max(1, |x|)`.
    pub step: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Relative tolerance.
    pub rtol: f64,
}

impl Default for GradCheck {
    fn default() -> Self {
        Self { step: 1e-6, atol: 1e-6, rtol: 1e-5 }
    }
}

/// The outcome of a passing check.
#[derive(Clone, Debug)]
pub struct GradCheckReport {
    /// Number of input elements compared.
    pub checked: usize,
    /// The largest absolute difference between analytic and numeric gradients.
    pub max_abs_error: f64,
}

/// Reduces a function's output to a scalar: the output itself if it is one element, else
/// `sum(out * w)` with fixed, distinct weights so that every output element matters.
fn to_scalar<'t>(out: Var<'t, f64>) -> Result<Var<'t, f64>> {
    if out.value().numel() == 1 {
        return out.reshape(&[]);
    }
    let n = out.value().numel();
    let w: Vec<f64> = (0..n).map(|i| 0.5 + ((i * 7919) % 101) as f64 / 100.0).collect();
    let w = out.tape().constant(Tensor::new(w, &out.shape())?);
    Ok(out.mul(w)?.sum_all())
}

/// Evaluates the scalar loss for given inputs (no gradient recorded).
fn loss_value<F>(f: &F, inputs: &[Tensor<f64>]) -> Result<f64>
where
    F: for<'t> Fn(&'t Tape<f64>, &[Var<'t, f64>]) -> Result<Var<'t, f64>>,
{
    let tape = Tape::new();
    let vars: Vec<Var<'_, f64>> = inputs.iter().map(|t| tape.constant(t.clone())).collect();
    to_scalar(f(&tape, &vars)?)?.value().item()
}

/// Checks the gradients of `f` with respect to every element of every input with the default
/// settings. Returns a message naming the input, the element and both values on failure.
pub fn check_gradients<F>(f: F, inputs: &[Tensor<f64>]) -> std::result::Result<GradCheckReport, String>
where
    F: for<'t> Fn(&'t Tape<f64>, &[Var<'t, f64>]) -> Result<Var<'t, f64>>,
{
    check_gradients_with(GradCheck::default(), f, inputs)
}

/// [`check_gradients`] with explicit settings.
pub fn check_gradients_with<F>(
    cfg: GradCheck,
    f: F,
    inputs: &[Tensor<f64>],
) -> std::result::Result<GradCheckReport, String>
where
    F: for<'t> Fn(&'t Tape<f64>, &[Var<'t, f64>]) -> Result<Var<'t, f64>>,
{
    let err = |e: crate::TensorError| e.to_string();
    let tape = Tape::new();
    let vars: Vec<Var<'_, f64>> = inputs.iter().map(|t| tape.var(t.clone())).collect();
    let loss = to_scalar(f(&tape, &vars).map_err(err)?).map_err(err)?;
    let grads = tape.backward(loss).map_err(err)?;
    let mut report = GradCheckReport { checked: 0, max_abs_error: 0.0 };
    for (i, input) in inputs.iter().enumerate() {
        let analytic = grads.get_or_zeros(vars[i]);
        for j in 0..input.numel() {
            let x = input.data()[j];
            let h = cfg.step * x.abs().max(1.0);
            let mut plus = inputs.to_vec();
            plus[i].data_mut()[j] = x + h;
            let mut minus = inputs.to_vec();
            minus[i].data_mut()[j] = x - h;
            let numeric = (loss_value(&f, &plus).map_err(err)? - loss_value(&f, &minus).map_err(err)?) / (2.0 * h);
            let a = analytic.data()[j];
            let diff = (a - numeric).abs();
            report.max_abs_error = report.max_abs_error.max(diff);
            report.checked += 1;
            let within = diff <= cfg.atol + cfg.rtol * a.abs().max(numeric.abs());
            if !within {
                return Err(format!(
                    "gradient mismatch at input {i} (shape {:?}) element {j}: analytic {a:e}, numeric {numeric:e}, difference {diff:e}",
                    input.shape()
                ));
            }
        }
    }
    Ok(report)
}
