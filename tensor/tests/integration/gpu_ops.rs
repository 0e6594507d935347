//! Every op of the tape on the GPU against the CPU, forward and backward, in f32 (feature
//! `gpu`; CI runs these on Mesa's lavapipe, and `test.sh` fails when no adapter is found).
//!
//! Each check records the same computation twice, once on host tensors and once on the same
//! values moved to the GPU, reduces its output with fixed random weights to a scalar loss,
//! and compares the output and every input's gradient. Tolerances (`|gpu - cpu| <= atol +
//! rtol |cpu|`), and why:
//! - `EXACT` (0): copies, selections and sums the GPU kernel performs in the CPU's order.
//! - `ELEMENTWISE` (rtol 2e-5, atol 1e-6): WGSL's `exp`, `log`, `pow` and `sqrt` are allowed
//!   a few ulp (more for `exp` of large arguments), and derived functions (tanh, sigmoid,
//!   softplus) a few more; 2e-5 is about 170 ulp of f32.
//! - `SUMS` (rtol 1e-4, atol 1e-4): products and reductions over up to a few hundred terms of
//!   magnitude <= 1 add in another order than the CPU's (tiles, eight-lane partial sums);
//!   rounding differences grow with the number of terms times f32's 6e-8.
#![cfg(feature = "gpu")]

use crate::common;

use common::{rng, uniform};
use rand::RngExt;
use tensor::{Activation, Device, Result, Tape, Tensor, Var};

/// The tests of this file one at a time: one of them counts the device's uploads, which the
/// others would change.
fn serial() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// A tolerance: `atol + rtol * |cpu|`.
#[derive(Clone, Copy)]
struct Tol(f64, f64);
const EXACT: Tol = Tol(0.0, 0.0);
const ELEMENTWISE: Tol = Tol(2e-5, 1e-6);
const SUMS: Tol = Tol(1e-4, 1e-4);

/// Uniform f32 values in [-1, 1].
fn randn(seed: u64, shape: &[usize]) -> Tensor<f32> {
    uniform(&mut rng(seed), shape).cast()
}

/// f32 values in [0.5, 2] (log, sqrt, powf, division).
fn positive(seed: u64, shape: &[usize]) -> Tensor<f32> {
    common::positive(&mut rng(seed), shape).cast()
}

fn close(what: &str, got: &Tensor<f32>, want: &Tensor<f32>, tol: Tol) {
    assert_eq!(got.shape(), want.shape(), "{what}: shapes");
    for (i, (g, w)) in got.data().iter().zip(want.data()).enumerate() {
        let bound = tol.1 + tol.0 * w.abs() as f64;
        assert!(
            ((g - w).abs() as f64) <= bound || (g.is_nan() && w.is_nan()),
            "{what}: element {i}: gpu {g} vs cpu {w} (bound {bound:e})"
        );
    }
}

/// The computation under test: output of the inputs' vars.
type Body<'a> = dyn for<'t> Fn(&'t Tape<f32>, &[Var<'t, f32>]) -> Result<Var<'t, f32>> + 'a;

/// One run of `f` on `inputs` placed on `device`: the output and the gradients of the loss
/// `sum(out * weights)` for every input, brought to the host.
fn run(device: Device, inputs: &[Tensor<f32>], f: &Body<'_>) -> (Tensor<f32>, Vec<Option<Tensor<f32>>>, Device) {
    let tape = Tape::<f32>::new();
    let vars: Vec<Var<'_, f32>> = inputs.iter().map(|x| tape.var(x.to_device(device).unwrap())).collect();
    let out = f(&tape, &vars).unwrap();
    let weights = randn(99, &out.shape()).to_device(device).unwrap();
    let loss = out.mul(tape.constant(weights)).unwrap().sum_all();
    let grads = tape.backward(loss).unwrap();
    let produced_on = out.value().device();
    let gs = vars.iter().map(|&v| grads.get(v).map(|g| g.to_device(Device::Cpu).unwrap())).collect();
    (out.value().to_device(Device::Cpu).unwrap(), gs, produced_on)
}

/// Checks `f` on the GPU against the CPU: output, every gradient, that the GPU output was
/// computed on the GPU, and that a second GPU run gives the same bits.
fn check(name: &str, inputs: &[Tensor<f32>], tol: Tol, f: &Body<'_>) {
    let (want, want_g, _) = run(Device::Cpu, inputs, f);
    let (got, got_g, on) = run(Device::Gpu, inputs, f);
    assert_eq!(on, Device::Gpu, "{name}: the output was not computed on the GPU");
    close(&format!("{name} forward"), &got, &want, tol);
    for (i, (g, w)) in got_g.iter().zip(&want_g).enumerate() {
        match (g, w) {
            (Some(g), Some(w)) => close(&format!("{name} gradient of input {i}"), g, w, tol),
            (None, None) => {}
            _ => panic!("{name}: gradient of input {i} present on one device only"),
        }
    }
    let (again, again_g, _) = run(Device::Gpu, inputs, f);
    assert_eq!(again.data(), got.data(), "{name}: two GPU runs differ");
    for (a, b) in again_g.iter().zip(&got_g) {
        assert_eq!(
            a.as_ref().map(|t| t.data().to_vec()),
            b.as_ref().map(|t| t.data().to_vec()),
            "{name}: two GPU runs' gradients differ"
        );
    }
}

#[test]
fn unary_ops_forward_and_backward() {
    let _serial = serial();
    type U = fn(Var<'_, f32>) -> Var<'_, f32>;
    let ops: [(&str, U, bool); 15] = [
        ("neg", |x| x.neg(), false),
        ("exp", |x| x.exp(), false),
        ("log", |x| x.log(), true),
        ("sqrt", |x| x.sqrt(), true),
        ("square", |x| x.square(), false),
        ("tanh", |x| x.scale(3.0).tanh(), false),
        ("sigmoid", |x| x.scale(4.0).sigmoid(), false),
        ("relu", |x| x.relu(), false),
        ("softplus", |x| x.scale(20.0).softplus(), false),
        ("abs", |x| x.abs(), false),
        ("powf 3", |x| x.powf(3.0), false),
        ("powf 0.5", |x| x.powf(0.5), true),
        ("clamp", |x| x.clamp(-0.5, 0.25), false),
        ("scale", |x| x.scale(-1.5), false),
        ("add_scalar", |x| x.add_scalar(0.75), false),
    ];
    for (i, (name, op, pos)) in ops.into_iter().enumerate() {
        let x = if pos { positive(i as u64, &[7, 33]) } else { randn(i as u64, &[7, 33]) };
        check(name, &[x], ELEMENTWISE, &|_, v| Ok(op(v[0])));
    }
}

#[test]
fn binary_ops_with_broadcasting() {
    let _serial = serial();
    type B = for<'t> fn(Var<'t, f32>, Var<'t, f32>) -> Result<Var<'t, f32>>;
    let ops: [(&str, B); 6] = [
        ("add", |a, b| a.add(b)),
        ("sub", |a, b| a.sub(b)),
        ("mul", |a, b| a.mul(b)),
        ("div", |a, b| a.div(b)),
        ("minimum", |a, b| a.minimum(b)),
        ("maximum", |a, b| a.maximum(b)),
    ];
    // The last three: one value of `b` per row of `a` (rows of 15, 7 and 24 values), which
    // mul and div differentiate in one kernel with the rows' sums inside.
    let shapes: [(&[usize], &[usize]); 8] = [
        (&[4, 5], &[4, 5]),
        (&[4, 5], &[5]),
        (&[3, 4, 5], &[4, 1]),
        (&[4, 1], &[1, 6]),
        (&[2, 3], &[]),
        (&[6, 3, 5], &[6, 1, 1]),
        (&[6, 7], &[6, 1]),
        (&[5, 2, 12], &[5, 1, 1]),
    ];
    for (name, op) in ops {
        for (s, (sa, sb)) in shapes.iter().enumerate() {
            let a = randn(10 + s as u64, sa);
            let b = if name == "div" { positive(20 + s as u64, sb) } else { randn(20 + s as u64, sb) };
            let label = format!("{name} {sa:?} {sb:?}");
            check(&label, &[a.clone(), b.clone()], SUMS, &|_, v| op(v[0], v[1]));
            // One gradient wanted, the other operand a constant (either side).
            check(&format!("{label}, b constant"), &[a.clone(), b.clone()], SUMS, &|t, v| {
                op(v[0], t.constant(v[1].value().clone()))
            });
            check(&format!("{label}, a constant"), &[a, b], SUMS, &|t, v| op(t.constant(v[0].value().clone()), v[1]));
        }
    }
}

#[test]
fn fused_binary_gradients_keep_the_bits_of_their_rules() {
    let _serial = serial();
    // Broadcast both ways, so each gradient is also summed back: the one-launch kernel
    // against the rules written as separate element-wise ops and sums on the GPU.
    let (a, b) = (randn(40, &[3, 4, 5]), positive(41, &[4, 1]));
    let w = randn(42, &[3, 4, 5]);
    let bits = |t: &Tensor<f32>| t.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    type B = for<'t> fn(Var<'t, f32>, Var<'t, f32>) -> Result<Var<'t, f32>>;
    let ops: [(&str, B); 2] = [("mul", |a, b| a.mul(b)), ("div", |a, b| a.div(b))];
    for (name, op) in ops {
        let tape = Tape::<f32>::new();
        let (av, bv) = (tape.var(a.to_device(Device::Gpu).unwrap()), tape.var(b.to_device(Device::Gpu).unwrap()));
        let wv = tape.constant(w.to_device(Device::Gpu).unwrap());
        let y = op(av, bv).unwrap();
        let grads = tape.backward(y.mul(wv).unwrap().sum_all()).unwrap();
        let (ga, gb) = (grads.get(av).unwrap(), grads.get(bv).unwrap());
        let _off = tape.no_grad();
        let (want_a, want_b) = if name == "mul" {
            (wv.mul(bv).unwrap(), wv.mul(av).unwrap())
        } else {
            (wv.div(bv).unwrap(), wv.mul(y).unwrap().div(bv).unwrap().neg())
        };
        let want_b = want_b.sum(0, false).unwrap().sum(1, true).unwrap();
        assert_eq!(
            bits(&ga.to_device(Device::Cpu).unwrap()),
            bits(&want_a.value().to_device(Device::Cpu).unwrap()),
            "{name}: ga"
        );
        assert_eq!(
            bits(&gb.to_device(Device::Cpu).unwrap()),
            bits(&want_b.value().to_device(Device::Cpu).unwrap()),
            "{name}: gb"
        );
    }
}

#[test]
fn an_input_used_several_times_accumulates_its_gradient() {
    let _serial = serial();
    let x = randn(30, &[5, 6]);
    check("x * x", std::slice::from_ref(&x), SUMS, &|_, v| v[0].mul(v[0]));
    check("exp x + x^2 + narrow", std::slice::from_ref(&x), SUMS, &|_, v| {
        let y = v[0].exp().add(v[0].square())?;
        y.narrow(1, 0, 3)?.add(v[0].narrow(1, 2, 3)?)
    });
    // An add passes one gradient to both inputs, so a device gradient starts out shared:
    // added to out of place when a second contribution comes (`x + x`), copied before an
    // in-place rule writes it (the narrow of `x`, whose rule runs after the add's).
    check("x + x", std::slice::from_ref(&x), EXACT, &|_, v| v[0].add(v[0]));
    let y = randn(31, &[5, 6]);
    check("x + y, then a narrow of x", &[x, y], EXACT, &|_, v| {
        let early = v[0].narrow(1, 0, 2)?;
        v[0].add(v[1])?.narrow(1, 0, 2)?.add(early)
    });
}

#[test]
fn reductions_on_the_gpu_match_the_cpu_forward_and_backward() {
    let _serial = serial();
    let x = randn(1, &[3, 70, 5]);
    for axis in 0..3 {
        for keep in [false, true] {
            check(&format!("sum {axis} {keep}"), std::slice::from_ref(&x), SUMS, &|_, v| v[0].sum(axis, keep));
            check(&format!("mean {axis} {keep}"), std::slice::from_ref(&x), SUMS, &|_, v| v[0].mean(axis, keep));
            check(&format!("max {axis} {keep}"), std::slice::from_ref(&x), EXACT, &|_, v| v[0].max(axis, keep));
        }
    }
    check("sum_all", std::slice::from_ref(&x), SUMS, &|_, v| Ok(v[0].sum_all()));
    check("mean_all", std::slice::from_ref(&x), SUMS, &|_, v| v[0].mean_all());
    check("max_all", std::slice::from_ref(&x), EXACT, &|_, v| v[0].max_all());
    // A long axis: the two-pass reduction (chunks of 1024, then their sum).
    let long = randn(2, &[5000]);
    check("sum of 5000", &[long], Tol(1e-4, 1e-3), &|_, v| Ok(v[0].sum_all()));
    // Several threads per output (reduce_axis.wgsl's lanes): a layer's bias gradient (rows
    // summed, 64 columns side by side, two passes), outputs that share a workgroup across
    // rows of `outer` (inner 5), an axis shorter than a lane's share, and maxima over long
    // axes of every sign (the lanes' tree must keep the first pass's maximum).
    let rows = randn(3, &[3000, 64]);
    check("bias gradient of 3000 rows", std::slice::from_ref(&rows), Tol(1e-4, 1e-3), &|_, v| v[0].sum(0, false));
    check("max of 3000 rows", &[rows], EXACT, &|_, v| v[0].max(0, false));
    let mixed = randn(4, &[7, 300, 5]);
    check("sum 1 of [7, 300, 5]", std::slice::from_ref(&mixed), SUMS, &|_, v| v[0].sum(1, false));
    check("mean 1 of [7, 300, 5]", std::slice::from_ref(&mixed), SUMS, &|_, v| v[0].mean(1, true));
    check("max 1 of [7, 300, 5]", &[mixed], EXACT, &|_, v| v[0].max(1, false));
    let short = randn(5, &[9, 6, 2]);
    check("sum 1 of [9, 6, 2]", &[short], SUMS, &|_, v| v[0].sum(1, false));
    check("max of 4100 negatives", &[randn(6, &[4100])], EXACT, &|_, v| v[0].add_scalar(-3.0).max_all());
}

#[test]
fn matrix_products_on_the_gpu_match_the_cpu_forward_and_backward() {
    let _serial = serial();
    for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
        let a = randn(3, if ta { &[2, 17, 9] } else { &[2, 9, 17] });
        let b = randn(4, if tb { &[13, 17] } else { &[17, 13] });
        check(&format!("matmul {ta} {tb}"), &[a, b], SUMS, &|_, v| v[0].matmul_t(v[1], ta, tb));
    }
    // The same tensor on both sides (a Gram matrix): both gradients go to one input.
    check("gram", &[randn(5, &[4, 3, 8])], SUMS, &|_, v| v[0].matmul_t(v[0], true, false));
}

#[test]
fn layers_on_the_gpu_match_the_cpu_forward_and_backward() {
    let _serial = serial();
    let x = randn(6, &[11, 20]);
    let w = randn(7, &[20, 9]);
    let b = randn(8, &[9]);
    for act in [Activation::Identity, Activation::Relu, Activation::Tanh] {
        check(&format!("linear {act:?}"), &[x.clone(), w.clone(), b.clone()], SUMS, &|_, v| {
            v[0].linear(v[1], Some(v[2]), act)
        });
    }
    let (x2, w2) = (randn(9, &[11, 5]), randn(10, &[5, 9]));
    check("linear_sum", &[x, w, x2, w2, b], SUMS, &|t, v| {
        t.linear_sum(&[(v[0], v[1]), (v[2], v[3])], Some(v[4]), Activation::Relu)
    });
    let s = randn(11, &[6, 10]);
    check("softmax", std::slice::from_ref(&s), SUMS, &|_, v| Ok(v[0].scale(3.0).softmax()));
    // A layer reading row blocks of its weight in place, the weight also used whole by a
    // second layer: against the CPU, and the same bits as the narrowed weights on each device.
    let parts =
        [randn(12, &[70, 20]), randn(13, &[70, 5]), randn(14, &[70, 1]), randn(15, &[26, 9]), randn(16, &[70, 26])];
    let (rows, narrowed) = (&rows_then_whole as &Body<'_>, &narrows_then_whole as &Body<'_>);
    check("linear_rows", &parts, SUMS, rows);
    same_bits("linear_rows", &parts, rows, narrowed);
    // Some of a layer's output columns, each with its part of the bias, the weight and bias
    // also used whole: against the CPU, and the bits of narrowed weights and biases.
    let layer = [randn(17, &[70, 12]), randn(18, &[12, 40]), randn(19, &[40])];
    let (cols, narrowed) = (&columns_then_whole as &Body<'_>, &narrowed_columns_then_whole as &Body<'_>);
    check("linear_columns", &layer, SUMS, cols);
    same_bits("linear_columns", &layer, cols, narrowed);
    check("norm_last", std::slice::from_ref(&s), SUMS, &|_, v| Ok(v[0].norm_last(1e-8)));
    check("standardize", &[s], SUMS, &|_, v| Ok(v[0].standardize(1e-5)));
}

/// `tanh(cat(v0, v1, v2) @ v3 + b)` by `linear_rows` (bias: the first 9 columns of `v4`'s
/// first row), then a second layer using the weight `v3` whole on `v4`, both outputs added.
fn rows_then_whole<'t>(t: &'t Tape<f32>, v: &[Var<'t, f32>]) -> Result<Var<'t, f32>> {
    let b = v[4].narrow(0, 0, 1)?.narrow(1, 0, 9)?.reshape(&[9])?;
    let y = t.linear_rows(&v[..3], v[3], Some(b), Activation::Tanh)?;
    y.add(v[4].linear(v[3], None, Activation::Identity)?)
}

/// [`rows_then_whole`] with the weight's row blocks cut out by `narrow`.
fn narrows_then_whole<'t>(t: &'t Tape<f32>, v: &[Var<'t, f32>]) -> Result<Var<'t, f32>> {
    let b = v[4].narrow(0, 0, 1)?.narrow(1, 0, 9)?.reshape(&[9])?;
    let terms = [(v[0], v[3].narrow(0, 0, 20)?), (v[1], v[3].narrow(0, 20, 5)?), (v[2], v[3].narrow(0, 25, 1)?)];
    let y = t.linear_sum(&terms, Some(b), Activation::Tanh)?;
    y.add(v[4].linear(v[3], None, Activation::Identity)?)
}

/// `f` and `g` give the same bits, output and gradients, on the CPU and on the GPU.
fn same_bits(name: &str, inputs: &[Tensor<f32>], f: &Body<'_>, g: &Body<'_>) {
    let bits = |t: &Tensor<f32>| t.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for device in [Device::Cpu, Device::Gpu] {
        let (a, ag, _) = run(device, inputs, f);
        let (b, bg, _) = run(device, inputs, g);
        assert_eq!(bits(&a), bits(&b), "{device}: {name} against narrowed weights");
        for (i, (x, y)) in ag.iter().zip(&bg).enumerate() {
            assert_eq!(
                x.as_ref().map(bits),
                y.as_ref().map(bits),
                "{device}: gradient {i}, {name} against narrowed weights"
            );
        }
    }
}

/// Columns 0..16 (tanh), 16..36 and 36..40 of the layer `v0 @ v1 + v2`, side by side, plus the
/// whole layer (so the weight's and bias's gradients gather from both).
fn columns_then_whole<'t>(t: &'t Tape<f32>, v: &[Var<'t, f32>]) -> Result<Var<'t, f32>> {
    let a = v[0].linear_columns(v[1], Some(v[2]), 0, 16, Activation::Tanh)?;
    let b = v[0].linear_columns(v[1], Some(v[2]), 16, 20, Activation::Identity)?;
    let c = v[0].linear_columns(v[1], None, 36, 4, Activation::Relu)?;
    t.cat(&[a, b, c], 1)?.add(v[0].linear(v[1], Some(v[2]), Activation::Identity)?)
}

/// [`columns_then_whole`] with the weight's and bias's columns cut out by `narrow`.
fn narrowed_columns_then_whole<'t>(t: &'t Tape<f32>, v: &[Var<'t, f32>]) -> Result<Var<'t, f32>> {
    let cols = |s, n| -> Result<(Var<'t, f32>, Var<'t, f32>)> { Ok((v[1].narrow(1, s, n)?, v[2].narrow(0, s, n)?)) };
    let ((wa, ba), (wb, bb), (wc, _)) = (cols(0, 16)?, cols(16, 20)?, cols(36, 4)?);
    let a = v[0].linear(wa, Some(ba), Activation::Tanh)?;
    let b = v[0].linear(wb, Some(bb), Activation::Identity)?;
    let c = v[0].linear(wc, None, Activation::Relu)?;
    t.cat(&[a, b, c], 1)?.add(v[0].linear(v[1], Some(v[2]), Activation::Identity)?)
}

#[test]
fn layout_ops_on_the_gpu_match_the_cpu_forward_and_backward() {
    let _serial = serial();
    let x = randn(12, &[2, 3, 4]);
    check("reshape", std::slice::from_ref(&x), EXACT, &|_, v| v[0].reshape(&[6, 4]));
    check("permute", std::slice::from_ref(&x), EXACT, &|_, v| v[0].permute(&[2, 0, 1]));
    check("transpose", std::slice::from_ref(&x), EXACT, &|_, v| v[0].transpose(0, 2));
    check("unsqueeze+expand", std::slice::from_ref(&x), SUMS, &|_, v| v[0].unsqueeze(1)?.expand(&[2, 5, 3, 4]));
    check("narrow", std::slice::from_ref(&x), EXACT, &|_, v| v[0].narrow(1, 1, 2));
    // Two narrows of one input accumulate into one gradient buffer.
    check("narrow twice", std::slice::from_ref(&x), EXACT, &|_, v| v[0].narrow(2, 0, 3)?.add(v[0].narrow(2, 1, 3)?));
    let y = randn(13, &[2, 5, 4]);
    check("cat", &[x.clone(), y.clone()], EXACT, &|t, v| t.cat(&[v[0], v[1], v[0]], 1));
    // Nine parts (a launch joins six), one of them empty, along each axis in turn.
    let lens = [3, 0, 1, 2, 4, 1, 3, 2, 5];
    for axis in 0..3 {
        let parts: Vec<Tensor<f32>> = (0..9)
            .map(|i| {
                let mut shape = vec![2, 3, 4];
                shape[axis] = lens[i];
                randn(50 + i as u64, &shape)
            })
            .collect();
        check(&format!("cat of nine on axis {axis}"), &parts, EXACT, &|t, v| t.cat(v, axis));
    }
    check("stack", &[x.clone(), x.clone()], EXACT, &|t, v| t.stack(&[v[0], v[1]], 0));
}

#[test]
fn index_ops_on_the_gpu_match_the_cpu_forward_and_backward() {
    let _serial = serial();
    let x = randn(14, &[3, 6, 2]);
    let idx = [5, 0, 0, 3, 5, 5, 1];
    check("index_select", std::slice::from_ref(&x), EXACT, &|_, v| v[0].index_select(1, &idx));
    let src = randn(15, &[3, 7, 2]);
    check("index_add", &[x.clone(), src.clone()], EXACT, &|_, v| v[0].index_add(1, &idx, v[1]));
    check("scatter_add", &[src], EXACT, &|_, v| v[0].scatter_add(1, &idx, 6));
    let mut r = rng(16);
    let gidx: Vec<usize> = (0..3 * 4 * 2).map(|_| r.random_range(0..6)).collect();
    check("gather", std::slice::from_ref(&x), EXACT, &|_, v| v[0].gather(1, &[3, 4, 2], &gidx));
    let rows = randn(17, &[9, 3]);
    let seg = [0, 0, 1, 3, 3, 3, 4, 4, 4];
    check("segment_sum", std::slice::from_ref(&rows), EXACT, &|_, v| v[0].segment_sum(&seg, 6));
    check("segment_mean", &[rows], ELEMENTWISE, &|_, v| v[0].segment_mean(&seg, 6));
    let (a, b) = (randn(18, &[4, 5]), randn(19, &[5]));
    let mask: Vec<bool> = (0..20).map(|i| i % 3 != 1).collect();
    check("where", &[a, b], EXACT, &|t, v| t.where_select(&mask, v[0], v[1]));
}

/// An op never moves an operand behind the caller's back: a host constant meeting a GPU
/// value is an error naming both devices (and uploads nothing), while the same constant
/// recorded on a GPU tape, or moved with `to_device`, joins the op. f64 stays on the host.
#[test]
fn mixed_devices_are_an_error_and_f64_stays_on_the_host() {
    let _serial = serial();
    let tape = Tape::<f32>::new();
    let x = tape.var(randn(20, &[3, 4]).to_device(Device::Gpu).unwrap());
    let c = tape.constant(randn(21, &[4]));
    let before = tensor::gpu::gpu().unwrap().stats().uploads;
    let err = x.mul(c).unwrap_err().to_string();
    assert!(err.contains("cpu") && err.contains("gpu") && err.contains("to_device"), "{err}");
    assert_eq!(tensor::gpu::gpu().unwrap().stats().uploads, before, "nothing was uploaded");
    let moved = tape.constant(randn(21, &[4]).to_device(Device::Gpu).unwrap());
    assert_eq!(x.mul(moved).unwrap().value().device(), Device::Gpu);
    let gpu_tape = Tape::<f32>::on(Device::Gpu);
    let (x, c) = (gpu_tape.var(randn(20, &[3, 4])), gpu_tape.constant(randn(21, &[4])));
    assert_eq!(x.mul(c).unwrap().value().device(), Device::Gpu);
    let err = Tensor::<f64>::zeros(&[2]).to_device(Device::Gpu).unwrap_err().to_string();
    assert!(err.contains("f32") && err.contains("f64"), "{err}");
    let info = tensor::gpu::gpu().unwrap().adapter().to_string();
    assert!(!info.is_empty());
}

/// A leaf a GPU tape cannot place there (f64 stays on the host) would have its ops run on
/// the host unnoticed: the tape says so, and its backward pass refuses with the reason.
#[test]
fn a_gpu_tape_refuses_to_differentiate_what_stayed_on_the_host() {
    let _serial = serial();
    let tape = Tape::<f64>::on(Device::Gpu);
    let x = tape.var(Tensor::<f64>::new(vec![1.0, 2.0], &[2]).unwrap());
    assert_eq!(x.value().device(), Device::Cpu);
    let why = tape.misplaced().expect("the f64 leaf is recorded as misplaced");
    assert!(why.contains("f64"), "{why}");
    let err = tape.backward(x.square().sum_all()).unwrap_err().to_string();
    assert!(err.contains("backward") && err.contains("stayed on the host") && err.contains("f64"), "{err}");
    // An f32 tape on the GPU places everything and says nothing.
    let tape = Tape::<f32>::on(Device::Gpu);
    let y = tape.var(randn(24, &[2, 3]));
    assert!(tape.misplaced().is_none());
    assert!(tape.backward(y.sum_all()).is_ok());
}

#[test]
fn a_gpu_tape_uploads_its_leaves_once() {
    let _serial = serial();
    let tape = Tape::<f32>::on(Device::Gpu);
    let x = tape.var(randn(22, &[2, 3]));
    let c = tape.constant(randn(23, &[3]));
    assert_eq!((x.value().device(), c.value().device()), (Device::Gpu, Device::Gpu));
    let before = tensor::gpu::gpu().unwrap().stats().uploads;
    let y = x.mul(c).unwrap().add(c).unwrap().sum_all();
    let g = tape.backward(y).unwrap();
    assert_eq!(g.get(x).unwrap().device(), Device::Gpu);
    // The backward seed is the one upload (nothing else crosses: every operand is there).
    assert_eq!(tensor::gpu::gpu().unwrap().stats().uploads - before, 1);
}

/// An index list seen before is not uploaded again, nor its scatter lists rebuilt: the
/// second pass over the same list uploads only the leaf and the backward seed, and gives the
/// same bits; a list of the same length with other contents is uploaded and used.
#[test]
fn index_lists_are_uploaded_once_while_they_recur() {
    let _serial = serial();
    let x = randn(60, &[4, 50, 3]);
    let mut r = rng(61);
    let first: Vec<usize> = (0..333).map(|_| r.random_range(0..50)).collect();
    let mut other = first.clone();
    other[200] = (other[200] + 1) % 50;
    // Uploads of one pass (x, the seed, and whatever index lists it needs) and its results.
    let pass = |idx: &[usize]| {
        let before = tensor::gpu::gpu().unwrap().stats().uploads;
        let tape = Tape::<f32>::on(Device::Gpu);
        let xv = tape.var(x.clone());
        let y = xv.index_select(1, idx).unwrap();
        let loss = y.mul(y).unwrap().sum_all();
        let g = tape.backward(loss).unwrap().get(xv).unwrap().to_device(Device::Cpu).unwrap();
        let uploads = tensor::gpu::gpu().unwrap().stats().uploads - before;
        (uploads, y.value().to_device(Device::Cpu).unwrap(), g)
    };
    let cpu = |idx: &[usize]| {
        let tape = Tape::<f32>::new();
        let xv = tape.var(x.clone());
        let y = xv.index_select(1, idx).unwrap();
        let g = tape.backward(y.mul(y).unwrap().sum_all()).unwrap().get(xv).unwrap().clone();
        (y.value().clone(), g)
    };
    let (n1, y1, g1) = pass(&first);
    let (n2, y2, g2) = pass(&first);
    // The list (one buffer) and the scatter lists of its adjoint (three) the first time only.
    assert_eq!((n1, n2), (2 + 4, 2), "uploads of the first and second pass");
    assert_eq!((y1.data(), g1.data()), (y2.data(), g2.data()));
    let (yc, gc) = cpu(&first);
    assert_eq!((y1.data(), g1.data()), (yc.data(), gc.data()), "against the CPU");
    let (n3, y3, g3) = pass(&other);
    assert_eq!(n3, 2 + 4, "a changed list must be uploaded");
    let (yc, gc) = cpu(&other);
    assert_eq!((y3.data(), g3.data()), (yc.data(), gc.data()), "the changed list against the CPU");
}

/// Timing on the GPU's clock: every launch between start and stop is timed once, labelled
/// with the op that made it (forward or backward), without changing any value.
#[test]
fn the_gpu_clock_times_every_launch_and_names_its_op() {
    let _serial = serial();
    let gpu = tensor::gpu::gpu().unwrap();
    assert!(gpu.stop_timing().is_err(), "stopping what was not started");
    let (a, b) = (randn(24, &[64, 48]), randn(25, &[48, 32]));
    let step = || {
        let tape = Tape::<f32>::on(Device::Gpu);
        let (x, w) = (tape.var(a.clone()), tape.var(b.clone()));
        let loss = x.matmul(w).unwrap().tanh().sum_all();
        let g = tape.backward(loss).unwrap();
        (loss.value().to_device(Device::Cpu).unwrap(), g.get(w).unwrap().to_device(Device::Cpu).unwrap())
    };
    let untimed = step();
    gpu.start_timing().expect("lavapipe and NVIDIA's Vulkan drivers have timestamp queries");
    assert!(gpu.timing());
    let launches = gpu.stats().launches;
    let timed = step();
    let launched = gpu.stats().launches - launches;
    let t = gpu.stop_timing().unwrap();
    assert!(!gpu.timing());
    assert_eq!(timed.0.data(), untimed.0.data(), "timing changed the loss");
    assert_eq!(timed.1.data(), untimed.1.data(), "timing changed a gradient");
    assert_eq!(t.launches as u64, launched, "every launch timed once");
    assert_eq!(t.rows.iter().map(|r| r.launches).sum::<usize>(), t.launches);
    for label in ["matmul", "tanh", "matmul (backward)", "tanh (backward)"] {
        assert!(t.rows.iter().any(|r| r.label == label), "no row of {label:?}:\n{t}");
    }
    assert!(t.rows.iter().all(|r| r.label != "leaf"), "launches credited to a leaf:\n{t}");
    assert!(t.busy_s > 0.0 && t.span_s > 0.0, "{t}");
    assert!(t.rows.iter().all(|r| r.seconds >= 0.0));
    // Launches outside a tape, then a new tape's leaves: they keep no op's name.
    gpu.start_timing().unwrap();
    let x = a.to_device(Device::Gpu).unwrap();
    let _ = x.map_unary(tensor::UnaryOp::Neg);
    let _ = step();
    let t = gpu.stop_timing().unwrap();
    let outside = t.rows.iter().find(|r| r.label == "-").unwrap_or_else(|| panic!("no '-' row:\n{t}"));
    assert_eq!((outside.kernel, outside.launches), ("unary_forward", 1), "{t}");
    // Timing off: nothing more is recorded, and a new start begins empty.
    step();
    gpu.start_timing().unwrap();
    assert_eq!(gpu.stop_timing().unwrap().launches, 0);
}

#[test]
fn optimiser_kernels_match_the_host_formulas() {
    let _serial = serial();
    let x = randn(24, &[300]);
    let xg = x.to_device(Device::Gpu).unwrap();
    let clamped = xg.map_unary(tensor::UnaryOp::Clamp(-0.1, 0.1));
    assert_eq!(clamped.device(), Device::Gpu);
    assert_eq!(clamped.to_host().unwrap().to_vec(), x.map_unary(tensor::UnaryOp::Clamp(-0.1, 0.1)).to_vec());
    let (sq_cpu, sq_gpu) = (x.sum_of_squares().unwrap(), xg.sum_of_squares().unwrap());
    assert!((sq_cpu - sq_gpu).abs() <= 1e-5 * sq_cpu, "{sq_cpu} vs {sq_gpu}");
    // Non-finite values are found on the device, by index.
    let mut bad = x.clone();
    bad.data_mut()[7] = f32::NAN;
    let ts = [xg.clone(), bad.to_device(Device::Gpu).unwrap()];
    assert_eq!(tensor::first_non_finite(&ts).unwrap(), Some(1));
    assert_eq!(tensor::first_non_finite(&ts[..1]).unwrap(), None);
    assert!(!ts[1].all_finite() && ts[0].all_finite());
    let mut inf = x.clone();
    inf.data_mut()[0] = f32::NEG_INFINITY;
    assert!(!inf.to_device(Device::Gpu).unwrap().all_finite());
    // A list like a model's gradients: an empty tensor, finite ones, and two with non-finite
    // values past the first workgroup (the last element of 70,000; an infinity deep inside
    // another): the first of them is reported, after one launch per non-empty tensor.
    let mut long_nan = randn(25, &[70_000]);
    long_nan.data_mut()[69_999] = f32::NAN;
    let mut deep_inf = randn(26, &[300, 10]);
    deep_inf.data_mut()[2_345] = f32::INFINITY;
    let list: Vec<Tensor<f32>> = [Tensor::<f32>::zeros(&[0]), randn(27, &[5000]), long_nan, x.clone(), deep_inf]
        .iter()
        .map(|t| t.to_device(Device::Gpu).unwrap())
        .collect();
    let gpu = tensor::gpu::gpu().unwrap();
    gpu.start_timing().unwrap();
    assert_eq!(tensor::first_non_finite(&list).unwrap(), Some(2));
    assert_eq!(gpu.stop_timing().unwrap().launches, 4, "one launch per non-empty tensor");
    assert_eq!(tensor::first_non_finite(&list[3..]).unwrap(), Some(1));
    assert_eq!(tensor::first_non_finite(&list[..2]).unwrap(), None);
    // Adam: two steps against the formula in f64.
    let (b1, b2, eps, lr) = (0.9f64, 0.999f64, 1e-8f64, 3e-3f64);
    let (mut p, mut m, mut v) = (x.clone(), vec![0.0f64; 300], vec![0.0f64; 300]);
    let mut pd = xg.clone();
    let (mut md, mut vd) = (
        Tensor::<f32>::zeros(&[300]).to_device(Device::Gpu).unwrap(),
        Tensor::<f32>::zeros(&[300]).to_device(Device::Gpu).unwrap(),
    );
    for t in 1..=2 {
        let g = randn(30 + t, &[300]);
        let (c1, c2) = (1.0 / (1.0 - b1.powi(t as i32)), 1.0 / (1.0 - b2.powi(t as i32)));
        let step = tensor::gpu::AdamStep { lr, beta1: b1, beta2: b2, c1, c2, eps, clip: None };
        (pd, md, vd) = tensor::adam_update(&pd, &g.to_device(Device::Gpu).unwrap(), &md, &vd, step).unwrap();
        let pv = p.data_mut();
        for i in 0..300 {
            let gi = g.data()[i] as f64;
            m[i] = b1 * m[i] + (1.0 - b1) * gi;
            v[i] = b2 * v[i] + (1.0 - b2) * gi * gi;
            pv[i] = (pv[i] as f64 - lr * (m[i] * c1) / ((v[i] * c2).sqrt() + eps)) as f32;
        }
    }
    close("adam parameters", &pd.to_device(Device::Cpu).unwrap(), &p, Tol(1e-6, 1e-6));
    // The CPU backend's f32-moment step (the same kernel formula) against the same formula.
    let (mut pc, mut mc, mut vc) = (x.clone(), Tensor::<f32>::zeros(&[300]), Tensor::<f32>::zeros(&[300]));
    for t in 1..=2 {
        let (c1, c2) = (1.0 / (1.0 - b1.powi(t as i32)), 1.0 / (1.0 - b2.powi(t as i32)));
        let step = tensor::AdamStep { lr, beta1: b1, beta2: b2, c1, c2, eps, clip: None };
        (pc, mc, vc) = tensor::adam_update(&pc, &randn(30 + t, &[300]), &mc, &vc, step).unwrap();
        assert_eq!(pc.device(), Device::Cpu);
    }
    close("adam parameters on the CPU backend", &pc, &p, Tol(1e-6, 1e-6));
    // With the clip inside the kernel: the same bits as clamping first (the `clamp` op),
    // then the plain step; and a clip that bites (values up to 1, limit 0.1) changes them.
    let g = randn(40, &[300]).to_device(Device::Gpu).unwrap();
    let step =
        tensor::gpu::AdamStep { lr, beta1: b1, beta2: b2, c1: 1.0 / (1.0 - b1), c2: 1.0 / (1.0 - b2), eps, clip: None };
    let clamped = g.map_unary(tensor::UnaryOp::Clamp(-0.1, 0.1));
    let plain = tensor::adam_update(&pd, &clamped, &md, &vd, step).unwrap();
    let gpu = tensor::gpu::gpu().unwrap();
    gpu.start_timing().unwrap();
    let fused = tensor::adam_update(&pd, &g, &md, &vd, tensor::gpu::AdamStep { clip: Some(0.1), ..step }).unwrap();
    assert_eq!(gpu.stop_timing().unwrap().launches, 1, "the clip inside the Adam launch");
    let unclipped = tensor::adam_update(&pd, &g, &md, &vd, step).unwrap();
    for (what, a, b) in
        [("parameter", &plain.0, &fused.0), ("first moment", &plain.1, &fused.1), ("second moment", &plain.2, &fused.2)]
    {
        assert_eq!(a.to_host().unwrap().to_vec(), b.to_host().unwrap().to_vec(), "adam with the clip inside: {what}");
    }
    assert_ne!(
        unclipped.1.to_host().unwrap().to_vec(),
        fused.1.to_host().unwrap().to_vec(),
        "the clip changes the first moment"
    );
}

/// Nothing moves behind the caller's back: host-only reads of a tensor on the GPU refuse
/// and name the explicit transfer, which counts one download with its bytes.
#[test]
fn host_reads_of_a_gpu_tensor_name_the_explicit_transfer() {
    let _serial = serial();
    let x = randn(25, &[64]).to_device(Device::Gpu).unwrap();
    assert!(x.host_data().is_none());
    let err = x.item().unwrap_err().to_string();
    assert!(err.contains("to_host"), "{err}");
    let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| x.data().len())).unwrap_err();
    let msg = panicked.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(msg.contains("to_host()") && msg.contains("gpu"), "{msg}");
    let before = tensor::transfers();
    let host = x.to_host().unwrap();
    let moved = tensor::transfers().since(&before);
    assert_eq!((moved.downloads, moved.download_bytes, moved.uploads), (1, 64 * 4, 0), "{moved}");
    assert_eq!(host.data().len(), 64);
    // A list comes back in one transfer and no launch, each tensor's values in place.
    let ys: Vec<Tensor<f32>> = (0..3).map(|k| randn(26 + k, &[5 + k as usize, 3])).collect();
    let mut mixed: Vec<Tensor<f32>> = ys.iter().map(|y| y.to_device(Device::Gpu).unwrap()).collect();
    mixed.push(ys[0].clone());
    let before = tensor::transfers();
    let back = tensor::to_device_all(&mixed, Device::Cpu).unwrap();
    let moved = tensor::transfers().since(&before);
    assert_eq!((moved.downloads, moved.launches), (1, 0), "{moved}");
    assert_eq!(moved.download_bytes, (15 + 18 + 21) * 4);
    for (b, y) in back.iter().zip(ys.iter().chain([&ys[0]])) {
        assert_eq!((b.device(), b.shape(), b.data()), (Device::Cpu, y.shape(), y.data()));
    }
}

/// The Gaussian radial basis of host values (the critic's edge features) computed on the
/// GPU from the values uploaded matches the CPU's f64 evaluation, lands on the GPU, costs two
/// uploads (the values and the centres) and gives the same bits twice.
#[test]
fn a_gaussian_basis_is_computed_on_the_gpu_from_its_values() {
    let _serial = serial();
    let x: Vec<f64> = (0..37).map(|i| 0.55 * i as f64).collect();
    let centres: Vec<f64> = (0..62).map(|k| 20.0 * k as f64 / 61.0).collect();
    let coeff = -0.5 / (20.0f64 / 61.0).powi(2);
    let want = Tape::<f32>::new().gaussian_basis(&x, &centres, coeff).unwrap().value();
    let tape = Tape::<f32>::on(Device::Gpu);
    let before = tensor::gpu::gpu().unwrap().stats().uploads;
    let got = tape.gaussian_basis(&x, &centres, coeff).unwrap().value();
    assert_eq!(tensor::gpu::gpu().unwrap().stats().uploads - before, 2);
    assert_eq!(got.device(), Device::Gpu);
    let got = got.to_host().unwrap();
    // f32 arithmetic against the f64 evaluation rounded once: exp's relative error grows
    // with |exponent| (up to about 125 here), so the bound is relative.
    close("gaussian_basis", &got, &want, Tol(2e-4, 1e-6));
    let again = tape.gaussian_basis(&x, &centres, coeff).unwrap().value().to_host().unwrap();
    assert_eq!(again.data(), got.data(), "two GPU evaluations differ");
}
