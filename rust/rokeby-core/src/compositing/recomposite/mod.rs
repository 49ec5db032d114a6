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
//! * eq. 4 as R0 + vα_R(R(r~) − R0), with the angle from the chord, acos(r·r~) = 2 asin(‖r − r~‖/2),
//!   which is exactly 0 when r~ = r (acos(r·r) is not, for a dot product rounded below 1); v = 1
//!   without trigonometry once the chord reaches 2 sin(ε/2).
//! * eq. 5 as I + α[(k_D c_D D~ + k_R c_R R~)^(1/γ) − (c_D D0 + c_R R0)^(1/γ)]: the same as the
//!   paper's where I = (c_D D0 + c_R R0)^(1/γ), and it keeps what I holds besides diffuse and
//!   reflection shading (emission, transmission, …) where it does not. c_D, c_R are the renderer's
//!   reflectance (colour) buffers when diffuse/reflection *illumination* is given (Cycles'
//!   DiffDir + DiffInd and DiffCol; the paper's §6 extension to spatially varying reflectance),
//!   else 1.
//!
//! Pixels without a patch (id < 0), of a patch without reconstruction, or with a non-finite input
//! other than I are returned as I unchanged (counted in [`Stats::masked`]).
//!
//! Evaluation: chunks of 1024 pixels in parallel; each chunk first lists the pixels that need
//! eqs. 3–5 (32 at a time where the normals are all unmodified or the pixels all of one patch),
//! copies I (with streaming stores where nothing is edited), then runs the listed pixels in
//! batches of up to 64, structure of arrays (one f32 lane per pixel, loops over the lanes that
//! LLVM vectorises), in an AVX2 instantiation where the CPU has it (detected at run time; the
//! portable one otherwise). The two give the same bits (the same IEEE operations in the same
//! order, no FMA contraction; tested). Against a one-pixel-at-a-time implementation (the tests'
//! reference, `tests.rs`) they differ only by rounding: n, ñ and v are normalised with a
//! Newton-refined f32 estimate of 1/‖·‖ (≈ 1e-14 relative; which normals are rejected is exactly
//! [`unit_row`]'s), and x^(1/γ) for γ ≠ 1 comes from f64 polynomials (within 1 ulp of `powf`). The
//! texels of a batch are prefetched before eq. 3 is evaluated and fetched after it (eight lanes
//! per gather in the AVX2 instantiation); runs of 64 consecutive pixels are de-interleaved with
//! AVX2 shuffles there. Each thread keeps its lane arrays: an edit allocates nothing per chunk.
//! A [`Recompositor`] also keeps, per pixel, what does not depend on ñ ([`Prepared`]: unit n and
//! v, validity, eq. 5's subtracted term), computed once by the same lane functions: the same
//! bits, fewer instructions per edit (tested against [`recomposite`] for every kind of view).

use crate::compositing::reconstruct::ParaboloidMap;
use crate::compositing::sh::{self, SH_COEFFS};
use crate::error::{Result, RokebyError};
use crate::unit_vector::unit_row;
use rayon::prelude::*;
use std::mem::MaybeUninit;

mod chunks;
mod lanes;
mod session;
#[cfg(test)]
mod tests;

use chunks::*;
use lanes::*;
pub use session::{Recompositor, Window};

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
        Params {
            k_d: 1.0,
            k_r: 1.0,
            gamma: 1.0,
            epsilon: EPSILON,
        }
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
    /// Values (channels) of recomposited pixels that are not finite where I's are (eq. 5
    /// overflowed float32).
    pub overflow: usize,
}

fn check(name: &str, v: &[f32], want: usize, optional: bool) -> Result<()> {
    if (optional && v.is_empty()) || v.len() == want {
        Ok(())
    } else {
        Err(RokebyError::invalid(
            name,
            format!(
                "expected {want} values{}, got {}",
                if optional { " or none" } else { "" },
                v.len()
            ),
        ))
    }
}

/// Eqs. 3–5 for every pixel; returns I~ (H·W×3).
pub fn recomposite(b: &Buffers, patches: &[Patch], p: &Params) -> Result<(Vec<f32>, Stats)> {
    recomposite_with(b, patches, p, true)
}

/// Edited pixels per batch: eqs. 3–5 run on up to 64 pixels at once, structure of arrays (one
/// f32 lane each; 8 lanes per AVX2 register, 4 per SSE2 register on the portable path).
const LANES: usize = 64;
type Lanes = [f32; LANES];
/// Pixels examined at once when listing the pixels to recomposite.
const SCAN: usize = 32;
/// Pixels per parallel task.
const CHUNK: usize = 1024;

/// The 1×1 dual-paraboloid map (two faces, 3 channels) that stands in for a missing one.
static NO_MAP: [f32; 6] = [0.0; 6];

/// How the view vector v (surface → eye) is given.
#[derive(Clone, Copy)]
enum View {
    PerPixel,
    /// One unit vector for the frame (orthographic camera).
    Constant([f32; 3]),
    /// One vector that cannot be normalised: every pixel that reaches eqs. 3–5 is masked.
    Invalid,
}

/// Per-frame constants of eqs. 3–5 and the buffers they read.
struct Frame<'a> {
    b: &'a Buffers<'a>,
    /// Per patch, f32 SH coefficients of eq. 1 (channel-major); zero where diffuse is not edited,
    /// which gives D(ñ) − D(n) = +0 exactly, as skipping it did.
    sh: Vec<[[f32; SH_COEFFS]; 3]>,
    /// Per patch, its reflection environment (eq. 2): the texels (a 1×1 map of zeros without
    /// one), the map's size (as f32 too) and whether there is one.
    env_data: Vec<&'a [f32]>,
    env_n: Vec<usize>,
    env_size: Vec<f32>,
    has_env: Vec<bool>,
    /// Per patch: whether it has anything to edit (an SH or a map); pixels of others are masked.
    has_content: Vec<bool>,
    k_d: f32,
    k_r: f32,
    unit_material: bool,
    inv_gamma: f32,
    gamma_one: bool,
    inv_eps: f32,
    /// 2 sin(ε/2): the chord |r − r~| at which eq. 4's v reaches 1.
    chord_eps: f32,
    view: View,
    /// Run the chunks through the AVX2 instantiation (x86-64 with AVX2 detected at run time).
    avx2: bool,
    /// Every map's texel indices (< 2·size²) fit in i32 lanes (size ≤ 32767).
    small_maps: bool,
    /// A [`Recompositor`]'s per-pixel terms that do not depend on ñ (None: computed per batch).
    pre: Option<&'a Prepared>,
}

/// Per pixel, what eqs. 3–5 compute that does not depend on ñ, k_D or k_R, kept by a
/// [`Recompositor`] for the session (an edit then only normalises ñ, reflects about it,
/// evaluates the SH difference and the lookup, and shades). Computed by the kernel's own lane
/// functions on the same inputs, so an edit gives the same bits as without it. Blocks of
/// structure of arrays: a batch of consecutive pixels loads at most two slices per component.
struct Prepared {
    /// Blocks of [`BLOCK`] pixels, each `comps` lane arrays: unit n ([`unit_lanes`], 3), eq. 5's
    /// subtracted term g(c_D D0 + c_R R0) (g = x^(1/γ), [`pow_lanes`]; 3) and, with a per-pixel
    /// view, unit v (3).
    tab: Vec<f32>,
    /// D0, R0, c_D, c_R, α_D, α_R, α finite, n (and v) normalisable: the pixel can be
    /// recomposited (else it is masked when edited).
    ok: Vec<bool>,
}

/// The buffers' lengths, the parameters and the maps, checked before any pixel is touched.
fn validate(b: &Buffers, patches: &[Patch], p: &Params) -> Result<()> {
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
    if !(p.gamma.is_finite() && (MIN_GAMMA..=MAX_GAMMA).contains(&p.gamma)) {
        return Err(RokebyError::invalid(
            "gamma",
            format!(
                "must be in [{MIN_GAMMA}, {MAX_GAMMA}] (a display gamma), got {}",
                p.gamma
            ),
        ));
    }
    if p.epsilon.is_nan() || p.epsilon <= 0.0 {
        return Err(RokebyError::invalid("epsilon", "must be positive"));
    }
    if !(p.k_d.is_finite() && p.k_r.is_finite()) {
        return Err(RokebyError::invalid("k_d", "k_d and k_r must be finite"));
    }
    validate_patches(patches)
}

/// The patches' reflection maps: 3 channels, 2·size²·3 values, size ≥ 1 (SH coefficients are
/// finite by type: the callers check them).
fn validate_patches(patches: &[Patch]) -> Result<()> {
    if let Some(e) = patches
        .iter()
        .filter_map(|q| q.env.as_ref())
        .find(|e| e.channels != 3)
    {
        return Err(RokebyError::invalid(
            "patches",
            format!("reflection maps must have 3 channels, got {}", e.channels),
        ));
    }
    // The fuzzer found an empty (size 0) map panicking in the lookup's clamp.
    if let Some(e) = patches
        .iter()
        .filter_map(|q| q.env.as_ref())
        .find(|e| e.size == 0 || e.data.len() != 2 * e.size * e.size * e.channels)
    {
        return Err(RokebyError::invalid(
            "patches",
            format!(
                "reflection map of size {} holds {} values, expected 2×size×size×3 with size ≥ 1",
                e.size,
                e.data.len()
            ),
        ));
    }
    Ok(())
}

/// The per-frame constants of eqs. 3–5 for buffers `b` (already validated) and `patches`.
fn frame<'a>(b: &'a Buffers<'a>, patches: &'a [Patch], p: &Params, simd: bool) -> Frame<'a> {
    Frame {
        b,
        pre: None,
        sh: patches
            .iter()
            .map(|q| {
                q.sh.map(|c| c.map(|ch| ch.map(|x| x as f32)))
                    .unwrap_or([[0.0; SH_COEFFS]; 3])
            })
            .collect(),
        env_data: patches
            .iter()
            .map(|q| q.env.as_ref().map_or(&NO_MAP[..], |e| &e.data[..]))
            .collect(),
        has_env: patches.iter().map(|q| q.env.is_some()).collect(),
        env_size: patches
            .iter()
            .map(|q| q.env.as_ref().map_or(1.0, |e| e.size as f32))
            .collect(),
        env_n: patches
            .iter()
            .map(|q| q.env.as_ref().map_or(1, |e| e.size))
            .collect(),
        has_content: patches
            .iter()
            .map(|q| q.sh.is_some() || q.env.is_some())
            .collect(),
        k_d: p.k_d as f32,
        k_r: p.k_r as f32,
        unit_material: p.k_d == 1.0 && p.k_r == 1.0,
        inv_gamma: (1.0 / p.gamma) as f32,
        gamma_one: p.gamma == 1.0,
        inv_eps: (1.0 / p.epsilon) as f32,
        chord_eps: if p.epsilon >= std::f64::consts::PI {
            f32::INFINITY
        } else {
            (2.0 * (0.5 * p.epsilon).sin()) as f32
        },
        view: match b.view.len() == 3 {
            false => View::PerPixel,
            true => unit_row(b.view).map_or(View::Invalid, |v| View::Constant(to32(v))),
        },
        avx2: simd && avx2_available(),
        small_maps: patches
            .iter()
            .filter_map(|q| q.env.as_ref())
            .all(|e| e.size <= 32767),
    }
}

fn add(x: Stats, y: Stats) -> Stats {
    Stats {
        masked: x.masked + y.masked,
        edited: x.edited + y.edited,
        overflow: x.overflow + y.overflow,
    }
}

/// Eqs. 3–5 for the pixels `base..base + o.len()/3` (consecutive, row-major) into `o`, chunks
/// of [`CHUNK`] pixels in parallel. Every element of `o` is written.
fn run_range(f: &Frame, base: usize, o: &mut [MaybeUninit<f32>]) -> Stats {
    o.par_chunks_mut(3 * CHUNK)
        .enumerate()
        .map(|(chunk, o)| with_work(|w| run_chunk(f, base + chunk * CHUNK, o, w)))
        .reduce(Stats::default, add)
}

/// Eqs. 3–5 for the pixels of window `win` of a `width`-pixel-wide frame into `o`: the window's
/// pixels only (rows of `win.cols.len()` pixels) when `o_full` is false, else the whole frame
/// (H·W×3), of which only the window's pixels are written. Rows in parallel; a window of whole
/// rows runs as one range.
fn run_window(
    f: &Frame,
    width: usize,
    win: &Window,
    o: &mut [MaybeUninit<f32>],
    o_full: bool,
) -> Stats {
    let (r0, r1, c0, c1) = (win.rows.start, win.rows.end, win.cols.start, win.cols.end);
    let cw = c1 - c0;
    if c0 == 0 && c1 == width {
        let o = if o_full {
            &mut o[3 * r0 * width..3 * r1 * width]
        } else {
            o
        };
        return run_range(f, r0 * width, o);
    }
    let (stride, off) = if o_full {
        (3 * width, 3 * c0)
    } else {
        (3 * cw, 0)
    };
    let o = if o_full {
        &mut o[3 * r0 * width..3 * r1 * width]
    } else {
        o
    };
    o.par_chunks_mut(stride)
        .enumerate()
        .map(|(k, row)| {
            let base = (r0 + k) * width + c0;
            let row = &mut row[off..off + 3 * cw];
            with_work(|w| {
                let mut st = Stats::default();
                for (q, piece) in row.chunks_mut(3 * CHUNK).enumerate() {
                    st = add(st, run_chunk(f, base + q * CHUNK, piece, w));
                }
                st
            })
        })
        .reduce(Stats::default, add)
}

/// [`recomposite`] with the AVX2 instantiation allowed (`simd`) or not: both give the same bits
/// (no FMA contraction, the same operations in the same order).
fn recomposite_with(
    b: &Buffers,
    patches: &[Patch],
    p: &Params,
    simd: bool,
) -> Result<(Vec<f32>, Stats)> {
    let n = b.ids.len();
    validate(b, patches, p)?;
    let f = frame(b, patches, p, simd);
    // Chunks of rows in parallel; every pixel starts as I (one copy), and only pixels whose normal
    // or material changed run eqs. 3–5 — in f32 (the buffers' precision), in batches: with ñ = n
    // the formulas still give I bit for bit (zero SH difference, zero chord, identical shade and
    // shade0).
    // The copy of I is made by the tasks too, into memory that is written once (not zeroed
    // first), in parallel.
    let mut out: Vec<f32> = Vec::with_capacity(3 * n);
    let stats = run_range(&f, 0, &mut out.spare_capacity_mut()[..3 * n]);
    // SAFETY: the chunks cover all 3n elements and each chunk was initialised by its task (a panic
    // there would have unwound past this line, leaving the length 0).
    unsafe { out.set_len(3 * n) };
    if p.gamma != 1.0 && stats.overflow > 0 {
        return Err(overflow_error(
            first_overflow(&out, b.image).unwrap_or(0),
            p,
        ));
    }
    Ok((out, stats))
}

/// The gamma range [`recomposite`] accepts: display gammas, far from where x^(1/γ) of a finite HDR
/// pixel overflows float32 for any practical value.
pub const MIN_GAMMA: f64 = 0.1;
pub const MAX_GAMMA: f64 = 10.0;

/// The first value of `out` that is not finite where `image`'s is (the same pixels), as a
/// pixel offset.
fn first_overflow(out: &[f32], image: &[f32]) -> Option<usize> {
    out.iter()
        .zip(image)
        .position(|(x, y)| !x.is_finite() && y.is_finite())
        .map(|i| i / 3)
}

/// Finite input never gives inf or NaN out: the power of eq. 5 (γ ≠ 1), or large k_D, k_R, can
/// still overflow for extreme pixel values. The kernel counts such values ([`Stats::overflow`]);
/// this refuses them naming the first pixel (row-major index in the frame).
fn overflow_error(pixel: usize, p: &Params) -> RokebyError {
    RokebyError::invalid(
        "image",
        format!(
            "pixel {pixel} overflows float32 in eq. 5 (γ = {}, k_D = {}, k_R = {}): its values are too large for this gamma and these factors",
            p.gamma, p.k_d, p.k_r
        ),
    )
}

#[inline]
fn to32(v: glam::DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
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
        if let (Some(co), Some(n)) = (
            &patches[id as usize].sh,
            unit_row(&normals[3 * i..3 * i + 3]),
        ) {
            for c in 0..3 {
                o[c] = sh::eval(&co[c], n.to_array()) as f32;
            }
        }
    });
    Ok(out)
}
