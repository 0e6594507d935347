//! Physics equivariance of the tasks: rotating the whole initial scene about the vertical and
//! applying the same actions gives the rotated trajectory (qpos to 1e-6 over 50 control
//! steps), rotated vector observations, rotated headings, unchanged scalars and rewards.

#![allow(clippy::needless_range_loop)] // index loops mirror the array layouts

use envs::tasks::placement::{RootPlacement, Start};
use envs::tasks::{StartMode, VecEnv};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const STEPS: usize = 50;

fn rot(p: [f64; 3], angle: f64, point: [f64; 2]) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let (dx, dy) = (p[0] - point[0], p[1] - point[1]);
    [point[0] + c * dx - s * dy, point[1] + s * dx + c * dy, p[2]]
}

fn rot_vec(v: [f64; 3], angle: f64) -> [f64; 3] {
    rot(v, angle, [0.0, 0.0])
}

fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// Runs the fixed start of `seed` unrotated and rotated by `angle` about `point` with the
/// same random actions; checks every control step. Returns the largest qpos error.
fn check(name: &str, seed: u64, angle: f64, point: [f64; 2]) -> f64 {
    let a = VecEnv::from_name(name, 1, 0, StartMode::fixed(seed)).unwrap();
    let b = VecEnv::from_name(name, 1, 0, StartMode::fixed_rotated(seed, angle, point)).unwrap();
    check_envs(name, a, b, seed, angle, point).0
}

/// Like [`check`] from a hand-built start; returns the largest qpos error and the number of
/// steps with contacts between different agents.
fn check_start(name: &str, start: &Start, angle: f64, point: [f64; 2]) -> (f64, usize) {
    let mut a = VecEnv::from_name(name, 1, 0, StartMode::Random).unwrap();
    let mut b = VecEnv::from_name(name, 1, 0, StartMode::Random).unwrap();
    a.set_start(0, start).unwrap();
    b.set_start(0, &start.rotated(angle, point)).unwrap();
    check_envs(name, a, b, 1, angle, point)
}

fn check_envs(name: &str, mut a: VecEnv, mut b: VecEnv, seed: u64, angle: f64, point: [f64; 2]) -> (f64, usize) {
    let mut touching = 0;
    a.set_curriculum_alpha(0.5).unwrap();
    b.set_curriculum_alpha(0.5).unwrap();
    let scene = a.scene().clone();
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 100);
    let mut worst: f64 = 0.0;
    let qrot = [(0.5 * angle).cos(), 0.0, 0.0, (0.5 * angle).sin()];
    for step in 0..STEPS {
        let actions: Vec<f32> = (0..a.n_actions()).map(|_| rng.random_range(-1.0f32..1.0)).collect();
        let oa = a.step(&actions).unwrap().clone();
        let ob = b.step(&actions).unwrap().clone();
        assert!(!oa.terminated[0] && !oa.truncated[0], "{name}: the episode ended early at step {step}");
        assert_eq!(oa.terminated, ob.terminated);
        // Trajectory: roots rotated about the point, orientations pre-multiplied, hinges equal.
        let (da, db) = (a.data(0).unwrap(), b.data(0).unwrap());
        let tree = |g: usize| scene.model.geoms[g].tree;
        touching += da.contacts.iter().any(|c| tree(c.geom1) != tree(c.geom2) && tree(c.geom1) != usize::MAX) as usize;
        for ag in &scene.agents {
            let q = &da.qpos[ag.qpos_adr..ag.qpos_adr + ag.nq];
            let r = &db.qpos[ag.qpos_adr..ag.qpos_adr + ag.nq];
            let p = rot([q[0], q[1], q[2]], angle, point);
            let mut qq = quat_mul(qrot, [q[3], q[4], q[5], q[6]]);
            if qq.iter().zip(&r[3..7]).map(|(x, y)| x * y).sum::<f64>() < 0.0 {
                qq.iter_mut().for_each(|x| *x = -*x);
            }
            let mut err: f64 = 0.0;
            for k in 0..3 {
                err = err.max((p[k] - r[k]).abs());
            }
            for k in 0..4 {
                err = err.max((qq[k] - r[3 + k]).abs());
            }
            for k in 7..ag.nq {
                err = err.max((q[k] - r[k]).abs());
            }
            worst = worst.max(err);
            assert!(err < 1e-6, "{name} step {step}: rotated trajectory differs by {err:e}");
        }
        // Observations: vectors rotate, scalars are equal, headings shift by the angle.
        let n = oa.obs.nodes;
        for node in 0..n {
            let pa = oa.obs.vector(0, node, 0).map(f64::from);
            let pb = ob.obs.vector(0, node, 0).map(f64::from);
            let pr = rot(pa, angle, point);
            for k in 0..3 {
                assert!((pr[k] - pb[k]).abs() < 1e-4, "{name} step {step} node {node}: position {pr:?} vs {pb:?}");
            }
            for v in 1..3 {
                let va = rot_vec(oa.obs.vector(0, node, v).map(f64::from), angle);
                let vb = ob.obs.vector(0, node, v).map(f64::from);
                for k in 0..3 {
                    let tol = 1e-4 * (1.0 + va[k].abs());
                    assert!((va[k] - vb[k]).abs() < tol, "{name} step {step} node {node} vector {v}: {va:?} vs {vb:?}");
                }
            }
            let (sa, sb) = (oa.obs.node_scalars(0, node), ob.obs.node_scalars(0, node));
            for (x, y) in sa.iter().zip(sb) {
                assert!((x - y).abs() < 1e-5, "{name} step {step} node {node}: scalars {sa:?} vs {sb:?}");
            }
        }
        for ag in 0..oa.obs.agents {
            let (ha, hb) = (oa.obs.heading[ag] as f64, ob.obs.heading[ag] as f64);
            assert!(angle_diff(ha + angle, hb) < 1e-4, "{name} step {step}: heading {ha} + {angle} vs {hb}");
        }
        for (ra, rb) in oa.reward.iter().zip(&ob.reward) {
            let tol = 1e-4 * (1.0 + ra.abs());
            assert!((ra - rb).abs() < tol, "{name} step {step}: reward {ra} vs {rb}");
        }
    }
    (worst, touching)
}

#[test]
fn reach_1_ant_rotated_180_about_the_origin() {
    let e = check("team_reach/1_ant", 3, std::f64::consts::PI, [0.0, 0.0]);
    eprintln!("team_reach/1_ant max qpos error {e:e}");
}

#[test]
fn reach_1_centipede_rotated_by_an_arbitrary_angle() {
    let e = check("team_reach/1_centipede", 4, 0.7, [1.5, 2.0]);
    eprintln!("team_reach/1_centipede max qpos error {e:e}");
}

#[test]
fn reach_3_ant_claw_centipede_rotated_about_a_point() {
    let e = check("team_reach/3_ant_claw_centipede", 5, 1.234, [0.7, -2.1]);
    eprintln!("team_reach/3_ant_claw_centipede max qpos error {e:e}");
}

#[test]
fn sumo_2_ants_rotated_about_a_point() {
    let e = check("team_sumo/2_ants", 11, 2.5, [-1.0, 0.5]);
    eprintln!("team_sumo/2_ants max qpos error {e:e}");
}

#[test]
fn sumo_2_ants_rotated_while_the_ants_push_each_other() {
    // Two ants of each team, legs interleaved at the start so that they touch at once.
    let p = |x: f64, y: f64, yaw: f64| RootPlacement { xy: [x, y], yaw };
    let start = Start {
        agents: vec![p(-0.75, 0.0, 0.785), p(0.0, 1.5, 0.0), p(0.75, 0.0, 0.0), p(0.0, -1.5, 0.3)],
        balls: vec![[0.0, 0.0]],
    };
    let (e, touching) = check_start("team_sumo/2_ants", &start, 2.0, [0.3, -0.4]);
    eprintln!("team_sumo/2_ants pushing: max qpos error {e:e}, {touching} steps with contacts between agents");
    assert!(touching >= 5, "the ants touched at only {touching} steps");
}
