//! Tests of the Brax v1 config loader: the seven MeBen morphologies, the parser's robustness
//! and every error path.

use envs::brax::config::{AngleLimit, ColliderShape};
use envs::brax::morphologies::{MORPHOLOGIES, known_names};
use envs::brax::{BraxError, load_config_file, load_morphology, morphology, parse_config};

/// Expected actuated DoF (MEBEN.md section 1; the two sumo unimals counted from their files).
const ACTUATED_DOF: [(&str, usize); 7] = [
    ("ant", 8),
    ("claw", 16),
    ("centipede", 14),
    ("unimal_5506-10-14-17-10-38-34", 13),
    ("unimal_5506-12-11-17-05-56-16", 10),
    ("unimal_5506-13-5-02-21-35-41", 13),
    ("unimal_5506-15-11-01-10-04-14", 10),
];

#[test]
fn all_seven_morphologies_load_with_their_actuated_dof() {
    assert_eq!(MORPHOLOGIES.len(), 7);
    for (name, dof) in ACTUATED_DOF {
        let config = load_morphology(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(config.actuated_dof(), dof, "{name}");
        // Every joint is actuated in these files.
        assert_eq!(config.dof(), dof, "{name}");
        // One connected tree: every body but the root is some joint's child.
        let children: std::collections::BTreeSet<&str> = config.joints.iter().map(|j| j.child.as_str()).collect();
        assert_eq!(children.len() + 1, config.bodies.len(), "{name}");
    }
}

#[test]
fn morphologies_are_found_by_name_stem_and_alias() {
    let by_stem = morphology("5506-10-14-17-10-38-34").unwrap();
    assert_eq!(by_stem.name, "unimal_5506-10-14-17-10-38-34");
    assert_eq!(morphology("unimal_1").unwrap().name, by_stem.name);
    assert_eq!(morphology("unimal_2").unwrap().name, "unimal_5506-12-11-17-05-56-16");
    assert_eq!(morphology("claw.txt").unwrap().name, "claw");
    let names = known_names();
    for m in &MORPHOLOGIES {
        assert!(names.contains(&m.name));
        assert!(names.contains(&m.file_stem));
    }
}

#[test]
fn unknown_morphology_lists_the_known_names() {
    let err = load_morphology("spider").unwrap_err();
    let BraxError::UnknownMorphology { name, known } = &err else { panic!("{err:?}") };
    assert_eq!(name, "spider");
    assert_eq!(known.len(), known_names().len());
    let text = err.to_string();
    for n in ["ant", "claw", "centipede", "unimal_5506-15-11-01-10-04-14", "unimal_1"] {
        assert!(text.contains(n), "{text}");
    }
}

#[test]
fn ant_config_matches_the_mujoco_ant_design() {
    let ant = load_morphology("ant").unwrap();
    let torso = &ant.bodies[ant.root_body()];
    assert_eq!(torso.name, "torso");
    assert_eq!(torso.mass, 10.0);
    // A capsule of total length 2r is MuJoCo's sphere of radius 0.25.
    assert_eq!(torso.colliders[0].shape, ColliderShape::Capsule { radius: 0.25, length: 0.5, end: 1 });
    let mut hips = 0;
    let mut ankles = 0;
    for j in &ant.joints {
        if j.parent == "torso" {
            hips += 1;
            assert_eq!(j.angle_limits, vec![AngleLimit { min: -30.0, max: 30.0 }]);
        } else {
            ankles += 1;
            assert_eq!(j.angle_limits, vec![AngleLimit { min: 30.0, max: 70.0 }]);
        }
        assert_eq!(j.angular_damping, 35.0);
    }
    assert_eq!((hips, ankles), (4, 4));
    for b in ant.bodies.iter().filter(|b| b.name != "torso") {
        let ColliderShape::Capsule { radius, .. } = b.colliders[0].shape else { panic!("{} has no capsule", b.name) };
        assert_eq!(radius, 0.08);
    }
    assert!(ant.actuators.iter().all(|a| a.strength == 350.0));
}

#[test]
fn missing_bounds_of_an_angle_limit_are_zero() {
    // unimal_1's joint limby_16: `angle_limit { }` then `angle_limit { max: 30.0 }`.
    let u = load_morphology("unimal_1").unwrap();
    let j = &u.joints[u.joint_index("limby_16").unwrap()];
    assert_eq!(j.angle_limits, vec![AngleLimit { min: 0.0, max: 0.0 }, AngleLimit { min: 0.0, max: 30.0 }]);
    let j = &u.joints[u.joint_index("limbx_18").unwrap()];
    assert_eq!(j.angle_limits, vec![AngleLimit { min: -45.0, max: 0.0 }]);
}

#[test]
fn loads_from_a_user_file_and_reports_unreadable_ones() {
    let dir = std::env::temp_dir().join(format!("brax_loader_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ant_copy.txt");
    std::fs::write(&path, morphology("ant").unwrap().text).unwrap();
    let from_file = load_config_file(&path).unwrap();
    let built_in = load_morphology("ant").unwrap();
    assert_eq!(from_file.bodies, built_in.bodies);
    assert_eq!(from_file.source, path.display().to_string());

    let bad = dir.join("bad.txt");
    std::fs::write(&bad, "bodies {\n  name: \"a\"\n  mass: 1\n\n").unwrap();
    let err = load_config_file(&bad).unwrap_err();
    let text = err.to_string();
    assert!(text.starts_with(&format!("{}:5:", bad.display())), "{text}");
    assert!(text.contains("expected `}` to close `bodies` opened at line 1"), "{text}");

    let missing = dir.join("does_not_exist.txt");
    let err = load_config_file(&missing).unwrap_err();
    assert!(matches!(err, BraxError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("does_not_exist.txt"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A minimal valid two-body config, edited by the error tests.
const TWO_BODIES: &str = r#"
bodies { name: "a" mass: 1 colliders { sphere { radius: 0.1 } } }
bodies { name: "b" mass: 1 colliders { capsule { radius: 0.05 length: 0.3 } } }
joints {
  name: "j"
  parent: "a"
  child: "b"
  angle_limit { min: -10 max: 10 }
}
actuators { name: "m" joint: "j" strength: 100 torque {} }
"#;

/// Loads `text` and returns the error message, checking it names the source and `line`.
fn config_error(text: &str, line: usize) -> String {
    let err = parse_config(text, "cfg.txt").expect_err("the config should be rejected");
    let location = err.location().expect("errors in a text have a location");
    assert_eq!(location.source, "cfg.txt");
    assert_eq!(location.line, line, "{err}");
    err.to_string()
}

#[test]
fn the_minimal_config_is_valid() {
    let c = parse_config(TWO_BODIES, "cfg.txt").unwrap();
    assert_eq!((c.bodies.len(), c.joints.len(), c.actuated_dof()), (2, 1, 1));
}

#[test]
fn malformed_syntax_names_file_line_and_expectation() {
    let text = TWO_BODIES.replace("parent: \"a\"", "parent \"a\"");
    let m = config_error(&text, 6);
    // Line 6, column 10: where the string stands instead of `:`.
    assert!(m.contains("cfg.txt:6:10: syntax error"), "{m}");
    assert!(m.contains("expected `:` or `{` after field name `parent`"), "{m}");
}

#[test]
fn unknown_body_in_a_joint_is_reported_with_known_bodies() {
    let text = TWO_BODIES.replace("child: \"b\"", "child: \"c\"");
    // Reported at the `child` field itself: line 7, column 3.
    let m = config_error(&text, 7);
    assert!(m.starts_with("cfg.txt:7:3: "), "{m}");
    assert!(m.contains("joints[\"j\"].child"), "{m}");
    assert!(m.contains("\"c\""), "{m}");
    assert!(m.contains("unknown body name; known bodies: \"a\", \"b\""), "{m}");
}

#[test]
fn a_body_with_two_parents_is_rejected() {
    let text = format!(
        "{TWO_BODIES}\nbodies {{ name: \"c\" mass: 1 colliders {{ sphere {{ radius: 0.1 }} }} }}\njoints {{ name: \"k\" parent: \"c\" child: \"b\" angle_limit {{ }} }}\n"
    );
    let m = config_error(&text, 13);
    assert!(m.contains("body has two parents"), "{m}");
    assert!(m.contains("\"j\""), "{m}");
}

#[test]
fn two_joints_on_one_child_must_share_the_joint_point() {
    // The sumo unimal 5506-13-5-02-21-35-41 gives limb_end_3 two joints from torso_0 at the
    // same point (limbx_1 and limby_1): accepted. Different points are not.
    let u = load_morphology("unimal_5506-13-5-02-21-35-41").unwrap();
    let on_limb: Vec<&str> = u.joints.iter().filter(|j| j.child == "limb_end_3").map(|j| j.name.as_str()).collect();
    assert_eq!(on_limb, vec!["limbx_1", "limby_1"]);
    let text = format!(
        "{TWO_BODIES}\njoints {{ name: \"k\" parent: \"a\" child: \"b\" parent_offset {{ x: 0.1 }} angle_limit {{ }} }}\n"
    );
    let m = config_error(&text, 12);
    assert!(m.contains("must share parent_offset"), "{m}");
    let same_point = format!("{TWO_BODIES}\njoints {{ name: \"k\" parent: \"a\" child: \"b\" angle_limit {{ }} }}\n");
    assert_eq!(parse_config(&same_point, "cfg.txt").unwrap().dof(), 2);
}

#[test]
fn missing_required_fields_are_named() {
    let m = config_error(&TWO_BODIES.replace("mass: 1 colliders { capsule", "colliders { capsule"), 3);
    assert!(m.contains("field `bodies[\"b\"].mass`: missing required field `mass`"), "{m}");
    let m = config_error(&TWO_BODIES.replace("  child: \"b\"\n", ""), 4);
    assert!(m.contains("missing required field `child`"), "{m}");
    let m = config_error(&TWO_BODIES.replace(" length: 0.3", ""), 3);
    assert!(m.contains("capsule[0].length"), "{m}");
    let m = config_error(&TWO_BODIES.replace("strength: 100 ", ""), 10);
    assert!(m.contains("missing required field `strength`"), "{m}");
}

#[test]
fn wrong_counts_and_values_are_rejected() {
    let three =
        TWO_BODIES.replace("angle_limit { min: -10 max: 10 }", "angle_limit { } angle_limit { } angle_limit { }");
    let m = config_error(&three, 4);
    assert!(m.contains("1 or 2 `angle_limit` entries"), "{m}");
    assert!(m.contains("found 3"), "{m}");
    let none = TWO_BODIES.replace("angle_limit { min: -10 max: 10 }", "");
    assert!(config_error(&none, 4).contains("found 0"));
    let reversed = TWO_BODIES.replace("min: -10 max: 10", "min: 10 max: -10");
    let m = config_error(&reversed, 8);
    assert!(m.contains("min 10 > max -10"), "{m}");
    let text_mass = TWO_BODIES.replace("name: \"a\" mass: 1", "name: \"a\" mass: \"heavy\"");
    let m = config_error(&text_mass, 2);
    assert!(m.contains("bodies[\"a\"].mass` = \"heavy\": expected a number"), "{m}");
    let twice = TWO_BODIES.replace("name: \"a\" mass: 1", "name: \"a\" mass: 1 mass: 2");
    assert!(config_error(&twice, 2).contains("field given twice"));
    let short = TWO_BODIES.replace("length: 0.3", "length: 0.05");
    assert!(config_error(&short, 3).contains("at least 2 * radius"));
    let inf = TWO_BODIES.replace("radius: 0.1", "radius: inf");
    assert!(config_error(&inf, 2).contains("finite"));
    let end = TWO_BODIES.replace("length: 0.3", "length: 0.3 end: 2");
    assert!(config_error(&end, 3).contains("`end` must be -1, 0 or 1"));
}

/// Absurd physical values are refused at their field with the accepted range.
/// Before, `mass: 1e300`, `parent_offset { x: 1e160 }`, `strength: 1e300` or a
/// collider at `x: 1e300` passed the loader and were reported by the simulator as a mass
/// matrix that is not positive definite; `angle_limit { min: -1e300 max: 1e300 }` loaded and
/// made training stop on a non-finite gradient; `radius: 1e-200` became "degenerate body
/// geometry"; `mass: 1e-300`, `angular_damping: 1e300`, `rotation { y: 1e300 }` and a negative
/// `inertia` loaded silently.
#[test]
fn extreme_physical_values_are_refused_naming_field_value_and_range() {
    let cases: &[(&str, &str, usize, &str, &str)] = &[
        (
            "name: \"a\" mass: 1",
            "name: \"a\" mass: 1e300",
            2,
            "bodies[\"a\"].mass` = 1e300",
            "a mass must be between 1e-6 and 1e6 kg",
        ),
        ("name: \"a\" mass: 1", "name: \"a\" mass: 1e-300", 2, "bodies[\"a\"].mass` = 1e-300", "a mass must be"),
        ("radius: 0.1", "radius: 1e160", 2, "sphere[0].radius` = 1e160", "a size must be between 1e-4 and 1000 m"),
        ("radius: 0.05", "radius: 1e-200", 3, "capsule[0].radius` = 1e-200", "a size must be"),
        ("length: 0.3", "length: 1e300", 3, "capsule[0].length` = 1e300", "a size must be"),
        (
            "child: \"b\"",
            "child: \"b\" parent_offset { x: 1e160 }",
            7,
            "joints[\"j\"].parent_offset.x` = 1e160",
            "a length or position must be between -1000 and 1000 m",
        ),
        (
            "child: \"b\"",
            "child: \"b\" child_offset { z: -2e3 }",
            7,
            "joints[\"j\"].child_offset.z` = -2e3",
            "a length or position",
        ),
        (
            "child: \"b\"",
            "child: \"b\" rotation { y: 1e300 }",
            7,
            "joints[\"j\"].rotation.y` = 1e300",
            "an angle must be between -3600 and 3600 degrees",
        ),
        (
            "child: \"b\"",
            "child: \"b\" reference_rotation { x: -1e20 }",
            7,
            "reference_rotation.x` = -1e20",
            "an angle",
        ),
        (
            "child: \"b\"",
            "child: \"b\" angular_damping: 1e300",
            7,
            "joints[\"j\"].angular_damping` = 1e300",
            "a damping must be between 0 and 1e6 N m s/rad",
        ),
        ("min: -10 max: 10", "min: -1e300 max: 1e300", 8, "angle_limit[0].min` = -1e300", "an angle must be"),
        ("strength: 100", "strength: 1e300", 10, "actuators[\"m\"].strength` = 1e300", "a gear or strength must be"),
        (
            "sphere { radius: 0.1 }",
            "position { x: 1e300 } sphere { radius: 0.1 }",
            2,
            "colliders[0].position.x` = 1e300",
            "a length or position",
        ),
        (
            "sphere { radius: 0.1 }",
            "rotation { z: 1e17 } sphere { radius: 0.1 }",
            2,
            "colliders[0].rotation.z` = 1e17",
            "an angle",
        ),
        (
            "name: \"a\" mass: 1",
            "name: \"a\" mass: 1 inertia { x: -1 y: 1 z: 1 }",
            2,
            "bodies[\"a\"].inertia.x` = -1",
            "an inertia must be between 1e-12 and 1e12 kg m^2",
        ),
        (
            "name: \"a\" mass: 1",
            "name: \"a\" mass: 1 inertia { x: 1 y: 1 }",
            2,
            "bodies[\"a\"].inertia` = {...}: `z` is missing, so 0",
            "an inertia must be",
        ),
    ];
    for (old, new, line, field, range) in cases {
        assert!(TWO_BODIES.contains(old), "{old}");
        let m = config_error(&TWO_BODIES.replacen(old, new, 1), *line);
        assert!(m.contains(field), "{new}: field missing from: {m}");
        assert!(m.contains("is out of range") && m.contains(range), "{new}: range missing from: {m}");
    }
    // The bounds themselves are accepted, and so is every built-in morphology (loaded above).
    let edge = TWO_BODIES
        .replacen("name: \"a\" mass: 1", "name: \"a\" mass: 1e6", 1)
        .replacen("radius: 0.1", "radius: 1e-4", 1)
        .replacen("min: -10 max: 10", "min: -3600 max: 3600", 1)
        .replacen("strength: 100", "strength: 1e6", 1);
    parse_config(&edge, "cfg.txt").unwrap();
}

#[test]
fn unknown_and_unsupported_fields_are_rejected_and_scene_settings_ignored() {
    let typo = TWO_BODIES.replace("strength: 100", "strenght: 100");
    let m = config_error(&typo, 10);
    assert!(m.contains("unknown field `strenght`"), "{m}");
    let servo = TWO_BODIES.replace("torque {}", "angle {}");
    assert!(config_error(&servo, 10).contains("does not support"));
    let bx = TWO_BODIES.replace("sphere { radius: 0.1 }", "box { halfsize { x: 1 } }");
    assert!(config_error(&bx, 2).contains("`box` is a Brax feature"));
    let scene = format!("friction: 0.6\ngravity {{ z: -9.8 }}\ndt: 0.05\nsubsteps: 10\n{TWO_BODIES}");
    assert!(parse_config(&scene, "cfg.txt").is_ok());
}

#[test]
fn structure_errors_unknown_joint_duplicates_and_disconnected_bodies() {
    let m = config_error(&TWO_BODIES.replace("joint: \"j\"", "joint: \"x\""), 10);
    assert!(m.contains("unknown joint name; known joints: \"j\""), "{m}");
    let dup = TWO_BODIES.replace("name: \"b\"", "name: \"a\"");
    assert!(config_error(&dup, 3).contains("duplicate body name"));
    let loose = format!("{TWO_BODIES}\nbodies {{ name: \"c\" mass: 1 }}\n");
    let m = config_error(&loose, 2);
    assert!(m.contains("several bodies have no parent joint: \"a\", \"c\""), "{m}");
    let self_joint = TWO_BODIES.replace("child: \"b\"", "child: \"a\"");
    assert!(config_error(&self_joint, 7).contains("to itself"));
}

/// A tiny deterministic generator (xorshift) for the fuzz test.
fn next(state: &mut u64) -> u64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    *state
}

#[test]
fn fuzzed_truncated_and_mutated_inputs_never_panic() {
    let alphabet: Vec<char> = "{}<>[]:;,-#\"'\\ \n0123456789.eExyz_abc".chars().collect();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut rejected = 0;
    let mut total = 0;
    for m in &MORPHOLOGIES {
        let chars: Vec<char> = m.text.chars().collect();
        // Truncations at many points (a parse either succeeds or errors, never panics).
        for cut in (0..chars.len()).step_by(37) {
            let text: String = chars[..cut].iter().collect();
            total += 1;
            if load_morphology_text(&text).is_err() {
                rejected += 1;
            }
        }
        // Random mutations: replace, insert or delete a few characters.
        for _ in 0..200 {
            let mut c = chars.clone();
            for _ in 0..1 + next(&mut state) % 4 {
                let at = (next(&mut state) as usize) % c.len();
                let ch = alphabet[(next(&mut state) as usize) % alphabet.len()];
                match next(&mut state) % 3 {
                    0 => c[at] = ch,
                    1 => c.insert(at, ch),
                    _ => {
                        c.remove(at);
                    }
                }
            }
            total += 1;
            if load_morphology_text(&c.iter().collect::<String>()).is_err() {
                rejected += 1;
            }
        }
    }
    // Most damaged inputs must be rejected (the test fails if the loader accepts anything).
    assert!(rejected * 2 > total, "only {rejected} of {total} damaged inputs rejected");
}

/// Parses text and, if it is a valid config, runs the queries a caller would make.
fn load_morphology_text(text: &str) -> Result<(), BraxError> {
    let c = parse_config(text, "fuzz")?;
    let _ = (c.dof(), c.actuated_dof(), c.root_body());
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Conversion into the simulator's model.

use envs::brax::rotation::{euler_degrees_to_quat, quat_rotate};
use envs::brax::tree::TreeShape;
use envs::brax::{AgentTree, BraxPhysics, agent_model};
use envs::kinematics::kinematics;
use envs::{Data, Model, Shape};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn euler_to_quaternion_matches_hand_computed_cases() {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let cases: [([f64; 3], [f64; 4]); 5] = [
        ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
        ([0.0, 0.0, 90.0], [h, 0.0, 0.0, h]),
        ([0.0, -90.0, 0.0], [h, 0.0, -h, 0.0]),
        // qx(90) * qy(90) = (h, h, 0, 0) * (h, 0, h, 0) = (1/2, 1/2, 1/2, 1/2).
        ([90.0, 90.0, 0.0], [0.5, 0.5, 0.5, 0.5]),
        // qx(90) * qy(-90) = (h, h, 0, 0) * (h, 0, -h, 0) = (1/2, 1/2, -1/2, -1/2).
        ([90.0, -90.0, 0.0], [0.5, 0.5, -0.5, -0.5]),
    ];
    for (angles, expected) in cases {
        let q = euler_degrees_to_quat(angles);
        for k in 0..4 {
            assert!(close(q[k], expected[k], 1e-12), "{angles:?}: {q:?}");
        }
    }
    // The ant's hip joint frame `rotation { y: -90 }` turns the x axis (1st DoF) to +z:
    // the hips turn about the vertical, as MuJoCo's ant `hip` axis "0 0 1".
    let axis = quat_rotate(euler_degrees_to_quat([0.0, -90.0, 0.0]), [1.0, 0.0, 0.0]);
    assert!(close(axis[2], 1.0, 1e-12), "{axis:?}");
}

/// Lowest geom surface point of the model at `d`'s pose, from the simulator's kinematics.
fn lowest_geom_point(m: &Model, d: &Data) -> f64 {
    let mut lowest = f64::INFINITY;
    for (g, geom) in m.geoms.iter().enumerate() {
        let c = d.geom_xpos[g];
        let z = match geom.shape {
            Shape::Sphere { radius } => c[2] - radius,
            Shape::Capsule { radius, half_length } => c[2] - half_length * d.geom_xmat[g][2][2].abs() - radius,
            Shape::Plane => continue,
        };
        lowest = lowest.min(z);
    }
    lowest
}

#[test]
fn every_morphology_builds_and_rests_on_the_ground() {
    for (name, dof) in ACTUATED_DOF {
        let config = load_morphology(name).unwrap();
        let (model, tree) = agent_model(&config, &BraxPhysics::default()).unwrap();
        assert_eq!(model.nu(), dof, "{name}");
        assert_eq!(model.nq, 7 + dof, "{name}");
        assert_eq!(model.qpos0, tree.rest_qpos(), "{name}");
        let mass: f64 = config.bodies.iter().map(|b| b.mass).sum();
        assert!(close(model.tree_mass(0), mass, 1e-9), "{name}");
        // The simulator's own kinematics at qpos0 puts the lowest collider point on z = 0.
        let mut d = Data::new(&model);
        kinematics(&model, &mut d);
        let lowest = lowest_geom_point(&model, &d);
        assert!(close(lowest, 0.0, 1e-9), "{name}: lowest point {lowest}");
        assert!(tree.rest_height() > 0.0, "{name}");
        // Every rest angle is the middle of its range.
        for j in model.joints.iter().filter(|j| j.limited) {
            let q = model.qpos0[j.qpos_adr];
            assert!(close(q, 0.5 * (j.range[0] + j.range[1]), 1e-12), "{name}");
        }
    }
}

#[test]
fn ant_rest_height_is_the_foot_below_the_torso() {
    // Hips at 0, ankles at 50 deg: the foot cap's centre is 2 * 0.28284 m along the leg
    // from the ankle, 50 deg below the horizontal; add the capsule radius 0.08.
    let tree = AgentTree::from_config(&load_morphology("ant").unwrap(), &BraxPhysics::default());
    let expected = 2.0 * 0.282_842_708_826_065_05 * 50f64.to_radians().sin() + 0.08;
    assert!(close(tree.rest_height(), expected, 1e-9), "{}", tree.rest_height());
}

#[test]
fn ant_geometry_matches_mujoco_ant_xml() {
    let ant = load_morphology("ant").unwrap();
    let physics = BraxPhysics::default();
    let (model, tree) = agent_model(&ant, &physics).unwrap();
    // Torso: a sphere of radius 0.25 (ant.xml torso_geom), the capsule of length 2r.
    assert_eq!(tree.bodies[0].name, "torso");
    assert_eq!(tree.bodies[0].geoms[0].shape, TreeShape::Sphere { radius: 0.25 });
    let torso = model.body_id("torso").unwrap().0;
    let torso_geoms: Vec<&envs::model::Geom> = model.geoms.iter().filter(|g| g.body == torso).collect();
    assert_eq!(torso_geoms[0].shape, Shape::Sphere { radius: 0.25 });
    // Legs: capsules of radius 0.08 (ant.xml size="0.08").
    let legs = model.geoms.iter().filter(|g| g.body != torso && g.shape != Shape::Plane);
    let mut n = 0;
    for g in legs {
        let Shape::Capsule { radius, .. } = g.shape else { panic!("leg geom is not a capsule: {g:?}") };
        assert_eq!(radius, 0.08);
        n += 1;
    }
    assert_eq!(n, 8);
    // Hips +-30 deg about the vertical; ankles 30..70 deg about a horizontal axis across
    // the leg (ant.xml hip_i range -30 30 axis 0 0 1; ankle_1 range 30 70 axis -1 1 0).
    let mut d = Data::new(&model);
    d.qpos.iter_mut().skip(7).for_each(|q| *q = 0.0);
    kinematics(&model, &mut d);
    let (mut hips, mut ankles) = (0, 0);
    for (j, joint) in model.joints.iter().enumerate().skip(1) {
        let [lo, hi] = joint.range.map(f64::to_degrees);
        let axis = d.xaxis[j];
        if joint.name.starts_with("torso_") {
            hips += 1;
            assert!(close(lo, -30.0, 1e-9) && close(hi, 30.0, 1e-9), "{}", joint.name);
            assert!(close(axis[2], 1.0, 1e-9), "{}: {axis:?}", joint.name);
        } else {
            ankles += 1;
            assert!(close(lo, 30.0, 1e-9) && close(hi, 70.0, 1e-9), "{}", joint.name);
            assert!(close(axis[2], 0.0, 1e-9), "{}: {axis:?}", joint.name);
            // The axis is horizontal and across the leg: perpendicular to the anchor's
            // horizontal direction from the torso centre.
            let a = d.xanchor[j];
            assert!(close(axis[0] * a[0] + axis[1] * a[1], 0.0, 1e-9), "{}", joint.name);
        }
        assert_eq!(joint.damping, 35.0);
        assert!(close(joint.armature, 0.35, 1e-12));
    }
    assert_eq!((hips, ankles), (4, 4));
    assert!(model.actuators.iter().all(|a| a.gear == 350.0));
    assert!(model.actuators.iter().all(|a| a.ctrlrange == Some([-1.0, 1.0])));
    // Positive ankle angles bend the legs down (as ant.xml's ankle_1 range 30..70): at the
    // rest pose every foot is below the torso.
    let mut d = Data::new(&model);
    kinematics(&model, &mut d);
    for b in ["$ Body 4_0", "$ Body 4_1", "$ Body 4_2", "$ Body 4_3"] {
        let id = model.body_id(b).unwrap().0;
        assert!(d.xpos[id][2] < d.xpos[torso][2] - 0.1, "{b}");
    }
}

#[test]
fn universal_and_doubled_joints_become_chained_hinges() {
    let physics = BraxPhysics::default();
    // Claw hips: 2 DoF about the joint frame's x then y axes (orthogonal).
    let claw = AgentTree::from_config(&load_morphology("claw").unwrap(), &physics);
    let hip = claw.bodies.iter().find(|b| b.name == "Aux 1_0").unwrap();
    assert_eq!(hip.hinges.len(), 2);
    assert_eq!(hip.hinges[0].name, "torso_Aux 1_0.1");
    let (a, b) = (hip.hinges[0].axis, hip.hinges[1].axis);
    assert!(close(a[0] * b[0] + a[1] * b[1] + a[2] * b[2], 0.0, 1e-12));
    assert_eq!(claw.motors.len(), 16);
    // The sumo unimal's limb_end_3 (joints limbx_1 and limby_1 from torso_0): 3 hinges.
    let u = AgentTree::from_config(&load_morphology("unimal_5506-13-5-02-21-35-41").unwrap(), &physics);
    let limb = u.bodies.iter().find(|b| b.name == "limb_end_3").unwrap();
    let names: Vec<&str> = limb.hinges.iter().map(|h| h.name.as_str()).collect();
    assert_eq!(names, vec!["limbx_1", "limby_1.1", "limby_1.2"]);
    assert_eq!(u.motors.len(), 13);
}

// ---------------------------------------------------------------------------------------
// Dynamics of the converted agents.

use envs::step;

/// The lowest collider point of `m` touches z = 0 at `qpos`: returns the lifted qpos.
fn lifted(m: &Model, mut qpos: Vec<f64>) -> Vec<f64> {
    let mut d = Data::new(m);
    qpos[2] = 0.0;
    d.reset_to(m, &qpos).unwrap();
    kinematics(m, &mut d);
    qpos[2] = -lowest_geom_point(m, &d);
    qpos
}

/// Steps `d` for `seconds` with zero controls; returns the torso height and vertical speed.
fn settle(m: &Model, d: &mut Data, seconds: f64) -> (f64, f64) {
    let n = (seconds / m.opt.timestep).round() as usize;
    for _ in 0..n {
        step(m, d);
    }
    assert!(d.is_finite());
    (d.qpos[2], d.qvel[2])
}

#[test]
fn ant_from_config_and_from_mjcf_stand_alike_at_rest() {
    // MuJoCo's ant (ant.xml) through the simulator's MJCF loader, put in the same rest pose
    // as the Brax ant: every hinge at the middle of its range (hips 0, ankles +-50 deg),
    // upright, lowest point on the ground.
    let mj = envs::mjcf::load_str(include_str!("../../morphologies/mujoco_ant.xml"), "mujoco_ant.xml").unwrap();
    assert_eq!(mj.opt.timestep, 0.01);
    let mut q = mj.qpos0.clone();
    q[3..7].copy_from_slice(&[1.0, 0.0, 0.0, 0.0]);
    for j in mj.joints.iter().filter(|j| j.limited) {
        q[j.qpos_adr] = 0.5 * (j.range[0] + j.range[1]);
    }
    let q = lifted(&mj, q);
    let mut dm = Data::new(&mj);
    dm.reset_to(&mj, &q).unwrap();

    let (bm, tree) = agent_model(&load_morphology("ant").unwrap(), &BraxPhysics::default()).unwrap();
    let mut db = Data::new(&bm);
    // Same leg geometry below the ankle (0.4 sqrt 2 m shin, radius 0.08) and same ankle
    // angle: the two start at the same height.
    assert!(close(q[2], tree.rest_height(), 1e-6), "{} vs {}", q[2], tree.rest_height());

    // Two seconds (40 control steps) without action.
    let (hm, vm) = settle(&mj, &mut dm, 2.0);
    let (hb, vb) = settle(&bm, &mut db, 2.0);
    // Both stand (torso well above the 0.25 m of a torso lying on the ground) and are at
    // rest (vertical speed below 1 cm/s, no jitter).
    assert!(hm > 0.4 && hb > 0.4, "mjcf {hm}, brax {hb}");
    assert!(vm.abs() < 0.01 && vb.abs() < 0.01, "mjcf {vm}, brax {vb}");
    // Within 10%: the legs below the ankle and the ankle angle are the same, but the masses
    // differ 20-fold (density 5 in ant.xml: 0.91 kg; MeBen: 18 kg), as do armature, damping
    // and the hip positions (0.28 m vs 0.30 m from the centre); the contact and friction
    // softness then let the two sag by slightly different amounts.
    assert!((hb - hm).abs() < 0.1 * hm, "mjcf {hm}, brax {hb}");
}

#[test]
fn every_morphology_survives_bang_bang_actions_at_the_default_time_step() {
    // The constants of BraxPhysics and the integrator of brax_options() (EulerGyro) must keep
    // every agent finite and on the ground under the extreme actions RL produces: 400 control
    // steps of +-1 (5 physics steps each).
    for (name, _) in ACTUATED_DOF {
        let (m, _) = agent_model(&load_morphology(name).unwrap(), &BraxPhysics::default()).unwrap();
        assert_eq!(m.opt.integrator, envs::Integrator::EulerGyro);
        let mut d = Data::new(&m);
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut highest: f64 = 0.0;
        for _ in 0..400 {
            for c in d.ctrl.iter_mut() {
                *c = if (next(&mut state) >> 11) & 1 == 0 { 1.0 } else { -1.0 };
            }
            for _ in 0..5 {
                step(&m, &mut d);
            }
            assert!(d.is_finite(), "{name}: non-finite state at t = {}", d.time);
            highest = highest.max(d.qpos[2]);
        }
        assert!(highest < 5.0, "{name}: torso reached {highest} m");
        // Joint limits hold (soft constraints: within 0.2 rad).
        for j in m.joints.iter().filter(|j| j.limited) {
            let q = d.qpos[j.qpos_adr];
            assert!(q > j.range[0] - 0.2 && q < j.range[1] + 0.2, "{name}: {} at {q}", j.name);
        }
    }
}

#[test]
fn the_light_torso_unimal_survives_bang_bang_actions_from_many_seeds() {
    // unimal_2's torso is 2.5 of its 24.2 kg: the root turns cheaply against its limbs. An
    // earlier EulerGyro took the root's gyroscopic derivative as if the whole tree were rigid
    // (composite inertia), far stiffer than the root's own response; `I + S h K` of its
    // Woodbury update then crossed singularity and every one of 32 seeds of this test blew up
    // within 0.6 s. With the exact derivative columns, none does (32 of 32 seeds measured).
    let (m, _) = agent_model(&load_morphology("unimal_2").unwrap(), &BraxPhysics::default()).unwrap();
    assert_eq!(m.opt.integrator, envs::Integrator::EulerGyro);
    for seed in 0..8u64 {
        let mut d = Data::new(&m);
        let mut state = 0x2545_F491_4F6C_DD1Du64 ^ seed.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        for _ in 0..400 {
            for c in d.ctrl.iter_mut() {
                *c = if (next(&mut state) >> 11) & 1 == 0 { 1.0 } else { -1.0 };
            }
            for _ in 0..5 {
                step(&m, &mut d);
            }
            assert!(d.is_finite(), "seed {seed}: non-finite state at t = {}", d.time);
            assert!(d.qpos[2] < 5.0, "seed {seed}: torso at {} m", d.qpos[2]);
        }
    }
}

#[test]
fn a_model_the_simulator_rejects_is_a_brax_error() {
    let physics = BraxPhysics { friction: -1.0, ..BraxPhysics::default() };
    let err = agent_model(&load_morphology("ant").unwrap(), &physics).unwrap_err();
    assert!(matches!(err, BraxError::Model { .. }), "{err:?}");
    let text = err.to_string();
    assert!(text.starts_with("ant: the simulator rejected the model"), "{text}");
    assert!(text.contains("friction"), "{text}");
}
