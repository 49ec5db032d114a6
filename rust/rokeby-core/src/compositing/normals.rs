//! The normal-editing tools of compositing-stage shape editing (Zubiaga et al. 2016, §5 and
//! Fig. 1: "embossing", bump decals and smoothing of the normal buffer), on screen-space normal
//! buffers (H×W×3 f32, rows top first, x right, y up, z towards the viewer).
//!
//! Every tool follows one rule (`apply`): the edited normal is renormalised (f32) where it
//! differs from the input, and the input is kept bit for bit elsewhere — on background pixels
//! (|n|₁ = 0, or not finite), outside the mask, and where the edit changes nothing — so that an
//! edit that changes nothing leaves the recomposited image exactly as it was (eqs. 3–5 take the
//! identity path there).
//!
//! * [`emboss`]: n_z → β n_z (β ∈ (0, 1]: the surface bulges; the paper's LUMO-style emboss).
//! * [`bump`]: ñ = normalize(n − s ∇h), ∇h = (∂h/∂col, −∂h/∂row, 0), with the gradient as
//!   numpy's `gradient` takes it (central differences inside, one-sided at the borders).
//! * [`noise_decal`]: a procedural height decal (fractal gradient noise, faded like the paper's
//!   ripple) for [`bump`].
//! * [`bilateral`]: a cross-bilateral filter of (n_x, n_y) with a spatial Gaussian σ_s (pixels,
//!   window radius ⌈2σ_s⌉) and a range Gaussian on the relative depth difference σ_d, so that
//!   occluding contours stay sharp; n_z = √(1 − |n̄|²). Accumulated in f64.
//!
//! Rows run in parallel (rayon); the output does not depend on the number of threads.

use crate::error::{Result, RokebyError};
use crate::unit_vector::unit_f32;
use glam::Vec3;
use rayon::prelude::*;

/// The largest spatial σ of [`bilateral`], in pixels (its window is ⌈2σ⌉ pixels each way).
pub const MAX_SIGMA_S: f64 = 50.0;

/// A screen-space normal buffer's size, and the optional edit mask (true: may be edited).
#[derive(Clone, Copy)]
pub struct Frame<'a> {
    pub width: usize,
    pub height: usize,
    pub mask: Option<&'a [bool]>,
}

impl Frame<'_> {
    fn check(&self, normals: &[f32]) -> Result<()> {
        let px = self.width * self.height;
        if px == 0 {
            return Err(RokebyError::invalid("normals", "the frame is empty"));
        }
        if normals.len() != 3 * px {
            return Err(RokebyError::invalid(
                "normals",
                format!(
                    "expected {}×{}×3 values, got {}",
                    self.height,
                    self.width,
                    normals.len()
                ),
            ));
        }
        if let Some(m) = self.mask {
            if m.len() != px {
                return Err(RokebyError::invalid(
                    "mask",
                    format!(
                        "expected {}×{} values like the normals, got {}",
                        self.height,
                        self.width,
                        m.len()
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// f32 unit vector as `compositing._unit` makes it ([`unit_f32`]: e/‖e‖ in f32), 0 where e has no
/// direction.
#[inline]
fn unit(e: [f32; 3]) -> [f32; 3] {
    unit_f32(Vec3::from_array(e)).map_or([0.0; 3], |u| u.to_array())
}

/// The rule shared by the tools: for each pixel, `edit(i, n)` proposes ñ; the result is
/// unit(ñ) unless the pixel is background (|n|₁ = 0, or a component not finite), masked out, or
/// ñ equals n exactly.
fn apply<F>(normals: &[f32], f: &Frame, edit: F) -> Vec<f32>
where
    F: Fn(usize, [f32; 3]) -> [f32; 3] + Sync,
{
    let w = f.width;
    let mut out = vec![0.0f32; normals.len()];
    out.par_chunks_mut(3 * w).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let i = y * w + x;
            let n = [normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]];
            let on = n.iter().all(|v| v.is_finite())
                && n[0].abs() + n[1].abs() + n[2].abs() > 0.0
                && f.mask.is_none_or(|m| m[i]);
            let r = if on {
                let e = edit(i, n);
                if e == n {
                    n
                } else {
                    unit(e)
                }
            } else {
                n
            };
            row[3 * x..3 * x + 3].copy_from_slice(&r);
        }
    });
    out
}

/// Embossing: n_z → β n_z, renormalised; β ∈ (0, 1].
pub fn emboss(normals: &[f32], f: &Frame, beta: f32) -> Result<Vec<f32>> {
    f.check(normals)?;
    if !(beta > 0.0 && beta <= 1.0) {
        return Err(RokebyError::invalid(
            "beta",
            format!("must be in (0, 1], got {beta}"),
        ));
    }
    Ok(apply(normals, f, |_, n| [n[0], n[1], n[2] * beta]))
}

/// ∂h/∂row and ∂h/∂col at pixel (y, x) as numpy's `gradient` (edge order 1): central differences
/// inside, one-sided at the borders, 0 along an axis of length 1.
#[inline]
fn gradient(h: &[f32], w: usize, rows: usize, y: usize, x: usize) -> (f32, f32) {
    let at = |yy: usize, xx: usize| h[yy * w + xx];
    let d = |len: usize, k: usize, get: &dyn Fn(usize) -> f32| -> f32 {
        if len < 2 {
            0.0
        } else if k == 0 {
            get(1) - get(0)
        } else if k == len - 1 {
            get(len - 1) - get(len - 2)
        } else {
            (get(k + 1) - get(k - 1)) / 2.0
        }
    };
    (d(rows, y, &|yy| at(yy, x)), d(w, x, &|xx| at(y, xx)))
}

/// Bump mapping in screen space: ñ = normalize(n − s ∇h) with ∇h = (∂h/∂col, −∂h/∂row, 0);
/// `height` (H×W) in pixels of height per pixel.
pub fn bump(normals: &[f32], f: &Frame, height: &[f32], strength: f32) -> Result<Vec<f32>> {
    f.check(normals)?;
    if height.len() != f.width * f.height {
        return Err(RokebyError::invalid(
            "height",
            format!(
                "expected {}×{} values like the normals, got {}",
                f.height,
                f.width,
                height.len()
            ),
        ));
    }
    if !strength.is_finite() {
        return Err(RokebyError::invalid(
            "strength",
            format!("must be finite, got {strength}"),
        ));
    }
    let (w, rows) = (f.width, f.height);
    let s = strength as f64;
    Ok(apply(normals, f, |i, n| {
        let (gy, gx) = gradient(height, w, rows, i / w, i % w);
        let e = [n[0] - strength * gx, n[1] + strength * gy, n[2]];
        if e.iter().all(|x| x.is_finite()) {
            return e;
        }
        // A huge strength overflowed float32: in f64, scaled to the largest component (the result
        // is unit(ñ)), the normal tilts towards the gradient instead of becoming NaN.
        let e = [
            n[0] as f64 - s * gx as f64,
            n[1] as f64 + s * gy as f64,
            n[2] as f64,
        ];
        let m = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        if m > 0.0 && m.is_finite() {
            [(e[0] / m) as f32, (e[1] / m) as f32, (e[2] / m) as f32]
        } else {
            n
        }
    }))
}

/// Cross-bilateral smoothing of the normals with depth: per pixel, the weighted mean of (n_x, n_y)
/// over the window |dx|, |dy| ≤ r = max(1, ⌈2σ_s⌉) of valid pixels q (finite depth, |n|₁ > 0),
/// weights exp(−(dx² + dy²)/(2σ_s²)) · exp(−½ ((d_q − d_p)/max(|d_p|, 1e-6)/σ_d)²), summed in
/// the window's row-major order in f64; n_z = √(1 − min(|n̄|², 1)).
///
/// Wide windows are sampled, not summed whole: for σ_s above [`EXACT_SIGMA_S`] the window's taps
/// are taken every ⌈σ_s / EXACT_SIGMA_S⌉ pixels (still at least 8 taps per σ_s; the
/// normals stay within about 0.02, a degree, of the whole-window sum), so one pixel costs at most about 33² taps whatever σ_s (σ_s = 50 on a 1080p frame
/// would otherwise take about 19 minutes). Cancellable between rows ([`crate::cancel`]).
pub fn bilateral(
    normals: &[f32],
    f: &Frame,
    depth: &[f32],
    sigma_s: f64,
    sigma_d: f64,
) -> Result<Vec<f32>> {
    f.check(normals)?;
    let (w, rows) = (f.width, f.height);
    if depth.len() != w * rows {
        return Err(RokebyError::invalid(
            "depth",
            format!(
                "expected {rows}×{w} values like the normals, got {}",
                depth.len()
            ),
        ));
    }
    if !(sigma_s.is_finite() && sigma_s > 0.0) {
        return Err(RokebyError::invalid(
            "sigma_s",
            format!("must be positive and finite, got {sigma_s}"),
        ));
    }
    if !(sigma_d.is_finite() && sigma_d > 0.0) {
        return Err(RokebyError::invalid(
            "sigma_d",
            format!("must be positive and finite, got {sigma_d}"),
        ));
    }
    if sigma_s > MAX_SIGMA_S {
        return Err(RokebyError::invalid("sigma_s", format!("at most {MAX_SIGMA_S} pixels (a window of {0}×{0} pixels around every pixel), got {sigma_s}", 2 * (2.0 * MAX_SIGMA_S).ceil() as usize + 1)));
    }
    let stride = (sigma_s / EXACT_SIGMA_S).ceil().max(1.0) as usize;
    let r = ((2.0 * sigma_s).ceil() as usize).max(1);
    let r = r / stride * stride; // taps at multiples of the stride, the centre included
    let valid = |i: usize| {
        let n = &normals[3 * i..3 * i + 3];
        n.iter().all(|v| v.is_finite())
            && n[0].abs() + n[1].abs() + n[2].abs() > 0.0
            && depth[i].is_finite()
    };
    let side = 2 * r + 1; // the weight table is indexed by pixel offset; only multiples of `stride` are read
                          // The centre weighs 1 exactly (so that a σ_s small enough to underflow 2σ_s² still leaves the
                          // pixel itself, instead of 0/0).
    let ws: Vec<f64> = (0..side * side)
        .map(|k| {
            let (dy, dx) = ((k / side) as f64 - r as f64, (k % side) as f64 - r as f64);
            if dx == 0.0 && dy == 0.0 {
                1.0
            } else {
                (-(dx * dx + dy * dy) / (2.0 * sigma_s * sigma_s)).exp()
            }
        })
        .collect();
    let edit = |i: usize, n: [f32; 3]| -> [f32; 3] {
        if !valid(i) || crate::cancel::requested() {
            return n; // kept by the rule below (masked: not valid); a cancelled call is discarded
        }
        let (y, x) = ((i / w) as isize, (i % w) as isize);
        let dp = depth[i] as f64;
        let scale = dp.abs().max(1e-6);
        let (mut ax, mut ay, mut wsum) = (0.0f64, 0.0f64, 0.0f64);
        for dy in (-(r as isize)..=(r as isize)).step_by(stride) {
            let yy = y + dy;
            if yy < 0 || yy >= rows as isize {
                continue;
            }
            for dx in (-(r as isize)..=(r as isize)).step_by(stride) {
                let xx = x + dx;
                if xx < 0 || xx >= w as isize {
                    continue;
                }
                let q = yy as usize * w + xx as usize;
                if !valid(q) {
                    continue;
                }
                let rel = (depth[q] as f64 - dp) / scale / sigma_d;
                let wt = ws[(dy + r as isize) as usize * side + (dx + r as isize) as usize]
                    * (-0.5 * rel * rel).exp();
                ax += wt * normals[3 * q] as f64;
                ay += wt * normals[3 * q + 1] as f64;
                wsum += wt;
            }
        }
        let d = wsum.max(1e-300);
        let (mx, my) = (ax / d, ay / d);
        let l2 = (mx * mx + my * my).min(1.0);
        [mx as f32, my as f32, (1.0 - l2).sqrt() as f32]
    };
    let out = apply(normals, f, edit);
    crate::cancel::check()?;
    Ok(out)
}

/// The largest σ_s (pixels) [`bilateral`] sums over its whole window; wider ones are sampled.
pub const EXACT_SIGMA_S: f64 = 8.0;

/// A procedural bump decal: fractal gradient noise (Perlin's 2002 noise with a quintic fade,
/// `octaves` octaves of halving amplitude, each with its own hashed gradients from `seed`) of
/// feature size `size` pixels, faded by (1 − d/radius)₊² around `center` (x, y in pixels, the
/// ripple's window). Heights in pixels, within about ±size/4 (lower towards the rim), so that
/// slopes are about ±0.5 whatever the size; (H×W) row-major, rows top first. Pair with [`bump`].
pub fn noise_decal(
    width: usize,
    height: usize,
    size: f64,
    octaves: u32,
    seed: u32,
    center: (f64, f64),
    radius: f64,
) -> Result<Vec<f32>> {
    if width == 0 || height == 0 {
        return Err(RokebyError::invalid("shape", "the frame is empty"));
    }
    if !(size.is_finite() && size >= 1.0) {
        return Err(RokebyError::invalid(
            "size",
            format!("must be at least 1 pixel, got {size}"),
        ));
    }
    if !(1..=8).contains(&octaves) {
        return Err(RokebyError::invalid(
            "octaves",
            format!("must be 1 to 8, got {octaves}"),
        ));
    }
    if !(radius.is_finite() && radius > 0.0) {
        return Err(RokebyError::invalid(
            "radius",
            format!("must be positive and finite, got {radius}"),
        ));
    }
    if !(center.0.is_finite() && center.1.is_finite()) {
        return Err(RokebyError::invalid("center", "must be finite"));
    }
    let norm: f64 = (0..octaves).map(|o| 0.5f64.powi(o as i32)).sum();
    let amp = size / 4.0 / norm;
    let mut out = crate::alloc::filled("height×width", &[height, width], 0.0f32)?;
    out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (x, v) in row.iter_mut().enumerate() {
            let (dx, dy) = (x as f64 + 0.5 - center.0, y as f64 + 0.5 - center.1);
            let fade = (1.0 - (dx * dx + dy * dy).sqrt() / radius).max(0.0);
            if fade == 0.0 {
                continue;
            }
            let mut sum = 0.0;
            for o in 0..octaves {
                let f = (1u64 << o) as f64 / size;
                sum += 0.5f64.powi(o as i32)
                    * gradient_noise(
                        x as f64 * f,
                        y as f64 * f,
                        seed.wrapping_add(o.wrapping_mul(0x9e37_79b9)),
                    );
            }
            *v = (amp * sum * fade * fade) as f32;
        }
    });
    Ok(out)
}

/// A 32-bit integer hash of a lattice point (x, y) and a seed (a multiply–xorshift mix).
#[inline]
fn lattice_hash(ix: i64, iy: i64, seed: u32) -> u32 {
    let mut h = (ix as u32).wrapping_mul(0x8da6_b343)
        ^ (iy as u32).wrapping_mul(0xd816_3841)
        ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^ (h >> 16)
}

/// 2D gradient noise in [−1, 1] (unit gradients at hashed angles, quintic interpolation, scaled
/// by √2 so that its extremes reach about ±1).
fn gradient_noise(x: f64, y: f64, seed: u32) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let dot = |cx: i64, cy: i64, ox: f64, oy: f64| {
        let a =
            lattice_hash(ix + cx, iy + cy, seed) as f64 / 4_294_967_296.0 * std::f64::consts::TAU;
        a.cos() * ox + a.sin() * oy
    };
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (fade(fx), fade(fy));
    let n00 = dot(0, 0, fx, fy);
    let n10 = dot(1, 0, fx - 1.0, fy);
    let n01 = dot(0, 1, fx, fy - 1.0);
    let n11 = dot(1, 1, fx - 1.0, fy - 1.0);
    let a = n00 + u * (n10 - n00);
    let b = n01 + u * (n11 - n01);
    std::f64::consts::SQRT_2 * (a + v * (b - a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(w: usize) -> (Vec<f32>, Vec<f32>) {
        let mut n = vec![0.0f32; 3 * w * w];
        let mut d = vec![f32::INFINITY; w * w];
        for y in 0..w {
            for x in 0..w {
                let (u, v) = (
                    (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                    1.0 - (y as f32 + 0.5) / w as f32 * 2.0,
                );
                let s = u * u + v * v;
                if s < 1.0 {
                    let i = y * w + x;
                    n[3 * i..3 * i + 3].copy_from_slice(&[u, v, (1.0 - s).sqrt()]);
                    d[i] = 5.0 - (1.0 - s).sqrt();
                }
            }
        }
        (n, d)
    }

    #[test]
    fn tools_keep_background_masked_and_unchanged_pixels_bit_for_bit() {
        let w = 40;
        let (n, d) = sphere(w);
        let mask: Vec<bool> = (0..w * w).map(|i| i % w < w / 2).collect();
        let f = Frame {
            width: w,
            height: w,
            mask: Some(&mask),
        };
        let h: Vec<f32> = (0..w * w)
            .map(|i| ((i % w) as f32 * 0.3).sin() * 2.0)
            .collect();
        for out in [
            emboss(&n, &f, 0.5).unwrap(),
            bump(&n, &f, &h, 1.0).unwrap(),
            bilateral(&n, &f, &d, 2.0, 0.02).unwrap(),
        ] {
            for i in 0..w * w {
                let (a, b) = (&out[3 * i..3 * i + 3], &n[3 * i..3 * i + 3]);
                let bg = b.iter().all(|&v| v == 0.0);
                if bg || !mask[i] {
                    assert_eq!(a, b, "pixel {i} must be kept");
                } else {
                    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
                    assert!((l - 1.0).abs() < 1e-6, "unit: {l}");
                }
            }
        }
        // β = 1 and a flat height change nothing: the input comes back bit for bit.
        let all = Frame {
            width: w,
            height: w,
            mask: None,
        };
        assert_eq!(emboss(&n, &all, 1.0).unwrap(), n);
        assert_eq!(bump(&n, &all, &vec![3.0; w * w], 2.0).unwrap(), n);
    }

    #[test]
    fn emboss_and_bump_do_what_they_say() {
        let w = 32;
        let (n, _) = sphere(w);
        let f = Frame {
            width: w,
            height: w,
            mask: None,
        };
        let e = emboss(&n, &f, 0.25).unwrap();
        let i = (w / 2) * w + w / 4; // left of the centre: n_x < 0
        let (a, b) = (&n[3 * i..3 * i + 3], &e[3 * i..3 * i + 3]);
        assert!(b[2] < a[2] && b[0].abs() > a[0].abs() && b[0] * a[0] > 0.0);
        // A ramp h = col: ∇h = (1, 0) → ñ ∝ n − s(1, 0, 0) on every surface pixel.
        let h: Vec<f32> = (0..w * w).map(|i| (i % w) as f32).collect();
        let bu = bump(&n, &f, &h, 0.5).unwrap();
        let want = unit([a[0] - 0.5, a[1], a[2]]);
        assert_eq!(&bu[3 * i..3 * i + 3], &want);
        // Rows go down, screen y up: h = row gives ∂h/∂row = 1 → ñ_y = n_y + s.
        let hv: Vec<f32> = (0..w * w).map(|i| (i / w) as f32).collect();
        let bv = bump(&n, &f, &hv, 0.5).unwrap();
        assert_eq!(&bv[3 * i..3 * i + 3], &unit([a[0], a[1] + 0.5, a[2]]));
    }

    #[test]
    fn bilateral_smooths_surfaces_and_keeps_depth_edges() {
        // Two planes at different depths, normals noisy; the filter must not mix them.
        let (w, rows) = (48, 24);
        let mut n = vec![0.0f32; 3 * w * rows];
        let mut d = vec![0.0f32; w * rows];
        let mut st = 12345u64;
        for i in 0..w * rows {
            st = st
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let jitter = ((st >> 33) as f32 / (1u64 << 31) as f32 - 0.5) * 0.2;
            let left = i % w < w / 2;
            let (nx, dep) = if left {
                (0.5 + jitter, 2.0)
            } else {
                (-0.5 + jitter, 8.0)
            };
            n[3 * i..3 * i + 3].copy_from_slice(&unit([nx, 0.0, 0.8]));
            d[i] = dep;
        }
        let f = Frame {
            width: w,
            height: rows,
            mask: None,
        };
        let s = bilateral(&n, &f, &d, 3.0, 0.02).unwrap();
        let spread = |a: &[f32], left: bool| {
            let xs: Vec<f32> = (0..w * rows)
                .filter(|i| (i % w < w / 2) == left)
                .map(|i| a[3 * i])
                .collect();
            let m = xs.iter().sum::<f32>() / xs.len() as f32;
            (
                m,
                (xs.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / xs.len() as f32).sqrt(),
            )
        };
        for left in [true, false] {
            let (m0, s0) = spread(&n, left);
            let (m1, s1) = spread(&s, left);
            assert!(s1 < 0.3 * s0, "smoothed: {s1} vs {s0}");
            assert!(
                (m1 - m0).abs() < 0.01,
                "the depth edge keeps the planes apart: {m1} vs {m0}"
            );
        }
        // Threads do not change the result.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| bilateral(&n, &f, &d, 3.0, 0.02).unwrap());
        assert_eq!(one, s);
    }

    #[test]
    fn noise_decal_is_a_seeded_fading_bump_of_its_size() {
        let (w, h) = (200, 120);
        let c = (100.0, 60.0);
        let a = noise_decal(w, h, 12.0, 3, 7, c, 50.0).unwrap();
        assert_eq!(
            a,
            noise_decal(w, h, 12.0, 3, 7, c, 50.0).unwrap(),
            "deterministic"
        );
        let b = noise_decal(w, h, 12.0, 3, 8, c, 50.0).unwrap();
        assert!(
            a.iter().zip(&b).filter(|(x, y)| x != y).count() > 1000,
            "another seed, another decal"
        );
        // Zero outside the radius, not zero inside; heights about ±size/4, slopes about ±0.5.
        let mut slopes = Vec::new();
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let d = ((x as f64 + 0.5 - c.0).powi(2) + (y as f64 + 0.5 - c.1).powi(2)).sqrt();
                let v = a[y * w + x];
                if d >= 50.0 {
                    assert_eq!(v, 0.0);
                } else if d < 20.0 {
                    assert!(v.abs() <= 12.0 / 4.0 * 1.6, "{v}");
                    slopes.push(((a[y * w + x + 1] - a[y * w + x - 1]) / 2.0).abs());
                }
            }
        }
        slopes.sort_by(f32::total_cmp);
        let median = slopes[slopes.len() / 2];
        assert!((0.05..1.0).contains(&median), "median slope {median}");
        let inside: Vec<f32> = (0..w * h).filter(|i| a[*i] != 0.0).map(|i| a[i]).collect();
        assert!(inside.len() > 5000);
        let mean = inside.iter().map(|v| *v as f64).sum::<f64>() / inside.len() as f64;
        assert!(mean.abs() < 0.5, "about zero-mean: {mean}");
        // Finer size, finer detail: more sign changes along a row through the centre.
        let changes = |z: &[f32]| {
            (61..139)
                .filter(|&x| (z[60 * w + x] > 0.0) != (z[60 * w + x + 1] > 0.0))
                .count()
        };
        let fine = noise_decal(w, h, 4.0, 1, 7, c, 50.0).unwrap();
        let coarse = noise_decal(w, h, 24.0, 1, 7, c, 50.0).unwrap();
        assert!(
            changes(&fine) > 2 * changes(&coarse).max(1),
            "{} vs {}",
            changes(&fine),
            changes(&coarse)
        );
        let err = |r: Result<Vec<f32>>| r.unwrap_err().to_string();
        assert!(err(noise_decal(w, h, 0.5, 3, 1, c, 50.0)).contains("size"));
        assert!(err(noise_decal(w, h, 8.0, 0, 1, c, 50.0)).contains("octaves"));
        assert!(err(noise_decal(w, h, 8.0, 3, 1, c, 0.0)).contains("radius"));
        assert!(err(noise_decal(0, h, 8.0, 3, 1, c, 5.0)).contains("empty"));
        assert!(err(noise_decal(w, h, 8.0, 3, 1, (f64::NAN, 0.0), 5.0)).contains("center"));
    }

    #[test]
    fn bad_arguments_are_named() {
        let (n, d) = sphere(8);
        let f = Frame {
            width: 8,
            height: 8,
            mask: None,
        };
        let err = |r: Result<Vec<f32>>| r.unwrap_err().to_string();
        assert!(err(emboss(&n, &f, 0.0)).contains("beta"));
        assert!(err(emboss(&n, &f, f32::NAN)).contains("beta"));
        assert!(err(emboss(&n[..9], &f, 0.5)).contains("normals"));
        assert!(err(bump(&n, &f, &d[..5], 1.0)).contains("height"));
        assert!(err(bump(&n, &f, &d, f32::INFINITY)).contains("strength"));
        assert!(err(bilateral(&n, &f, &d, 0.0, 0.02)).contains("sigma_s"));
        assert!(err(bilateral(&n, &f, &d, 1.0, -1.0)).contains("sigma_d"));
        assert!(err(bilateral(&n, &f, &d, 1e6, 0.02)).contains("at most 50 pixels"));
        // Extremes that are allowed: a σ_s whose square underflows leaves each pixel as it was (its
        // own weight only); a denormal σ_d keeps only neighbours at exactly the same depth. Never
        // NaN, never a zeroed normal.
        for (ss, sd) in [(1e-200, 0.02), (1.0, 1e-310)] {
            let out = bilateral(&n, &f, &d, ss, sd).unwrap();
            for i in 0..64 {
                let (a, b) = (&out[3 * i..3 * i + 3], &n[3 * i..3 * i + 3]);
                assert!(a.iter().all(|v| v.is_finite()));
                if b.iter().any(|&v| v != 0.0) {
                    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
                    assert!((l - 1.0).abs() < 1e-5, "σ_s {ss} σ_d {sd}: {a:?}");
                    if ss < 1e-100 {
                        assert!(
                            (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6,
                            "{a:?} vs {b:?}"
                        );
                    }
                }
            }
        }
        // An infinite normal is not a surface: kept as it is, not turned into NaN.
        let mut inf = n.clone();
        inf[3 * 27] = f32::INFINITY;
        let e = emboss(&inf, &f, 0.5).unwrap();
        assert_eq!(e[3 * 27], f32::INFINITY);
        let short = [true; 3];
        assert!(err(emboss(
            &n,
            &Frame {
                width: 8,
                height: 8,
                mask: Some(&short)
            },
            0.5
        ))
        .contains("mask"));
        assert!(err(emboss(
            &[],
            &Frame {
                width: 0,
                height: 0,
                mask: None
            },
            0.5
        ))
        .contains("empty"));
    }
}
