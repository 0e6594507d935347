//! Soft constraints: joint limits, resting contact, friction on an incline, collisions
//! between agents, collision filtering. Every tolerance is justified where it is used.

use envs::constraints::impedance;
use envs::diagnostics::{kinetic_energy, momentum};
use envs::{BodyId, Data, GeomSpec, HingeSpec, Model, ModelBuilder, Options};

/// Solves the soft-constraint rest condition `(1 - imp)/imp * w * f = k * imp * depth` for the
/// depth (positive), where `w` is the row's `A_kk` (or invweight) and `f` its force; MuJoCo's
/// `k = 1 / (dmax^2 tau^2 zeta^2)`. Bisection: the left side decreases and the right side
/// increases with depth.
fn rest_depth(o: &Options, w: f64, f: f64) -> f64 {
    let tau = o.solref[0].max(2.0 * o.timestep);
    let dmax = o.solimp[1];
    let k = 1.0 / (dmax * dmax * tau * tau * o.solref[1] * o.solref[1]);
    let g = |x: f64| {
        let imp = impedance(&o.solimp, -x);
        (1.0 - imp) / imp * w * f - k * imp * x
    };
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid) > 0.0 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

#[test]
fn joint_driven_into_its_limit_stays_near_it() {
    let m = {
        let mut b = ModelBuilder::new();
        b.set_options(Options { timestep: 0.01, gravity: [0.0; 3], ..Options::default() });
        let body = b.add_body(BodyId::WORLD, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
        let hinge = b.add_hinge(body, HingeSpec::new([0.0, 0.0, 1.0]).range(-0.5, 0.5).armature(0.1).damping(0.5));
        b.add_geom(body, GeomSpec::capsule_fromto(0.05, [0.0; 3], [0.5, 0.0, 0.0]));
        b.add_actuator(hinge, 20.0, Some([-1.0, 1.0]));
        b.build().unwrap()
    };
    let mut d = Data::new(&m);
    d.ctrl[0] = 1.0; // 20 N m towards the upper limit
    let mut qmax: f64 = 0.0;
    let mut tail = Vec::new();
    for s in 0..300 {
        envs::step(&m, &mut d);
        qmax = qmax.max(d.qpos[0]);
        if s >= 200 {
            tail.push(d.qpos[0]);
        }
    }
    // Predicted rest violation: the limit row carries f = 20 N m, w = dof_invweight0.
    let depth = rest_depth(&m.opt, m.dof_invweight0[0], 20.0);
    let q_end = *tail.last().unwrap();
    // At rest the PGS solution is exact (one row): 1% of the depth covers round-off in the
    // bisection and the last micro-motion.
    assert!((q_end - (0.5 + depth)).abs() < 0.01 * depth + 1e-9, "q {q_end} vs limit + {depth}");
    // The overshoot while hitting the limit stays small: within 0.1 rad of the limit
    // (critically damped soft constraint with time constant 2 dt).
    assert!(qmax < 0.6, "overshoot to {qmax}");
    // No jitter once resting: the last second varies by less than 1e-9 rad.
    let spread =
        tail.iter().fold(f64::NEG_INFINITY, |a, &x| a.max(x)) - tail.iter().fold(f64::INFINITY, |a, &x| a.min(x));
    assert!(spread < 1e-9, "jitter {spread}");
}

fn ball_on_plane(dt: f64, z0: f64) -> Model {
    let mut b = ModelBuilder::new();
    b.set_options(Options { timestep: dt, ..Options::default() });
    b.add_geom(BodyId::WORLD, GeomSpec::plane());
    let ball = b.add_body(BodyId::WORLD, [0.0, 0.0, z0], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(ball);
    b.add_geom(ball, GeomSpec::sphere(0.1));
    b.build().unwrap()
}

#[test]
fn sphere_dropped_on_the_plane_settles_at_the_predicted_depth_without_jitter() {
    let m = ball_on_plane(0.01, 0.3);
    let mut d = Data::new(&m);
    let mut zs = Vec::new();
    for _ in 0..400 {
        envs::step(&m, &mut d);
        zs.push(d.qpos[2]);
    }
    assert!(zs.iter().all(|z| *z > 0.0), "fell through the plane");
    // Rest: the normal row carries m g with A_nn = J_n M^-1 J_n^T = 1 / m (a normal force
    // through the centre of a sphere does not turn it).
    let mass = m.bodies[1].mass;
    let depth = rest_depth(&m.opt, 1.0 / mass, mass * 9.81);
    let z_end = *zs.last().unwrap();
    // The contact is exactly soft-constraint equilibrium at rest: 1% of the (0.2 mm) depth.
    assert!((z_end - (0.1 - depth)).abs() < 0.01 * depth, "z {z_end} vs {}", 0.1 - depth);
    // No jitter: over the last second the height varies by less than 1 nm.
    let tail = &zs[300..];
    let spread =
        tail.iter().fold(f64::NEG_INFINITY, |a, &x| a.max(x)) - tail.iter().fold(f64::INFINITY, |a, &x| a.min(x));
    assert!(spread < 1e-9, "jitter {spread}");
    // And it does not wander sideways or spin up.
    assert!(d.qpos[0].abs() < 1e-9 && d.qpos[1].abs() < 1e-9);
    assert!(d.qvel.iter().all(|v| v.abs() < 1e-9), "qvel {:?}", d.qvel);
}

/// A sled: a capsule lying along x (sliding along its axis it cannot roll), on the plane
/// z = 0, with gravity tilted by `angle` about y so that the plane is an incline sloping down
/// towards +x. (A sled on three non-collinear points slides ~3% too easily: the block
/// Gauss-Seidel friction projection lets the contacts squeeze each other sideways instead of
/// dissipating maximally; collinear supports, like every capsule, are exact.)
fn sled(angle: f64) -> (Model, Data) {
    let mut b = ModelBuilder::new();
    let g = 9.81;
    b.set_options(Options { timestep: 0.005, gravity: [g * angle.sin(), 0.0, -g * angle.cos()], ..Options::default() });
    b.add_geom(BodyId::WORLD, GeomSpec::plane());
    let body = b.add_body(BodyId::WORLD, [0.0, 0.0, 0.05], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(body);
    b.add_geom(body, GeomSpec::capsule_fromto(0.05, [-0.15, 0.0, 0.0], [0.15, 0.0, 0.0]));
    let m = b.build().unwrap();
    let d = Data::new(&m);
    (m, d)
}

/// Slope of a least-squares line through (t, v).
fn slope(t: &[f64], v: &[f64]) -> f64 {
    let n = t.len() as f64;
    let (mt, mv) = (t.iter().sum::<f64>() / n, v.iter().sum::<f64>() / n);
    let num: f64 = t.iter().zip(v).map(|(a, b)| (a - mt) * (b - mv)).sum();
    let den: f64 = t.iter().map(|a| (a - mt) * (a - mt)).sum();
    num / den
}

#[test]
fn sled_slides_above_the_friction_angle_with_the_right_acceleration() {
    // mu = 1: friction angle 45 degrees. At 60 degrees: a = g (sin - mu cos) = 3.59 m/s^2.
    let angle = 60f64.to_radians();
    let (m, mut d) = sled(angle);
    let (mut ts, mut vs) = (Vec::new(), Vec::new());
    for _ in 0..400 {
        envs::step(&m, &mut d);
        if d.time > 0.5 {
            ts.push(d.time);
            vs.push(d.qvel[0]);
        }
    }
    let expected = 9.81 * (angle.sin() - angle.cos());
    let a = slope(&ts, &vs);
    // Sliding saturates the friction disc exactly (|f_t| = mu f_n); the soft normal contact
    // settles within ~0.1 s: 2% covers the residual PGS error.
    assert!((a - expected).abs() < 0.02 * expected, "acceleration {a} vs {expected}");
}

#[test]
fn sled_sticks_below_the_friction_angle_after_decelerating_at_the_right_rate() {
    // At 30 degrees a sled launched down the slope at 1 m/s decelerates at
    // g (mu cos - sin) = 3.59 m/s^2, stops after ~0.28 s and stays.
    let angle = 30f64.to_radians();
    let (m, mut d) = sled(angle);
    // Let it settle on the incline first (it must not start sliding on its own).
    for _ in 0..200 {
        envs::step(&m, &mut d);
    }
    // Soft friction creeps at v ~ R F / (2 b mu^2): a few mm/s here, far from sliding.
    assert!(d.qvel[0].abs() < 0.01, "creeps at {} m/s", d.qvel[0]);
    d.qvel[0] = 1.0;
    let (mut ts, mut vs) = (Vec::new(), Vec::new());
    for _ in 0..400 {
        envs::step(&m, &mut d);
        if d.time > 1.03 && d.time < 1.2 {
            ts.push(d.time);
            vs.push(d.qvel[0]);
        }
    }
    let expected = -9.81 * (angle.cos() - angle.sin());
    let a = slope(&ts, &vs);
    // 1%: the deceleration is measured over 0.17 s of sliding right after the kick (the
    // friction disc saturates exactly; measured within 0.1%).
    assert!((a - expected).abs() < 0.01 * expected.abs(), "deceleration {a} vs {expected}");
    assert!(d.qvel[0].abs() < 0.01, "still moving at {} m/s after 2 s", d.qvel[0]);
    let x0 = d.qpos[0];
    for _ in 0..200 {
        envs::step(&m, &mut d);
    }
    // Sticking: under 1 cm of creep per second (sliding would cover ~1.8 m).
    assert!((d.qpos[0] - x0).abs() < 0.01, "slid {} m in 1 s", d.qpos[0] - x0);
}

/// Two free bodies (two trees) flying into each other in zero gravity.
fn two_bodies(g1: GeomSpec, g2: GeomSpec) -> (Model, Data) {
    let mut b = ModelBuilder::new();
    b.set_options(Options { timestep: 0.002, gravity: [0.0; 3], ..Options::default() });
    let a = b.add_body(BodyId::WORLD, [-0.5, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(a);
    b.add_geom(a, g1);
    let c = b.add_body(BodyId::WORLD, [0.5, 0.05, 0.02], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(c);
    b.add_geom(c, g2);
    let m = b.build().unwrap();
    let mut d = Data::new(&m);
    d.qvel[0] = 2.0; // body a moves +x
    d.qvel[6] = -1.0; // body c moves -x
    d.qvel[11] = 3.0; // and spins (friction couples it)
    (m, d)
}

#[test]
fn two_bodies_colliding_in_zero_gravity_conserve_momentum() {
    // Spheres: equal and opposite contact forces at one point conserve linear and angular
    // momentum exactly in the discrete step too (isotropic inertia: no gyroscopic term).
    let (m, mut d) = two_bodies(GeomSpec::sphere(0.1), GeomSpec::sphere(0.15).density(500.0));
    let (p0, l0) = momentum(&m, &mut d);
    let e0 = kinetic_energy(&m, &mut d);
    let mut touched = false;
    for _ in 0..500 {
        envs::step(&m, &mut d);
        touched |= !d.contacts.is_empty();
        let (p, l) = momentum(&m, &mut d);
        for k in 0..3 {
            // Round-off of sums of O(10) numbers over 500 steps.
            assert!((p[k] - p0[k]).abs() < 1e-9 && (l[k] - l0[k]).abs() < 1e-9, "p {p:?} {p0:?} l {l:?} {l0:?}");
        }
    }
    assert!(touched, "the bodies never met");
    // They bounced apart (velocity of a reversed or reduced) and lost, never gained, energy.
    assert!(d.qvel[0] < 1.0, "body a still moves at {}", d.qvel[0]);
    let e = kinetic_energy(&m, &mut d);
    assert!(e <= e0 * (1.0 + 1e-12), "energy {e} > {e0}");

    // Capsules (Team Sumo limbs): linear momentum is still exact; angular momentum only to
    // first order (explicit gyroscopic term of non-isotropic bodies), so it is not checked.
    let (m, mut d) = two_bodies(
        GeomSpec::capsule_fromto(0.08, [0.0, -0.2, 0.0], [0.0, 0.2, 0.0]),
        GeomSpec::capsule_fromto(0.08, [0.0, 0.0, -0.2], [0.0, 0.0, 0.2]),
    );
    let (p0, _) = momentum(&m, &mut d);
    let mut touched = false;
    for _ in 0..500 {
        envs::step(&m, &mut d);
        touched |= !d.contacts.is_empty();
        let (p, _) = momentum(&m, &mut d);
        for k in 0..3 {
            assert!((p[k] - p0[k]).abs() < 1e-9, "p {p:?} {p0:?}");
        }
    }
    assert!(touched, "the capsules never met");
}

#[test]
fn collision_filtering_same_agent_goal_balls_and_bits() {
    let mut b = ModelBuilder::new();
    b.set_options(Options { timestep: 0.01, gravity: [0.0; 3], ..Options::default() });
    // Agent 1: two overlapping geoms on parent and child (no self-collision).
    let a = b.add_body(BodyId::WORLD, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(a);
    b.add_geom(a, GeomSpec::sphere(0.2));
    let a2 = b.add_body(a, [0.1, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    b.add_hinge(a2, HingeSpec::new([0.0, 0.0, 1.0]));
    b.add_geom(a2, GeomSpec::sphere(0.2));
    // A goal ball overlapping everything, colliding with nothing.
    let goal = b.add_body(BodyId::WORLD, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
    b.add_geom(goal, GeomSpec::sphere(0.5).collision(0, 0));
    // Agent 2 overlapping agent 1, but with bits that do not match agent 1 (contype 2,
    // conaffinity 2 vs 1/1).
    let c = b.add_body(BodyId::WORLD, [0.3, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(c);
    b.add_geom(c, GeomSpec::sphere(0.2).collision(2, 2));
    // Agent 3 overlapping agent 1 with default bits: collides with agent 1 only.
    let e = b.add_body(BodyId::WORLD, [-0.25, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
    b.add_free_joint(e);
    let ge = b.add_geom(e, GeomSpec::sphere(0.2));
    let m = b.build().unwrap();
    let mut d = Data::new(&m);
    envs::forward(&m, &mut d);
    // Agent 3's sphere overlaps both spheres of agent 1 (centres 0.25 and 0.35 apart, radii
    // 0.2 + 0.2): two contacts, nothing else.
    assert_eq!(d.contacts.len(), 2, "{:?}", d.contacts);
    assert!(d.contacts.iter().all(|c| c.geom2 == ge.0 || c.geom1 == ge.0));
}

#[test]
fn the_ant_rests_on_the_ground_without_jitter() {
    // Unactuated, the ant's damped ankles sag under its weight until they reach their 30
    // degree limit (tens of seconds from the benchmark pose; MuJoCo does the same), so start
    // it there and drop it from 0.5 m.
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/mujoco_ant.xml");
    let mut m = envs::mjcf::load_file(path).unwrap();
    m.opt.timestep = 0.01;
    let mut d = Data::new(&m);
    let a = 30f64.to_radians();
    d.reset_to(&m, &[0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.0, a, 0.0, -a, 0.0, -a, 0.0, a]).unwrap();
    for _ in 0..300 {
        envs::step(&m, &mut d);
    }
    let (x0, y0) = (d.qpos[0], d.qpos[1]);
    let mut zs = Vec::new();
    for _ in 0..100 {
        envs::step(&m, &mut d);
        zs.push(d.qpos[2]);
    }
    // Standing on its four feet: the shin (0.4 sqrt 2 long, tilted 30 degrees down) ends in a
    // cap of radius 0.08, so the torso is at 0.08 + 0.4 sqrt 2 sin 30 = 0.3628 m minus the
    // soft-contact depth (a fraction of a millimetre for a quarter of the weight per foot).
    let geometric = 0.08 + 0.4 * 2f64.sqrt() * a.sin();
    let z = zs[99];
    assert_eq!(d.contacts.len(), 4, "contacts {:?}", d.contacts);
    assert!(z < geometric && z > geometric - 0.002, "torso at {z}, geometry {geometric}");
    // Without jitter: the torso height varies by less than 1 nm over the last second, and the
    // ant does not creep (< 1 micrometre).
    let spread = zs.iter().fold(f64::NEG_INFINITY, |a, &x| a.max(x)) - zs.iter().fold(f64::INFINITY, |a, &x| a.min(x));
    assert!(spread < 1e-9, "jitter {spread}");
    assert!((d.qpos[0] - x0).hypot(d.qpos[1] - y0) < 1e-6, "creep");
}
