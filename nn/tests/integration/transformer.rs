//! Transformer layers: finite-difference gradient checks (f64) of LayerNorm, multi-head
//! attention (with and without a key padding mask) and the encoder; forward values against
//! a plain-loop reference of PyTorch's formulas; padding, permutation and configuration.

use nn::{
    Bound, LayerNorm, MultiHeadAttention, NnError, ParamStore, TransformerConfig, TransformerEncoder,
    TransformerEncoderLayer,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tensor::gradcheck::check_gradients;
use tensor::{Float, Tape, Tensor, TensorError, Var};

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Uniform values in [-1, 1].
fn uniform(r: &mut ChaCha8Rng, shape: &[usize]) -> Tensor<f64> {
    let n = shape.iter().product();
    Tensor::new((0..n).map(|_| r.random_range(-1.0..1.0)).collect(), shape).unwrap()
}

/// Replaces every parameter by generic values (ones/zeros of LayerNorm and zero biases
/// would hide mistakes in their gradients).
fn randomise(store: &mut ParamStore<f64>, r: &mut ChaCha8Rng) {
    for i in 0..store.len() {
        let id = nn::ParamId(i);
        let shape = store.get(id).shape().to_vec();
        let name = store.name(id).to_string();
        let mut v = uniform(r, &shape);
        if name.contains("norm") && name.ends_with("weight") {
            v.data_mut().iter_mut().for_each(|x| *x = 1.0 + 0.5 * *x);
        }
        store.set(id, v).unwrap();
    }
}

fn to_tensor_err(e: NnError) -> TensorError {
    match e {
        NnError::Tensor(e) => e,
        other => panic!("layer error in a gradient check: {other}"),
    }
}

/// Finite-difference check of `f` with respect to every parameter of `store` and every
/// tensor of `inputs`: the parameters enter the check as its first inputs and reach the
/// layer through `Bound::from_vars`.
fn check_layer<F>(store: &ParamStore<f64>, inputs: Vec<Tensor<f64>>, f: F)
where
    F: for<'t> Fn(&Bound<'t, f64>, &[Var<'t, f64>]) -> nn::Result<Var<'t, f64>>,
{
    let np = store.len();
    let mut all = store.values().to_vec();
    all.extend(inputs);
    let report = check_gradients(
        |_: &Tape<f64>, v| {
            let p = Bound::from_vars(v[..np].to_vec());
            f(&p, &v[np..]).map_err(to_tensor_err)
        },
        &all,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(report.checked, all.iter().map(|t| t.numel()).sum::<usize>());
}

/// Runs `f` on a fresh tape with `store` bound and `x` as a constant; returns the value.
fn eval<T: Float, F>(store: &ParamStore<T>, x: &Tensor<T>, f: F) -> Tensor<T>
where
    F: for<'t> Fn(&Bound<'t, T>, Var<'t, T>) -> nn::Result<Var<'t, T>>,
{
    let tape = Tape::new();
    let p = store.bind(&tape);
    f(&p, tape.constant(x.clone())).unwrap().value()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// `[B, N, D]` data with the tokens of batch element `b` taken in the order `order[b]`.
fn select_tokens(x: &Tensor<f64>, order: &[Vec<usize>]) -> Tensor<f64> {
    let d = x.shape()[2];
    let n = x.shape()[1];
    let m = order[0].len();
    let mut out = Vec::new();
    for (b, o) in order.iter().enumerate() {
        assert_eq!(o.len(), m);
        for &j in o {
            out.extend_from_slice(&x.data()[(b * n + j) * d..(b * n + j + 1) * d]);
        }
    }
    Tensor::new(out, &[order.len(), m, d]).unwrap()
}

// ---------------------------------------------------------------------------------------
// Plain-loop reference of PyTorch's formulas, reading parameters by name.
// ---------------------------------------------------------------------------------------

struct Ref<'a>(&'a ParamStore<f64>);

impl Ref<'_> {
    fn p(&self, name: &str) -> &[f64] {
        self.0.get(self.0.find(name).unwrap_or_else(|| panic!("no parameter {name}"))).data()
    }

    /// Rows of `x` (width `fin`) times `{prefix}.weight [fin, fout]` plus `{prefix}.bias`.
    fn linear(&self, prefix: &str, x: &[f64], fin: usize) -> Vec<f64> {
        let w = self.p(&format!("{prefix}.weight"));
        let b = self.p(&format!("{prefix}.bias"));
        let fout = b.len();
        assert_eq!(w.len(), fin * fout);
        let mut y = Vec::new();
        for row in x.chunks(fin) {
            for o in 0..fout {
                y.push(b[o] + (0..fin).map(|i| row[i] * w[i * fout + o]).sum::<f64>());
            }
        }
        y
    }

    fn layer_norm(&self, prefix: &str, x: &[f64], d: usize, eps: f64) -> Vec<f64> {
        let g = self.p(&format!("{prefix}.weight"));
        let b = self.p(&format!("{prefix}.bias"));
        let mut y = Vec::new();
        for row in x.chunks(d) {
            let mean = row.iter().sum::<f64>() / d as f64;
            let var = row.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d as f64;
            for i in 0..d {
                y.push((row[i] - mean) / (var + eps).sqrt() * g[i] + b[i]);
            }
        }
        y
    }

    /// Self-attention of `x: [B, N, D]`; padded keys are skipped, a fully padded row
    /// attends uniformly to every key.
    fn attention(
        &self,
        prefix: &str,
        x: &[f64],
        bn: (usize, usize),
        d: usize,
        heads: usize,
        mask: Option<&[bool]>,
    ) -> Vec<f64> {
        let (bsz, n) = bn;
        let q = self.linear(&format!("{prefix}.q"), x, d);
        let k = self.linear(&format!("{prefix}.k"), x, d);
        let v = self.linear(&format!("{prefix}.v"), x, d);
        let dh = d / heads;
        let mut ctx = vec![0.0; bsz * n * d];
        for b in 0..bsz {
            let padded = |j: usize| mask.is_some_and(|m| m[b * n + j]);
            let all_padded = (0..n).all(padded);
            for h in 0..heads {
                for i in 0..n {
                    let qi = &q[(b * n + i) * d + h * dh..][..dh];
                    let keys: Vec<usize> = (0..n).filter(|&j| all_padded || !padded(j)).collect();
                    let s: Vec<f64> = keys
                        .iter()
                        .map(|&j| {
                            let kj = &k[(b * n + j) * d + h * dh..][..dh];
                            qi.iter().zip(kj).map(|(a, c)| a * c).sum::<f64>() / (dh as f64).sqrt()
                        })
                        .collect();
                    let mx = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    let e: Vec<f64> = s.iter().map(|v| (v - mx).exp()).collect();
                    let z: f64 = e.iter().sum();
                    for (&j, w) in keys.iter().zip(&e) {
                        for c in 0..dh {
                            ctx[(b * n + i) * d + h * dh + c] += w / z * v[(b * n + j) * d + h * dh + c];
                        }
                    }
                }
            }
        }
        self.linear(&format!("{prefix}.out"), &ctx, d)
    }

    fn encoder_layer(
        &self,
        prefix: &str,
        x: &[f64],
        bn: (usize, usize),
        cfg: &TransformerConfig,
        mask: Option<&[bool]>,
    ) -> Vec<f64> {
        let d = cfg.model_dim;
        let a = self.attention(&format!("{prefix}.self_attn"), x, bn, d, cfg.heads, mask);
        let x1: Vec<f64> = x.iter().zip(&a).map(|(u, v)| u + v).collect();
        let x1 = self.layer_norm(&format!("{prefix}.norm1"), &x1, d, cfg.layer_norm_eps);
        let h: Vec<f64> = self.linear(&format!("{prefix}.linear1"), &x1, d).into_iter().map(|v| v.max(0.0)).collect();
        let f = self.linear(&format!("{prefix}.linear2"), &h, cfg.ff_dim);
        let x2: Vec<f64> = x1.iter().zip(&f).map(|(u, v)| u + v).collect();
        self.layer_norm(&format!("{prefix}.norm2"), &x2, d, cfg.layer_norm_eps)
    }
}

fn tiny_config(num_layers: usize) -> TransformerConfig {
    TransformerConfig { model_dim: 4, ff_dim: 6, num_layers, heads: 2, ..TransformerConfig::default() }
}

/// Batch element 0: token 1 padded; batch element 1: tokens 0 and 3 padded (N = 4).
const MASK_2X4: [bool; 8] = [false, true, false, false, true, false, false, true];

// ---------------------------------------------------------------------------------------
// LayerNorm
// ---------------------------------------------------------------------------------------

#[test]
fn layer_norm_gradients_match_finite_differences() {
    let mut r = rng(10);
    let mut store = ParamStore::<f64>::new();
    let ln = LayerNorm::new(&mut store.scope("ln", &mut nn::init_rng(0)), 5).unwrap();
    assert_eq!(store.names(), ["ln.weight", "ln.bias"]);
    randomise(&mut store, &mut r);
    check_layer(&store, vec![uniform(&mut r, &[2, 3, 5])], |p, v| ln.forward(p, v[0]));
}

#[test]
fn layer_norm_rows_have_zero_mean_and_unit_variance() {
    let mut r = rng(11);
    let mut store = ParamStore::<f64>::new();
    let ln = LayerNorm::new(&mut store.scope("ln", &mut nn::init_rng(0)), 6).unwrap();
    // Rows with different offsets and scales, one of them constant.
    let mut x = uniform(&mut r, &[4, 6]);
    for (i, v) in x.data_mut().iter_mut().enumerate() {
        let row = i / 6;
        *v = if row == 3 { 7.0 } else { 10.0 * row as f64 - 3.0 + (1.0 + 4.0 * row as f64) * *v };
    }
    let y = eval(&store, &x, |p, x| ln.forward(p, x));
    for (row_in, row) in x.data().chunks(6).zip(y.data().chunks(6)) {
        let mean = row.iter().sum::<f64>() / 6.0;
        let var = row.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 6.0;
        assert!(mean.abs() < 1e-12, "row mean {mean}");
        // Biased variance of the input, v; the output variance is v / (v + eps).
        let m_in = row_in.iter().sum::<f64>() / 6.0;
        let v_in = row_in.iter().map(|v| (v - m_in).powi(2)).sum::<f64>() / 6.0;
        let expected = v_in / (v_in + 1e-5);
        assert!((var - expected).abs() < 1e-12, "row variance {var}, expected {expected}");
        if v_in > 0.1 {
            assert!((var - 1.0).abs() < 1e-4);
        }
    }
    assert!(y.data()[18..].iter().all(|&v| v == 0.0), "a constant row normalises to the bias");

    // Generic weight and bias against the reference formula.
    randomise(&mut store, &mut r);
    let y = eval(&store, &x, |p, x| ln.forward(p, x));
    let expected = Ref(&store).layer_norm("ln", x.data(), 6, 1e-5);
    assert!(max_diff(y.data(), &expected) < 1e-12);
}

#[test]
fn layer_norm_rejects_bad_sizes() {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(0);
    assert!(matches!(LayerNorm::new(&mut store.scope("a", &mut init), 0), Err(NnError::Config(_))));
    assert!(matches!(LayerNorm::with_eps(&mut store.scope("b", &mut init), 3, 0.0), Err(NnError::Config(_))));
    let ln = LayerNorm::new(&mut store.scope("c", &mut init), 3).unwrap();
    let tape = Tape::new();
    let p = store.bind(&tape);
    let err = ln.forward(&p, tape.constant(Tensor::zeros(&[2, 4]))).unwrap_err().to_string();
    assert!(err.contains("dim 3") && err.contains("[2, 4]"), "{err}");
}

// ---------------------------------------------------------------------------------------
// Multi-head attention
// ---------------------------------------------------------------------------------------

fn tiny_attention(seed: u64) -> (ParamStore<f64>, MultiHeadAttention) {
    let mut store = ParamStore::<f64>::new();
    let mha = MultiHeadAttention::new(&mut store.scope("attn", &mut nn::init_rng(seed)), 4, 2).unwrap();
    randomise(&mut store, &mut rng(seed + 100));
    (store, mha)
}

#[test]
fn attention_names_and_sizes() {
    let (store, mha) = tiny_attention(0);
    let names: Vec<&str> = store.names().iter().map(|s| s.as_str()).collect();
    assert_eq!(
        names,
        [
            "attn.q.weight",
            "attn.q.bias",
            "attn.k.weight",
            "attn.k.bias",
            "attn.v.weight",
            "attn.v.bias",
            "attn.out.weight",
            "attn.out.bias"
        ]
    );
    assert_eq!(store.num_elements(), 4 * (4 * 4 + 4));
    assert_eq!(mha.head_dim(), 2);
}

#[test]
fn attention_gradients_without_mask() {
    let (store, mha) = tiny_attention(1);
    let x = uniform(&mut rng(20), &[2, 3, 4]);
    check_layer(&store, vec![x], |p, v| mha.forward(p, v[0], None));
}

#[test]
fn attention_gradients_with_mask() {
    let (store, mha) = tiny_attention(2);
    let x = uniform(&mut rng(21), &[2, 4, 4]);
    check_layer(&store, vec![x], |p, v| mha.forward(p, v[0], Some(&MASK_2X4)));
    // A fully padded batch element (the second) next to a partly padded one.
    let x = uniform(&mut rng(22), &[2, 3, 4]);
    let mask = [false, false, true, true, true, true];
    check_layer(&store, vec![x], |p, v| mha.forward(p, v[0], Some(&mask)));
}

#[test]
fn attention_matches_reference() {
    let (store, mha) = tiny_attention(3);
    let x = uniform(&mut rng(23), &[2, 4, 4]);
    for mask in [None, Some(&MASK_2X4[..])] {
        let y = eval(&store, &x, |p, x| mha.forward(p, x, mask));
        let expected = Ref(&store).attention("attn", x.data(), (2, 4), 4, 2, mask);
        assert!(max_diff(y.data(), &expected) < 1e-12, "mask {mask:?}");
    }
    // Heads are not interchangeable with a single head of the same width.
    let expected_one_head = Ref(&store).attention("attn", x.data(), (2, 4), 4, 1, None);
    let y = eval(&store, &x, |p, x| mha.forward(p, x, None));
    assert!(max_diff(y.data(), &expected_one_head) > 1e-6);
}

#[test]
fn padded_keys_are_ignored() {
    let (store, mha) = tiny_attention(4);
    let mut x = uniform(&mut rng(24), &[2, 4, 4]);
    // Real tokens: batch 0 -> 0, 2, 3; batch 1 -> 1, 2.
    let y = eval(&store, &x, |p, x| mha.forward(p, x, Some(&MASK_2X4)));
    let real: [&[usize]; 2] = [&[0, 2, 3], &[1, 2]];
    let compare = |y: &Tensor<f64>, x: &Tensor<f64>| {
        for (b, toks) in real.iter().enumerate() {
            // The same sequence without its padded tokens, as a batch of one.
            let xb = Tensor::new(x.data()[b * 16..(b + 1) * 16].to_vec(), &[1, 4, 4]).unwrap();
            let xb = select_tokens(&xb, &[toks.to_vec()]);
            let yb = eval(&store, &xb, |p, x| mha.forward(p, x, None));
            for (i, &j) in toks.iter().enumerate() {
                let got = &y.data()[(b * 4 + j) * 4..][..4];
                let want = &yb.data()[i * 4..][..4];
                assert!(max_diff(got, want) < 1e-14, "batch {b} token {j}: {got:?} vs {want:?}");
            }
        }
    };
    compare(&y, &x);
    // Changing the padded tokens changes nothing at the real positions.
    for (i, v) in x.data_mut().iter_mut().enumerate() {
        let token = i / 4;
        if MASK_2X4[token] {
            *v = 100.0 + i as f64;
        }
    }
    let y2 = eval(&store, &x, |p, x| mha.forward(p, x, Some(&MASK_2X4)));
    compare(&y2, &x);
    for (t, padded) in MASK_2X4.iter().enumerate() {
        if !padded {
            assert_eq!(&y.data()[t * 4..][..4], &y2.data()[t * 4..][..4], "token {t}");
        }
    }
}

#[test]
fn permuting_tokens_permutes_outputs() {
    let (store, mha) = tiny_attention(5);
    let mut enc_store = ParamStore::<f64>::new();
    let enc = TransformerEncoder::new(&mut enc_store.scope("", &mut nn::init_rng(6)), tiny_config(2)).unwrap();
    randomise(&mut enc_store, &mut rng(60));
    let x = uniform(&mut rng(25), &[2, 4, 4]);
    let perm = [vec![2, 0, 3, 1], vec![3, 1, 0, 2]];
    let xp = select_tokens(&x, &perm);
    let mask_p: Vec<bool> =
        perm.iter().enumerate().flat_map(|(b, o)| o.iter().map(move |&j| MASK_2X4[b * 4 + j])).collect();
    for mask in [None, Some(&MASK_2X4[..])] {
        let mp = mask.map(|_| &mask_p[..]);
        let y = eval(&store, &x, |p, x| mha.forward(p, x, mask));
        let yp = eval(&store, &xp, |p, x| mha.forward(p, x, mp));
        assert!(max_diff(select_tokens(&y, &perm).data(), yp.data()) < 1e-12);
        let y = eval(&enc_store, &x, |p, x| enc.forward(p, x, mask));
        let yp = eval(&enc_store, &xp, |p, x| enc.forward(p, x, mp));
        assert!(max_diff(select_tokens(&y, &perm).data(), yp.data()) < 1e-12);
        // And the output is not trivially permutation invariant.
        assert!(max_diff(y.data(), yp.data()) > 1e-3);
    }
}

fn fully_padded_is_finite<T: Float>() {
    let cfg = tiny_config(2);
    let mut store = ParamStore::<T>::new();
    let enc = TransformerEncoder::new(&mut store.scope("enc", &mut nn::init_rng(7)), cfg).unwrap();
    let x: Tensor<T> = uniform(&mut rng(26), &[2, 3, 4]).cast();
    let mask = [true, true, true, false, true, false];
    let tape = Tape::new();
    let p = store.bind(&tape);
    let xv = tape.var(x);
    let y = enc.forward(&p, xv, Some(&mask)).unwrap();
    assert!(y.value().all_finite(), "{} outputs: {:?}", T::NAME, y.value().data());
    let g = tape.backward(y.square().sum_all()).unwrap();
    assert!(g.get_or_zeros(xv).all_finite());
    assert!(p.grads(&g).iter().all(|t| t.all_finite()));
    // The fully padded element attends uniformly: its attention output is the same at every
    // position, whatever the queries.
    let a = enc.layers[0].self_attn.forward(&p, xv, Some(&mask)).unwrap().value();
    let a: Vec<f64> = a.data().iter().map(|v| v.to_f64()).collect();
    for t in 1..3 {
        assert!(max_diff(&a[..4], &a[t * 4..][..4]) < 1e-5);
    }
}

#[test]
fn fully_padded_row_gives_finite_values() {
    fully_padded_is_finite::<f32>();
    fully_padded_is_finite::<f64>();
}

#[test]
fn attention_rejects_bad_sizes_and_inputs() {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(0);
    let err = MultiHeadAttention::new(&mut store.scope("a", &mut init), 10, 3).unwrap_err();
    assert!(matches!(err, NnError::Config(_)));
    let msg = err.to_string();
    assert!(msg.contains("dim 10") && msg.contains("heads 3"), "{msg}");
    assert!(MultiHeadAttention::new(&mut store.scope("b", &mut init), 4, 0).is_err());
    assert!(MultiHeadAttention::new(&mut store.scope("c", &mut init), 0, 2).is_err());
    assert!(store.is_empty(), "failed constructions add no parameter");

    let mha = MultiHeadAttention::new(&mut store.scope("d", &mut init), 4, 2).unwrap();
    let tape = Tape::new();
    let p = store.bind(&tape);
    let bad = tape.constant(Tensor::zeros(&[2, 3, 5]));
    assert!(mha.forward(&p, bad, None).unwrap_err().to_string().contains("[2, 3, 5]"));
    let x = tape.constant(Tensor::zeros(&[2, 3, 4]));
    let msg = mha.forward(&p, x, Some(&[false; 5])).unwrap_err().to_string();
    assert!(msg.contains("5 entries") && msg.contains('6'), "{msg}");
}

// ---------------------------------------------------------------------------------------
// Encoder
// ---------------------------------------------------------------------------------------

#[test]
fn encoder_layer_gradients_and_reference() {
    let cfg = tiny_config(1);
    let mut store = ParamStore::<f64>::new();
    let layer = TransformerEncoderLayer::new(&mut store.scope("layer", &mut nn::init_rng(8)), cfg).unwrap();
    randomise(&mut store, &mut rng(80));
    let x = uniform(&mut rng(27), &[2, 3, 4]);
    let mask = [false, true, false, false, false, true];
    check_layer(&store, vec![x.clone()], |p, v| layer.forward(p, v[0], None));
    check_layer(&store, vec![x.clone()], |p, v| layer.forward(p, v[0], Some(&mask)));
    for m in [None, Some(&mask[..])] {
        let y = eval(&store, &x, |p, x| layer.forward(p, x, m));
        let expected = Ref(&store).encoder_layer("layer", x.data(), (2, 3), &cfg, m);
        assert!(max_diff(y.data(), &expected) < 1e-12);
    }
}

#[test]
fn encoder_gradients_and_reference() {
    let cfg = tiny_config(2);
    let mut store = ParamStore::<f64>::new();
    let enc = TransformerEncoder::new(&mut store.scope("enc", &mut nn::init_rng(9)), cfg).unwrap();
    randomise(&mut store, &mut rng(90));
    let x = uniform(&mut rng(28), &[2, 3, 4]);
    let mask = [false, false, true, true, false, false];
    check_layer(&store, vec![x.clone()], |p, v| enc.forward(p, v[0], Some(&mask)));
    let y = eval(&store, &x, |p, x| enc.forward(p, x, Some(&mask)));
    let r = Ref(&store);
    let h = r.encoder_layer("enc.layers.0", x.data(), (2, 3), &cfg, Some(&mask));
    let expected = r.encoder_layer("enc.layers.1", &h, (2, 3), &cfg, Some(&mask));
    assert!(max_diff(y.data(), &expected) < 1e-12);
}

#[test]
fn default_config_is_the_papers_transformer() {
    let cfg = TransformerConfig::default();
    assert_eq!((cfg.model_dim, cfg.ff_dim, cfg.num_layers, cfg.heads), (128, 256, 3, 2));
    assert_eq!(cfg.layer_norm_eps, 1e-5);
    let mut store = ParamStore::<f32>::new();
    let enc = TransformerEncoder::new(&mut store.scope("tf", &mut nn::init_rng(0)), cfg).unwrap();
    assert_eq!(enc.layers.len(), 3);
    // PyTorch's nn.TransformerEncoderLayer(128, 2, 256) has the same count per layer:
    // in_proj 3 (D^2 + D), out_proj D^2 + D, linear1 D F + F, linear2 F D + D, norms 4 D.
    let (d, f) = (128, 256);
    let per_layer = 4 * (d * d + d) + d * f + f + f * d + d + 4 * d;
    assert_eq!(store.num_elements(), 3 * per_layer);
    assert_eq!(store.num_elements_under("tf.layers.1."), per_layer);
    let layer2: Vec<&str> =
        store.names().iter().filter(|n| n.starts_with("tf.layers.2.")).map(|s| s.as_str()).collect();
    assert_eq!(
        layer2,
        [
            "tf.layers.2.self_attn.q.weight",
            "tf.layers.2.self_attn.q.bias",
            "tf.layers.2.self_attn.k.weight",
            "tf.layers.2.self_attn.k.bias",
            "tf.layers.2.self_attn.v.weight",
            "tf.layers.2.self_attn.v.bias",
            "tf.layers.2.self_attn.out.weight",
            "tf.layers.2.self_attn.out.bias",
            "tf.layers.2.linear1.weight",
            "tf.layers.2.linear1.bias",
            "tf.layers.2.linear2.weight",
            "tf.layers.2.linear2.bias",
            "tf.layers.2.norm1.weight",
            "tf.layers.2.norm1.bias",
            "tf.layers.2.norm2.weight",
            "tf.layers.2.norm2.bias",
        ]
    );
    // A forward pass at the paper's sizes in f32 keeps the shape.
    let x: Tensor<f32> = uniform(&mut rng(29), &[2, 5, 128]).cast();
    let y = eval(&store, &x, |p, x| enc.forward(p, x, None));
    assert_eq!(y.shape(), [2, 5, 128]);
    assert!(y.all_finite());
}

#[test]
fn invalid_configs_are_errors_naming_the_values() {
    let cases: [(TransformerConfig, &[&str]); 5] = [
        (TransformerConfig { model_dim: 10, heads: 3, ..Default::default() }, &["model_dim 10", "heads 3"]),
        (TransformerConfig { model_dim: 0, ..Default::default() }, &["model_dim 0"]),
        (TransformerConfig { ff_dim: 0, ..Default::default() }, &["ff_dim 0"]),
        (TransformerConfig { num_layers: 0, ..Default::default() }, &["num_layers 0"]),
        (TransformerConfig { heads: 0, ..Default::default() }, &["heads 0"]),
    ];
    for (cfg, words) in cases {
        let mut store = ParamStore::<f64>::new();
        let err = TransformerEncoder::new(&mut store.scope("enc", &mut nn::init_rng(0)), cfg).unwrap_err();
        assert!(matches!(err, NnError::Config(_)), "{cfg:?}: {err}");
        let msg = err.to_string();
        for w in words {
            assert!(msg.contains(w), "{cfg:?}: `{msg}` does not name `{w}`");
        }
        assert!(store.is_empty());
        let err = TransformerEncoderLayer::new(&mut store.scope("l", &mut nn::init_rng(0)), cfg).unwrap_err();
        assert!(matches!(err, NnError::Config(_)));
    }
    let cfg = TransformerConfig { layer_norm_eps: -1.0, ..Default::default() };
    assert!(cfg.validate().unwrap_err().to_string().contains("-1"));
    assert!(TransformerConfig::default().validate().is_ok());
}

#[test]
#[should_panic(expected = "gradient mismatch")]
fn gradient_check_catches_a_missing_gradient_path() {
    // The helper must reject a function whose analytic gradient misses a dependence: a
    // second attention pass on the detached input.
    let (store, mha) = tiny_attention(11);
    let x = uniform(&mut rng(30), &[1, 3, 4]);
    check_layer(&store, vec![x], |p, v| {
        let y = mha.forward(p, v[0], None)?;
        Ok(y.add(mha.forward(p, v[0].detach(), None)?)?)
    });
}

#[test]
fn empty_sets_of_tokens_keep_their_shape() {
    let mut store = ParamStore::<f64>::new();
    let enc = TransformerEncoder::new(&mut store.scope("enc", &mut nn::init_rng(12)), tiny_config(2)).unwrap();
    for shape in [[2, 0, 4], [0, 3, 4]] {
        let x = Tensor::zeros(&shape);
        for mask in [None, Some(vec![true; shape[0] * shape[1]])] {
            let y = eval(&store, &x, |p, x| enc.forward(p, x, mask.as_deref()));
            assert_eq!(y.shape(), shape);
        }
    }
}
