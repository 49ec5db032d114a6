//! Eqs. 3–5 on lanes of up to 64 pixels (structure of arrays, one f32 lane per pixel): unit
//! vectors, the SH basis difference, reflection, the power of eq. 5, the texel gathers.

use super::*;

/// Squared lengths (f32) for which [`unit_lanes`] decides in f32: inside, the f64 squared length
/// is within a few ulps of it, far from [`unit_row`]'s limits (length > 1e-12, finite) and from f32
/// underflow/overflow of the squares; outside (tiny, huge, NaN or inf), the lane is redone in f64.
pub(super) const SQ_MIN: f32 = 1e-20;
pub(super) const SQ_MAX: f32 = 1e36;

/// Unit vectors of the lanes `v` (into `u`, in f32: 1/√(x² + y² + z²)), and whether each could
/// be normalised, exactly as [`unit_row`] decides it (finite, f64 length > 1e-12): lanes whose f32
/// squared length is outside (SQ_MIN, SQ_MAX) — rare: tiny, huge or non-finite — are classified
/// and normalised in f64 as [`unit_row`] does. `ok` is and-ed with the result.
#[inline(always)]
pub(super) fn unit_lanes(v: &[Lanes; 3], u: &mut [Lanes; 3], ok: &mut [bool; LANES], nb: usize) {
    let nb = nb.min(LANES);
    let mut rare = false;
    for l in 0..nb {
        let (x, y, z) = (v[0][l], v[1][l], v[2][l]);
        let s = x * x + y * y + z * z;
        let clear = (s > SQ_MIN) & (s < SQ_MAX);
        rare |= !clear;
        // 1/√s from f32 (≈ 1e-7 relative), then a Newton step in f64 on the f64 squared length
        // (exact squares of f32 values): ≈ 1e-14 relative, so the rounded components are
        // [`unit_row`]'s except in rare near-ties (1 ulp there).
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
pub(super) fn basis_diff_lanes(
    n: &[Lanes; 3],
    e: &[Lanes; 3],
    dy: &mut [Lanes; SH_COEFFS],
    nb: usize,
) {
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
pub(super) fn reflect_lanes(v: &[Lanes; 3], n: &[Lanes; 3], r: &mut [Lanes; 3], nb: usize) {
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
pub(super) fn pow_lanes(x: &mut Lanes, p: f64, nb: usize) {
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
pub(super) fn batch(
    f: &Frame,
    base: usize,
    ks: &[u32],
    o: &mut [f32],
    st: &mut Stats,
    w: &mut Work,
) {
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
pub(super) unsafe fn fetch_avx2(
    data: &[f32],
    corner: &[[i32; LANES]; 4],
    t: &mut [[Lanes; 3]; 4],
    nb: usize,
) {
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
pub(super) fn gather_passes(b: &Buffers, run: Option<usize>, nb: usize, w: &mut Work, simd: bool) {
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
pub(super) fn static_terms(f: &Frame, run: Option<usize>, nb: usize, w: &mut Work) {
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
pub(super) fn shade0_lanes(f: &Frame, nb: usize, w: &mut Work) {
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

/// v[3·px_l + c] for the lanes' pixels px (3-vector buffers), as lanes per component, into g;
/// `run`: the pixels are run, run + 1, …, run + LANES − 1.
#[inline(always)]
pub(super) fn gather3(
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
pub(super) unsafe fn deinterleave_avx2(q: &[f32; 3 * LANES], g: &mut [Lanes; 3]) {
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
pub(super) fn col3(
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
pub(super) fn opt1(v: &[f32], px: &[usize; LANES], run: Option<usize>, nb: usize, g: &mut Lanes) {
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
pub(super) fn paraboloid_texel_lanes(
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
pub(super) fn clamp_lane(x: f32, hi: f32) -> f32 {
    let x = if x >= 0.0 { x } else { 0.0 };
    if x > hi {
        hi
    } else {
        x
    }
}
