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
//! eqs. 3–5 (unmodified normals are found 16 at a time), then runs them in batches of up to 64,
//! structure of arrays (one f32 lane per pixel, loops over the lanes that LLVM vectorises), in an
//! AVX2 instantiation where the CPU has it (detected at run time; the portable one otherwise).
//! Both give the same bits as the former one-pixel-at-a-time code (kept in the tests as the
//! reference): the same IEEE operations in the same order, no FMA contraction, n, ñ and v still
//! normalised in f64.

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
    recomposite_with(b, patches, p, true)
}

/// Edited pixels per batch: eqs. 3–5 run on up to 64 pixels at once, structure of arrays (one
/// f32 lane each; 8 lanes per AVX2 register, 4 per SSE2 register on the portable path).
const LANES: usize = 64;
type Lanes = [f32; LANES];
/// Pixels compared at once when looking for unmodified normals.
const SCAN: usize = 16;
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
}

/// [`recomposite`] with the AVX2 instantiation allowed (`simd`) or not: both give the same bits
/// (no FMA contraction, the same operations in the same order).
fn recomposite_with(b: &Buffers, patches: &[Patch], p: &Params, simd: bool) -> Result<(Vec<f32>, Stats)> {
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
    let f = Frame {
        b,
        sh: patches.iter().map(|q| q.sh.map(|c| c.map(|ch| ch.map(|x| x as f32))).unwrap_or([[0.0; SH_COEFFS]; 3])).collect(),
        env_data: patches.iter().map(|q| q.env.as_ref().map_or(&NO_MAP[..], |e| &e.data[..])).collect(),
        has_env: patches.iter().map(|q| q.env.is_some()).collect(),
        env_size: patches.iter().map(|q| q.env.as_ref().map_or(1.0, |e| e.size as f32)).collect(),
        env_n: patches.iter().map(|q| q.env.as_ref().map_or(1, |e| e.size)).collect(),
        has_content: patches.iter().map(|q| q.sh.is_some() || q.env.is_some()).collect(),
        k_d: p.k_d as f32,
        k_r: p.k_r as f32,
        unit_material: p.k_d == 1.0 && p.k_r == 1.0,
        inv_gamma: (1.0 / p.gamma) as f32,
        gamma_one: p.gamma == 1.0,
        inv_eps: (1.0 / p.epsilon) as f32,
        chord_eps: if p.epsilon >= std::f64::consts::PI { f32::INFINITY } else { (2.0 * (0.5 * p.epsilon).sin()) as f32 },
        view: match b.view.len() == 3 {
            false => View::PerPixel,
            true => unit(b.view).map_or(View::Invalid, |v| View::Constant(to32(v))),
        },
        avx2: simd && avx2_available(),
    };
    // Chunks of rows in parallel; every pixel starts as I (one copy), and only pixels whose normal
    // or material changed run eqs. 3–5 — in f32 (the buffers' precision), 8 at a time: with ñ = n
    // the formulas still give I bit for bit (zero SH difference, zero chord, identical shade and
    // shade0).
    // The copy of I is made by the tasks too, into memory that is written once (not zeroed
    // first), in parallel.
    let mut out: Vec<f32> = Vec::with_capacity(3 * n);
    let stats = out.spare_capacity_mut()[..3 * n]
        .par_chunks_mut(3 * CHUNK)
        .enumerate()
        .map(|(chunk, o)| {
            let src = &b.image[3 * chunk * CHUNK..3 * chunk * CHUNK + o.len()];
            for (d, s) in o.iter_mut().zip(src) {
                d.write(*s);
            }
            // SAFETY: every element of `o` was initialised just above (o.len() == src.len()).
            let o = unsafe { &mut *(o as *mut [std::mem::MaybeUninit<f32>] as *mut [f32]) };
            run_chunk(&f, chunk * CHUNK, o)
        })
        .reduce(Stats::default, |x, y| Stats { masked: x.masked + y.masked, edited: x.edited + y.edited });
    // SAFETY: the chunks cover all 3n elements and each chunk was initialised by its task (a panic
    // there would have unwound past this line, leaving the length 0).
    unsafe { out.set_len(3 * n) };
    Ok((out, stats))
}

#[cfg(target_arch = "x86_64")]
fn avx2_available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_available() -> bool {
    false
}

fn run_chunk(f: &Frame, base: usize, o: &mut [f32]) -> Stats {
    #[cfg(target_arch = "x86_64")]
    if f.avx2 {
        // SAFETY: AVX2 was detected on this CPU (`avx2_available`).
        return unsafe { chunk_avx2(f, base, o) };
    }
    chunk(f, base, o)
}

/// [`chunk`] compiled for AVX2: the lane loops become 8-wide ymm arithmetic. Only vectorisation
/// changes; the operations and their rounding are those of the portable path.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn chunk_avx2(f: &Frame, base: usize, o: &mut [f32]) -> Stats {
    chunk(f, base, o)
}

/// One chunk of pixels (`o` = I~ of pixels base.., initially I): first the pixels that need
/// eqs. 3–5 (in a patch, normal or material changed, the patch has an SH or a map), then those
/// in batches of [`LANES`].
#[inline(always)]
fn chunk(f: &Frame, base: usize, o: &mut [f32]) -> Stats {
    let b = f.b;
    let mut st = Stats::default();
    let mut todo = [0u32; CHUNK];
    let mut m = 0;
    let npx = o.len() / 3;
    let mut start = 0;
    while start < npx {
        let end = (start + SCAN).min(npx);
        if f.unit_material && end - start == SCAN {
            // SCAN unmodified normals in a row (the common case): one vector comparison.
            let i = 3 * (base + start);
            let (nrm, edt) = (&b.normals[i..i + 3 * SCAN], &b.edited[i..i + 3 * SCAN]);
            let mut same = true;
            for j in 0..3 * SCAN {
                same &= nrm[j] == edt[j];
            }
            if same {
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
            let same = f.unit_material & (nrm[3 * q] == edt[3 * q]) & (nrm[3 * q + 1] == edt[3 * q + 1]) & (nrm[3 * q + 2] == edt[3 * q + 2]);
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
    for ks in todo[..m].chunks(LANES) {
        batch(f, base, ks, o, &mut st);
    }
    st
}

/// Unit vectors of 8 lanes, normalised in f64 as [`unit`] does (then rounded to f32), and whether
/// each could be (finite, length > 1e-12).
#[inline(always)]
fn unit_lanes(v: &[Lanes; 3], nb: usize) -> ([Lanes; 3], [bool; LANES]) {
    let nb = nb.min(LANES);
    let mut u = [[0.0f32; LANES]; 3];
    let mut ok = [false; LANES];
    for l in 0..nb {
        let (x, y, z) = (v[0][l] as f64, v[1][l] as f64, v[2][l] as f64);
        let len = (x * x + y * y + z * z).sqrt();
        ok[l] = len.is_finite() & (len > 1e-12);
        let r = 1.0 / len;
        u[0][l] = (x * r) as f32;
        u[1][l] = (y * r) as f32;
        u[2][l] = (z * r) as f32;
    }
    (u, ok)
}

/// The order-2 SH basis Y_k(n) of eq. 1 ([`sh::basis`] in f32) for 8 unit normals.
#[inline(always)]
fn basis_lanes(n: &[Lanes; 3], nb: usize) -> [Lanes; SH_COEFFS] {
    let nb = nb.min(LANES);
    let (c0, c1, c2) = (0.282_094_8_f32, 0.488_602_5_f32, 1.092_548_4_f32);
    let mut y = [[0.0f32; LANES]; SH_COEFFS];
    for l in 0..nb {
        let (x, yy, z) = (n[0][l], n[1][l], n[2][l]);
        y[0][l] = c0;
        y[1][l] = c1 * yy;
        y[2][l] = c1 * z;
        y[3][l] = c1 * x;
        y[4][l] = c2 * x * yy;
        y[5][l] = c2 * yy * z;
        y[6][l] = 0.315_391_57 * (3.0 * z * z - 1.0);
        y[7][l] = c2 * x * z;
        y[8][l] = 0.546_274_2 * (x * x - yy * yy);
    }
    y
}

/// Mirror reflection of the view v about n: r = 2(n·v)n − v, for 8 lanes.
#[inline(always)]
fn reflect_lanes(v: &[Lanes; 3], n: &[Lanes; 3], nb: usize) -> [Lanes; 3] {
    let nb = nb.min(LANES);
    let mut r = [[0.0f32; LANES]; 3];
    for l in 0..nb {
        let d = 2.0 * (n[0][l] * v[0][l] + n[1][l] * v[1][l] + n[2][l] * v[2][l]);
        for c in 0..3 {
            r[c][l] = d * n[c][l] - v[c][l];
        }
    }
    r
}

/// Eqs. 3–5 for up to [`LANES`] pixels `ks` (offsets from `base`) of one chunk, structure of
/// arrays: the buffers are gathered into lanes (a short batch repeats its last pixel, whose
/// results are not stored), computed lane-wise, and I~ is stored for the pixels that pass the
/// masks (unit n, ñ and v; finite shading, reflectance and α's).
#[inline(always)]
fn batch(f: &Frame, base: usize, ks: &[u32], o: &mut [f32], st: &mut Stats) {
    let b = f.b;
    // The loops below run over the batch's nb lanes, a run-time count: LLVM then keeps them as
    // loops and vectorises them (a constant count of 8 was unrolled and left scalar).
    let nb = ks.len().min(LANES);
    let mut k = [0usize; LANES];
    let mut px = [0usize; LANES];
    let mut id = [0usize; LANES];
    for l in 0..nb {
        k[l] = ks[l] as usize;
        px[l] = base + k[l];
        id[l] = b.ids[px[l]] as usize;
    }
    // Consecutive pixels (the common case: a full batch inside an edited region) are loaded as
    // one slice per buffer and de-interleaved; others are gathered lane by lane.
    let run = (nb == LANES && k[LANES - 1] - k[0] == LANES - 1).then_some(px[0]);
    let vec3 = |v: &[f32]| gather3(v, &px, run, nb);
    let col = |v: &[f32]| if v.is_empty() { [[1.0; LANES]; 3] } else { gather3(v, &px, run, nb) };
    let opt = |v: &[f32]| if v.is_empty() { [1.0; LANES] } else { gather1(v, &px, run, nb) };
    let (d0, r0) = (vec3(b.diffuse), vec3(b.reflection));
    let (cd, cr) = (col(b.diffuse_color), col(b.reflection_color));
    let (ad, ar, a) = (opt(b.alpha_d), opt(b.alpha_r), opt(b.alpha));
    let (nn, ok_n) = unit_lanes(&vec3(b.normals), nb);
    let (ne, ok_e) = unit_lanes(&vec3(b.edited), nb);
    let (vv, ok_v) = match f.view {
        View::PerPixel => unit_lanes(&vec3(b.view), nb),
        View::Constant(v) => ([[v[0]; LANES], [v[1]; LANES], [v[2]; LANES]], [true; LANES]),
        View::Invalid => ([[0.0; LANES], [0.0; LANES], [1.0; LANES]], [false; LANES]),
    };
    let mut ok = [false; LANES];
    for l in 0..nb {
        let mut fin = ad[l].is_finite() & ar[l].is_finite() & a[l].is_finite();
        for c in 0..3 {
            fin &= d0[c][l].is_finite() & r0[c][l].is_finite() & cd[c][l].is_finite() & cr[c][l].is_finite();
        }
        ok[l] = fin & ok_n[l] & ok_e[l] & ok_v[l];
    }
    let uniform = id[..nb].iter().all(|&x| x == id[0]);

    // Eq. 3: D(ñ) − D(n) = Σ_k c_k (Y_k(ñ) − Y_k(n)), the basis evaluated once per normal; the
    // clamp [·] = max(min(0, D0), ·); D~ = D0 + α_D([·] − D0).
    let (yn, ye) = (basis_lanes(&nn, nb), basis_lanes(&ne, nb));
    let mut dy = [[0.0f32; LANES]; SH_COEFFS];
    for j in 0..SH_COEFFS {
        for l in 0..nb {
            dy[j][l] = ye[j][l] - yn[j][l];
        }
    }
    let mut dt = [[0.0f32; LANES]; 3];
    for c in 0..3 {
        let mut s = [0.0f32; LANES];
        if uniform {
            let co = &f.sh[id[0]][c];
            for j in 0..SH_COEFFS {
                for l in 0..nb {
                    s[l] += co[j] * dy[j][l];
                }
            }
        } else {
            for j in 0..SH_COEFFS {
                for l in 0..nb {
                    s[l] += f.sh[id[l]][c][j] * dy[j][l];
                }
            }
        }
        for l in 0..nb {
            let res = (d0[c][l] + s[l]).max(d0[c][l].min(0.0));
            dt[c][l] = d0[c][l] + ad[l] * (res - d0[c][l]);
        }
    }

    // Eq. 4. The angle from the chord |r − r~| = 2 sin(θ/2): v = 1 without any trigonometry once
    // the chord reaches 2 sin(ε/2); exactly 0 when r~ = r.
    let r = reflect_lanes(&vv, &nn, nb);
    let re = reflect_lanes(&vv, &ne, nb);
    let mut chord = [0.0f32; LANES];
    let mut vis = [1.0f32; LANES];
    let mut short = false;
    for l in 0..nb {
        let dr = [r[0][l] - re[0][l], r[1][l] - re[1][l], r[2][l] - re[2][l]];
        chord[l] = (dr[0] * dr[0] + dr[1] * dr[1] + dr[2] * dr[2]).sqrt();
        short |= !(chord[l] >= f.chord_eps);
    }
    if short {
        for l in 0..nb {
            if !(chord[l] >= f.chord_eps) {
                vis[l] = 2.0 * (0.5 * chord[l]).min(1.0).asin() * f.inv_eps;
            }
        }
    }
    let mut wgt = [0.0f32; LANES];
    for l in 0..nb {
        wgt[l] = vis[l] * ar[l];
    }
    // R(r~): the dual-paraboloid lookup, the texel coordinates lane-wise, the bilinear fetch per
    // lane (where the patch has a map and v α_R ≠ 0; else R0, which eq. 4 then returns).
    let mut size = [0.0f32; LANES];
    for l in 0..nb {
        size[l] = f.env_size[id[l]];
    }
    let (face, tx, ty) = paraboloid_texel_lanes(&re, &size, nb);
    // The four texels (i0|i1, j0|j1) around (tx, ty) and the bilinear weights, ParaboloidMap's
    // way; fetched for every lane (a patch without a map has a 1×1 map of zeros here: the
    // coordinates are always inside the map), used where the patch has a map and v α_R ≠ 0.
    let (mut fx, mut fy) = ([0.0f32; LANES], [0.0f32; LANES]);
    let (mut j0, mut i0, mut j1, mut i1) = ([0i32; LANES], [0i32; LANES], [0i32; LANES], [0i32; LANES]);
    let mut last = [0i32; LANES];
    let mut fetch = [false; LANES];
    for l in 0..nb {
        last[l] = f.env_n[id[l]] as i32 - 1;
        fetch[l] = f.has_env[id[l]];
    }
    for l in 0..nb {
        // tx, ty ∈ [0, size − 1]: truncation is the floor, as `as usize` was.
        j0[l] = tx[l] as i32;
        i0[l] = ty[l] as i32;
        j1[l] = (j0[l] + 1).min(last[l]);
        i1[l] = (i0[l] + 1).min(last[l]);
        fx[l] = tx[l] - j0[l] as f32;
        fy[l] = ty[l] - i0[l] as f32;
        fetch[l] &= ok[l] & (wgt[l] != 0.0);
    }
    let mut t = [[[0.0f32; LANES]; 3]; 4];
    for l in 0..nb {
        let (data, n) = (f.env_data[id[l]], f.env_n[id[l]]);
        let (row0, row1) = ((face[l] * n + i0[l] as usize) * n, (face[l] * n + i1[l] as usize) * n);
        let corner = [row0 + j0[l] as usize, row0 + j1[l] as usize, row1 + j0[l] as usize, row1 + j1[l] as usize];
        for q in 0..4 {
            let v = &data[3 * corner[q]..3 * corner[q] + 3];
            for c in 0..3 {
                t[q][c][l] = v[c];
            }
        }
    }
    let mut look = r0;
    for c in 0..3 {
        for l in 0..nb {
            let top = t[0][c][l] + fx[l] * (t[1][c][l] - t[0][c][l]);
            let bot = t[2][c][l] + fx[l] * (t[3][c][l] - t[2][c][l]);
            let v = top + fy[l] * (bot - top);
            if fetch[l] {
                look[c][l] = v;
            }
        }
    }

    // Eqs. 4 and 5: R~ = R0 + vα_R(R(r~) − R0); I~ = I + α[g(k_D c_D D~ + k_R c_R R~) − g(c_D D0 + c_R R0)].
    let mut shade = [[0.0f32; LANES]; 3];
    let mut shade0 = [[0.0f32; LANES]; 3];
    for c in 0..3 {
        for l in 0..nb {
            let rt = r0[c][l] + wgt[l] * (look[c][l] - r0[c][l]);
            shade[c][l] = f.k_d * (cd[c][l] * dt[c][l]) + f.k_r * (cr[c][l] * rt);
            shade0[c][l] = cd[c][l] * d0[c][l] + cr[c][l] * r0[c][l];
        }
    }
    if !f.gamma_one {
        for c in 0..3 {
            for l in 0..nb {
                shade[c][l] = shade[c][l].max(0.0).powf(f.inv_gamma);
                shade0[c][l] = shade0[c][l].max(0.0).powf(f.inv_gamma);
            }
        }
    }
    let mut delta = [[0.0f32; LANES]; 3];
    for c in 0..3 {
        for l in 0..nb {
            delta[c][l] = a[l] * (shade[c][l] - shade0[c][l]);
        }
    }
    if run.is_some() && ok[..nb].iter().all(|&x| x) {
        st.edited += LANES;
        let q = &mut o[3 * k[0]..3 * k[0] + 3 * LANES];
        for l in 0..nb {
            for c in 0..3 {
                q[3 * l + c] += delta[c][l];
            }
        }
        return;
    }
    for l in 0..nb {
        if ok[l] {
            st.edited += 1;
            let q = &mut o[3 * k[l]..3 * k[l] + 3];
            for c in 0..3 {
                q[c] += delta[c][l];
            }
        } else {
            st.masked += 1;
        }
    }
}

/// v[3·px_l + c] for the 8 lanes' pixels px (3-vector buffers), as lanes per component; `run`:
/// the pixels are run, run + 1, …, run + 7.
#[inline(always)]
fn gather3(v: &[f32], px: &[usize; LANES], run: Option<usize>, nb: usize) -> [Lanes; 3] {
    let nb = nb.min(LANES);
    let mut g = [[0.0f32; LANES]; 3];
    if let Some(p) = run {
        let q = &v[3 * p..3 * p + 3 * LANES];
        for l in 0..nb {
            for c in 0..3 {
                g[c][l] = q[3 * l + c];
            }
        }
    } else {
        for l in 0..nb {
            let q = &v[3 * px[l]..3 * px[l] + 3];
            for c in 0..3 {
                g[c][l] = q[c];
            }
        }
    }
    g
}

/// v[px_l] for the 8 lanes' pixels px (scalar buffers); `run` as for [`gather3`].
#[inline(always)]
fn gather1(v: &[f32], px: &[usize; LANES], run: Option<usize>, nb: usize) -> Lanes {
    let nb = nb.min(LANES);
    let mut g = [0.0f32; LANES];
    if let Some(p) = run {
        g[..nb].copy_from_slice(&v[p..p + nb]);
    } else {
        for l in 0..nb {
            g[l] = v[px[l]];
        }
    }
    g
}

/// The texel position of direction d in a dual-paraboloid map of `size` texels (per lane):
/// `ParaboloidMap::lookup`'s face choice and convention (texel centres, coordinates clamped to
/// the map), for 8 lanes. Returns (face, x, y) with x, y ∈ [0, size − 1].
#[inline(always)]
fn paraboloid_texel_lanes(d: &[Lanes; 3], size: &Lanes, nb: usize) -> ([usize; LANES], Lanes, Lanes) {
    let nb = nb.min(LANES);
    let mut face = [0usize; LANES];
    let (mut tx, mut ty) = ([0.0f32; LANES], [0.0f32; LANES]);
    for l in 0..nb {
        let (x, y, z) = (d[0][l], d[1][l], d[2][l]);
        let len = (x * x + y * y + z * z).sqrt();
        let unit = (len > 0.0) & len.is_finite();
        let (x, y, z) = if unit { (x / len, y / len, z / len) } else { (0.0, 0.0, 1.0) };
        face[l] = usize::from(z < 0.0);
        let k = 1.0 / (1.0 + z.abs());
        let s = size[l];
        tx[l] = clamp_lane((x * k + 1.0) * 0.5 * s - 0.5, s - 1.0);
        ty[l] = clamp_lane((y * k + 1.0) * 0.5 * s - 0.5, s - 1.0);
    }
    (face, tx, ty)
}

/// `x.clamp(0.0, hi)` without the panic path (hi ≥ 0 here), so that it vectorises.
#[inline(always)]
fn clamp_lane(x: f32, hi: f32) -> f32 {
    let x = if x < 0.0 { 0.0 } else { x };
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
    /// and constant views. Bit-identical results and the same edited/masked counts.
    #[test]
    fn recomposite_batches_match_scalar_reference() {
        let mut g = Rng(0x9e37_79b9_7f4a_7c15);
        let (w, h) = (97, 43); // 4171 pixels: 4 chunks, the last one partial
        let n = w * h;
        let map = |g: &mut Rng, size: usize| ParaboloidMap { size, channels: 3, data: (0..2 * size * size * 3).map(|_| g.next()).collect() };
        let sh = |g: &mut Rng| -> [[f64; SH_COEFFS]; 3] { std::array::from_fn(|_| std::array::from_fn(|_| 2.0 * g.next() as f64 - 1.0)) };
        let patches = vec![
            Patch { sh: Some(sh(&mut g)), env: Some(map(&mut g, 16)) },
            Patch { sh: Some(sh(&mut g)), env: None },
            Patch { sh: None, env: Some(map(&mut g, 5)) },
            Patch { sh: None, env: None },
            Patch { sh: Some(sh(&mut g)), env: Some(map(&mut g, 1)) },
        ];
        let mut ids = vec![0i32; n];
        let mut normals = vec![0.0f32; 3 * n];
        let mut edited = vec![0.0f32; 3 * n];
        let mut view = vec![0.0f32; 3 * n];
        let buf = |g: &mut Rng, lo: f32, hi: f32| -> Vec<f32> { (0..3 * n).map(|_| lo + (hi - lo) * g.next()).collect() };
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
            ids[i] = if (i / 200) % 3 == 2 { (g.next() * 7.0) as i32 - 1 } else { ((i / 200) % 5) as i32 };
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
                [nv[0] + g.next() - 0.5, nv[1] - 0.3, nv[2] * (0.2 + g.next())]
            };
            edited[3 * i..3 * i + 3].copy_from_slice(&e);
            let vv = [0.3 * (g.next() - 0.5), 0.3 * (g.next() - 0.5), 1.0];
            view[3 * i..3 * i + 3].copy_from_slice(&vv);
        }
        // Non-finite and degenerate inputs.
        for &(i, what) in &[(5usize, 0), (300, 1), (301, 2), (777, 3), (1500, 4), (2222, 5), (4170, 0), (3001, 6)] {
            match what {
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
                let p = Params { k_d, k_r, gamma, epsilon };
                let (want, st0) = recomposite_scalar(&b, &patches, &p).unwrap();
                assert!(st0.edited > 0 && st0.masked > 0, "{st0:?}");
                for simd in [false, true] {
                    let (got, st) = recomposite_with(&b, &patches, &p, simd).unwrap();
                    assert_eq!((st.edited, st.masked), (st0.edited, st0.masked), "γ {gamma} simd {simd}");
                    for (i, (x, y)) in got.iter().zip(&want).enumerate() {
                        assert!(x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()), "value {i}: {x} vs {y} (γ {gamma}, k_D {k_d}, simd {simd})");
                        assert!(!x.is_nan(), "NaN output at {i}");
                    }
                }
                cases += 1;
            }
        }
        assert_eq!(cases, 15);
    }
}
