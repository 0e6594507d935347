//! The Tanh-Normal density of the policies integrates to 1 over the action interval, and the
//! entropy bonus's one-sample estimate (Brax's `NormalTanhDistribution.entropy`) is unbiased:
//! its mean over many samples is the entropy of `a = tanh(x)` found by integration.

use models::distribution::{normal_entropy, tanh_normal_entropy, tanh_normal_log_prob};
use rl::mappo::seeding::{standard_normal, stream};
use tensor::{Tape, Tensor};

#[test]
fn tanh_normal_density_integrates_to_one() {
    // Midpoint rule over a in (-1, 1) with u = atanh(a); the density near +-1 is integrable
    // but steep, so the grid is fine (2e6 cells) and the parameters keep the mass away from
    // the edges' last cells.
    for (loc, std) in [(0.0, 1.0), (0.7, 0.3), (-1.2, 0.8), (0.3, 0.05)] {
        let n = 2_000_000usize;
        let h = 2.0 / n as f64;
        let u: Vec<f64> = (0..n).map(|i| (-1.0 + (i as f64 + 0.5) * h).atanh()).collect();
        let tape = Tape::<f64>::new();
        let uv = tape.constant(Tensor::new(u, &[n, 1]).unwrap());
        let l = tape.constant(Tensor::full(&[n, 1], loc));
        let s = tape.constant(Tensor::full(&[n, 1], std));
        let lp = tanh_normal_log_prob(uv, l, s).unwrap().value();
        let integral: f64 = lp.data().iter().map(|x| x.exp() * h).sum();
        assert!((integral - 1.0).abs() < 1e-4, "loc {loc} std {std}: integral {integral}");
    }
}

/// `-integral p(a) ln p(a) da` over `(-1, 1)` for `a = tanh(x)`, `x ~ Normal(loc, std)`,
/// written with the substitution `a = tanh(x)` (`p(a) da = phi(x) dx`) as
/// `-integral phi(x) ln p(tanh x) dx`, midpoint rule over `loc +- 12 std` (the density of `a`
/// is steep near +-1, the integrand in `x` is smooth), `ln p` from `tanh_normal_log_prob`.
fn tanh_normal_entropy_by_integration(loc: f64, std: f64) -> f64 {
    let n = 400_000usize;
    let (lo, h) = (loc - 12.0 * std, 24.0 * std / n as f64);
    let x: Vec<f64> = (0..n).map(|i| lo + (i as f64 + 0.5) * h).collect();
    let tape = Tape::<f64>::new();
    let xv = tape.constant(Tensor::new(x.clone(), &[n, 1]).unwrap());
    let l = tape.constant(Tensor::full(&[n, 1], loc));
    let s = tape.constant(Tensor::full(&[n, 1], std));
    let log_pa = tanh_normal_log_prob(xv, l, s).unwrap().value();
    x.iter()
        .zip(log_pa.data())
        .map(|(&x, &lp)| {
            let z = (x - loc) / std;
            let phi = (-0.5 * z * z).exp() / (std * (2.0 * std::f64::consts::PI).sqrt());
            -phi * lp * h
        })
        .sum()
}

#[test]
fn the_entropy_estimate_averages_to_the_tanh_normal_entropy() {
    let samples = 200_000usize;
    let mut rng = stream(5, "mc", 0, 0);
    for (loc, std) in [(0.0, 1.0), (0.7, 0.3), (-1.2, 0.8), (2.0, 0.5), (0.3, 2.0)] {
        let truth = tanh_normal_entropy_by_integration(loc, std);
        let eps: Vec<f64> = (0..samples).map(|_| standard_normal(&mut rng)).collect();
        let tape = Tape::<f64>::new();
        let l = tape.constant(Tensor::full(&[samples, 1], loc));
        let s = tape.constant(Tensor::full(&[samples, 1], std));
        let e = tape.constant(Tensor::new(eps, &[samples, 1]).unwrap());
        let h = tanh_normal_entropy(l, s, e).unwrap().value();
        let mean = h.data().iter().sum::<f64>() / samples as f64;
        let var = h.data().iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (samples - 1) as f64;
        let se = (var / samples as f64).sqrt();
        // Four standard errors of the Monte-Carlo mean (the integral is exact to ~1e-9).
        assert!((mean - truth).abs() < 4.0 * se, "loc {loc} std {std}: mean {mean} vs {truth} (s.e. {se})");
        // The check can fail: the Normal part alone is far off.
        let normal = normal_entropy(s).unwrap().value().data()[0];
        assert!((normal - truth).abs() > 20.0 * se, "loc {loc} std {std}: {normal} vs {truth}");
    }
}
