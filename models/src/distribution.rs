//! The Tanh-Normal action distribution of the paper's policies (eq. (pi)): a Normal with
//! mean `loc` and standard deviation `softplus(scale) + 0.001`, squashed by `tanh` into
//! `[-1, 1]`. Log-probabilities include the Jacobian of the squashing.

use tensor::{Float, Result, Var};

/// Minimum standard deviation added after the softplus (the reference release's 0.001).
pub const MIN_STD: f64 = 0.001;

/// `ln(2 pi) / 2`.
const HALF_LN_2PI: f64 = 0.918_938_533_204_672_8;

/// `std = softplus(scale) + 0.001`.
pub fn std_from_scale<'t, T: Float>(scale: Var<'t, T>) -> Var<'t, T> {
    scale.softplus().add_scalar(MIN_STD)
}

/// Log-density of the pre-squash value `u` under `Normal(loc, std)`, summed over the last
/// axis: `sum(-0.5 ((u - loc) / std)^2 - ln std - ln(2 pi) / 2)`.
pub fn normal_log_prob<'t, T: Float>(u: Var<'t, T>, loc: Var<'t, T>, std: Var<'t, T>) -> Result<Var<'t, T>> {
    let last = u.rank() - 1;
    let z = u.sub(loc)?.div(std)?;
    z.square().scale(-0.5).sub(std.log())?.add_scalar(-HALF_LN_2PI).sum(last, false)
}

/// `ln |d tanh(u) / du|` summed over the last axis, in the stable form
/// `2 (ln 2 - u - softplus(-2u))`.
pub fn tanh_log_det_jacobian<'t, T: Float>(u: Var<'t, T>) -> Result<Var<'t, T>> {
    let last = u.rank() - 1;
    let per = u.add(u.scale(-2.0).softplus())?.scale(-2.0).add_scalar(2.0 * std::f64::consts::LN_2);
    per.sum(last, false)
}

/// Log-probability of the action `tanh(u)` (given its pre-squash value `u`):
/// `normal_log_prob(u) - ln |d tanh / du|`.
pub fn tanh_normal_log_prob<'t, T: Float>(u: Var<'t, T>, loc: Var<'t, T>, std: Var<'t, T>) -> Result<Var<'t, T>> {
    normal_log_prob(u, loc, std)?.sub(tanh_log_det_jacobian(u)?)
}

/// Entropy of the Normal part, summed over the last axis: `sum(ln std + (1 + ln 2 pi) / 2)`.
pub fn normal_entropy<'t, T: Float>(std: Var<'t, T>) -> Result<Var<'t, T>> {
    let last = std.rank() - 1;
    std.log().add_scalar(0.5 + HALF_LN_2PI).sum(last, false)
}
