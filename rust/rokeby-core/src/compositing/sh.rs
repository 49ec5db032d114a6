//! Prefiltered diffuse environment as order-2 real spherical harmonics (Zubiaga et al. 2016, §3.1).
//!
//! ```text
//!   D(n) = Σ_{l=0..2} Σ_{m=−l..l} c_{l,m} Y_{l,m}(n)                              (eq. 1)
//!   c* = argmin_c Σ_{x∈P} ‖D0(x) − D(n(x))‖²   s.t.  D(n(x)) ≥ D0(x)             (§3.1 QP)
//! ```
//!
//! Nine coefficients per colour channel, channels fitted independently. Two fits:
//! * [`Fit::LeastSquares`]: the 9×9 normal equations AᵀA c = AᵀD0 (f64, Cholesky), accumulated in
//!   one pass with the basis evaluated on the fly (8 pixels side by side; no N×9 matrix stored).
//! * [`Fit::Constrained`]: the QP above, solved by the dual active-set method of Goldfarb & Idnani
//!   (1983) — the paper's [GI83] — on the same 9×9 Hessian AᵀA with one inequality per pixel. It
//!   starts from the unconstrained optimum and adds the most violated constraint at a time; with 9
//!   unknowns at most 9 constraints are active, so each step is a handful of tiny dense solves.
//!   The search for the most violated constraint runs over a working set of pixels, grown by
//!   passes over the whole patch until none is violated (constraint screening, see
//!   `qp_screened`): the same unique optimum in a few passes instead of one per step. Residuals
//!   D0 − D(n) are then ≤ 0 (to f64 rounding): they measure occlusion only.
//!
//! Passes run in parallel over fixed chunks of pixels whose partial sums are combined in order,
//! so the fits are the same on any number of threads.
//!
//! Both fits add a tiny ridge (1e-9 · trace/9) to AᵀA so that patches whose normals span only
//! part of the sphere (a plane: rank 1) still have a unique, minimal-norm-like solution.

use crate::error::{Result, RokebyError};
use crate::unit_vector::unit_row;
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

/// D(n) of every channel's coefficients at each normal (N×3, any length, normalised here):
/// N×C values, row-major. A zero or non-finite normal is an error naming its row (it has no
/// direction, and would give NaN).
pub fn eval_many(coeffs: &[[f64; SH_COEFFS]], normals: &[f32]) -> Result<Vec<f32>> {
    if !normals.len().is_multiple_of(3) {
        return Err(RokebyError::invalid("normals", "expected N×3 values"));
    }
    let ch = coeffs.len();
    if let Some((c, _)) = coeffs
        .iter()
        .enumerate()
        .find(|(_, r)| r.iter().any(|x| !x.is_finite()))
    {
        return Err(RokebyError::invalid(
            "coeffs",
            format!("row {c} is not finite"),
        ));
    }
    let n = normals.len() / 3;
    let mut out = crate::alloc::filled("normals × channels", &[n, ch], 0.0f32)?;
    for (i, nr) in normals.chunks_exact(3).enumerate() {
        let v = [nr[0] as f64, nr[1] as f64, nr[2] as f64];
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if !(l.is_finite() && l > 1e-30) {
            return Err(RokebyError::invalid(
                "normals",
                format!("normal {i} is zero or not finite: it has no direction"),
            ));
        }
        let u = v.map(|x| x / l);
        for c in 0..ch {
            let d = eval(&coeffs[c], u);
            if d.abs() > f32::MAX as f64 {
                return Err(RokebyError::invalid(
                    "coeffs",
                    format!("D(n) of channel {c} at normal {i} ({d:e}) overflows float32"),
                ));
            }
            out[i * ch + c] = d as f32;
        }
    }
    Ok(out)
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
#[cfg(test)]
fn unit_normals(normals: &[f32], arg: &str) -> Result<Vec<[f64; 3]>> {
    if !normals.len().is_multiple_of(3) {
        return Err(RokebyError::invalid(
            arg,
            format!("expected N×3 values, got {}", normals.len()),
        ));
    }
    normals
        .chunks_exact(3)
        .enumerate()
        .map(|(i, c)| {
            unit_row(c).map(|u| u.to_array()).ok_or_else(|| {
                RokebyError::invalid(arg, format!("normal {i} is zero or not finite"))
            })
        })
        .collect()
}

/// Pixels per work unit of the passes over the patch. Fixed, so that the partial sums and their
/// (sequential) combination do not depend on the number of threads: results are the same on any
/// thread count.
const CHUNK: usize = 4096;
/// Pixels evaluated side by side in the Hessian pass (SIMD lanes after vectorisation).
const LANES: usize = 8;
/// Upper-triangle index pairs (i ≤ j) of the 9×9 Hessian.
const PAIRS: [(usize, usize); 45] = {
    let mut p = [(0, 0); 45];
    let mut k = 0;
    let mut i = 0;
    while i < SH_COEFFS {
        let mut j = i;
        while j < SH_COEFFS {
            p[k] = (i, j);
            k += 1;
            j += 1;
        }
        i += 1;
    }
    p
};

/// The basis rows of pixels p0..p0+m (m ≤ LANES) side by side: `b[k][l]` = Y_k of pixel p0 + l,
/// bit for bit `basis(unit_row(..))` (same operations in the same order, in lanes so that they
/// vectorise). Lanes l ≥ m hold the basis of +z.
#[inline(always)]
fn basis_lanes(normals: &[f32], p0: usize, m: usize) -> [[f64; LANES]; SH_COEFFS] {
    let (mut x, mut y, mut z) = ([0.0f64; LANES], [0.0f64; LANES], [1.0f64; LANES]);
    for l in 0..m {
        let p = 3 * (p0 + l);
        x[l] = normals[p] as f64;
        y[l] = normals[p + 1] as f64;
        z[l] = normals[p + 2] as f64;
    }
    let mut b = [[0.0f64; LANES]; SH_COEFFS];
    for l in 0..LANES {
        let len = (x[l] * x[l] + y[l] * y[l] + z[l] * z[l]).sqrt();
        let (x, y, z) = (x[l] / len, y[l] / len, z[l] / len);
        b[0][l] = 0.282_094_791_773_878_14;
        b[1][l] = 0.488_602_511_902_919_9 * y;
        b[2][l] = 0.488_602_511_902_919_9 * z;
        b[3][l] = 0.488_602_511_902_919_9 * x;
        b[4][l] = 1.092_548_430_592_079_2 * x * y;
        b[5][l] = 1.092_548_430_592_079_2 * y * z;
        b[6][l] = 0.315_391_565_252_520_05 * (3.0 * z * z - 1.0);
        b[7][l] = 1.092_548_430_592_079_2 * x * z;
        b[8][l] = 0.546_274_215_296_039_6 * (x * x - y * y);
    }
    b
}

/// Per chunk of pixels: the upper triangle of AᵀA (45 entries) and Aᵀb per channel (9·C),
/// accumulated in f64 in LANES independent lanes (summed at the chunk's end). Compiled twice, for
/// x86-64 and for AVX2 (picked at run time): the same IEEE operations in the same order (no FMA),
/// so the same bits either way.
fn normal_equations_chunk(
    normals: &[f32],
    values: &[f32],
    channels: usize,
) -> (Vec<f64>, Vec<f64>) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { normal_equations_chunk_avx2(normals, values, channels) };
    }
    normal_equations_chunk_any(normals, values, channels)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn normal_equations_chunk_avx2(
    normals: &[f32],
    values: &[f32],
    channels: usize,
) -> (Vec<f64>, Vec<f64>) {
    normal_equations_chunk_any(normals, values, channels)
}

#[inline(always)]
fn normal_equations_chunk_any(
    normals: &[f32],
    values: &[f32],
    channels: usize,
) -> (Vec<f64>, Vec<f64>) {
    let n = normals.len() / 3;
    let mut h = [[0.0f64; LANES]; 45];
    let mut g = vec![[0.0f64; LANES]; SH_COEFFS * channels];
    let mut v = vec![[0.0f64; LANES]; channels];
    let mut p0 = 0;
    while p0 < n {
        let m = (n - p0).min(LANES);
        let mut b = basis_lanes(normals, p0, m);
        if m < LANES {
            // Padding lanes contribute zero.
            for bk in b.iter_mut() {
                for x in bk[m..].iter_mut() {
                    *x = 0.0;
                }
            }
        }
        for (c, vc) in v.iter_mut().enumerate() {
            for l in 0..LANES {
                vc[l] = if l < m {
                    values[(p0 + l) * channels + c] as f64
                } else {
                    0.0
                };
            }
        }
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            for l in 0..LANES {
                h[k][l] += b[i][l] * b[j][l];
            }
        }
        for c in 0..channels {
            for k in 0..SH_COEFFS {
                let gk = &mut g[c * SH_COEFFS + k];
                for l in 0..LANES {
                    gk[l] += b[k][l] * v[c][l];
                }
            }
        }
        p0 += LANES;
    }
    let hs = h.iter().map(|x| x.iter().sum()).collect();
    let gs = g.iter().map(|x| x.iter().sum()).collect();
    (hs, gs)
}

/// The index of the first `width`-wide row of `data` for which `bad` holds (chunks in parallel).
fn first_bad(data: &[f32], width: usize, bad: impl Fn(&[f32]) -> bool + Sync) -> Option<usize> {
    data.par_chunks(width * CHUNK)
        .enumerate()
        .map(|(ci, c)| c.chunks_exact(width).position(&bad).map(|i| ci * CHUNK + i))
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .next()
}

/// Fits eq. 1 to the pixels of one patch: `normals` N×3 (screen space), `values` N×C (D0).
///
/// One pass accumulates the normal equations (basis evaluated on the fly, no N×9 matrix is
/// stored); least squares solves them; the QP (§3.1) runs [GI83] on a screened working set of
/// pixel constraints, checked against all pixels by further passes (see [`qp_screened`]); a last
/// pass gives the residual statistics.
pub fn fit(normals: &[f32], values: &[f32], channels: usize, method: Fit) -> Result<ShFit> {
    fit_with_tolerance(normals, values, channels, method, &[])
}

/// A fit over the usable rows of one patch's pixels.
#[derive(Debug, Clone)]
pub struct PatchFit {
    pub fit: ShFit,
    /// Rows used: finite, non-zero normal and finite values.
    pub pixels: usize,
    /// Rows left out (a non-finite or zero normal, or a non-finite value).
    pub masked: usize,
}

/// [`fit_with_tolerance`] over the rows of a patch that can be used: rows with a non-finite or
/// zero normal (|n|² ≤ 10⁻²⁴) or a non-finite value are left out (background and masked pixels
/// of a render), and counted. An error when no row is usable. `tolerance`: empty, one value for
/// every channel, or one per channel.
pub fn fit_patch(
    normals: &[f32],
    values: &[f32],
    channels: usize,
    method: Fit,
    tolerance: &[f64],
) -> Result<PatchFit> {
    if channels == 0
        || !normals.len().is_multiple_of(3)
        || values.len() / channels != normals.len() / 3
    {
        return Err(RokebyError::invalid(
            "values",
            format!(
                "expected {} rows of {channels} channels (one per normal), got {} values",
                normals.len() / 3,
                values.len()
            ),
        ));
    }
    let rows = normals.len() / 3;
    let usable = |i: usize| {
        let nr = &normals[3 * i..3 * i + 3];
        let l2 = nr.iter().map(|x| (*x as f64) * (*x as f64)).sum::<f64>();
        nr.iter()
            .chain(&values[channels * i..channels * (i + 1)])
            .all(|x| x.is_finite())
            && l2 > 1e-24
    };
    // One pass counts the unusable rows; a filtered copy is made only when there are some (a
    // render's patch usually has none, and the copy cost a third of the least-squares fit).
    let masked = (0..rows).filter(|&i| !usable(i)).count();
    if masked == rows {
        return Err(RokebyError::invalid(
            "normals",
            format!(
                "no usable pixel ({masked} of {rows} have a non-finite or zero normal or value)"
            ),
        ));
    }
    let (keep_n, keep_v): (std::borrow::Cow<[f32]>, std::borrow::Cow<[f32]>) = if masked == 0 {
        (normals.into(), values.into())
    } else {
        let mut kn = Vec::with_capacity(3 * (rows - masked));
        let mut kv = Vec::with_capacity(channels * (rows - masked));
        for i in (0..rows).filter(|&i| usable(i)) {
            kn.extend_from_slice(&normals[3 * i..3 * i + 3]);
            kv.extend_from_slice(&values[channels * i..channels * (i + 1)]);
        }
        (kn.into(), kv.into())
    };
    let tolerance = if tolerance.len() == 1 && channels > 1 {
        vec![tolerance[0]; channels]
    } else {
        tolerance.to_vec()
    };
    let fit = fit_with_tolerance(&keep_n, &keep_v, channels, method, &tolerance)?;
    Ok(PatchFit {
        fit,
        pixels: rows - masked,
        masked,
    })
}

/// [`fit`] with the QP's constraints relaxed by a per-channel noise tolerance τ_c ≥ 0:
/// D(n(x)) ≥ D0(x) − τ_c. The paper's QP (τ = 0) treats every pixel as exact, so on a
/// path-traced render the fit rises until the noisiest pixel sits below it; τ of about two noise
/// standard deviations leaves the noise in the residual and keeps the constraint for what it is
/// meant for, occlusion (which darkens pixels by more than the noise). `tolerance`: empty (all
/// zero) or one value per channel; only [`Fit::Constrained`] takes a non-zero one.
pub fn fit_with_tolerance(
    normals: &[f32],
    values: &[f32],
    channels: usize,
    method: Fit,
    tolerance: &[f64],
) -> Result<ShFit> {
    if channels == 0 {
        return Err(RokebyError::invalid("values", "need at least one channel"));
    }
    if !normals.len().is_multiple_of(3) {
        return Err(RokebyError::invalid(
            "normals",
            format!("expected N×3 values, got {}", normals.len()),
        ));
    }
    if let Some(i) = first_bad(normals, 3, |c| unit_row(c).is_none()) {
        return Err(RokebyError::invalid(
            "normals",
            format!("normal {i} is zero or not finite"),
        ));
    }
    let n = normals.len() / 3;
    if n == 0 {
        return Err(RokebyError::invalid("normals", "no pixels to fit"));
    }
    if values.len() != n * channels {
        return Err(RokebyError::invalid(
            "values",
            format!(
                "expected {n}×{channels} values (one row per normal), got {}",
                values.len()
            ),
        ));
    }
    if let Some(i) = first_bad(values, 1, |v| !v[0].is_finite()) {
        return Err(RokebyError::invalid(
            "values",
            format!(
                "value {} of pixel {} is not finite",
                i % channels,
                i / channels
            ),
        ));
    }
    if !tolerance.is_empty() && tolerance.len() != channels {
        return Err(RokebyError::invalid(
            "tolerance",
            format!(
                "expected one value per channel ({channels}), got {}",
                tolerance.len()
            ),
        ));
    }
    if let Some(t) = tolerance.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
        return Err(RokebyError::invalid(
            "tolerance",
            format!("must be finite and ≥ 0, got {t}"),
        ));
    }
    let slack: Vec<f64> = if tolerance.is_empty() {
        vec![0.0; channels]
    } else {
        tolerance.to_vec()
    };
    if method == Fit::LeastSquares && slack.iter().any(|&t| t > 0.0) {
        return Err(RokebyError::invalid(
            "tolerance",
            "only the constrained fit (qp) has constraints to relax",
        ));
    }
    // Hessian H = AᵀA (+ ridge), shared by all channels, and g = Aᵀb per channel; f64.
    let parts: Vec<(Vec<f64>, Vec<f64>)> = normals
        .par_chunks(3 * CHUNK)
        .zip(values.par_chunks(channels * CHUNK))
        .map(|(nc, vc)| normal_equations_chunk(nc, vc, channels))
        .collect();
    let mut hu = vec![0.0f64; 45];
    let mut gs = vec![0.0f64; SH_COEFFS * channels];
    for (ph, pg) in &parts {
        for k in 0..45 {
            hu[k] += ph[k];
        }
        for k in 0..gs.len() {
            gs[k] += pg[k];
        }
    }
    let mut h = [[0.0f64; SH_COEFFS]; SH_COEFFS];
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        h[i][j] = hu[k];
        h[j][i] = hu[k];
    }
    let trace: f64 = (0..SH_COEFFS).map(|i| h[i][i]).sum();
    for (i, row) in h.iter_mut().enumerate() {
        row[i] += 1e-9 * trace / SH_COEFFS as f64;
    }
    let chol = Chol::new(&h)
        .ok_or_else(|| RokebyError::numerical("SH fit", "the normal equations are singular"))?;
    let x0: Vec<[f64; SH_COEFFS]> = (0..channels)
        .map(|c| {
            let mut g = [0.0; SH_COEFFS];
            g.copy_from_slice(&gs[c * SH_COEFFS..(c + 1) * SH_COEFFS]);
            chol.solve(&g)
        })
        .collect();
    let (coeffs, iterations, stats) = match method {
        Fit::LeastSquares => {
            let stats = residual_pass(normals, values, channels, &x0, &[]).0;
            (x0, vec![0; channels], stats)
        }
        Fit::Constrained => qp_screened(&chol, normals, values, channels, x0, &slack)?,
    };
    Ok(ShFit {
        coeffs,
        max_residual: stats.iter().map(|s| s.0).collect(),
        rms_residual: stats.iter().map(|s| (s.1 / n as f64).sqrt()).collect(),
        iterations,
    })
}

/// One chunk of [`residual_pass`] (chunk index `ci`), dispatched like [`normal_equations_chunk`].
// Returns the pass's two results as one tuple: per channel (largest residual, sum of squares),
// per watched channel the (pixel, slack) list.
#[allow(clippy::type_complexity)]
fn residual_chunk(
    ci: usize,
    nc: &[f32],
    vc: &[f32],
    channels: usize,
    x: &[[f64; SH_COEFFS]],
    watch: &[(usize, f64, f64)],
) -> (Vec<(f64, f64)>, Vec<Vec<(u32, f64)>>) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { residual_chunk_avx2(ci, nc, vc, channels, x, watch) };
    }
    residual_chunk_any(ci, nc, vc, channels, x, watch)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
// Returns the pass's two results as one tuple: per channel (largest residual, sum of squares),
// per watched channel the (pixel, slack) list.
#[allow(clippy::type_complexity)]
unsafe fn residual_chunk_avx2(
    ci: usize,
    nc: &[f32],
    vc: &[f32],
    channels: usize,
    x: &[[f64; SH_COEFFS]],
    watch: &[(usize, f64, f64)],
) -> (Vec<(f64, f64)>, Vec<Vec<(u32, f64)>>) {
    residual_chunk_any(ci, nc, vc, channels, x, watch)
}

#[inline(always)]
// Returns the pass's two results as one tuple: per channel (largest residual, sum of squares),
// per watched channel the (pixel, slack) list.
#[allow(clippy::type_complexity)]
fn residual_chunk_any(
    ci: usize,
    nc: &[f32],
    vc: &[f32],
    channels: usize,
    x: &[[f64; SH_COEFFS]],
    watch: &[(usize, f64, f64)],
) -> (Vec<(f64, f64)>, Vec<Vec<(u32, f64)>>) {
    let n = nc.len() / 3;
    let mut mx = vec![[f64::NEG_INFINITY; LANES]; channels];
    let mut ss = vec![[0.0f64; LANES]; channels];
    let mut viol: Vec<Vec<(u32, f64)>> = vec![Vec::new(); watch.len()];
    let mut dots = vec![[0.0f64; LANES]; channels];
    let mut p0 = 0;
    while p0 < n {
        let m = (n - p0).min(LANES);
        let b = basis_lanes(nc, p0, m);
        for c in 0..channels {
            let xc = &x[c];
            let mut s = [0.0f64; LANES];
            for k in 0..SH_COEFFS {
                for l in 0..LANES {
                    s[l] += b[k][l] * xc[k];
                }
            }
            dots[c] = s;
            if m == LANES {
                for l in 0..LANES {
                    let d = vc[(p0 + l) * channels + c] as f64 - s[l];
                    mx[c][l] = if d > mx[c][l] { d } else { mx[c][l] };
                    ss[c][l] += d * d;
                }
            } else {
                for l in 0..m {
                    let d = vc[(p0 + l) * channels + c] as f64 - s[l];
                    mx[c][l] = if d > mx[c][l] { d } else { mx[c][l] };
                    ss[c][l] += d * d;
                }
            }
        }
        for (w, &(c, theta, tau)) in watch.iter().enumerate() {
            for l in 0..m {
                let slack = dots[c][l] - (vc[(p0 + l) * channels + c] as f64 - tau);
                if slack < theta {
                    viol[w].push(((ci * CHUNK + p0 + l) as u32, slack));
                }
            }
        }
        p0 += LANES;
    }
    let st = (0..channels)
        .map(|c| {
            (
                mx[c].iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b)),
                ss[c].iter().sum(),
            )
        })
        .collect();
    (st, viol)
}

/// One pass over the pixels with the coefficients `x[c]`: per channel (largest residual
/// D0 − D(n), sum of squared residuals), and, for the channels listed in `watch` as (c, θ, τ),
/// the pixels whose slack D(n) − (D0 − τ) is below θ (index, slack), in pixel order. The slack
/// is the one [GI83] computes (`GiState::run`: dot9(a, x) − b with b = D0 − τ), bit for bit.
// Returns the pass's two results as one tuple: per channel (largest residual, sum of squares),
// per watched channel the (pixel, slack) list.
#[allow(clippy::type_complexity)]
fn residual_pass(
    normals: &[f32],
    values: &[f32],
    channels: usize,
    x: &[[f64; SH_COEFFS]],
    watch: &[(usize, f64, f64)],
) -> (Vec<(f64, f64)>, Vec<Vec<(u32, f64)>>) {
    let parts: Vec<(Vec<(f64, f64)>, Vec<Vec<(u32, f64)>>)> = normals
        .par_chunks(3 * CHUNK)
        .zip(values.par_chunks(channels * CHUNK))
        .enumerate()
        .map(|(ci, (nc, vc))| residual_chunk(ci, nc, vc, channels, x, watch))
        .collect();
    let mut st = vec![(f64::NEG_INFINITY, 0.0f64); channels];
    let mut viol: Vec<Vec<(u32, f64)>> = vec![Vec::new(); watch.len()];
    for (pst, pv) in parts {
        for c in 0..channels {
            st[c].0 = st[c].0.max(pst[c].0);
            st[c].1 += pst[c].1;
        }
        for (w, v) in pv.into_iter().enumerate() {
            viol[w].extend(v);
        }
    }
    (st, viol)
}

/// Size of the regular sample of pixels that seeds the working sets of [`qp_screened`].
const SCREEN_SAMPLE: usize = 2048;
/// Constraints added to a channel's working set per round of [`qp_screened`] (the most violated).
const SCREEN_BATCH: usize = 512;

/// The QP of §3.1 by [GI83] on a working set. Goldfarb–Idnani is a dual method: its state (x
/// optimal for the equality-constrained problem of its active set, multipliers ≥ 0) stays valid
/// when constraints are added to the problem. So each channel runs it on a subset S of the pixel
/// constraints (at first those of a regular sample of `SCREEN_SAMPLE` pixels violated at the
/// least-squares optimum); a pass over all pixels then lists those the subset's optimum violates,
/// the most violated `SCREEN_BATCH` of them join S and the method continues from where it stopped.
/// The same pass lists the candidates, pixels with a slack under a small margin; the next rounds
/// check only those, and a full pass follows when none of them is violated. When a full pass finds
/// no violation (beyond the tolerance) the subset's optimum is feasible for all pixels and
/// therefore the optimum of the whole QP (strictly convex: the optimum is unique). Same result as
/// running [GI83] on all N constraints at once, at two or three passes over the pixels instead of
/// one per step.
// The per-channel results of the screened QP as one tuple, as `fit` returns them.
#[allow(clippy::type_complexity)]
fn qp_screened(
    chol: &Chol,
    normals: &[f32],
    values: &[f32],
    channels: usize,
    x0: Vec<[f64; SH_COEFFS]>,
    slack: &[f64],
) -> Result<(Vec<[f64; SH_COEFFS]>, Vec<usize>, Vec<(f64, f64)>)> {
    let n = normals.len() / 3;
    let tols: Vec<f64> = (0..channels)
        .map(|c| {
            let scale = (0..n)
                .map(|i| values[i * channels + c].abs() as f64)
                .fold(0.0f64, f64::max)
                .max(1e-30);
            1e-12 * scale
        })
        .collect();
    let max_steps = 50 * SH_COEFFS + 4 * n.min(10_000);
    let mut st: Vec<GiState> = x0.into_iter().map(GiState::new).collect();
    let mut rows: Vec<Vec<[f64; SH_COEFFS]>> = vec![Vec::new(); channels];
    let mut rhs: Vec<Vec<f64>> = vec![Vec::new(); channels];
    // Round 0: a regular sample of the pixels (every k-th), those violated at x0 (no pass).
    let k = (n / SCREEN_SAMPLE).max(1);
    for p in (0..n).step_by(k) {
        let a = basis(
            unit_row(&normals[3 * p..3 * p + 3])
                .expect("validated")
                .to_array(),
        );
        for c in 0..channels {
            let bv = values[p * channels + c] as f64 - slack[c];
            if dot9(&a, &st[c].x) - bv < -tols[c] {
                rows[c].push(a);
                rhs[c].push(bv);
            }
        }
    }
    // Candidate screening: a full pass also lists, per channel, the pixels whose slack is below
    // θ (a small positive margin), the ones that can become violated while x moves a little. The
    // rounds after it check only those; when none of them is violated, a full pass over all
    // pixels verifies the optimum (and gives the statistics), or starts over with what it finds.
    // The result is the same unique optimum as screening every pixel in every round.
    let theta: Vec<f64> = tols.iter().map(|t| t * CANDIDATE_MARGIN).collect();
    let mut cand: Vec<Option<Vec<u32>>> = vec![None; channels];
    let mut open: Vec<usize> = (0..channels).collect(); // not yet verified by a full pass
    let mut dirty: Vec<usize> = open.clone(); // working set grown since [GI83] last ran
    loop {
        // [GI83] on each channel whose working set grew, from where it stopped.
        let res: Vec<Result<()>> = st
            .par_iter_mut()
            .enumerate()
            .filter(|(c, _)| dirty.contains(c))
            .map(|(c, s)| s.run(chol, &rows[c], &rhs[c], tols[c], max_steps))
            .collect();
        for r in res {
            r?;
        }
        dirty.clear();
        if open.iter().all(|&c| cand[c].is_some()) {
            for &c in &open {
                let x = st[c].x;
                let mut v: Vec<(u32, f64)> = cand[c]
                    .as_ref()
                    .expect("checked")
                    .iter()
                    .filter_map(|&p| {
                        let pu = p as usize;
                        let a = basis(
                            unit_row(&normals[3 * pu..3 * pu + 3])
                                .expect("validated")
                                .to_array(),
                        );
                        let sl = dot9(&a, &x) - (values[pu * channels + c] as f64 - slack[c]);
                        (sl < -tols[c]).then_some((p, sl))
                    })
                    .collect();
                if add_most_violated(
                    &mut v, c, normals, values, channels, slack, &mut rows, &mut rhs,
                ) {
                    dirty.push(c);
                }
            }
            if !dirty.is_empty() {
                continue;
            }
        }
        // One pass over all pixels: the statistics, the constraints still violated and the candidates.
        let x: Vec<[f64; SH_COEFFS]> = st.iter().map(|s| s.x).collect();
        let watch: Vec<(usize, f64, f64)> = open.iter().map(|&c| (c, theta[c], slack[c])).collect();
        let (stats, listed) = residual_pass(normals, values, channels, &x, &watch);
        let mut still = Vec::new();
        for (w, l) in listed.into_iter().enumerate() {
            let c = open[w];
            let mut v: Vec<(u32, f64)> = l.iter().copied().filter(|e| e.1 < -tols[c]).collect();
            // Candidates worth keeping only while they are few; otherwise full passes, as before.
            cand[c] = (l.len() <= n / 8).then(|| l.into_iter().map(|e| e.0).collect());
            if add_most_violated(
                &mut v, c, normals, values, channels, slack, &mut rows, &mut rhs,
            ) {
                dirty.push(c);
                still.push(c);
            }
        }
        if still.is_empty() {
            let it = st.iter().map(|s| s.steps).collect();
            return Ok((x, it, stats));
        }
        open = still;
    }
}

/// Candidates' margin θ over the violation tolerance (θ = CANDIDATE_MARGIN · tol = 1e-3 of the
/// channel's largest |D0|, tol being 1e-12 of it).
const CANDIDATE_MARGIN: f64 = 1e9;

/// Adds the most violated `SCREEN_BATCH` of the (pixel, slack) list `v` to channel c's working
/// set, in pixel order (ties by pixel index); whether there was any.
// Channel c's working-set state of [GI83], passed piecewise (its parts live in separate per-
// channel vectors of the caller).
#[allow(clippy::too_many_arguments)]
fn add_most_violated(
    v: &mut Vec<(u32, f64)>,
    c: usize,
    normals: &[f32],
    values: &[f32],
    channels: usize,
    slack: &[f64],
    rows: &mut [Vec<[f64; SH_COEFFS]>],
    rhs: &mut [Vec<f64>],
) -> bool {
    if v.is_empty() {
        return false;
    }
    if v.len() > SCREEN_BATCH {
        v.select_nth_unstable_by(SCREEN_BATCH, |a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        v.truncate(SCREEN_BATCH);
    }
    v.sort_unstable_by_key(|e| e.0);
    for &(p, _) in v.iter() {
        let p = p as usize;
        rows[c].push(basis(
            unit_row(&normals[3 * p..3 * p + 3])
                .expect("validated")
                .to_array(),
        ));
        rhs[c].push(values[p * channels + c] as f64 - slack[c]);
    }
    true
}

/// The state of [GI83] on one channel: x, the active constraints (indices into the working set)
/// and their multipliers.
struct GiState {
    x: [f64; SH_COEFFS],
    active: Vec<usize>,
    lambda: Vec<f64>,
    steps: usize,
}

impl GiState {
    fn new(x: [f64; SH_COEFFS]) -> Self {
        GiState {
            x,
            active: Vec::new(),
            lambda: Vec::new(),
            steps: 0,
        }
    }

    /// Goldfarb–Idnani dual active-set method for
    ///   min ½ cᵀHc − gᵀc   s.t.  aᵢᵀc ≥ bᵢ  (the rows given),
    /// continued from the current state until no given constraint is violated beyond `tol`.
    fn run(
        &mut self,
        chol: &Chol,
        a: &[[f64; SH_COEFFS]],
        b: &[f64],
        tol: f64,
        max_steps: usize,
    ) -> Result<()> {
        let (x, active, lambda) = (&mut self.x, &mut self.active, &mut self.lambda);
        loop {
            // Most violated constraint (the first of equal ones).
            let mut p = usize::MAX;
            let mut sp = f64::INFINITY;
            for (i, (r, &bi)) in a.iter().zip(b).enumerate() {
                let s = dot9(r, x) - bi;
                if s < sp {
                    sp = s;
                    p = i;
                }
            }
            if p == usize::MAX || sp >= -tol {
                return Ok(());
            }
            let np = a[p];
            let mut lam_p = 0.0f64;
            loop {
                self.steps += 1;
                if self.steps > max_steps {
                    return Err(RokebyError::numerical(
                        "SH fit",
                        "the constrained fit did not converge",
                    ));
                }
                // z = H⁻¹n − H⁻¹N r,  r = (NᵀH⁻¹N)⁻¹ NᵀH⁻¹n.
                let hn = chol.solve(&np);
                let q = active.len();
                let mut r = [0.0f64; SH_COEFFS + 1];
                let mut z = hn;
                if q > 0 {
                    let mut hcols = [[0.0f64; SH_COEFFS]; SH_COEFFS + 1];
                    for (k, &j) in active.iter().enumerate() {
                        hcols[k] = chol.solve(&a[j]);
                    }
                    let m: Vec<Vec<f64>> = (0..q)
                        .map(|i| (0..q).map(|k| dot9(&a[active[i]], &hcols[k])).collect())
                        .collect();
                    let rhs: Vec<f64> = (0..q).map(|i| dot9(&a[active[i]], &hn)).collect();
                    let sol = crate::numerical::solve_dense(m, rhs).ok_or_else(|| {
                        RokebyError::numerical(
                            "SH fit",
                            "the constrained fit's active set is degenerate",
                        )
                    })?;
                    r[..q].copy_from_slice(&sol);
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
                let s_now = dot9(&np, x) - b[p];
                let t2 = if zn > 1e-14 * dot9(&np, &np) {
                    -s_now / zn
                } else {
                    f64::INFINITY
                };
                if !t1.is_finite() && !t2.is_finite() {
                    return Err(RokebyError::invalid(
                        "values",
                        "constrained SH fit is infeasible",
                    ));
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
}

/// A direct fit, the reference of the tests: the N×9 matrix A stored, [GI83] on all N
/// constraints with a full pass per step.
#[cfg(test)]
pub(crate) fn fit_reference(
    normals: &[f32],
    values: &[f32],
    channels: usize,
    method: Fit,
) -> Result<ShFit> {
    fit_reference_tolerance(normals, values, channels, method, &[])
}

/// [`fit_reference`] with the constraints D(n) ≥ D0 − τ_c (`tolerance` empty: τ = 0).
#[cfg(test)]
pub(crate) fn fit_reference_tolerance(
    normals: &[f32],
    values: &[f32],
    channels: usize,
    method: Fit,
    tolerance: &[f64],
) -> Result<ShFit> {
    if channels == 0 {
        return Err(RokebyError::invalid("values", "need at least one channel"));
    }
    let ns = unit_normals(normals, "normals")?;
    let n = ns.len();
    if n == 0 {
        return Err(RokebyError::invalid("normals", "no pixels to fit"));
    }
    if values.len() != n * channels {
        return Err(RokebyError::invalid(
            "values",
            format!(
                "expected {n}×{channels} values (one row per normal), got {}",
                values.len()
            ),
        ));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(RokebyError::invalid(
            "values",
            format!(
                "value {} of pixel {} is not finite",
                i % channels,
                i / channels
            ),
        ));
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
        .reduce(
            || [[0.0; SH_COEFFS]; SH_COEFFS],
            |mut x, y| {
                for i in 0..SH_COEFFS {
                    for j in 0..SH_COEFFS {
                        x[i][j] += y[i][j];
                    }
                }
                x
            },
        );
    let trace: f64 = (0..SH_COEFFS).map(|i| h[i][i]).sum();
    // Mirrors the upper triangle into the lower one: h[i][j] = h[j][i] reads another row.
    #[allow(clippy::needless_range_loop)]
    for i in 0..SH_COEFFS {
        for j in 0..i {
            h[i][j] = h[j][i];
        }
        h[i][i] += 1e-9 * trace / SH_COEFFS as f64;
    }
    let chol = Chol::new(&h)
        .ok_or_else(|| RokebyError::numerical("SH fit", "the normal equations are singular"))?;
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
                Fit::Constrained => {
                    let tau = tolerance.get(c).copied().unwrap_or(0.0);
                    let rhs: Vec<f64> = b.iter().map(|v| v - tau).collect();
                    goldfarb_idnani(&chol, x0, &a, &rhs)
                }
            }
        })
        .collect();
    let mut out = ShFit {
        coeffs: vec![],
        max_residual: vec![],
        rms_residual: vec![],
        iterations: vec![],
    };
    for (c, r) in per_channel.into_iter().enumerate() {
        let (x, it) = r?;
        let (mx, ss) = a
            .par_iter()
            .enumerate()
            .map(|(i, row)| {
                let d = values[i * channels + c] as f64 - dot9(row, &x);
                (d, d * d)
            })
            .reduce(
                || (f64::NEG_INFINITY, 0.0),
                |p, q| (p.0.max(q.0), p.1 + q.1),
            );
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
type Chol = crate::numerical::DenseCholesky<SH_COEFFS>;

/// Goldfarb–Idnani dual active-set method for
///   min ½ cᵀHc − gᵀc   s.t.  aᵢᵀc ≥ bᵢ  (i = 1..N),
/// started at the unconstrained optimum x0 = H⁻¹g. Returns the optimum and the number of steps.
/// A direct solver (a full pass over all N constraints per step), the tests' reference.
#[cfg(test)]
fn goldfarb_idnani(
    chol: &Chol,
    mut x: [f64; SH_COEFFS],
    a: &[[f64; SH_COEFFS]],
    b: &[f64],
) -> Result<([f64; SH_COEFFS], usize)> {
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
            .reduce(
                || (usize::MAX, f64::INFINITY),
                |u, v| if v.1 < u.1 { v } else { u },
            );
        if p == usize::MAX || sp >= -tol {
            return Ok((x, steps));
        }
        let np = a[p];
        let mut lam_p = 0.0f64;
        loop {
            steps += 1;
            if steps > max_steps {
                return Err(RokebyError::numerical(
                    "SH fit",
                    "the constrained fit did not converge",
                ));
            }
            // z = H⁻¹n − H⁻¹N r,  r = (NᵀH⁻¹N)⁻¹ NᵀH⁻¹n.
            let hn = chol.solve(&np);
            let q = active.len();
            let mut r = vec![0.0; q];
            let mut z = hn;
            if q > 0 {
                let hcols: Vec<[f64; SH_COEFFS]> =
                    active.iter().map(|&j| chol.solve(&a[j])).collect();
                let m: Vec<Vec<f64>> = (0..q)
                    .map(|i| (0..q).map(|k| dot9(&a[active[i]], &hcols[k])).collect())
                    .collect();
                let rhs: Vec<f64> = (0..q).map(|i| dot9(&a[active[i]], &hn)).collect();
                r = crate::numerical::solve_dense(m, rhs).ok_or_else(|| {
                    RokebyError::numerical(
                        "SH fit",
                        "the constrained fit's active set is degenerate",
                    )
                })?;
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
            let t2 = if zn > 1e-14 * dot9(&np, &np) {
                -s_now / zn
            } else {
                f64::INFINITY
            };
            if !t1.is_finite() && !t2.is_finite() {
                return Err(RokebyError::invalid(
                    "values",
                    "constrained SH fit is infeasible",
                ));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_patch_leaves_out_unusable_rows() {
        let (ns, vs) = scene(200, 3, 0.0, 0.0, 5);
        let mut n2 = ns.clone();
        let mut v2 = vs.clone();
        n2.extend_from_slice(&[0.0, 0.0, 0.0, f32::NAN, 0.0, 1.0]);
        v2.extend_from_slice(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0]);
        let p = fit_patch(&n2, &v2, 3, Fit::LeastSquares, &[]).unwrap();
        assert_eq!((p.pixels, p.masked), (ns.len() / 3, 2));
        assert_eq!(
            p.fit.coeffs,
            fit(&ns, &vs, 3, Fit::LeastSquares).unwrap().coeffs
        );
        let e = fit_patch(&[0.0; 3], &[1.0; 3], 3, Fit::Constrained, &[]).unwrap_err();
        assert!(e.to_string().starts_with("normals: no usable pixel"), "{e}");
    }

    /// Deterministic pseudo-random numbers in [0, 1) (splitmix64).
    fn rand01(state: &mut u64) -> f64 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// N random normals (not unit, as the fit normalises them) and C channels of D0: a known SH
    /// environment, `occl` of the pixels darkened (occlusion), plus noise of amplitude `noise`.
    const TRUTH: [[f64; SH_COEFFS]; 3] = [
        [1.2, 0.3, 0.5, -0.2, 0.1, 0.05, 0.15, -0.05, 0.04],
        [1.0, 0.2, 0.45, -0.1, 0.05, 0.02, 0.1, -0.04, 0.03],
        [0.9, 0.1, 0.4, 0.0, 0.02, 0.01, 0.08, -0.02, 0.02],
    ];

    fn scene(n: usize, channels: usize, occl: f64, noise: f64, seed: u64) -> (Vec<f32>, Vec<f32>) {
        let mut st = seed;
        let truth = TRUTH;
        let mut ns = Vec::with_capacity(3 * n);
        let mut vs = Vec::with_capacity(channels * n);
        for _ in 0..n {
            let z = 2.0 * rand01(&mut st) - 1.0;
            let phi = std::f64::consts::TAU * rand01(&mut st);
            let r = (1.0 - z * z).sqrt();
            let len = 0.5 + rand01(&mut st);
            let u = [r * phi.cos(), r * phi.sin(), z];
            ns.extend(u.map(|x| (x * len) as f32));
            let un = unit_row(&ns[ns.len() - 3..]).unwrap().to_array();
            let dark = if rand01(&mut st) < occl { 0.5 } else { 1.0 };
            for c in 0..channels {
                let e = noise * (2.0 * rand01(&mut st) - 1.0);
                vs.push((eval(&truth[c % 3], un) * dark + e) as f32);
            }
        }
        (ns, vs)
    }

    /// Relative RMS of D(n) − D_true(n) over 2000 directions spread over the sphere.
    fn error_vs_truth(f: &ShFit, c: usize) -> f64 {
        let (mut e2, mut t2) = (0.0, 0.0);
        let m = 2000;
        for i in 0..m {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / m as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = std::f64::consts::PI * (3.0 - 5f64.sqrt()) * i as f64;
            let n = [r * phi.cos(), r * phi.sin(), z];
            let t = eval(&TRUTH[c], n);
            e2 += (eval(&f.coeffs[c], n) - t).powi(2);
            t2 += t * t;
        }
        (e2 / t2).sqrt()
    }

    #[test]
    fn noise_tolerance_keeps_the_qp_near_the_truth_on_noisy_pixels() {
        // 20% of the pixels occluded (×0.5), uniform noise of ±0.06 (σ ≈ 0.035) on every pixel.
        let (ns, vs) = scene(30_000, 3, 0.2, 0.06, 11);
        let qp = fit(&ns, &vs, 3, Fit::Constrained).unwrap();
        let ls = fit(&ns, &vs, 3, Fit::LeastSquares).unwrap();
        let tau = [0.06; 3];
        let tol = fit_with_tolerance(&ns, &vs, 3, Fit::Constrained, &tau).unwrap();
        for (c, &tau_c) in tau.iter().enumerate() {
            let (e_qp, e_ls, e_tol) = (
                error_vs_truth(&qp, c),
                error_vs_truth(&ls, c),
                error_vs_truth(&tol, c),
            );
            // The plain QP sits on the noise peaks (+0.06 everywhere), LS on the occlusion's average
            // darkening; the tolerant QP on neither.
            assert!(
                e_tol < 0.25 * e_qp && e_tol < 0.25 * e_ls,
                "ch {c}: tolerant {e_tol} qp {e_qp} ls {e_ls}"
            );
            assert!(
                tol.max_residual[c] <= tau_c + 1e-9,
                "D0 − D(n) ≤ τ: {}",
                tol.max_residual[c]
            );
            assert!(
                tol.max_residual[c] > 0.5 * tau_c,
                "the tolerance is used: {}",
                tol.max_residual[c]
            );
        }
        // An independent check of middle τs: the direct solver (`fit_reference`: the N×9 matrix
        // stored, one Goldfarb–Idnani run over all N constraints, no screening) with b − τ.
        for t in [[0.01, 0.03, 0.05], [0.02; 3]] {
            let refq = fit_reference_tolerance(&ns, &vs, 3, Fit::Constrained, &t).unwrap();
            let mid = fit_with_tolerance(&ns, &vs, 3, Fit::Constrained, &t).unwrap();
            for c in 0..3 {
                let scale = refq.coeffs[c].iter().fold(1.0f64, |s, x| s.max(x.abs()));
                for k in 0..SH_COEFFS {
                    assert!(
                        (mid.coeffs[c][k] - refq.coeffs[c][k]).abs() <= 1e-9 * scale,
                        "τ {t:?} ch {c} k {k}: {} vs {}",
                        mid.coeffs[c][k],
                        refq.coeffs[c][k]
                    );
                }
                assert!((mid.max_residual[c] - refq.max_residual[c]).abs() <= 1e-9 * scale);
                assert!(mid.max_residual[c] <= t[c] + 1e-9);
            }
        }
        // τ = 0 is the paper's QP, bit for bit; a τ above every residual leaves the LS optimum.
        let zero = fit_with_tolerance(&ns, &vs, 3, Fit::Constrained, &[0.0; 3]).unwrap();
        assert_eq!(zero.coeffs, qp.coeffs);
        let loose = fit_with_tolerance(&ns, &vs, 3, Fit::Constrained, &[10.0; 3]).unwrap();
        assert_eq!(loose.coeffs, ls.coeffs);
        assert_eq!(loose.iterations, vec![0; 3]);
        for (t, msg) in [
            (vec![0.1; 2], "one value per channel"),
            (vec![0.1, -0.1, 0.1], "≥ 0"),
            (vec![0.1, f64::NAN, 0.1], "≥ 0"),
        ] {
            let e = fit_with_tolerance(&ns, &vs, 3, Fit::Constrained, &t)
                .unwrap_err()
                .to_string();
            assert!(e.contains("tolerance") && e.contains(msg), "{e}");
        }
        let e = fit_with_tolerance(&ns, &vs, 3, Fit::LeastSquares, &tau)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("tolerance") && e.contains("only the constrained fit"),
            "{e}"
        );
    }

    #[test]
    fn fast_fit_matches_reference() {
        for (n, ch, occl, noise, seed) in [
            (1, 1, 0.0, 0.0, 1),
            (7, 2, 0.3, 0.01, 2),
            (9000, 3, 0.2, 0.01, 3),
            (20_000, 1, 0.5, 0.002, 4),
            (CHUNK + 3, 4, 0.2, 0.05, 5),
        ] {
            let (ns, vs) = scene(n, ch, occl, noise, seed);
            for m in [Fit::LeastSquares, Fit::Constrained] {
                let a = fit(&ns, &vs, ch, m).unwrap();
                let b = fit_reference(&ns, &vs, ch, m).unwrap();
                for c in 0..ch {
                    let scale = b.coeffs[c].iter().fold(1.0f64, |s, x| s.max(x.abs()));
                    for k in 0..SH_COEFFS {
                        // n = 1, 7: under-determined, the ridge picks the solution; rounding of
                        // the tiny ridge system is amplified there.
                        let tol = if n < 9 { 1e-6 } else { 1e-9 };
                        assert!(
                            (a.coeffs[c][k] - b.coeffs[c][k]).abs() <= tol * scale,
                            "n {n} {m:?} ch {c} k {k}: {} vs {}",
                            a.coeffs[c][k],
                            b.coeffs[c][k]
                        );
                    }
                    assert!((a.max_residual[c] - b.max_residual[c]).abs() <= 1e-9 * scale);
                    assert!((a.rms_residual[c] - b.rms_residual[c]).abs() <= 1e-9 * scale);
                    if m == Fit::Constrained {
                        assert!(
                            a.max_residual[c] <= 1e-12 * 3.0,
                            "QP residual {}",
                            a.max_residual[c]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn fit_is_the_same_on_any_thread_count() {
        let (ns, vs) = scene(50_000, 3, 0.2, 0.01, 9);
        let run = |t: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            pool.install(|| {
                (
                    fit(&ns, &vs, 3, Fit::LeastSquares).unwrap(),
                    fit(&ns, &vs, 3, Fit::Constrained).unwrap(),
                )
            })
        };
        let (l1, q1) = run(1);
        for t in [2, 3, 5] {
            let (l, q) = run(t);
            assert_eq!(l.coeffs, l1.coeffs);
            assert_eq!(q.coeffs, q1.coeffs);
            assert_eq!(q.iterations, q1.iterations);
            assert_eq!(q.rms_residual, q1.rms_residual);
        }
    }

    /// KKT conditions of the QP at the returned optimum, on a case where the bound holds with
    /// equality at many pixels (noise-free, occluded data: the unoccluded pixels lie on D(n) to f32
    /// rounding, so hundreds of constraints are nearly active and the full nine of them exactly):
    /// primal feasibility,
    /// stationarity H c − Aᵀb = Σ λᵢ aᵢ over the active set with λ ≥ 0, complementary slackness.
    #[test]
    fn qp_satisfies_kkt_with_many_active_constraints() {
        for (n, occl, noise, seed) in [
            (5000, 0.3, 0.0, 11),
            (20_000, 0.2, 0.0, 12),
            (20_000, 0.2, 1e-3, 13),
        ] {
            let (ns, vs) = scene(n, 1, occl, noise, seed);
            let f = fit(&ns, &vs, 1, Fit::Constrained).unwrap();
            let r = fit_reference(&ns, &vs, 1, Fit::Constrained).unwrap();
            let x = f.coeffs[0];
            // The same optimum as the direct solver (unique: H is positive definite).
            for (k, &xk) in x.iter().enumerate() {
                assert!(
                    (xk - r.coeffs[0][k]).abs() < 1e-9,
                    "k {k}: {} vs {}",
                    xk,
                    r.coeffs[0][k]
                );
            }
            // Rebuild H, g and the slacks.
            let rows: Vec<[f64; SH_COEFFS]> = ns
                .chunks_exact(3)
                .map(|c| basis(unit_row(c).unwrap().to_array()))
                .collect();
            let b: Vec<f64> = vs.iter().map(|&v| v as f64).collect();
            let mut h = [[0.0f64; SH_COEFFS]; SH_COEFFS];
            let mut g = [0.0f64; SH_COEFFS];
            for (a, &bi) in rows.iter().zip(&b) {
                for i in 0..SH_COEFFS {
                    g[i] += a[i] * bi;
                    for j in 0..SH_COEFFS {
                        h[i][j] += a[i] * a[j];
                    }
                }
            }
            let trace: f64 = (0..SH_COEFFS).map(|i| h[i][i]).sum();
            for (i, row) in h.iter_mut().enumerate() {
                row[i] += 1e-9 * trace / SH_COEFFS as f64;
            }
            let slack: Vec<f64> = rows
                .iter()
                .zip(&b)
                .map(|(a, &bi)| dot9(a, &x) - bi)
                .collect();
            let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(
                slack.iter().all(|&s| s >= -1e-12 * scale),
                "primal feasibility"
            );
            let act: Vec<usize> = (0..n)
                .filter(|&i| slack[i].abs() <= 1e-10 * scale)
                .collect();
            // Nine unknowns: at most nine independent active constraints; the noise-free cases
            // have hundreds within f32 rounding of the bound (D0 is stored in f32).
            assert!(
                act.len() >= 7,
                "expected many active constraints, got {}",
                act.len()
            );
            if noise == 0.0 {
                let near = slack.iter().filter(|&&s| s <= 1e-6 * scale).count();
                assert!(
                    near >= 100,
                    "expected hundreds of nearly active constraints, got {near}"
                );
            }
            // grad = H x − g must be a non-negative combination of the active rows: solve the
            // NNLS min ‖Σ λᵢ aᵢ − grad‖ (λ ≥ 0) by projected coordinate descent.
            let mut grad = [0.0f64; SH_COEFFS];
            for i in 0..SH_COEFFS {
                grad[i] = dot9(&h[i], &x) - g[i];
            }
            let gn = dot9(&grad, &grad).sqrt();
            assert!(gn > 1e-6, "the bound must matter in this case");
            let mut lam = vec![0.0f64; act.len()];
            let mut res = grad;
            for _ in 0..5000 {
                for (k, &i) in act.iter().enumerate() {
                    let a = &rows[i];
                    let aa = dot9(a, a);
                    let step = dot9(a, &res) / aa;
                    let new = (lam[k] + step).max(0.0);
                    let d = new - lam[k];
                    if d != 0.0 {
                        for j in 0..SH_COEFFS {
                            res[j] -= d * a[j];
                        }
                        lam[k] = new;
                    }
                }
            }
            let rn = dot9(&res, &res).sqrt();
            assert!(
                rn <= 1e-6 * gn,
                "stationarity: ‖H x − g − Aᵀλ‖ = {rn:e} of ‖H x − g‖ = {gn:e} ({} active)",
                act.len()
            );
            // Complementary slackness holds by construction (λ only on slack ≈ 0); λ ≥ 0 too.
            assert!(lam.iter().all(|&l| l >= 0.0));
        }
    }

    /// Process CPU time in ms (RAYON_NUM_THREADS=1: the one worker's time).
    pub(crate) fn cpu_ms() -> f64 {
        #[repr(C)]
        struct Timespec {
            sec: i64,
            nsec: i64,
        }
        extern "C" {
            fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
        }
        let mut ts = Timespec { sec: 0, nsec: 0 };
        // CLOCK_PROCESS_CPUTIME_ID = 2 on Linux.
        unsafe { clock_gettime(2, &mut ts) };
        ts.sec as f64 * 1e3 + ts.nsec as f64 * 1e-6
    }

    /// `cargo test --release --lib sh::tests::timing -- --ignored --nocapture` (RAYON_NUM_THREADS=1).
    #[test]
    #[ignore]
    fn timing() {
        let (ns, vs) = scene(201_756, 3, 0.2, 0.01, 7);
        for m in [Fit::LeastSquares, Fit::Constrained] {
            for (name, f) in [
                (
                    "new",
                    fit as fn(&[f32], &[f32], usize, Fit) -> Result<ShFit>,
                ),
                ("ref", fit_reference),
            ] {
                let mut ts = vec![];
                for _ in 0..7 {
                    let t = cpu_ms();
                    f(&ns, &vs, 3, m).unwrap();
                    ts.push(cpu_ms() - t);
                }
                ts.sort_by(f64::total_cmp);
                eprintln!(
                    "{m:?} {name}: {:.2} ms cpu (median of 7; min {:.2})",
                    ts[3], ts[0]
                );
            }
        }
    }
}
