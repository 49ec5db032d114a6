//! Errors across the boundary: core errors mapped by kind (bad input → `ValueError`, memory →
//! `MemoryError`, numerical failure → [`NumericalError`], a `RuntimeError` subclass, cancelled →
//! `KeyboardInterrupt`, internal bug → `RuntimeError`), and the work run without the GIL with
//! panics caught so that none crosses into Python.

use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use rokeby_core::RokebyError;
use std::panic::{catch_unwind, AssertUnwindSafe};

pyo3::create_exception!(
    rokeby_native,
    NumericalError,
    PyRuntimeError,
    "A numerical method of the core failed on input that passed validation (a factorisation broke down, an iteration did not converge)."
);

pub(crate) fn core_err(e: RokebyError) -> PyErr {
    let text = e.to_string();
    match e {
        RokebyError::InvalidArgument { .. } => PyValueError::new_err(text),
        RokebyError::OutOfMemory { .. } => PyMemoryError::new_err(text),
        RokebyError::Numerical { .. } => NumericalError::new_err(text),
        RokebyError::Cancelled => PyKeyboardInterrupt::new_err("rokeby_native: cancelled"),
        RokebyError::Internal(_) => PyRuntimeError::new_err(format!("rokeby_native {text}")),
    }
}

pub(crate) fn panic_err(p: Box<dyn std::any::Any + Send>) -> PyErr {
    let msg = p
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown".into());
    PyRuntimeError::new_err(format!(
        "rokeby_native internal error (please report): {msg}"
    ))
}

/// Runs `f` without the GIL; a panic (a bug) becomes RuntimeError instead of crossing into Python.
pub(crate) fn run_detached<T: Send, F: FnOnce() -> Result<T, RokebyError> + Send>(
    py: Python<'_>,
    f: F,
) -> PyResult<T> {
    let res = py.detach(|| catch_unwind(AssertUnwindSafe(f)));
    match res {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(core_err(e)),
        Err(p) => Err(panic_err(p)),
    }
}

/// Like [`run_detached`] for long work that checks [`rokeby_core::cancel`] between rows: the work
/// runs on a worker thread while this thread, every 50 ms, takes the GIL back to let Python run
/// its signal handlers; Ctrl-C (KeyboardInterrupt) or `rokeby_native.cancel()` from another
/// thread stops the work at its next row and the call raises.
pub(crate) fn run_cancellable<T: Send, F: FnOnce() -> Result<T, RokebyError> + Send>(
    py: Python<'_>,
    f: F,
) -> PyResult<T> {
    use std::sync::mpsc;
    use std::time::Duration;
    rokeby_core::cancel::reset();
    std::thread::scope(|scope| {
        let (tx, rx) = mpsc::channel();
        scope.spawn(move || {
            let _ = tx.send(catch_unwind(AssertUnwindSafe(f)));
        });
        let mut interrupted: Option<PyErr> = None;
        let mut rx = rx;
        loop {
            let (got, back) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
            rx = back;
            match got {
                Ok(res) => {
                    if let Some(err) = interrupted {
                        return Err(err);
                    }
                    return match res {
                        Ok(Ok(v)) => Ok(v),
                        Ok(Err(e)) => Err(core_err(e)),
                        Err(p) => Err(panic_err(p)),
                    };
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if interrupted.is_none() {
                        if let Err(e) = py.check_signals() {
                            rokeby_core::cancel::request();
                            interrupted = Some(e);
                        }
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err("rokeby_native internal error (please report): the worker thread ended without a result"));
                }
            }
        }
    })
}
