//! MJCF morphologies in the tasks (`envs::mjcf_agent`): MeBen's ant written as MJCF
//! (`tests/data/ant.xml`) against the built-in Brax ant (same model up to round-off except
//! the shins' ground-touching ends; same task spec; same first observations; the same
//! trajectories to a stated tolerance); MuJoCo's own `ant.xml` with its welded bodies fused
//! (same dynamics as the unfused model); every refused construct named by file, line,
//! element, attribute and value, through the task builder too; truncated files never panic.

#![allow(clippy::result_large_err)] // MjcfError carries file/line/element/attribute/value

use envs::brax::{BraxPhysics, add_agent, brax_options};
use envs::mjcf::MjcfError;
use envs::mjcf_agent::{load_agent_file, load_agent_str};
use envs::model::{CapsuleEnds, Model};
use envs::tasks::{Scene, StartMode, TaskError, VecEnv};
use envs::{BodyId, Data, ModelBuilder, forward};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ANT_XML: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/ant.xml");
const MUJOCO_ANT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/mujoco_ant.xml");

fn ant_text() -> String {
    std::fs::read_to_string(ANT_XML).unwrap()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

fn mat_diff(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> f64 {
    max_abs_diff(&a.concat(), &b.concat())
}

/// The scenes of one composition with the Brax ant and with the MJCF ant in its place.
fn scenes(template: &str) -> (Scene, Scene) {
    let brax = Scene::from_name(&template.replace("{ant}", "ant")).unwrap();
    let mjcf = Scene::from_name(&template.replace("{ant}", ANT_XML)).unwrap();
    (brax, mjcf)
}

#[test]
fn the_mjcf_ant_builds_the_brax_ants_model_up_to_round_off() {
    let (brax, mjcf) = scenes("team_reach:agents={ant};R=3");
    let (a, b) = (&brax.model, &mjcf.model);
    assert_eq!((a.nq, a.nv, a.nu(), a.bodies.len(), a.joints.len(), a.geoms.len()), (15, 14, 8, 10, 9, 10));
    assert_eq!((b.nq, b.nv, b.nu(), b.bodies.len(), b.joints.len(), b.geoms.len()), (15, 14, 8, 10, 9, 10));
    // Exact where both files say the same number; 1e-12 where the two loaders reach it by
    // different products (Euler angles in degrees vs radians, fromto vs Brax's collider
    // rotation, inertia rescaled to the mass vs computed from it).
    let tol = 1e-12;
    for (x, y) in a.bodies.iter().zip(&b.bodies) {
        assert_eq!((x.parent, x.mass), (y.parent, y.mass));
        assert!(max_abs_diff(&x.pos, &y.pos) < tol && max_abs_diff(&x.quat, &y.quat) < tol);
        assert!(max_abs_diff(&x.ipos, &y.ipos) < tol && mat_diff(&x.inertia, &y.inertia) < tol);
    }
    for (x, y) in a.joints.iter().zip(&b.joints) {
        assert_eq!((x.kind, x.body, x.limited, x.damping), (y.kind, y.body, y.limited, y.damping));
        assert!((x.armature - y.armature).abs() < tol, "Brax's 350 / 1000 is 0.35000000000000003");
        assert!(max_abs_diff(&x.axis, &y.axis) < tol && max_abs_diff(&x.anchor, &y.anchor) < tol);
        assert!(max_abs_diff(&x.range, &y.range) < tol);
    }
    assert!(max_abs_diff(&a.qpos0, &b.qpos0) < tol);
    for (x, y) in a.actuators.iter().zip(&b.actuators) {
        assert_eq!((x.joint, x.gear, x.ctrlrange), (y.joint, y.gear, y.ctrlrange));
    }
    // Geoms: same shapes and centres, capsule axes parallel (the roll about the axis differs
    // and means nothing). The one physical difference: Brax's shins touch the ground only
    // with the foot cap (`end: -1`); MJCF capsules touch with both.
    let mut shins = 0;
    for (x, y) in a.geoms.iter().zip(&b.geoms) {
        assert_eq!((x.body, x.friction, x.contype, x.conaffinity), (y.body, y.friction, y.contype, y.conaffinity));
        match (x.shape, y.shape) {
            (
                envs::Shape::Capsule { radius: r1, half_length: h1 },
                envs::Shape::Capsule { radius: r2, half_length: h2 },
            ) => {
                assert!((r1 - r2).abs() < tol && (h1 - h2).abs() < tol);
                let (ax, ay) = ([x.mat[0][2], x.mat[1][2], x.mat[2][2]], [y.mat[0][2], y.mat[1][2], y.mat[2][2]]);
                let dot: f64 = ax.iter().zip(&ay).map(|(p, q)| p * q).sum();
                assert!((dot.abs() - 1.0).abs() < tol, "capsule axes {ax:?} {ay:?}");
            }
            (s1, s2) => assert_eq!(s1, s2),
        }
        assert!(max_abs_diff(&x.pos, &y.pos) < tol);
        assert_eq!(y.ends, CapsuleEnds::Both);
        if x.ends != CapsuleEnds::Both {
            shins += 1;
        }
    }
    assert_eq!(shins, 4);
}

#[test]
fn the_mjcf_ant_gives_the_brax_ants_task_spec_and_first_observation() {
    for template in [
        "team_reach:agents={ant}+claw;R=5;balls=2",
        "team_sumo:team1=claw+{ant};team2={ant}+ant;R=3",
        "team_reach:agents={ant}",
    ] {
        let (brax, mjcf) = scenes(template);
        // Nodes, parents, DoF, action slices, entity and limb types, limits: all equal (the
        // limb types of the MJCF ant's MuJoCo-style names come from the depth rule, the Brax
        // ant's from the release's table: torso, thigh, leg alike).
        let (mut sa, mut sb) = (brax.obs_spec.clone(), mjcf.obs_spec.clone());
        let limits = |s: &mut envs::layout::ObsSpec| std::mem::take(&mut s.static_scalars);
        let (la, lb) = (limits(&mut sa), limits(&mut sb));
        assert_eq!(sa, sb, "{template}");
        // The scaled limits go through degrees -> radians -> degrees by different products.
        assert_eq!(la.len(), lb.len());
        assert!(la.iter().zip(&lb).all(|(x, y)| (x - y).abs() <= 1e-6), "{template}");
        assert_eq!(brax.n_actions, mjcf.n_actions);
        for (x, y) in brax.agents.iter().zip(&mjcf.agents) {
            assert_eq!((x.nq, x.nv, x.action_offset, x.n_actions()), (y.nq, y.nv, y.action_offset, y.n_actions()));
            assert!((x.rest_height - y.rest_height).abs() < 1e-12 && (x.footprint - y.footprint).abs() < 1e-12);
        }
        // Same seed: the same starts, so the same first observation (f32: equal to its
        // rounding).
        let mut ea = VecEnv::new(&brax.spec, 8, 3, StartMode::Random).unwrap();
        let mut eb = VecEnv::new(&mjcf.spec, 8, 3, StartMode::Random).unwrap();
        let (oa, ob) = (ea.reset().clone(), eb.reset().clone());
        let close = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(p, q)| (p - q).abs() <= 1e-6);
        assert!(close(&oa.vectors, &ob.vectors) && close(&oa.scalars, &ob.scalars) && close(&oa.heading, &ob.heading));
    }
}

/// Max |qpos difference| between the two VecEnvs after each of `steps` control steps of the
/// same random actions (16 environments, same seed).
fn task_divergence(brax: &Scene, mjcf: &Scene, steps: usize) -> Vec<f64> {
    let batch = 16;
    let mut ea = VecEnv::new(&brax.spec, batch, 11, StartMode::Random).unwrap();
    let mut eb = VecEnv::new(&mjcf.spec, batch, 11, StartMode::Random).unwrap();
    ea.set_auto_reset(false);
    eb.set_auto_reset(false);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    (0..steps)
        .map(|_| {
            let actions: Vec<f32> = (0..batch * ea.n_actions()).map(|_| rng.random_range(-1.0f32..1.0)).collect();
            ea.step(&actions).unwrap();
            eb.step(&actions).unwrap();
            (0..batch).map(|e| max_abs_diff(&ea.data(e).unwrap().qpos, &eb.data(e).unwrap().qpos)).fold(0.0, f64::max)
        })
        .collect()
}

#[test]
fn the_mjcf_ant_follows_the_brax_ants_trajectory_until_a_knee_touches_the_ground() {
    // In the task, under random actions: round-off only (measured 1.7e-12 after 50 control
    // steps, 16 environments) until, at step 70 of one of them, an MJCF shin's knee cap
    // touches the ground, which Brax's `end: -1` (only the foot cap touches) excludes; from
    // then on the two differ by centimetres (measured 0.12 after 100 steps). With Brax's
    // `end` ignored the same run stays at round-off (measured 5.9e-10 after 100 steps, 3.3e-5
    // after 200, by switching `BraxPhysics::capsule_ends` off): the next test holds that.
    let (brax, mjcf) = scenes("team_reach:agents={ant}");
    let d = task_divergence(&brax, &mjcf, 100);
    println!("max |qpos difference| after 50 and 100 control steps: {:e} {:e}", d[49], d[99]);
    // 1e-9: the measured 1.7e-12 with room for round-off to grow differently on another CPU.
    assert!(d[49] < 1e-9, "after 50 steps: {:e}", d[49]);
}

/// One agent on the ground with MeBen's options, its qpos0 the rest pose lifted by 1 cm.
fn one_agent(tree: &envs::brax::AgentTree, physics: &BraxPhysics) -> Model {
    let mut b = ModelBuilder::new();
    b.set_options(brax_options());
    b.add_geom(BodyId::WORLD, envs::GeomSpec::plane().friction(physics.friction));
    add_agent(&mut b, tree, physics, "", [0.0, 0.0, tree.rest_height() + 0.01], [1.0, 0.0, 0.0, 0.0]);
    b.build().unwrap()
}

#[test]
fn with_both_capsule_ends_touching_the_two_ants_move_alike_to_round_off() {
    // The Brax ant with `end` ignored against the MJCF ant: from random starts (yaw, joint
    // angles, velocities) under random controls the two stay within round-off growth
    // (measured 2.3e-9 after 100 control steps over these 8 starts). The bound is a margin
    // over that for round-off growing differently elsewhere, not a physical difference: a
    // real one (a knee cap touching, above) shows as centimetres.
    let loose = BraxPhysics { capsule_ends: false, ..BraxPhysics::default() };
    let brax_tree = envs::brax::AgentTree::from_config(&envs::brax::load_morphology("ant").unwrap(), &loose);
    let mjcf_tree = load_agent_file(ANT_XML, &BraxPhysics::default()).unwrap();
    let (ma, mb) = (one_agent(&brax_tree, &loose), one_agent(&mjcf_tree, &BraxPhysics::default()));
    let mut worst: f64 = 0.0;
    for seed in 0..8 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut da, mut db) = (Data::new(&ma), Data::new(&mb));
        let yaw: f64 = rng.random_range(-3.0..3.0);
        let mut qpos = ma.qpos0.clone();
        qpos[3..7].copy_from_slice(&[(0.5 * yaw).cos(), 0.0, 0.0, (0.5 * yaw).sin()]);
        for q in &mut qpos[7..] {
            *q += rng.random_range(-0.2..0.2);
        }
        let qvel: Vec<f64> = (0..ma.nv).map(|_| rng.random_range(-0.5..0.5)).collect();
        for d in [&mut da, &mut db] {
            d.qpos.copy_from_slice(&qpos);
            d.qvel.copy_from_slice(&qvel);
        }
        for _ in 0..100 {
            let ctrl: Vec<f64> = (0..ma.nu()).map(|_| rng.random_range(-1.0..1.0)).collect();
            da.ctrl.copy_from_slice(&ctrl);
            db.ctrl.copy_from_slice(&ctrl);
            for _ in 0..5 {
                envs::step(&ma, &mut da);
                envs::step(&mb, &mut db);
            }
        }
        worst = worst.max(max_abs_diff(&da.qpos, &db.qpos));
    }
    println!("max |qpos difference| after 100 control steps, 8 random starts: {worst:e}");
    assert!(worst < 1e-6, "{worst:e}");
}

#[test]
fn mujocos_ant_has_its_welded_thighs_fused_without_changing_its_dynamics() {
    // MuJoCo's ant.xml: 13 bodies, of which the four `*_leg` bodies have no joint: fused into
    // the torso, 9 remain. Fusing moves mass, not motion: the accelerations of the fused
    // model equal the file's own (loaded as it is by `mjcf::load_file`) at random states.
    let file = envs::mjcf::load_file(MUJOCO_ANT).unwrap();
    let tree = load_agent_file(MUJOCO_ANT, &BraxPhysics::default()).unwrap();
    assert_eq!((file.bodies.len() - 1, tree.bodies.len(), tree.hinges().len(), tree.motors.len()), (13, 9, 8, 8));
    let torso_and_thighs: f64 = [1, 2, 5, 8, 11].iter().map(|&b| file.bodies[b].mass).sum();
    assert!((tree.bodies[0].mass - torso_and_thighs).abs() < 1e-15);
    // Motors keep the file's order (hip_4 first) and gear; unnamed motors take their joint's name.
    assert_eq!(tree.motors[0].name, "hip_4");
    assert_eq!(tree.hinges()[tree.motors[0].hinge].name, "hip_4");
    assert!(tree.motors.iter().all(|m| m.gear == 150.0));
    let mut b = ModelBuilder::new();
    b.set_options(file.opt.clone());
    add_agent(&mut b, &tree, &BraxPhysics::default(), "", [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
    let fused = b.build().unwrap();
    assert_eq!((fused.nq, fused.nv, fused.nu()), (file.nq, file.nv, file.nu()));
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..20 {
        // High above the floor: no contacts; joints within their ranges: no limits.
        let mut q = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        q.iter_mut().for_each(|x| *x /= n);
        let mut qpos = vec![0.3, -0.2, 5.0, q[0], q[1], q[2], q[3]];
        for j in &file.joints[1..] {
            qpos.push(rng.random_range(j.range[0] + 0.05..j.range[1] - 0.05));
        }
        let qvel: Vec<f64> = (0..file.nv).map(|_| rng.random_range(-2.0..2.0)).collect();
        let ctrl: Vec<f64> = (0..file.nu()).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut acc = Vec::new();
        for m in [&file, &fused] {
            let mut d = Data::new(m);
            d.qpos.copy_from_slice(&qpos);
            d.qvel.copy_from_slice(&qvel);
            d.ctrl.copy_from_slice(&ctrl);
            forward(m, &mut d);
            acc.push(d.qacc.clone());
        }
        let scale = acc[0].iter().fold(1.0f64, |m, x| m.max(x.abs()));
        assert!(max_abs_diff(&acc[0], &acc[1]) < 1e-10 * scale, "{:?}\n{:?}", acc[0], acc[1]);
    }
    // And it plays: a Team Sumo scene of MuJoCo's ant against MeBen's steps and stays finite.
    let mut env =
        VecEnv::from_name(&format!("team_sumo:team1={MUJOCO_ANT};team2=ant"), 2, 0, StartMode::Random).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..50 {
        let a: Vec<f32> = (0..2 * env.n_actions()).map(|_| rng.random_range(-1.0f32..1.0)).collect();
        env.step(&a).unwrap();
    }
    assert!(env.obs().vectors.iter().all(|x| x.is_finite()));
}

/// The fixture with `from` replaced by `to` (which must occur), loaded as an agent.
fn edited(from: &str, to: &str) -> Result<envs::brax::AgentTree, MjcfError> {
    let text = ant_text();
    assert!(text.contains(from), "{from}");
    load_agent_str(&text.replacen(from, to, 1), "edited.xml", &BraxPhysics::default())
}

fn line_of(text: &str, needle: &str) -> u32 {
    text.lines().position(|l| l.contains(needle)).unwrap() as u32 + 1
}

/// Asserts an error's element, attribute, value and message, and that it names the file
/// and the line where `at` is written.
fn refused(
    e: MjcfError,
    text: &str,
    at: &str,
    element: &str,
    attribute: Option<&str>,
    value: Option<&str>,
    says: &str,
) {
    let shown = e.to_string();
    assert_eq!((e.file.as_str(), e.element.as_str()), ("edited.xml", element), "{shown}");
    assert_eq!((e.attribute.as_deref(), e.value.as_deref()), (attribute, value), "{shown}");
    assert_eq!(e.line, line_of(text, at), "{shown}");
    assert!(e.message.contains(says), "{shown}");
    assert!(shown.starts_with(&format!("edited.xml:{}: <{element}>", e.line)), "{shown}");
}

/// (replace, with, the text the error points at, element, attribute, value, message)
type Case<'a> = (&'a str, String, &'a str, &'a str, Option<&'a str>, Option<&'a str>, &'a str);

#[test]
fn every_refused_construct_names_file_line_element_attribute_and_value() {
    let hip = r#"<joint name="hip_1" axis="0 0 1" pos="0 0 0" range="-30 30"/>"#;
    let thigh = r#"<geom name="thigh_1_geom" type="capsule""#;
    let torso = r#"<body name="torso" pos="0 0 0.75">"#;
    let root = r#"<joint name="root" type="free" pos="0 0 0" armature="0" damping="0" limited="false" margin="0.01"/>"#;
    let motor = r#"<motor name="hip_1" joint="hip_1"/>"#;
    let cases: Vec<Case> = vec![
        (hip, r#"<joint name="hip_1" axis="0 0 1" pos="0 0 0"/>"#.into(), "hip_1\" axis", "joint", Some("range"), None, "needs a range"),
        (hip, r#"<joint name="hip_1" axis="0 0 1" range="-30 30" limited="false"/>"#.into(), "hip_1\" axis", "joint", Some("limited"), Some("false"), "every hinge needs a range"),
        (hip, r#"<joint name="hip_1" axis="0 0 1" range="-30 30" stiffness="10"/>"#.into(), "hip_1\" axis", "joint", Some("stiffness"), Some("10"), "only 0"),
        (hip, r#"<joint name="hip_1" axis="0 0 1" range="-30 30" actuatorfrcrange="-1 1"/>"#.into(), "hip_1\" axis", "joint", Some("actuatorfrcrange"), Some("-1 1"), "not supported in an agent morphology"),
        (thigh, r#"<geom name="thigh_1_geom" friction="0.5" type="capsule""#.into(), "thigh_1_geom", "geom", Some("friction"), Some("0.5"), "the scene's, 1"),
        (thigh, r#"<geom name="thigh_1_geom" condim="1" type="capsule""#.into(), "thigh_1_geom", "geom", Some("condim"), Some("1"), "condim=\"3\""),
        (thigh, r#"<geom name="thigh_1_geom" contype="0" type="capsule""#.into(), "thigh_1_geom", "geom", Some("contype"), Some("0"), "collides with nothing"),
        (thigh, r#"<geom name="thigh_1_geom" fluidshape="ellipsoid" type="capsule""#.into(), "thigh_1_geom", "geom", Some("fluidshape"), Some("ellipsoid"), "not supported"),
        (torso, r#"<body name="torso" pos="0 0 0.75" euler="0 0 30">"#.into(), "name=\"torso\"", "body", Some("euler"), Some("0 0 30"), "must not be rotated"),
        (torso, r#"<body name="torso" gravcomp="1">"#.into(), "name=\"torso\"", "body", Some("gravcomp"), Some("1"), "not supported"),
        (root, String::new(), "name=\"torso\"", "body", None, None, "needs a free joint"),
        (root, r#"<freejoint name="root"/><joint name="extra" axis="0 0 1" range="-1 1"/>"#.into(), "name=\"torso\"", "body", None, None, "a free joint must be the only joint"),
        (root, r#"<joint name="root" type="free" damping="0"/>"#.into(), "armature=\"0.35\"", "joint", Some("armature"), Some("0.35"), "must be 0 on the free joint"),
        (motor, r#"<motor name="hip_1" joint="hip_1" ctrlrange="-2 2"/>"#.into(), "<motor name=\"hip_1\"", "motor", Some("ctrlrange"), Some("-2 2"), "must be \"-1 1\""),
        (motor, r#"<motor name="hip_1" joint="hip_1" gear="350 0 0 1 0 0"/>"#.into(), "<motor name=\"hip_1\"", "motor", Some("gear"), Some("350 0 0 1 0 0"), "one gear"),
        (motor, r#"<motor name="hip_1" joint="hip_1" forcerange="-1 1"/>"#.into(), "<motor name=\"hip_1\"", "motor", Some("forcerange"), Some("-1 1"), "not supported"),
        (r#"<motor name="ankle_1" joint="ankle_1"/>"#, r#"<motor name="ankle_1" joint="hip_1"/>"#.into(), "<motor name=\"ankle_1\"", "motor", Some("joint"), Some("hip_1"), "a second motor on this hinge"),
        (r#"<geom name="floor" type="plane""#, r#"<geom name="floor" type="sphere""#.into(), "name=\"floor\"", "geom", Some("type"), Some("sphere"), "fixed to the world"),
        ("  </worldbody>", r#"<body name="second"><freejoint/><geom size="0.1"/></body></worldbody>"#.into(), "name=\"second\"", "body", None, None, "a second top-level body"),
        ("  <actuator>", "<tendon/><actuator>".into(), "<tendon/>", "tendon", None, None, "not supported in an agent morphology"),
        ("  <actuator>", "<equality/><actuator>".into(), "<equality/>", "equality", None, None, "not supported"),
        (hip, format!("{hip}<frame/>"), "<frame/>", "frame", None, None, "not supported"),
        (r#"inertiafromgeom="true""#, r#"inertiafromgeom="true" settotalmass="5""#.into(), "settotalmass", "compiler", Some("settotalmass"), Some("5"), "not supported"),
        (
            r#"<geom name="shin_1_geom""#,
            r#"<body name="empty" pos="0.5 0 0"><joint name="loose" axis="0 1 0" range="-1 1"/></body><geom name="shin_1_geom""#.into(),
            "name=\"empty\"",
            "body",
            None,
            None,
            "a moving body without mass",
        ),
        // The loader's own refusals reach the user the same way.
        (thigh, r#"<geom name="thigh_1_geom" type="box""#.into(), "thigh_1_geom", "geom", Some("type"), Some("box"), "not supported"),
        (hip, r#"<joint name="hip_1" type="ball"/>"#.into(), "hip_1\" type", "joint", Some("type"), Some("ball"), "not supported"),
    ];
    for (from, to, at, element, attribute, value, says) in cases {
        let text = ant_text().replacen(from, &to, 1);
        let e = edited(from, &to).expect_err(&to);
        refused(e, &text, at, element, attribute, value, says);
    }
    // A world without a body, a malformed file, a missing file.
    let e = load_agent_str("<mujoco><worldbody/></mujoco>", "edited.xml", &BraxPhysics::default()).unwrap_err();
    assert_eq!((e.element.as_str(), e.line), ("worldbody", 0));
    assert!(e.to_string().contains("holds no body"), "{e}");
    let e = edited("</mujoco>", "</mujoc").unwrap_err();
    assert!(e.line > 0 && e.to_string().starts_with(&format!("edited.xml:{}: malformed XML", e.line)), "{e}");
    let e = load_agent_file("/nonexistent/agent.xml", &BraxPhysics::default()).unwrap_err();
    assert!(e.to_string().starts_with("/nonexistent/agent.xml: cannot read the file"), "{e}");
}

#[test]
fn the_task_builder_reports_mjcf_errors_with_the_file_name() {
    let dir = std::env::temp_dir().join(format!("meben_tasks_mjcf_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("no_range.xml");
    std::fs::write(&bad, ant_text().replace(r#" range="30 70""#, "")).unwrap();
    let name = format!("team_reach:agents=ant+{}", bad.display());
    let e = VecEnv::from_name(&name, 2, 0, StartMode::Random).unwrap_err();
    let TaskError::Morphology { name: morphology, message } = &e else { panic!("{e:?}") };
    assert_eq!(morphology, &bad.display().to_string());
    let line = line_of(&ant_text(), "ankle_1");
    assert!(message.starts_with(&format!("{}:{line}: <joint> attribute 'range'", bad.display())), "{message}");
    // A missing file is a file that cannot be read, not an unknown name.
    let missing = dir.join("missing.xml");
    let e = Scene::from_name(&format!("team_reach:agents={}", missing.display())).unwrap_err();
    assert!(e.to_string().contains("cannot read the morphology file"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn truncated_and_mutated_files_never_panic() {
    let text = ant_text();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut loaded = 0;
    for k in 0..300 {
        let cut = (next() as usize) % text.len();
        let candidate = if k % 2 == 0 {
            text[..cut].to_string()
        } else {
            // Replace one character by one of the syntax's own.
            let pool = ['<', '>', '"', '=', ' ', '-', '0', '9', 'e', '/'];
            let mut chars: Vec<char> = text.chars().collect();
            let at = cut.min(chars.len() - 1);
            chars[at] = pool[(next() as usize) % pool.len()];
            chars.into_iter().collect()
        };
        if load_agent_str(&candidate, "fuzz.xml", &BraxPhysics::default()).is_ok() {
            loaded += 1;
        }
    }
    // Edits inside numbers or comments still load; truncations never do.
    assert!(loaded < 150, "{loaded}");
}
