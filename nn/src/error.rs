//! Errors of the `nn` crate: every message names the parameter, file or field at fault.

use std::fmt;
use std::path::PathBuf;

use tensor::TensorError;

/// An error from building, running, saving or loading a network.
#[derive(Debug)]
pub enum NnError {
    /// A tensor operation failed (shapes, axes, indices).
    Tensor(TensorError),
    /// A parameter is missing, duplicated or has the wrong shape.
    Param {
        /// The dotted parameter name.
        name: String,
        /// What is wrong.
        detail: String,
    },
    /// A layer was configured with impossible sizes or options.
    Config(String),
    /// Reading or writing a file failed.
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file could be read but its contents are not a valid state.
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong (with the position for syntax errors).
        detail: String,
    },
}

impl fmt::Display for NnError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NnError::Tensor(e) => write!(f, "{e}"),
            NnError::Param { name, detail } => write!(f, "parameter `{name}`: {detail}"),
            NnError::Config(d) => write!(f, "invalid layer configuration: {d}"),
            NnError::Io { path, source } => write!(f, "{}: {source}", path.display()),
            NnError::Format { path, detail } => write!(f, "{}: {detail}", path.display()),
        }
    }
}

impl std::error::Error for NnError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            NnError::Tensor(e) => Some(e),
            NnError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl From<TensorError> for NnError {
    fn from(e: TensorError) -> Self {
        NnError::Tensor(e)
    }
}

/// Result alias for the `nn` crate.
pub type Result<T> = std::result::Result<T, NnError>;
