//! Environment maps E(r): one radiance value per direction r, stored on four parametrisations of
//! the sphere, with the exact direction formulas both ways, bilinear seam-correct lookups and
//! conversions between them (lecture notes "Environment mapping"; Blinn & Newell 1976).
//!
//! Every map is an array `[face][row][col][channel]` of f32 (row 0 is the top row of the image
//! file, as OpenEXR and numpy read it). Map coordinates (x, y) are in texels: texel (row i,
//! col j) covers [j, j+1] × [i, i+1] and has its centre at (j + ½, i + ½).
//!
//! * [`Layout::LatLong`] — equirectangular, Blender's convention (EEVEE's
//!   `node_tex_environment_equirectangular`, Cycles' `direction_to_equirectangular`; +X at the
//!   image centre, as `rokeby.reflection.render.reflmap.direction_to_uv`):
//!   ```text
//!   u = ½ − atan2(d_y, d_x)/(2π),   v = ½ + atan2(d_z, hypot(d_x, d_y))/π
//!   x = u·W,  y = (1 − v)·H                    (z up: the top row of the file looks up)
//!   d(u, v) = (cos φ cos λ, sin φ cos λ, sin λ),  φ = 2π(½ − u),  λ = π(v − ½)
//!   ```
//!   (The form u = atan2(d_y, −d_x)/(2π) + ½ differs from this by half a turn.)
//!   The seam u = 0 ≡ 1 wraps; across a pole the neighbour of column j is column j + W/2.
//! * [`Layout::Cube`] — six 90° faces +X, −X, +Y, −Y, +Z, −Z (OpenGL's table): the ray meets the
//!   2×2×2 cube at r / max(|r_x|, |r_y|, |r_z|) (notes, "Cube map"), on the face of the major axis
//!   m_a, with face coordinates s = (s_c/|m_a| + 1)/2, t = (t_c/|m_a| + 1)/2, x = s·S, y = t·S:
//!   ```text
//!   face  +X   −X   +Y   −Y   +Z   −Z
//!   s_c   −r_z +r_z +r_x +r_x +r_x −r_x
//!   t_c   −r_y −r_y +r_z −r_z −r_y −r_y
//!   ```
//!   Bilinear taps that leave a face are looked up on the face they fall on.
//! * [`Layout::Sphere`] — the mirror-ball (disk) map of an orthographic view along v = (0, 0, 1):
//!   ```text
//!   (s, t) = (r_x, r_y) / sqrt(r_x² + r_y² + (r_z + 1)²)                      (notes, eq. after (*))
//!   n = (s, t, sqrt(1 − s² − t²)),  r = 2(n·v)n − v                            (notes, (*))
//!   x = (s + 1)/2·S,  y = (1 − t)/2·S
//!   ```
//!   Texels outside the disk hold the rim value, r = (0, 0, −1).
//! * [`Layout::Paraboloid`] — the dual-paraboloid map of Heidrich & Seidel 1998, face 0 for
//!   r_z ≥ 0 and face 1 for r_z < 0:
//!   ```text
//!   (u, v) = (r_x, r_y) / (1 + |r_z|),   x = (u + 1)/2·S,  y = (v + 1)/2·S
//!   r(u, v) = (2u, 2v, ±(1 − u² − v²)) / (1 + u² + v²)
//!   ```
//!   This is the layout of `reconstruct::ParaboloidMap`: texels beyond the unit circle
//!   hold the other face's value there (the inverse formula continues across the equator).
//!
//! Conversions evaluate each target texel (optionally n×n sub-texel samples, averaged) by a
//! bilinear lookup in the source, in parallel over rows.

use crate::error::{Result, RokebyError};
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{PI, TAU};

/// Parametrisation of an environment map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    LatLong,
    Cube,
    Sphere,
    Paraboloid,
}

impl Layout {
    pub fn parse(s: &str) -> Option<Layout> {
        match s.to_ascii_lowercase().as_str() {
            "latlong" | "lat-long" | "lat_long" | "equirectangular" => Some(Layout::LatLong),
            "cube" | "cubemap" | "cube_map" => Some(Layout::Cube),
            "sphere" | "spheremap" | "sphere_map" | "mirror_ball" | "mirrorball" => {
                Some(Layout::Sphere)
            }
            "paraboloid" | "dual_paraboloid" | "dual-paraboloid" => Some(Layout::Paraboloid),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Layout::LatLong => "latlong",
            Layout::Cube => "cube",
            Layout::Sphere => "sphere",
            Layout::Paraboloid => "paraboloid",
        }
    }

    /// Number of faces: 1, 6, 1, 2.
    pub fn faces(self) -> usize {
        match self {
            Layout::LatLong | Layout::Sphere => 1,
            Layout::Cube => 6,
            Layout::Paraboloid => 2,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Direction formulas. `d` need not be unit where a formula is scale invariant; the inverse
// formulas return unit vectors.

/// Lat-long (u, v) ∈ [0, 1) × [0, 1] of a direction (Blender's convention).
#[inline]
pub fn latlong_uv(d: DVec3) -> (f64, f64) {
    let u = 0.5 - d.y.atan2(d.x) / TAU;
    let v = d.z.atan2(d.x.hypot(d.y)) / PI + 0.5;
    (u, v)
}

/// Direction of lat-long (u, v).
#[inline]
pub fn latlong_dir(u: f64, v: f64) -> DVec3 {
    let phi = TAU * (0.5 - u);
    let lat = PI * (v - 0.5);
    let (sp, cp) = phi.sin_cos();
    let (sl, cl) = lat.sin_cos();
    DVec3::new(cp * cl, sp * cl, sl)
}

/// Cube face (0..6: +X, −X, +Y, −Y, +Z, −Z) and face coordinates (s, t) ∈ [0, 1]² of a direction.
#[inline]
pub fn cube_face_st(d: DVec3) -> (usize, f64, f64) {
    let (ax, ay, az) = (d.x.abs(), d.y.abs(), d.z.abs());
    let (face, sc, tc, ma) = if ax >= ay && ax >= az {
        if d.x >= 0.0 {
            (0, -d.z, -d.y, ax)
        } else {
            (1, d.z, -d.y, ax)
        }
    } else if ay >= az {
        if d.y >= 0.0 {
            (2, d.x, d.z, ay)
        } else {
            (3, d.x, -d.z, ay)
        }
    } else if d.z >= 0.0 {
        (4, d.x, -d.y, az)
    } else {
        (5, -d.x, -d.y, az)
    };
    if ma <= 0.0 {
        return (4, 0.5, 0.5);
    }
    (face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0))
}

/// Direction through face coordinates (s, t) of a cube face (s, t may leave [0, 1]: the point then
/// lies on the face's plane beyond its edge).
#[inline]
pub fn cube_dir(face: usize, s: f64, t: f64) -> DVec3 {
    let sc = 2.0 * s - 1.0;
    let tc = 2.0 * t - 1.0;
    let p = match face {
        0 => DVec3::new(1.0, -tc, -sc),
        1 => DVec3::new(-1.0, -tc, sc),
        2 => DVec3::new(sc, 1.0, tc),
        3 => DVec3::new(sc, -1.0, -tc),
        4 => DVec3::new(sc, -tc, 1.0),
        _ => DVec3::new(-sc, -tc, -1.0),
    };
    p.normalize()
}

/// Sphere-map (s, t) in the unit disk of a direction (notes: (s, t) = (r_x, r_y)/√(r_x²+r_y²+(r_z+1)²)).
/// `d` must be unit. The antipode of the view, r = (0, 0, −1), maps to the rim point (1, 0).
#[inline]
pub fn sphere_st(d: DVec3) -> (f64, f64) {
    let den = (d.x * d.x + d.y * d.y + (d.z + 1.0) * (d.z + 1.0)).sqrt();
    if den < 1e-300 {
        return (1.0, 0.0);
    }
    (d.x / den, d.y / den)
}

/// Reflected direction r = 2(n·v)n − v at sphere-map (s, t), n = (s, t, √(1 − s² − t²)),
/// v = (0, 0, 1). Points outside the disk are moved onto its rim.
#[inline]
pub fn sphere_dir(s: f64, t: f64) -> DVec3 {
    let rho2 = s * s + t * t;
    let (s, t, nz) = if rho2 >= 1.0 {
        let k = 1.0 / rho2.sqrt();
        (s * k, t * k, 0.0)
    } else {
        (s, t, (1.0 - rho2).sqrt())
    };
    DVec3::new(2.0 * nz * s, 2.0 * nz * t, 2.0 * nz * nz - 1.0).normalize()
}

/// Dual-paraboloid face (0: r_z ≥ 0, 1: r_z < 0) and (u, v) = (r_x, r_y)/(1 + |r_z|) of a unit direction.
#[inline]
pub fn paraboloid_uv(d: DVec3) -> (usize, f64, f64) {
    if d.z >= 0.0 {
        (0, d.x / (1.0 + d.z), d.y / (1.0 + d.z))
    } else {
        (1, d.x / (1.0 - d.z), d.y / (1.0 - d.z))
    }
}

/// Direction of (face, u, v): (2u, 2v, ±(1 − u² − v²))/(1 + u² + v²); beyond the unit circle it
/// continues onto the other hemisphere.
#[inline]
pub fn paraboloid_dir(face: usize, u: f64, v: f64) -> DVec3 {
    let s = u * u + v * v;
    let z = (1.0 - s) / (1.0 + s);
    DVec3::new(
        2.0 * u / (1.0 + s),
        2.0 * v / (1.0 + s),
        if face == 0 { z } else { -z },
    )
}

/// Solid angle of row `i` of texels of an H×W lat-long map: (2π/W)(sin λ_top − sin λ_bottom).
#[inline]
pub fn latlong_texel_solid_angle(height: usize, width: usize, i: usize) -> f64 {
    let top = PI * (0.5 - i as f64 / height as f64);
    let bot = PI * (0.5 - (i + 1) as f64 / height as f64);
    TAU / width as f64 * (top.sin() - bot.sin())
}

// ---------------------------------------------------------------------------------------------

/// An environment map: `faces` × `height` × `width` texels of `channels` f32 values.
#[derive(Debug, Clone)]
pub struct EnvMap {
    pub layout: Layout,
    pub height: usize,
    pub width: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl EnvMap {
    /// Checks the shape (`arg` names the argument in messages) and that every value is finite.
    pub fn new(
        layout: Layout,
        height: usize,
        width: usize,
        channels: usize,
        data: Vec<f32>,
        arg: &str,
    ) -> Result<EnvMap> {
        check_dims(layout, height, width, channels, arg)?;
        let n = layout.faces() * height * width * channels;
        if data.len() != n {
            return Err(RokebyError::invalid(
                arg,
                format!(
                    "expected {n} values ({}×{height}×{width}×{channels}), got {}",
                    layout.faces(),
                    data.len()
                ),
            ));
        }
        if let Some(k) = data.iter().position(|v| !v.is_finite()) {
            let t = k / channels;
            let (f, r, c) = (t / (height * width), (t / width) % height, t % width);
            let at = if layout.faces() > 1 {
                format!("face {f}, row {r}, column {c}")
            } else {
                format!("row {r}, column {c}")
            };
            return Err(RokebyError::invalid(
                arg,
                format!(
                    "value at {at}, channel {} is {} (NaN/inf are not radiance)",
                    k % channels,
                    data[k]
                ),
            ));
        }
        Ok(EnvMap {
            layout,
            height,
            width,
            channels,
            data,
        })
    }

    /// A map filled with zeros (shape checked).
    pub fn zeros(layout: Layout, height: usize, width: usize, channels: usize) -> Result<EnvMap> {
        check_dims(layout, height, width, channels, "size")?;
        Ok(EnvMap {
            layout,
            height,
            width,
            channels,
            data: vec![0.0; layout.faces() * height * width * channels],
        })
    }

    pub fn faces(&self) -> usize {
        self.layout.faces()
    }

    #[inline]
    fn offset(&self, face: usize, i: usize, j: usize) -> usize {
        ((face * self.height + i) * self.width + j) * self.channels
    }

    /// The values of one texel.
    #[inline]
    pub fn texel(&self, face: usize, i: usize, j: usize) -> &[f32] {
        let k = self.offset(face, i, j);
        &self.data[k..k + self.channels]
    }

    /// Unit direction at map coordinates (x, y) of a face (texel units, see the module docs).
    #[inline]
    pub fn direction(&self, face: usize, x: f64, y: f64) -> DVec3 {
        let (w, h) = (self.width as f64, self.height as f64);
        match self.layout {
            Layout::LatLong => latlong_dir(x / w, 1.0 - y / h),
            Layout::Cube => cube_dir(face, x / w, y / h),
            Layout::Sphere => sphere_dir(2.0 * x / w - 1.0, 1.0 - 2.0 * y / h),
            Layout::Paraboloid => paraboloid_dir(face, 2.0 * x / w - 1.0, 2.0 * y / h - 1.0),
        }
    }

    /// Direction through the centre of texel (row i, col j).
    #[inline]
    pub fn texel_direction(&self, face: usize, i: usize, j: usize) -> DVec3 {
        self.direction(face, j as f64 + 0.5, i as f64 + 0.5)
    }

    /// Face and map coordinates (x, y) of a direction (normalised here; zero gives +Z).
    #[inline]
    pub fn coords(&self, d: DVec3) -> (usize, f64, f64) {
        let d = d.normalize_or(DVec3::Z);
        let (w, h) = (self.width as f64, self.height as f64);
        match self.layout {
            Layout::LatLong => {
                let (u, v) = latlong_uv(d);
                (0, u * w, (1.0 - v) * h)
            }
            Layout::Cube => {
                let (f, s, t) = cube_face_st(d);
                (f, s * w, t * h)
            }
            Layout::Sphere => {
                let (s, t) = sphere_st(d);
                (0, 0.5 * (s + 1.0) * w, 0.5 * (1.0 - t) * h)
            }
            Layout::Paraboloid => {
                let (f, u, v) = paraboloid_uv(d);
                (f, 0.5 * (u + 1.0) * w, 0.5 * (v + 1.0) * h)
            }
        }
    }

    /// Adds `wt` × the value of tap (i, j) of a bilinear footprint on `face` to `out`, following
    /// seams: lat-long columns wrap and rows continue across the poles (column j + W/2); a cube
    /// tap off its face, and a paraboloid tap off its square (where the equator touches the
    /// sides), is the bilinear value, on the face it falls on, of the direction through the tap's
    /// centre on the extended face; sphere-map taps are clamped (texels off the disk hold the rim).
    #[inline]
    fn add_tap(&self, face: usize, i: i64, j: i64, wt: f32, out: &mut [f32]) {
        let (h, w) = (self.height as i64, self.width as i64);
        let c = self.channels;
        let inside = (0..h).contains(&i) && (0..w).contains(&j);
        let k = match self.layout {
            Layout::LatLong => {
                let (mut i, mut j) = (i, j);
                if i < 0 {
                    i = -1 - i;
                    j += w / 2;
                } else if i >= h {
                    i = 2 * h - 1 - i;
                    j += w / 2;
                }
                let i = i.clamp(0, h - 1) as usize;
                self.offset(0, i, j.rem_euclid(w) as usize)
            }
            Layout::Cube | Layout::Paraboloid if !inside => {
                let (x, y) = (j as f64 + 0.5, i as f64 + 0.5);
                let d = match self.layout {
                    Layout::Cube => cube_dir(face, x / w as f64, y / h as f64),
                    _ => paraboloid_dir(face, 2.0 * x / w as f64 - 1.0, 2.0 * y / h as f64 - 1.0),
                };
                let (f, x2, y2) = self.coords(d);
                let mut tmp = [0.0f32; 16];
                let mut heap;
                let v: &mut [f32] = if c <= 16 {
                    &mut tmp[..c]
                } else {
                    heap = vec![0.0f32; c];
                    &mut heap
                };
                self.bilinear_clamped(f, x2, y2, v);
                for (acc, &x) in out[..c].iter_mut().zip(&v[..c]) {
                    *acc += wt * x;
                }
                return;
            }
            _ => self.offset(face, i.clamp(0, h - 1) as usize, j.clamp(0, w - 1) as usize),
        };
        for (acc, &x) in out[..c].iter_mut().zip(&self.data[k..k + c]) {
            *acc += wt * x;
        }
    }

    /// Bilinear lookup within one face, taps clamped to it.
    fn bilinear_clamped(&self, face: usize, x: f64, y: f64, out: &mut [f32]) {
        let (h, w) = (self.height as i64, self.width as i64);
        let (xs, ys) = (x - 0.5, y - 0.5);
        let (j0, i0) = (xs.floor(), ys.floor());
        let (fx, fy) = ((xs - j0) as f32, (ys - i0) as f32);
        let (j0, i0) = (j0 as i64, i0 as i64);
        let c = self.channels;
        for o in out[..c].iter_mut() {
            *o = 0.0;
        }
        for (i, j, wt) in [
            (i0, j0, (1.0 - fx) * (1.0 - fy)),
            (i0, j0 + 1, fx * (1.0 - fy)),
            (i0 + 1, j0, (1.0 - fx) * fy),
            (i0 + 1, j0 + 1, fx * fy),
        ] {
            let k = self.offset(face, i.clamp(0, h - 1) as usize, j.clamp(0, w - 1) as usize);
            for (acc, &x) in out[..c].iter_mut().zip(&self.data[k..k + c]) {
                *acc += wt * x;
            }
        }
    }

    /// Bilinear lookup at map coordinates of a face, written into `out[..channels]`.
    pub fn sample_at(&self, face: usize, x: f64, y: f64, out: &mut [f32]) {
        let (xs, ys) = (x - 0.5, y - 0.5);
        let (j0, i0) = (xs.floor(), ys.floor());
        let (fx, fy) = ((xs - j0) as f32, (ys - i0) as f32);
        let (j0, i0) = (j0 as i64, i0 as i64);
        for o in out[..self.channels].iter_mut() {
            *o = 0.0;
        }
        let taps = [
            (i0, j0, (1.0 - fx) * (1.0 - fy)),
            (i0, j0 + 1, fx * (1.0 - fy)),
            (i0 + 1, j0, (1.0 - fx) * fy),
            (i0 + 1, j0 + 1, fx * fy),
        ];
        for (i, j, wt) in taps {
            if wt != 0.0 {
                self.add_tap(face, i, j, wt, out);
            }
        }
    }

    /// Bilinear, seam-correct lookup E(d) (d need not be unit), written into `out[..channels]`.
    #[inline]
    pub fn sample(&self, d: DVec3, out: &mut [f32]) {
        let (f, x, y) = self.coords(d);
        self.sample_at(f, x, y, out);
    }

    /// Looks up N directions (N×3, need not be unit) → N×channels values.
    pub fn sample_many(&self, dirs: &[f32]) -> Result<Vec<f32>> {
        let dirs = finite_dirs(dirs, "directions")?;
        let c = self.channels;
        let mut out = vec![0.0f32; dirs.len() * c];
        out.par_chunks_mut(c)
            .zip(dirs.par_iter())
            .for_each(|(o, d)| self.sample(*d, o));
        Ok(out)
    }

    /// The same environment on another parametrisation (`height`×`width` texels per face; cube,
    /// sphere and paraboloid faces must be square). Each target texel averages `supersample`²
    /// bilinear lookups at a regular sub-texel grid (1: the texel centre only).
    pub fn convert(
        &self,
        layout: Layout,
        height: usize,
        width: usize,
        supersample: usize,
    ) -> Result<EnvMap> {
        if supersample == 0 || supersample > 16 {
            return Err(RokebyError::invalid(
                "supersample",
                format!("must be 1..16, got {supersample}"),
            ));
        }
        let mut out = EnvMap::zeros(layout, height, width, self.channels)?;
        let c = self.channels;
        let n = supersample;
        let inv = 1.0 / (n * n) as f32;
        let row_len = width * c;
        out.data
            .par_chunks_mut(row_len)
            .enumerate()
            .for_each(|(fr, row)| {
                let (face, i) = (fr / height, fr % height);
                let mut tmp = vec![0.0f32; c];
                for j in 0..width {
                    let o = &mut row[j * c..(j + 1) * c];
                    for a in 0..n {
                        for b in 0..n {
                            let x = j as f64 + (b as f64 + 0.5) / n as f64;
                            let y = i as f64 + (a as f64 + 0.5) / n as f64;
                            let d = out_direction(layout, height, width, face, x, y);
                            self.sample(d, &mut tmp);
                            for ch in 0..c {
                                o[ch] += tmp[ch];
                            }
                        }
                    }
                    if n > 1 {
                        for v in o.iter_mut() {
                            *v *= inv;
                        }
                    }
                }
            });
        Ok(out)
    }
}

/// Direction at map coordinates of a map of the given layout and size (without the map).
#[inline]
fn out_direction(
    layout: Layout,
    height: usize,
    width: usize,
    face: usize,
    x: f64,
    y: f64,
) -> DVec3 {
    let probe = EnvMap {
        layout,
        height,
        width,
        channels: 0,
        data: Vec::new(),
    };
    probe.direction(face, x, y)
}

/// The most values one map may hold (4 GiB of float32): larger requests are errors, not aborts.
pub const MAX_VALUES: usize = 1 << 30;

fn check_dims(
    layout: Layout,
    height: usize,
    width: usize,
    channels: usize,
    arg: &str,
) -> Result<()> {
    if channels == 0 {
        return Err(RokebyError::invalid(arg, "needs at least one channel"));
    }
    let n = [layout.faces(), height, width, channels]
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b));
    if n.is_none_or(|n| n > MAX_VALUES) {
        return Err(RokebyError::invalid(
            arg,
            format!("a {} map of {}×{height}×{width}×{channels} values is more than {MAX_VALUES} (4 GiB of float32)", layout.name(), layout.faces()),
        ));
    }
    match layout {
        Layout::LatLong => {
            if height < 2 || width < 2 {
                return Err(RokebyError::invalid(
                    arg,
                    format!("a lat-long map needs at least 2×2 texels, got {height}×{width}"),
                ));
            }
        }
        _ => {
            if height != width || height == 0 {
                return Err(RokebyError::invalid(
                    arg,
                    format!(
                        "{} faces must be square and non-empty, got {height}×{width}",
                        layout.name()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// N×3 directions, finite and non-zero.
pub fn finite_dirs(dirs: &[f32], arg: &str) -> Result<Vec<DVec3>> {
    if !dirs.len().is_multiple_of(3) {
        return Err(RokebyError::invalid(
            arg,
            format!("expected N×3 values, got {}", dirs.len()),
        ));
    }
    dirs.chunks_exact(3)
        .enumerate()
        .map(|(i, c)| {
            let d = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
            if !d.is_finite() || d.length_squared() < 1e-24 {
                Err(RokebyError::invalid(
                    arg,
                    format!("direction {i} is zero or not finite"),
                ))
            } else {
                Ok(d.normalize())
            }
        })
        .collect()
}
