//! The error type of the model stages: bad options, observations that do not match their
//! [`envs::layout::ObsSpec`], and failures of the layers underneath.

use std::fmt;

/// Everything a model stage can reject.
#[derive(Debug)]
pub enum ModelError {
    /// An unknown name or option value (the message lists the accepted ones).
    Option(String),
    /// Observations, specs or assignments whose shapes or contents do not fit together.
    Input(String),
    /// A layer or tensor operation failed.
    Nn(nn::NnError),
}

/// `Result` with [`ModelError`].
pub type Result<T> = std::result::Result<T, ModelError>;

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelError::Option(m) => write!(f, "invalid option: {m}"),
            ModelError::Input(m) => write!(f, "invalid model input: {m}"),
            ModelError::Nn(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ModelError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ModelError::Nn(e) => Some(e),
            _ => None,
        }
    }
}

impl From<envs::layout::LayoutError> for ModelError {
    fn from(e: envs::layout::LayoutError) -> Self {
        ModelError::Input(e.0)
    }
}

impl From<nn::NnError> for ModelError {
    fn from(e: nn::NnError) -> Self {
        ModelError::Nn(e)
    }
}

impl From<tensor::TensorError> for ModelError {
    fn from(e: tensor::TensorError) -> Self {
        ModelError::Nn(nn::NnError::Tensor(e))
    }
}
