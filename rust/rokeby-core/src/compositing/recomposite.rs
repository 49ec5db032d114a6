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
//! order, no FMA contraction; tested). Against the former one-pixel-at-a-time code (kept in the
//! tests as the reference) they differ only by rounding: n, ñ and v are normalised with a
//! Newton-refined f32 estimate of 1/‖·‖ (≈ 1e-14 relative; which normals are rejected is exactly
//! [`unit`]'s), and x^(1/γ) for γ ≠ 1 comes from f64 polynomials (within 1 ulp of `powf`). The
//! texels of a batch are prefetched before eq. 3 is evaluated and fetched after it (eight lanes
//! per gather in the AVX2 instantiation); runs of 64 consecutive pixels are de-interleaved with
//! AVX2 shuffles there. Each thread keeps its lane arrays: an edit allocates nothing per chunk.
//! A [`Recompositor`] also keeps, per pixel, what does not depend on ñ ([`Prepared`]: unit n and
//! v, validity, eq. 5's subtracted term), computed once by the same lane functions: the same
//! bits, fewer instructions per edit (tested against [`recomposite`] for every kind of view).

use crate::error::{Result, RokebyError};
use crate::reconstruct::{unit, ParaboloidMap};
use crate::sh::{self, SH_COEFFS};
use rayon::prelude::*;
use std::mem::MaybeUninit;

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
/// [`Recompositor`] for the session (issue 23: an edit then only normalises ñ, reflects about it,
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
            true => unit(b.view).map_or(View::Invalid, |v| View::Constant(to32(v))),
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

/// A rectangle of pixels: rows × cols (half-open ranges).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Window {
    pub rows: std::ops::Range<usize>,
    pub cols: std::ops::Range<usize>,
}

/// One rendered frame held for many recompositings (an artist's edit loop: a slider, a brush).
///
/// The passes are checked and copied once, when it is made; each edit then gives only what
/// changed — the edited normals ñ (the whole frame, borrowed, or a window of them, copied into
/// the frame's ñ kept here), k_D, k_R, or new patches — and eqs. 3–5 write I~ into a buffer of
/// the caller (the whole frame or only a window of it), with nothing allocated per edit. The
/// result equals [`recomposite`]'s on the same inputs bit for bit (the same kernel), and
/// overflow (a finite I giving a non-finite I~, whatever γ) is refused naming the pixel. On
/// request it also keeps, per pixel, the terms of eqs. 3–5 that do not depend on ñ
/// ([`Recompositor::set_prepared`]: 25–37 bytes a pixel, the same bits).
pub struct Recompositor {
    width: usize,
    height: usize,
    ids: Vec<i32>,
    normals: Vec<f32>,
    /// ñ of the frame as last given by [`Recompositor::set_edited`] (starts as n).
    edited: Vec<f32>,
    view: Vec<f32>,
    diffuse: Vec<f32>,
    reflection: Vec<f32>,
    alpha_d: Vec<f32>,
    alpha_r: Vec<f32>,
    alpha: Vec<f32>,
    image: Vec<f32>,
    diffuse_color: Vec<f32>,
    reflection_color: Vec<f32>,
    patches: Vec<Patch>,
    gamma: f64,
    epsilon: f64,
    /// The per-pixel terms that do not depend on ñ ([`Prepared`]), or None (computed per edit).
    pre: Option<Prepared>,
    /// Whether the AVX2 instantiation may run (false: the portable one; the same bits).
    simd: bool,
}

impl Recompositor {
    /// The frame (`width`×`height`, `b` as for [`recomposite`]; `b.edited` is ignored: ñ starts
    /// as n) checked and copied.
    pub fn new(
        width: usize,
        height: usize,
        b: &Buffers,
        patches: Vec<Patch>,
        gamma: f64,
        epsilon: f64,
    ) -> Result<Self> {
        if width.checked_mul(height) != Some(b.ids.len()) {
            return Err(RokebyError::invalid(
                "ids",
                format!("expected {width}×{height} values, got {}", b.ids.len()),
            ));
        }
        let p = Params {
            gamma,
            epsilon,
            ..Params::default()
        };
        validate(
            &Buffers {
                edited: b.normals,
                ..*b
            },
            &patches,
            &p,
        )?;
        let mut rc = Recompositor {
            width,
            height,
            ids: b.ids.to_vec(),
            normals: b.normals.to_vec(),
            edited: b.normals.to_vec(),
            view: b.view.to_vec(),
            diffuse: b.diffuse.to_vec(),
            reflection: b.reflection.to_vec(),
            alpha_d: b.alpha_d.to_vec(),
            alpha_r: b.alpha_r.to_vec(),
            alpha: b.alpha.to_vec(),
            image: b.image.to_vec(),
            diffuse_color: b.diffuse_color.to_vec(),
            reflection_color: b.reflection_color.to_vec(),
            patches,
            gamma,
            epsilon,
            pre: None,
            simd: true,
        };
        // Off by default: on a quiet machine the terms saved no time (15.2 ms per 1080p edit with
        // them, 14.9 without) for 73 MB more per session (docs/compositing.md).
        rc.set_prepared(false);
        Ok(rc)
    }

    /// The passes as the kernel reads them, ñ = `edited`.
    fn buffers<'a>(&'a self, edited: &'a [f32]) -> Buffers<'a> {
        Buffers {
            ids: &self.ids,
            normals: &self.normals,
            edited,
            view: &self.view,
            diffuse: &self.diffuse,
            reflection: &self.reflection,
            alpha_d: &self.alpha_d,
            alpha_r: &self.alpha_r,
            alpha: &self.alpha,
            image: &self.image,
            diffuse_color: &self.diffuse_color,
            reflection_color: &self.reflection_color,
        }
    }

    /// Keep (the default), or drop, the per-pixel terms of eqs. 3–5 that do not depend on ñ:
    /// unit n and v, the validity of each pixel's passes and eq. 5's subtracted term g(c_D D0 +
    /// c_R R0) — 25 (orthographic view) or 37 bytes per pixel ([`Recompositor::prepared_bytes`]),
    /// computed once here instead of in every edit. The results are the same bits either way.
    pub fn set_prepared(&mut self, on: bool) {
        if !on {
            self.pre = None;
        } else if self.pre.is_none() {
            let p = Params {
                gamma: self.gamma,
                epsilon: self.epsilon,
                ..Params::default()
            };
            let b = self.buffers(&self.normals);
            let f = frame(&b, &self.patches, &p, self.simd);
            let pre = Prepared::new(&f, self.ids.len());
            self.pre = Some(pre);
        }
    }

    /// Bytes held by the per-pixel terms ([`Recompositor::set_prepared`]; 0 without them).
    pub fn prepared_bytes(&self) -> usize {
        self.pre.as_ref().map_or(0, Prepared::bytes)
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// The whole frame as a window.
    pub fn full(&self) -> Window {
        Window {
            rows: 0..self.height,
            cols: 0..self.width,
        }
    }

    /// The rendered image I (H·W×3).
    pub fn image(&self) -> &[f32] {
        &self.image
    }

    /// New reconstructions (one per patch id); the passes stay.
    pub fn set_patches(&mut self, patches: Vec<Patch>) -> Result<()> {
        validate_patches(&patches)?;
        self.patches = patches;
        Ok(())
    }

    fn check_window(&self, win: &Window) -> Result<()> {
        let ok = win.rows.start < win.rows.end
            && win.rows.end <= self.height
            && win.cols.start < win.cols.end
            && win.cols.end <= self.width;
        if ok {
            Ok(())
        } else {
            Err(RokebyError::invalid(
                "window",
                format!(
                    "rows {:?} × cols {:?} is empty or not inside the {}×{} frame",
                    win.rows, win.cols, self.height, self.width
                ),
            ))
        }
    }

    /// ñ of the pixels of `win` from `values`: the window's pixels (rows of `win.cols.len()`)
    /// or, with `full`, a whole H·W×3 frame of which the window is read.
    pub fn set_edited(&mut self, win: &Window, values: &[f32], full: bool) -> Result<()> {
        self.check_window(win)?;
        let (cw, w) = (win.cols.len(), self.width);
        let want = if full {
            3 * w * self.height
        } else {
            3 * cw * win.rows.len()
        };
        check("edited_normals", values, want, false)?;
        for (k, r) in win.rows.clone().enumerate() {
            let src = if full {
                (r * w + win.cols.start) * 3
            } else {
                3 * k * cw
            };
            let dst = (r * w + win.cols.start) * 3;
            self.edited[dst..dst + 3 * cw].copy_from_slice(&values[src..src + 3 * cw]);
        }
        Ok(())
    }

    /// Eqs. 3–5 on the pixels of `win` into `out`: only the window's pixels (rows of
    /// `win.cols.len()`, `out_full` false) or a whole H·W×3 frame of which only the window is
    /// written. ñ: `edited` (a whole H·W×3 frame, read in place) or, when None, the one kept
    /// here ([`Recompositor::set_edited`]). On error `out`'s window holds no useful values.
    pub fn run(
        &self,
        win: &Window,
        edited: Option<&[f32]>,
        k_d: f64,
        k_r: f64,
        out: &mut [f32],
        out_full: bool,
    ) -> Result<Stats> {
        self.check_window(win)?;
        let edited = edited.unwrap_or(&self.edited);
        check(
            "edited_normals",
            edited,
            3 * self.width * self.height,
            false,
        )?;
        let want = if out_full {
            3 * self.width * self.height
        } else {
            3 * win.rows.len() * win.cols.len()
        };
        check("out", out, want, false)?;
        if !(k_d.is_finite() && k_r.is_finite()) {
            return Err(RokebyError::invalid("k_d", "k_d and k_r must be finite"));
        }
        let p = Params {
            k_d,
            k_r,
            gamma: self.gamma,
            epsilon: self.epsilon,
        };
        let b = self.buffers(edited);
        let mut f = frame(&b, &self.patches, &p, self.simd);
        f.pre = self.pre.as_ref();
        // SAFETY: f32 and MaybeUninit<f32> have the same layout; the kernel only writes.
        let o = unsafe { &mut *(out as *mut [f32] as *mut [MaybeUninit<f32>]) };
        let st = run_window(&f, self.width, win, o, out_full);
        if st.overflow > 0 {
            // The first overflowing pixel of the window, named by its index in the frame.
            let (w, cw) = (self.width, win.cols.len());
            for (k, r) in win.rows.clone().enumerate() {
                let px = r * w + win.cols.start;
                let o = if out_full { 3 * px } else { 3 * k * cw };
                let img = &self.image[3 * px..3 * px + 3 * cw];
                if let Some(c) = first_overflow(&out[o..o + 3 * cw], img) {
                    return Err(overflow_error(px + c, &p));
                }
            }
        }
        Ok(st)
    }
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

#[cfg(target_arch = "x86_64")]
fn avx2_available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_available() -> bool {
    false
}

fn run_chunk(f: &Frame, base: usize, o: &mut [MaybeUninit<f32>], w: &mut Work) -> Stats {
    #[cfg(target_arch = "x86_64")]
    if f.avx2 {
        // SAFETY: AVX2 was detected on this CPU (`avx2_available`).
        return unsafe { chunk_avx2(f, base, o, w) };
    }
    chunk(f, base, o, w)
}

/// [`chunk`] compiled for AVX2: the lane loops become 8-wide ymm arithmetic. Only vectorisation
/// changes; the operations and their rounding are those of the portable path.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn chunk_avx2(f: &Frame, base: usize, o: &mut [MaybeUninit<f32>], w: &mut Work) -> Stats {
    chunk(f, base, o, w)
}

/// One chunk of pixels (`o` = I~ of pixels base.., not yet written): first the pixels that need
/// eqs. 3–5 (in a patch, normal or material changed, the patch has an SH or a map) are listed,
/// then I is copied into `o`, then the listed pixels run in batches of [`LANES`].
#[inline(always)]
fn chunk(f: &Frame, base: usize, o: &mut [MaybeUninit<f32>], w: &mut Work) -> Stats {
    let b = f.b;
    let mut st = Stats::default();
    // The list of the chunk's pixels to recomposite: the job's, not zeroed per chunk (entries past
    // `m` are stale, never read).
    let mut todo = std::mem::take(&mut w.todo);
    let mut m = 0;
    let npx = o.len() / 3;
    let mut start = 0;
    while start < npx {
        let end = (start + SCAN).min(npx);
        if end - start == SCAN {
            // SCAN pixels at once (the common cases): all normals unmodified (one vector
            // comparison), or all of one patch, each either to recomposite or all outside.
            let i = 3 * (base + start);
            let (nrm, edt) = (&b.normals[i..i + 3 * SCAN], &b.edited[i..i + 3 * SCAN]);
            let mut eq = [false; 3 * SCAN];
            let mut same = true;
            for j in 0..3 * SCAN {
                eq[j] = nrm[j] == edt[j];
                same &= eq[j];
            }
            if f.unit_material && same {
                start = end;
                continue;
            }
            let ids = &b.ids[base + start..base + end];
            let mut one = true;
            let mut any_same = false;
            for q in 0..SCAN {
                one &= ids[q] == ids[0];
                any_same |= eq[3 * q] & eq[3 * q + 1] & eq[3 * q + 2];
            }
            let id = ids[0];
            let inside = (id >= 0) & ((id as usize) < f.sh.len());
            if one && !inside {
                start = end;
                continue;
            }
            if one && !(f.unit_material && any_same) {
                if f.has_content[id as usize] {
                    for (q, t) in todo[m..m + SCAN].iter_mut().enumerate() {
                        *t = (start + q) as u32;
                    }
                    m += SCAN;
                } else {
                    st.masked += SCAN;
                }
                start = end;
                continue;
            }
        }
        let (i0, i1) = (3 * (base + start), 3 * (base + end));
        let (nrm, edt) = (&b.normals[i0..i1], &b.edited[i0..i1]);
        for (q, k) in (start..end).enumerate() {
            let id = b.ids[base + k];
            let inside = (id >= 0) & ((id as usize) < f.sh.len());
            // Unmodified normal and material: eqs. 3–5 give I exactly; skip the arithmetic.
            let same = f.unit_material
                & (nrm[3 * q] == edt[3 * q])
                & (nrm[3 * q + 1] == edt[3 * q + 1])
                & (nrm[3 * q + 2] == edt[3 * q + 2]);
            if inside & !same {
                if f.has_content[id as usize] {
                    todo[m] = k as u32;
                    m += 1;
                } else {
                    st.masked += 1;
                }
            }
        }
        start = end;
    }
    let src = &b.image[3 * base..3 * base + o.len()];
    if m == 0 {
        // Nothing to recomposite: I~ = I, written around the cache (it is not read again here).
        copy_streaming(src, o);
        w.todo = todo;
        return st;
    }
    // SAFETY: `o` and `src` have the same length and do not overlap (`o` is the new output).
    unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), o.as_mut_ptr() as *mut f32, o.len()) };
    // SAFETY: every element of `o` was initialised just above (o.len() == src.len()).
    let o = unsafe { &mut *(o as *mut [MaybeUninit<f32>] as *mut [f32]) };
    // The lane arrays `w` are written in place by each batch, never zeroed or copied per batch
    // (lanes past a short batch's end keep stale values, never read).
    for ks in todo[..m].chunks(LANES) {
        batch(f, base, ks, o, &mut st, w);
    }
    w.todo = todo;
    st
}

/// `o` = `src` (same length), with non-temporal stores on x86-64 (no read of the destination's
/// cache lines first), a plain copy elsewhere or where `o` is not 16-byte aligned.
#[inline(always)]
fn copy_streaming(src: &[f32], o: &mut [MaybeUninit<f32>]) {
    assert_eq!(src.len(), o.len());
    #[cfg(target_arch = "x86_64")]
    if (o.as_ptr() as usize).is_multiple_of(16) {
        use std::arch::x86_64::{_mm_loadu_ps, _mm_sfence, _mm_stream_ps};
        let n4 = o.len() / 4 * 4;
        let (d, s) = (o.as_mut_ptr() as *mut f32, src.as_ptr());
        // SAFETY: SSE is baseline on x86-64; i + 4 ≤ n4 ≤ len for both slices; d + i is 16-byte
        // aligned (d is, i is a multiple of 4); the sfence orders the streaming stores before
        // anything this thread does next (the rayon join that publishes `o`).
        unsafe {
            let mut i = 0;
            while i < n4 {
                _mm_stream_ps(d.add(i), _mm_loadu_ps(s.add(i)));
                i += 4;
            }
            _mm_sfence();
        }
        for (x, y) in o[n4..].iter_mut().zip(&src[n4..]) {
            x.write(*y);
        }
        return;
    }
    // SAFETY: same length, no overlap (`o` is the new output).
    unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), o.as_mut_ptr() as *mut f32, o.len()) };
}

thread_local! {
    /// Each thread's lane arrays, made on its first chunk and kept (about 25 kB): an edit
    /// allocates none.
    static WORK: std::cell::RefCell<Option<Box<Work>>> = const { std::cell::RefCell::new(None) };
}

/// `run` with this thread's [`Work`] (a fresh one if it is in use: never, as the kernels do not
/// re-enter rayon, but a panic must not be the answer).
fn with_work<R>(run: impl FnOnce(&mut Work) -> R) -> R {
    WORK.with(|cell| match cell.try_borrow_mut() {
        Ok(mut slot) => run(slot.get_or_insert_with(Work::new)),
        Err(_) => run(&mut Work::new()),
    })
}

/// The lane arrays (structure of arrays, one f32 lane per pixel) of one batch.
struct Work {
    /// A chunk's pixels to recomposite ([`CHUNK`] entries).
    todo: Vec<u32>,
    k: [usize; LANES],
    px: [usize; LANES],
    id: [usize; LANES],
    d0: [Lanes; 3],
    r0: [Lanes; 3],
    cd: [Lanes; 3],
    cr: [Lanes; 3],
    ad: Lanes,
    ar: Lanes,
    a: Lanes,
    /// A gathered vector before normalisation.
    raw: [Lanes; 3],
    nn: [Lanes; 3],
    ne: [Lanes; 3],
    vv: [Lanes; 3],
    ok: [bool; LANES],
    dy: [Lanes; SH_COEFFS],
    dt: [Lanes; 3],
    r: [Lanes; 3],
    re: [Lanes; 3],
    chord: Lanes,
    wgt: Lanes,
    size: Lanes,
    last: [i32; LANES],
    face: [i32; LANES],
    tx: Lanes,
    ty: Lanes,
    fx: Lanes,
    fy: Lanes,
    /// Texel indices (not ×3) of the four corners i0j0, i0j1, i1j0, i1j1.
    corner: [[i32; LANES]; 4],
    fetch: [bool; LANES],
    t: [[Lanes; 3]; 4],
    shade: [Lanes; 3],
    shade0: [Lanes; 3],
}

impl Work {
    fn new() -> Box<Work> {
        const Z: Lanes = [0.0; LANES];
        Box::new(Work {
            todo: vec![0; CHUNK],
            k: [0; LANES],
            px: [0; LANES],
            id: [0; LANES],
            d0: [Z; 3],
            r0: [Z; 3],
            cd: [Z; 3],
            cr: [Z; 3],
            ad: Z,
            ar: Z,
            a: Z,
            raw: [Z; 3],
            nn: [Z; 3],
            ne: [Z; 3],
            vv: [Z; 3],
            ok: [false; LANES],
            dy: [Z; SH_COEFFS],
            dt: [Z; 3],
            r: [Z; 3],
            re: [Z; 3],
            chord: Z,
            wgt: Z,
            size: Z,
            last: [0; LANES],
            face: [0; LANES],
            tx: Z,
            ty: Z,
            fx: Z,
            fy: Z,
            corner: [[0; LANES]; 4],
            fetch: [false; LANES],
            t: [[Z; 3]; 4],
            shade: [Z; 3],
            shade0: [Z; 3],
        })
    }
}

/// Squared lengths (f32) for which [`unit_lanes`] decides in f32: inside, the f64 squared length
/// is within a few ulps of it, far from [`unit`]'s limits (length > 1e-12, finite) and from f32
/// underflow/overflow of the squares; outside (tiny, huge, NaN or inf), the lane is redone in f64.
const SQ_MIN: f32 = 1e-20;
const SQ_MAX: f32 = 1e36;

/// Unit vectors of the lanes `v` (into `u`, in f32: 1/√(x² + y² + z²)), and whether each could
/// be normalised, exactly as [`unit`] decides it (finite, f64 length > 1e-12): lanes whose f32
/// squared length is outside (SQ_MIN, SQ_MAX) — rare: tiny, huge or non-finite — are classified
/// and normalised in f64 as [`unit`] does. `ok` is and-ed with the result.
#[inline(always)]
fn unit_lanes(v: &[Lanes; 3], u: &mut [Lanes; 3], ok: &mut [bool; LANES], nb: usize) {
    let nb = nb.min(LANES);
    let mut rare = false;
    for l in 0..nb {
        let (x, y, z) = (v[0][l], v[1][l], v[2][l]);
        let s = x * x + y * y + z * z;
        let clear = (s > SQ_MIN) & (s < SQ_MAX);
        rare |= !clear;
        // 1/√s from f32 (≈ 1e-7 relative), then a Newton step in f64 on the f64 squared length
        // (exact squares of f32 values): ≈ 1e-14 relative, so the rounded components are
        // [`unit`]'s except in rare near-ties (1 ulp there).
        let (xd, yd, zd) = (x as f64, y as f64, z as f64);
        let sd = xd * xd + yd * yd + zd * zd;
        let r0 = (1.0 / s.sqrt()) as f64;
        let r = r0 * (1.5 - 0.5 * sd * r0 * r0);
        u[0][l] = (xd * r) as f32;
        u[1][l] = (yd * r) as f32;
        u[2][l] = (zd * r) as f32;
    }
    if rare {
        for l in 0..nb {
            let (x, y, z) = (v[0][l], v[1][l], v[2][l]);
            let s = x * x + y * y + z * z;
            if !((s > SQ_MIN) & (s < SQ_MAX)) {
                let (x, y, z) = (x as f64, y as f64, z as f64);
                let len = (x * x + y * y + z * z).sqrt();
                let good = len.is_finite() & (len > 1e-12);
                let r = if good { 1.0 / len } else { 0.0 };
                u[0][l] = (x * r) as f32;
                u[1][l] = (y * r) as f32;
                u[2][l] = (z * r) as f32;
                ok[l] &= good;
            }
        }
    }
}

/// Y_k(ñ) − Y_k(n) for the order-2 SH basis of eq. 1 ([`sh::basis`] in f32), per lane.
#[inline(always)]
fn basis_diff_lanes(n: &[Lanes; 3], e: &[Lanes; 3], dy: &mut [Lanes; SH_COEFFS], nb: usize) {
    let nb = nb.min(LANES);
    let (c1, c2, c6, c8) = (
        0.488_602_5_f32,
        1.092_548_4_f32,
        0.315_391_57_f32,
        0.546_274_2_f32,
    );
    for l in 0..nb {
        let (x, y, z) = (n[0][l], n[1][l], n[2][l]);
        let (xe, ye, ze) = (e[0][l], e[1][l], e[2][l]);
        dy[0][l] = 0.0; // Y_00 is a constant: its difference is 0
        dy[1][l] = c1 * ye - c1 * y;
        dy[2][l] = c1 * ze - c1 * z;
        dy[3][l] = c1 * xe - c1 * x;
        dy[4][l] = c2 * xe * ye - c2 * x * y;
        dy[5][l] = c2 * ye * ze - c2 * y * z;
        dy[6][l] = c6 * (3.0 * ze * ze - 1.0) - c6 * (3.0 * z * z - 1.0);
        dy[7][l] = c2 * xe * ze - c2 * x * z;
        dy[8][l] = c8 * (xe * xe - ye * ye) - c8 * (x * x - y * y);
    }
}

/// Mirror reflection of the view v about n: r = 2(n·v)n − v, per lane.
#[inline(always)]
fn reflect_lanes(v: &[Lanes; 3], n: &[Lanes; 3], r: &mut [Lanes; 3], nb: usize) {
    let nb = nb.min(LANES);
    for l in 0..nb {
        let d = 2.0 * (n[0][l] * v[0][l] + n[1][l] * v[1][l] + n[2][l] * v[2][l]);
        for c in 0..3 {
            r[c][l] = d * n[c][l] - v[c][l];
        }
    }
}

/// x^p for the lanes of x, with x first clamped as `x.max(0.0)` (NaN → 0): powf's values (0 for
/// 0, ∞ for ∞), within 1 ulp (tested). log2 (atanh series) and exp2 (Taylor series) in f64,
/// relative error about 1e-11 before the rounding to f32 — the lanes vectorise, where powf is a
/// call per value.
// The lane loops run `for l in 0..nb` (a run-time count, which LLVM vectorises; see `batch`) and
// keep that one shape in every kernel, whether they index one lane array or several.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn pow_lanes(x: &mut Lanes, p: f64, nb: usize) {
    let nb = nb.min(LANES);
    // 1.5·2^52: adding and subtracting it rounds an f64 of magnitude < 2^51 to an integer.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    for l in 0..nb {
        let xv = x[l].max(0.0);
        // x = 2^e · m, m ∈ [√½, √2); subnormals scaled by 2^24 first.
        let sub = xv < f32::MIN_POSITIVE;
        let bits = if sub { xv * 16_777_216.0 } else { xv }.to_bits();
        let mut e = (bits >> 23) as i32 - if sub { 127 + 24 } else { 127 };
        let mut mb = (bits & 0x007f_ffff) | 0x3f80_0000;
        if mb > 0x3fb5_04f3 {
            mb -= 0x0080_0000;
            e += 1;
        }
        let m = f32::from_bits(mb) as f64;
        // log2 m = (2/ln 2) atanh t, t = (m − 1)/(m + 1), |t| ≤ 0.1716: terms to t^11 (the
        // next is below 1e-11 of log2 m).
        let t = (m - 1.0) / (m + 1.0);
        let t2 = t * t;
        let s = 1.0
            + t2 * (1.0 / 3.0
                + t2 * (1.0 / 5.0 + t2 * (1.0 / 7.0 + t2 * (1.0 / 9.0 + t2 * (1.0 / 11.0)))));
        let l2 = e as f64 + (2.0 * std::f64::consts::LOG2_E) * (t * s);
        // 2^y = 2^i · e^(f ln 2), i = round(y), |f| ≤ ½: Taylor terms to (f ln 2)^10 (the next
        // is below 3e-13).
        // Not `clamp`: a NaN exponent (p·l2 with p = ±∞ at x = 1) must go to a bound, as
        // `max`/`min` send it, and never reach the bit tricks below.
        #[allow(clippy::manual_clamp)]
        let y = (p * l2).max(-1000.0).min(1000.0);
        let big = y + MAGIC;
        let f = y - (big - MAGIC);
        let i = big.to_bits().wrapping_sub(MAGIC.to_bits());
        let w = f * std::f64::consts::LN_2;
        let mut q = 1.0 / 3_628_800.0;
        for c in [
            1.0 / 362_880.0,
            1.0 / 40_320.0,
            1.0 / 5_040.0,
            1.0 / 720.0,
            1.0 / 120.0,
            1.0 / 24.0,
            1.0 / 6.0,
            0.5,
            1.0,
            1.0,
        ] {
            q = c + w * q;
        }
        let scale = f64::from_bits(i.wrapping_add(1023) << 52);
        let r = (q * scale) as f32;
        x[l] = if xv == f32::INFINITY {
            f32::INFINITY
        } else if xv > 0.0 {
            r
        } else {
            0.0
        };
    }
}

/// Eqs. 3–5 for up to [`LANES`] pixels `ks` (offsets from `base`) of one chunk, structure of
/// arrays in `w`: the buffers are gathered into lanes, computed lane-wise, and I~ is stored for
/// the pixels that pass the masks (unit n, ñ and v; finite shading, reflectance and α's).
// Lane loops (see `pow_lanes`): one subscript l over the nb lanes of several arrays (w.k, w.px,
// w.id, ...), as eqs. 3–5 are written per pixel.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn batch(f: &Frame, base: usize, ks: &[u32], o: &mut [f32], st: &mut Stats, w: &mut Work) {
    let b = f.b;
    // The loops below run over the batch's nb lanes, a run-time count: LLVM then keeps them as
    // loops and vectorises them (a constant count of 8 was unrolled and left scalar).
    let nb = ks.len().min(LANES);
    for l in 0..nb {
        w.k[l] = ks[l] as usize;
        w.px[l] = base + w.k[l];
    }
    // Consecutive pixels (the common case: a full batch inside an edited region) are loaded as
    // one slice per buffer and de-interleaved; others are gathered lane by lane.
    let run = (nb == LANES && w.k[LANES - 1] - w.k[0] == LANES - 1).then_some(w.px[0]);
    if let Some(p) = run {
        let ids: &[i32; LANES] = b.ids[p..p + LANES].try_into().unwrap();
        for l in 0..LANES {
            w.id[l] = ids[l] as usize;
        }
    } else {
        for l in 0..nb {
            w.id[l] = b.ids[w.px[l]] as usize;
        }
    }
    match f.pre {
        Some(pre) => {
            // The session's tables: unit n and v, the validity and eq. 5's subtracted term.
            gather_passes(b, run, nb, w, f.avx2);
            pre.load(run, nb, w, f.view);
        }
        None => static_terms(f, run, nb, w),
    }
    gather3(b.edited, &w.px, run, nb, &mut w.raw, f.avx2);
    unit_lanes(&w.raw, &mut w.ne, &mut w.ok, nb);
    let id0 = w.id[0];
    let uniform = w.id[..nb].iter().all(|&x| x == id0);

    // Eq. 4. The angle from the chord |r − r~| = 2 sin(θ/2): v = 1 without any trigonometry once
    // the chord reaches 2 sin(ε/2); exactly 0 when r~ = r.
    reflect_lanes(&w.vv, &w.nn, &mut w.r, nb);
    reflect_lanes(&w.vv, &w.ne, &mut w.re, nb);
    let mut short = false;
    for l in 0..nb {
        let dr = [
            w.r[0][l] - w.re[0][l],
            w.r[1][l] - w.re[1][l],
            w.r[2][l] - w.re[2][l],
        ];
        w.chord[l] = (dr[0] * dr[0] + dr[1] * dr[1] + dr[2] * dr[2]).sqrt();
        // chord_eps comes from the validated ε (never NaN); a NaN chord counts as short.
        short |= w.chord[l].is_nan() || w.chord[l] < f.chord_eps;
    }
    // wgt = v α_R.
    if short {
        for l in 0..nb {
            let vis = if w.chord[l] >= f.chord_eps {
                1.0
            } else {
                2.0 * (0.5 * w.chord[l]).min(1.0).asin() * f.inv_eps
            };
            w.wgt[l] = vis * w.ar[l];
        }
    } else {
        for l in 0..nb {
            w.wgt[l] = 1.0 * w.ar[l];
        }
    }
    // R(r~): the dual-paraboloid lookup, the texel coordinates lane-wise, the bilinear fetch per
    // lane (where the patch has a map and v α_R ≠ 0; else R0, which eq. 4 then returns).
    if uniform {
        w.size[..nb].fill(f.env_size[id0]);
        w.last[..nb].fill(f.env_n[id0] as i32 - 1);
        w.fetch[..nb].fill(f.has_env[id0]);
    } else {
        for l in 0..nb {
            w.size[l] = f.env_size[w.id[l]];
            w.last[l] = f.env_n[w.id[l]] as i32 - 1;
            w.fetch[l] = f.has_env[w.id[l]];
        }
    }
    paraboloid_texel_lanes(&w.re, &w.size, &mut w.face, &mut w.tx, &mut w.ty, nb);
    // The four texels (i0|i1, j0|j1) around (tx, ty) and the bilinear weights, ParaboloidMap's
    // way; fetched for every lane (a patch without a map has a 1×1 map of zeros here: the
    // coordinates are always inside the map), used where the patch has a map and v α_R ≠ 0.
    for l in 0..nb {
        let last = w.last[l];
        // tx, ty ∈ [0, size − 1] (never NaN: `clamp_lane`), so truncation is the floor, as
        // `as usize` was; the integer clamps only make the bounds evident.
        // SAFETY: tx, ty are finite and in [0, size − 1], and size < 2^31 (a map holds 6·size²
        // values in memory).
        let (jt, it) = unsafe {
            (
                w.tx[l].to_int_unchecked::<i32>(),
                w.ty[l].to_int_unchecked::<i32>(),
            )
        };
        let j0 = jt.max(0).min(last);
        let i0 = it.max(0).min(last);
        let j1 = (j0 + 1).min(last);
        let i1 = (i0 + 1).min(last);
        w.fx[l] = w.tx[l] - j0 as f32;
        w.fy[l] = w.ty[l] - i0 as f32;
        w.fetch[l] &= w.ok[l] & (w.wgt[l] != 0.0);
        // Texel indices when they fit in i32 (below 2n²), else the rows and columns.
        let n = last + 1;
        let (row0, row1) = if f.small_maps {
            ((w.face[l] * n + i0) * n, (w.face[l] * n + i1) * n)
        } else {
            (0, 0)
        };
        w.corner[0][l] = if f.small_maps { row0 + j0 } else { i0 };
        w.corner[1][l] = if f.small_maps { row0 + j1 } else { j0 };
        w.corner[2][l] = if f.small_maps { row1 + j0 } else { i1 };
        w.corner[3][l] = if f.small_maps { row1 + j1 } else { j1 };
    }
    // The texels are fetched after eq. 3: start loading their cache lines now (the first and
    // last value of each row's pair of texels).
    #[cfg(target_arch = "x86_64")]
    for l in 0..nb {
        let data = if uniform {
            f.env_data[id0]
        } else {
            f.env_data[w.id[l]]
        };
        if f.small_maps {
            for q in [0, 2] {
                let k = 3 * w.corner[q][l] as usize;
                // Prefetching is a hint: an address past the map is not dereferenced.
                let p = data.as_ptr().wrapping_add(k) as *const i8;
                let p1 = data.as_ptr().wrapping_add(k + 5) as *const i8;
                // SAFETY: `_mm_prefetch` does not access memory (SSE is baseline on x86-64).
                unsafe {
                    std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p);
                    std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p1);
                }
            }
        }
    }

    // Eq. 3: D(ñ) − D(n) = Σ_k c_k (Y_k(ñ) − Y_k(n)); the clamp [·] = max(min(0, D0), ·);
    // D~ = D0 + α_D([·] − D0).
    basis_diff_lanes(&w.nn, &w.ne, &mut w.dy, nb);
    for c in 0..3 {
        let s = &mut w.dt[c];
        s[..nb].fill(0.0);
        if uniform {
            let co = &f.sh[id0][c];
            for j in 0..SH_COEFFS {
                for l in 0..nb {
                    s[l] += co[j] * w.dy[j][l];
                }
            }
        } else {
            for j in 0..SH_COEFFS {
                for l in 0..nb {
                    s[l] += f.sh[w.id[l]][c][j] * w.dy[j][l];
                }
            }
        }
        let d0 = &w.d0[c];
        for l in 0..nb {
            let res = (d0[l] + s[l]).max(d0[l].min(0.0));
            s[l] = d0[l] + w.ad[l] * (res - d0[l]);
        }
    }

    // SAFETY (the unchecked loads): face ∈ {0, 1} and i, j ∈ [0, n − 1] (clamped above), so a
    // texel index is below 2n², and every map (or NO_MAP, n = 1) holds 2n²·3 values (checked in
    // `recomposite_with`).
    #[cfg(target_arch = "x86_64")]
    let gathered = f.avx2 && f.small_maps && uniform && {
        // SAFETY: AVX2 was detected (`f.avx2`); the indices are inside the map (above).
        unsafe { fetch_avx2(f.env_data[id0], &w.corner, &mut w.t, nb) };
        true
    };
    #[cfg(not(target_arch = "x86_64"))]
    let gathered = false;
    if gathered {
    } else if f.small_maps && uniform {
        let data = f.env_data[id0];
        for l in 0..nb {
            for q in 0..4 {
                let k = 3 * w.corner[q][l] as usize;
                debug_assert!(k + 3 <= data.len());
                for c in 0..3 {
                    w.t[q][c][l] = unsafe { *data.get_unchecked(k + c) };
                }
            }
        }
    } else {
        for l in 0..nb {
            let data = f.env_data[w.id[l]];
            let corner = if f.small_maps {
                [
                    w.corner[0][l] as usize,
                    w.corner[1][l] as usize,
                    w.corner[2][l] as usize,
                    w.corner[3][l] as usize,
                ]
            } else {
                let n = w.last[l] as usize + 1;
                let face = w.face[l] as usize;
                let (i0, j0, i1, j1) = (
                    w.corner[0][l] as usize,
                    w.corner[1][l] as usize,
                    w.corner[2][l] as usize,
                    w.corner[3][l] as usize,
                );
                let (row0, row1) = ((face * n + i0) * n, (face * n + i1) * n);
                [row0 + j0, row0 + j1, row1 + j0, row1 + j1]
            };
            for q in 0..4 {
                let k = 3 * corner[q];
                debug_assert!(k + 3 <= data.len());
                for c in 0..3 {
                    w.t[q][c][l] = unsafe { *data.get_unchecked(k + c) };
                }
            }
        }
    }
    // Eqs. 4 and 5: R~ = R0 + vα_R(R(r~) − R0); I~ = I + α[g(k_D c_D D~ + k_R c_R R~) − g(c_D D0 + c_R R0)].
    for c in 0..3 {
        let t = &w.t;
        for l in 0..nb {
            let top = t[0][c][l] + w.fx[l] * (t[1][c][l] - t[0][c][l]);
            let bot = t[2][c][l] + w.fx[l] * (t[3][c][l] - t[2][c][l]);
            let v = top + w.fy[l] * (bot - top);
            let r0 = w.r0[c][l];
            let look = if w.fetch[l] { v } else { r0 };
            let rt = r0 + w.wgt[l] * (look - r0);
            w.shade[c][l] = f.k_d * (w.cd[c][l] * w.dt[c][l]) + f.k_r * (w.cr[c][l] * rt);
        }
    }
    if !f.gamma_one {
        let p = f.inv_gamma as f64;
        for c in 0..3 {
            pow_lanes(&mut w.shade[c], p, nb);
        }
    }
    if f.pre.is_none() {
        shade0_lanes(f, nb, w);
    }
    if run.is_some() && w.ok[..nb].iter().all(|&x| x) {
        st.edited += LANES;
        let q = &mut o[3 * w.k[0]..3 * w.k[0] + 3 * LANES];
        // Overflow (finite I, non-finite I~) counted in the same pass as the store.
        let mut bad = 0u32;
        for l in 0..nb {
            for c in 0..3 {
                let i = q[3 * l + c];
                let x = i + w.a[l] * (w.shade[c][l] - w.shade0[c][l]);
                q[3 * l + c] = x;
                bad += u32::from(i.is_finite() & !x.is_finite());
            }
        }
        st.overflow += bad as usize;
        return;
    }
    for l in 0..nb {
        if w.ok[l] {
            st.edited += 1;
            let q = &mut o[3 * w.k[l]..3 * w.k[l] + 3];
            for c in 0..3 {
                let i = q[c];
                q[c] = i + w.a[l] * (w.shade[c][l] - w.shade0[c][l]);
                st.overflow += usize::from(i.is_finite() & !q[c].is_finite());
            }
        } else {
            st.masked += 1;
        }
    }
}

/// The four texels' channels of the lanes (`corner`: texel indices into `data`) into `t`, eight
/// lanes per AVX2 gather (the lanes past `nb` are masked off: their indices are stale).
///
/// # Safety
/// AVX2 must be available, and every index of `corner[..][..nb]` below `data.len() / 3`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn fetch_avx2(data: &[f32], corner: &[[i32; LANES]; 4], t: &mut [[Lanes; 3]; 4], nb: usize) {
    use std::arch::x86_64::*;
    let nb = nb.min(LANES);
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    for (cq, tq) in corner.iter().zip(t.iter_mut()) {
        let mut l = 0;
        while l < nb {
            let k = _mm256_loadu_si256(cq.as_ptr().add(l) as *const __m256i);
            let k3 = _mm256_add_epi32(k, _mm256_add_epi32(k, k));
            let live = _mm256_cmpgt_epi32(_mm256_set1_epi32((nb - l) as i32), lane);
            let m = _mm256_castsi256_ps(live);
            for (c, tc) in tq.iter_mut().enumerate() {
                let v =
                    _mm256_mask_i32gather_ps::<4>(_mm256_setzero_ps(), data.as_ptr().add(c), k3, m);
                _mm256_storeu_ps(tc.as_mut_ptr().add(l), v);
            }
            l += 8;
        }
    }
}

/// D0, R0, c_D, c_R and the α's of the lanes' pixels `px` into `w` (1 where an optional buffer
/// is empty).
#[inline(always)]
fn gather_passes(b: &Buffers, run: Option<usize>, nb: usize, w: &mut Work, simd: bool) {
    let px = &w.px;
    gather3(b.diffuse, px, run, nb, &mut w.d0, simd);
    gather3(b.reflection, px, run, nb, &mut w.r0, simd);
    col3(b.diffuse_color, px, run, nb, &mut w.cd, simd);
    col3(b.reflection_color, px, run, nb, &mut w.cr, simd);
    opt1(b.alpha_d, px, run, nb, &mut w.ad);
    opt1(b.alpha_r, px, run, nb, &mut w.ar);
    opt1(b.alpha, px, run, nb, &mut w.a);
}

/// What eqs. 3–5 need of the lanes' pixels `w.px` besides ñ: the passes ([`gather_passes`]),
/// unit n and v (`w.nn`, `w.vv`) and whether the pixel can be recomposited (`w.ok`: finite
/// passes, n and v normalisable).
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn static_terms(f: &Frame, run: Option<usize>, nb: usize, w: &mut Work) {
    let b = f.b;
    let nb = nb.min(LANES);
    gather_passes(b, run, nb, w, f.avx2);
    for l in 0..nb {
        let mut fin = w.ad[l].is_finite() & w.ar[l].is_finite() & w.a[l].is_finite();
        for c in 0..3 {
            fin &= w.d0[c][l].is_finite()
                & w.r0[c][l].is_finite()
                & w.cd[c][l].is_finite()
                & w.cr[c][l].is_finite();
        }
        w.ok[l] = fin;
    }
    gather3(b.normals, &w.px, run, nb, &mut w.raw, f.avx2);
    unit_lanes(&w.raw, &mut w.nn, &mut w.ok, nb);
    match f.view {
        View::PerPixel => {
            gather3(b.view, &w.px, run, nb, &mut w.raw, f.avx2);
            unit_lanes(&w.raw, &mut w.vv, &mut w.ok, nb);
        }
        View::Constant(v) => {
            for c in 0..3 {
                w.vv[c][..nb].fill(v[c]);
            }
        }
        View::Invalid => {
            for c in 0..3 {
                w.vv[c][..nb].fill([0.0, 0.0, 1.0][c]);
            }
            w.ok[..nb].fill(false);
        }
    }
}

/// Eq. 5's subtracted term g(c_D D0 + c_R R0) of the lanes into `w.shade0` (g = x^(1/γ)).
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn shade0_lanes(f: &Frame, nb: usize, w: &mut Work) {
    let nb = nb.min(LANES);
    for c in 0..3 {
        for l in 0..nb {
            w.shade0[c][l] = w.cd[c][l] * w.d0[c][l] + w.cr[c][l] * w.r0[c][l];
        }
    }
    if !f.gamma_one {
        for c in 0..3 {
            pow_lanes(&mut w.shade0[c], f.inv_gamma as f64, nb);
        }
    }
}

/// Pixels of one block of [`Prepared::tab`]: one batch's lanes.
const BLOCK: usize = LANES;
/// Blocks per parallel task when preparing.
const PREP_BLOCKS: usize = CHUNK / BLOCK;

impl Prepared {
    /// The tables of the frame `f` (`f.pre` is None; the passes already validated) of `n` pixels,
    /// blocks of pixels in parallel, through the same lane functions as a batch.
    fn new(f: &Frame, n: usize) -> Prepared {
        let comps = Self::comps(f.view);
        let blocks = n.div_ceil(BLOCK);
        let mut tab = vec![0.0f32; blocks * comps * BLOCK];
        let mut ok = vec![false; blocks * BLOCK];
        tab.par_chunks_mut(PREP_BLOCKS * comps * BLOCK)
            .zip(ok.par_chunks_mut(PREP_BLOCKS * BLOCK))
            .enumerate()
            .for_each(|(t, (tab, ok))| {
                with_work(|w| {
                    let blocks = tab.chunks_mut(comps * BLOCK).zip(ok.chunks_mut(BLOCK));
                    for (j, (tb, okb)) in blocks.enumerate() {
                        let base = (t * PREP_BLOCKS + j) * BLOCK;
                        prepare_block(f, base, (n - base).min(BLOCK), w, tb, okb);
                    }
                })
            });
        Prepared { tab, ok }
    }

    /// Lane arrays per block: unit n, g(c_D D0 + c_R R0) and, with a per-pixel view, unit v.
    fn comps(view: View) -> usize {
        if matches!(view, View::PerPixel) {
            9
        } else {
            6
        }
    }

    /// Bytes held.
    fn bytes(&self) -> usize {
        4 * self.tab.len() + self.ok.len()
    }

    /// The lanes' unit n, v, validity and eq. 5's subtracted term into `w`; `run` as for
    /// [`gather3`].
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn load(&self, run: Option<usize>, nb: usize, w: &mut Work, view: View) {
        let nb = nb.min(LANES);
        let px = &w.px;
        let comps = Self::comps(view);
        let stride = comps * BLOCK;
        let one = |c: usize, g: &mut Lanes| {
            if let Some(p) = run {
                // A run of BLOCK pixels spans at most two blocks.
                let (k, o) = (p / BLOCK, p % BLOCK);
                let a = k * stride + c * BLOCK;
                if o == 0 {
                    // A whole block (runs of a chunk start at multiples of BLOCK): a fixed-size copy.
                    let src: &Lanes = self.tab[a..a + BLOCK].try_into().unwrap();
                    *g = *src;
                } else {
                    g[..BLOCK - o].copy_from_slice(&self.tab[a + o..a + BLOCK]);
                    let a = a + stride;
                    g[BLOCK - o..].copy_from_slice(&self.tab[a..a + o]);
                }
            } else {
                for l in 0..nb {
                    let q = px[l];
                    g[l] = self.tab[(q / BLOCK) * stride + c * BLOCK + q % BLOCK];
                }
            }
        };
        for c in 0..3 {
            one(c, &mut w.nn[c]);
            one(3 + c, &mut w.shade0[c]);
        }
        match view {
            View::PerPixel => {
                for c in 0..3 {
                    one(6 + c, &mut w.vv[c]);
                }
            }
            View::Constant(v) => {
                for c in 0..3 {
                    w.vv[c][..nb].fill(v[c]);
                }
            }
            View::Invalid => {
                for c in 0..3 {
                    w.vv[c][..nb].fill([0.0, 0.0, 1.0][c]);
                }
            }
        }
        if let Some(p) = run {
            let src: &[bool; LANES] = self.ok[p..p + LANES].try_into().unwrap();
            w.ok = *src;
        } else {
            for l in 0..nb {
                w.ok[l] = self.ok[w.px[l]];
            }
        }
    }
}

/// One block of [`Prepared`]: pixels base..base + nb into `tb` (comps × BLOCK) and `okb`.
fn prepare_block(
    f: &Frame,
    base: usize,
    nb: usize,
    w: &mut Work,
    tb: &mut [f32],
    okb: &mut [bool],
) {
    #[cfg(target_arch = "x86_64")]
    if f.avx2 {
        // SAFETY: AVX2 was detected on this CPU (`avx2_available`).
        return unsafe { prepare_block_avx2(f, base, nb, w, tb, okb) };
    }
    prepare_block_lanes(f, base, nb, w, tb, okb)
}

/// [`prepare_block_lanes`] compiled for AVX2 (the same bits, as [`chunk_avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn prepare_block_avx2(
    f: &Frame,
    base: usize,
    nb: usize,
    w: &mut Work,
    tb: &mut [f32],
    okb: &mut [bool],
) {
    prepare_block_lanes(f, base, nb, w, tb, okb)
}

#[inline(always)]
fn prepare_block_lanes(
    f: &Frame,
    base: usize,
    nb: usize,
    w: &mut Work,
    tb: &mut [f32],
    okb: &mut [bool],
) {
    let nb = nb.min(BLOCK);
    for (l, p) in w.px[..nb].iter_mut().enumerate() {
        *p = base + l;
    }
    static_terms(f, (nb == BLOCK).then_some(base), nb, w);
    shade0_lanes(f, nb, w);
    for c in 0..3 {
        tb[c * BLOCK..c * BLOCK + nb].copy_from_slice(&w.nn[c][..nb]);
        tb[(3 + c) * BLOCK..(3 + c) * BLOCK + nb].copy_from_slice(&w.shade0[c][..nb]);
        if matches!(f.view, View::PerPixel) {
            tb[(6 + c) * BLOCK..(6 + c) * BLOCK + nb].copy_from_slice(&w.vv[c][..nb]);
        }
    }
    okb[..nb].copy_from_slice(&w.ok[..nb]);
}

/// v[3·px_l + c] for the lanes' pixels px (3-vector buffers), as lanes per component, into g;
/// `run`: the pixels are run, run + 1, …, run + LANES − 1.
#[inline(always)]
fn gather3(
    v: &[f32],
    px: &[usize; LANES],
    run: Option<usize>,
    nb: usize,
    g: &mut [Lanes; 3],
    simd: bool,
) {
    let nb = nb.min(LANES);
    if let Some(p) = run {
        let q: &[f32; 3 * LANES] = v[3 * p..3 * p + 3 * LANES].try_into().unwrap();
        #[cfg(target_arch = "x86_64")]
        if simd {
            // SAFETY: `simd` is set only where AVX2 was detected (`Frame::avx2`).
            unsafe { deinterleave_avx2(q, g) };
            return;
        }
        let _ = simd;
        let [g0, g1, g2] = g;
        for l in 0..LANES {
            g0[l] = q[3 * l];
            g1[l] = q[3 * l + 1];
            g2[l] = q[3 * l + 2];
        }
    } else {
        for l in 0..nb {
            let q = &v[3 * px[l]..3 * px[l] + 3];
            for c in 0..3 {
                g[c][l] = q[c];
            }
        }
    }
}

/// `g[c][l] = q[3l + c]` (three interleaved components into lanes), eight lanes at a time: three
/// loads, two blends and one permutation per component.
///
/// # Safety
/// AVX2 must be available.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn deinterleave_avx2(q: &[f32; 3 * LANES], g: &mut [Lanes; 3]) {
    use std::arch::x86_64::*;
    // Of a = x0 y0 z0 x1 y1 z1 x2 y2, b = z2 x3 y3 z3 x4 y4 z4 x5, c = y5 z5 x6 y6 z6 x7 y7 z7,
    // x lies at a{0,3,6}, b{1,4,7}, c{2,5}; y at c{0,3,6}, a{1,4,7}, b{2,5}; z at b{0,3,6},
    // c{1,4,7}, a{2,5}: blend those positions together, then put them in order.
    let px = _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5);
    let py = _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6);
    let pz = _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7);
    for k in 0..LANES / 8 {
        let s = q.as_ptr().add(24 * k);
        let (a, b, c) = (
            _mm256_loadu_ps(s),
            _mm256_loadu_ps(s.add(8)),
            _mm256_loadu_ps(s.add(16)),
        );
        let x = _mm256_blend_ps::<0x24>(_mm256_blend_ps::<0x92>(a, b), c);
        let y = _mm256_blend_ps::<0x49>(_mm256_blend_ps::<0x24>(a, b), c);
        let z = _mm256_blend_ps::<0x92>(_mm256_blend_ps::<0x49>(a, b), c);
        _mm256_storeu_ps(
            g[0].as_mut_ptr().add(8 * k),
            _mm256_permutevar8x32_ps(x, px),
        );
        _mm256_storeu_ps(
            g[1].as_mut_ptr().add(8 * k),
            _mm256_permutevar8x32_ps(y, py),
        );
        _mm256_storeu_ps(
            g[2].as_mut_ptr().add(8 * k),
            _mm256_permutevar8x32_ps(z, pz),
        );
    }
}

/// [`gather3`] of an optional colour buffer: 1 where it is empty.
#[inline(always)]
fn col3(
    v: &[f32],
    px: &[usize; LANES],
    run: Option<usize>,
    nb: usize,
    g: &mut [Lanes; 3],
    simd: bool,
) {
    if v.is_empty() {
        for c in g.iter_mut() {
            c[..nb.min(LANES)].fill(1.0);
        }
    } else {
        gather3(v, px, run, nb, g, simd);
    }
}

/// v[px_l] for the lanes' pixels px (an optional scalar buffer; 1 where it is empty) into g;
/// `run` as for [`gather3`].
#[inline(always)]
fn opt1(v: &[f32], px: &[usize; LANES], run: Option<usize>, nb: usize, g: &mut Lanes) {
    let nb = nb.min(LANES);
    if v.is_empty() {
        g[..nb].fill(1.0);
    } else if let Some(p) = run {
        g[..nb].copy_from_slice(&v[p..p + nb]);
    } else {
        for l in 0..nb {
            g[l] = v[px[l]];
        }
    }
}

/// The texel position of direction d in a dual-paraboloid map of `size` texels (per lane):
/// `ParaboloidMap::lookup`'s face choice and convention (texel centres, coordinates clamped to
/// the map). Gives (face, x, y) with x, y ∈ [0, size − 1].
#[inline(always)]
fn paraboloid_texel_lanes(
    d: &[Lanes; 3],
    size: &Lanes,
    face: &mut [i32; LANES],
    tx: &mut Lanes,
    ty: &mut Lanes,
    nb: usize,
) {
    let nb = nb.min(LANES);
    for l in 0..nb {
        let (x, y, z) = (d[0][l], d[1][l], d[2][l]);
        let len = (x * x + y * y + z * z).sqrt();
        let unit = (len > 0.0) & len.is_finite();
        let (x, y, z) = if unit {
            (x / len, y / len, z / len)
        } else {
            (0.0, 0.0, 1.0)
        };
        face[l] = i32::from(z < 0.0);
        let k = 1.0 / (1.0 + z.abs());
        let s = size[l];
        tx[l] = clamp_lane((x * k + 1.0) * 0.5 * s - 0.5, s - 1.0);
        ty[l] = clamp_lane((y * k + 1.0) * 0.5 * s - 0.5, s - 1.0);
    }
}

/// `x.clamp(0.0, hi)` without the panic path (hi ≥ 0 here), so that it vectorises; NaN gives 0.
#[inline(always)]
fn clamp_lane(x: f32, hi: f32) -> f32 {
    let x = if x >= 0.0 { x } else { 0.0 };
    if x > hi {
        hi
    } else {
        x
    }
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
        if let (Some(co), Some(n)) = (&patches[id as usize].sh, unit(&normals[3 * i..3 * i + 3])) {
            for c in 0..3 {
                o[c] = sh::eval(&co[c], n.to_array()) as f32;
            }
        }
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The former per-pixel implementation of eqs. 3–5, kept as the reference: one pixel at a
    /// time, scalar, f64 normalisation of n, ñ and v (as [`unit`]) and f32 arithmetic after it.
    fn recomposite_scalar(b: &Buffers, patches: &[Patch], p: &Params) -> Result<(Vec<f32>, Stats)> {
        validate(b, patches, p)?;
        // Per-patch constants, once per frame: f32 SH coefficients (channel-major) and flags.
        let sh32: Vec<Option<[[f32; SH_COEFFS]; 3]>> = patches
            .iter()
            .map(|q| q.sh.map(|c| c.map(|ch| ch.map(|x| x as f32))))
            .collect();
        let (k_d, k_r) = (p.k_d as f32, p.k_r as f32);
        let unit_material = p.k_d == 1.0 && p.k_r == 1.0;
        let inv_gamma = (1.0 / p.gamma) as f32;
        let gamma_one = p.gamma == 1.0;
        let inv_eps = (1.0 / p.epsilon) as f32;
        let chord_eps = if p.epsilon >= std::f64::consts::PI {
            f32::INFINITY
        } else {
            (2.0 * (0.5 * p.epsilon).sin()) as f32
        };
        let const_view = if b.view.len() == 3 {
            unit(b.view).map(to32)
        } else {
            None
        };
        let g = |x: f32| {
            if gamma_one {
                x
            } else {
                x.max(0.0).powf(inv_gamma)
            }
        };
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
                    let col = |v: &[f32]| -> [f32; 3] {
                        if v.is_empty() {
                            [1.0; 3]
                        } else {
                            [v[3 * i], v[3 * i + 1], v[3 * i + 2]]
                        }
                    };
                    let d0 = [b.diffuse[3 * i], b.diffuse[3 * i + 1], b.diffuse[3 * i + 2]];
                    let r0 = [
                        b.reflection[3 * i],
                        b.reflection[3 * i + 1],
                        b.reflection[3 * i + 2],
                    ];
                    let (ad, ar, a) = (opt(b.alpha_d), opt(b.alpha_r), opt(b.alpha));
                    let (cd, cr) = (col(b.diffuse_color), col(b.reflection_color));
                    let finite = d0
                        .iter()
                        .chain(&r0)
                        .chain(&cd)
                        .chain(&cr)
                        .all(|x| x.is_finite())
                        && ad.is_finite()
                        && ar.is_finite()
                        && a.is_finite();
                    let vv = match const_view {
                        Some(v) => Some(v),
                        None if b.view.len() == 3 => None,
                        None => unit(&b.view[3 * i..3 * i + 3]).map(to32),
                    };
                    let (Some(nn), Some(ne), Some(vv)) =
                        (unit(nb).map(to32), unit(eb).map(to32), vv)
                    else {
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
                    let vis = if chord >= chord_eps {
                        1.0
                    } else {
                        2.0 * (0.5 * chord).min(1.0).asin() * inv_eps
                    };
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
            .reduce(Stats::default, add);
        Ok((out, stats))
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
        [
            c0,
            c1 * y,
            c1 * z,
            c1 * x,
            c2 * x * y,
            c2 * y * z,
            0.315_391_57 * (3.0 * z * z - 1.0),
            c2 * x * z,
            0.546_274_2 * (x * x - y * y),
        ]
    }

    /// `ParaboloidMap::lookup` for 3 channels in f32: the same face choice, texel convention (texel
    /// centres, coordinates clamped to the map) and bilinear weights.
    #[inline]
    fn lookup32(m: &ParaboloidMap, d: [f32; 3]) -> [f32; 3] {
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let d = if l > 0.0 && l.is_finite() {
            [d[0] / l, d[1] / l, d[2] / l]
        } else {
            [0.0, 0.0, 1.0]
        };
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

    /// A small deterministic generator (xorshift64*), uniform in [0, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32) / (1u64 << 24) as f32
        }
    }

    /// The batched path (AVX2 where detected, and the portable one) against the per-pixel scalar
    /// reference on a random frame: patches with SH + map, SH only, map only, nothing and ids
    /// beyond the list; unmodified, slightly and strongly edited normals (v from asin and v = 1);
    /// zero and non-finite normals, NaN/inf shading and α; a pixel count that is not a multiple
    /// of 8 (nor are the edited pixels of a chunk); γ = 1 and 2.2; k_D, k_R = 1 and not; per-pixel
    /// and constant views; tiny, huge and nearly-too-short normals (classified as [`unit`] does).
    /// The same edited/masked counts, values within 2e-5·(1 + |I~|) of the reference (the batched
    /// path normalises with a Newton-refined f32 estimate and raises to 1/γ by polynomials, not
    /// `powf`), and the same bits from the portable and the AVX2 paths.
    #[test]
    fn recomposite_batches_match_scalar_reference() {
        let mut g = Rng(0x9e37_79b9_7f4a_7c15);
        let (w, h) = (97, 43); // 4171 pixels: 4 chunks, the last one partial
        let n = w * h;
        let map = |g: &mut Rng, size: usize| ParaboloidMap {
            size,
            channels: 3,
            data: (0..2 * size * size * 3).map(|_| g.next()).collect(),
        };
        let sh = |g: &mut Rng| -> [[f64; SH_COEFFS]; 3] {
            std::array::from_fn(|_| std::array::from_fn(|_| 2.0 * g.next() as f64 - 1.0))
        };
        let patches = vec![
            Patch {
                sh: Some(sh(&mut g)),
                env: Some(map(&mut g, 16)),
            },
            Patch {
                sh: Some(sh(&mut g)),
                env: None,
            },
            Patch {
                sh: None,
                env: Some(map(&mut g, 5)),
            },
            Patch {
                sh: None,
                env: None,
            },
            Patch {
                sh: Some(sh(&mut g)),
                env: Some(map(&mut g, 1)),
            },
        ];
        let mut ids = vec![0i32; n];
        let mut normals = vec![0.0f32; 3 * n];
        let mut edited = vec![0.0f32; 3 * n];
        let mut view = vec![0.0f32; 3 * n];
        let buf = |g: &mut Rng, lo: f32, hi: f32| -> Vec<f32> {
            (0..3 * n).map(|_| lo + (hi - lo) * g.next()).collect()
        };
        let mut diffuse = buf(&mut g, -0.1, 2.0);
        let reflection = buf(&mut g, 0.0, 2.0);
        let image = buf(&mut g, 0.0, 3.0);
        let dcol = buf(&mut g, 0.0, 1.0);
        let rcol = buf(&mut g, 0.0, 1.0);
        let mut alpha_d: Vec<f32> = (0..n).map(|_| g.next()).collect();
        let alpha_r: Vec<f32> = (0..n).map(|_| g.next()).collect();
        let alpha: Vec<f32> = (0..n).map(|_| g.next()).collect();
        for i in 0..n {
            // Runs of one patch (uniform batches) and mixed stretches.
            ids[i] = if (i / 200) % 3 == 2 {
                (g.next() * 7.0) as i32 - 1
            } else {
                ((i / 200) % 5) as i32
            };
            let nv = [2.0 * g.next() - 1.0, 2.0 * g.next() - 1.0, 0.2 + g.next()];
            normals[3 * i..3 * i + 3].copy_from_slice(&nv);
            let kind = g.next();
            let e = if kind < 0.25 {
                nv
            } else if kind < 0.4 {
                [nv[0] + 1e-3 * g.next(), nv[1], nv[2]]
            } else if kind < 0.45 {
                [2.0 * nv[0], 2.0 * nv[1], 2.0 * nv[2]]
            } else {
                [
                    nv[0] + g.next() - 0.5,
                    nv[1] - 0.3,
                    nv[2] * (0.2 + g.next()),
                ]
            };
            edited[3 * i..3 * i + 3].copy_from_slice(&e);
            let vv = [0.3 * (g.next() - 0.5), 0.3 * (g.next() - 0.5), 1.0];
            view[3 * i..3 * i + 3].copy_from_slice(&vv);
        }
        // Non-finite and degenerate inputs.
        for &(i, what) in &[
            (5usize, 0),
            (300, 1),
            (301, 2),
            (777, 3),
            (1500, 4),
            (2222, 5),
            (4170, 0),
            (3001, 6),
            (2500, 7),
            (2501, 8),
            (2502, 9),
            (2503, 10),
            (2504, 11),
        ] {
            match what {
                // Beyond f32 squares (the f64 fallback): accepted.
                7 => edited[3 * i..3 * i + 3].copy_from_slice(&[3e20, -1e20, 2e19]),
                8 => view[3 * i..3 * i + 3].copy_from_slice(&[0.0, 2e-20, 1e-20]),
                // Around unit()'s 1e-12 limit: 9.9999998e-13 (as f32) is too short, 2e-12 not.
                9 => normals[3 * i..3 * i + 3].copy_from_slice(&[1e-12, 0.0, 0.0]),
                10 => edited[3 * i..3 * i + 3].copy_from_slice(&[0.0, -2e-12, 0.0]),
                11 => edited[3 * i..3 * i + 3].copy_from_slice(&[f32::INFINITY, 0.0, 1.0]),
                0 => edited[3 * i] = f32::NAN,
                1 => normals[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]),
                2 => diffuse[3 * i + 1] = f32::INFINITY,
                3 => alpha_d[i] = f32::NAN,
                4 => view[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]),
                5 => edited[3 * i..3 * i + 3].copy_from_slice(&[1e-30; 3]),
                _ => diffuse[3 * i] = f32::NAN,
            }
        }
        let mut cases = 0;
        let mut worst = 0.0f64;
        for (gamma, k_d, k_r, colours, const_view, epsilon) in [
            (1.0, 1.0, 1.0, false, false, EPSILON),
            (2.2, 1.0, 1.0, true, false, EPSILON),
            (1.0, 1.3, 0.7, true, true, 0.2),
            (2.2, 0.5, 1.0, false, true, 4.0),
            (1.0, 1.0, 1.0, true, false, 0.3),
        ] {
            for cut in [n, n - 5, 8 * 131 + 3] {
                let third = [0.1f32, -0.2, 1.0];
                let b = Buffers {
                    ids: &ids[..cut],
                    normals: &normals[..3 * cut],
                    edited: &edited[..3 * cut],
                    view: if const_view { &third } else { &view[..3 * cut] },
                    diffuse: &diffuse[..3 * cut],
                    reflection: &reflection[..3 * cut],
                    alpha_d: &alpha_d[..cut],
                    alpha_r: &alpha_r[..cut],
                    alpha: if colours { &alpha[..cut] } else { &[] },
                    image: &image[..3 * cut],
                    diffuse_color: if colours { &dcol[..3 * cut] } else { &[] },
                    reflection_color: if colours { &rcol[..3 * cut] } else { &[] },
                };
                let p = Params {
                    k_d,
                    k_r,
                    gamma,
                    epsilon,
                };
                let (want, st0) = recomposite_scalar(&b, &patches, &p).unwrap();
                assert!(st0.edited > 0 && st0.masked > 0, "{st0:?}");
                let (portable, _) = recomposite_with(&b, &patches, &p, false).unwrap();
                for simd in [false, true] {
                    let (got, st) = recomposite_with(&b, &patches, &p, simd).unwrap();
                    assert_eq!(
                        (st.edited, st.masked),
                        (st0.edited, st0.masked),
                        "γ {gamma} simd {simd}"
                    );
                    for (i, (x, y)) in got.iter().zip(&want).enumerate() {
                        let d = (*x as f64 - *y as f64).abs() / (1.0 + (*y as f64).abs());
                        worst = worst.max(d);
                        assert!(
                            d <= 2e-5,
                            "value {i}: {x} vs {y} (γ {gamma}, k_D {k_d}, simd {simd})"
                        );
                        assert!(!x.is_nan(), "NaN output at {i}");
                        assert_eq!(
                            x.to_bits(),
                            portable[i].to_bits(),
                            "value {i}: AVX2 and portable paths differ"
                        );
                    }
                }
                cases += 1;
            }
        }
        assert_eq!(cases, 15);
        eprintln!("largest difference from the scalar reference: {worst:.3e}");
    }

    /// A random frame for the [`Recompositor`] tests: (w, h, ids, normals, edited, view, the
    /// shading passes, α's, I, colours) and four patches (SH + map, SH, map, nothing).
    #[allow(clippy::type_complexity)]
    fn session_frame(w: usize, h: usize) -> (Vec<i32>, Vec<Vec<f32>>, Vec<Vec<f32>>, Vec<Patch>) {
        let mut g = Rng(0x005e_ed0f_7e57);
        let n = w * h;
        let ids: Vec<i32> = (0..n).map(|i| ((i / 37) % 5) as i32 - 1).collect();
        let mut v3 = |lo: f32, hi: f32| -> Vec<f32> {
            (0..3 * n).map(|_| lo + (hi - lo) * g.next()).collect()
        };
        let normals: Vec<f32> = v3(-1.0, 1.0)
            .chunks(3)
            .flat_map(|c| [c[0], c[1], c[2].abs() + 0.3])
            .collect();
        let mut edited = normals.clone();
        for (i, x) in edited.iter_mut().enumerate() {
            if (i / 3) % 3 != 0 {
                *x += 0.2 * ((i % 7) as f32 - 3.0) / 3.0;
            }
        }
        let view: Vec<f32> = (0..n)
            .flat_map(|i| [0.01 * (i % 5) as f32, -0.1, 1.0])
            .collect();
        let threes = vec![
            v3(0.0, 2.0),
            v3(0.0, 2.0),
            v3(0.0, 3.0),
            v3(0.0, 1.0),
            v3(0.0, 1.0),
        ];
        let ones: Vec<Vec<f32>> = (0..3).map(|_| (0..n).map(|_| g.next()).collect()).collect();
        let map = |g: &mut Rng, size: usize| ParaboloidMap {
            size,
            channels: 3,
            data: (0..2 * size * size * 3).map(|_| g.next()).collect(),
        };
        let sh = |g: &mut Rng| -> [[f64; SH_COEFFS]; 3] {
            std::array::from_fn(|_| std::array::from_fn(|_| g.next() as f64 - 0.5))
        };
        let patches = vec![
            Patch {
                sh: Some(sh(&mut g)),
                env: Some(map(&mut g, 8)),
            },
            Patch {
                sh: Some(sh(&mut g)),
                env: None,
            },
            Patch {
                sh: None,
                env: Some(map(&mut g, 4)),
            },
            Patch::default(),
        ];
        let mut vecs = vec![normals, edited, view];
        vecs.extend(threes);
        (ids, vecs, ones, patches)
    }

    /// The session object against [`recomposite`] (the oracle): the whole frame, windows into a
    /// window-shaped and a frame-shaped buffer (only the window written), ñ borrowed or kept,
    /// k_D, k_R ≠ 1, γ = 2.2, new patches — the same bits.
    #[test]
    fn recompositor_matches_recomposite() {
        let (w, h) = (83, 29);
        let (ids, v, a, patches) = session_frame(w, h);
        let (normals, edited, view) = (&v[0], &v[1], &v[2]);
        for gamma in [1.0, 2.2] {
            let b = Buffers {
                ids: &ids,
                normals,
                edited,
                view,
                diffuse: &v[3],
                reflection: &v[4],
                alpha_d: &a[0],
                alpha_r: &a[1],
                alpha: &a[2],
                image: &v[5],
                diffuse_color: &v[6],
                reflection_color: &v[7],
            };
            let mut rc = Recompositor::new(w, h, &b, patches.clone(), gamma, EPSILON).unwrap();
            for (k_d, k_r) in [(1.0, 1.0), (1.3, 0.6)] {
                let p = Params {
                    k_d,
                    k_r,
                    gamma,
                    ..Params::default()
                };
                let (want, st0) = recomposite(&b, &patches, &p).unwrap();
                assert!(st0.edited > 0);
                // The whole frame, ñ borrowed.
                let mut out = vec![f32::NAN; 3 * w * h];
                let st = rc
                    .run(&rc.full(), Some(edited), k_d, k_r, &mut out, true)
                    .unwrap();
                assert_eq!((st.edited, st.masked), (st0.edited, st0.masked));
                assert!(out
                    .iter()
                    .zip(&want)
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
                // Without the per-pixel tables, and through the portable instantiation (tables
                // made by it too): the same bits.
                for (prepared, simd) in [(false, true), (true, false), (false, false)] {
                    let mut other =
                        Recompositor::new(w, h, &b, patches.clone(), gamma, EPSILON).unwrap();
                    other.simd = simd;
                    other.set_prepared(false);
                    other.set_prepared(prepared);
                    assert_eq!(other.prepared_bytes() > 0, prepared);
                    let mut o2 = vec![f32::NAN; 3 * w * h];
                    let st2 = other
                        .run(&other.full(), Some(edited), k_d, k_r, &mut o2, true)
                        .unwrap();
                    assert_eq!((st2.edited, st2.masked), (st0.edited, st0.masked));
                    assert!(o2
                        .iter()
                        .zip(&want)
                        .all(|(x, y)| x.to_bits() == y.to_bits()));
                }
                // A window: ñ kept here, set from the whole frame; window- and frame-shaped out.
                let win = Window {
                    rows: 3..17,
                    cols: 10..71,
                };
                rc.set_edited(&win, edited, true).unwrap();
                let mut small = vec![0.0f32; 3 * 14 * 61];
                rc.run(&win, None, k_d, k_r, &mut small, false).unwrap();
                let mut big = vec![-7.0f32; 3 * w * h];
                rc.run(&win, None, k_d, k_r, &mut big, true).unwrap();
                for r in 0..h {
                    for c in 0..w {
                        let i = 3 * (r * w + c);
                        let inside = win.rows.contains(&r) && win.cols.contains(&c);
                        for ch in 0..3 {
                            if inside {
                                let j = 3 * ((r - 3) * 61 + c - 10) + ch;
                                assert_eq!(small[j].to_bits(), want[i + ch].to_bits());
                                assert_eq!(big[i + ch].to_bits(), want[i + ch].to_bits());
                            } else {
                                assert_eq!(big[i + ch], -7.0, "outside the window: untouched");
                            }
                        }
                    }
                }
                // Whole rows as a window, ñ given window-shaped.
                let rows = Window {
                    rows: 20..29,
                    cols: 0..w,
                };
                rc.set_edited(&rows, &edited[3 * 20 * w..], false).unwrap();
                let mut part = vec![0.0f32; 3 * 9 * w];
                rc.run(&rows, None, k_d, k_r, &mut part, false).unwrap();
                assert!(part
                    .iter()
                    .zip(&want[3 * 20 * w..])
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
            }
            // New patches: the oracle with the same.
            let swapped: Vec<Patch> = patches.iter().rev().cloned().collect();
            rc.set_patches(swapped.clone()).unwrap();
            let (want, _) = recomposite(
                &b,
                &swapped,
                &Params {
                    gamma,
                    ..Params::default()
                },
            )
            .unwrap();
            let mut out = vec![0.0f32; 3 * w * h];
            rc.run(&rc.full(), Some(edited), 1.0, 1.0, &mut out, true)
                .unwrap();
            assert!(out
                .iter()
                .zip(&want)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
        }
    }

    /// The session's per-pixel tables with a view for the whole frame (orthographic), one that
    /// cannot be normalised, and non-finite passes and normals: the same bits and counts as
    /// [`recomposite`], with and without the tables, AVX2 and portable.
    #[test]
    fn recompositor_tables_match_recomposite_for_every_view() {
        let (w, h) = (67, 23);
        let (ids, v, a, patches) = session_frame(w, h);
        let mut v = v;
        let mut a = a;
        v[3][3 * 100 + 1] = f32::NAN; // D0
        v[4][3 * 200] = f32::INFINITY; // R0
        v[7][3 * 300 + 2] = f32::NAN; // c_R
        a[1][400] = f32::NAN; // α_R
        v[0][3 * 500] = f32::NAN; // n
        v[0][3 * 600..3 * 600 + 3].fill(0.0); // n = 0
        for view in [v[2].clone(), vec![0.1, -0.2, 1.0], vec![0.0; 3]] {
            let b = Buffers {
                ids: &ids,
                normals: &v[0],
                edited: &v[1],
                view: &view,
                diffuse: &v[3],
                reflection: &v[4],
                alpha_d: &a[0],
                alpha_r: &a[1],
                alpha: &a[2],
                image: &v[5],
                diffuse_color: &v[6],
                reflection_color: &v[7],
            };
            for gamma in [1.0, 2.2] {
                let p = Params {
                    gamma,
                    k_d: 1.1,
                    ..Params::default()
                };
                let (want, st0) = recomposite(&b, &patches, &p).unwrap();
                assert!(st0.masked > 0);
                for (prepared, simd) in [(true, true), (true, false), (false, true)] {
                    let mut rc =
                        Recompositor::new(w, h, &b, patches.clone(), gamma, EPSILON).unwrap();
                    rc.simd = simd;
                    rc.set_prepared(false);
                    rc.set_prepared(prepared);
                    let mut out = vec![f32::NAN; 3 * w * h];
                    let st = rc
                        .run(&rc.full(), Some(&v[1]), 1.1, 1.0, &mut out, true)
                        .unwrap();
                    assert_eq!((st.edited, st.masked), (st0.edited, st0.masked));
                    assert!(out
                        .iter()
                        .zip(&want)
                        .all(|(x, y)| x.to_bits() == y.to_bits()));
                }
            }
        }
    }

    /// Bad input to the session object: wrong lengths, windows outside the frame, non-finite
    /// k's, bad maps — errors naming the argument; overflow refused naming the pixel, at γ = 1
    /// too.
    #[test]
    fn recompositor_refuses_bad_input() {
        let (w, h) = (16, 8);
        let (ids, v, a, patches) = session_frame(w, h);
        let b = Buffers {
            ids: &ids,
            normals: &v[0],
            edited: &v[1],
            view: &v[2],
            diffuse: &v[3],
            reflection: &v[4],
            alpha_d: &a[0],
            alpha_r: &a[1],
            alpha: &a[2],
            image: &v[5],
            diffuse_color: &[],
            reflection_color: &[],
        };
        let arg = |e: RokebyError| match e {
            RokebyError::InvalidArgument { arg, .. } => arg,
            e => panic!("{e}"),
        };
        let e = Recompositor::new(w + 1, h, &b, patches.clone(), 1.0, EPSILON)
            .err()
            .unwrap();
        assert_eq!(arg(e), "ids");
        let short = Buffers {
            diffuse: &v[3][3..],
            ..b
        };
        let e = Recompositor::new(w, h, &short, patches.clone(), 1.0, EPSILON)
            .err()
            .unwrap();
        assert_eq!(arg(e), "diffuse");
        let e = Recompositor::new(w, h, &b, patches.clone(), f64::NAN, EPSILON)
            .err()
            .unwrap();
        assert_eq!(arg(e), "gamma");
        let mut rc = Recompositor::new(w, h, &b, patches.clone(), 1.0, EPSILON).unwrap();
        let mut out = vec![0.0f32; 3 * w * h];
        let full = rc.full();
        let e = rc
            .run(&full, Some(&v[1][3..]), 1.0, 1.0, &mut out, true)
            .err()
            .unwrap();
        assert_eq!(arg(e), "edited_normals");
        let e = rc
            .run(&full, None, 1.0, 1.0, &mut out[3..], true)
            .err()
            .unwrap();
        assert_eq!(arg(e), "out");
        let e = rc
            .run(&full, None, f64::NAN, 1.0, &mut out, true)
            .err()
            .unwrap();
        assert_eq!(arg(e), "k_d");
        for win in [
            Window {
                rows: 0..h + 1,
                cols: 0..w,
            },
            Window {
                rows: 2..2,
                cols: 0..w,
            },
            Window {
                rows: 0..h,
                cols: 5..w + 3,
            },
        ] {
            let e = rc.run(&win, None, 1.0, 1.0, &mut out, true).err().unwrap();
            assert_eq!(arg(e), "window");
            let e = rc.set_edited(&win, &v[1], true).err().unwrap();
            assert_eq!(arg(e), "window");
        }
        let bad = Patch {
            sh: None,
            env: Some(ParaboloidMap {
                size: 4,
                channels: 3,
                data: vec![0.0; 5],
            }),
        };
        assert_eq!(arg(rc.set_patches(vec![bad]).err().unwrap()), "patches");
        // k_D = 3e38 overflows float32 in eq. 5 at γ = 1 (D~ ≥ 1.2 somewhere): refused, naming a
        // pixel.
        let e = rc
            .run(&full, Some(&v[1]), 3e38, 1.0, &mut out, true)
            .err()
            .unwrap();
        assert!(e.to_string().contains("overflows"), "{e}");
    }

    /// Unmodified normals with k_D = k_R = 1 give I bit for bit (any γ, view, NaN inputs), on both
    /// paths, and nothing is counted.
    #[test]
    fn recomposite_identity_is_bit_exact() {
        let mut g = Rng(0x1234_5678_9abc_def1);
        let n = 2500;
        let ids: Vec<i32> = (0..n).map(|i| (i % 4) - 1).collect();
        let v3 = |g: &mut Rng| -> Vec<f32> { (0..3 * n).map(|_| 2.0 * g.next() - 0.5).collect() };
        let normals = v3(&mut g);
        let view = v3(&mut g);
        let mut diffuse = v3(&mut g);
        diffuse[7] = f32::NAN;
        let reflection = v3(&mut g);
        let mut image = v3(&mut g);
        image[10] = f32::NAN;
        image[11] = f32::INFINITY;
        let a: Vec<f32> = (0..n).map(|_| g.next()).collect();
        let map = ParaboloidMap {
            size: 8,
            channels: 3,
            data: (0..2 * 8 * 8 * 3).map(|_| g.next()).collect(),
        };
        let sh: [[f64; SH_COEFFS]; 3] =
            std::array::from_fn(|_| std::array::from_fn(|_| g.next() as f64));
        let patches = vec![
            Patch {
                sh: Some(sh),
                env: Some(map),
            },
            Patch {
                sh: Some(sh),
                env: None,
            },
            Patch::default(),
        ];
        for gamma in [1.0, 2.2] {
            let b = Buffers {
                ids: &ids,
                normals: &normals,
                edited: &normals,
                view: &view,
                diffuse: &diffuse,
                reflection: &reflection,
                alpha_d: &a,
                alpha_r: &a,
                alpha: &a,
                image: &image,
                diffuse_color: &[],
                reflection_color: &[],
            };
            for simd in [false, true] {
                let (out, st) = recomposite_with(
                    &b,
                    &patches,
                    &Params {
                        gamma,
                        ..Params::default()
                    },
                    simd,
                )
                .unwrap();
                assert_eq!((st.edited, st.masked), (0, 0));
                assert!(
                    out.iter()
                        .zip(&image)
                        .all(|(x, y)| x.to_bits() == y.to_bits()),
                    "γ {gamma} simd {simd}"
                );
            }
        }
    }

    /// `pow_lanes` against `powf`: within 1 ulp (f32) over the whole range — subnormals, huge
    /// values, exponents from 1/2.2 to 10 — and powf's values for 0, ∞, negatives and NaN
    /// (after the clamp to ≥ 0).
    #[test]
    fn pow_lanes_matches_powf() {
        let mut g = Rng(0x0bad_cafe_f00d_1234);
        for p in [1.0 / 2.2f32, 0.5, 1.0 / 1.8, 2.0, 3.3, 10.0, 1.0] {
            let mut worst = 0u32;
            for round in 0..400 {
                let mut x = [0.0f32; LANES];
                for (l, v) in x.iter_mut().enumerate() {
                    // log-uniform over the positive f32 range (subnormals included) and specials.
                    *v = f32::from_bits((g.next() * 0x7f7f_ffff as f32) as u32);
                    if round == 0 {
                        *v = [
                            0.0,
                            -0.0,
                            -1.0,
                            f32::NAN,
                            f32::INFINITY,
                            f32::NEG_INFINITY,
                            1.0,
                            f32::MIN_POSITIVE,
                            1e-45,
                            f32::MAX,
                            2.0,
                            0.5,
                        ][l % 12];
                    }
                }
                let mut y = x;
                pow_lanes(&mut y, p as f64, LANES);
                for l in 0..LANES {
                    let want = x[l].max(0.0).powf(p);
                    if want.is_finite() && want > 0.0 && y[l].is_finite() {
                        worst = worst.max(want.to_bits().abs_diff(y[l].to_bits()));
                    } else {
                        assert_eq!(
                            y[l].to_bits(),
                            want.to_bits(),
                            "{}^{p}: {} vs {want}",
                            x[l],
                            y[l]
                        );
                    }
                }
            }
            assert!(worst <= 1, "p {p}: {worst} ulp");
        }
    }
}
