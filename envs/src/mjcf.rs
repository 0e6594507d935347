//! MJCF (MuJoCo XML) loader for the subset the project needs, into a [`Model`] through
//! [`ModelBuilder`].
//!
//! Supported: `compiler` (`angle`, `inertiafromgeom` true/auto, `eulerseq`,
//! `coordinate="local"`), `option` (`timestep`, `gravity`, `integrator`, child
//! `<flag contact=... limit=.../>`), `default` classes (nested; `class` and `childclass`) for
//! `geom`, `joint` and `motor`, `worldbody`/`body` (`name`, `pos`, `quat`, `euler`,
//! `childclass`), `geom` (sphere, capsule by `size` or `fromto`, plane; `pos`, `quat`, `euler`,
//! `density`, `mass`, `friction` (sliding coefficient), `contype`, `conaffinity`), `joint`
//! (free, hinge: `axis`, `pos`, `range`, `limited`, `armature`, `damping`) and `freejoint`,
//! `actuator/motor` (`joint`, `gear`, `ctrlrange`, `ctrllimited`). Purely visual or unrelated
//! elements (`asset`, `light`, `camera`, `site`, `custom`, ...) and attributes (`rgba`,
//! `material`, `condim`, `margin`, ...) are ignored. Anything that would change the physics
//! but is not supported (other geom, joint or actuator types, `include`, orientation by
//! `axisangle`/`xyaxes`/`zaxis`, `coordinate="global"`, `inertiafromgeom="false"`) is an
//! error rather than silently wrong.
//!
//! The `integrator` is recorded in [`crate::Options::integrator`]; `Euler` and `implicit` are
//! stepped as named, `RK4` and `implicitfast` with Euler (see [`crate::integrator`]).
//!
//! Every number is checked against its physical range ([`crate::limits`]: lengths, sizes,
//! masses, densities, angles, time step, gravity, gears, damping, armature, friction,
//! control ranges), so that an absurd value is refused where it is written rather than
//! reported later as a singular mass matrix or a non-finite state.
//!
//! Every error is a [`MjcfError`] naming the file, the line, the element, the attribute and
//! the offending value; loading never panics.

#![allow(clippy::result_large_err)] // errors carry file/line/element/attribute/value; cold path

use crate::builder::{GeomSpec, HingeSpec, ModelBuilder};
use crate::limits::{self, Limit};
use crate::math::{self, Quat, Vec3};
use crate::model::{BodyId, Integrator, JointId, Model, ModelError};
use std::collections::HashMap;
use std::fmt;
use std::path::Path;

/// A loading error with its location.
#[derive(Clone, Debug, PartialEq)]
pub struct MjcfError {
    /// File name (or the name given to [`load_str`]).
    pub file: String,
    /// 1-based line (0 when the error has no location, e.g. an unreadable file).
    pub line: u32,
    /// Element name (without angle brackets), empty if none.
    pub element: String,
    /// Attribute name, if the error concerns one.
    pub attribute: Option<String>,
    /// The offending value, if any.
    pub value: Option<String>,
    /// What is wrong / what was expected.
    pub message: String,
}

impl fmt::Display for MjcfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // `file[:line][: <element>][ attribute 'a'][ value "v"]: message`.
        write!(f, "{}", self.file)?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
        }
        if !self.element.is_empty() {
            write!(f, ": <{}>", self.element)?;
        }
        if let Some(a) = &self.attribute {
            write!(f, " attribute '{a}'")?;
        }
        if let Some(v) = &self.value {
            write!(f, " value \"{v}\"")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for MjcfError {}

impl MjcfError {
    /// An error about the text as a whole, at `line` (0: no location) and not about one
    /// element.
    pub(crate) fn whole(file: &str, line: u32, message: String) -> MjcfError {
        MjcfError { file: file.to_string(), line, element: String::new(), attribute: None, value: None, message }
    }
}

/// The text of an MJCF file and the name its errors give it (the path as displayed).
pub(crate) fn read_file(path: &Path) -> Result<(String, String), MjcfError> {
    let name = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|e| MjcfError::whole(&name, 0, format!("cannot read the file: {e}")))?;
    Ok((text, name))
}

/// `text` as an XML document; malformed XML is an error at its line.
pub(crate) fn parse_xml<'i>(text: &'i str, file: &str) -> Result<roxmltree::Document<'i>, MjcfError> {
    roxmltree::Document::parse(text).map_err(|e| MjcfError::whole(file, e.pos().row, format!("malformed XML: {e}")))
}

/// Loads an MJCF file.
pub fn load_file(path: impl AsRef<Path>) -> Result<Model, MjcfError> {
    let (text, name) = read_file(path.as_ref())?;
    load_str(&text, &name)
}

/// Loads MJCF from a string; `file` names it in error messages.
pub fn load_str(text: &str, file: &str) -> Result<Model, MjcfError> {
    load_str_with_sources(text, file).map(|(model, _)| model)
}

/// Loads MJCF from a string and says where each body, joint, geom and actuator of the model
/// came from (for checks a caller makes beyond the loader's, such as
/// [`crate::mjcf_agent`]'s); `file` names it in error messages.
pub fn load_str_with_sources(text: &str, file: &str) -> Result<(Model, MjcfSources), MjcfError> {
    let doc = parse_xml(text, file)?;
    let mut p = Parser {
        file: file.to_string(),
        doc: &doc,
        degree: true,
        eulerseq: *b"xyz",
        classes: HashMap::new(),
        b: ModelBuilder::new(),
        joints: HashMap::new(),
        sources: MjcfSources::default(),
        joint_ndof: Vec::new(),
        newlines: text.bytes().enumerate().filter(|(_, c)| *c == b'\n').map(|(i, _)| i).collect(),
    };
    let model = p.run()?;
    Ok((model, p.sources))
}

/// One attribute of an element as it applies (its own, or its class default's), with the
/// line where it is written.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceAttribute {
    /// Attribute name.
    pub name: String,
    /// Value as written.
    pub value: String,
    /// 1-based line where it is written (the element's, or its `<default>` class's).
    pub line: u32,
}

/// The element behind one body, joint, geom or actuator of a loaded model.
#[derive(Clone, Debug, PartialEq)]
pub struct ElementSource {
    /// Element name (`body`, `joint`, `freejoint`, `geom`, `motor`).
    pub element: String,
    /// 1-based line of the element.
    pub line: u32,
    /// Every attribute that applies to it, class defaults included, sorted by name.
    pub attributes: Vec<SourceAttribute>,
}

impl ElementSource {
    /// The attribute with this name, if it applies.
    pub fn get(&self, name: &str) -> Option<&SourceAttribute> {
        self.attributes.iter().find(|a| a.name == name)
    }
}

/// Where every part of a loaded model came from, in model order: `bodies[i]` is model body
/// `i + 1` (the world has no element), `joints[j]` model joint `j`, `geoms[g]` model geom
/// `g`, `actuators[u]` model actuator `u`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MjcfSources {
    /// The body elements.
    pub bodies: Vec<ElementSource>,
    /// The joint and freejoint elements.
    pub joints: Vec<ElementSource>,
    /// The geom elements.
    pub geoms: Vec<ElementSource>,
    /// The actuator elements.
    pub actuators: Vec<ElementSource>,
}

/// One attribute value with the line it came from.
#[derive(Clone, Debug)]
struct Val {
    text: String,
    line: u32,
    element: String,
}

/// Attribute defaults of one class for the element kinds we use.
#[derive(Clone, Debug, Default)]
struct Class {
    geom: HashMap<String, Val>,
    joint: HashMap<String, Val>,
    motor: HashMap<String, Val>,
}

struct Parser<'a, 'i> {
    file: String,
    doc: &'a roxmltree::Document<'i>,
    degree: bool,
    eulerseq: [u8; 3],
    classes: HashMap<String, Class>,
    b: ModelBuilder,
    joints: HashMap<String, JointId>,
    /// The elements that became bodies, joints, geoms, actuators (also locate
    /// `ModelBuilder::build` errors).
    sources: MjcfSources,
    /// DoF of each joint in `sources.joints`.
    joint_ndof: Vec<usize>,
    /// Byte offsets of the text's line breaks, for [`Parser::line_of`].
    newlines: Vec<usize>,
}

type Node<'a, 'i> = roxmltree::Node<'a, 'i>;

/// Resolved attributes of one element: class defaults overridden by its own attributes.
struct Attrs {
    map: HashMap<String, Val>,
    element: String,
    line: u32,
}

impl Attrs {
    fn source(&self) -> ElementSource {
        let mut attributes: Vec<SourceAttribute> = self
            .map
            .iter()
            .map(|(name, v)| SourceAttribute { name: name.clone(), value: v.text.clone(), line: v.line })
            .collect();
        attributes.sort_by(|a, b| a.name.cmp(&b.name));
        ElementSource { element: self.element.clone(), line: self.line, attributes }
    }
}

impl<'a, 'i> Parser<'a, 'i> {
    /// 1-based line of byte offset `pos`: one plus the line breaks before it, as
    /// `roxmltree::Document::text_pos_at` counts, found by binary search in the table of line
    /// breaks (`text_pos_at` scans from the start of the text: once per element and attribute,
    /// that is quadratic in the size of the file).
    fn line_of(&self, pos: usize) -> u32 {
        1 + self.newlines.partition_point(|&nl| nl < pos) as u32
    }

    fn err_node(&self, node: Node, msg: impl Into<String>) -> MjcfError {
        MjcfError {
            file: self.file.clone(),
            line: self.line_of(node.range().start),
            element: node.tag_name().name().to_string(),
            attribute: None,
            value: None,
            message: msg.into(),
        }
    }

    fn err_attr(&self, a: &Attrs, name: &str, msg: impl Into<String>) -> MjcfError {
        let (line, value, element) = match a.map.get(name) {
            Some(v) => (v.line, Some(v.text.clone()), v.element.clone()),
            None => (a.line, None, a.element.clone()),
        };
        MjcfError {
            file: self.file.clone(),
            line,
            element,
            attribute: Some(name.to_string()),
            value,
            message: msg.into(),
        }
    }

    fn own_attrs(&self, node: Node) -> HashMap<String, Val> {
        node.attributes()
            .map(|at| {
                (
                    at.name().to_string(),
                    Val {
                        text: at.value().to_string(),
                        line: self.line_of(at.range().start),
                        element: node.tag_name().name().to_string(),
                    },
                )
            })
            .collect()
    }

    /// Attributes of `node` (a geom, joint or motor) after applying its class.
    fn resolve(&self, node: Node, kind: &str, childclass: &str) -> Result<Attrs, MjcfError> {
        let own = self.own_attrs(node);
        let class_name = own.get("class").map(|v| v.text.clone()).unwrap_or_else(|| childclass.to_string());
        let class = self.classes.get(&class_name).ok_or_else(|| {
            let mut e = self.err_node(node, format!("unknown default class '{class_name}'"));
            e.attribute = Some("class".into());
            e.value = Some(class_name.clone());
            e
        })?;
        let defaults = match kind {
            "geom" => &class.geom,
            "joint" => &class.joint,
            _ => &class.motor,
        };
        let mut map = defaults.clone();
        map.extend(own);
        Ok(Attrs { map, element: node.tag_name().name().to_string(), line: self.line_of(node.range().start) })
    }

    fn plain(&self, node: Node) -> Attrs {
        Attrs {
            map: self.own_attrs(node),
            element: node.tag_name().name().to_string(),
            line: self.line_of(node.range().start),
        }
    }

    fn nums(&self, a: &Attrs, name: &str, min: usize, max: usize) -> Result<Option<Vec<f64>>, MjcfError> {
        let Some(v) = a.map.get(name) else { return Ok(None) };
        let mut out = Vec::new();
        for tok in v.text.split_whitespace() {
            match tok.parse::<f64>() {
                Ok(x) if x.is_finite() => out.push(x),
                _ => return Err(self.err_attr(a, name, format!("'{tok}' is not a finite number"))),
            }
        }
        if out.len() < min || out.len() > max {
            let want = if min == max { format!("{min}") } else { format!("{min} to {max}") };
            return Err(self.err_attr(a, name, format!("expected {want} numbers, found {}", out.len())));
        }
        Ok(Some(out))
    }

    fn num(&self, a: &Attrs, name: &str) -> Result<Option<f64>, MjcfError> {
        Ok(self.nums(a, name, 1, 1)?.map(|v| v[0]))
    }

    fn vec3(&self, a: &Attrs, name: &str) -> Result<Option<Vec3>, MjcfError> {
        Ok(self.nums(a, name, 3, 3)?.map(|v| [v[0], v[1], v[2]]))
    }

    /// Attribute `name` (a non-negative number) checked against `limit`.
    fn nonneg(&self, a: &Attrs, name: &str, limit: &Limit) -> Result<Option<f64>, MjcfError> {
        match a.map.get(name) {
            None => Ok(None),
            Some(v) => {
                let x = v.text.trim().parse::<f64>().ok().filter(|x| x.is_finite() && *x >= 0.0);
                let x = x.ok_or_else(|| self.err_attr(a, name, "expected a non-negative number"))?;
                self.within(a, name, &[x], limit)?;
                Ok(Some(x))
            }
        }
    }

    /// Checks the numbers `values` read from attribute `name` against `limit`.
    fn within(&self, a: &Attrs, name: &str, values: &[f64], limit: &Limit) -> Result<(), MjcfError> {
        for &x in values {
            limit.check(x).map_err(|m| self.err_attr(a, name, m))?;
        }
        Ok(())
    }

    /// Checks angles read from attribute `name` (in the compiler's unit) against
    /// [`limits::ANGLE_DEGREES`].
    fn angles_within(&self, a: &Attrs, name: &str, values: &[f64]) -> Result<(), MjcfError> {
        let degrees: Vec<f64> = values.iter().map(|&x| if self.degree { x } else { x.to_degrees() }).collect();
        self.within(a, name, &degrees, &limits::ANGLE_DEGREES)
    }

    /// A `vec3` attribute whose components are lengths ([`limits::LENGTH`]).
    fn position(&self, a: &Attrs, name: &str) -> Result<Option<Vec3>, MjcfError> {
        let p = self.vec3(a, name)?;
        if let Some(p) = &p {
            self.within(a, name, p, &limits::LENGTH)?;
        }
        Ok(p)
    }

    fn bits(&self, a: &Attrs, name: &str, default: u32) -> Result<u32, MjcfError> {
        match a.map.get(name) {
            None => Ok(default),
            Some(v) => v
                .text
                .trim()
                .parse::<u32>()
                .map_err(|_| self.err_attr(a, name, "expected a non-negative integer bit mask")),
        }
    }

    fn keyword<'s>(&self, a: &'s Attrs, name: &str, allowed: &[&str]) -> Result<Option<&'s str>, MjcfError> {
        match a.map.get(name) {
            None => Ok(None),
            Some(v) if allowed.contains(&v.text.trim()) => Ok(Some(v.text.trim())),
            Some(_) => Err(self.err_attr(a, name, format!("expected one of {}", allowed.join(", ")))),
        }
    }

    fn angle(&self, x: f64) -> f64 {
        if self.degree { x.to_radians() } else { x }
    }

    /// Orientation from `quat` or `euler` (others are rejected).
    fn orientation(&self, a: &Attrs) -> Result<Quat, MjcfError> {
        for bad in ["axisangle", "xyaxes", "zaxis"] {
            if a.map.contains_key(bad) {
                return Err(self.err_attr(a, bad, "unsupported orientation attribute (use quat or euler)"));
            }
        }
        if a.map.contains_key("quat") && a.map.contains_key("euler") {
            return Err(self.err_attr(a, "euler", "both quat and euler given"));
        }
        if let Some(q) = self.nums(a, "quat", 4, 4)? {
            // Scaled by the largest component first: the squares of 1e300 would overflow.
            let s = q.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let q: Vec<f64> = q.iter().map(|x| if s > 0.0 { x / s } else { 0.0 }).collect();
            let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
            if s == 0.0 || s * n < 1e-12 {
                return Err(self.err_attr(a, "quat", "zero quaternion"));
            }
            return Ok([q[0] / n, q[1] / n, q[2] / n, q[3] / n]);
        }
        if let Some(e) = self.vec3(a, "euler")? {
            self.angles_within(a, "euler", &e)?;
            return Ok(math::quat_euler([self.angle(e[0]), self.angle(e[1]), self.angle(e[2])], self.eulerseq));
        }
        Ok(math::QUAT_IDENTITY)
    }

    fn run(&mut self) -> Result<Model, MjcfError> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "mujoco" {
            return Err(self.err_node(root, "the root element must be <mujoco>"));
        }
        let top: Vec<Node> = root.children().filter(|n| n.is_element()).collect();
        for n in &top {
            if n.tag_name().name() == "include" {
                return Err(self.err_node(*n, "<include> is not supported"));
            }
        }
        for n in top.iter().filter(|n| n.tag_name().name() == "compiler") {
            self.compiler(*n)?;
        }
        let mut opts = self.b.options().clone();
        for n in top.iter().filter(|n| n.tag_name().name() == "option") {
            self.option(*n, &mut opts)?;
        }
        self.b.set_options(opts);
        self.classes.insert("main".into(), Class::default());
        for n in top.iter().filter(|n| n.tag_name().name() == "default") {
            self.default_class(*n, None)?;
        }
        for n in top.iter().filter(|n| n.tag_name().name() == "worldbody") {
            self.body_children(*n, BodyId::WORLD, "main", true)?;
        }
        for n in top.iter().filter(|n| n.tag_name().name() == "actuator") {
            self.actuators(*n)?;
        }
        self.b.build().map_err(|e| self.model_error(e))
    }

    fn compiler(&mut self, n: Node) -> Result<(), MjcfError> {
        let a = self.plain(n);
        if let Some(v) = self.keyword(&a, "angle", &["degree", "radian"])? {
            self.degree = v == "degree";
        }
        if let Some(v) = self.keyword(&a, "inertiafromgeom", &["true", "false", "auto"])?
            && v == "false"
        {
            return Err(self.err_attr(&a, "inertiafromgeom", "only inertia from geoms is supported (true or auto)"));
        }
        self.keyword(&a, "coordinate", &["local"])?;
        if let Some(v) = a.map.get("eulerseq") {
            let s = v.text.trim().as_bytes();
            if s.len() != 3 || !s.iter().all(|c| b"xyzXYZ".contains(c)) {
                return Err(self.err_attr(&a, "eulerseq", "expected three letters from xyzXYZ"));
            }
            self.eulerseq = [s[0], s[1], s[2]];
        }
        Ok(())
    }

    fn option(&mut self, n: Node, o: &mut crate::model::Options) -> Result<(), MjcfError> {
        let a = self.plain(n);
        if let Some(t) = self.num(&a, "timestep")? {
            if t <= 0.0 {
                return Err(self.err_attr(&a, "timestep", "must be positive"));
            }
            self.within(&a, "timestep", &[t], &limits::TIMESTEP)?;
            o.timestep = t;
        }
        if let Some(g) = self.vec3(&a, "gravity")? {
            self.within(&a, "gravity", &g, &limits::GRAVITY)?;
            o.gravity = g;
        }
        if let Some(v) = self.keyword(&a, "integrator", &["Euler", "RK4", "implicit", "implicitfast"])? {
            o.integrator = match v {
                "Euler" => Integrator::Euler,
                "RK4" => Integrator::Rk4,
                "implicit" => Integrator::Implicit,
                _ => Integrator::ImplicitFast,
            };
        }
        for f in n.children().filter(|c| c.is_element() && c.tag_name().name() == "flag") {
            let fa = self.plain(f);
            if let Some(v) = self.keyword(&fa, "contact", &["enable", "disable"])? {
                o.disable_contact = v == "disable";
            }
            if let Some(v) = self.keyword(&fa, "limit", &["enable", "disable"])? {
                o.disable_limit = v == "disable";
            }
        }
        Ok(())
    }

    fn default_class(&mut self, n: Node, parent: Option<&str>) -> Result<(), MjcfError> {
        let a = self.plain(n);
        let name = match (a.map.get("class"), parent) {
            (Some(v), _) => v.text.clone(),
            (None, None) => "main".to_string(),
            (None, Some(_)) => return Err(self.err_node(n, "a nested <default> needs a class attribute")),
        };
        if parent.is_some() && self.classes.contains_key(&name) {
            return Err(self.err_attr(&a, "class", "default class defined twice"));
        }
        let mut class = match parent {
            Some(p) => self.classes[p].clone(),
            None => self.classes.get(&name).cloned().unwrap_or_default(),
        };
        for c in n.children().filter(|c| c.is_element()) {
            let own = self.own_attrs(c);
            match c.tag_name().name() {
                "geom" => class.geom.extend(own),
                "joint" => class.joint.extend(own),
                "motor" => class.motor.extend(own),
                _ => {}
            }
        }
        self.classes.insert(name.clone(), class);
        for c in n.children().filter(|c| c.is_element() && c.tag_name().name() == "default") {
            self.default_class(c, Some(&name))?;
        }
        Ok(())
    }

    /// Geoms, joints and child bodies of `n` (the worldbody or a body) on body `body`.
    fn body_children(&mut self, n: Node, body: BodyId, childclass: &str, world: bool) -> Result<(), MjcfError> {
        for c in n.children().filter(|c| c.is_element()) {
            match c.tag_name().name() {
                "geom" => self.geom(c, body, childclass)?,
                "joint" | "freejoint" if world => {
                    return Err(self.err_node(c, "the world body cannot have joints"));
                }
                "joint" | "freejoint" => self.joint(c, body, childclass, n)?,
                "body" => self.body(c, body, childclass)?,
                "inertial" => return Err(self.err_node(c, "<inertial> is not supported (inertia comes from geoms)")),
                _ => {}
            }
        }
        Ok(())
    }

    fn body(&mut self, n: Node, parent: BodyId, childclass: &str) -> Result<(), MjcfError> {
        let a = self.plain(n);
        let pos = self.position(&a, "pos")?.unwrap_or([0.0; 3]);
        let quat = self.orientation(&a)?;
        let cc = match a.map.get("childclass") {
            Some(v) => {
                if !self.classes.contains_key(&v.text) {
                    return Err(self.err_attr(&a, "childclass", "unknown default class"));
                }
                v.text.clone()
            }
            None => childclass.to_string(),
        };
        let id = self.b.add_body(parent, pos, quat);
        let name = a.map.get("name").map(|v| v.text.clone()).unwrap_or_default();
        self.b.set_body_name(id, &name);
        self.sources.bodies.push(a.source());
        self.body_children(n, id, &cc, false)
    }

    fn geom(&mut self, n: Node, body: BodyId, childclass: &str) -> Result<(), MjcfError> {
        let a = self.resolve(n, "geom", childclass)?;
        let ty = self.keyword(
            &a,
            "type",
            &["sphere", "capsule", "plane", "box", "cylinder", "ellipsoid", "mesh", "hfield", "sdf"],
        )?;
        let ty = ty.unwrap_or("sphere");
        let size = self.nums(&a, "size", 1, 3)?;
        let fromto = self.nums(&a, "fromto", 6, 6)?;
        if let Some(f) = &fromto {
            self.within(&a, "fromto", f, &limits::LENGTH)?;
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let mut spec = match ty {
            "sphere" => {
                let s = size.ok_or_else(|| self.err_attr(&a, "size", "a sphere needs size (radius)"))?;
                if !positive(s[0]) {
                    return Err(self.err_attr(&a, "size", "the radius must be positive"));
                }
                self.within(&a, "size", &s[..1], &limits::SIZE)?;
                GeomSpec::sphere(s[0])
            }
            "capsule" => {
                let s = size.ok_or_else(|| self.err_attr(&a, "size", "a capsule needs size (radius [half-length])"))?;
                if !positive(s[0]) {
                    return Err(self.err_attr(&a, "size", "the radius must be positive"));
                }
                self.within(&a, "size", &s[..1], &limits::SIZE)?;
                match &fromto {
                    Some(f) => {
                        let (p, q) = ([f[0], f[1], f[2]], [f[3], f[4], f[5]]);
                        if math::norm(math::sub(q, p)) < 1e-12 {
                            return Err(self.err_attr(&a, "fromto", "the two end points coincide"));
                        }
                        if a.map.contains_key("pos") || a.map.contains_key("quat") || a.map.contains_key("euler") {
                            return Err(self.err_attr(&a, "fromto", "fromto cannot be combined with pos/quat/euler"));
                        }
                        GeomSpec::capsule_fromto(s[0], p, q)
                    }
                    None => {
                        if s.len() < 2 || s[1] < 0.0 {
                            return Err(self.err_attr(
                                &a,
                                "size",
                                "a capsule without fromto needs size \"radius half-length\"",
                            ));
                        }
                        self.within(&a, "size", &s[1..2], &limits::LENGTH)?;
                        GeomSpec::capsule(s[0], s[1])
                    }
                }
            }
            "plane" => GeomSpec::plane(),
            other => {
                return Err(self.err_attr(
                    &a,
                    "type",
                    format!("geom type '{other}' is not supported (sphere, capsule, plane)"),
                ));
            }
        };
        if fromto.is_none() {
            if let Some(p) = self.position(&a, "pos")? {
                spec.pos = p;
            }
            spec.quat = self.orientation(&a)?;
        } else if ty != "capsule" {
            return Err(self.err_attr(&a, "fromto", "fromto is only supported for capsules"));
        }
        if let Some(dn) = self.num(&a, "density")? {
            if dn < 0.0 {
                return Err(self.err_attr(&a, "density", "must be non-negative"));
            }
            self.within(&a, "density", &[dn], &limits::DENSITY)?;
            spec.density = dn;
        }
        if let Some(m) = self.num(&a, "mass")? {
            if m < 0.0 {
                return Err(self.err_attr(&a, "mass", "must be non-negative"));
            }
            self.within(&a, "mass", &[m], &limits::MASS)?;
            spec.mass = Some(m);
        }
        if let Some(f) = self.nums(&a, "friction", 1, 3)? {
            if f[0] < 0.0 {
                return Err(self.err_attr(&a, "friction", "must be non-negative"));
            }
            self.within(&a, "friction", &f[..1], &limits::FRICTION)?;
            spec.friction = f[0];
        }
        spec.contype = self.bits(&a, "contype", 1)?;
        spec.conaffinity = self.bits(&a, "conaffinity", 1)?;
        if ty == "plane" && body != BodyId::WORLD {
            return Err(self.err_attr(&a, "type", "planes are only supported in the worldbody"));
        }
        if let Some(v) = a.map.get("name") {
            spec.name = v.text.clone();
        }
        self.b.add_geom(body, spec);
        self.sources.geoms.push(a.source());
        Ok(())
    }

    fn joint(&mut self, n: Node, body: BodyId, childclass: &str, body_node: Node) -> Result<(), MjcfError> {
        let a = if n.tag_name().name() == "freejoint" { self.plain(n) } else { self.resolve(n, "joint", childclass)? };
        let ty = if n.tag_name().name() == "freejoint" {
            "free"
        } else {
            self.keyword(&a, "type", &["free", "hinge", "slide", "ball"])?.unwrap_or("hinge")
        };
        let name = a.map.get("name").map(|v| v.text.clone()).unwrap_or_default();
        let id = match ty {
            "free" => {
                let top = body_node.parent_element().is_some_and(|p| p.tag_name().name() == "worldbody");
                if !top {
                    return Err(self.err_attr(&a, "type", "a free joint is only allowed in a top-level body"));
                }
                if let Some(p) = self.vec3(&a, "pos")?
                    && p != [0.0; 3]
                {
                    return Err(self.err_attr(&a, "pos", "a free joint must be at the body origin"));
                }
                let id = self.b.add_free_joint(body);
                let armature = self.nonneg(&a, "armature", &limits::ARMATURE)?;
                let damping = self.nonneg(&a, "damping", &limits::DAMPING)?;
                self.b.set_joint_armature_damping(id, armature.unwrap_or(0.0), damping.unwrap_or(0.0));
                id
            }
            "hinge" => {
                let axis = self.vec3(&a, "axis")?.unwrap_or([0.0, 0.0, 1.0]);
                if math::norm(axis) < 1e-12 {
                    return Err(self.err_attr(&a, "axis", "zero joint axis"));
                }
                let mut spec = HingeSpec::new(axis);
                if let Some(p) = self.position(&a, "pos")? {
                    spec.anchor = p;
                }
                let range = self.nums(&a, "range", 2, 2)?;
                if let Some(r) = &range {
                    self.angles_within(&a, "range", r)?;
                }
                let limited = match self.keyword(&a, "limited", &["true", "false", "auto"])? {
                    Some("true") => true,
                    Some("false") => false,
                    _ => range.is_some(),
                };
                if limited {
                    let r = range.ok_or_else(|| self.err_attr(&a, "range", "a limited joint needs a range"))?;
                    if r[0] >= r[1] {
                        return Err(self.err_attr(&a, "range", "the lower limit must be below the upper limit"));
                    }
                    spec.range = Some([self.angle(r[0]), self.angle(r[1])]);
                }
                spec.armature = self.nonneg(&a, "armature", &limits::ARMATURE)?.unwrap_or(0.0);
                spec.damping = self.nonneg(&a, "damping", &limits::DAMPING)?.unwrap_or(0.0);
                spec.name = name.clone();
                self.b.add_hinge(body, spec)
            }
            other => {
                return Err(self.err_attr(&a, "type", format!("joint type '{other}' is not supported (free, hinge)")));
            }
        };
        self.b.set_joint_name(id, &name);
        if !name.is_empty() && self.joints.insert(name.clone(), id).is_some() {
            return Err(self.err_attr(&a, "name", "duplicate joint name"));
        }
        self.sources.joints.push(a.source());
        self.joint_ndof.push(if ty == "free" { 6 } else { 1 });
        Ok(())
    }

    fn actuators(&mut self, n: Node) -> Result<(), MjcfError> {
        for c in n.children().filter(|c| c.is_element()) {
            if c.tag_name().name() != "motor" {
                return Err(self.err_node(c, "only <motor> actuators are supported"));
            }
            let a = self.resolve(c, "motor", "main")?;
            let jname = a
                .map
                .get("joint")
                .map(|v| v.text.clone())
                .ok_or_else(|| self.err_attr(&a, "joint", "a motor needs a joint"))?;
            let joint =
                *self.joints.get(&jname).ok_or_else(|| self.err_attr(&a, "joint", "no hinge joint with this name"))?;
            let gear = self.nums(&a, "gear", 1, 6)?.map_or(1.0, |g| g[0]);
            self.within(&a, "gear", &[gear], &limits::TORQUE)?;
            let range = self.nums(&a, "ctrlrange", 2, 2)?;
            if let Some(r) = &range {
                self.within(&a, "ctrlrange", r, &limits::CONTROL)?;
            }
            let limited = match self.keyword(&a, "ctrllimited", &["true", "false", "auto"])? {
                Some("true") => true,
                Some("false") => false,
                _ => range.is_some(),
            };
            let ctrlrange = if limited {
                let r = range.ok_or_else(|| self.err_attr(&a, "ctrlrange", "ctrllimited needs a ctrlrange"))?;
                if r[0] > r[1] {
                    return Err(self.err_attr(&a, "ctrlrange", "the lower bound must not exceed the upper bound"));
                }
                Some([r[0], r[1]])
            } else {
                None
            };
            let id = self.b.add_actuator(joint, gear, ctrlrange);
            if let Some(v) = a.map.get("name") {
                self.b.set_actuator_name(id, &v.text);
            }
            self.sources.actuators.push(a.source());
        }
        Ok(())
    }

    /// Locates a builder error on the element that caused it.
    fn model_error(&self, e: ModelError) -> MjcfError {
        let loc = |v: &Vec<ElementSource>, i: usize| {
            v.get(i).map(|s| (s.line, s.element.clone())).unwrap_or((0, String::new()))
        };
        let (line, element) = match &e {
            ModelError::BadFreeJoint { body } => loc(&self.sources.bodies, body.wrapping_sub(1)),
            ModelError::PlaneOnMovingBody { geom } => loc(&self.sources.geoms, *geom),
            ModelError::ActuatorNotOnHinge { actuator } => loc(&self.sources.actuators, *actuator),
            ModelError::SingularMassMatrix { dof, .. } => {
                let (mut first, mut found) = (0, (0, String::new()));
                for (i, n) in self.joint_ndof.iter().enumerate() {
                    if *dof < first + n {
                        found = loc(&self.sources.joints, i);
                        break;
                    }
                    first += n;
                }
                found
            }
            _ => (0, String::new()),
        };
        MjcfError { file: self.file.clone(), line, element, attribute: None, value: None, message: e.to_string() }
    }
}
