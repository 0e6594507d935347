//! Tests of the policy/critic interface (`models::policy`): invariance of the SHNN,
//! SHTransformer and SHGNN policies and values, heading and goal-direction normalisation
//! (`mlp_hn`, `transformer_hn`, `hnn_hn`, `hnn_dn`), the MLP and HNN baselines' lack of
//! invariance, forward on every built-in environment, gradient checks through whole small
//! SHNN, SHGNN and HNN+DN models, parameter counts, and errors.

use crate::common;

use common::{max_diff, rng};
use std::cell::RefCell;

use envs::layout::{N_SCALARS, NODE_VECTOR_LEN, ObsBatch, ObsRows, ObsSpec};
use envs::tasks::{BUILTIN_NAMES, StartMode, VecEnv};
use models::input::InputProcessor;
use models::kind::Head;
use models::{
    AssignmentMethod, EntityAbstraction, GraphBuilder, HiddenWidths, MlpNetwork, Model, ModelDescription, ModelKind,
    MpSizes, PolicyOutput, ShnnCritic, ShnnModel, Translation,
};
use nn::{Bound, ParamStore};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use tensor::gradcheck::check_gradients;
use tensor::{Tape, Tensor, Var};

const B: usize = 3;

/// `batch` observations of `name` after a few random control steps, in `f64`:
/// `(spec, vectors, scalars, headings)`.
fn observations(name: &str, batch: usize, seed: u64) -> (ObsSpec, Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut env = VecEnv::from_name(name, batch, seed, StartMode::Random).unwrap();
    let mut r = rng(seed);
    let na = env.n_actions();
    for _ in 0..3 {
        let actions: Vec<f32> = (0..batch * na).map(|_| r.random_range(-1.0..1.0)).collect();
        env.step(&actions).unwrap();
    }
    let o = env.obs();
    let f = |x: &[f32]| x.iter().map(|&v| v as f64).collect::<Vec<_>>();
    (env.scene().obs_spec.clone(), f(&o.vectors), f(&o.scalars), f(&o.heading))
}

/// Rotates every 3-vector about the vertical by `angle`, translates positions by
/// `(tx, ty, 0)` and shifts the headings by `angle`.
fn transform(vectors: &[f64], heading: &[f64], angle: f64, t: [f64; 2]) -> (Vec<f64>, Vec<f64>) {
    (common::transform(vectors, angle, t), heading.iter().map(|h| h + angle).collect())
}

/// Reflects every 3-vector through the vertical plane y = 0 (`y -> -y`) and negates the
/// headings. This is the action of `O_g(3)` on the network's inputs, which treat all three
/// channels as vectors (physically the angular velocity is a pseudovector).
fn reflect(vectors: &[f64], heading: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut out = vectors.to_vec();
    out.chunks_mut(3).for_each(|v| v[1] = -v[1]);
    (out, heading.iter().map(|h| -h).collect())
}

/// The model named by the string `s` (`name` or `name:key=value;..`).
fn named(s: &str) -> ModelDescription {
    ModelDescription::parse(s).unwrap()
}

fn build(config: &ModelDescription, spec: &ObsSpec, team: usize, seed: u64) -> (ParamStore<f64>, Model) {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(seed);
    let model = Model::new(&mut store.scope("team", &mut init), config, spec, team).unwrap();
    (store, model)
}

/// Every output of a forward pass flattened: per agent loc then scale, then the value.
fn flatten<T: tensor::Float>(out: &PolicyOutput<'_, T>) -> Vec<f64> {
    let mut v = Vec::new();
    for a in &out.agents {
        v.extend(a.loc.value().data().iter().map(|x| x.to_f64()));
        v.extend(a.scale.value().data().iter().map(|x| x.to_f64()));
    }
    v.extend(out.team_value().unwrap().value().data().iter().map(|x| x.to_f64()));
    v
}

fn run(model: &mut Model, store: &ParamStore<f64>, spec: &ObsSpec, v: &[f64], s: &[f64], h: &[f64]) -> Vec<f64> {
    let tape = Tape::new();
    let p = store.bind(&tape);
    let obs = ObsRows::new(spec.n_nodes, spec.n_agents, v, s, h).unwrap();
    flatten(&model.forward_batch(&p, &obs).unwrap())
}

#[test]
fn shnn_policies_and_values_are_invariant_under_rotations_about_gravity_and_translations() {
    let cases = [
        ("shnn", "team_reach/2_ants", 0),
        ("shnn", "team_sumo/2_ants", 0),
        ("shnn", "team_sumo/2_ants", 1),
        ("shnn", "team_reach/2_ant_claw", 0),
        ("shnn_og3", "team_reach/2_ants", 0),
        ("shnn_so3", "team_sumo/2_ants", 1),
        ("shtransformer", "team_reach/2_ant_claw", 0),
        ("shtransformer", "team_sumo/2_ants", 1),
        ("shgnn", "team_reach/2_ant_claw", 0),
        ("shgnn", "team_reach/3_ant_claw_centipede", 0),
        ("shgnn", "team_sumo/2_ants", 1),
    ];
    for (model_name, env, team) in cases {
        let (spec, vectors, scalars, heading) = observations(env, B, 11);
        let (store, mut model) = build(&named(model_name), &spec, team, 3);
        let base = run(&mut model, &store, &spec, &vectors, &scalars, &heading);
        let mut r = rng(5);
        for _ in 0..3 {
            let angle = r.random_range(0.0..std::f64::consts::TAU);
            let t = [r.random_range(-5.0..5.0), r.random_range(-5.0..5.0)];
            let (v, h) = transform(&vectors, &heading, angle, t);
            let moved = run(&mut model, &store, &spec, &v, &scalars, &h);
            let d = max_diff(&moved, &base);
            assert!(d < 1e-9, "{model_name} on {env} team {team}, angle {angle}: {d}");
        }
        // The check can fail: tilting the scene (about the x axis) changes the outputs.
        let (s, c) = 0.3f64.sin_cos();
        let mut tilt = vectors.clone();
        for q in tilt.chunks_mut(3) {
            let (y, z) = (q[1], q[2]);
            q[1] = c * y - s * z;
            q[2] = s * y + c * z;
        }
        let tilted = run(&mut model, &store, &spec, &tilt, &scalars, &heading);
        assert!(max_diff(&tilted, &base) > 1e-6, "{model_name} on {env}: a tilt should change the outputs");
    }
}

#[test]
fn shnn_og3_is_also_invariant_under_reflections_and_shnn_is_not() {
    let (spec, vectors, scalars, heading) = observations("team_reach/2_ants", B, 12);
    let (rv, rh) = reflect(&vectors, &heading);
    for (name, invariant) in [("shnn_og3", true), ("shnn", false)] {
        let (store, mut model) = build(&named(name), &spec, 0, 4);
        let base = run(&mut model, &store, &spec, &vectors, &scalars, &heading);
        let mirrored = run(&mut model, &store, &spec, &rv, &scalars, &rh);
        let d = max_diff(&mirrored, &base);
        assert_eq!(d < 1e-9, invariant, "{name}: reflection changes the outputs by {d}");
        if !invariant {
            assert!(d > 1e-4, "{name}: {d}");
        }
    }
}

#[test]
fn mlp_hn_is_invariant_under_yaw_and_mlp_is_not() {
    for (env, team) in [("team_reach/2_ant_claw", 0), ("team_sumo/2_ants", 1)] {
        let (spec, vectors, scalars, heading) = observations(env, B, 13);
        let (v, h) = transform(&vectors, &heading, 2.1, [3.0, -1.5]);
        for (name, invariant) in [("mlp_hn", true), ("transformer_hn", true), ("mlp", false)] {
            let (store, mut model) = build(&named(name), &spec, team, 6);
            let base = run(&mut model, &store, &spec, &vectors, &scalars, &heading);
            let moved = run(&mut model, &store, &spec, &v, &scalars, &h);
            let d = max_diff(&moved, &base);
            if invariant {
                assert!(d < 1e-9, "{name} on {env}: {d}");
            } else {
                assert!(d > 1e-3, "{name} on {env} should change under a rotation: {d}");
            }
            // A rotation alone (no translation) changes mlp too.
            let (v2, h2) = transform(&vectors, &heading, 0.7, [0.0, 0.0]);
            let d2 = max_diff(&run(&mut model, &store, &spec, &v2, &scalars, &h2), &base);
            assert_eq!(d2 < 1e-9, invariant, "{name} on {env}, rotation only: {d2}");
        }
    }
}

#[test]
fn hnn_hn_and_hnn_dn_are_invariant_under_yaw_and_hnn_only_under_translation() {
    for (env, team) in [("team_reach/2_ant_claw", 0), ("team_sumo/2_ants", 1)] {
        let (spec, vectors, scalars, heading) = observations(env, B, 14);
        // Same parameters, different frames: the goal direction is not the heading.
        let outputs = |name: &str| {
            let (store, mut model) = build(&named(name), &spec, team, 7);
            run(&mut model, &store, &spec, &vectors, &scalars, &heading)
        };
        assert!(max_diff(&outputs("hnn_hn"), &outputs("hnn_dn")) > 1e-6, "{env}");
        for (name, yaw_invariant) in [("hnn_hn", true), ("hnn_dn", true), ("hnn", false)] {
            let (store, mut model) = build(&named(name), &spec, team, 7);
            let base = run(&mut model, &store, &spec, &vectors, &scalars, &heading);
            // A horizontal translation alone leaves every HNN unchanged.
            let (v, h) = transform(&vectors, &heading, 0.0, [2.5, -4.0]);
            let d = max_diff(&run(&mut model, &store, &spec, &v, &scalars, &h), &base);
            assert!(d < 1e-9, "{name} on {env}, translation: {d}");
            let (v, h) = transform(&vectors, &heading, 2.1, [3.0, -1.5]);
            let d = max_diff(&run(&mut model, &store, &spec, &v, &scalars, &h), &base);
            if yaw_invariant {
                assert!(d < 1e-9, "{name} on {env}: {d}");
            } else {
                assert!(d > 1e-3, "{name} on {env} should change under a rotation: {d}");
            }
        }
    }
}

/// `ModelKind::is_equivariant` is what the models do: the equivariant kinds give the same
/// policy and value for a scene rotated about the vertical and translated, the others
/// (`mlp`, `hnn`: the world frame) change.
#[test]
fn every_kind_is_invariant_exactly_when_it_says_so() {
    let (spec, vectors, scalars, heading) = observations("team_reach/2_ants", B, 15);
    let (v, h) = transform(&vectors, &heading, 1.3, [2.0, -3.5]);
    for kind in ModelKind::ALL {
        let (store, mut model) = build(&named(kind.name()), &spec, 0, 8);
        let base = run(&mut model, &store, &spec, &vectors, &scalars, &heading);
        let d = max_diff(&run(&mut model, &store, &spec, &v, &scalars, &h), &base);
        if kind.is_equivariant() {
            assert!(d < 1e-9, "{kind}: {d}");
        } else {
            assert!(d > 1e-3, "{kind} should change under a rotation: {d}");
        }
    }
}

#[test]
fn forward_on_every_builtin_environment_for_every_model() {
    for env in BUILTIN_NAMES {
        let mut venv = VecEnv::from_name(env, 2, 1, StartMode::Random).unwrap();
        let na = venv.n_actions();
        venv.step(&vec![0.5; 2 * na]).unwrap();
        let spec = venv.scene().obs_spec.clone();
        for kind in ModelKind::ALL {
            let name = kind.name();
            for team in 0..spec.n_teams {
                let mut store = ParamStore::<f32>::new();
                let mut init = nn::init_rng(0);
                let prefix = format!("team{team}");
                let mut model = Model::new(&mut store.scope(&prefix, &mut init), &named(name), &spec, team).unwrap();
                assert!(store.names().iter().all(|n| n.starts_with(&format!("{prefix}."))));
                assert_eq!(model.num_params(&store), store.num_elements());
                let tape = Tape::new();
                let p = store.bind(&tape);
                let out = model.forward_batch(&p, &venv.obs().rows()).unwrap();
                let own: Vec<usize> = (0..spec.n_agents).filter(|&a| spec.agent_team[a] == team).collect();
                assert_eq!(model.agents(), own.as_slice());
                assert_eq!(out.agents.len(), own.len(), "{name} on {env}");
                for (a, pol) in own.iter().zip(&out.agents) {
                    assert_eq!(pol.agent, *a);
                    let dof = spec.agent_dof[*a];
                    assert_eq!(pol.loc.shape(), [2, dof], "{name} on {env} agent {a}");
                    assert_eq!(pol.scale.shape(), [2, dof], "{name} on {env} agent {a}");
                    assert!(pol.loc.value().all_finite() && pol.scale.value().all_finite(), "{name} on {env}");
                    assert!(pol.std().value().data().iter().all(|&s| s >= 0.001));
                    // One MLP head per agent, or one Transformer or GNN head for the team.
                    let own_head = store.num_elements_under(&format!("{prefix}.actor.{a}."));
                    assert_eq!(own_head > 0, kind.head() == Head::Mlp, "{name}");
                }
                assert_eq!(out.team_value().unwrap().shape(), [2], "{name} on {env}");
                assert!(out.team_value().unwrap().value().all_finite(), "{name} on {env}");
                // Acting skips the value network and gets the same policy, to the bit.
                let obs = venv.obs();
                let acting = model.forward_policy_batch(&p, &obs.rows()).unwrap();
                assert!(acting.value.is_none() && acting.team_value().is_err(), "{name} on {env}");
                assert_eq!(acting.assignment, out.assignment, "{name} on {env}");
                for (x, y) in out.agents.iter().zip(&acting.agents) {
                    assert_eq!(x.loc.value().data(), y.loc.value().data(), "{name} on {env}");
                    assert_eq!(x.scale.value().data(), y.scale.value().data(), "{name} on {env}");
                }
                // What the kind says of the model is what was built: the entity stage (and a
                // Transformer or GNN head) exist once per team.
                assert_eq!(model.kind(), kind);
                let shared = store.num_elements_under(&format!("{prefix}.entity."));
                assert_eq!(shared > 0, kind.has_entity_stage(), "{name}");
                assert_eq!(model.entity_stage().is_some(), kind.family() == models::kind::Family::Shnn, "{name}");
                let head = store.num_elements_under(&format!("{prefix}.actor.encoder."));
                assert_eq!(head > 0, kind.head() == Head::Transformer, "{name}");
                let gnn = store.num_elements_under(&format!("{prefix}.actor.mp."));
                assert_eq!(gnn > 0, kind.head() == Head::Gnn, "{name}");
            }
        }
    }
}

fn tiny(name: &str) -> ModelDescription {
    let mut d = named(&format!("{name}:head=6;critic_hidden=5"));
    let sizes = MpSizes { vectors: 3, scalars: 4, hidden: 5, layers: 1, steps: 2 };
    match &mut d {
        ModelDescription::Shnn(o) => o.stage.sizes = sizes,
        ModelDescription::Hnn(o) => o.stage.sizes = sizes,
        _ => panic!("{name} has no entity stage"),
    }
    d
}

/// Policy and value of `model` with the parameters `v` (store order) as tape inputs.
fn whole<'t>(model: &RefCell<Model>, obs: &ObsRows<'_, f64>, v: &[Var<'t, f64>]) -> tensor::Result<Var<'t, f64>> {
    let tape = v[0].tape();
    let p = Bound::from_vars(v.to_vec());
    let out = model.borrow_mut().forward_batch(&p, obs).expect("forward");
    let flat = |x: Var<'t, f64>| x.reshape(&[x.value().numel()]);
    let mut parts = Vec::new();
    for a in &out.agents {
        parts.push(flat(a.loc)?);
        parts.push(flat(a.std())?);
    }
    parts.push(out.team_value().unwrap());
    tape.cat(&parts, 0)
}

#[test]
fn gradients_through_whole_small_shnn_shgnn_and_hnn_dn() {
    for (name, env, team) in [
        ("shnn", "team_reach/2_ants", 0),
        ("shnn", "team_sumo/1_centipede", 1),
        ("shgnn", "team_reach/2_ant_claw", 0),
        ("hnn_dn", "team_sumo/2_ants", 1),
    ] {
        let (spec, vectors, scalars, heading) = observations(env, 2, 21);
        let (store, model) = build(&tiny(name), &spec, team, 9);
        let model = RefCell::new(model);
        let obs = ObsRows::new(spec.n_nodes, spec.n_agents, &vectors[..], &scalars[..], &heading[..]).unwrap();
        let params: Vec<Tensor<f64>> = store.values().to_vec();
        let report = check_gradients(|_, v| whole(&model, &obs, v), &params).unwrap();
        assert_eq!(report.checked, store.num_elements(), "{env}");
        // The check can fail: a term the tape does not see is caught.
        let wrong = check_gradients(
            |_, v| {
                let y = whole(&model, &obs, v)?;
                y.add(v[0].detach().square().sum_all())
            },
            &params,
        );
        assert!(wrong.is_err(), "{env}: a detached term must be caught");
    }
}

#[test]
fn unknown_names_and_options_are_errors_listing_the_known_ones() {
    let (spec, ..) = observations("team_reach/1_ant", 1, 0);
    let mut store = ParamStore::<f32>::new();
    let mut init = nn::init_rng(0);
    let mut err = |c: &ModelDescription, team: usize| {
        Model::new(&mut store.scope("m", &mut init), c, &spec, team).unwrap_err().to_string()
    };
    // An option a model does not take cannot be written in Rust; in a string the types
    // reject it as they parse it, naming the model and the options it takes.
    let msg = |s: &str| ModelDescription::parse(s).unwrap_err().to_string();
    let e = msg("resnet");
    for kind in ModelKind::ALL {
        assert!(e.contains(kind.name()), "{e}");
    }
    let e = msg("transformer_hn:assignment=hungarian");
    assert!(e.contains("assignment") && e.contains("transformer_hn"), "{e}");
    let e = msg("mlp:variant=flat;assignment=hungarian");
    assert!(e.contains("assignment") && e.contains("variant"), "{e}");
    let e = msg("hnn:critic=shared");
    assert!(e.contains("critic"), "{e}");
    let e = msg("shnn_so3:gravity=every_layer");
    assert!(e.contains("gravity"), "{e}");
    assert!(err(&named("shnn"), 1).contains("team 1"));
    // Hidden widths are typed as a list: an empty one is refused when the model is built.
    let mut empty = named("mlp_hn");
    if let ModelDescription::Mlp(o) = &mut empty {
        o.network = MlpNetwork::Release {
            assignment: Default::default(),
            hidden: HiddenWidths { head: vec![], critic: vec![8] },
            scorer: Default::default(),
        };
    }
    assert!(err(&empty, 0).contains("hidden"));
    let e = msg("shtransformer:head=8");
    assert!(e.contains("head") && e.contains("shtransformer"), "{e}");
    let e = msg("transformer_hn:translation=none");
    assert!(e.contains("translation") && e.contains("none"), "{e}");
    // Parsing.
    let c = named(
        "shnn:assignment=hungarian;translation=root_mean;abstraction=mean;seed=4;head=32x16;neighbour=raw;\
         critic=shared;gravity=every_layer;actor_steps=2;critic_hidden=8",
    );
    let ModelDescription::Shnn(o) = &c else { panic!("{c:?}") };
    assert_eq!((o.stage.assignment.method, o.stage.assignment.seed), (AssignmentMethod::Hungarian, 4));
    assert_eq!(o.stage.translation, Translation::RootMean);
    assert_eq!(o.stage.abstraction, EntityAbstraction::Mean);
    let hidden = HiddenWidths { head: vec![32, 16], critic: vec![8] };
    assert_eq!(o.model, ShnnModel::Shnn { gravity: models::GravityMode::EveryLayer, hidden });
    assert_eq!(o.stage.neighbour, models::NeighbourOffset::Raw);
    assert_eq!(o.critic, ShnnCritic::Shared);
    assert_eq!(o.stage.actor_steps, 2);
    assert!(Model::new(&mut store.scope("ok", &mut init), &c, &spec, 0).is_ok());
    let e = msg("shnn:depth=3");
    assert!(models::OPTION_KEYS.iter().all(|k| e.contains(k)), "{e}");
    assert!(msg("shnn:critic=big").contains("separate"));
    assert!(msg("shnn:neighbour=far").contains("unit"));
    assert!(msg("shnn:gravity=up").contains("every_layer"));
    assert!(msg("shnn:actor_steps=0").contains("positive"));
    assert!(msg("mlp:variant=deep").contains("release"));
    let e = msg("shnn:assignment=best");
    assert!(["greedy", "hungarian", "stochastic", "none"].iter().all(|k| e.contains(k)), "{e}");
    assert!(msg("shnn:translation=x").contains("body_mean"));
    assert!(msg("shnn:abstraction=x").contains("mean"));
    assert!(msg("shnn:assignment").contains("key=value"));
    assert!(msg("shnn:head=256x0").contains("positive"));
    assert!(msg("gnn").contains("shnn_og3"));
}

/// A rotation matrix (row-major) from a random unit quaternion.
fn random_rotation(r: &mut ChaCha8Rng) -> [[f64; 3]; 3] {
    let q: Vec<f64> = (0..4).map(|_| r.random_range(-1.0..1.0)).collect();
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let (w, x, y, z) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
    [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ]
}

/// Left-multiplies every `[3, m]` block of `x` by `rot`.
fn rotate_blocks(x: &[f64], m: usize, rot: &[[f64; 3]; 3]) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    for (blk, o) in x.chunks(3 * m).zip(out.chunks_mut(3 * m)) {
        for (i, row) in rot.iter().enumerate() {
            for k in 0..m {
                o[i * m + k] = (0..3).map(|j| row[j] * blk[j * m + k]).sum();
            }
        }
    }
    out
}

#[test]
fn shnn_so3_message_passing_is_equivariant_under_any_rotation_with_fixed_scalars() {
    let (spec, vectors, scalars, _) = observations("team_sumo/2_ants", B, 17);
    let obs = ObsBatch::new(B, spec.n_nodes, &vectors[..], &scalars[..]).unwrap();
    let inputs = InputProcessor::new(&spec, Translation::RootMean).unwrap().entities::<f64, f64>(&obs).unwrap();
    let graph = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 0, 0).unwrap().build(&inputs).unwrap();
    let mut r = rng(8);
    for (name, equivariant) in [("shnn_so3", true), ("shnn", false)] {
        let (store, model) = build(&named(name), &spec, 0, 2);
        let mp = model.entity_stage().expect("an SHNN model has an entity stage");
        let m = mp.config.vectors;
        let stage = |z: Vec<f64>| {
            let tape = Tape::new();
            let p = store.bind(&tape);
            let z0 = tape.constant(Tensor::new(z, inputs.z.shape()).unwrap());
            let f = mp.forward(&p, z0, tape.constant(inputs.h.clone()), &graph.edges, None).unwrap();
            (f.z.value().to_vec(), f.h.value().to_vec())
        };
        let (z, h) = stage(inputs.z.to_vec());
        for _ in 0..3 {
            let rot = random_rotation(&mut r);
            let (zr, hr) = stage(rotate_blocks(&inputs.z.to_vec(), 3, &rot));
            let (dz, dh) = (max_diff(&zr, &rotate_blocks(&z, m, &rot)), max_diff(&hr, &h));
            if equivariant {
                assert!(dz < 1e-9 && dh < 1e-9, "{name}: Z' {dz}, h' {dh}");
            } else {
                assert!(dh > 1e-6, "{name}: with gravity a general rotation changes h' ({dh})");
            }
        }
    }
    assert!(
        Model::new(&mut ParamStore::<f64>::new().scope("m", &mut nn::init_rng(0)), &named("mlp"), &spec, 0)
            .unwrap()
            .entity_stage()
            .is_none()
    );
}

/// Parameters of an MLP with layer sizes `sizes` (weights and biases).
fn mlp_params(sizes: &[usize]) -> usize {
    sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
}

/// The counts that follow from the structures and widths (m = 32 vectors, s = 64 scalars,
/// hidden 64 x 2, heads 256, 256; `ns` scalars per node, `ns + 1` per entity), written out
/// here independently of the code, for team 0 of a Reach scene whose agents have `ks` nodes
/// (`K_a`) and `ne` entities.
struct Counts {
    ns: usize,
    ks: Vec<usize>,
    ne: usize,
}

impl Counts {
    const M: usize = 32;
    const S: usize = 64;
    const HD: usize = 64;

    /// One subequivariant message-passing layer: W1 `[2m + 1 + g, m]`, MLP_e, W2
    /// `[2m + g, m]`, MLP_n.
    fn mp_layer(edge_scalars: usize, g: usize) -> usize {
        let (m, s, hd) = (Self::M, Self::S, Self::HD);
        (2 * m + 1 + g) * m
            + mlp_params(&[m * m + 2 * s + edge_scalars, hd, hd, m * m + s])
            + (2 * m + g) * m
            + mlp_params(&[m * m + 2 * s, hd, hd, m * m + s])
    }

    /// The actor's entity stage (embeddings, one layer, W_u).
    fn entity(&self, edge_scalars: usize, g: usize) -> usize {
        let (m, s) = (Self::M, Self::S);
        4 * m + (self.ns + 1) * s + s + Self::mp_layer(edge_scalars, g) + m
    }

    /// SHNN's heads on `[(K_a + slots) rows of 3c + ns, h'_a]`.
    fn shnn_heads(&self, c: usize, slots: usize) -> usize {
        self.ks.iter().map(|&k| mlp_params(&[(k + slots) * (3 * c + self.ns) + Self::S, 256, 256, 2 * (k - 1)])).sum()
    }

    /// The separate critic: its stage (no W_u; 64 RBF + 2 edge types) and MLP on `ne` h'.
    fn critic(&self) -> usize {
        let (m, s) = (Self::M, Self::S);
        4 * m + (self.ns + 1) * s + s + Self::mp_layer(66, 0) + mlp_params(&[self.ne * s, 256, 256, 1])
    }

    /// The release's MLP: node embeddings and per-agent heads on `K_a + 2` rows of 128.
    fn mlp_policy(&self) -> usize {
        let embed = (9 * 64 + 64) + (self.ns * 64 + 64);
        embed + self.ks.iter().map(|&k| mlp_params(&[(k + 2) * 128, 256, 256, 2 * (k - 1)])).sum::<usize>()
    }

    /// The release MLP's critic.
    fn mlp_critic(&self) -> usize {
        (9 * 64 + 64) + (self.ns * 64 + 64) + mlp_params(&[self.ne * 128, 256, 256, 1])
    }

    /// A Transformer head for `f` token features and `out` outputs per token.
    fn transformer(f: usize, out: usize) -> usize {
        (f + 1) * 128 + 3 * 132_480 + (128 + f + 1) * out
    }
}

/// The parameter counts of the table in `docs/MODELS.md` ("Parameter counts"),
/// team 0 of `team_reach/3_ant_claw_centipede` (all three agents), part by part, against
/// the counts the structures imply; and those counts with the release's widths give the
/// release's own figures.
#[test]
fn parameter_counts_of_the_docs_table() {
    let (spec, ..) = observations("team_reach/3_ant_claw_centipede", 1, 0);
    let ks: Vec<usize> = (0..3).map(|a| 1 + spec.agent_dof[a]).collect();
    assert_eq!(ks, [9, 17, 15]);
    // The release's node rows carry 9 scalars (18 features with the 9 vector components)
    // for SHNN and 10 for its MLP; its policies are 771,916 and 1,759,116 parameters (the
    // paper's Table: SHNN 0.772M, MLP+HN 1.759M).
    let release_shnn = Counts { ns: 9, ks: ks.clone(), ne: 6 };
    assert_eq!(release_shnn.entity(0, 0) + release_shnn.shnn_heads(3, 1), 771_916);
    let c = Counts { ns: 10, ks, ne: 6 };
    assert_eq!(c.mlp_policy(), 1_759_116);
    let (m, s) = (Counts::M, Counts::S);
    let gnn = 4 * m + (10 + s + 1) * s + s + Counts::mp_layer(1, 0) + mlp_params(&[3 * m + s, 2]);
    let hnn_entity = mlp_params(&[9 + 11, s]) + mlp_params(&[2 * s + 3, 64, 64, s]) + mlp_params(&[2 * s, 64, 64, s]);
    let hnn_heads: usize = c.ks.iter().map(|&k| mlp_params(&[(k + 1) * 19 + s, 256, 256, 2 * (k - 1)])).sum();
    let flat_heads: usize =
        (0..3).map(|a| mlp_params(&[spec.agent_view(a).len() * 19, 256, 256, 256, 2 * (c.ks[a] - 1)])).sum();
    // (model, entity stage, actor, critic)
    let expected = [
        ("shnn", c.entity(0, 0), c.shnn_heads(3, 1), c.critic()),
        ("shnn_og3", c.entity(0, 0), c.shnn_heads(m, 1), c.critic()),
        ("shnn_so3", c.entity(0, 0) - m, c.shnn_heads(3, 1), c.critic() - m),
        ("mlp", 0, c.mlp_policy(), c.mlp_critic()),
        ("mlp_hn", 0, c.mlp_policy(), c.mlp_critic()),
        ("mlp_hn:variant=flat", 0, flat_heads, mlp_params(&[spec.n_nodes * 19, 256, 256, 256, 1])),
        ("transformer_hn", 0, Counts::transformer(19, 2), Counts::transformer(19, 1)),
        (
            "shtransformer",
            c.entity(0, 0),
            Counts::transformer(3 * 3 + 10 + s, 2),
            c.critic() - mlp_params(&[6 * s, 256, 256, 1]) + Counts::transformer(s, 1),
        ),
        ("shgnn", c.entity(0, 0), gnn, c.critic()),
        ("shnn:critic=shared", c.entity(0, 0), c.shnn_heads(3, 1), mlp_params(&[6 * s, 256, 256, 1])),
        ("shnn:neighbour=none;translation=assigned_entity", c.entity(1, 0), c.shnn_heads(3, 0), c.critic()),
        ("shnn:gravity=every_layer", c.entity(0, 1), c.shnn_heads(3, 1), c.critic() + 2 * m),
        ("shnn:neighbour=raw", c.entity(1, 0), c.shnn_heads(3, 1), c.critic()),
        ("hnn", hnn_entity, hnn_heads, mlp_params(&[6 * s, 256, 256, 1])),
        ("hnn_dn", hnn_entity, hnn_heads, mlp_params(&[6 * s, 256, 256, 1])),
    ];
    for (name, entity, actor, critic) in expected {
        let (store, model) = build(&named(name), &spec, 0, 0);
        let part = |p: &str| store.num_elements_under(&format!("team.{p}"));
        let got = (part("entity."), part("actor."), part("critic."));
        assert_eq!(got, (entity, actor, critic), "{name}: update the table in docs/MODELS.md");
        let counts = model.param_counts(&store);
        assert_eq!((counts.policy, counts.critic), (entity + actor, critic), "{name}");
        assert_eq!(model.num_params(&store), entity + actor + critic, "{name}");
        eprintln!("{name}: policy {} critic {} (entity {entity}, actor {actor})", counts.policy, counts.critic);
    }
}

/// Team Sumo is symmetric: team 1's model on a scene whose teams swapped places sees what
/// team 0's model (same parameter values) sees on the original scene, because each reads the
/// entity types from its own team's view (own, opponent, centre).
#[test]
fn sumo_team_1_sees_the_scene_from_its_own_side() {
    let (spec, vectors, scalars, heading) = observations("team_sumo/2_ants", B, 31);
    // Node blocks of the two teams (both are two ants) and the centre ball.
    let half = spec.agent_root_node[2];
    assert_eq!(half * 2 + 1, spec.n_nodes);
    let swap_nodes = |x: &[f64], width: usize, keep: usize| {
        let mut out = x.to_vec();
        for b in 0..B {
            for n in 0..half {
                for k in keep..width {
                    let (i, j) = ((b * spec.n_nodes + n) * width + k, (b * spec.n_nodes + n + half) * width + k);
                    out[i] = x[j];
                    out[j] = x[i];
                }
            }
        }
        out
    };
    // Vectors and the physical scalars move with the agents; the entity-type columns are the
    // raw observation's (team 0's view) of the swapped scene.
    let sv = swap_nodes(&vectors, NODE_VECTOR_LEN, 0);
    let ss = swap_nodes(&scalars, N_SCALARS, 3);
    let sh: Vec<f64> = heading.chunks(4).flat_map(|h| [h[2], h[3], h[0], h[1]]).collect();
    for name in ["shnn", "mlp_hn", "shgnn"] {
        let (s0, mut m0) = build(&named(name), &spec, 0, 6);
        let (s1, mut m1) = build(&named(name), &spec, 1, 6);
        assert_eq!(
            s0.values().iter().map(|t| t.to_vec()).collect::<Vec<_>>(),
            s1.values().iter().map(|t| t.to_vec()).collect::<Vec<_>>()
        );
        let own = run(&mut m0, &s0, &spec, &vectors, &scalars, &heading);
        let mirrored = run(&mut m1, &s1, &spec, &sv, &ss, &sh);
        assert!(max_diff(&own, &mirrored) < 1e-9, "{name}: {}", max_diff(&own, &mirrored));
        // Without the view (team 1 fed team 0's column order for its own agents) it differs.
        let mut wrong = ss.clone();
        spec.to_team_view(1, &mut wrong).unwrap();
        let other = run(&mut m1, &s1, &spec, &sv, &wrong, &sh);
        assert!(max_diff(&own, &other) > 1e-6, "{name}");
    }
}

/// The release's MLP (`mlp_hn`) against a plain hand computation of its formula
/// (`models/MLP.py`: per-row affine embeddings of the 9 vector components and the scalars,
/// rows = own nodes, own root, assigned ball, positions relative to the own root in the
/// heading frame; 256, 256 per agent; the critic on every entity root relative to the mean
/// root), which the model computes with the embedding folded into the first layer.
#[test]
fn release_mlp_matches_its_formula_computed_by_hand() {
    let (spec, vectors, scalars, heading) = observations("team_reach/2_ants", B, 41);
    let (mut store, mut model) = build(&named("mlp_hn"), &spec, 0, 12);
    let mut r = rng(3);
    // Generic biases (zero biases would hide a misplaced one).
    let ids: Vec<nn::ParamId> =
        store.names().iter().filter(|n| n.ends_with("bias")).map(|n| store.find(n).unwrap()).collect();
    for id in ids {
        let t = store.get(id).clone();
        let v: Vec<f64> = (0..t.numel()).map(|_| r.random_range(-0.5..0.5)).collect();
        store.set(id, Tensor::new(v, t.shape()).unwrap()).unwrap();
    }
    let got = run(&mut model, &store, &spec, &vectors, &scalars, &heading);
    let param = |n: &str| store.get(store.find(&format!("team.{n}")).unwrap()).to_vec();
    let obs = ObsBatch::new(B, spec.n_nodes, &vectors[..], &scalars[..]).unwrap();
    // A node's 19 features seen from `origin` in the frame of heading `yaw`.
    let row = |b: usize, node: usize, origin: [f64; 3], yaw: f64| -> Vec<f64> {
        let (s, c) = yaw.sin_cos();
        let mut f = Vec::new();
        for k in 0..3 {
            let mut v = obs.vec3(b, node, k);
            if k == 0 {
                (0..3).for_each(|i| v[i] -= origin[i]);
            }
            f.extend([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]]);
        }
        f.extend((0..10).map(|i| obs.scalar(b, node, i)));
        f
    };
    let affine = |x: &[f64], w: &[f64], bias: &[f64], relu: bool| -> Vec<f64> {
        let out = bias.len();
        (0..out)
            .map(|j| {
                let y = bias[j] + x.iter().enumerate().map(|(i, xi)| xi * w[i * out + j]).sum::<f64>();
                if relu { y.max(0.0) } else { y }
            })
            .collect()
    };
    // [e^z of every row, then e^h of every row] through `layers` MLP layers under `prefix`.
    let mlp = |rows: &[Vec<f64>], embed: &str, prefix: &str| -> Vec<f64> {
        let (ez, eh): (Vec<f64>, Vec<f64>) = (
            rows.iter()
                .flat_map(|x| {
                    affine(
                        &x[..9],
                        &param(&format!("{embed}.embed_z.weight")),
                        &param(&format!("{embed}.embed_z.bias")),
                        false,
                    )
                })
                .collect(),
            rows.iter()
                .flat_map(|x| {
                    affine(
                        &x[9..],
                        &param(&format!("{embed}.embed_h.weight")),
                        &param(&format!("{embed}.embed_h.bias")),
                        false,
                    )
                })
                .collect(),
        );
        let mut h: Vec<f64> = ez.into_iter().chain(eh).collect();
        for i in 0..3 {
            h = affine(&h, &param(&format!("{prefix}.{i}.weight")), &param(&format!("{prefix}.{i}.bias")), i < 2);
        }
        h
    };
    let graph_inputs = InputProcessor::new(&spec, Translation::RootMean).unwrap().entities::<f64, f64>(&obs).unwrap();
    let graph = GraphBuilder::new(&spec, AssignmentMethod::Greedy, 0, 0).unwrap().build(&graph_inputs).unwrap();
    let mut want = Vec::new();
    for a in 0..2 {
        let (root, k) = (spec.agent_root_node[a], 1 + spec.agent_dof[a]);
        let outs: Vec<Vec<f64>> = (0..B)
            .map(|b| {
                let (o, yaw) = (obs.vec3(b, root, 0), heading[b * 2 + a]);
                let ball = spec.entity_root_node[graph.agent_entity[b * 2 + a]];
                let mut rows: Vec<Vec<f64>> = (root..root + k).map(|n| row(b, n, o, yaw)).collect();
                rows.push(row(b, root, o, yaw));
                rows.push(row(b, ball, o, yaw));
                mlp(&rows, "actor", &format!("actor.{a}"))
            })
            .collect();
        let dof = k - 1;
        want.extend(outs.iter().flat_map(|o| o[..dof].to_vec()));
        want.extend(outs.iter().flat_map(|o| o[dof..].to_vec()));
    }
    for b in 0..B {
        let roots: Vec<usize> = spec.entity_root_node.clone();
        let mut c = [0.0; 3];
        for &n in &roots {
            (0..3).for_each(|i| c[i] += obs.vec3(b, n, 0)[i] / roots.len() as f64);
        }
        let rows: Vec<Vec<f64>> = roots.iter().map(|&n| row(b, n, c, heading[b * 2])).collect();
        want.extend(mlp(&rows, "critic", "critic.mlp"));
    }
    assert!(max_diff(&got, &want) < 1e-10, "{}", max_diff(&got, &want));
}
