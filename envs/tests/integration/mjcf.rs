//! MJCF loader: the reference ant loads with MuJoCo's masses and inertias; defaults, classes
//! and orientations behave as in MuJoCo; every error path reports file, line, element,
//! attribute and value.

use envs::mjcf::{MjcfError, load_file, load_str};

const ANT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/morphologies/mujoco_ant.xml");

#[test]
fn the_reference_ant_loads_with_mujocos_masses_and_inertias() {
    let m = load_file(ANT).unwrap();
    assert_eq!((m.nq, m.nv, m.nu(), m.trees.len()), (15, 14, 8, 1));
    assert_eq!(m.opt.integrator, envs::Integrator::Rk4);
    assert_eq!(m.opt.timestep, 0.01);
    // Values printed by MuJoCo 4.0 (model.body_mass, body_inertia) for the same file; the
    // formulas are the same closed forms, so agreement is to round-off (1e-12 relative).
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
    assert!(close(m.bodies[1].mass, 0.32724923474893675));
    assert!(close(m.bodies[2].mass, 0.03915775372846671));
    assert!(close(m.bodies[4].mass, 0.06759220453268026));
    assert!(close(m.bodies[1].inertia[0][0], 0.00818123086872342));
    // aux_1: capsule along (1, 1, 0) / sqrt 2; MuJoCo's principal moments.
    let i = m.bodies[3].inertia;
    let u = std::f64::consts::FRAC_1_SQRT_2;
    let axial = u * u * (i[0][0] + i[0][1] + i[1][0] + i[1][1]);
    assert!(close(axial, 0.00011844189805957), "axial {axial}");
    assert!(close(i[2][2], 0.0005679660831928), "transverse {}", i[2][2]);
    assert!((m.bodies[2].ipos[0] - 0.1).abs() < 1e-15 && (m.bodies[2].ipos[1] - 0.1).abs() < 1e-15);
    // Defaults: hinges limited, armature 1, damping 1 (class main); the root overrides them.
    let hip = &m.joints[m.joint_id("hip_1").unwrap().0];
    assert!(hip.limited && hip.armature == 1.0 && hip.damping == 1.0);
    assert!((hip.range[1] - 30f64.to_radians()).abs() < 1e-15);
    assert_eq!(m.joints[0].armature, 0.0);
    // Actuators in file order: the first drives hip_4 with gear 150, clamped to [-1, 1].
    assert_eq!(m.actuators[0].joint, m.joint_id("hip_4").unwrap().0);
    assert_eq!((m.actuators[0].gear, m.actuators[0].ctrlrange), (150.0, Some([-1.0, 1.0])));
    // Collisions: conaffinity 0 on the ant, 1 on the floor: only ant-floor pairs (13 geoms).
    assert_eq!((m.plane_pairs.len(), m.geom_pairs.len()), (13, 0));
}

#[test]
fn defaults_classes_childclass_and_orientations() {
    let xml = r#"<mujoco>
  <compiler angle="radian" eulerseq="zyx"/>
  <option timestep="0.005" gravity="0 0 -1" integrator="implicit"><flag contact="disable" limit="disable"/></option>
  <default>
    <geom density="2" friction="0.7 0.1 0.1"/>
    <joint damping="3"/>
    <default class="leg">
      <geom density="4"/>
      <joint armature="0.5" range="-1 1"/>
      <default class="foot"><geom friction="0.2"/></default>
    </default>
  </default>
  <worldbody>
    <geom type="plane" size="1 1 1"/>
    <body name="a" pos="0 0 1" euler="0.3 -0.2 1.1">
      <joint type="free"/>
      <geom size="0.1"/>
      <body name="b" childclass="leg" pos="0.2 0 0" quat="0 0 0 2">
        <joint name="j" axis="0 2 0"/>
        <geom type="capsule" size="0.05 0.1"/>
        <geom class="foot" type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="j" gear="7"/></actuator>
</mujoco>"#;
    let m = load_str(xml, "test.xml").unwrap();
    assert_eq!(m.opt.timestep, 0.005);
    assert_eq!(m.opt.gravity, [0.0, 0.0, -1.0]);
    assert_eq!(m.opt.integrator, envs::Integrator::Implicit);
    assert!(m.opt.disable_contact && m.opt.disable_limit);
    // MuJoCo's body_quat for euler="0.3 -0.2 1.1" with eulerseq zyx (radians).
    let q = m.bodies[1].quat;
    let mj = [0.8309424152086116, 0.5269548219718452, -0.00643555567205394, 0.17835891295669043];
    for k in 0..4 {
        assert!((q[k] - mj[k]).abs() < 1e-12, "{q:?} vs {mj:?}");
    }
    assert_eq!(m.bodies[2].quat, [0.0, 0.0, 0.0, 1.0]); // normalised
    let j = &m.joints[1];
    // Class leg via childclass: armature, range (limited auto), damping inherited from main.
    assert_eq!((j.armature, j.damping, j.limited, j.range), (0.5, 3.0, true, [-1.0, 1.0]));
    assert_eq!(j.axis, [0.0, 1.0, 0.0]);
    // Friction: main 0.7 for the sphere and the leg capsule, class foot 0.2.
    assert_eq!([m.geoms[1].friction, m.geoms[2].friction, m.geoms[3].friction], [0.7, 0.7, 0.2]);
    // Density: main 2 for body a (sphere), leg 4 for body b.
    let vol = 4.0 / 3.0 * std::f64::consts::PI * 0.001;
    assert!((m.bodies[1].mass - 2.0 * vol).abs() < 1e-15);
    // The free joint takes the damping of class main on its six dofs, as MuJoCo.
    assert_eq!(&m.dof_damping[..6], &[3.0; 6]);
    assert_eq!(m.dof_armature[0], 0.0);
    // Motor without ctrlrange: unclamped.
    assert_eq!((m.actuators[0].gear, m.actuators[0].ctrlrange), (7.0, None));
}

/// Loads `xml` expecting an error; checks the line and that the message names `parts`.
fn expect_err(xml: &str, line: u32, parts: &[&str]) -> MjcfError {
    let e = load_str(xml, "bad.xml").expect_err("should fail");
    let text = e.to_string();
    assert!(text.starts_with(&format!("bad.xml:{line}:")), "wrong location: {text}");
    for p in parts {
        assert!(text.contains(p), "'{p}' missing from: {text}");
    }
    e
}

/// A minimal valid document with `body` inside the worldbody and `extra` after it.
fn doc(top: &str, body: &str, extra: &str) -> String {
    format!("<mujoco>\n{top}\n<worldbody>\n{body}\n</worldbody>\n{extra}\n</mujoco>")
}

const BODY: &str = r#"<body name="b" pos="0 0 1"><joint name="j" type="hinge"/><geom size="0.1"/></body>"#;

#[test]
fn file_and_document_errors() {
    let e = load_file("/nonexistent/model.xml").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/model.xml") && e.to_string().contains("cannot read"));
    expect_err("<mujoco>\n<worldbody>\n</mujoco>", 3, &["malformed XML"]);
    expect_err("<robot/>", 1, &["<robot>", "root element must be <mujoco>"]);
    expect_err("<mujoco>\n<include file=\"x.xml\"/>\n</mujoco>", 2, &["<include>", "not supported"]);
}

#[test]
fn compiler_and_option_errors() {
    let e = expect_err(
        &doc("<compiler angle=\"grad\"/>", BODY, ""),
        2,
        &["<compiler>", "'angle'", "\"grad\"", "degree, radian"],
    );
    assert_eq!(e.attribute.as_deref(), Some("angle"));
    assert_eq!(e.value.as_deref(), Some("grad"));
    assert_eq!(e.element, "compiler");
    expect_err(&doc("<compiler inertiafromgeom=\"false\"/>", BODY, ""), 2, &["inertiafromgeom", "\"false\""]);
    expect_err(&doc("<compiler coordinate=\"global\"/>", BODY, ""), 2, &["coordinate", "\"global\""]);
    expect_err(&doc("<compiler eulerseq=\"xyw\"/>", BODY, ""), 2, &["eulerseq", "\"xyw\"", "three letters"]);
    expect_err(&doc("<option timestep=\"-0.01\"/>", BODY, ""), 2, &["<option>", "timestep", "\"-0.01\"", "positive"]);
    expect_err(&doc("<option timestep=\"fast\"/>", BODY, ""), 2, &["timestep", "'fast' is not a finite number"]);
    expect_err(&doc("<option timestep=\"nan\"/>", BODY, ""), 2, &["timestep", "not a finite number"]);
    expect_err(&doc("<option gravity=\"0 -9.81\"/>", BODY, ""), 2, &["gravity", "expected 3 numbers, found 2"]);
    expect_err(&doc("<option integrator=\"Verlet\"/>", BODY, ""), 2, &["integrator", "\"Verlet\"", "Euler, RK4"]);
    expect_err(
        &doc("<option>\n<flag contact=\"off\"/>\n</option>", BODY, ""),
        3,
        &["<flag>", "contact", "\"off\"", "enable, disable"],
    );
    expect_err(&doc("<option>\n<flag limit=\"no\"/></option>", BODY, ""), 3, &["<flag>", "limit", "\"no\""]);
}

#[test]
fn default_class_errors_name_the_file_line_element_attribute_and_value() {
    expect_err(&doc("<default>\n<default>\n</default>\n</default>", BODY, ""), 3, &["<default>", "needs a class"]);
    expect_err(
        &doc("<default>\n<default class=\"a\"/>\n<default class=\"a\"/>\n</default>", BODY, ""),
        4,
        &["class", "\"a\"", "defined twice"],
    );
    expect_err(
        &doc("", "<body>\n<geom class=\"nope\" size=\"0.1\"/>\n</body>", ""),
        5,
        &["<geom>", "class", "\"nope\"", "unknown default class"],
    );
    expect_err(&doc("", "<body childclass=\"nope\">\n<geom size=\"0.1\"/></body>", ""), 4, &["childclass", "\"nope\""]);
    // An error in a value inherited from a default points at the default's line.
    expect_err(
        &doc("<default>\n<geom density=\"heavy\"/>\n</default>", BODY, ""),
        3,
        &["<geom>", "density", "\"heavy\""],
    );
}

#[test]
fn body_errors_name_the_file_line_element_attribute_and_value() {
    expect_err(&doc("", "<joint type=\"hinge\"/>", ""), 4, &["<joint>", "world body cannot have joints"]);
    expect_err(&doc("", "<body>\n<inertial mass=\"1\"/>\n</body>", ""), 5, &["<inertial>", "not supported"]);
    expect_err(
        &doc("", "<body axisangle=\"0 0 1 30\"><geom size=\"1\"/></body>", ""),
        4,
        &["axisangle", "unsupported"],
    );
    expect_err(&doc("", "<body quat=\"1 0 0 0\" euler=\"0 0 0\"/>", ""), 4, &["euler", "both quat and euler"]);
    expect_err(&doc("", "<body quat=\"0 0 0 0\"/>", ""), 4, &["quat", "\"0 0 0 0\"", "zero quaternion"]);
    expect_err(&doc("", "<body pos=\"0 0\"/>", ""), 4, &["<body>", "pos", "\"0 0\"", "expected 3 numbers"]);
    expect_err(&doc("", "<body euler=\"0 x 0\"/>", ""), 4, &["euler", "'x' is not a finite number"]);
}

#[test]
fn geom_errors_name_the_file_line_element_attribute_and_value() {
    let g = |geom: &str| doc("", &format!("<body>\n{geom}\n</body>"), "");
    expect_err(&g("<geom type=\"box\" size=\"1 1 1\"/>"), 5, &["<geom>", "type", "\"box\"", "not supported"]);
    expect_err(&g("<geom type=\"blob\"/>"), 5, &["type", "\"blob\"", "expected one of"]);
    expect_err(&g("<geom type=\"sphere\"/>"), 5, &["size", "needs size"]);
    expect_err(&g("<geom size=\"-0.1\"/>"), 5, &["size", "\"-0.1\"", "radius must be positive"]);
    expect_err(&g("<geom type=\"capsule\"/>"), 5, &["size", "capsule needs size"]);
    expect_err(
        &g("<geom type=\"capsule\" size=\"0\" fromto=\"0 0 0 1 0 0\"/>"),
        5,
        &["size", "radius must be positive"],
    );
    expect_err(&g("<geom type=\"capsule\" size=\"0.1\"/>"), 5, &["size", "half-length"]);
    expect_err(&g("<geom type=\"capsule\" size=\"0.1 -1\"/>"), 5, &["size", "half-length"]);
    expect_err(&g("<geom type=\"capsule\" size=\"0.1\" fromto=\"1 1 1 1 1 1\"/>"), 5, &["fromto", "coincide"]);
    expect_err(&g("<geom type=\"capsule\" size=\"0.1\" fromto=\"0 0 0 1 1\"/>"), 5, &["fromto", "expected 6 numbers"]);
    expect_err(
        &g("<geom type=\"capsule\" size=\"0.1\" fromto=\"0 0 0 1 0 0\" pos=\"1 0 0\"/>"),
        5,
        &["fromto", "cannot be combined"],
    );
    expect_err(&g("<geom size=\"0.1\" fromto=\"0 0 0 1 0 0\"/>"), 5, &["fromto", "only supported for capsules"]);
    expect_err(&g("<geom size=\"0.1\" density=\"-1\"/>"), 5, &["density", "\"-1\"", "non-negative"]);
    expect_err(&g("<geom size=\"0.1\" mass=\"-1\"/>"), 5, &["mass", "non-negative"]);
    expect_err(&g("<geom size=\"0.1\" friction=\"-1\"/>"), 5, &["friction", "non-negative"]);
    expect_err(&g("<geom size=\"0.1\" friction=\"1 1 1 1\"/>"), 5, &["friction", "expected 1 to 3 numbers, found 4"]);
    expect_err(&g("<geom size=\"0.1\" contype=\"-1\"/>"), 5, &["contype", "\"-1\"", "bit mask"]);
    expect_err(&g("<geom size=\"0.1\" conaffinity=\"x\"/>"), 5, &["conaffinity", "bit mask"]);
    expect_err(
        &g("<geom type=\"plane\" size=\"1 1 1\"/>"),
        5,
        &["type", "\"plane\"", "only supported in the worldbody"],
    );
}

#[test]
fn joint_errors_name_the_file_line_element_attribute_and_value() {
    let j = |joint: &str| doc("", &format!("<body>\n<geom size=\"0.1\"/>\n{joint}\n</body>"), "");
    expect_err(&j("<joint type=\"slide\"/>"), 6, &["<joint>", "type", "\"slide\"", "not supported"]);
    expect_err(&j("<joint type=\"screw\"/>"), 6, &["type", "\"screw\"", "expected one of"]);
    expect_err(&j("<joint axis=\"0 0 0\"/>"), 6, &["axis", "\"0 0 0\"", "zero joint axis"]);
    expect_err(&j("<joint limited=\"true\"/>"), 6, &["range", "limited joint needs a range"]);
    expect_err(&j("<joint limited=\"yes\" range=\"0 1\"/>"), 6, &["limited", "\"yes\"", "true, false, auto"]);
    expect_err(&j("<joint range=\"1 -1\"/>"), 6, &["range", "\"1 -1\"", "lower limit"]);
    expect_err(&j("<joint range=\"1\"/>"), 6, &["range", "expected 2 numbers"]);
    expect_err(&j("<joint armature=\"-1\"/>"), 6, &["armature", "\"-1\"", "non-negative"]);
    expect_err(&j("<joint damping=\"lots\"/>"), 6, &["damping", "\"lots\""]);
    expect_err(&j("<joint name=\"a\"/>\n<joint name=\"a\"/>"), 7, &["name", "\"a\"", "duplicate joint name"]);
    expect_err(&j("<joint type=\"free\" pos=\"0 0 1\"/>"), 6, &["pos", "body origin"]);
    expect_err(&j("<joint type=\"free\" damping=\"-2\"/>"), 6, &["damping", "\"-2\"", "non-negative"]);
    // A free joint inside a child body.
    expect_err(
        &doc("", "<body>\n<geom size=\"0.1\"/>\n<body>\n<freejoint/>\n<geom size=\"0.1\"/>\n</body>\n</body>", ""),
        7,
        &["<freejoint>", "top-level body"],
    );
    // A free joint plus a hinge on the same body: reported on the body.
    expect_err(
        &doc("", "<body>\n<freejoint/>\n<joint/>\n<geom size=\"0.1\"/>\n</body>", ""),
        4,
        &["<body>", "free joint"],
    );
    // A hinge on a body without mass: singular mass matrix, reported on the joint.
    expect_err(&doc("", "<body>\n<joint name=\"massless\"/>\n</body>", ""), 5, &["<joint>", "mass matrix"]);
}

#[test]
fn actuator_errors_name_the_file_line_element_attribute_and_value() {
    let a = |act: &str| doc("", BODY, &format!("<actuator>\n{act}\n</actuator>"));
    expect_err(&a("<position joint=\"j\"/>"), 7, &["<position>", "only <motor>"]);
    expect_err(&a("<motor gear=\"1\"/>"), 7, &["<motor>", "joint", "needs a joint"]);
    expect_err(&a("<motor joint=\"k\"/>"), 7, &["joint", "\"k\"", "no hinge joint with this name"]);
    expect_err(&a("<motor joint=\"j\" gear=\"strong\"/>"), 7, &["gear", "\"strong\""]);
    expect_err(&a("<motor joint=\"j\" ctrllimited=\"true\"/>"), 7, &["ctrlrange", "ctrllimited needs a ctrlrange"]);
    expect_err(&a("<motor joint=\"j\" ctrlrange=\"1 -1\"/>"), 7, &["ctrlrange", "\"1 -1\"", "lower bound"]);
    expect_err(&a("<motor joint=\"j\" ctrllimited=\"maybe\"/>"), 7, &["ctrllimited", "\"maybe\""]);
    expect_err(&a("<motor joint=\"j\" class=\"none\"/>"), 7, &["class", "\"none\"", "unknown default class"]);
}

/// Absurd physical values are refused where they are written, with the accepted range
/// Before, `mass="1e300"`, `size="1e160"`, `pos="1e300 .."`,
/// `armature="1e300"` or `density="1e-300"` were reported as "mass matrix not positive
/// definite" on some joint's line; `timestep="1e9"`, `gravity="0 0 -1e300"` and
/// `gear="1e300"` loaded and the rollout stopped on a non-finite state; `fromto` with 1e300
/// gave "bad value inf for geom 2 half_length" without a line; `timestep="1e-300"`,
/// `density="1e300"`, `size="1e-200"`, `friction="1e300"`, `damping="1e300"`,
/// `range="-1e300 1e300"`, `euler="1e300 0 0"` and `ctrlrange="-1e300 1e300"` loaded silently.
#[test]
fn extreme_physical_values_are_refused_where_written() {
    let top = |attrs: &str| doc(&format!("<option {attrs}/>"), BODY, "");
    let g = |attrs: &str| doc("", &format!("<body>\n<geom {attrs}/>\n</body>"), "");
    let j = |attrs: &str| doc("", &format!("<body>\n<geom size=\"0.1\"/>\n<joint {attrs}/>\n</body>"), "");
    let b = |attrs: &str| doc("", &format!("<body {attrs}>\n<geom size=\"0.1\"/>\n</body>"), "");
    let a = |attrs: &str| doc("", BODY, &format!("<actuator>\n<motor joint=\"j\" {attrs}/>\n</actuator>"));
    let cases: Vec<(String, u32, &str, &str)> = vec![
        (top("timestep=\"1e9\""), 2, "'timestep' value \"1e9\"", "a time step must be between 1e-6 and 1 s"),
        (top("timestep=\"1e-300\""), 2, "'timestep' value \"1e-300\"", "a time step"),
        (top("gravity=\"0 0 -1e300\""), 2, "'gravity'", "a gravity component must be between -1000 and 1000 m/s^2"),
        (g("size=\"1e160\""), 5, "'size' value \"1e160\"", "a size must be between 1e-4 and 1000 m"),
        (g("size=\"1e-200\""), 5, "'size' value \"1e-200\"", "a size"),
        (
            g("type=\"capsule\" size=\"0.1 1e300\""),
            5,
            "'size'",
            "a length or position must be between -1000 and 1000 m",
        ),
        (g("type=\"capsule\" size=\"0.1\" fromto=\"0 0 0 1e300 0 0\""), 5, "'fromto'", "a length or position"),
        (g("size=\"0.1\" pos=\"0 1e300 0\""), 5, "'pos'", "a length or position"),
        (g("size=\"0.1\" mass=\"1e300\""), 5, "'mass' value \"1e300\"", "a mass must be 0 or between 1e-6 and 1e6 kg"),
        (g("size=\"0.1\" density=\"1e300\""), 5, "'density'", "a density must be 0 or between 1e-6 and 1e6 kg/m^3"),
        (g("size=\"0.1\" density=\"1e-300\""), 5, "'density'", "a density"),
        (g("size=\"0.1\" friction=\"1e300\""), 5, "'friction'", "a friction coefficient must be between 0 and 1000"),
        (g("size=\"0.1\" euler=\"0 0 1e300\""), 5, "'euler'", "an angle must be between -3600 and 3600 degrees"),
        (j("armature=\"1e300\""), 6, "'armature'", "an armature must be between 0 and 1e6 kg m^2"),
        (j("damping=\"1e300\""), 6, "'damping'", "a damping must be between 0 and 1e6 N m s/rad"),
        (j("range=\"-1e300 1e300\""), 6, "'range'", "an angle"),
        (j("pos=\"1e300 0 0\""), 6, "'pos'", "a length or position"),
        (b("pos=\"1e160 0 0\""), 4, "<body> attribute 'pos'", "a length or position"),
        (b("euler=\"1e300 0 0\""), 4, "'euler'", "an angle"),
        (a("gear=\"1e300\""), 7, "'gear'", "a gear or strength must be between -1e6 and 1e6 N m"),
        (a("ctrlrange=\"-1e300 1e300\""), 7, "'ctrlrange'", "a control must be between -1e6 and 1e6"),
    ];
    for (xml, line, attr, range) in &cases {
        expect_err(xml, *line, &[attr, "is out of range", range]);
    }
    // Radians: 100 rad is 5730 degrees.
    let rad = doc("<compiler angle=\"radian\"/>", "<body euler=\"100 0 0\">\n<geom size=\"0.1\"/>\n</body>", "");
    expect_err(&rad, 4, &["'euler'", "5729.5", "an angle"]);
    // The bounds themselves load.
    load_str(&g("size=\"1e-4\" mass=\"1e6\" friction=\"1000\" pos=\"1000 0 0\""), "edge.xml").unwrap();
    load_str(&top("timestep=\"1\" gravity=\"0 0 -1000\""), "edge.xml").unwrap();
}

/// Huge but finite direction components are normalised, not zeroed: before, the norm of a
/// hinge axis "0 0 1e300" overflowed and the axis became (0, 0, 0), a joint that moves
/// nothing (here refused as "mass matrix not positive definite"; with armature, as in the
/// ant, loaded silently); a quaternion "1e300 0 0 0" was refused as a zero quaternion.
#[test]
fn huge_axis_and_quaternion_components_are_normalised_not_zeroed() {
    let xml = |axis: &str, quat: &str| {
        doc("", &format!("<body quat=\"{quat}\">\n<geom size=\"0.1\"/>\n<joint axis=\"{axis}\"/>\n</body>"), "")
    };
    let huge = load_str(&xml("0 0 1e300", "1e300 0 0 0"), "huge.xml").unwrap();
    let unit = load_str(&xml("0 0 1", "1 0 0 0"), "unit.xml").unwrap();
    assert_eq!(huge.joints[0].axis, [0.0, 0.0, 1.0]);
    assert_eq!(huge.joints[0].axis, unit.joints[0].axis);
    assert_eq!(huge.bodies[1].quat, unit.bodies[1].quat);
}
