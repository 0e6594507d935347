//! The one error type of the Brax config loader.
//!
//! Every failure (bad syntax, a config that does not describe a valid agent, an unknown
//! built-in morphology, an unreadable file) is a [`BraxError`]; nothing in the loader panics
//! on bad input. Messages start with `source:line:column:` so that editors can jump to them.

use std::fmt;
use std::path::PathBuf;

/// A position in a config text: the source name (file path or built-in name), 1-based line
/// and 1-based column (in characters).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// File path or built-in morphology name the text came from.
    pub source: String,
    /// 1-based line number.
    pub line: usize,
    /// 1-based column number, counted in characters.
    pub column: usize,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.source, self.line, self.column)
    }
}

/// Why a Brax config could not be loaded.
#[derive(Clone, Debug, PartialEq)]
pub enum BraxError {
    /// The text is not valid protobuf text format.
    Syntax {
        /// Where the parser stopped.
        location: Location,
        /// What was expected and what was found instead.
        message: String,
    },
    /// The text parses but does not describe a valid agent (unknown body, missing field, ...).
    Config {
        /// Where the offending field (or message) starts.
        location: Location,
        /// Dotted path of the field, e.g. `joints.angle_limit`.
        field: String,
        /// The offending value as written, when there is one.
        value: Option<String>,
        /// What is wrong.
        message: String,
    },
    /// A built-in morphology was asked for by a name that does not exist.
    UnknownMorphology {
        /// The name asked for.
        name: String,
        /// Every accepted name.
        known: Vec<String>,
    },
    /// The simulator refused the model made from a valid config.
    Model {
        /// The config's source name.
        source: String,
        /// The simulator's message.
        message: String,
    },
    /// A config file could not be read.
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's message.
        message: String,
    },
}

impl BraxError {
    /// The location of the error, when it has one.
    pub fn location(&self) -> Option<&Location> {
        match self {
            BraxError::Syntax { location, .. } | BraxError::Config { location, .. } => Some(location),
            _ => None,
        }
    }
}

impl fmt::Display for BraxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BraxError::Syntax { location, message } => {
                write!(f, "{location}: syntax error: {message}")
            }
            BraxError::Config { location, field, value, message } => {
                write!(f, "{location}: field `{field}`")?;
                if let Some(value) = value {
                    write!(f, " = {value}")?;
                }
                write!(f, ": {message}")
            }
            BraxError::UnknownMorphology { name, known } => {
                write!(f, "unknown morphology `{name}`; known names: {}", known.join(", "))
            }
            BraxError::Model { source, message } => {
                write!(f, "{source}: the simulator rejected the model: {message}")
            }
            BraxError::Io { path, message } => {
                write!(f, "cannot read Brax config {}: {message}", path.display())
            }
        }
    }
}

impl std::error::Error for BraxError {}
