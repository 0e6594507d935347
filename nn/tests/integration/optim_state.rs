//! Adam against a hand-computed step, clipping, schedules, and saved state.

use crate::common;

use common::*;
use nn::{Adam, AdamConfig, LrSchedule, Mlp, ParamStore, StateDict, clip_elementwise, clip_global_norm};
use tensor::{Activation, Tape, Tensor};

#[test]
fn adam_matches_hand_computed_steps() {
    let mut store = ParamStore::<f64>::new();
    let id = store.add("p", Tensor::from_f64(&[1.0], &[1]).unwrap()).unwrap();
    let cfg = AdamConfig { lr: LrSchedule::Constant(0.1), ..AdamConfig::default() };
    let mut adam = Adam::new(cfg, &store);
    // Step 1, g = 0.5: m = 0.05, v = 0.00025, m^ = 0.5, v^ = 0.25,
    // p = 1 - 0.1 * 0.5 / (0.5 + 1e-8) = 0.900000002.
    adam.step(&mut store, &[Tensor::from_f64(&[0.5], &[1]).unwrap()]).unwrap();
    assert!((store.get(id).data()[0] - 0.900000002).abs() < 1e-15);
    // Step 2, g = -1: m = -0.055, v = 0.00124975, m^ = -0.055 / 0.19, v^ = 0.00124975 / 0.001999,
    // p = 0.900000002 + 0.1 * 0.2894736842105263 / (sqrt(0.6251875937969075) + 1e-8).
    adam.step(&mut store, &[Tensor::from_f64(&[-1.0], &[1]).unwrap()]).unwrap();
    let want = 0.900000002 + 0.1 * 0.2894736842105263 / (0.6251875937969075f64.sqrt() + 1e-8);
    assert!((store.get(id).data()[0] - want).abs() < 1e-14, "{} vs {want}", store.get(id).data()[0]);
    assert!((want - 0.9366103542405654).abs() < 1e-15);
    assert_eq!(adam.t, 2);
    // Wrong gradient count is an error, not a panic.
    assert!(adam.step(&mut store, &[]).is_err());
}

#[test]
fn clipping_and_lr_schedules_give_the_hand_computed_values() {
    let mut g: Vec<Tensor<f64>> = vec![Tensor::from_f64(&[0.5, -0.05, -3.0], &[3]).unwrap()];
    clip_elementwise(&mut g, 0.1);
    assert_eq!(g[0].data(), &[0.1, -0.05, -0.1]);
    let mut g: Vec<Tensor<f64>> =
        vec![Tensor::from_f64(&[3.0], &[1]).unwrap(), Tensor::from_f64(&[4.0], &[1]).unwrap()];
    let n = clip_global_norm(&mut g, 1.0);
    assert!((n - 5.0).abs() < 1e-12);
    assert!((g[0].data()[0] - 0.6).abs() < 1e-12 && (g[1].data()[0] - 0.8).abs() < 1e-12);
    let mut small: Vec<Tensor<f64>> = vec![Tensor::from_f64(&[0.3], &[1]).unwrap()];
    clip_global_norm(&mut small, 1.0);
    assert_eq!(small[0].data(), &[0.3]);
    let s = LrSchedule::Linear { start: 1.0, end: 0.0, steps: 4 };
    assert_eq!([s.at(0), s.at(1), s.at(4), s.at(9)], [1.0, 0.75, 0.0, 0.0]);
    assert_eq!(LrSchedule::Constant(0.3).at(100), 0.3);
}

fn model(seed: u64) -> (ParamStore<f32>, Mlp) {
    let mut store = ParamStore::new();
    let mut init = nn::init_rng(seed);
    let mlp = Mlp::new(&mut store.scope("actor", &mut init), &[4, 8, 2], Activation::Relu).unwrap();
    (store, mlp)
}

fn output(store: &ParamStore<f32>, mlp: &Mlp, x: &Tensor<f32>) -> Vec<f32> {
    let tape = Tape::new();
    let p = store.bind(&tape);
    mlp.forward(&p, tape.constant(x.clone())).unwrap().value().to_vec()
}

#[test]
fn save_then_load_gives_identical_outputs() {
    let dir = std::env::temp_dir().join(format!("nn-state-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("params.json");
    let (a, mlp) = model(1);
    StateDict::from_store(&a).unwrap().save(&path).unwrap();
    let (mut b, mlp_b) = model(2);
    let x: Tensor<f32> = uniform(&mut rng(3), &[5, 4]).cast();
    assert_ne!(output(&a, &mlp, &x), output(&b, &mlp_b, &x));
    StateDict::load(&path).unwrap().load_into(&mut b).unwrap();
    assert_eq!(output(&a, &mlp, &x), output(&b, &mlp_b, &x)); // bit-identical
    assert!(!dir.join("params.json.tmp").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn loading_a_wrong_state_fails_clearly() {
    let (a, _) = model(1);
    let sd = StateDict::from_store(&a).unwrap();
    // Wrong shape.
    let mut bad = sd.clone();
    bad.tensors[0].shape = vec![8, 4];
    let (mut b, _) = model(2);
    let before = b.values().to_vec();
    let e = bad.load_into(&mut b).unwrap_err().to_string();
    assert!(e.contains("actor.0.weight") && e.contains("[8, 4]") && e.contains("[4, 8]"), "{e}");
    assert_eq!(b.values(), &before[..], "a failed load must not change the model");
    // Missing name.
    let mut missing = sd.clone();
    missing.tensors.retain(|t| t.name != "actor.1.bias");
    let e = missing.load_into(&mut b).unwrap_err().to_string();
    assert!(e.contains("actor.1.bias") && e.contains("missing"), "{e}");
    // Extra name.
    let mut extra = sd.clone();
    extra.tensors[0].name = "critic.0.weight".into();
    let e = extra.load_into(&mut b).unwrap_err().to_string();
    assert!(e.contains("critic.0.weight"), "{e}");
    // Not a state file at all, and a missing file.
    let dir = std::env::temp_dir().join(format!("nn-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("garbage.json");
    std::fs::write(&p, "{\"version\": 1, \"tensors\": [{\"name\": 3}]}").unwrap();
    let e = StateDict::load(&p).unwrap_err().to_string();
    assert!(e.contains("garbage.json") && e.contains("not a saved state"), "{e}");
    let e = StateDict::load(&dir.join("nope.json")).unwrap_err().to_string();
    assert!(e.contains("nope.json"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
