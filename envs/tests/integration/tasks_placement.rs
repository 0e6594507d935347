//! Placement statistics over many seeds: inside R, uniform over the disc (mean of r^2/R^2 is
//! 1/2, Kolmogorov-Smirnov on r^2/R^2, chi-square over the angle), uniform yaw; Sumo rings;
//! agents do not overlap; fixed starts and their rotation.

use envs::tasks::placement::{START_CLEARANCE, rotate_xy, sample_start};
use envs::tasks::vec_env::env_rng;
use envs::tasks::{BUILTIN_NAMES, Scene, StartMode, VecEnv};
use std::f64::consts::{PI, TAU};

const N: usize = 20_000;

/// KS statistic of samples against U(0, 1), times sqrt(n).
fn ks_uniform(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(|a, b| a.total_cmp(b));
    let n = xs.len() as f64;
    let d = xs
        .iter()
        .enumerate()
        .map(|(i, &x)| (x - i as f64 / n).abs().max(((i + 1) as f64 / n - x).abs()))
        .fold(0.0, f64::max);
    d * n.sqrt()
}

/// Chi-square statistic of angles in 16 equal bins.
fn chi_square_angles(angles: &[f64]) -> f64 {
    let bins = 16;
    let mut counts = vec![0usize; bins];
    for &a in angles {
        let k = ((a.rem_euclid(TAU) / TAU) * bins as f64) as usize;
        counts[k.min(bins - 1)] += 1;
    }
    let expected = angles.len() as f64 / bins as f64;
    counts.iter().map(|&c| (c as f64 - expected).powi(2) / expected).sum()
}

/// Checks that points are uniform over the disc of radius `r`.
fn assert_uniform_disc(what: &str, pts: &[[f64; 2]], r: f64) {
    let u: Vec<f64> = pts.iter().map(|p| (p[0] * p[0] + p[1] * p[1]) / (r * r)).collect();
    assert!(u.iter().all(|&x| x <= 1.0 + 1e-12), "{what}: a point outside R");
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    // Standard error of the mean of U(0, 1): 0.289 / sqrt(N) = 0.002.
    assert!((mean - 0.5).abs() < 0.01, "{what}: mean r^2/R^2 = {mean}, expected 1/2");
    let ks = ks_uniform(u);
    assert!(ks < 1.95, "{what}: KS statistic sqrt(n) D = {ks} (p < 0.001 for uniform r^2)");
    let angles: Vec<f64> = pts.iter().map(|p| p[1].atan2(p[0])).collect();
    let chi = chi_square_angles(&angles);
    assert!(chi < 37.7, "{what}: angle chi-square {chi} with 15 dof (p < 0.001)");
}

#[test]
fn reach_single_agent_and_balls_are_uniform_over_the_disc() {
    let scene = Scene::from_name("team_reach/1_ant").unwrap();
    let (mut agents, mut balls, mut yaws) = (Vec::new(), Vec::new(), Vec::new());
    for seed in 0..N as u64 {
        let s = sample_start(&scene, &mut env_rng(seed, 0));
        agents.push(s.agents[0].xy);
        yaws.push(s.agents[0].yaw);
        balls.push(s.balls[0]);
    }
    assert_uniform_disc("1_ant agent", &agents, 5.0);
    assert_uniform_disc("1_ant ball", &balls, 5.0);
    let chi = chi_square_angles(&yaws);
    assert!(chi < 37.7, "yaw chi-square {chi}");
}

#[test]
fn reach_balls_of_a_multi_agent_scene_are_uniform_and_agents_inside_r() {
    let scene = Scene::from_name("team_reach/3_ant_claw_centipede").unwrap();
    let mut balls = Vec::new();
    let mut overlaps = 0;
    for seed in 0..(N / 3) as u64 {
        let s = sample_start(&scene, &mut env_rng(seed, 1));
        balls.extend(s.balls.iter().copied());
        for (i, a) in s.agents.iter().enumerate() {
            assert!(a.xy[0].hypot(a.xy[1]) <= 5.0, "agent outside R: {a:?}");
            for (j, b) in s.agents.iter().enumerate().take(i) {
                let gap = (a.xy[0] - b.xy[0]).hypot(a.xy[1] - b.xy[1])
                    - scene.agents[i].footprint
                    - scene.agents[j].footprint;
                overlaps += (gap < 0.0) as usize;
            }
        }
    }
    assert_uniform_disc("3_ant_claw_centipede balls", &balls, 5.0);
    assert_eq!(overlaps, 0, "agents' footprints overlap at the start");
}

#[test]
fn sumo_agents_start_in_the_ring_inside_r_minus_1() {
    for name in BUILTIN_NAMES.iter().filter(|n| n.starts_with("team_sumo/")) {
        let scene = Scene::from_name(name).unwrap();
        let r = scene.spec.radius;
        let hi = (r - 1.0).min(2.0);
        for seed in 0..500 {
            let s = sample_start(&scene, &mut env_rng(seed, 0));
            assert_eq!(s.balls, vec![[0.0, 0.0]]);
            for a in &s.agents {
                let rho = a.xy[0].hypot(a.xy[1]);
                assert!((1.0..=hi).contains(&rho), "{name}: agent at radius {rho}, expected 1 ..= {hi}");
            }
        }
    }
}

#[test]
fn every_builtin_starts_agents_at_rest_height_plus_clearance() {
    for name in BUILTIN_NAMES {
        let env = VecEnv::from_name(name, 1, 0, StartMode::Random).unwrap();
        let (scene, d) = (env.scene(), env.data(0).unwrap());
        for a in &scene.agents {
            let z = d.qpos[a.qpos_adr + 2];
            assert!((z - a.rest_height - START_CLEARANCE).abs() < 1e-12, "{name}: root z {z}");
            let quat = &d.qpos[a.qpos_adr + 3..a.qpos_adr + 7];
            assert!(quat[1] == 0.0 && quat[2] == 0.0, "{name}: the start is not upright: {quat:?}");
        }
    }
}

#[test]
fn fixed_start_repeats_and_rotates() {
    let scene = Scene::from_name("team_reach/2_ants").unwrap();
    let f = envs::tasks::FixedStart { seed: 9, angle: PI, point: [1.0, -1.0] };
    let base = envs::tasks::eval_modes::fixed_start(&scene, &envs::tasks::FixedStart { angle: 0.0, ..f });
    let rotated = envs::tasks::eval_modes::fixed_start(&scene, &f);
    for (a, b) in base.agents.iter().zip(&rotated.agents) {
        let p = rotate_xy(a.xy, PI, [1.0, -1.0]);
        assert!((p[0] - b.xy[0]).abs() < 1e-12 && (p[1] - b.xy[1]).abs() < 1e-12);
        assert!((a.yaw + PI - b.yaw).abs() < 1e-12);
    }
    // Every episode of a fixed mode starts the same, in every environment.
    let mut env = VecEnv::from_name("team_reach/2_ants", 2, 5, StartMode::fixed(9)).unwrap();
    let q0 = env.data(0).unwrap().qpos.clone();
    assert_eq!(env.data(1).unwrap().qpos, q0);
    env.step(&vec![0.3; 2 * env.n_actions()]).unwrap();
    env.reset();
    assert_eq!(env.data(0).unwrap().qpos, q0);
    assert_eq!(env.balls(0).unwrap(), base.balls.as_slice());
    // Bad rotations are errors.
    let e = VecEnv::from_name("team_reach/2_ants", 1, 0, StartMode::fixed_rotated(1, f64::NAN, [0.0, 0.0]));
    assert!(e.unwrap_err().to_string().contains("NaN"));
}
