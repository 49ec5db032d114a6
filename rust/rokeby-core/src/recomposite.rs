//! Recompositing (Zubiaga et al. 2016, §4, eqs. 3–5): new shading from edited normals ñ.
//!
//! ```text
//!   D~ = α_D [D0 − D(n) + D(ñ)] + (1 − α_D) D0                                   (eq. 3)
//!   R~ = v α_R R(r~) + (1 − v α_R) R0,  v = min(1, acos(r·r~)/ε), ε = 0.005π       (eq. 4)
//!   I~ = α (k_D D~ + k_R R~)^(1/γ) + (1 − α) I                                    (eq. 5)
//! ```
//!
//! Written so that unmodified normals give the input back **bit for bit** (tested), not merely
//! up to rounding:
//! * eq. 3 as D0 + α_D([D0 + (D(ñ) − D(n))] − D0): with ñ = n the SH difference is exactly 0
//!   and the bracket is D0. The clamp [·] is max(min(0, D0), ·): it keeps edits non-negative
//!   without moving a (noisy) negative D0 that was not edited.
//! * eq. 4 as R0 + vα_R(R(r~) − R0), with the angle 2·atan2(‖r − r~‖, ‖r + r~‖), which is exactly
//!   0 when r~ = r (acos(r·r) is not, for a dot product rounded below 1).
//! * eq. 5 as I + α[(k_D c_D D~ + k_R c_R R~)^(1/γ) − (c_D D0 + c_R R0)^(1/γ)]: the same as the
//!   paper's where I = (c_D D0 + c_R R0)^(1/γ), and it keeps what I holds besides diffuse and
//!   reflection shading (emission, transmission, …) where it does not. c_D, c_R are the renderer's
//!   reflectance (colour) buffers when diffuse/reflection *illumination* is given (Cycles'
//!   DiffDir + DiffInd and DiffCol; the paper's §6 extension to spatially varying reflectance),
//!   else 1.
//!
//! Pixels without a patch (id < 0), of a patch without reconstruction, or with a non-finite input
//! other than I are returned as I unchanged (counted in [`Stats::masked`]).

use crate::error::{Result, RokebyError};
use crate::reconstruct::{unit, ParaboloidMap};
use crate::sh::{self, SH_COEFFS};
use rayon::prelude::*;

/// ε of eq. 4.
pub const EPSILON: f64 = 0.005 * std::f64::consts::PI;

/// What was reconstructed for one object/material patch.
#[derive(Debug, Clone, Default)]
pub struct Patch {
    /// Three channels' SH coefficients (eq. 1), or None: diffuse is not edited.
    pub sh: Option<[[f64; SH_COEFFS]; 3]>,
    /// Reflection environment (3 channels), or None: reflection is not edited.
    pub env: Option<ParaboloidMap>,
}

#[derive(Debug, Clone, Copy)]
pub struct Params {
    pub k_d: f64,
    pub k_r: f64,
    pub gamma: f64,
    pub epsilon: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params { k_d: 1.0, k_r: 1.0, gamma: 1.0, epsilon: EPSILON }
    }
}

/// Per-pixel buffers, all row-major H·W (×3 where a colour/vector). Optional ones may be empty.
pub struct Buffers<'a> {
    pub ids: &'a [i32],
    pub normals: &'a [f32],
    pub edited: &'a [f32],
    /// View vectors (surface → eye), H·W×3, or one vector (3) for an orthographic camera.
    pub view: &'a [f32],
    pub diffuse: &'a [f32],
    pub reflection: &'a [f32],
    pub alpha_d: &'a [f32],
    pub alpha_r: &'a [f32],
    pub alpha: &'a [f32],
    pub image: &'a [f32],
    pub diffuse_color: &'a [f32],
    pub reflection_color: &'a [f32],
}

#[derive(Debug, Clone, Copy, Default)]
pub struct Stats {
    /// Pixels returned unchanged because an input was not finite or the patch has nothing.
    pub masked: usize,
    /// Pixels recomposited (normal edited, or k_D, k_R ≠ 1).
    pub edited: usize,
}

fn check(name: &str, v: &[f32], want: usize, optional: bool) -> Result<()> {
    if (optional && v.is_empty()) || v.len() == want {
        Ok(())
    } else {
        Err(RokebyError::invalid(name, format!("expected {want} values{}, got {}", if optional { " or none" } else { "" }, v.len())))
    }
}

/// Eqs. 3–5 for every pixel; returns I~ (H·W×3).
pub fn recomposite(b: &Buffers, patches: &[Patch], p: &Params) -> Result<(Vec<f32>, Stats)> {
    let n = b.ids.len();
    check("normals", b.normals, 3 * n, false)?;
    check("edited_normals", b.edited, 3 * n, false)?;
    if b.view.len() != 3 {
        check("view", b.view, 3 * n, false)?;
    }
    check("diffuse", b.diffuse, 3 * n, false)?;
    check("reflection", b.reflection, 3 * n, false)?;
    check("alpha_d", b.alpha_d, n, true)?;
    check("alpha_r", b.alpha_r, n, true)?;
    check("alpha", b.alpha, n, true)?;
    check("image", b.image, 3 * n, false)?;
    check("diffuse_color", b.diffuse_color, 3 * n, true)?;
    check("reflection_color", b.reflection_color, 3 * n, true)?;
    if !(p.gamma > 0.0 && p.gamma.is_finite()) {
        return Err(RokebyError::invalid("gamma", format!("must be positive and finite, got {}", p.gamma)));
    }
    if !(p.epsilon > 0.0) {
        return Err(RokebyError::invalid("epsilon", "must be positive"));
    }
    if !(p.k_d.is_finite() && p.k_r.is_finite()) {
        return Err(RokebyError::invalid("k_d", "k_d and k_r must be finite"));
    }
    if let Some(e) = patches.iter().filter_map(|q| q.env.as_ref()).find(|e| e.channels != 3) {
        return Err(RokebyError::invalid("patches", format!("reflection maps must have 3 channels, got {}", e.channels)));
    }
    // The fuzzer found an empty (size 0) map panicking in the lookup's clamp.
    if let Some(e) = patches.iter().filter_map(|q| q.env.as_ref()).find(|e| e.size == 0 || e.data.len() != 2 * e.size * e.size * e.channels) {
        return Err(RokebyError::invalid("patches", format!("reflection map of size {} holds {} values, expected 2×size×size×3 with size ≥ 1", e.size, e.data.len())));
    }
    // Per-patch constants, once per frame: f32 SH coefficients (channel-major) and flags.
    let sh32: Vec<Option<[[f32; SH_COEFFS]; 3]>> = patches.iter().map(|q| q.sh.map(|c| c.map(|ch| ch.map(|x| x as f32)))).collect();
    let (k_d, k_r) = (p.k_d as f32, p.k_r as f32);
    let unit_material = p.k_d == 1.0 && p.k_r == 1.0;
    let inv_gamma = (1.0 / p.gamma) as f32;
    let gamma_one = p.gamma == 1.0;
    let inv_eps = (1.0 / p.epsilon) as f32;
    let chord_eps = if p.epsilon >= std::f64::consts::PI { f32::INFINITY } else { (2.0 * (0.5 * p.epsilon).sin()) as f32 };
    let const_view = if b.view.len() == 3 { unit(b.view).map(to32) } else { None };
    let g = |x: f32| if gamma_one { x } else { x.max(0.0).powf(inv_gamma) };
    // Rows in parallel; every pixel starts as I (one copy), and only pixels whose normal or
    // material changed run eqs. 3–5 — in f32 (the buffers' precision): with ñ = n the formulas
    // below still give I bit for bit (zero SH difference, zero chord, identical shade and shade0).
    let mut out = b.image.to_vec();
    const CHUNK: usize = 1024;
    let stats = out
        .par_chunks_mut(3 * CHUNK)
        .enumerate()
        .map(|(chunk, o)| {
            let mut st = Stats::default();
            for (k, px) in o.chunks_exact_mut(3).enumerate() {
                let i = chunk * CHUNK + k;
                let id = b.ids[i];
                if id < 0 || id as usize >= patches.len() {
                    continue;
                }
                let nb = &b.normals[3 * i..3 * i + 3];
                let eb = &b.edited[3 * i..3 * i + 3];
                if unit_material && nb == eb {
                    // Unmodified normal and material: eqs. 3–5 give I exactly; skip the arithmetic.
                    continue;
                }
                let patch = &patches[id as usize];
                let sh = &sh32[id as usize];
                if sh.is_none() && patch.env.is_none() {
                    st.masked += 1;
                    continue;
                }
                let opt = |v: &[f32]| if v.is_empty() { 1.0 } else { v[i] };
                let col = |v: &[f32]| -> [f32; 3] { if v.is_empty() { [1.0; 3] } else { [v[3 * i], v[3 * i + 1], v[3 * i + 2]] } };
                let d0 = [b.diffuse[3 * i], b.diffuse[3 * i + 1], b.diffuse[3 * i + 2]];
                let r0 = [b.reflection[3 * i], b.reflection[3 * i + 1], b.reflection[3 * i + 2]];
                let (ad, ar, a) = (opt(b.alpha_d), opt(b.alpha_r), opt(b.alpha));
                let (cd, cr) = (col(b.diffuse_color), col(b.reflection_color));
                let finite = d0.iter().chain(&r0).chain(&cd).chain(&cr).all(|x| x.is_finite()) && ad.is_finite() && ar.is_finite() && a.is_finite();
                let vv = match const_view {
                    Some(v) => Some(v),
                    None if b.view.len() == 3 => None,
                    None => unit(&b.view[3 * i..3 * i + 3]).map(to32),
                };
                let (Some(nn), Some(ne), Some(vv)) = (unit(nb).map(to32), unit(eb).map(to32), vv) else {
                    st.masked += 1;
                    continue;
                };
                if !finite {
                    st.masked += 1;
                    continue;
                }
                st.edited += 1;
                // Eq. 3: D(ñ) − D(n) = Σ_k c_k (Y_k(ñ) − Y_k(n)), the basis evaluated once per normal.
                let mut dt = [0.0f32; 3];
                let dbasis = if sh.is_some() {
                    let (be, bn) = (basis32(ne), basis32(nn));
                    std::array::from_fn(|k| be[k] - bn[k])
                } else {
                    [0.0f32; SH_COEFFS]
                };
                for c in 0..3 {
                    let delta = match sh {
                        Some(co) => {
                            let mut s = 0.0f32;
                            for k in 0..SH_COEFFS {
                                s += co[c][k] * dbasis[k];
                            }
                            s
                        }
                        None => 0.0,
                    };
                    let res = (d0[c] + delta).max(d0[c].min(0.0));
                    dt[c] = d0[c] + ad * (res - d0[c]);
                }
                // Eq. 4. The angle from the chord |r − r~| = 2 sin(θ/2): v = 1 without any
                // trigonometry once the chord reaches 2 sin(ε/2); exactly 0 when r~ = r.
                let r = reflect32(vv, nn);
                let re = reflect32(vv, ne);
                let dr = [r[0] - re[0], r[1] - re[1], r[2] - re[2]];
                let chord = (dr[0] * dr[0] + dr[1] * dr[1] + dr[2] * dr[2]).sqrt();
                let vis = if chord >= chord_eps { 1.0 } else { 2.0 * (0.5 * chord).min(1.0).asin() * inv_eps };
                let look = match &patch.env {
                    Some(env) if vis * ar != 0.0 => lookup32(env, re),
                    _ => r0,
                };
                // Eqs. 4 and 5.
                for c in 0..3 {
                    let rt = r0[c] + vis * ar * (look[c] - r0[c]);
                    let shade = k_d * (cd[c] * dt[c]) + k_r * (cr[c] * rt);
                    let shade0 = cd[c] * d0[c] + cr[c] * r0[c];
                    px[c] += a * (g(shade) - g(shade0));
                }
            }
            st
        })
        .reduce(Stats::default, |x, y| Stats { masked: x.masked + y.masked, edited: x.edited + y.edited });
    Ok((out, stats))
}

#[inline]
fn to32(v: glam::DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

#[inline]
fn reflect32(v: [f32; 3], n: [f32; 3]) -> [f32; 3] {
    let d = 2.0 * (n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
    [d * n[0] - v[0], d * n[1] - v[1], d * n[2] - v[2]]
}

/// [`sh::basis`] in f32.
#[inline]
fn basis32(n: [f32; 3]) -> [f32; SH_COEFFS] {
    let [x, y, z] = n;
    let (c0, c1, c2) = (0.282_094_8_f32, 0.488_602_5_f32, 1.092_548_4_f32);
    [c0, c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z, 0.315_391_57 * (3.0 * z * z - 1.0), c2 * x * z, 0.546_274_2 * (x * x - y * y)]
}

/// `ParaboloidMap::lookup` for 3 channels in f32: the same face choice, texel convention (texel
/// centres, coordinates clamped to the map) and bilinear weights.
#[inline]
fn lookup32(m: &ParaboloidMap, d: [f32; 3]) -> [f32; 3] {
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = if l > 0.0 && l.is_finite() { [d[0] / l, d[1] / l, d[2] / l] } else { [0.0, 0.0, 1.0] };
    let face = usize::from(d[2] < 0.0);
    let k = 1.0 / (1.0 + d[2].abs());
    let s = m.size as f32;
    let x = ((d[0] * k + 1.0) * 0.5 * s - 0.5).clamp(0.0, s - 1.0);
    let y = ((d[1] * k + 1.0) * 0.5 * s - 0.5).clamp(0.0, s - 1.0);
    let (j0, i0) = (x as usize, y as usize);
    let (j1, i1) = ((j0 + 1).min(m.size - 1), (i0 + 1).min(m.size - 1));
    let (fx, fy) = (x - j0 as f32, y - i0 as f32);
    let idx = |i: usize, j: usize| ((face * m.size + i) * m.size + j) * 3;
    let (k00, k01, k10, k11) = (idx(i0, j0), idx(i0, j1), idx(i1, j0), idx(i1, j1));
    let t = &m.data;
    std::array::from_fn(|c| {
        let top = t[k00 + c] + fx * (t[k01 + c] - t[k00 + c]);
        let bot = t[k10 + c] + fx * (t[k11 + c] - t[k10 + c]);
        top + fy * (bot - top)
    })
}

/// Reconstructed diffuse D(n) per pixel (H·W×3; the SH of each pixel's patch; 0 without one) —
/// for visualising and validating eq. 1.
pub fn eval_diffuse(ids: &[i32], normals: &[f32], patches: &[Patch]) -> Result<Vec<f32>> {
    check("normals", normals, 3 * ids.len(), false)?;
    let mut out = vec![0.0f32; 3 * ids.len()];
    out.par_chunks_mut(3).enumerate().for_each(|(i, o)| {
        let id = ids[i];
        if id < 0 || id as usize >= patches.len() {
            return;
        }
        if let (Some(co), Some(n)) = (&patches[id as usize].sh, unit(&normals[3 * i..3 * i + 3])) {
            for c in 0..3 {
                o[c] = sh::eval(&co[c], n.to_array()) as f32;
            }
        }
    });
    Ok(out)
}
