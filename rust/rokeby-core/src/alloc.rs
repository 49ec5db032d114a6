//! Fallible allocation: every buffer whose size a caller or a file controls is allocated here,
//! after its byte count is computed without overflow and checked against a limit, with
//! `try_reserve_exact`, so that a huge request becomes [`RokebyError::OutOfMemory`] (Python's
//! `MemoryError`) instead of aborting the process or paging the machine to a halt.
//!
//! The limit is the machine's physical memory (Linux `/proc/meminfo`), or the environment
//! variable `ROKEBY_MAX_ALLOC_BYTES` when set (tests use it to run under an address-space
//! limit). On other systems without the variable only the allocator's own refusal applies.

use crate::error::{Result, RokebyError};
use std::sync::OnceLock;

fn physical_memory() -> Option<u128> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The largest single allocation the core makes, in bytes (`None`: no limit of its own).
pub fn max_bytes() -> Option<u128> {
    static LIMIT: OnceLock<Option<u128>> = OnceLock::new();
    *LIMIT.get_or_init(|| {
        if let Ok(text) = std::env::var("ROKEBY_MAX_ALLOC_BYTES") {
            // "1000000000", "1e9" or "1.5e9": a number of bytes; anything else is ignored with a
            // warning on stderr (the process has no caller to raise to here).
            match text.trim().parse::<f64>() {
                Ok(v) if v.is_finite() && v >= 1.0 => return Some(v as u128),
                _ => eprintln!("rokeby_native: ROKEBY_MAX_ALLOC_BYTES={text:?} is not a number of bytes; using the machine's memory"),
            }
        }
        physical_memory()
    })
}

/// The byte count of `dims` elements of `T`, checked for overflow and against [`max_bytes`].
pub fn check<T>(what: &str, dims: &[usize]) -> Result<usize> {
    let mut n: u128 = 1;
    for &d in dims {
        n = n.saturating_mul(d as u128);
    }
    let bytes = n.saturating_mul(std::mem::size_of::<T>().max(1) as u128);
    let over_limit = max_bytes().is_some_and(|l| bytes > l);
    if over_limit || bytes > isize::MAX as u128 {
        return Err(RokebyError::out_of_memory(
            what,
            Some(bytes),
            Some(max_bytes().unwrap_or(isize::MAX as u128)),
        ));
    }
    Ok(n as usize)
}

/// A vector of `product(dims)` copies of `value`, or OutOfMemory naming `what`.
pub fn filled<T: Clone>(what: &str, dims: &[usize], value: T) -> Result<Vec<T>> {
    let n = check::<T>(what, dims)?;
    let mut v = with_capacity::<T>(what, dims)?;
    v.resize(n, value);
    Ok(v)
}

/// An empty vector with room for exactly `product(dims)` elements, or OutOfMemory naming `what`.
pub fn with_capacity<T>(what: &str, dims: &[usize]) -> Result<Vec<T>> {
    let n = check::<T>(what, dims)?;
    let mut v: Vec<T> = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        RokebyError::out_of_memory(
            what,
            Some((n as u128) * std::mem::size_of::<T>() as u128),
            None,
        )
    })?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overflowing_and_huge_requests_are_errors_not_aborts() {
        let e = filled::<f32>("out", &[usize::MAX, 4], 0.0).unwrap_err();
        assert!(matches!(e, RokebyError::OutOfMemory { .. }), "{e:?}");
        assert!(e.to_string().starts_with("out: needs"), "{e}");
        let e = filled::<f64>("levels", &[1 << 40, 1 << 20], 0.0).unwrap_err();
        assert!(matches!(e, RokebyError::OutOfMemory { .. }));
        assert_eq!(filled::<u8>("small", &[3, 2], 7).unwrap(), vec![7; 6]);
        assert!(with_capacity::<f32>("empty", &[0]).unwrap().is_empty());
    }
}
