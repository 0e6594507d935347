//! The Tanh-Normal density of the policies integrates to 1 over the action interval.

use models::distribution::tanh_normal_log_prob;
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
