//! The Tanh-Normal action distribution of the paper's policies (eq. (pi)): a Normal with
//! mean `loc` and standard deviation `softplus(scale) + 0.001`, squashed by `tanh` into
//! `[-1, 1]`. Log-probabilities include the Jacobian of the squashing. Its entropy has no
//! closed form: [`tanh_normal_entropy`] is the one-sample estimate Brax's
//! `NormalTanhDistribution.entropy` returns (the reference release's entropy bonus), and
//! [`normal_entropy`] the Normal part alone.

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

/// Brax's one-sample estimate of the Tanh-Normal's entropy, summed over the last axis:
/// `sum(ln std + (1 + ln 2 pi) / 2 + ln |d tanh(x) / dx|)` at the reparameterised sample
/// `x = loc + std * eps` (`eps` standard-normal noise of the shape of `loc`; the gradient
/// flows through `x` into `loc` and `std`), with the log-Jacobian in the stable form
/// `2 (ln 2 - x - softplus(-2x))`. The entropy of `a = tanh(x)` is
/// `H(x) + E[ln |d tanh / dx|]`, so the estimate is unbiased.
pub fn tanh_normal_entropy<'t, T: Float>(loc: Var<'t, T>, std: Var<'t, T>, eps: Var<'t, T>) -> Result<Var<'t, T>> {
    let x = loc.add(std.mul(eps)?)?;
    normal_entropy(std)?.add(tanh_log_det_jacobian(x)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tensor::gradcheck::check_gradients;
    use tensor::{Tape, Tensor};

    const LOC: [f64; 6] = [0.0, 0.7, -1.2, 2.5, 0.3, -0.05];
    const SCALE: [f64; 6] = [0.5, -1.0, 0.2, 1.5, -3.0, 0.0];
    const EPS: [f64; 6] = [0.3, -1.1, 2.0, -0.4, 0.9, -2.5];

    #[test]
    fn tanh_normal_entropy_is_the_hand_computed_sum() {
        let tape = Tape::<f64>::new();
        let c = |x: &[f64]| tape.constant(Tensor::new(x.to_vec(), &[2, 3]).unwrap());
        let h = tanh_normal_entropy(c(&LOC), std_from_scale(c(&SCALE)), c(&EPS)).unwrap().value();
        assert_eq!(h.shape(), &[2]);
        for row in 0..2 {
            let mut want = 0.0;
            for k in row * 3..row * 3 + 3 {
                let std = (1.0 + SCALE[k].exp()).ln() + MIN_STD;
                let x = LOC[k] + std * EPS[k];
                // ln(1 - tanh(x)^2) directly (fine at these |x| < 4).
                want += std.ln() + 0.5 * (1.0 + (2.0 * std::f64::consts::PI).ln()) + (1.0 - x.tanh().powi(2)).ln();
            }
            assert!((h.data()[row] - want).abs() < 1e-12, "row {row}: {} vs {want}", h.data()[row]);
        }
    }

    #[test]
    fn tanh_normal_entropy_gradients_match_finite_differences() {
        let t = |x: &[f64]| Tensor::new(x.to_vec(), &[2, 3]).unwrap();
        // Gradients into loc and scale through the sample, and into eps too.
        check_gradients(|_, v| tanh_normal_entropy(v[0], std_from_scale(v[1]), v[2]), &[t(&LOC), t(&SCALE), t(&EPS)])
            .unwrap();
    }
}
