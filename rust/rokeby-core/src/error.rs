//! Errors of the core. Every public entry point validates its input and returns one of these
//! instead of panicking; the binding crate maps them to Python exceptions.

use thiserror::Error;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum RokebyError {
    /// An argument has the wrong size or a value outside its domain. `arg` names the argument the
    /// way the Python API spells it, so that the message tells a user which input to fix.
    #[error("{arg}: {msg}")]
    InvalidArgument { arg: String, msg: String },
}

impl RokebyError {
    pub fn invalid(arg: impl Into<String>, msg: impl Into<String>) -> Self {
        RokebyError::InvalidArgument { arg: arg.into(), msg: msg.into() }
    }
}

pub type Result<T> = std::result::Result<T, RokebyError>;
