//! Seeded property tests over random shapes: kernels against naive reference loops, random
//! broadcast gradient checks, and bit-identical results whatever the thread count.

use crate::common;

use common::*;
use rand::RngExt;
use tensor::gradcheck::check_gradients;
use tensor::shape::{broadcast_shapes, numel, strides};
use tensor::{Activation, Tape, Tensor};

/// A random shape of rank 0..=max_rank with dims 1..=max_dim.
fn random_shape(r: &mut rand_chacha::ChaCha8Rng, max_rank: usize, max_dim: usize) -> Vec<usize> {
    let rank = r.random_range(0..=max_rank);
    (0..rank).map(|_| r.random_range(1..=max_dim)).collect()
}

/// A shape that broadcasts with `s`: drop some leading dims, set some dims to 1.
fn broadcastable(r: &mut rand_chacha::ChaCha8Rng, s: &[usize]) -> Vec<usize> {
    let drop = r.random_range(0..=s.len());
    s[drop..].iter().map(|&d| if r.random_bool(0.3) { 1 } else { d }).collect()
}

/// Reads `x` at a multi-index of the broadcast shape `out`.
fn at_broadcast(x: &Tensor<f64>, out: &[usize], idx: &[usize]) -> f64 {
    let off = out.len() - x.rank();
    let st = strides(x.shape());
    let p: usize = (0..x.rank()).map(|d| if x.shape()[d] == 1 { 0 } else { idx[d + off] * st[d] }).sum();
    x.data()[p]
}

fn unravel(mut i: usize, shape: &[usize]) -> Vec<usize> {
    let mut idx = vec![0; shape.len()];
    for d in (0..shape.len()).rev() {
        idx[d] = i % shape[d];
        i /= shape[d];
    }
    idx
}

#[test]
fn broadcast_binary_matches_naive() {
    let mut r = rng(100);
    for _ in 0..200 {
        let sa = random_shape(&mut r, 4, 4);
        let sb = if r.random_bool(0.5) { broadcastable(&mut r, &sa) } else { sa.clone() };
        let (sa, sb) = if r.random_bool(0.5) { (sa, sb) } else { (sb, sa) };
        let a = uniform(&mut r, &sa);
        let b = positive(&mut r, &sb);
        let out = broadcast_shapes("t", &sa, &sb).unwrap();
        let tape = Tape::new();
        let (va, vb) = (tape.constant(a.clone()), tape.constant(b.clone()));
        let got = va.mul(vb).unwrap().sub(vb).unwrap().div(vb).unwrap().value();
        assert_eq!(got.shape(), &out[..]);
        for i in 0..numel(&out) {
            let idx = unravel(i, &out);
            let (x, y) = (at_broadcast(&a, &out, &idx), at_broadcast(&b, &out, &idx));
            let want = (x * y - y) / y;
            assert!((got.data()[i] - want).abs() < 1e-12, "{sa:?} {sb:?}");
        }
    }
}

#[test]
fn broadcast_gradients_on_random_shapes() {
    let mut r = rng(101);
    for _ in 0..40 {
        let sa = random_shape(&mut r, 3, 3);
        let sb = broadcastable(&mut r, &sa);
        let a = uniform(&mut r, &sa);
        let b = positive(&mut r, &sb);
        check_gradients(|_, v| v[0].mul(v[1])?.add(v[1])?.div(v[1].add(v[0])?), &[a, b]).unwrap();
    }
}

fn naive_matmul(a: &Tensor<f64>, b: &Tensor<f64>, ta: bool, tb: bool) -> Vec<f64> {
    // 2-D only.
    let (ar, ac) = (a.shape()[0], a.shape()[1]);
    let (br, bc) = (b.shape()[0], b.shape()[1]);
    let (m, k) = if ta { (ac, ar) } else { (ar, ac) };
    let n = if tb { br } else { bc };
    let ga = |i: usize, p: usize| if ta { a.data()[p * ac + i] } else { a.data()[i * ac + p] };
    let gb = |p: usize, j: usize| if tb { b.data()[j * bc + p] } else { b.data()[p * bc + j] };
    let mut out = vec![0.0; m * n];
    for i in 0..m {
        for j in 0..n {
            out[i * n + j] = (0..k).map(|p| ga(i, p) * gb(p, j)).sum();
        }
    }
    out
}

#[test]
fn matmul_matches_naive_for_random_sizes_and_transposes() {
    let mut r = rng(102);
    for trial in 0..64 {
        // Mix tiny (direct loop) and larger (faer, and row-block parallel) sizes, and
        // short-wide products with a long inner dim (column-block parallel).
        let big = trial % 10 == 0;
        let hi = if big { 300 } else { 40 };
        let (m, k, n) = if trial % 16 == 3 {
            // Small result, long inner dim: the inner-dim split (forced ta, !tb below).
            (r.random_range(40..=150), r.random_range(4000..=6000), r.random_range(40..=150))
        } else if trial % 16 == 7 {
            // Tall, thin A^T B with a long inner dim (the transposed-problem path).
            (r.random_range(400..=600), r.random_range(2400..=3000), r.random_range(8..=100))
        } else if trial % 16 == 11 {
            // Short, wide A^T B with a long inner dim (the inner-dim split, forced ta, !tb).
            (r.random_range(30..=40), r.random_range(1000..=1200), r.random_range(200..=250))
        } else if trial % 16 == 15 {
            (r.random_range(1..=100), r.random_range(2000..=3000), r.random_range(256..=400))
        } else {
            (r.random_range(1..=hi), r.random_range(1..=hi), r.random_range(1..=hi))
        };
        let (ta, tb) =
            if [3, 7, 11].contains(&(trial % 16)) { (true, false) } else { (r.random_bool(0.5), r.random_bool(0.5)) };
        let a = uniform(&mut r, &if ta { [k, m] } else { [m, k] });
        let b = uniform(&mut r, &if tb { [n, k] } else { [k, n] });
        let tape = Tape::new();
        let got = tape.constant(a.clone()).matmul_t(tape.constant(b.clone()), ta, tb).unwrap().value();
        let want = naive_matmul(&a, &b, ta, tb);
        for (x, y) in got.data().iter().zip(&want) {
            assert!((x - y).abs() < 1e-10 * (k as f64), "m{m} k{k} n{n} ta{ta} tb{tb}");
        }
    }
}

#[test]
fn batched_matmul_matches_per_batch_products() {
    let mut r = rng(103);
    for _ in 0..30 {
        let (m, k, n) = (r.random_range(1..=6), r.random_range(1..=6), r.random_range(1..=6));
        let batch = random_shape(&mut r, 2, 3);
        let bb = broadcastable(&mut r, &batch);
        let mut sa = batch.clone();
        sa.extend([m, k]);
        let mut sb = bb.clone();
        sb.extend([k, n]);
        let a = uniform(&mut r, &sa);
        let b = uniform(&mut r, &sb);
        let tape = Tape::new();
        let got = tape.constant(a.clone()).matmul(tape.constant(b.clone())).unwrap().value();
        let out_batch = broadcast_shapes("t", &batch, &bb).unwrap();
        for bi in 0..numel(&out_batch) {
            let idx = unravel(bi, &out_batch);
            let pick = |x: &Tensor<f64>, bshape: &[usize], rows: usize, cols: usize| {
                let off = out_batch.len() - bshape.len();
                let st = strides(bshape);
                let p: usize = (0..bshape.len()).map(|d| if bshape[d] == 1 { 0 } else { idx[d + off] * st[d] }).sum();
                Tensor::new(x.data()[p * rows * cols..(p + 1) * rows * cols].to_vec(), &[rows, cols]).unwrap()
            };
            let want = naive_matmul(&pick(&a, &batch, m, k), &pick(&b, &bb, k, n), false, false);
            let got_b = &got.data()[bi * m * n..(bi + 1) * m * n];
            for (x, y) in got_b.iter().zip(&want) {
                assert!((x - y).abs() < 1e-12);
            }
        }
    }
}

/// Tiny batched products whose output rows are 16, 32 or 64 wide (the fixed-width loops with
/// register accumulators) or whose rows are dotted (the A B^T loops), in every transpose,
/// against naive loops, and their fused backward by finite differences.
#[test]
fn tiny_products_of_fixed_row_widths_match_naive_and_gradcheck() {
    let mut r = rng(108);
    for &n in &[16, 32, 64, 8, 24] {
        for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
            let (m, k, batch) = (r.random_range(1..=4), r.random_range(1..=5), 3);
            let a = uniform(&mut r, &if ta { [batch, k, m] } else { [batch, m, k] });
            let b = uniform(&mut r, &if tb { [batch, n, k] } else { [batch, k, n] });
            let tape = Tape::new();
            let got = tape.constant(a.clone()).matmul_t(tape.constant(b.clone()), ta, tb).unwrap().value();
            let (sa, sb) = (a.shape()[1..].to_vec(), b.shape()[1..].to_vec());
            for i in 0..batch {
                let pick = |x: &Tensor<f64>, s: &[usize]| {
                    let len = s[0] * s[1];
                    Tensor::new(x.data()[i * len..(i + 1) * len].to_vec(), s).unwrap()
                };
                let want = naive_matmul(&pick(&a, &sa), &pick(&b, &sb), ta, tb);
                for (x, y) in got.data()[i * m * n..(i + 1) * m * n].iter().zip(&want) {
                    assert!((x - y).abs() < 1e-12, "m{m} k{k} n{n} ta{ta} tb{tb}");
                }
            }
            // Both operands want gradients, and each also feeds a later op, so that the
            // product's backward adds into gradient slots that already hold values.
            check_gradients(
                |_, v| {
                    let y = v[0].matmul_t(v[1], ta, tb)?.square().sum_all();
                    y.add(v[0].square().sum_all())?.add(v[1].square().sum_all())
                },
                &[a, b],
            )
            .unwrap();
        }
        // A Gram matrix Z^T Z of n x n (one operand twice: both contributions go to one slot).
        let z = uniform(&mut r, &[3, 3, n]);
        check_gradients(|_, v| Ok(v[0].matmul_t(v[0], true, false)?.square().sum_all()), &[z]).unwrap();
    }
}

/// Values and input gradients of `loss = sum(w_out * (A C)) + sum(w_gram * (A^T A)) +
/// sum(w_outer * (A A^T))` computed in `T`, returned in f64: the three products, `dA`, `dC`.
fn tiny_products_in<T: tensor::Float>(inputs: &[Tensor<f64>; 5]) -> Vec<Vec<f64>> {
    let [a, c, w_out, w_gram, w_outer] = inputs;
    let tape = Tape::new();
    let (av, cv) = (tape.var(a.cast::<T>()), tape.var(c.cast::<T>()));
    let prod = av.matmul(cv).unwrap();
    let gram = av.matmul_t(av, true, false).unwrap();
    let outer = av.matmul_t(av, false, true).unwrap();
    let (wo, wg, wr) = (tape.constant(w_out.cast()), tape.constant(w_gram.cast()), tape.constant(w_outer.cast()));
    let terms = [prod.mul(wo).unwrap().sum_all(), gram.mul(wg).unwrap().sum_all(), outer.mul(wr).unwrap().sum_all()];
    let loss = terms[0].add(terms[1]).unwrap().add(terms[2]).unwrap();
    let g = tape.backward(loss).unwrap();
    let v = |t: &Tensor<T>| t.cast::<f64>().data().to_vec();
    vec![v(&prod.value()), v(&gram.value()), v(&outer.value()), v(g.get(av).unwrap()), v(g.get(cv).unwrap())]
}

/// The f32 tiny batched products (direct loops with eight partial sums) and their fused
/// gradients, against the same products in f64 on the same values: `M C`, `Z^T Z` (one
/// operand twice) and `Z Z^T`, with inner and outer sizes that are and are not multiples of
/// 8.
#[test]
fn f32_tiny_batched_products_and_gradients_match_f64() {
    let mut r = rng(107);
    for &(m, k, n) in &[(3, 32, 32), (3, 8, 9), (5, 16, 3), (1, 40, 17), (3, 7, 12), (2, 24, 8)] {
        let batch = 37;
        // Inputs rounded to f32 first, so the f64 reference differs only in its arithmetic.
        let round = |t: Tensor<f64>| -> Tensor<f64> { t.cast::<f32>().cast() };
        let inputs = [
            round(uniform(&mut r, &[batch, m, k])),
            round(uniform(&mut r, &[batch, k, n])),
            round(uniform(&mut r, &[batch, m, n])),
            round(uniform(&mut r, &[batch, k, k])),
            round(uniform(&mut r, &[batch, m, m])),
        ];
        let got = tiny_products_in::<f32>(&inputs);
        let want = tiny_products_in::<f64>(&inputs);
        // Each entry is a sum of at most 2k + 2m products of values below 1 in magnitude (the
        // gradient of A^T A and A A^T takes both operands' terms); f32 rounds each addition
        // by at most 6e-8 relative.
        let tol = 2e-7 * (2 * k + 2 * m) as f64;
        for (name, (g, w)) in ["A C", "A^T A", "A A^T", "dA", "dC"].iter().zip(got.iter().zip(&want)) {
            assert_eq!(g.len(), w.len());
            for (x, y) in g.iter().zip(w) {
                assert!((x - y).abs() <= tol, "{name} m{m} k{k} n{n}: {x} vs {y}");
            }
        }
    }
}

#[test]
fn reductions_and_permutes_match_naive() {
    let mut r = rng(104);
    for _ in 0..100 {
        let mut s = random_shape(&mut r, 4, 5);
        if s.is_empty() {
            s.push(3);
        }
        let x = uniform(&mut r, &s);
        let axis = r.random_range(0..s.len());
        let tape = Tape::new();
        let v = tape.constant(x.clone());
        let sum = v.sum(axis, true).unwrap().value();
        let max = v.max(axis, true).unwrap().value();
        for i in 0..x.numel() {
            let mut idx = unravel(i, &s);
            idx[axis] = 0;
            let st = strides(&s);
            let base: usize = idx.iter().zip(&st).map(|(a, b)| a * b).sum();
            let vals: Vec<f64> = (0..s[axis]).map(|k| x.data()[base + k * st[axis]]).collect();
            let mut rs = s.clone();
            rs[axis] = 1;
            let o: usize = idx.iter().zip(strides(&rs)).map(|(a, b)| a * b).sum();
            assert!((sum.data()[o] - vals.iter().sum::<f64>()).abs() < 1e-12);
            assert_eq!(max.data()[o], vals.iter().copied().fold(f64::MIN, f64::max));
        }
        // A random permutation moves element idx to the permuted index.
        let mut perm: Vec<usize> = (0..s.len()).collect();
        for i in (1..perm.len()).rev() {
            let j = r.random_range(0..=i);
            perm.swap(i, j);
        }
        let p = v.permute(&perm).unwrap().value();
        let ps: Vec<usize> = perm.iter().map(|&d| s[d]).collect();
        for i in 0..p.numel() {
            let pidx = unravel(i, &ps);
            let mut src = vec![0; s.len()];
            for (d, &pd) in perm.iter().enumerate() {
                src[pd] = pidx[d];
            }
            let o: usize = src.iter().zip(strides(&s)).map(|(a, b)| a * b).sum();
            assert_eq!(p.data()[i], x.data()[o]);
        }
    }
}

/// Every permutation of the axes of a shape (Heap's algorithm).
fn permutations(n: usize) -> Vec<Vec<usize>> {
    fn heap(k: usize, p: &mut Vec<usize>, out: &mut Vec<Vec<usize>>) {
        if k <= 1 {
            out.push(p.clone());
            return;
        }
        for i in 0..k {
            heap(k - 1, p, out);
            let j = if k.is_multiple_of(2) { i } else { 0 };
            p.swap(j, k - 1);
        }
    }
    let mut out = Vec::new();
    heap(n, &mut (0..n).collect(), &mut out);
    out
}

#[test]
fn large_permutes_and_expands_match_naive() {
    // Large enough for the parallel copy in blocks of the first axis: blocks of many first-axis
    // indices with a shorter last block ([1000, 37]), one index a block ([2, 3, 8000]), and
    // every permutation of a rank-4 shape. The buffers come from the pool with whatever an
    // earlier op left in them, so a missed element would show.
    let mut r = rng(107);
    for s in [vec![7, 50, 3, 40], vec![1000, 37], vec![2, 3, 8000]] {
        let x = uniform(&mut r, &s);
        for perm in permutations(s.len()) {
            let tape = Tape::new();
            let p = tape.constant(x.clone()).permute(&perm).unwrap().value();
            let ps: Vec<usize> = perm.iter().map(|&d| s[d]).collect();
            assert_eq!(p.shape(), &ps[..]);
            for i in 0..p.numel() {
                let pidx = unravel(i, &ps);
                let mut src = vec![0; s.len()];
                for (d, &pd) in perm.iter().enumerate() {
                    src[pd] = pidx[d];
                }
                let o: usize = src.iter().zip(strides(&s)).map(|(a, b)| a * b).sum();
                assert_eq!(p.data()[i], x.data()[o], "{s:?} {perm:?} at {pidx:?}");
            }
        }
    }
    for (from, to) in [(vec![1, 37], vec![1000, 37]), (vec![1000, 1], vec![1000, 40]), (vec![5, 1, 9], vec![5, 800, 9])]
    {
        let x = uniform(&mut r, &from);
        let tape = Tape::new();
        let e = tape.constant(x.clone()).expand(&to).unwrap().value();
        assert_eq!(e.shape(), &to[..]);
        for i in 0..e.numel() {
            assert_eq!(e.data()[i], at_broadcast(&x, &to, &unravel(i, &to)), "{from:?} -> {to:?}");
        }
    }
}

#[test]
fn kernels_write_every_element_of_a_recycled_buffer() {
    // Kernels take their outputs from the pool without zeroing them (`pool::for_overwrite`),
    // so each must write every element. With the pool full of NaN buffers of the sizes used,
    // an element left unwritten would come out NaN.
    let (rows, cols) = (7000, 10);
    let n = rows * cols;
    for _ in 0..60 {
        tensor::pool::recycle(vec![f64::NAN; n]);
        tensor::pool::recycle(vec![f64::NAN; 2 * n]);
    }
    let mut r = rng(108);
    let tape = Tape::new();
    let x = tape.var(uniform(&mut r, &[rows, cols]));
    let bias = tape.var(uniform(&mut r, &[cols]));
    let per_row = tape.var(positive(&mut r, &[rows, 1]));
    let den = tape.var(positive(&mut r, &[rows, cols]));
    // Unary, bias row, one value per row, equal shapes, and their gradients.
    let a = x.tanh().add(bias).unwrap().mul(per_row).unwrap().div(den).unwrap();
    let rows_out = a.softmax().standardize(1e-5);
    let norms = a.norm_last(1e-8).mean_all().unwrap();
    let moved = rows_out.permute(&[1, 0]).unwrap();
    let wide = a.reshape(&[rows, 1, cols]).unwrap().expand(&[rows, 2, cols]).unwrap();
    let idx: Vec<usize> = (0..n).map(|i| (i * 7 + 3) % cols).collect();
    let gathered = a.gather(1, &[rows, cols], &idx).unwrap();
    let mask: Vec<bool> = (0..n).map(|i| i % 3 == 0).collect();
    let picked = tape.where_select(&mask, a, x).unwrap();
    let seg: Vec<usize> = (0..rows).map(|i| i / 7).collect();
    let segments = x.segment_mean(&seg, rows / 7).unwrap();
    let means = a.mean(1, true).unwrap();
    let parts = [moved, wide, gathered, picked, segments, means];
    let mut loss = norms;
    for p in parts {
        loss = loss.add(p.square().mean_all().unwrap()).unwrap();
    }
    let g = tape.backward(loss).unwrap();
    for (name, v) in
        [("moved", moved), ("wide", wide), ("gathered", gathered), ("picked", picked), ("rows_out", rows_out)]
    {
        assert!(v.value().data().iter().all(|v| v.is_finite()), "{name} has an unwritten element");
    }
    for (name, v) in [("x", x), ("bias", bias), ("per_row", per_row), ("den", den)] {
        assert!(
            g.get(v).unwrap().data().iter().all(|v| v.is_finite()),
            "the gradient of {name} has an unwritten element"
        );
    }
}

#[test]
fn large_layer_with_bias_and_activation_and_its_bias_gradient_match_naive() {
    // Large enough for the product split into row blocks (bias and activation per block) and
    // for the bias gradient's sum split into runs of rows.
    let mut r = rng(106);
    let (m, k, n) = (700, 90, 130);
    let (x, w, b) = (uniform(&mut r, &[m, k]), uniform(&mut r, &[k, n]), uniform(&mut r, &[n]));
    let up = uniform(&mut r, &[m, n]);
    let tape = Tape::new();
    let (xv, wv, bv) = (tape.constant(x.clone()), tape.constant(w.clone()), tape.var(b.clone()));
    let y = xv.linear(wv, Some(bv), Activation::Relu).unwrap();
    let loss = y.mul(tape.constant(up.clone())).unwrap().sum_all();
    let g = tape.backward(loss).unwrap();
    let prod = naive_matmul(&x, &w, false, false);
    let mut db = vec![0.0; n];
    for i in 0..m {
        for j in 0..n {
            let pre = prod[i * n + j] + b.data()[j];
            assert!((y.value().data()[i * n + j] - pre.max(0.0)).abs() < 1e-12);
            if pre > 0.0 {
                db[j] += up.data()[i * n + j];
            }
        }
    }
    let got = g.get(bv).unwrap();
    db.iter().zip(got.data()).for_each(|(want, got)| assert!((want - got).abs() < 1e-10, "{want} {got}"));
}

/// Runs a workload with large f32 products and reductions (parallel paths) and returns the
/// bits of the result and of the gradient.
fn workload() -> (Vec<u32>, Vec<u32>) {
    let mut r = rng(105);
    let x: Tensor<f32> = uniform(&mut r, &[600, 256]).cast();
    let w: Tensor<f32> = uniform(&mut r, &[256, 300]).cast();
    let bw: Tensor<f32> = uniform(&mut r, &[64, 32, 32]).cast();
    let bz: Tensor<f32> = uniform(&mut r, &[64, 3, 32]).cast();
    let wide: Tensor<f32> = uniform(&mut r, &[600, 300]).cast();
    let (pp, qq): (Tensor<f32>, Tensor<f32>) =
        (uniform(&mut r, &[4096, 64]).cast(), uniform(&mut r, &[4096, 48]).cast());
    let ss: Tensor<f32> = uniform(&mut r, &[4096, 600]).cast();
    let tape = Tape::new();
    let (xv, wv) = (tape.var(x), tape.var(w));
    let (bwv, bzv) = (tape.var(bw), tape.var(bz));
    let h = xv.matmul(wv).unwrap().tanh();
    let z = bzv.matmul(bwv).unwrap();
    // x[:, :100]^T wide: a 100 x 300 product with inner dim 600 (the column-block path).
    let xw = xv.narrow(1, 0, 100).unwrap().matmul_t(tape.constant(wide), true, false).unwrap();
    // p^T q: a 64 x 48 result with inner dim 4096 (the inner-dim split).
    let pv = tape.var(pp);
    let pq = pv.matmul_t(tape.constant(qq), true, false).unwrap();
    // p^T s: a short, wide 64 x 600 result with inner dim 4096 (the inner-dim split too).
    let ps = pv.matmul_t(tape.constant(ss), true, false).unwrap();
    // A layer with bias and activation applied per block of rows, and its bias gradient (a
    // sum over 600 rows, split into runs).
    let bias = tape.var(uniform(&mut r, &[300]).cast());
    let lin = xv.linear(wv, Some(bias), Activation::Relu).unwrap();
    let loss = h.sum_all().add(z.square().mean_all().unwrap()).unwrap().add(xw.square().mean_all().unwrap()).unwrap();
    let loss = loss.add(pq.square().mean_all().unwrap()).unwrap().add(lin.square().mean_all().unwrap()).unwrap();
    let loss = loss.add(ps.square().mean_all().unwrap()).unwrap();
    let g = tape.backward(loss).unwrap();
    let bits = |t: &Tensor<f32>| t.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let mut grads = bits(g.get(wv).unwrap());
    grads.extend(bits(g.get(xv).unwrap()));
    grads.extend(bits(g.get(pv).unwrap()));
    grads.extend(bits(&pq.value()));
    grads.extend(bits(&ps.value()));
    grads.extend(bits(g.get(bwv).unwrap()));
    grads.extend(bits(g.get(bzv).unwrap()));
    grads.extend(bits(g.get(bias).unwrap()));
    (bits(&loss.value()), grads)
}

#[test]
fn results_are_bit_identical_across_thread_counts() {
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(workload);
    let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(workload);
    let four = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(workload);
    assert_eq!(one, two);
    assert_eq!(one, four);
}
