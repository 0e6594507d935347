//! Invariance end to end: the observation normaliser the trainer builds by default
//! (`obs_norm = "auto"`, the invariant normaliser) followed by every invariant model gives the
//! same action distribution and value for a raw observation and for the same scene rotated
//! about the vertical through a random point and translated horizontally, in f64 to 1e-9.
//! The test can fail: the per-node normaliser it replaced breaks this for every model, and
//! `mlp` (not invariant) changes.
//!
//! Only the public model interface is used (`ModelDescription::parse`, `Model::new`,
//! `Model::forward_batch` on `ObsRows`, `PolicyOutput`), with the raw observation arrays
//! of a `VecEnv` in its layout (`[B, N, 3, 3]` vectors: position, velocity, angular
//! velocity per node; `[B, N, N_SCALARS]` scalars; `[B, A]` headings).

use envs::layout::ObsRows;
use envs::layout::ObsSpec;
use envs::tasks::{StartMode, VecEnv};
use models::{Model, ModelDescription, ModelKind};
use nn::ParamStore;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rl::mappo::normalizer::{CLIP, ObsNormalizer};
use rl::{ObsNormKind, Preset, TrainConfig};
use tensor::Tape;

/// Rows of the observation batch the models see.
const B: usize = 4;

/// Raw observations of a scene after random actions: `(spec, vectors, scalars, headings)` of
/// the last step's `B` rows in f64, and every visited step's (vectors, scalars) in f32 (the
/// normaliser's training data).
struct Scene {
    spec: ObsSpec,
    vectors: Vec<f64>,
    scalars: Vec<f64>,
    heading: Vec<f64>,
    visited: Vec<(Vec<f32>, Vec<f32>)>,
}

fn scene(name: &str, seed: u64) -> Scene {
    let mut env = VecEnv::from_name(name, 8, seed, StartMode::Random).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let na = env.n_actions();
    let mut visited = vec![(env.obs().vectors.clone(), env.obs().scalars.clone())];
    for _ in 0..40 {
        let actions: Vec<f32> = (0..8 * na).map(|_| rng.random_range(-1.0..1.0f32)).collect();
        env.step(&actions).unwrap();
        visited.push((env.obs().vectors.clone(), env.obs().scalars.clone()));
    }
    let spec = env.scene().obs_spec.clone();
    let o = env.obs();
    let first = o.rows().slice(0..B);
    let f64s = |x: &[f32]| x.iter().map(|&v| v as f64).collect::<Vec<_>>();
    Scene { vectors: f64s(first.vectors), scalars: f64s(first.scalars), heading: f64s(first.heading), spec, visited }
}

/// The normaliser a default configuration builds for `env`, after the visited observations.
fn default_normaliser(env: &str, s: &Scene) -> ObsNormalizer {
    let config = TrainConfig::preset(Preset::Quick, env);
    assert_eq!(config.obs_norm, ObsNormKind::Auto);
    let mut n = ObsNormalizer::new(config.obs_norm.resolve(), &s.spec);
    for (v, sc) in &s.visited {
        n.update(v, sc);
    }
    n
}

/// The per-node normaliser this one replaced, for contrast: every 3-vector (positions
/// included) divided by the running RMS norm of its node and kind, its norm clipped to
/// `CLIP`; scalars as the default normaliser.
struct PerNode {
    inv: Vec<f64>,
    scalars: ObsNormalizer,
}

impl PerNode {
    fn new(s: &Scene, scalars: ObsNormalizer) -> PerNode {
        let n3 = s.spec.n_nodes * 3;
        let (mut sum, mut count) = (vec![0.0f64; n3], 0.0);
        for (v, _) in &s.visited {
            for row in v.chunks_exact(n3 * 3) {
                for (j, x) in row.chunks_exact(3).enumerate() {
                    sum[j] += x.iter().map(|&c| (c as f64).powi(2)).sum::<f64>();
                }
                count += 1.0;
            }
        }
        PerNode { inv: sum.iter().map(|x| 1.0 / (x / count).sqrt().max(1e-3)).collect(), scalars }
    }

    fn apply(&self, v: &[f64], s: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (mut ov, mut os) = (vec![], vec![]);
        self.scalars.apply(v, s, &mut ov, &mut os);
        let mut out = v.to_vec();
        for row in out.chunks_exact_mut(self.inv.len() * 3) {
            for (j, x) in row.chunks_exact_mut(3).enumerate() {
                let mut k = self.inv[j];
                let norm = x.iter().map(|c| c * c).sum::<f64>().sqrt() * k;
                if norm > CLIP as f64 {
                    k *= CLIP as f64 / norm;
                }
                x.iter_mut().for_each(|c| *c *= k);
            }
        }
        (out, os)
    }
}

/// The scene rotated by `angle` about the vertical through `point`, then translated by `t`:
/// positions `q + R (p - q) + t`, velocities and angular velocities `R v`, headings shifted
/// by the angle (wrapped to (-pi, pi] as the environment writes them), scalars unchanged.
fn moved(s: &Scene, angle: f64, point: [f64; 2], t: [f64; 2]) -> (Vec<f64>, Vec<f64>) {
    let (sn, c) = angle.sin_cos();
    let mut v = s.vectors.clone();
    for (i, q) in v.chunks_exact_mut(3).enumerate() {
        let (mut x, mut y) = (q[0], q[1]);
        if i % 3 == 0 {
            x -= point[0];
            y -= point[1];
        }
        q[0] = c * x - sn * y;
        q[1] = sn * x + c * y;
        if i % 3 == 0 {
            q[0] += point[0] + t[0];
            q[1] += point[1] + t[1];
        }
    }
    let h = s.heading.iter().map(|h| (h + angle).sin().atan2((h + angle).cos())).collect();
    (v, h)
}

fn build(name: &str, spec: &ObsSpec, team: usize) -> (ParamStore<f64>, Model) {
    let mut store = ParamStore::<f64>::new();
    let mut init = nn::init_rng(17);
    let config = ModelDescription::parse(name).unwrap();
    let model = Model::new(&mut store.scope(&format!("team{team}"), &mut init), &config, spec, team).unwrap();
    (store, model)
}

/// Every agent's loc and scale, then the value, of normalised observations.
fn outputs(model: &mut Model, store: &ParamStore<f64>, spec: &ObsSpec, v: &[f64], s: &[f64], h: &[f64]) -> Vec<f64> {
    let tape = Tape::<f64>::new();
    let p = store.bind(&tape);
    let obs = ObsRows::new(spec.n_nodes, spec.n_agents, v, s, h).unwrap();
    assert_eq!(obs.len(), B);
    let out = model.forward_batch(&p, &obs).unwrap();
    let mut all = Vec::new();
    for a in &out.agents {
        all.extend(a.loc.value().data());
        all.extend(a.scale.value().data());
    }
    all.extend(out.team_value().unwrap().value().data());
    all
}

/// Largest difference relative to `max(1, |a|)`.
fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs() / x.abs().max(1.0)).fold(0.0, f64::max)
}

#[test]
fn normaliser_and_invariant_models_commute_with_rotations_about_gravity_and_translations() {
    let mut cases: Vec<(&str, &str, usize)> =
        ModelKind::ALL.iter().filter(|k| k.is_equivariant()).map(|k| ("team_reach/2_ants", k.name(), 0)).collect();
    for team in 0..2 {
        cases.push(("team_sumo/2_ants", "shnn", team));
        cases.push(("team_sumo/2_ants", "mlp_hn", team));
    }
    let mut scenes: Vec<(&str, Scene)> = Vec::new();
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    for (env, name, team) in cases {
        if !scenes.iter().any(|(e, _)| *e == env) {
            scenes.push((env, scene(env, 3)));
        }
        let s = &scenes.iter().find(|(e, _)| *e == env).unwrap().1;
        let norm = default_normaliser(env, s);
        // Non-trivial statistics: a position scale and velocity scales far from 1.
        assert!(norm.vectors.count > 100.0 && (norm.position_scale() - 1.0).abs() > 0.1, "{}", norm.describe());
        let old = PerNode::new(s, norm.clone());
        let (store, mut model) = build(name, &s.spec, team);
        let (mut nv, mut ns) = (vec![], vec![]);
        norm.apply(&s.vectors, &s.scalars, &mut nv, &mut ns);
        let base = outputs(&mut model, &store, &s.spec, &nv, &ns, &s.heading);
        let (ov, os) = old.apply(&s.vectors, &s.scalars);
        let old_base = outputs(&mut model, &store, &s.spec, &ov, &os, &s.heading);
        for _ in 0..3 {
            let angle = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let point = [rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0)];
            let t = [rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0)];
            let (mv, mh) = moved(s, angle, point, t);
            norm.apply(&mv, &s.scalars, &mut nv, &mut ns);
            let d = max_diff(&outputs(&mut model, &store, &s.spec, &nv, &ns, &mh), &base);
            assert!(d < 1e-9, "{name} on {env} team {team}, angle {angle} point {point:?} shift {t:?}: {d}");
            // The per-node normaliser turns the translation into different shifts per node.
            let (ov, os) = old.apply(&mv, &s.scalars);
            let d_old = max_diff(&outputs(&mut model, &store, &s.spec, &ov, &os, &mh), &old_base);
            assert!(d_old > 1e-6, "{name} on {env} team {team}: the per-node normaliser should break it ({d_old})");
        }
    }
    // A model that is not invariant changes.
    let (env, s) = &scenes[0];
    let norm = default_normaliser(env, s);
    let (store, mut model) = build("mlp", &s.spec, 0);
    let (mut nv, mut ns) = (vec![], vec![]);
    norm.apply(&s.vectors, &s.scalars, &mut nv, &mut ns);
    let base = outputs(&mut model, &store, &s.spec, &nv, &ns, &s.heading);
    let (mv, mh) = moved(s, 1.1, [0.5, -1.0], [2.0, 3.0]);
    norm.apply(&mv, &s.scalars, &mut nv, &mut ns);
    let d = max_diff(&outputs(&mut model, &store, &s.spec, &nv, &ns, &mh), &base);
    assert!(d > 1e-3, "mlp should change under a rotation and translation: {d}");
}
