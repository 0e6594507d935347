//! The one error type of the MeBen tasks: every failure caused by user input (an unknown
//! environment name, a bad composition, a bad action array, a bad curriculum factor) is a
//! [`TaskError`] whose message names the offending value; nothing here panics on user input.

use std::fmt;

/// Why a task could not be built or stepped.
#[derive(Clone, Debug, PartialEq)]
pub enum TaskError {
    /// An environment name that is neither built in nor a valid custom composition.
    UnknownEnv {
        /// The name asked for.
        name: String,
        /// Every built-in name.
        known: Vec<String>,
    },
    /// A custom composition or a setting with a bad value.
    BadSpec {
        /// Which setting (e.g. `R`, `balls`, `team1`).
        what: String,
        /// The value as given.
        value: String,
        /// What is wrong and what is accepted.
        message: String,
    },
    /// A morphology that could not be loaded or turned into a model.
    Morphology {
        /// The morphology name or path.
        name: String,
        /// The loader's message.
        message: String,
    },
    /// The simulator refused the scene.
    Model {
        /// The simulator's message.
        message: String,
    },
    /// An action array of the wrong length or with a non-finite entry.
    BadActions {
        /// What is wrong (names the index and the value).
        message: String,
    },
    /// A run-time argument out of range (batch size, curriculum factor, environment index...).
    BadArgument {
        /// The argument's name.
        what: String,
        /// The value as given.
        value: String,
        /// What is accepted.
        message: String,
    },
}

impl fmt::Display for TaskError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TaskError::UnknownEnv { name, known } => write!(
                f,
                "unknown environment {name:?}; known environments: {}; or a custom composition such as \
                 \"team_reach:agents=ant+claw;R=5;balls=2\" or \"team_sumo:team1=ant+claw;team2=ant+ant;R=3\"",
                known.join(", ")
            ),
            TaskError::BadSpec { what, value, message } => write!(f, "bad {what} {value:?}: {message}"),
            TaskError::Morphology { name, message } => write!(f, "morphology {name:?}: {message}"),
            TaskError::Model { message } => write!(f, "the simulator refused the scene: {message}"),
            TaskError::BadActions { message } => write!(f, "bad actions: {message}"),
            TaskError::BadArgument { what, value, message } => write!(f, "bad {what} = {value}: {message}"),
        }
    }
}

impl std::error::Error for TaskError {}
