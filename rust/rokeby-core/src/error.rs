//! Errors of the core. Every public entry point validates its input and returns one of these
//! instead of panicking; the binding crate maps them to Python exceptions:
//!
//! | variant            | meaning                                                        | Python            |
//! |--------------------|----------------------------------------------------------------|-------------------|
//! | `InvalidArgument`  | an argument has the wrong size or a value outside its domain   | `ValueError`      |
//! | `OutOfMemory`      | a size the caller or a file asks for is over the memory limit  | `MemoryError`     |
//! | `Numerical`        | a solve or iteration failed on valid input                     | `NumericalError` (a `RuntimeError`) |
//! | `Cancelled`        | [`crate::cancel::request`] stopped the call                    | `KeyboardInterrupt` |
//! | `Internal`         | a bug in the core (an invariant broke)                         | `RuntimeError`    |

use thiserror::Error;

#[derive(Debug, Clone, PartialEq, Error)]
pub enum RokebyError {
    /// An argument has the wrong size or a value outside its domain. `arg` names the argument the
    /// way the Python API spells it, so that the message tells a user which input to fix.
    #[error("{arg}: {msg}")]
    InvalidArgument { arg: String, msg: String },
    /// Memory for `what` (`bytes` of it) could not be had: over the limit of
    /// [`crate::alloc::max_bytes`], or the allocator refused it. Nothing was allocated.
    #[error("{what}: {msg}")]
    OutOfMemory { what: String, msg: String },
    /// A numerical method failed on input that passed validation (a factorisation broke down,
    /// an iteration did not converge). `what` names the computation.
    #[error("{what}: {msg}")]
    Numerical { what: String, msg: String },
    /// The call was cancelled ([`crate::cancel::request`], Ctrl-C in the binding).
    #[error("cancelled")]
    Cancelled,
    /// An invariant of the core broke: a bug, to be reported.
    #[error("internal error (please report): {0}")]
    Internal(String),
}

impl RokebyError {
    pub fn invalid(arg: impl Into<String>, msg: impl Into<String>) -> Self {
        RokebyError::InvalidArgument {
            arg: arg.into(),
            msg: msg.into(),
        }
    }
    pub fn numerical(what: impl Into<String>, msg: impl Into<String>) -> Self {
        RokebyError::Numerical {
            what: what.into(),
            msg: msg.into(),
        }
    }
    /// Out of memory for `what` that needs `bytes` (over `limit`, when known).
    pub fn out_of_memory(
        what: impl Into<String>,
        bytes: Option<u128>,
        limit: Option<u128>,
    ) -> Self {
        let need = match bytes {
            Some(b) => format!("needs {} of memory", human_bytes(b)),
            None => "ran out of memory".into(),
        };
        let msg = match limit {
            Some(l) => format!("{need}, more than the limit of {} (ROKEBY_MAX_ALLOC_BYTES, or the machine's memory)", human_bytes(l)),
            None => format!("{need}: the allocator refused it"),
        };
        RokebyError::OutOfMemory {
            what: what.into(),
            msg,
        }
    }
    pub fn internal(msg: impl Into<String>) -> Self {
        RokebyError::Internal(msg.into())
    }
}

/// "1.5 GiB" for messages.
pub fn human_bytes(b: u128) -> String {
    const UNITS: [&str; 6] = ["bytes", "KiB", "MiB", "GiB", "TiB", "PiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u < UNITS.len() - 1 {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} bytes")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

pub type Result<T> = std::result::Result<T, RokebyError>;
