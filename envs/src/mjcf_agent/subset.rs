//! Which MJCF an agent morphology may use: the elements and attributes [`super`] reads, those
//! it ignores on purpose (visual ones, solver tuning, and the scene's own settings), and
//! everything else, refused with an [`MjcfError`] naming the file, line, element, attribute
//! and value. The loader ([`crate::mjcf`]) has already refused what the simulator cannot
//! represent at all (other geom, joint and actuator types, `<inertial>`, `<include>`, ...);
//! these checks add what a MeBen agent cannot be.

#![allow(clippy::result_large_err)] // errors carry file/line/element/attribute/value; cold path

use crate::brax::BraxPhysics;
use crate::mjcf::{self, ElementSource, MjcfError, MjcfSources};
use crate::model::Model;

/// How an agent morphology treats the attributes of one element kind; any other attribute is
/// refused.
struct Attributes {
    /// Read and used (or checked below).
    read: &'static [&'static str],
    /// Ignored on purpose: no effect on the agent's physics in a MeBen scene.
    ignored: &'static [&'static str],
    /// Accepted only when every number is 0 (physics the tree cannot carry otherwise).
    zero: &'static [&'static str],
}

const BODY: Attributes =
    Attributes { read: &["name", "pos", "quat", "euler", "childclass"], ignored: &["user"], zero: &[] };

const JOINT: Attributes = Attributes {
    read: &["name", "type", "axis", "pos", "range", "limited", "armature", "damping", "class"],
    // Contact-solver tuning of the limits (the simulator's own), and visual grouping.
    ignored: &["margin", "solreflimit", "solimplimit", "solreffriction", "solimpfriction", "group", "user"],
    zero: &["stiffness", "springref", "ref", "frictionloss", "springdamper"],
};

const FREEJOINT: Attributes = Attributes { read: &["name"], ignored: &["group"], zero: &[] };

const GEOM: Attributes = Attributes {
    read: &[
        "name",
        "type",
        "size",
        "fromto",
        "pos",
        "quat",
        "euler",
        "density",
        "mass",
        "friction",
        "contype",
        "conaffinity",
        "condim",
        "class",
    ],
    // Appearance, and the contact solver's tuning (the simulator's own, as for Brax configs).
    ignored: &["rgba", "material", "group", "margin", "gap", "solref", "solimp", "solmix", "priority", "user"],
    zero: &[],
};

const MOTOR: Attributes = Attributes {
    read: &["name", "joint", "gear", "ctrlrange", "ctrllimited", "class"],
    ignored: &["group", "user"],
    zero: &[],
};

/// Top-level elements with no effect on an agent in a MeBen scene. `option` (time step,
/// integrator, gravity) is the scene's, as a Brax config's `dt` and `gravity` are.
const TOP_IGNORED: [&str; 8] = ["option", "size", "visual", "statistic", "asset", "custom", "keyframe", "sensor"];
/// Top-level elements read (through the loader).
const TOP_READ: [&str; 4] = ["compiler", "default", "worldbody", "actuator"];
/// Children of `<worldbody>` and `<body>` that never touch the physics.
const DECORATION: [&str; 3] = ["site", "camera", "light"];
/// `<compiler>` attributes: read by the loader, or about files and visuals only.
const COMPILER: [&str; 10] = [
    "angle",
    "coordinate",
    "inertiafromgeom",
    "eulerseq",
    "meshdir",
    "texturedir",
    "assetdir",
    "discardvisual",
    "strippath",
    // Bodies without joints are always fused into their parent here.
    "fusestatic",
];

/// An error on `source`'s element, about `attribute` (with its value and line) if given.
pub(super) fn error(
    file: &str,
    source: &ElementSource,
    attribute: Option<&str>,
    message: impl Into<String>,
) -> MjcfError {
    let found = attribute.and_then(|a| source.get(a));
    MjcfError {
        file: file.to_string(),
        line: found.map_or(source.line, |a| a.line),
        element: source.element.clone(),
        attribute: attribute.map(str::to_string),
        value: found.map(|a| a.value.clone()),
        message: message.into(),
    }
}

fn node_error(file: &str, doc: &roxmltree::Document, node: roxmltree::Node, message: String) -> MjcfError {
    MjcfError {
        file: file.to_string(),
        line: doc.text_pos_at(node.range().start).row,
        element: node.tag_name().name().to_string(),
        attribute: None,
        value: None,
        message,
    }
}

/// Refuses elements an agent morphology cannot hold: top-level sections that change the
/// physics (`contact`, `equality`, `tendon`, ...), and anything in `<worldbody>` or a
/// `<body>` other than bodies, geoms, joints and decorations (`site`, `camera`, `light`).
pub(super) fn check_elements(text: &str, file: &str) -> Result<(), MjcfError> {
    let doc = mjcf::parse_xml(text, file)?;
    for top in doc.root_element().children().filter(|n| n.is_element()) {
        let name = top.tag_name().name();
        if TOP_IGNORED.contains(&name) {
            continue;
        }
        if !TOP_READ.contains(&name) {
            let why = format!(
                "<{name}> is not supported in an agent morphology (read: {}; ignored: {})",
                TOP_READ.join(", "),
                TOP_IGNORED.join(", ")
            );
            return Err(node_error(file, &doc, top, why));
        }
        match name {
            "compiler" => check_compiler(file, &doc, top)?,
            "worldbody" => check_body_children(file, &doc, top)?,
            _ => {}
        }
    }
    Ok(())
}

fn check_compiler(file: &str, doc: &roxmltree::Document, node: roxmltree::Node) -> Result<(), MjcfError> {
    for a in node.attributes() {
        let ok = COMPILER.contains(&a.name()) || (a.name() == "autolimits" && a.value().trim() == "true");
        if !ok {
            return Err(MjcfError {
                file: file.to_string(),
                line: doc.text_pos_at(a.range().start).row,
                element: "compiler".into(),
                attribute: Some(a.name().to_string()),
                value: Some(a.value().to_string()),
                message: format!(
                    "not supported in an agent morphology (accepted: {}, autolimits=\"true\")",
                    COMPILER.join(", ")
                ),
            });
        }
    }
    Ok(())
}

fn check_body_children(file: &str, doc: &roxmltree::Document, node: roxmltree::Node) -> Result<(), MjcfError> {
    for c in node.children().filter(|n| n.is_element()) {
        let name = c.tag_name().name();
        match name {
            "body" => check_body_children(file, doc, c)?,
            // The loader reads (or refuses) these.
            "geom" | "joint" | "freejoint" | "inertial" => {}
            _ if DECORATION.contains(&name) => {}
            _ => {
                let why = format!(
                    "<{name}> is not supported in an agent morphology (a body holds bodies, geoms, joints, {})",
                    DECORATION.join(", ")
                );
                return Err(node_error(file, doc, c, why));
            }
        }
    }
    Ok(())
}

/// Checks the attributes of one element against its kind's rules.
fn check(file: &str, source: &ElementSource, rules: &Attributes) -> Result<(), MjcfError> {
    for a in &source.attributes {
        let name = a.name.as_str();
        if rules.read.contains(&name) || rules.ignored.contains(&name) {
            continue;
        }
        if rules.zero.contains(&name) {
            let zero = a.value.split_whitespace().all(|t| t.parse::<f64>().is_ok_and(|x| x == 0.0));
            if zero {
                continue;
            }
            return Err(error(file, source, Some(name), "only 0 is supported in an agent morphology"));
        }
        let mut accepted: Vec<&str> = rules.read.iter().chain(rules.ignored).copied().collect();
        accepted.extend(rules.zero.iter().map(|z| if *z == "springdamper" { "springdamper=\"0 0\"" } else { z }));
        let message = format!("not supported in an agent morphology (accepted: {})", accepted.join(", "));
        return Err(error(file, source, Some(name), message));
    }
    Ok(())
}

/// Refuses attributes an agent cannot carry, and values that disagree with the scene:
/// a geom's sliding friction other than the scene's (`physics.friction`; every agent geom
/// gets it), `condim` other than 3 (sliding friction, the simulator's only contact kind), a
/// geom that collides with nothing (`contype` and `conaffinity` both 0: a MeBen scene makes
/// every agent geom collide), and a motor gear with more than one non-zero component. The
/// world's own geoms are not the agent's and are checked by [`super::agent_tree`].
pub(super) fn check_attributes(
    model: &Model,
    sources: &MjcfSources,
    file: &str,
    physics: &BraxPhysics,
) -> Result<(), MjcfError> {
    for s in &sources.bodies {
        check(file, s, &BODY)?;
    }
    for s in &sources.joints {
        check(file, s, if s.element == "freejoint" { &FREEJOINT } else { &JOINT })?;
    }
    for (g, s) in sources.geoms.iter().enumerate() {
        if model.geoms.get(g).is_none_or(|geom| geom.body == 0) {
            continue;
        }
        check(file, s, &GEOM)?;
        if model.geoms[g].friction != physics.friction {
            let message = format!(
                "the sliding friction must be the scene's, {} (every agent geom and the ground have it)",
                physics.friction
            );
            return Err(error(file, s, Some("friction"), message));
        }
        if s.get("condim").is_some_and(|a| a.value.trim() != "3") {
            return Err(error(file, s, Some("condim"), "only condim=\"3\" (sliding friction) is supported"));
        }
        let off = |a: &str| s.get(a).is_some_and(|v| v.value.trim() == "0");
        if off("contype") && off("conaffinity") {
            let message = "a geom that collides with nothing is not supported in an agent morphology: in a MeBen \
                           scene every agent geom collides with the ground and the other agents";
            return Err(error(file, s, Some("contype"), message));
        }
    }
    for s in &sources.actuators {
        check(file, s, &MOTOR)?;
        if let Some(g) = s.get("gear") {
            let extra = g.value.split_whitespace().skip(1).any(|t| t.parse::<f64>() != Ok(0.0));
            if extra {
                return Err(error(
                    file,
                    s,
                    Some("gear"),
                    "a hinge motor takes one gear; the other components must be 0",
                ));
            }
        }
    }
    Ok(())
}
