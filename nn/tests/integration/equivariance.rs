//! Equivariance of the subequivariant layer and of message passing (f64, to 1e-9):
//! rotations about gravity rotate vector outputs and leave scalars unchanged; so do
//! reflections through vertical planes; without the gravity channel, any rotation or
//! reflection; with gravity, a tilt is NOT a symmetry (the check can fail).

use crate::common;

use common::*;
use nn::message_passing::{Aggregation, EdgeDistance, EdgeList, MessagePassingConfig};
use nn::{ParamStore, SubeqMessagePassing, SubeqSizes, SubequivariantFn};
use tensor::{Tape, Tensor};

const TOL: f64 = 1e-9;
const G: [f64; 3] = [0.0, 0.0, -1.0];

fn subeq(gravity: Option<[f64; 3]>) -> (ParamStore<f64>, SubequivariantFn) {
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(7);
    let sz = SubeqSizes { m_in: 4, s_in: 3, m_mid: 5, m_out: 3, s_out: 2, hidden: 16, layers: 2 };
    let f = SubequivariantFn::new(&mut store.scope("f", &mut init), sz, gravity).unwrap();
    (store, f)
}

fn run_subeq(
    store: &ParamStore<f64>,
    f: &SubequivariantFn,
    z: &Tensor<f64>,
    h: &Tensor<f64>,
) -> (Tensor<f64>, Tensor<f64>) {
    let tape = Tape::new();
    let p = store.bind(&tape);
    let (zo, ho) = f.forward(&p, tape.constant(z.clone()), tape.constant(h.clone())).unwrap();
    (zo.value(), ho.value())
}

/// Max error of `f(R z) - R f(z)` over vectors and `h(R z) - h(z)` over scalars.
fn subeq_error(gravity: Option<[f64; 3]>, rot: &[[f64; 3]; 3], seed: u64) -> (f64, f64) {
    let (store, f) = subeq(gravity);
    let mut r = rng(seed);
    let z = uniform(&mut r, &[6, 3, 4]);
    let h = uniform(&mut r, &[6, 3]);
    let (z1, h1) = run_subeq(&store, &f, &z, &h);
    let (z2, h2) = run_subeq(&store, &f, &rotate(rot, &z), &h);
    (max_diff(&z2, &rotate(rot, &z1)), max_diff(&h1, &h2))
}

#[test]
fn subequivariant_fn_rotations_about_gravity() {
    let mut r = rng(10);
    for k in 0..5 {
        let a = rand::RngExt::random_range(&mut r, 0.0..std::f64::consts::TAU);
        let (ez, eh) = subeq_error(Some(G), &rot_z(a), k);
        assert!(ez < TOL && eh < TOL, "angle {a}: vectors {ez:e}, scalars {eh:e}");
    }
}

#[test]
fn subequivariant_fn_vertical_reflections() {
    for (k, a) in [0.3, 1.7, 4.0].into_iter().enumerate() {
        let (ez, eh) = subeq_error(Some(G), &vertical_reflection(a), k as u64);
        assert!(ez < TOL && eh < TOL, "reflection {a}: {ez:e} {eh:e}");
    }
}

#[test]
fn subequivariant_fn_without_gravity_is_o3_equivariant() {
    let mut r = rng(11);
    for k in 0..5 {
        let rot = random_rotation(&mut r);
        let (ez, eh) = subeq_error(None, &rot, k);
        assert!(ez < TOL && eh < TOL, "{ez:e} {eh:e}");
        // A general reflection: rotation composed with a point reflection.
        let mut refl = rot;
        refl.iter_mut().for_each(|row| row.iter_mut().for_each(|v| *v = -*v));
        let (ez, eh) = subeq_error(None, &refl, k);
        assert!(ez < TOL && eh < TOL, "{ez:e} {eh:e}");
    }
}

#[test]
fn gravity_breaks_symmetry_under_tilts() {
    // A rotation about the x axis moves g: the layer must notice.
    let (s, c) = 0.8f64.sin_cos();
    let tilt = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]];
    let (ez, eh) = subeq_error(Some(G), &tilt, 3);
    assert!(ez > 1e-3 || eh > 1e-3, "a tilt should change the output: {ez:e} {eh:e}");
}

fn mp(gravity: Option<[f64; 3]>) -> (ParamStore<f64>, SubeqMessagePassing) {
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(8);
    let cfg = MessagePassingConfig {
        vectors: 4,
        scalars: 3,
        hidden: 16,
        layers: 2,
        distance: EdgeDistance::Rbf(nn::RadialBasis::new(8, 4.0).unwrap()),
        aggregation: Aggregation::Mean,
        gravity,
        edge_scalars: 0,
    };
    let layer = SubeqMessagePassing::new(&mut store.scope("mp", &mut init), cfg).unwrap();
    (store, layer)
}

fn run_mp(
    store: &ParamStore<f64>,
    layer: &SubeqMessagePassing,
    z: &Tensor<f64>,
    h: &Tensor<f64>,
    x: &Tensor<f64>,
    e: &EdgeList,
) -> (Tensor<f64>, Tensor<f64>) {
    let tape = Tape::new();
    let p = store.bind(&tape);
    let xv = tape.constant(x.clone());
    let (z1, h1) = layer.forward(&p, tape.constant(z.clone()), tape.constant(h.clone()), xv, e).unwrap();
    let (z2, h2) = layer.forward(&p, z1, h1, xv, e).unwrap();
    (z2.value(), h2.value())
}

fn mp_error(gravity: Option<[f64; 3]>, rot: &[[f64; 3]; 3], shift: [f64; 3], seed: u64) -> (f64, f64) {
    let (store, layer) = mp(gravity);
    let mut r = rng(seed);
    let edges = EdgeList::fully_connected(2, 4);
    let z = uniform(&mut r, &[8, 3, 4]);
    let h = uniform(&mut r, &[8, 3]);
    let x = uniform(&mut r, &[8, 3, 1]);
    let (z1, h1) = run_mp(&store, &layer, &z, &h, &x, &edges);
    let mut xr = rotate(rot, &x);
    xr.data_mut().chunks_mut(3).for_each(|p| p.iter_mut().zip(shift).for_each(|(v, s)| *v += s));
    let (z2, h2) = run_mp(&store, &layer, &rotate(rot, &z), &h, &xr, &edges);
    (max_diff(&z2, &rotate(rot, &z1)), max_diff(&h1, &h2))
}

#[test]
fn message_passing_rotations_reflections_translations() {
    let mut r = rng(12);
    for k in 0..4 {
        let a = rand::RngExt::random_range(&mut r, 0.0..std::f64::consts::TAU);
        let (ez, eh) = mp_error(Some(G), &rot_z(a), [1.5, -2.0, 0.7], k);
        assert!(ez < TOL && eh < TOL, "rotation {a}: {ez:e} {eh:e}");
        let (ez, eh) = mp_error(Some(G), &vertical_reflection(a), [0.0; 3], k);
        assert!(ez < TOL && eh < TOL, "reflection {a}: {ez:e} {eh:e}");
        let rot = random_rotation(&mut r);
        let (ez, eh) = mp_error(None, &rot, [3.0, 1.0, -1.0], k);
        assert!(ez < TOL && eh < TOL, "no gravity, any rotation: {ez:e} {eh:e}");
    }
    let (s, c) = 0.8f64.sin_cos();
    let tilt = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]];
    let (ez, eh) = mp_error(Some(G), &tilt, [0.0; 3], 9);
    assert!(ez > 1e-3 || eh > 1e-3, "a tilt should change the output");
}
