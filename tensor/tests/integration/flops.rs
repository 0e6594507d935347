//! FLOP counting of profiled tapes: matrix products against hand-computed `2 m n k`
//! values forward and backward, the convention for the other ops, and nothing counted
//! without profiling.

use tensor::{Activation, FlopCount, Tape, Tensor};

/// `2 m n k`: one product.
fn mm(m: u64, k: u64, n: u64) -> u64 {
    2 * m * k * n
}

fn ones(shape: &[usize]) -> Tensor<f32> {
    Tensor::ones(shape)
}

#[test]
fn single_matmul_counts_one_product_forward_and_one_per_gradient_backward() {
    let (m, k, n) = (7, 5, 3);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x = tape.var(ones(&[m, k]));
    let w = tape.var(ones(&[k, n]));
    let loss = x.matmul(w).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    let (m, k, n) = (m as u64, k as u64, n as u64);
    assert_eq!(f.matmul_forward, mm(m, k, n));
    // dX = G W^T and dW = X^T G: two products of the same size.
    assert_eq!(f.matmul_backward, 2 * mm(m, k, n));
    // sum_all: one add per input element, its gradient one per input element.
    assert_eq!(f.other_forward, m * n);
    assert_eq!(f.other_backward, m * n);
    assert_eq!(f.total(), 3 * mm(m, k, n) + 2 * m * n);
    assert_eq!(f.matmul(), 3 * mm(m, k, n));
    assert_eq!(f.forward() + f.backward(), f.total());
}

#[test]
fn backward_counts_only_products_for_inputs_that_want_a_gradient() {
    let (m, k, n) = (6u64, 4u64, 9u64);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x = tape.constant(ones(&[6, 4]));
    let w = tape.var(ones(&[4, 9]));
    let loss = x.matmul(w).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    assert_eq!(f.matmul_forward, mm(m, k, n));
    assert_eq!(f.matmul_backward, mm(m, k, n));
}

#[test]
fn two_layer_mlp_matches_hand_computed_products() {
    // x [b, i] -> relu(x W1 + b1) [b, h] -> W2 [h, o] -> mean of squares.
    let (b, i, h, o) = (32usize, 12usize, 20usize, 5usize);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x = tape.constant(ones(&[b, i]));
    let w1 = tape.var(ones(&[i, h]));
    let b1 = tape.var(ones(&[h]));
    let w2 = tape.var(ones(&[h, o]));
    let hid = x.matmul(w1).unwrap().add(b1).unwrap().relu();
    let loss = hid.matmul(w2).unwrap().square().mean_all().unwrap();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    let (b, i, h, o) = (b as u64, i as u64, h as u64, o as u64);
    assert_eq!(f.matmul_forward, mm(b, i, h) + mm(b, h, o));
    // Layer 1: x is a constant, only dW1. Layer 2: dhid and dW2.
    assert_eq!(f.matmul_backward, mm(b, i, h) + 2 * mm(b, h, o));
    // Forward: add, relu (b h each), square (b o), mean (b o).
    assert_eq!(f.other_forward, 2 * b * h + 2 * b * o);
    // Backward: mean (b o), square (2 b o), relu (2 b h), add: 0 for the full-size input,
    // one add per element of the [b, h] gradient summed down to the bias.
    assert_eq!(f.other_backward, b * o + 2 * b * o + 2 * b * h + b * h);
}

#[test]
fn fused_linear_counts_like_its_parts() {
    let (b, i, h) = (16usize, 8usize, 24usize);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x = tape.var(ones(&[2, b / 2, i]));
    let w = tape.var(ones(&[i, h]));
    let bias = tape.var(ones(&[h]));
    let loss = x.linear(w, Some(bias), Activation::Tanh).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    let (b, i, h) = (b as u64, i as u64, h as u64);
    assert_eq!(f.matmul_forward, mm(b, i, h));
    assert_eq!(f.matmul_backward, 2 * mm(b, i, h));
    // Bias and tanh (b h each), then the sum.
    assert_eq!(f.other_forward, 3 * b * h);
    // Sum's gradient, tanh's derivative (2 b h), the bias row sum.
    assert_eq!(f.other_backward, b * h + 2 * b * h + b * h);
}

#[test]
fn a_layer_over_parts_counts_each_product_and_the_sums_between_them() {
    let (b, i1, i2, h) = (10u64, 7u64, 3u64, 5u64);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x1 = tape.constant(ones(&[10, 7]));
    let x2 = tape.var(ones(&[10, 3]));
    let (w1, w2) = (tape.var(ones(&[7, 5])), tape.var(ones(&[3, 5])));
    let loss = tape.linear_sum(&[(x1, w1), (x2, w2)], None, Activation::Relu).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    assert_eq!(f.matmul_forward, mm(b, i1, h) + mm(b, i2, h));
    // The constant x1 wants no gradient: only dW1, dX2 and dW2.
    assert_eq!(f.matmul_backward, mm(b, i1, h) + 2 * mm(b, i2, h));
    // One add (the second part), the relu, then the sum.
    assert_eq!(f.other_forward, 3 * b * h);
    // Sum's gradient and relu's derivative (2 b h).
    assert_eq!(f.other_backward, b * h + 2 * b * h);
}

#[test]
fn batched_and_transposed_products() {
    // a [B, m, k] @ w [k, n]: w is broadcast over the batch, so its gradient is a batch of
    // products summed over the batch.
    let (nb, m, k, n) = (3u64, 4u64, 5u64, 6u64);
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let a = tape.var(ones(&[3, 4, 5]));
    let w = tape.var(ones(&[5, 6]));
    let y = a.matmul(w).unwrap();
    // A^T A per batch entry: one operand used twice, two backward products.
    let gram = a.matmul_t(a, true, false).unwrap();
    let loss = y.sum_all().add(gram.sum_all()).unwrap();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    assert_eq!(f.matmul_forward, nb * mm(m, k, n) + nb * mm(k, m, k));
    assert_eq!(f.matmul_backward, 2 * nb * mm(m, k, n) + 2 * nb * mm(k, m, k));
    // Forward: the two sums and the add of two scalars.
    assert_eq!(f.other_forward, nb * m * n + nb * k * k + 1);
    // Backward: the two sums, and the batch of w gradients summed to one.
    assert_eq!(f.other_backward, nb * m * n + nb * k * k + nb * k * n);
}

#[test]
fn no_grad_values_are_counted_forward_only() {
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x = tape.var(ones(&[8, 8]));
    let y = {
        let _g = tape.no_grad();
        x.matmul(x).unwrap()
    };
    let loss = x.mul(y).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    assert_eq!(f.matmul_forward, mm(8, 8, 8));
    assert_eq!(f.matmul_backward, 0);
    // mul and sum forward; backward: sum, and mul for x only.
    assert_eq!(f.other_forward, 64 + 64);
    assert_eq!(f.other_backward, 64 + 64);
}

#[test]
fn nothing_is_counted_without_profiling() {
    let tape = Tape::<f32>::new();
    let x = tape.var(ones(&[4, 4]));
    let loss = x.matmul(x).unwrap().sum_all();
    tape.backward(loss).unwrap();
    assert_eq!(tape.profile_flops(), None);
    assert!(tape.profile_report().is_none());

    // Counting starts with profiling: earlier ops are not included.
    let y = x.matmul(x).unwrap();
    tape.enable_profiling();
    let loss = y.matmul(x).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let f = tape.profile_flops().unwrap();
    assert_eq!(f.matmul_forward, mm(4, 4, 4));
}

#[test]
fn report_shows_flops_and_rates() {
    let tape = Tape::<f32>::new();
    tape.enable_profiling();
    let x = tape.var(ones(&[64, 64]));
    let loss = x.matmul(x).unwrap().reshape(&[4096]).unwrap().sum_all();
    tape.backward(loss).unwrap();
    let report = tape.profile_report().unwrap();
    let line = |dir: &str| {
        let start = report.find(dir).unwrap();
        report[start..].lines().find(|l| l.trim_start().starts_with("matmul")).unwrap().to_owned()
    };
    assert!(line("forward:").contains("0.524 MFLOP"), "{report}");
    assert!(line("backward:").contains("1.049 MFLOP"), "{report}");
    assert!(report.contains("GFLOP/s"), "{report}");
    // Reshape does no arithmetic: no rate.
    let reshape = report.lines().find(|l| l.trim_start().starts_with("reshape")).unwrap();
    assert!(reshape.trim_end().ends_with('-'), "{report}");
}

#[test]
fn flop_counts_add_up() {
    let a = FlopCount { matmul_forward: 1, matmul_backward: 2, other_forward: 3, other_backward: 4 };
    let b = a + a;
    assert_eq!(b, FlopCount { matmul_forward: 2, matmul_backward: 4, other_forward: 6, other_backward: 8 });
    assert_eq!(b.total(), 20);
    assert!(
        (FlopCount { matmul_forward: 190_000_000_000, ..FlopCount::default() }.seconds_at(190.0) - 1.0).abs() < 1e-12
    );
}
