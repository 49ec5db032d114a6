//! Prefiltered diffuse environment as order-2 real spherical harmonics (Zubiaga et al. 2016, §3.1).
//!
//! ```text
//!   D(n) = Σ_{l=0..2} Σ_{m=−l..l} c_{l,m} Y_{l,m}(n)                              (eq. 1)
//!   c* = argmin_c Σ_{x∈P} ‖D0(x) − D(n(x))‖²   s.t.  D(n(x)) ≥ D0(x)             (§3.1 QP)
//! ```
//!
//! Nine coefficients per colour channel, channels fitted independently. Two fits:
//! * [`Fit::LeastSquares`]: the 9×9 normal equations AᵀA c = AᵀD0 (f64, Cholesky).
//! * [`Fit::Constrained`]: the QP above, solved by the dual active-set method of Goldfarb & Idnani
//!   (1983) — the paper's [GI83] — on the same 9×9 Hessian AᵀA with one inequality per pixel. It
//!   starts from the unconstrained optimum and adds the most violated pixel constraint at a time;
//!   with 9 unknowns at most 9 constraints are active, so each step is a handful of tiny dense
//!   solves plus one O(9N) pass over the pixels for the slacks (parallel). Residuals D0 − D(n) are
//!   then ≤ 0 (to f64 rounding): they measure occlusion only.
//!
//! Both fits add a tiny ridge (1e-9 · trace/9) to AᵀA so that patches whose normals span only
//! part of the sphere (a plane: rank 1) still have a unique, minimal-norm-like solution.

use crate::error::{Result, RokebyError};
use rayon::prelude::*;

/// Number of order-2 real SH basis functions.
pub const SH_COEFFS: usize = 9;

/// Y_{l,m}(n) for l ≤ 2 in the order (0,0), (1,−1), (1,0), (1,1), (2,−2), (2,−1), (2,0), (2,1),
/// (2,2) — the real basis of Ramamoorthi & Hanrahan 2001 ([RH01a]). `n` should be unit.
#[inline]
pub fn basis(n: [f64; 3]) -> [f64; SH_COEFFS] {
    let [x, y, z] = n;
    [
        0.282_094_791_773_878_14,
        0.488_602_511_902_919_9 * y,
        0.488_602_511_902_919_9 * z,
        0.488_602_511_902_919_9 * x,
        1.092_548_430_592_079_2 * x * y,
        1.092_548_430_592_079_2 * y * z,
        0.315_391_565_252_520_05 * (3.0 * z * z - 1.0),
        1.092_548_430_592_079_2 * x * z,
        0.546_274_215_296_039_6 * (x * x - y * y),
    ]
}

/// D(n) for one channel's coefficients (eq. 1).
#[inline]
pub fn eval(coeffs: &[f64; SH_COEFFS], n: [f64; 3]) -> f64 {
    let b = basis(n);
    let mut s = 0.0;
    for k in 0..SH_COEFFS {
        s += coeffs[k] * b[k];
    }
    s
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fit {
    /// Plain least squares (the fast option).
    LeastSquares,
    /// The QP of §3.1: D(n(x)) ≥ D0(x) for every pixel.
    Constrained,
}

impl Fit {
    pub fn parse(s: &str) -> Option<Fit> {
        match s {
            "ls" | "least_squares" | "lsq" => Some(Fit::LeastSquares),
            "qp" | "constrained" => Some(Fit::Constrained),
            _ => None,
        }
    }
}

/// Result of a fit: `coeffs[c]` are channel c's nine coefficients.
#[derive(Debug, Clone)]
pub struct ShFit {
    pub coeffs: Vec<[f64; SH_COEFFS]>,
    /// Per channel: the largest D0 − D(n) over the pixels (≤ ~0 for the constrained fit).
    pub max_residual: Vec<f64>,
    /// Per channel: root mean square of D0 − D(n).
    pub rms_residual: Vec<f64>,
    /// Per channel: active-set iterations of the QP (0 for least squares).
    pub iterations: Vec<usize>,
}

/// Normal unit vectors (N×3) must be finite and non-zero; they are normalised in f64.
fn unit_normals(normals: &[f32], arg: &str) -> Result<Vec<[f64; 3]>> {
    if normals.len() % 3 != 0 {
        return Err(RokebyError::invalid(arg, format!("expected N×3 values, got {}", normals.len())));
    }
    normals
        .chunks_exact(3)
        .enumerate()
        .map(|(i, c)| {
            let v = [c[0] as f64, c[1] as f64, c[2] as f64];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if !l.is_finite() || l < 1e-12 {
                Err(RokebyError::invalid(arg, format!("normal {i} is zero or not finite")))
            } else {
                Ok([v[0] / l, v[1] / l, v[2] / l])
            }
        })
        .collect()
}

/// Fits eq. 1 to the pixels of one patch: `normals` N×3 (screen space), `values` N×C (D0).
pub fn fit(normals: &[f32], values: &[f32], channels: usize, method: Fit) -> Result<ShFit> {
    if channels == 0 {
        return Err(RokebyError::invalid("values", "need at least one channel"));
    }
    let ns = unit_normals(normals, "normals")?;
    let n = ns.len();
    if n == 0 {
        return Err(RokebyError::invalid("normals", "no pixels to fit"));
    }
    if values.len() != n * channels {
        return Err(RokebyError::invalid("values", format!("expected {n}×{channels} values (one row per normal), got {}", values.len())));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(RokebyError::invalid("values", format!("value {} of pixel {} is not finite", i % channels, i / channels)));
    }
    let a: Vec<[f64; SH_COEFFS]> = ns.par_iter().map(|&v| basis(v)).collect();
    // Hessian H = AᵀA (+ ridge), shared by all channels; accumulated in f64.
    let mut h = a
        .par_chunks(4096)
        .map(|rows| {
            let mut h = [[0.0f64; SH_COEFFS]; SH_COEFFS];
            for r in rows {
                for i in 0..SH_COEFFS {
                    for j in i..SH_COEFFS {
                        h[i][j] += r[i] * r[j];
                    }
                }
            }
            h
        })
        .reduce(|| [[0.0; SH_COEFFS]; SH_COEFFS], |mut x, y| {
            for i in 0..SH_COEFFS {
                for j in 0..SH_COEFFS {
                    x[i][j] += y[i][j];
                }
            }
            x
        });
    let trace: f64 = (0..SH_COEFFS).map(|i| h[i][i]).sum();
    for i in 0..SH_COEFFS {
        for j in 0..i {
            h[i][j] = h[j][i];
        }
        h[i][i] += 1e-9 * trace / SH_COEFFS as f64;
    }
    let chol = Chol::new(&h).ok_or_else(|| RokebyError::invalid("normals", "normal equations are singular"))?;
    let per_channel: Vec<Result<([f64; SH_COEFFS], usize)>> = (0..channels)
        .into_par_iter()
        .map(|c| {
            let b: Vec<f64> = (0..n).map(|i| values[i * channels + c] as f64).collect();
            let mut g = [0.0; SH_COEFFS];
            for (r, &bi) in a.iter().zip(&b) {
                for k in 0..SH_COEFFS {
                    g[k] += r[k] * bi;
                }
            }
            let x0 = chol.solve(&g);
            match method {
                Fit::LeastSquares => Ok((x0, 0)),
                Fit::Constrained => goldfarb_idnani(&chol, x0, &a, &b),
            }
        })
        .collect();
    let mut out = ShFit { coeffs: vec![], max_residual: vec![], rms_residual: vec![], iterations: vec![] };
    for (c, r) in per_channel.into_iter().enumerate() {
        let (x, it) = r?;
        let (mx, ss) = a
            .par_iter()
            .enumerate()
            .map(|(i, row)| {
                let d = values[i * channels + c] as f64 - dot9(row, &x);
                (d, d * d)
            })
            .reduce(|| (f64::NEG_INFINITY, 0.0), |p, q| (p.0.max(q.0), p.1 + q.1));
        out.coeffs.push(x);
        out.max_residual.push(mx);
        out.rms_residual.push((ss / n as f64).sqrt());
        out.iterations.push(it);
    }
    Ok(out)
}

#[inline]
fn dot9(a: &[f64; SH_COEFFS], b: &[f64; SH_COEFFS]) -> f64 {
    let mut s = 0.0;
    for k in 0..SH_COEFFS {
        s += a[k] * b[k];
    }
    s
}

/// Cholesky factor of the 9×9 Hessian.
struct Chol {
    l: [[f64; SH_COEFFS]; SH_COEFFS],
}

impl Chol {
    fn new(h: &[[f64; SH_COEFFS]; SH_COEFFS]) -> Option<Chol> {
        let mut l = [[0.0; SH_COEFFS]; SH_COEFFS];
        for i in 0..SH_COEFFS {
            for j in 0..=i {
                let mut s = h[i][j];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                if i == j {
                    if !(s > 0.0) {
                        return None;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        Some(Chol { l })
    }

    /// H⁻¹ b.
    fn solve(&self, b: &[f64; SH_COEFFS]) -> [f64; SH_COEFFS] {
        let l = &self.l;
        let mut y = *b;
        for i in 0..SH_COEFFS {
            for k in 0..i {
                y[i] -= l[i][k] * y[k];
            }
            y[i] /= l[i][i];
        }
        for i in (0..SH_COEFFS).rev() {
            for k in i + 1..SH_COEFFS {
                y[i] -= l[k][i] * y[k];
            }
            y[i] /= l[i][i];
        }
        y
    }
}

/// Solves the small dense system M x = b (Gaussian elimination, partial pivoting). None if singular.
fn solve_small(mut m: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let q = b.len();
    for col in 0..q {
        let piv = (col..q).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[piv][col].abs() < 1e-300 {
            return None;
        }
        m.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..q {
            let f = m[r][col] / m[col][col];
            for k in col..q {
                m[r][k] -= f * m[col][k];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = vec![0.0; q];
    for i in (0..q).rev() {
        let mut s = b[i];
        for k in i + 1..q {
            s -= m[i][k] * x[k];
        }
        x[i] = s / m[i][i];
    }
    Some(x)
}

/// Goldfarb–Idnani dual active-set method for
///   min ½ cᵀHc − gᵀc   s.t.  aᵢᵀc ≥ bᵢ  (i = 1..N),
/// started at the unconstrained optimum x0 = H⁻¹g. Returns the optimum and the number of steps.
fn goldfarb_idnani(chol: &Chol, mut x: [f64; SH_COEFFS], a: &[[f64; SH_COEFFS]], b: &[f64]) -> Result<([f64; SH_COEFFS], usize)> {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-30);
    let tol = 1e-12 * scale;
    let mut active: Vec<usize> = Vec::new();
    let mut lambda: Vec<f64> = Vec::new();
    let max_steps = 50 * SH_COEFFS + 4 * a.len().min(10_000);
    let mut steps = 0usize;
    loop {
        // Most violated constraint.
        let (p, sp) = a
            .par_iter()
            .zip(b.par_iter())
            .enumerate()
            .map(|(i, (r, &bi))| (i, dot9(r, &x) - bi))
            .reduce(|| (usize::MAX, f64::INFINITY), |u, v| if v.1 < u.1 { v } else { u });
        if p == usize::MAX || sp >= -tol {
            return Ok((x, steps));
        }
        let np = a[p];
        let mut lam_p = 0.0f64;
        loop {
            steps += 1;
            if steps > max_steps {
                return Err(RokebyError::invalid("values", "constrained SH fit did not converge"));
            }
            // z = H⁻¹n − H⁻¹N r,  r = (NᵀH⁻¹N)⁻¹ NᵀH⁻¹n.
            let hn = chol.solve(&np);
            let q = active.len();
            let mut r = vec![0.0; q];
            let mut z = hn;
            if q > 0 {
                let hcols: Vec<[f64; SH_COEFFS]> = active.iter().map(|&j| chol.solve(&a[j])).collect();
                let m: Vec<Vec<f64>> = (0..q).map(|i| (0..q).map(|k| dot9(&a[active[i]], &hcols[k])).collect()).collect();
                let rhs: Vec<f64> = (0..q).map(|i| dot9(&a[active[i]], &hn)).collect();
                r = solve_small(m, rhs).ok_or_else(|| RokebyError::invalid("values", "constrained SH fit: degenerate active set"))?;
                for k in 0..q {
                    for d in 0..SH_COEFFS {
                        z[d] -= hcols[k][d] * r[k];
                    }
                }
            }
            // Partial step: the first active multiplier that would reach zero.
            let mut t1 = f64::INFINITY;
            let mut drop = usize::MAX;
            for k in 0..q {
                if r[k] > 0.0 {
                    let t = lambda[k] / r[k];
                    if t < t1 {
                        t1 = t;
                        drop = k;
                    }
                }
            }
            let zn = dot9(&z, &np);
            let s_now = dot9(&np, &x) - b[p];
            let t2 = if zn > 1e-14 * dot9(&np, &np) { -s_now / zn } else { f64::INFINITY };
            if !t1.is_finite() && !t2.is_finite() {
                return Err(RokebyError::invalid("values", "constrained SH fit is infeasible"));
            }
            if !t2.is_finite() {
                // Constraint p is linearly dependent on the active set: move multipliers only.
                for k in 0..q {
                    lambda[k] -= t1 * r[k];
                }
                lam_p += t1;
                active.remove(drop);
                lambda.remove(drop);
                continue;
            }
            let t = t1.min(t2);
            for d in 0..SH_COEFFS {
                x[d] += t * z[d];
            }
            for k in 0..q {
                lambda[k] -= t * r[k];
            }
            lam_p += t;
            if t2 <= t1 {
                active.push(p);
                lambda.push(lam_p);
                break;
            }
            active.remove(drop);
            lambda.remove(drop);
        }
    }
}
