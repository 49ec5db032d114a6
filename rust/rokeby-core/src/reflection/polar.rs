//! Ortho-normalisation: the rotational factor R of the polar decomposition M = R S
//! (Ritschel et al. 2009, eq. 5, "ortho(...)"), defined for every 3×3 input.
//!
//! R is the rotation (det R = +1) that maximises tr(Rᵀ M), i.e. the closest rotation to M — the
//! solution of the weighted least-squares problem of eq. 2. Degenerate inputs get a documented,
//! deterministic answer instead of NaN:
//! * rank 3 and rank 2: unique; det M < 0 is handled by flipping the smallest singular direction;
//! * rank 1 (one constraint, or all constraints along one rₙ/eₙ pair): every rotation that maps
//!   v₁ to u₁ is optimal; we return the one with the smallest angle, or — with a tie-break matrix
//!   B — the one among them that best fits B (see [`ortho_tiebreak`]);
//! * u₁ = −v₁ (a half turn, e ≈ −r): the rotation by π about a fixed axis perpendicular to v₁;
//! * rank 0 (M ≈ 0): the identity.
//!
//! Two methods are offered because users trade speed for accuracy ([`PolarMethod`]):
//! [`ortho_svd`] is a one-sided Jacobi SVD in f64 (exact to rounding); [`ortho_iterative`] is
//! Newton's method on SO(3) (with the step of Müller, Bender, Chentanez and Macklin 2016 where the
//! Hessian is indefinite), warm-started from a neighbouring pixel, whose result is accepted only
//! after a second-order optimality test and otherwise recomputed with the SVD, so it never returns
//! a non-optimal rotation.

use crate::error::{Result, RokebyError};
use glam::{DMat3, DQuat, DVec3};

/// Which algorithm computes `ortho`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PolarMethod {
    /// One-sided Jacobi SVD in f64, with explicit rank handling. Reference accuracy.
    Svd,
    /// Newton's method on SO(3), warm-started from the previous pixel, verified optimal, with the
    /// SVD as fallback. Faster on coherent inputs (neighbouring pixels); same optimum.
    Iterative,
}

impl PolarMethod {
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "svd" | "exact" => Some(PolarMethod::Svd),
            "iterative" | "fast" => Some(PolarMethod::Iterative),
            _ => None,
        }
    }
}

/// Relative size under which a singular value counts as zero.
const RANK_TOL: f64 = 1e-10;

/// The smallest rotation taking unit vector `from` to unit vector `to`.
/// Antiparallel vectors (within 1e-7 rad of a half turn) give a half turn about a deterministic
/// axis perpendicular to `from`; the error that introduces is below 1e-7 rad.
pub fn min_rotation(from: DVec3, to: DVec3) -> DQuat {
    let c = from.dot(to);
    let v = from.cross(to);
    let s = v.length();
    if s < 1e-7 {
        if c > 0.0 {
            return DQuat::IDENTITY;
        }
        let axis = from.any_orthonormal_vector();
        return DQuat::from_xyzw(axis.x, axis.y, axis.z, 0.0);
    }
    // (v, 1 + c) normalised is the half-angle quaternion; stable for all angles away from π,
    // and near π the branch above takes over.
    let angle = s.atan2(c);
    DQuat::from_axis_angle(v / s, angle)
}

/// One-sided (Hestenes) Jacobi SVD of a 3×3 matrix in f64: returns (A V, V) where the columns of
/// A V are U Σ (mutually orthogonal) and V is orthogonal. Converges quadratically; at most 30 sweeps.
fn jacobi_one_sided(m: &DMat3) -> ([DVec3; 3], [DVec3; 3]) {
    let mut a = [m.x_axis, m.y_axis, m.z_axis];
    let mut v = [DVec3::X, DVec3::Y, DVec3::Z];
    for _sweep in 0..30 {
        let mut rotated = false;
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let alpha = a[p].length_squared();
            let beta = a[q].length_squared();
            let gamma = a[p].dot(a[q]);
            if gamma == 0.0 || gamma.abs() <= 1e-15 * (alpha * beta).sqrt() {
                continue;
            }
            rotated = true;
            let zeta = (beta - alpha) / (2.0 * gamma);
            let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
            let c = 1.0 / (1.0 + t * t).sqrt();
            let s = c * t;
            let (ap, aq) = (a[p], a[q]);
            a[p] = c * ap - s * aq;
            a[q] = s * ap + c * aq;
            let (vp, vq) = (v[p], v[q]);
            v[p] = c * vp - s * vq;
            v[q] = s * vp + c * vq;
        }
        if !rotated {
            break;
        }
    }
    (a, v)
}

/// Singular value decomposition M = U diag(σ) Vᵀ with σ sorted descending. U's columns for zero
/// singular values are not meaningful; the callers below never use them.
pub struct Svd3 {
    pub u: [DVec3; 3],
    pub sigma: [f64; 3],
    pub v: [DVec3; 3],
}

pub fn svd3(m: &DMat3) -> Svd3 {
    let (a, v) = jacobi_one_sided(m);
    let mut sigma = [a[0].length(), a[1].length(), a[2].length()];
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| {
        sigma[j]
            .partial_cmp(&sigma[i])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let u_raw = [a[idx[0]], a[idx[1]], a[idx[2]]];
    let v_sorted = [v[idx[0]], v[idx[1]], v[idx[2]]];
    let s_sorted = [sigma[idx[0]], sigma[idx[1]], sigma[idx[2]]];
    sigma = s_sorted;
    let u = [
        if sigma[0] > 0.0 {
            u_raw[0] / sigma[0]
        } else {
            DVec3::ZERO
        },
        if sigma[1] > 0.0 {
            u_raw[1] / sigma[1]
        } else {
            DVec3::ZERO
        },
        if sigma[2] > 0.0 {
            u_raw[2] / sigma[2]
        } else {
            DVec3::ZERO
        },
    ];
    Svd3 {
        u,
        sigma,
        v: v_sorted,
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    // a bᵀ, column j = a * b[j]
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Rotation about unit `axis` by angle θ chosen to maximise tr(Rᵀ C) (closed form).
/// tr(T_θᵀ C) = uᵀCu + cos θ (tr C − uᵀCu) + sin θ · s, with s the axial part of C along u.
fn best_twist(axis: DVec3, c: &DMat3) -> DQuat {
    let u = axis;
    let cu = *c * u;
    let utcu = u.dot(cu);
    let tr = c.x_axis.x + c.y_axis.y + c.z_axis.z;
    // C_ij = c.col(j)[i]
    let s = u.x * (c.y_axis.z - c.z_axis.y)
        + u.y * (c.z_axis.x - c.x_axis.z)
        + u.z * (c.x_axis.y - c.y_axis.x);
    let a = tr - utcu;
    // No preference when B's part that could twist about u is rounding noise relative to B
    // (e.g. every other constraint asks for the same r → e: B ∝ u uᵀ after R₀); an absolute
    // threshold let that noise pick an arbitrary twist.
    let scale = c.to_cols_array().iter().fold(0.0f64, |m, x| m.max(x.abs()));
    // `scale` is never NaN (f64::max skips NaN); a NaN part gives no preference either.
    let part = a.abs() + s.abs();
    if part.is_nan() || part <= 1e-10 * scale {
        return DQuat::IDENTITY;
    }
    DQuat::from_axis_angle(u, s.atan2(a))
}

/// `ortho(M)`, exact, by SVD: the rotation maximising tr(Rᵀ M). See the module docs for the
/// degenerate cases.
pub fn ortho_svd(m: &DMat3) -> DQuat {
    ortho_tiebreak(m, None)
}

/// `ortho(M)` where a rank-1 M is completed by the tie-break matrix `b`: among the rotations with
/// R v₁ = u₁ (all optimal for M) the one maximising tr(Rᵀ B). This is the limit of ortho(M + εB)
/// as ε → 0, which makes the MLS field continuous at a constraint point (B holds the other
/// constraints). Without `b` (or when B gives no preference) it is the smallest such rotation.
pub fn ortho_tiebreak(m: &DMat3, b: Option<&DMat3>) -> DQuat {
    let svd = svd3(m);
    let [s1, s2, _s3] = svd.sigma;
    if !(s1 > 1e-300 && s1.is_finite()) {
        return match b {
            Some(b) => ortho_tiebreak(b, None),
            None => DQuat::IDENTITY,
        };
    }
    let u1 = svd.u[0];
    let v1 = svd.v[0].normalize();
    if s2 > RANK_TOL * s1 {
        // Rank ≥ 2: R = u₁v₁ᵀ + u₂v₂ᵀ + (u₁×u₂)(v₁×v₂)ᵀ, which equals U diag(1,1,det U det V) Vᵀ.
        let u2 = (svd.u[1] - svd.u[1].dot(u1) * u1).normalize();
        let v2 = (svd.v[1] - svd.v[1].dot(v1) * v1).normalize();
        let r = outer(u1, v1) + outer(u2, v2) + outer(u1.cross(u2), v1.cross(v2));
        return quat_from_rotation(&r);
    }
    let r0 = min_rotation(v1, u1.normalize());
    match b {
        Some(b) => {
            let c = *b * DMat3::from_quat(r0).transpose();
            (best_twist(u1.normalize(), &c) * r0).normalize()
        }
        None => r0,
    }
}

/// Quaternion of a rotation matrix, re-orthonormalised through glam's branch-on-trace method,
/// normalised, with w ≥ 0.
pub fn quat_from_rotation(r: &DMat3) -> DQuat {
    canonical(DQuat::from_mat3(r).normalize())
}

/// The representative with w ≥ 0 (q and −q are the same rotation).
pub fn canonical(q: DQuat) -> DQuat {
    if q.w < 0.0 {
        -q
    } else {
        q
    }
}

/// S = Rᵀ M split into what Newton's method on SO(3) needs. For R' = R exp([ω]):
/// tr(R'ᵀ M) ≈ tr(S) + ω·g − ½ ωᵀ H ω with g = vee(S − Sᵀ) and H = tr(S)·I − sym(S).
struct NewtonTerms {
    g: DVec3,
    h: DMat3,
    tr: f64,
    /// ‖S‖²_F, for the rank test.
    fro2: f64,
}

#[inline]
fn newton_terms(q: DQuat, m: &DMat3) -> NewtonTerms {
    let s = DMat3::from_quat(q).transpose() * *m;
    // S_ij = s.col(j)[i]
    let g = DVec3::new(
        s.y_axis.z - s.z_axis.y,
        s.z_axis.x - s.x_axis.z,
        s.x_axis.y - s.y_axis.x,
    );
    let tr = s.x_axis.x + s.y_axis.y + s.z_axis.z;
    let h = DMat3::from_diagonal(DVec3::splat(tr)) - (s + s.transpose()) * 0.5;
    let fro2 = s.x_axis.length_squared() + s.y_axis.length_squared() + s.z_axis.length_squared();
    NewtonTerms { g, h, tr, fro2 }
}

/// Leading principal minors of a symmetric 3×3 matrix, all > tol (positive definite).
#[inline]
fn positive_definite(h: &DMat3, tol: f64) -> bool {
    let m1 = h.x_axis.x;
    let m2 = m1 * h.y_axis.y - h.y_axis.x * h.x_axis.y;
    m1 > tol && m2 > tol * tol && h.determinant() > tol * tol * tol
}

/// What the iterative method concluded.
pub enum Iterated {
    /// A verified maximum of tr(Rᵀ M).
    Optimal(DQuat),
    /// Converged, but M is numerically rank 1 there: the twist about the edited ray is free and
    /// must be chosen by rule (the SVD path with its tie-break).
    RankOne,
    /// No verified maximum within the step budget.
    Failed,
}

/// Iterative `ortho`: Newton's method on SO(3) for max tr(Rᵀ M) from `init` (a neighbouring
/// pixel's rotation), quadratically convergent. Steps use the quaternion (ω/2, 1)/‖·‖, a rotation
/// that agrees with exp(ω) to second order (so convergence stays quadratic) and needs no sin/cos.
/// Where H is not positive definite (far from the maximum) it takes the step of Müller, Bender,
/// Chentanez and Macklin (2016), ω = g / |tr S|, at most a quarter turn. A result is accepted only
/// when the last step was a Newton step with H positive definite — a strict local maximum, which
/// for tr(Rᵀ M) on SO(3) is the global one — so the caller's SVD fallback handles the rest.
pub fn ortho_iterative(m: &DMat3, init: DQuat, max_iter: usize) -> Iterated {
    let scale =
        (m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()).sqrt();
    if !(scale > 1e-300 && scale.is_finite()) {
        return Iterated::Failed;
    }
    let mut q = init;
    for _ in 0..max_iter {
        let t = newton_terms(q, m);
        // Rank test at (near) the solution: S has eigenvalues (σ₁, σ₂, ±σ₃), so
        // tr(S)² − ‖S‖²_F = 2(σ₁σ₂ ± …) vanishes relative to σ₁² exactly when σ₂ ≈ 0.
        let newton = positive_definite(&t.h, 1e-6 * scale);
        let omega = if newton {
            t.h.inverse() * t.g
        } else {
            t.g / (t.tr.abs() + 1e-12 * scale)
        };
        let w2 = omega.length_squared();
        // Quadratic convergence: a Newton step below 1e-4 rad leaves an error of order 1e-8 rad
        // after it is taken, under the float32 resolution of the output (6e-8).
        if newton && w2 < 1e-8 {
            if t.tr * t.tr - t.fro2 < 1e-6 * t.fro2 {
                return Iterated::RankOne;
            }
            let half = omega * 0.5;
            return Iterated::Optimal(canonical(
                (q * DQuat::from_xyzw(half.x, half.y, half.z, 1.0)).normalize(),
            ));
        }
        if !newton && w2 < 1e-24 {
            // Stationary but not a strict maximum: a saddle, or a rank-deficient optimum.
            return Iterated::RankOne;
        }
        let max_step = std::f64::consts::FRAC_PI_2;
        let omega = if w2 > max_step * max_step {
            omega * (max_step / w2.sqrt())
        } else {
            omega
        };
        let half = omega * 0.5;
        q = (q * DQuat::from_xyzw(half.x, half.y, half.z, 1.0)).normalize();
    }
    Iterated::Failed
}

/// M scaled so its largest entry is 1. The polar factor of s·M is that of M for any s > 0, and
/// at unit size the SVD's and Newton's products stay far from overflow and underflow for entries
/// anywhere in f64's range (entries of 1e122 would overflow unscaled; the `polar` fuzz target
/// covers it).
fn unit_scale(m: &DMat3) -> DMat3 {
    let s = m.to_cols_array().iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if s.is_finite() && s > 0.0 {
        DMat3::from_cols(m.x_axis / s, m.y_axis / s, m.z_axis / s)
    } else {
        *m
    }
}

/// `ortho` with the chosen method; `warm` is the previous result (a neighbouring pixel) and is
/// updated. The iterative method falls back to the SVD when its result is not verified optimal
/// or when M is rank-deficient (where the answer is chosen by rule, not by optimisation).
/// `tiebreak` is only formed when the rank-1 rule needs it.
pub fn ortho(
    m: &DMat3,
    tiebreak: impl FnOnce() -> Option<DMat3>,
    method: PolarMethod,
    warm: &mut DQuat,
) -> DQuat {
    let m = &unit_scale(m);
    let tiebreak = || tiebreak().map(|b| unit_scale(&b));
    let q = match method {
        PolarMethod::Svd => ortho_tiebreak(m, tiebreak().as_ref()),
        PolarMethod::Iterative => match ortho_iterative(m, *warm, 10) {
            Iterated::Optimal(q) => q,
            Iterated::RankOne | Iterated::Failed => ortho_tiebreak(m, tiebreak().as_ref()),
        },
    };
    *warm = q;
    q
}

/// `ortho` of a batch of row-major 3×3 matrices (`matrices`: 9 values each, numpy's (i, j) order),
/// warm-started from one matrix to the next: canonical unit quaternions (x, y, z, w), w ≥ 0,
/// 4 values per matrix. A matrix with a non-finite entry is refused by its index.
pub fn ortho_batch(matrices: &[f32], method: PolarMethod) -> Result<Vec<f32>> {
    if !matrices.len().is_multiple_of(9) {
        return Err(RokebyError::invalid(
            "matrices",
            format!("expected 9 values per matrix, got {}", matrices.len()),
        ));
    }
    if let Some(i) = matrices.iter().position(|x| !x.is_finite()) {
        return Err(RokebyError::invalid(
            "matrices",
            format!("matrix {} has a non-finite entry", i / 9),
        ));
    }
    let mut warm = DQuat::IDENTITY;
    let mut out = crate::alloc::with_capacity::<f32>("ortho output", &[matrices.len() / 9, 4])?;
    for c in matrices.chunks_exact(9) {
        // Row-major (i, j) → column-major glam.
        let m = DMat3::from_cols_array(&[
            c[0] as f64,
            c[3] as f64,
            c[6] as f64,
            c[1] as f64,
            c[4] as f64,
            c[7] as f64,
            c[2] as f64,
            c[5] as f64,
            c[8] as f64,
        ]);
        let q = canonical(ortho(&m, || None, method, &mut warm));
        out.extend_from_slice(&[q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ortho_batch_reads_row_major_and_refuses_non_finite() {
        // A rotation by 90° about z, row-major: [[0, -1, 0], [1, 0, 0], [0, 0, 1]].
        let m = [0.0f32, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let q = ortho_batch(&m, PolarMethod::Svd).unwrap();
        let s = std::f32::consts::FRAC_1_SQRT_2;
        assert!((q[2] - s).abs() < 1e-6 && (q[3] - s).abs() < 1e-6, "{q:?}");
        let mut bad = m;
        bad[4] = f32::NAN;
        let e = ortho_batch(&[m, bad].concat(), PolarMethod::Iterative).unwrap_err();
        assert!(e.to_string().starts_with("matrices: matrix 1"), "{e}");
        assert!(matches!(e, RokebyError::InvalidArgument { .. }));
    }

    fn is_rotation(q: DQuat) -> bool {
        let r = DMat3::from_quat(q);
        let i = r.transpose() * r;
        (i - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|x| x.abs() < 1e-10)
            && (r.determinant() - 1.0).abs() < 1e-10
    }

    #[test]
    fn rank1_gives_min_rotation() {
        let r = DVec3::new(0.0, 0.0, 1.0);
        let e = DVec3::new(1.0, 0.0, 1.0).normalize();
        let m = outer(e, r) * 3.0;
        let q = ortho_svd(&m);
        assert!(is_rotation(q));
        assert!((q * r - e).length() < 1e-12);
        let expect = min_rotation(r, e);
        assert!(q.dot(expect).abs() > 1.0 - 1e-12);
    }

    #[test]
    fn huge_and_tiny_matrices_give_the_same_rotation() {
        let r = DVec3::new(0.3, -0.2, 0.9).normalize();
        let e = DVec3::new(0.5, 0.1, 0.8).normalize();
        let m = outer(e, r) + outer(DVec3::X, DVec3::Y) * 0.3;
        for method in [PolarMethod::Svd, PolarMethod::Iterative] {
            let mut w = DQuat::IDENTITY;
            let q = ortho(&m, || None, method, &mut w);
            for s in [1e-300, 1e-160, 1e122, 1e300] {
                let mut w = DQuat::IDENTITY;
                let qs = ortho(&(m * s), || None, method, &mut w);
                assert!(
                    is_rotation(qs) && qs.dot(q).abs() > 1.0 - 1e-12,
                    "{s}: {qs:?} vs {q:?}"
                );
            }
        }
    }

    #[test]
    fn half_turn_is_deterministic_and_exact() {
        let r = DVec3::new(0.3, -0.2, 0.9).normalize();
        let m = outer(-r, r);
        let q1 = ortho_svd(&m);
        let q2 = ortho_svd(&m);
        assert_eq!(q1, q2);
        assert!((q1 * r + r).length() < 1e-9);
        assert!(is_rotation(q1));
    }

    #[test]
    fn reflection_input_gives_proper_rotation() {
        let m = DMat3::from_diagonal(DVec3::new(3.0, 2.0, -1.0));
        let q = ortho_svd(&m);
        assert!(is_rotation(q));
        assert!(q.dot(DQuat::IDENTITY).abs() > 1.0 - 1e-12);
    }

    #[test]
    fn zero_matrix_is_identity() {
        assert_eq!(ortho_svd(&DMat3::ZERO), DQuat::IDENTITY);
    }

    #[test]
    fn iterative_matches_svd_on_rotations() {
        let r = DQuat::from_euler(glam::EulerRot::XYZ, 0.4, -1.1, 2.0);
        let s = DMat3::from_diagonal(DVec3::new(2.0, 1.0, 0.5));
        let m = DMat3::from_quat(r) * s;
        let a = ortho_svd(&m);
        let mut warm = DQuat::IDENTITY;
        let b = ortho(&m, || None, PolarMethod::Iterative, &mut warm);
        assert!(a.dot(b).abs() > 1.0 - 1e-12, "{a:?} vs {b:?}");
    }

    #[test]
    fn tiebreak_twists_about_the_edited_ray() {
        // Rank-1 M pins x → x; the tie-break matrix is a rotation by 0.7 about x.
        let m = outer(DVec3::X, DVec3::X);
        let b = DMat3::from_quat(DQuat::from_rotation_x(0.7));
        let q = ortho_tiebreak(&m, Some(&b));
        assert!(q.dot(DQuat::from_rotation_x(0.7)).abs() > 1.0 - 1e-12);
    }
}

/// The rotation vector (axis × angle, angle in [0, π]) of a unit quaternion: the compact form in
/// which the add-on stores the field as a mesh attribute. Accurate for small angles
/// (2·atan2(|u|, w) rather than acos), exact at the identity.
pub fn rotation_vector(q: DQuat) -> DVec3 {
    let q = canonical(q);
    let u = DVec3::new(q.x, q.y, q.z);
    let s = u.length();
    if s < 1e-12 {
        // sin(θ/2) ≈ θ/2: u · 2/w
        return u * (2.0 / q.w.max(1e-300));
    }
    u * (2.0 * s.atan2(q.w) / s)
}

#[cfg(test)]
mod rotation_vector_tests {
    use super::*;

    #[test]
    fn rotation_vector_round_trips_small_large_and_half_turns() {
        for &(axis, angle) in &[
            (DVec3::Z, 0.0),
            (DVec3::new(1.0, 2.0, -0.5).normalize(), 1e-9),
            (DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7),
            (DVec3::X, 3.0),
            (DVec3::new(0.0, 1.0, 1.0).normalize(), std::f64::consts::PI),
        ] {
            let v = rotation_vector(DQuat::from_axis_angle(axis, angle));
            assert!(
                (v.length() - angle).abs() < 1e-12,
                "angle {angle}: |v| = {}",
                v.length()
            );
            if angle > 0.0 {
                assert!(
                    (v.normalize() - axis).length() < 1e-9
                        || (angle - std::f64::consts::PI).abs() < 1e-12
                );
            }
            let back = if v.length() > 0.0 {
                DQuat::from_axis_angle(v.normalize(), v.length())
            } else {
                DQuat::IDENTITY
            };
            assert!(back.dot(DQuat::from_axis_angle(axis, angle)).abs() > 1.0 - 1e-12);
        }
        // The double cover: q and -q give the same rotation vector.
        let q = DQuat::from_axis_angle(DVec3::Y, 0.4);
        assert!((rotation_vector(q) - rotation_vector(-q)).length() < 1e-15);
    }
}
