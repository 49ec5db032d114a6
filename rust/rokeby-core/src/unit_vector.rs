//! Unit vectors, one home: every "normalise, or say that there is no direction" of the core.
//!
//! A vector has a direction when its length ‖v‖ = √(x² + y² + z²) is finite and greater than a
//! small limit ([`MIN_LENGTH`], or the caller's own); its unit vector is v / ‖v‖, each component
//! divided by the length. Division, not glam's `normalize` (v · (1/‖v‖), one more rounding): the
//! lanes of the SH fit ([`crate::compositing::sh`]) and the Python twins (numpy's `v / norm`)
//! reproduce these roundings bit for bit. glam's `normalize_or_zero` stays where a zero vector is
//! the wanted answer and no twin must agree bit for bit (mesh normals, light directions).

use glam::{DVec3, Vec3};

/// Vectors this short (or shorter) have no direction: 1e-12, far below any length a scene or an
/// image gives a normal or a view vector, far above where the squares of f32 components underflow.
pub const MIN_LENGTH: f64 = 1e-12;

/// v / ‖v‖ when ‖v‖ is finite and greater than `min_length`, else `None` (zero, tiny, NaN or
/// infinite components).
#[inline]
pub fn unit_longer_than(v: DVec3, min_length: f64) -> Option<DVec3> {
    let len = v.length();
    if len.is_finite() && len > min_length {
        Some(v / len)
    } else {
        None
    }
}

/// v / ‖v‖ when ‖v‖ is finite and greater than [`MIN_LENGTH`], else `None`.
#[inline]
pub fn unit(v: DVec3) -> Option<DVec3> {
    unit_longer_than(v, MIN_LENGTH)
}

/// The unit vector of one row (x, y, z) of an f32 array, computed in f64 ([`unit`]).
#[inline]
pub fn unit_row(c: &[f32]) -> Option<DVec3> {
    unit(DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64))
}

/// [`unit`] in f32 arithmetic (length, limit test and division in f32), for results that must
/// equal an f32 twin's bit for bit (the Python normal tools' float32 `v / norm`).
#[inline]
pub fn unit_f32(v: Vec3) -> Option<Vec3> {
    let len = v.length();
    if len.is_finite() && len > MIN_LENGTH as f32 {
        Some(v / len)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_divides_by_the_length() {
        let v = DVec3::new(3.0, -4.0, 12.0);
        assert_eq!(
            unit(v),
            Some(DVec3::new(3.0 / 13.0, -4.0 / 13.0, 12.0 / 13.0))
        );
        let f = Vec3::new(0.1, 0.7, -0.3);
        let l = (0.1f32 * 0.1 + 0.7 * 0.7 + 0.3 * 0.3).sqrt();
        assert_eq!(unit_f32(f), Some(Vec3::new(0.1 / l, 0.7 / l, -0.3 / l)));
    }

    #[test]
    fn no_direction_for_short_or_non_finite_vectors() {
        for v in [
            DVec3::ZERO,
            DVec3::new(1e-13, 0.0, 0.0),
            DVec3::new(f64::NAN, 1.0, 0.0),
            DVec3::new(f64::INFINITY, 0.0, 0.0),
            DVec3::new(1e300, 1e300, 0.0), // the length overflows
        ] {
            assert_eq!(unit(v), None, "{v:?}");
        }
        assert!(unit(DVec3::new(2e-12, 0.0, 0.0)).is_some());
        assert_eq!(
            unit_longer_than(DVec3::new(1e-15, 0.0, 0.0), 1e-20),
            Some(DVec3::X)
        );
        assert_eq!(unit_row(&[0.0, 0.0, 0.0]), None);
        assert_eq!(unit_row(&[0.0, 2.0, 0.0]), Some(DVec3::Y));
        assert_eq!(unit_f32(Vec3::new(1e-13, 0.0, 0.0)), None);
        assert_eq!(unit_f32(Vec3::new(f32::NAN, 0.0, 0.0)), None);
    }
}
