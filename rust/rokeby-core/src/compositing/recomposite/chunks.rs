//! Chunks of pixels: the AVX2 or portable instantiation chosen at run time, the listing of the
//! pixels that need eqs. 3–5, the copy of I (streaming stores where nothing is edited) and each
//! thread's lane arrays ([`Work`]).

use super::*;

#[cfg(target_arch = "x86_64")]
pub(super) fn avx2_available() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

#[cfg(not(target_arch = "x86_64"))]
pub(super) fn avx2_available() -> bool {
    false
}

pub(super) fn run_chunk(f: &Frame, base: usize, o: &mut [MaybeUninit<f32>], w: &mut Work) -> Stats {
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
pub(super) unsafe fn chunk_avx2(
    f: &Frame,
    base: usize,
    o: &mut [MaybeUninit<f32>],
    w: &mut Work,
) -> Stats {
    chunk(f, base, o, w)
}

/// One chunk of pixels (`o` = I~ of pixels base.., not yet written): first the pixels that need
/// eqs. 3–5 (in a patch, normal or material changed, the patch has an SH or a map) are listed,
/// then I is copied into `o`, then the listed pixels run in batches of [`LANES`].
#[inline(always)]
pub(super) fn chunk(f: &Frame, base: usize, o: &mut [MaybeUninit<f32>], w: &mut Work) -> Stats {
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
pub(super) fn copy_streaming(src: &[f32], o: &mut [MaybeUninit<f32>]) {
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
pub(super) fn with_work<R>(run: impl FnOnce(&mut Work) -> R) -> R {
    WORK.with(|cell| match cell.try_borrow_mut() {
        Ok(mut slot) => run(slot.get_or_insert_with(Work::new)),
        Err(_) => run(&mut Work::new()),
    })
}

/// The lane arrays (structure of arrays, one f32 lane per pixel) of one batch.
pub(super) struct Work {
    /// A chunk's pixels to recomposite ([`CHUNK`] entries).
    pub(super) todo: Vec<u32>,
    pub(super) k: [usize; LANES],
    pub(super) px: [usize; LANES],
    pub(super) id: [usize; LANES],
    pub(super) d0: [Lanes; 3],
    pub(super) r0: [Lanes; 3],
    pub(super) cd: [Lanes; 3],
    pub(super) cr: [Lanes; 3],
    pub(super) ad: Lanes,
    pub(super) ar: Lanes,
    pub(super) a: Lanes,
    /// A gathered vector before normalisation.
    pub(super) raw: [Lanes; 3],
    pub(super) nn: [Lanes; 3],
    pub(super) ne: [Lanes; 3],
    pub(super) vv: [Lanes; 3],
    pub(super) ok: [bool; LANES],
    pub(super) dy: [Lanes; SH_COEFFS],
    pub(super) dt: [Lanes; 3],
    pub(super) r: [Lanes; 3],
    pub(super) re: [Lanes; 3],
    pub(super) chord: Lanes,
    pub(super) wgt: Lanes,
    pub(super) size: Lanes,
    pub(super) last: [i32; LANES],
    pub(super) face: [i32; LANES],
    pub(super) tx: Lanes,
    pub(super) ty: Lanes,
    pub(super) fx: Lanes,
    pub(super) fy: Lanes,
    /// Texel indices (not ×3) of the four corners i0j0, i0j1, i1j0, i1j1.
    pub(super) corner: [[i32; LANES]; 4],
    pub(super) fetch: [bool; LANES],
    pub(super) t: [[Lanes; 3]; 4],
    pub(super) shade: [Lanes; 3],
    pub(super) shade0: [Lanes; 3],
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
