//! Prefiltered environment maps for shading under environment light (Fraser, "Interactive
//! Real-Time BRDF Editing under Environment Lighting"; Ramamoorthi & Hanrahan 2001, 2002).
//!
//! The reflection equation (Fraser, eq. 1)
//! ```text
//!   I(x, ω_o) = ∫_Ω L(ω_i) ρ(ω_i, ω_o) max(0, ω_i·n) dω_i
//! ```
//! and the seed's brute-force sum over an N×M lat-long map (Fraser, eq. 2)
//! ```text
//!   I ≈ Σ_u Σ_v E(u, v) ρ(ω_i, ω_o) max(0, ω_i·n) sin(vπ/M) (π/M)(2π/N)
//! ```
//! are precomputed here once per environment and lobe, as functions of one direction:
//!
//! * **Diffuse** — order-2 spherical harmonics (Ramamoorthi & Hanrahan 2001, "An efficient
//!   representation for irradiance environment maps"): L_lm = ∫ L Y_lm dω, irradiance
//!   E(n) = Σ_lm Â_l L_lm Y_lm(n) with Â_0 = π, Â_1 = 2π/3, Â_2 = π/4. Maps store E(n)/π, the
//!   radiance of a white Lambertian surface, so a constant environment stays constant. The basis
//!   is `sh::basis` (the compositing module), shared.
//! * **Specular** — a radially symmetric lobe k(r·ω_i) about the reflected direction r,
//!   normalised: P(r) = ∫ L(ω) k(r·ω) dω / ∫ k(r·ω) dω. The lobes:
//!   - [`Lobe::Phong`]: k = max(0, c)^σ. With Fraser's normalisation (1 + σ)/(2π) this is the
//!     reflection equation of the specular Phong BRDF exactly (the cos θ_i of the equation cancels
//!     the BRDF's 1/(ω_i·n)), so P is the rendered specular radiance for k_s = 1.
//!   - [`Lobe::Ggx`] (Walter et al. 2007; Blender's roughness r, α = r²) and
//!     [`Lobe::TorranceSparrow`] (Fraser's simplified form, S = exp(−(θ_h/σ)²)/(πσ²)): microfacet
//!     lobes, prefiltered with the split-sum assumption n = v = r (Karis 2013), under which the
//!     half vector makes θ_h = γ/2 with γ the angle between r and ω_i. GGX keeps the n·ω_i weight
//!     (k = D(h)·c), Fraser's Torrance–Sparrow divides it out (k = S(θ_h)). P is then the
//!     prefiltered radiance; the full integral is P times the lobe's directional albedo.
//!
//! **Fast specular prefiltering** (multi-scale ring convolution). On a lat-long grid every
//! texel of a row sees the same kernel shifted in φ: for output row i and source row j the sum
//! over the source row is a 1D circular convolution with weights
//! w_ij(Δφ) = k(sin λ_i sin λ_j + cos λ_i cos λ_j cos Δφ)·Ω_j, each applied to a whole row at once
//! (contiguous, vectorised). The lobe is split by a smooth partition of unity into rings
//! [0, 2R₀], [R₀, 4R₀], [2R₀, 8R₀], …, R₀ its half-energy angle; ring k is evaluated on the
//! solid-angle-weighted 2×2 mip of the input whose texels are nearest R_k/K wide (K = 6, so
//! R_k spans K/√2 to K√2 texels; never finer than the input), and its output (numerator and weight sum) upsampled bilinearly to the level's
//! resolution (ring 0's). Outer rings, where the lobe is smooth, thus cost what the core costs, and
//! heavy tails (GGX) are kept out to where less than `tail` = 1e-5 of the lobe's energy is left.
//! Numerator and denominator go through the same linear steps, so a constant environment comes
//! out constant to rounding. The cost of the approximation (texels averaged within 1/K of the
//! ring radius, bilinear upsampling, energy cut) is measured against [`brute_force`] in
//! docs/envmaps.md.

use crate::compositing::sh::{basis, SH_COEFFS};
use crate::envmaps::envmap::{finite_dirs, latlong_texel_solid_angle, EnvMap, Layout};
use crate::error::{Result, RokebyError};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{PI, TAU};

/// A radially symmetric specular lobe about the reflected direction (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lobe {
    /// Normalised Phong, exponent σ ≥ 0.
    Phong { sigma: f64 },
    /// GGX / Trowbridge–Reitz with α = roughness² (0 ≤ roughness ≤ 1).
    Ggx { alpha: f64 },
    /// Fraser's simplified Torrance–Sparrow, σ ≥ 0 (radians of half-angle; larger is rougher).
    TorranceSparrow { sigma: f64 },
    /// The reflection maps' blur (`reflection/render/reflmap.py`, the levels of a captured
    /// panorama): a Gaussian of angular standard deviation σ ≥ 0 radians about r, applied
    /// separably on the lat-long grid at its own resolution (see [`gaussian_level`]). Its
    /// [`Lobe::kernel`], exp(−γ²/2σ²), is the spherical Gaussian it approximates (for
    /// [`brute_force`]).
    Gaussian { sigma: f64 },
}

impl Lobe {
    pub fn phong(sigma: f64) -> Result<Lobe> {
        if !sigma.is_finite() || sigma < 0.0 {
            return Err(RokebyError::invalid(
                "exponent",
                format!("Phong exponent σ must be finite and ≥ 0, got {sigma}"),
            ));
        }
        Ok(Lobe::Phong { sigma })
    }

    pub fn ggx_roughness(roughness: f64) -> Result<Lobe> {
        if !roughness.is_finite() || !(0.0..=1.0).contains(&roughness) {
            return Err(RokebyError::invalid(
                "roughness",
                format!("GGX roughness must be in [0, 1], got {roughness}"),
            ));
        }
        Ok(Lobe::Ggx {
            alpha: roughness * roughness,
        })
    }

    pub fn torrance_sparrow(sigma: f64) -> Result<Lobe> {
        if !sigma.is_finite() || sigma < 0.0 {
            return Err(RokebyError::invalid(
                "sigma",
                format!("Torrance–Sparrow σ must be finite and ≥ 0, got {sigma}"),
            ));
        }
        Ok(Lobe::TorranceSparrow { sigma })
    }

    pub fn gaussian(sigma: f64) -> Result<Lobe> {
        if !sigma.is_finite() || sigma < 0.0 {
            return Err(RokebyError::invalid(
                "sigma",
                format!("Gaussian σ must be finite and ≥ 0 (radians), got {sigma}"),
            ));
        }
        Ok(Lobe::Gaussian { sigma })
    }

    /// A delta lobe (GGX α ≤ 1e-12, or σ_TS = 0): the prefiltered map is the environment itself.
    pub fn is_mirror(&self) -> bool {
        match *self {
            Lobe::Phong { .. } => false,
            // Below 1e-12 rad the lobe is a delta at any resolution, and its peak 1/(πα²) would
            // overflow (the fuzzer found α = 2.3e-10 giving k(1) = inf before the stable t below).
            Lobe::Ggx { alpha } => alpha <= 1e-12,
            Lobe::TorranceSparrow { sigma } | Lobe::Gaussian { sigma } => sigma <= 0.0,
        }
    }

    /// Unnormalised kernel k(c), c = r·ω_i (zero for c ≤ 0: below the surface when n = r).
    #[inline]
    pub fn kernel(&self, c: f64) -> f64 {
        if c <= 0.0 {
            return 0.0;
        }
        let c = c.min(1.0);
        // A mirror lobe (GGX α = 0, Torrance–Sparrow σ = 0) is a delta: its kernel is the indicator
        // of c = 1 (the fuzzer found 0/0 = NaN at c = 1). Mirror levels never use the kernel.
        if self.is_mirror() {
            return if c >= 1.0 { 1.0 } else { 0.0 };
        }
        match *self {
            Lobe::Phong { sigma } => c.powf(sigma),
            Lobe::Ggx { alpha } => {
                // cos²θ_h = (1 + c)/2 (h halves the angle between n = r and ω_i).
                let a2 = alpha * alpha;
                let ch2 = 0.5 * (1.0 + c);
                // ch2·(α² − 1) + 1 without cancelling α² against 1 (t = 0 for tiny α at c = 1).
                let t = 0.5 * (1.0 - c) + ch2 * a2;
                a2 / (PI * t * t) * c
            }
            Lobe::TorranceSparrow { sigma } => {
                let th = (0.5 * (1.0 + c)).sqrt().min(1.0).acos();
                (-(th / sigma) * (th / sigma)).exp()
            }
            Lobe::Gaussian { sigma } => {
                let g = c.acos() / sigma;
                (-0.5 * g * g).exp()
            }
        }
    }

    /// Angles (radians) within which half, and all but `tail`, of the lobe's energy
    /// ∫ k(cos γ) sin γ dγ lies (trapezoid rule on a grid refined quadratically towards γ = 0).
    pub fn radii(&self, tail: f64) -> (f64, f64) {
        const N: usize = 1 << 14;
        let g = |i: usize| 0.5 * PI * (i as f64 / N as f64).powi(2);
        let f = |i: usize| {
            let x = g(i);
            self.kernel(x.cos()) * x.sin()
        };
        let mut cum = vec![0.0f64; N + 1];
        for i in 1..=N {
            cum[i] = cum[i - 1] + 0.5 * (f(i) + f(i - 1)) * (g(i) - g(i - 1));
        }
        let total = cum[N];
        if total.is_nan() || total <= 0.0 {
            return (0.0, 0.0);
        }
        let find = |frac: f64| -> f64 {
            let target = frac * total;
            let i = cum.partition_point(|&v| v < target).clamp(1, N);
            let (a, b) = (cum[i - 1], cum[i]);
            let t = if b > a { (target - a) / (b - a) } else { 1.0 };
            g(i - 1) + t * (g(i) - g(i - 1))
        };
        (find(0.5), find(1.0 - tail).max(find(0.5)))
    }
}

/// Rows kept by lobes with a step at the horizon (see [`prefilter`]).
pub const STEP_ROWS: usize = 64;

/// Tuning of [`prefilter`].
#[derive(Debug, Clone, Copy)]
pub struct PrefilterParams {
    /// K: texels per ring radius on the mip a ring is evaluated on.
    pub texels_per_radius: f64,
    /// Fraction of the lobe's energy left out beyond the last ring.
    pub tail: f64,
}

impl Default for PrefilterParams {
    fn default() -> Self {
        PrefilterParams {
            texels_per_radius: 6.0,
            tail: 1e-5,
        }
    }
}

/// One prefiltered level.
#[derive(Debug, Clone)]
pub struct Level {
    /// The prefiltered lat-long map at the level's own resolution (the input's for sharp lobes,
    /// coarser mips for rough ones).
    pub map: EnvMap,
    /// Half-energy angle R₀ and the cut-off angle of the lobe (radians).
    pub core_radius: f64,
    pub cut_radius: f64,
    /// Rings evaluated (0 for a mirror level, which copies the input, and for a
    /// [`Lobe::Gaussian`] level, which is blurred separably).
    pub rings: usize,
}

/// The prefiltering works on lat-long maps. Values need only be finite (checked by `EnvMap::new`):
/// every step is linear, and the shipped HDRs carry small negative values from lossy compression
/// (courtyard.exr down to −1.6e-4), which the seed's sum would also just add.
fn check_latlong(env: &EnvMap, arg: &str) -> Result<()> {
    if env.layout != Layout::LatLong {
        return Err(RokebyError::invalid(
            arg,
            format!(
                "expected a lat-long map, got {} (convert it first)",
                env.layout.name()
            ),
        ));
    }
    Ok(())
}

/// Solid-angle weighted 2×2 average (None when a side is odd or the map is already tiny).
fn downsample(env: &EnvMap) -> Option<EnvMap> {
    let (h, w, c) = (env.height, env.width, env.channels);
    if h % 2 != 0 || w % 2 != 0 || h < 8 || w < 8 {
        return None;
    }
    let (h2, w2) = (h / 2, w / 2);
    let mut data = vec![0.0f32; h2 * w2 * c];
    data.par_chunks_mut(w2 * c)
        .enumerate()
        .for_each(|(i, row)| {
            let a = latlong_texel_solid_angle(h, w, 2 * i);
            let b = latlong_texel_solid_angle(h, w, 2 * i + 1);
            let (wa, wb) = ((a / (2.0 * (a + b))) as f32, (b / (2.0 * (a + b))) as f32);
            for j in 0..w2 {
                for ch in 0..c {
                    let p = |ii: usize, jj: usize| env.data[(ii * w + jj) * c + ch];
                    row[j * c + ch] = wa * (p(2 * i, 2 * j) + p(2 * i, 2 * j + 1))
                        + wb * (p(2 * i + 1, 2 * j) + p(2 * i + 1, 2 * j + 1));
                }
            }
        });
    Some(EnvMap {
        layout: Layout::LatLong,
        height: h2,
        width: w2,
        channels: c,
        data,
    })
}

/// Bilinear (seam-correct) resampling of a lat-long map to another size with aligned grids.
fn resample(env: &EnvMap, height: usize, width: usize) -> EnvMap {
    if env.height == height && env.width == width {
        return env.clone();
    }
    let c = env.channels;
    let (sx, sy) = (
        env.width as f64 / width as f64,
        env.height as f64 / height as f64,
    );
    let mut data = vec![0.0f32; height * width * c];
    data.par_chunks_mut(width * c)
        .enumerate()
        .for_each(|(i, row)| {
            for j in 0..width {
                env.sample_at(
                    0,
                    (j as f64 + 0.5) * sx,
                    (i as f64 + 0.5) * sy,
                    &mut row[j * c..(j + 1) * c],
                );
            }
        });
    EnvMap {
        layout: Layout::LatLong,
        height,
        width,
        channels: c,
        data,
    }
}

/// Smooth step from 1 (x ≤ 1) to 0 (x ≥ 2), C¹: the ring partition of unity.
#[inline]
fn ring_step(x: f64) -> f64 {
    if x <= 1.0 {
        1.0
    } else if x >= 2.0 {
        0.0
    } else {
        let t = x - 1.0;
        1.0 - t * t * (3.0 - 2.0 * t)
    }
}

/// acc += w·s, the inner loop of the ring convolution: AVX2+FMA when the CPU has them (checked
/// at run time, so the wheel stays portable), else what the compiler vectorises for the baseline.
#[inline]
fn axpy(acc: &mut [f32], s: &[f32], w: f32) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the features axpy_fma is compiled for were detected on this CPU just above.
            unsafe { axpy_fma(acc, s, w) };
            return;
        }
    }
    for (a, b) in acc.iter_mut().zip(s) {
        *a += w * b;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn axpy_fma(acc: &mut [f32], s: &[f32], w: f32) {
    for (a, b) in acc.iter_mut().zip(s) {
        *a = b.mul_add(w, *a);
    }
}

/// One ring: Σ_j Σ_Δφ w_ij(Δφ) L_j(φ + Δφ) with w = k(c)·window(γ)·Ω_j, for every texel of
/// `src`'s grid. Returns a map with channels + 1 values per texel, the last one the weight sum.
fn ring_pass(src: &EnvMap, lobe: &Lobe, r_in: Option<f64>, r_out: Option<f64>, cut: f64) -> EnvMap {
    let (h, w, c) = (src.height, src.width, src.channels);
    let lo = r_in.unwrap_or(0.0);
    let hi = r_out.map_or(cut, |r| (2.0 * r).min(cut));
    // (`hi + half` below: the horizon ramp reaches half a texel past c = 0.)
    let window =
        |g: f64| r_out.map_or(1.0, |r| ring_step(g / r)) - r_in.map_or(0.0, |r| ring_step(g / r));
    // Each source row twice in a row, so that any circular shift is one contiguous slice.
    let mut dbl = vec![0.0f32; h * 2 * w * c];
    dbl.par_chunks_mut(2 * w * c)
        .enumerate()
        .for_each(|(j, d)| {
            let s = &src.data[j * w * c..(j + 1) * w * c];
            d[..w * c].copy_from_slice(s);
            d[w * c..].copy_from_slice(s);
        });
    let lat = |i: usize| PI * (0.5 - (i as f64 + 0.5) / h as f64);
    let dlat = PI / h as f64;
    let reach = (hi / dlat).ceil() as usize + 1;
    let half = 0.5 * dlat;
    let mut out = vec![0.0f32; h * w * (c + 1)];
    out.par_chunks_mut(w * (c + 1))
        .enumerate()
        .for_each(|(i, orow)| {
            let (si, ci) = lat(i).sin_cos();
            let mut acc = vec![0.0f32; w * c];
            let mut den = 0.0f64;
            for j in i.saturating_sub(reach)..(i + reach + 1).min(h) {
                let (sj, cj) = lat(j).sin_cos();
                let omega = latlong_texel_solid_angle(h, w, j);
                let drow = &dbl[j * 2 * w * c..(j + 1) * 2 * w * c];
                for dx in 0..=w / 2 {
                    let cosg =
                        (si * sj + ci * cj * (TAU * dx as f64 / w as f64).cos()).clamp(-1.0, 1.0);
                    let g = cosg.acos();
                    if g > hi + half {
                        break;
                    }
                    if g < lo {
                        continue;
                    }
                    // The lobe ends at the horizon c = 0 (a step for low Phong exponents): weight a
                    // texel there by the part of it above (a linear ramp over its width).
                    let cover = ((cosg + half) / (2.0 * half)).clamp(0.0, 1.0);
                    let wt = lobe.kernel(cosg.max(1e-12)) * cover * window(g) * omega;
                    if wt.is_nan() || wt <= 0.0 {
                        continue;
                    }
                    let wt32 = wt as f32;
                    let other = (w - dx) % w;
                    for o in if other == dx {
                        [dx, usize::MAX]
                    } else {
                        [dx, other]
                    } {
                        if o == usize::MAX {
                            continue;
                        }
                        den += wt;
                        axpy(&mut acc, &drow[o * c..(o + w) * c], wt32);
                    }
                }
            }
            for x in 0..w {
                orow[x * (c + 1)..x * (c + 1) + c].copy_from_slice(&acc[x * c..(x + 1) * c]);
                orow[x * (c + 1) + c] = den as f32;
            }
        });
    EnvMap {
        layout: Layout::LatLong,
        height: h,
        width: w,
        channels: c + 1,
        data: out,
    }
}

/// The most lobe parameters [`prefilter`] takes in one call (a roughness ladder has 5–10).
pub const MAX_LOBES: usize = 256;

/// Specular prefiltering of a lat-long environment for each lobe (see the module docs).
/// Cancellable between rings ([`crate::cancel`]).
pub fn prefilter(env: &EnvMap, lobes: &[Lobe], params: &PrefilterParams) -> Result<Vec<Level>> {
    check_latlong(env, "image")?;
    if !(params.texels_per_radius.is_finite() && params.texels_per_radius >= 1.0) {
        return Err(RokebyError::invalid(
            "texels_per_radius",
            format!("must be ≥ 1, got {}", params.texels_per_radius),
        ));
    }
    if !(params.tail.is_finite() && params.tail > 0.0 && params.tail < 0.5) {
        return Err(RokebyError::invalid(
            "tail",
            format!("must be in (0, 0.5), got {}", params.tail),
        ));
    }
    if lobes.len() > MAX_LOBES {
        return Err(RokebyError::invalid(
            "params",
            format!(
                "at most {MAX_LOBES} lobe parameters in one call, got {}",
                lobes.len()
            ),
        ));
    }
    // Every level can be as large as the input: bound the whole result before computing any.
    crate::alloc::check::<f32>(
        "prefiltered levels (params × image)",
        &[lobes.len() + 1, env.data.len()],
    )?;
    let mut mips = vec![env.clone()];
    // Only the ring convolution uses the mip chain.
    let rings = lobes
        .iter()
        .any(|l| !l.is_mirror() && !matches!(l, Lobe::Gaussian { .. }));
    if rings {
        while let Some(m) = downsample(mips.last().expect("non-empty")) {
            mips.push(m);
        }
    }
    let texel = |m: usize| PI / mips[m].height as f64;
    let kk = params.texels_per_radius;
    let mut levels = Vec::with_capacity(lobes.len());
    for lobe in lobes {
        crate::cancel::check()?;
        if let (Lobe::Gaussian { sigma }, false) = (*lobe, lobe.is_mirror()) {
            levels.push(gaussian_level(env, sigma)?);
            continue;
        }
        let (r0, cut) = if lobe.is_mirror() {
            (0.0, 0.0)
        } else {
            lobe.radii(params.tail)
        };
        if lobe.is_mirror() || r0 < 0.5 * texel(0) {
            levels.push(Level {
                map: env.clone(),
                core_radius: r0,
                cut_radius: cut,
                rings: 0,
            });
            continue;
        }
        // Mip of ring k: the one whose texel is nearest R_k/K in ratio (R_k/texel within
        // [K/√2, K√2], fewer only where the input is too coarse, more only at the coarsest mip).
        // A lobe that ends in a step at the horizon (Phong σ ≈ 0, wide Torrance–Sparrow) makes
        // the result change sharply where a bright source crosses it: such lobes keep at least
        // STEP_ROWS rows (cheap: their outputs are small either way).
        let step = lobe.kernel(1e-9) > 1e-3 * lobe.kernel(1.0);
        let coarsest = if step {
            (0..mips.len())
                .rev()
                .find(|&m| mips[m].height >= STEP_ROWS)
                .unwrap_or(0)
        } else {
            mips.len() - 1
        };
        let mip_for =
            |r: f64| ((r / (kk * texel(0))).log2().round().max(0.0) as usize).min(coarsest);
        let m0 = mip_for(r0);
        let (h0, w0) = (mips[m0].height, mips[m0].width);
        let mut total: Option<EnvMap> = None;
        let mut k = 0usize;
        loop {
            crate::cancel::check()?;
            let rk = r0 * (1u64 << k.min(60)) as f64;
            let last = 2.0 * rk >= cut;
            let r_in = if k == 0 { None } else { Some(0.5 * rk) };
            let r_out = if last { None } else { Some(rk) };
            let ring = ring_pass(&mips[mip_for(rk)], lobe, r_in, r_out, cut);
            let ring = resample(&ring, h0, w0);
            match total.as_mut() {
                None => total = Some(ring),
                Some(t) => t
                    .data
                    .par_iter_mut()
                    .zip(ring.data.par_iter())
                    .for_each(|(a, b)| *a += b),
            }
            k += 1;
            if last {
                break;
            }
        }
        let t = total.expect("at least one ring");
        let c = env.channels;
        let mut data = vec![0.0f32; h0 * w0 * c];
        data.par_chunks_mut(c)
            .zip(t.data.par_chunks(c + 1))
            .for_each(|(o, s)| {
                let den = s[c];
                for ch in 0..c {
                    o[ch] = if den > 0.0 { s[ch] / den } else { 0.0 };
                }
            });
        levels.push(Level {
            map: EnvMap {
                layout: Layout::LatLong,
                height: h0,
                width: w0,
                channels: c,
                data,
            },
            core_radius: r0,
            cut_radius: cut,
            rings: k,
        });
    }
    Ok(levels)
}

/// The narrowest level a [`Lobe::Gaussian`] is blurred at (texels across).
pub const GAUSSIAN_MIN_WIDTH: usize = 32;

/// The width a [`Lobe::Gaussian`] of σ radians is blurred at: the smallest power of two ≥ 8π/σ
/// (σ spans 4 texels along the equator), at least [`GAUSSIAN_MIN_WIDTH`].
fn gaussian_target_width(sigma: f64) -> usize {
    let e = (8.0 * PI / sigma).log2().ceil();
    let e = if e.is_nan() { 62.0 } else { e.clamp(5.0, 62.0) };
    (1usize << e as u32).max(GAUSSIAN_MIN_WIDTH)
}

/// The circular convolution kernel g (length n) whose discrete Fourier transform is the real,
/// even `gain` (gain[j] for frequencies j = 0 ..= n/2 cycles per n samples, decreasing):
/// g[m] = (1/n)·(G₀ + 2 Σ_{0<j<n/2} G_j cos(2πjm/n) + G_{n/2} (−1)^m [n even]). Convolving with g
/// is multiplying the spectrum by the gain (numpy's rfft · gain · irfft) exactly.
fn circular_kernel(gain: &[f64], n: usize) -> Vec<f64> {
    let cos: Vec<f64> = (0..n).map(|k| (TAU * k as f64 / n as f64).cos()).collect();
    // Frequencies whose gain is below 1e-18 add nothing a float can hold.
    let top = gain.iter().position(|&x| x < 1e-18).unwrap_or(gain.len());
    (0..n)
        .map(|m| {
            let mut s = gain[0];
            for (j, &gj) in gain.iter().enumerate().take(top).skip(1) {
                let nyquist = n.is_multiple_of(2) && 2 * j == n;
                s += if nyquist { 1.0 } else { 2.0 } * gj * cos[(j * m) % n];
            }
            s / n as f64
        })
        .collect()
}

/// `out[m] = Σ_d g[d]·r[(m − d) mod n]` for an (n, c) interleaved signal `r` (f64).
fn circular_convolve(r: &[f64], g: &[f64], c: usize) -> Vec<f64> {
    let n = g.len();
    let mut r2 = Vec::with_capacity(2 * n * c);
    r2.extend_from_slice(r);
    r2.extend_from_slice(r);
    let gmax = g.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    let mut out = vec![0.0f64; n * c];
    for (d, &gd) in g.iter().enumerate() {
        // The Gaussian's far tail (|g| below 1e-13 of its peak) changes no f32 result.
        if gd.abs() <= 1e-13 * gmax {
            continue;
        }
        let src = &r2[(n - d) * c..(2 * n - d) * c];
        for (o, s) in out.iter_mut().zip(src) {
            *o += gd * s;
        }
    }
    out
}

/// Gains exp(−2(π f s)²) of a Gaussian of `s` samples at frequencies f = j/n, j = 0 ..= n/2.
fn gaussian_gain(n: usize, s: f64) -> Vec<f64> {
    (0..=n / 2)
        .map(|j| {
            let x = PI * (j as f64 / n as f64) * s;
            (-2.0 * x * x).exp()
        })
        .collect()
}

/// A [`Lobe::Gaussian`] level: the map box-averaged (plain f×f means) down to
/// [`gaussian_target_width`] (never upsampled), then blurred by a Gaussian of σ radians made
/// separable on the lat-long grid:
///
/// 1. along each meridian — column x followed by column x + W/2 reversed form a great circle
///    through both poles, so the blur wraps over the poles: a circular convolution of 2H samples
///    of π/H radians with a Gaussian of σH/π samples;
/// 2. along each parallel — a circular convolution (wrapping at the seam) with a Gaussian of
///    σ / (2π cos λ / W) samples, λ the row's latitude (wider towards the poles; cos λ ≥ 1e-9·…).
///
/// Each convolution multiplies the spectrum by the Gaussian's gain exp(−2(π f s)²) exactly
/// ([`circular_kernel`]), in f64; the meridian pass's result is rounded to f32 before the parallel
/// pass. This is the blur `reflmap.py` computed with numpy FFTs up to its first release
/// (tests/reflection/test_reflmap.py compares the two). Rows may be top-down or bottom-up: both
/// passes are symmetric about the equator.
pub fn gaussian_level(env: &EnvMap, sigma: f64) -> Result<Level> {
    check_latlong(env, "image")?;
    let (h, w, c) = (env.height, env.width, env.channels);
    if w % 2 != 0 {
        return Err(RokebyError::invalid(
            "image",
            format!("the Gaussian lobe pairs each meridian with the opposite one: the width must be even, got {w}"),
        ));
    }
    let mut f = (w / w.min(gaussian_target_width(sigma))).max(1);
    while f > 1 && (h % f != 0 || w % f != 0 || (w / f) % 2 != 0) {
        f -= 1;
    }
    let (h2, w2) = (h / f, w / f);
    // Box average (f32 values, as stored).
    let mut px = vec![0.0f32; h2 * w2 * c];
    px.par_chunks_mut(w2 * c).enumerate().for_each(|(i, row)| {
        let inv = 1.0 / (f * f) as f64;
        for j in 0..w2 {
            for ch in 0..c {
                let mut s = 0.0f64;
                for ii in i * f..(i + 1) * f {
                    for jj in j * f..(j + 1) * f {
                        s += env.data[(ii * w + jj) * c + ch] as f64;
                    }
                }
                row[j * c + ch] = (s * inv) as f32;
            }
        }
    });
    crate::cancel::check()?;
    // 1. Meridians: ring of column x (rows 0 → H−1), then column x + W/2 (rows H−1 → 0).
    let half = w2 / 2;
    let n = 2 * h2;
    let g = circular_kernel(&gaussian_gain(n, sigma / (PI / h2 as f64)), n);
    let rings: Vec<Vec<f64>> = (0..half)
        .into_par_iter()
        .map(|x| {
            let mut ring = vec![0.0f64; n * c];
            for i in 0..h2 {
                for ch in 0..c {
                    ring[i * c + ch] = px[(i * w2 + x) * c + ch] as f64;
                    ring[(h2 + i) * c + ch] = px[((h2 - 1 - i) * w2 + x + half) * c + ch] as f64;
                }
            }
            circular_convolve(&ring, &g, c)
        })
        .collect();
    let mut mid = vec![0.0f32; h2 * w2 * c];
    for (x, ring) in rings.iter().enumerate() {
        for i in 0..h2 {
            for ch in 0..c {
                mid[(i * w2 + x) * c + ch] = ring[i * c + ch] as f32;
                mid[((h2 - 1 - i) * w2 + x + half) * c + ch] = ring[(h2 + i) * c + ch] as f32;
            }
        }
    }
    drop(rings);
    crate::cancel::check()?;
    // 2. Parallels: per row a Gaussian of σ / (2π cos λ / W) samples, wrapping at the seam.
    let mut data = vec![0.0f32; h2 * w2 * c];
    data.par_chunks_mut(w2 * c)
        .zip(mid.par_chunks(w2 * c))
        .enumerate()
        .for_each(|(i, (orow, irow))| {
            let lat = ((i as f64 + 0.5) / h2 as f64 - 0.5) * PI;
            let s_row = sigma / (TAU * lat.cos() / w2 as f64).max(1e-9);
            let g = circular_kernel(&gaussian_gain(w2, s_row), w2);
            let r: Vec<f64> = irow.iter().map(|&v| v as f64).collect();
            for (o, v) in orow.iter_mut().zip(circular_convolve(&r, &g, c)) {
                *o = v as f32;
            }
        });
    Ok(Level {
        map: EnvMap {
            layout: Layout::LatLong,
            height: h2,
            width: w2,
            channels: c,
            data,
        },
        // Half the energy of a narrow 2D Gaussian lies within σ√(2 ln 2); it reaches everywhere.
        core_radius: sigma * (2.0 * std::f64::consts::LN_2).sqrt(),
        cut_radius: PI,
        rings: 0,
    })
}

/// Texel directions and the seed's weights sin θ (π/M)(2π/N) of a lat-long map (Fraser, eq. 2).
fn seed_weights(env: &EnvMap) -> (Vec<DVec3>, Vec<f64>) {
    let (h, w) = (env.height, env.width);
    let mut dirs = Vec::with_capacity(h * w);
    let mut wts = Vec::with_capacity(h * w);
    for i in 0..h {
        let theta = PI * (i as f64 + 0.5) / h as f64;
        let wt = theta.sin() * (PI / h as f64) * (TAU / w as f64);
        for j in 0..w {
            dirs.push(env.texel_direction(0, i, j));
            wts.push(wt);
        }
    }
    (dirs, wts)
}

/// Reference: P(r) by the seed's brute-force sum over every texel (Fraser, eq. 2), normalised by
/// the same sum of the kernel; N×3 directions → N×channels (f64). A mirror lobe returns the
/// bilinear lookup.
pub fn brute_force(env: &EnvMap, lobe: &Lobe, directions: &[f32]) -> Result<Vec<f64>> {
    check_latlong(env, "image")?;
    let rs = finite_dirs(directions, "directions")?;
    let c = env.channels;
    if lobe.is_mirror() {
        let v = env.sample_many(directions)?;
        return Ok(v.into_iter().map(f64::from).collect());
    }
    let (dirs, wts) = seed_weights(env);
    let mut out = vec![0.0f64; rs.len() * c];
    out.par_chunks_mut(c).zip(rs.par_iter()).for_each(|(o, r)| {
        let mut den = 0.0;
        for (t, (d, &wt)) in dirs.iter().zip(&wts).enumerate() {
            let cosg = r.dot(*d);
            if cosg <= 0.0 {
                continue;
            }
            let k = lobe.kernel(cosg) * wt;
            den += k;
            for (acc, &x) in o[..c].iter_mut().zip(&env.data[t * c..t * c + c]) {
                *acc += k * x as f64;
            }
        }
        if den > 0.0 {
            for v in o.iter_mut() {
                *v /= den;
            }
        } else {
            // Every texel's weight underflowed (a lobe far narrower than the texels; the fuzzer
            // found 0/0 = NaN): the lobe is a delta at this resolution, as for a mirror.
            let mut tmp = vec![0.0f32; c];
            env.sample(*r, &mut tmp);
            for (v, t) in o.iter_mut().zip(&tmp) {
                *v = *t as f64;
            }
        }
    });
    Ok(out)
}

/// Â_l of the clamped cosine (Ramamoorthi & Hanrahan 2001, eq. 8) for each of the nine terms.
pub const A_HAT: [f64; SH_COEFFS] = [
    PI,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    2.0 * PI / 3.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
    PI / 4.0,
];

/// L_lm = Σ L(d) Y_lm(d) Ω over the texels of a lat-long map (exact texel solid angles), per channel.
pub fn sh_project(env: &EnvMap) -> Result<Vec<[f64; SH_COEFFS]>> {
    check_latlong(env, "image")?;
    let (h, w, c) = (env.height, env.width, env.channels);
    let rows: Vec<Vec<[f64; SH_COEFFS]>> = (0..h)
        .into_par_iter()
        .map(|i| {
            let omega = latlong_texel_solid_angle(h, w, i);
            let mut acc = vec![[0.0f64; SH_COEFFS]; c];
            for j in 0..w {
                let y = basis(env.texel_direction(0, i, j).to_array());
                let t = env.texel(0, i, j);
                for ch in 0..c {
                    let l = t[ch] as f64 * omega;
                    for k in 0..SH_COEFFS {
                        acc[ch][k] += l * y[k];
                    }
                }
            }
            acc
        })
        .collect();
    let mut out = vec![[0.0f64; SH_COEFFS]; c];
    for r in rows {
        for ch in 0..c {
            for k in 0..SH_COEFFS {
                out[ch][k] += r[ch][k];
            }
        }
    }
    Ok(out)
}

/// E(n)/π = Σ Â_l L_lm Y_lm(n)/π: the radiance of a white Lambertian surface of normal n.
#[inline]
pub fn sh_irradiance(coeffs: &[[f64; SH_COEFFS]], n: DVec3, out: &mut [f64]) {
    let y = basis(n.to_array());
    for (o, cf) in out.iter_mut().zip(coeffs) {
        let mut s = 0.0;
        for k in 0..SH_COEFFS {
            s += A_HAT[k] * cf[k] * y[k];
        }
        *o = s / PI;
    }
}

/// The SH irradiance (E/π) as a lat-long map of the given size, and the coefficients L_lm.
pub fn irradiance_map(
    env: &EnvMap,
    height: usize,
    width: usize,
) -> Result<(EnvMap, Vec<[f64; SH_COEFFS]>)> {
    let coeffs = sh_project(env)?;
    let mut out = EnvMap::zeros(Layout::LatLong, height, width, env.channels)?;
    let c = env.channels;
    let probe = out.clone();
    out.data
        .par_chunks_mut(width * c)
        .enumerate()
        .for_each(|(i, row)| {
            let mut tmp = vec![0.0f64; c];
            for j in 0..width {
                sh_irradiance(&coeffs, probe.texel_direction(0, i, j), &mut tmp);
                for ch in 0..c {
                    row[j * c + ch] = tmp[ch] as f32;
                }
            }
        });
    Ok((out, coeffs))
}

/// Reference irradiance E(n)/π = (1/π) Σ L max(0, n·d) sin θ (π/M)(2π/N) (the seed's sum with the
/// clamped cosine as the lobe); N×3 normals → N×channels.
pub fn brute_force_irradiance(env: &EnvMap, normals: &[f32]) -> Result<Vec<f64>> {
    check_latlong(env, "image")?;
    let ns = finite_dirs(normals, "normals")?;
    let c = env.channels;
    let (dirs, wts) = seed_weights(env);
    let mut out = vec![0.0f64; ns.len() * c];
    out.par_chunks_mut(c).zip(ns.par_iter()).for_each(|(o, n)| {
        for (t, (d, &wt)) in dirs.iter().zip(&wts).enumerate() {
            let cosg = n.dot(*d);
            if cosg > 0.0 {
                for (acc, &x) in o[..c].iter_mut().zip(&env.data[t * c..t * c + c]) {
                    *acc += cosg * wt * x as f64;
                }
            }
        }
        for v in o.iter_mut() {
            *v /= PI;
        }
    });
    Ok(out)
}
