//! Tests of the model-independent components: assignment, local frames, Tanh-Normal.

use models::distribution::{normal_entropy, std_from_scale, tanh_normal_log_prob};
use models::frame::{heading_frame, local_frame, to_frame};
use models::{Assigner, AssignmentMethod, UNASSIGNED, distance_matrix};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tensor::gradcheck::check_gradients;
use tensor::{Tape, Tensor};

fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

fn assign(method: AssignmentMethod, dist: &[f64], n: usize, m: usize) -> Vec<usize> {
    let mut a = Assigner::new(n, m);
    let mut out = vec![0; m];
    a.assign(method, dist, n, m, &mut out, &mut rng(0));
    out
}

#[test]
fn greedy_follows_algorithm_1() {
    // 3 agents x 2 objects. Object 0 is nearest to agent 1; object 1 is also nearest to
    // agent 1, which is taken, so it gets agent 2 (next nearest), not the optimum.
    #[rustfmt::skip]
    let d = [
        5.0, 4.0,  // agent 0
        1.0, 1.5,  // agent 1
        9.0, 3.0,  // agent 2
    ];
    assert_eq!(assign(AssignmentMethod::Greedy, &d, 3, 2), vec![1, 2]);
    // A case where greedy is not optimal:
    #[rustfmt::skip]
    let d2 = [
        1.0, 2.0,  // agent 0
        1.5, 10.0, // agent 1
    ];
    // Greedy: object 0 -> agent 0 (1.0), object 1 -> agent 1 (10): total 11.
    assert_eq!(assign(AssignmentMethod::Greedy, &d2, 2, 2), vec![0, 1]);
    // Hungarian: object 0 -> agent 1 (1.5), object 1 -> agent 0 (2): total 3.5.
    assert_eq!(assign(AssignmentMethod::Hungarian, &d2, 2, 2), vec![1, 0]);
    // Ties go to the lowest agent index.
    assert_eq!(assign(AssignmentMethod::Greedy, &[2.0, 2.0, 2.0], 3, 1), vec![0]);
    // More objects than agents: the surplus stays unassigned.
    assert_eq!(assign(AssignmentMethod::Greedy, &[1.0, 2.0, 3.0], 1, 3), vec![0, UNASSIGNED, UNASSIGNED]);
    assert_eq!(assign(AssignmentMethod::None, &d, 3, 2), vec![UNASSIGNED; 2]);
}

fn brute_force(dist: &[f64], n: usize, m: usize) -> f64 {
    // Minimal total over injective maps objects -> agents (m <= n).
    fn rec(j: usize, used: &mut Vec<bool>, dist: &[f64], n: usize, m: usize) -> f64 {
        if j == m {
            return 0.0;
        }
        let mut best = f64::INFINITY;
        for i in 0..n {
            if !used[i] {
                used[i] = true;
                best = best.min(dist[i * m + j] + rec(j + 1, used, dist, n, m));
                used[i] = false;
            }
        }
        best
    }
    rec(0, &mut vec![false; n], dist, n, m)
}

#[test]
fn hungarian_equals_brute_force_on_random_instances() {
    let mut r = rng(1);
    let mut assigner = Assigner::new(6, 6);
    let mut out = [0; 6];
    for _ in 0..300 {
        let n = r.random_range(1..=6);
        let m = r.random_range(1..=n);
        let dist: Vec<f64> = (0..n * m).map(|_| r.random_range(0.0..10.0)).collect();
        // One assigner reused across instances (no per-scene allocation).
        assigner.assign(AssignmentMethod::Hungarian, &dist, n, m, &mut out[..m], &mut rng(0));
        let mut seen = vec![false; n];
        let mut total = 0.0;
        for (j, &i) in out[..m].iter().enumerate() {
            assert!(i < n && !seen[i], "not one-to-one: {:?}", &out[..m]);
            seen[i] = true;
            total += dist[i * m + j];
        }
        let best = brute_force(&dist, n, m);
        assert!((total - best).abs() < 1e-9, "hungarian {total} vs brute force {best}");
        // Greedy is never better than the optimum.
        assigner.assign(AssignmentMethod::Greedy, &dist, n, m, &mut out[..m], &mut rng(0));
        let greedy: f64 = out[..m].iter().enumerate().map(|(j, &i)| dist[i * m + j]).sum();
        assert!(greedy >= best - 1e-9);
    }
    // More objects than agents.
    let dist = [4.0, 1.0, 3.0]; // 1 agent, 3 objects
    assert_eq!(assign(AssignmentMethod::Hungarian, &dist, 1, 3), vec![UNASSIGNED, 0, UNASSIGNED]);
}

#[test]
fn stochastic_assignment_is_a_seeded_permutation() {
    let mut a = Assigner::new(5, 5);
    let d = vec![0.0; 25];
    let (mut x, mut y) = (vec![0; 5], vec![0; 5]);
    a.assign(AssignmentMethod::Stochastic, &d, 5, 5, &mut x, &mut rng(7));
    a.assign(AssignmentMethod::Stochastic, &d, 5, 5, &mut y, &mut rng(7));
    assert_eq!(x, y);
    let mut s = x.clone();
    s.sort();
    assert_eq!(s, vec![0, 1, 2, 3, 4]);
    // Different seeds give different assignments at least sometimes.
    let differs = (0..20).any(|k| {
        a.assign(AssignmentMethod::Stochastic, &d, 5, 5, &mut y, &mut rng(100 + k));
        x != y
    });
    assert!(differs);
    assert!(AssignmentMethod::parse("hungarian").is_ok());
    assert!(AssignmentMethod::parse("optimal").unwrap_err().contains("optimal"));
}

#[test]
fn distance_matrix_is_euclidean() {
    let mut out = vec![0.0; 2];
    distance_matrix(&[[0.0, 0.0, 0.0]], &[[3.0, 4.0, 0.0], [0.0, 0.0, -2.0]], &mut out);
    assert_eq!(out, vec![5.0, 2.0]);
}

fn rot_z(a: f64) -> [[f64; 3]; 3] {
    let (s, c) = a.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

fn apply(r: &[[f64; 3]; 3], v: &[f64]) -> Vec<f64> {
    // v: rows of 3-vectors
    v.chunks(3).flat_map(|p| (0..3).map(move |i| (0..3).map(|k| r[i][k] * p[k]).sum::<f64>())).collect()
}

#[test]
fn local_frame_is_a_rotation_and_equivariant_about_gravity() {
    let mut r = rng(3);
    let u: Vec<f64> = (0..15).map(|_| r.random_range(-1.0..1.0)).collect();
    let tape = Tape::<f64>::new();
    // eps = 0: exact unit vectors (eps only matters for vertical u).
    let o = local_frame(tape.constant(Tensor::new(u.clone(), &[5, 3]).unwrap()), 0.0).unwrap().value();
    for f in o.data().chunks(9) {
        // Columns orthonormal, determinant +1, third column = z.
        let col = |j: usize| [f[j], f[3 + j], f[6 + j]];
        for a in 0..3 {
            for b in 0..3 {
                let d: f64 = (0..3).map(|i| col(a)[i] * col(b)[i]).sum();
                assert!((d - f64::from(u8::from(a == b))).abs() < 1e-12);
            }
        }
        let det = f[0] * (f[4] * f[8] - f[5] * f[7]) - f[1] * (f[3] * f[8] - f[5] * f[6])
            + f[2] * (f[3] * f[7] - f[4] * f[6]);
        assert!((det - 1.0).abs() < 1e-12);
        assert_eq!(col(2), [0.0, 0.0, 1.0]);
    }
    // Invariance of O^T Z: rotating u and Z about z leaves the frame coordinates unchanged.
    let z: Vec<f64> = (0..5 * 3 * 2).map(|_| r.random_range(-1.0..1.0)).collect();
    let rot = rot_z(1.234);
    // Z is [5, 3, 2]: rotate each column vector (stride 2).
    let rotate_z = |z: &[f64]| -> Vec<f64> {
        let mut out = z.to_vec();
        for b in 0..5 {
            for c in 0..2 {
                for i in 0..3 {
                    out[(b * 3 + i) * 2 + c] = (0..3).map(|k| rot[i][k] * z[(b * 3 + k) * 2 + c]).sum();
                }
            }
        }
        out
    };
    let local = |u: Vec<f64>, z: Vec<f64>| {
        let tape = Tape::<f64>::new();
        let o = local_frame(tape.constant(Tensor::new(u, &[5, 3]).unwrap()), 1e-12).unwrap();
        to_frame(o, tape.constant(Tensor::new(z, &[5, 3, 2]).unwrap())).unwrap().value()
    };
    let a = local(u.clone(), z.clone());
    let b = local(apply(&rot, &u), rotate_z(&z));
    assert!(a.all_close(&b, 0.0, 1e-12));
    // Gradient of the frame construction.
    check_gradients(|_, v| local_frame(v[0], 1e-9), &[Tensor::new(u, &[5, 3]).unwrap()]).unwrap();
}

#[test]
fn heading_frame_matches_local_frame_of_the_heading_direction() {
    let yaw = [0.3, -2.0, 3.0];
    let h: Tensor<f64> = heading_frame(&yaw);
    let u: Vec<f64> = yaw.iter().flat_map(|a| [a.cos(), a.sin(), 0.7]).collect();
    let tape = Tape::<f64>::new();
    let o = local_frame(tape.constant(Tensor::new(u, &[3, 3]).unwrap()), 0.0).unwrap().value();
    assert!(h.all_close(&o, 0.0, 1e-12));
}

#[test]
fn tanh_normal_density_integrates_to_one() {
    // p_A(a) = exp(log_prob(atanh a)) over a in (-1, 1), midpoint rule on a fine grid.
    for (loc, scale) in [(0.0, 0.0), (0.8, -1.0), (-1.5, 0.5)] {
        let k = 200_000;
        let a: Vec<f64> = (0..k).map(|i| -1.0 + (i as f64 + 0.5) * 2.0 / k as f64).collect();
        let u: Vec<f64> = a.iter().map(|&x: &f64| x.atanh()).collect();
        let tape = Tape::<f64>::new();
        let uv = tape.constant(Tensor::new(u, &[k, 1]).unwrap());
        let locv = tape.constant(Tensor::full(&[k, 1], loc));
        let std = std_from_scale(tape.constant(Tensor::full(&[k, 1], scale)));
        let lp = tanh_normal_log_prob(uv, locv, std).unwrap().value();
        let total: f64 = lp.data().iter().map(|l| l.exp()).sum::<f64>() * 2.0 / k as f64;
        // The midpoint rule's error here is far below 1e-3 for these smooth densities.
        assert!((total - 1.0).abs() < 1e-3, "loc {loc} scale {scale}: {total}");
        let ent = normal_entropy(std.narrow(0, 0, 1).unwrap()).unwrap().value().item().unwrap();
        let sd = scale.exp().ln_1p() + 0.001;
        assert!((ent - (sd.ln() + 0.5 * (1.0 + (2.0 * std::f64::consts::PI).ln()))).abs() < 1e-12);
    }
}

#[test]
fn tanh_normal_log_prob_gradients() {
    let mut r = rng(5);
    let mk = |r: &mut ChaCha8Rng| Tensor::new((0..8).map(|_| r.random_range(-1.0..1.0)).collect(), &[2, 4]).unwrap();
    let (u, loc, scale) = (mk(&mut r), mk(&mut r), mk(&mut r));
    check_gradients(|_, v| tanh_normal_log_prob(v[0], v[1], std_from_scale(v[2])), &[u, loc, scale]).unwrap();
}
