//! Cancelling long native work. Loops over rows (blurs, bilateral filters, prefiltering,
//! reconstruction) call [`check`] between rows; [`request`] (Python: `rokeby_native.cancel()`,
//! or Ctrl-C while the binding waits for a cancellable call) makes them return
//! [`RokebyError::Cancelled`] soon after. The flag is process-wide: a request stops every
//! cancellable call in flight, and each new cancellable call starts by clearing it ([`reset`]).

use crate::error::{Result, RokebyError};
use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Ask the cancellable calls in flight to stop.
pub fn request() {
    REQUESTED.store(true, Ordering::Relaxed);
}

/// Clear a request (at the start of a cancellable call).
pub fn reset() {
    REQUESTED.store(false, Ordering::Relaxed);
}

pub fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed)
}

/// `Err(Cancelled)` once a request was made.
#[inline]
pub fn check() -> Result<()> {
    if requested() {
        Err(RokebyError::Cancelled)
    } else {
        Ok(())
    }
}
