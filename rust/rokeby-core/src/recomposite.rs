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
use crate::reconstruct::{reflect, unit, ParaboloidMap};
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
    let mut out = vec![0.0f32; 3 * n];
    let inv_gamma = 1.0 / p.gamma;
    let inv_eps = 1.0 / p.epsilon;
    let chord_eps = if p.epsilon >= std::f64::consts::PI { f64::INFINITY } else { 2.0 * (0.5 * p.epsilon).sin() };
    let stats = out
        .par_chunks_mut(3 * 256)
        .enumerate()
        .map(|(chunk, o)| {
            let mut st = Stats::default();
            let mut look = [0.0f64; 3];
            for (k, px) in o.chunks_exact_mut(3).enumerate() {
                let i = chunk * 256 + k;
                let img = &b.image[3 * i..3 * i + 3];
                px.copy_from_slice(img);
                let id = b.ids[i];
                if id < 0 || id as usize >= patches.len() {
                    continue;
                }
                let patch = &patches[id as usize];
                let nb = &b.normals[3 * i..3 * i + 3];
                let eb = &b.edited[3 * i..3 * i + 3];
                if nb == eb && p.k_d == 1.0 && p.k_r == 1.0 {
                    // Unmodified normal and material: eqs. 3–5 give I exactly; skip the arithmetic.
                    continue;
                }
                let opt = |v: &[f32], def: f32| if v.is_empty() { def } else { v[i] };
                let col = |v: &'_ [f32]| -> [f64; 3] { if v.is_empty() { [1.0; 3] } else { [v[3 * i] as f64, v[3 * i + 1] as f64, v[3 * i + 2] as f64] } };
                let vb = if b.view.len() == 3 { b.view } else { &b.view[3 * i..3 * i + 3] };
                let (an, ae, av) = (unit(nb), unit(eb), unit(vb));
                let d0 = &b.diffuse[3 * i..3 * i + 3];
                let r0 = &b.reflection[3 * i..3 * i + 3];
                let (ad, ar, a) = (opt(b.alpha_d, 1.0) as f64, opt(b.alpha_r, 1.0) as f64, opt(b.alpha, 1.0) as f64);
                let (cd, cr) = (col(b.diffuse_color), col(b.reflection_color));
                let finite = d0.iter().chain(r0).all(|x| x.is_finite()) && ad.is_finite() && ar.is_finite() && a.is_finite() && cd.iter().chain(&cr).all(|x| x.is_finite());
                let (Some(nn), Some(ne), Some(vv)) = (an, ae, av) else {
                    st.masked += 1;
                    continue;
                };
                if !finite || (patch.sh.is_none() && patch.env.is_none()) {
                    st.masked += 1;
                    continue;
                }
                st.edited += 1;
                // Eq. 3: D(ñ) − D(n) = Σ_k c_k (Y_k(ñ) − Y_k(n)), the basis evaluated once per normal.
                let mut dt = [0.0f64; 3];
                let mut dbasis = [0.0f64; SH_COEFFS];
                if patch.sh.is_some() {
                    let (be, bn) = (sh::basis(ne.to_array()), sh::basis(nn.to_array()));
                    for k in 0..SH_COEFFS {
                        dbasis[k] = be[k] - bn[k];
                    }
                }
                for c in 0..3 {
                    let d0c = d0[c] as f64;
                    let delta = match &patch.sh {
                        Some(co) => {
                            let mut s = 0.0;
                            for k in 0..SH_COEFFS {
                                s += co[c][k] * dbasis[k];
                            }
                            s
                        }
                        None => 0.0,
                    };
                    let res = (d0c + delta).max(d0c.min(0.0));
                    dt[c] = d0c + ad * (res - d0c);
                }
                // Eq. 4. The angle from the chord |r − r~| = 2 sin(θ/2): v = 1 without any
                // trigonometry once the chord reaches 2 sin(ε/2); exactly 0 when r~ = r.
                let mut rt = [0.0f64; 3];
                let r = reflect(vv, nn);
                let re = reflect(vv, ne);
                let chord = (r - re).length();
                let vis = if chord >= chord_eps { 1.0 } else { 2.0 * (0.5 * chord).min(1.0).asin() * inv_eps };
                match &patch.env {
                    Some(env) if vis * ar != 0.0 => env.lookup(re, &mut look),
                    _ => look = [r0[0] as f64, r0[1] as f64, r0[2] as f64],
                }
                for c in 0..3 {
                    let r0c = r0[c] as f64;
                    rt[c] = r0c + vis * ar * (look[c] - r0c);
                }
                // Eq. 5.
                for c in 0..3 {
                    let shade = p.k_d * (cd[c] * dt[c]) + p.k_r * (cr[c] * rt[c]);
                    let shade0 = cd[c] * d0[c] as f64 + cr[c] * r0[c] as f64;
                    let g = |x: f64| if p.gamma == 1.0 { x } else { x.max(0.0).powf(inv_gamma) };
                    px[c] = (img[c] as f64 + a * (g(shade) - g(shade0))) as f32;
                }
            }
            st
        })
        .reduce(Stats::default, |x, y| Stats { masked: x.masked + y.masked, edited: x.edited + y.edited });
    Ok((out, stats))
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
