//! Shared helpers for the nn tests.

#![allow(dead_code)]

use nn::{Bound, ParamStore};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tensor::gradcheck::check_gradients;
use tensor::{Tape, Tensor, TensorError, Var};

/// Seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Uniform values in [-1, 1].
pub fn uniform(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f64> {
    let n = shape.iter().product();
    Tensor::new((0..n).map(|_| r.random_range(-1.0..1.0)).collect(), shape).unwrap()
}

/// Turns an nn error into a tensor error so layer forwards fit the gradcheck closure.
pub fn te(e: nn::NnError) -> TensorError {
    TensorError::Invalid { op: "layer", detail: e.to_string() }
}

/// Gradient check of a layer with respect to all of its parameters and `inputs`.
/// `f(bound, inputs)` runs the layer.
pub fn check_layer<F>(store: &ParamStore<f64>, inputs: Vec<Tensor<f64>>, f: F)
where
    F: for<'t> Fn(&Bound<'t, f64>, &[Var<'t, f64>]) -> nn::Result<Var<'t, f64>>,
{
    let np = store.len();
    let mut all: Vec<Tensor<f64>> = store.values().to_vec();
    all.extend(inputs);
    let report = check_gradients(
        |_tape: &Tape<f64>, v| {
            let bound = Bound::from_vars(v[..np].to_vec());
            f(&bound, &v[np..]).map_err(te)
        },
        &all,
    );
    match report {
        Ok(r) => assert!(r.checked > 0),
        Err(e) => panic!("{e}"),
    }
}

/// Rotation about the z axis by `a` radians.
pub fn rot_z(a: f64) -> [[f64; 3]; 3] {
    let (s, c) = a.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

/// A rotation from a random unit quaternion (any axis).
pub fn random_rotation(r: &mut ChaCha8Rng) -> [[f64; 3]; 3] {
    let mut q: [f64; 4] = [0.0; 4];
    loop {
        for v in q.iter_mut() {
            *v = r.random_range(-1.0..1.0);
        }
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if n > 0.1 && n <= 1.0 {
            q.iter_mut().for_each(|v| *v /= n);
            break;
        }
    }
    let [w, x, y, z] = q;
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

/// Reflection through the vertical plane with horizontal normal at angle `a`.
pub fn vertical_reflection(a: f64) -> [[f64; 3]; 3] {
    let n = [a.cos(), a.sin(), 0.0];
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = f64::from(u8::from(i == j)) - 2.0 * n[i] * n[j];
        }
    }
    m
}

/// Applies `r` to the 3 spatial rows of vector features `[N, 3, m]`.
pub fn rotate(r: &[[f64; 3]; 3], z: &Tensor<f64>) -> Tensor<f64> {
    let s = z.shape();
    let (n, m) = (s[0], s[2]);
    let d = z.data();
    let mut out = vec![0.0; d.len()];
    for b in 0..n {
        for i in 0..3 {
            for c in 0..m {
                out[(b * 3 + i) * m + c] = (0..3).map(|k| r[i][k] * d[(b * 3 + k) * m + c]).sum();
            }
        }
    }
    Tensor::new(out, s).unwrap()
}

/// Largest absolute difference.
pub fn max_diff(a: &Tensor<f64>, b: &Tensor<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    a.data().iter().zip(b.data()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}
