//! 2D moving-least-squares curve deformation (Schaefer, McPhail, Warren 2006, "Image deformation
//! using moving least squares"), used by Mattausch et al. §5.2 to deform a shadow-boundary segment
//! in the light's frustum, and the sinusoidal boundary noise of §5.3.
//!
//! For a point v with control points p_i → q_i and weights w_i = 1/|p_i − v|^{2a} (Schaefer's α,
//! here `alpha`), with p* = Σ w_i p_i / Σ w_i, q* likewise, p̂_i = p_i − p*, q̂_i = q_i − q*:
//!
//! * affine (Schaefer eq. 5): f(v) = (v − p*) (Σ w_i p̂_iᵀ p̂_i)⁻¹ Σ w_j p̂_jᵀ q̂_j + q*;
//! * similarity (§2.2): the best rotation-and-scale, written with complex numbers:
//!   f(v) = q* + c (v − p*), c = Σ w_i conj(p̂_i) q̂_i / Σ w_i |p̂_i|²;
//! * rigid (§2.3): f(v) = q* + (c/|c|)(v − p*) — in 2D the optimal rotation of Schaefer's rigid
//!   deformation is the normalised similarity coefficient.
//!
//! At a control point itself (w infinite) f(p_i) = q_i. When the affine moment matrix is singular
//! (fewer than three non-collinear control points near v) the similarity map is used instead.

use crate::error::{Result, RokebyError};
use glam::{DMat2, DVec2};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MlsStyle {
    Affine,
    Similarity,
    Rigid,
}

impl MlsStyle {
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "affine" => Some(MlsStyle::Affine),
            "similarity" | "similar" => Some(MlsStyle::Similarity),
            "rigid" => Some(MlsStyle::Rigid),
            _ => None,
        }
    }
}

/// Validated control points p_i → q_i.
#[derive(Debug, Clone)]
pub struct Mls2d {
    p: Vec<DVec2>,
    q: Vec<DVec2>,
    style: MlsStyle,
    alpha: f64,
}

impl Mls2d {
    /// `alpha` is Schaefer's α (weights 1/d^{2α}); 1 is the paper's choice.
    pub fn new(p: Vec<DVec2>, q: Vec<DVec2>, style: MlsStyle, alpha: f64) -> Result<Self> {
        if p.len() != q.len() {
            return Err(RokebyError::invalid(
                "controls",
                format!("{} rest points but {} targets", p.len(), q.len()),
            ));
        }
        if p.is_empty() {
            return Err(RokebyError::invalid(
                "controls",
                "at least one control point is needed",
            ));
        }
        if !p.iter().chain(&q).all(|x| x.is_finite()) {
            return Err(RokebyError::invalid(
                "controls",
                "control points must be finite",
            ));
        }
        // The fuzzer found a control point at −1e300: its squared offsets overflow (inf · 0 = NaN
        // in the moment matrices), so coordinates are bounded where squares stay finite.
        if !p.iter().chain(&q).all(|x| x.abs().max_element() <= 1e150) {
            return Err(RokebyError::invalid(
                "controls",
                "control point coordinates must be within ±1e150",
            ));
        }
        if !(alpha.is_finite() && alpha > 0.0) {
            return Err(RokebyError::invalid(
                "mls_alpha",
                format!("must be positive and finite, got {alpha}"),
            ));
        }
        Ok(Mls2d { p, q, style, alpha })
    }

    /// f(v).
    pub fn deform(&self, v: DVec2) -> DVec2 {
        let mut d2s = Vec::with_capacity(self.p.len());
        for (i, &pi) in self.p.iter().enumerate() {
            let d2 = (pi - v).length_squared();
            if d2 == 0.0 {
                return self.q[i];
            }
            d2s.push(d2);
        }
        // Weights 1/d^{2α} scaled by the nearest one's, (d²_min/d²)^α ∈ (0, 1] (the deformation is
        // invariant to a common factor): the fuzzer found α = 1e30 making every 1/d^{2α} 0 or inf.
        let dmin = d2s.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let w: Vec<f64> = d2s.iter().map(|&d2| (dmin / d2).powf(self.alpha)).collect();
        let ws: f64 = w.iter().sum();
        let ps = self
            .p
            .iter()
            .zip(&w)
            .fold(DVec2::ZERO, |a, (&x, &wi)| a + x * wi)
            / ws;
        let qs = self
            .q
            .iter()
            .zip(&w)
            .fold(DVec2::ZERO, |a, (&x, &wi)| a + x * wi)
            / ws;
        let x = v - ps;
        let similarity = || {
            let mut num = DVec2::ZERO; // complex Σ w conj(p̂) q̂
            let mut den = 0.0;
            for ((&pi, &qi), &wi) in self.p.iter().zip(&self.q).zip(&w) {
                let (ph, qh) = (pi - ps, qi - qs);
                num += wi * DVec2::new(ph.x * qh.x + ph.y * qh.y, ph.x * qh.y - ph.y * qh.x);
                den += wi * ph.length_squared();
            }
            if den > 0.0 {
                num / den
            } else {
                DVec2::X
            }
        };
        let rotate = |c: DVec2, x: DVec2| DVec2::new(c.x * x.x - c.y * x.y, c.x * x.y + c.y * x.x);
        match self.style {
            MlsStyle::Affine => {
                // Row-vector convention of the paper: x M with M = A⁻¹ B,
                // A = Σ w p̂ᵀ p̂, B = Σ w p̂ᵀ q̂ (2×2, column-major here as Mᵀ acting on columns).
                // M = I + A⁻¹ (B − A), B − A = Σ w p̂ᵀ (q̂ − p̂): the same map, but exactly the identity
                // at rest (q = p), where A⁻¹ A carried cond(A)·ε of error (the fuzzer found 6e-5 at
                // a nearly collinear, still invertible A).
                let mut a = DMat2::ZERO;
                let mut b = DMat2::ZERO;
                for ((&pi, &qi), &wi) in self.p.iter().zip(&self.q).zip(&w) {
                    let (ph, qh) = (pi - ps, qi - qs);
                    let dh = qh - ph;
                    // outer(ph, ph) and outer(ph, q̂ − p̂) as column-major matrices.
                    a += DMat2::from_cols(ph * ph.x, ph * ph.y) * wi;
                    b += DMat2::from_cols(ph * dh.x, ph * dh.y) * wi;
                }
                let det = a.determinant();
                let scale = a.x_axis.length_squared() + a.y_axis.length_squared();
                if det.abs() <= 1e-12 * scale || scale == 0.0 {
                    return rotate(similarity(), x) + qs;
                }
                // f = x + (A⁻¹ (B − A))ᵀ x + q* in column form; (B − A)[r][c] = Σ w ph_r (q̂ − p̂)_c.
                let m = a.inverse() * b;
                x + m.transpose() * x + qs
            }
            MlsStyle::Similarity => rotate(similarity(), x) + qs,
            MlsStyle::Rigid => {
                let c = similarity();
                let l = c.length();
                let r = if l > 0.0 { c / l } else { DVec2::X };
                rotate(r, x) + qs
            }
        }
    }

    pub fn deform_all(&self, v: &[DVec2]) -> Vec<DVec2> {
        v.iter().map(|&x| self.deform(x)).collect()
    }
}

/// §5.3: offsets h·sin(f·u) along the boundary normal n = (−t_y, t_x)/|t|, t = v_{i−1} − v_{i+1}
/// (central differences; one-sided at the ends of an open segment), u the arc length from the
/// first point (u_{i+1} = u_i + |v_{i+1} − v_i|).
pub fn sinusoidal_noise(
    points: &[DVec2],
    closed: bool,
    amplitude: f64,
    frequency: f64,
) -> Result<Vec<DVec2>> {
    if !(amplitude.is_finite() && frequency.is_finite()) {
        return Err(RokebyError::invalid(
            "noise",
            "amplitude and frequency must be finite",
        ));
    }
    // The fuzzer found NaN points passed through (NaN output); they are an error like MLS controls.
    if !points.iter().all(|p| p.is_finite()) {
        return Err(RokebyError::invalid(
            "points",
            "boundary points must be finite",
        ));
    }
    let m = points.len();
    if m < 2 || amplitude == 0.0 {
        return Ok(points.to_vec());
    }
    // hypot, not length(): the fuzzer found |Δ| ≈ 1e300 squaring to inf (u = inf, sin(inf) = NaN).
    let len = |d: DVec2| d.x.hypot(d.y);
    let mut u = vec![0.0; m];
    for i in 1..m {
        u[i] = u[i - 1] + len(points[i] - points[i - 1]);
    }
    let out: Vec<DVec2> = (0..m)
        .map(|i| {
            let (prev, next) = if closed {
                (points[(i + m - 1) % m], points[(i + 1) % m])
            } else {
                (points[i.saturating_sub(1)], points[(i + 1).min(m - 1)])
            };
            let t = prev - next;
            let l = len(t);
            if l == 0.0 {
                return points[i];
            }
            let n = DVec2::new(-t.y, t.x) / l;
            points[i] + n * (amplitude * (frequency * u[i]).sin())
        })
        .collect();
    if !out.iter().all(|p| p.is_finite()) {
        return Err(RokebyError::invalid(
            "points",
            "the boundary's coordinates or the noise amplitude overflow f64",
        ));
    }
    Ok(out)
}
