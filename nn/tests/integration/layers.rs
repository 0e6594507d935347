//! Finite-difference gradient checks (f64) of every layer with respect to its parameters
//! and inputs.

use crate::common;

use common::*;
use nn::message_passing::{Aggregation, EdgeDistance, EdgeList, MessagePassingConfig};
use nn::{Init, Linear, Mlp, ParamStore, RadialBasis, SubeqMessagePassing, SubeqSizes, SubequivariantFn, VectorLinear};
use tensor::Activation;

#[test]
fn linear_and_mlp_gradients_match_finite_differences() {
    let mut r = rng(1);
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(0);
    let lin = Linear::new(&mut store.scope("lin", &mut init), 3, 4).unwrap();
    // Non-zero bias so the check covers it with a generic value.
    let b = lin.bias.unwrap();
    store.set(b, uniform(&mut r, &[4])).unwrap();
    check_layer(&store, vec![uniform(&mut r, &[2, 5, 3])], |p, v| lin.forward_act(p, v[0], Activation::Tanh));

    let mut store = ParamStore::<f64>::new();
    let mlp = Mlp::with_init(
        &mut store.scope("mlp", &mut init),
        &[3, 6, 5, 2],
        Activation::Tanh,
        Init::Orthogonal { gain: 2f64.sqrt() },
        Init::LecunUniform,
    )
    .unwrap();
    assert_eq!(
        store.names(),
        ["mlp.0.weight", "mlp.0.bias", "mlp.1.weight", "mlp.1.bias", "mlp.2.weight", "mlp.2.bias"]
    );
    assert_eq!(store.num_elements(), 3 * 6 + 6 + 6 * 5 + 5 + 5 * 2 + 2);
    check_layer(&store, vec![uniform(&mut r, &[4, 3])], |p, v| mlp.forward(p, v[0]));
}

#[test]
fn mlp_forward_parts_equals_forward_of_the_concatenation() {
    let mut r = rng(11);
    for sizes in [vec![5, 2], vec![5, 4, 3, 2]] {
        let mut store = ParamStore::<f64>::new();
        let mlp = Mlp::new(&mut store.scope("mlp", &mut nn::init_rng(1)), &sizes, Activation::Relu).unwrap();
        randomise_biases(&mut store, &mut r);
        let (a, b) = (uniform(&mut r, &[4, 2]), uniform(&mut r, &[4, 3]));
        let tape = tensor::Tape::new();
        let p = store.bind(&tape);
        let (va, vb) = (tape.constant(a), tape.constant(b));
        let parts = mlp.forward_parts(&p, &[va, vb]).unwrap().value();
        let whole = mlp.forward(&p, tape.cat(&[va, vb], 1).unwrap()).unwrap().value();
        let diff = parts.data().iter().zip(whole.data()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(diff < 1e-12, "{sizes:?}: {diff}");
        // Parts that do not add up to the input width are an error.
        assert!(mlp.forward_parts(&p, &[va]).is_err(), "{sizes:?}");
    }
    // Gradients through the single-layer path (no activation), parameters and inputs.
    let mut store = ParamStore::<f64>::new();
    let lin = Mlp::new(&mut store.scope("m", &mut nn::init_rng(2)), &[5, 2], Activation::Relu).unwrap();
    randomise_biases(&mut store, &mut r);
    check_layer(&store, vec![uniform(&mut r, &[3, 2]), uniform(&mut r, &[3, 3])], |p, v| {
        lin.forward_parts(p, &[v[0], v[1]])
    });
}

#[test]
fn radial_basis_gradients_match_finite_differences() {
    let mut r = rng(2);
    let rbf = RadialBasis::new(8, 3.0).unwrap();
    let store = ParamStore::<f64>::new();
    let d =
        tensor::Tensor::new((0..6).map(|_| rand::RngExt::random_range(&mut r, 0.0..3.0)).collect(), &[6, 1]).unwrap();
    check_layer(&store, vec![d], |_, v| rbf.forward(v[0]));
    assert!(RadialBasis::new(1, 3.0).is_err());
    assert!(RadialBasis::new(8, 0.0).is_err());
}

#[test]
fn vector_linear_and_gram() {
    let mut r = rng(3);
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(1);
    let vl = VectorLinear::new(&mut store.scope("vl", &mut init), 4, 3).unwrap();
    check_layer(&store, vec![uniform(&mut r, &[2, 3, 4])], |p, v| nn::gram(vl.forward(p, v[0])?));
}

/// The normaliser from `Z Z^T` equals `||Z^T Z||_F + 1` computed from the Gram matrix, and
/// its gradient checks.
#[test]
fn gram_norm_from_the_outer_product() {
    let mut r = rng(7);
    let z = uniform(&mut r, &[5, 3, 6]);
    let tape = tensor::Tape::<f64>::new();
    let zv = tape.var(z.clone());
    let direct = nn::equivariant::norm_plus_one(nn::gram(zv).unwrap()).unwrap().value();
    let outer = nn::equivariant::gram_norm_plus_one(zv).unwrap().value();
    assert_eq!(outer.shape(), [5, 1]);
    for (a, b) in direct.data().iter().zip(outer.data()) {
        assert!((a - b).abs() < 1e-12 * a.abs(), "{a} vs {b}");
    }
    let store = ParamStore::<f64>::new();
    check_layer(&store, vec![z], |_, v| nn::equivariant::gram_norm_plus_one(v[0]));
}

#[test]
fn subequivariant_function_gradients_match_finite_differences() {
    let mut r = rng(4);
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(2);
    let sz = SubeqSizes { m_in: 3, s_in: 2, m_mid: 3, m_out: 2, s_out: 2, hidden: 5, layers: 2 };
    let f = SubequivariantFn::new(&mut store.scope("f", &mut init), sz, Some([0.0, 0.0, -1.0])).unwrap();
    randomise_biases(&mut store, &mut r);
    check_layer(&store, vec![uniform(&mut r, &[3, 3, 3]), uniform(&mut r, &[3, 2])], |p, v| {
        let (z, h) = f.forward(p, v[0], v[1])?;
        Ok(z.reshape(&[3, 6])?.sum(1, false)?.add(h.sum(1, false)?)?)
    });
}

#[test]
fn message_passing_sum_mean_raw_rbf() {
    let mut r = rng(5);
    // The last case adds caller-supplied edge scalars (checked as an input too).
    for (agg, dist, extra) in [
        (Aggregation::Mean, EdgeDistance::Raw, 0),
        (Aggregation::Sum, EdgeDistance::Rbf(RadialBasis::new(4, 2.0).unwrap()), 0),
        (Aggregation::Mean, EdgeDistance::None, 0),
        (Aggregation::Mean, EdgeDistance::Raw, 3),
    ] {
        let mut store = ParamStore::<f64>::new();
        let mut init = nn::init_rng(3);
        let cfg = MessagePassingConfig {
            vectors: 2,
            scalars: 2,
            hidden: 4,
            layers: 2,
            distance: dist.clone(),
            aggregation: agg,
            gravity: Some([0.0, 0.0, -1.0]),
            edge_scalars: extra,
        };
        let mp = SubeqMessagePassing::new(&mut store.scope("mp", &mut init), cfg).unwrap();
        randomise_biases(&mut store, &mut r);
        // Two graphs of 3 nodes plus one isolated node (no edges: aggregation gives 0).
        let mut edges = EdgeList::fully_connected(2, 3);
        edges.num_nodes = 7;
        let mut inputs = vec![uniform(&mut r, &[7, 3, 2]), uniform(&mut r, &[7, 2]), uniform(&mut r, &[7, 3, 1])];
        if extra > 0 {
            inputs.push(uniform(&mut r, &[edges.len(), extra]));
        }
        check_layer(&store, inputs.clone(), |p, v| {
            let s = v.get(3).copied();
            let (z, h) = mp.forward_with(p, v[0], v[1], v[2], &edges, s)?;
            let (z, h) = mp.forward_with(p, z, h, v[2], &edges, s)?; // two rounds with shared weights
            tensor_cat_sum(z, h)
        });
        if extra > 0 {
            // A missing or mis-shaped edge-scalar input is an error, not a panic.
            let tape = tensor::Tape::new();
            let p = store.bind(&tape);
            let (z, h, x) = (
                tape.constant(uniform(&mut r, &[7, 3, 2])),
                tape.constant(uniform(&mut r, &[7, 2])),
                tape.constant(uniform(&mut r, &[7, 3, 1])),
            );
            assert!(mp.forward(&p, z, h, x, &edges).is_err());
            let wrong = tape.constant(uniform(&mut r, &[edges.len(), extra + 1]));
            assert!(mp.forward_with(&p, z, h, x, &edges, Some(wrong)).is_err());
        }
        // Two rounds over one geometry computed once give the bits of two rounds that each
        // compute it, outputs and parameter gradients; a geometry of other edges is refused.
        let two_rounds = |shared: bool| {
            let tape = tensor::Tape::new();
            let p = store.bind(&tape);
            let v: Vec<_> = inputs.iter().map(|t| tape.var(t.clone())).collect();
            let s = v.get(3).copied();
            let (z, h) = if shared {
                let geometry = mp.edge_geometry(v[2], &edges).unwrap();
                let (z, h) = mp.forward_over(&p, v[0], v[1], &geometry, &edges, s).unwrap();
                mp.forward_over(&p, z, h, &geometry, &edges, s).unwrap()
            } else {
                let (z, h) = mp.forward_with(&p, v[0], v[1], v[2], &edges, s).unwrap();
                mp.forward_with(&p, z, h, v[2], &edges, s).unwrap()
            };
            let out = tensor_cat_sum(z, h).unwrap();
            let grads = tape.backward(out.square().sum_all()).unwrap();
            let mut bits: Vec<u64> = out.value().data().iter().map(|x| x.to_bits()).collect();
            for g in p.grads(&grads).iter().chain([grads.get(v[0]).unwrap(), grads.get(v[1]).unwrap()]) {
                bits.extend(g.data().iter().map(|x| x.to_bits()));
            }
            let gx = grads.get(v[2]).unwrap().clone();
            (bits, gx)
        };
        let ((shared, gx_shared), (apart, gx_apart)) = (two_rounds(true), two_rounds(false));
        assert_eq!(shared, apart, "{dist:?} {agg:?} {extra}: a shared geometry changed the bits");
        // The positions' gradient adds the two rounds' contributions in another order.
        for (a, b) in gx_shared.data().iter().zip(gx_apart.data()) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
        }
        let tape = tensor::Tape::new();
        let p = store.bind(&tape);
        let other = EdgeList::fully_connected(1, 3);
        let geometry = mp.edge_geometry(tape.constant(inputs[2].clone()), &EdgeList { num_nodes: 7, ..other }).unwrap();
        let (z, h) = (tape.constant(inputs[0].clone()), tape.constant(inputs[1].clone()));
        let s = inputs.get(3).map(|t| tape.constant(t.clone()));
        assert!(mp.forward_over(&p, z, h, &geometry, &edges, s).is_err());
    }
}

fn tensor_cat_sum<'t>(z: tensor::Var<'t, f64>, h: tensor::Var<'t, f64>) -> nn::Result<tensor::Var<'t, f64>> {
    let n = z.shape()[0];
    let zf = z.reshape(&[n, z.shape()[1] * z.shape()[2]])?;
    Ok(z.tape().cat(&[zf, h], 1)?)
}

/// Zero biases make some paths trivially linear; give them generic values.
fn randomise_biases(store: &mut ParamStore<f64>, r: &mut rand_chacha::ChaCha8Rng) {
    let ids: Vec<nn::ParamId> =
        store.names().iter().filter(|n| n.ends_with("bias")).map(|n| store.find(n).unwrap()).collect();
    for id in ids {
        let shape = store.get(id).shape().to_vec();
        let v = uniform(r, &shape);
        let v = tensor::Tensor::new(v.data().iter().map(|x| x * 0.5).collect(), &shape).unwrap();
        store.set(id, v).unwrap();
    }
}

#[test]
fn bad_configurations_are_errors() {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(0);
    assert!(Linear::new(&mut store.scope("a", &mut init), 0, 3).is_err());
    assert!(Mlp::new(&mut store.scope("b", &mut init), &[3], Activation::Relu).is_err());
    let _ = Linear::new(&mut store.scope("c", &mut init), 2, 3).unwrap();
    let dup = Linear::new(&mut store.scope("c", &mut init), 2, 3).unwrap_err().to_string();
    assert!(dup.contains("c.weight") && dup.contains("twice"), "{dup}");
    assert!(EdgeList::new(vec![1, 0], vec![0, 1], 2).is_err());
    assert!(EdgeList::new(vec![0, 1], vec![2, 0], 2).unwrap_err().to_string().contains("node 2"));
}

#[test]
fn vector_mixing_of_channel_parts_equals_mixing_their_concatenation() {
    let mut r = rng(8);
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(6);
    let g = [0.0, 0.0, -1.0];
    let mix = nn::equivariant::VectorLinear::new(&mut store.scope("w", &mut init), 2 + 3 + 1, 4).unwrap();
    let (a, b) = (uniform(&mut r, &[5, 3, 2]), uniform(&mut r, &[5, 3, 3]));
    let tape = tensor::Tape::new();
    let p = store.bind(&tape);
    let (va, vb) = (tape.constant(a.clone()), tape.constant(b.clone()));
    let joined = nn::equivariant::append_gravity(tape.cat(&[va, vb], 2).unwrap(), g).unwrap();
    let whole = mix.forward(&p, joined).unwrap().value();
    let parts = mix.forward_channels(&p, &[va, vb], Some(g)).unwrap().value();
    assert!(whole.all_close(&parts, 0.0, 1e-12));
    // Channels that do not add up to the layer's input (here: gravity left out) are an error.
    assert!(mix.forward_channels(&p, &[va, vb], None).is_err());
    assert!(mix.forward_channels(&p, &[], Some(g)).is_err());
    check_layer(&store, vec![a, b], |p, v| mix.forward_channels(p, &[v[0], v[1]], Some(g)));
}

#[test]
fn mlp_on_input_parts_equals_mlp_on_their_concatenation() {
    let mut r = rng(6);
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(4);
    let mlp = Mlp::new(&mut store.scope("m", &mut init), &[7, 5, 3], Activation::Relu).unwrap();
    randomise_biases(&mut store, &mut r);
    let (a, b) = (uniform(&mut r, &[4, 3]), uniform(&mut r, &[4, 4]));
    let tape = tensor::Tape::new();
    let p = store.bind(&tape);
    let (va, vb) = (tape.constant(a), tape.constant(b));
    let whole = mlp.forward_hidden(&p, tape.cat(&[va, vb], 1).unwrap()).unwrap().value();
    let parts = mlp.forward_hidden_parts(&p, &[va, vb]).unwrap().value();
    assert!(whole.all_close(&parts, 0.0, 1e-12));
    // Parts that do not add up to the input width are an error.
    assert!(mlp.forward_hidden_parts(&p, &[va]).is_err());
    check_layer(&store, vec![uniform(&mut r, &[4, 3]), uniform(&mut r, &[4, 4])], |p, v| {
        mlp.forward_output_columns(p, mlp.forward_hidden_parts(p, &[v[0], v[1]])?, 1, 2)
    });
}
