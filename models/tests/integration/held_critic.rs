//! `assign_critic=held` (`models::mlp`, `models::shnn`, docs/MODELS.md "What the value
//! reads"): the value of a model with a learned assignment reads the assignment held into
//! each step. Its weight `W_σ` starts at zero, so the model starts as without it; once
//! trained, the value of a held scene depends on which agent holds which ball and the value
//! of a scene that draws does not; `mlp_hn`'s value stays invariant under yaw and
//! translation, SHNN's under rotations about gravity and translations; the gradient of the
//! value reaches every parameter (checked by finite differences).

use crate::common::{self, max_diff, rng};
use envs::layout::{ObsRows, ObsSpec};
use envs::tasks::{StartMode, VecEnv};
use models::{Model, ModelDescription, MpSizes, NO_AGENT};
use nn::{Bound, ParamStore};
use rand::RngExt;
use std::cell::RefCell;
use tensor::gradcheck::check_gradients;
use tensor::{Tape, Tensor, Var};

const B: usize = 4;

/// `B` scenes of Team Reach with two ants after a few random steps, in `f64`: `(spec,
/// vectors, scalars, headings)`.
fn scenes(seed: u64) -> (ObsSpec, Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut env = VecEnv::from_name("team_reach/2_ants", B, seed, StartMode::Random).unwrap();
    let mut r = rng(seed);
    for _ in 0..3 {
        let actions: Vec<f32> = (0..B * env.n_actions()).map(|_| r.random_range(-1.0..1.0)).collect();
        env.step(&actions).unwrap();
    }
    let o = env.obs();
    let f = |x: &[f32]| x.iter().map(|&v| f64::from(v)).collect::<Vec<_>>();
    (env.scene().obs_spec.clone(), f(&o.vectors), f(&o.scalars), f(&o.heading))
}

fn build(s: &str, spec: &ObsSpec) -> (ParamStore<f64>, Model) {
    build_from(&ModelDescription::parse(s).unwrap(), spec)
}

fn build_from(d: &ModelDescription, spec: &ObsSpec) -> (ParamStore<f64>, Model) {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(3);
    let model = Model::new(&mut store.scope("team", &mut init), d, spec, 0).unwrap();
    (store, model)
}

/// The values `[B]` of `model` given the assignment `sigma`, held where `held` says (`None`:
/// the plain forward pass with the assignment given).
fn values(
    model: &mut Model,
    store: &ParamStore<f64>,
    obs: &ObsRows<'_, f64>,
    sigma: &[u32],
    held: Option<&[bool]>,
) -> Vec<f64> {
    let tape = Tape::new();
    let p = store.bind(&tape);
    let out = match held {
        Some(h) => model.forward_batch_held(&p, obs, sigma, h).unwrap(),
        None => model.forward_batch_with(&p, obs, Some(sigma)).unwrap(),
    };
    out.team_value().unwrap().value().to_vec()
}

#[test]
fn the_held_critic_starts_as_the_plain_value_and_reads_the_held_assignment() {
    for (base, critic) in [("mlp_hn", ""), ("shnn", ""), ("shnn", ";critic=shared")] {
        held_critic_of(base, critic);
    }
}

fn held_critic_of(base: &str, critic: &str) {
    let case = format!("{base}{critic}");
    let (spec, vectors, scalars, heading) = scenes(17);
    let obs = ObsRows::new(spec.n_nodes, spec.n_agents, &vectors[..], &scalars[..], &heading[..]).unwrap();
    let (plain_store, mut plain) = build(&format!("{base}:assignment=learned{critic}"), &spec);
    let (mut store, mut model) = build(&format!("{base}:assignment=learned;assign_critic=held{critic}"), &spec);
    assert!(model.value_reads_held() && !plain.value_reads_held());
    // The same parameters, and W_σ [m n, 256], zero, counted in the critic.
    let width = model.assignment_width();
    let w = store.find("team.critic.held.weight").expect("W_σ");
    let columns = store.get(w).shape()[1];
    assert_eq!(store.get(w).shape(), &[width * 2, columns]);
    assert!(store.get(w).to_vec().iter().all(|&x| x == 0.0));
    let rest: Vec<(&str, Vec<f64>)> =
        store.iter().filter(|(n, _)| !n.contains(".held.")).map(|(n, t)| (n, t.to_vec())).collect();
    let plain_params: Vec<(&str, Vec<f64>)> = plain_store.iter().map(|(n, t)| (n, t.to_vec())).collect();
    assert_eq!(rest, plain_params, "{case}: the other parameters start as without assign_critic");
    let (counts, plain_counts) = (model.param_counts(&store), plain.param_counts(&plain_store));
    assert_eq!((counts.policy, counts.critic), (plain_counts.policy, plain_counts.critic + width * 2 * columns));

    // A drawn assignment and its swap (two agents, two balls).
    plain.reseed(5);
    let sigma = {
        let tape = Tape::new();
        plain.forward_batch(&plain_store.bind(&tape), &obs).unwrap().assignment
    };
    let swapped: Vec<u32> = sigma.iter().map(|&i| if i == NO_AGENT { i } else { 1 - i }).collect();
    assert_ne!(sigma, swapped);
    let held = [true, false, true, false];
    let reference = values(&mut plain, &plain_store, &obs, &sigma, None);
    // W_σ = 0: the value is the plain model's, held or not.
    assert_eq!(values(&mut model, &store, &obs, &sigma, Some(&held)), reference);

    // Trained (W_σ random), a held scene's value reads which agent holds which ball; a
    // scene that draws reads none, nor does the plain forward pass.
    let mut r = rng(23);
    let random: Vec<f64> = (0..width * 2 * columns).map(|_| r.random_range(-0.5..0.5)).collect();
    store.set(w, Tensor::new(random, &[width * 2, columns]).unwrap()).unwrap();
    let v_held = values(&mut model, &store, &obs, &sigma, Some(&held));
    let v_swapped = values(&mut model, &store, &obs, &swapped, Some(&held));
    assert_eq!(values(&mut model, &store, &obs, &sigma, Some(&[false; B])), reference);
    assert_eq!(values(&mut model, &store, &obs, &sigma, None), reference);
    for b in 0..B {
        assert_eq!(v_held[b] != reference[b], held[b], "{case}, scene {b}: {} vs {}", v_held[b], reference[b]);
        // (critic=shared's value reads the actor's features, which read σ, held or not.)
        if held[b] || critic.is_empty() {
            assert_eq!(v_swapped[b] != v_held[b], held[b], "{case}, scene {b}");
        }
    }

    // The value stays invariant under a rotation about gravity and a translation.
    let (v2, h2) = (common::transform(&vectors, 2.1, [3.0, -1.5]), heading.iter().map(|h| h + 2.1).collect::<Vec<_>>());
    let moved = ObsRows::new(spec.n_nodes, spec.n_agents, &v2[..], &scalars[..], &h2[..]).unwrap();
    let d = max_diff(&values(&mut model, &store, &moved, &sigma, Some(&held)), &v_held);
    assert!(d < 1e-9, "{case}: {d}");

    // Held flags for another batch size, or to a value that reads none, are errors.
    let tape = Tape::new();
    let e = model.forward_batch_held(&store.bind(&tape), &obs, &sigma, &held[..3]).unwrap_err().to_string();
    assert!(e.contains("held flags of 3 scenes for 4 scenes"), "{e}");
    let e = plain.forward_batch_held(&plain_store.bind(&tape), &obs, &sigma, &held).unwrap_err().to_string();
    assert!(e.contains("reads no assignment (assign_critic=held)"), "{e}");
    let (hnn_store, mut hnn) = build("hnn", &spec);
    let e = hnn.forward_batch_held(&hnn_store.bind(&tape), &obs, &sigma, &held).unwrap_err().to_string();
    assert!(e.contains("given to `hnn`, whose value reads no assignment"), "{e}");
}

/// The gradient of the value, with some scenes holding their assignment, reaches every
/// parameter as finite differences say (a small model: 6-wide heads, a 5-wide critic, an
/// affine scorer).
#[test]
fn the_held_critics_value_differentiates_through_every_parameter() {
    for base in ["mlp_hn", "shnn"] {
        let mut d = ModelDescription::parse(&format!(
            "{base}:assignment=learned;assign_critic=held;head=6;critic_hidden=5;assign_hidden=none"
        ))
        .unwrap();
        if let ModelDescription::Shnn(o) = &mut d {
            o.stage.sizes = MpSizes { vectors: 3, scalars: 4, hidden: 5, layers: 1, steps: 2 };
        }
        held_value_gradients(&d);
    }
}

fn held_value_gradients(d: &ModelDescription) {
    let (spec, vectors, scalars, heading) = scenes(29);
    let obs = ObsRows::new(spec.n_nodes, spec.n_agents, &vectors[..], &scalars[..], &heading[..]).unwrap();
    let (mut store, model) = build_from(d, &spec);
    let w = store.find("team.critic.held.weight").unwrap();
    let shape = store.get(w).shape().to_vec();
    let mut r = rng(31);
    let random: Vec<f64> = (0..shape.iter().product::<usize>()).map(|_| r.random_range(-0.5..0.5)).collect();
    store.set(w, Tensor::new(random, &shape).unwrap()).unwrap();
    let mut given = model.clone();
    given.reseed(2);
    let sigma = given.forward_batch(&store.bind(&Tape::new()), &obs).unwrap().assignment;
    let held = [true, true, false, true];
    let model = RefCell::new(model);
    let report = check_gradients(|_, v| held_value(&model, &obs, &sigma, &held, v), store.values()).unwrap();
    assert_eq!(report.checked, store.num_elements());
}

/// The value of `model` with the parameters `v` (store order) as tape inputs.
fn held_value<'t>(
    model: &RefCell<Model>,
    obs: &ObsRows<'_, f64>,
    sigma: &[u32],
    held: &[bool],
    v: &[Var<'t, f64>],
) -> tensor::Result<Var<'t, f64>> {
    let p = Bound::from_vars(v.to_vec());
    let out = model.borrow_mut().forward_batch_held(&p, obs, sigma, held).expect("forward");
    Ok(out.team_value().unwrap())
}
