//! Smooth dynamics (no contacts): pendulum, free fall, tumbling, momentum, mass matrix,
//! forward/inverse dynamics, armature. Every tolerance is justified where it is used.

use envs::diagnostics::{kinetic_energy, momentum, potential_energy};
use envs::{BodyId, Data, GeomSpec, HingeSpec, Model, ModelBuilder, Options};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ANT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/mujoco_ant.xml");

fn options(dt: f64, gravity: [f64; 3]) -> Options {
    Options { timestep: dt, gravity, disable_contact: true, ..Options::default() }
}

/// A point-like pendulum: a sphere of radius `r` hanging `l` below a hinge about y.
fn pendulum(l: f64, r: f64, dt: f64) -> (Model, f64, f64) {
    let mut b = ModelBuilder::new();
    b.set_options(options(dt, [0.0, 0.0, -9.81]));
    let body = b.add_body(BodyId::WORLD, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
    b.add_hinge(body, HingeSpec::new([0.0, 1.0, 0.0]));
    b.add_geom(body, GeomSpec::sphere(r).at([0.0, 0.0, -l]));
    let m = b.build().unwrap();
    let mass = m.bodies[1].mass;
    let inertia = mass * (l * l + 0.4 * r * r);
    (m, mass, inertia)
}

fn ant(gravity: [f64; 3]) -> Model {
    let mut m = envs::mjcf::load_file(ANT).unwrap();
    m.opt.timestep = 0.01;
    m.opt.gravity = gravity;
    m.opt.disable_contact = true;
    m
}

#[test]
fn pendulum_small_angle_period() {
    let (l, r, dt) = (1.0, 0.1, 0.001);
    let (m, mass, inertia) = pendulum(l, r, dt);
    let theta0 = 0.05;
    let mut d = Data::new(&m);
    d.qpos[0] = theta0;
    let mut crossings = Vec::new();
    let mut prev = d.qpos[0];
    for _ in 0..10_000 {
        envs::step(&m, &mut d);
        let q = d.qpos[0];
        if prev < 0.0 && q >= 0.0 {
            // Linear interpolation of the crossing time within the step.
            crossings.push(d.time - dt * q / (q - prev));
        }
        prev = q;
    }
    assert!(crossings.len() >= 4);
    let period = (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64;
    // Compound pendulum with the finite-amplitude correction T0 (1 + theta0^2 / 16).
    let expected = 2.0 * std::f64::consts::PI * (inertia / (mass * 9.81 * l)).sqrt() * (1.0 + theta0 * theta0 / 16.0);
    // Tolerance 1e-4 relative: symplectic Euler's frequency error is (w h)^2 / 24 ~ 4e-7 and
    // the next amplitude term ~ 1e-8, while a wrong inertia (e.g. dropping the sphere's own
    // 2/5 m r^2, 0.4% of I) would show as 2e-3.
    assert!((period - expected).abs() / expected < 1e-4, "period {period} vs {expected}");
}

#[test]
fn pendulum_energy_drift_is_bounded_without_damping() {
    let (l, dt) = (1.0, 0.001);
    let (m, mass, _) = pendulum(l, 0.1, dt);
    let mut d = Data::new(&m);
    d.qpos[0] = 1.0;
    let energy = |d: &mut Data| kinetic_energy(&m, d) + potential_energy(&m, d);
    let e0 = energy(&mut d);
    let scale = mass * 9.81 * l;
    let mut es = Vec::new();
    for _ in 0..20_000 {
        envs::step(&m, &mut d);
        es.push(energy(&mut d));
    }
    let max_dev = es.iter().map(|e| (e - e0).abs()).fold(0.0, f64::max) / scale;
    // Symplectic Euler: the energy oscillates with amplitude O(h w) ~ 0.3% of m g l, no trend.
    assert!(max_dev < 1e-2, "energy deviation {max_dev}");
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let drift = (mean(&es[18_000..]) - mean(&es[..2_000])).abs() / scale;
    // Averages over ~1 s windows 18 s apart: a secular drift (explicit Euler gains ~h w^2 E
    // per second, i.e. ~1% over 20 s) would show; the symplectic scheme keeps it < 1e-3.
    assert!(drift < 1e-3, "energy drift {drift}");
}

#[test]
fn free_fall_matches_the_integrator_closed_form() {
    let mut b = ModelBuilder::new();
    let g = [0.3, -0.2, -9.81];
    b.set_options(options(0.01, g));
    let body = b.add_body(BodyId::WORLD, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(body);
    b.add_geom(body, GeomSpec::sphere(0.2));
    let m = b.build().unwrap();
    let mut d = Data::new(&m);
    let v0 = [1.0, -2.0, 3.0];
    d.qvel[..3].copy_from_slice(&v0);
    let (h, n) = (0.01, 100);
    for _ in 0..n {
        envs::step(&m, &mut d);
    }
    let nf = n as f64;
    for k in 0..3 {
        // v_n = v0 + n h g;  x_n = x0 + n h v0 + h^2 g n (n + 1) / 2  (velocity updated first).
        let v = v0[k] + nf * h * g[k];
        let x = [1.0, 2.0, 3.0][k] + nf * h * v0[k] + h * h * g[k] * nf * (nf + 1.0) / 2.0;
        // 100 additions of O(1) numbers: round-off ~1e-14.
        assert!((d.qvel[k] - v).abs() < 1e-10, "v[{k}] {} vs {v}", d.qvel[k]);
        assert!((d.qpos[k] - x).abs() < 1e-10, "x[{k}] {} vs {x}", d.qpos[k]);
    }
}

/// An asymmetric rigid body (three different principal moments, centre of mass at the body
/// origin, like any MJCF body whose geoms are centred) in zero gravity, spinning mostly about
/// its intermediate axis: the unstable, tumbling case.
fn tumbler(integrator: envs::Integrator, dt: f64) -> (Model, Data) {
    let mut b = ModelBuilder::new();
    let mut o = options(dt, [0.0; 3]);
    o.integrator = integrator;
    b.set_options(o);
    let body = b.add_body(BodyId::WORLD, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(body);
    b.add_geom(body, GeomSpec::capsule_fromto(0.05, [-0.3, 0.0, 0.0], [0.3, 0.0, 0.0]));
    b.add_geom(body, GeomSpec::capsule_fromto(0.04, [0.0, -0.12, 0.0], [0.0, 0.12, 0.0]));
    let m = b.build().unwrap();
    let mut d = Data::new(&m);
    d.qvel[..6].copy_from_slice(&[0.3, -0.1, 0.2, 0.3, 0.2, 4.0]);
    (m, d)
}

/// Runs a tumbler for 10 s; returns (largest relative angular momentum error, largest
/// relative energy gain, final relative energy change).
fn tumble(integrator: envs::Integrator, dt: f64) -> (f64, f64, f64) {
    let (m, mut d) = tumbler(integrator, dt);
    let (p0, l0) = momentum(&m, &mut d);
    let e0 = kinetic_energy(&m, &mut d);
    let (mut lerr, mut gain) = (0.0f64, 0.0f64);
    for _ in 0..(10.0 / dt).round() as usize {
        envs::step(&m, &mut d);
        let (p, l) = momentum(&m, &mut d);
        // Linear momentum: exactly conserved (free body, no force) up to round-off.
        assert!(envs::math::norm(envs::math::sub(p, p0)) < 1e-9 * (1.0 + envs::math::norm(p0)));
        lerr = lerr.max(envs::math::norm(envs::math::sub(l, l0)) / envs::math::norm(l0));
        gain = gain.max(kinetic_energy(&m, &mut d) / e0 - 1.0);
    }
    (lerr, gain, kinetic_energy(&m, &mut d) / e0 - 1.0)
}

#[test]
fn torque_free_tumbling_conserves_angular_momentum_and_never_gains_energy() {
    // `Implicit` (Coriolis/centrifugal forces implicit, as MuJoCo's `implicit`) and
    // `EulerGyro` (implicit gyroscopic term of the floating root; exact for one rigid body).
    for integrator in [envs::Integrator::Implicit, envs::Integrator::EulerGyro] {
        let (l1, gain1, end1) = tumble(integrator, 0.005);
        let (l2, gain2, _) = tumble(integrator, 0.0025);
        // Never gains energy: 1e-12 relative is round-off of the energy sum.
        assert!(gain1 <= 1e-12 && gain2 <= 1e-12, "{integrator:?}: energy gained: {gain1} {gain2}");
        // ... without simply damping the motion out: < 6% lost over 10 s of tumbling at 5 ms.
        assert!(end1 > -0.06, "{integrator:?}: energy lost {end1}");
        // Angular momentum: conserved to first order in h (the scheme is first order): 3% over
        // 10 s at h = 5 ms (a wrong gyroscopic term gives O(1) errors), and halving h halves
        // the error (ratio 2 +- 20%).
        assert!(l1 < 0.03, "{integrator:?}: angular momentum error {l1}");
        assert!((l1 / l2 - 2.0).abs() < 0.4, "{integrator:?}: not first order: {l1} {l2}");
    }
}

#[test]
fn euler_tumbling_conserves_angular_momentum_to_first_order() {
    // MuJoCo's Euler (the default) treats the gyroscopic force explicitly and gains energy
    // h^2/2 |f|^2 per step; angular momentum still converges at first order.
    let (l1, gain1, _) = tumble(envs::Integrator::Euler, 0.005);
    let (l2, gain2, _) = tumble(envs::Integrator::Euler, 0.0025);
    assert!(l1 < 0.03 && (l1 / l2 - 2.0).abs() < 0.4, "angular momentum errors {l1} {l2}");
    // The energy gain is first order too (5% at 5 ms over 10 s).
    assert!(gain1 < 0.05 && (gain1 / gain2 - 2.0).abs() < 0.4, "energy gains {gain1} {gain2}");
}

/// Largest total linear and angular momentum norms of the ant in zero gravity under random
/// controls (held 0.05 s each) for 10 s, and the largest momentum scale seen.
fn ant_momentum_drift(dt: f64) -> (f64, f64, f64) {
    let mut m = ant([0.0; 3]);
    m.opt.timestep = dt;
    let mut d = Data::new(&m);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut pmax, mut lmax, mut scale) = (0.0f64, 0.0f64, 0.0f64);
    let frames = (0.05 / dt).round() as usize;
    for _ in 0..200 {
        for c in d.ctrl.iter_mut() {
            *c = rng.random_range(-1.0..1.0);
        }
        for _ in 0..frames {
            envs::step(&m, &mut d);
        }
        let (p, l) = momentum(&m, &mut d);
        pmax = pmax.max(envs::math::norm(p));
        lmax = lmax.max(envs::math::norm(l));
        // Momentum flowing between bodies: sum over bodies of m (|v| + |w|).
        let mut s = 0.0;
        for b in 1..m.bodies.len() {
            let c = d.cvel[b];
            s += m.bodies[b].mass * (envs::math::norm([c[3], c[4], c[5]]) + envs::math::norm([c[0], c[1], c[2]]));
        }
        scale = scale.max(s);
    }
    (pmax, lmax, scale)
}

#[test]
fn actuated_ant_in_zero_gravity_keeps_total_momentum() {
    // Motor torques and joint-limit forces are internal: total momentum stays zero in
    // continuous time; the first-order step conserves it to O(h) (as MuJoCo's Euler).
    let (p1, l1, scale) = ant_momentum_drift(0.01);
    let (p4, l4, _) = ant_momentum_drift(0.0025);
    assert!(scale > 1.0, "the ant should move: scale {scale}");
    // 2% of the momentum exchanged between bodies at h = 10 ms (measured ~1.5%); a missing
    // reaction torque would give O(100%).
    assert!(p1 < 0.02 * scale && l1 < 0.02 * scale, "momentum {p1} {l1} vs scale {scale}");
    // First order: dividing h by 4 divides the drift by ~4 (at least 2.5).
    assert!(p1 / p4 > 2.5 && l1 / l4 > 2.5, "not first order: {p1}/{p4}, {l1}/{l4}");
}

/// Random pose and velocity of the ant.
fn random_state(m: &Model, d: &mut Data, rng: &mut ChaCha8Rng) {
    for i in 0..3 {
        d.qpos[i] = rng.random_range(-1.0..1.0);
    }
    let q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
    let q = envs::math::quat_normalize(q);
    d.qpos[3..7].copy_from_slice(&q);
    for i in 7..m.nq {
        d.qpos[i] = rng.random_range(-1.5..1.5);
    }
    for v in d.qvel.iter_mut() {
        *v = rng.random_range(-2.0..2.0);
    }
}

#[test]
fn mass_matrix_is_symmetric_positive_definite_and_matches_inverse_dynamics() {
    let m = ant([0.0, 0.0, -9.81]);
    let mut d = Data::new(&m);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let nv = m.nv;
    for _ in 0..20 {
        random_state(&m, &mut d, &mut rng);
        envs::forward(&m, &mut d);
        let mm = envs::crba::dense_mass_matrix(&m, &d);
        // Column j of M from inverse dynamics: ID(e_j) - ID(0) (RNE, independent of CRBA).
        let zero = vec![0.0; nv];
        let c = envs::rne::inverse_dynamics(&m, &mut d, &zero);
        let scale = mm.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for j in 0..nv {
            let mut e = vec![0.0; nv];
            e[j] = 1.0;
            let col = envs::rne::inverse_dynamics(&m, &mut d, &e);
            for i in 0..nv {
                // Two algorithms, same arithmetic depth: agreement to ~1e-14 relative.
                let mij = col[i] - c[i];
                assert!((mij - mm[i * nv + j]).abs() < 1e-10 * scale, "M[{i}][{j}] {} vs {mij}", mm[i * nv + j]);
                assert!((mm[i * nv + j] - mm[j * nv + i]).abs() < 1e-12 * scale);
            }
        }
        // Positive definite: a dense Cholesky has positive pivots.
        let mut a = mm.clone();
        for k in 0..nv {
            for p in 0..k {
                let l = a[k * nv + p];
                for i in k..nv {
                    a[i * nv + k] -= l * a[i * nv + p];
                }
            }
            let piv = a[k * nv + k];
            assert!(piv > 1e-9 * scale, "pivot {k} = {piv}");
            let s = piv.sqrt();
            for i in k..nv {
                a[i * nv + k] /= s;
            }
        }
    }
}

#[test]
fn forward_then_inverse_dynamics_round_trip() {
    let mut m = ant([0.0, 0.0, -9.81]);
    m.opt.disable_limit = true;
    let mut d = Data::new(&m);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let h = m.opt.timestep;
    for _ in 0..20 {
        random_state(&m, &mut d, &mut rng);
        for c in d.ctrl.iter_mut() {
            *c = rng.random_range(-1.0..1.0);
        }
        for f in d.qfrc_applied.iter_mut() {
            *f = rng.random_range(-5.0..5.0);
        }
        envs::forward(&m, &mut d);
        let qacc = d.qacc.clone();
        let tau = envs::rne::inverse_dynamics(&m, &mut d, &qacc);
        for i in 0..m.nv {
            // forward solves (M + hD) qacc = tau_act + tau_app - D v - c, so
            // M qacc + c = tau_act + tau_app - D (v + h qacc).
            let damp = m.dof_damping[i];
            let expect = d.qfrc_actuator[i] + d.qfrc_applied[i] - damp * (d.qvel[i] + h * qacc[i]);
            // Forces up to ~200 N m; round-off ~1e-13 relative.
            assert!((tau[i] - expect).abs() < 1e-9 * (1.0 + expect.abs()), "dof {i}: {} vs {expect}", tau[i]);
        }
    }
}

#[test]
fn hinge_under_constant_torque_accelerates_at_torque_over_inertia_plus_armature() {
    for (armature, damping) in [(0.0, 0.0), (0.7, 0.0), (0.7, 2.0)] {
        let mut b = ModelBuilder::new();
        b.set_options(options(0.01, [0.0, 0.0, -9.81]));
        let body = b.add_body(BodyId::WORLD, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0]);
        // Vertical axis: gravity exerts no torque about it.
        b.add_hinge(body, HingeSpec::new([0.0, 0.0, 1.0]).armature(armature).damping(damping));
        b.add_geom(body, GeomSpec::sphere(0.1).at([0.5, 0.0, 0.0]));
        let m = b.build().unwrap();
        let mass = m.bodies[1].mass;
        let inertia = mass * (0.25 + 0.4 * 0.01) + armature;
        let tau = 3.0;
        let mut d = Data::new(&m);
        d.qfrc_applied[0] = tau;
        let h = m.opt.timestep;
        let mut v: f64 = 0.0;
        for _ in 0..50 {
            envs::step(&m, &mut d);
            // Implicit damping: v' = v + h (tau - D v) / (I + a + h D); no Coriolis for one hinge.
            v += h * (tau - damping * v) / (inertia + h * damping);
            assert!((d.qvel[0] - v).abs() < 1e-12 * (1.0 + v.abs()), "v {} vs {v}", d.qvel[0]);
        }
        if damping == 0.0 {
            assert!((d.qacc[0] - tau / inertia).abs() < 1e-12 * tau / inertia);
        }
    }
}

#[test]
fn root_spin_bias_derivative_matches_central_differences() {
    // `EulerGyro`'s columns of dc/dqvel for the floating root's angular dofs, from one
    // forward-mode Newton-Euler pass, against central differences of the bias (quadratic in
    // qvel, so the differences are exact up to round-off): the MuJoCo ant and a MeBen unimal
    // whose torso is a tenth of its mass, at random poses and velocities.
    let (unimal, _) =
        envs::brax::agent_model(&envs::brax::load_morphology("unimal_2").unwrap(), &envs::brax::BraxPhysics::default())
            .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    for m in [ant([0.0, 0.0, -9.81]), unimal] {
        let nv = m.nv;
        for _ in 0..3 {
            let mut d = Data::new(&m);
            random_state(&m, &mut d, &mut rng);
            for v in d.qvel.iter_mut() {
                *v = rng.random_range(-5.0..5.0);
            }
            envs::forward(&m, &mut d);
            let mut cols = vec![0.0; 3 * nv];
            envs::integrator::root_spin_bias_derivative(&m, &mut d, &mut cols);
            let (mut worst, mut scale) = (0.0f64, 0.0f64);
            for k in 0..3 {
                let mut e = d.clone();
                let bias = |e: &mut Data, w: f64| {
                    e.qvel[3 + k] = w;
                    envs::kinematics::com_vel(&m, e);
                    envs::rne::bias(&m, e);
                    e.qfrc_bias.clone()
                };
                let (plus, minus) = (bias(&mut e, d.qvel[3 + k] + 1.0), bias(&mut e, d.qvel[3 + k] - 1.0));
                for i in 0..nv {
                    let fd = 0.5 * (plus[i] - minus[i]);
                    worst = worst.max((fd - cols[k * nv + i]).abs());
                    scale = scale.max(fd.abs());
                }
            }
            assert!(scale > 1e-3, "a moving state has gyroscopic coupling: {scale}");
            assert!(worst < 1e-10 * scale, "analytic vs central differences: {worst} (scale {scale})");
        }
    }
}

#[test]
fn three_column_solve_matches_three_single_solves() {
    // `crba::ltdl_solve3` (EulerGyro's columns) against `ltdl_solve` column by column.
    let m = ant([0.0, 0.0, -9.81]);
    let nv = m.nv;
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let mut d = Data::new(&m);
    random_state(&m, &mut d, &mut rng);
    envs::forward(&m, &mut d);
    let cols: Vec<f64> = (0..3 * nv).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut together = cols.clone();
    envs::crba::ltdl_solve3(&m, &d.qh, &mut together);
    for k in 0..3 {
        let mut single = cols[k * nv..(k + 1) * nv].to_vec();
        envs::crba::ltdl_solve(&m, &d.qh, &mut single);
        for i in 0..nv {
            assert!((single[i] - together[k * nv + i]).abs() <= 1e-12 * (1.0 + single[i].abs()), "column {k}, dof {i}");
        }
    }
}
