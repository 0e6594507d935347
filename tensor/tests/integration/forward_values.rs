//! Forward values of every op against hand-computed or closed-form results.

use tensor::{Activation, Tape, Tensor, TensorError};

fn t(data: &[f64], shape: &[usize]) -> Tensor<f64> {
    Tensor::from_f64(data, shape).unwrap()
}

fn close(a: &Tensor<f64>, b: &[f64]) {
    assert_eq!(a.numel(), b.len(), "{a:?} vs {b:?}");
    for (x, y) in a.data().iter().zip(b) {
        assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "{a:?} vs {b:?}");
    }
}

#[test]
fn unary_ops_give_the_closed_form_values() {
    let tape = Tape::<f64>::new();
    let x = tape.constant(t(&[-2.0, 0.0, 0.5, 3.0], &[4]));
    let e = std::f64::consts::E;
    close(&x.neg().value(), &[2.0, 0.0, -0.5, -3.0]);
    close(&x.exp().value(), &[e.powi(-2), 1.0, e.sqrt(), e.powi(3)]);
    close(&x.square().value(), &[4.0, 0.0, 0.25, 9.0]);
    close(&x.relu().value(), &[0.0, 0.0, 0.5, 3.0]);
    close(&x.abs().value(), &[2.0, 0.0, 0.5, 3.0]);
    close(&x.clamp(-1.0, 1.0).value(), &[-1.0, 0.0, 0.5, 1.0]);
    close(&x.scale(2.0).value(), &[-4.0, 0.0, 1.0, 6.0]);
    close(&x.add_scalar(1.0).value(), &[-1.0, 1.0, 1.5, 4.0]);
    close(
        &x.sigmoid().value(),
        &[1.0 / (1.0 + e * e), 0.5, 1.0 / (1.0 + (-0.5f64).exp()), 1.0 / (1.0 + (-3.0f64).exp())],
    );
    close(&x.tanh().value(), &[(-2.0f64).tanh(), 0.0, 0.5f64.tanh(), 3.0f64.tanh()]);
    close(&x.softplus().value(), &[(1.0 + e.powi(-2)).ln(), 2f64.ln(), (1.0 + e.sqrt()).ln(), (1.0 + e.powi(3)).ln()]);
    let p = tape.constant(t(&[1.0, 4.0, 9.0], &[3]));
    close(&p.sqrt().value(), &[1.0, 2.0, 3.0]);
    close(&p.log().value(), &[0.0, 4f64.ln(), 9f64.ln()]);
    close(&p.powf(1.5).value(), &[1.0, 8.0, 27.0]);
    // Softplus stays finite and exact for large inputs (no overflow of e^x).
    let big = tape.constant(t(&[800.0, -800.0], &[2]));
    close(&big.softplus().value(), &[800.0, 0.0]);
    close(&big.sigmoid().value(), &[1.0, 0.0]);
}

#[test]
fn binary_ops_broadcast_to_the_hand_computed_values() {
    let tape = Tape::<f64>::new();
    let a = tape.constant(t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[2, 3]));
    let row = tape.constant(t(&[10.0, 20.0, 30.0], &[3]));
    let col = tape.constant(t(&[1.0, 2.0], &[2, 1]));
    close(&a.add(row).unwrap().value(), &[11.0, 22.0, 33.0, 14.0, 25.0, 36.0]);
    close(&a.sub(col).unwrap().value(), &[0.0, 1.0, 2.0, 2.0, 3.0, 4.0]);
    close(&a.mul(col).unwrap().value(), &[1.0, 2.0, 3.0, 8.0, 10.0, 12.0]);
    close(&a.div(row).unwrap().value(), &[0.1, 0.1, 0.1, 0.4, 0.25, 0.2]);
    let s = tape.constant(Tensor::scalar(3.5));
    close(&a.minimum(s).unwrap().value(), &[1.0, 2.0, 3.0, 3.5, 3.5, 3.5]);
    close(&a.maximum(s).unwrap().value(), &[3.5, 3.5, 3.5, 4.0, 5.0, 6.0]);
    // Both sides broadcast: [2,1] + [3] -> [2,3].
    close(&col.add(row).unwrap().value(), &[11.0, 21.0, 31.0, 12.0, 22.0, 32.0]);
    let bad = tape.constant(t(&[1.0, 2.0], &[2]));
    let err = a.add(bad).unwrap_err();
    assert!(matches!(err, TensorError::ShapeMismatch { .. }));
    let msg = err.to_string();
    assert!(msg.contains("add") && msg.contains("[2, 3]") && msg.contains("[2]"), "{msg}");
}

#[test]
fn reductions_give_the_hand_computed_values() {
    let tape = Tape::<f64>::new();
    let x = tape.constant(t(&[1.0, 5.0, 3.0, 4.0, 2.0, 6.0], &[2, 3]));
    close(&x.sum(0, false).unwrap().value(), &[5.0, 7.0, 9.0]);
    close(&x.sum(1, false).unwrap().value(), &[9.0, 12.0]);
    assert_eq!(x.sum(1, true).unwrap().shape(), vec![2, 1]);
    close(&x.mean(1, false).unwrap().value(), &[3.0, 4.0]);
    close(&x.max(0, false).unwrap().value(), &[4.0, 5.0, 6.0]);
    close(&x.max(1, true).unwrap().value(), &[5.0, 6.0]);
    close(&x.sum_all().value(), &[21.0]);
    close(&x.mean_all().unwrap().value(), &[3.5]);
    close(&x.max_all().unwrap().value(), &[6.0]);
    assert!(matches!(x.sum(2, false), Err(TensorError::BadAxis { .. })));
}

#[test]
fn matmul_gives_the_hand_computed_products() {
    let tape = Tape::<f64>::new();
    let a = tape.constant(t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], &[2, 3]));
    let b = tape.constant(t(&[7.0, 8.0, 9.0, 10.0, 11.0, 12.0], &[3, 2]));
    close(&a.matmul(b).unwrap().value(), &[58.0, 64.0, 139.0, 154.0]);
    // a^T a through the transpose flag: [[17,22,27],[22,29,36],[27,36,45]].
    close(&a.matmul_t(a, true, false).unwrap().value(), &[17.0, 22.0, 27.0, 22.0, 29.0, 36.0, 27.0, 36.0, 45.0]);
    // a a^T = [[14, 32], [32, 77]].
    close(&a.matmul_t(a, false, true).unwrap().value(), &[14.0, 32.0, 32.0, 77.0]);
    // Batched with a broadcast right operand.
    let ab = tape.constant(t(&[1.0, 0.0, 0.0, 1.0, 2.0, 0.0, 0.0, 2.0], &[2, 2, 2]));
    let v = tape.constant(t(&[1.0, 2.0, 3.0, 4.0], &[2, 2]));
    close(&ab.matmul(v).unwrap().value(), &[1.0, 2.0, 3.0, 4.0, 2.0, 4.0, 6.0, 8.0]);
    let err = a.matmul(a).unwrap_err().to_string();
    assert!(err.contains("matmul") && err.contains("[2, 3]"), "{err}");
    // linear = act(x w + b)
    let w = tape.constant(t(&[1.0, -1.0, 0.5, 0.5, 0.0, 1.0], &[3, 2]));
    let bias = tape.constant(t(&[0.0, -10.0], &[2]));
    close(&a.linear(w, Some(bias), Activation::Relu).unwrap().value(), &[2.0, 0.0, 6.5, 0.0]);
}

#[test]
fn layout_and_index_values() {
    let tape = Tape::<f64>::new();
    let x = tape.constant(t(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], &[2, 3]));
    close(&x.transpose(0, 1).unwrap().value(), &[0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
    close(&x.narrow(1, 1, 2).unwrap().value(), &[1.0, 2.0, 4.0, 5.0]);
    close(&tape.cat(&[x, x], 0).unwrap().value(), &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    close(&tape.cat(&[x, x], 1).unwrap().value(), &[0.0, 1.0, 2.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 3.0, 4.0, 5.0]);
    let st = tape.stack(&[x, x], 2).unwrap();
    assert_eq!(st.shape(), vec![2, 3, 2]);
    close(&st.value(), &[0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0, 5.0, 5.0]);
    close(&x.index_select(1, &[2, 2, 0]).unwrap().value(), &[2.0, 2.0, 0.0, 5.0, 5.0, 3.0]);
    close(&x.gather(1, &[2, 2], &[2, 0, 1, 1]).unwrap().value(), &[2.0, 0.0, 4.0, 4.0]);
    // Duplicate indices accumulate.
    let src = tape.constant(t(&[1.0, 10.0, 100.0], &[3, 1]));
    close(&src.scatter_add(0, &[1, 1, 0], 3).unwrap().value(), &[100.0, 11.0, 0.0]);
    let rows = tape.constant(t(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0], &[4, 2]));
    close(&rows.segment_sum(&[0, 0, 2, 2], 3).unwrap().value(), &[4.0, 6.0, 0.0, 0.0, 12.0, 14.0]);
    close(&rows.segment_mean(&[0, 0, 2, 2], 3).unwrap().value(), &[2.0, 3.0, 0.0, 0.0, 6.0, 7.0]);
    let zero = tape.constant(Tensor::scalar(-1.0));
    close(
        &tape.where_select(&[true, false, true, false, true, false], x, zero).unwrap().value(),
        &[0.0, -1.0, 2.0, -1.0, 4.0, -1.0],
    );
    close(&x.expand(&[2, 2, 3]).unwrap().value(), &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    close(&tape.constant(t(&[3.0, 4.0, 0.0, 0.0], &[2, 2])).norm_last(0.0).value(), &[5.0, 0.0]);
    // [1, 3] -> mean 2, variance 2/3: (x - 2) / sqrt(2/3).
    let sd = (2.0f64 / 3.0).sqrt();
    close(&tape.constant(t(&[1.0, 2.0, 3.0], &[1, 3])).standardize(0.0).value(), &[-1.0 / sd, 0.0, 1.0 / sd]);
    let sm = tape.constant(t(&[0.0, 2f64.ln()], &[1, 2])).softmax();
    close(&sm.value(), &[1.0 / 3.0, 2.0 / 3.0]);
}

#[test]
fn errors_name_the_op_and_shapes() {
    let tape = Tape::<f64>::new();
    let x = tape.constant(t(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], &[2, 3]));
    assert!(matches!(x.index_select(1, &[3]), Err(TensorError::IndexOutOfRange { index: 3, len: 3, .. })));
    assert!(x.narrow(1, 2, 2).unwrap_err().to_string().contains("narrow"));
    assert!(x.reshape(&[4]).unwrap_err().to_string().contains("reshape"));
    assert!(x.permute(&[0, 0]).unwrap_err().to_string().contains("permute"));
    assert!(x.segment_sum(&[1, 0], 2).unwrap_err().to_string().contains("sorted"));
    let y = tape.constant(t(&[0.0; 4], &[2, 2]));
    assert!(tape.cat(&[x, y], 0).unwrap_err().to_string().contains("[2, 3]"));
    assert!(tape.backward(x).unwrap_err().to_string().contains("single value"));
    assert!(Tensor::<f32>::new(vec![1.0; 5], &[2, 3]).is_err());
}

/// The Gaussian basis is the f64 formula `exp((coeff * y) * y)`, `y = x - c`, rounded once
/// to the tape's precision, bit for bit, one row a value.
#[test]
fn a_gaussian_basis_is_the_f64_formula_rounded_once() {
    let x = [0.0, 0.3, 7.25, 19.999, 25.0];
    let centres = [0.0, 0.5, 10.0, 20.0];
    let coeff = -1.7;
    let tape = Tape::<f32>::new();
    let b = tape.gaussian_basis(&x, &centres, coeff).unwrap();
    assert_eq!(b.shape(), vec![5, 4]);
    let want: Vec<f32> =
        x.iter().flat_map(|&xe| centres.iter().map(move |&c| (coeff * (xe - c) * (xe - c)).exp() as f32)).collect();
    assert_eq!(b.value().data(), &want[..]);
    let empty = tape.gaussian_basis(&[], &centres, coeff).unwrap();
    assert_eq!(empty.shape(), vec![0, 4]);
}
