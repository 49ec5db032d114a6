//! Prefiltered reflection environment reconstructed from a reflection buffer (Zubiaga et al. 2016,
//! §3.2), stored as a dual-paraboloid map [HS98].
//!
//! 1. **Partial reconstruction** (eq. 2). Each 2×2 block of patch pixels is a spherical quad of
//!    reflected directions r; blocks cut by a discontinuity (an invalid pixel, a reflected-direction
//!    jump or a depth jump) leave the triangle that is still whole (the paper's boundary
//!    triangles). A quad is interpolated as two spherical triangles, where the spherical barycentric
//!    coordinates of [LBS06] are exact and unique (λ solves Σλⱼvⱼ = q, then normalised to Σλⱼ = 1:
//!    the partition-of-unity form the paper uses). Both triangles carry their polygon's weight
//!    w = (1 − acos(ℓ)/π)^η, ℓ the cosine of the polygon's longest arc, η = 200, so that the least
//!    curved image locations win. Pixels masked out (self-reflections from the reflection-occlusion
//!    buffer α_R, other patches, non-finite values) form no polygon. As in the paper, the search
//!    runs on a 2D grid over the orthographic projection of the rectified normals
//!    n' = (r + z)/‖r + z‖ (so that r = reflect(z, n') — a single hemisphere), conservatively
//!    (bounding box of the projected corners padded by the arcs' sagitta), and barycentric
//!    coordinates are computed on n' too; the grid holds the texel centres (fewer than the
//!    polygons), and each polygon visits those in its box, lazily computing its weight and its
//!    corners' dual vectors only when one lies inside. Weights are combined in log space, so that
//!    η = 200 does not underflow for large polygons when nothing smaller covers a direction.
//! 2. **Hole filling** by harmonic interpolation with the recovered texels as Dirichlet values.
//!    The paraboloid parametrisation (u, v) = (r_x, r_y)/(1 ± r_z) is the stereographic projection,
//!    which is conformal, and harmonicity is invariant under conformal maps in 2D: the harmonic
//!    interpolant on the sphere is the harmonic interpolant in (u, v). So each face uses the plain
//!    5-point Laplacian on its texel grid; across the equator (the unit circle, where both faces
//!    meet) a neighbour that falls outside the disk is the other face's bilinear value at the
//!    inverted position uv/|uv|², which is where that direction lies on the other face. One sparse
//!    LU (faer) solves all channels and the two position channels at once.
//! 3. **Regularisation**: a second map holds the image position x of the pixels that produced each
//!    texel (eq. 2 with R0(xⱼ) replaced by xⱼ, hole-filled the same way); where its gradient is
//!    large, neighbouring texels come from remote polygons, and a Gaussian whose σ grows with the
//!    gradient magnitude blurs the radiance there.
//!
//! Storage is f32; barycentric coordinates, weights, accumulations and the solve are f64.

use crate::error::{Result, RokebyError};
use crate::numerical::Triplet;
use crate::unit_vector::unit_row;
use faer::linalg::solvers::Solve;
use faer::Mat;
use glam::DVec3;
use rayon::prelude::*;

/// η of the polygon weights (paper §3.2).
pub const ETA: f64 = 200.0;

/// A dual-paraboloid map: two `size`×`size` faces (0: r_z ≥ 0, 1: r_z < 0), `channels` floats per
/// texel, laid out [face][row][col][channel]. Texel (i, j) has its centre at
/// u = (j + ½)·2/size − 1, v = (i + ½)·2/size − 1; texels with u² + v² > 1 lie beyond the equator
/// and hold the other face's value there, so that bilinear lookups are seamless.
#[derive(Debug, Clone)]
pub struct ParaboloidMap {
    pub size: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

#[inline]
fn texel_uv(size: usize, i: usize, j: usize) -> (f64, f64) {
    let h = 2.0 / size as f64;
    ((j as f64 + 0.5) * h - 1.0, (i as f64 + 0.5) * h - 1.0)
}

/// The dual-paraboloid projection both ways (face, u, v) ↔ unit direction: the map layout is the
/// one of `envmap`, so its formulas serve here under the names this module uses.
pub use crate::envmaps::envmap::{paraboloid_dir as uv_to_dir, paraboloid_uv as dir_to_uv};

/// Solid angle of texel (i, j) of either face (the projection's area factor 4/(1 + ρ²)²).
#[inline]
fn texel_solid_angle(size: usize, i: usize, j: usize) -> f64 {
    let (u, v) = texel_uv(size, i, j);
    let s = u * u + v * v;
    let h = 2.0 / size as f64;
    4.0 * h * h / ((1.0 + s) * (1.0 + s))
}

impl ParaboloidMap {
    pub fn new(size: usize, channels: usize) -> Self {
        ParaboloidMap {
            size,
            channels,
            data: vec![0.0; 2 * size * size * channels],
        }
    }

    #[inline]
    fn idx(&self, face: usize, i: usize, j: usize) -> usize {
        ((face * self.size + i) * self.size + j) * self.channels
    }

    /// Bilinear lookup in a direction (need not be unit), written into `out` (`channels` values).
    pub fn lookup(&self, d: DVec3, out: &mut [f64]) {
        let d = d.normalize_or(DVec3::Z);
        let (face, u, v) = dir_to_uv(d);
        self.lookup_uv(face, u, v, out);
    }

    fn lookup_uv(&self, face: usize, u: f64, v: f64, out: &mut [f64]) {
        let s = self.size as f64;
        let x = ((u + 1.0) * 0.5 * s - 0.5).clamp(0.0, s - 1.0);
        let y = ((v + 1.0) * 0.5 * s - 0.5).clamp(0.0, s - 1.0);
        // x, y ≥ 0 after the clamp: truncation is floor (and needs no libm call).
        let (j0, i0) = (x as usize, y as usize);
        let (j1, i1) = ((j0 + 1).min(self.size - 1), (i0 + 1).min(self.size - 1));
        let (fx, fy) = (x - j0 as f64, y - i0 as f64);
        let c = self.channels;
        if c == 3 {
            let (k00, k01, k10, k11) = (
                self.idx(face, i0, j0),
                self.idx(face, i0, j1),
                self.idx(face, i1, j0),
                self.idx(face, i1, j1),
            );
            let d = &self.data;
            for ch in 0..3 {
                let top = d[k00 + ch] as f64 + fx * (d[k01 + ch] as f64 - d[k00 + ch] as f64);
                let bot = d[k10 + ch] as f64 + fx * (d[k11 + ch] as f64 - d[k10 + ch] as f64);
                out[ch] = top + fy * (bot - top);
            }
            return;
        }
        let taps = [
            (i0, j0, (1.0 - fx) * (1.0 - fy)),
            (i0, j1, fx * (1.0 - fy)),
            (i1, j0, (1.0 - fx) * fy),
            (i1, j1, fx * fy),
        ];
        for o in out.iter_mut().take(c) {
            *o = 0.0;
        }
        for (i, j, w) in taps {
            let k = self.idx(face, i, j);
            for (acc, &x) in out[..c].iter_mut().zip(&self.data[k..k + c]) {
                *acc += w * x as f64;
            }
        }
    }
}

/// Parameters of the reconstruction.
#[derive(Debug, Clone)]
pub struct ReflectionParams {
    /// Texels per side of each paraboloid face.
    pub size: usize,
    /// Polygons whose corners' reflected directions differ by more than this (radians) across an
    /// edge straddle a discontinuity and are not formed.
    pub max_edge_angle: f64,
    /// Relative depth jump |d_a − d_b| / min(d_a, d_b) above which an edge is a discontinuity.
    pub max_depth_jump: f64,
    /// Largest σ (texels) of the regularising blur; 0 disables it.
    pub blur_sigma: f64,
    /// Smallest fraction of the sphere's solid angle the partial map must cover.
    pub min_coverage: f64,
}

impl Default for ReflectionParams {
    fn default() -> Self {
        ReflectionParams {
            size: 128,
            max_edge_angle: 0.5,
            max_depth_jump: 0.05,
            blur_sigma: 2.0,
            min_coverage: 0.01,
        }
    }
}

/// The partial map of eq. 2 and its position map.
#[derive(Debug, Clone)]
pub struct PartialMap {
    /// Radiance (eq. 2), zero where not covered.
    pub map: ParaboloidMap,
    /// Image position (x, y) in pixels of the contributing polygons (eq. 2 with xⱼ for R0(xⱼ)).
    pub positions: ParaboloidMap,
    /// Per texel of both faces (size·size·2): covered by at least one polygon.
    pub covered: Vec<bool>,
    /// Fraction of the sphere's solid angle covered.
    pub coverage: f64,
    /// Number of spherical triangles formed.
    pub triangles: usize,
}

/// Screen-space reflected directions r = 2(n·v)n − v for unit normals n and unit view vectors v
/// (pointing from the surface to the eye), both H·W×3. Pixels whose n or v is not finite give
/// NaN (NaN in, NaN out); pixels whose n or v is zero (background pixels of a normal pass) give
/// the zero vector: they have no direction, and finite input never gives NaN.
pub fn reflect_dirs(normals: &[f32], view: &[f32]) -> Result<Vec<f32>> {
    if !normals.len().is_multiple_of(3) {
        return Err(RokebyError::invalid("normals", "expected N×3 values"));
    }
    if view.len() != normals.len() && view.len() != 3 {
        return Err(RokebyError::invalid(
            "view",
            format!(
                "expected {} values (like normals) or one vector (3), got {}",
                normals.len(),
                view.len()
            ),
        ));
    }
    let mut out = vec![0.0f32; normals.len()];
    out.par_chunks_mut(3).enumerate().for_each(|(p, o)| {
        let n = unit_row(&normals[3 * p..3 * p + 3]);
        let vv = if view.len() == 3 {
            unit_row(view)
        } else {
            unit_row(&view[3 * p..3 * p + 3])
        };
        let finite = normals[3 * p..3 * p + 3].iter().all(|x| x.is_finite())
            && if view.len() == 3 {
                view.iter().all(|x| x.is_finite())
            } else {
                view[3 * p..3 * p + 3].iter().all(|x| x.is_finite())
            };
        let r = match (n, vv) {
            (Some(n), Some(v)) => reflect(v, n),
            _ if finite => DVec3::ZERO,
            _ => DVec3::NAN,
        };
        o.copy_from_slice(&[r.x as f32, r.y as f32, r.z as f32]);
    });
    Ok(out)
}

/// reflect(v, n) = 2(n·v)n − v (v towards the eye).
#[inline]
pub fn reflect(v: DVec3, n: DVec3) -> DVec3 {
    2.0 * n.dot(v) * n - v
}

/// Rectified normal n'(r) = (r + z)/‖r + z‖ (undefined for r = −z).
#[inline]
fn rectify(r: DVec3) -> Option<DVec3> {
    let s = r + DVec3::Z;
    let l = s.length();
    if l > 1e-6 {
        Some(s / l)
    } else {
        None
    }
}

/// Checks the arguments of [`partial`].
// The arguments of `partial`, one by one as it receives them.
#[allow(clippy::too_many_arguments)]
fn check_partial_args(
    width: usize,
    height: usize,
    refl: &[f32],
    values: &[f32],
    channels: usize,
    mask: &[f32],
    depth: &[f32],
    params: &ReflectionParams,
) -> Result<()> {
    let np = width * height;
    if np == 0 {
        return Err(RokebyError::invalid("image", "empty image"));
    }
    if refl.len() != np * 3 {
        return Err(RokebyError::invalid(
            "reflected",
            format!("expected {height}×{width}×3 values, got {}", refl.len()),
        ));
    }
    if channels == 0 || values.len() != np * channels {
        return Err(RokebyError::invalid(
            "values",
            format!(
                "expected {height}×{width}×{channels} values, got {}",
                values.len()
            ),
        ));
    }
    if mask.len() != np {
        return Err(RokebyError::invalid(
            "mask",
            format!("expected {height}×{width} values, got {}", mask.len()),
        ));
    }
    if !depth.is_empty() && depth.len() != np {
        return Err(RokebyError::invalid(
            "depth",
            format!(
                "expected {height}×{width} values or none, got {}",
                depth.len()
            ),
        ));
    }
    if !(8..=4096).contains(&params.size) {
        return Err(RokebyError::invalid(
            "size",
            format!("map size must be in 8..=4096, got {}", params.size),
        ));
    }
    // Every parameter must be finite and in range: a NaN (blur_sigma = NaN) would give a NaN map.
    if !(params.max_edge_angle.is_finite() && params.max_edge_angle > 0.0) {
        return Err(RokebyError::invalid(
            "max_edge_angle",
            format!(
                "must be positive and finite (radians), got {}",
                params.max_edge_angle
            ),
        ));
    }
    if params.max_depth_jump.is_nan() || params.max_depth_jump < 0.0 {
        return Err(RokebyError::invalid(
            "max_depth_jump",
            format!("must be ≥ 0, got {}", params.max_depth_jump),
        ));
    }
    if !(params.blur_sigma.is_finite() && params.blur_sigma >= 0.0) {
        return Err(RokebyError::invalid(
            "blur_sigma",
            format!(
                "must be ≥ 0 and finite (0 disables the blur), got {}",
                params.blur_sigma
            ),
        ));
    }
    if !(0.0..=1.0).contains(&params.min_coverage) {
        return Err(RokebyError::invalid(
            "min_coverage",
            format!("must be a fraction in [0, 1], got {}", params.min_coverage),
        ));
    }
    Ok(())
}

/// Coverage: the covered fraction of the sphere's solid angle.
fn coverage_of(s: usize, covered: &[bool]) -> f64 {
    let (mut cov, mut total) = (0.0, 0.0);
    for face in 0..2 {
        for i in 0..s {
            for j in 0..s {
                let (u, v) = texel_uv(s, i, j);
                if u * u + v * v > 1.0 {
                    continue;
                }
                let a = texel_solid_angle(s, i, j);
                total += a;
                if covered[(face * s + i) * s + j] {
                    cov += a;
                }
            }
        }
    }
    cov / total
}

/// Cells per side of the lookup grid of texel centres over (n'_x, n'_y) ∈ [−1, 1]², per texel of
/// a face's side (about one texel centre per cell).
const TEXEL_GRID_PER_SIDE: f64 = 1.5;
/// Image rows of 2×2 blocks per parallel task (fixed: the hits come out in the polygons' order on
/// any number of threads).
const ROWS_PER_TASK: usize = 8;

/// A texel centre inside a spherical triangle: `t` its index in the sorted texel centres, `v` the
/// triangle's corners (pixels), `l` its (unnormalised) barycentric coordinates there, `lw` the log
/// weight of the triangle's polygon.
struct Hit {
    t: u32,
    v: [u32; 3],
    l: [f64; 3],
    lw: f64,
}

/// Bounding box (x0, x1, y0, y1) of the orthographic projection of the spherical triangle with
/// unit corners `ns`, padded by the sagitta of its longest arc 1 − cos(θ/2) = 1 − √((1 + cos θ)/2).
#[inline(always)]
fn tri_box(ns: &[DVec3; 3]) -> [f64; 4] {
    box_of(
        ns,
        fmin(fmin(ns[0].dot(ns[1]), ns[1].dot(ns[2])), ns[2].dot(ns[0])),
    )
}

/// [`tri_box`] given the smallest cosine `mind` of the three arcs.
#[inline(always)]
fn box_of(ns: &[DVec3; 3], mind: f64) -> [f64; 4] {
    let pad = sagitta(mind);
    [
        fmin(fmin(ns[0].x, ns[1].x), ns[2].x) - pad,
        fmax(fmax(ns[0].x, ns[1].x), ns[2].x) + pad,
        fmin(fmin(ns[0].y, ns[1].y), ns[2].y) - pad,
        fmax(fmax(ns[0].y, ns[1].y), ns[2].y) + pad,
    ]
}

/// 1 − cos(θ/2) for cos θ = `c` (the sagitta of an arc of the unit sphere), plus 1e-9.
#[inline(always)]
fn sagitta(c: f64) -> f64 {
    (1.0 - (0.5 * (1.0 + c.clamp(-1.0, 1.0))).sqrt()) + 1e-9
}

#[inline(always)]
fn fmin(a: f64, b: f64) -> f64 {
    if b < a {
        b
    } else {
        a
    }
}

#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// Whether neighbouring pixels a, b (reflected directions ra, rb) lie on one smooth piece of the
/// surface: their directions within the edge angle (cos_edge) and, with a depth pass, their
/// depths within max_depth_jump relative of each other (eq. 2's quads stop at discontinuities).
#[inline]
fn no_discontinuity(
    ra: DVec3,
    rb: DVec3,
    depth: &[f32],
    a: usize,
    b: usize,
    cos_edge: f64,
    max_depth_jump: f64,
) -> bool {
    if ra.dot(rb) < cos_edge {
        return false;
    }
    if !depth.is_empty() {
        let (da, db) = (depth[a] as f64, depth[b] as f64);
        if (da - db).abs() > max_depth_jump * da.abs().min(db.abs()) {
            return false;
        }
    }
    true
}

/// Partial reconstruction (eq. 2) of one patch.
///
/// * `refl`: H·W×3 reflected directions r (screen space, unit);
/// * `values`: H·W×C reflection shading R0;
/// * `mask`: H·W, > 0.5 where the pixel belongs to the patch and is unoccluded (α_R);
/// * `depth`: H·W or empty (no depth discontinuities).
///
/// Eq. 2 is evaluated per texel over the polygons containing its direction, in the polygons'
/// order (image rows, then columns), as in the paper's grid query; the search runs the other way
/// round for speed: the texel centres are binned on a grid over (n'_x, n'_y), and each 2×2 block
/// of pixels, as it is formed, looks up the centres in its padded box (both triangles of a quad at
/// once) and then tests those in each triangle's own box. The hits come out in the polygons'
/// order (fixed tasks of block rows) and are accumulated per texel in that order (each texel by
/// one task), so the map does not depend on the number of threads.
// Entry point: the G-buffer planes of the reflection pass (refl, values, mask, depth), their size
// and channels, one argument each as the binding hands them over (shared by `check_partial_args`).
#[allow(clippy::too_many_arguments)]
pub fn partial(
    width: usize,
    height: usize,
    refl: &[f32],
    values: &[f32],
    channels: usize,
    mask: &[f32],
    depth: &[f32],
    params: &ReflectionParams,
) -> Result<PartialMap> {
    check_partial_args(width, height, refl, values, channels, mask, depth, params)?;
    let np = width * height;
    let s = params.size;
    let ch = channels;
    // Per-pixel r and n'; invalid pixels (masked, non-finite, r = −z) have ok = false.
    let mut rr = vec![DVec3::ZERO; np];
    let mut nr = vec![DVec3::ZERO; np];
    let mut ok = vec![false; np];
    rr.par_chunks_mut(width)
        .zip(nr.par_chunks_mut(width))
        .zip(ok.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, ((ro, no), ko))| {
            for x in 0..width {
                let p = y * width + x;
                if !(mask[p] > 0.5
                    && values[p * channels..(p + 1) * channels]
                        .iter()
                        .all(|v| v.is_finite()))
                {
                    continue;
                }
                if !depth.is_empty() && !depth[p].is_finite() {
                    continue;
                }
                let Some(r) = unit_row(&refl[3 * p..3 * p + 3]) else {
                    continue;
                };
                let Some(n) = rectify(r) else { continue };
                ro[x] = r;
                no[x] = n;
                ko[x] = true;
            }
        });
    let cos_edge = params.max_edge_angle.cos();
    // Pixels a and b (both valid) are connected: no discontinuity between them.
    let edge = |a: usize, b: usize| -> bool {
        no_discontinuity(rr[a], rr[b], depth, a, b, cos_edge, params.max_depth_jump)
    };
    let connected = |a: usize, b: usize| -> bool { ok[a] && ok[b] && edge(a, b) };
    // Per pixel p, the edges to its neighbours without discontinuity (both pixels valid): bit 0 to
    // p + 1, bit 1 to p + W, bit 2 to p + W + 1 (the quads' diagonal).
    let mut links = vec![0u8; np];
    links.par_chunks_mut(width).enumerate().for_each(|(y, lo)| {
        for (x, l) in lo.iter_mut().enumerate() {
            let p = y * width + x;
            if !ok[p] {
                continue;
            }
            let (right, down) = (x + 1 < width, y + 1 < height);
            *l = (right && connected(p, p + 1)) as u8
                | ((down && connected(p, p + width)) as u8) << 1
                | ((right && down && connected(p, p + width + 1)) as u8) << 2;
        }
    });
    // w = (1 − acos(ℓ)/π)^η of a polygon, ℓ the cosine of its longest arc; in log space.
    let log_weight = |vs: &[u32]| -> f64 {
        let mut l = 1.0f64;
        for a in 0..vs.len() {
            for b in a + 1..vs.len() {
                l = l.min(rr[vs[a] as usize].dot(rr[vs[b] as usize]));
            }
        }
        ETA * (1.0 - l.clamp(-1.0, 1.0).acos() / std::f64::consts::PI)
            .max(1e-300)
            .ln()
    };
    // Lookup grid of the texel centres' rectified directions q.
    let gt = ((TEXEL_GRID_PER_SIDE * s as f64).ceil() as usize).max(8);
    let half_g = 0.5 * gt as f64;
    // floor((x + 1)·g/2) clamped to the grid; `as` saturates (negative or NaN → 0).
    let cell = |x: f64| -> usize { (((x + 1.0) * half_g) as usize).min(gt - 1) };
    // Texel centres inside the disks (the others are not reconstructed), sorted by grid cell.
    let mut tex: Vec<(u32, u32, DVec3)> = Vec::with_capacity(2 * s * s);
    for face in 0..2 {
        for i in 0..s {
            crate::cancel::check()?;
            for j in 0..s {
                let (u, v) = texel_uv(s, i, j);
                if u * u + v * v > 1.0 {
                    continue;
                }
                let Some(q) = rectify(uv_to_dir(face, u, v)) else {
                    continue;
                };
                tex.push((
                    (cell(q.y) * gt + cell(q.x)) as u32,
                    ((face * s + i) * s + j) as u32,
                    q,
                ));
            }
        }
    }
    // By grid row, then by q.x (so by cell within a row: cell(x) is monotone), then texel; the
    // keys are unique, so an unstable sort gives that order. q.x as an integer ordered like
    // `f64::total_cmp`.
    let total_key = |x: f64| -> i64 {
        let b = x.to_bits() as i64;
        b ^ ((((b >> 63) as u64) >> 1) as i64)
    };
    crate::cancel::check()?;
    tex.sort_unstable_by_key(|t| (t.0 / gt as u32, total_key(t.2.x), t.1));
    crate::cancel::check()?;
    let tex_xy: Vec<[f64; 2]> = tex.iter().map(|t| [t.2.x, t.2.y]).collect();
    let mut cell_start = vec![0u32; gt * gt + 1];
    for t in &tex {
        cell_start[t.0 as usize + 1] += 1;
    }
    for k in 0..gt * gt {
        cell_start[k + 1] += cell_start[k];
    }
    // The texel centres in the box `bx`, into `cand`.
    let centres_in = |bx: &[f64; 4], cand: &mut Vec<u32>| {
        cand.clear();
        let (cx0, cx1) = (cell(bx[0]), cell(bx[1]));
        for cy in cell(bx[2])..=cell(bx[3]) {
            let (k0, k1) = (
                cell_start[cy * gt + cx0] as usize,
                cell_start[cy * gt + cx1 + 1] as usize,
            );
            for (t, &[qx, qy]) in tex_xy[k0..k1].iter().enumerate() {
                if qx > bx[1] {
                    break; // the row is sorted by q.x
                }
                if qx < bx[0] || qy < bx[2] || qy > bx[3] {
                    continue;
                }
                cand.push((k0 + t) as u32);
            }
        }
    };
    // The candidates inside triangle `tv` (in its own box, barycentric coordinates ≥ 0) of the
    // polygon `poly`, whose log weight is computed at the first hit.
    let tri_hits = |tv: [u32; 3],
                    vs: &[DVec3; 3],
                    bx: &[f64; 4],
                    poly: &[u32],
                    cand: &[u32],
                    logw: &mut Option<f64>,
                    hits: &mut Vec<Hit>| {
        // Dual vectors of the corners (λ = (q·d₀, q·d₁, q·d₂)), when a centre is in the box.
        let mut duals: Option<[DVec3; 3]> = None;
        for &t in cand {
            let [qx, qy] = tex_xy[t as usize];
            if qx < bx[0] || qx > bx[1] || qy < bx[2] || qy > bx[3] {
                continue;
            }
            let duals = *duals.get_or_insert_with(|| {
                let det = vs[0].dot(vs[1].cross(vs[2]));
                if det.abs() < 1e-300 {
                    // Degenerate: contains nothing.
                    [DVec3::ZERO, DVec3::ZERO, DVec3::ZERO]
                } else {
                    let inv = 1.0 / det;
                    [
                        vs[1].cross(vs[2]) * inv,
                        vs[2].cross(vs[0]) * inv,
                        vs[0].cross(vs[1]) * inv,
                    ]
                }
            });
            let q = tex[t as usize].2;
            // Spherical barycentric coordinates: λ solves Σλⱼvⱼ = q ([LBS06]).
            let l = [q.dot(duals[0]), q.dot(duals[1]), q.dot(duals[2])];
            let tol = -1e-12;
            if l[0] < tol || l[1] < tol || l[2] < tol {
                continue;
            }
            let sum = l[0] + l[1] + l[2];
            if sum.is_nan() || sum <= 0.0 {
                continue;
            }
            let lw = *logw.get_or_insert_with(|| log_weight(poly));
            hits.push(Hit { t, v: tv, l, lw });
        }
    };
    // Polygons per 2×2 block and their hits, in the polygons' order (rows of blocks in parallel).
    let quad_rows = height.saturating_sub(1);
    let tasks: Vec<(usize, Vec<Hit>)> = (0..quad_rows.div_ceil(ROWS_PER_TASK))
        .into_par_iter()
        .map(|task| {
            let (mut n_tris, mut hits, mut cand) = (
                0usize,
                Vec::with_capacity(ROWS_PER_TASK * width / 2),
                Vec::new(),
            );
            for y in task * ROWS_PER_TASK..((task + 1) * ROWS_PER_TASK).min(quad_rows) {
                if crate::cancel::requested() {
                    break; // the call returns Cancelled below
                }
                for x in 0..width - 1 {
                    let a = y * width + x;
                    let (b, c, d) = (a + 1, a + 1 + width, a + width);
                    let (la, lb, ld) = (links[a], links[b], links[d]);
                    // (a, b), (d, a), (a, c), (b, c), (d, c) all connected.
                    if la == 7 && lb & 2 != 0 && ld & 1 != 0 {
                        n_tris += 2;
                        // Both triangles (a, b, c), (a, c, d) from the five arcs' cosines; the
                        // union of their boxes selects the candidates of both.
                        let (na, nb, nc, nd) = (nr[a], nr[b], nr[c], nr[d]);
                        let (ab, bc, ca, cd, da) =
                            (na.dot(nb), nb.dot(nc), nc.dot(na), nc.dot(nd), nd.dot(na));
                        let (v1, v2) = ([na, nb, nc], [na, nc, nd]);
                        let b1 = box_of(&v1, fmin(fmin(ab, bc), ca));
                        let b2 = box_of(&v2, fmin(fmin(ca, cd), da));
                        centres_in(
                            &[
                                fmin(b1[0], b2[0]),
                                fmax(b1[1], b2[1]),
                                fmin(b1[2], b2[2]),
                                fmax(b1[3], b2[3]),
                            ],
                            &mut cand,
                        );
                        if !cand.is_empty() {
                            let poly = [a as u32, b as u32, c as u32, d as u32];
                            let mut logw = None;
                            tri_hits(
                                [poly[0], poly[1], poly[2]],
                                &v1,
                                &b1,
                                &poly,
                                &cand,
                                &mut logw,
                                &mut hits,
                            );
                            tri_hits(
                                [poly[0], poly[2], poly[3]],
                                &v2,
                                &b2,
                                &poly,
                                &cand,
                                &mut logw,
                                &mut hits,
                            );
                        }
                        continue;
                    }
                    // At most a boundary triangle: the first whole one of these.
                    let (ab, ad, ac, bc, dc) = (
                        la & 1 != 0,
                        la & 2 != 0,
                        la & 4 != 0,
                        lb & 2 != 0,
                        ld & 1 != 0,
                    );
                    let tri = if ab && bc && ac {
                        [a, b, c]
                    } else if ab && ad && connected(b, d) {
                        [a, b, d]
                    } else if bc && dc && connected(b, d) {
                        [b, c, d]
                    } else if ac && dc && ad {
                        [a, c, d]
                    } else {
                        continue;
                    };
                    n_tris += 1;
                    let tv = tri.map(|p| p as u32);
                    let vs = tri.map(|p| nr[p]);
                    let bx = tri_box(&vs);
                    centres_in(&bx, &mut cand);
                    if !cand.is_empty() {
                        tri_hits(tv, &vs, &bx, &tv, &cand, &mut None, &mut hits);
                    }
                }
            }
            (n_tris, hits)
        })
        .collect();
    crate::cancel::check()?;
    let triangles: usize = tasks.iter().map(|t| t.0).sum();
    let mut map = ParaboloidMap::new(s, ch);
    let mut positions = ParaboloidMap::new(s, 2);
    let mut covered = vec![false; 2 * s * s];
    if triangles == 0 {
        return Ok(PartialMap {
            map,
            positions,
            covered,
            coverage: 0.0,
            triangles: 0,
        });
    }
    // Per texel (in `tex` order): [m, den, x, y, acc…]: the online log-sum of eq. 2's weights.
    // The hits come in the polygons' order; each task takes a fixed range of texels and all
    // their hits (the result does not depend on the ranges).
    let nt = tex.len();
    let stride = 4 + ch;
    let mut acc = vec![0.0f64; nt * stride];
    let per_range = nt.div_ceil(rayon::current_num_threads().max(1)).max(1);
    acc.par_chunks_mut(per_range * stride)
        .enumerate()
        .for_each(|(range, out)| {
            let t0 = range * per_range;
            let t1 = t0 + out.len() / stride;
            for a in out.chunks_exact_mut(stride) {
                a[0] = f64::NEG_INFINITY;
            }
            for h in tasks.iter().flat_map(|t| &t.1) {
                let t = h.t as usize;
                if t < t0 || t >= t1 {
                    continue;
                }
                let a = &mut out[(t - t0) * stride..(t - t0 + 1) * stride];
                let (l, lw) = (h.l, h.lw);
                let sum = l[0] + l[1] + l[2];
                // Online log-sum of weights: rescale when a larger one appears.
                if lw > a[0] {
                    let f = if a[0].is_finite() {
                        (a[0] - lw).exp()
                    } else {
                        0.0
                    };
                    for x in a[1..].iter_mut() {
                        *x *= f;
                    }
                    a[0] = lw;
                }
                // exp(0) = 1 exactly: the common case of the largest weight so far.
                let w = if lw == a[0] { 1.0 } else { (lw - a[0]).exp() };
                a[1] += w;
                let ws = w / sum;
                for (c, &pi) in h.v.iter().enumerate() {
                    let lam = ws * l[c];
                    let p = pi as usize;
                    for cc in 0..ch {
                        a[4 + cc] += lam * values[p * ch + cc] as f64;
                    }
                    a[2] += lam * (p % width) as f64;
                    a[3] += lam * (p / width) as f64;
                }
            }
        });
    drop(tasks);
    for (t, a) in tex.iter().zip(acc.chunks_exact(stride)) {
        let den = a[1];
        if den > 0.0 {
            let k = t.1 as usize;
            covered[k] = true;
            for cc in 0..ch {
                map.data[k * ch + cc] = (a[4 + cc] / den) as f32;
            }
            positions.data[2 * k] = (a[2] / den) as f32;
            positions.data[2 * k + 1] = (a[3] / den) as f32;
        }
    }
    let coverage = coverage_of(s, &covered);
    Ok(PartialMap {
        map,
        positions,
        covered,
        coverage,
        triangles,
    })
}

/// A direct partial reconstruction (a grid of triangles queried per texel), the reference of
/// the tests.
#[cfg(test)]
// The same arguments as `partial` (the test reference).
#[allow(clippy::too_many_arguments)]
pub(crate) fn partial_reference(
    width: usize,
    height: usize,
    refl: &[f32],
    values: &[f32],
    channels: usize,
    mask: &[f32],
    depth: &[f32],
    params: &ReflectionParams,
) -> Result<PartialMap> {
    struct Tri {
        v: [u32; 3],
        logw: f64,
    }
    check_partial_args(width, height, refl, values, channels, mask, depth, params)?;
    let np = width * height;
    // Per-pixel r and n'; invalid pixels (masked, non-finite, r = −z) are None.
    let pix: Vec<Option<(DVec3, DVec3)>> = (0..np)
        .into_par_iter()
        .map(|p| {
            if !(mask[p] > 0.5
                && values[p * channels..(p + 1) * channels]
                    .iter()
                    .all(|v| v.is_finite()))
            {
                return None;
            }
            if !depth.is_empty() && !depth[p].is_finite() {
                return None;
            }
            let r = unit_row(&refl[3 * p..3 * p + 3])?;
            Some((r, rectify(r)?))
        })
        .collect();
    let cos_edge = params.max_edge_angle.cos();
    let connected = |a: usize, b: usize| -> bool {
        match (pix[a], pix[b]) {
            (Some((ra, _)), Some((rb, _))) => {
                no_discontinuity(ra, rb, depth, a, b, cos_edge, params.max_depth_jump)
            }
            _ => false,
        }
    };
    let log_weight = |vs: &[usize]| -> f64 {
        let mut l = 1.0f64;
        for a in 0..vs.len() {
            for b in a + 1..vs.len() {
                l = l.min(pix[vs[a]].unwrap().0.dot(pix[vs[b]].unwrap().0));
            }
        }
        ETA * (1.0 - l.clamp(-1.0, 1.0).acos() / std::f64::consts::PI)
            .max(1e-300)
            .ln()
    };
    // Polygons per 2×2 block, rows in parallel.
    let tris: Vec<Tri> = (0..height.saturating_sub(1))
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut out = Vec::new();
            for x in 0..width - 1 {
                let a = y * width + x;
                let (b, c, d) = (a + 1, a + 1 + width, a + width);
                let ok = [a, b, c, d].map(|p| pix[p].is_some());
                if ok.iter().all(|&o| o)
                    && connected(a, b)
                    && connected(b, c)
                    && connected(c, d)
                    && connected(d, a)
                    && connected(a, c)
                {
                    let lw = log_weight(&[a, b, c, d]);
                    out.push(Tri {
                        v: [a as u32, b as u32, c as u32],
                        logw: lw,
                    });
                    out.push(Tri {
                        v: [a as u32, c as u32, d as u32],
                        logw: lw,
                    });
                    continue;
                }
                for t in [[a, b, c], [a, b, d], [b, c, d], [a, c, d]] {
                    if t.iter().all(|&p| pix[p].is_some())
                        && connected(t[0], t[1])
                        && connected(t[1], t[2])
                        && connected(t[2], t[0])
                    {
                        out.push(Tri {
                            v: [t[0] as u32, t[1] as u32, t[2] as u32],
                            logw: log_weight(&t),
                        });
                        break;
                    }
                }
            }
            out
        })
        .collect();
    let s = params.size;
    let ch = channels;
    let mut map = ParaboloidMap::new(s, ch);
    let mut positions = ParaboloidMap::new(s, 2);
    let mut covered = vec![false; 2 * s * s];
    if tris.is_empty() {
        return Ok(PartialMap {
            map,
            positions,
            covered,
            coverage: 0.0,
            triangles: 0,
        });
    }
    // Grid over (n'_x, n'_y) ∈ [−1, 1]².
    let g = ((tris.len() as f64).sqrt() * 0.5).clamp(8.0, 1024.0) as usize;
    let cell =
        |x: f64| -> usize { (((x + 1.0) * 0.5 * g as f64).floor().max(0.0) as usize).min(g - 1) };
    let ranges: Vec<(usize, usize, usize, usize)> = tris
        .par_iter()
        .map(|t| {
            let ns = t.v.map(|p| pix[p as usize].unwrap().1);
            let mut mind = 1.0f64;
            for a in 0..3 {
                mind = mind.min(ns[a].dot(ns[(a + 1) % 3]));
            }
            let pad = (1.0 - (0.5 * mind.clamp(-1.0, 1.0).acos()).cos()) + 1e-9;
            let xs = ns.map(|n| n.x);
            let ys = ns.map(|n| n.y);
            let (x0, x1) = (
                xs.iter().cloned().fold(f64::INFINITY, f64::min) - pad,
                xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + pad,
            );
            let (y0, y1) = (
                ys.iter().cloned().fold(f64::INFINITY, f64::min) - pad,
                ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + pad,
            );
            (cell(x0), cell(x1), cell(y0), cell(y1))
        })
        .collect();
    let mut counts = vec![0u32; g * g + 1];
    for &(x0, x1, y0, y1) in &ranges {
        for cy in y0..=y1 {
            for cx in x0..=x1 {
                counts[cy * g + cx + 1] += 1;
            }
        }
    }
    for k in 0..g * g {
        counts[k + 1] += counts[k];
    }
    let mut fill = counts.clone();
    let mut cells = vec![0u32; counts[g * g] as usize];
    for (ti, &(x0, x1, y0, y1)) in ranges.iter().enumerate() {
        for cy in y0..=y1 {
            for cx in x0..=x1 {
                let k = cy * g + cx;
                cells[fill[k] as usize] = ti as u32;
                fill[k] += 1;
            }
        }
    }
    // Query every texel of both faces (rows in parallel).
    let row_len = s * ch;
    map.data
        .par_chunks_mut(row_len)
        .zip(positions.data.par_chunks_mut(s * 2))
        .zip(covered.par_chunks_mut(s))
        .enumerate()
        .for_each(|(row, ((mrow, prow), crow))| {
            let (face, i) = (row / s, row % s);
            let mut acc = vec![0.0f64; ch];
            for j in 0..s {
                let (u, v) = texel_uv(s, i, j);
                if u * u + v * v > 1.0 {
                    continue;
                }
                let d = uv_to_dir(face, u, v);
                let Some(q) = rectify(d) else { continue };
                let k = cell(q.y) * g + cell(q.x);
                let mut m = f64::NEG_INFINITY;
                let mut den = 0.0f64;
                let mut pos = [0.0f64; 2];
                for a in acc.iter_mut() {
                    *a = 0.0;
                }
                for &ti in &cells[counts[k] as usize..counts[k + 1] as usize] {
                    let t = &tris[ti as usize];
                    let vs = t.v.map(|p| pix[p as usize].unwrap().1);
                    let det = vs[0].dot(vs[1].cross(vs[2]));
                    if det.abs() < 1e-300 {
                        continue;
                    }
                    let l = [
                        q.dot(vs[1].cross(vs[2])) / det,
                        vs[0].dot(q.cross(vs[2])) / det,
                        vs[0].dot(vs[1].cross(q)) / det,
                    ];
                    let tol = -1e-12;
                    if l[0] < tol || l[1] < tol || l[2] < tol {
                        continue;
                    }
                    let sum = l[0] + l[1] + l[2];
                    if sum.is_nan() || sum <= 0.0 {
                        continue;
                    }
                    // Online log-sum of weights: rescale when a larger one appears.
                    if t.logw > m {
                        let f = if m.is_finite() {
                            (m - t.logw).exp()
                        } else {
                            0.0
                        };
                        den *= f;
                        pos[0] *= f;
                        pos[1] *= f;
                        for a in acc.iter_mut() {
                            *a *= f;
                        }
                        m = t.logw;
                    }
                    let w = (t.logw - m).exp();
                    den += w;
                    for (c, &pi) in t.v.iter().enumerate() {
                        let lam = w * l[c] / sum;
                        let p = pi as usize;
                        for (cc, a) in acc.iter_mut().enumerate() {
                            *a += lam * values[p * ch + cc] as f64;
                        }
                        pos[0] += lam * (p % width) as f64;
                        pos[1] += lam * (p / width) as f64;
                    }
                }
                if den > 0.0 {
                    crow[j] = true;
                    for cc in 0..ch {
                        mrow[j * ch + cc] = (acc[cc] / den) as f32;
                    }
                    prow[2 * j] = (pos[0] / den) as f32;
                    prow[2 * j + 1] = (pos[1] / den) as f32;
                }
            }
        });
    let coverage = coverage_of(s, &covered);
    Ok(PartialMap {
        map,
        positions,
        covered,
        coverage,
        triangles: tris.len(),
    })
}

/// Taps (texel index in face·size·size numbering, weight) of the bilinear value of `face` at
/// (u, v), using only texels inside the disk (weights renormalised; the nearest inside texel
/// along the radius when no tap is inside).
fn disk_taps(s: usize, face: usize, u: f64, v: f64) -> Vec<(usize, f64)> {
    let sf = s as f64;
    let x = ((u + 1.0) * 0.5 * sf - 0.5).clamp(0.0, sf - 1.0);
    let y = ((v + 1.0) * 0.5 * sf - 0.5).clamp(0.0, sf - 1.0);
    let (j0, i0) = (x.floor() as usize, y.floor() as usize);
    let (j1, i1) = ((j0 + 1).min(s - 1), (i0 + 1).min(s - 1));
    let (fx, fy) = (x - j0 as f64, y - i0 as f64);
    let inside = |i: usize, j: usize| {
        let (a, b) = texel_uv(s, i, j);
        a * a + b * b <= 1.0
    };
    let mut taps: Vec<(usize, f64)> = Vec::with_capacity(4);
    for (i, j, w) in [
        (i0, j0, (1.0 - fx) * (1.0 - fy)),
        (i0, j1, fx * (1.0 - fy)),
        (i1, j0, (1.0 - fx) * fy),
        (i1, j1, fx * fy),
    ] {
        if w > 0.0 && inside(i, j) {
            if let Some(t) = taps.iter_mut().find(|t| t.0 == (face * s + i) * s + j) {
                t.1 += w;
            } else {
                taps.push(((face * s + i) * s + j, w));
            }
        }
    }
    let tw: f64 = taps.iter().map(|t| t.1).sum();
    if tw > 1e-12 {
        for t in taps.iter_mut() {
            t.1 /= tw;
        }
        return taps;
    }
    let mut k = 1.0;
    loop {
        let f = 1.0 - k / sf;
        let (uu, vv) = (u * f, v * f);
        let j = ((((uu + 1.0) * 0.5 * sf).floor()) as usize).min(s - 1);
        let i = ((((vv + 1.0) * 0.5 * sf).floor()) as usize).min(s - 1);
        if inside(i, j) || f <= 0.0 {
            return vec![((face * s + i) * s + j, 1.0)];
        }
        k += 1.0;
    }
}

/// Fills the uncovered texels of `maps` (all sharing `covered`) by harmonic interpolation with
/// the covered texels as Dirichlet values. Texels inside the disk carry the 5-point Laplacian;
/// a band of texels just beyond the equator (1 < |uv| ≤ 1 + 2h, where inside the grid) are
/// unknowns too, each equal to
/// the other face's bilinear value at its inverted position uv/|uv|² (an overset-grid coupling,
/// second-order like the stencil). Returns the number of filled texels inside the disks; errors
/// when nothing is covered. Call [`fill_beyond_equator`] afterwards for the remaining texels.
pub fn fill_holes(maps: &mut [&mut ParaboloidMap], covered: &[bool]) -> Result<usize> {
    let s = maps[0].size;
    if covered.len() != 2 * s * s || maps.iter().any(|m| m.size != s) {
        return Err(RokebyError::invalid(
            "covered",
            "size does not match the map",
        ));
    }
    crate::cancel::check()?;
    let h = 2.0 / s as f64;
    let rho2 = |i: usize, j: usize| {
        let (a, b) = texel_uv(s, i, j);
        a * a + b * b
    };
    let band_r2 = (1.0 + 2.0 * h) * (1.0 + 2.0 * h);
    let mut var_id = vec![u32::MAX; 2 * s * s];
    let mut vars: Vec<usize> = Vec::new();
    let mut any_known = false;
    let mut n_disk = 0usize;
    for face in 0..2 {
        for i in 0..s {
            for j in 0..s {
                let t = (face * s + i) * s + j;
                if rho2(i, j) <= 1.0 {
                    if covered[t] {
                        any_known = true;
                    } else {
                        var_id[t] = vars.len() as u32;
                        vars.push(t);
                        n_disk += 1;
                    }
                }
            }
        }
    }
    if !any_known {
        return Err(RokebyError::invalid(
            "covered",
            "no texel was recovered: nothing to fill the holes from",
        ));
    }
    if n_disk == 0 {
        return Ok(0);
    }
    for face in 0..2 {
        for i in 0..s {
            for j in 0..s {
                let r2 = rho2(i, j);
                if r2 > 1.0 && r2 <= band_r2 {
                    let t = (face * s + i) * s + j;
                    var_id[t] = vars.len() as u32;
                    vars.push(t);
                }
            }
        }
    }
    let nv = vars.len();
    let total_ch: usize = maps.iter().map(|m| m.channels).sum();
    // Bilinear taps of `face` at (u, v), every tap a disk or band texel.
    let taps_at = |face: usize, u: f64, v: f64| -> Vec<(usize, f64)> {
        let sf = s as f64;
        let x = ((u + 1.0) * 0.5 * sf - 0.5).clamp(0.0, sf - 1.0);
        let y = ((v + 1.0) * 0.5 * sf - 0.5).clamp(0.0, sf - 1.0);
        let (j0, i0) = (x.floor() as usize, y.floor() as usize);
        let (j1, i1) = ((j0 + 1).min(s - 1), (i0 + 1).min(s - 1));
        let (fx, fy) = (x - j0 as f64, y - i0 as f64);
        let taps = [
            (i0, j0, (1.0 - fx) * (1.0 - fy)),
            (i0, j1, fx * (1.0 - fy)),
            (i1, j0, (1.0 - fx) * fy),
            (i1, j1, fx * fy),
        ];
        if taps
            .iter()
            .all(|&(i, j, w)| w == 0.0 || rho2(i, j) <= band_r2)
        {
            taps.iter()
                .filter(|t| t.2 != 0.0)
                .map(|&(i, j, w)| ((face * s + i) * s + j, w))
                .collect()
        } else {
            disk_taps(s, face, u, v)
        }
    };
    // One equation per unknown texel: its (unknown, coefficient) terms and a right-hand side per
    // channel.
    type Row = (Vec<(usize, f64)>, Vec<f64>);
    let rows: Vec<Row> = vars
        .par_iter()
        .map(|&t| {
            let face = t / (s * s);
            let (i, j) = ((t / s) % s, t % s);
            let mut coef: Vec<(usize, f64)> = Vec::with_capacity(6);
            let mut rhs = vec![0.0f64; total_ch];
            let mut add = |tt: usize, w: f64, coef: &mut Vec<(usize, f64)>| {
                if var_id[tt] == u32::MAX {
                    // A covered disk texel: a Dirichlet value.
                    let mut off = 0;
                    for m in maps.iter() {
                        for c in 0..m.channels {
                            rhs[off + c] -= w * m.data[tt * m.channels + c] as f64;
                        }
                        off += m.channels;
                    }
                } else {
                    coef.push((var_id[tt] as usize, w));
                }
            };
            if rho2(i, j) <= 1.0 {
                // 4 x_t − Σ neighbours = 0 (every neighbour is a disk or band texel).
                coef.push((var_id[t] as usize, 4.0));
                for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (ii, jj) = (i as i64 + di, j as i64 + dj);
                    if ii >= 0
                        && jj >= 0
                        && (ii as usize) < s
                        && (jj as usize) < s
                        && rho2(ii as usize, jj as usize) <= band_r2
                    {
                        add((face * s + ii as usize) * s + jj as usize, -1.0, &mut coef);
                    } else {
                        // Beyond the grid (near the axes the band leaves [−1, 1]²): the other
                        // face's value at the inverted position.
                        let (u, v) = ((jj as f64 + 0.5) * h - 1.0, (ii as f64 + 0.5) * h - 1.0);
                        let r2 = u * u + v * v;
                        for (tt, w) in taps_at(1 - face, u / r2, v / r2) {
                            add(tt, -w, &mut coef);
                        }
                    }
                }
            } else {
                // x_t − (other face's bilinear value at uv/|uv|²) = 0.
                coef.push((var_id[t] as usize, 1.0));
                let (u, v) = texel_uv(s, i, j);
                let r2 = u * u + v * v;
                for (tt, w) in taps_at(1 - face, u / r2, v / r2) {
                    add(tt, -w, &mut coef);
                }
            }
            (coef, rhs)
        })
        .collect();
    let mut trip: Vec<Triplet<u32, u32, f64>> = Vec::with_capacity(nv * 6);
    let mut b = Mat::<f64>::zeros(nv, total_ch);
    for (r, (coef, rhs)) in rows.iter().enumerate() {
        for &(c, w) in coef {
            trip.push(Triplet::new(r as u32, c as u32, w));
        }
        for (k, &v) in rhs.iter().enumerate() {
            b[(r, k)] = v;
        }
    }
    let a = crate::numerical::assemble(nv, &trip, "hole filling")?;
    crate::cancel::check()?;
    let lu = crate::numerical::lu(&a, "hole filling")?;
    crate::cancel::check()?; // the sparse factorisation and solve run to completion once started
    let x = lu.solve(&b);
    for (r, &t) in vars.iter().enumerate() {
        let mut off = 0;
        for m in maps.iter_mut() {
            for c in 0..m.channels {
                m.data[t * m.channels + c] = x[(r, off + c)] as f32;
            }
            off += m.channels;
        }
    }
    Ok(n_disk)
}

/// Texels outside the unit disk take the other face's value at their direction (for seamless
/// bilinear lookups near the equator).
pub fn fill_beyond_equator(m: &mut ParaboloidMap) {
    let s = m.size;
    let c = m.channels;
    let src = m.data.clone();
    let view = ParaboloidMap {
        size: s,
        channels: c,
        data: src,
    };
    m.data
        .par_chunks_mut(s * c)
        .enumerate()
        .for_each(|(row, out)| {
            let (face, i) = (row / s, row % s);
            let mut tmp = vec![0.0f64; c];
            for j in 0..s {
                let (u, v) = texel_uv(s, i, j);
                let r2 = u * u + v * v;
                if r2 <= 1.0 {
                    continue;
                }
                let taps = disk_taps(s, 1 - face, u / r2, v / r2);
                for t in tmp.iter_mut() {
                    *t = 0.0;
                }
                for (tt, w) in taps {
                    for (acc, &x) in tmp[..c].iter_mut().zip(&view.data[tt * c..tt * c + c]) {
                        *acc += w * x as f64;
                    }
                }
                for k in 0..c {
                    out[j * c + k] = tmp[k] as f32;
                }
            }
        });
}

/// The paper's regularisation: Gaussian blur of `map` with σ per texel driven by the gradient
/// magnitude of the (hole-filled) position map. σ = σ_max · clamp((g − g₀)/(g₁ − g₀), 0, 1) with
/// g₀ = 4 and g₁ = 16 times the median gradient: smooth parts (neighbouring texels from
/// neighbouring pixels) are untouched. Returns the number of blurred texels.
///
/// The kernel is clipped to the map: σ is capped at the map's size S (a wider Gaussian over an
/// S×S map is indistinguishable from a box, and uncapped σ = 1e9 never returned) and its
/// support at S texels each side, so one texel costs at most (2S+1)² taps. Cancellable between
/// rows ([`crate::cancel`]).
pub fn regularize(
    map: &mut ParaboloidMap,
    positions: &ParaboloidMap,
    sigma_max: f64,
) -> Result<usize> {
    let s = map.size;
    if sigma_max.is_nan() || sigma_max <= 0.0 {
        return Ok(0);
    }
    let sigma_max = sigma_max.min(s as f64);
    let inside = |i: i64, j: i64| {
        if i < 0 || j < 0 || i >= s as i64 || j >= s as i64 {
            return false;
        }
        let (a, b) = texel_uv(s, i as usize, j as usize);
        a * a + b * b <= 1.0
    };
    let pos = |f: usize, i: usize, j: usize| {
        let k = ((f * s + i) * s + j) * 2;
        (positions.data[k] as f64, positions.data[k + 1] as f64)
    };
    let grad: Vec<f64> = (0..2 * s * s)
        .into_par_iter()
        .map(|t| {
            let (f, i, j) = (t / (s * s), (t / s) % s, t % s);
            if !inside(i as i64, j as i64) {
                return -1.0;
            }
            let p = pos(f, i, j);
            let mut g2 = 0.0;
            for (di, dj) in [(1i64, 0i64), (0, 1)] {
                let (a, b) = (i as i64 + di, j as i64 + dj);
                let (c, d) = (i as i64 - di, j as i64 - dj);
                let q1 = if inside(a, b) {
                    Some(pos(f, a as usize, b as usize))
                } else {
                    None
                };
                let q0 = if inside(c, d) {
                    Some(pos(f, c as usize, d as usize))
                } else {
                    None
                };
                let (dx, dy) = match (q0, q1) {
                    (Some(a), Some(b)) => ((b.0 - a.0) * 0.5, (b.1 - a.1) * 0.5),
                    (None, Some(b)) => (b.0 - p.0, b.1 - p.1),
                    (Some(a), None) => (p.0 - a.0, p.1 - a.1),
                    (None, None) => (0.0, 0.0),
                };
                g2 += dx * dx + dy * dy;
            }
            g2.sqrt()
        })
        .collect();
    let mut g_sorted: Vec<f64> = grad.iter().cloned().filter(|g| *g >= 0.0).collect();
    if g_sorted.is_empty() {
        return Ok(0);
    }
    g_sorted.sort_by(|a, b| a.total_cmp(b));
    let med = g_sorted[g_sorted.len() / 2].max(1e-6);
    let (g0, g1) = (4.0 * med, 16.0 * med);
    let c = map.channels;
    let src = map.data.clone();
    let blurred: Vec<Result<usize>> = map
        .data
        .par_chunks_mut(s * c)
        .enumerate()
        .map(|(row, out)| {
            crate::cancel::check()?;
            let (f, i) = (row / s, row % s);
            let mut n = 0;
            let mut acc = vec![0.0f64; c];
            for j in 0..s {
                let g = grad[(f * s + i) * s + j];
                if g < 0.0 {
                    continue;
                }
                let sigma = sigma_max * ((g - g0) / (g1 - g0)).clamp(0.0, 1.0);
                if sigma < 0.25 {
                    continue;
                }
                n += 1;
                let rad = ((2.5 * sigma).ceil() as i64).min(s as i64);
                let mut wsum = 0.0;
                for a in acc.iter_mut() {
                    *a = 0.0;
                }
                let (i0, i1) = ((-rad).max(-(i as i64)), rad.min(s as i64 - 1 - i as i64));
                let (j0, j1) = ((-rad).max(-(j as i64)), rad.min(s as i64 - 1 - j as i64));
                for di in i0..=i1 {
                    for dj in j0..=j1 {
                        let (ii, jj) = (i as i64 + di, j as i64 + dj);
                        if !inside(ii, jj) {
                            continue;
                        }
                        let w = (-((di * di + dj * dj) as f64) / (2.0 * sigma * sigma)).exp();
                        let k = ((f * s + ii as usize) * s + jj as usize) * c;
                        for (a, &x) in acc[..c].iter_mut().zip(&src[k..k + c]) {
                            *a += w * x as f64;
                        }
                        wsum += w;
                    }
                }
                for ch in 0..c {
                    out[j * c + ch] = (acc[ch] / wsum) as f32;
                }
            }
            Ok(n)
        })
        .collect();
    blurred.into_iter().sum()
}

/// The three steps for one patch: partial map, hole filling, regularisation.
#[derive(Debug, Clone)]
pub struct ReflectionEnv {
    pub map: ParaboloidMap,
    /// The texels the partial map covered (eq. 2), before hole filling.
    pub covered: Vec<bool>,
    pub coverage: f64,
    pub triangles: usize,
    pub filled_texels: usize,
    pub blurred_texels: usize,
}

// Entry point: the G-buffer planes of the reflection pass (refl, values, mask, depth), their size
// and channels, one argument each as the binding hands them over (shared by `check_partial_args`).
#[allow(clippy::too_many_arguments)]
pub fn reconstruct(
    width: usize,
    height: usize,
    refl: &[f32],
    values: &[f32],
    channels: usize,
    mask: &[f32],
    depth: &[f32],
    params: &ReflectionParams,
) -> Result<ReflectionEnv> {
    let mut p = partial(width, height, refl, values, channels, mask, depth, params)?;
    if p.coverage < params.min_coverage {
        return Err(RokebyError::invalid(
            "mask",
            format!(
                "the patch's reflections cover {:.2}% of the sphere of directions ({} triangles), below min_coverage = {:.2}%: holes would cover nearly all of it",
                100.0 * p.coverage,
                p.triangles,
                100.0 * params.min_coverage
            ),
        ));
    }
    let filled = fill_holes(&mut [&mut p.map, &mut p.positions], &p.covered)?;
    let blurred = regularize(&mut p.map, &p.positions, params.blur_sigma)?;
    fill_beyond_equator(&mut p.map);
    Ok(ReflectionEnv {
        map: p.map,
        covered: p.covered,
        coverage: p.coverage,
        triangles: p.triangles,
        filled_texels: filled,
        blurred_texels: blurred,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An orthographic sphere of width `w` with a procedural bump (folds in the Gauss map, as in
    /// bench/compositing.py), its reflected directions for the view +z, a smooth R0, the mask
    /// (the disk, minus a few pixels), the depth.
    fn bumpy_sphere(w: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
        let (mut refl, mut vals, mut mask, mut depth) = (vec![], vec![], vec![], vec![]);
        for i in 0..w {
            for j in 0..w {
                let (x, y) = (
                    (j as f64 + 0.5) / w as f64 * 2.0 - 1.0,
                    (i as f64 + 0.5) / w as f64 * 2.0 - 1.0,
                );
                let s = x * x + y * y;
                let inside = s < 0.98 && (i * 7 + j * 3) % 97 != 0;
                let z = (1.0 - s).max(0.0).sqrt();
                let pi = std::f64::consts::PI;
                let n = DVec3::new(
                    x + 0.25 * (9.0 * pi * x).sin() * (5.0 * pi * y).cos(),
                    y + 0.25 * (7.0 * pi * y).cos() * (4.0 * pi * x).sin(),
                    z,
                )
                .normalize();
                let r = reflect(DVec3::Z, n);
                refl.extend([r.x as f32, r.y as f32, r.z as f32]);
                vals.extend([
                    (0.5 + 0.3 * r.x + 0.2 * r.y * r.z) as f32,
                    (0.4 + 0.1 * (3.0 * r.z).sin()) as f32,
                    (0.3 + 0.2 * r.y) as f32,
                ]);
                mask.push(if inside { 1.0 } else { 0.0 });
                depth.push(if inside {
                    (5.0 - z) as f32
                } else {
                    f32::INFINITY
                });
            }
        }
        (refl, vals, mask, depth)
    }

    /// The polygon-visits-texels search gives the per-texel grid query's map: same
    /// triangles, same covered texels, values within f64 rounding (the barycentric coordinates
    /// come from precomputed dual vectors) — equal after the f32 store here.
    #[test]
    fn partial_matches_reference() {
        for (w, size, use_depth) in [
            (96, 16, true),
            (160, 32, true),
            (128, 64, false),
            (200, 128, true),
        ] {
            let (refl, vals, mask, depth) = bumpy_sphere(w);
            let d: &[f32] = if use_depth { &depth } else { &[] };
            let params = ReflectionParams {
                size,
                ..Default::default()
            };
            let a = partial(w, w, &refl, &vals, 3, &mask, d, &params).unwrap();
            let b = partial_reference(w, w, &refl, &vals, 3, &mask, d, &params).unwrap();
            assert_eq!(a.triangles, b.triangles);
            assert_eq!(a.covered, b.covered, "w {w} size {size}");
            assert_eq!(a.coverage, b.coverage);
            let md = a
                .map
                .data
                .iter()
                .zip(&b.map.data)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            let pd = a
                .positions
                .data
                .iter()
                .zip(&b.positions.data)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(md <= 1e-6, "w {w} size {size}: map differs by {md}");
            assert!(pd <= 1e-3, "w {w} size {size}: positions differ by {pd} px");
            assert!(a.coverage > 0.5);
        }
    }

    #[test]
    fn partial_is_the_same_on_any_thread_count() {
        let w = 160;
        let (refl, vals, mask, depth) = bumpy_sphere(w);
        let params = ReflectionParams {
            size: 32,
            ..Default::default()
        };
        let run = |t: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            pool.install(|| partial(w, w, &refl, &vals, 3, &mask, &depth, &params).unwrap())
        };
        let one = run(1);
        for t in [2, 3, 7] {
            let p = run(t);
            assert_eq!(p.map.data, one.map.data);
            assert_eq!(p.positions.data, one.positions.data);
            assert_eq!(p.covered, one.covered);
        }
    }
}
