//! A finite-difference gradient check of every differentiable op (see `tensor::gradcheck`
//! for the tolerances and why they hold).

use crate::common;

use common::*;
use tensor::gradcheck::check_gradients;
use tensor::{Activation, Tensor};

/// Asserts that the check passes, printing the mismatch if not.
macro_rules! gc {
    ($inputs:expr, $f:expr) => {{
        let inputs: Vec<Tensor<f64>> = $inputs;
        match check_gradients($f, &inputs) {
            Ok(r) => assert!(r.checked > 0),
            Err(e) => panic!("{}", e),
        }
    }};
}

#[test]
fn unary_op_gradients_match_finite_differences() {
    let mut r = rng(1);
    let x = uniform(&mut r, &[3, 4]);
    let xa = away_from_zero(&mut r, &[3, 4]);
    let xp = positive(&mut r, &[3, 4]);
    gc!(vec![x.clone()], |_, v| Ok(v[0].neg()));
    gc!(vec![x.clone()], |_, v| Ok(v[0].exp()));
    gc!(vec![xp.clone()], |_, v| Ok(v[0].log()));
    gc!(vec![xp.clone()], |_, v| Ok(v[0].sqrt()));
    gc!(vec![x.clone()], |_, v| Ok(v[0].square()));
    gc!(vec![x.clone()], |_, v| Ok(v[0].tanh()));
    gc!(vec![x.scale_by(4.0)], |_, v| Ok(v[0].sigmoid()));
    gc!(vec![xa.clone()], |_, v| Ok(v[0].relu()));
    gc!(vec![x.scale_by(5.0)], |_, v| Ok(v[0].softplus()));
    gc!(vec![xa.clone()], |_, v| Ok(v[0].abs()));
    gc!(vec![xp.clone()], |_, v| Ok(v[0].powf(1.7)));
    gc!(vec![xp.clone()], |_, v| Ok(v[0].powf(-0.5)));
    // A band that some inputs fall inside and some outside (the chance of an input within
    // the 1e-6 step of a boundary is negligible, and the seed is fixed).
    gc!(vec![xa.clone()], |_, v| Ok(v[0].clamp(-0.55, 0.55)));
    gc!(vec![x.clone()], |_, v| Ok(v[0].scale(-2.5)));
    gc!(vec![x.clone()], |_, v| Ok(v[0].add_scalar(0.3)));
}

/// Scales a tensor (test convenience).
trait ScaleBy {
    fn scale_by(&self, c: f64) -> Tensor<f64>;
}
impl ScaleBy for Tensor<f64> {
    fn scale_by(&self, c: f64) -> Tensor<f64> {
        Tensor::new(self.data().iter().map(|v| v * c).collect(), self.shape()).unwrap()
    }
}

#[test]
fn binary_ops_with_broadcasting() {
    let mut r = rng(2);
    // (lhs shape, rhs shape): equal, size-1, rank-expanding, scalar, both sides broadcast.
    let cases: [(&[usize], &[usize]); 6] = [
        (&[2, 3], &[2, 3]),
        (&[2, 3], &[3]),
        (&[2, 1, 3], &[4, 1]),
        (&[2, 3], &[]),
        (&[3], &[2, 4, 3]),
        (&[1, 3], &[2, 1]),
    ];
    for (sa, sb) in cases {
        let a = uniform(&mut r, sa);
        let b = uniform(&mut r, sb);
        let bp = positive(&mut r, sb);
        gc!(vec![a.clone(), b.clone()], |_, v| v[0].add(v[1]));
        gc!(vec![a.clone(), b.clone()], |_, v| v[0].sub(v[1]));
        gc!(vec![a.clone(), b.clone()], |_, v| v[0].mul(v[1]));
        gc!(vec![a.clone(), bp.clone()], |_, v| v[0].div(v[1]));
        gc!(vec![bp.clone(), a.clone()], |_, v| v[1].div(v[0]));
    }
}

#[test]
fn per_row_scaling_and_norms() {
    // The fused backward of a * b and a / b when b holds one value per row.
    let mut r = rng(21);
    let a = uniform(&mut r, &[4, 3]);
    let b = positive(&mut r, &[4, 1]);
    gc!(vec![a.clone(), b.clone()], |_, v| v[0].div(v[1]));
    gc!(vec![a.clone(), b.clone()], |_, v| v[0].mul(v[1]));
    let a3 = uniform(&mut r, &[2, 3, 5]);
    let b3 = positive(&mut r, &[2, 3, 1]);
    gc!(vec![a3.clone(), b3.clone()], |_, v| v[0].div(v[1]));
    gc!(vec![a3.clone()], |_, v| Ok(v[0].norm_last(0.0)));
    gc!(vec![a3.clone()], |_, v| Ok(v[0].standardize(1e-5)));
    gc!(vec![a3], |_, v| Ok(v[0].norm_last(1e-3).add_scalar(1.0)));
}

#[test]
fn minimum_and_maximum_away_from_ties() {
    let mut r = rng(3);
    let a = away_from_zero(&mut r, &[4, 3]);
    // b = a shifted by at least 0.1 in either direction: no ties.
    let shift = away_from_zero(&mut r, &[4, 3]);
    let b = Tensor::new(a.data().iter().zip(shift.data()).map(|(x, s)| x + 0.5 * s).collect(), &[4, 3]).unwrap();
    gc!(vec![a.clone(), b.clone()], |_, v| v[0].minimum(v[1]));
    gc!(vec![a.clone(), b.clone()], |_, v| v[0].maximum(v[1]));
    // Broadcast: a column against the matrix.
    let c = Tensor::from_f64(&[0.05, -0.35, 0.72, 0.01], &[4, 1]).unwrap();
    let m = Tensor::from_f64(&[0.5, -0.2, 0.9, 0.4, -0.6, 0.3, 0.1, 0.8, -0.9, 0.6, 0.2, -0.3], &[4, 3]).unwrap();
    gc!(vec![m.clone(), c.clone()], |_, v| v[0].maximum(v[1]));
    gc!(vec![c.clone(), m.clone()], |_, v| v[0].minimum(v[1]));
}

#[test]
fn reduction_gradients_match_finite_differences() {
    let mut r = rng(4);
    let x = distinct(&mut r, &[2, 3, 4]);
    for axis in 0..3 {
        for keep in [false, true] {
            gc!(vec![x.clone()], |_, v| v[0].sum(axis, keep));
            gc!(vec![x.clone()], |_, v| v[0].mean(axis, keep));
            gc!(vec![x.clone()], |_, v| v[0].max(axis, keep));
        }
    }
    gc!(vec![x.clone()], |_, v| Ok(v[0].sum_all()));
    gc!(vec![x.clone()], |_, v| v[0].mean_all());
    gc!(vec![x.clone()], |_, v| v[0].max_all());
}

#[test]
fn matmul_plain_transposed_and_batched() {
    let mut r = rng(5);
    let a = uniform(&mut r, &[3, 4]);
    let b = uniform(&mut r, &[4, 5]);
    gc!(vec![a.clone(), b.clone()], |_, v| v[0].matmul(v[1]));
    // All transpose flags (operands stored transposed).
    let at = uniform(&mut r, &[4, 3]);
    let bt = uniform(&mut r, &[5, 4]);
    gc!(vec![at.clone(), b.clone()], |_, v| v[0].matmul_t(v[1], true, false));
    gc!(vec![a.clone(), bt.clone()], |_, v| v[0].matmul_t(v[1], false, true));
    gc!(vec![at.clone(), bt.clone()], |_, v| v[0].matmul_t(v[1], true, true));
    // Non-contiguous input produced by a transpose op.
    gc!(vec![at.clone(), b.clone()], |_, v| v[0].transpose(0, 1)?.matmul(v[1]));
    // Batched, and batch dims broadcast (size-1 and rank-expanding).
    let ba = uniform(&mut r, &[2, 3, 4]);
    let bb = uniform(&mut r, &[2, 4, 2]);
    gc!(vec![ba.clone(), bb.clone()], |_, v| v[0].matmul(v[1]));
    gc!(vec![ba.clone(), b.clone()], |_, v| v[0].matmul(v[1]));
    let c = uniform(&mut r, &[2, 1, 3, 4]);
    let d = uniform(&mut r, &[3, 2, 4]);
    gc!(vec![c.clone(), d.clone()], |_, v| v[0].matmul_t(v[1], false, true));
    // Batches of tiny products with both gradients fused in one pass, every transpose
    // combination, and the Gram matrix of one tensor with itself (both operands the same).
    let za = uniform(&mut r, &[4, 3, 5]);
    let zt = uniform(&mut r, &[4, 5, 3]);
    let wb = uniform(&mut r, &[4, 5, 2]);
    let wt = uniform(&mut r, &[4, 2, 5]);
    gc!(vec![za.clone(), wb.clone()], |_, v| v[0].matmul(v[1]));
    gc!(vec![zt.clone(), wb.clone()], |_, v| v[0].matmul_t(v[1], true, false));
    gc!(vec![za.clone(), wt.clone()], |_, v| v[0].matmul_t(v[1], false, true));
    gc!(vec![zt.clone(), wt.clone()], |_, v| v[0].matmul_t(v[1], true, true));
    gc!(vec![za.clone()], |_, v| v[0].matmul_t(v[0], true, false));
    gc!(vec![za.clone()], |_, v| v[0].matmul_t(v[0], false, true));
    // Only one operand wanting a gradient (the other a constant, as the observation vectors
    // expressed in a learned frame): the one-sided fused pass.
    gc!(vec![zt.clone()], |t, v| v[0].matmul_t(t.constant(wb.clone()), true, false));
    gc!(vec![wt.clone()], |t, v| t.constant(za.clone()).matmul_t(v[0], false, true));
    // Large enough to take the faer path (m n k >= 16384) and the transposed faer path.
    let la = uniform(&mut r, &[20, 30]);
    let lb = uniform(&mut r, &[30, 40]);
    gc!(vec![la.clone(), lb.clone()], |_, v| v[0].matmul(v[1]));
    let lat = uniform(&mut r, &[30, 20]);
    let lbt = uniform(&mut r, &[40, 30]);
    gc!(vec![lat, lbt], |_, v| v[0].matmul_t(v[1], true, true));
}

#[test]
fn fused_linear_and_softmax() {
    let mut r = rng(6);
    let x = away_from_zero(&mut r, &[2, 3, 4]);
    let w = uniform(&mut r, &[4, 5]);
    let b = uniform(&mut r, &[5]);
    for act in [Activation::Identity, Activation::Tanh] {
        gc!(vec![x.clone(), w.clone(), b.clone()], |_, v| v[0].linear(v[1], Some(v[2]), act));
        gc!(vec![x.clone(), w.clone()], |_, v| v[0].linear(v[1], None, act));
    }
    // Relu: choose weights so that no pre-activation is within 1e-3 of zero.
    let x2 = Tensor::from_f64(&[0.5, -1.0, 2.0, 1.5, 0.25, -0.75], &[2, 3]).unwrap();
    let w2 = Tensor::from_f64(&[1.0, -1.0, 0.5, 0.3, -0.2, 0.8], &[3, 2]).unwrap();
    let b2 = Tensor::from_f64(&[0.1, -0.2], &[2]).unwrap();
    gc!(vec![x2, w2, b2], |_, v| v[0].linear(v[1], Some(v[2]), Activation::Relu));
    gc!(vec![uniform(&mut r, &[3, 5])], |_, v| Ok(v[0].softmax()));
    // One layer over several inputs of different widths: every input, weight and the bias.
    let (xa, xb, xc) = (uniform(&mut r, &[2, 3, 4]), uniform(&mut r, &[2, 3, 2]), uniform(&mut r, &[2, 3, 1]));
    let (wa, wb, wc) = (uniform(&mut r, &[4, 5]), uniform(&mut r, &[2, 5]), uniform(&mut r, &[1, 5]));
    for act in [Activation::Identity, Activation::Tanh] {
        gc!(vec![xa.clone(), wa.clone(), xb.clone(), wb.clone(), xc.clone(), wc.clone(), b.clone()], |t, v| t
            .linear_sum(&[(v[0], v[1]), (v[2], v[3]), (v[4], v[5])], Some(v[6]), act));
        // The same layer reading row blocks of one weight in place.
        let w = Tensor::new([wa.data(), wb.data(), wc.data()].concat(), &[7, 5]).unwrap();
        gc!(vec![xa.clone(), xb.clone(), xc.clone(), w.clone(), b.clone()], |t, v| t.linear_rows(
            &v[..3],
            v[3],
            Some(v[4]),
            act
        ));
        // Some of a layer's output columns, with their part of the bias.
        gc!(vec![xa.clone(), wa.clone(), b.clone()], |_, v| v[0].linear_columns(v[1], Some(v[2]), 1, 3, act));
        // A constant part (no gradient wanted for it) and no bias.
        gc!(vec![wa.clone(), xb.clone(), wb.clone()], |t, v| t.linear_sum(
            &[(t.constant(xa.clone()), v[0]), (v[1], v[2])],
            None,
            act
        ));
    }
}

#[test]
fn a_layer_over_parts_equals_the_layer_over_their_concatenation() {
    let mut r = rng(7);
    let (xa, xb) = (uniform(&mut r, &[6, 3]), uniform(&mut r, &[6, 4]));
    let (wa, wb, b) = (uniform(&mut r, &[3, 2]), uniform(&mut r, &[4, 2]), uniform(&mut r, &[2]));
    let tape = tensor::Tape::new();
    let (xa, xb, wa, wb, b) = (tape.var(xa), tape.var(xb), tape.var(wa), tape.var(wb), tape.var(b));
    let parts = tape.linear_sum(&[(xa, wa), (xb, wb)], Some(b), Activation::Tanh).unwrap();
    let whole =
        tape.cat(&[xa, xb], 1).unwrap().linear(tape.cat(&[wa, wb], 0).unwrap(), Some(b), Activation::Tanh).unwrap();
    let (p, w) = (parts.value(), whole.value());
    p.data().iter().zip(w.data()).for_each(|(a, b)| assert!((a - b).abs() < 1e-12));
    // Parts must agree in their leading dims and output width.
    let bad = tape.var(uniform(&mut r, &[5, 4]));
    assert!(tape.linear_sum(&[(xa, wa), (bad, wb)], None, Activation::Identity).is_err());
    assert!(tape.linear_sum(&[], None, Activation::Identity).is_err());
    // Row blocks of one weight: the widths must add up to its rows.
    let w = tape.cat(&[wa, wb], 0).unwrap();
    let rows = tape.linear_rows(&[xa, xb], w, Some(b), Activation::Tanh).unwrap();
    assert_eq!(rows.value().data(), parts.value().data(), "linear_rows against linear_sum of the blocks");
    let err = tape.linear_rows(&[xa], w, None, Activation::Identity).unwrap_err().to_string();
    assert!(err.contains("sum to 3") && err.contains("[3, out]"), "{err}");
    assert!(tape.linear_rows(&[xa, xb, xb], w, None, Activation::Identity).is_err());
    assert!(tape.linear_rows(&[], w, None, Activation::Identity).is_err());
    // Output columns: within the weight's width, the bias of the full width.
    let cols = xa.linear_columns(wa, None, 1, 1, Activation::Identity).unwrap();
    let narrowed = xa.linear(wa.narrow(1, 1, 1).unwrap(), None, Activation::Identity).unwrap();
    assert_eq!(cols.value().data(), narrowed.value().data(), "linear_columns against a narrowed weight");
    let err = xa.linear_columns(wa, None, 1, 2, Activation::Identity).unwrap_err().to_string();
    assert!(err.contains("columns 1..3") && err.contains("[3, 2]"), "{err}");
    let short_bias = wa.narrow(1, 0, 1).unwrap().reshape(&[3]).unwrap();
    assert!(xa.linear_columns(wa, Some(short_bias), 0, 1, Activation::Identity).is_err());
}

#[test]
fn layout_op_gradients_match_finite_differences() {
    let mut r = rng(7);
    let x = uniform(&mut r, &[2, 3, 4]);
    gc!(vec![x.clone()], |_, v| v[0].reshape(&[6, 4]));
    gc!(vec![x.clone()], |_, v| v[0].unsqueeze(1));
    gc!(vec![x.clone()], |_, v| v[0].permute(&[2, 0, 1]));
    gc!(vec![x.clone()], |_, v| v[0].transpose(0, 2));
    gc!(vec![uniform(&mut r, &[3, 1])], |_, v| v[0].expand(&[2, 3, 4]));
    gc!(vec![x.clone()], |_, v| v[0].narrow(1, 1, 2));
    gc!(vec![x.clone()], |_, v| v[0].narrow(2, 0, 3));
    let y = uniform(&mut r, &[2, 2, 4]);
    gc!(vec![x.clone(), y.clone()], |t, v| t.cat(&[v[0], v[1], v[0]], 1));
    let z = uniform(&mut r, &[2, 3, 4]);
    gc!(vec![x.clone(), z.clone()], |t, v| t.stack(&[v[0], v[1]], 3));
    gc!(vec![x.clone(), z.clone()], |t, v| t.stack(&[v[0], v[1]], 0));
}

#[test]
fn index_ops_with_repeated_indices() {
    let mut r = rng(8);
    let x = uniform(&mut r, &[4, 3]);
    gc!(vec![x.clone()], |_, v| v[0].index_select(0, &[2, 0, 2, 3, 2]));
    gc!(vec![x.clone()], |_, v| v[0].index_select(1, &[1, 1, 0]));
    let src = uniform(&mut r, &[5, 3]);
    gc!(vec![x.clone(), src.clone()], |_, v| v[0].index_add(0, &[1, 3, 1, 0, 1], v[1]));
    gc!(vec![src.clone()], |_, v| v[0].scatter_add(0, &[2, 2, 0, 5, 2], 6));
    // gather along axis 1 with repeats.
    gc!(vec![x.clone()], |_, v| v[0].gather(1, &[4, 2], &[0, 0, 2, 1, 1, 1, 2, 0]));
    gc!(vec![x.clone()], |_, v| v[0].gather(0, &[2, 3], &[3, 3, 0, 1, 3, 2]));
    // Segments with an empty one (segment 2).
    let seg = [0, 0, 1, 3, 3];
    gc!(vec![src.clone()], |_, v| v[0].segment_sum(&seg, 4));
    gc!(vec![src.clone()], |_, v| v[0].segment_mean(&seg, 4));
    let mask = [true, false, false, true, true, false, false, true, false, true, true, false];
    let b = uniform(&mut r, &[3]);
    gc!(vec![x.clone(), b.clone()], |t, v| t.where_select(&mask, v[0], v[1]));
}

#[test]
fn gradients_of_reused_vars_and_composites_match_finite_differences() {
    let mut r = rng(9);
    let x = uniform(&mut r, &[3, 2]);
    // A tensor used several times: x*x + exp(x) + x.
    gc!(vec![x.clone()], |_, v| v[0].mul(v[0])?.add(v[0].exp())?.add(v[0]));
    // A small MLP with a softplus head (the policy's std parameterisation).
    let input = uniform(&mut r, &[5, 4]);
    let w1 = uniform(&mut r, &[4, 8]);
    let b1 = uniform(&mut r, &[8]);
    let w2 = uniform(&mut r, &[8, 2]);
    gc!(vec![input, w1, b1, w2], |_, v| {
        let h = v[0].linear(v[1], Some(v[2]), Activation::Tanh)?;
        let out = h.matmul(v[3])?;
        let loc = out.narrow(1, 0, 1)?;
        let std = out.narrow(1, 1, 1)?.softplus().add_scalar(1e-3);
        loc.square().div(std)?.add(std.log())?.mean_all()
    });
}

#[test]
fn detach_and_no_grad_stop_gradients() {
    let tape = tensor::Tape::<f64>::new();
    let x = tape.var(Tensor::from_f64(&[1.0, 2.0], &[2]).unwrap());
    let loss = x.detach().mul(x).unwrap().sum_all();
    let g = tape.backward(loss).unwrap();
    assert_eq!(g.get(x).unwrap().data(), &[1.0, 2.0]); // not 2x: the detached factor is constant
    let y = {
        let _guard = tape.no_grad();
        x.square()
    };
    assert!(!y.requires_grad());
    assert!(tape.grad_enabled());
    let loss = y.mul(x).unwrap().sum_all();
    let g = tape.backward(loss).unwrap();
    assert_eq!(g.get(x).unwrap().data(), &[1.0, 4.0]);
    // A constant gets no gradient at all.
    let c = tape.constant(Tensor::from_f64(&[3.0], &[1]).unwrap());
    let loss = c.mul(x).unwrap().sum_all();
    let g = tape.backward(loss).unwrap();
    assert!(g.get(c).is_none());
}

#[test]
fn the_checker_catches_a_wrong_gradient() {
    // d/dx (stop_grad(x) * x) is x analytically on the tape but 2x numerically: the check must fail.
    let x = Tensor::from_f64(&[0.7, -1.3], &[2]).unwrap();
    let res = check_gradients(|_, v| Ok(v[0].detach().mul(v[0])?.sum_all()), &[x]);
    let msg = res.expect_err("a wrong gradient must be reported");
    assert!(msg.contains("element 0"), "{msg}");
}
