//! Property tests (proptest): the training configuration survives its TOML file, a
//! checkpoint survives save and load bit for bit, and the normaliser's statistics do not
//! depend on how the observations were grouped into batches (to a stated tolerance: the
//! normaliser promises a fixed order, not associativity). Case counts are kept small so that
//! the file runs in seconds in release mode.

use crate::common;

use std::sync::OnceLock;

use common::TempDir;
use envs::tasks::BUILTIN_NAMES;
use proptest::prelude::*;
use rl::mappo::checkpoint::Checkpoint;
use rl::mappo::normalizer::RunningStats;
use rl::{EntropyKind, NormStart, ObsNormKind, Preset, RunDir, TrainConfig, TrainOptions};

/// Model specifications valid for every environment (options of `models::ModelDescription::parse`).
const MODELS: [&str; 8] = [
    "shnn",
    "mlp_hn",
    "mlp:head=4;critic_hidden=8x8",
    "shnn:assignment=hungarian;neighbour=raw;critic=shared",
    "shtransformer",
    "hnn_dn:actor_steps=2",
    "shnn:translation=assigned_entity;gravity=every_layer;seed=7",
    "transformer_hn",
];

/// Any finite f64 in `[lo, hi]`, from every part of the range: round values, the ends, and
/// arbitrary bit patterns (many digits, subnormals when `lo` is 0).
fn float_in(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(lo),
        Just(hi),
        (lo..=hi),
        any::<u64>().prop_map(move |bits| {
            let x = f64::from_bits(bits).abs();
            if x.is_finite() && x >= lo && x <= hi { x } else { lo + (hi - lo) * (bits as f64 / u64::MAX as f64) }
        }),
    ]
}

/// Valid training configurations with every field drawn (sizes kept consistent).
fn train_configs() -> impl Strategy<Value = TrainConfig> {
    let env = prop_oneof![
        proptest::sample::select(BUILTIN_NAMES.to_vec()).prop_map(|s: &str| s.to_string()),
        (1u32..=3, float_in(0.5, 1000.0)).prop_map(|(n, r)| {
            let agents = ["ant", "claw", "centipede"][..n as usize].join("+");
            format!("team_reach:agents={agents};R={r};balls={n}")
        }),
    ];
    let sizes = (0u32..=4, 0u32..=4, 0u32..=4, 1usize..=5).prop_map(|(e, b, m, u)| {
        // num_envs divides batch_size * num_minibatches.
        (1usize << e, 1usize << (e + b), 1usize << m, u)
    });
    let scalars = (
        float_in(0.0, 1.0),
        float_in(0.0, 1.0),
        float_in(0.0, 10.0),
        float_in(0.0, 10.0),
        float_in(0.0, 1.0),
        float_in(1e-12, 1.0),
        float_in(0.0, 100.0),
        float_in(0.0, 1e3),
        float_in(0.0, 1.0),
    );
    let rotations = proptest::collection::vec(float_in(-720.0, 720.0), 0..4).prop_map(|extra| {
        let mut v = vec![0.0];
        for r in extra {
            if !v.contains(&r) {
                v.push(r);
            }
        }
        v
    });
    let kinds = (
        proptest::sample::select(vec![EntropyKind::TanhNormal, EntropyKind::Normal]),
        proptest::sample::select(vec![
            ObsNormKind::Auto,
            ObsNormKind::Invariant,
            ObsNormKind::Elementwise,
            ObsNormKind::None,
        ]),
        proptest::sample::select(vec![NormStart::Empty, NormStart::FirstObservation]),
    );
    // Seeds and steps mostly in TOML's integer range, sometimes beyond (validation refuses those).
    let big = || prop_oneof![0..=i64::MAX as u64, any::<u64>()];
    let counts = (big(), big(), 1usize..=64, 0usize..=100, 1usize..=4096, 0usize..=1000, 0usize..=64);
    (
        env,
        proptest::sample::select(MODELS.to_vec()),
        sizes,
        scalars,
        rotations,
        kinds,
        counts,
        any::<(bool, bool, bool, bool, bool)>(),
    )
        .prop_map(|(env, model, (ne, bs, nm, ul), s, rot, (ent, norm, start), c, flags)| {
            let mut t = TrainConfig::preset(if flags.4 { Preset::Paper } else { Preset::Quick }, &env);
            t.model = model.to_string();
            t.opponent = if t.is_sumo() && flags.0 { "mlp_hn".into() } else { String::new() };
            (t.num_envs, t.batch_size, t.num_minibatches, t.unroll_length) = (ne, bs, nm, ul);
            (t.discount, t.gae_lambda, t.clip_epsilon, t.value_coef, t.entropy_coef) = (s.0, s.1, s.2, s.3, s.4);
            (t.learning_rate, t.grad_clip, t.reward_scaling, t.curriculum_fraction) = (s.5, s.6, s.7, s.8);
            t.eval_rotations = rot;
            (t.entropy, t.obs_norm, t.obs_norm_start) = (ent, norm, start);
            (t.seed, t.steps, t.epochs, t.num_evals, t.eval_episodes, t.checkpoint_every, t.threads) = c;
            t.steps = t.steps.max(1);
            (t.fixed_start, t.lr_decay, t.eval_deterministic) = (flags.1, flags.2, flags.3);
            t
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    /// A valid configuration written as TOML (a run's `config.toml`) reads back equal, field
    /// for field and bit for bit, through both readers: `TrainConfig::load` (a run's file) and
    /// `TrainConfig::resolve` (a `--config` file over a preset).
    #[test]
    fn a_configuration_survives_its_toml_file(config in train_configs()) {
        prop_assume!(config.validate("generated").is_ok());
        let dir = TempDir::new("prop-config");
        let path = dir.0.join("config.toml");
        config.save(&path).unwrap();
        let loaded = TrainConfig::load(&path).unwrap();
        prop_assert_eq!(&loaded, &config);
        let resolved = TrainConfig::resolve(None, Some(&path), &[]).unwrap();
        prop_assert_eq!(&resolved, &config);
        for (a, b) in [(loaded.discount, config.discount), (loaded.learning_rate, config.learning_rate)] {
            prop_assert_eq!(a.to_bits(), b.to_bits());
        }
        prop_assert_eq!(loaded.to_toml(), config.to_toml());
    }
}

/// A real checkpoint of a tiny run (one iteration of `mlp` on `team_reach/1_ant`), made once.
fn base_checkpoint() -> &'static Checkpoint {
    static BASE: OnceLock<Checkpoint> = OnceLock::new();
    BASE.get_or_init(|| {
        let dir = TempDir::new("prop-checkpoint-base");
        let config = common::tiny("team_reach/1_ant", "mlp:head=8;critic_hidden=8", 1, &[]);
        let run = RunDir::new(&dir.0);
        rl::train(&config, &run, &TrainOptions::default()).unwrap();
        Checkpoint::load(&run.checkpoint()).unwrap()
    })
}

/// Any finite f64, from arbitrary bit patterns (subnormals, -0, huge and tiny values).
fn any_finite_f64() -> impl Strategy<Value = f64> {
    any::<u64>().prop_map(f64::from_bits).prop_filter("finite", |x| x.is_finite())
}

/// Any finite f32 (a network parameter), as the f64 a checkpoint stores.
fn any_finite_f32() -> impl Strategy<Value = f64> {
    any::<u32>().prop_map(f32::from_bits).prop_filter("finite", |x| x.is_finite()).prop_map(f64::from)
}

/// The bits of every number the test changes, for comparison.
fn changed_bits(c: &Checkpoint) -> Vec<u64> {
    let t = &c.teams[0];
    let mut bits: Vec<u64> = t.params.tensors.iter().flat_map(|p| p.data.iter().map(|x| x.to_bits())).collect();
    for s in [&t.normalizer.positions, &t.normalizer.vectors, &t.normalizer.scalars] {
        bits.push(s.count.to_bits());
        bits.extend(s.mean.iter().chain(&s.m2).map(|x| x.to_bits()));
    }
    bits.extend(c.episode_returns.iter().map(|x| x.to_bits()));
    let physics = &c.env.envs[0].physics;
    bits.extend(physics.qpos.iter().chain(&physics.qvel).map(|x| x.to_bits()));
    bits.push(c.wall_s.to_bits());
    bits
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, failure_persistence: None, ..ProptestConfig::default() })]

    /// save -> load -> save gives identical bytes, and every parameter (any finite f32, as
    /// f64), normaliser statistic, running return and physics state value (any finite f64,
    /// subnormals and -0 included) reads back with the same bits.
    #[test]
    fn a_checkpoint_survives_save_and_load_bit_for_bit(
        params in proptest::collection::vec(any_finite_f32(), 64),
        stats in proptest::collection::vec(any_finite_f64(), 64),
        wall_s in float_in(0.0, 1e12),
    ) {
        let mut c = base_checkpoint().clone();
        let t = &mut c.teams[0];
        for (x, p) in t.params.tensors.iter_mut().flat_map(|p| p.data.iter_mut()).zip(params.iter().cycle()) {
            *x = *p;
        }
        let mut k = stats.iter().cycle();
        for s in [&mut t.normalizer.positions, &mut t.normalizer.vectors, &mut t.normalizer.scalars] {
            for x in s.mean.iter_mut().chain(s.m2.iter_mut()) {
                *x = *k.next().unwrap();
            }
        }
        for x in c.episode_returns.iter_mut() {
            *x = *k.next().unwrap();
        }
        let physics = &mut c.env.envs[0].physics;
        for x in physics.qpos.iter_mut().chain(physics.qvel.iter_mut()) {
            *x = *k.next().unwrap();
        }
        c.wall_s = wall_s;
        let dir = TempDir::new("prop-checkpoint");
        // Two directories: the JSON names its tensors file after its own name.
        let (first, second) = (dir.0.join("a/checkpoint.json"), dir.0.join("b/checkpoint.json"));
        for d in ["a", "b"] {
            std::fs::create_dir_all(dir.0.join(d)).unwrap();
        }
        c.save(&first).unwrap();
        let loaded = Checkpoint::load(&first).unwrap();
        prop_assert_eq!(changed_bits(&loaded), changed_bits(&c));
        loaded.save(&second).unwrap();
        prop_assert!(std::fs::read(&first).unwrap() == std::fs::read(&second).unwrap(), "the second save differs");
        let tensors = |d: &str| {
            let files: Vec<Vec<u8>> = std::fs::read_dir(dir.0.join(d))
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|x| x == "safetensors"))
                .map(|p| std::fs::read(p).unwrap())
                .collect();
            files
        };
        prop_assert!(tensors("a").len() == 1 && tensors("a") == tensors("b"), "the tensors files differ");
    }
}

/// Rows of `dim` features with magnitudes up to `scale`.
fn rows(dim: usize) -> impl Strategy<Value = (Vec<f64>, f64)> {
    (1usize..=200, float_in(1e-3, 1e6))
        .prop_flat_map(move |(n, scale)| (proptest::collection::vec(-scale..=scale, n * dim), Just(scale)))
}

/// Statistics of `data` merged batch by batch, the batches cut at `cuts` (sorted row indices)
/// and merged in the order given by `tree`: `false` merges left to right, `true` merges the
/// second half first and then the first half into it (a different association and order).
fn grouped(data: &[f64], dim: usize, cuts: &[usize], tree: bool) -> RunningStats {
    let mut bounds = vec![0];
    bounds.extend(cuts.iter().copied());
    bounds.push(data.len() / dim);
    let batches: Vec<RunningStats> =
        bounds.windows(2).map(|w| RunningStats::from_rows(&data[w[0] * dim..w[1] * dim], dim)).collect();
    let merge_all = |bs: &[RunningStats]| {
        let mut s = RunningStats::new(dim);
        for b in bs {
            s.merge(b);
        }
        s
    };
    if !tree {
        return merge_all(&batches);
    }
    let (left, right) = batches.split_at(batches.len() / 2);
    let mut s = merge_all(right);
    let l = merge_all(left);
    // Merging is symmetric up to rounding: (right) + (left) rather than (left) + (right).
    s.merge(&l);
    s
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, failure_persistence: None, ..ProptestConfig::default() })]

    /// The normaliser promises a fixed order (the same batches give the same bits whatever
    /// the thread count), not associativity: the same rows cut into different batches, or
    /// merged in another order, give the same count exactly, the same mean to 1e-12 x the
    /// largest |x| and the same sum of squared deviations to 1e-10 x n x the largest |x|^2.
    /// Why these bounds: every merge (Chan et al.) adds a few ulps (1.1e-16) relative to these
    /// magnitudes and a case has at most 201 batches, so the error stays below ~1e-13; the
    /// bounds leave two to three orders of magnitude of margin. Merging an empty batch
    /// changes no bit.
    #[test]
    fn normaliser_statistics_do_not_depend_on_the_batching(
        (data, scale) in rows(3),
        cuts_a in proptest::collection::btree_set(0usize..=200, 0..8),
        cuts_b in proptest::collection::btree_set(0usize..=200, 0..8),
        tree in any::<bool>(),
    ) {
        let dim = 3;
        let n = data.len() / dim;
        let cut = |c: &std::collections::BTreeSet<usize>| c.iter().map(|&i| i.min(n)).collect::<Vec<_>>();
        let whole = RunningStats::from_rows(&data, dim);
        let a = grouped(&data, dim, &cut(&cuts_a), false);
        let b = grouped(&data, dim, &cut(&cuts_b), tree);
        for s in [&a, &b] {
            prop_assert_eq!(s.count, n as f64);
            for j in 0..dim {
                prop_assert!((s.mean[j] - whole.mean[j]).abs() <= 1e-12 * scale, "mean {} vs {}", s.mean[j], whole.mean[j]);
                let tol = 1e-10 * n as f64 * scale * scale;
                prop_assert!((s.m2[j] - whole.m2[j]).abs() <= tol, "m2 {} vs {}", s.m2[j], whole.m2[j]);
            }
        }
        let mut same = a.clone();
        same.merge(&RunningStats::new(dim));
        prop_assert_eq!(same, a);
    }
}
