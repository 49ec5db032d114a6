//! A [`Recompositor`]: the session of one frame whose normals are edited again and again (the
//! brush), and the per-pixel tables it may keep ([`Prepared`]).

use super::*;

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
    pub(super) simd: bool,
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

/// Pixels of one block of [`Prepared::tab`]: one batch's lanes.
pub(super) const BLOCK: usize = LANES;
/// Blocks per parallel task when preparing.
pub(super) const PREP_BLOCKS: usize = CHUNK / BLOCK;

impl Prepared {
    /// The tables of the frame `f` (`f.pre` is None; the passes already validated) of `n` pixels,
    /// blocks of pixels in parallel, through the same lane functions as a batch.
    pub(super) fn new(f: &Frame, n: usize) -> Prepared {
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
    pub(super) fn comps(view: View) -> usize {
        if matches!(view, View::PerPixel) {
            9
        } else {
            6
        }
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> usize {
        4 * self.tab.len() + self.ok.len()
    }

    /// The lanes' unit n, v, validity and eq. 5's subtracted term into `w`; `run` as for
    /// [`gather3`].
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    pub(super) fn load(&self, run: Option<usize>, nb: usize, w: &mut Work, view: View) {
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
pub(super) fn prepare_block(
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
pub(super) unsafe fn prepare_block_avx2(
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
pub(super) fn prepare_block_lanes(
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
