//! MeBen's seven agent configs, compiled into the library, and loading configs from files.
//!
//! The texts are copies of `../shared/reference/morphologies/*.txt` kept in
//! `envs/morphologies/`, so no file is needed at run time.

use std::path::Path;

use super::config::SystemConfig;
use super::error::BraxError;
use super::prototext;

/// A built-in morphology.
#[derive(Clone, Copy, Debug)]
pub struct Morphology {
    /// Canonical name (`ant`, `claw`, `centipede`, `unimal_<id>`).
    pub name: &'static str,
    /// The file stem in MeBen's release (also accepted by [`morphology`]).
    pub file_stem: &'static str,
    /// Other accepted names (MeBen's Team Reach roles `unimal_1`, `unimal_2`).
    pub aliases: &'static [&'static str],
    /// What it is.
    pub description: &'static str,
    /// The config text (protobuf text format).
    pub text: &'static str,
}

/// Every built-in morphology.
pub const MORPHOLOGIES: [Morphology; 7] = [
    Morphology {
        name: "ant",
        file_stem: "ant",
        aliases: &[],
        description: "MeBen's ant: sphere torso, 4 legs of hip + ankle (8 actuated DoF)",
        text: include_str!("../../morphologies/ant.txt"),
    },
    Morphology {
        name: "claw",
        file_stem: "claw",
        aliases: &[],
        description: "4 legs with 2-DoF universal hips, knee and ankle (16 actuated DoF)",
        text: include_str!("../../morphologies/claw.txt"),
    },
    Morphology {
        name: "centipede",
        file_stem: "centipede",
        aliases: &[],
        description: "3 torso segments with 2 legs each (14 actuated DoF)",
        text: include_str!("../../morphologies/centipede.txt"),
    },
    Morphology {
        name: "unimal_5506-10-14-17-10-38-34",
        file_stem: "5506-10-14-17-10-38-34",
        aliases: &["unimal_1"],
        description: "Team Reach 2_unimals, unimal_1 (13 actuated DoF)",
        text: include_str!("../../morphologies/5506-10-14-17-10-38-34.txt"),
    },
    Morphology {
        name: "unimal_5506-12-11-17-05-56-16",
        file_stem: "5506-12-11-17-05-56-16",
        aliases: &["unimal_2"],
        description: "Team Reach 2_unimals, unimal_2 (10 actuated DoF)",
        text: include_str!("../../morphologies/5506-12-11-17-05-56-16.txt"),
    },
    Morphology {
        name: "unimal_5506-13-5-02-21-35-41",
        file_stem: "5506-13-5-02-21-35-41",
        aliases: &[],
        description: "Team Sumo unimal (13 actuated DoF)",
        text: include_str!("../../morphologies/5506-13-5-02-21-35-41.txt"),
    },
    Morphology {
        name: "unimal_5506-15-11-01-10-04-14",
        file_stem: "5506-15-11-01-10-04-14",
        aliases: &[],
        description: "Team Sumo unimal (10 actuated DoF)",
        text: include_str!("../../morphologies/5506-15-11-01-10-04-14.txt"),
    },
];

/// Every accepted name: canonical names, then file stems and aliases that differ from them.
pub fn known_names() -> Vec<&'static str> {
    let mut names: Vec<&'static str> = MORPHOLOGIES.iter().map(|m| m.name).collect();
    for m in &MORPHOLOGIES {
        if m.file_stem != m.name {
            names.push(m.file_stem);
        }
        names.extend(m.aliases.iter().copied());
    }
    names
}

/// The built-in morphology with this canonical name, file stem or alias (a trailing `.txt`
/// is accepted too). An unknown name gives [`BraxError::UnknownMorphology`] listing the
/// known names.
pub fn morphology(name: &str) -> Result<&'static Morphology, BraxError> {
    let key = name.strip_suffix(".txt").unwrap_or(name);
    MORPHOLOGIES.iter().find(|m| m.name == key || m.file_stem == key || m.aliases.contains(&key)).ok_or_else(|| {
        BraxError::UnknownMorphology {
            name: name.to_string(),
            known: known_names().iter().map(|s| s.to_string()).collect(),
        }
    })
}

/// Parses and checks a built-in morphology.
pub fn load_morphology(name: &str) -> Result<SystemConfig, BraxError> {
    let m = morphology(name)?;
    parse_config(m.text, m.name)
}

/// Parses and checks config text; `source` names it in error messages.
pub fn parse_config(text: &str, source: &str) -> Result<SystemConfig, BraxError> {
    let tree = prototext::parse(text, source)?;
    SystemConfig::from_message(&tree, source)
}

/// Reads, parses and checks a config file; errors name the path.
pub fn load_config_file(path: impl AsRef<Path>) -> Result<SystemConfig, BraxError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path)
        .map_err(|e| BraxError::Io { path: path.to_path_buf(), message: e.to_string() })?;
    parse_config(&text, &path.display().to_string())
}
