//! The one error type of training, evaluation and the `meben` program. Every failure a user
//! can cause (a malformed config, an unknown environment or model name, an impossible size,
//! a damaged checkpoint, a non-finite loss) is an [`RlError`] whose message names the file,
//! the field and the value.

use std::fmt;
use std::path::PathBuf;

/// Why training, evaluation or a `meben` command failed.
#[derive(Debug)]
pub enum RlError {
    /// A configuration value that is out of range or unknown.
    Config {
        /// Where the value came from: a file path, `command line` or `built-in`.
        source: String,
        /// The field (e.g. `num_envs`).
        field: String,
        /// The value as given.
        value: String,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// A file could not be read, written or parsed.
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A checkpoint that does not fit the run (other sizes, names or version).
    Checkpoint {
        /// The checkpoint file.
        path: PathBuf,
        /// What does not fit.
        message: String,
    },
    /// A policy file (`meben export-policy`) that cannot be used: damaged, truncated, not a
    /// policy file, or not fitting its model; or a pretrained policy that is not shipped.
    Policy {
        /// The policy file (or the manifest of shipped policies).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A loss or a network output became NaN or infinite; the last good checkpoint is kept.
    NonFinite {
        /// What was non-finite (e.g. `team 0 loss at iteration 12, epoch 1, minibatch 3`).
        message: String,
    },
    /// A run directory whose lock another process holds ([`crate::app::lock`]): it is
    /// training there. A sweep reports such a run as taken, not failed.
    RunInUse {
        /// The run directory.
        run: PathBuf,
        /// Its lock file.
        lock: PathBuf,
        /// The holder as the lock file names it (`process <pid> on host <host>`).
        holder: String,
    },
    /// A training stopped on request ([`crate::stop::StopFlag`]): after a finished
    /// iteration, whose checkpoint it wrote, so that the same command resumes it; or before
    /// it began, having changed nothing.
    Interrupted {
        /// The run directory.
        run: PathBuf,
        /// The last finished iteration, which the checkpoint holds (`None`: stopped before
        /// training began).
        iteration: Option<u64>,
    },
    /// The environment rejected a setting or an action array.
    Env(envs::tasks::TaskError),
    /// A model could not be built or run.
    Model(models::ModelError),
    /// A layer, optimiser or saved-state operation failed.
    Nn(nn::NnError),
}

/// `Result` with [`RlError`].
pub type Result<T> = std::result::Result<T, RlError>;

impl RlError {
    /// A configuration error.
    pub fn config(source: impl Into<String>, field: &str, value: impl ToString, message: impl Into<String>) -> Self {
        RlError::Config {
            source: source.into(),
            field: field.into(),
            value: value.to_string(),
            message: message.into(),
        }
    }

    /// A file error.
    pub fn file(path: impl Into<PathBuf>, message: impl ToString) -> Self {
        RlError::File { path: path.into(), message: message.to_string() }
    }
}

impl fmt::Display for RlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RlError::Config { source, field, value, message } => {
                write!(f, "{source}: field `{field}` = {value:?}: {message}")
            }
            RlError::File { path, message } => write!(f, "{}: {message}", path.display()),
            RlError::Checkpoint { path, message } => write!(f, "checkpoint {}: {message}", path.display()),
            RlError::Policy { path, message } => write!(f, "policy file {}: {message}", path.display()),
            RlError::NonFinite { message } => write!(f, "non-finite value: {message}"),
            RlError::RunInUse { run, lock, holder } => write!(
                f,
                "{}: the run directory is in use by {holder} (lock file {}); wait for it to finish, stop it, or \
                 choose another --out",
                run.display(),
                lock.display()
            ),
            RlError::Interrupted { run, iteration: Some(i) } => write!(
                f,
                "{}: interrupted after iteration {i}, which its checkpoint holds (the same command resumes the run)",
                run.display()
            ),
            RlError::Interrupted { run, iteration: None } => {
                write!(f, "{}: interrupted before training began (nothing was changed)", run.display())
            }
            RlError::Env(e) => write!(f, "{e}"),
            RlError::Model(e) => write!(f, "{e}"),
            RlError::Nn(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for RlError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            RlError::Env(e) => Some(e),
            RlError::Model(e) => Some(e),
            RlError::Nn(e) => Some(e),
            _ => None,
        }
    }
}

impl From<envs::tasks::TaskError> for RlError {
    fn from(e: envs::tasks::TaskError) -> Self {
        RlError::Env(e)
    }
}

impl From<models::ModelError> for RlError {
    fn from(e: models::ModelError) -> Self {
        RlError::Model(e)
    }
}

impl From<nn::NnError> for RlError {
    fn from(e: nn::NnError) -> Self {
        RlError::Nn(e)
    }
}

impl From<tensor::TensorError> for RlError {
    fn from(e: tensor::TensorError) -> Self {
        RlError::Nn(nn::NnError::Tensor(e))
    }
}
